//! The chassis state a gateway publishes zero-copy: the latest of every feedback frame with its
//! receive time, in either protocol (v1's frames and v2's fill the same fields where they mean
//! the same thing, and v2's own where they do not), the link, the chassis model, odometry and
//! the last command. [`StatePayload::store`] and [`StatePayload::store_v2`] match every message
//! of each protocol, so a new feedback message does not compile until it has a place here.

use iceoryx2::prelude::ZeroCopySend;
use scout_protocol::model::Model;
use scout_protocol::v2::{
    BrakeV2, ControlModeV2, DriverStateV2, ErrorBitsV2, MessageV2, MotionModeV2, SwitchPosition,
};
use scout_protocol::version::Protocol;
use scout_protocol::{
    ChassisState, ControlMode, FaultBits, Light, LightCommand, LightMode, Message, Severity,
    SystemStatus, Transport,
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
        /// The chassis speaks another protocol than the gateway was told to use, or feedback of
        /// both protocols arrives: nothing it sends is used (the log says what was seen).
        ProtocolMismatch = 3 => "protocol_mismatch",
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
    /// The chassis' protocol as `u8` ([`Protocol::raw`]; 0 until it is known).
    pub protocol: u8,
    /// Valid frames received.
    pub rx_frames: u64,
    /// Frames rejected for their checksum.
    pub checksum_errors: u64,
    /// Frames lost, from gaps in the rolling counts.
    pub dropped_frames: u64,
    /// Other rejected input: unknown ids, bad lengths, malformed slcan lines, another host's
    /// commands, the other protocol's frames.
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

    /// The chassis' protocol, once known.
    pub fn protocol(&self) -> Option<Protocol> {
        Protocol::from_raw(self.protocol)
    }
}

/// What the gateway knows of the chassis it drives: the model and the limits and geometry it
/// drives it with.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct ChassisPayload {
    /// [`Model`] as `u8` ([`Model::raw`]; 0 until it is known).
    pub model: u8,
    /// The fastest the gateway lets it go, m/s.
    pub max_linear: f64,
    /// The fastest the gateway lets it turn, rad/s (on v1 also the rate at 100 %).
    pub max_angular: f64,
    /// The fastest the gateway lets it go sideways, m/s (0: it does not).
    pub max_lateral: f64,
    /// Distance between the left and right wheels, m.
    pub track: f64,
    /// Wheel radius, m.
    pub wheel_radius: f64,
    /// Motor turns per wheel turn.
    pub gear_ratio: f64,
}

impl ChassisPayload {
    /// The payload for `model`, driven at most at `max_angular` rad/s.
    pub fn new(model: Model, max_angular: f64) -> Self {
        let geometry = model.geometry();
        Self {
            model: model.raw(),
            max_linear: model.limits().linear,
            max_angular,
            max_lateral: model.limits().lateral,
            track: geometry.track,
            wheel_radius: geometry.wheel_radius,
            gear_ratio: geometry.gear_ratio,
        }
    }

    /// The model, once known.
    pub fn model(&self) -> Option<Model> {
        Model::from_raw(self.model)
    }
}

/// When a feedback frame was last received: `valid` is false until the first one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct Received {
    /// Whether a frame of this kind has been received since the link came up.
    pub valid: bool,
    /// The rolling count of the last frame (0 for v2 frames that carry none).
    pub count: u8,
    /// CLOCK_BOOTTIME time of the last frame, ns.
    pub at_ns: u64,
}

/// The chassis' system state: v1's 0x151 or v2's 0x211, raw as the chassis sent it (the
/// control mode and fault word mean different things in each protocol:
/// [`StatePayload::control_mode_name`] and [`StatePayload::faults`] read them).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct SystemPayload {
    /// When it was received.
    pub received: Received,
    /// Raw chassis state byte (0 normal, 1 e-stop, 2 exception; the same in both protocols).
    pub state: u8,
    /// Raw control mode byte (v1: 0 RC, 1 CAN, 2 serial; v2: 0 standby, 1 CAN, 2 UART, 3 RC).
    pub control_mode: u8,
    /// Battery voltage, 0.1 V.
    pub battery_decivolts: u16,
    /// The fault word (v1: 0x151 bytes 4-5; v2: 0x211 bytes 4-5).
    pub fault_bits: u16,
    /// v2: 0x211 byte 6, reserved on a SCOUT, a Hunter's parking brake (0 released, 1 locked:
    /// [`SystemPayload::brake`]).
    pub byte_6: u8,
}

