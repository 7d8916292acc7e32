//! Tests of the chassis with protocol v2 firmware, on a simulated clock.

use std::time::Duration;

use scout_protocol::model::Model;
use scout_protocol::v2::{
    BmsV2, BrakeV2, ControlModeV2, ErrorClearV2, MessageV2, MotionV2, SwitchPosition,
    VersionRequestForm,
};
use scout_protocol::{ChassisState, Transport};

use crate::chassis::{Chassis, Feedback, Ignored, Injection, Protection, SimParams};

const fn ms(millis: u64) -> Duration {
    Duration::from_millis(millis)
}

fn chassis(model: Model) -> Chassis {
    Chassis::new(SimParams::for_model(model), Transport::Can).with_protocol_v2()
}

fn go(linear: f64, angular: f64) -> MessageV2 {
    MessageV2::MotionCommand(MotionV2::from_si(linear, angular))
}

const TAKE: MessageV2 = MessageV2::ControlMode(ControlModeV2::Can);

/// Sends `command` every 20 ms from `from` for `duration`, collecting the feedback frames.
fn drive(
    chassis: &mut Chassis,
    command: MessageV2,
    from: Duration,
    duration: Duration,
) -> (Duration, Vec<MessageV2>) {
    let mut now = from;
    let mut frames = Vec::new();
    while now < from + duration {
        chassis.handle_v2(now, command);
        if let Some(feedback) = chassis.poll_feedback(now) {
            frames.extend(feedback.v2().expect("v2 frames"));
        }
        now += ms(20);
    }
    (now, frames)
}

fn system_states(frames: &[MessageV2]) -> Vec<scout_protocol::v2::SystemStateV2> {
    frames
        .iter()
        .filter_map(|frame| match frame {
            MessageV2::SystemState(state) => Some(*state),
            _ => None,
        })
        .collect()
}

#[test]
fn standby_at_power_on_obeys_nothing_but_0x421() {
    let mut chassis = chassis(Model::Scout2);
    assert_eq!(
        chassis.handle_v2(ms(0), go(0.5, 0.0)),
        Some(Ignored::NotCommandMode)
    );
    assert_eq!(chassis.target_at(ms(0)).linear, 0.0);
    assert_eq!(chassis.stats().control_mode, "standby");
    assert_eq!(chassis.stats().ignored.standby, 1);
    assert_eq!(chassis.handle_v2(ms(10), TAKE), None);
    assert_eq!(chassis.stats().control_mode, "can");
    assert_eq!(chassis.handle_v2(ms(20), go(0.5, 0.0)), None);
    assert_eq!(chassis.target_at(ms(20)).linear, 0.5);
    // The same 500 ms timeout as v1.
    assert_eq!(chassis.target_at(ms(519)).linear, 0.5);
    assert_eq!(chassis.target_at(ms(520)).linear, 0.0);
    assert_eq!(chassis.stats().commands["0x421"], 1);
    assert_eq!(chassis.stats().commands["0x111"], 2);
}

#[test]
fn the_rc_takes_the_mode_ignores_0x421_and_leaves_the_chassis_in_standby() {
    let mut chassis = chassis(Model::Scout2);
    chassis.handle_v2(ms(0), TAKE);
    chassis.inject(ms(10), Injection::Rc(true));
    assert_eq!(chassis.stats().control_mode, "rc");
    assert_eq!(chassis.handle_v2(ms(20), go(0.5, 0.0)), Some(Ignored::Rc));
    chassis.handle_v2(ms(30), TAKE);
    assert_eq!(
        chassis.stats().control_mode,
        "rc",
        "0x421 does not fight the RC"
    );
    chassis.inject(ms(40), Injection::Rc(false));
    assert_eq!(chassis.stats().control_mode, "standby");
    assert_eq!(
        chassis.handle_v2(ms(50), go(0.5, 0.0)),
        Some(Ignored::NotCommandMode),
        "the host must take control again"
    );
    chassis.handle_v2(ms(60), TAKE);
    assert_eq!(chassis.handle_v2(ms(70), go(0.5, 0.0)), None);
}

