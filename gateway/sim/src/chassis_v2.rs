//! The chassis with protocol v2 firmware (SCOUT 2.0, SCOUT MINI): the same physical model, other
//! frames, and v2's rules (protocol-v2-notes 3 and 5): standby at power-on, where only 0x421
//! is obeyed; 0x111 drives only in CAN command mode; the RC takes the mode (3) and, when it lets
//! go, leaves the chassis in standby until the host sends 0x421 again; speeds in mm/s and
//! mrad/s, clamped to the model's limits; wheel odometers in mm; 0x211 and 0x241 every 100 ms,
//! the rest every 20 ms.

use std::time::Duration;

use scout_protocol::sequence::RollingCounter;
use scout_protocol::v2::{
    ActuatorHighV2, ActuatorLowV2, BmsV2, BrakeV2, ControlModeV2, DriverStateV2, ErrorBitsV2,
    ErrorClearV2, LightsV2, MessageV2, MotionV2, OdometerV2, RcStateV2, SwitchPosition,
    SystemStateV2, VersionRequestForm, VersionV2,
};
use scout_protocol::{ChassisState, Fault, LightCommand, Motor};

use super::{BATTERY_CUTOFF_VOLTS, BATTERY_WARNING_VOLTS, Chassis, Ignored, LastCommand, Speeds};

/// 0x211 and 0x241 go out every this many feedback periods (100 ms, the 2020 manual's period).
const SLOW_EVERY: u32 = 5;

/// What the simulated firmware answers a version request with.
const VERSION: VersionV2 = VersionV2 {
    controller_hardware: 0x0100,
    driver_hardware: 0x0100,
    controller_software: 0x0203,
    driver_software: 0x0105,
};

/// The answer to the current SDK's version request: ten ASCII frames (the SDK waits for 80
/// characters).
const VERSION_TEXT: &[u8; 80] =
    b"scout-sim v2 firmware: controller hw 1.0 sw 2.3, driver hw 1.0 sw 1.5           ";

/// The protocol v2 firmware's own state.
#[derive(Debug, Clone)]
pub(super) struct FirmwareV2 {
    /// Who controls the chassis.
    mode: ControlModeV2,
    /// Left and right wheel distances, m.
    odometer: (f64, f64),
    /// Feedback periods sent.
    tick: u32,
    light_count: RollingCounter,
    system_count: RollingCounter,
    rc_count: RollingCounter,
    /// Replies to send with the next feedback (version answers).
    replies: Vec<MessageV2>,
}

impl FirmwareV2 {
    pub(super) fn new() -> Self {
        Self {
            mode: ControlModeV2::Standby,
            odometer: (0.0, 0.0),
            tick: 0,
            light_count: RollingCounter::default(),
            system_count: RollingCounter::default(),
            rc_count: RollingCounter::default(),
            replies: Vec::new(),
        }
    }

    /// Integrates the wheels' distances over `dt` s at `left` and `right` m/s.
    pub(super) fn step(&mut self, left: f64, right: f64, dt: f64) {
        self.odometer.0 += left * dt;
        self.odometer.1 += right * dt;
    }

    /// The RC transmitter switched on (it takes the mode) or off (standby).
    pub(super) fn set_rc(&mut self, on: bool) {
        self.mode = if on {
            ControlModeV2::Rc
        } else {
            ControlModeV2::Standby
        };
    }

    /// Standby, unless the RC holds the chassis (what a firmware does by itself, for tests).
    pub(super) fn fall_back_to_standby(&mut self) {
        if self.mode != ControlModeV2::Rc {
            self.mode = ControlModeV2::Standby;
        }
    }

    /// Who controls the chassis now.
    pub(super) fn mode(&self) -> ControlModeV2 {
        self.mode
    }
}

fn mm(meters: f64) -> i32 {
    (meters * 1000.0)
        .round()
        .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32
}

fn tenths_u16(value: f64) -> u16 {
    (value * 10.0).round().clamp(0.0, f64::from(u16::MAX)) as u16
}

