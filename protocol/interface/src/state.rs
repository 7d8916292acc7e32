//! The chassis state a gateway publishes zero-copy: the latest of every feedback message with
//! its receive time, the link, odometry and the last command. [`StatePayload::store`] and
//! [`StatePayload::received`] match every message kind, so a new feedback message does not
//! compile until it has a place here.

use iceoryx2::prelude::ZeroCopySend;
use scout_protocol::{
    ChassisState, ControlMode, FaultBits, Light, LightCommand, LightMode, Message, MessageKind,
    MotionFeedback, Motor, MotorFeedback, SystemStatus, Transport,
};

use crate::text::FixedText;

wire_enum! {
    /// The state of the link, published at once on every change.
    LinkState {
        /// Feedback arrives.
        Ok = 0 => "ok",
        /// No valid feedback for 100 ms (or none yet).
        Silent = 1 => "silent",
        /// The port is closed or failing; the gateway is reopening it.
        Disconnected = 2 => "disconnected",
        /// The chassis speaks protocol v2, which this gateway does not support.
        ProtocolV2 = 3 => "protocol_v2",
    }
}

/// The link to the chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct LinkPayload {
    /// [`LinkState`] as `u8`.
    pub state: u8,
    /// [`Transport`] as `u8` ([`Transport::raw`]).
    pub transport: u8,
    /// Valid frames received.
    pub rx_frames: u64,
    /// Frames rejected for their checksum.
    pub checksum_errors: u64,
    /// Frames lost, from gaps in the rolling counts.
    pub dropped_frames: u64,
    /// Other rejected input: unknown ids, bad lengths, malformed slcan lines.
    pub rejected_frames: u64,
    /// Bytes thrown away while resynchronising (serial).
    pub discarded_bytes: u64,
    /// Frames the operating system dropped before the gateway read them, because its receive
    /// queue was full (SocketCAN reports it; a tty's driver does not).
    pub overflowed_frames: u64,
    /// Frames sent to the chassis.
    pub tx_frames: u64,
    /// Times the port was reopened after a fault.
    pub reconnects: u64,
    /// The device or interface.
    pub device: FixedText<96>,
}

impl LinkPayload {
    /// The link state (`silent` for a byte this version does not know).
    pub fn state(&self) -> LinkState {
        LinkState::from_raw(self.state).unwrap_or(LinkState::Silent)
    }

    /// The transport, if the byte names one.
    pub fn transport(&self) -> Option<Transport> {
        Transport::from_raw(self.transport)
    }
}

/// When a feedback frame was last received: `valid` is false until the first one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct Received {
    /// Whether a frame of this kind has been received since the link came up.
    pub valid: bool,
    /// The rolling count of the last frame.
    pub count: u8,
    /// CLOCK_MONOTONIC time of the last frame, ns.
    pub at_ns: u64,
}

/// The 0x151 system status.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct SystemPayload {
    /// When it was received.
    pub received: Received,
    /// Raw chassis state byte (0 normal, 1 e-stop, 2 exception).
    pub state: u8,
    /// Raw control mode byte (0 RC, 1 CAN, 2 serial).
    pub control_mode: u8,
    /// Battery voltage, 0.1 V.
    pub battery_decivolts: u16,
    /// The fault word (byte 4 high).
    pub fault_bits: u16,
}

/// The 0x131 motion feedback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct MotionPayload {
    /// When it was received.
    pub received: Received,
    /// mm/s.
    pub linear_mm_s: i16,
    /// mrad/s.
    pub angular_mrad_s: i16,
}

/// One 0x200..0x203 motor feedback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct MotorPayload {
    /// When it was received.
    pub received: Received,
    /// 0.1 A, signed.
    pub current_deciamps: i16,
    /// Shaft rpm.
    pub rpm: i16,
    /// deg C.
    pub driver_temperature: i8,
    /// deg C.
    pub motor_temperature: i8,
}

/// One light of a light feedback or request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct LightPayload {
    /// Raw mode (0 off, 1 on, 2 breath, 3 custom).
    pub mode: u8,
    /// 0..100.
    pub brightness: u8,
}

impl LightPayload {
    /// The payload of `light`.
    pub fn new(light: Light) -> Self {
        Self {
            mode: light.mode.raw(),
            brightness: light.brightness,
        }
    }

    /// The light it carries.
    pub fn light(self) -> Light {
        Light {
            mode: LightMode::from_raw(self.mode),
            brightness: self.brightness,
        }
    }
}

/// The 0x141 light feedback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct LightsPayload {
    /// When it was received.
    pub received: Received,
    /// Host light control enabled.
    pub enabled: bool,
    /// Front light.
    pub front: LightPayload,
    /// Rear light.
    pub rear: LightPayload,
}

/// Odometry integrated from 0x131 in the gateway, since start or the last reset.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct OdometryPayload {
    /// m.
    pub x: f64,
    /// m.
    pub y: f64,
    /// rad, -pi..pi.
    pub yaw: f64,
    /// Distance travelled, m.
    pub distance: f64,
    /// How many times it was reset.
    pub resets: u32,
}

/// The motion command the gateway last sent.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct CommandPayload {
    /// m/s, as sent (after percent rounding).
    pub linear: f64,
    /// rad/s, as sent.
    pub angular: f64,
    /// CLOCK_MONOTONIC time it was sent, ns.
    pub at_ns: u64,
}

