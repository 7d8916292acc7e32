//! The Tracers, the Bunkers and the Hunters across processes: each drives a figure its wheels
//! allow on its simulator with the gateway's odometry closing on the simulator's pose, every
//! one is capped at its own limits and refuses what it cannot do (a sideways speed; a turn in
//! place on the Hunter), and the command each kind gets is where the vendor puts it in 0x111
//! (read by a chassis emulated apart from this project's codec).

use std::cell::Cell;
use std::time::{Duration, Instant};

use scout_clients::Class;
use scout_system_tests::{Sim, TempDir};

use scout_protocol::kinematics;
use scout_protocol::model::{Drive, Model};
use scout_protocol::version::Protocol;
use scout_system_tests::{Gateway, connect, robot_name, scout, wait_for_state, wait_for_status};

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
        drive_refused(
            &name,
            &["--lateral", "0.2"],
            &format!("a {model} does not move sideways"),
        );
    }
}

/// A Tracer's 0x111 as the vendor lays it out: the forward speed in bytes 0-1, the yaw rate in
/// 2-3, nothing in the sideways and steering fields; zero on every field when the client ends.
#[test]
fn a_tracers_command_is_where_the_vendor_puts_it_in_0x111() {
    let (chassis, _gateway, drive) =
        EmulatedChassis::driven("tracer", &["--linear", "0.1", "--angular", "0.3"]);
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
    chassis.ends_at_zero();
    drop(drive);
}

/// `scout drive --name NAME ARGS` for 0.3 s is refused whole (exit 4), saying `why`.
fn drive_refused(name: &str, args: &[&str], why: &str) {
    let (code, stdout, stderr) =
        scout(&[&["drive", "--name", name], args, &["--duration", "0.3"]].concat());
    let said = format!("{stdout}{stderr}");
    assert_eq!(code, Some(4), "{args:?}: {said}");
    assert!(said.contains(why), "{said}");
}

/// The newest state's odometry: x, y, yaw and distance, waiting up to 2 s for a first one.
fn odometry(states: &scout_clients::client::StateSubscriber) -> (f64, f64, f64, f64) {
    let state = wait_for_state(states, Duration::from_secs(2), |_| true);
    let value = |key: &str| state["odometry"][key].as_f64().expect("odometry");
    (value("x"), value("y"), value("yaw"), value("distance"))
}

/// A figure driven by a client as teleop, each leg ending on the gateway's odometry as a
/// planner's would.
struct Figure {
    states: scout_clients::client::StateSubscriber,
    drive: scout_clients::control::Controller,
}

impl Figure {
    /// Control of `robot` taken, its state read from `states`.
    fn start(
        robot: &scout_clients::client::Robot,
        states: scout_clients::client::StateSubscriber,
    ) -> Self {
        let mut drive = robot
            .controller("figure", Some(Class::Teleop))
            .expect("a controller");
        let deadline = Instant::now() + LIMIT;
        while drive.take_control().is_err() {
            assert!(Instant::now() < deadline, "no control");
            std::thread::sleep(Duration::from_millis(50));
        }
        Self { states, drive }
    }

    /// The newest odometry: x, y, yaw, distance.
    fn odometry(&self) -> (f64, f64, f64, f64) {
        odometry(&self.states)
    }

