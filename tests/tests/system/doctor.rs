//! `scout doctor` against real set-ups: the simulator with and without a gateway, a
//! pseudo-terminal nobody writes to, garbage at the wrong baud rate, a chassis speaking protocol
//! v2 behind an slcan adapter, the simulator's e-stop and RC, a port another robot's gateway
//! holds. (SocketCAN: `tests/tests/socketcan/doctor.rs`, in the VM.)

use std::io::Write;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use scout_system_tests::{
    Gateway, Sim, command, connect, doctor_check as check, free_port, robot_name, run_with_input,
    tcp, wait_for_state,
};
use serde_json::Value;
use serialport::{SerialPort, TTYPort};

/// `scout doctor ARGS --json`, listening 1.5 s: the exit code and the checks.
fn doctor(args: &[&str]) -> (Option<i32>, Vec<Value>) {
    let args: Vec<&str> = args.iter().copied().chain(["--listen", "1.5"]).collect();
    scout_system_tests::doctor(&args)
}

fn verdict<'a>(checks: &'a [Value], name: &str) -> &'a str {
    check(checks, name)["verdict"].as_str().expect("a verdict")
}

fn fix<'a>(checks: &'a [Value], name: &str) -> &'a str {
    check(checks, name)["fix"].as_str().unwrap_or("")
}

fn none_failed(checks: &[Value]) -> bool {
    checks.iter().all(|c| c["verdict"] != "fail")
}

#[test]
fn the_simulator_behind_a_gateway_passes_and_its_port_is_checked_through_the_gateway() {
    let name = robot_name("doctor-gw");
    let sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    connect(&name);

    let (code, checks) = doctor(&["--name", &name]);
    assert_eq!(code, Some(0), "{checks:#?}");
    assert!(none_failed(&checks), "{checks:#?}");
    for name in [
        "gateway",
        "link",
        "traffic",
        "errors",
        "chassis.estop",
        "chassis.control",
    ] {
        assert_eq!(verdict(&checks, name), "pass", "{name}: {checks:#?}");
    }
    // A host stall the gateway really had (an `overrun` it latched, on a loaded machine) makes
    // the stops check warn, and says so: that is the gateway doing its job.
    let stops = check(&checks, "stops");
    assert!(
        stops["verdict"] == "pass"
            || (stops["verdict"] == "warn"
                && stops["detail"]
                    .as_str()
                    .is_some_and(|d| d.contains("overrun"))),
        "{checks:#?}"
    );
    let gateway_pid = format!("(pid {})", gateway.pid());
    assert!(
        check(&checks, "gateway")["detail"]
            .as_str()
            .is_some_and(|d| d.contains(&gateway_pid)),
        "which process: {checks:#?}"
    );

    // The same port named: never opened twice, asked of the gateway that holds it.
    let (code, checks) = doctor(&["--name", &name, "--serial", &device]);
    assert_eq!(code, Some(0), "{checks:#?}");
    let port = check(&checks, "port");
    assert_eq!(port["verdict"], "pass");
    assert!(
        port["detail"]
            .as_str()
            .is_some_and(|d| d.contains("held by the gateway")),
        "{port}"
    );
    assert_eq!(verdict(&checks, "traffic"), "pass");
}

#[test]
fn the_simulator_without_a_gateway_passes_its_port_checks_and_names_the_gateway_to_start() {
    let name = robot_name("doctor-port");
    let sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let (code, checks) = doctor(&["--name", &name, "--serial", &device]);
    assert_eq!(code, Some(0), "{checks:#?}");
    for name in [
        "device",
        "port",
        "traffic",
        "protocol",
        "errors",
        "other-host",
        "chassis.estop",
        "chassis.control",
        "chassis.faults",
        "chassis.battery",
    ] {
        assert_eq!(verdict(&checks, name), "pass", "{name}: {checks:#?}");
    }
    assert_eq!(verdict(&checks, "gateway"), "warn");
    assert!(
        fix(&checks, "gateway").contains(&format!("scout-gateway --serial {device}")),
        "{checks:#?}"
    );

    // Nothing to check and no gateway: a failure that says what to give.
    let (code, checks) = doctor(&["--name", &name]);
    assert_eq!(code, Some(1), "{checks:#?}");
    assert_eq!(verdict(&checks, "gateway"), "fail");
    assert!(fix(&checks, "gateway").contains("--serial"), "{checks:#?}");
}

#[test]
fn a_missing_device_fails_with_where_to_look() {
    let (code, checks) = doctor(&[
        "--name",
        &robot_name("doctor-none"),
        "--serial",
        "/dev/nonexistent-scout-tty",
    ]);
    assert_eq!(code, Some(1), "{checks:#?}");
    assert_eq!(verdict(&checks, "device"), "fail");
    assert!(
        fix(&checks, "device").contains("/dev/serial/by-id"),
        "{checks:#?}"
    );
}

