//! The gateway driving a protocol v2 chassis (SCOUT 2.0, SCOUT MINI): the simulator's v2 firmware
//! behind a serial-line CAN adapter on a pseudo-terminal, the gateway with `--protocol auto`
//! (the default). The command mode is taken only when a client drives and never from the RC,
//! the model's limits hold, and the chassis is left in standby at exit.

use std::time::{Duration, Instant};

use scout_system_tests::{
    Driver, Gateway, Sim, chassis_stays_still, comes_to_rest, connect, drive_until_moving, moving,
    release_all, robot_name, wait_for_state, wait_for_status,
};

/// How many 0x421 frames the simulator has received.
fn mode_requests(sim: &mut Sim) -> u64 {
    sim.stats()["commands"]["0x421"].as_u64().unwrap_or(0)
}

#[test]
fn a_scout2_is_told_by_its_frames_taken_only_when_driven_and_left_in_standby() {
    let name = robot_name("v2-scout2");
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "scout2"]);
    let device = sim.port().to_owned();
    let mut gateway = Gateway::start(&["--slcan", &device, "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("subscribe");
    let state = wait_for_state(&states, Duration::from_secs(10), |s| {
        s["link"]["state"] == "ok" && !s["firmware"].is_null() && !s["odometer"].is_null()
    });
    assert_eq!(state["link"]["protocol"], "v2", "{state}");
    assert_eq!(state["chassis"]["model"], "scout2");
    assert_eq!(state["system"]["control_mode"], "standby");
    assert!(
        state["firmware"]["text"]
            .as_str()
            .is_some_and(|text| text.contains("scout-sim v2")),
        "the version request answered: {state}"
    );
    assert!(state["motors"][0]["driver_voltage"].is_number(), "{state}");
    // Nothing takes the chassis before a client drives.
    std::thread::sleep(Duration::from_millis(500));
    assert_eq!(mode_requests(&mut sim), 0, "no 0x421 at start-up");
    assert_eq!(sim.stats()["control_mode"], "standby");

    let mut driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.5", "--duration", "3"],
        Duration::from_secs(5),
    );
    let stats = sim.stats();
    assert_eq!(stats["control_mode"], "can", "{stats}");
    assert!(mode_requests(&mut sim) >= 1);
    let driving = wait_for_state(&states, Duration::from_secs(5), |s| {
        s["system"]["control_mode"] == "can" && s["odometry"]["distance"].as_f64() > Some(0.2)
    });
    assert!(
        driving["odometer"]["left"].as_f64() > Some(0.15),
        "{driving}"
    );
    assert!(
        driving["motion"]["linear"].as_f64() > Some(0.3),
        "{driving}"
    );
    assert_eq!(driver.wait_exit(Duration::from_secs(10)), Some(0));
    comes_to_rest(&mut sim, Duration::from_secs(5));

    gateway.signal(nix::sys::signal::Signal::SIGTERM);
    assert_eq!(gateway.wait_exit(Duration::from_secs(10)), Some(0));
    assert_eq!(
        sim.stats()["control_mode"],
        "standby",
        "standby on exit: {}",
        gateway.log()
    );
}

#[test]
fn a_scout_mini_goes_as_fast_as_a_mini_and_a_scout2_gateway_caps_it() {
    let name = robot_name("v2-mini");
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "scout-mini"]);
    let device = sim.port().to_owned();
    let gateway = Gateway::start(&["--slcan", &device, "--name", &name, "--model", "scout-mini"]);
    let states = connect(&name).subscribe().expect("subscribe");
    let state = wait_for_state(&states, Duration::from_secs(10), |s| {
        s["link"]["state"] == "ok"
    });
    assert_eq!(state["chassis"]["max_linear"], 3.0, "{state}");
    let _driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "2.5", "--duration", "6"],
        Duration::from_secs(5),
    );
    let deadline = Instant::now() + Duration::from_secs(6);
    while sim.stats()["actual"]["linear"].as_f64() < Some(2.0) {
        assert!(
            Instant::now() < deadline,
            "a MINI reaches 2 m/s: {}",
            gateway.log()
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    drop(gateway);

    // The same chassis behind a gateway that thinks it a SCOUT 2.0: at most 1.5 m/s.
    let name = robot_name("v2-capped");
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "scout-mini"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--slcan", &device, "--name", &name, "--protocol", "v2"]);
    let _driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "2.5", "--duration", "5"],
        Duration::from_secs(5),
    );
    std::thread::sleep(Duration::from_secs(3));
    let stats = sim.stats();
    let commanded = stats["last_command"]["linear"].as_f64().expect("a command");
    assert!((commanded - 1.5).abs() < 1e-9, "capped at 1.5 m/s: {stats}");
}

