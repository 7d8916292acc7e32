//! scout-protocol: the AgileX SCOUT chassis protocol v1 (CAN and serial) and v2 (CAN), without I/O.
//!
//! Sans-IO and `no_std`: bytes and frames go in, typed messages come out, and back. No clock
//! (time comes in as an argument) and no allocation.
//!
//! - [`message`]: the typed payload of every frame, shared by both links.
//! - [`fault`]: the 16 fault bits of the system status.
//! - [`can`]: CAN frames (id, 8 bytes, rolling count, checksum).
//! - [`serial`]: 13-byte RS232 frames and a streaming decoder.
//! - [`slcan`]: the ASCII lines of serial-line CAN adapters.
//! - [`gs_usb`]: the host protocol of candleLight-style USB-CAN adapters.
//! - [`candump`]: candump's text formats.
//! - [`model`]: the SCOUT models' limits and geometry.
//! - [`battery`]: the models' batteries and the rest-voltage curve.
//! - [`units`]: m/s and rad/s to whole percent and back.
//! - [`sequence`]: rolling counters and gap tracking.
//! - [`v2`]: protocol v2 (SCOUT 2.0, SCOUT MINI) CAN frames.
//! - [`version`]: protocol v1 / v2 detection.
//! - [`link`]: the transports and their framing, shared by the gateway and the simulator.
//! - [`kinematics`]: the skid-steer pose step (with `std`).
//! - [`listed!`]: an enum and the list of its variants, declared once.
#![cfg_attr(not(any(test, feature = "std")), no_std)]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[macro_use]
mod listed;

pub mod battery;
pub mod can;
pub mod candump;
pub mod fault;
pub mod gs_usb;
#[cfg(feature = "std")]
pub mod kinematics;
pub mod link;
pub mod message;
pub mod model;
pub mod sequence;
pub mod serial;
pub mod slcan;
pub mod units;
pub mod v2;
pub mod version;

pub use can::CanFrame;
pub use fault::{Fault, FaultBits, Severity};
pub use link::Transport;
pub use message::{
    ChassisState, ControlMode, Counted, Direction, FaultClear, Light, LightCommand, LightFeedback,
    LightMode, Message, MessageKind, MotionCommand, MotionFeedback, Motor, MotorFeedback,
    SystemStatus,
};
