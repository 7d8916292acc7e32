//! scout-io: what the two programs that face the chassis (scout-gateway and scout-sim) share
//! with the operating system.
//!
//! - [`port`]: the chassis port as an OS resource: a tty (serial, slcan adapter, pseudo-terminal)
//!   or a SocketCAN socket.
//! - [`logging`]: `tracing` to standard error, never blocking the caller.

pub mod logging;
pub mod port;

pub use port::{BusError, Incoming, Port};
