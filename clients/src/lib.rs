//! scout-clients: the client library of scout-gateway and the pieces of the `scout` tool.
//!
//! - [`client`]: connect to a robot by name; subscribe to its state.
//! - [`control`]: drive, stop, release, resume, lights, fault clear; the arbiter's status.
//! - [`ipc`]: the iceoryx2 services and zero-copy payloads shared with the gateway.
//! - [`remote`]: the zenoh keys, session settings, remote commands and a remote state reader.
//! - [`state`]: the public JSON form of the chassis state.
//! - [`echo`]: `scout echo`, the state on a terminal or as JSON lines.
//! - [`decode`]: candump text and serial hex to decoded frames (`scout decode`).

pub mod client;
pub mod control;
pub mod decode;
pub mod echo;
pub mod ipc;
pub mod remote;
pub mod state;
