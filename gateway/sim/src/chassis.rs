//! The simulated SCOUT chassis: commands and time in, feedback out. No clock, no I/O.
//!
//! It behaves as the manual and protocol-notes describe: feedback every 20 ms with a rolling count
//! per id; motion commands only in the link's control mode; no valid command for 500 ms means
//! speed 0; a bad command checksum sets the checksum error bit; latched protections stop the
//! chassis until the matching fault-clear code; RC and e-stop override the host.

use std::time::Duration;

use scout_protocol::battery;
use scout_protocol::sequence::RollingCounter;
use scout_protocol::{
    ChassisState, ControlMode, Counted, Fault, FaultBits, FaultClear, Light, LightCommand,
    LightMode, Message, MessageKind, MotionCommand, MotionFeedback, Motor, MotorFeedback,
    SystemStatus, units,
};
use serde::Serialize;

use scout_protocol::Transport;
use scout_protocol::model::{FourWheel, Model, Steering};
use scout_protocol::v2::{MessageV2, MotionModeStateV2, MotionModeV2, MotionV2, WheelsV2};

#[path = "chassis_v2.rs"]
mod v2;

/// The chassis' physical parameters and firmware constants.
#[derive(Debug, Clone, PartialEq, serde::Deserialize, Serialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimParams {
    /// rad/s at 100 % angular command (protocol-notes 4.1); protocol v2 firmware clamps its
    /// commands to it.
    pub max_angular: f64,
    /// m/s: protocol v2 firmware clamps its commands to it (v1's percent is of 1.5 m/s).
    pub max_linear: f64,
    /// m/s sideways: protocol v2 firmware clamps 0x111's lateral field to it (0: the chassis
    /// does not move sideways and ignores the field; the SCOUT MINI OMNI's is 2.0).
    pub max_lateral: f64,
    /// Distance between the left and right wheels, m (vendor SDK value).
    pub track_width: f64,
    /// Wheel radius, m.
    pub wheel_radius: f64,
    /// Motor turns per wheel turn.
    pub gear_ratio: f64,
    /// How many actuators report on protocol v2 (1 and 2, or 1 to 4): two on the Tracers and
    /// Bunkers, three on the Hunter, four on the SCOUTs.
    pub actuators: u8,
    /// Front to rear axle of a steered chassis, m (0: it does not steer, and turns by its
    /// yaw-rate field). A steered one takes a steering angle in 0x111 (its yaw-rate field is
    /// ignored), turns its wheels at `steering_rate`, and reports the angle in 0x221.
    pub wheelbase: f64,
    /// A steered chassis' widest central angle, rad.
    pub max_central_steering: f64,
    /// A steered chassis' widest inner-wheel angle, rad (0x111's steering is clamped to it).
    pub max_steering: f64,
    /// How fast a steered chassis turns its wheels, rad/s.
    pub steering_rate: f64,
    /// Four steered wheels in motion modes (a Ranger; protocol v2): 0x141 sets the mode, only
    /// standing still, and the change takes `mode_change`, reported in 0x291, during which 0x111
    /// moves nothing; 0x111 then carries the wheels' speed and angle (`wheelbase`,
    /// `max_steering` the inner wheels' widest in dual Ackermann, `max_parallel_steering`) or
    /// the spin rate. It starts in dual Ackermann.
    pub motion_modes: bool,
    /// The widest wheel angle in parallel mode, rad.
    pub max_parallel_steering: f64,
    /// Spinning takes its rate in 0x111's bytes 4-5 (a Ranger Mini 2.0), not 2-3.
    pub spin_in_lateral: bool,
    /// How long a mode change takes.
    #[serde(with = "millis")]
    pub mode_change: Duration,
    /// A parking brake (a Hunter; protocol v2): it starts locked, 0x131 locks or releases
    /// it, 0x211 byte 6 reports it, and while it is locked 0x111 moves nothing.
    pub parking_brake: bool,
    /// Linear acceleration limit, m/s².
    pub linear_acceleration: f64,
    /// Angular acceleration limit, rad/s².
    pub angular_acceleration: f64,
    /// Battery voltage at rest at start, V (its charge is the curve's at that voltage).
    pub battery_voltage: f64,
    /// Battery capacity, Ah (sets how fast the charge falls with load: a small one discharges
    /// in a test's time).
    pub battery_capacity_ah: f64,
    /// The pack's resistance, ohm: the voltage sags by the current through it.
    pub battery_resistance_ohm: f64,
    /// Protocol v2: the chassis has a smart battery, reported in 0x361 and 0x362.
    pub bms: bool,
    /// The smart battery's state of health, %.
    pub battery_health_percent: f64,
    /// Ambient temperature, deg C.
    pub ambient_temperature: f64,
    /// Feedback period.
    #[serde(with = "millis")]
    pub feedback_period: Duration,
    /// Communication protection: speed 0 after this long without a valid motion command.
    #[serde(with = "millis")]
    pub command_timeout: Duration,
    /// On serial, host light control lapses after this long without a light command.
    #[serde(with = "millis")]
    pub serial_light_timeout: Duration,
    /// What the firmware reports of the distance travelled (speed, wheel odometers) over the
    /// truth: a deliberate odometry error, for calibration (1.0: none).
    pub reported_distance_scale: f64,
    /// What the firmware reports of the turn (yaw rate) over the truth (scout_ros#5 saw 1.26).
    pub reported_yaw_scale: f64,
}

impl Default for SimParams {
    fn default() -> Self {
        Self {
            max_angular: units::DEFAULT_MAX_ANGULAR_SPEED,
            max_linear: units::MAX_LINEAR_SPEED,
            max_lateral: 0.0,
            track_width: 0.583,
            wheel_radius: 0.165,
            gear_ratio: 32.0,
            actuators: 4,
            wheelbase: 0.0,
            max_central_steering: 0.0,
            max_steering: 0.0,
            steering_rate: 0.0,
            motion_modes: false,
            max_parallel_steering: 0.0,
            spin_in_lateral: false,
            mode_change: Duration::from_secs(1),
            parking_brake: false,
            linear_acceleration: 1.0,
            angular_acceleration: 1.5,
            battery_voltage: 26.0,
            battery_capacity_ah: 30.0,
            battery_resistance_ohm: 0.06,
            bms: false,
            battery_health_percent: 96.0,
            ambient_temperature: 25.0,
            feedback_period: Duration::from_millis(20),
            command_timeout: Duration::from_millis(500),
            serial_light_timeout: Duration::from_millis(500),
            reported_distance_scale: 1.0,
            reported_yaw_scale: 1.0,
        }
    }
}

