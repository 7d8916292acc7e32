//! The chassis simulator: a sans-IO model of the SCOUT ([`chassis`]), its fault-injection
//! language ([`script`]) and the driver loop that puts it on a pseudo-terminal or CAN interface
//! ([`run`]).

pub mod chassis;
pub mod run;
pub mod script;

#[cfg(test)]
mod chassis_tests;

pub use chassis::{Chassis, SimParams};
