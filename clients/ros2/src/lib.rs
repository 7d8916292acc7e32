//! scout-ros2: the chassis as a ROS 2 node, without a ROS install: `scout ros2` (the `scout-ros2`
//! program), the bridge ([`bridge`]) over DDS ([`dds_node`], with its [`ros_discovery`] entry,
//! decoding what it reads as [`dds_wire`] says)
//! or rmw_zenoh ([`zenoh_node`], [`rmw`]: data keys, the sample attachment, liveliness tokens),
//! with its settings ([`config`]), the messages it makes from the state ([`publish`]), when a
//! cmd_vel stream may take control ([`stream`]), the CDR of its messages ([`msgs`], [`cdr`]) and
//! their definitions ([`definitions`]).
//! Without the `node` feature (on by default), only the sans-IO parts: the messages, their CDR
//! and settings, for a recorder that writes them.

#[cfg(feature = "node")]
pub mod bridge;
pub mod cdr;
pub mod config;
#[cfg(feature = "node")]
pub mod dds_node;
#[cfg(feature = "dds")]
pub mod dds_wire;
pub mod definitions;
pub mod msgs;
pub mod publish;
pub mod rmw;
pub mod ros_discovery;
pub mod stream;
#[cfg(feature = "node")]
pub mod zenoh_node;
