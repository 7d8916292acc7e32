//! The gateway and the simulator on one virtual bus: state end to end, the 0x130 stream as the
//! chassis saw it, teleop over autonomy, an e-stop to the wire, the interface going down and
//! away, frames the gateway must refuse, a v2 chassis, and a chassis of the other protocol
//! joining the bus.

use std::time::{Duration, Instant};

use scout_protocol::can;
use scout_system_tests::{
    Driver, Gateway, Sim, chassis_stays_still, connect, connect_within, drive_until_moving,
    release_all, robot_name, scout, wait_for_state, wait_for_status,
};

use crate::{Bus, LIMIT};

/// The simulator and the gateway on `bus`, the link up, with the gateway's robot name. A start
/// whose link never comes up is reported (what each side saw) and made once more: inside the VM
/// the simulator has now and then heard nothing and answered nothing for 30 s at start (CI saw
/// it three times in two runs of this file, not in the runs around them); these tests are about
/// what comes after, and a second silent start fails.
pub fn start(bus: &Bus, test: &str) -> (Sim, Gateway, String) {
    start_with(bus, test, &["--can", bus.name()])
}

/// [`start`] with the gateway on `port` (its transport arguments), the simulator on `bus`.
pub fn start_with(bus: &Bus, test: &str, port: &[&str]) -> (Sim, Gateway, String) {
    let name = robot_name(test);
    let mut attempt = 1;
    loop {
        let mut sim = Sim::start(&["--can", bus.name()]);
        let gateway = Gateway::start(&[port, &["--name", &name]].concat());
        let state = connect_within(&name, LIMIT).subscribe().expect("subscribe");
        match link_up(&state) {
            Ok(()) => {
                // The emulated CPU can be slow enough at start-up for the gateway to latch a
                // stop of its own (a late tick, a silent chassis).
                release_all(&name);
                return (sim, gateway, name);
            }
            Err(last) => {
                let why = explain(&last, &mut sim, &gateway, bus);
                assert!(attempt < 2, "{why}");
                eprintln!("{test}: starting the simulator and the gateway again, after:\n{why}");
                attempt += 1;
            }
        }
    }
}

/// Waits for the gateway's link to be `ok`; the last state seen if it never is.
fn link_up(state: &scout_clients::client::StateSubscriber) -> Result<(), serde_json::Value> {
    let deadline = Instant::now() + LIMIT;
    let mut last = serde_json::Value::Null;
    while Instant::now() < deadline {
        if let Some(sample) = state
            .next_timeout(Duration::from_millis(200))
            .expect("receive state")
        {
            last =
                scout_clients::interface::json::state_json(&sample, scout_clients::monotonic_ns());
            if last["link"]["state"] == "ok" {
                return Ok(());
            }
        }
    }
    Err(last)
}

/// What each side saw when the link did not come up: the simulator's counters (or what its
/// process waits in), the interface's, and the gateway's log.
fn explain(last: &serde_json::Value, sim: &mut Sim, gateway: &Gateway, bus: &Bus) -> String {
    let interface = std::process::Command::new("ip")
        .args(["-s", "-d", "link", "show", "dev", bus.name()])
        .output()
        .map(|out| String::from_utf8_lossy(&out.stdout).into_owned())
        .unwrap_or_else(|error| format!("ip failed: {error}"));
    format!(
        "the gateway's link was not ok within {LIMIT:?}\n\
         last state: {last}\n\
         simulator: {}\n\
         interface: {interface}\n\
         gateway log:\n{}",
        sim.stats_or_state(),
        gateway.log()
    )
}

/// `scout resume`: arms autonomy.
fn resume(name: &str) {
    let (code, _, stderr) = scout(&["resume", "--name", name]);
    assert_eq!(code, Some(0), "{stderr}");
}