#[test]
fn the_rc_takes_a_v2_chassis_and_nothing_fights_it_or_restarts_after_it() {
    let name = robot_name("v2-rc");
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--slcan", &device, "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    // A client that keeps streaming across everything below.
    let _stream = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.5"],
        Duration::from_secs(5),
    );
    sim.send("rc on");
    wait_for_status(&status, Duration::from_secs(5), |s| {
        s["stops"]
            .as_array()
            .is_some_and(|stops| stops.iter().any(|stop| stop["cause"] == "rc_override"))
    });
    let before = mode_requests(&mut sim);
    std::thread::sleep(Duration::from_secs(1));
    assert_eq!(
        mode_requests(&mut sim),
        before,
        "no 0x421 while the RC holds it"
    );
    sim.send("rc off");
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        sim.stats()["control_mode"],
        "standby",
        "the RC left it in standby"
    );
    chassis_stays_still(&mut sim, Duration::from_secs(1));
    release_all(&name);
    chassis_stays_still(&mut sim, Duration::from_secs(1));
    assert_eq!(
        mode_requests(&mut sim),
        before,
        "a release takes nothing; the stream that went on across it drives nothing"
    );
    // A deliberate new drive takes the chassis again.
    let _again = Driver::start(&name, &["--linear", "0.5", "--duration", "3"]);
    moving(&mut sim, Duration::from_secs(5));
    assert!(mode_requests(&mut sim) > before);
}

#[test]
fn a_gateway_told_v1_names_a_v2_chassis_and_moves_nothing() {
    let name = robot_name("v2-mismatch");
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "scout2"]);
    let device = sim.port().to_owned();
    let gateway = Gateway::start(&["--slcan", &device, "--name", &name, "--protocol", "v1"]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("subscribe");
    let state = wait_for_state(&states, Duration::from_secs(10), |s| {
        s["link"]["state"] == "protocol_mismatch"
    });
    assert_eq!(
        state["motion"],
        serde_json::Value::Null,
        "nothing of v2 is used"
    );
    let status = robot.status().expect("status");
    let status = wait_for_status(&status, Duration::from_secs(5), |s| {
        s["stops"].as_array().is_some_and(|stops| !stops.is_empty())
    });
    let reason = status["stops"][0]["reason"]
        .as_str()
        .unwrap_or_default()
        .to_owned();
    assert!(reason.contains("--protocol v2"), "{status}");
    assert!(
        gateway.log().contains("0x221"),
        "the log names the ids seen:\n{}",
        gateway.log()
    );
    let (code, _, _) = scout_system_tests::scout(&[
        "drive",
        "--name",
        &name,
        "--linear",
        "0.5",
        "--duration",
        "1",
    ]);
    assert_eq!(
        code,
        Some(4),
        "refused: the chassis is silent to this gateway"
    );
    let stats = sim.stats();
    assert_eq!(stats["actual"]["linear"], 0.0, "{stats}");
    assert_eq!(stats["control_mode"], "standby", "no 0x421: {stats}");
}

#[test]
fn a_chassis_that_reports_a_rangers_motion_mode_is_not_driven_as_a_scout() {
    let name = robot_name("v2-ranger");
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "scout2"]);
    let device = sim.port().to_owned();
    let gateway = Gateway::start(&["--slcan", &device, "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("subscribe");
    let driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.5", "--duration", "30"],
        Duration::from_secs(5),
    );
    // The feedback of a Ranger Mini arrives (0x291: parallel mode, not changing).
    sim.send("frame 291 0100000000000000");
    let state = wait_for_state(&states, Duration::from_secs(5), |s| {
        s["link"]["state"] == "protocol_mismatch"
    });
    let status = robot.status().expect("status");
    let status = wait_for_status(&status, Duration::from_secs(5), |s| {
        s["stops"].as_array().is_some_and(|stops| !stops.is_empty())
    });
    let reason = status["stops"][0]["reason"].as_str().unwrap_or_default();
    assert!(
        reason.contains("not a scout2") && reason.contains("0x291"),
        "{status}\n{state}"
    );
    comes_to_rest(&mut sim, Duration::from_secs(2));
    // The client streaming on moves nothing; the log says what the chassis looks like.
    chassis_stays_still(&mut sim, Duration::from_secs(1));
    assert!(gateway.log().contains("a Ranger Mini"), "{}", gateway.log());
    drop(driver);
}
