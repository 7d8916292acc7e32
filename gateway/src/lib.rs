//! scout-gateway: the one process that owns a SCOUT chassis port.
//!
//! In the order data flows:
//! - [`device`]: the port with its framing, or the simulated chassis in-process (`--sim`).
//! - [`core`]: the sans-IO core: frames, requests, deaths and time in; frames to send, state and
//!   status to publish and the next deadline out. It holds:
//!   - [`state`]: the chassis state tracker (protocol, link state, statistics, odometry);
//!   - [`battery`]: the battery's charge, charging and level, from a smart battery or the voltage;
//!   - [`arbiter`]: who drives: safety stop > teleop > autonomy;
//!   - [`command_mode`]: a protocol v2 chassis' command mode, taken with 0x421 and watched.
//! - [`driver`]: the one thread that does I/O around the core: port, iceoryx2, clock, `ppoll`.
//! - [`blackbox`]: the last minutes of frames, kept on a thread of its own, saved on a stop.
//! - [`wait`]: waiting on the port and the clients' wake-up event at once.
//! - [`monitor`]: dead-process detection for clients.
//! - [`stop_endpoint`]: the stop socket beside iceoryx2, which is also the robot name's lock.
//! - [`identity`]: who a requesting process is, by the operating system; the operator role.
//! - [`share`]: request budgets: a token bucket per client, a share of the stop endpoint per user.
//! - [`modes`]: a Ranger's motion modes: which one a command needs, and what each carries.
//! - [`brake`]: a Hunter's parking brake: released for a client's drive, locked when idle.
//! - [`standstill`]: whether the chassis stands still (a mode changes, a brake locks only so).
//! - [`config`]: the configuration file and its lookup.
//! - [`lock`]: one gateway per device.
//! - [`run_dir`]: where the locks, the unclean-exit marker and the black box live, trusted only
//!   when nobody else can change it.
//!
//! The zenoh bridge (`scout-bridge`) is an ordinary local client that the `scout-gateway` binary
//! starts beside the driver; the contract with every client is `scout-interface`.

pub mod arbiter;
pub mod battery;
pub mod blackbox;
pub mod brake;
pub mod command_mode;
pub mod config;
pub mod core;
pub mod device;
pub mod driver;
pub mod identity;
pub mod lock;
pub mod modes;
pub mod monitor;
pub mod run_dir;
pub mod share;
pub mod standstill;
pub mod state;
pub mod stop_endpoint;
pub mod wait;

#[cfg(test)]
mod core_tests;
