//! scout-interface: the contract between scout-gateway and everything that talks to it, in one
//! crate that both sides use and neither owns (the gateway does not depend on its client library,
//! nor the clients on the gateway).
//!
//! - [`services`]: the iceoryx2 services of a robot, their names and sizing, created by the
//!   gateway and opened by clients; the request round trip.
//! - [`ipc`]: the iceoryx2 service flavour, its objects files in one directory whose
//!   permissions decide who is a local client.
//! - [`state`]: the zero-copy chassis state payload, one field per feedback message.
//! - [`control`]: control requests and answers, typed and on the wire; the arbiter's status.
//! - [`json`]: the public JSON forms of the state and the status (`scout echo`, zenoh).
//! - [`link`]: what protects each zenoh link, and the rule that remote peers drive only over
//!   links that authenticate them.
//! - [`remote`]: zenoh key expressions, remote commands and their permissions.
//! - [`stop_socket`]: the stop endpoint beside iceoryx2 (a Unix datagram socket): stops and
//!   releases that need no shared memory and no client slot.
//! - [`text`]: fixed-capacity text for shared-memory payloads.
//! - [`robot`]: a robot's name, checked once, and the node and file names made from it.
//! - [`failure`]: what kind of failure an error is, and the exit code of each kind.
//!
//! Every iceoryx2 payload's type name carries [`LAYOUT_VERSION`]: a client built against another
//! layout is refused when it opens a service ("the gateway speaks another interface version")
//! instead of misreading shared memory. Raise it with every change to a payload's fields.
#![warn(missing_docs)]

#[macro_use]
mod macros;

pub mod control;
pub mod failure;
pub mod ipc;
pub mod json;
pub mod link;
pub mod remote;
pub mod robot;
pub mod services;
pub mod state;
pub mod stop_socket;
pub mod text;

/// The layout version in every payload's iceoryx2 type name (`scout::StatePayload.v14`). Raise it
/// when a payload changes: the sizes pinned below stop the build until it is raised.
pub const LAYOUT_VERSION: u32 = 14;

pub use control::{
    Accepted, Class, ControlRequest, ControlResponse, DriveMode, LightsSetting, Rejection,
    RejectionKind, Request, RequestKind, StatusPayload,
};
pub use scout_protocol::Transport;
pub use services::{Ipc, Role, ServiceError};
pub use state::{LinkState, StatePayload};
pub use text::FixedText;

/// Pins a shared-memory payload's size and alignment at compile time: a change to either is a new
/// layout, which a client or gateway of the old one would misread.
macro_rules! pin_layout {
    ($payload:ty, $size:literal, $align:literal) => {
        const _: () = assert!(
            core::mem::size_of::<$payload>() == $size
                && core::mem::align_of::<$payload>() == $align,
            concat!(
                stringify!($payload),
                "'s size or alignment changed: raise LAYOUT_VERSION (the `.vN` of every type \
                 name follows it), then pin the new size and alignment here"
            )
        );
    };
}

pin_layout!(state::StatePayload, 1032, 8);
pin_layout!(control::StatusPayload, 6840, 8);
pin_layout!(control::ControlRequest, 216, 8);
pin_layout!(control::ControlResponse, 200, 8);
