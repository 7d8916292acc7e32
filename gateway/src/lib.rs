//! scout-gateway: the process that owns a SCOUT chassis port, and the chassis simulator.
//!
//! - [`link`]: message framing per transport (serial, slcan, SocketCAN), shared by both.
//! - [`port`]: the port as an OS resource (tty or SocketCAN socket).
//! - [`sim`]: the simulated chassis and the `scout-sim` driver loop.

pub mod link;
pub mod port;
pub mod sim;
