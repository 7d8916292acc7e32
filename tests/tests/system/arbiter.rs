//! The arbiter across processes: clients of each class, the stop from a third process, clients
//! that die or stop, bad values; the chassis (scout-sim) sees the result.

use std::time::Duration;

use nix::sys::signal::Signal;
use scout_clients::control::ControlError;
use scout_clients::{Class, RejectionKind};
use scout_system_tests::{
    Driver, Gateway, Sim, connect, robot_name, scout, status_now, wait_for_state, wait_for_status,
};

const LIMIT: Duration = Duration::from_secs(10);

fn selected_client(status: &serde_json::Value) -> Option<&str> {
    status["selected"]["client"].as_str()
}

#[test]
fn teleop_overrides_autonomy_at_once() {
    let name = robot_name("override");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let state = robot.subscribe().expect("state");
    resume(&name);
    let _autonomy = Driver::start(
        &name,
        &[
            "--linear", "0.4", "--class", "autonomy", "--client", "planner",
        ],
    );
    wait_for_status(&status, LIMIT, |s| selected_client(s) == Some("planner"));
    wait_for_state(&state, LIMIT, |s| {
        s["command"]["linear"].as_f64() > Some(0.35)
    });
    let mut teleop = robot
        .controller("joystick", Some(Class::Teleop))
        .expect("teleop");
    teleop.take_control().expect("teleop takes control");
    teleop.drive(0.0, 0.0).expect("teleop accepted");
    let accepted_at = scout_clients::monotonic_ns();
    // Every status published after the answer shows teleop driving.
    let after = wait_for_status(&status, LIMIT, |s| {
        let published =
            scout_clients::monotonic_ns() as f64 - s["age_ms"].as_f64().unwrap_or(0.0) * 1e6;
        published > accepted_at as f64
    });
    assert_eq!(selected_client(&after), Some("joystick"), "{after}");
    assert_eq!(after["autonomy_armed"], false);
    // The output ramps down from the autonomy speed at the deceleration limit.
    let slowing = wait_for_state(&state, LIMIT, |s| {
        s["command"]["linear"].as_f64() < Some(0.35)
    });
    assert!(
        slowing["command"]["linear"].as_f64() > Some(0.0),
        "ramps, does not jump: {slowing}"
    );
    // The autonomy client is refused from now on, with the reason.
    let mut planner = robot
        .controller("planner-2", Some(Class::Autonomy))
        .expect("autonomy");
    let Err(ControlError::Rejected(rejected)) = planner.take_control() else {
        panic!("autonomy must be refused after a teleop takeover")
    };
    assert_eq!(rejected.kind, Some(RejectionKind::AutonomyDisarmed));
    assert!(rejected.reason.contains("autonomy disarmed"), "{rejected}");
}