impl Chassis {
    /// A valid v2 frame from the host, received at `now`. Returns why a motion command was
    /// ignored, if it was.
    pub fn handle_v2(&mut self, now: Duration, message: MessageV2) -> Option<Ignored> {
        self.advance(now);
        *self.commands_v2.entry(message.can_id()).or_default() += 1;
        let Some(firmware) = self.v2.as_mut() else {
            self.stats.rejected += 1;
            return None;
        };
        match message {
            MessageV2::MotionCommand(command) => self.handle_motion_v2(now, command),
            MessageV2::ControlMode(mode) => {
                // The RC has the top authority: while it holds the chassis, 0x421 changes nothing.
                if firmware.mode != ControlModeV2::Rc {
                    match mode {
                        ControlModeV2::Standby | ControlModeV2::Can | ControlModeV2::Uart => {
                            firmware.mode = mode;
                        }
                        ControlModeV2::Rc | ControlModeV2::Unknown(_) => self.stats.rejected += 1,
                    }
                }
                None
            }
            MessageV2::LightCommand(lights) => {
                self.host_lights = Some((
                    LightCommand {
                        enabled: lights.host_controls(),
                        front: scout_protocol::Light {
                            mode: lights.front_mode,
                            brightness: lights.front_brightness,
                        },
                        rear: scout_protocol::Light {
                            mode: lights.rear_mode,
                            brightness: lights.rear_brightness,
                        },
                    },
                    now,
                ));
                None
            }
            MessageV2::ErrorClear(code) => {
                self.clear_error_v2(code);
                None
            }
            MessageV2::SetMotionMode(mode) => {
                self.set_motion_mode(now, mode);
                None
            }
            MessageV2::Brake(brake) => {
                self.set_brake(brake);
                None
            }
            MessageV2::VersionRequest(VersionRequestForm::Binary) => {
                firmware.replies.push(MessageV2::Version(VERSION));
                None
            }
            MessageV2::VersionRequest(VersionRequestForm::Text) => {
                firmware
                    .replies
                    .extend(VERSION_TEXT.chunks_exact(8).map(|chunk| {
                        let mut text = [0; 8];
                        text.copy_from_slice(chunk);
                        MessageV2::VersionText(text)
                    }));
                None
            }
            // Frames only a chassis sends, from another node on the bus: not commands.
            MessageV2::SystemState(_)
            | MessageV2::MotionState(_)
            | MessageV2::LightState(_)
            | MessageV2::RcState(_)
            | MessageV2::ActuatorHigh(_)
            | MessageV2::ActuatorLow(_)
            | MessageV2::MotorAngles(_)
            | MessageV2::MotorSpeeds(_)
            | MessageV2::MotionModeState(_)
            | MessageV2::Odometer(_)
            | MessageV2::Version(_)
            | MessageV2::VersionText(_)
            | MessageV2::Bms(_)
            | MessageV2::BmsAlarm(_) => {
                self.stats.rejected += 1;
                None
            }
        }
    }

    fn handle_motion_v2(&mut self, now: Duration, command: MotionV2) -> Option<Ignored> {
        let firmware = self.v2.as_ref()?;
        let mode = firmware.mode;
        let (max_linear, max_angular, max_lateral) = (
            self.params.max_linear,
            self.params.max_angular,
            self.params.max_lateral,
        );
        if let Some(previous) = self.last_motion_received.replace(now) {
            self.intervals.record(now.saturating_sub(previous));
        }
        self.stats.last_command = Some(LastCommand {
            linear: command.linear(),
            lateral: command.lateral(),
            angular: command.angular(),
            steering: command.steering(),
            control_mode: mode.name(),
            fault_clear: "none",
        });
        match mode {
            ControlModeV2::Can => {}
            ControlModeV2::Rc => {
                self.stats.ignored.rc += 1;
                return Some(Ignored::Rc);
            }
            ControlModeV2::Standby | ControlModeV2::Uart | ControlModeV2::Unknown(_) => {
                self.stats.ignored.standby += 1;
                return Some(Ignored::NotCommandMode);
            }
        }
        self.last_valid_motion = Some(now);
        if let Some(ranger) = self.params.four_wheel() {
            if let Some(ignored) = self.four_wheel_target(&ranger, &command) {
                return Some(ignored);
            }
        } else {
            self.target = Speeds {
                linear: command.linear().clamp(-max_linear, max_linear),
                lateral: command.lateral().clamp(-max_lateral, max_lateral),
                angular: command.angular().clamp(-max_angular, max_angular),
            };
            if let Some(steering) = self.params.steering() {
                // A steered chassis turns by its wheels' angle; its yaw-rate field means
                // nothing.
                self.target.angular = 0.0;
                self.target_steering = command
                    .steering()
                    .clamp(-steering.max_inner, steering.max_inner);
            }
        }
        if self.drive_inhibited() {
            self.stats.ignored.inhibited += 1;
            return Some(Ignored::Inhibited);
        }
        if self.brake_locked && command.linear_mm_s != 0 {
            // Not kept for after a release: the wheels move on a command received released.
            self.target = Speeds::default();
            self.stats.ignored.brake_locked += 1;
            return Some(Ignored::BrakeLocked);
        }
        None
    }

