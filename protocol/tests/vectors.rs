//! Golden vectors from the vendor manual (sections 3.3, 3.4) and protocol-notes, byte for byte.

use scout_protocol::message::FaultClear;
use scout_protocol::{
    CanFrame, ChassisState, ControlMode, Light, LightCommand, LightMode, Message, MotionCommand,
    can, serial, units,
};

fn can_frame(id: u16, data: [u8; 8]) -> CanFrame {
    CanFrame::new(id, &data).expect("valid frame")
}

fn motion(control_mode: ControlMode, linear_percent: i8, angular_percent: i8) -> Message {
    Message::MotionCommand(MotionCommand {
        control_mode,
        fault_clear: FaultClear::None,
        linear_percent,
        angular_percent,
    })
}

/// (message, count, the frame the manual or notes print)
fn can_vectors() -> Vec<(Message, u8, CanFrame)> {
    vec![
        // Manual 3.3.1 note 3, example 1: 0.15 m/s forward.
        (
            motion(ControlMode::Can, 10, 0),
            0,
            can_frame(0x130, [0x01, 0, 0x0A, 0, 0, 0, 0, 0x44]),
        ),
        // Example 2: 10 % angular.
        (
            motion(ControlMode::Can, 0, 10),
            0,
            can_frame(0x130, [0x01, 0, 0, 0x0A, 0, 0, 0, 0x44]),
        ),
        // Example 3: stand still, enter command mode.
        (
            motion(ControlMode::Can, 0, 0),
            0,
            can_frame(0x130, [0x01, 0, 0, 0, 0, 0, 0, 0x3A]),
        ),
        // Vendor unit test: example 2 with count 1.
        (
            motion(ControlMode::Can, 0, 10),
            1,
            can_frame(0x130, [0x01, 0, 0, 0x0A, 0, 0, 1, 0x45]),
        ),
        // Vendor light test vector: front on 100, rear custom 50.
        (
            Message::LightCommand(LightCommand {
                enabled: true,
                front: Light {
                    mode: LightMode::On,
                    brightness: 100,
                },
                rear: Light {
                    mode: LightMode::Custom,
                    brightness: 50,
                },
            }),
            0,
            can_frame(0x140, [0x01, 0x01, 0x64, 0x03, 0x32, 0x00, 0x00, 0xE4]),
        ),
    ]
}

#[test]
fn can_vectors_encode_byte_for_byte() {
    for (message, count, frame) in can_vectors() {
        assert_eq!(can::encode(&message, count), frame, "{message:?}");
    }
}

#[test]
fn can_vectors_decode_to_their_message() {
    for (message, count, frame) in can_vectors() {
        let counted = can::decode(&frame).expect("valid vector");
        assert_eq!((counted.message, counted.count), (message, count));
    }
}

/// The v1.2.5 manual's maximum angular speed (protocol-notes 4.1), which example 2 assumes.
#[allow(clippy::approx_constant)]
const MANUAL_V1_2_5_MAX_ANGULAR: f64 = 0.7853;

#[test]
fn manual_examples_mean_the_speeds_the_manual_says() {
    let Message::MotionCommand(forward) = can_vectors()[0].0 else {
        panic!("motion vector")
    };
    assert!((forward.linear(scout_protocol::units::MAX_LINEAR_SPEED) - 0.15).abs() < 1e-12);
    let Message::MotionCommand(turn) = can_vectors()[1].0 else {
        panic!("motion vector")
    };
    assert!(
        (turn.angular(MANUAL_V1_2_5_MAX_ANGULAR) - 0.07853).abs() < 1e-12,
        "the manual's 0.07853 rad/s at v1.2.5"
    );
    assert_eq!(
        units::speed_to_percent(0.15, units::MAX_LINEAR_SPEED),
        Ok((10, false))
    );
}

const SERIAL_FORWARD: [u8; serial::FRAME_LEN] = [
    0x5A, 0xA5, 0x0A, 0x55, 0x01, 0x02, 0x00, 0x0A, 0x00, 0x00, 0x00, 0x00, 0x6B,
];

#[test]
fn serial_manual_example_byte_for_byte() {
    // Manual 3.4.2 example: 0.15 m/s forward in serial mode.
    let message = motion(ControlMode::Serial, 10, 0);
    assert_eq!(serial::encode(&message, 0), SERIAL_FORWARD);
    let counted = serial::decode(&SERIAL_FORWARD).expect("valid vector");
    assert_eq!((counted.message, counted.count), (message, 0));
}

#[test]
fn capture_status_frame_decodes_as_estop_rc_23_9_volts() {
    let frame = can_frame(0x151, [0x01, 0x00, 0x00, 0xEF, 0x00, 0x3C, 0xE4, 0x6A]);
    let Message::SystemStatus(status) = can::decode(&frame).expect("valid").message else {
        panic!("0x151 is the system status")
    };
    assert_eq!(status.state, ChassisState::EStop);
    assert_eq!(status.control_mode, ControlMode::Rc);
    assert!((status.battery_voltage() - 23.9).abs() < 1e-9);
    let faults: Vec<_> = status.faults.iter().map(|f| f.name()).collect();
    assert_eq!(
        faults,
        [
            "motor_1_comm_fault",
            "motor_2_comm_fault",
            "motor_3_comm_fault",
            "motor_4_comm_fault"
        ]
    );
}
