//! AgileX protocol v2 (SCOUT 2.0, SCOUT MINI and MINI OMNI firmware since 2020) on CAN: every
//! frame a SCOUT host sends or receives, as named byte ranges, `decode` and `encode`.
//!
//! What sets v2 apart from v1 (protocol-v2-notes 1-3): other ids; every multi-byte field
//! big-endian in SI multiples (mm/s, mrad/s, 0.1 V, 0.1 A, mm); **no checksum**; a rolling count
//! in byte 7 of 0x121, 0x211, 0x231 and 0x241 only; a control-mode frame (0x421) the host must
//! send before the chassis obeys 0x111. Sans-IO and `no_std` like the rest of the crate.
//!
//! Where the documents disagree (the error bits of 0x211, the driver state bits, the numbering of
//! the control mode), every bit is decoded and kept: the bits all sources agree on are named, the
//! rest are reported as unknown rather than guessed.

use core::ops::Range;

use crate::can::CanFrame;
use crate::fault::Severity;
use crate::message::{ChassisState, LightMode, raw_enum};

/// The CAN ids of protocol v2 that concern a SCOUT (protocol-v2-notes 2).
pub mod id {
    /// Motion command, host to chassis, every 20 ms (the chassis stops after 500 ms without).
    pub const MOTION_COMMAND: u16 = 0x111;
    /// Light command, host to chassis.
    pub const LIGHT_COMMAND: u16 = 0x121;
    /// Motion-mode set, host to chassis: a Ranger's dual Ackermann, parallel, spin... (ugv_sdk
    /// `CAN_MSG_SET_MOTION_MODE_ID`, `SetMotionModeFrame`: the mode in byte 0).
    pub const SET_MOTION_MODE: u16 = 0x141;
    /// Parking brake, host to chassis: a Hunter's lock or release in byte 0 (ugv_sdk
    /// `CAN_MSG_BRAKING_COMMAND_ID`, `BrakeModeConfigFrame`; the Hunter 2.0 protocol sheet:
    /// "speed control needs the brake released"). v1's motion feedback has the same id.
    pub const BRAKE: u16 = 0x131;
    /// Control-mode set, host to chassis: standby, CAN, UART.
    pub const CONTROL_MODE: u16 = 0x421;
    /// Error clear, host to chassis.
    pub const ERROR_CLEAR: u16 = 0x441;
    /// Version request, older form (answered by 0x41A).
    pub const VERSION_REQUEST: u16 = 0x411;
    /// Version request (DLC 1) and its ASCII reply (DLC 8), current SDK form.
    pub const VERSION_TEXT: u16 = 0x4A1;
    /// System state, chassis to host.
    pub const SYSTEM_STATE: u16 = 0x211;
    /// Motion state, chassis to host.
    pub const MOTION_STATE: u16 = 0x221;
    /// Light state, chassis to host.
    pub const LIGHT_STATE: u16 = 0x231;
    /// RC transmitter state, chassis to host.
    pub const RC_STATE: u16 = 0x241;
    /// Actuator high-speed feedback of motor 1 (0x251..=0x254 for motors 1..=4).
    pub const ACTUATOR_HIGH: u16 = 0x251;
    /// Actuator low-speed feedback of motor 1 (0x261..=0x264 for motors 1..=4).
    pub const ACTUATOR_LOW: u16 = 0x261;
    /// Wheel odometers, chassis to host.
    pub const ODOMETER: u16 = 0x311;
    /// Steering motors' angles, chassis to host: a chassis with steered wheels (ugv_sdk
    /// `CAN_MSG_MOTOR_ANGLE_INFO`).
    pub const MOTOR_ANGLES: u16 = 0x271;
    /// Wheel motors' speeds of a steered chassis (ugv_sdk `CAN_MSG_MOTOR_SPEED_INFO`).
    pub const MOTOR_SPEEDS: u16 = 0x281;
    /// The motion mode and whether it is changing, chassis to host: a Ranger (ugv_sdk
    /// `CAN_MSG_CURRENT_CTRL_MODE`, parsed as `AgxMsgMotionModeState`).
    pub const MOTION_MODE_STATE: u16 = 0x291;
    /// Version reply, older binary form.
    pub const VERSION_BINARY: u16 = 0x41A;
    /// Smart battery (BMS): charge, health, voltage, current, temperature.
    pub const BMS: u16 = 0x361;
    /// Smart battery (BMS): alarm and warning bytes.
    pub const BMS_ALARM: u16 = 0x362;
}

/// Field layouts, as byte ranges of the data.
mod field {
    use core::ops::Range;

    /// 0x111 and 0x221.
    pub mod motion {
        use super::Range;
        pub const LINEAR: Range<usize> = 0..2;
        pub const ANGULAR: Range<usize> = 2..4;
        pub const LATERAL: Range<usize> = 4..6;
        pub const STEERING: Range<usize> = 6..8;
    }

    /// 0x121 and 0x231.
    pub mod light {
        pub const HOST_CONTROL: usize = 0;
        pub const FRONT_MODE: usize = 1;
        pub const FRONT_BRIGHTNESS: usize = 2;
        pub const REAR_MODE: usize = 3;
        pub const REAR_BRIGHTNESS: usize = 4;
    }

    /// 0x211.
    pub mod system {
        use super::Range;
        pub const STATE: usize = 0;
        pub const CONTROL_MODE: usize = 1;
        pub const BATTERY: Range<usize> = 2..4;
        pub const ERRORS: Range<usize> = 4..6;
        pub const RESERVED: usize = 6;
    }

    /// 0x241.
    pub mod rc {
        pub const SWITCHES: usize = 0;
        pub const RIGHT_HORIZONTAL: usize = 1;
        pub const RIGHT_VERTICAL: usize = 2;
        pub const LEFT_VERTICAL: usize = 3;
        pub const LEFT_HORIZONTAL: usize = 4;
        pub const KNOB: usize = 5;
    }

    /// 0x251..=0x254.
    pub mod actuator_high {
        use super::Range;
        pub const RPM: Range<usize> = 0..2;
        pub const CURRENT: Range<usize> = 2..4;
        pub const PULSES: Range<usize> = 4..8;
    }

    /// 0x261..=0x264.
    pub mod actuator_low {
        use super::Range;
        pub const DRIVER_VOLTAGE: Range<usize> = 0..2;
        pub const DRIVER_TEMPERATURE: Range<usize> = 2..4;
        pub const MOTOR_TEMPERATURE: usize = 4;
        pub const DRIVER_STATE: usize = 5;
    }

    /// 0x271 and 0x281: one value per wheel, front left, front right, rear left, rear right.
    pub mod wheels {
        use super::Range;
        pub const WHEEL: [Range<usize>; 4] = [0..2, 2..4, 4..6, 6..8];
    }

    /// 0x291.
    pub mod motion_mode {
        pub const MODE: usize = 0;
        pub const CHANGING: usize = 1;
    }

    /// 0x311.
    pub mod odometer {
        use super::Range;
        pub const LEFT: Range<usize> = 0..4;
        pub const RIGHT: Range<usize> = 4..8;
    }

    /// 0x41A.
    pub mod version {
        use super::Range;
        pub const CONTROLLER_HARDWARE: Range<usize> = 0..2;
        pub const DRIVER_HARDWARE: Range<usize> = 2..4;
        pub const CONTROLLER_SOFTWARE: Range<usize> = 4..6;
        pub const DRIVER_SOFTWARE: Range<usize> = 6..8;
    }

    /// 0x361.
    pub mod bms {
        use super::Range;
        pub const CHARGE: usize = 0;
        pub const HEALTH: usize = 1;
        pub const VOLTAGE: Range<usize> = 2..4;
        pub const CURRENT: Range<usize> = 4..6;
        pub const TEMPERATURE: Range<usize> = 6..8;
    }

    /// The rolling count of the frames that carry one.
    pub const COUNT: usize = 7;
    /// The one meaningful byte of the on-demand frames (0x421, 0x441, 0x411, 0x4A1 request).
    pub const CODE: usize = 0;
}