/// A pseudo-terminal whose other end a thread of the test writes `line` to every 20 ms (nothing
/// when `line` is empty).
struct Pty {
    _master_side: TTYPort,
    path: String,
    stop: Arc<AtomicBool>,
    writer: Option<JoinHandle<()>>,
}

impl Pty {
    fn new(line: fn(u32) -> Vec<u8>) -> Pty {
        let (master, slave) = TTYPort::pair().expect("a pseudo-terminal");
        let path = slave.name().expect("pty path");
        // The slave end stays open in this process, so the master never sees a hang-up.
        let stop = Arc::new(AtomicBool::new(false));
        let writing = Arc::clone(&stop);
        let mut out = master.try_clone_native().expect("clone the master");
        // A full pty (nobody reads after the doctor exits) times a write out instead of blocking.
        out.set_timeout(Duration::from_millis(50)).expect("timeout");
        let writer = std::thread::spawn(move || {
            let _slave = slave;
            let mut n = 0;
            while !writing.load(Ordering::Relaxed) {
                let bytes = line(n);
                if !bytes.is_empty() {
                    let _ = out.write_all(&bytes);
                }
                n += 1;
                std::thread::sleep(Duration::from_millis(20));
            }
        });
        Pty {
            _master_side: master,
            path,
            stop,
            writer: Some(writer),
        }
    }
}

impl Drop for Pty {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(writer) = self.writer.take() {
            let _ = writer.join();
        }
    }
}

#[test]
fn a_port_nobody_writes_to_fails_with_what_to_check() {
    let pty = Pty::new(|_| Vec::new());
    let (code, checks) = doctor(&["--name", &robot_name("doctor-quiet"), "--serial", &pty.path]);
    assert_eq!(code, Some(1), "{checks:#?}");
    assert_eq!(verdict(&checks, "device"), "pass");
    assert_eq!(verdict(&checks, "port"), "pass");
    let traffic = check(&checks, "traffic");
    assert_eq!(traffic["verdict"], "fail");
    assert!(
        traffic["detail"]
            .as_str()
            .is_some_and(|d| d.contains("nothing received")),
        "{traffic}"
    );
    assert!(fix(&checks, "traffic").contains("115200"), "{checks:#?}");
}

#[test]
fn garbage_at_the_wrong_baud_rate_fails_as_such() {
    // What 115200 8N1 frames look like read at another rate: bytes, never a whole frame.
    let pty = Pty::new(|n| {
        (0..26_u32)
            .map(|i| ((n * 31 + i * 17) % 251) as u8 | 0x80)
            .collect()
    });
    let (code, checks) = doctor(&["--name", &robot_name("doctor-baud"), "--serial", &pty.path]);
    assert_eq!(code, Some(1), "{checks:#?}");
    let traffic = check(&checks, "traffic");
    assert_eq!(traffic["verdict"], "fail", "{checks:#?}");
    assert!(fix(&checks, "traffic").contains("baud"), "{checks:#?}");
}

