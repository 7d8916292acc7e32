//! scout-foxglove: the chassis in Foxglove (or its open fork Lichtblick): MCAP recordings
//! (`scout record`) and a live Foxglove WebSocket server (`scout foxglove`) with the same
//! channels, so a recording replays like the live view. Built on the `foxglove` SDK; a crate of
//! its own so that `scout` and the client library carry none of it.
//!
//! - [`transcript`]: states and statuses in, the channels' messages out (sans-IO).
//! - [`channels`]: the topics, their schemas and encodings, on one Foxglove context.
//! - [`schema`]: the JSON schemas of the JSON channels.
//! - [`source`]: reading a gateway on a thread of its own, an ordinary subscriber.
//! - [`record`]: `scout record`, the MCAP file.
//! - [`ros2`]: `scout record --ros2`, ROS 2 messages in a rosbag2 bag.
//! - [`live`]: `scout foxglove`, the WebSocket server, stops as problems, an optional e-stop.
//! - [`subprotocol`]: the protocol under its old name too, in front of the SDK's server.
//! - [`origin`]: which web pages may connect to the live view.
//! - [`backend`]: the SDK's server behind the front, reachable from the front alone.

pub mod backend;
pub mod channels;
pub mod live;
pub mod origin;
pub mod record;
pub mod ros2;
pub mod schema;
pub mod source;
pub mod subprotocol;
pub mod transcript;

#[cfg(test)]
mod layout_tests;