/// The data length of every v2 frame the host sends, and of every frame the chassis sends.
pub const DLC: u8 = 8;

fn i16_at(data: &[u8; 8], range: Range<usize>) -> i16 {
    i16::from_be_bytes([data[range.start], data[range.start + 1]])
}

fn u16_at(data: &[u8; 8], range: Range<usize>) -> u16 {
    u16::from_be_bytes([data[range.start], data[range.start + 1]])
}

fn i32_at(data: &[u8; 8], range: Range<usize>) -> i32 {
    let mut bytes = [0; 4];
    bytes.copy_from_slice(&data[range]);
    i32::from_be_bytes(bytes)
}

fn put(data: &mut [u8; 8], range: Range<usize>, bytes: &[u8]) {
    data[range].copy_from_slice(bytes);
}

raw_enum! {
    /// Who controls a v2 chassis (0x211 byte 1, 0x421 byte 0). Firmware and SDKs before late
    /// 2023 numbered it 0 = RC; read anything but [`ControlModeV2::Can`] as "not ours".
    ControlModeV2 {
        /// Standby: the power-on default; the chassis obeys only 0x421.
        Standby = 0x00 => "standby",
        /// CAN command mode: the host drives.
        Can = 0x01 => "can",
        /// UART command mode.
        Uart = 0x02 => "uart",
        /// The RC transmitter drives.
        Rc = 0x03 => "rc",
    }
}

raw_enum! {
    /// What 0x441 clears: everything, or one motor's error.
    ErrorClearV2 {
        /// Every error.
        All = 0x00 => "all",
        /// Motor 1's error.
        Motor1 = 0x01 => "motor_1",
        /// Motor 2's error.
        Motor2 = 0x02 => "motor_2",
        /// Motor 3's error.
        Motor3 = 0x03 => "motor_3",
        /// Motor 4's error.
        Motor4 = 0x04 => "motor_4",
    }
}

raw_enum! {
    /// A Ranger's motion mode (0x141 byte 0, 0x291 byte 0), as the vendor SDK numbers them
    /// (ugv_sdk `ranger_interface.hpp` `MotionMode`; agilex-family-notes: Ranger Mini 2.0 and
    /// 3.0; the Mini 1.0 numbers side slip 3).
    MotionModeV2 {
        /// Both axles steer, mirrored: turns on a circle no tighter than its minimum radius.
        DualAckermann = 0x00 => "dual_ackermann",
        /// Every wheel at one angle: moves in any direction without turning.
        Parallel = 0x01 => "parallel",
        /// The wheels tangent to a circle about the centre: turns in place.
        Spin = 0x02 => "spin",
        /// The wheels set to hold the robot still.
        Park = 0x03 => "park",
        /// Straight sideways.
        SideSlip = 0x04 => "side_slip",
    }
}

raw_enum! {
    /// A Hunter's parking brake: asked in 0x131 byte 0, reported in 0x211 byte 6 (ugv_sdk
    /// `AgxBrakeMode`: 0 unlock, 1 lock; the Hunter 2.0 manual's table 3.1: "0x00 Brake
    /// unlocked state, 0x01 Brake locked state").
    BrakeV2 {
        /// Free: the wheels may turn.
        Released = 0x00 => "released",
        /// Holding the wheels.
        Locked = 0x01 => "locked",
    }
}

raw_enum! {
    /// An RC switch's position (2 bits of 0x241 byte 0).
    SwitchPosition {
        /// Up (0b10).
        Up = 0b10 => "up",
        /// Middle (0b01; SWB and SWC only).
        Middle = 0b01 => "middle",
        /// Down (0b11).
        Down = 0b11 => "down",
    }
}

/// A bit field with the bits the sources agree on named; the others are unknown.
macro_rules! named_bits {
    ($(#[$meta:meta])* $name:ident($raw:ty) { $($(#[$bmeta:meta])* $mask:literal => $text:literal,)+ }) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
        #[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
        pub struct $name(pub $raw);

        impl $name {
            /// Every named bit: its mask and name.
            pub const NAMED: &'static [($raw, &'static str)] = &[$(($mask, $text),)+];

            /// The bits no source names for a SCOUT.
            pub const fn unknown(self) -> $raw {
                self.0 & !(0 $(| $mask)+)
            }

            /// The names of the named bits that are set, in bit order.
            pub fn names(self) -> impl Iterator<Item = &'static str> {
                Self::NAMED
                    .iter()
                    .filter(move |(mask, _)| self.0 & mask != 0)
                    .map(|(_, name)| *name)
            }
        }
    };
}

named_bits! {
    /// 0x211 bytes 4-5 as one big-endian u16, named as the vendor SDK masks them (SCOUT 1.0's
    /// 2020 manual puts three of them in byte 4 instead; protocol-v2-notes 3.6). 0x0080 (the
    /// SDK's HUNTER steering encoder; a Bunker Mini reports it in e-stop) and the top six bits
    /// are unknown.
    ErrorBitsV2(u16) {
        /// Battery under-voltage fault (cut-off).
        0x0001 => "battery_undervoltage_fault",
        /// Battery under-voltage warning.
        0x0002 => "battery_undervoltage_warning",
        /// RC signal lost.
        0x0004 => "rc_signal_lost",
        /// Motor 1 communication lost.
        0x0008 => "motor_1_comm",
        /// Motor 2 communication lost.
        0x0010 => "motor_2_comm",
        /// Motor 3 communication lost.
        0x0020 => "motor_3_comm",
        /// Motor 4 communication lost.
        0x0040 => "motor_4_comm",
        /// Motor driver error.
        0x0100 => "motor_driver",
        /// Host (high-level) communication error.
        0x0200 => "host_comm",
    }
}

impl ErrorBitsV2 {
    /// How serious a named bit is, as this project acts on it: the under-voltage warning and a
    /// lost RC signal are warnings; the cut-off, a motor's or the driver's error and the host
    /// communication error are faults (the gateway stops the robot while one is set). `None`
    /// for an unnamed mask.
    pub const fn severity(mask: u16) -> Option<Severity> {
        Some(match mask {
            0x0002 | 0x0004 => Severity::Warning,
            0x0001 | 0x0008 | 0x0010 | 0x0020 | 0x0040 | 0x0100 | 0x0200 => Severity::Fault,
            _ => return None,
        })
    }

    /// Every set bit with its severity, in bit order: named bits by name, the others as
    /// `unknown_bit_N` with [`Severity::Reserved`] (reported, never acted on: a Bunker Mini sets
    /// 0x0080 while in e-stop).
    pub fn faults(self) -> impl Iterator<Item = (&'static str, Severity)> {
        (0..16u16)
            .map(|bit| 1u16 << bit)
            .filter(move |mask| self.0 & mask != 0)
            .map(|mask| {
                let named = Self::NAMED.iter().find(|(m, _)| *m == mask);
                match (named, Self::severity(mask)) {
                    (Some((_, name)), Some(severity)) => (*name, severity),
                    _ => (
                        UNKNOWN_BITS[mask.trailing_zeros() as usize],
                        Severity::Reserved,
                    ),
                }
            })
    }
}

/// Names for bits no source names.
const UNKNOWN_BITS: [&str; 16] = [
    "unknown_bit_0",
    "unknown_bit_1",
    "unknown_bit_2",
    "unknown_bit_3",
    "unknown_bit_4",
    "unknown_bit_5",
    "unknown_bit_6",
    "unknown_bit_7",
    "unknown_bit_8",
    "unknown_bit_9",
    "unknown_bit_10",
    "unknown_bit_11",
    "unknown_bit_12",
    "unknown_bit_13",
    "unknown_bit_14",
    "unknown_bit_15",
];

