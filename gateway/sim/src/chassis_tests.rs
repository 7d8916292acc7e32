//! Tests of the chassis model with a simulated clock.

use std::time::Duration;

use scout_protocol::{
    ChassisState, ControlMode, Counted, Fault, FaultClear, Light, LightCommand, LightMode, Message,
    MessageKind, MotionCommand, Motor, can, candump, serial,
};

use crate::chassis::{Chassis, Feedback, Ignored, Injection, MotorValue, Protection, SimParams};
use scout_protocol::Transport;

const fn ms(millis: u64) -> Duration {
    Duration::from_millis(millis)
}

fn motion(mode: ControlMode, linear_percent: i8, angular_percent: i8) -> Counted {
    Counted {
        message: Message::MotionCommand(MotionCommand {
            control_mode: mode,
            fault_clear: FaultClear::None,
            linear_percent,
            angular_percent,
        }),
        count: 0,
    }
}

fn clear(code: FaultClear) -> Counted {
    let mut counted = motion(ControlMode::Can, 0, 0);
    if let Message::MotionCommand(command) = &mut counted.message {
        command.fault_clear = code;
    }
    counted
}

/// Sends `command` every 20 ms from `from` for `duration`, polling feedback as a driver would.
fn drive(chassis: &mut Chassis, command: Counted, from: Duration, duration: Duration) -> Duration {
    let mut now = from;
    while now < from + duration {
        chassis.handle_message(now, command);
        let _ = chassis.poll_feedback(now);
        now += ms(20);
    }
    now
}

fn status_faults(chassis: &Chassis) -> Vec<Fault> {
    chassis.system_status().faults.iter().collect()
}

#[test]
fn command_times_out_after_exactly_500_ms() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    assert_eq!(
        chassis.handle_message(ms(1000), motion(ControlMode::Can, 10, 0)),
        None
    );
    assert!((chassis.target_at(ms(1000)).linear - 0.15).abs() < 1e-9);
    assert!(
        (chassis.target_at(ms(1499)).linear - 0.15).abs() < 1e-9,
        "still valid at 499 ms"
    );
    assert_eq!(
        chassis.target_at(ms(1500)).linear,
        0.0,
        "communication protection at 500 ms"
    );
}

#[test]
fn control_mode_must_match_the_link() {
    let mut can = Chassis::new(SimParams::default(), Transport::Can);
    assert_eq!(
        can.handle_message(ms(0), motion(ControlMode::Serial, 50, 0)),
        Some(Ignored::WrongMode)
    );
    assert_eq!(
        can.handle_message(ms(20), motion(ControlMode::Rc, 50, 0)),
        Some(Ignored::WrongMode)
    );
    assert_eq!(can.target_at(ms(40)).linear, 0.0);
    let mut serial = Chassis::new(SimParams::default(), Transport::Serial);
    assert_eq!(
        serial.handle_message(ms(0), motion(ControlMode::Can, 50, 0)),
        Some(Ignored::WrongMode)
    );
    assert_eq!(
        serial.handle_message(ms(20), motion(ControlMode::Serial, 50, 0)),
        None
    );
    assert!(serial.target_at(ms(40)).linear > 0.7);
    assert_eq!(serial.stats().ignored.wrong_mode, 1);
}

#[test]
fn each_protection_latches_until_its_clear_code() {
    for (protection, fault, code, other_code) in [
        (
            Protection::DriverOvertemp,
            Fault::DriverOvertempProtection,
            FaultClear::DriverOverTemp,
            FaultClear::MotorOverCurrent,
        ),
        (
            Protection::MotorOvercurrent,
            Fault::MotorOvercurrentProtection,
            FaultClear::MotorOverCurrent,
            FaultClear::DriverOverTemp,
        ),
    ] {
        let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
        let now = drive(
            &mut chassis,
            motion(ControlMode::Can, 50, 0),
            ms(0),
            ms(1000),
        );
        assert!(chassis.actual().linear > 0.5);
        chassis.inject(now, Injection::Protect(protection));
        assert!(status_faults(&chassis).contains(&fault));
        let command = motion(ControlMode::Can, 50, 0);
        assert_eq!(
            chassis.handle_message(now, command),
            Some(Ignored::Inhibited)
        );
        let now = drive(&mut chassis, command, now, ms(2000));
        assert_eq!(
            chassis.actual().linear,
            0.0,
            "coasts to a stop and ignores motion"
        );
        chassis.handle_message(now, clear(other_code));
        assert!(
            status_faults(&chassis).contains(&fault),
            "only the matching code clears it"
        );
        chassis.handle_message(now + ms(20), clear(code));
        assert!(!status_faults(&chassis).contains(&fault));
        drive(&mut chassis, command, now + ms(40), ms(1000));
        assert!(
            chassis.actual().linear > 0.5,
            "motion accepted again after the clear"
        );
    }
}

