//! The ROS 2 messages made from the gateway's state and status (sans-IO: the state, the status
//! and both clocks in, CDR payloads out): odometry and its transform on each new 0x131, the
//! battery on each new 0x151, the wheels with each odometry, diagnostics once a second and on
//! every change of level.

use std::time::Duration;

use scout_interface::StatePayload;
use scout_interface::control::StatusPayload;
use scout_interface::json::{state_json, status_json};
use scout_interface::state::{BatteryLevel, BatteryPayload, BatterySource, LinkState, Received};
use scout_protocol::model::Model;
use scout_protocol::{ChassisState, Severity};
use serde_json::Value;

use crate::config::Ros2Config;
use crate::msgs::{self, Battery, Header, Joints, Odometry, Status, Transform};

scout_protocol::listed! {
    /// The topics the bridge publishes.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
    pub enum Topic {
        Odom,
        Tf,
        BatteryState,
        JointStates,
        Diagnostics,
    }
}

impl Topic {
    pub fn message(self) -> msgs::MessageType {
        match self {
            Topic::Odom => msgs::ODOMETRY,
            Topic::Tf => msgs::TF_MESSAGE,
            Topic::BatteryState => msgs::BATTERY_STATE,
            Topic::JointStates => msgs::JOINT_STATE,
            Topic::Diagnostics => msgs::DIAGNOSTIC_ARRAY,
        }
    }

    /// Its name as configured (unresolved), or `None` when it is switched off.
    pub fn name(self, config: &Ros2Config) -> Option<&str> {
        let topics = &config.topics;
        match self {
            Topic::Odom => Some(&topics.odom),
            Topic::Tf => config.publish_tf.then_some(topics.tf.as_str()),
            Topic::BatteryState => Some(&topics.battery_state),
            Topic::JointStates => Some(&topics.joint_states),
            Topic::Diagnostics => Some(&topics.diagnostics),
        }
    }
}

/// Both clocks read at one instant: the gateway's times are CLOCK_BOOTTIME, ROS stamps are
/// wall-clock time since the Unix epoch.
#[derive(Debug, Clone, Copy)]
pub struct Clocks {
    pub monotonic_ns: u64,
    pub unix: Duration,
}

impl Clocks {
    /// The wall-clock time of a CLOCK_BOOTTIME instant.
    pub fn stamp(&self, at_ns: u64) -> Duration {
        self.unix.saturating_sub(Duration::from_nanos(
            self.monotonic_ns.saturating_sub(at_ns),
        ))
    }
}

/// No state for this long: the gateway is reported gone.
pub const SILENT_AFTER: Duration = Duration::from_secs(1);

/// Diagnostics go out at least this often (ROS' diagnostic_updater's rate).
pub const DIAGNOSTICS_PERIOD: Duration = Duration::from_secs(1);

/// The relative errors of skid-steer odometry (1 sigma) behind its covariance, each axis
/// calibrated (`scout calibrate`: what remains is slip and floors) or not (tyres and firmware:
/// scout_ros#5 saw a turn 26 % off).
const DISTANCE_ERROR: [f64; 2] = [0.02, 0.05];
const TURN_ERROR: [f64; 2] = [0.03, 0.25];
/// Heading lost per metre driven, rad/m (skid-steer slips on uneven floors).
const HEADING_PER_METRE: f64 = 0.02;
/// What the odometry is never better than: 1 cm, 0.01 rad, 1 cm/s, 0.01 rad/s (1 sigma).
const FLOOR: f64 = 0.01;
/// Planar: z, roll and pitch unknown (robot_localization ignores them).
const UNKNOWN: f64 = 1e6;

/// /odom's covariance diagonals (x, y, z, roll, pitch, yaw), pose then twist: the position's
/// uncertainty grows with the distance since the last reset, the heading's with the turning
/// and the distance, the twist's with the speeds; each axis smaller once its factor is
/// calibrated (off 1.0).
fn odometry_covariance(state: &StatePayload, speed: f64, angular: f64) -> ([f64; 6], [f64; 6]) {
    let odometry = &state.odometry;
    let error = |errors: [f64; 2], factor: f64| errors[usize::from(factor == 1.0)];
    let distance_error = error(DISTANCE_ERROR, odometry.distance_scale);
    let turn_error = error(TURN_ERROR, odometry.yaw_scale);
    let variance = |sigma: f64| (sigma + FLOOR).powi(2);
    let distance = odometry.distance.abs();
    let position = variance(distance_error * distance);
    let heading = variance(turn_error * odometry.rotation.abs() + HEADING_PER_METRE * distance);
    let speed = variance(distance_error * speed.abs());
    let rate = variance(turn_error * angular.abs());
    (
        [position, position, UNKNOWN, UNKNOWN, UNKNOWN, heading],
        [speed, speed, UNKNOWN, UNKNOWN, UNKNOWN, rate],
    )
}

/// diagnostic_msgs/DiagnosticStatus levels.
const OK: u8 = 0;
const WARN: u8 = 1;
const ERROR: u8 = 2;
const STALE: u8 = 3;

/// sensor_msgs/BatteryState health.
const HEALTH_UNKNOWN: u8 = 0;
const HEALTH_GOOD: u8 = 1;
const HEALTH_DEAD: u8 = 3;
const HEALTH_OVERVOLTAGE: u8 = 4;