named_bits! {
    /// 0x261..=0x264 byte 5: the motor driver's state. Bits 0-4 as the SCOUT manual names
    /// them (the SDK calls bit 2 "overload" and bit 4 "sensor fault"); bits 5-7 mean different
    /// things in each source (driver fault, enabled, disabled, reset) and are unknown.
    DriverStateV2(u8) {
        /// Supply voltage low.
        0x01 => "supply_voltage_low",
        /// Motor over-temperature.
        0x02 => "motor_overtemp",
        /// Over-current.
        0x04 => "overcurrent",
        /// Driver over-temperature.
        0x08 => "driver_overtemp",
        /// The CAN link to the driver is lost.
        0x10 => "driver_link_lost",
    }
}

/// 0x111 (command) and 0x221 (state): body rates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotionV2 {
    /// Forward speed, mm/s.
    pub linear_mm_s: i16,
    /// Yaw rate, mrad/s, counter-clockwise seen from above.
    pub angular_mrad_s: i16,
    /// Leftward speed, mm/s (MINI OMNI only; 0 otherwise).
    pub lateral_mm_s: i16,
    /// Steering angle, mrad (Ackermann robots; 0 on a SCOUT).
    pub steering_mrad: i16,
}

impl MotionV2 {
    /// The rates for `linear` m/s and `angular` rad/s, rounded to the wire's unit and saturated
    /// at its range (non-finite values give 0). Lateral and steering 0.
    pub fn from_si(linear: f64, angular: f64) -> Self {
        Self {
            linear_mm_s: thousandths(linear),
            angular_mrad_s: thousandths(angular),
            lateral_mm_s: 0,
            steering_mrad: 0,
        }
    }

    /// These rates with a leftward speed of `lateral` m/s (the SCOUT MINI OMNI's bytes 4-5:
    /// vendor SDK `MotionCommandFrame.lateral_velocity`), rounded and saturated alike.
    pub fn with_lateral(self, lateral: f64) -> Self {
        Self {
            lateral_mm_s: thousandths(lateral),
            ..self
        }
    }

    /// These rates with the inner wheel's steering angle `steering` rad (a steered chassis'
    /// bytes 6-7: vendor SDK `MotionCommandFrame.steering_angle`), rounded and saturated alike.
    pub fn with_steering(self, steering: f64) -> Self {
        Self {
            steering_mrad: thousandths(steering),
            ..self
        }
    }

    /// rad, the inner wheel's steering angle.
    pub fn steering(&self) -> f64 {
        f64::from(self.steering_mrad) / 1000.0
    }

    /// These rates held within `linear`, `angular`, `lateral` and `steering` (m/s, rad/s,
    /// m/s, rad; each non-negative) once rounded: a limit that is not a whole number of the wire's unit rounds
    /// down (0.5235 rad/s is 523 mrad/s, where rounding the rate would send 524). What a
    /// chassis receives is never beyond its model's limits.
    pub fn within(self, linear: f64, angular: f64, lateral: f64, steering: f64) -> Self {
        let hold = |value: i16, limit: f64| {
            // Whole units below the limit, with a margin for the limit's own binary error.
            let most = (limit * 1000.0 + 1e-6).clamp(0.0, f64::from(i16::MAX)) as i16;
            value.clamp(-most, most)
        };
        Self {
            linear_mm_s: hold(self.linear_mm_s, linear),
            angular_mrad_s: hold(self.angular_mrad_s, angular),
            lateral_mm_s: hold(self.lateral_mm_s, lateral),
            steering_mrad: hold(self.steering_mrad, steering),
        }
    }

    /// m/s.
    pub fn linear(&self) -> f64 {
        f64::from(self.linear_mm_s) / 1000.0
    }

    /// rad/s.
    pub fn angular(&self) -> f64 {
        f64::from(self.angular_mrad_s) / 1000.0
    }

    /// m/s.
    pub fn lateral(&self) -> f64 {
        f64::from(self.lateral_mm_s) / 1000.0
    }

    fn parse(data: &[u8; 8]) -> Self {
        use field::motion::*;
        Self {
            linear_mm_s: i16_at(data, LINEAR),
            angular_mrad_s: i16_at(data, ANGULAR),
            lateral_mm_s: i16_at(data, LATERAL),
            steering_mrad: i16_at(data, STEERING),
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::motion::*;
        put(data, LINEAR, &self.linear_mm_s.to_be_bytes());
        put(data, ANGULAR, &self.angular_mrad_s.to_be_bytes());
        put(data, LATERAL, &self.lateral_mm_s.to_be_bytes());
        put(data, STEERING, &self.steering_mrad.to_be_bytes());
    }
}

/// `value` × 1000, rounded and saturated to an i16 (0 for NaN).
fn thousandths(value: f64) -> i16 {
    let scaled = value * 1000.0;
    if scaled.is_nan() {
        0
    } else if scaled >= f64::from(i16::MAX) {
        i16::MAX
    } else if scaled <= f64::from(i16::MIN) {
        i16::MIN
    } else {
        // Round half away from zero without `f64::round` (not in core).
        (scaled + if scaled < 0.0 { -0.5 } else { 0.5 }) as i16
    }
}

/// 0x121 (command) and 0x231 (state): the lights.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct LightsV2 {
    /// Byte 0: 1 when the host controls the lights, 0 for the chassis' own behaviour (other
    /// values kept as received).
    pub host_control: u8,
    /// Front light mode.
    pub front_mode: LightMode,
    /// Front brightness 0..100 (custom mode).
    pub front_brightness: u8,
    /// Rear light mode.
    pub rear_mode: LightMode,
    /// Rear brightness 0..100 (custom mode).
    pub rear_brightness: u8,
    /// Bytes 5-6, reserved.
    pub reserved: [u8; 2],
    /// The rolling count (byte 7).
    pub count: u8,
}

impl LightsV2 {
    /// Whether the host controls the lights.
    pub const fn host_controls(&self) -> bool {
        self.host_control == 1
    }

    fn parse(data: &[u8; 8]) -> Self {
        use field::light::*;
        Self {
            host_control: data[HOST_CONTROL],
            front_mode: LightMode::from_raw(data[FRONT_MODE]),
            front_brightness: data[FRONT_BRIGHTNESS],
            rear_mode: LightMode::from_raw(data[REAR_MODE]),
            rear_brightness: data[REAR_BRIGHTNESS],
            reserved: [data[5], data[6]],
            count: data[field::COUNT],
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::light::*;
        data[HOST_CONTROL] = self.host_control;
        data[FRONT_MODE] = self.front_mode.raw();
        data[FRONT_BRIGHTNESS] = self.front_brightness;
        data[REAR_MODE] = self.rear_mode.raw();
        data[REAR_BRIGHTNESS] = self.rear_brightness;
        data[5..7].copy_from_slice(&self.reserved);
        data[field::COUNT] = self.count;
    }
}

/// 0x211: the chassis' system state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SystemStateV2 {
    /// Normal, e-stop or exception (the same values as v1's 0x151 byte 0).
    pub state: ChassisState,
    /// Who controls the chassis.
    pub control_mode: ControlModeV2,
    /// Battery voltage, 0.1 V.
    pub battery_decivolts: u16,
    /// The error bits.
    pub errors: ErrorBitsV2,
    /// Byte 6: reserved on a SCOUT, a Hunter's parking brake ([`SystemStateV2::brake`]).
    pub reserved: u8,
    /// The rolling count (byte 7).
    pub count: u8,
}

impl SystemStateV2 {
    /// Byte 6 read as a Hunter's parking brake (on other models it is reserved, 0).
    pub const fn brake(&self) -> BrakeV2 {
        BrakeV2::from_raw(self.reserved)
    }

    /// Battery voltage, V.
    pub fn battery_voltage(&self) -> f64 {
        f64::from(self.battery_decivolts) / 10.0
    }