/// The body rates: v1's 0x131 or v2's 0x221.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct MotionPayload {
    /// When it was received.
    pub received: Received,
    /// mm/s.
    pub linear_mm_s: i16,
    /// mrad/s.
    pub angular_mrad_s: i16,
    /// Leftward, mm/s (v2, MINI OMNI; 0 otherwise).
    pub lateral_mm_s: i16,
    /// The inner wheel's steering angle, mrad, positive to the left (v2, a steered chassis:
    /// the Hunter, a Ranger; 0 otherwise). Its yaw rate is in `angular_mrad_s`.
    pub steering_mrad: i16,
    /// A Ranger's motion mode as 0x291 last said it (`MotionModeV2` raw; see `mode_state`).
    pub mode: u8,
    /// 0: no motion mode reported (any chassis but a Ranger), 1: settled in `mode`, 2:
    /// changing to it.
    pub mode_state: u8,
    /// A Ranger's four steering angles as 0x271 last said them, mrad, in its order (which
    /// wheel each is, no source says).
    pub wheel_angles_mrad: [i16; 4],
    /// A Ranger's four wheel speeds as 0x281 last said them, mm/s, in its order.
    pub wheel_speeds_mm_s: [i16; 4],
    /// Bit 0: 0x271 reported, bit 1: 0x281 reported, since the port opened.
    pub wheels_reported: u8,
}

/// One motor: v1's 0x200..0x203, or v2's 0x251..0x254 (speed, current, encoder) and
/// 0x261..0x264 (its driver).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct MotorPayload {
    /// When the speed and current were received.
    pub received: Received,
    /// 0.1 A, signed.
    pub current_deciamps: i16,
    /// Shaft rpm.
    pub rpm: i16,
    /// Encoder position, pulses (v2).
    pub pulses: i32,
    /// When the driver's values were received (on v1 they come with the speed).
    pub driver_received: Received,
    /// deg C.
    pub driver_temperature: i16,
    /// deg C.
    pub motor_temperature: i8,
    /// The driver's supply, 0.1 V (v2).
    pub driver_decivolts: u16,
    /// The driver's state bits (v2, 0x261.. byte 5).
    pub driver_state: u8,
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

/// The light state: v1's 0x141 or v2's 0x231.
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

/// The wheel odometers (v2's 0x311): cumulative distances as the chassis counts them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct OdometerPayload {
    /// When it was received.
    pub received: Received,
    /// Left side, mm.
    pub left_mm: i32,
    /// Right side, mm.
    pub right_mm: i32,
}

/// The RC transmitter (v2's 0x241).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct RcPayload {
    /// When it was received.
    pub received: Received,
    /// SWA, SWB, SWC, SWD as raw two-bit positions (0b10 up, 0b01 middle, 0b11 down).
    pub switches: [u8; 4],
    /// Right stick horizontal, right vertical, left vertical, left horizontal, knob VRA.
    pub sticks: [i8; 5],
}

/// A smart battery (v2's 0x361 and 0x362, sent only with a BMS fitted).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct BmsPayload {
    /// When 0x361 was received.
    pub received: Received,
    /// State of charge, %.
    pub charge_percent: u8,
    /// State of health, %.
    pub health_percent: u8,
    /// Pack voltage, 0.1 V.
    pub decivolts: i16,
    /// Pack current, 0.1 A.
    pub deciamps: i16,
    /// Temperature, 0.1 deg C.
    pub decidegrees: i16,
    /// When 0x362 was received.
    pub alarms_received: Received,
    /// 0x362's alarm and warning bytes, raw (their layout changed between vendor releases).
    pub alarms: [u8; 8],
}

wire_enum! {
    /// Where the battery's state of charge comes from.
    BatterySource {
        /// Nothing reported yet.
        None = 0 => "none",
        /// A smart battery's own report (v2's 0x361).
        Bms = 1 => "bms",
        /// Estimated by the gateway from the pack voltage under the measured load.
        Voltage = 2 => "voltage",
    }
}

