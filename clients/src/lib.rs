//! scout-clients: the client library of scout-gateway and the pieces of the `scout` tool.
//!
//! - [`client`]: connect to a robot by name; subscribe to its state.
//! - [`control`]: drive, stop, release, resume, lights, fault clear; the arbiter's status.
//! - [`remote`]: gateways through zenoh: read the state, drive and stop as a remote peer
//!   (feature `remote`, on by default).
//! - [`echo`]: `scout echo`, the state on a terminal or as JSON lines.
//! - [`decode`]: candump text and serial hex to decoded frames (`scout decode`).
//! - [`failure`]: the kind of a client error, and every program's exit code from it.
//!
//! The contract with the gateway (payloads, requests, JSON schemas, zenoh keys) is
//! [`scout_interface`], re-exported here as [`interface`].

pub mod client;
pub mod control;
pub mod decode;
pub mod echo;
pub mod failure;
#[cfg(feature = "remote")]
pub mod remote;

/// This library's error types and the interface crate's, each of which says its kind
/// ([`failure::FailureKind`]): what [`failure::exit_code`] knows besides a program's own.
pub const ERROR_KINDS: &[failure::KindOf] = &[
    failure::kind_if::<client::ClientError>,
    failure::kind_if::<control::ControlError>,
    failure::kind_if::<echo::EchoError>,
    scout_interface::failure::kind_of,
];

pub use scout_interface as interface;
pub use scout_interface::control::{
    Accepted, Class, DriveMode, Rejected, RejectionKind, ReleaseTarget, Request, StopCause,
};
pub use scout_interface::services::monotonic_ns;
pub use scout_interface::{StatePayload, StatusPayload};