#[test]
fn feedback_is_v2_frames_with_the_system_state_every_100_ms() {
    let mut chassis = chassis(Model::Scout2);
    chassis.handle_v2(ms(0), TAKE);
    chassis.inject(ms(0), Injection::Rc(false));
    chassis.handle_v2(ms(0), TAKE);
    let (_, frames) = drive(&mut chassis, go(0.5, 0.0), ms(0), ms(1000));
    let count = |id: u16| frames.iter().filter(|f| f.can_id() == id).count();
    assert_eq!(count(0x221), 50, "motion state every 20 ms");
    for id in [
        0x251, 0x252, 0x253, 0x254, 0x261, 0x262, 0x263, 0x264, 0x231, 0x311,
    ] {
        assert_eq!(count(id), 50, "0x{id:03X}");
    }
    let states = system_states(&frames);
    assert_eq!(states.len(), 10, "0x211 every 100 ms");
    assert!(
        states
            .windows(2)
            .all(|w| w[1].count == w[0].count.wrapping_add(1))
    );
    assert_eq!(states[9].control_mode, ControlModeV2::Can);
    let volts = states[9].battery_voltage();
    assert!(
        (25.5..26.0).contains(&volts),
        "26.0 V at rest, sagging under load: {volts}"
    );
    assert_eq!(count(0x241), 0, "no RC frames with the transmitter off");
    // Every frame the chassis sends decodes as itself.
    for frame in &frames {
        assert_eq!(scout_protocol::v2::decode(&frame.encode()), Ok(*frame));
    }
}

#[test]
fn the_odometers_count_each_side_in_mm() {
    let mut chassis = chassis(Model::Scout2);
    chassis.handle_v2(ms(0), TAKE);
    let (now, _) = drive(&mut chassis, go(0.5, 0.0), ms(0), ms(3000));
    let (_, frames) = drive(&mut chassis, go(0.0, 0.2), now, ms(20));
    let odometer = frames
        .iter()
        .find_map(|f| match f {
            MessageV2::Odometer(o) => Some(*o),
            _ => None,
        })
        .expect("0x311");
    let pose = chassis.pose();
    assert!(odometer.left_mm > 1000, "{odometer:?}");
    assert!(
        (odometer.left_mm - odometer.right_mm).abs() <= 2,
        "straight: {odometer:?}"
    );
    assert!(
        (f64::from(odometer.left_mm) / 1000.0 - pose.x).abs() < 0.01,
        "{odometer:?} against the ground truth {pose:?}"
    );
}

#[test]
fn a_tracer_or_a_bunker_reports_two_actuators() {
    for model in [Model::Tracer, Model::Bunker, Model::Scout2] {
        let mut chassis = chassis(model);
        chassis.handle_v2(ms(0), TAKE);
        let (_, frames) = drive(&mut chassis, go(0.5, 0.3), ms(0), ms(200));
        let reported = |ids: std::ops::RangeInclusive<u16>| {
            ids.filter(|id| frames.iter().any(|f| f.can_id() == *id))
                .count()
        };
        let actuators = usize::from(model.actuators());
        assert_eq!(reported(0x251..=0x258), actuators, "{model}: high speed");
        assert_eq!(reported(0x261..=0x268), actuators, "{model}: low speed");
    }
}

#[test]
fn a_hunter_steers_by_its_wheels_angle_and_reports_it() {
    let mut chassis = chassis(Model::Hunter2);
    chassis.handle_v2(ms(0), TAKE);
    chassis.handle_v2(ms(0), MessageV2::Brake(BrakeV2::Released));
    // A yaw rate in the yaw-rate field turns nothing; the steering field turns the wheels.
    let (now, _) = drive(&mut chassis, go(0.5, 0.5), ms(0), ms(1000));
    assert_eq!(chassis.stats().steering, 0.0);
    assert!(
        chassis.actual().angular.abs() < 1e-12,
        "{:?}",
        chassis.actual()
    );
    let steer = MessageV2::MotionCommand(MotionV2::from_si(0.5, 0.0).with_steering(0.3));
    // The wheels turn at 1 rad/s: 0.3 rad takes 300 ms.
    let (now, _) = drive(&mut chassis, steer, now, ms(100));
    let turning = chassis.stats().steering;
    assert!((0.05..0.15).contains(&turning), "{turning}");
    let (_, frames) = drive(&mut chassis, steer, now, ms(1000));
    let steering = Model::Hunter2.steering().expect("steered");
    assert!((chassis.stats().steering - 0.3).abs() < 1e-9);
    let yaw = steering.yaw_rate_from_inner(chassis.actual().linear, 0.3);
    assert!((chassis.actual().angular - yaw).abs() < 1e-9 && yaw > 0.1);
    let motion = frames
        .iter()
        .rev()
        .find_map(|f| match f {
            MessageV2::MotionState(m) => Some(*m),
            _ => None,
        })
        .expect("0x221");
    assert_eq!((motion.angular_mrad_s, motion.steering_mrad), (0, 300));
    // Never beyond its widest angle.
    let wide = MessageV2::MotionCommand(MotionV2::from_si(0.5, 0.0).with_steering(-1.5));
    drive(&mut chassis, wide, ms(3000), ms(2000));
    assert_eq!(chassis.stats().steering, -steering.max_inner);
}