#[test]
fn crossing_a_threshold_latches_the_protection() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    let motor = Motor::new(3).expect("motor 3");
    chassis.inject(ms(0), Injection::PinMotor(motor, MotorValue::Current, 16.0));
    assert!(status_faults(&chassis).contains(&Fault::MotorOvercurrentWarning));
    assert!(!status_faults(&chassis).contains(&Fault::MotorOvercurrentProtection));
    chassis.inject(
        ms(10),
        Injection::PinMotor(motor, MotorValue::Current, 21.0),
    );
    chassis.inject(ms(20), Injection::UnpinMotor(motor));
    let faults = status_faults(&chassis);
    assert!(
        !faults.contains(&Fault::MotorOvercurrentWarning),
        "the warning clears itself"
    );
    assert!(
        faults.contains(&Fault::MotorOvercurrentProtection),
        "the protection stays"
    );
    chassis.inject(
        ms(30),
        Injection::PinMotor(motor, MotorValue::DriverTemperature, 70.0),
    );
    let faults = status_faults(&chassis);
    assert!(faults.contains(&Fault::DriverOvertempWarning));
    assert!(faults.contains(&Fault::DriverOvertempProtection));
}

#[test]
fn rc_transmitter_overrides_the_host() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    chassis.inject(ms(0), Injection::Rc(true));
    assert_eq!(chassis.system_status().control_mode, ControlMode::Rc);
    assert_eq!(
        chassis.handle_message(ms(0), motion(ControlMode::Can, 50, 0)),
        Some(Ignored::Rc)
    );
    assert_eq!(chassis.target_at(ms(20)).linear, 0.0);
    chassis.inject(ms(40), Injection::Rc(false));
    assert_eq!(chassis.system_status().control_mode, ControlMode::Can);
    assert_eq!(
        chassis.handle_message(ms(60), motion(ControlMode::Can, 50, 0)),
        None
    );
}

#[test]
fn estop_stops_at_once_and_reports_like_the_real_chassis() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    let now = drive(
        &mut chassis,
        motion(ControlMode::Can, 50, 0),
        ms(0),
        ms(1000),
    );
    chassis.inject(now, Injection::EStop(true));
    assert_eq!(chassis.actual().linear, 0.0);
    let status = chassis.system_status();
    assert_eq!(status.state, ChassisState::EStop);
    assert_eq!(
        status.faults.0 & 0x3C,
        0x3C,
        "motor 1-4 communication faults, as in the capture"
    );
    chassis.inject(now + ms(20), Injection::EStop(false));
    assert_eq!(chassis.system_status().state, ChassisState::Normal);
    assert_eq!(chassis.system_status().faults.0 & 0x3C, 0);
}

#[test]
fn battery_thresholds() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    chassis.inject(ms(0), Injection::Battery(22.4));
    assert_eq!(status_faults(&chassis), [Fault::BatteryUndervoltageWarning]);
    assert_eq!(
        chassis.handle_message(ms(0), motion(ControlMode::Can, 50, 0)),
        None
    );
    chassis.inject(ms(20), Injection::Battery(21.9));
    assert_eq!(
        status_faults(&chassis),
        [
            Fault::BatteryUndervoltageWarning,
            Fault::BatteryUndervoltageFault
        ]
    );
    assert_eq!(chassis.system_status().battery_decivolts, 219);
    assert_eq!(
        chassis.handle_message(ms(40), motion(ControlMode::Can, 50, 0)),
        Some(Ignored::Inhibited)
    );
    assert_eq!(
        chassis.target_at(ms(60)).linear,
        0.0,
        "drive cut below 22 V"
    );
    chassis.inject(ms(80), Injection::Battery(24.0));
    chassis.handle_message(ms(100), clear(FaultClear::BatteryUnderVoltage));
    assert_eq!(status_faults(&chassis), []);
}

#[test]
fn battery_discharges_with_load() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    drive(
        &mut chassis,
        motion(ControlMode::Can, 100, 0),
        ms(0),
        ms(10_000),
    );
    assert!(chassis.stats().battery_voltage < SimParams::default().battery_voltage);
}

