//! The local interface between scout-gateway and its clients: iceoryx2 service names, their
//! sizing, and the `#[repr(C)]` payloads that travel zero-copy through shared memory.

use iceoryx2::node::{Node, NodeCreationFailure};
use iceoryx2::prelude::{
    CallbackProgression, Config, LogLevel, NodeBuilder, NodeName, NodeState, ServiceName,
    SignalHandlingMode, ZeroCopySend,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};

/// The iceoryx2 service flavour every process uses: inter-process, shared memory.
pub type Ipc = iceoryx2::service::ipc::Service;

/// The state's publish-subscribe service.
pub type StateService = publish_subscribe::PortFactory<Ipc, StatePayload, ()>;

/// The state's event service: a notification follows every published state.
pub type StateEvents = event::PortFactory<Ipc>;

/// Local subscriber processes a gateway serves at once.
pub const MAX_SUBSCRIBERS: usize = 64;
/// Command-sending processes a gateway serves at once.
pub const MAX_CONTROLLERS: usize = 32;
/// Nodes (processes) that may use one robot's services at once.
pub const MAX_NODES: usize = 128;
/// Samples a slow subscriber keeps before the oldest is overwritten.
pub const SUBSCRIBER_BUFFER: usize = 8;

/// The prefix of every service and key of a robot.
pub fn prefix(robot: &str) -> String {
    format!("scout/{robot}")
}

/// The publish-subscribe service (and its event service) carrying [`StatePayload`].
pub fn state_service(robot: &str) -> String {
    format!("{}/state", prefix(robot))
}

/// A robot name is the key of every service: letters, digits, `-` and `_`, 1..=32 characters.
pub fn check_robot_name(name: &str) -> Result<(), String> {
    let valid = !name.is_empty()
        && name.len() <= FixedText::<32>::CAPACITY
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    if valid {
        Ok(())
    } else {
        Err(format!(
            "robot name `{name}` must be 1 to 32 letters, digits, `-` or `_` (it names iceoryx2 services and zenoh keys)"
        ))
    }
}

/// Quiets iceoryx2's own logger (its messages duplicate our errors) unless `IOX2_LOG_LEVEL`
/// asks for more.
pub fn quiet_iceoryx2_logs() {
    iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Fatal);
}

/// A node named `name`, without iceoryx2's signal handlers: the program owns SIGINT and SIGTERM.
pub fn node(name: &str) -> Result<Node<Ipc>, NodeCreationFailure> {
    let mut builder = NodeBuilder::new().signal_handling_mode(SignalHandlingMode::Disabled);
    if let Ok(name) = NodeName::new(name) {
        builder = builder.name(&name);
    }
    builder.create::<Ipc>()
}

/// Removes what dead processes (SIGKILL, crash) left in shared memory; returns how many.
pub fn remove_dead_nodes() -> usize {
    let mut removed = 0;
    let _ = iceoryx2::node::Node::<Ipc>::list(Config::global_config(), |state| {
        if let NodeState::Dead(view) = state
            && view.try_remove_stale_resources().is_ok()
        {
            removed += 1;
        }
        CallbackProgression::Continue
    });
    removed
}

/// Why a robot's services could not be created or opened.
#[derive(Debug, thiserror::Error)]
pub enum ServiceError {
    /// The name is not a valid iceoryx2 service name.
    #[error("invalid service name `{0}`")]
    Name(String),
    /// No gateway has created the service.
    #[error(
        "no gateway named '{robot}' is running: start one with `scout-gateway --name {robot} --sim` (or --serial/--slcan/--can DEVICE)"
    )]
    NoGateway {
        /// The robot name.
        robot: String,
    },
    /// iceoryx2 refused.
    #[error("iceoryx2 service {service}: {reason}")]
    Iceoryx {
        /// The service.
        service: String,
        /// iceoryx2's error.
        reason: String,
    },
}

fn service_name(name: &str) -> Result<ServiceName, ServiceError> {
    ServiceName::new(name).map_err(|_| ServiceError::Name(name.to_owned()))
}

/// Who calls a `*_services` function.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The gateway: creates the services, sized for all its clients.
    Gateway,
    /// A client: opens them; a missing service means no gateway runs.
    Client,
}

/// The error of creating or opening `service` of `robot`: a service that does not exist means
/// that no gateway of that name runs.
fn service_error(
    robot: &str,
    service: &str,
    missing: bool,
    reason: impl std::fmt::Display,
) -> ServiceError {
    if missing {
        ServiceError::NoGateway {
            robot: robot.to_owned(),
        }
    } else {
        ServiceError::Iceoryx {
            service: service.to_owned(),
            reason: reason.to_string(),
        }
    }
}

