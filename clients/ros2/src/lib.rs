//! scout-ros2: ROS 2 over rmw_zenoh, without a ROS install: `scout ros2` (the `scout-ros2` program), the bridge that makes the chassis
//! a ROS 2 node ([`bridge`]), with its settings ([`config`]), the messages it makes from the
//! state ([`publish`]), when a cmd_vel stream may take control ([`stream`]), the CDR of its
//! messages ([`msgs`], [`cdr`]) and what rmw_zenoh puts around them ([`rmw`]: data keys, the
//! sample attachment, liveliness tokens).

pub mod bridge;
pub mod cdr;
pub mod config;
pub mod dds_node;
pub mod msgs;
pub mod publish;
pub mod rmw;
pub mod stream;
pub mod zenoh_node;
