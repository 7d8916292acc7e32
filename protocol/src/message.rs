//! Typed SCOUT v1 messages: the six payload bytes every CAN and serial frame carries.
//!
//! Each payload type has `parse` (6 bytes to a typed value, never failing: unknown raw values are
//! kept) and `emit` (the typed value back to the same 6 bytes). The links (CAN, serial) add the
//! rolling count and checksum around these bytes.

use crate::fault::FaultBits;
use crate::units;

/// The payload length shared by every message on both links.
pub const PAYLOAD_LEN: usize = 6;

/// Six payload bytes.
pub type Payload = [u8; PAYLOAD_LEN];

/// Field layout of the 0x130 motion command.
mod motion_command {
    pub const CONTROL_MODE: usize = 0;
    pub const FAULT_CLEAR: usize = 1;
    pub const LINEAR: usize = 2;
    pub const ANGULAR: usize = 3;
}

/// Field layout of the 0x140 light command and 0x141 light feedback.
mod light {
    pub const ENABLE: usize = 0;
    pub const FRONT_MODE: usize = 1;
    pub const FRONT_BRIGHTNESS: usize = 2;
    pub const REAR_MODE: usize = 3;
    pub const REAR_BRIGHTNESS: usize = 4;
}

/// Field layout of the 0x151 system status.
mod system_status {
    use core::ops::Range;
    pub const STATE: usize = 0;
    pub const CONTROL_MODE: usize = 1;
    pub const BATTERY: Range<usize> = 2..4;
    pub const FAULTS: Range<usize> = 4..6;
}

/// Field layout of the 0x131 motion feedback.
mod motion_feedback {
    use core::ops::Range;
    pub const LINEAR: Range<usize> = 0..2;
    pub const ANGULAR: Range<usize> = 2..4;
}

/// Field layout of the 0x200..0x203 motor driver feedback.
mod motor_feedback {
    use core::ops::Range;
    pub const CURRENT: Range<usize> = 0..2;
    pub const RPM: Range<usize> = 2..4;
    pub const DRIVER_TEMPERATURE: usize = 4;
    pub const MOTOR_TEMPERATURE: usize = 5;
}

fn read_i16(payload: &Payload, field: core::ops::Range<usize>) -> i16 {
    i16::from_be_bytes([payload[field.start], payload[field.start + 1]])
}

fn read_u16(payload: &Payload, field: core::ops::Range<usize>) -> u16 {
    u16::from_be_bytes([payload[field.start], payload[field.start + 1]])
}

fn write_bytes(payload: &mut Payload, field: core::ops::Range<usize>, bytes: [u8; 2]) {
    payload[field].copy_from_slice(&bytes);
}

