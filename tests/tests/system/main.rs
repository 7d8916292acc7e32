//! The multi-process system tests, one module per area. Each runs the real binaries, with a
//! deadline, on its own pseudo-terminals and names.

mod arbiter;
mod battery;
mod bench;
mod blackbox;
mod decode;
mod doctor;
mod examples;
mod family;
mod foxglove;
mod gateway;
mod odometry;
mod package;
mod protocol_v2;
mod python;
mod release;
mod remote;
mod ros2;
mod ros2_dds;
mod safety;
mod sideways;
mod sim;
mod status;
mod teleop;
mod users;
mod watchdog;
mod web;