/// Makes the messages, remembering what it already sent.
#[derive(Debug)]
pub struct Messages {
    config: Ros2Config,
    last_motion: Option<u64>,
    last_system: Option<u64>,
    /// Wheel angles integrated from the motors' speeds, rad.
    wheel_angles: [f64; 4],
    last_motors: [Option<u64>; 4],
    last_diagnostics: Option<(u64, [u8; 4])>,
    /// What makes them, the name of its own diagnostic status (`<node>: <maker>`).
    maker: &'static str,
}

/// The bridge's own counters as diagnostic values, read when they are needed.
pub type Counted<'a> = &'a dyn Fn() -> Vec<(String, String)>;

/// One message to publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Outgoing {
    pub topic: Topic,
    pub payload: Vec<u8>,
}

impl Messages {
    pub fn new(config: Ros2Config) -> Self {
        Self::made_by(config, "ros2 bridge")
    }

    /// Messages made by `maker` (named in its diagnostic status: `ros2 bridge`, `recorder`).
    pub fn made_by(config: Ros2Config, maker: &'static str) -> Self {
        Self {
            config,
            last_motion: None,
            last_system: None,
            wheel_angles: [0.0; 4],
            last_motors: [None; 4],
            last_diagnostics: None,
            maker,
        }
    }

    /// What to publish for a state (and the arbiter's latest status, if known); `bridge` gives
    /// what the bridge itself counted, asked only when diagnostics go out.
    pub fn handle_state(
        &mut self,
        state: &StatePayload,
        status: Option<&StatusPayload>,
        clocks: Clocks,
        bridge: Counted<'_>,
    ) -> Vec<Outgoing> {
        let mut out = Vec::new();
        if let Some(at_ns) = fresh(state.motion.received, &mut self.last_motion) {
            self.odometry(state, clocks.stamp(at_ns), &mut out);
            self.joints(state, clocks, &mut out);
            self.steering_joints(state, clocks.stamp(at_ns), &mut out);
        }
        if let Some(at_ns) = fresh(state.system.received, &mut self.last_system) {
            self.battery(state, clocks.stamp(at_ns), &mut out);
        }
        self.diagnostics(state, status, clocks, bridge, &mut out);
        out
    }

    /// What to publish while no state arrives (the gateway stopped, hangs or restarts): after
    /// [`SILENT_AFTER`], diagnostics saying so, at their usual rate.
    pub fn handle_silence(
        &mut self,
        robot: &str,
        last_state_ns: u64,
        clocks: Clocks,
        bridge: Counted<'_>,
    ) -> Vec<Outgoing> {
        let silent = Duration::from_nanos(clocks.monotonic_ns.saturating_sub(last_state_ns));
        if silent < SILENT_AFTER {
            return Vec::new();
        }
        let node = &self.config.node;
        let gateway = Status {
            level: ERROR,
            name: format!("{node}: link"),
            message: format!(
                "no state from gateway '{robot}' for {:.1} s: is scout-gateway running?",
                silent.as_secs_f64()
            ),
            hardware_id: robot.to_owned(),
            values: Vec::new(),
        };
        let stale = |part: &str| Status {
            level: STALE,
            name: format!("{node}: {part}"),
            message: "no state from the gateway".into(),
            hardware_id: robot.to_owned(),
            values: Vec::new(),
        };
        let statuses = [
            gateway,
            stale("chassis"),
            stale("battery"),
            stale("arbiter"),
        ];
        let mut out = Vec::new();
        self.publish_diagnostics(statuses, robot, clocks, bridge, &mut out);
        out
    }

    fn odometry(&self, state: &StatePayload, stamp: Duration, out: &mut Vec<Outgoing>) {
        let frames = &self.config.frames;
        let header = Header {
            stamp,
            frame_id: &frames.odom,
        };
        let odometry = &state.odometry;
        // The speeds the chassis reports, calibrated as the pose is (the factors are 1.0 in a
        // state from before they were published).
        let scale = |factor: f64| if factor > 0.0 { factor } else { 1.0 };
        let linear = state.motion.linear() * scale(odometry.distance_scale);
        let lateral = state.motion.lateral() * scale(odometry.distance_scale);
        let angular = state.motion.angular() * scale(odometry.yaw_scale);
        let (pose_covariance, twist_covariance) =
            odometry_covariance(state, linear.hypot(lateral), angular);
        out.push(Outgoing {
            topic: Topic::Odom,
            payload: Odometry {
                header: header.clone(),
                child_frame_id: &frames.base,
                x: odometry.x,
                y: odometry.y,
                yaw: odometry.yaw,
                linear,
                lateral,
                angular,
                pose_covariance,
                twist_covariance,
            }
            .encode(),
        });
        if self.config.publish_tf {
            out.push(Outgoing {
                topic: Topic::Tf,
                payload: Transform {
                    header,
                    child_frame_id: &frames.base,
                    x: odometry.x,
                    y: odometry.y,
                    yaw: odometry.yaw,
                }
                .encode(),
            });
        }
    }