fn light_feedback(chassis: &mut Chassis, now: Duration) -> LightCommand {
    let batch = chassis
        .poll_feedback(now)
        .and_then(Feedback::v1)
        .expect("a feedback period");
    match batch[5].message {
        Message::LightFeedback(lights) => lights,
        other => panic!("0x141 expected, found {other:?}"),
    }
}

#[test]
fn light_modes() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Serial);
    // The chassis' own logic: standing still, front off and rear breathing.
    let own = light_feedback(&mut chassis, ms(0));
    assert!(!own.enabled);
    assert_eq!(
        (own.front.mode, own.rear.mode),
        (LightMode::Off, LightMode::Breath)
    );
    let command = LightCommand {
        enabled: true,
        front: Light {
            mode: LightMode::Custom,
            brightness: 42,
        },
        rear: Light {
            mode: LightMode::Breath,
            brightness: 0,
        },
    };
    chassis.handle_message(
        ms(10),
        Counted {
            message: Message::LightCommand(command),
            count: 0,
        },
    );
    let first = light_feedback(&mut chassis, ms(20));
    let second = light_feedback(&mut chassis, ms(40));
    assert!(first.enabled);
    assert_eq!(
        first.front,
        Light {
            mode: LightMode::Custom,
            brightness: 42
        }
    );
    assert_eq!(first.rear.mode, LightMode::Breath);
    assert_ne!(
        first.rear.brightness, second.rear.brightness,
        "breathing animates"
    );
    // Serial light commands lapse after 500 ms.
    assert!(light_feedback(&mut chassis, ms(500)).enabled);
    assert!(!light_feedback(&mut chassis, ms(520)).enabled);
}

#[test]
fn every_feedback_id_counts_and_wraps() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    let mut last = [None::<u8>; MessageKind::COUNT];
    for period in 0..300u64 {
        let batch = chassis
            .poll_feedback(ms(period * 20))
            .and_then(Feedback::v1)
            .expect("one batch a period");
        assert_eq!(batch.len(), 7);
        for counted in batch {
            let slot = &mut last[counted.message.kind().index()];
            if let Some(previous) = *slot {
                assert_eq!(counted.count, previous.wrapping_add(1));
            }
            *slot = Some(counted.count);
        }
        assert!(
            chassis.poll_feedback(ms(period * 20 + 19)).is_none(),
            "one batch per 20 ms"
        );
    }
    assert_eq!(
        last[MessageKind::SystemStatus.index()],
        Some((299 % 256) as u8)
    );
}

#[test]
fn bad_command_checksum_sets_the_error_bit_until_a_valid_command() {
    let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
    chassis.handle_checksum_error(ms(0));
    assert_eq!(status_faults(&chassis), [Fault::CommandChecksumError]);
    assert_eq!(chassis.target_at(ms(0)).linear, 0.0, "the frame is ignored");
    chassis.handle_message(ms(20), motion(ControlMode::Can, 0, 0));
    assert_eq!(status_faults(&chassis), []);
    assert_eq!(chassis.stats().checksum_failures, 1);
}

#[test]
fn manual_example_frames_reach_their_speeds() {
    // CAN: `130#01000A0000000044` is 0.15 m/s forward; `130#0100000A00000044` 10 % angular.
    for (line, linear, angular) in [
        ("130#01000A0000000044", 0.15, 0.0),
        ("130#0100000A00000044", 0.0, 0.05235),
    ] {
        let frame = candump::parse(line).expect("manual line").frame;
        let command = can::decode(&frame).expect("valid manual frame");
        let mut chassis = Chassis::new(SimParams::default(), Transport::Can);
        drive(&mut chassis, command, ms(0), ms(2000));
        let feedback = chassis
            .poll_feedback(ms(2000))
            .and_then(Feedback::v1)
            .expect("feedback");
        let Message::MotionFeedback(motion) = feedback[0].message else {
            panic!("0x131 first")
        };
        assert!(
            (motion.linear() - linear).abs() < 0.001,
            "{line}: {}",
            motion.linear()
        );
        assert!(
            (motion.angular() - angular).abs() < 0.001,
            "{line}: {}",
            motion.angular()
        );
    }
    // Serial: `5A A5 0A 55 01 02 00 0A 00 00 00 00 6B` is 0.15 m/s forward in serial mode.
    let bytes = [
        0x5A, 0xA5, 0x0A, 0x55, 0x01, 0x02, 0x00, 0x0A, 0x00, 0x00, 0x00, 0x00, 0x6B,
    ];
    let command = serial::decode(&bytes).expect("valid manual frame");
    let mut chassis = Chassis::new(SimParams::default(), Transport::Serial);
    drive(&mut chassis, command, ms(0), ms(2000));
    assert!((chassis.actual().linear - 0.15).abs() < 1e-9);
}