impl SimParams {
    /// These parameters with the keys `table` sets replaced (a `--params` file, the gateway's
    /// `[sim]` table); an unknown key or a wrong type is an error.
    pub fn with_overrides(&self, table: &toml::Table) -> Result<Self, toml::de::Error> {
        let mut merged = toml::Table::try_from(self)
            .map_err(|error| <toml::de::Error as serde::de::Error>::custom(error.to_string()))?;
        merged.extend(table.clone());
        merged.try_into()
    }

    /// The defaults with `model`'s limits and geometry.
    pub fn for_model(model: Model) -> Self {
        let limits = model.limits();
        let geometry = model.geometry();
        Self {
            max_angular: limits.angular,
            max_linear: limits.linear,
            max_lateral: limits.lateral,
            track_width: geometry.track,
            wheel_radius: geometry.wheel_radius,
            gear_ratio: geometry.gear_ratio,
            actuators: model.actuators(),
            parking_brake: model.parking_brake(),
            ..Self::default()
        }
        .with_steering(model.steering())
        .with_four_wheel(model.four_wheel())
    }

    fn with_four_wheel(self, ranger: Option<FourWheel>) -> Self {
        match ranger {
            None => self,
            Some(ranger) => Self {
                motion_modes: true,
                wheelbase: ranger.wheelbase,
                max_steering: ranger.max_inner,
                max_parallel_steering: ranger.max_parallel,
                spin_in_lateral: ranger.spin_in_lateral,
                steering_rate: ranger.rate,
                mode_change: Duration::from_secs_f64(ranger.mode_change),
                ..self
            },
        }
    }

    /// The four-wheel steering of a Ranger (`motion_modes`), else `None`.
    pub fn four_wheel(&self) -> Option<FourWheel> {
        self.motion_modes.then_some(FourWheel {
            wheelbase: self.wheelbase,
            track: self.track_width,
            max_inner: self.max_steering,
            max_parallel: self.max_parallel_steering,
            spin_in_lateral: self.spin_in_lateral,
            rate: self.steering_rate,
            mode_change: self.mode_change.as_secs_f64(),
        })
    }

    fn with_steering(self, steering: Option<Steering>) -> Self {
        match steering {
            None => self,
            Some(steering) => Self {
                wheelbase: steering.wheelbase,
                max_central_steering: steering.max_central,
                max_steering: steering.max_inner,
                steering_rate: steering.rate,
                ..self
            },
        }
    }

    /// The steering of a front-steered chassis (a wheelbase set, no motion modes), else `None`.
    pub fn steering(&self) -> Option<Steering> {
        (self.wheelbase > 0.0 && !self.motion_modes).then_some(Steering {
            wheelbase: self.wheelbase,
            track: self.track_width,
            max_central: self.max_central_steering,
            max_inner: self.max_steering,
            rate: self.steering_rate,
        })
    }
}

/// Durations as whole milliseconds in configuration files.
mod millis {
    use std::time::Duration;

    pub fn serialize<S: serde::Serializer>(d: &Duration, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u64(d.as_millis() as u64)
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        Ok(Duration::from_millis(serde::Deserialize::deserialize(d)?))
    }
}

/// The pack: its true charge against the model's rest-voltage curve
/// ([`scout_protocol::battery`]), a voltage sag through its resistance, a charger in constant
/// current up to the charge voltage.
#[derive(Debug, Clone, Copy)]
struct Battery {
    /// The true charge, %.
    charge_percent: f64,
    /// Rest voltage beyond the curve (an injected voltage outside its range), V.
    offset_volts: f64,
    /// The charger's current, A (0: none).
    charger_amps: f64,
    /// The pack's current at the last step, A (positive charging).
    current: f64,
}

impl Battery {
    fn new(params: &SimParams) -> Self {
        let curve = battery::SCOUT_BATTERY.curve;
        let charge_percent = battery::percent_at(curve, params.battery_voltage);
        Self {
            charge_percent,
            offset_volts: params.battery_voltage - battery::volts_at(curve, charge_percent),
            charger_amps: 0.0,
            current: 0.0,
        }
    }

    /// The rest voltage, V.
    fn rest(&self) -> f64 {
        battery::volts_at(battery::SCOUT_BATTERY.curve, self.charge_percent) + self.offset_volts
    }

    /// Moves the charge so that the pack rests at `rest` V.
    fn set_rest(&mut self, rest: f64) {
        let curve = battery::SCOUT_BATTERY.curve;
        self.charge_percent = battery::percent_at(curve, rest);
        self.offset_volts = rest - battery::volts_at(curve, self.charge_percent);
    }

    /// `dt` s at a load of `load` A: the charge moves, and the terminal voltage is returned.
    fn step(&mut self, load: f64, dt: f64, params: &SimParams) -> f64 {
        let full = battery::SCOUT_BATTERY.full_charge_volts;
        let charging = self.charger_amps > 0.0 && self.charge_percent < 100.0;
        let charger = if charging {
            self.charger_amps
        } else if self.charger_amps > 0.0 {
            // Full: the charger holds its voltage and feeds the load, nothing flows in or out.
            load.min(self.charger_amps)
        } else {
            0.0
        };
        self.current = charger - load;
        let percent_per_amp_second = 100.0 / (params.battery_capacity_ah * 3600.0);
        self.charge_percent =
            (self.charge_percent + self.current * dt * percent_per_amp_second).clamp(0.0, 100.0);
        let terminal = self.rest() + self.current * params.battery_resistance_ohm;
        if self.charger_amps > 0.0 && !charging {
            // Charged: the charger holds its voltage, nothing flows.
            full
        } else {
            // Charging in constant current the pack's voltage rises above its rest by the
            // drop across it, up to the charge voltage; discharging it sags below.
            terminal.min(full.max(self.rest()))
        }
    }
}

