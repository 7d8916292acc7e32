//! scout-doctor (run as `scout doctor`): checks a SCOUT set-up in order and says, for each
//! check that fails, how to fix it. It uses the gateway's own device code and lock (a port a
//! gateway holds is checked through that gateway, never opened twice) and the client library.
//!
//! - [`check`]: one check's verdict, detail and fix; text and JSON.
//! - [`traffic`]: what a port said while listened to, and the verdicts (sans-IO).
//! - [`can`]: a SocketCAN interface as `ip` describes it, and the verdicts.
//! - [`usb`]: gs_usb USB-CAN adapters on the USB bus: their drivers and names (sans-IO verdicts).
//! - [`port`]: the device file, opening and listening.
//! - [`gateway`]: the checks through a running gateway.
//! - [`remote`]: the robot's state through zenoh, when asked.
//! - [`doctor`]: all of them, in order.

pub mod can;
pub mod check;
pub mod doctor;
pub mod gateway;
pub mod port;
pub mod remote;
pub mod traffic;
pub mod usb;