/// Declares a `u8`-backed enum whose unknown raw values are kept in `Unknown(u8)`.
macro_rules! raw_enum {
    ($(#[$meta:meta])* $name:ident { $($(#[$vmeta:meta])* $variant:ident = $value:literal => $text:literal,)+ }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
        #[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
        pub enum $name {
            $($(#[$vmeta])* $variant,)+
            /// A raw value the manual does not define, kept as received.
            Unknown(u8),
        }

        impl $name {
            /// The typed value of a raw byte.
            pub const fn from_raw(raw: u8) -> Self {
                match raw {
                    $($value => Self::$variant,)+
                    other => Self::Unknown(other),
                }
            }

            /// The raw byte on the wire.
            pub const fn raw(self) -> u8 {
                match self {
                    $(Self::$variant => $value,)+
                    Self::Unknown(raw) => raw,
                }
            }

            /// The snake_case name used in JSON and logs (`unknown` for unknown values).
            pub const fn name(self) -> &'static str {
                match self {
                    $(Self::$variant => $text,)+
                    Self::Unknown(_) => "unknown",
                }
            }
        }

        impl core::fmt::Display for $name {
            fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
                match self {
                    Self::Unknown(raw) => write!(f, "unknown(0x{raw:02x})"),
                    known => f.write_str(known.name()),
                }
            }
        }
    };
}

pub(crate) use raw_enum;

raw_enum! {
    /// Who controls the chassis (0x130 byte 0, 0x151 byte 1).
    ControlMode {
        /// The RC transmitter drives.
        Rc = 0x00 => "rc",
        /// CAN command mode: every CAN 0x130 must carry this.
        Can = 0x01 => "can",
        /// Serial command mode: every serial motion command must carry this.
        Serial = 0x02 => "serial",
    }
}

raw_enum! {
    /// The chassis state in 0x151 byte 0 (the v1.2 manual prints 0x01 twice; 0x02 is exception).
    ChassisState {
        /// Normal operation.
        Normal = 0x00 => "normal",
        /// Emergency stop pressed.
        EStop = 0x01 => "estop",
        /// System exception.
        Exception = 0x02 => "exception",
    }
}

raw_enum! {
    /// The fault-clear code of 0x130 byte 1.
    FaultClear {
        /// No fault to clear.
        None = 0x00 => "none",
        /// Clear the battery under-voltage fault.
        BatteryUnderVoltage = 0x01 => "battery_undervoltage",
        /// Clear the battery over-voltage fault.
        BatteryOverVoltage = 0x02 => "battery_overvoltage",
        /// Clear the motor 1 communication fault.
        Motor1Comm = 0x03 => "motor_1_comm",
        /// Clear the motor 2 communication fault.
        Motor2Comm = 0x04 => "motor_2_comm",
        /// Clear the motor 3 communication fault.
        Motor3Comm = 0x05 => "motor_3_comm",
        /// Clear the motor 4 communication fault.
        Motor4Comm = 0x06 => "motor_4_comm",
        /// Clear the latched driver over-temperature protection.
        DriverOverTemp = 0x07 => "driver_overtemp",
        /// Clear the latched motor over-current protection.
        MotorOverCurrent = 0x08 => "motor_overcurrent",
    }
}

impl FaultClear {
    /// Every defined code that clears something, in code order.
    pub const ALL: [FaultClear; 8] = [
        Self::BatteryUnderVoltage,
        Self::BatteryOverVoltage,
        Self::Motor1Comm,
        Self::Motor2Comm,
        Self::Motor3Comm,
        Self::Motor4Comm,
        Self::DriverOverTemp,
        Self::MotorOverCurrent,
    ];

    /// The code for a name as printed by [`FaultClear::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .chain([Self::None])
            .find(|code| code.name() == name)
    }
}

raw_enum! {
    /// A light's mode (0x140 and 0x141 bytes 1 and 3).
    LightMode {
        /// Always off.
        Off = 0x00 => "off",
        /// Always on.
        On = 0x01 => "on",
        /// Breathing: the chassis animates the brightness.
        Breath = 0x02 => "breath",
        /// The brightness given in the frame.
        Custom = 0x03 => "custom",
    }
}

impl LightMode {
    /// The four defined modes.
    pub const ALL: [LightMode; 4] = [Self::Off, Self::On, Self::Breath, Self::Custom];

    /// The mode for a name as printed by [`LightMode::name`] (`off`, `on`, `breath`, `custom`).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|mode| mode.name() == name)
    }
}

/// One light (front or rear): its mode and brightness (0..100, used in custom mode).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Light {
    /// The mode.
    pub mode: LightMode,
    /// Brightness 0..100 as sent or reported (the chassis may report any byte).
    pub brightness: u8,
}

#[allow(clippy::derivable_impls, reason = "the enum is declared by raw_enum!")]
impl Default for LightMode {
    fn default() -> Self {
        Self::Off
    }
}

/// 0x130: the motion command, host to chassis, every 20 ms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotionCommand {
    /// Must be [`ControlMode::Can`] on CAN and [`ControlMode::Serial`] on serial.
    pub control_mode: ControlMode,
    /// A fault to clear, or [`FaultClear::None`].
    pub fault_clear: FaultClear,
    /// Percent of the maximum linear speed (1.5 m/s); -100..100 on the wire, any i8 decoded.
    pub linear_percent: i8,
    /// Percent of the maximum angular speed; -100..100 on the wire, any i8 decoded.
    pub angular_percent: i8,
}

impl MotionCommand {
    /// A command of zero speed in the given mode.
    pub const fn stop(control_mode: ControlMode) -> Self {
        Self {
            control_mode,
            fault_clear: FaultClear::None,
            linear_percent: 0,
            angular_percent: 0,
        }
    }