/// Creates or opens the event service paired with `name`.
fn event_service(
    node: &Node<Ipc>,
    robot: &str,
    name: &str,
    role: Role,
    (notifiers, listeners): (usize, usize),
) -> Result<StateEvents, ServiceError> {
    use iceoryx2::service::builder::event::EventOpenError;
    let builder = node.service_builder(&service_name(name)?).event();
    match role {
        Role::Gateway => builder
            .max_notifiers(notifiers)
            .max_listeners(listeners)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(|e| service_error(robot, name, false, e)),
        Role::Client => builder
            .open()
            .map_err(|e| service_error(robot, name, e == EventOpenError::DoesNotExist, e)),
    }
}

/// Creates or opens a publish-subscribe service of `Payload` with one latest sample of history.
fn latest_value_service<Payload: std::fmt::Debug + ZeroCopySend>(
    node: &Node<Ipc>,
    robot: &str,
    name: &str,
    role: Role,
) -> Result<publish_subscribe::PortFactory<Ipc, Payload, ()>, ServiceError> {
    use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<Payload>();
    match role {
        Role::Gateway => builder
            .max_publishers(2)
            .max_subscribers(MAX_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .history_size(1)
            .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
            .enable_safe_overflow(true)
            .open_or_create()
            .map_err(|e| service_error(robot, name, false, e)),
        Role::Client => builder.open().map_err(|e| {
            service_error(robot, name, e == PublishSubscribeOpenError::DoesNotExist, e)
        }),
    }
}

/// The state services of `robot`: publish-subscribe and its event service.
pub fn state_services(
    node: &Node<Ipc>,
    robot: &str,
    role: Role,
) -> Result<(StateService, StateEvents), ServiceError> {
    let name = state_service(robot);
    // Events first: clients take the publish-subscribe service as the sign that all exist.
    let events = event_service(node, robot, &name, role, (2, MAX_SUBSCRIBERS))?;
    let state = latest_value_service(node, robot, &name, role)?;
    Ok((state, events))
}

/// Text in a fixed buffer (payloads cannot hold `String`). Longer text is cut at a character
/// boundary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
pub struct FixedText<const N: usize> {
    len: u16,
    bytes: [u8; N],
}

impl<const N: usize> FixedText<N> {
    /// The most bytes it holds.
    pub const CAPACITY: usize = N;

    /// Empty text.
    pub const fn empty() -> Self {
        Self {
            len: 0,
            bytes: [0; N],
        }
    }

    /// `text`, cut to fit.
    pub fn new(text: &str) -> Self {
        let mut end = text.len().min(N);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0; N];
        bytes[..end].copy_from_slice(&text.as_bytes()[..end]);
        Self {
            len: end as u16,
            bytes,
        }
    }

    /// The text (empty if the bytes are not UTF-8, which [`FixedText::new`] never produces).
    pub fn as_str(&self) -> &str {
        let len = usize::from(self.len).min(N);
        std::str::from_utf8(&self.bytes[..len]).unwrap_or("")
    }
}

impl<const N: usize> Default for FixedText<N> {
    fn default() -> Self {
        Self::empty()
    }
}

/// The link to the chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct LinkPayload {
    /// [`LinkState`] as `u8`.
    pub state: u8,
    /// [`TransportKind`] as `u8`.
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
    /// Frames sent to the chassis.
    pub tx_frames: u64,
    /// Times the port was reopened after a fault.
    pub reconnects: u64,
    /// The device or interface.
    pub device: FixedText<96>,
}

/// The state of the link, published at once on every change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum LinkState {
    /// Feedback arrives.
    Ok = 0,
    /// No valid feedback for 100 ms (or none yet).
    Silent = 1,
    /// The port is closed or failing; the gateway is reopening it.
    Disconnected = 2,
    /// The chassis speaks protocol v2, which this gateway does not support.
    ProtocolV2 = 3,
}

impl LinkState {
    /// From the payload byte.
    pub fn from_raw(raw: u8) -> Self {
        match raw {
            0 => Self::Ok,
            2 => Self::Disconnected,
            3 => Self::ProtocolV2,
            _ => Self::Silent,
        }
    }

    /// The name in JSON and logs.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ok => "ok",
            Self::Silent => "silent",
            Self::Disconnected => "disconnected",
            Self::ProtocolV2 => "protocol_v2",
        }
    }
}