/// Battery thresholds of the manual (section 2.1).
const BATTERY_WARNING_VOLTS: f64 = battery::SCOUT_BATTERY.warning_volts;
const BATTERY_CUTOFF_VOLTS: f64 = battery::SCOUT_BATTERY.cutoff_volts;
const BATTERY_OVERVOLTAGE_VOLTS: f64 = 30.0;
/// How far a Ranger's wheels may point from where they are told and still roll, rad (an
/// assumption: no source says what its firmware does while its wheels turn).
const ALIGNED: f64 = 0.2;
/// Driver temperature thresholds (fault table of 0x151).
const OVERTEMP_WARNING_C: f64 = 55.0;
const OVERTEMP_PROTECTION_C: f64 = 65.0;
/// Motor current thresholds, A rms.
const OVERCURRENT_WARNING_A: f64 = 15.0;
const OVERCURRENT_PROTECTION_A: f64 = 20.0;
/// Breathing lights step 1 % per feedback period, 0..100..0 (as in the real capture).
const BREATH_STEPS: u32 = 200;
/// Below this the chassis counts as standing still (for its own light logic).
const STANDSTILL: f64 = 0.01;
/// The simulation's integration step.
const STEP: Duration = Duration::from_millis(5);

/// A value of one motor that can be pinned by fault injection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MotorValue {
    /// Current, A.
    Current,
    /// Shaft speed, rpm.
    Rpm,
    /// Driver temperature, deg C.
    DriverTemperature,
    /// Motor temperature, deg C.
    MotorTemperature,
}

/// A latched protection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Protection {
    /// Driver over-temperature (65 C).
    DriverOvertemp,
    /// Motor over-current (20 A).
    MotorOvercurrent,
}

impl Protection {
    fn fault(self) -> Fault {
        match self {
            Self::DriverOvertemp => Fault::DriverOvertempProtection,
            Self::MotorOvercurrent => Fault::MotorOvercurrentProtection,
        }
    }
}

/// A self-clearing warning that can be forced on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Warning {
    /// Driver over-temperature warning.
    DriverOvertemp,
    /// Motor over-current warning.
    MotorOvercurrent,
}

impl Warning {
    fn fault(self) -> Fault {
        match self {
            Self::DriverOvertemp => Fault::DriverOvertempWarning,
            Self::MotorOvercurrent => Fault::MotorOvercurrentWarning,
        }
    }
}

/// A change of the chassis' condition, from the fault-injection language.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Injection {
    /// Emergency stop pressed (true) or released.
    EStop(bool),
    /// RC transmitter on (control mode RC, host commands ignored) or off.
    Rc(bool),
    /// Latch a protection, as if the threshold had been crossed.
    Protect(Protection),
    /// Force a warning on, or back to automatic.
    Warn(Warning, bool),
    /// Motor communication fault on or off.
    MotorCommFault(Motor, bool),
    /// Set the battery's voltage at rest (the charge moves to where the curve puts it; beyond
    /// the curve's ends, the pack is out of its range: an injected fault). Under load it sags.
    Battery(f64),
    /// A charger feeding this many amps (0: unplugged); it stops at full charge.
    Charger(f64),
    /// Pin one of a motor's values.
    PinMotor(Motor, MotorValue, f64),
    /// Unpin all of a motor's values.
    UnpinMotor(Motor),
    /// Protocol v2 firmware falls back to standby by itself (ignored by v1 firmware).
    Standby,
}

#[derive(Debug, Clone, Copy, Default)]
struct MotorState {
    current: f64,
    rpm: f64,
    driver_temperature: f64,
    motor_temperature: f64,
    pinned_current: Option<f64>,
    pinned_rpm: Option<f64>,
    pinned_driver_temperature: Option<f64>,
    pinned_motor_temperature: Option<f64>,
}

impl MotorState {
    fn current(&self) -> f64 {
        self.pinned_current.unwrap_or(self.current)
    }

    fn rpm(&self) -> f64 {
        self.pinned_rpm.unwrap_or(self.rpm)
    }

    fn driver_temperature(&self) -> f64 {
        self.pinned_driver_temperature
            .unwrap_or(self.driver_temperature)
    }

    fn motor_temperature(&self) -> f64 {
        self.pinned_motor_temperature
            .unwrap_or(self.motor_temperature)
    }

    fn pin(&mut self, value: MotorValue, to: f64) {
        let slot = match value {
            MotorValue::Current => &mut self.pinned_current,
            MotorValue::Rpm => &mut self.pinned_rpm,
            MotorValue::DriverTemperature => &mut self.pinned_driver_temperature,
            MotorValue::MotorTemperature => &mut self.pinned_motor_temperature,
        };
        *slot = Some(to);
    }

    fn unpin(&mut self) {
        self.pinned_current = None;
        self.pinned_rpm = None;
        self.pinned_driver_temperature = None;
        self.pinned_motor_temperature = None;
    }
}

/// The ground-truth pose, integrated from the actual speeds: m in the start frame, rad
/// counter-clockwise from the start heading.
pub use scout_protocol::kinematics::Pose;

/// Why a received motion command did not move the chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ignored {
    /// Its control mode is not the link's (0x01 CAN, 0x02 serial).
    WrongMode,
    /// The RC transmitter has authority.
    Rc,
    /// A protection is latched, the battery is cut off or the e-stop is pressed.
    Inhibited,
    /// Protocol v2: the chassis is not in CAN command mode (standby until 0x421 `[01]`).
    NotCommandMode,
    /// A Ranger is changing its motion mode (0x291 says so).
    ModeChanging,
    /// A Hunter's parking brake is locked (0x211 byte 6 says so).
    BrakeLocked,
}

/// Statistics for tests and people: what the chassis received and did.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SimStats {
    /// Valid commands received, by CAN id (`"0x130"`, `"0x140"`).
    pub commands: std::collections::BTreeMap<String, u64>,
    /// Motion commands that did not move the chassis, by reason.
    pub ignored: IgnoredCounts,
    /// Command frames rejected for their checksum.
    pub checksum_failures: u64,
    /// Other rejected input (unknown ids, bad lengths, malformed lines).
    pub rejected: u64,
    /// Intervals between consecutive valid motion commands.
    pub motion_command_intervals: IntervalStats,
    /// The last valid motion command.
    pub last_command: Option<LastCommand>,
    /// The chassis' actual speeds.
    pub actual: Speeds,
    /// The inner wheel's steering angle, rad (a steered chassis).
    pub steering: f64,
    /// A Ranger's motion mode (`dual_ackermann`, `parallel`, `spin`...; empty for any other).
    pub motion_mode: &'static str,
    /// A Ranger's mode changes made.
    pub mode_changes: u64,
    /// A Ranger's mode changes refused: asked while it moved, or while it changed.
    pub mode_changes_refused: u64,
    /// A Hunter's parking brake (`locked`, `released`; empty for any other).
    pub brake: &'static str,
    /// A Hunter's parking brake changes made (0x131 locking or releasing it).
    pub brake_changes: u64,
    /// Ground-truth pose.
    pub pose: Pose,
    /// Battery voltage, V.
    pub battery_voltage: f64,
    /// The pack's true charge, %.
    pub battery_percent: f64,
    /// The pack's current, A (positive charging).
    pub battery_current: f64,
    /// The 0x151 fault names now set.
    pub faults: Vec<&'static str>,
    /// Who controls the chassis, as its status frame reports it (`can`, `rc`; v2 also
    /// `standby`).
    pub control_mode: &'static str,
}