/// Waits until the simulator's last motion command has `linear` near `wanted`.
pub fn chassis_commanded(sim: &mut Sim, wanted: f64) -> serde_json::Value {
    let deadline = Instant::now() + LIMIT;
    loop {
        let stats = sim.stats();
        if stats["last_command"]["linear"]
            .as_f64()
            .is_some_and(|linear| (linear - wanted).abs() < 0.011)
        {
            return stats;
        }
        assert!(
            Instant::now() < deadline,
            "the chassis was never commanded {wanted} m/s: {stats}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn state_and_motion_end_to_end_with_valid_checksums() {
    let Some(bus) = Bus::create("state_and_motion_end_to_end_with_valid_checksums") else {
        return;
    };
    let (mut sim, _gateway, name) = start(&bus, "can-e2e");
    let robot = connect(&name);
    let state = robot.subscribe().expect("subscribe");
    let ok = wait_for_state(&state, LIMIT, |s| {
        s["link"]["state"] == "ok" && !s["system"].is_null() && !s["motors"][3].is_null()
    });
    assert_eq!(ok["link"]["transport"], "can");
    assert_eq!(ok["link"]["device"], bus.name());
    assert_eq!(ok["system"]["control_mode"], "can", "{ok}");
    let _driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.5", "--client", "driver"],
        LIMIT,
    );
    wait_for_state(&state, LIMIT, |s| {
        s["motion"]["linear"].as_f64() > Some(0.2)
    });
    let stats = sim.stats();
    let intervals = &stats["motion_command_intervals"];
    eprintln!(
        "0x130 as the simulator saw it: {} commands, mean {} ms, max {} ms, p99 {} ms",
        intervals["count"], intervals["mean_ms"], intervals["max_ms"], intervals["p99_ms"]
    );
    assert_eq!(stats["checksum_failures"], 0, "{stats}");
    assert_eq!(stats["rejected"], 0, "{stats}");
    assert!(intervals["count"].as_u64() > Some(10), "{stats}");
    // The chassis never timed out (its 500 ms): a functional bound, not a timing target.
    assert!(intervals["max_ms"].as_f64() < Some(500.0), "{stats}");
    let seen = wait_for_state(&state, LIMIT, |_| true);
    assert_eq!(seen["link"]["checksum_errors"], 0, "{seen}");
    assert_eq!(seen["link"]["rejected_frames"], 0, "{seen}");
}

#[test]
fn teleop_overrides_autonomy_and_an_estop_reaches_the_wire() {
    let Some(bus) = Bus::create("teleop_overrides_autonomy_and_an_estop_reaches_the_wire") else {
        return;
    };
    let (mut sim, _gateway, name) = start(&bus, "can-override");
    let robot = connect(&name);
    let status = robot.status().expect("status");
    resume(&name);
    let _autonomy = Driver::start(
        &name,
        &[
            "--linear", "0.3", "--class", "autonomy", "--client", "planner",
        ],
    );
    chassis_commanded(&mut sim, 0.3);
    let _teleop = Driver::start(
        &name,
        &[
            "--linear", "0.6", "--class", "teleop", "--client", "joystick",
        ],
    );
    wait_for_status(&status, LIMIT, |s| s["selected"]["client"] == "joystick");
    chassis_commanded(&mut sim, 0.6);
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--reason", "test"]);
    assert_eq!(code, Some(0), "{stderr}");
    let stopped = chassis_commanded(&mut sim, 0.0);
    assert_eq!(stopped["checksum_failures"], 0, "{stopped}");
    chassis_stays_still_after_braking(&mut sim);
}

/// The chassis brakes to rest, then stays there.
pub fn chassis_stays_still_after_braking(sim: &mut Sim) {
    let deadline = Instant::now() + LIMIT;
    while sim.stats()["actual"]["linear"] != 0.0 {
        assert!(Instant::now() < deadline, "the chassis never came to rest");
        std::thread::sleep(Duration::from_millis(50));
    }
    chassis_stays_still(sim, Duration::from_secs(1));
}

/// The interface goes away while a client streams: the client loses control, the stop latches,
/// the gateway reopens when the interface is back, and nothing moves until a release and a new
/// take.
fn lose_the_interface(
    test: &str,
    robot: &str,
    real_ok: bool,
    cut: impl Fn(&Bus),
    restore: impl Fn(&Bus),
) {
    let Some(bus) = Bus::create(test) else {
        return;
    };
    if bus.is_real() && !real_ok {
        scout_system_tests::skip(test, "needs a virtual interface (it deletes it)");
        return;
    }
    let (mut sim, _gateway, name) = start(&bus, robot);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let state = robot.subscribe().expect("state");
    let mut driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.5", "--client", "streamer"],
        LIMIT,
    );
    cut(&bus);
    assert_eq!(driver.wait_exit(LIMIT), Some(4), "the driver lost control");
    let lost = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    let cause = &lost["stops"][0]["cause"];
    assert!(
        *cause == "link_lost" || *cause == "link_fault",
        "a link stop: {lost}"
    );
    wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "disconnected");
    restore(&bus);
    let back = wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "ok");
    assert!(back["link"]["reconnects"].as_u64() >= Some(1), "{back}");
    wait_for_status(&status, LIMIT, |s| s["stops"][0]["persists"] == false);
    chassis_commanded(&mut sim, 0.0);
    chassis_stays_still_after_braking(&mut sim);
    release_all(&name);
    chassis_stays_still(&mut sim, Duration::from_secs(1));
    // A new take drives again (and a stall of the emulated CPU that latches an overrun here
    // is released and the drive started again: the release rule is what was checked above).
    let _again = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.4", "--client", "streamer-2"],
        LIMIT,
    );
}