#[test]
fn estop_from_a_third_process_release_then_resume() {
    let name = robot_name("estop");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let state = robot.subscribe().expect("state");
    resume(&name);
    let mut autonomy = Driver::start(
        &name,
        &[
            "--linear", "0.5", "--class", "autonomy", "--client", "planner",
        ],
    );
    wait_for_state(&state, LIMIT, |s| {
        s["motion"]["linear"].as_f64() > Some(0.3)
    });
    let (code, stdout, stderr) = scout(&[
        "estop",
        "--name",
        &name,
        "--client",
        "safety",
        "--reason",
        "person ahead",
    ]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    // The zero command went out at once: the very next state shows it sent.
    let stopped = wait_for_state(&state, LIMIT, |s| s["command"]["linear"] == 0.0);
    assert_eq!(stopped["command"]["angular"], 0.0);
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], "safety");
    assert_eq!(latched["stops"][0]["cause"], "client");
    assert_eq!(latched["stops"][0]["reason"], "person ahead");
    assert_eq!(latched["selected"], serde_json::Value::Null);
    // The autonomy client that was streaming lost its control: `scout drive` exits 4 naming
    // the cause, and never takes control again by itself.
    assert_eq!(autonomy.wait_exit(LIMIT), Some(4));
    assert_eq!(
        sim.stats()["last_command"]["linear"],
        0.0,
        "the chassis is told zero"
    );
    // Drive is refused while latched; the refusal says why and exits 4.
    let (code, _, stderr) = scout(&[
        "drive",
        "--name",
        &name,
        "--linear",
        "0.2",
        "--duration",
        "0.2",
    ]);
    assert_eq!(code, Some(4), "{stderr}");
    assert!(
        stderr.contains("stopped by #1 safety (client): person ahead"),
        "{stderr}"
    );
    // Release does not restart motion, and autonomy stays disarmed until resume.
    let (code, ..) = scout(&["release", "--name", &name]);
    assert_eq!(code, Some(0));
    let released = wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    assert_eq!(released["autonomy_armed"], false);
    assert_eq!(
        released["selected"],
        serde_json::Value::Null,
        "no motion after release: {released}"
    );
    std::thread::sleep(Duration::from_millis(300));
    let still = wait_for_state(&state, LIMIT, |_| true);
    assert_eq!(still["command"]["linear"], 0.0, "{still}");
    resume(&name);
    let resumed = wait_for_status(&status, LIMIT, |s| s["autonomy_armed"] == true);
    assert_eq!(
        resumed["selected"],
        serde_json::Value::Null,
        "resume restarts nothing"
    );
}

/// `scout resume`: arms autonomy (it starts disarmed).
fn resume(name: &str) {
    let (code, _, stderr) = scout(&["resume", "--name", name]);
    assert_eq!(code, Some(0), "{stderr}");
}

#[test]
fn a_killed_driver_is_released_at_once_a_stopped_one_when_stale() {
    let name = robot_name("killed");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    resume(&name);
    let killed = Driver::start(
        &name,
        &[
            "--linear", "0.3", "--class", "autonomy", "--client", "doomed",
        ],
    );
    wait_for_status(&status, LIMIT, |s| selected_client(s) == Some("doomed"));
    killed.signal(Signal::SIGKILL);
    // Dead-process detection removes the client; it does not linger until its command ages out.
    let gone = wait_for_status(&status, LIMIT, |s| {
        s["sources"]
            .as_array()
            .is_some_and(|sources| sources.iter().all(|c| c["client"] != "doomed"))
    });
    assert_eq!(gone["selected"], serde_json::Value::Null);
    // A stopped (SIGSTOP) process is alive: it loses control when its command goes stale.
    let mut resume = robot.controller("operator", None).expect("controller");
    resume.resume().expect("resume");
    let stopped = Driver::start(
        &name,
        &[
            "--linear", "0.3", "--class", "autonomy", "--client", "frozen",
        ],
    );
    wait_for_status(&status, LIMIT, |s| selected_client(s) == Some("frozen"));
    stopped.signal(Signal::SIGSTOP);
    let stale = wait_for_status(&status, LIMIT, |s| s["selected"].is_null());
    let frozen = stale["sources"]
        .as_array()
        .and_then(|a| a.iter().find(|c| c["client"] == "frozen").cloned());
    let frozen = frozen.expect("a stopped client is still listed");
    assert_eq!(frozen["holding"], false);
    assert!(
        frozen["age_ms"].as_f64() >= Some(400.0),
        "stale after its command's age: {frozen}"
    );
    stopped.signal(Signal::SIGCONT);
}