/// Counts of ignored motion commands.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct IgnoredCounts {
    /// Wrong control mode byte.
    pub wrong_mode: u64,
    /// RC transmitter on.
    pub rc: u64,
    /// E-stop, latched protection or battery cut-off.
    pub inhibited: u64,
    /// Protocol v2: not in CAN command mode (standby).
    pub standby: u64,
    /// A Ranger: motion asked for (not zero) while it changes its mode.
    pub mode_changing: u64,
    /// A Hunter: a speed asked for while its parking brake is locked.
    pub brake_locked: u64,
}

/// Summary of the intervals between motion commands, in ms.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct IntervalStats {
    /// Intervals measured.
    pub count: u64,
    /// Mean, ms.
    pub mean_ms: f64,
    /// Largest, ms.
    pub max_ms: f64,
    /// 99th percentile of the latest 65536, ms.
    pub p99_ms: f64,
}

/// The last valid motion command, in physical units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LastCommand {
    /// m/s.
    pub linear: f64,
    /// m/s leftward (v2).
    pub lateral: f64,
    /// rad/s.
    pub angular: f64,
    /// rad, the inner wheel's steering angle (v2; 0 but on a steered chassis).
    pub steering: f64,
    /// `rc`, `can`, `serial`.
    pub control_mode: &'static str,
    /// The fault-clear code's name.
    pub fault_clear: &'static str,
}

/// A body velocity.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Speeds {
    /// m/s.
    pub linear: f64,
    /// m/s leftward (a chassis that moves sideways).
    pub lateral: f64,
    /// rad/s.
    pub angular: f64,
}

/// The simulated chassis.
#[derive(Debug, Clone)]
pub struct Chassis {
    params: SimParams,
    transport: Transport,
    now: Duration,
    next_feedback: Duration,
    last_valid_motion: Option<Duration>,
    last_motion_received: Option<Duration>,
    target: Speeds,
    actual: Speeds,
    /// A steered chassis' inner-wheel angle now and the one commanded, rad.
    steering: f64,
    target_steering: f64,
    /// A Ranger's motion mode, and until when it changes to it.
    motion_mode: MotionModeV2,
    changing_until: Option<Duration>,
    /// A Hunter's parking brake holds the wheels.
    brake_locked: bool,
    /// A Ranger's wheel speed (m/s, dual Ackermann and parallel) and spin rate (rad/s) now.
    wheel_speed: f64,
    spin_rate: f64,
    pose: Pose,
    motors: [MotorState; 4],
    /// The pack: its charge and what the chassis measures of it.
    battery: Battery,
    /// The terminal voltage the chassis measures, V.
    battery_voltage: f64,
    estop: bool,
    rc: bool,
    /// Latched bits: protections, battery faults, injected motor communication faults.
    latched: FaultBits,
    forced_warnings: FaultBits,
    checksum_error: bool,
    host_lights: Option<(LightCommand, Duration)>,
    breath_tick: u32,
    counters: [RollingCounter; MessageKind::COUNT],
    stats: SimStats,
    intervals: IntervalRecorder,
    /// Valid commands received, by [`MessageKind::index`].
    commands: [u64; MessageKind::COUNT],
    /// Protocol v2 firmware, when the chassis speaks v2.
    v2: Option<v2::FirmwareV2>,
    /// Valid v2 frames received, by CAN id.
    commands_v2: std::collections::BTreeMap<u16, u64>,
}

/// The feedback frames of one period, in the chassis' protocol.
#[derive(Debug, Clone, PartialEq)]
pub enum Feedback {
    /// Protocol v1: seven frames with their rolling counts.
    V1(FeedbackBatch),
    /// Protocol v2: the period's frames (0x211 and 0x241 every fifth period) and any replies.
    V2(Vec<MessageV2>),
}

impl Feedback {
    /// The v1 frames, if the chassis speaks v1.
    pub fn v1(self) -> Option<FeedbackBatch> {
        match self {
            Self::V1(batch) => Some(batch),
            Self::V2(_) => None,
        }
    }

    /// The v2 frames, if the chassis speaks v2.
    pub fn v2(self) -> Option<Vec<MessageV2>> {
        match self {
            Self::V1(_) => None,
            Self::V2(frames) => Some(frames),
        }
    }
}

/// The feedback frames of one period, in the order the real chassis sends them.
pub type FeedbackBatch = [Counted; 7];

impl Chassis {
    /// A chassis at rest at time zero, on `transport`.
    pub fn new(params: SimParams, transport: Transport) -> Self {
        let ambient = params.ambient_temperature;
        let motor = MotorState {
            driver_temperature: ambient,
            motor_temperature: ambient,
            ..MotorState::default()
        };
        Self {
            battery: Battery::new(&params),
            battery_voltage: params.battery_voltage,
            brake_locked: params.parking_brake,
            params,
            transport,
            now: Duration::ZERO,
            next_feedback: Duration::ZERO,
            last_valid_motion: None,
            last_motion_received: None,
            target: Speeds::default(),
            actual: Speeds::default(),
            steering: 0.0,
            target_steering: 0.0,
            motion_mode: MotionModeV2::DualAckermann,
            changing_until: None,
            wheel_speed: 0.0,
            spin_rate: 0.0,
            pose: Pose::default(),
            motors: [motor; 4],
            estop: false,
            rc: false,
            latched: FaultBits::NONE,
            forced_warnings: FaultBits::NONE,
            checksum_error: false,
            host_lights: None,
            breath_tick: 0,
            counters: [RollingCounter::default(); MessageKind::COUNT],
            stats: SimStats::default(),
            intervals: IntervalRecorder::default(),
            commands: [0; MessageKind::COUNT],
            v2: None,
            commands_v2: std::collections::BTreeMap::new(),
        }
    }