wire_enum! {
    /// What set the battery's level: its charge against the thresholds, or the chassis' own
    /// under-voltage bits (held 30 s after they clear), whichever is worse.
    LevelFrom {
        /// No level yet.
        None = 0 => "none",
        /// The state of charge against the configured thresholds.
        Charge = 1 => "charge",
        /// The chassis' battery under-voltage warning.
        ChassisWarning = 2 => "chassis_warning",
        /// The chassis' battery under-voltage fault: it cut the drives off.
        ChassisCutoff = 3 => "chassis_cutoff",
    }
}

impl LevelFrom {
    /// In words, for a status line: `""` for the charge (the percent says it).
    pub fn words(self) -> &'static str {
        match self {
            LevelFrom::None | LevelFrom::Charge => "",
            LevelFrom::ChassisWarning => "the chassis warns of battery under-voltage",
            LevelFrom::ChassisCutoff => "the chassis cut the drives off for battery under-voltage",
        }
    }
}

wire_enum! {
    /// Whether the battery charges: the values of ROS's `sensor_msgs/BatteryState`
    /// `power_supply_status`.
    PowerStatus {
        /// Not known.
        Unknown = 0 => "unknown",
        /// A charger feeds it.
        Charging = 1 => "charging",
        /// The robot runs on it.
        Discharging = 2 => "discharging",
        /// Neither charging nor feeding a load (a smart battery at rest).
        NotCharging = 3 => "not_charging",
        /// Charged, the charger still connected.
        Full = 4 => "full",
    }
}

wire_enum! {
    /// The state of charge against the configured thresholds.
    BatteryLevel {
        /// No state of charge known.
        Unknown = 0 => "unknown",
        /// Above the low threshold.
        Ok = 1 => "ok",
        /// At or below the low threshold (or the chassis warns of under-voltage): charge soon.
        Low = 2 => "low",
        /// At or below the critical threshold (or the chassis cut the drives off): what the
        /// gateway does then is configured (`[battery] on_critical`).
        Critical = 3 => "critical",
    }
}

/// The battery as the gateway judges it, from whatever the chassis offers: a smart battery's
/// report, else an estimate from the voltage. The unknown is NaN.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct BatteryPayload {
    /// [`BatterySource`] as `u8`.
    pub source: u8,
    /// [`PowerStatus`] as `u8`.
    pub status: u8,
    /// [`BatteryLevel`] as `u8`.
    pub level: u8,
    /// [`LevelFrom`] as `u8`: what set the level.
    pub level_from: u8,
    /// State of charge, 0..=100 %.
    pub percent: f64,
    /// Pack voltage, V.
    pub voltage: f64,
    /// Pack current, A: positive charging, negative discharging.
    pub current: f64,
    /// State of health, %.
    pub health_percent: f64,
    /// Temperature, deg C.
    pub temperature: f64,
    /// Rated capacity, Ah.
    pub capacity_ah: f64,
    /// The low threshold in force, %.
    pub low_percent: f64,
    /// The critical threshold in force, %.
    pub critical_percent: f64,
}

impl BatteryPayload {
    /// Nothing known yet: every number NaN, the thresholds as given.
    pub fn unknown(low_percent: f64, critical_percent: f64) -> Self {
        Self {
            source: BatterySource::None.raw(),
            status: PowerStatus::Unknown.raw(),
            level: BatteryLevel::Unknown.raw(),
            level_from: LevelFrom::None.raw(),
            percent: f64::NAN,
            voltage: f64::NAN,
            current: f64::NAN,
            health_percent: f64::NAN,
            temperature: f64::NAN,
            capacity_ah: f64::NAN,
            low_percent,
            critical_percent,
        }
    }

    /// The charge, %, if anything reported one.
    pub fn percent(&self) -> Option<f64> {
        (self.source() != BatterySource::None && self.percent.is_finite()).then_some(self.percent)
    }

    /// Where the charge comes from (`none` for a byte this version does not know).
    pub fn source(&self) -> BatterySource {
        BatterySource::from_raw(self.source).unwrap_or(BatterySource::None)
    }

    /// Whether it charges.
    pub fn status(&self) -> PowerStatus {
        PowerStatus::from_raw(self.status).unwrap_or(PowerStatus::Unknown)
    }

