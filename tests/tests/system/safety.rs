//! Safety across real processes: nothing but a deliberate act restarts motion (a gateway
//! restart, a lost port, a silent chassis, a chassis e-stop), stops stack and are released only
//! by their owner or an operator, a stop is never refused, and a flood does not starve the tick.

use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use scout_clients::control::ControlError;
use scout_clients::{Class, RejectionKind, ReleaseTarget};
use scout_system_tests::{
    Driver, Gateway, Sim, chassis_stays_still, connect, moving, release_all, robot_name, scout,
    wait_for_state, wait_for_status,
};

const LIMIT: Duration = Duration::from_secs(10);

#[test]
fn a_gateway_restart_does_not_resume_a_client_that_keeps_streaming() {
    let name = robot_name("restart-live");
    let mut gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let (code, ..) = scout(&["resume", "--name", &name]);
    assert_eq!(code, Some(0));
    let mut planner = robot
        .controller("planner", Some(Class::Autonomy))
        .expect("controller");
    planner.take_control().expect("control");
    let state = robot.subscribe().expect("state");
    for _ in 0..50 {
        planner.drive(0.5, 0.0).expect("driving");
        std::thread::sleep(Duration::from_millis(20));
    }
    wait_for_state(&state, LIMIT, |s| {
        s["command"]["linear"].as_f64() > Some(0.3)
    });
    gateway.signal(Signal::SIGKILL);
    gateway.wait_exit(LIMIT);
    let _new = Gateway::start(&["--sim", "--name", &name]);
    // The killed gateway's services linger until the new one cleans them up and creates its
    // own: retry until the new status service is there.
    let deadline = Instant::now() + LIMIT;
    let status = loop {
        match connect(&name).status() {
            Ok(status) => break status,
            Err(error) => assert!(Instant::now() < deadline, "{error}"),
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    // The unclean exit left a stop, and the client that kept streaming drives nothing.
    let stopped = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(stopped["stops"][0]["cause"], "gateway_start");
    let state = connect(&name).subscribe().expect("state");
    let end = Instant::now() + Duration::from_secs(2);
    while Instant::now() < end {
        let answer = planner.drive(0.5, 0.0);
        assert!(answer.is_err(), "the old stream was accepted: {answer:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    let latest = wait_for_state(&state, LIMIT, |_| true);
    assert_eq!(latest["command"]["linear"], 0.0, "{latest}");
    assert_eq!(latest["motion"]["linear"], 0.0, "{latest}");
    // Released: still nothing, until it takes control again (and autonomy is resumed).
    release_all(&name);
    let err = planner.drive(0.5, 0.0).expect_err("no control");
    assert!(err.lost_control(), "{err}");
    let err = planner.take_control().expect_err("disarmed");
    assert_eq!(err.rejection(), Some(RejectionKind::AutonomyDisarmed));
}

#[test]
fn a_lost_port_and_a_silent_chassis_stop_a_streaming_driver_for_good() {
    let name = robot_name("unplug-live");
    let mut sim = Sim::start(&["--serial", "--link", &link(&name)]);
    let gateway = Gateway::start(&["--serial", &link(&name), "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let mut driver = Driver::start(&name, &["--linear", "0.5", "--client", "streamer"]);
    moving(&mut sim, LIMIT);
    sim.send("unplug 1500");
    // The driver's control ended with the link: it exits 4, naming the cause.
    assert_eq!(driver.wait_exit(LIMIT), Some(4));
    let lost = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(lost["stops"][0]["cause"], "link_lost", "{lost}");
    // The port comes back: the stop can be released, and nothing moves.
    sim.next_port_line();
    wait_for_status(&status, LIMIT, |s| s["stops"][0]["persists"] == false);
    chassis_stays_still(&mut sim, Duration::from_secs(1));
    release_all(&name);
    // A chassis power cycle: silent for longer than its timeout.
    let mut driver = Driver::start(&name, &["--linear", "0.5", "--client", "streamer-2"]);
    moving(&mut sim, LIMIT);
    sim.send("silence 1200");
    assert_eq!(driver.wait_exit(LIMIT), Some(4));
    let silent = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(silent["stops"][0]["cause"], "chassis_silent", "{silent}");
    wait_for_status(&status, LIMIT, |s| s["stops"][0]["persists"] == false);
    chassis_stays_still(&mut sim, Duration::from_secs(1));
    drop(gateway);
}

fn link(name: &str) -> String {
    std::env::temp_dir()
        .join(format!("{name}.tty"))
        .to_string_lossy()
        .into_owned()
}

#[test]
fn a_chassis_estop_episode_needs_a_release_and_a_new_take() {
    let name = robot_name("estop-episode");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let status = connect(&name).status().expect("status");
    let mut driver = Driver::start(&name, &["--linear", "0.5", "--client", "streamer"]);
    moving(&mut sim, LIMIT);
    sim.send("estop on");
    assert_eq!(driver.wait_exit(LIMIT), Some(4));
    wait_for_status(&status, LIMIT, |s| {
        s["stops"].as_array().is_some_and(|stops| {
            stops
                .iter()
                .any(|stop| stop["cause"] == "chassis_estop" && stop["persists"] == true)
        })
    });
    // Refused while the e-stop is down.
    let (code, _, stderr) = scout(&["release", "--name", &name]);
    assert_eq!(code, Some(4), "{stderr}");
    assert!(stderr.contains("cannot release yet"), "{stderr}");
    sim.send("estop off");
    // The e-stop left the motors' communication faults latched: clear them, then release.
    let (code, ..) = scout(&["clear-fault", "--name", &name, "all"]);
    assert_eq!(code, Some(0));
    wait_for_status(&status, LIMIT, |s| {
        s["stops"]
            .as_array()
            .is_some_and(|stops| stops.iter().all(|stop| stop["persists"] == false))
    });
    release_all(&name);
    chassis_stays_still(&mut sim, Duration::from_secs(1));
}

#[test]
fn stacked_stops_are_released_by_their_owners_or_an_operator() {
    let name = robot_name("stacked");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    for owner in ["safety-officer", "lidar-guard"] {
        let (code, _, stderr) = scout(&["estop", "--name", &name, "--client", owner]);
        assert_eq!(code, Some(0), "{stderr}");
    }
    let both = wait_for_status(&status, LIMIT, |s| s["stop_total"] == 2);
    assert_eq!(both["stops"][1]["owner"], "lidar-guard");
    // A program that is not an operator releases neither.
    let mut random = robot.controller("random-user", None).expect("controller");
    for target in [
        ReleaseTarget::All,
        ReleaseTarget::Owner("safety-officer".into()),
        ReleaseTarget::Own,
    ] {
        let Err(ControlError::Rejected(refused)) = random.release(target, u64::MAX) else {
            panic!("a stranger released a stop")
        };
        assert_eq!(refused.kind, Some(RejectionKind::NotAllowed), "{refused}");
        assert!(
            refused.reason.contains("lidar-guard"),
            "lists what holds: {refused}"
        );
    }
    // The owner releases its own; an operator (the scout tool) releases another's.
    let (code, _, stderr) = scout(&[
        "release",
        "--name",
        &name,
        "--client",
        "lidar-guard",
        "--own",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    let (code, _, stderr) = scout(&["release", "--name", &name, "--owner", "safety-officer"]);
    assert_eq!(code, Some(0), "{stderr}");
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
}

#[test]
fn a_stop_goes_through_with_every_control_slot_taken() {
    let name = robot_name("slots");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let mut controllers = Vec::new();
    while let Ok(controller) = robot.controller(&format!("c{}", controllers.len()), None) {
        controllers.push(controller);
        assert!(controllers.len() <= 64, "the control service is sized");
    }
    assert_eq!(
        controllers.len(),
        scout_clients::interface::services::MAX_CONTROLLERS
    );
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--client", "guard"]);
    assert_eq!(code, Some(0), "{stderr}");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], "guard");
    // Releasing needs no slot either: every control port is still taken.
    let (code, stdout, stderr) = scout(&["release", "--name", &name]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    assert_eq!(
        controllers.len(),
        scout_clients::interface::services::MAX_CONTROLLERS
    );
}

#[test]
fn the_operator_role_comes_from_the_process_not_from_a_name() {
    let name = robot_name("identity");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--reason", "person ahead"]);
    assert_eq!(code, Some(0), "{stderr}");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    let newest = latched["newest_stop"].as_u64().expect("newest_stop");
    assert_eq!(latched["stops"][0]["owner"], "operator");
    // A library client that names itself `operator` releases nothing of scout estop's.
    let mut impostor = robot.controller("operator", None).expect("controller");
    for target in [
        ReleaseTarget::Own,
        ReleaseTarget::Owner("operator".into()),
        ReleaseTarget::All,
    ] {
        let refused = impostor
            .release(target, newest)
            .expect_err("not an operator");
        assert_eq!(
            refused.rejection(),
            Some(RejectionKind::NotAllowed),
            "{refused}"
        );
    }
    // A copy of the scout tool is another file: not the installed scout, no operator.
    let scout_bin = scout_system_tests::bin("scout");
    let dir = std::env::temp_dir().join(format!("{name}-copy"));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let copy = dir.join("scout");
    std::fs::copy(&scout_bin, &copy).expect("copy scout");
    let run_copy = |args: &[&str]| {
        std::process::Command::new(&copy)
            .args(args)
            .args(["--name", &name])
            .output()
            .expect("run the copy")
    };
    let output = run_copy(&["release"]);
    assert_eq!(output.status.code(), Some(4), "{output:?}");
    assert!(
        String::from_utf8_lossy(&output.stdout).contains("only an operator"),
        "{output:?}"
    );
    assert_eq!(wait_for_status(&status, LIMIT, |_| true)["latched"], true);
    // Its `scout estop` is a stop of its user's, beside the person's, which keeps its reason.
    let output = run_copy(&["estop", "--reason", "impostor reason"]);
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(output.status.code(), Some(0), "{output:?}");
    let uid = nix::unistd::getuid();
    let both = wait_for_status(&status, LIMIT, |s| s["stop_total"] == 2);
    assert_eq!(both["stops"][0]["owner"], "operator", "{both}");
    assert_eq!(both["stops"][0]["reason"], "person ahead", "{both}");
    assert_eq!(both["stops"][1]["owner"], format!("uid-{uid}"), "{both}");
    // The installed scout, run by this user, is the operator.
    let (code, stdout, stderr) = scout(&["release", "--name", &name]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
}

/// `scout estop` latches and `scout release` releases with `/dev/shm` full: run inside a mount
/// namespace whose `/dev/shm` is a small tmpfs filled to the last byte. Needs root (or user namespaces) and `unshare`.
#[test]
fn scout_estop_and_release_work_with_dev_shm_full() {
    let test = "scout_estop_and_release_work_with_dev_shm_full";
    let probe = std::process::Command::new("unshare")
        .args(["-m", "true"])
        .output();
    if !probe.as_ref().is_ok_and(|o| o.status.success()) {
        return scout_system_tests::skip(test, &format!("no mount namespace here ({probe:?})"));
    }
    let name = robot_name("fullshm");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let scout_bin = scout_system_tests::bin("scout");
    // `scout ARGS --name NAME` in a mount namespace whose /dev/shm is a 64 KiB tmpfs filled to
    // the last byte.
    let in_full_shm = |args: &str| {
        let script = format!(
            "mount -t tmpfs -o size=64k tmpfs /dev/shm && \
             (dd if=/dev/zero of=/dev/shm/fill bs=4096 2>/dev/null; true) && \
             test \"$(df --output=avail /dev/shm | tail -1 | tr -d ' ')\" = 0 && \
             exec {} {args} --name {name}",
            scout_bin.display()
        );
        std::process::Command::new("unshare")
            .args(["-m", "--propagation", "private", "sh", "-c", &script])
            .output()
            .expect("unshare")
    };
    let output = in_full_shm("estop --reason 'dev/shm full'");
    assert_eq!(output.status.code(), Some(0), "{output:?}");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["reason"], "dev/shm full");
    // A person can recover too: `scout release` goes through the stop endpoint, up to the
    // newest stop the gateway names, and says what fills /dev/shm.
    let output = in_full_shm("release");
    assert_eq!(output.status.code(), Some(0), "{output:?}");
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(said.contains("the largest there: fill"), "{said}");
    assert!(
        String::from_utf8_lossy(&output.stdout).contains("through the stop endpoint"),
        "{output:?}"
    );
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    // Whatever fails there is an error with an exit code, never a signal.
    let output = in_full_shm("status");
    assert!(
        output.status.code().is_some(),
        "killed by a signal: {output:?}"
    );
}

#[test]
fn a_request_flood_neither_starves_the_tick_nor_holds_up_a_stop() {
    let name = robot_name("flood");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let _driver = Driver::start(&name, &["--linear", "0.3", "--client", "streamer"]);
    moving(&mut sim, LIMIT);
    let before = sim.stats()["motion_command_intervals"]["count"]
        .as_u64()
        .unwrap_or(0);
    let floods: Vec<_> = (0..16)
        .map(|_| {
            let mut flood = scout_system_tests::command("scout-bench");
            flood.args(["flood", &name, "1000", "3"]);
            flood
                .stdout(std::process::Stdio::null())
                .spawn()
                .expect("flood")
        })
        .collect();
    std::thread::sleep(Duration::from_secs(1));
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--client", "guard"]);
    assert_eq!(code, Some(0), "{stderr}");
    wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    for mut flood in floods {
        let _ = flood.wait();
    }
    let stats = sim.stats();
    let intervals = &stats["motion_command_intervals"];
    assert!(
        intervals["count"].as_u64().unwrap_or(0) > before + 50,
        "{stats}"
    );
    let after = wait_for_status(&status, LIMIT, |_| true);
    // The safety rule, not the machine's speed: no gap the chassis could have timed out in, or
    // the gateway saw it and latched an overrun (a loaded host stalls it now and then), and the
    // chassis stands still since the guard's stop either way.
    let overrun = after["stops"]
        .as_array()
        .is_some_and(|stops| stops.iter().any(|stop| stop["cause"] == "overrun"));
    assert!(
        intervals["max_ms"].as_f64() < Some(500.0) || overrun,
        "a gap the gateway did not latch: {stats}\n{after}"
    );
    chassis_stays_still(&mut sim, Duration::from_millis(500));
    assert!(
        after["rejections"]["rate_limited"].as_u64() > Some(0),
        "{after}"
    );
    println!("flood: {intervals}, tick {}", after["tick"]);
}

/// A host suspend while a teleop drives: the gateway and the client are stopped for 2 s (the
/// chassis times out meanwhile) and go on with their CLOCK_MONOTONIC showing no gap, as after a
/// real suspend (`suspend_shim.c`, preloaded). The gateway's clock counts the suspend: the gap
/// latches a stop, and the client streaming on moves nothing.
#[test]
fn a_host_suspend_latches_a_stop_and_moves_nothing() {
    let test = "a_host_suspend_latches_a_stop_and_moves_nothing";
    let dir = scout_system_tests::TempDir::new(&robot_name("suspend"));
    let shim = dir.path().join("suspend_shim.so");
    let source = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/system/suspend_shim.c");
    let built = std::process::Command::new("cc")
        .args(["-shared", "-fPIC", "-O2", "-o"])
        .arg(&shim)
        .arg(source)
        .arg("-ldl")
        .output();
    if !built.as_ref().is_ok_and(|o| o.status.success()) {
        return scout_system_tests::skip(test, &format!("no C compiler for the shim: {built:?}"));
    }
    let offset = dir.path().join("suspended_ns");
    std::fs::write(&offset, "0").expect("offset file");
    let (shim, offset) = (shim.to_string_lossy(), offset.to_string_lossy());
    let env = [
        ("LD_PRELOAD", shim.as_ref()),
        ("SCOUT_SUSPEND_SHIM_FILE", offset.as_ref()),
    ];
    let name = robot_name("suspend");
    let mut sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let gateway = Gateway::start_with_env(&["--serial", &port, "--name", &name], &env);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let mut drive = scout_system_tests::command("scout");
    drive
        .args(["drive", "--name", &name, "--linear", "0.3"])
        .envs(env)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    let driver = scout_system_tests::Background::spawn(drive);
    moving(&mut sim, LIMIT);
    // The suspend: both processes stand still; the chassis stops by its own timeout.
    gateway.signal(Signal::SIGSTOP);
    driver.signal(Signal::SIGSTOP);
    let suspended = Instant::now();
    scout_system_tests::comes_to_rest(&mut sim, LIMIT);
    std::thread::sleep(Duration::from_secs(2).saturating_sub(suspended.elapsed()));
    std::fs::write(&*offset, suspended.elapsed().as_nanos().to_string()).expect("offset");
    gateway.signal(Signal::SIGCONT);
    driver.signal(Signal::SIGCONT);
    // The resumed client streams on; nothing moves.
    chassis_stays_still(&mut sim, Duration::from_secs(2));
    let after = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    let causes: Vec<&serde_json::Value> = after["stops"]
        .as_array()
        .map(|stops| stops.iter().map(|stop| &stop["cause"]).collect())
        .unwrap_or_default();
    assert!(
        causes.iter().any(|cause| *cause == "overrun"),
        "{after}\n{}",
        gateway.log()
    );
}

/// Processes whose identity was once expensive to read (tens of thousands of memory mappings:
/// the gateway read `/proc/PID/maps` on the control thread for each datagram) flood the stop
/// endpoint with releases while another user of the robot stops it: the tick is never held up
/// long enough to latch an `overrun` (a stall the chassis could have timed out in), the guard's
/// stop latches, and the flood is refused at its user's share, counted.
#[test]
fn a_stop_endpoint_flood_from_processes_of_many_mappings_stalls_nothing() {
    let name = robot_name("dgram-flood");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let max_maps: usize = std::fs::read_to_string("/proc/sys/vm/max_map_count")
        .ok()
        .and_then(|text| text.trim().parse().ok())
        .unwrap_or(65_530);
    let mappings = (max_maps.saturating_sub(5_000)).min(60_000).to_string();
    let floods: Vec<_> = (0..2)
        .map(|_| {
            let mut flood = scout_system_tests::command("scout-bench");
            flood.args(["datagram-flood", &name, "4", "--mappings", &mappings]);
            let mut child = flood
                .stdout(std::process::Stdio::piped())
                .spawn()
                .expect("flood");
            let lines = scout_system_tests::line_reader(child.stdout.take().expect("stdout"));
            let ready = lines.recv_timeout(LIMIT).expect("the flood is ready");
            println!("flood {}: {ready}", child.id());
            (child, lines)
        })
        .collect();
    std::thread::sleep(Duration::from_secs(1));
    let asked = Instant::now();
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--client", "guard"]);
    let answered = asked.elapsed();
    assert_eq!(code, Some(0), "{stderr}");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], "guard", "{latched}");
    for (mut flood, lines) in floods {
        let _ = flood.wait();
        println!(
            "flood {}: {:?}",
            flood.id(),
            lines.try_iter().collect::<Vec<_>>()
        );
    }
    let after = wait_for_status(&status, LIMIT, |_| true);
    let stops = after["stops"].as_array().cloned().unwrap_or_default();
    assert!(
        stops.iter().all(|stop| stop["cause"] != "overrun"),
        "the flood stalled the tick past the chassis' timeout: {after}"
    );
    assert!(
        after["rejections"]["rate_limited"].as_u64() > Some(0),
        "the flood was refused at its share: {after}"
    );
    println!(
        "scout estop answered in {answered:?} during the flood; tick {}",
        after["tick"]
    );
}

/// A client in another network namespace than the gateway (a container sharing its shared
/// memory, not its network) cannot reach the abstract stop socket: `scout estop` and `scout
/// release` go through the iceoryx2 stop service instead.
#[test]
fn stops_and_releases_reach_the_gateway_from_another_network_namespace() {
    let test = "stops_and_releases_reach_the_gateway_from_another_network_namespace";
    let probe = std::process::Command::new("unshare")
        .args(["-n", "true"])
        .output();
    if !probe.as_ref().is_ok_and(|o| o.status.success()) {
        return scout_system_tests::skip(test, &format!("no network namespace here ({probe:?})"));
    }
    let name = robot_name("netns");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let scout_bin = scout_system_tests::bin("scout");
    let in_netns = |args: &[&str]| {
        std::process::Command::new("unshare")
            .arg("-n")
            .arg(&scout_bin)
            .args(args)
            .args(["--name", &name])
            .output()
            .expect("unshare")
    };
    let output = in_netns(&["estop", "--reason", "from a container"]);
    assert_eq!(output.status.code(), Some(0), "{output:?}");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["reason"], "from a container");
    let output = in_netns(&["release"]);
    assert_eq!(output.status.code(), Some(0), "{output:?}");
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
}
