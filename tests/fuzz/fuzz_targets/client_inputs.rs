//! Fuzzes what peers on the network send the gateway's bridges: a ROS 2 cmd_vel (CDR, plain,
//! stamped and AckermannDriveStamped, as the rmw_zenoh path and the DDS reader each decode it) with its rmw_zenoh
//! attachment, a std_srvs/Trigger request (both paths), and a zenoh remote command (its key and
//! JSON payload down to the arbiter request it makes).
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_ros2::{dds_wire, msgs, rmw};
use scout_interface::control::Class;
use scout_interface::remote::{self, RemoteCommand};

fuzz_target!(|input: &[u8]| {
    let _ = msgs::decode_twist(input, false);
    let _ = msgs::decode_twist(input, true);
    let _ = dds_wire::decode_cmd_vel(input, false);
    let _ = dds_wire::decode_cmd_vel(input, true);
    let _ = msgs::decode_ackermann(input);
    let _ = dds_wire::decode_ackermann(input);
    let _ = msgs::decode_trigger_request(input);
    let _ = dds_wire::decode_trigger_request(input);
    let _ = rmw::parse_attachment(input);
    // The first line is the key, the rest the payload.
    let (key, payload) = match input.iter().position(|&b| b == b'\n') {
        Some(at) => (&input[..at], &input[at + 1..]),
        None => (input, &[][..]),
    };
    let Ok(key) = core::str::from_utf8(key) else {
        return;
    };
    let Ok((kind, _peer)) = remote::parse_command_key(key) else {
        return;
    };
    if let Ok(command) = serde_json::from_slice::<RemoteCommand>(payload) {
        for control in [None, Some((1, Class::Teleop)), Some((7, Class::Autonomy))] {
            let _ = command.request(kind, control);
        }
    }
});
