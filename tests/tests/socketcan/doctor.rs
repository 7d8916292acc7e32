//! `scout doctor --can` on a virtual bus: the simulator on it (passes), the interface down, no
//! other node on the bus, and a bus-off error frame while it listens.

use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use scout_system_tests::{Sim, doctor_check as check, robot_name};
use serde_json::Value;

use crate::{Bus, can_utils};

/// `scout doctor --can IFACE --json`: the exit code and the checks.
fn doctor(interface: &str) -> (Option<i32>, Vec<Value>) {
    let name = robot_name("doctor-can");
    scout_system_tests::doctor(&["--name", &name, "--can", interface, "--listen", "2"])
}

#[test]
fn doctor_on_a_bus_with_the_chassis_passes() {
    const TEST: &str = "doctor_on_a_bus_with_the_chassis_passes";
    let Some(bus) = Bus::create(TEST) else { return };
    let mut sim = Sim::start(&["--can", bus.name()]);
    sim.wait_sending();
    let (code, checks) = doctor(bus.name());
    assert_eq!(
        code,
        Some(0),
        "{checks:#?}\nthe simulator now: {}",
        sim.stats_or_state()
    );
    for name in [
        "can.interface",
        "can.up",
        "port",
        "traffic",
        "protocol",
        "chassis.estop",
    ] {
        assert_eq!(
            check(&checks, name)["verdict"],
            "pass",
            "{name}: {checks:#?}"
        );
    }
}

#[test]
fn doctor_on_a_bus_that_is_down_or_has_no_other_node_fails_with_the_fix() {
    const TEST: &str = "doctor_on_a_bus_that_is_down_or_has_no_other_node_fails_with_the_fix";
    let Some(bus) = Bus::create(TEST) else { return };
    if bus.is_real() {
        scout_system_tests::skip(TEST, "a real interface is not set down by a test");
        return;
    }

    // Up, and nobody on it.
    let (code, checks) = doctor(bus.name());
    assert_eq!(code, Some(1), "{checks:#?}");
    let traffic = check(&checks, "traffic");
    assert_eq!(traffic["verdict"], "fail", "{checks:#?}");
    assert!(
        traffic["fix"]
            .as_str()
            .is_some_and(|f| f.contains("500 kbit/s")),
        "{traffic}"
    );

    // Down: said so with the commands that bring it up, and the port is not listened to.
    bus.set_up(false).expect("ip link set down");
    let (code, checks) = doctor(bus.name());
    assert_eq!(code, Some(1), "{checks:#?}");
    let up = check(&checks, "can.up");
    assert_eq!(up["verdict"], "fail", "{checks:#?}");
    assert!(
        up["fix"]
            .as_str()
            .is_some_and(|f| f.contains(&format!("ip link set {} up", bus.name()))),
        "{up}"
    );
}

#[test]
fn doctor_names_a_bus_off_it_hears() {
    const TEST: &str = "doctor_names_a_bus_off_it_hears";
    let Some(bus) = Bus::create(TEST) else { return };
    if !can_utils(TEST) {
        return;
    }
    if bus.is_real() {
        scout_system_tests::skip(
            TEST,
            "error frames come from a real controller, not cansend",
        );
        return;
    }
    let _sim = Sim::start(&["--can", bus.name()]);
    let interface = bus.name().to_owned();
    // CAN_ERR_FLAG with CAN_ERR_BUSOFF (linux/can/error.h), every 200 ms while the doctor runs
    // (the emulated CPU makes its start slow and uneven).
    let running = Arc::new(AtomicBool::new(true));
    let injecting = Arc::clone(&running);
    let injector = std::thread::spawn(move || {
        let mut sent = 0;
        while injecting.load(Ordering::Relaxed) {
            let status = Command::new("cansend")
                .args([&interface, "20000040#0000000000000000"])
                .status()
                .expect("cansend");
            assert!(status.success(), "cansend");
            sent += 1;
            std::thread::sleep(Duration::from_millis(200));
        }
        sent
    });
    let (code, checks) = doctor(bus.name());
    running.store(false, Ordering::Relaxed);
    assert!(injector.join().expect("injector") > 0);
    assert_eq!(code, Some(1), "{checks:#?}");
    let read = check(&checks, "port.read");
    assert_eq!(read["verdict"], "fail", "{checks:#?}");
    assert!(
        read["detail"]
            .as_str()
            .is_some_and(|d| d.contains("bus-off")),
        "{read}"
    );
}

#[test]
fn doctor_on_a_bus_with_a_v2_chassis_names_it_and_what_to_do() {
    const TEST: &str = "doctor_on_a_bus_with_a_v2_chassis_names_it_and_what_to_do";
    let Some(bus) = Bus::create(TEST) else { return };
    let mut sim = Sim::start(&[
        "--can",
        bus.name(),
        "--protocol",
        "v2",
        "--model",
        "scout-mini",
    ]);
    sim.wait_sending();
    let (_, checks) = doctor(bus.name());
    assert_eq!(
        check(&checks, "traffic")["verdict"],
        "pass",
        "{checks:#?}\nthe simulator now: {}",
        sim.stats_or_state()
    );
    let protocol = check(&checks, "protocol");
    assert_eq!(protocol["verdict"], "pass", "{checks:#?}");
    assert!(
        protocol["detail"]
            .as_str()
            .is_some_and(|d| d.contains("--protocol v2")),
        "{protocol}"
    );
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
}