    /// The level against the thresholds.
    pub fn level(&self) -> BatteryLevel {
        BatteryLevel::from_raw(self.level).unwrap_or(BatteryLevel::Unknown)
    }

    /// What set the level.
    pub fn level_from(&self) -> LevelFrom {
        LevelFrom::from_raw(self.level_from).unwrap_or(LevelFrom::None)
    }
}

/// The chassis' firmware versions, as its replies to the version requests said them (v2): the
/// older binary form (0x41A) and the current text form (0x4A1), whichever it answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct FirmwarePayload {
    /// When the last part of a reply was received.
    pub received: Received,
    /// The binary reply's four versions, as text (empty before one).
    pub versions: FixedText<64>,
    /// The text reply, eight characters a frame, as received (empty before one).
    pub text: FixedText<96>,
}

/// Odometry integrated in the gateway, since start or the last reset: from the body rates on
/// v1; on v2 the distance from the wheel odometers and the heading from the body rates.
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
    /// The distance calibration in force (the gateway's `[odometry] distance_scale`).
    pub distance_scale: f64,
    /// The turn calibration in force (`[odometry] yaw_scale`).
    pub yaw_scale: f64,
    /// How much it turned in all, either way, rad.
    pub rotation: f64,
}

/// The range a calibration factor may take: beyond it, something else is wrong (a model, a
/// gear ratio), not a calibration.
pub const ODOMETRY_SCALE_RANGE: std::ops::RangeInclusive<f64> = 0.5..=2.0;

/// The motion command the gateway last sent.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct CommandPayload {
    /// m/s, as sent (after the wire's rounding).
    pub linear: f64,
    /// m/s leftward, as sent.
    pub lateral: f64,
    /// rad/s, as sent.
    pub angular: f64,
    /// CLOCK_BOOTTIME time it was sent, ns.
    pub at_ns: u64,
}

/// The chassis state a gateway publishes on every decoded feedback frame and link change.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("scout::StatePayload.v14")]
#[repr(C)]
pub struct StatePayload {
    /// Increases by one with every publication.
    pub seq: u64,
    /// CLOCK_BOOTTIME time of publication, ns.
    pub published_ns: u64,
    /// The robot's name.
    pub robot: FixedText<32>,
    /// The link.
    pub link: LinkPayload,
    /// The model, its limits and geometry.
    pub chassis: ChassisPayload,
    /// The system state.
    pub system: SystemPayload,
    /// The body rates.
    pub motion: MotionPayload,
    /// Motor 1 first.
    pub motors: [MotorPayload; 4],
    /// The lights.
    pub lights: LightsPayload,
    /// The wheel odometers (v2).
    pub odometer: OdometerPayload,
    /// The RC transmitter (v2).
    pub rc: RcPayload,
    /// The smart battery (v2, when fitted).
    pub bms: BmsPayload,
    /// The battery as the gateway judges it (charge, charging, level).
    pub battery: BatteryPayload,
    /// The firmware versions (v2).
    pub firmware: FirmwarePayload,
    /// Odometry.
    pub odometry: OdometryPayload,
    /// The last motion command sent.
    pub command: CommandPayload,
}

/// A fault or warning the chassis reports, named as `scout decode` names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ChassisFault {
    /// The bit's name.
    pub name: &'static str,
    /// How serious it is.
    pub severity: Severity,
}

impl StatePayload {
    /// The chassis' protocol, once known.
    pub fn protocol(&self) -> Option<Protocol> {
        self.link.protocol()
    }