    /// The wheels: speed from the motor shaft's rpm through the gearbox, effort as the motor
    /// current (A); the angle from the wheel odometer of the wheel's side where the chassis
    /// has one (protocol v2: that side's distance over the wheel radius), else integrated from
    /// the speed. Motors 2 and 3 (left) turn mirrored, as their rpm does, so each wheel's angle
    /// changes at the speed its joint reports.
    fn joints(&mut self, state: &StatePayload, clocks: Clocks, out: &mut Vec<Outgoing>) {
        let gear_ratio = self.config.gear_ratio.unwrap_or(state.chassis.gear_ratio);
        let odometer = state.odometer;
        let radius = state.chassis.wheel_radius;
        let mut velocity = [0.0; 4];
        let mut effort = [0.0; 4];
        let mut newest = 0;
        for (i, motor) in state.motors.iter().enumerate() {
            if !motor.received.valid
                || gear_ratio.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater)
            {
                continue;
            }
            velocity[i] = f64::from(motor.rpm) / gear_ratio * std::f64::consts::TAU / 60.0;
            effort[i] = f64::from(motor.current_deciamps) / 10.0;
            let at = motor.received.at_ns;
            if odometer.received.valid && radius > 0.0 {
                let (side_mm, turning) = match i {
                    // Motors 1 and 4 are on the right, 2 and 3 on the left (mirrored).
                    0 | 3 => (odometer.right_mm, 1.0),
                    _ => (odometer.left_mm, -1.0),
                };
                self.wheel_angles[i] = turning * f64::from(side_mm) / 1000.0 / radius;
            } else if let Some(last) = self.last_motors[i]
                && at > last
            {
                let dt = Duration::from_nanos(at - last).as_secs_f64().min(0.1);
                self.wheel_angles[i] += velocity[i] * dt;
            }
            self.last_motors[i] = Some(at);
            newest = newest.max(at);
        }
        if newest == 0 {
            return;
        }
        // The wheels whose motors report: four on a SCOUT, two on a Tracer or a Bunker.
        let reported: Vec<usize> = (0..4).filter(|&i| state.motors[i].received.valid).collect();
        let pick = |values: &[f64; 4]| reported.iter().map(|&i| values[i]).collect();
        out.push(Outgoing {
            topic: Topic::JointStates,
            payload: Joints {
                header: Header {
                    stamp: clocks.stamp(newest),
                    frame_id: "",
                },
                names: reported
                    .iter()
                    .map(|&i| self.config.wheel_joints[i].as_str())
                    .collect(),
                position: pick(&self.wheel_angles),
                velocity: pick(&velocity),
                effort: pick(&effort),
            }
            .encode(),
        });
    }

    /// The steering joints' angles, a JointState of their own: a Hunter's front wheels from
    /// the inner wheel's angle it reports (0x221), a Ranger's four as 0x271 reports them;
    /// nothing on a chassis that does not steer.
    fn steering_joints(&self, state: &StatePayload, stamp: Duration, out: &mut Vec<Outgoing>) {
        let model = state.chassis.model();
        let angles: Vec<f64> = match (model.and_then(Model::steering), state.motion.wheel_angles())
        {
            (Some(steering), _) => {
                let (left, right) = steering.front_wheels(state.motion.steering());
                vec![left, right]
            }
            (None, Some(angles)) => angles.to_vec(),
            (None, None) => return,
        };
        let names = &self.config.steering_joints;
        out.push(Outgoing {
            topic: Topic::JointStates,
            payload: Joints {
                header: Header {
                    stamp,
                    frame_id: "",
                },
                names: names
                    .iter()
                    .take(angles.len())
                    .map(String::as_str)
                    .collect(),
                position: angles,
                velocity: Vec::new(),
                effort: Vec::new(),
            }
            .encode(),
        });
    }

    /// The battery as the gateway judges it (`state.battery`): the charge as `percentage`
    /// 0..1 (a smart battery's, or the gateway's estimate from the voltage), charging or not;
    /// the current and temperature where a smart battery measures them; NaN only for what
    /// nothing measures or estimates.
    fn battery(&self, state: &StatePayload, stamp: Duration, out: &mut Vec<Outgoing>) {
        let faults = state.faults();
        let has = |name: &str| faults.iter().any(|fault| fault.name == name);
        let health = if has("battery_overvoltage_fault") {
            HEALTH_OVERVOLTAGE
        } else if has("battery_undervoltage_fault") {
            HEALTH_DEAD
        } else if state.system.received.valid {
            HEALTH_GOOD
        } else {
            HEALTH_UNKNOWN
        };
        let battery = match state.battery.source() {
            BatterySource::None => BatteryPayload::unknown(f64::NAN, f64::NAN),
            BatterySource::Bms | BatterySource::Voltage => state.battery,
        };
        let voltage = if battery.voltage.is_finite() {
            battery.voltage
        } else {
            state.system.battery_voltage()
        };
        out.push(Outgoing {
            topic: Topic::BatteryState,
            payload: Battery {
                header: Header {
                    stamp,
                    frame_id: &self.config.frames.base,
                },
                voltage: voltage as f32,
                temperature: battery.temperature as f32,
                current: battery.current as f32,
                design_capacity: battery.capacity_ah as f32,
                percentage: battery.percent().map_or(f32::NAN, |p| (p / 100.0) as f32),
                status: battery.status,
                health,
                present: state.system.received.valid,
            }
            .encode(),
        });
    }

    fn diagnostics(
        &mut self,
        state: &StatePayload,
        status: Option<&StatusPayload>,
        clocks: Clocks,
        bridge: Counted<'_>,
        out: &mut Vec<Outgoing>,
    ) {
        let statuses = diagnostic_statuses(&self.config.node, state, status, clocks.monotonic_ns);
        self.publish_diagnostics(statuses, state.robot.as_str(), clocks, bridge, out);
    }

    /// The diagnostics, with the bridge's own counters, when a second has passed or a level
    /// changed.
    fn publish_diagnostics(
        &mut self,
        statuses: [Status; 4],
        robot: &str,
        clocks: Clocks,
        bridge: Counted<'_>,
        out: &mut Vec<Outgoing>,
    ) {
        let levels = statuses.each_ref().map(|status| status.level);
        let due = match self.last_diagnostics {
            None => true,
            Some((at, last_levels)) => {
                last_levels != levels
                    || clocks.monotonic_ns.saturating_sub(at)
                        >= DIAGNOSTICS_PERIOD.as_nanos() as u64
            }
        };
        if !due {
            return;
        }
        self.last_diagnostics = Some((clocks.monotonic_ns, levels));
        let header = Header {
            stamp: clocks.unix,
            frame_id: "",
        };
        let mut statuses = statuses.to_vec();
        statuses.push(Status {
            level: OK,
            name: format!("{}: {}", self.config.node, self.maker),
            message: "counters".into(),
            hardware_id: robot.to_owned(),
            values: bridge(),
        });
        out.push(Outgoing {
            topic: Topic::Diagnostics,
            payload: msgs::encode_diagnostics(&header, &statuses),
        });
    }
}