    /// Parses the payload.
    pub fn parse(payload: &Payload) -> Self {
        use motion_command::*;
        Self {
            control_mode: ControlMode::from_raw(payload[CONTROL_MODE]),
            fault_clear: FaultClear::from_raw(payload[FAULT_CLEAR]),
            linear_percent: payload[LINEAR] as i8,
            angular_percent: payload[ANGULAR] as i8,
        }
    }

    /// Writes the payload.
    pub fn emit(&self, payload: &mut Payload) {
        use motion_command::*;
        *payload = [0; PAYLOAD_LEN];
        payload[CONTROL_MODE] = self.control_mode.raw();
        payload[FAULT_CLEAR] = self.fault_clear.raw();
        payload[LINEAR] = self.linear_percent as u8;
        payload[ANGULAR] = self.angular_percent as u8;
    }

    /// The commanded linear speed in m/s, for a chassis whose 100 % is `max_linear` (the
    /// SCOUT's 1.5 m/s, [`units::MAX_LINEAR_SPEED`]; the vendor SDK scales a MINI's by 3.0).
    pub fn linear(&self, max_linear: f64) -> f64 {
        units::percent_to_speed(self.linear_percent, max_linear)
    }

    /// The commanded angular speed in rad/s, for a chassis whose maximum is `max_angular`.
    pub fn angular(&self, max_angular: f64) -> f64 {
        units::percent_to_speed(self.angular_percent, max_angular)
    }
}

/// 0x140: the light command, host to chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LightCommand {
    /// `true`: the host controls the lights; `false`: the chassis runs its own light logic.
    pub enabled: bool,
    /// The front light.
    pub front: Light,
    /// The rear light.
    pub rear: Light,
}

/// 0x141: the light feedback, chassis to host. Same layout as the command.
pub type LightFeedback = LightCommand;

impl LightCommand {
    /// Parses the payload (any non-zero enable byte counts as enabled).
    pub fn parse(payload: &Payload) -> Self {
        use light::*;
        Self {
            enabled: payload[ENABLE] != 0,
            front: Light {
                mode: LightMode::from_raw(payload[FRONT_MODE]),
                brightness: payload[FRONT_BRIGHTNESS],
            },
            rear: Light {
                mode: LightMode::from_raw(payload[REAR_MODE]),
                brightness: payload[REAR_BRIGHTNESS],
            },
        }
    }

    /// Writes the payload.
    pub fn emit(&self, payload: &mut Payload) {
        use light::*;
        *payload = [0; PAYLOAD_LEN];
        payload[ENABLE] = u8::from(self.enabled);
        payload[FRONT_MODE] = self.front.mode.raw();
        payload[FRONT_BRIGHTNESS] = self.front.brightness;
        payload[REAR_MODE] = self.rear.mode.raw();
        payload[REAR_BRIGHTNESS] = self.rear.brightness;
    }
}

/// 0x151: the system status, chassis to host, every 20 ms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SystemStatus {
    /// Normal, e-stop or exception.
    pub state: ChassisState,
    /// Who controls the chassis.
    pub control_mode: ControlMode,
    /// Battery voltage in tenths of a volt.
    pub battery_decivolts: u16,
    /// The 16 fault bits.
    pub faults: FaultBits,
}

impl SystemStatus {
    /// Parses the payload.
    pub fn parse(payload: &Payload) -> Self {
        use system_status::*;
        Self {
            state: ChassisState::from_raw(payload[STATE]),
            control_mode: ControlMode::from_raw(payload[CONTROL_MODE]),
            battery_decivolts: read_u16(payload, BATTERY),
            faults: FaultBits(read_u16(payload, FAULTS)),
        }
    }

    /// Writes the payload.
    pub fn emit(&self, payload: &mut Payload) {
        use system_status::*;
        *payload = [0; PAYLOAD_LEN];
        payload[STATE] = self.state.raw();
        payload[CONTROL_MODE] = self.control_mode.raw();
        write_bytes(payload, BATTERY, self.battery_decivolts.to_be_bytes());
        write_bytes(payload, FAULTS, self.faults.0.to_be_bytes());
    }

    /// Battery voltage in volts.
    pub fn battery_voltage(&self) -> f64 {
        f64::from(self.battery_decivolts) / 10.0
    }
}