    fn parse(data: &[u8; 8]) -> Self {
        use field::system::*;
        Self {
            state: ChassisState::from_raw(data[STATE]),
            control_mode: ControlModeV2::from_raw(data[CONTROL_MODE]),
            battery_decivolts: u16_at(data, BATTERY),
            errors: ErrorBitsV2(u16_at(data, ERRORS)),
            reserved: data[RESERVED],
            count: data[field::COUNT],
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::system::*;
        data[STATE] = self.state.raw();
        data[CONTROL_MODE] = self.control_mode.raw();
        put(data, BATTERY, &self.battery_decivolts.to_be_bytes());
        put(data, ERRORS, &self.errors.0.to_be_bytes());
        data[RESERVED] = self.reserved;
        data[field::COUNT] = self.count;
    }
}

/// 0x241: the RC transmitter (sent by the SDK's firmware; not in the 2020 manual). Stick byte
/// order differs between SDK generations (protocol-v2-notes 3.8): the current one's is used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct RcStateV2 {
    /// SWA (bits 1:0): up, or down (a wireless e-stop on SCOUT V2.5 and newer).
    pub swa: SwitchPosition,
    /// SWB (bits 3:2): up is command mode, middle manual RC.
    pub swb: SwitchPosition,
    /// SWC (bits 5:4).
    pub swc: SwitchPosition,
    /// SWD (bits 7:6).
    pub swd: SwitchPosition,
    /// Right stick, horizontal.
    pub right_horizontal: i8,
    /// Right stick, vertical.
    pub right_vertical: i8,
    /// Left stick, vertical.
    pub left_vertical: i8,
    /// Left stick, horizontal.
    pub left_horizontal: i8,
    /// Knob VRA.
    pub knob: i8,
    /// Byte 6, reserved.
    pub reserved: u8,
    /// The rolling count (byte 7).
    pub count: u8,
}

impl RcStateV2 {
    fn parse(data: &[u8; 8]) -> Self {
        use field::rc::*;
        let switch = |shift: u8| SwitchPosition::from_raw((data[SWITCHES] >> shift) & 0b11);
        Self {
            swa: switch(0),
            swb: switch(2),
            swc: switch(4),
            swd: switch(6),
            right_horizontal: data[RIGHT_HORIZONTAL] as i8,
            right_vertical: data[RIGHT_VERTICAL] as i8,
            left_vertical: data[LEFT_VERTICAL] as i8,
            left_horizontal: data[LEFT_HORIZONTAL] as i8,
            knob: data[KNOB] as i8,
            reserved: data[6],
            count: data[field::COUNT],
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::rc::*;
        data[SWITCHES] = (self.swa.raw() & 0b11)
            | (self.swb.raw() & 0b11) << 2
            | (self.swc.raw() & 0b11) << 4
            | (self.swd.raw() & 0b11) << 6;
        data[RIGHT_HORIZONTAL] = self.right_horizontal as u8;
        data[RIGHT_VERTICAL] = self.right_vertical as u8;
        data[LEFT_VERTICAL] = self.left_vertical as u8;
        data[LEFT_HORIZONTAL] = self.left_horizontal as u8;
        data[KNOB] = self.knob as u8;
        data[6] = self.reserved;
        data[field::COUNT] = self.count;
    }
}

/// 0x251..=0x254: one motor's speed, current and encoder position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ActuatorHighV2 {
    /// Motor 1..=4 (from the id).
    pub motor: u8,
    /// Motor speed, rpm.
    pub rpm: i16,
    /// Motor current, 0.1 A, signed (read unsigned, a negative current is ~6553 A).
    pub current_deciamps: i16,
    /// Encoder position, pulses.
    pub pulses: i32,
}

impl ActuatorHighV2 {
    /// Current, A.
    pub fn current(&self) -> f64 {
        f64::from(self.current_deciamps) / 10.0
    }

    fn parse(motor: u8, data: &[u8; 8]) -> Self {
        use field::actuator_high::*;
        Self {
            motor,
            rpm: i16_at(data, RPM),
            current_deciamps: i16_at(data, CURRENT),
            pulses: i32_at(data, PULSES),
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::actuator_high::*;
        put(data, RPM, &self.rpm.to_be_bytes());
        put(data, CURRENT, &self.current_deciamps.to_be_bytes());
        put(data, PULSES, &self.pulses.to_be_bytes());
    }
}

/// 0x261..=0x264: one motor driver's voltage, temperatures and state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct ActuatorLowV2 {
    /// Motor 1..=4 (from the id).
    pub motor: u8,
    /// Driver supply voltage, 0.1 V.
    pub driver_decivolts: u16,
    /// Driver temperature, °C.
    pub driver_temperature: i16,
    /// Motor temperature, °C (-40: no sensor, as seen on a HUNTER SE).
    pub motor_temperature: i8,
    /// The driver's state bits.
    pub driver_state: DriverStateV2,
    /// Bytes 6-7, reserved.
    pub reserved: [u8; 2],
}

impl ActuatorLowV2 {
    /// Driver supply voltage, V.
    pub fn driver_voltage(&self) -> f64 {
        f64::from(self.driver_decivolts) / 10.0
    }

    fn parse(motor: u8, data: &[u8; 8]) -> Self {
        use field::actuator_low::*;
        Self {
            motor,
            driver_decivolts: u16_at(data, DRIVER_VOLTAGE),
            driver_temperature: i16_at(data, DRIVER_TEMPERATURE),
            motor_temperature: data[MOTOR_TEMPERATURE] as i8,
            driver_state: DriverStateV2(data[DRIVER_STATE]),
            reserved: [data[6], data[7]],
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::actuator_low::*;
        put(data, DRIVER_VOLTAGE, &self.driver_decivolts.to_be_bytes());
        put(
            data,
            DRIVER_TEMPERATURE,
            &self.driver_temperature.to_be_bytes(),
        );
        data[MOTOR_TEMPERATURE] = self.motor_temperature as u8;
        data[DRIVER_STATE] = self.driver_state.0;
        data[6..8].copy_from_slice(&self.reserved);
    }
}

/// 0x311: the wheel odometers, cumulative, mm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct OdometerV2 {
    /// Left side, mm.
    pub left_mm: i32,
    /// Right side, mm.
    pub right_mm: i32,
}

impl OdometerV2 {
    fn parse(data: &[u8; 8]) -> Self {
        use field::odometer::*;
        Self {
            left_mm: i32_at(data, LEFT),
            right_mm: i32_at(data, RIGHT),
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::odometer::*;
        put(data, LEFT, &self.left_mm.to_be_bytes());
        put(data, RIGHT, &self.right_mm.to_be_bytes());
    }
}

/// 0x271 (steering angles, mrad) or 0x281 (wheel speeds, mm/s) of a steered chassis' four
/// wheels: front left, front right, rear left, rear right (ugv_sdk `MoterAngleFrame`
/// `angle_5..8` and `MoterSpeedFrame` `speed_1..4`, each x0.001).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct WheelsV2(pub [i16; 4]);

impl WheelsV2 {
    fn parse(data: &[u8; 8]) -> Self {
        Self(field::wheels::WHEEL.map(|range| i16_at(data, range)))
    }

    fn emit(&self, data: &mut [u8; 8]) {
        for (range, value) in field::wheels::WHEEL.into_iter().zip(self.0) {
            put(data, range, &value.to_be_bytes());
        }
    }

    /// Each wheel's value in SI units (rad or m/s).
    pub fn si(&self) -> [f64; 4] {
        self.0.map(|value| f64::from(value) / 1000.0)
    }
}

/// 0x291: a Ranger's motion mode and whether it is changing it (ugv_sdk `MotionModeStateFrame`);
/// bytes 2-7 no source names, kept as received.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct MotionModeStateV2 {
    /// The mode it is in, or changing to.
    pub mode: MotionModeV2,
    /// Byte 1: not zero while the wheels turn to the mode; nothing may move it meanwhile.
    pub changing: u8,
    /// Bytes 2-7.
    pub reserved: [u8; 6],
}