/// The brake reported by 0x211 byte 6, from the frames of a drive.
fn brake_reported(frames: &[MessageV2]) -> Option<BrakeV2> {
    frames.iter().rev().find_map(|f| match f {
        MessageV2::SystemState(system) => Some(system.brake()),
        _ => None,
    })
}

#[test]
fn a_hunters_parking_brake_starts_locked_and_holds_it_until_released() {
    let mut chassis = chassis(Model::Hunter2);
    chassis.handle_v2(ms(0), TAKE);
    let (now, frames) = drive(&mut chassis, go(0.5, 0.0), ms(0), ms(500));
    assert_eq!(brake_reported(&frames), Some(BrakeV2::Locked));
    assert_eq!(chassis.actual().linear, 0.0);
    assert_eq!(chassis.stats().ignored.brake_locked, 25);
    assert_eq!(
        chassis.handle_v2(now, go(0.5, 0.0)),
        Some(Ignored::BrakeLocked)
    );
    chassis.handle_v2(now, MessageV2::Brake(BrakeV2::Released));
    let (now, frames) = drive(&mut chassis, go(0.5, 0.0), now, ms(1000));
    assert_eq!(brake_reported(&frames), Some(BrakeV2::Released));
    assert!(chassis.actual().linear > 0.4, "{:?}", chassis.actual());
    // Locked while moving: it stops (at its deceleration) and stays so.
    chassis.handle_v2(now, MessageV2::Brake(BrakeV2::Locked));
    drive(&mut chassis, go(0.5, 0.0), now, ms(1000));
    assert_eq!(chassis.actual().linear, 0.0);
    let stats = chassis.stats();
    assert_eq!((stats.brake, stats.brake_changes), ("locked", 2));
    // A model without one rejects 0x131 and reports nothing in byte 6.
    let mut scout = chassis_v2_plain();
    scout.handle_v2(ms(0), MessageV2::Brake(BrakeV2::Locked));
    assert_eq!((scout.stats().rejected, scout.stats().brake), (1, ""));
    let (_, frames) = drive(&mut scout, go(0.5, 0.0), ms(0), ms(200));
    assert_eq!(brake_reported(&frames), Some(BrakeV2::Released));
}

#[test]
fn commands_are_clamped_to_the_models_limits() {
    for (model, linear) in [
        (Model::Scout2, 1.5),
        (Model::ScoutMini, 3.0),
        (Model::Tracer, 1.5),
        (Model::BunkerPro, 1.5),
    ] {
        let mut chassis = chassis(model);
        chassis.handle_v2(ms(0), TAKE);
        chassis.handle_v2(ms(10), go(5.0, -9.0));
        let target = chassis.target_at(ms(10));
        assert_eq!(target.linear, linear, "{model}");
        assert_eq!(target.angular, -model.limits().angular, "{model}");
    }
    // A Hunter SE (no brake to release): its speed and its steering field, each to its own.
    let mut se = chassis(Model::HunterSe);
    se.handle_v2(ms(0), TAKE);
    let wide = MotionV2::from_si(9.0, 0.0).with_steering(-1.5);
    drive(&mut se, MessageV2::MotionCommand(wide), ms(0), ms(3000));
    assert_eq!(se.target_at(ms(3000)).linear, 4.8);
    assert_eq!(se.stats().steering, -0.4);
}