/// 0x131: the motion feedback, chassis to host, every 20 ms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotionFeedback {
    /// Linear speed in mm/s (m/s x 1000).
    pub linear_mm_s: i16,
    /// Angular speed in mrad/s (rad/s x 1000).
    pub angular_mrad_s: i16,
}

impl MotionFeedback {
    /// Parses the payload.
    pub fn parse(payload: &Payload) -> Self {
        use motion_feedback::*;
        Self {
            linear_mm_s: read_i16(payload, LINEAR),
            angular_mrad_s: read_i16(payload, ANGULAR),
        }
    }

    /// Writes the payload.
    pub fn emit(&self, payload: &mut Payload) {
        use motion_feedback::*;
        *payload = [0; PAYLOAD_LEN];
        write_bytes(payload, LINEAR, self.linear_mm_s.to_be_bytes());
        write_bytes(payload, ANGULAR, self.angular_mrad_s.to_be_bytes());
    }

    /// Linear speed in m/s.
    pub fn linear(&self) -> f64 {
        f64::from(self.linear_mm_s) / 1000.0
    }

    /// Angular speed in rad/s.
    pub fn angular(&self) -> f64 {
        f64::from(self.angular_mrad_s) / 1000.0
    }
}

/// A motor: 1..4 (vendor SDK: 1 front-right, 2 front-left, 3 rear-left, 4 rear-right).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Motor(u8);

impl Motor {
    /// The four motors in order.
    pub const ALL: [Motor; 4] = [Motor(1), Motor(2), Motor(3), Motor(4)];

    /// Motor `number` (1..=4), or `None`.
    pub const fn new(number: u8) -> Option<Self> {
        match number {
            1..=4 => Some(Self(number)),
            _ => None,
        }
    }

    /// The motor number, 1..=4.
    pub const fn number(self) -> u8 {
        self.0
    }

    /// The index 0..=3.
    pub const fn index(self) -> usize {
        self.0 as usize - 1
    }
}

/// 0x200..0x203: one motor driver's feedback, chassis to host, every 20 ms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotorFeedback {
    /// Which motor (from the frame id).
    pub motor: Motor,
    /// Current in tenths of an ampere; signed (negative currents occur in practice).
    pub current_deciamps: i16,
    /// Motor shaft speed in rpm.
    pub rpm: i16,
    /// Driver temperature in deg C, signed.
    pub driver_temperature: i8,
    /// Motor temperature in deg C, signed (reserved, 0, in manual v1.2).
    pub motor_temperature: i8,
}

impl MotorFeedback {
    /// Parses the payload of `motor`'s frame.
    pub fn parse(motor: Motor, payload: &Payload) -> Self {
        use motor_feedback::*;
        Self {
            motor,
            current_deciamps: read_i16(payload, CURRENT),
            rpm: read_i16(payload, RPM),
            driver_temperature: payload[DRIVER_TEMPERATURE] as i8,
            motor_temperature: payload[MOTOR_TEMPERATURE] as i8,
        }
    }

    /// Writes the payload (the motor number goes in the frame id, not here).
    pub fn emit(&self, payload: &mut Payload) {
        use motor_feedback::*;
        *payload = [0; PAYLOAD_LEN];
        write_bytes(payload, CURRENT, self.current_deciamps.to_be_bytes());
        write_bytes(payload, RPM, self.rpm.to_be_bytes());
        payload[DRIVER_TEMPERATURE] = self.driver_temperature as u8;
        payload[MOTOR_TEMPERATURE] = self.motor_temperature as u8;
    }

    /// Current in amperes.
    pub fn current(&self) -> f64 {
        f64::from(self.current_deciamps) / 10.0
    }
}

/// Which message a frame carries; the key both links map to their ids.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub enum MessageKind {
    /// 0x130, host to chassis.
    MotionCommand,
    /// 0x140, host to chassis.
    LightCommand,
    /// 0x151, chassis to host.
    SystemStatus,
    /// 0x131, chassis to host.
    MotionFeedback,
    /// 0x200..0x203, chassis to host.
    MotorFeedback(Motor),
    /// 0x141, chassis to host.
    LightFeedback,
}

/// Which way a message travels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Host to chassis (commands).
    Command,
    /// Chassis to host (feedback).
    Feedback,
}