/// How the gateway reaches the chassis (also the `transport` key of its configuration).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum TransportKind {
    /// RS232.
    Serial = 0,
    /// slcan adapter.
    Slcan = 1,
    /// SocketCAN.
    Can = 2,
    /// The in-process simulator.
    Sim = 3,
}

impl TransportKind {
    /// From the payload byte.
    pub fn from_raw(raw: u8) -> Option<Self> {
        Some(match raw {
            0 => Self::Serial,
            1 => Self::Slcan,
            2 => Self::Can,
            3 => Self::Sim,
            _ => return None,
        })
    }

    /// The name in JSON, logs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Serial => "serial",
            Self::Slcan => "slcan",
            Self::Can => "can",
            Self::Sim => "sim",
        }
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

/// One light of the 0x141 feedback.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct LightPayload {
    /// Raw mode (0 off, 1 on, 2 breath, 3 custom).
    pub mode: u8,
    /// 0..100.
    pub brightness: u8,
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
#[type_name("scout::StatePayload")]
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

/// CLOCK_MONOTONIC now, ns: the clock of every `*_ns` field, comparable across processes.
pub fn monotonic_ns() -> u64 {
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC)
        .map(|t| t.tv_sec() as u64 * 1_000_000_000 + t.tv_nsec() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_text_cuts_at_a_character_boundary() {
        assert_eq!(FixedText::<4>::new("scout").as_str(), "scou");
        assert_eq!(FixedText::<4>::new("ab\u{e9}\u{e9}").as_str(), "ab\u{e9}");
        assert_eq!(FixedText::<8>::new("").as_str(), "");
    }

    #[test]
    fn robot_names_are_checked() {
        assert!(check_robot_name("scout-1_b").is_ok());
        for bad in ["", "a/b", "with space", "*", &"x".repeat(33)] {
            assert!(check_robot_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn link_state_round_trips() {
        for state in [
            LinkState::Ok,
            LinkState::Silent,
            LinkState::Disconnected,
            LinkState::ProtocolV2,
        ] {
            assert_eq!(LinkState::from_raw(state as u8), state);
        }
    }
}

/// Conversions between the payloads and scout-protocol's typed messages.
mod convert {
    use scout_protocol::{
        ChassisState, ControlMode, FaultBits, Light, LightCommand, LightMode, MotionFeedback,
        Motor, MotorFeedback, SystemStatus,
    };

    use super::*;

    impl SystemPayload {
        /// The payload of a received status.
        pub fn new(status: &SystemStatus, received: Received) -> Self {
            Self {
                received,
                state: status.state.raw(),
                control_mode: status.control_mode.raw(),
                battery_decivolts: status.battery_decivolts,
                fault_bits: status.faults.0,
            }
        }

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
        /// The payload of received motion feedback.
        pub fn new(motion: &MotionFeedback, received: Received) -> Self {
            Self {
                received,
                linear_mm_s: motion.linear_mm_s,
                angular_mrad_s: motion.angular_mrad_s,
            }
        }

        /// The feedback it carries.
        pub fn feedback(&self) -> MotionFeedback {
            MotionFeedback {
                linear_mm_s: self.linear_mm_s,
                angular_mrad_s: self.angular_mrad_s,
            }
        }
    }

    impl MotorPayload {
        /// The payload of received motor feedback.
        pub fn new(motor: &MotorFeedback, received: Received) -> Self {
            Self {
                received,
                current_deciamps: motor.current_deciamps,
                rpm: motor.rpm,
                driver_temperature: motor.driver_temperature,
                motor_temperature: motor.motor_temperature,
            }
        }

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
        /// The payload of received light feedback.
        pub fn new(lights: &LightCommand, received: Received) -> Self {
            let light = |l: Light| LightPayload {
                mode: l.mode.raw(),
                brightness: l.brightness,
            };
            Self {
                received,
                enabled: lights.enabled,
                front: light(lights.front),
                rear: light(lights.rear),
            }
        }

        /// The feedback it carries.
        pub fn feedback(&self) -> LightCommand {
            let light = |l: LightPayload| Light {
                mode: LightMode::from_raw(l.mode),
                brightness: l.brightness,
            };
            LightCommand {
                enabled: self.enabled,
                front: light(self.front),
                rear: light(self.rear),
            }
        }
    }
}

/// The request-response service carrying [`ControlRequest`] and [`ControlResponse`], and the
/// event service a client notifies after sending so that the gateway wakes at once.
pub fn control_service(robot: &str) -> String {
    format!("{}/control", prefix(robot))
}

/// The publish-subscribe service carrying [`StatusPayload`].
pub fn status_service(robot: &str) -> String {
    format!("{}/status", prefix(robot))
}

/// What a [`ControlRequest`] asks for (its `kind` byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum RequestKind {
    /// Drive at `linear`, `angular` as `class` for `ttl_ms` (0: the class's maximum age).
    Drive = 1,
    /// Latch the safety stop (`reason`).
    Stop = 2,
    /// Release the latched stop and this client's control.
    Release = 3,
    /// Arm autonomy.
    Resume = 4,
    /// Set the lights (`lights`).
    Lights = 5,
    /// Clear a fault (`fault_clear`: a code 1..8, or [`CLEAR_ALL_FAULTS`]).
    ClearFault = 6,
    /// Register (`heartbeat_ms` > 0) or drop (0) a heartbeat stop source; also a beat.
    Heartbeat = 7,
    /// Reset the gateway's odometry.
    ResetOdometry = 8,
    /// Give up this client's control (never touches the stop).
    Relinquish = 9,
}

impl RequestKind {
    /// From the payload byte.
    pub fn from_raw(raw: u8) -> Option<Self> {
        Some(match raw {
            1 => Self::Drive,
            2 => Self::Stop,
            3 => Self::Release,
            4 => Self::Resume,
            5 => Self::Lights,
            6 => Self::ClearFault,
            7 => Self::Heartbeat,
            8 => Self::ResetOdometry,
            9 => Self::Relinquish,
            _ => return None,
        })
    }
}

/// `fault_clear` value asking for every fault-clear code in turn.
pub const CLEAR_ALL_FAULTS: u8 = 0xFF;

/// A controlling client's class.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Class {
    /// A person driving: overrides autonomy.
    Teleop = 1,
    /// A program driving.
    Autonomy = 2,
}

impl Class {
    /// From the payload byte (0 is "no class").
    pub fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            1 => Some(Self::Teleop),
            2 => Some(Self::Autonomy),
            _ => None,
        }
    }

    /// The name in JSON, logs and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Self::Teleop => "teleop",
            Self::Autonomy => "autonomy",
        }
    }
}

