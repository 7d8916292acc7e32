//! scout-gateway: the process that owns a SCOUT chassis port, and the chassis simulator.
//!
//! - [`arbiter`]: who drives: safety stop > teleop > autonomy (sans-IO).
//! - [`bridge`]: zenoh for remote peers: state, status, liveliness, info, remote commands.
//! - [`control`]: the control loop, the one thread that touches the port and the clock.
//! - [`state`]: the chassis state tracker (sans-IO).
//! - [`device`]: the port or the in-process simulator, messages in and out.
//! - [`config`]: the configuration file and its lookup.
//! - [`requests`]: control requests on the wire to the arbiter and back.
//! - [`monitor`]: dead-process detection for clients.
//! - [`wait`]: waiting on the port and the clients' wake-up event at once.
//! - [`logging`]: `tracing` to standard error, never blocking the caller.
//! - [`lock`]: one gateway per robot name and device.
//! - [`link`]: message framing per transport (serial, slcan, SocketCAN), shared with the simulator.
//! - [`port`]: the port as an OS resource (tty or SocketCAN socket).
//! - [`sim`]: the simulated chassis and the `scout-sim` driver loop.

pub mod arbiter;
pub mod bridge;
pub mod config;
pub mod control;
pub mod device;
pub mod link;
pub mod lock;
pub mod logging;
pub mod monitor;
pub mod port;
pub mod requests;
pub mod sim;
pub mod state;
pub mod wait;