/// The chassis state a gateway publishes on every decoded feedback frame and link change.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("scout::StatePayload.v5")]
#[repr(C)]
pub struct StatePayload {
    /// Increases by one with every publication.
    pub seq: u64,
    /// CLOCK_MONOTONIC time of publication, ns.
    pub published_ns: u64,
    /// The robot's name.
    pub robot: FixedText<32>,
    /// The link.
    pub link: LinkPayload,
    /// 0x151.
    pub system: SystemPayload,
    /// 0x131.
    pub motion: MotionPayload,
    /// 0x200..0x203, motor 1 first.
    pub motors: [MotorPayload; 4],
    /// 0x141.
    pub lights: LightsPayload,
    /// Odometry.
    pub odometry: OdometryPayload,
    /// The last motion command sent.
    pub command: CommandPayload,
    /// The maximum angular speed the gateway converts with, rad/s.
    pub max_angular: f64,
}

impl StatePayload {
    /// Keeps a received feedback message as the latest of its kind. Returns `false` for a
    /// host-to-chassis command, which has no place in the state.
    pub fn store(&mut self, message: &Message, received: Received) -> bool {
        match message {
            Message::SystemStatus(status) => {
                self.system = SystemPayload {
                    received,
                    state: status.state.raw(),
                    control_mode: status.control_mode.raw(),
                    battery_decivolts: status.battery_decivolts,
                    fault_bits: status.faults.0,
                };
            }
            Message::MotionFeedback(motion) => {
                self.motion = MotionPayload {
                    received,
                    linear_mm_s: motion.linear_mm_s,
                    angular_mrad_s: motion.angular_mrad_s,
                };
            }
            Message::MotorFeedback(motor) => {
                self.motors[motor.motor.index()] = MotorPayload {
                    received,
                    current_deciamps: motor.current_deciamps,
                    rpm: motor.rpm,
                    driver_temperature: motor.driver_temperature,
                    motor_temperature: motor.motor_temperature,
                };
            }
            Message::LightFeedback(lights) => {
                self.lights = LightsPayload {
                    received,
                    enabled: lights.enabled,
                    front: LightPayload::new(lights.front),
                    rear: LightPayload::new(lights.rear),
                };
            }
            Message::MotionCommand(_) | Message::LightCommand(_) => return false,
        }
        true
    }

    /// The latest message of `kind` with when it came, or `None` before the first one and for
    /// host-to-chassis commands.
    pub fn received(&self, kind: MessageKind) -> Option<(Received, Message)> {
        let (received, message) = match kind {
            MessageKind::SystemStatus => (
                self.system.received,
                Message::SystemStatus(self.system.status()),
            ),
            MessageKind::MotionFeedback => (
                self.motion.received,
                Message::MotionFeedback(self.motion.feedback()),
            ),
            MessageKind::MotorFeedback(motor) => {
                let payload = &self.motors[motor.index()];
                (
                    payload.received,
                    Message::MotorFeedback(payload.feedback(motor)),
                )
            }
            MessageKind::LightFeedback => (
                self.lights.received,
                Message::LightFeedback(self.lights.feedback()),
            ),
            MessageKind::MotionCommand | MessageKind::LightCommand => return None,
        };
        received.valid.then_some((received, message))
    }
}

impl SystemPayload {
    /// The status it carries.
    pub fn status(&self) -> SystemStatus {
        SystemStatus {
            state: ChassisState::from_raw(self.state),
            control_mode: ControlMode::from_raw(self.control_mode),
            battery_decivolts: self.battery_decivolts,
            faults: FaultBits(self.fault_bits),
        }
    }
}

impl MotionPayload {
    /// The feedback it carries.
    pub fn feedback(&self) -> MotionFeedback {
        MotionFeedback {
            linear_mm_s: self.linear_mm_s,
            angular_mrad_s: self.angular_mrad_s,
        }
    }
}

impl MotorPayload {
    /// The feedback it carries, for `motor`.
    pub fn feedback(&self, motor: Motor) -> MotorFeedback {
        MotorFeedback {
            motor,
            current_deciamps: self.current_deciamps,
            rpm: self.rpm,
            driver_temperature: self.driver_temperature,
            motor_temperature: self.motor_temperature,
        }
    }
}

impl LightsPayload {
    /// The feedback it carries.
    pub fn feedback(&self) -> LightCommand {
        LightCommand {
            enabled: self.enabled,
            front: self.front.light(),
            rear: self.rear.light(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_protocol::Direction;

    #[test]
    fn link_state_round_trips() {
        for state in LinkState::ALL {
            assert_eq!(LinkState::from_raw(state.raw()), Some(*state));
        }
    }

    fn sample(kind: MessageKind) -> Message {
        Message::parse(kind, &[1, 2, 3, 4, 5, 6])
    }

    #[test]
    fn every_feedback_message_is_stored_and_read_back() {
        let received = Received {
            valid: true,
            count: 9,
            at_ns: 42,
        };
        for kind in MessageKind::ALL {
            let mut state = StatePayload::default();
            let message = sample(kind);
            let stored = state.store(&message, received);
            match kind.direction() {
                Direction::Feedback => {
                    assert!(stored, "{kind:?}");
                    assert_eq!(state.received(kind), Some((received, message)), "{kind:?}");
                }
                Direction::Command => {
                    assert!(!stored, "{kind:?}");
                    assert_eq!(state, StatePayload::default());
                }
            }
        }
    }
}