/// The receive time of a frame newer than the one last used.
fn fresh(received: Received, last: &mut Option<u64>) -> Option<u64> {
    if !received.valid || last.is_some_and(|last| received.at_ns <= last) {
        return None;
    }
    *last = Some(received.at_ns);
    Some(received.at_ns)
}

/// The link, the chassis, the battery and the arbiter, each a DiagnosticStatus named
/// `<node>: <part>`.
pub fn diagnostic_statuses(
    node: &str,
    state: &StatePayload,
    status: Option<&StatusPayload>,
    now_ns: u64,
) -> [Status; 4] {
    let robot = state.robot.as_str().to_owned();
    let json = state_json(state, now_ns);
    let link_state = state.link.state();
    let link = Status {
        level: match link_state {
            LinkState::Ok => OK,
            LinkState::Silent | LinkState::Disconnected | LinkState::ProtocolMismatch => ERROR,
        },
        name: format!("{node}: link"),
        message: link_state.name().to_owned(),
        hardware_id: robot.clone(),
        values: flatten(&json["link"]),
    };
    let system = &state.system;
    let faults = state.faults();
    let chassis_state = ChassisState::from_raw(system.state);
    let worst = faults
        .iter()
        .map(|fault| fault.severity)
        .fold(OK, |level, severity| {
            level.max(match severity {
                Severity::Warning | Severity::Reserved => WARN,
                Severity::Fault | Severity::Protection => ERROR,
            })
        });
    let (level, message) = if !system.received.valid || link_state != LinkState::Ok {
        (STALE, "no system status from the chassis".to_owned())
    } else {
        let named: Vec<&str> = faults.iter().map(|fault| fault.name).collect();
        let level = match chassis_state {
            ChassisState::Normal => worst,
            _ => ERROR,
        };
        let mut message = chassis_state.name().to_owned();
        if !named.is_empty() {
            message = format!("{message}: {}", named.join(", "));
        }
        (level, message)
    };
    let mut chassis_values = flatten(&json["system"]);
    chassis_values.extend(flatten(&serde_json::json!({ "motion": json["motion"] })));
    let chassis = Status {
        level,
        name: format!("{node}: chassis"),
        message,
        hardware_id: robot.clone(),
        values: chassis_values,
    };
    let battery_state = &state.battery;
    let (level, message) = match battery_state.level() {
        BatteryLevel::Unknown => (STALE, "no battery report yet".to_owned()),
        level => {
            let charge = battery_state
                .percent()
                .map_or_else(|| "charge unknown".to_owned(), |p| format!("{p:.0} %"));
            let source = match battery_state.source() {
                BatterySource::Bms => "smart battery",
                BatterySource::Voltage | BatterySource::None => "estimated from the voltage",
            };
            let mut message = format!(
                "{}: {charge} ({source}), {}",
                level.name(),
                battery_state.status().name()
            );
            let why = battery_state.level_from().words();
            if !why.is_empty() {
                message = format!("{message}; {why}");
            }
            match level {
                _ if link_state != LinkState::Ok => {
                    (STALE, format!("no report from the chassis; last {message}"))
                }
                BatteryLevel::Ok => (OK, message),
                BatteryLevel::Low => (WARN, format!("{message}: charge soon")),
                BatteryLevel::Critical | BatteryLevel::Unknown => {
                    (ERROR, format!("{message}: charge now"))
                }
            }
        }
    };
    let battery = Status {
        level,
        name: format!("{node}: battery"),
        message,
        hardware_id: robot.clone(),
        values: flatten(&json["battery"]),
    };
    let arbiter = match status {
        Some(status) => {
            let json = status_json(status, now_ns);
            let stops: Vec<String> = status
                .stops()
                .iter()
                .map(|stop| format!("{}: {}", stop.owner.as_str(), stop.reason.as_str()))
                .collect();
            let (level, message) = if status.stopped() {
                (WARN, format!("stopped by {}", stops.join("; ")))
            } else {
                let driving = json["selected"]["client"].as_str().unwrap_or("nobody");
                (OK, format!("driving: {driving}"))
            };
            let mut values = flatten(&serde_json::json!({
                "latched": json["latched"],
                "stop_total": json["stop_total"],
                "selected": json["selected"],
                "output": json["output"],
                "autonomy_armed": json["autonomy_armed"],
                "tick": json["tick"],
            }));
            values.extend(flatten(
                &serde_json::json!({ "rejections": json["rejections"] }),
            ));
            Status {
                level,
                name: format!("{node}: arbiter"),
                message,
                hardware_id: robot,
                values,
            }
        }
        None => Status {
            level: STALE,
            name: format!("{node}: arbiter"),
            message: "no status from the gateway yet".into(),
            hardware_id: robot,
            values: Vec::new(),
        },
    };
    [link, chassis, battery, arbiter]
}

