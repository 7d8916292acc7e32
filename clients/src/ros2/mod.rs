//! ROS 2 over rmw_zenoh, without a ROS install: the CDR of the messages the chassis' ROS 2
//! bridge speaks ([`msgs`], [`cdr`]) and what rmw_zenoh puts around them ([`rmw`]: data keys,
//! the sample attachment, liveliness tokens). The bridge itself (`scout ros2`) is not built yet.

pub mod cdr;
pub mod msgs;
pub mod rmw;