#[test]
fn a_protocol_v2_chassis_behind_slcan_is_named_with_what_to_do() {
    // The simulator's SCOUT 2.0 at power-on: standby until the host sends 0x421.
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "scout2"]);
    let device = sim.port().to_owned();
    let (code, checks) = doctor(&["--name", &robot_name("doctor-v2"), "--slcan", &device]);
    assert_eq!(
        code,
        Some(0),
        "a v2 chassis at power-on is ready: {checks:#?}"
    );
    assert_eq!(
        verdict(&checks, "traffic"),
        "pass",
        "v2 frames are valid: {checks:#?}"
    );
    let protocol = check(&checks, "protocol");
    assert_eq!(protocol["verdict"], "pass", "{checks:#?}");
    let detail = protocol["detail"].as_str().unwrap_or_default();
    assert!(
        detail.contains("0x221") && detail.contains("--protocol v2"),
        "{protocol}"
    );
    assert_eq!(verdict(&checks, "errors"), "pass", "{checks:#?}");
    let control = check(&checks, "chassis.control");
    assert_eq!(
        control["verdict"], "pass",
        "standby until 0x421: {checks:#?}"
    );
    assert!(
        control["detail"]
            .as_str()
            .is_some_and(|d| d.contains("421#01")),
        "{control}"
    );
    assert_eq!(
        verdict(&checks, "chassis.rc"),
        "skip",
        "the transmitter is off"
    );
    assert_eq!(verdict(&checks, "chassis.estop"), "pass");

    // The RC in manual, the e-stop pressed: each named with what to do.
    sim.send("rc on");
    sim.send("estop on");
    let (_, checks) = doctor(&["--name", &robot_name("doctor-v2"), "--slcan", &device]);
    assert_eq!(verdict(&checks, "chassis.estop"), "fail", "{checks:#?}");
    assert!(fix(&checks, "chassis.estop").contains("SWA"), "{checks:#?}");
    assert_eq!(verdict(&checks, "chassis.control"), "warn", "{checks:#?}");
    assert!(
        fix(&checks, "chassis.control").contains("SWB up"),
        "{checks:#?}"
    );
    assert_eq!(verdict(&checks, "chassis.rc"), "warn", "{checks:#?}");

    // The same through a gateway that drives it (protocol v2, told by its frames).
    let name = robot_name("doctor-v2-gw");
    let _gateway = Gateway::start(&["--slcan", &device, "--name", &name]);
    let states = connect(&name).subscribe().expect("subscribe");
    wait_for_state(&states, Duration::from_secs(10), |s| {
        s["link"]["protocol"] == "v2" && !s["system"].is_null()
    });
    let (_, checks) = doctor(&["--name", &name]);
    assert_eq!(verdict(&checks, "link"), "pass", "{checks:#?}");
    assert_eq!(verdict(&checks, "chassis.estop"), "fail", "{checks:#?}");
    assert_eq!(verdict(&checks, "chassis.rc"), "warn", "{checks:#?}");
    assert!(
        fix(&checks, "chassis.control").contains("SWB up"),
        "{checks:#?}"
    );
}

#[test]
fn the_chassis_estop_and_the_rc_are_named_with_their_fixes_on_the_port_and_through_the_gateway() {
    let name = robot_name("doctor-estop");
    let mut sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    sim.send("estop on");
    sim.send("rc on");
    let (code, checks) = doctor(&["--name", &name, "--serial", &device]);
    assert_eq!(code, Some(1), "{checks:#?}");
    assert_eq!(verdict(&checks, "chassis.estop"), "fail", "{checks:#?}");
    assert!(
        fix(&checks, "chassis.estop").contains("e-stop"),
        "{checks:#?}"
    );
    assert_eq!(verdict(&checks, "chassis.control"), "warn", "{checks:#?}");
    assert!(
        fix(&checks, "chassis.control").contains("RC"),
        "{checks:#?}"
    );

    // Through a gateway: the same, and the stop the chassis' e-stop latched.
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    connect(&name);
    let (code, checks) = doctor(&["--name", &name]);
    assert_eq!(code, Some(1), "{checks:#?}");
    assert_eq!(verdict(&checks, "chassis.estop"), "fail", "{checks:#?}");
    assert_eq!(verdict(&checks, "chassis.control"), "warn", "{checks:#?}");
    let stops = check(&checks, "stops");
    assert_eq!(stops["verdict"], "warn", "{checks:#?}");
    assert!(
        stops["detail"]
            .as_str()
            .is_some_and(|d| d.contains("chassis_estop")),
        "{stops}"
    );
}

#[test]
fn a_port_another_robots_gateway_holds_is_named_with_its_pid() {
    let name = robot_name("doctor-held");
    let sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    connect(&name);
    let other = robot_name("doctor-other");
    let (code, checks) = doctor(&["--name", &other, "--serial", &device]);
    assert_eq!(code, Some(1), "{checks:#?}");
    let port = check(&checks, "port");
    assert_eq!(port["verdict"], "fail", "{checks:#?}");
    let detail = port["detail"].as_str().expect("detail");
    assert!(
        detail.contains("held by another scout-gateway")
            && detail.contains(&gateway.pid().to_string()),
        "{detail}"
    );
}

/// A gateway of another run directory takes no lock the doctor sees: the port's exclusive open
/// is refused, and the doctor names the gateway holding it (it said "gone: plug it in").
#[test]
fn a_port_a_gateway_of_another_run_directory_holds_is_named_with_its_robot() {
    let name = robot_name("doctor-rundir");
    let sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let run_dir = scout_system_tests::TempDir::new(&name);
    let gateway = Gateway::start_in(run_dir.path(), &["--serial", &device, "--name", &name]);
    connect(&name);
    let other = robot_name("doctor-rundir-other");
    let (code, checks) = doctor(&["--name", &other, "--serial", &device]);
    assert_eq!(code, Some(1), "{checks:#?}");
    assert_eq!(verdict(&checks, "port"), "fail", "{checks:#?}");
    let fix = fix(&checks, "port");
    assert!(
        fix.contains(&format!("pid {}, robot {name}", gateway.pid())) && !fix.contains("plug"),
        "{fix}"
    );
}