#[test]
fn interface_down_and_up_needs_a_release() {
    lose_the_interface(
        "interface_down_and_up_needs_a_release",
        "can-down",
        true,
        |bus| bus.set_up(false).expect("set the interface down"),
        |bus| bus.set_up(true).expect("set the interface up"),
    );
}

#[test]
fn interface_deleted_and_created_again_needs_a_release() {
    lose_the_interface(
        "interface_deleted_and_created_again_needs_a_release",
        "can-unplug",
        false,
        |bus| bus.delete().expect("delete the interface"),
        |bus| bus.add().expect("create the interface again"),
    );
}

/// `cansend`'s `ID#DATA` for a frame.
pub fn cansend_text(id: u16, data: &[u8]) -> String {
    let hex: String = data.iter().map(|byte| format!("{byte:02X}")).collect();
    format!("{id:03X}#{hex}")
}

/// Sends one raw frame (standard or extended id) on `bus` from a socket of this test's own.
pub fn send_raw(bus: &Bus, frame: socketcan::CanFrame) {
    use socketcan::Socket;
    let socket = socketcan::CanSocket::open(bus.name()).expect("open the bus");
    socket.write_frame(&frame).expect("send a frame");
}

#[test]
fn garbage_and_wrong_checksum_frames_are_refused_and_counted() {
    use socketcan::{EmbeddedFrame, ExtendedId, StandardId};
    let Some(bus) = Bus::create("garbage_and_wrong_checksum_frames_are_refused_and_counted") else {
        return;
    };
    let (mut sim, _gateway, name) = start(&bus, "can-garbage");
    let state = connect(&name).subscribe().expect("state");
    wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "ok");
    // A 0x151 whose checksum is off by one, one of the wrong length, one with an id SCOUT does
    // not use, an extended id, and the simulator's own corrupted feedback.
    let mut status = can::encode(
        &scout_protocol::Message::SystemStatus(scout_protocol::message::SystemStatus {
            state: scout_protocol::message::ChassisState::Normal,
            control_mode: scout_protocol::message::ControlMode::Can,
            battery_decivolts: 250,
            faults: scout_protocol::fault::FaultBits(0),
        }),
        0,
    )
    .data()
    .to_vec();
    status[7] = status[7].wrapping_add(1);
    let standard = |id: u16, data: &[u8]| {
        socketcan::CanFrame::new(StandardId::new(id).expect("id"), data).expect("frame")
    };
    send_raw(&bus, standard(0x151, &status));
    send_raw(&bus, standard(0x151, &[0; 3]));
    send_raw(&bus, standard(0x123, &[1, 2, 3]));
    send_raw(
        &bus,
        socketcan::CanFrame::new(ExtendedId::new(0x151).expect("id"), &[0; 8]).expect("frame"),
    );
    sim.send("corrupt 3");
    let counted = wait_for_state(&state, LIMIT, |s| {
        s["link"]["checksum_errors"].as_u64() >= Some(4)
            && s["link"]["rejected_frames"].as_u64() >= Some(3)
    });
    assert_eq!(counted["link"]["state"], "ok", "{counted}");
    let later = wait_for_state(&state, LIMIT, |s| {
        s["seq"].as_u64() > counted["seq"].as_u64().map(|seq| seq + 10)
    });
    assert_eq!(
        later["link"]["state"], "ok",
        "refused frames do not cut the link: {later}"
    );
    assert_eq!(
        later["system"]["battery_voltage"].as_f64().map(f64::round),
        Some(26.0)
    );
}