    /// Drives at `velocity` (forward, sideways, yaw rate) until `done` says so of the
    /// odometry (at most 20 s).
    fn leg(
        &mut self,
        (linear, lateral, angular): (f64, f64, f64),
        done: &dyn Fn((f64, f64, f64, f64)) -> bool,
    ) {
        let deadline = Instant::now() + Duration::from_secs(20);
        while !done(self.odometry()) {
            assert!(
                Instant::now() < deadline,
                "the leg ({linear}, {lateral}, {angular}) took too long: odometry {:?}",
                self.odometry()
            );
            self.drive
                .drive_body(linear, lateral, angular, None)
                .expect("a drive");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Stops, waits for the chassis to rest, and checks the odometry ends within 2 % of `path`
    /// (m) of the simulator's pose; returns the simulator's statistics.
    fn closes(mut self, sim: &mut Sim, model: &str, path: f64) -> serde_json::Value {
        self.drive.stop("figure done").expect("a stop");
        wait_for_state(&self.states, LIMIT, |s| {
            let still = |key: &str| s["motion"][key].as_f64().is_some_and(|v| v.abs() < 0.001);
            still("linear") && still("angular")
        });
        let (x, y, yaw, _) = self.odometry();
        let stats = sim.stats();
        let value = |key: &str| stats["pose"][key].as_f64().expect("a pose");
        let (true_x, true_y, true_yaw) = (value("x"), value("y"), value("yaw"));
        eprintln!(
            "{model}: odometry ({x:.3}, {y:.3}, {yaw:.3}), truth ({true_x:.3}, {true_y:.3}, \
             {true_yaw:.3}) over {path:.2} m"
        );
        let position = (x - true_x).hypot(y - true_y) / path;
        let turned = kinematics::wrap_angle(yaw - true_yaw).abs() / std::f64::consts::TAU;
        assert_within(position, turned);
        stats
    }
}

/// A leg's end: the odometry's heading at or past `heading` (turning left).
fn turned_to(heading: f64) -> impl Fn((f64, f64, f64, f64)) -> bool {
    move |(_, _, yaw, _)| kinematics::wrap_angle(heading - yaw) <= 0.0
}

/// A Hunter 2.0 drives a rounded square on its simulator at 0.8 m/s (four sides of 1 m, each
/// followed by a quarter turn on a 1.5 m circle, steering on the gateway's odometry as a
/// planner would): the odometry ends within 2 % of the path of the simulator's pose. It refuses
/// to turn in place; its parking brake, locked at power-on, is released for the drive.
#[test]
fn a_hunter_drives_a_rounded_square_and_its_odometry_follows() {
    let stats = rounded_square(Model::Hunter2, 0.8, 1.5);
    // Its parking brake was released for the drive, and no speed reached it locked.
    assert_eq!(stats["ignored"]["brake_locked"], 0, "{stats}");
    assert!(stats["brake_changes"].as_u64() >= Some(1), "{stats}");
}

/// A Hunter SE drives the rounded square at 1.6 m/s (faster than a Hunter 2.0 may), its
/// quarter turns on a 2 m circle (its tightest is 1.57 m), with the same closing odometry; it
/// has no parking brake, and the simulator rejected nothing (a 0x131 sent it would be).
#[test]
fn a_hunter_se_drives_a_rounded_square_faster_and_its_odometry_follows() {
    let stats = rounded_square(Model::HunterSe, 1.6, 2.0);
    assert_eq!(stats["rejected"], 0, "{stats}");
}

/// A Hunter 2.0 (its brake locked, as it powers up) behind a gateway told it is a Hunter SE is
/// not driven: the gateway stops at the first 0x211 and says why, and a drive is refused.
#[test]
fn a_hunter_2_is_not_driven_as_a_hunter_se() {
    let name = robot_name("hunter2-as-se");
    let _dir = TempDir::new(&name);
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "hunter2"]);
    let port = sim.port().to_owned();
    let gateway = Gateway::start(&["--slcan", &port, "--model", "hunter-se", "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("state");
    wait_for_state(&states, LIMIT, |s| {
        s["link"]["state"] == "protocol_mismatch"
    });
    let status = robot.status().expect("status");
    let status = wait_for_status(&status, LIMIT, |s| {
        s["stops"].as_array().is_some_and(|stops| !stops.is_empty())
    });
    let reason = status["stops"][0]["reason"].as_str().unwrap_or_default();
    assert!(
        reason.contains("not a hunter-se") && reason.contains("0x211 byte 6"),
        "{status}"
    );
    drive_refused(&name, &["--linear", "0.5"], "not a hunter-se");
    // No speed reached it (its brake, locked, would have held it still all the same).
    assert_eq!(sim.stats()["ignored"]["brake_locked"], 0);
    assert!(gateway.log().contains("a Hunter 2.0"), "{}", gateway.log());
}

/// `model` drives a rounded square at `speed` m/s on its simulator: four sides of 1 m, each
/// followed by a quarter turn on a circle of `radius` m, each leg ending on the gateway's
/// odometry; asserts the odometry closes on the simulator's pose and that a turn in place is
/// refused; returns the simulator's statistics.
fn rounded_square(model: Model, speed: f64, radius: f64) -> serde_json::Value {
    let name = robot_name(&format!("{model}-figure"));
    let _dir = TempDir::new(&name);
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", model.name()]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--slcan", &port, "--model", model.name(), "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("state");
    wait_for_state(&states, LIMIT, |s| s["link"]["state"] == "ok");
    // Turning standing still is refused whole, with the reason.
    drive_refused(
        &name,
        &["--angular", "0.3"],
        &format!("a {model} cannot turn in place"),
    );
    // Its parking brake in the state: locked at power-on, or none.
    let brake = match model.parking_brake() {
        true => serde_json::json!("locked"),
        false => serde_json::Value::Null,
    };
    wait_for_state(&states, LIMIT, |s| s["system"]["brake"] == brake);
    let mut figure = Figure::start(&robot, states);
    let mut path = 0.0;
    for corner in 1..=4 {
        let start = figure.odometry().3;
        figure.leg((speed, 0.0, 0.0), &|(_, _, _, distance)| {
            distance - start >= 1.0
        });
        let heading = f64::from(corner) * std::f64::consts::FRAC_PI_2;
        figure.leg((speed, 0.0, speed / radius), &turned_to(heading));
        path += 1.0 + radius * std::f64::consts::FRAC_PI_2;
    }
    let stats = figure.closes(&mut sim, model.name(), path);
    let value = |key: &str| stats["pose"][key].as_f64().expect("a pose");
    let (true_x, true_y, true_yaw) = (value("x"), value("y"), value("yaw"));
    // It went round (each leg ended on the odometry, or the test would have failed there): back
    // near where it started and facing about the way it started. Loose bounds: each leg ends a
    // client's poll late, on a loaded machine more, the wheels take their time to turn in and
    // out of each corner (more of it the faster it goes), and the figure is 3.5 to 5 m across.
    assert!(true_x.hypot(true_y) < radius + 0.5, "({true_x}, {true_y})");
    assert!(true_yaw.abs() < 0.7, "{true_yaw}");
    stats
}

/// A Hunter's 0x111 as the vendor lays it out: the speed in bytes 0-1, nothing in the yaw-rate
/// field, the inner wheel's angle for the asked turn in bytes 6-7; zero on every field when
/// the client ends. Its parking brake (locked at start, reported in 0x211 byte 6) is released
/// with 0x131 `[00]` before any speed reaches it, and locked with 0x131 `[01]` once the client
/// has ended and the chassis stands still.
#[test]
fn a_hunters_command_is_its_speed_and_steering_angle_in_0x111() {
    let (chassis, _gateway) = a_hunter_steers_in_0x111(Model::Hunter2);
    let locked = serde_json::json!({ "brake": 1 });
    assert!(chassis.wait_event(&locked, LIMIT), "{:?}", chassis.events());
    let events = chassis.events();
    assert_eq!(
        events,
        [serde_json::json!({ "brake": 0 }), locked],
        "released once, locked once, nothing moved while locked"
    );
}

/// A Hunter SE's 0x111 as the Hunter 2.0's, with its own geometry: its inner wheel's angle for
/// the asked turn in bytes 6-7. It has no parking brake: no 0x131 reaches it, before the drive
/// or in the 3 s after it (a Hunter 2.0 is locked about a second after its drive).
#[test]
fn a_hunter_ses_command_is_its_speed_and_steering_angle_and_no_brake() {
    let (chassis, _gateway) = a_hunter_steers_in_0x111(Model::HunterSe);
    let locked = serde_json::json!({ "brake": 1 });
    let after = Duration::from_secs(3);
    assert!(
        !chassis.wait_event(&locked, after),
        "{:?}",
        chassis.events()
    );
    assert_eq!(chassis.events(), [] as [serde_json::Value; 0]);
}

/// Hunter `model` driven at 0.3 m/s turning at 0.2 rad/s ([`steers_in_0x111`]): its inner
/// wheel's angle for that turn, by its geometry.
fn a_hunter_steers_in_0x111(model: Model) -> (EmulatedChassis, Gateway) {
    let steering = model.steering().expect("steered");
    let inner = steering.inner_from_central(steering.central_for(0.3, 0.2));
    steers_in_0x111(model, 0.2, inner)
}

/// `model` driven at 0.3 m/s turning at `angular` rad/s, on the emulated chassis: 0x111 carries
/// the speed in bytes 0-1 and `inner` (the inner wheel's angle, rad) in bytes 6-7, nothing in
/// the yaw-rate and sideways fields; zero on every field when the client ends.
fn steers_in_0x111(model: Model, angular: f64, inner: f64) -> (EmulatedChassis, Gateway) {
    let (chassis, gateway, drive) = EmulatedChassis::driven(
        model.name(),
        &["--linear", "0.3", "--angular", &angular.to_string()],
    );
    let mrad = (inner * 1000.0).round() as i64;
    let seen = chassis.commands_until(|c| c[0] == 300 && (c[3] - mrad).abs() <= 1);
    let last = seen.last().copied().unwrap_or_default();
    assert!(
        last[0] == 300 && (last[3] - mrad).abs() <= 1,
        "{model}: {mrad} mrad: {seen:?}"
    );
    assert!(
        seen.iter().all(|c| c[1] == 0 && c[2] == 0),
        "{model}: no yaw rate, no sideways: {seen:?}"
    );
    chassis.ends_at_zero();
    drop(drive);
    (chassis, gateway)
}

/// A Ranger Mini 2.0 on its simulator drives a figure of every mode, each leg ending on the
/// gateway's odometry as a planner's would: 1 m forward (dual Ackermann), 0.8 m to the left
/// (parallel), a quarter turn in place (spin), a quarter circle forward (dual Ackermann). The
/// odometry ends within 2 % of the path of the simulator's pose; the simulated firmware saw no
/// mode change asked while it moved and no motion while it changed.
#[test]
fn a_ranger_drives_every_mode_and_its_odometry_follows() {
    every_mode_figure(Model::RangerMini2);
}

/// The same figure on a Ranger Mini 3.0, whose spin rate goes in the yaw-rate field.
#[test]
fn a_ranger_mini_3_drives_every_mode_and_its_odometry_follows() {
    every_mode_figure(Model::RangerMini3);
}

fn every_mode_figure(model: Model) {
    let name = robot_name(&format!("{model}-figure"));
    let _dir = TempDir::new(&name);
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", model.name()]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--slcan", &port, "--model", model.name(), "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("state");
    wait_for_state(&states, LIMIT, |s| s["link"]["state"] == "ok");
    // A mode named on the command line: what it does not carry is refused whole, with the
    // reason; park parks it (and the figure's first leg takes it out of the park it asked for).
    drive_refused(
        &name,
        &["--mode", "parallel", "--angular", "0.3"],
        "parallel mode does not turn",
    );
    let (code, stdout, stderr) = scout(&[
        "drive",
        "--name",
        &name,
        "--mode",
        "park",
        "--duration",
        "2.5",
    ]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    assert_eq!(sim.stats()["motion_mode"], "park");
    let mut figure = Figure::start(&robot, states);
    figure.leg((0.5, 0.0, 0.0), &|(x, _, _, _)| x >= 1.0);
    figure.leg((0.0, 0.4, 0.0), &|(_, y, _, _)| y >= 0.8);
    let sideways = wait_for_state(&figure.states, LIMIT, |_| true);
    assert_eq!(
        sideways["motion"]["mode"], "parallel",
        "{}",
        sideways["motion"]
    );
    assert_eq!(sideways["motion"]["mode_changing"], false);
    // Its four wheels (0x271) all point left.
    let angles = sideways["motion"]["wheel_angles"].as_array().cloned();
    assert!(
        angles.is_some_and(|angles| angles.len() == 4
            && angles.iter().all(|angle| {
                (angle.as_f64().unwrap_or_default() - std::f64::consts::FRAC_PI_2).abs() < 0.02
            })),
        "{}",
        sideways["motion"]
    );
    figure.leg((0.0, 0.0, 0.8), &turned_to(std::f64::consts::FRAC_PI_2));
    figure.leg((0.4, 0.0, 0.4), &turned_to(std::f64::consts::PI));
    let path = 1.0 + 0.8 + std::f64::consts::FRAC_PI_2;
    let stats = figure.closes(&mut sim, model.name(), path);
    let true_yaw = stats["pose"]["yaw"].as_f64().expect("a pose");
    // It went where the legs say: about 1 m ahead and 0.8 m to the left before the turns
    // (the last quarter circle of 1 m radius adds about 1 m each way), facing backwards.
    assert!(true_yaw.abs() > 2.5, "{true_yaw}");
    assert_eq!(stats["ignored"]["mode_changing"], 0, "{stats}");
    assert_eq!(stats["mode_changes_refused"], 0, "{stats}");
    assert!(stats["mode_changes"].as_u64() >= Some(5), "{stats}");
}

/// A Ranger Mini 2.0's spin and a Ranger Mini 3.0's turn as the vendor lays them out, read by
/// a chassis emulated apart from this project (`v2_chassis.py --motion-modes`): the Mini 2.0
/// is asked for spin mode (0x141 `[02]`) and then spins by bytes 4-5, never by the yaw-rate
/// field (ugv_sdk PR 10), and nothing moves it while it changes; the Mini 3.0 turns in dual
/// Ackermann, the mode it reports, with its speed and inner wheels' angle; zero on every field
/// when the client ends.
#[test]
fn a_rangers_mode_and_command_are_where_the_vendor_puts_them() {
    let (chassis, _gateway, drive) =
        EmulatedChassis::driven("ranger-mini-2", &["--angular", "0.5"]);
    let seen = chassis.commands_until(|c| c[2] == 500);
    assert_eq!(seen.last().map(|c| c[2]), Some(500), "{seen:?}");
    assert!(
        seen.iter().all(|c| c[0] == 0 && c[1] == 0 && c[3] == 0),
        "the spin rate in bytes 4-5 alone: {seen:?}"
    );
    let events = chassis.events();
    assert!(
        events.contains(&serde_json::json!({ "set_motion_mode": 2 })),
        "{events:?}"
    );
    assert!(
        events
            .iter()
            .all(|event| event.get("moved_while_changing").is_none()),
        "{events:?}"
    );
    chassis.ends_at_zero();
    drop(drive);

    let ranger = Model::RangerMini3.four_wheel().expect("a Ranger");
    steers_in_0x111(Model::RangerMini3, 0.3, ranger.inner_for(0.3, 0.3));
}