    /// The same chassis with protocol v2 firmware: standby at power-on until the host sends
    /// 0x421 `[01]`; speeds clamped to `max_linear` and `max_angular`.
    pub fn with_protocol_v2(mut self) -> Self {
        self.v2 = Some(v2::FirmwareV2::new());
        self
    }

    /// The parameters.
    pub fn params(&self) -> &SimParams {
        &self.params
    }

    /// A valid (checksum-checked) message from the host, received at `now`. Returns why a
    /// motion command was ignored, if it was.
    pub fn handle_message(&mut self, now: Duration, counted: Counted) -> Option<Ignored> {
        self.advance(now);
        if self.v2.is_some() {
            // v2 firmware does not know v1's ids.
            self.stats.rejected += 1;
            return None;
        }
        self.commands[counted.message.kind().index()] += 1;
        match counted.message {
            Message::MotionCommand(command) => self.handle_motion(now, command),
            Message::LightCommand(lights) => {
                self.host_lights = Some((lights, now));
                None
            }
            // Feedback from another chassis on the bus is not a command.
            Message::SystemStatus(_)
            | Message::MotionFeedback(_)
            | Message::MotorFeedback(_)
            | Message::LightFeedback(_) => {
                self.stats.rejected += 1;
                None
            }
        }
    }

    /// A command frame rejected for its checksum: ignored, and the checksum error bit is set.
    pub fn handle_checksum_error(&mut self, now: Duration) {
        self.advance(now);
        self.stats.checksum_failures += 1;
        self.checksum_error = true;
    }

    /// Any other rejected input: counted.
    pub fn handle_rejected(&mut self, now: Duration) {
        self.advance(now);
        self.stats.rejected += 1;
    }

    fn handle_motion(&mut self, now: Duration, command: MotionCommand) -> Option<Ignored> {
        if let Some(previous) = self.last_motion_received.replace(now) {
            self.intervals.record(now.saturating_sub(previous));
        }
        self.stats.last_command = Some(LastCommand {
            linear: command.linear(self.params.max_linear),
            lateral: 0.0,
            angular: command.angular(self.params.max_angular),
            steering: 0.0,
            control_mode: command.control_mode.name(),
            fault_clear: command.fault_clear.name(),
        });
        if self.rc {
            self.stats.ignored.rc += 1;
            return Some(Ignored::Rc);
        }
        if command.control_mode != self.transport.control_mode() {
            self.stats.ignored.wrong_mode += 1;
            return Some(Ignored::WrongMode);
        }
        self.checksum_error = false;
        self.clear_fault(command.fault_clear);
        self.last_valid_motion = Some(now);
        self.target = Speeds {
            linear: command.linear(self.params.max_linear),
            lateral: 0.0,
            angular: command.angular(self.params.max_angular),
        };
        if self.drive_inhibited() {
            self.stats.ignored.inhibited += 1;
            return Some(Ignored::Inhibited);
        }
        None
    }

    fn clear_fault(&mut self, code: FaultClear) {
        let fault = match code {
            FaultClear::BatteryUnderVoltage if self.battery_voltage >= BATTERY_CUTOFF_VOLTS => {
                Fault::BatteryUndervoltageFault
            }
            FaultClear::BatteryOverVoltage if self.battery_voltage <= BATTERY_OVERVOLTAGE_VOLTS => {
                Fault::BatteryOvervoltageFault
            }
            FaultClear::Motor1Comm => Fault::Motor1CommFault,
            FaultClear::Motor2Comm => Fault::Motor2CommFault,
            FaultClear::Motor3Comm => Fault::Motor3CommFault,
            FaultClear::Motor4Comm => Fault::Motor4CommFault,
            FaultClear::DriverOverTemp => Fault::DriverOvertempProtection,
            FaultClear::MotorOverCurrent => Fault::MotorOvercurrentProtection,
            _ => return,
        };
        self.latched = self.latched.with(fault, false);
    }

    /// Applies a fault injection at `now`.
    pub fn inject(&mut self, now: Duration, injection: Injection) {
        self.advance(now);
        match injection {
            Injection::EStop(pressed) => {
                self.estop = pressed;
                if pressed {
                    self.actual = Speeds::default();
                }
            }
            Injection::Rc(on) => {
                self.rc = on;
                if let Some(firmware) = self.v2.as_mut() {
                    firmware.set_rc(on);
                }
            }
            Injection::Protect(protection) => {
                self.latched = self.latched.with(protection.fault(), true);
            }
            Injection::Warn(warning, on) => {
                self.forced_warnings = self.forced_warnings.with(warning.fault(), on);
            }
            Injection::MotorCommFault(motor, on) => {
                self.latched = self.latched.with(motor_comm_fault(motor), on);
            }
            Injection::Battery(volts) => {
                self.battery.set_rest(volts);
                self.battery_voltage =
                    volts + self.battery.current * self.params.battery_resistance_ohm;
            }
            Injection::Charger(amps) => self.battery.charger_amps = amps.max(0.0),
            Injection::PinMotor(motor, value, to) => self.motors[motor.index()].pin(value, to),
            Injection::UnpinMotor(motor) => self.motors[motor.index()].unpin(),
            Injection::Standby => {
                if let Some(firmware) = self.v2.as_mut() {
                    firmware.fall_back_to_standby();
                }
            }
        }
        self.update_latches();
    }

    /// When [`Chassis::poll_feedback`] next has frames.
    pub fn next_feedback_at(&self) -> Duration {
        self.next_feedback
    }

    /// The feedback frames due at `now`, if a period has come. The schedule is absolute: a late
    /// poll sends one batch and skips the periods it missed.
    pub fn poll_feedback(&mut self, now: Duration) -> Option<Feedback> {
        if now < self.next_feedback {
            return None;
        }
        self.advance(now);
        let period = self.params.feedback_period.max(Duration::from_millis(1));
        while self.next_feedback <= now {
            self.next_feedback += period;
        }
        self.breath_tick = (self.breath_tick + 1) % BREATH_STEPS;
        if self.v2.is_some() {
            return Some(Feedback::V2(self.feedback_v2()));
        }
        let status = Message::SystemStatus(self.system_status());
        let motion = Message::MotionFeedback(MotionFeedback {
            linear_mm_s: to_i16(self.actual.linear * 1000.0 * self.params.reported_distance_scale),
            angular_mrad_s: to_i16(self.actual.angular * 1000.0 * self.params.reported_yaw_scale),
        });
        let motor = |n: usize| Message::MotorFeedback(self.motor_feedback(Motor::ALL[n]));
        let messages = [
            motion,
            motor(0),
            motor(1),
            motor(2),
            motor(3),
            Message::LightFeedback(self.lights()),
            status,
        ];
        Some(Feedback::V1(messages.map(|message| Counted {
            message,
            count: self.counters[message.kind().index()].next_count(),
        })))
    }

