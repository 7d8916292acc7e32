//! CAN faults: error frames (bus-off, error-passive) read with the error filter, and a full
//! transmit queue (`ENOBUFS`, made with netem on the interface): each latches `link_fault`, the
//! streaming client loses control, and the first command after recovery is zero.

use std::process::Command;

use scout_system_tests::{
    Sim, chassis_stays_still, connect_within, drive_until_moving, release_all, wait_for_status,
};

use crate::bus::{chassis_commanded, chassis_stays_still_after_braking, start};
use crate::{Bus, LIMIT, can_utils, tc};

/// A client streams, `fault` happens, `recover` undoes it: the stop is `link_fault`, it lasts
/// until the link is healthy again, and nothing moves until a release and a new take.
pub fn fault_latches_a_link_fault(
    sim: &mut Sim,
    name: &str,
    fault: impl FnOnce(),
    recover: impl FnOnce(),
) {
    let status = connect_within(name, LIMIT).status().expect("status");
    let mut driver = drive_until_moving(
        sim,
        name,
        &["--linear", "0.5", "--client", "streamer"],
        LIMIT,
    );
    fault();
    assert_eq!(driver.wait_exit(LIMIT), Some(4), "the driver lost control");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["cause"], "link_fault", "{latched}");
    recover();
    wait_for_status(&status, LIMIT, |s| s["stops"][0]["persists"] == false);
    chassis_commanded(sim, 0.0);
    chassis_stays_still_after_braking(sim);
    release_all(name);
    chassis_stays_still(sim, std::time::Duration::from_secs(1));
}

#[test]
fn bus_off_and_error_passive_frames_latch_a_link_fault() {
    const TEST: &str = "bus_off_and_error_passive_frames_latch_a_link_fault";
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
    let (mut sim, _gateway, name) = start(&bus, "can-errors");
    error_frames_latch_link_faults(&bus, &mut sim, &name);
}

/// A bus-off, then an error-passive error frame put on `bus` with `cansend`: each latches a
/// `link_fault` ([`fault_latches_a_link_fault`]). CAN_ERR_FLAG with CAN_ERR_BUSOFF; CAN_ERR_CRTL
/// with CAN_ERR_CRTL_TX_PASSIVE in byte 1 (linux/can/error.h). cansend sends an 8-digit id with
/// the error flag as an error frame.
pub fn error_frames_latch_link_faults(bus: &Bus, sim: &mut Sim, name: &str) {
    for frame in ["20000040#0000000000000000", "20000004#0020000000000000"] {
        let send = || {
            let sent = Command::new("cansend")
                .args([bus.name(), frame])
                .status()
                .expect("cansend");
            assert!(sent.success(), "cansend {frame}");
        };
        fault_latches_a_link_fault(sim, name, send, || {});
    }
}

#[test]
fn a_full_transmit_queue_latches_a_link_fault() {
    const TEST: &str = "a_full_transmit_queue_latches_a_link_fault";
    let Some(bus) = Bus::create(TEST) else { return };
    let (mut sim, _gateway, name) = start(&bus, "can-enobufs");
    // A bus nobody acknowledges: frames wait in a queue of two, the third write gets ENOBUFS.
    // Deleting the queue drops what waits in it, as bringing an adapter back does.
    let stuck = || {
        tc(&[
            "qdisc",
            "add",
            "dev",
            bus.name(),
            "root",
            "netem",
            "delay",
            "5s",
            "limit",
            "2",
        ])
        .expect("netem on the interface");
    };
    let cleared = || tc(&["qdisc", "del", "dev", bus.name(), "root"]).expect("delete netem");
    fault_latches_a_link_fault(&mut sim, &name, stuck, cleared);
}
