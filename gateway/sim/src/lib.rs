//! scout-sim: a simulated AgileX SCOUT chassis. A sans-IO model ([`chassis`]: commands and time
//! in, feedback out), its fault-injection language ([`script`]), a gateway black box's replay
//! ([`replay`]) and the driver that puts it on a pseudo-terminal or a CAN interface ([`run`]). It depends on the protocol and the OS port, not
//! on iceoryx2 or zenoh; the gateway's `--sim` runs the same model in-process.

pub mod chassis;
pub mod replay;
pub mod run;
pub mod script;

#[cfg(test)]
mod chassis_tests;
#[cfg(test)]
mod chassis_v2_tests;

pub use chassis::{Chassis, Feedback, SimParams};