/// `{"a": {"b": 1}}` as `[("a.b", "1")]`; strings without their quotes.
fn flatten(value: &Value) -> Vec<(String, String)> {
    fn walk(prefix: &str, value: &Value, out: &mut Vec<(String, String)>) {
        match value {
            Value::Object(fields) => {
                for (key, value) in fields {
                    let key = if prefix.is_empty() {
                        key.clone()
                    } else {
                        format!("{prefix}.{key}")
                    };
                    walk(&key, value, out);
                }
            }
            Value::String(text) => out.push((prefix.to_owned(), text.clone())),
            other => out.push((prefix.to_owned(), other.to_string())),
        }
    }
    let mut out = Vec::new();
    walk("", value, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cdr::Reader;
    use scout_interface::state::ChassisPayload;
    use scout_interface::state::PowerStatus;
    use scout_protocol::version::Protocol;

    const SECOND: u64 = 1_000_000_000;

    fn clocks(monotonic_ns: u64) -> Clocks {
        Clocks {
            monotonic_ns,
            unix: Duration::from_secs(1_700_000_000) + Duration::from_nanos(monotonic_ns),
        }
    }

    fn received(at_ns: u64) -> Received {
        Received {
            valid: true,
            count: 0,
            at_ns,
        }
    }

    fn state(at_ns: u64) -> StatePayload {
        let mut state = StatePayload {
            robot: scout_interface::FixedText::new("r1"),
            ..Default::default()
        };
        state.link.state = LinkState::Ok.raw();
        state.link.protocol = Protocol::V1.raw();
        state.chassis = ChassisPayload::new(Model::Scout, Model::Scout.limits().angular);
        state.motion.received = received(at_ns);
        state.motion.linear_mm_s = 500;
        state.motion.angular_mrad_s = -100;
        state.system.received = received(at_ns);
        state.system.battery_decivolts = 255;
        state.odometry.x = 1.5;
        for motor in &mut state.motors {
            motor.received = received(at_ns);
            motor.rpm = 3200;
            motor.current_deciamps = 12;
        }
        state
    }

    fn topics(out: &[Outgoing]) -> Vec<Topic> {
        out.iter().map(|o| o.topic).collect()
    }

    /// The names and positions of the steering JointState in `out`, if one went out.
    fn steering(out: &[Outgoing]) -> Option<(Vec<String>, Vec<f64>)> {
        out.iter()
            .filter(|o| o.topic == Topic::JointStates)
            .find_map(|o| {
                let mut r = Reader::new(&o.payload).expect("CDR");
                r.i32().ok()?;
                r.u32().ok()?;
                r.skip_string().ok()?;
                let names = (0..r.u32().ok()?)
                    .map(|_| r.string().expect("a name"))
                    .collect::<Vec<_>>();
                let positions = (0..r.u32().ok()?)
                    .map(|_| r.f64().expect("a position"))
                    .collect::<Vec<_>>();
                (r.u32() == Ok(0) && r.u32() == Ok(0)).then_some((names, positions))
            })
    }

    #[test]
    fn the_wheels_joints_are_those_whose_motors_report() {
        let mut tracer = state(SECOND);
        tracer.chassis = ChassisPayload::new(Model::Tracer, 1.0);
        for motor in &mut tracer.motors[2..] {
            motor.received = Received::default();
        }
        let out = Messages::new(Ros2Config::default()).handle_state(
            &tracer,
            None,
            clocks(SECOND),
            &Vec::new,
        );
        let joints = out
            .iter()
            .find(|o| o.topic == Topic::JointStates)
            .expect("the wheels");
        let mut r = Reader::new(&joints.payload).expect("CDR");
        r.i32().expect("sec");
        r.u32().expect("nanosec");
        r.skip_string().expect("frame");
        assert_eq!(r.u32(), Ok(2), "two names");
        assert_eq!(r.string().as_deref(), Ok("front_right_wheel"));
        assert_eq!(r.string().as_deref(), Ok("front_left_wheel"));
        for _ in 0..3 {
            let count = r.u32().expect("a sequence");
            assert_eq!(count, 2, "positions, velocities, efforts");
            (0..count).for_each(|_| {
                r.f64().expect("a value");
            });
        }
    }

    #[test]
    fn a_steered_chassis_publishes_its_steering_joints_positions_alone() {
        let mut hunter = state(SECOND);
        hunter.chassis = ChassisPayload::new(Model::Hunter2, 1.146);
        hunter.motion.steering_mrad = 400;
        let out = Messages::new(Ros2Config::default()).handle_state(
            &hunter,
            None,
            clocks(SECOND),
            &Vec::new,
        );
        let (names, positions) = steering(&out).expect("the steering joints");
        assert_eq!(names, ["front_left_steering", "front_right_steering"]);
        let steered = Model::Hunter2
            .steering()
            .expect("steered")
            .front_wheels(0.4);
        assert_eq!(positions, [steered.0, steered.1]);
        let mut ranger = state(SECOND);
        ranger.chassis = ChassisPayload::new(Model::RangerMini3, 4.8);
        ranger.motion.wheel_angles_mrad = [100, 200, -100, -200];
        ranger.motion.wheels_reported = 1;
        let out = Messages::new(Ros2Config::default()).handle_state(
            &ranger,
            None,
            clocks(SECOND),
            &Vec::new,
        );
        let (names, positions) = steering(&out).expect("the steering joints");
        assert_eq!(names.len(), 4);
        assert_eq!(positions, [0.1, 0.2, -0.1, -0.2]);
        // A SCOUT steers nothing: its wheels' JointState alone.
        let out = Messages::new(Ros2Config::default()).handle_state(
            &state(SECOND),
            None,
            clocks(SECOND),
            &Vec::new,
        );
        assert_eq!(steering(&out), None);
    }

    #[test]
    fn each_frame_is_published_once_with_its_receive_time() {
        let mut messages = Messages::new(Ros2Config::default());
        let first =
            messages.handle_state(&state(SECOND), None, clocks(SECOND + 2_000_000), &Vec::new);
        assert_eq!(
            topics(&first),
            [
                Topic::Odom,
                Topic::Tf,
                Topic::JointStates,
                Topic::BatteryState,
                Topic::Diagnostics
            ]
        );
        // The odometry is stamped when its 0x131 arrived, 2 ms before now.
        let mut odom = Reader::new(&first[0].payload).expect("CDR");
        assert_eq!(odom.i32(), Ok(1_700_000_001));
        assert_eq!(odom.u32(), Ok(0));
        // The same frames again: nothing new, and diagnostics only once a second.
        let again =
            messages.handle_state(&state(SECOND), None, clocks(SECOND + 20_000_000), &Vec::new);
        assert!(again.is_empty(), "{:?}", topics(&again));
        let later = messages.handle_state(
            &state(SECOND + 20_000_000),
            None,
            clocks(SECOND + 22_000_000),
            &Vec::new,
        );
        assert_eq!(
            topics(&later),
            [
                Topic::Odom,
                Topic::Tf,
                Topic::JointStates,
                Topic::BatteryState
            ]
        );
        assert_eq!(
            topics(&messages.handle_state(&state(SECOND), None, clocks(3 * SECOND), &Vec::new)),
            [Topic::Diagnostics]
        );
    }

    #[test]
    fn the_tf_switch_and_a_change_of_level() {
        let config = Ros2Config {
            publish_tf: false,
            ..Default::default()
        };
        let mut messages = Messages::new(config);
        let out = messages.handle_state(&state(SECOND), None, clocks(SECOND), &Vec::new);
        assert!(!topics(&out).contains(&Topic::Tf));
        let mut estop = state(SECOND);
        estop.system.state = ChassisState::EStop.raw();
        // A change of level goes out at once.
        let out = messages.handle_state(&estop, None, clocks(SECOND + 1), &Vec::new);
        assert_eq!(topics(&out), [Topic::Diagnostics]);
    }

    #[test]
    fn diagnostics_say_what_is_wrong() {
        let mut chassis = state(SECOND);
        chassis.system.fault_bits = 0x0800 | 0x0001; // under-voltage warning and fault
        let [link, system, _, arbiter] = diagnostic_statuses("scout", &chassis, None, SECOND);
        assert_eq!((link.level, link.message.as_str()), (OK, "ok"));
        assert!(link.values.contains(&("rx_frames".into(), "0".into())));
        assert_eq!(system.level, ERROR);
        assert!(
            system.message.contains("battery_undervoltage_fault"),
            "{}",
            system.message
        );
        assert!(
            system
                .values
                .contains(&("battery_voltage".into(), "25.5".into()))
        );
        assert_eq!(arbiter.level, STALE);
        let mut silent = state(SECOND);
        silent.link.state = LinkState::Silent.raw();
        let [link, system, battery, _] = diagnostic_statuses("scout", &silent, None, SECOND);
        assert_eq!(
            (link.level, system.level, battery.level),
            (ERROR, STALE, STALE)
        );
    }

    #[test]
    fn the_odometry_is_calibrated_and_its_covariance_says_what_is_known() {
        let mut state = state(SECOND);
        state.odometry.distance_scale = 1.0;
        state.odometry.yaw_scale = 1.0;
        let (pose, twist) = odometry_covariance(&state, 0.5, 0.0);
        assert_eq!(pose[0], 0.01f64.powi(2), "at the origin: the floor");
        assert!(
            twist[0] > 0.01f64.powi(2),
            "a speed is uncertain in proportion"
        );
        assert_eq!((pose[2], twist[3]), (UNKNOWN, UNKNOWN));
        state.odometry.distance = 10.0;
        let (far, _) = odometry_covariance(&state, 0.5, 0.0);
        assert!(
            far[0] > pose[0] && far[5] > pose[5],
            "it grows with the distance"
        );
        state.odometry.rotation = 20.0;
        let (spun, _) = odometry_covariance(&state, 0.0, 0.0);
        assert!(
            spun[5] > 4.0 * far[5],
            "and the heading with the turning: {spun:?}"
        );
        state.odometry.yaw_scale = 0.7937;
        let (calibrated, calibrated_twist) = odometry_covariance(&state, 0.5, 0.4);
        let (_, uncalibrated_twist) = {
            let mut raw = state;
            raw.odometry.yaw_scale = 1.0;
            odometry_covariance(&raw, 0.5, 0.4)
        };
        assert!(
            calibrated[5] < spun[5],
            "the heading: smaller once the turn is calibrated"
        );
        assert_eq!(calibrated[0], spun[0], "the distance is not calibrated yet");
        assert!(calibrated_twist[5] < uncalibrated_twist[5]);
        // The twist /odom carries is the calibrated one: 1 rad/s reported is 0.7937 turned.
        state.motion.linear_mm_s = 0;
        state.motion.angular_mrad_s = 1000;
        let mut messages = Messages::new(Ros2Config::default());
        let out = messages.handle_state(&state, None, clocks(SECOND), &Vec::new);
        let odom = out.iter().find(|o| o.topic == Topic::Odom).expect("/odom");
        let mut reader = Reader::new(&odom.payload).expect("CDR");
        reader.i32().and_then(|_| reader.u32()).expect("stamp");
        reader
            .skip_string()
            .and_then(|()| reader.skip_string())
            .expect("frames");
        // Pose (7), its covariance (36), the twist's linear (3), then its angular z.
        for _ in 0..(7 + 36 + 3 + 2) {
            reader.f64().expect("f64");
        }
        assert_eq!(reader.f64(), Ok(0.7937), "the calibrated turn rate");
    }

    #[test]
    fn the_battery_is_ok_low_critical_or_stale_in_diagnostics() {
        let mut chassis = state(SECOND);
        let [_, _, battery, _] = diagnostic_statuses("scout", &chassis, None, SECOND);
        assert_eq!(
            (battery.level, battery.message.as_str()),
            (STALE, "no battery report yet")
        );
        for (level, percent, expected, says) in [
            (
                BatteryLevel::Ok,
                64.0,
                OK,
                "ok: 64 % (estimated from the voltage), discharging",
            ),
            (
                BatteryLevel::Low,
                18.0,
                WARN,
                "low: 18 % (estimated from the voltage), discharging: charge soon",
            ),
            (
                BatteryLevel::Critical,
                7.0,
                ERROR,
                "critical: 7 % (estimated from the voltage), discharging: charge now",
            ),
        ] {
            chassis.battery = BatteryPayload {
                source: BatterySource::Voltage.raw(),
                status: PowerStatus::Discharging.raw(),
                level: level.raw(),
                percent,
                voltage: 24.5,
                ..BatteryPayload::unknown(20.0, 10.0)
            };
            let [_, _, battery, _] = diagnostic_statuses("scout", &chassis, None, SECOND);
            assert_eq!((battery.level, battery.message.as_str()), (expected, says));
            assert_eq!(battery.name, "scout: battery");
            assert!(
                battery
                    .values
                    .contains(&("level".into(), level.name().into())),
                "{:?}",
                battery.values
            );
        }
    }

    #[test]
    fn a_silent_gateway_is_reported() {
        let mut messages = Messages::new(Ros2Config::default());
        assert!(
            messages
                .handle_silence("r1", SECOND, clocks(SECOND + 500_000_000), &Vec::new)
                .is_empty()
        );
        let out = messages.handle_silence("r1", SECOND, clocks(3 * SECOND), &Vec::new);
        assert_eq!(topics(&out), [Topic::Diagnostics]);
        let text = String::from_utf8_lossy(&out[0].payload);
        assert!(
            text.contains("no state from gateway 'r1' for 2.0 s"),
            "{text}"
        );
        // The gateway back: a change of level goes out at once.
        let back =
            messages.handle_state(&state(3 * SECOND), None, clocks(3 * SECOND + 1), &Vec::new);
        assert!(topics(&back).contains(&Topic::Diagnostics));
    }

    #[test]
    fn wheels_turn_through_the_gearbox() {
        let mut messages = Messages::new(Ros2Config::default());
        messages.handle_state(&state(SECOND), None, clocks(SECOND), &Vec::new);
        messages.handle_state(
            &state(SECOND + 20_000_000),
            None,
            clocks(SECOND + 20_000_000),
            &Vec::new,
        );
        // 3200 rpm / 32 = 100 rpm = 10.47 rad/s, for 20 ms.
        let expected = 100.0 * std::f64::consts::TAU / 60.0 * 0.02;
        assert!((messages.wheel_angles[0] - expected).abs() < 1e-9);
    }

    /// A SCOUT MINI on protocol v2, its odometers at `left_mm` and `right_mm`, its right motors
    /// turning forward and its left ones mirrored at `rpm`.
    fn mini(at_ns: u64, left_mm: i32, right_mm: i32, rpm: i16) -> StatePayload {
        let mut state = state(at_ns);
        state.link.protocol = Protocol::V2.raw();
        state.chassis = ChassisPayload::new(Model::ScoutMini, 2.5235);
        state.odometer.received = received(at_ns);
        state.odometer.left_mm = left_mm;
        state.odometer.right_mm = right_mm;
        for (i, motor) in state.motors.iter_mut().enumerate() {
            motor.rpm = if matches!(i, 0 | 3) { rpm } else { -rpm };
        }
        state
    }

    #[test]
    fn on_v2_wheel_angles_come_from_the_odometers_and_agree_with_the_speeds() {
        let mut messages = Messages::new(Ros2Config::default());
        let radius = Model::ScoutMini.geometry().wheel_radius;
        let gear = Model::ScoutMini.geometry().gear_ratio;
        // 0.5 m/s on both sides for 20 ms: 10 mm; the motors at the matching rpm.
        let rpm = (0.5 / radius / std::f64::consts::TAU * 60.0 * gear).round() as i16;
        messages.handle_state(
            &mini(SECOND, 1000, 2000, rpm),
            None,
            clocks(SECOND),
            &Vec::new,
        );
        let before = messages.wheel_angles;
        let t = SECOND + 20_000_000;
        let out = messages.handle_state(&mini(t, 1010, 2010, rpm), None, clocks(t), &Vec::new);
        assert!(topics(&out).contains(&Topic::JointStates));
        assert!(
            (messages.wheel_angles[0] - 2.010 / radius).abs() < 1e-9,
            "right: its odometer"
        );
        assert!(
            (messages.wheel_angles[1] + 1.010 / radius).abs() < 1e-9,
            "left, mirrored"
        );
        let speed = |i: usize| {
            f64::from(mini(t, 0, 0, rpm).motors[i].rpm) / gear * std::f64::consts::TAU / 60.0
        };
        for (i, (after, before)) in messages.wheel_angles.iter().zip(before).enumerate() {
            let rate = (after - before) / 0.02;
            assert!(
                (rate - speed(i)).abs() < 0.05 * speed(i).abs(),
                "wheel {i}: {rate} vs {}",
                speed(i)
            );
        }
    }

    /// Reads a BatteryState's numbers: voltage, temperature, current, charge, capacity,
    /// design capacity, percentage; then status and health.
    fn battery_fields(out: &[Outgoing]) -> ([f32; 7], u8, u8) {
        let battery = out
            .iter()
            .find(|o| o.topic == Topic::BatteryState)
            .expect("battery");
        let mut reader = Reader::new(&battery.payload).expect("CDR");
        reader.i32().and_then(|_| reader.u32()).expect("stamp");
        reader.skip_string().expect("frame id");
        let numbers = [(); 7].map(|_| reader.f32().expect("f32"));
        (
            numbers,
            reader.u8().expect("status"),
            reader.u8().expect("health"),
        )
    }

    #[test]
    fn the_gateways_battery_fills_battery_state_as_ros_users_expect() {
        let mut messages = Messages::new(Ros2Config::default());
        let mut state = mini(SECOND, 0, 0, 0);
        state.battery = BatteryPayload {
            source: BatterySource::Bms.raw(),
            status: PowerStatus::Charging.raw(),
            level: BatteryLevel::Ok.raw(),
            percent: 87.0,
            voltage: 26.2,
            current: 5.2,
            temperature: 31.2,
            capacity_ah: 30.0,
            ..BatteryPayload::unknown(20.0, 10.0)
        };
        let out = messages.handle_state(&state, None, clocks(SECOND), &Vec::new);
        let (
            [
                voltage,
                temperature,
                current,
                charge,
                capacity,
                design,
                percentage,
            ],
            status,
            _,
        ) = battery_fields(&out);
        assert_eq!((voltage, temperature, current), (26.2, 31.2, 5.2));
        assert!(charge.is_nan() && capacity.is_nan(), "not measured");
        assert_eq!((design, percentage), (30.0, 0.87));
        assert_eq!(status, 1, "POWER_SUPPLY_STATUS_CHARGING");
        // Nothing known: NaN and unknown, the voltage the chassis reports.
        let state = mini(2 * SECOND, 0, 0, 0);
        let out = messages.handle_state(&state, None, clocks(2 * SECOND), &Vec::new);
        let ([voltage, .., percentage], status, _) = battery_fields(&out);
        assert_eq!(voltage, 25.5);
        assert!(percentage.is_nan());
        assert_eq!(status, 0, "POWER_SUPPLY_STATUS_UNKNOWN");
    }
}
