//! scout-gateway against scout-sim over pseudo-terminals: state end to end, the command cadence
//! the chassis sees, ownership, shutdown, reconnect and garbage.

use std::time::Duration;

use nix::sys::signal::Signal;
use scout_system_tests::{Gateway, Sim, connect, robot_name, wait_for_state};

const STATE_LIMIT: Duration = Duration::from_secs(10);

fn temp_link(test: &str) -> (std::path::PathBuf, String) {
    let dir = std::env::temp_dir().join(format!("scout-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let link = dir.join("chassis");
    let text = link.to_str().expect("utf-8").to_owned();
    (dir, text)
}

fn check_state_end_to_end(transport: &str) {
    let name = robot_name(&format!("e2e-{transport}"));
    let mut sim = Sim::start(&[&format!("--{transport}")]);
    sim.send("battery 24.7");
    let port = sim.port().to_owned();
    let gateway = Gateway::start(&[&format!("--{transport}"), &port, "--name", &name]);
    let robot = connect(&name);
    let subscriber = robot.subscribe().expect("subscribe");
    let state = wait_for_state(&subscriber, STATE_LIMIT, |s| {
        s["link"]["state"] == "ok" && !s["system"].is_null() && !s["lights"].is_null()
    });
    assert_eq!(state["robot"], name.as_str());
    assert_eq!(state["link"]["transport"], transport);
    assert_eq!(state["link"]["device"], port.as_str());
    let mode = if transport == "serial" {
        "serial"
    } else {
        "can"
    };
    assert_eq!(state["system"]["control_mode"], mode);
    assert_eq!(state["system"]["state"], "normal");
    assert_eq!(state["system"]["battery_voltage"], 24.7);
    assert_eq!(state["motors"].as_array().map(Vec::len), Some(4));
    assert_eq!(state["lights"]["rear"]["mode"], "breath");
    assert_eq!(state["link"]["checksum_errors"], 0, "{}", gateway.log());
    // The e-stop reaches every subscriber.
    sim.send("estop on");
    let state = wait_for_state(&subscriber, STATE_LIMIT, |s| {
        s["system"]["state"] == "estop"
    });
    assert!(
        state["system"]["faults"]
            .as_array()
            .expect("faults")
            .contains(&"motor_1_comm_fault".into())
    );
    // The chassis hears 0x130 with valid checksums in its link's control mode (the 20 ms grid
    // itself is tested exactly, in simulated time, in the gateway's core tests).
    let deadline = std::time::Instant::now() + STATE_LIMIT;
    let stats = loop {
        let stats = sim.stats();
        if stats["commands"]["0x130"].as_u64().unwrap_or(0) >= 40 {
            break stats;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "too few commands: {stats}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(stats["checksum_failures"], 0, "{stats}");
    assert_eq!(stats["ignored"]["wrong_mode"], 0, "{stats}");
    assert_eq!(stats["last_command"]["linear"], 0.0);
}

#[test]
fn serial_state_end_to_end() {
    check_state_end_to_end("serial");
}

#[test]
fn slcan_state_end_to_end() {
    check_state_end_to_end("slcan");
}

#[test]
fn second_gateway_is_refused_and_the_first_keeps_running() {
    let name = robot_name("second");
    let sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let mut first = Gateway::start(&["--serial", &port, "--name", &name]);
    let subscriber = connect(&name).subscribe().expect("subscribe");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    // Refused whatever its environment: a systemd unit and a login shell have different run
    // directories, and the name's lock does not depend on them. The refusal names the holder.
    let other_run_dir = std::env::temp_dir().join(format!("{name}-run"));
    let other_run_dir = other_run_dir.to_string_lossy();
    for env in [
        vec![],
        vec![
            ("SCOUT_RUN_DIR", other_run_dir.as_ref()),
            ("XDG_RUNTIME_DIR", "/nonexistent"),
        ],
    ] {
        let mut same_name = Gateway::start_with_env(&["--sim", "--name", &name], &env);
        assert_eq!(same_name.wait_exit(Duration::from_secs(10)), Some(2));
        let holder = format!(
            "already served by another scout-gateway on this host (pid {})",
            first.pid()
        );
        assert!(same_name.log().contains(&holder), "{}", same_name.log());
    }
    let other_name = robot_name("second-other");
    let mut same_device = Gateway::start(&["--serial", &port, "--name", &other_name]);
    assert_eq!(same_device.wait_exit(Duration::from_secs(10)), Some(2));
    assert!(
        same_device.log().contains(&format!("device {port}")),
        "{}",
        same_device.log()
    );
    assert!(first.is_running());
    let state = wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    assert_eq!(state["robot"], name.as_str());
}

#[test]
fn sigterm_sends_zero_speed_then_exits_0() {
    let name = robot_name("sigterm");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let mut gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let subscriber = connect(&name).subscribe().expect("subscribe");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    let before = sim.stats()["commands"]["0x130"].as_u64().expect("count");
    gateway.signal(Signal::SIGTERM);
    assert_eq!(
        gateway.wait_exit(Duration::from_secs(10)),
        Some(0),
        "{}",
        gateway.log()
    );
    let after = sim.stats();
    let sent = after["commands"]["0x130"].as_u64().expect("count") - before;
    assert!(
        sent >= 3,
        "at least 3 zero commands after SIGTERM, got {sent}: {after}"
    );
    assert_eq!(after["last_command"]["linear"], 0.0);
    assert_eq!(after["last_command"]["angular"], 0.0);
    assert!(
        gateway.log().contains("stopping: sending zero speed"),
        "{}",
        gateway.log()
    );
}

#[test]
fn reconnects_after_the_chassis_is_unplugged() {
    let name = robot_name("unplug");
    let (dir, link) = temp_link("unplug");
    let mut sim = Sim::start(&["--serial", "--link", &link]);
    let _gateway = Gateway::start(&["--serial", &link, "--name", &name]);
    let subscriber = connect(&name).subscribe().expect("subscribe");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    sim.send("unplug 700");
    wait_for_state(&subscriber, STATE_LIMIT, |s| {
        s["link"]["state"] == "disconnected"
    });
    let state = wait_for_state(&subscriber, STATE_LIMIT, |s| {
        s["link"]["state"] == "ok" && s["link"]["reconnects"] == 1
    });
    assert_eq!(state["system"]["state"], "normal");
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn silence_is_published_and_the_link_resumes() {
    let name = robot_name("silence");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let subscriber = connect(&name).subscribe().expect("subscribe");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    sim.send("silence 500");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "silent");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
}

#[test]
fn garbage_and_corrupt_frames_are_counted_and_survived() {
    let name = robot_name("garbage");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let mut gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let subscriber = connect(&name).subscribe().expect("subscribe");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    sim.send("garbage 3000");
    sim.send("corrupt 7");
    let state = wait_for_state(&subscriber, STATE_LIMIT, |s| {
        s["link"]["checksum_errors"].as_u64() >= Some(7)
            && s["link"]["discarded_bytes"].as_u64() >= Some(1000)
    });
    assert_eq!(state["link"]["state"], "ok");
    let rx = state["link"]["rx_frames"].as_u64().expect("rx");
    wait_for_state(&subscriber, STATE_LIMIT, |s| {
        s["link"]["rx_frames"].as_u64() > Some(rx + 50)
    });
    assert!(gateway.is_running());
}

#[test]
fn restart_after_sigkill_needs_no_manual_cleanup() {
    let name = robot_name("sigkill");
    let mut first = Gateway::start(&["--sim", "--name", &name]);
    let subscriber = connect(&name).subscribe().expect("subscribe");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    drop(subscriber);
    first.signal(Signal::SIGKILL);
    first.wait_exit(Duration::from_secs(10));
    let mut second = Gateway::start(&["--sim", "--name", &name]);
    let subscriber = connect(&name).subscribe().expect("subscribe after restart");
    let state = wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    assert_eq!(state["robot"], name.as_str());
    assert!(second.is_running(), "{}", second.log());
}

#[test]
fn echo_without_a_gateway_says_how_to_start_one() {
    let name = robot_name("nobody");
    let mut echo = scout_system_tests::command("scout");
    echo.args(["echo", "--json", "--count", "1", "--name", &name]);
    let output = scout_system_tests::run_with_input(echo, b"", Duration::from_secs(20));
    assert_eq!(output.status.code(), Some(3));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains(&format!("no gateway named '{name}' is running")),
        "{stderr}"
    );
    assert!(stderr.contains("scout-gateway"), "{stderr}");
}

#[test]
fn echo_json_prints_n_updates_then_exits() {
    let name = robot_name("echo");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    let mut echo = scout_system_tests::command("scout");
    echo.args(["echo", "--json", "--count", "5", "--name", &name]);
    let output = scout_system_tests::run_with_input(echo, b"", Duration::from_secs(20));
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON line"))
        .collect();
    assert_eq!(lines.len(), 5);
    for pair in lines.windows(2) {
        assert!(pair[1]["seq"].as_u64() > pair[0]["seq"].as_u64());
    }
}

/// Ctrl-C (and SIGTERM) end `scout echo` as a person expects: exit 0, no error (it said
/// "waiting for the state: InterruptSignal" and exited 1).
#[test]
fn echo_ends_on_ctrl_c_with_exit_0() {
    use std::io::{BufRead, BufReader};
    let name = robot_name("echo-sigint");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    for signal in [Signal::SIGINT, Signal::SIGTERM] {
        let mut echo = scout_system_tests::command("scout");
        echo.args(["echo", "--json", "--name", &name])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped());
        let mut child = echo.spawn().expect("scout echo");
        let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
        lines.next().expect("a first state").expect("a line");
        let pid = nix::unistd::Pid::from_raw(child.id() as i32);
        nix::sys::signal::kill(pid, signal).expect("signal");
        // Read on, so it never blocks on a full pipe.
        std::thread::spawn(move || for _ in lines {});
        let output = scout_system_tests::wait_output(child, Duration::from_secs(10));
        assert_eq!(
            output.status.code(),
            Some(0),
            "{signal}: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
}

#[test]
fn echo_into_a_closed_pipe_ends_quietly_with_exit_0() {
    use std::io::{BufRead, BufReader};
    let name = robot_name("pipe");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    // `scout echo --json | head -1`: the reader takes one line and closes the pipe.
    let mut echo = scout_system_tests::command("scout")
        .args(["echo", "--json", "--name", &name])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start scout echo");
    let mut first = String::new();
    BufReader::new(echo.stdout.take().expect("stdout"))
        .read_line(&mut first)
        .expect("one line");
    assert!(first.starts_with('{'), "{first}");
    let output = scout_system_tests::wait_output(echo, Duration::from_secs(10));
    assert_eq!(output.status.code(), Some(0));
    assert_eq!(String::from_utf8_lossy(&output.stderr), "");
}

#[test]
fn odometry_reset_from_a_client() {
    let name = robot_name("odometry");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let subscriber = robot.subscribe().expect("subscribe");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    robot
        .controller("odometer", None)
        .expect("controller")
        .reset_odometry()
        .expect("reset");
    wait_for_state(&subscriber, STATE_LIMIT, |s| s["odometry"]["resets"] == 1);
}

#[test]
fn a_late_subscriber_gets_the_latest_state_at_once() {
    let name = robot_name("late");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let robot = connect(&name);
    let early = robot.subscribe().expect("subscribe");
    wait_for_state(&early, STATE_LIMIT, |s| s["link"]["state"] == "ok");
    // A silent chassis: nothing is published after the change to `silent`.
    sim.send("silence 60000");
    let silent = wait_for_state(&early, STATE_LIMIT, |s| s["link"]["state"] == "silent");
    let late = robot.subscribe().expect("late subscribe");
    let state = late
        .next_timeout(Duration::from_secs(1))
        .expect("receive")
        .expect("the latest state at once, though no frame arrives");
    assert!(state.seq >= silent["seq"].as_u64().expect("seq"));
    let json = scout_clients::interface::json::state_json(&state, scout_clients::monotonic_ns());
    assert_eq!(json["link"]["state"], "silent");
}

#[test]
fn thirty_two_subscriber_processes_at_once() {
    const PROCESSES: usize = 32;
    let name = robot_name("many");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    let children: Vec<_> = (0..PROCESSES)
        .map(|_| {
            scout_system_tests::command("scout")
                .args(["echo", "--json", "--count", "20", "--name", &name])
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("spawn scout echo")
        })
        .collect();
    for child in children {
        let output = child.wait_with_output().expect("scout echo output");
        assert!(
            output.status.success(),
            "{}",
            String::from_utf8_lossy(&output.stderr)
        );
        assert_eq!(String::from_utf8_lossy(&output.stdout).lines().count(), 20);
    }
}