    /// A Hunter's 0x131: the brake locks (the wheels stop turning) or releases; anything else,
    /// or on a chassis without one, is rejected.
    fn set_brake(&mut self, brake: BrakeV2) {
        let locked = match (self.params.parking_brake, brake) {
            (true, BrakeV2::Locked) => true,
            (true, BrakeV2::Released) => false,
            (false, _) | (true, BrakeV2::Unknown(_)) => {
                self.stats.rejected += 1;
                return;
            }
        };
        if locked != self.brake_locked {
            self.stats.brake_changes += 1;
        }
        self.brake_locked = locked;
    }

    /// 0x441: every latched error, or one motor's communication fault.
    fn clear_error_v2(&mut self, code: ErrorClearV2) {
        let motor = |number| Motor::new(number).map(super::motor_comm_fault);
        let clear: Vec<Fault> = match code {
            ErrorClearV2::All => {
                let mut all = vec![
                    Fault::DriverOvertempProtection,
                    Fault::MotorOvercurrentProtection,
                    Fault::Motor1CommFault,
                    Fault::Motor2CommFault,
                    Fault::Motor3CommFault,
                    Fault::Motor4CommFault,
                ];
                if self.battery_voltage >= BATTERY_CUTOFF_VOLTS {
                    all.push(Fault::BatteryUndervoltageFault);
                }
                all
            }
            ErrorClearV2::Motor1 => motor(1).into_iter().collect(),
            ErrorClearV2::Motor2 => motor(2).into_iter().collect(),
            ErrorClearV2::Motor3 => motor(3).into_iter().collect(),
            ErrorClearV2::Motor4 => motor(4).into_iter().collect(),
            ErrorClearV2::Unknown(_) => Vec::new(),
        };
        for fault in clear {
            self.latched = self.latched.with(fault, false);
        }
    }

    /// The v2 system state now.
    pub fn system_state_v2(&self) -> Option<SystemStateV2> {
        let firmware = self.v2.as_ref()?;
        let latched = self.latched;
        let mut errors = 0u16;
        let mut set = |bit: u16, on: bool| {
            if on {
                errors |= bit;
            }
        };
        set(0x0001, latched.contains(Fault::BatteryUndervoltageFault));
        set(0x0002, self.battery_voltage < BATTERY_WARNING_VOLTS);
        for (n, bit) in [(1, 0x0008), (2, 0x0010), (3, 0x0020), (4, 0x0040)] {
            let motor = Motor::new(n).expect("motors 1..=4");
            set(bit, latched.contains(super::motor_comm_fault(motor)));
        }
        set(0x0100, latched.any_protection());
        Some(SystemStateV2 {
            state: if self.estop {
                ChassisState::EStop
            } else {
                ChassisState::Normal
            },
            control_mode: firmware.mode,
            battery_decivolts: tenths_u16(self.battery_voltage),
            errors: ErrorBitsV2(errors),
            reserved: u8::from(self.params.parking_brake && self.brake_locked),
            count: 0,
        })
    }

    fn driver_state_v2(&self, motor: Motor) -> DriverStateV2 {
        let latched = self.latched;
        let mut bits = 0u8;
        if self.battery_voltage < BATTERY_WARNING_VOLTS {
            bits |= 0x01;
        }
        if latched.contains(Fault::MotorOvercurrentProtection) {
            bits |= 0x04;
        }
        if latched.contains(Fault::DriverOvertempProtection) {
            bits |= 0x08;
        }
        if latched.contains(super::motor_comm_fault(motor)) {
            bits |= 0x10;
        }
        DriverStateV2(bits)
    }

    /// A smart battery's frames: 0x361 (charge, health, voltage, current positive charging,
    /// temperature) and 0x362 (no alarms).
    fn bms_v2(&self) -> [MessageV2; 2] {
        let tenths = |value: f64| super::to_i16(value * 10.0);
        let battery = &self.battery;
        [
            MessageV2::Bms(BmsV2 {
                charge_percent: battery.charge_percent.round().clamp(0.0, 100.0) as u8,
                health_percent: self.params.battery_health_percent.round().clamp(0.0, 100.0) as u8,
                decivolts: tenths(self.battery_voltage),
                deciamps: tenths(battery.current),
                decidegrees: tenths(self.params.ambient_temperature),
            }),
            MessageV2::BmsAlarm([0; 8]),
        ]
    }