    /// The speeds the chassis is driving toward at `now`: the last command, or zero when the
    /// command is older than the timeout or driving is inhibited.
    pub fn target_at(&self, now: Duration) -> Speeds {
        let fresh = self
            .last_valid_motion
            .is_some_and(|at| now.saturating_sub(at) < self.params.command_timeout);
        if fresh && !self.drive_inhibited() && !self.brake_locked {
            self.target
        } else {
            Speeds::default()
        }
    }

    /// The actual speeds.
    pub fn actual(&self) -> Speeds {
        self.actual
    }

    /// The ground-truth pose.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// The system status as 0x151 would report it now.
    pub fn system_status(&self) -> SystemStatus {
        SystemStatus {
            state: if self.estop {
                ChassisState::EStop
            } else {
                ChassisState::Normal
            },
            control_mode: if self.rc {
                ControlMode::Rc
            } else {
                self.transport.control_mode()
            },
            battery_decivolts: (self.battery_voltage * 10.0).round().clamp(0.0, 65535.0) as u16,
            faults: self.faults(),
        }
    }

    /// The statistics at the current time.
    pub fn stats(&self) -> SimStats {
        let mut stats = self.stats.clone();
        stats.motion_command_intervals = self.intervals.stats();
        stats.commands = MessageKind::ALL
            .iter()
            .filter(|kind| self.commands[kind.index()] > 0)
            .map(|kind| {
                (
                    format!("0x{:03X}", kind.can_id()),
                    self.commands[kind.index()],
                )
            })
            .chain(
                self.commands_v2
                    .iter()
                    .map(|(id, count)| (format!("0x{id:03X}"), *count)),
            )
            .collect();
        stats.control_mode = match &self.v2 {
            Some(firmware) => firmware.mode().name(),
            None => self.system_status().control_mode.name(),
        };
        stats.actual = self.actual;
        stats.steering = self.steering;
        stats.motion_mode = if self.params.motion_modes {
            self.motion_mode.name()
        } else {
            ""
        };
        stats.brake = match (self.params.parking_brake, self.brake_locked) {
            (false, _) => "",
            (true, true) => "locked",
            (true, false) => "released",
        };
        stats.pose = self.pose;
        stats.battery_voltage = self.battery_voltage;
        stats.battery_percent = self.battery.charge_percent;
        stats.battery_current = self.battery.current;
        stats.faults = self.faults().iter().map(Fault::name).collect();
        stats
    }

    fn drive_inhibited(&self) -> bool {
        self.estop
            || self.rc
            || self.latched.any_protection()
            || self.latched.contains(Fault::BatteryUndervoltageFault)
    }

    /// The hottest driver temperature and the largest motor current (magnitude).
    fn hottest_and_highest(&self) -> (f64, f64) {
        let hottest = self
            .motors
            .iter()
            .map(MotorState::driver_temperature)
            .fold(f64::MIN, f64::max);
        let highest = self
            .motors
            .iter()
            .map(|m| m.current().abs())
            .fold(0.0, f64::max);
        (hottest, highest)
    }

    fn faults(&self) -> FaultBits {
        let mut bits = FaultBits(self.latched.0 | self.forced_warnings.0);
        let (hottest, highest) = self.hottest_and_highest();
        bits = bits
            .with(Fault::CommandChecksumError, self.checksum_error)
            .with(
                Fault::BatteryUndervoltageWarning,
                self.battery_voltage < BATTERY_WARNING_VOLTS,
            );
        if hottest > OVERTEMP_WARNING_C {
            bits = bits.with(Fault::DriverOvertempWarning, true);
        }
        if highest > OVERCURRENT_WARNING_A {
            bits = bits.with(Fault::MotorOvercurrentWarning, true);
        }
        if self.estop {
            // The drivers lose power with the e-stop: their communication fails (real capture).
            for motor in Motor::ALL {
                bits = bits.with(motor_comm_fault(motor), true);
            }
        }
        bits
    }

    fn update_latches(&mut self) {
        let (hottest, highest) = self.hottest_and_highest();
        let mut latched = self.latched;
        if hottest > OVERTEMP_PROTECTION_C {
            latched = latched.with(Fault::DriverOvertempProtection, true);
        }
        if highest > OVERCURRENT_PROTECTION_A {
            latched = latched.with(Fault::MotorOvercurrentProtection, true);
        }
        if self.battery_voltage < BATTERY_CUTOFF_VOLTS {
            latched = latched.with(Fault::BatteryUndervoltageFault, true);
        }
        if self.battery_voltage > BATTERY_OVERVOLTAGE_VOLTS {
            latched = latched.with(Fault::BatteryOvervoltageFault, true);
        }
        self.latched = latched;
    }

    /// Moves the simulation forward to `now` in small steps.
    fn advance(&mut self, now: Duration) {
        while self.now < now {
            let step = (now - self.now).min(STEP);
            self.step(self.now + step, step.as_secs_f64());
        }
    }

    fn step(&mut self, at: Duration, dt: f64) {
        self.now = at;
        let target = self.target_at(at);
        let previous = self.actual;
        if let Some(ranger) = self.params.four_wheel() {
            self.step_four_wheel(&ranger, target, at, dt);
        } else if self.estop {
            self.actual = Speeds::default();
        } else {
            self.actual.linear += ramp(
                target.linear - self.actual.linear,
                self.params.linear_acceleration * dt,
            );
            self.actual.angular += ramp(
                target.angular - self.actual.angular,
                self.params.angular_acceleration * dt,
            );
            // Sideways as forward.
            self.actual.lateral += ramp(
                target.lateral - self.actual.lateral,
                self.params.linear_acceleration * dt,
            );
        }
        if let Some(steering) = self.params.steering() {
            // The wheels turn at their rate; the yaw is what they and the speed make.
            // (A Ranger's are stepped above.)
            self.steering += ramp(self.target_steering - self.steering, steering.rate * dt);
            self.actual.angular = steering.yaw_rate_from_inner(self.actual.linear, self.steering);
        }
        let Speeds {
            linear,
            lateral,
            angular,
        } = self.actual;
        self.pose.step_body(linear, lateral, angular, dt);
        if let Some(firmware) = self.v2.as_mut() {
            let half_track = self.params.track_width / 2.0;
            firmware.step(
                linear - angular * half_track,
                linear + angular * half_track,
                dt,
            );
        }
        let acceleration = (linear - previous.linear) / dt;
        self.step_motors(acceleration, dt);
        self.update_latches();
    }