#[test]
fn acceleration_is_limited_and_the_pose_integrates() {
    let params = SimParams::default();
    let mut chassis = Chassis::new(params.clone(), Transport::Can);
    drive(
        &mut chassis,
        motion(ControlMode::Can, 100, 0),
        ms(0),
        ms(500),
    );
    let after_half_second = chassis.actual().linear;
    assert!(after_half_second <= params.linear_acceleration * 0.5 + 1e-9);
    assert!(after_half_second > 0.3);
    // Drive straight: 1.5 s ramp (1.125 m) then 1.5 m/s.
    let end = drive(
        &mut chassis,
        motion(ControlMode::Can, 100, 0),
        ms(500),
        ms(2500),
    );
    let pose = chassis.pose();
    assert!(pose.y.abs() < 1e-9 && pose.yaw.abs() < 1e-9);
    let expected = 1.125 + 1.5 * (end.as_secs_f64() - 0.02 - 1.5);
    assert!(
        (pose.x - expected).abs() < 0.05,
        "x {} expected {expected}",
        pose.x
    );
    // Turning in place: the left motors and right motors turn the wheels opposite ways.
    drive(
        &mut chassis,
        motion(ControlMode::Can, 0, 100),
        end,
        ms(3000),
    );
    let batch = chassis
        .poll_feedback(end + ms(3000))
        .and_then(Feedback::v1)
        .expect("feedback");
    let rpm = |i: usize| match batch[i].message {
        Message::MotorFeedback(m) => m.rpm,
        other => panic!("{other:?}"),
    };
    // Wheel speeds ±ω·track/2 = ±0.1526 m/s: motor 1 (right) forward +, motor 2 (left) reverse
    // on its mirrored shaft, also +.
    assert!(rpm(1) > 250 && rpm(2) > 250, "{} {}", rpm(1), rpm(2));
    assert!(chassis.pose().yaw.abs() > 0.5);
}

#[test]
fn a_deliberate_odometry_error_is_in_the_reports_not_in_the_motion() {
    let params = SimParams {
        reported_distance_scale: 0.95,
        reported_yaw_scale: 1.26,
        ..SimParams::default()
    };
    let mut chassis = Chassis::new(params, Transport::Can);
    let end = drive(
        &mut chassis,
        motion(ControlMode::Can, 20, 40),
        ms(0),
        ms(3000),
    );
    let batch = chassis
        .poll_feedback(end + ms(20))
        .and_then(Feedback::v1)
        .expect("feedback");
    let actual = chassis.actual();
    assert!(actual.linear > 0.2 && actual.angular > 0.1, "{actual:?}");
    let Message::MotionFeedback(reported) = batch[0].message else {
        panic!("motion feedback first: {:?}", batch[0]);
    };
    assert!((f64::from(reported.linear_mm_s) / 1000.0 - actual.linear * 0.95).abs() < 0.002);
    assert!((f64::from(reported.angular_mrad_s) / 1000.0 - actual.angular * 1.26).abs() < 0.002);
}

#[test]
fn the_pack_follows_its_curve_down_with_load_and_up_on_a_charger_until_full() {
    let params = SimParams {
        battery_capacity_ah: 0.05,
        ..SimParams::default()
    };
    let mut chassis = Chassis::new(params, Transport::Can);
    let start = chassis.stats();
    assert!(
        (start.battery_percent - 80.0).abs() < 1e-9,
        "26.0 V at rest is 80 %"
    );
    let at = drive(
        &mut chassis,
        motion(ControlMode::Can, 100, 0),
        ms(0),
        ms(30_000),
    );
    let driven = chassis.stats();
    assert!(driven.battery_percent < 70.0, "{}", driven.battery_percent);
    assert!(driven.battery_current < 0.0, "{}", driven.battery_current);
    chassis.inject(at, Injection::Charger(10.0));
    let at = drive(&mut chassis, motion(ControlMode::Can, 0, 0), at, ms(60_000));
    let charged = chassis.stats();
    assert_eq!(charged.battery_percent, 100.0);
    assert_eq!(
        charged.battery_voltage, 29.2,
        "the charger holds its voltage when full"
    );
    chassis.inject(at, Injection::Charger(0.0));
    drive(&mut chassis, motion(ControlMode::Can, 0, 0), at, ms(1_000));
    let rested = chassis.stats();
    assert!(
        (26.5..26.7).contains(&rested.battery_voltage),
        "{}",
        rested.battery_voltage
    );
}