#[test]
fn nan_and_huge_values_are_rejected_or_clamped() {
    let name = robot_name("values");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let mut teleop = robot
        .controller("fuzzy", Some(Class::Teleop))
        .expect("teleop");
    teleop.take_control().expect("control");
    for (linear, angular) in [
        (f64::NAN, 0.0),
        (0.0, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NAN),
    ] {
        match teleop.drive(linear, angular) {
            Err(ControlError::Rejected(rejected)) => {
                assert_eq!(rejected.kind, Some(RejectionKind::NotFinite));
                assert!(rejected.reason.contains("NaN or infinite"), "{rejected}");
            }
            other => panic!("{linear} {angular} accepted: {other:?}"),
        }
    }
    let state = robot.subscribe().expect("state");
    let status = robot.status().expect("status");
    // Driven (the command lives only while it is sent) until the status shows the cap holding.
    let deadline = std::time::Instant::now() + LIMIT;
    let counted = loop {
        let accepted = teleop
            .drive(1e9, -1e9)
            .expect("huge values are clamped, not refused");
        assert!(accepted.clamped);
        std::thread::sleep(Duration::from_millis(20));
        let shown = status_now(&status, Duration::ZERO).unwrap_or_default();
        let capped = shown["rejections"]["not_finite"] == 3
            && shown["output"]["linear"].as_f64() > Some(1.4);
        if capped || std::time::Instant::now() > deadline {
            break shown;
        }
    };
    assert_eq!(counted["rejections"]["not_finite"], 3, "{counted}");
    assert_eq!(counted["output"]["limited"], true, "{counted}");
    let capped = wait_for_state(&state, LIMIT, |s| {
        s["command"]["linear"].as_f64() > Some(1.4)
    });
    assert!(capped["command"]["linear"].as_f64() <= Some(1.5));
    assert!(capped["command"]["angular"].as_f64() >= Some(-0.53));
}

#[test]
fn lights_are_repeated_and_fault_clear_reaches_the_chassis() {
    let name = robot_name("lights");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let robot = connect(&name);
    let state = robot.subscribe().expect("state");
    let (code, _, stderr) = scout(&[
        "lights",
        "--name",
        &name,
        "--front",
        "custom:40",
        "--rear",
        "on",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    let lit = wait_for_state(&state, LIMIT, |s| s["lights"]["enabled"] == true);
    assert_eq!(
        lit["lights"]["front"],
        serde_json::json!({"mode": "custom", "brightness": 40})
    );
    // Serial light commands time out after 500 ms on the chassis: the gateway repeats them (at
    // 100 ms on serial; the period is tested exactly in the gateway's core tests).
    let deadline = std::time::Instant::now() + LIMIT;
    while sim.stats()["commands"]["0x140"].as_u64().unwrap_or(0) < 10 {
        assert!(std::time::Instant::now() < deadline, "lights not repeated");
        std::thread::sleep(Duration::from_millis(50));
    }
    let still = wait_for_state(&state, LIMIT, |_| true);
    assert_eq!(still["lights"]["enabled"], true);
    let (code, ..) = scout(&["lights", "--name", &name, "auto"]);
    assert_eq!(code, Some(0));
    wait_for_state(&state, LIMIT, |s| s["lights"]["enabled"] == false);
    // A latched protection, cleared by its code.
    sim.send("protect overtemp");
    wait_for_state(&state, LIMIT, |s| {
        s["system"]["faults"]
            .as_array()
            .is_some_and(|f| f.contains(&"driver_overtemp_protection".into()))
    });
    let (code, _, stderr) = scout(&["clear-fault", "--name", &name, "driver_overtemp"]);
    assert_eq!(code, Some(0), "{stderr}");
    wait_for_state(&state, LIMIT, |s| {
        s["system"]["faults"]
            .as_array()
            .is_some_and(|f| !f.contains(&"driver_overtemp_protection".into()))
    });
    let (code, _, stderr) = scout(&["clear-fault", "--name", &name, "everything"]);
    assert_eq!(code, Some(1), "{stderr}");
}

#[test]
fn status_json_and_errors_without_a_gateway() {
    let name = robot_name("status");
    let (code, _, stderr) = scout(&["status", "--name", &name]);
    assert_eq!(code, Some(3), "{stderr}");
    assert!(stderr.contains("no gateway named"), "{stderr}");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    let (code, stdout, stderr) = scout(&["status", "--name", &name, "--json"]);
    assert_eq!(code, Some(0), "{stderr}");
    let status: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    assert_eq!(status["latched"], false);
    assert_eq!(status["selected"], serde_json::Value::Null);
    assert_eq!(status["autonomy_armed"], false, "autonomy starts disarmed");
}

#[test]
fn a_heartbeat_source_that_dies_latches_the_stop() {
    let name = robot_name("deadman");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let mut remote = robot.controller("handheld", None).expect("controller");
    remote
        .heartbeat(Duration::from_millis(200))
        .expect("register");
    for _ in 0..5 {
        std::thread::sleep(Duration::from_millis(50));
        remote.heartbeat(Duration::from_millis(200)).expect("beat");
    }
    assert_eq!(wait_for_status(&status, LIMIT, |_| true)["latched"], false);
    // The handheld stops beating (its loop hung): the stop latches.
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], "handheld");
    assert_eq!(latched["stops"][0]["cause"], "heartbeat");
    assert_eq!(
        latched["stops"][0]["persists"], true,
        "the source is still silent"
    );
    // Nobody releases the deadman while its source is silent.
    let (code, _, stderr) = scout(&["release", "--name", &name]);
    assert_eq!(code, Some(4), "{stderr}");
    assert!(stderr.contains("cannot release yet"), "{stderr}");
    // The handheld dies: the stop can be released by an operator.
    drop(remote);
    drop(robot);
}