#[test]
fn estop_rc_and_errors_show_in_the_system_state() {
    let mut chassis = chassis(Model::Scout2);
    chassis.inject(ms(0), Injection::EStop(true));
    chassis.inject(ms(0), Injection::Rc(true));
    chassis.inject(ms(0), Injection::Protect(Protection::DriverOvertemp));
    let (_, frames) = drive(&mut chassis, go(0.0, 0.0), ms(0), ms(200));
    let state = system_states(&frames)[0];
    assert_eq!(state.state, ChassisState::EStop);
    assert_eq!(state.control_mode, ControlModeV2::Rc);
    assert_eq!(state.errors.0 & 0x0100, 0x0100, "motor driver error");
    let rc = frames
        .iter()
        .find_map(|f| match f {
            MessageV2::RcState(rc) => Some(*rc),
            _ => None,
        })
        .expect("0x241 while the RC is on");
    assert_eq!(rc.swb, SwitchPosition::Middle, "manual");
    let driver = frames
        .iter()
        .find_map(|f| match f {
            MessageV2::ActuatorLow(low) => Some(*low),
            _ => None,
        })
        .expect("0x261");
    assert_eq!(
        driver.driver_state.0 & 0x08,
        0x08,
        "driver over-temperature"
    );
    // 0x441 [00] clears the latched protection.
    chassis.handle_v2(ms(300), MessageV2::ErrorClear(ErrorClearV2::All));
    assert_eq!(chassis.system_state_v2().expect("v2").errors.0 & 0x0100, 0);
}

#[test]
fn version_requests_are_answered_in_the_form_asked() {
    let mut chassis = chassis(Model::Scout2);
    chassis.handle_v2(ms(0), MessageV2::VersionRequest(VersionRequestForm::Binary));
    chassis.handle_v2(ms(0), MessageV2::VersionRequest(VersionRequestForm::Text));
    let Some(Feedback::V2(frames)) = chassis.poll_feedback(ms(0)) else {
        panic!("v2 feedback")
    };
    assert!(frames.iter().any(|f| matches!(f, MessageV2::Version(_))));
    let text: Vec<u8> = frames
        .iter()
        .filter_map(|f| match f {
            MessageV2::VersionText(text) => Some(text.to_vec()),
            _ => None,
        })
        .flatten()
        .collect();
    assert_eq!(text.len(), 80);
    assert!(text.starts_with(b"scout-sim v2"));
    assert!(chassis.poll_feedback(ms(20)).is_some_and(|f| {
        f.v2()
            .is_some_and(|frames| !frames.iter().any(|f| matches!(f, MessageV2::Version(_))))
    }));
}

#[test]
fn a_smart_battery_reports_its_charge_and_a_charger_every_100_ms() {
    let params = SimParams {
        bms: true,
        battery_capacity_ah: 0.1,
        ..SimParams::for_model(Model::Scout2)
    };
    let mut chassis = Chassis::new(params, Transport::Can).with_protocol_v2();
    chassis.inject(ms(0), Injection::Charger(10.0));
    let (_, frames) = drive(&mut chassis, go(0.0, 0.0), ms(0), ms(1000));
    let reports: Vec<BmsV2> = frames
        .iter()
        .filter_map(|frame| match frame {
            MessageV2::Bms(bms) => Some(*bms),
            _ => None,
        })
        .collect();
    assert_eq!(reports.len(), 10, "0x361 every 100 ms");
    assert_eq!(frames.iter().filter(|f| f.can_id() == 0x362).count(), 10);
    let last = reports[9];
    assert!(last.charge_percent > 80, "charging from 80 %: {last:?}");
    assert!(last.deciamps > 90, "10 A in, the electronics out: {last:?}");
    assert_eq!((last.health_percent, last.decidegrees), (96, 250));
    // Without a BMS, none.
    let mut plain = chassis_v2_plain();
    let (_, frames) = drive(&mut plain, go(0.0, 0.0), ms(0), ms(500));
    assert!(
        frames
            .iter()
            .all(|f| !matches!(f, MessageV2::Bms(_) | MessageV2::BmsAlarm(_)))
    );
}

fn chassis_v2_plain() -> Chassis {
    chassis(Model::Scout2)
}