    /// Keeps a received protocol v1 feedback message as the latest of its kind. Returns
    /// `false` for a host-to-chassis command, which has no place in the state.
    pub fn store(&mut self, message: &Message, received: Received) -> bool {
        match message {
            Message::SystemStatus(status) => {
                self.system = SystemPayload {
                    received,
                    state: status.state.raw(),
                    control_mode: status.control_mode.raw(),
                    battery_decivolts: status.battery_decivolts,
                    fault_bits: status.faults.0,
                    byte_6: 0,
                };
            }
            Message::MotionFeedback(motion) => {
                self.motion = MotionPayload {
                    received,
                    linear_mm_s: motion.linear_mm_s,
                    angular_mrad_s: motion.angular_mrad_s,
                    lateral_mm_s: 0,
                    steering_mrad: 0,
                    ..MotionPayload::default()
                };
            }
            Message::MotorFeedback(motor) => {
                self.motors[motor.motor.index()] = MotorPayload {
                    received,
                    current_deciamps: motor.current_deciamps,
                    rpm: motor.rpm,
                    driver_received: received,
                    driver_temperature: i16::from(motor.driver_temperature),
                    motor_temperature: motor.motor_temperature,
                    ..MotorPayload::default()
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

    /// Keeps a received protocol v2 feedback frame. Returns `false` for a host-to-chassis
    /// command, which has no place in the state. A version reply in text comes eight
    /// characters a frame and is appended to what came before (the gateway clears it when it
    /// asks again).
    pub fn store_v2(&mut self, message: &MessageV2, received: Received) -> bool {
        let motor_index = |motor: u8| usize::from(motor.clamp(1, 4) - 1);
        match message {
            MessageV2::SystemState(system) => {
                self.system = SystemPayload {
                    received,
                    state: system.state.raw(),
                    control_mode: system.control_mode.raw(),
                    battery_decivolts: system.battery_decivolts,
                    fault_bits: system.errors.0,
                    byte_6: system.reserved,
                };
            }
            MessageV2::MotionState(motion) => {
                self.motion = MotionPayload {
                    received,
                    linear_mm_s: motion.linear_mm_s,
                    angular_mrad_s: motion.angular_mrad_s,
                    lateral_mm_s: motion.lateral_mm_s,
                    steering_mrad: motion.steering_mrad,
                    ..self.motion
                };
            }
            MessageV2::MotionModeState(mode) => {
                self.motion.mode = mode.mode.raw();
                self.motion.mode_state = if mode.changing != 0 { 2 } else { 1 };
            }
            MessageV2::LightState(lights) => {
                self.lights = LightsPayload {
                    received,
                    enabled: lights.host_controls(),
                    front: LightPayload::new(Light {
                        mode: lights.front_mode,
                        brightness: lights.front_brightness,
                    }),
                    rear: LightPayload::new(Light {
                        mode: lights.rear_mode,
                        brightness: lights.rear_brightness,
                    }),
                };
            }
            MessageV2::ActuatorHigh(high) => {
                let motor = &mut self.motors[motor_index(high.motor)];
                motor.received = received;
                motor.rpm = high.rpm;
                motor.current_deciamps = high.current_deciamps;
                motor.pulses = high.pulses;
            }
            MessageV2::ActuatorLow(low) => {
                let motor = &mut self.motors[motor_index(low.motor)];
                motor.driver_received = received;
                motor.driver_decivolts = low.driver_decivolts;
                motor.driver_temperature = low.driver_temperature;
                motor.motor_temperature = low.motor_temperature;
                motor.driver_state = low.driver_state.0;
            }
            MessageV2::Odometer(odometer) => {
                self.odometer = OdometerPayload {
                    received,
                    left_mm: odometer.left_mm,
                    right_mm: odometer.right_mm,
                };
            }
            MessageV2::RcState(rc) => {
                self.rc = RcPayload {
                    received,
                    switches: [rc.swa.raw(), rc.swb.raw(), rc.swc.raw(), rc.swd.raw()],
                    sticks: [
                        rc.right_horizontal,
                        rc.right_vertical,
                        rc.left_vertical,
                        rc.left_horizontal,
                        rc.knob,
                    ],
                };
            }
            MessageV2::Bms(bms) => {
                self.bms.received = received;
                self.bms.charge_percent = bms.charge_percent;
                self.bms.health_percent = bms.health_percent;
                self.bms.decivolts = bms.decivolts;
                self.bms.deciamps = bms.deciamps;
                self.bms.decidegrees = bms.decidegrees;
            }
            MessageV2::BmsAlarm(bytes) => {
                self.bms.alarms_received = received;
                self.bms.alarms = *bytes;
            }
            MessageV2::Version(version) => {
                let v = |word: u16| (word >> 8, word & 0xFF);
                let (ch, dh, cs, ds) = (
                    v(version.controller_hardware),
                    v(version.driver_hardware),
                    v(version.controller_software),
                    v(version.driver_software),
                );
                let versions = format!(
                    "controller hw {}.{} sw {}.{}, driver hw {}.{} sw {}.{}",
                    ch.0, ch.1, cs.0, cs.1, dh.0, dh.1, ds.0, ds.1
                );
                self.firmware.received = received;
                self.firmware.versions = FixedText::new(&versions);
            }
            MessageV2::VersionText(bytes) => {
                let mut text = self.firmware.text.as_str().to_owned();
                text.extend(bytes.iter().map(|&b| {
                    if (32..=126).contains(&b) {
                        b as char
                    } else {
                        ' '
                    }
                }));
                self.firmware.received = received;
                self.firmware.text = FixedText::new(&text);
            }
            MessageV2::MotorAngles(wheels) => {
                self.motion.wheel_angles_mrad = wheels.0;
                self.motion.wheels_reported |= 1;
            }
            MessageV2::MotorSpeeds(wheels) => {
                self.motion.wheel_speeds_mm_s = wheels.0;
                self.motion.wheels_reported |= 2;
            }
            MessageV2::MotionCommand(_)
            | MessageV2::LightCommand(_)
            | MessageV2::SetMotionMode(_)
            | MessageV2::Brake(_)
            | MessageV2::ControlMode(_)
            | MessageV2::ErrorClear(_)
            | MessageV2::VersionRequest(_) => return false,
        }
        true
    }

    /// The chassis state (normal, e-stop, exception), once reported.
    pub fn chassis_state(&self) -> Option<ChassisState> {
        self.system
            .received
            .valid
            .then(|| ChassisState::from_raw(self.system.state))
    }

    /// The control mode's name in the chassis' protocol (v1: `rc`, `can`, `serial`; v2:
    /// `standby`, `can`, `uart`, `rc`), once reported.
    pub fn control_mode_name(&self) -> Option<&'static str> {
        if !self.system.received.valid {
            return None;
        }
        let raw = self.system.control_mode;
        Some(match self.protocol()? {
            Protocol::V1 => ControlMode::from_raw(raw).name(),
            Protocol::V2 => ControlModeV2::from_raw(raw).name(),
        })
    }

    /// Whether the RC transmitter holds the chassis, as the last system state says.
    pub fn rc_in_control(&self) -> bool {
        let raw = self.system.control_mode;
        self.system.received.valid
            && match self.protocol() {
                Some(Protocol::V1) => ControlMode::from_raw(raw) == ControlMode::Rc,
                Some(Protocol::V2) => ControlModeV2::from_raw(raw) == ControlModeV2::Rc,
                None => false,
            }
    }

    /// Every fault bit set in the last system state, named and graded as in the chassis'
    /// protocol (v1's sixteen named bits; v2's named bits, the rest as `unknown_bit_N`).
    pub fn faults(&self) -> Vec<ChassisFault> {
        let bits = self.system.fault_bits;
        if !self.system.received.valid {
            return Vec::new();
        }
        match self.protocol() {
            Some(Protocol::V1) => FaultBits(bits)
                .iter()
                .map(|fault| ChassisFault {
                    name: fault.name(),
                    severity: fault.severity(),
                })
                .collect(),
            Some(Protocol::V2) => ErrorBitsV2(bits)
                .faults()
                .map(|(name, severity)| ChassisFault { name, severity })
                .collect(),
            None => Vec::new(),
        }
    }

    /// The fault bits no source names (v2; v1's reserved bits), for people to report.
    pub fn unknown_fault_bits(&self) -> u16 {
        match self.protocol() {
            Some(Protocol::V1) => FaultBits(self.system.fault_bits)
                .iter()
                .filter(|fault| fault.severity() == Severity::Reserved)
                .fold(0, |bits, fault| bits | fault.mask()),
            Some(Protocol::V2) => ErrorBitsV2(self.system.fault_bits).unknown(),
            None => 0,
        }
    }
}

impl SystemPayload {
    /// 0x211 byte 6 read as a Hunter's parking brake (meaningful on a model that has one).
    pub fn brake(&self) -> BrakeV2 {
        BrakeV2::from_raw(self.byte_6)
    }

    /// The status it carries, read as protocol v1's 0x151 (for v1 tools; see
    /// [`StatePayload::faults`] for either protocol).
    pub fn status_v1(&self) -> SystemStatus {
        SystemStatus {
            state: ChassisState::from_raw(self.state),
            control_mode: ControlMode::from_raw(self.control_mode),
            battery_decivolts: self.battery_decivolts,
            faults: FaultBits(self.fault_bits),
        }
    }

    /// Battery voltage, V.
    pub fn battery_voltage(&self) -> f64 {
        f64::from(self.battery_decivolts) / 10.0
    }
}

impl MotionPayload {
    /// A Ranger's four steering angles (rad), once 0x271 reported them.
    pub fn wheel_angles(&self) -> Option<[f64; 4]> {
        (self.wheels_reported & 1 != 0)
            .then(|| self.wheel_angles_mrad.map(|mrad| f64::from(mrad) / 1000.0))
    }

    /// A Ranger's four wheel speeds (m/s), once 0x281 reported them.
    pub fn wheel_speeds(&self) -> Option<[f64; 4]> {
        (self.wheels_reported & 2 != 0)
            .then(|| self.wheel_speeds_mm_s.map(|mm| f64::from(mm) / 1000.0))
    }

    /// m/s.
    pub fn linear(&self) -> f64 {
        f64::from(self.linear_mm_s) / 1000.0
    }

    /// rad/s.
    pub fn angular(&self) -> f64 {
        f64::from(self.angular_mrad_s) / 1000.0
    }

    /// m/s, leftward.
    pub fn lateral(&self) -> f64 {
        f64::from(self.lateral_mm_s) / 1000.0
    }

    /// rad, the inner wheel's steering angle (a steered chassis).
    pub fn steering(&self) -> f64 {
        f64::from(self.steering_mrad) / 1000.0
    }

    /// A Ranger's motion mode, once reported, and whether it is changing to it.
    pub fn mode(&self) -> Option<(MotionModeV2, bool)> {
        (self.mode_state != 0).then(|| (MotionModeV2::from_raw(self.mode), self.mode_state == 2))
    }
}

impl MotorPayload {
    /// Current, A.
    pub fn current(&self) -> f64 {
        f64::from(self.current_deciamps) / 10.0
    }

    /// The driver's state bits (v2).
    pub fn driver_state(&self) -> DriverStateV2 {
        DriverStateV2(self.driver_state)
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

impl RcPayload {
    /// SWA, SWB, SWC, SWD.
    pub fn switches(&self) -> [SwitchPosition; 4] {
        self.switches.map(SwitchPosition::from_raw)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_protocol::{CanFrame, Direction, MessageKind, v2};

    #[test]
    fn link_state_round_trips() {
        for state in LinkState::ALL {
            assert_eq!(LinkState::from_raw(state.raw()), Some(*state));
        }
    }

    #[test]
    fn power_status_is_ros_battery_state_numbering() {
        // sensor_msgs/BatteryState POWER_SUPPLY_STATUS_*.
        let ros = [
            (PowerStatus::Unknown, 0),
            (PowerStatus::Charging, 1),
            (PowerStatus::Discharging, 2),
            (PowerStatus::NotCharging, 3),
            (PowerStatus::Full, 4),
        ];
        assert_eq!(ros.len(), PowerStatus::ALL.len());
        for (status, raw) in ros {
            assert_eq!(status.raw(), raw);
        }
    }

    const RECEIVED: Received = Received {
        valid: true,
        count: 9,
        at_ns: 42,
    };

    #[test]
    fn every_v1_feedback_message_has_a_place_and_commands_have_none() {
        for kind in MessageKind::ALL {
            let mut state = StatePayload::default();
            let message = Message::parse(kind, &[1, 2, 3, 4, 5, 6]);
            let stored = state.store(&message, RECEIVED);
            match kind.direction() {
                Direction::Feedback => {
                    assert!(stored, "{kind:?}");
                    assert_ne!(state, StatePayload::default(), "{kind:?} left no trace");
                }
                Direction::Command => {
                    assert!(!stored, "{kind:?}");
                    assert_eq!(state, StatePayload::default());
                }
            }
        }
    }

    fn v2(id: u16, data: [u8; 8]) -> MessageV2 {
        v2::decode(&CanFrame::new(id, &data).expect("frame")).expect("a v2 frame")
    }

    #[test]
    fn every_v2_feedback_frame_has_a_place_and_commands_have_none() {
        let ids = [
            0x111, 0x121, 0x421, 0x441, 0x411, 0x211, 0x221, 0x231, 0x241, 0x251, 0x254, 0x261,
            0x264, 0x311, 0x41A, 0x4A1, 0x361, 0x362,
        ];
        for id in ids {
            let message = v2(id, [1, 2, 3, 4, 5, 6, 7, 8]);
            let mut state = StatePayload::default();
            let stored = state.store_v2(&message, RECEIVED);
            assert_eq!(stored, !message.is_command(), "0x{id:03X}");
            assert_eq!(state == StatePayload::default(), !stored, "0x{id:03X}");
        }
    }

    #[test]
    fn v2_frames_fill_the_shared_fields_and_their_own() {
        let mut state = StatePayload::default();
        state.link.protocol = Protocol::V2.raw();
        // The Bunker Mini's frames in e-stop (protocol-v2-notes 8, C1) and a HUNTER SE's.
        state.store_v2(&v2(0x211, [1, 0, 1, 0, 0, 0x80, 0, 0]), RECEIVED);
        state.store_v2(
            &v2(0x311, [0xFF, 0xFF, 0xFF, 0xC1, 0, 0, 0, 0x12]),
            RECEIVED,
        );
        state.store_v2(&v2(0x252, [0, 0, 0, 7, 0, 0xFF, 0xFB, 0x77]), RECEIVED);
        state.store_v2(&v2(0x263, [1, 7, 0, 0x27, 0xD8, 0x40, 0, 0]), RECEIVED);
        state.store_v2(&v2(0x241, [0xAA, 0, 0, 0, 0, 0, 0, 0x61]), RECEIVED);
        assert_eq!(state.chassis_state(), Some(ChassisState::EStop));
        assert_eq!(state.control_mode_name(), Some("standby"));
        assert!(!state.rc_in_control());
        assert_eq!(state.system.battery_voltage(), 25.6);
        assert_eq!(
            state.faults(),
            [ChassisFault {
                name: "unknown_bit_7",
                severity: Severity::Reserved
            }]
        );
        assert_eq!(state.unknown_fault_bits(), 0x0080);
        assert_eq!((state.odometer.left_mm, state.odometer.right_mm), (-63, 18));
        let motor = state.motors[1];
        assert_eq!((motor.current(), motor.pulses), (0.7, 0x00FF_FB77));
        let driver = state.motors[2];
        assert_eq!(driver.driver_decivolts, 263);
        assert_eq!(
            (driver.driver_temperature, driver.motor_temperature),
            (39, -40)
        );
        assert!(!state.motors[2].received.valid, "0x253 not received yet");
        assert_eq!(state.rc.switches(), [SwitchPosition::Up; 4]);
    }

    #[test]
    fn the_same_raw_control_mode_reads_by_protocol() {
        let mut state = StatePayload::default();
        state.system.received = RECEIVED;
        state.system.control_mode = 0;
        assert_eq!(state.control_mode_name(), None, "protocol not known yet");
        state.link.protocol = Protocol::V1.raw();
        assert_eq!(state.control_mode_name(), Some("rc"));
        assert!(state.rc_in_control());
        state.link.protocol = Protocol::V2.raw();
        assert_eq!(state.control_mode_name(), Some("standby"));
        assert!(!state.rc_in_control());
        state.system.control_mode = 3;
        assert!(state.rc_in_control());
    }

    #[test]
    fn version_replies_become_text() {
        let mut state = StatePayload::default();
        state.store_v2(&v2(0x41A, [1, 0, 1, 0, 2, 3, 1, 5]), RECEIVED);
        assert_eq!(
            state.firmware.versions.as_str(),
            "controller hw 1.0 sw 2.3, driver hw 1.0 sw 1.5"
        );
        state.store_v2(&v2(0x4A1, *b"scout v2"), RECEIVED);
        state.store_v2(&v2(0x4A1, [b' ', b'1', b'.', b'0', 0, 0, 0, 0]), RECEIVED);
        assert_eq!(state.firmware.text.as_str(), "scout v2 1.0    ");
        assert!(
            state.firmware.versions.as_str().starts_with("controller"),
            "kept apart"
        );
    }
}