impl std::str::FromStr for Class {
    type Err = String;

    fn from_str(text: &str) -> Result<Self, String> {
        match text {
            "teleop" => Ok(Self::Teleop),
            "autonomy" => Ok(Self::Autonomy),
            other => Err(format!("unknown class `{other}`: teleop or autonomy")),
        }
    }
}

/// The lights of a request: `auto` hands them back to the chassis; otherwise the raw modes
/// (0 off, 1 on, 2 breath, 3 custom) and brightness 0..100.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct LightsRequest {
    /// Hand the lights back to the chassis.
    pub auto: bool,
    /// Front light.
    pub front: LightPayload,
    /// Rear light.
    pub rear: LightPayload,
}

/// A request from a client to the gateway's arbiter.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("scout::ControlRequest")]
#[repr(C)]
pub struct ControlRequest {
    /// [`RequestKind`] as `u8`.
    pub kind: u8,
    /// [`Class`] byte (0: none), for drive.
    pub class: u8,
    /// Fault-clear code, for clear-fault.
    pub fault_clear: u8,
    /// Lights, for lights.
    pub lights: LightsRequest,
    /// The client's name (shown in the status and the audit log).
    pub client: FixedText<32>,
    /// The client's iceoryx2 node id, high and low 64 bits (dead-process detection).
    pub node: [u64; 2],
    /// The client's own request number.
    pub seq: u64,
    /// m/s, for drive.
    pub linear: f64,
    /// rad/s, for drive.
    pub angular: f64,
    /// The command's life, ms (0: the class's maximum age), for drive.
    pub ttl_ms: u32,
    /// The heartbeat period, ms, for heartbeat.
    pub heartbeat_ms: u32,
    /// Why, for stop.
    pub reason: FixedText<64>,
}

/// The gateway's answer to one request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("scout::ControlResponse")]
#[repr(C)]
pub struct ControlResponse {
    /// The request's `seq`.
    pub seq: u64,
    /// Accepted (true) or rejected.
    pub accepted: bool,
    /// Accepted, but a speed beyond the caps was clamped.
    pub clamped: bool,
    /// The rejection counter index (see the status' rejection names); 0xFF when accepted.
    pub code: u8,
    /// Why it was rejected.
    pub reason: FixedText<160>,
}