    /// The v2 frames of one feedback period (and any replies due), oldest first.
    pub(super) fn feedback_v2(&mut self) -> Vec<MessageV2> {
        let system = self.system_state_v2();
        let lights = self.lights();
        let actual = self.actual;
        let rc_on = self.rc;
        let motors: Vec<(ActuatorHighV2, ActuatorLowV2)> = Motor::ALL
            .iter()
            .take(usize::from(self.params.actuators))
            .map(|&motor| {
                let state = &self.motors[motor.index()];
                let high = ActuatorHighV2 {
                    motor: motor.number(),
                    rpm: super::to_i16(state.rpm()),
                    current_deciamps: super::to_i16(state.current() * 10.0),
                    pulses: 0,
                };
                let low = ActuatorLowV2 {
                    motor: motor.number(),
                    driver_decivolts: tenths_u16(self.battery_voltage),
                    driver_temperature: super::to_i16(state.driver_temperature()),
                    motor_temperature: super::to_i8(state.motor_temperature()),
                    driver_state: self.driver_state_v2(motor),
                    reserved: [0; 2],
                };
                (high, low)
            })
            .collect();
        let pulses_per_meter = 4096.0 / (2.0 * std::f64::consts::PI * self.params.wheel_radius)
            * self.params.gear_ratio;
        let (distance_scale, yaw_scale) = (
            self.params.reported_distance_scale,
            self.params.reported_yaw_scale,
        );
        let bms = self.params.bms.then(|| self.bms_v2()).into_iter().flatten();
        let (steered, steering) = (self.params.steering().is_some(), self.steering);
        let ranger = self.params.four_wheel().map(|_| self.four_wheel_state());
        let Some(firmware) = self.v2.as_mut() else {
            return Vec::new();
        };
        let (left, right) = firmware.odometer;
        // A steered chassis reports its wheels' angle, not a yaw rate (as its vendor driver
        // reads it: hunter_ros2 derives the yaw rate from the angle).
        let (angular, steering) = match steered {
            true => (0.0, steering),
            false => (actual.angular * yaw_scale, 0.0),
        };
        let mut frames = match ranger {
            // A Ranger reports its wheels and its mode; no wheel odometer (nothing reads it:
            // agilex-family-notes, and in parallel mode its wheels do not roll forward).
            Some((motion, mode, angles, speeds)) => vec![
                MessageV2::MotionState(motion),
                MessageV2::MotionModeState(mode),
                MessageV2::MotorAngles(angles),
                MessageV2::MotorSpeeds(speeds),
            ],
            None => vec![MessageV2::MotionState(MotionV2 {
                linear_mm_s: super::to_i16(actual.linear * 1000.0 * distance_scale),
                angular_mrad_s: super::to_i16(angular * 1000.0),
                lateral_mm_s: super::to_i16(actual.lateral * 1000.0 * distance_scale),
                steering_mrad: super::to_i16(steering * 1000.0),
            })],
        };
        for (mut high, low) in motors {
            // 1 and 4 are on the right (as in v1's numbering); a 4096-count encoder per turn.
            let side = if matches!(high.motor, 1 | 4) {
                right
            } else {
                left
            };
            high.pulses = (side * pulses_per_meter)
                .round()
                .clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
            frames.push(MessageV2::ActuatorHigh(high));
            frames.push(MessageV2::ActuatorLow(low));
        }
        frames.push(MessageV2::LightState(LightsV2 {
            host_control: u8::from(lights.enabled),
            front_mode: lights.front.mode,
            front_brightness: lights.front.brightness,
            rear_mode: lights.rear.mode,
            rear_brightness: lights.rear.brightness,
            reserved: [0; 2],
            count: firmware.light_count.next_count(),
        }));
        if ranger.is_none() {
            frames.push(MessageV2::Odometer(OdometerV2 {
                left_mm: mm(left * distance_scale),
                right_mm: mm(right * distance_scale),
            }));
        }
        if firmware.tick.is_multiple_of(SLOW_EVERY) {
            frames.extend(bms);
            if let Some(system) = system {
                frames.push(MessageV2::SystemState(SystemStateV2 {
                    count: firmware.system_count.next_count(),
                    ..system
                }));
            }
            if rc_on {
                // The transmitter in manual mode: SWB in the middle.
                frames.push(MessageV2::RcState(RcStateV2 {
                    swa: SwitchPosition::Up,
                    swb: SwitchPosition::Middle,
                    swc: SwitchPosition::Up,
                    swd: SwitchPosition::Up,
                    right_horizontal: 0,
                    right_vertical: 0,
                    left_vertical: 0,
                    left_horizontal: 0,
                    knob: 0,
                    reserved: 0,
                    count: firmware.rc_count.next_count(),
                }));
            }
        }
        firmware.tick = firmware.tick.wrapping_add(1);
        frames.append(&mut firmware.replies);
        frames
    }
}