impl MotionModeStateV2 {
    /// `mode`, settled (`changing` false) or not.
    pub const fn new(mode: MotionModeV2, changing: bool) -> Self {
        Self {
            mode,
            changing: changing as u8,
            reserved: [0; 6],
        }
    }

    fn parse(data: &[u8; 8]) -> Self {
        use field::motion_mode::*;
        let mut reserved = [0; 6];
        reserved.copy_from_slice(&data[CHANGING + 1..]);
        Self {
            mode: MotionModeV2::from_raw(data[MODE]),
            changing: data[CHANGING],
            reserved,
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::motion_mode::*;
        data[MODE] = self.mode.raw();
        data[CHANGING] = self.changing;
        data[CHANGING + 1..].copy_from_slice(&self.reserved);
    }

    /// The mode the chassis is settled in: `None` while it changes.
    pub const fn settled(&self) -> Option<MotionModeV2> {
        if self.changing != 0 {
            None
        } else {
            Some(self.mode)
        }
    }
}

/// 0x41A: versions as major.minor pairs (high byte major).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct VersionV2 {
    /// Controller hardware.
    pub controller_hardware: u16,
    /// Driver hardware.
    pub driver_hardware: u16,
    /// Controller software.
    pub controller_software: u16,
    /// Driver software.
    pub driver_software: u16,
}

impl VersionV2 {
    fn parse(data: &[u8; 8]) -> Self {
        use field::version::*;
        Self {
            controller_hardware: u16_at(data, CONTROLLER_HARDWARE),
            driver_hardware: u16_at(data, DRIVER_HARDWARE),
            controller_software: u16_at(data, CONTROLLER_SOFTWARE),
            driver_software: u16_at(data, DRIVER_SOFTWARE),
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::version::*;
        put(
            data,
            CONTROLLER_HARDWARE,
            &self.controller_hardware.to_be_bytes(),
        );
        put(data, DRIVER_HARDWARE, &self.driver_hardware.to_be_bytes());
        put(
            data,
            CONTROLLER_SOFTWARE,
            &self.controller_software.to_be_bytes(),
        );
        put(data, DRIVER_SOFTWARE, &self.driver_software.to_be_bytes());
    }
}

/// 0x361: a smart battery's basic values (only with a BMS fitted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct BmsV2 {
    /// State of charge, %.
    pub charge_percent: u8,
    /// State of health, %.
    pub health_percent: u8,
    /// Pack voltage, 0.1 V.
    pub decivolts: i16,
    /// Pack current, 0.1 A.
    pub deciamps: i16,
    /// Temperature, 0.1 °C.
    pub decidegrees: i16,
}

impl BmsV2 {
    fn parse(data: &[u8; 8]) -> Self {
        use field::bms::*;
        Self {
            charge_percent: data[CHARGE],
            health_percent: data[HEALTH],
            decivolts: i16_at(data, VOLTAGE),
            deciamps: i16_at(data, CURRENT),
            decidegrees: i16_at(data, TEMPERATURE),
        }
    }

    fn emit(&self, data: &mut [u8; 8]) {
        use field::bms::*;
        data[CHARGE] = self.charge_percent;
        data[HEALTH] = self.health_percent;
        put(data, VOLTAGE, &self.decivolts.to_be_bytes());
        put(data, CURRENT, &self.deciamps.to_be_bytes());
        put(data, TEMPERATURE, &self.decidegrees.to_be_bytes());
    }
}

/// Which version request: the older 0x411 (answered by 0x41A) or the current 0x4A1 (answered by
/// ASCII 0x4A1 frames).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum VersionRequestForm {
    /// 0x411 `[01]`.
    Binary,
    /// 0x4A1 `[01]`.
    Text,
}

/// Any v2 frame a SCOUT host sends or receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum MessageV2 {
    /// 0x111.
    MotionCommand(MotionV2),
    /// 0x121.
    LightCommand(LightsV2),
    /// 0x141.
    SetMotionMode(MotionModeV2),
    /// 0x131.
    Brake(BrakeV2),
    /// 0x421.
    ControlMode(ControlModeV2),
    /// 0x441.
    ErrorClear(ErrorClearV2),
    /// 0x411 or 0x4A1 with one byte.
    VersionRequest(VersionRequestForm),
    /// 0x211.
    SystemState(SystemStateV2),
    /// 0x221.
    MotionState(MotionV2),
    /// 0x231.
    LightState(LightsV2),
    /// 0x241.
    RcState(RcStateV2),
    /// 0x251..=0x254.
    ActuatorHigh(ActuatorHighV2),
    /// 0x261..=0x264.
    ActuatorLow(ActuatorLowV2),
    /// 0x271: the steering angles of a steered chassis' wheels, mrad.
    MotorAngles(WheelsV2),
    /// 0x281: the wheel speeds of a steered chassis, mm/s.
    MotorSpeeds(WheelsV2),
    /// 0x291.
    MotionModeState(MotionModeStateV2),
    /// 0x311.
    Odometer(OdometerV2),
    /// 0x41A.
    Version(VersionV2),
    /// 0x4A1 with eight bytes: eight characters of the version text.
    VersionText([u8; 8]),
    /// 0x361.
    Bms(BmsV2),
    /// 0x362: alarm and warning bytes, kept raw (their layout changed between SDK releases).
    BmsAlarm([u8; 8]),
}

/// Why a CAN frame is not a v2 frame of a SCOUT.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum V2Error {
    /// Not an id of protocol v2 that a SCOUT uses.
    UnknownId {
        /// The id found.
        id: u16,
    },
    /// Not the length this id has.
    BadLength {
        /// The id of the frame.
        id: u16,
        /// The length found.
        found: u8,
    },
}