/// One client in the arbiter's status.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct SourcePayload {
    /// The client's name.
    pub client: FixedText<32>,
    /// [`Class`] byte of its last command (0: none).
    pub class: u8,
    /// Whether it holds its class now.
    pub holding: bool,
    /// Its heartbeat period, ms (0: none).
    pub heartbeat_ms: u32,
    /// Requests it sent.
    pub requests: u64,
    /// How long ago it last sent a request, ms.
    pub age_ms: f64,
}

/// Most clients listed in a status.
pub const MAX_STATUS_SOURCES: usize = 32;
/// Rejection counters in a status.
pub const REJECTION_COUNTERS: usize = 8;

/// The arbiter's status, published on every change and at least once a second.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("scout::StatusPayload")]
#[repr(C)]
pub struct StatusPayload {
    /// Rises by one with every publication.
    pub seq: u64,
    /// CLOCK_MONOTONIC time of publication, ns.
    pub published_ns: u64,
    /// The robot's name.
    pub robot: FixedText<32>,
    /// The safety stop is latched.
    pub latched: bool,
    /// Who latched it.
    pub latched_by: FixedText<32>,
    /// Why.
    pub latched_reason: FixedText<64>,
    /// How long ago, ms.
    pub latched_age_ms: f64,
    /// [`Class`] byte of the selected source (0: none).
    pub selected_class: u8,
    /// The selected client.
    pub selected_client: FixedText<32>,
    /// The output, m/s.
    pub output_linear: f64,
    /// The output, rad/s.
    pub output_angular: f64,
    /// The fault-clear code going out.
    pub output_fault_clear: u8,
    /// A cap or rate limit is active.
    pub limited: bool,
    /// Autonomy may drive.
    pub autonomy_armed: bool,
    /// Host light control: 0 never set, 1 auto, 2 manual.
    pub lights: u8,
    /// How many entries of `sources` are used.
    pub source_count: u8,
    /// The known clients.
    pub sources: [SourcePayload; MAX_STATUS_SOURCES],
    /// Rejections by reason.
    pub rejections: [u64; REJECTION_COUNTERS],
}

/// The rejection counter names, in counter order (the same as the gateway's arbiter).
pub const REJECTION_NAMES: [&str; REJECTION_COUNTERS] = [
    "not_finite",
    "unknown_class",
    "unknown_request",
    "malformed",
    "latched",
    "held",
    "autonomy_disarmed",
    "too_many_clients",
];

/// The control request-response service.
pub type ControlService = iceoryx2::service::port_factory::request_response::PortFactory<
    Ipc,
    ControlRequest,
    (),
    ControlResponse,
    (),
>;

/// The status service.
pub type StatusService = publish_subscribe::PortFactory<Ipc, StatusPayload, ()>;

/// The control services of `robot`: requests and the wake-up event. Sized for
/// [`MAX_CONTROLLERS`] client processes.
pub fn control_services(
    node: &Node<Ipc>,
    robot: &str,
    role: Role,
) -> Result<(ControlService, StateEvents), ServiceError> {
    use iceoryx2::service::builder::request_response::RequestResponseOpenError;
    let name = control_service(robot);
    let builder = node
        .service_builder(&service_name(&name)?)
        .request_response::<ControlRequest, ControlResponse>();
    let requests = match role {
        Role::Gateway => builder
            .max_servers(2)
            .max_clients(MAX_CONTROLLERS)
            .max_nodes(MAX_NODES)
            .max_active_requests_per_client(4)
            .max_response_buffer_size(4)
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
            .open_or_create()
            .map_err(|e| service_error(robot, &name, false, e))?,
        Role::Client => builder.open().map_err(|e| {
            service_error(robot, &name, e == RequestResponseOpenError::DoesNotExist, e)
        })?,
    };
    let events = event_service(node, robot, &name, role, (MAX_CONTROLLERS, 2))?;
    Ok((requests, events))
}

/// The status service of `robot`.
pub fn status_services(
    node: &Node<Ipc>,
    robot: &str,
    role: Role,
) -> Result<StatusService, ServiceError> {
    latest_value_service(node, robot, &status_service(robot), role)
}

/// The node id as the two halves a [`ControlRequest`] carries.
pub fn node_halves(node: u128) -> [u64; 2] {
    [(node >> 64) as u64, node as u64]
}

/// The node id from a [`ControlRequest`]'s halves.
pub fn node_from_halves(halves: [u64; 2]) -> u128 {
    (u128::from(halves[0]) << 64) | u128::from(halves[1])
}
