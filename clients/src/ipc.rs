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

/// The event service a client notifies to reset the gateway's odometry.
pub fn reset_odometry_service(robot: &str) -> String {
    format!("{}/reset_odometry", prefix(robot))
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

/// Creates (gateway) the state services of `robot`, sized for [`MAX_SUBSCRIBERS`] processes.
pub fn create_state_services(
    node: &Node<Ipc>,
    robot: &str,
) -> Result<(StateService, StateEvents), ServiceError> {
    let name = state_service(robot);
    let service_name = service_name(&name)?;
    let iceoryx = |reason: String| ServiceError::Iceoryx {
        service: name.clone(),
        reason,
    };
    let state = node
        .service_builder(&service_name)
        .publish_subscribe::<StatePayload>()
        .max_publishers(2)
        .max_subscribers(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .history_size(1)
        .subscriber_max_buffer_size(SUBSCRIBER_BUFFER)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| iceoryx(e.to_string()))?;
    let events = node
        .service_builder(&service_name)
        .event()
        .max_notifiers(2)
        .max_listeners(MAX_SUBSCRIBERS)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| iceoryx(e.to_string()))?;
    Ok((state, events))
}

/// Creates (gateway) or opens (client) the odometry-reset event service of `robot`.
pub fn reset_odometry_events(node: &Node<Ipc>, robot: &str) -> Result<StateEvents, ServiceError> {
    let name = reset_odometry_service(robot);
    node.service_builder(&service_name(&name)?)
        .event()
        .max_notifiers(MAX_CONTROLLERS)
        .max_listeners(2)
        .max_nodes(MAX_NODES)
        .open_or_create()
        .map_err(|e| ServiceError::Iceoryx {
            service: name,
            reason: e.to_string(),
        })
}

/// Opens (client) the state services of `robot`.
pub fn open_state_services(
    node: &Node<Ipc>,
    robot: &str,
) -> Result<(StateService, StateEvents), ServiceError> {
    use iceoryx2::service::builder::event::EventOpenError;
    use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;
    let name = state_service(robot);
    let service_name = service_name(&name)?;
    let no_gateway = || ServiceError::NoGateway {
        robot: robot.to_owned(),
    };
    let iceoryx = |reason: String| ServiceError::Iceoryx {
        service: name.clone(),
        reason,
    };
    let state = node
        .service_builder(&service_name)
        .publish_subscribe::<StatePayload>()
        .open()
        .map_err(|e| match e {
            PublishSubscribeOpenError::DoesNotExist => no_gateway(),
            other => iceoryx(other.to_string()),
        })?;
    let events = node
        .service_builder(&service_name)
        .event()
        .open()
        .map_err(|e| match e {
            EventOpenError::DoesNotExist => no_gateway(),
            other => iceoryx(other.to_string()),
        })?;
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

/// How the gateway reaches the chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
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