impl core::fmt::Display for V2Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::UnknownId { id } => write!(f, "unknown CAN id 0x{id:03X} (not SCOUT v2)"),
            Self::BadLength { id, found } => write!(
                f,
                "CAN id 0x{id:03X}: data length {found}, expected {}",
                if on_demand(id) { "1 or 8" } else { "8" }
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for V2Error {}

/// The on-demand commands the manual sends with one byte and the SDK with eight.
const fn on_demand(id: u16) -> bool {
    matches!(id, id::CONTROL_MODE | id::ERROR_CLEAR | id::VERSION_REQUEST)
}

/// Whether `id` is one of the v2 ids [`decode`] reads.
pub const fn is_v2_id(id: u16) -> bool {
    matches!(
        id,
        id::MOTION_COMMAND
            | id::LIGHT_COMMAND
            | id::SET_MOTION_MODE
            | id::BRAKE
            | id::CONTROL_MODE
            | id::ERROR_CLEAR
            | id::VERSION_REQUEST
            | id::VERSION_TEXT
            | id::SYSTEM_STATE
            | id::MOTION_STATE
            | id::LIGHT_STATE
            | id::RC_STATE
            | 0x251..=0x254
            | 0x261..=0x264
            | id::MOTOR_ANGLES
            | id::MOTOR_SPEEDS
            | id::MOTION_MODE_STATE
            | id::ODOMETER
            | id::VERSION_BINARY
            | id::BMS
            | id::BMS_ALARM
    )
}

impl MessageV2 {
    /// The CAN id.
    pub const fn can_id(&self) -> u16 {
        match self {
            Self::MotionCommand(_) => id::MOTION_COMMAND,
            Self::LightCommand(_) => id::LIGHT_COMMAND,
            Self::SetMotionMode(_) => id::SET_MOTION_MODE,
            Self::Brake(_) => id::BRAKE,
            Self::ControlMode(_) => id::CONTROL_MODE,
            Self::ErrorClear(_) => id::ERROR_CLEAR,
            Self::VersionRequest(VersionRequestForm::Binary) => id::VERSION_REQUEST,
            Self::VersionRequest(VersionRequestForm::Text) | Self::VersionText(_) => {
                id::VERSION_TEXT
            }
            Self::SystemState(_) => id::SYSTEM_STATE,
            Self::MotionState(_) => id::MOTION_STATE,
            Self::LightState(_) => id::LIGHT_STATE,
            Self::RcState(_) => id::RC_STATE,
            Self::ActuatorHigh(m) => id::ACTUATOR_HIGH + (m.motor as u16).saturating_sub(1),
            Self::ActuatorLow(m) => id::ACTUATOR_LOW + (m.motor as u16).saturating_sub(1),
            Self::MotorAngles(_) => id::MOTOR_ANGLES,
            Self::MotorSpeeds(_) => id::MOTOR_SPEEDS,
            Self::MotionModeState(_) => id::MOTION_MODE_STATE,
            Self::Odometer(_) => id::ODOMETER,
            Self::Version(_) => id::VERSION_BINARY,
            Self::Bms(_) => id::BMS,
            Self::BmsAlarm(_) => id::BMS_ALARM,
        }
    }

    /// The snake_case name used in JSON and logs.
    pub const fn name(&self) -> &'static str {
        match self {
            Self::MotionCommand(_) => "motion_command",
            Self::LightCommand(_) => "light_command",
            Self::SetMotionMode(_) => "set_motion_mode",
            Self::Brake(_) => "brake",
            Self::ControlMode(_) => "control_mode",
            Self::ErrorClear(_) => "error_clear",
            Self::VersionRequest(_) => "version_request",
            Self::SystemState(_) => "system_state",
            Self::MotionState(_) => "motion_state",
            Self::LightState(_) => "light_state",
            Self::RcState(_) => "rc_state",
            Self::ActuatorHigh(_) => "actuator_high",
            Self::ActuatorLow(_) => "actuator_low",
            Self::MotorAngles(_) => "motor_angles",
            Self::MotorSpeeds(_) => "motor_speeds",
            Self::MotionModeState(_) => "motion_mode_state",
            Self::Odometer(_) => "odometer",
            Self::Version(_) => "version",
            Self::VersionText(_) => "version_text",
            Self::Bms(_) => "bms",
            Self::BmsAlarm(_) => "bms_alarm",
        }
    }

    /// The rolling count, for the frames that carry one (0x121, 0x211, 0x231, 0x241).
    pub const fn count(&self) -> Option<u8> {
        match self {
            Self::LightCommand(l) | Self::LightState(l) => Some(l.count),
            Self::SystemState(s) => Some(s.count),
            Self::RcState(r) => Some(r.count),
            Self::MotionCommand(_)
            | Self::SetMotionMode(_)
            | Self::Brake(_)
            | Self::ControlMode(_)
            | Self::ErrorClear(_)
            | Self::VersionRequest(_)
            | Self::MotionState(_)
            | Self::ActuatorHigh(_)
            | Self::ActuatorLow(_)
            | Self::MotorAngles(_)
            | Self::MotorSpeeds(_)
            | Self::MotionModeState(_)
            | Self::Odometer(_)
            | Self::Version(_)
            | Self::VersionText(_)
            | Self::Bms(_)
            | Self::BmsAlarm(_) => None,
        }
    }

    /// Host to chassis (a command) or chassis to host.
    pub const fn is_command(&self) -> bool {
        matches!(
            self,
            Self::MotionCommand(_)
                | Self::LightCommand(_)
                | Self::SetMotionMode(_)
                | Self::Brake(_)
                | Self::ControlMode(_)
                | Self::ErrorClear(_)
                | Self::VersionRequest(_)
        )
    }

    /// The frame carrying this message: eight bytes for every id, the unused ones zero (the
    /// manual's one-byte commands are accepted in the eight-byte form the vendor SDK sends).
    pub fn encode(&self) -> CanFrame {
        let mut data = [0; 8];
        match self {
            Self::MotionCommand(m) | Self::MotionState(m) => m.emit(&mut data),
            Self::LightCommand(m) | Self::LightState(m) => m.emit(&mut data),
            Self::SetMotionMode(mode) => data[field::CODE] = mode.raw(),
            Self::Brake(brake) => data[field::CODE] = brake.raw(),
            Self::ControlMode(mode) => data[field::CODE] = mode.raw(),
            Self::ErrorClear(code) => data[field::CODE] = code.raw(),
            Self::VersionRequest(_) => data[field::CODE] = 0x01,
            Self::SystemState(m) => m.emit(&mut data),
            Self::RcState(m) => m.emit(&mut data),
            Self::ActuatorHigh(m) => m.emit(&mut data),
            Self::ActuatorLow(m) => m.emit(&mut data),
            Self::MotorAngles(m) | Self::MotorSpeeds(m) => m.emit(&mut data),
            Self::MotionModeState(m) => m.emit(&mut data),
            Self::Odometer(m) => m.emit(&mut data),
            Self::Version(m) => m.emit(&mut data),
            Self::VersionText(text) | Self::BmsAlarm(text) => data = *text,
            Self::Bms(m) => m.emit(&mut data),
        }
        let len = match self {
            // The current SDK's version request is one byte; an eight-byte 0x4A1 is its reply.
            Self::VersionRequest(VersionRequestForm::Text) => 1,
            _ => usize::from(DLC),
        };
        CanFrame::new(self.can_id(), &data[..len]).expect("a v2 id with at most 8 bytes")
    }
}