#[test]
fn ctrl_c_stops_scout_drive_before_it_exits() {
    let name = robot_name("ctrl-c");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let mut driver = Driver::start(&name, &["--linear", "0.4", "--client", "keyboard"]);
    wait_for_status(&status, LIMIT, |s| selected_client(s) == Some("keyboard"));
    driver.signal(Signal::SIGINT);
    assert_eq!(driver.wait_exit(LIMIT), Some(0));
    // It sent zero and gave up control: nobody drives, and it is still listed (not dead).
    let after = wait_for_status(&status, LIMIT, |s| s["selected"].is_null());
    let keyboard = after["sources"]
        .as_array()
        .and_then(|a| a.iter().find(|c| c["client"] == "keyboard").cloned());
    if let Some(keyboard) = keyboard {
        assert_eq!(keyboard["holding"], false);
    }
    let stopped = wait_for_status(&status, LIMIT, |s| s["output"]["linear"] == 0.0);
    assert_eq!(
        stopped["latched"], false,
        "Ctrl-C stops the drive, it does not latch the stop"
    );
}

/// `scout drive` stalled past its class's age just before its end (a loaded host, SIGSTOP): the
/// gateway ended its control, and the program says so and exits 4 instead of "accepted" and 0.
#[test]
fn scout_drive_whose_control_lapsed_at_its_end_says_so_and_fails() {
    let name = robot_name("drive-lapsed");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let mut drive = scout_system_tests::command("scout");
    drive
        .args(["drive", "--name", &name, "--class", "teleop"])
        .args(["--linear", "0.2", "--duration", "2"])
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    let child = drive.spawn().expect("spawn scout drive");
    let pid = nix::unistd::Pid::from_raw(child.id() as i32);
    wait_for_status(&status, LIMIT, |s| {
        s["selected"]["client"]
            .as_str()
            .is_some_and(|client| client.starts_with("drive-"))
    });
    // Frozen for longer than its whole duration: it wakes up past its end, its control long
    // lapsed (teleop: 250 ms without a command).
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGSTOP).expect("SIGSTOP");
    std::thread::sleep(Duration::from_secs(3));
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGCONT).expect("SIGCONT");
    let output = scout_system_tests::wait_output(child, LIMIT);
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(output.status.code(), Some(4), "{said}");
    assert!(said.contains("stale"), "names the cause: {said}");
}