#[test]
fn a_v2_scout_mini_is_told_taken_driven_stopped_and_left_in_standby() {
    let Some(bus) = Bus::create("a_v2_scout_mini_is_told_taken_driven_stopped_and_left_in_standby")
    else {
        return;
    };
    let name = robot_name("can-v2");
    let mut sim = Sim::start(&[
        "--can",
        bus.name(),
        "--protocol",
        "v2",
        "--model",
        "scout-mini",
    ]);
    let mut gateway = Gateway::start(&[
        "--can",
        bus.name(),
        "--name",
        &name,
        "--model",
        "scout-mini",
    ]);
    let state = connect_within(&name, LIMIT).subscribe().expect("subscribe");
    let told = wait_for_state(&state, LIMIT, |s| {
        s["link"]["state"] == "ok" && !s["system"].is_null()
    });
    assert_eq!(told["link"]["protocol"], "v2", "{told}");
    assert_eq!(told["system"]["control_mode"], "standby", "{told}");
    release_all(&name);
    assert!(
        sim.stats()["commands"]["0x421"].is_null(),
        "nothing takes the chassis before a client drives"
    );
    let _driver = drive_until_moving(&mut sim, &name, &["--linear", "0.5"], LIMIT);
    let stats = sim.stats();
    assert_eq!(stats["control_mode"], "can", "{stats}");
    let intervals = &stats["motion_command_intervals"];
    eprintln!(
        "0x111 as the simulator saw it: {} commands, mean {} ms, max {} ms, p99 {} ms",
        intervals["count"], intervals["mean_ms"], intervals["max_ms"], intervals["p99_ms"]
    );
    wait_for_state(&state, LIMIT, |s| {
        s["odometer"]["left"].as_f64() > Some(0.1) && s["motion"]["linear"].as_f64() > Some(0.2)
    });
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--reason", "test"]);
    assert_eq!(code, Some(0), "{stderr}");
    chassis_commanded(&mut sim, 0.0);
    chassis_stays_still_after_braking(&mut sim);
    gateway.signal(nix::sys::signal::Signal::SIGTERM);
    assert_eq!(gateway.wait_exit(LIMIT), Some(0));
    assert_eq!(sim.stats()["control_mode"], "standby", "standby on exit");
}

#[test]
fn a_chassis_of_the_other_protocol_joining_the_bus_while_driving_stops_the_robot() {
    let Some(bus) = Bus::create("a_chassis_of_the_other_protocol_joining_the_bus") else {
        return;
    };
    let name = robot_name("can-both");
    let mut sim = Sim::start(&["--can", bus.name(), "--protocol", "v2"]);
    let _gateway = Gateway::start(&["--can", bus.name(), "--name", &name]);
    let robot = connect_within(&name, LIMIT);
    let state = robot.subscribe().expect("subscribe");
    let status = robot.status().expect("status");
    let told = wait_for_state(&state, LIMIT, |s| {
        s["link"]["state"] == "ok" && !s["system"].is_null()
    });
    assert_eq!(told["link"]["protocol"], "v2", "{told}");
    release_all(&name);
    let _driver = drive_until_moving(&mut sim, &name, &["--linear", "0.5"], LIMIT);
    // A v1 chassis is switched on on the same bus.
    let _other = Sim::start(&["--can", bus.name()]);
    chassis_commanded(&mut sim, 0.0);
    let mismatch = wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "protocol_mismatch");
    assert_eq!(mismatch["link"]["protocol"], "v2", "{mismatch}");
    let status = wait_for_status(&status, LIMIT, |s| {
        s["stops"]
            .as_array()
            .is_some_and(|stops| stops.iter().any(|stop| stop["cause"] == "chassis_silent"))
    });
    assert!(
        status.to_string().contains("both protocols"),
        "the stop says why: {status}"
    );
    chassis_stays_still_after_braking(&mut sim);
}