    /// A Ranger's step: the mode change ends when its time is up; meanwhile, and in e-stop,
    /// nothing moves; the wheels speed up and turn at their rates, and the body moves as its
    /// mode makes them move it.
    fn step_four_wheel(&mut self, ranger: &FourWheel, target: Speeds, at: Duration, dt: f64) {
        if self.changing_until.is_some_and(|until| at >= until) {
            self.changing_until = None;
        }
        // The wheels roll only once they point (nearly) where they are told: a turn of the
        // wheels from straight ahead to sideways does not drag the body forward meanwhile.
        let aligned = (self.target_steering - self.steering).abs() <= ALIGNED;
        let still = self.estop || self.changing_until.is_some();
        let (speed, spin) = if still {
            (0.0, 0.0)
        } else {
            (if aligned { target.linear } else { 0.0 }, target.angular)
        };
        if self.estop {
            (self.wheel_speed, self.spin_rate) = (0.0, 0.0);
        }
        self.wheel_speed += ramp(
            speed - self.wheel_speed,
            self.params.linear_acceleration * dt,
        );
        self.spin_rate += ramp(spin - self.spin_rate, self.params.angular_acceleration * dt);
        self.steering += ramp(self.target_steering - self.steering, ranger.rate * dt);
        self.actual = match self.motion_mode {
            MotionModeV2::DualAckermann => Speeds {
                linear: self.wheel_speed,
                lateral: 0.0,
                angular: ranger.yaw_rate_from_inner(self.wheel_speed, self.steering),
            },
            MotionModeV2::Parallel => {
                let (linear, lateral) = ranger.body_from_parallel(self.wheel_speed, self.steering);
                Speeds {
                    linear,
                    lateral,
                    angular: 0.0,
                }
            }
            MotionModeV2::Spin => Speeds {
                linear: 0.0,
                lateral: 0.0,
                angular: self.spin_rate,
            },
            MotionModeV2::Park | MotionModeV2::SideSlip | MotionModeV2::Unknown(_) => {
                Speeds::default()
            }
        };
    }

    /// A Ranger's 0x141: the mode changes, taking `mode_change`, only standing still and not
    /// while it changes already; the wheels turn to it.
    fn set_motion_mode(&mut self, now: Duration, mode: MotionModeV2) {
        if self.params.four_wheel().is_none() {
            self.stats.rejected += 1;
            return;
        }
        // Asked again for the mode it is in or changing to (the host repeats it until 0x291
        // says so): nothing to do.
        if mode == self.motion_mode {
            return;
        }
        let moving = self.wheel_speed.abs() > STANDSTILL || self.spin_rate.abs() > STANDSTILL;
        let known = !matches!(mode, MotionModeV2::Unknown(_));
        if moving || self.changing_until.is_some() || !known {
            self.stats.mode_changes_refused += 1;
            return;
        }
        self.motion_mode = mode;
        self.changing_until = Some(now + self.params.mode_change);
        self.stats.mode_changes += 1;
        self.target = Speeds::default();
        self.target_steering = 0.0;
    }

    /// A Ranger's 0x111 in the mode it is in: the wheels' speed and angle, or the spin rate
    /// (bytes 2-3, or 4-5 on a Mini 2.0: the other field then means nothing). Nothing while
    /// it changes its mode.
    fn four_wheel_target(&mut self, ranger: &FourWheel, command: &MotionV2) -> Option<Ignored> {
        let (max_linear, max_angular) = (self.params.max_linear, self.params.max_angular);
        if self.changing_until.is_some() {
            self.target = Speeds::default();
            if *command != MotionV2::default() {
                self.stats.ignored.mode_changing += 1;
            }
            return Some(Ignored::ModeChanging);
        }
        let speed = command.linear().clamp(-max_linear, max_linear);
        let spin = if ranger.spin_in_lateral {
            command.lateral()
        } else {
            command.angular()
        };
        self.target = Speeds::default();
        match self.motion_mode {
            MotionModeV2::DualAckermann => {
                self.target.linear = speed;
                self.target_steering = command
                    .steering()
                    .clamp(-ranger.max_inner, ranger.max_inner);
            }
            MotionModeV2::Parallel => {
                self.target.linear = speed;
                self.target_steering = command
                    .steering()
                    .clamp(-ranger.max_parallel, ranger.max_parallel);
            }
            MotionModeV2::Spin => {
                self.target.angular = spin.clamp(-max_angular, max_angular);
                self.target_steering = 0.0;
            }
            MotionModeV2::Park | MotionModeV2::SideSlip | MotionModeV2::Unknown(_) => {}
        }
        None
    }

    /// A Ranger's 0x221 (its wheels' speed and angle, or its spin rate) and 0x291.
    /// A Ranger's reports: 0x221, 0x291, and each wheel's angle (0x271) and speed (0x281) as
    /// the body moves, in [`FourWheel::wheels`]' order.
    fn four_wheel_state(&self) -> (MotionV2, MotionModeStateV2, WheelsV2, WheelsV2) {
        let spinning = self.motion_mode == MotionModeV2::Spin;
        let motion = MotionV2 {
            linear_mm_s: to_i16(if spinning {
                0.0
            } else {
                self.wheel_speed * 1000.0
            }),
            angular_mrad_s: to_i16(if spinning {
                self.spin_rate * 1000.0
            } else {
                0.0
            }),
            lateral_mm_s: 0,
            steering_mrad: to_i16(self.steering * 1000.0),
        };
        let mode = MotionModeStateV2::new(self.motion_mode, self.changing_until.is_some());
        let wheels = self.params.four_wheel().map_or([(0.0, 0.0); 4], |ranger| {
            let Speeds {
                linear,
                lateral,
                angular,
            } = self.actual;
            ranger.wheels(linear, lateral, angular)
        });
        let thousandths = |value: f64| to_i16(value * 1000.0);
        let angles = WheelsV2(wheels.map(|(angle, _)| thousandths(angle)));
        let speeds = WheelsV2(wheels.map(|(_, speed)| thousandths(speed)));
        (motion, mode, angles, speeds)
    }