impl MessageKind {
    /// Every kind, in a fixed order ([`MessageKind::index`] is the position here).
    pub const ALL: [MessageKind; 9] = [
        Self::MotionCommand,
        Self::LightCommand,
        Self::SystemStatus,
        Self::MotionFeedback,
        Self::MotorFeedback(Motor(1)),
        Self::MotorFeedback(Motor(2)),
        Self::MotorFeedback(Motor(3)),
        Self::MotorFeedback(Motor(4)),
        Self::LightFeedback,
    ];

    /// The number of kinds.
    pub const COUNT: usize = Self::ALL.len();

    /// The position in [`MessageKind::ALL`], for per-kind tables.
    pub const fn index(self) -> usize {
        match self {
            Self::MotionCommand => 0,
            Self::LightCommand => 1,
            Self::SystemStatus => 2,
            Self::MotionFeedback => 3,
            Self::MotorFeedback(motor) => 3 + motor.0 as usize,
            Self::LightFeedback => 8,
        }
    }

    /// The CAN id.
    pub const fn can_id(self) -> u16 {
        match self {
            Self::MotionCommand => 0x130,
            Self::LightCommand => 0x140,
            Self::SystemStatus => 0x151,
            Self::MotionFeedback => 0x131,
            Self::MotorFeedback(motor) => 0x1FF + motor.0 as u16,
            Self::LightFeedback => 0x141,
        }
    }

    /// The kind of a CAN id, or `None` for an id SCOUT v1 does not use.
    pub const fn from_can_id(id: u16) -> Option<Self> {
        Some(match id {
            0x130 => Self::MotionCommand,
            0x140 => Self::LightCommand,
            0x151 => Self::SystemStatus,
            0x131 => Self::MotionFeedback,
            0x200..=0x203 => Self::MotorFeedback(Motor((id - 0x1FF) as u8)),
            0x141 => Self::LightFeedback,
            _ => return None,
        })
    }

    /// Command or feedback.
    pub const fn direction(self) -> Direction {
        match self {
            Self::MotionCommand | Self::LightCommand => Direction::Command,
            Self::SystemStatus
            | Self::MotionFeedback
            | Self::MotorFeedback(_)
            | Self::LightFeedback => Direction::Feedback,
        }
    }

    /// The serial frame's command id (byte 5); the type byte follows from [`MessageKind::direction`].
    pub const fn serial_id(self) -> u8 {
        match self {
            Self::MotionCommand | Self::SystemStatus => 0x01,
            Self::LightCommand | Self::MotionFeedback => 0x02,
            Self::MotorFeedback(motor) => 0x02 + motor.0,
            Self::LightFeedback => 0x07,
        }
    }

    /// The kind of a serial (direction, id) pair, or `None` for a pair the protocol does not use.
    pub const fn from_serial(direction: Direction, id: u8) -> Option<Self> {
        Some(match (direction, id) {
            (Direction::Command, 0x01) => Self::MotionCommand,
            (Direction::Command, 0x02) => Self::LightCommand,
            (Direction::Feedback, 0x01) => Self::SystemStatus,
            (Direction::Feedback, 0x02) => Self::MotionFeedback,
            (Direction::Feedback, 0x03..=0x06) => Self::MotorFeedback(Motor(id - 0x02)),
            (Direction::Feedback, 0x07) => Self::LightFeedback,
            _ => return None,
        })
    }

    /// The snake_case name used in JSON and logs.
    pub const fn name(self) -> &'static str {
        match self {
            Self::MotionCommand => "motion_command",
            Self::LightCommand => "light_command",
            Self::SystemStatus => "system_status",
            Self::MotionFeedback => "motion_feedback",
            Self::MotorFeedback(_) => "motor_feedback",
            Self::LightFeedback => "light_feedback",
        }
    }
}

/// Any SCOUT v1 message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Message {
    /// 0x130.
    MotionCommand(MotionCommand),
    /// 0x140.
    LightCommand(LightCommand),
    /// 0x151.
    SystemStatus(SystemStatus),
    /// 0x131.
    MotionFeedback(MotionFeedback),
    /// 0x200..0x203.
    MotorFeedback(MotorFeedback),
    /// 0x141.
    LightFeedback(LightFeedback),
}