#[test]
fn usage_errors_exit_2() {
    let mut doctor = command("scout");
    doctor.args(["doctor", "--serial", "/dev/a", "--can", "can0"]);
    let output = run_with_input(doctor, b"", Duration::from_secs(30));
    assert_eq!(output.status.code(), Some(2));
    let mut doctor = command("scout");
    doctor.args(["doctor", "--listen", "0"]);
    let output = run_with_input(doctor, b"", Duration::from_secs(30));
    assert_eq!(output.status.code(), Some(2));
}

#[test]
fn doctor_reads_the_robot_through_zenoh_when_asked() {
    let name = robot_name("doctor-zenoh");
    let port = free_port();
    let _gateway = Gateway::start(&["--sim", "--name", &name, "--zenoh-listen", &tcp(port)]);
    connect(&name);
    let (code, checks) = doctor(&["--name", &name, "--zenoh", &tcp(port)]);
    assert_eq!(code, Some(0), "{checks:#?}");
    assert_eq!(verdict(&checks, "zenoh"), "pass", "{checks:#?}");
    // Which kind of link it is: loopback, this host only.
    let security = check(&checks, "zenoh.security");
    assert_eq!(security["verdict"], "pass", "{checks:#?}");
    assert!(
        (security["detail"].as_str()).is_some_and(|d| d.contains("this host only")),
        "{security}"
    );
    // The link, measured as a remote peer meets it.
    let link = check(&checks, "zenoh.link");
    assert_eq!(link["verdict"], "pass", "{checks:#?}");
    let detail = link["detail"].as_str().unwrap_or_default();
    assert!(
        detail.contains("20 of 20 queries answered") && detail.contains("remote commands off"),
        "{link}"
    );
    // One host, one clock: the offset is zero, within what the doctor says it may be off.
    let number = |after: &str| -> f64 {
        let rest = &detail[detail.find(after).expect(after) + after.len()..];
        let end = rest.find(' ').unwrap_or(rest.len());
        rest[..end].parse().expect("a number")
    };
    let (offset, within) = (number("clock offset "), number("(within "));
    assert!(offset.abs() <= within, "{link}");

    // Another robot's name at the same endpoint: reached, but no state.
    let other = robot_name("doctor-zenoh-other");
    let (_, checks) = doctor(&["--name", &other, "--zenoh", &tcp(port)]);
    let zenoh = check(&checks, "zenoh");
    assert_eq!(zenoh["verdict"], "fail", "{checks:#?}");
    assert!(
        zenoh["detail"]
            .as_str()
            .is_some_and(|d| d.contains("no state")),
        "{zenoh}"
    );

    // Nobody listening there.
    let (code, checks) = doctor(&["--name", &name, "--zenoh", &tcp(free_port())]);
    assert_eq!(code, Some(1), "{checks:#?}");
    assert_eq!(verdict(&checks, "zenoh"), "fail", "{checks:#?}");
}

/// A gateway started and SIGKILLed: what `scout doctor --name` then says of iceoryx2. Both run
/// in an iceoryx2 domain of their own: any other test's client connecting meanwhile would
/// remove what the killed gateway left (CI saw five tries in a row lose that race).
#[test]
fn what_a_killed_gateway_left_in_shared_memory_is_removed_and_named() {
    let name = robot_name("doctor-leftovers");
    let domain = scout_system_tests::IpcDomain::new(&name);
    let ipc_dir = domain.env().1.to_string_lossy().into_owned();
    let mut gateway =
        Gateway::start_with_env(&["--sim", "--name", &name], &[("SCOUT_IPC_DIR", &ipc_dir)]);
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while !gateway.log().contains("silent -> ok") {
        assert!(
            std::time::Instant::now() < deadline,
            "the gateway never drove the simulator: {}",
            gateway.log()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    gateway.signal(nix::sys::signal::Signal::SIGKILL);
    assert_eq!(gateway.wait_exit(Duration::from_secs(10)), None, "killed");
    let doctor_here = || scout_system_tests::doctor_in(Some(&domain), &["--name", &name]);
    let (_, checks) = doctor_here();
    let leftovers = check(&checks, "iceoryx2").clone();
    assert_eq!(leftovers["verdict"], "warn", "{leftovers}");
    let detail = leftovers["detail"].as_str().unwrap_or_default();
    assert!(
        detail.contains(&format!("the gateway of robot {name}")),
        "{leftovers}"
    );
    let (_, again) = doctor_here();
    assert_eq!(
        check(&again, "iceoryx2")["verdict"],
        "pass",
        "removed: {again:#?}"
    );
}