    fn step_motors(&mut self, acceleration: f64, dt: f64) {
        let half_track = self.params.track_width / 2.0;
        // Sideways motion is left out: which way each mecanum wheel then turns is in no source.
        let Speeds {
            linear, angular, ..
        } = self.actual;
        let (left, right) = (linear - angular * half_track, linear + angular * half_track);
        let rpm_per_mps =
            60.0 / (2.0 * std::f64::consts::PI * self.params.wheel_radius) * self.params.gear_ratio;
        let ambient = self.params.ambient_temperature;
        let mut total_current = 0.5; // electronics
        // Wheels dragged sideways to turn (skid-steer, tracks) draw most; steered ones do not.
        let steered = self.params.motion_modes || self.params.steering().is_some();
        let scrub = if steered { 0.0 } else { 5.0 };
        for motor in Motor::ALL {
            // 1 front-right, 2 front-left, 3 rear-left, 4 rear-right; left shafts turn the other
            // way for forward motion (vendor SDK; unverified on hardware).
            let (wheel, shaft_sign) = match motor.number() {
                1 | 4 => (right, 1.0),
                _ => (left, -1.0),
            };
            let state = &mut self.motors[motor.index()];
            state.rpm = shaft_sign * wheel * rpm_per_mps;
            let moving = wheel.abs() > STANDSTILL || angular.abs() > STANDSTILL;
            let load = if moving {
                0.4 + 1.2 * wheel.abs() + scrub * angular.abs()
            } else {
                0.0
            };
            let torque = load * wheel.signum() + 4.0 * acceleration;
            state.current = shaft_sign * torque;
            total_current += state.current().abs();
            let heat = 2.0 * state.current().abs();
            state.driver_temperature += (ambient + heat - state.driver_temperature) * dt / 60.0;
            state.motor_temperature +=
                (ambient + 1.5 * heat - state.motor_temperature) * dt / 120.0;
        }
        self.battery_voltage = self.battery.step(total_current, dt, &self.params);
    }

    fn motor_feedback(&self, motor: Motor) -> MotorFeedback {
        let state = &self.motors[motor.index()];
        MotorFeedback {
            motor,
            current_deciamps: to_i16(state.current() * 10.0),
            rpm: to_i16(state.rpm()),
            driver_temperature: to_i8(state.driver_temperature()),
            motor_temperature: to_i8(state.motor_temperature()),
        }
    }

    fn lights(&self) -> LightCommand {
        let breath = {
            let step = self.breath_tick % BREATH_STEPS;
            (if step <= 100 {
                step
            } else {
                BREATH_STEPS - step
            }) as u8
        };
        let shown = |light: Light| Light {
            brightness: match light.mode {
                LightMode::Off => 0,
                LightMode::On => 100,
                LightMode::Breath => breath,
                LightMode::Custom | LightMode::Unknown(_) => light.brightness,
            },
            ..light
        };
        let host = self.host_lights.filter(|(lights, at)| {
            lights.enabled
                && (self.transport != Transport::Serial
                    || self.now.saturating_sub(*at) < self.params.serial_light_timeout)
        });
        if let Some((lights, _)) = host {
            return LightCommand {
                enabled: true,
                front: shown(lights.front),
                rear: shown(lights.rear),
            };
        }
        // The chassis' own logic (manual 2.5, "normally off"): standing still, front off and rear
        // breathing; moving, front on and rear off.
        let Speeds {
            linear,
            lateral,
            angular,
        } = self.actual;
        let moving = [linear, lateral, angular]
            .iter()
            .any(|speed| speed.abs() > STANDSTILL);
        let (front, rear) = if moving {
            (LightMode::On, LightMode::Off)
        } else {
            (LightMode::Off, LightMode::Breath)
        };
        LightCommand {
            enabled: false,
            front: shown(Light {
                mode: front,
                brightness: 0,
            }),
            rear: shown(Light {
                mode: rear,
                brightness: 0,
            }),
        }
    }
}

fn motor_comm_fault(motor: Motor) -> Fault {
    [
        Fault::Motor1CommFault,
        Fault::Motor2CommFault,
        Fault::Motor3CommFault,
        Fault::Motor4CommFault,
    ][motor.index()]
}

fn ramp(error: f64, limit: f64) -> f64 {
    error.clamp(-limit, limit)
}

fn to_i16(value: f64) -> i16 {
    value
        .round()
        .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
}

fn to_i8(value: f64) -> i8 {
    value.round().clamp(f64::from(i8::MIN), f64::from(i8::MAX)) as i8
}

/// The intervals between motion commands in bounded memory: count, mean and maximum over all
/// of them, the 99th percentile over the latest [`IntervalRecorder::WINDOW`].
#[derive(Debug, Clone, Default)]
struct IntervalRecorder {
    count: u64,
    total: Duration,
    max: Duration,
    latest_us: Vec<u32>,
    next: usize,
}

impl IntervalRecorder {
    /// Intervals kept for the percentile: 22 minutes at 50 Hz.
    const WINDOW: usize = 1 << 16;

    fn record(&mut self, interval: Duration) {
        self.count += 1;
        self.total += interval;
        self.max = self.max.max(interval);
        let micros = u32::try_from(interval.as_micros()).unwrap_or(u32::MAX);
        if self.latest_us.len() < Self::WINDOW {
            self.latest_us.push(micros);
        } else {
            self.latest_us[self.next] = micros;
        }
        self.next = (self.next + 1) % Self::WINDOW;
    }

    fn stats(&self) -> IntervalStats {
        if self.count == 0 {
            return IntervalStats::default();
        }
        let mut sorted = self.latest_us.clone();
        sorted.sort_unstable();
        let p99_index = ((sorted.len() as f64 * 0.99).ceil() as usize).clamp(1, sorted.len()) - 1;
        IntervalStats {
            count: self.count,
            mean_ms: self.total.as_secs_f64() * 1000.0 / self.count as f64,
            max_ms: self.max.as_secs_f64() * 1000.0,
            p99_ms: f64::from(sorted[p99_index]) / 1000.0,
        }
    }
}