impl Message {
    /// The kind of this message.
    pub const fn kind(&self) -> MessageKind {
        match self {
            Self::MotionCommand(_) => MessageKind::MotionCommand,
            Self::LightCommand(_) => MessageKind::LightCommand,
            Self::SystemStatus(_) => MessageKind::SystemStatus,
            Self::MotionFeedback(_) => MessageKind::MotionFeedback,
            Self::MotorFeedback(feedback) => MessageKind::MotorFeedback(feedback.motor),
            Self::LightFeedback(_) => MessageKind::LightFeedback,
        }
    }

    /// Parses the payload of a message of `kind`.
    pub fn parse(kind: MessageKind, payload: &Payload) -> Self {
        match kind {
            MessageKind::MotionCommand => Self::MotionCommand(MotionCommand::parse(payload)),
            MessageKind::LightCommand => Self::LightCommand(LightCommand::parse(payload)),
            MessageKind::SystemStatus => Self::SystemStatus(SystemStatus::parse(payload)),
            MessageKind::MotionFeedback => Self::MotionFeedback(MotionFeedback::parse(payload)),
            MessageKind::MotorFeedback(motor) => {
                Self::MotorFeedback(MotorFeedback::parse(motor, payload))
            }
            MessageKind::LightFeedback => Self::LightFeedback(LightFeedback::parse(payload)),
        }
    }

    /// The six payload bytes.
    pub fn payload(&self) -> Payload {
        let mut payload = [0; PAYLOAD_LEN];
        match self {
            Self::MotionCommand(m) => m.emit(&mut payload),
            Self::LightCommand(m) | Self::LightFeedback(m) => m.emit(&mut payload),
            Self::SystemStatus(m) => m.emit(&mut payload),
            Self::MotionFeedback(m) => m.emit(&mut payload),
            Self::MotorFeedback(m) => m.emit(&mut payload),
        }
        payload
    }
}

/// A message with the rolling count it was received or sent with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Counted {
    /// The message.
    pub message: Message,
    /// The frame's rolling count (CAN byte 6, serial frame_id).
    pub count: u8,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_maps_to_its_ids_and_back() {
        for (index, kind) in MessageKind::ALL.into_iter().enumerate() {
            assert_eq!(kind.index(), index);
            assert_eq!(MessageKind::from_can_id(kind.can_id()), Some(kind));
            assert_eq!(
                MessageKind::from_serial(kind.direction(), kind.serial_id()),
                Some(kind)
            );
        }
    }

    #[test]
    fn capture_status_decodes_as_the_notes_say() {
        let status = SystemStatus::parse(&[0x01, 0x00, 0x00, 0xEF, 0x00, 0x3C]);
        assert_eq!(status.state, ChassisState::EStop);
        assert_eq!(status.control_mode, ControlMode::Rc);
        assert_eq!(status.battery_decivolts, 239);
    }

    #[test]
    fn motor_currents_and_temperatures_are_signed() {
        let motor = Motor::new(2).expect("motor 2");
        let feedback = MotorFeedback::parse(motor, &[0xFF, 0xF6, 0xFC, 0x18, 0xF6, 0xFB]);
        assert_eq!(feedback.current_deciamps, -10);
        assert_eq!(feedback.rpm, -1000);
        assert_eq!(feedback.driver_temperature, -10);
        assert_eq!(feedback.motor_temperature, -5);
    }

    #[test]
    fn unknown_raw_values_are_kept() {
        let command = MotionCommand::parse(&[0x07, 0x42, 0, 0, 0, 0]);
        assert_eq!(command.control_mode, ControlMode::Unknown(0x07));
        assert_eq!(command.fault_clear, FaultClear::Unknown(0x42));
        let mut payload = [0; PAYLOAD_LEN];
        command.emit(&mut payload);
        assert_eq!(payload, [0x07, 0x42, 0, 0, 0, 0]);
    }

    #[test]
    fn light_mode_names_round_trip() {
        for mode in LightMode::ALL {
            assert_eq!(LightMode::from_name(mode.name()), Some(mode));
        }
        assert_eq!(LightMode::from_name("disco"), None);
    }

    #[test]
    fn fault_clear_names_round_trip() {
        for code in FaultClear::ALL {
            assert_eq!(FaultClear::from_name(code.name()), Some(code));
        }
        assert_eq!(FaultClear::from_name("nonsense"), None);
    }
}
