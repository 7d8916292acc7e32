//! The Tracers and the Bunkers across processes: each drives a square on its simulator with the
//! gateway's odometry closing on the simulator's pose, every one of them is capped at its own
//! limits and refuses a sideways speed, and the command a Tracer gets is where the vendor puts
//! it in 0x111 (read by a chassis emulated apart from this project's codec).

use std::cell::Cell;
use std::time::Duration;

use scout_protocol::model::{Drive, Model};
use scout_protocol::version::Protocol;
use scout_system_tests::{Gateway, connect, robot_name, scout, wait_for_state};

use crate::odometry::{assert_within, exact_factors, square};
use crate::sideways::EmulatedChassis;

const LIMIT: Duration = Duration::from_secs(10);

/// The square of `odometry.rs` (the deliberately erring simulator, the factors that undo it)
/// on a simulated `model` over slcan, protocol v2.
fn square_of(model: Model) {
    let config = format!("model = \"{model}\"\n{}", exact_factors());
    let (position, yaw) = square(
        &format!("square-{model}"),
        &["--slcan", "--protocol", "v2", "--model", model.name()],
        &["--slcan"],
        &config,
    );
    assert_within(position, yaw);
}

#[test]
fn a_tracer_drives_a_square_and_its_odometry_follows() {
    square_of(Model::Tracer);
}

#[test]
fn a_bunker_drives_a_square_and_its_odometry_follows() {
    square_of(Model::Bunker);
}

/// For every Tracer and Bunker: the gateway says the model and its limits, a client asking for
/// more than the limits gets the limit and never more, its two actuators report (and not four),
/// and a sideways speed is refused whole with the reason.
#[test]
fn every_tracer_and_bunker_is_capped_at_its_limits_and_refuses_sideways() {
    let models = Model::ALL
        .into_iter()
        .filter(|model| matches!(model.drive(), Drive::Differential | Drive::Tracked));
    for model in models {
        let name = robot_name(&format!("caps-{model}"));
        // The Tracers speak v2 alone: their simulator does without being told.
        let protocol: &[&str] = match model.speaks(Protocol::V1) {
            true => &["--protocol", "v2"],
            false => &[],
        };
        let args = ["--sim", "--model", model.name(), "--name", &name];
        let _gateway = Gateway::start(&[&args[..], protocol].concat());
        let state = connect(&name).subscribe().expect("state");
        let ready = wait_for_state(&state, LIMIT, |s| {
            s["link"]["state"] == "ok" && !s["motors"][0].is_null()
        });
        let limits = model.limits();
        let chassis = &ready["chassis"];
        assert_eq!(chassis["model"], model.name(), "{chassis}");
        assert_eq!(chassis["max_linear"], limits.linear, "{chassis}");
        assert_eq!(chassis["max_angular"], limits.angular, "{chassis}");
        assert_eq!(
            ready["link"]["protocol"], "v2",
            "{model}: {}",
            ready["link"]
        );
        let motors = &ready["motors"];
        assert!(
            !motors[1].is_null() && motors[2].is_null() && motors[3].is_null(),
            "{model}: two actuators: {motors}"
        );
        let mut drive = scout_system_tests::Background::scout(&[
            "drive",
            "--name",
            &name,
            "--angular",
            "9",
            "--duration",
            "2",
        ]);
        let most = Cell::new(0.0_f64);
        wait_for_state(&state, LIMIT, |s| {
            let angular = s["command"]["angular"].as_f64().unwrap_or(0.0);
            most.set(most.get().max(angular));
            // The limit in whole mrad/s, rounded down.
            limits.angular - angular < 0.001
        });
        assert!(
            most.get() <= limits.angular,
            "{model}: {} over {}",
            most.get(),
            limits.angular
        );
        assert_eq!(drive.wait_exit(LIMIT), Some(0), "{model}: scout drive");
        let (code, stdout, stderr) = scout(&[
            "drive",
            "--name",
            &name,
            "--lateral",
            "0.2",
            "--duration",
            "0.3",
        ]);
        let said = format!("{stdout}{stderr}");
        assert_eq!(code, Some(4), "{model}: {said}");
        assert!(
            said.contains(&format!("a {model} does not move sideways")),
            "{said}"
        );
    }
}

/// A Tracer's 0x111 as the vendor lays it out: the forward speed in bytes 0-1, the yaw rate in
/// 2-3, nothing in the sideways and steering fields; zero on every field when the client ends.
#[test]
fn a_tracers_command_is_where_the_vendor_puts_it_in_0x111() {
    let chassis = EmulatedChassis::start();
    let name = robot_name("tracer-wire");
    let _gateway = Gateway::start(&[
        "--slcan",
        &chassis.port,
        "--protocol",
        "v2",
        "--model",
        "tracer",
        "--name",
        &name,
    ]);
    let state = connect(&name).subscribe().expect("state");
    wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "ok");
    let drive = scout_system_tests::Background::scout(&[
        "drive",
        "--name",
        &name,
        "--linear",
        "0.1",
        "--angular",
        "0.3",
        "--duration",
        "1.5",
    ]);
    let seen = chassis.commands_until(|c| c[0] == 100 && c[1] == 300);
    assert_eq!(
        seen.last().map(|c| (c[0], c[1])),
        Some((100, 300)),
        "{seen:?}"
    );
    assert!(
        seen.iter().all(|c| c[2] == 0 && c[3] == 0),
        "no sideways, no steering: {seen:?}"
    );
    let seen = chassis.commands_until(|c| *c == [0, 0, 0, 0]);
    assert_eq!(seen.last(), Some(&[0, 0, 0, 0]), "{seen:?}");
    drop(drive);
}