/// The v2 message a frame carries, after checking its id and length.
pub fn decode(frame: &CanFrame) -> Result<MessageV2, V2Error> {
    let id = frame.id();
    if !is_v2_id(id) {
        return Err(V2Error::UnknownId { id });
    }
    let bytes = frame.data();
    let found = bytes.len() as u8;
    // A one-byte 0x4A1 is the current version request; eight bytes are its ASCII reply.
    let accepted = found == DLC || (found == 1 && (on_demand(id) || id == id::VERSION_TEXT));
    if !accepted {
        return Err(V2Error::BadLength { id, found });
    }
    let mut data = [0; 8];
    data[..bytes.len()].copy_from_slice(bytes);
    let code = data[field::CODE];
    Ok(match id {
        id::MOTION_COMMAND => MessageV2::MotionCommand(MotionV2::parse(&data)),
        id::LIGHT_COMMAND => MessageV2::LightCommand(LightsV2::parse(&data)),
        id::SET_MOTION_MODE => MessageV2::SetMotionMode(MotionModeV2::from_raw(code)),
        id::BRAKE => MessageV2::Brake(BrakeV2::from_raw(code)),
        id::CONTROL_MODE => MessageV2::ControlMode(ControlModeV2::from_raw(code)),
        id::ERROR_CLEAR => MessageV2::ErrorClear(ErrorClearV2::from_raw(code)),
        id::VERSION_REQUEST => MessageV2::VersionRequest(VersionRequestForm::Binary),
        id::VERSION_TEXT if found == 1 => MessageV2::VersionRequest(VersionRequestForm::Text),
        id::VERSION_TEXT => MessageV2::VersionText(data),
        id::SYSTEM_STATE => MessageV2::SystemState(SystemStateV2::parse(&data)),
        id::MOTION_STATE => MessageV2::MotionState(MotionV2::parse(&data)),
        id::LIGHT_STATE => MessageV2::LightState(LightsV2::parse(&data)),
        id::RC_STATE => MessageV2::RcState(RcStateV2::parse(&data)),
        0x251..=0x254 => MessageV2::ActuatorHigh(ActuatorHighV2::parse((id - 0x250) as u8, &data)),
        0x261..=0x264 => MessageV2::ActuatorLow(ActuatorLowV2::parse((id - 0x260) as u8, &data)),
        id::MOTOR_ANGLES => MessageV2::MotorAngles(WheelsV2::parse(&data)),
        id::MOTOR_SPEEDS => MessageV2::MotorSpeeds(WheelsV2::parse(&data)),
        id::MOTION_MODE_STATE => MessageV2::MotionModeState(MotionModeStateV2::parse(&data)),
        id::ODOMETER => MessageV2::Odometer(OdometerV2::parse(&data)),
        id::VERSION_BINARY => MessageV2::Version(VersionV2::parse(&data)),
        id::BMS => MessageV2::Bms(BmsV2::parse(&data)),
        id::BMS_ALARM => MessageV2::BmsAlarm(data),
        other => return Err(V2Error::UnknownId { id: other }),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new(id, data).expect("a frame")
    }

    fn decoded(id: u16, data: &[u8]) -> MessageV2 {
        decode(&frame(id, data)).unwrap_or_else(|e| panic!("0x{id:03X}: {e}"))
    }

    #[test]
    fn a_rangers_mode_frames_as_the_vendor_sdk_lays_them_out() {
        // ugv_sdk `agilex_msg_parser_v2.c`: 0x141 the mode in byte 0 of eight; 0x291 the mode
        // and the changing flag in bytes 0 and 1; 0x271 four int16 big-endian x0.001 rad.
        let spin = MessageV2::SetMotionMode(MotionModeV2::Spin).encode();
        assert_eq!(
            (spin.id(), spin.data()),
            (0x141, &[2, 0, 0, 0, 0, 0, 0, 0][..])
        );
        let changing = decoded(0x291, &[1, 1, 0, 0, 0, 0, 0, 0]);
        assert_eq!(
            changing,
            MessageV2::MotionModeState(MotionModeStateV2::new(MotionModeV2::Parallel, true))
        );
        let MessageV2::MotionModeState(state) = changing else {
            unreachable!()
        };
        assert_eq!(state.settled(), None);
        let settled = MotionModeStateV2::new(MotionModeV2::DualAckermann, false);
        assert_eq!(settled.settled(), Some(MotionModeV2::DualAckermann));
        let angles = decoded(0x271, &[0x01, 0xF4, 0xFE, 0x0C, 0, 0, 0, 0]);
        assert_eq!(angles, MessageV2::MotorAngles(WheelsV2([500, -500, 0, 0])));
        assert!(!angles.is_command());
    }

    #[test]
    fn a_hunters_brake_as_the_vendor_lays_it_out() {
        // ugv_sdk `agilex_msg_parser_v2.c` `AgxMsgBrakeModeConfig`: 0x131, the mode in byte 0
        // of eight (`BRAKE_MODE_UNLOCK` 0, `BRAKE_MODE_LOCK` 1).
        let lock = MessageV2::Brake(BrakeV2::Locked).encode();
        assert_eq!(
            (lock.id(), lock.data()),
            (0x131, &[1, 0, 0, 0, 0, 0, 0, 0][..])
        );
        assert_eq!(
            decoded(0x131, &[0, 0, 0, 0, 0, 0, 0, 0]),
            MessageV2::Brake(BrakeV2::Released)
        );
        assert!(MessageV2::Brake(BrakeV2::Released).is_command());
        // The Hunter 2.0 manual's table 3.1: 0x211 byte 6, 0x01 the brake locked.
        let MessageV2::SystemState(system) = decoded(0x211, &[0, 1, 0x00, 0xFA, 0, 0, 1, 7]) else {
            unreachable!()
        };
        assert_eq!(system.brake(), BrakeV2::Locked);
    }

    #[test]
    fn the_manuals_motion_command_examples() {
        // protocol-v2-notes 3.1: 0.15 m/s forward, 0.05 rad/s rotation, -0.1 m/s.
        let forward = MessageV2::MotionCommand(MotionV2::from_si(0.15, 0.0));
        assert_eq!(forward.encode().data(), [0x00, 0x96, 0, 0, 0, 0, 0, 0]);
        let turn = MessageV2::MotionCommand(MotionV2::from_si(0.0, 0.05));
        assert_eq!(turn.encode().data(), [0, 0, 0x00, 0x32, 0, 0, 0, 0]);
        let back = MotionV2::from_si(-0.1, 0.0);
        assert_eq!(
            MessageV2::MotionCommand(back).encode().data(),
            [0xFF, 0x9C, 0, 0, 0, 0, 0, 0]
        );
        assert_eq!(forward.encode().id(), 0x111);
        // Hand-typed field notes: 111#001E000000000000 = 0.03 m/s, 111#0000006400000000 = 0.1 rad/s.
        let MessageV2::MotionCommand(slow) = decoded(0x111, &[0, 0x1E, 0, 0, 0, 0, 0, 0]) else {
            unreachable!()
        };
        assert_eq!(slow.linear(), 0.03);
        let MessageV2::MotionCommand(spin) = decoded(0x111, &[0, 0, 0, 0x64, 0, 0, 0, 0]) else {
            unreachable!()
        };
        assert_eq!(spin.angular(), 0.1);
    }

    #[test]
    fn si_rates_round_and_saturate() {
        assert_eq!(MotionV2::from_si(0.0004, -0.0005).linear_mm_s, 0);
        assert_eq!(MotionV2::from_si(0.0004, -0.0005).angular_mrad_s, -1);
        assert_eq!(MotionV2::from_si(1e9, -1e9).linear_mm_s, i16::MAX);
        assert_eq!(MotionV2::from_si(1e9, -1e9).angular_mrad_s, i16::MIN);
        assert_eq!(MotionV2::from_si(f64::NAN, f64::INFINITY).linear_mm_s, 0);
        assert_eq!(
            MotionV2::from_si(f64::NAN, f64::INFINITY).angular_mrad_s,
            i16::MAX
        );
    }

    #[test]
    fn a_bunker_mini_in_estop_before_0x421() {
        // Capture C1 (protocol-v2-notes 8): e-stop, standby, 25.6 V, error 0x0080.
        let MessageV2::SystemState(state) =
            decoded(0x211, &[0x01, 0x00, 0x01, 0x00, 0x00, 0x80, 0x00, 0x00])
        else {
            unreachable!()
        };
        assert_eq!(state.state, ChassisState::EStop);
        assert_eq!(state.control_mode, ControlModeV2::Standby);
        assert_eq!(state.battery_voltage(), 25.6);
        assert_eq!(state.errors, ErrorBitsV2(0x0080));
        assert_eq!(
            state.errors.names().count(),
            0,
            "0x0080 is not named for a SCOUT"
        );
        assert_eq!(state.errors.unknown(), 0x0080);
        assert_eq!(
            decoded(0x221, &[0; 8]),
            MessageV2::MotionState(MotionV2::default())
        );
        let MessageV2::RcState(rc) = decoded(0x241, &[0xAA, 0, 0, 0, 0, 0, 0, 0x61]) else {
            unreachable!()
        };
        assert_eq!(
            [rc.swa, rc.swb, rc.swc, rc.swd],
            [SwitchPosition::Up; 4],
            "every switch up"
        );
        assert_eq!(rc.count, 0x61);
        assert_eq!(
            decoded(0x311, &[0; 8]),
            MessageV2::Odometer(OdometerV2::default())
        );
    }

    #[test]
    fn a_hunter_se_at_rest_in_standby() {
        // Capture C2 (protocol-v2-notes 8).
        let MessageV2::SystemState(state) = decoded(0x211, &[0, 0, 0x01, 0x03, 0, 0, 0, 0xB1])
        else {
            unreachable!()
        };
        assert_eq!(state.state, ChassisState::Normal);
        assert_eq!(state.battery_voltage(), 25.9);
        assert_eq!(state.errors, ErrorBitsV2(0));
        assert_eq!(state.count, 0xB1);
        let MessageV2::MotionState(motion) = decoded(0x221, &[0, 0, 0, 0, 0, 0, 0xFF, 0xFF]) else {
            unreachable!()
        };
        assert_eq!(motion.steering_mrad, -1);
        assert_eq!(
            decoded(0x311, &[0xFF, 0xFF, 0xFF, 0xC1, 0, 0, 0, 0x12]),
            MessageV2::Odometer(OdometerV2 {
                left_mm: -63,
                right_mm: 18
            })
        );
        let MessageV2::ActuatorHigh(motor) = decoded(0x251, &[0, 0, 0, 0x0F, 0, 0, 0, 0x54]) else {
            unreachable!()
        };
        assert_eq!(
            (motor.motor, motor.rpm, motor.current(), motor.pulses),
            (1, 0, 1.5, 84)
        );
        let MessageV2::ActuatorHigh(motor) = decoded(0x252, &[0, 0, 0, 0x07, 0, 0xFF, 0xFB, 0x77])
        else {
            unreachable!()
        };
        assert_eq!(
            (motor.motor, motor.current(), motor.pulses),
            (2, 0.7, 0x00FF_FB77)
        );
        let MessageV2::ActuatorLow(driver) =
            decoded(0x263, &[0x01, 0x07, 0x00, 0x27, 0xD8, 0x40, 0, 0])
        else {
            unreachable!()
        };
        assert_eq!(driver.motor, 3);
        assert_eq!(driver.driver_voltage(), 26.3);
        assert_eq!(driver.driver_temperature, 39);
        assert_eq!(driver.motor_temperature, -40);
        assert_eq!(driver.driver_state.names().count(), 0);
        assert_eq!(
            driver.driver_state.unknown(),
            0x40,
            "bit 6 means different things"
        );
    }

    #[test]
    fn a_negative_motor_current_is_negative() {
        // ugv_sdk PR #50: read unsigned, -0.5 A came out near 6553 A.
        let MessageV2::ActuatorHigh(motor) = decoded(0x254, &[0xFF, 0x38, 0xFF, 0xFB, 0, 0, 0, 0])
        else {
            unreachable!()
        };
        assert_eq!((motor.motor, motor.rpm, motor.current()), (4, -200, -0.5));
    }

    #[test]
    fn the_on_demand_commands_in_both_lengths() {
        assert_eq!(
            decoded(0x421, &[0x01]),
            MessageV2::ControlMode(ControlModeV2::Can)
        );
        assert_eq!(
            decoded(0x421, &[0x01, 0, 0, 0, 0, 0, 0, 0]),
            MessageV2::ControlMode(ControlModeV2::Can)
        );
        let take = MessageV2::ControlMode(ControlModeV2::Can).encode();
        assert_eq!(
            (take.id(), take.data()),
            (0x421, &[1, 0, 0, 0, 0, 0, 0, 0][..])
        );
        let standby = MessageV2::ControlMode(ControlModeV2::Standby).encode();
        assert_eq!(standby.data(), [0; 8]);
        assert_eq!(
            decoded(0x441, &[0x00]),
            MessageV2::ErrorClear(ErrorClearV2::All)
        );
        assert_eq!(
            decoded(0x441, &[0x03]),
            MessageV2::ErrorClear(ErrorClearV2::Motor3)
        );
        assert_eq!(
            decoded(0x411, &[0x01]),
            MessageV2::VersionRequest(VersionRequestForm::Binary)
        );
        let text = MessageV2::VersionRequest(VersionRequestForm::Text).encode();
        assert_eq!((text.id(), text.data()), (0x4A1, &[0x01][..]));
        assert_eq!(
            decode(&text),
            Ok(MessageV2::VersionRequest(VersionRequestForm::Text))
        );
        assert_eq!(
            decoded(0x4A1, b"V1.2.3  "),
            MessageV2::VersionText(*b"V1.2.3  ")
        );
        assert_eq!(
            decoded(0x41A, &[1, 0, 1, 2, 2, 5, 3, 0]),
            MessageV2::Version(VersionV2 {
                controller_hardware: 0x0100,
                driver_hardware: 0x0102,
                controller_software: 0x0205,
                driver_software: 0x0300,
            })
        );
    }

    #[test]
    fn lights_in_both_directions() {
        // Magic-Pony/Tracer2_Record: 121#0100000000000000 turns the front light off under host
        // control.
        let MessageV2::LightCommand(lights) = decoded(0x121, &[1, 0, 0, 0, 0, 0, 0, 0]) else {
            unreachable!()
        };
        assert!(lights.host_controls());
        assert_eq!(lights.front_mode, LightMode::Off);
        let state = decoded(0x231, &[1, 3, 50, 2, 0, 0, 0, 9]);
        let MessageV2::LightState(state_lights) = state else {
            unreachable!()
        };
        assert_eq!(
            (
                state_lights.front_mode,
                state_lights.front_brightness,
                state_lights.rear_mode,
                state_lights.count
            ),
            (LightMode::Custom, 50, LightMode::Breath, 9)
        );
        assert_eq!(state.encode().data(), [1, 3, 50, 2, 0, 0, 0, 9]);
    }

    #[test]
    fn errors_name_what_is_known_and_keep_the_rest() {
        let errors = ErrorBitsV2(0x0001 | 0x0004 | 0x0020 | 0x0200 | 0x8000);
        let names: std::vec::Vec<_> = errors.names().collect();
        assert_eq!(
            names,
            [
                "battery_undervoltage_fault",
                "rc_signal_lost",
                "motor_3_comm",
                "host_comm"
            ]
        );
        assert_eq!(errors.unknown(), 0x8000);
        assert_eq!(DriverStateV2(0xFF).unknown(), 0xE0);
    }

    #[test]
    fn what_is_not_v2_says_why() {
        assert_eq!(
            decode(&frame(0x151, &[0; 8])),
            Err(V2Error::UnknownId { id: 0x151 })
        );
        assert_eq!(
            decode(&frame(0x130, &[0; 8])),
            Err(V2Error::UnknownId { id: 0x130 })
        );
        assert_eq!(
            decode(&frame(0x211, &[0; 7])),
            Err(V2Error::BadLength {
                id: 0x211,
                found: 7
            })
        );
        assert_eq!(
            decode(&frame(0x421, &[0; 2])),
            Err(V2Error::BadLength {
                id: 0x421,
                found: 2
            })
        );
        assert_eq!(
            std::format!(
                "{}",
                V2Error::BadLength {
                    id: 0x421,
                    found: 2
                }
            ),
            "CAN id 0x421: data length 2, expected 1 or 8"
        );
        assert_eq!(
            std::format!("{}", V2Error::UnknownId { id: 0x151 }),
            "unknown CAN id 0x151 (not SCOUT v2)"
        );
    }

    #[test]
    fn every_id_is_read_and_named() {
        for id in 0..=0x7FF_u16 {
            let result = decode(&frame(id, &[0; 8]));
            assert_eq!(result.is_ok(), is_v2_id(id), "0x{id:03X}");
            if let Ok(message) = result {
                assert_eq!(message.can_id(), id, "{}", message.name());
                assert_eq!(decode(&message.encode()), Ok(message), "{}", message.name());
                if id != id::VERSION_REQUEST {
                    // (A version request is encoded with its code, 0x01.)
                    assert_eq!(message.encode(), frame(id, &[0; 8]), "{}", message.name());
                }
            }
        }
    }

    #[test]
    fn error_bits_carry_a_severity_and_unknown_bits_are_kept() {
        let faults: Vec<_> = ErrorBitsV2(0x0283).faults().collect();
        assert_eq!(
            faults,
            [
                ("battery_undervoltage_fault", Severity::Fault),
                ("battery_undervoltage_warning", Severity::Warning),
                ("unknown_bit_7", Severity::Reserved),
                ("host_comm", Severity::Fault),
            ]
        );
        for (mask, name) in ErrorBitsV2::NAMED {
            assert!(
                ErrorBitsV2::severity(*mask).is_some(),
                "{name} has a severity"
            );
        }
        // The Bunker Mini's e-stop word (protocol-v2-notes 8, C1): nothing to act on.
        assert!(
            ErrorBitsV2(0x0080)
                .faults()
                .all(|(_, severity)| severity == Severity::Reserved)
        );
    }

    #[test]
    fn counts_are_read_from_the_frames_that_carry_one() {
        let system = decoded(0x211, &[0, 0, 1, 3, 0, 0, 0, 0xB1]);
        assert_eq!(system.count(), Some(0xB1));
        assert_eq!(decoded(0x221, &[0; 8]).count(), None);
    }
}
