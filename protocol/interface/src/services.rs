//! The iceoryx2 services of a robot: their names, their sizing, and how the gateway creates and
//! a client opens them; plus the client's request round trip ([`ControlPort`]).
//!
//! A robot `ROBOT` has four services: `scout/ROBOT/state` (publish-subscribe of
//! [`StatePayload`] with an event service that fires after each), `scout/ROBOT/status`
//! (publish-subscribe of [`StatusPayload`]), `scout/ROBOT/control` (request-response of
//! [`ControlRequest`] / [`ControlResponse`]) and `scout/ROBOT/stop` (the same payloads, stops
//! only: its own way in, sized apart, that a full control service or a flood cannot block).
//! Both request services share one wake-up event service (`scout/ROBOT/control`).
//!
//! A client's identity is its port: the gateway reads the port's name and node from iceoryx2
//! (the request's origin), never from the payload.

use std::time::{Duration, Instant};

use iceoryx2::node::{Node, NodeCreationFailure};
use iceoryx2::port::client::Client;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::{
    CallbackProgression, Config, LogLevel, NodeBuilder, NodeName, NodeState, ServiceName,
    SignalHandlingMode, ZeroCopySend,
};
use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
use iceoryx2::service::builder::publish_subscribe::{
    PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::builder::request_response::{
    RequestResponseOpenError, RequestResponseOpenOrCreateError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};

use crate::LAYOUT_VERSION;
use crate::control::{
    Accepted, ControlRequest, ControlResponse, MAX_CLIENTS, Rejected, StatusPayload,
};
use crate::state::StatePayload;

pub use crate::ipc::Ipc;
use crate::ipc::IpcDirError;

/// The state's publish-subscribe service.
pub type StateService = publish_subscribe::PortFactory<Ipc, StatePayload, ()>;

/// An event service paired with another service.
pub type Events = event::PortFactory<Ipc>;

/// The control request-response service.
pub type ControlService =
    request_response::PortFactory<Ipc, ControlRequest, (), ControlResponse, ()>;

/// The status service.
pub type StatusService = publish_subscribe::PortFactory<Ipc, StatusPayload, ()>;

/// Local subscriber processes a gateway serves at once.
pub const MAX_SUBSCRIBERS: usize = 64;
/// Control ports a gateway serves at once.
pub const MAX_CONTROLLERS: usize = MAX_CLIENTS;
/// Stop ports a gateway serves at once, apart from the control ports.
pub const MAX_STOPPERS: usize = 256;
/// Nodes (processes) that may use one robot's services at once.
pub const MAX_NODES: usize = 128;
/// Samples a slow subscriber keeps before the oldest is overwritten.
pub const SUBSCRIBER_BUFFER: usize = 8;
/// Requests one client may have in flight.
pub const MAX_REQUESTS_IN_FLIGHT: usize = 4;
/// How long a request waits for the gateway's answer.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(1);

/// The prefix of every service and key of a robot.
pub fn prefix(robot: &str) -> String {
    format!("scout/{robot}")
}

/// The state service (and its event service).
pub fn state_service(robot: &str) -> String {
    format!("{}/state", prefix(robot))
}

/// The control service (and its wake-up event service).
pub fn control_service(robot: &str) -> String {
    format!("{}/control", prefix(robot))
}

/// The status service.
pub fn status_service(robot: &str) -> String {
    format!("{}/status", prefix(robot))
}

/// The stop service.
pub fn stop_service(robot: &str) -> String {
    format!("{}/stop", prefix(robot))
}

/// A request service: control, or stops only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Way {
    /// `scout/ROBOT/control`: every request.
    Control,
    /// `scout/ROBOT/stop`: stops, never refused, never behind a full control service.
    Stop,
}

impl Way {
    fn service(self, robot: &str) -> String {
        match self {
            Self::Control => control_service(robot),
            Self::Stop => stop_service(robot),
        }
    }

    fn max_clients(self) -> usize {
        match self {
            Self::Control => MAX_CONTROLLERS,
            Self::Stop => MAX_STOPPERS,
        }
    }
}

/// Quiets iceoryx2's own logger (its messages duplicate our errors) unless `IOX2_LOG_LEVEL`
/// asks for more.
pub fn quiet_iceoryx2_logs() {
    iceoryx2::prelude::set_log_level_from_env_or(LogLevel::Fatal);
}

/// Why this process's iceoryx2 node could not be made.
#[derive(Debug, thiserror::Error)]
pub enum NodeError {
    /// The shared-memory directory cannot be used.
    #[error(transparent)]
    Dir(#[from] IpcDirError),
    /// iceoryx2 refused.
    #[error("creating this process's iceoryx2 node in {dir}: {failure:?}")]
    Create {
        /// The shared-memory directory.
        dir: String,
        /// What iceoryx2 said.
        failure: NodeCreationFailure,
    },
}

/// iceoryx2's configuration: every object in the shared-memory directory
/// ([`crate::ipc::ipc_dir`]).
pub fn config() -> Result<Config, IpcDirError> {
    crate::ipc::config_in(&crate::ipc::ipc_dir()?)
}

/// A node named `name`, without iceoryx2's signal handlers: the program owns SIGINT and SIGTERM.
pub fn node(name: &str) -> Result<Node<Ipc>, NodeError> {
    build_node(name, config()?)
}

/// The gateway's node: as [`node`], but it never waits for another process's object to be
/// ready (iceoryx2's `creation_timeout`, 1 s by default, spent retrying while it is not): an
/// object a client made that the gateway cannot open is given up at once, so that nothing a
/// client does stalls the control loop. (A client makes its objects before it registers with
/// a service, so they are ready when the gateway first sees it.)
pub fn gateway_node(name: &str) -> Result<Node<Ipc>, NodeError> {
    let mut config = config()?;
    config.global.creation_timeout = Duration::ZERO;
    build_node(name, config)
}

fn build_node(name: &str, config: Config) -> Result<Node<Ipc>, NodeError> {
    let mut builder = NodeBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .config(&config);
    if let Ok(name) = NodeName::new(name) {
        builder = builder.name(&name);
    }
    builder
        .create::<Ipc>()
        .map_err(|failure| NodeError::Create {
            dir: config.global.root_path().to_string(),
            failure,
        })
}

/// Why listing the nodes failed.
#[derive(Debug, thiserror::Error)]
pub enum ListError {
    /// The shared-memory directory cannot be used.
    #[error(transparent)]
    Dir(#[from] IpcDirError),
    /// iceoryx2 refused.
    #[error("listing the iceoryx2 nodes: {0:?}")]
    List(iceoryx2::node::NodeListFailure),
}

/// Removes what dead processes (SIGKILL, crash) left in shared memory; returns the names of
/// their nodes (`scout-gateway-ROBOT`, `scout-client-ROBOT`...; empty for an unnamed one).
pub fn remove_dead_nodes() -> Result<Vec<String>, ListError> {
    use iceoryx2::node::NodeView;
    quiet_iceoryx2_logs();
    let config = config()?;
    let mut removed = Vec::new();
    Node::<Ipc>::list(&config, |state| {
        if let NodeState::Dead(view) = state {
            let name = view
                .details()
                .as_ref()
                .map(|details| details.name().as_str().to_owned())
                .unwrap_or_default();
            if view.try_remove_stale_resources().is_ok() {
                removed.push(name);
            }
        }
        CallbackProgression::Continue
    })
    .map_err(ListError::List)?;
    Ok(removed)
}

/// The host's monotonic clock that counts suspend (CLOCK_BOOTTIME) now: the clock of every
/// `*_ns` field and of every command's stamp, comparable across processes, and the gateway's
/// one time base. CLOCK_MONOTONIC stands still while the host is suspended, so a suspend would
/// look like no time at all: the gateway would resume the command it sent before, to a chassis
/// that stopped by its own timeout meanwhile. On this clock a suspend is a gap like any stall.
pub fn monotonic() -> Duration {
    // CLOCK_BOOTTIME cannot fail on Linux (since 2.6.39) with a valid clock id.
    nix::time::clock_gettime(nix::time::ClockId::CLOCK_BOOTTIME)
        .map_or(Duration::ZERO, Duration::from)
}

/// [`monotonic`] now, ns.
pub fn monotonic_ns() -> u64 {
    monotonic().as_nanos() as u64
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
    /// The service exists with another payload layout: this program and the gateway were built
    /// from different versions of the interface.
    #[error(
        "gateway '{robot}' speaks another interface version than this program (layout v{LAYOUT_VERSION}) on {service}: use a scout and scout-gateway built from the same release"
    )]
    Incompatible {
        /// The robot name.
        robot: String,
        /// The service.
        service: String,
    },
    /// Creating or opening a publish-subscribe service failed.
    #[error("iceoryx2 service {service}: {error:?}")]
    PublishSubscribe {
        /// The service.
        service: String,
        /// iceoryx2's error.
        error: PublishSubscribeOpenOrCreateError,
    },
    /// Creating or opening an event service failed.
    #[error("iceoryx2 service {service}: {error:?}")]
    Event {
        /// The service.
        service: String,
        /// iceoryx2's error.
        error: EventOpenOrCreateError,
    },
    /// Creating or opening a request-response service failed.
    #[error("iceoryx2 service {service}: {error:?}")]
    RequestResponse {
        /// The service.
        service: String,
        /// iceoryx2's error.
        error: RequestResponseOpenOrCreateError,
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

/// What a client's open failed with, as far as the cause matters to the user.
enum OpenFailure {
    Missing,
    Incompatible,
    Other,
}

fn open_error(
    robot: &str,
    service: &str,
    failure: OpenFailure,
    other: ServiceError,
) -> ServiceError {
    match failure {
        OpenFailure::Missing => ServiceError::NoGateway {
            robot: robot.to_owned(),
        },
        OpenFailure::Incompatible => ServiceError::Incompatible {
            robot: robot.to_owned(),
            service: service.to_owned(),
        },
        OpenFailure::Other => other,
    }
}

/// Creates or opens the event service paired with `name`.
fn event_service(
    node: &Node<Ipc>,
    robot: &str,
    name: &str,
    role: Role,
    (notifiers, listeners): (usize, usize),
) -> Result<Events, ServiceError> {
    let error = |error| ServiceError::Event {
        service: name.to_owned(),
        error,
    };
    let builder = node.service_builder(&service_name(name)?).event();
    match role {
        Role::Gateway => builder
            .max_notifiers(notifiers)
            .max_listeners(listeners)
            .max_nodes(MAX_NODES)
            .open_or_create()
            .map_err(error),
        Role::Client => builder.open().map_err(|e| {
            let failure = match e {
                EventOpenError::DoesNotExist => OpenFailure::Missing,
                _ => OpenFailure::Other,
            };
            open_error(
                robot,
                name,
                failure,
                error(EventOpenOrCreateError::EventOpenError(e)),
            )
        }),
    }
}

/// Creates or opens a publish-subscribe service of `Payload` with one latest sample of history.
fn latest_value_service<Payload: std::fmt::Debug + ZeroCopySend>(
    node: &Node<Ipc>,
    robot: &str,
    name: &str,
    role: Role,
) -> Result<publish_subscribe::PortFactory<Ipc, Payload, ()>, ServiceError> {
    let error = |error| ServiceError::PublishSubscribe {
        service: name.to_owned(),
        error,
    };
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
            .map_err(error),
        Role::Client => builder.open().map_err(|e| {
            let failure = match e {
                PublishSubscribeOpenError::DoesNotExist => OpenFailure::Missing,
                PublishSubscribeOpenError::IncompatibleTypes => OpenFailure::Incompatible,
                _ => OpenFailure::Other,
            };
            let other = error(PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(e));
            open_error(robot, name, failure, other)
        }),
    }
}

/// The state services of `robot`: publish-subscribe and its event service.
pub fn state_services(
    node: &Node<Ipc>,
    robot: &str,
    role: Role,
) -> Result<(StateService, Events), ServiceError> {
    let name = state_service(robot);
    // Events first: clients take the publish-subscribe service as the sign that all exist.
    let events = event_service(node, robot, &name, role, (2, MAX_SUBSCRIBERS))?;
    let state = latest_value_service(node, robot, &name, role)?;
    Ok((state, events))
}

/// The status service of `robot`.
pub fn status_services(
    node: &Node<Ipc>,
    robot: &str,
    role: Role,
) -> Result<StatusService, ServiceError> {
    latest_value_service(node, robot, &status_service(robot), role)
}

/// A request service of `robot` (`way`) and the wake-up event both share.
pub fn request_services(
    node: &Node<Ipc>,
    robot: &str,
    way: Way,
    role: Role,
) -> Result<(ControlService, Events), ServiceError> {
    let name = way.service(robot);
    let error = |error| ServiceError::RequestResponse {
        service: name.clone(),
        error,
    };
    let builder = node
        .service_builder(&service_name(&name)?)
        .request_response::<ControlRequest, ControlResponse>();
    let requests = match role {
        // One server: a second gateway for this robot, even one whose stop socket lives in
        // another network namespace, cannot serve the same services.
        Role::Gateway => builder
            .max_servers(1)
            .max_clients(way.max_clients())
            .max_nodes(MAX_NODES)
            .max_active_requests_per_client(MAX_REQUESTS_IN_FLIGHT)
            .max_response_buffer_size(MAX_REQUESTS_IN_FLIGHT)
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
            .open_or_create()
            .map_err(error)?,
        Role::Client => builder.open().map_err(|e| {
            let failure = match e {
                RequestResponseOpenError::DoesNotExist => OpenFailure::Missing,
                RequestResponseOpenError::IncompatibleRequestOrResponseType => {
                    OpenFailure::Incompatible
                }
                _ => OpenFailure::Other,
            };
            let other = error(RequestResponseOpenOrCreateError::RequestResponseOpenError(
                e,
            ));
            open_error(robot, &name, failure, other)
        })?,
    };
    let wake = control_service(robot);
    let events = event_service(
        node,
        robot,
        &wake,
        role,
        (MAX_CONTROLLERS + MAX_STOPPERS, 2),
    )?;
    Ok((requests, events))
}

/// Why a request got no answer.
#[derive(Debug, thiserror::Error)]
pub enum RequestError {
    /// The arbiter refused it, with the reason.
    #[error("rejected: {0}")]
    Rejected(Rejected),
    /// No answer within [`ANSWER_TIMEOUT`]: the gateway is stopped, stuck or gone.
    #[error("no answer from gateway '{robot}' within {timeout:?}: is it running (not stopped)?")]
    NoAnswer {
        /// The robot.
        robot: String,
        /// How long it waited.
        timeout: Duration,
    },
    /// Sending the request failed.
    #[error("sending the request: {0:?}")]
    Send(iceoryx2::port::client::RequestSendError),
    /// Waking the gateway failed.
    #[error("waking the gateway: {0:?}")]
    Wake(iceoryx2::port::notifier::NotifierNotifyError),
    /// Receiving the answer failed.
    #[error("receiving the answer: {0:?}")]
    Receive(iceoryx2::port::ReceiveError),
}

impl From<Rejected> for RequestError {
    fn from(rejected: Rejected) -> Self {
        Self::Rejected(rejected)
    }
}

/// Why a control port could not be made.
#[derive(Debug, thiserror::Error)]
pub enum ControlPortError {
    /// The services could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// The client port could not be created (the gateway serves [`MAX_CONTROLLERS`] control
    /// and [`MAX_STOPPERS`] stop ports at once).
    #[error("creating a {way:?} port (all taken?): {error:?}")]
    Client {
        /// Which service.
        way: Way,
        /// iceoryx2's error.
        error: iceoryx2::service::port_factory::client::ClientCreateError,
    },
    /// The name cannot name an iceoryx2 port.
    #[error("client name `{0}` must be 1 to 32 bytes")]
    Name(String),
    /// The wake-up notifier could not be created.
    #[error("creating the wake-up notifier: {0:?}")]
    Notifier(iceoryx2::port::notifier::NotifierCreateError),
}

/// A client's way to the arbiter: sends one request at a time and waits for its answer. The
/// port's name is the client's name: the gateway reads it from iceoryx2 with the request.
#[derive(Debug)]
pub struct ControlPort {
    robot: String,
    seq: u64,
    client: Client<Ipc, ControlRequest, (), ControlResponse, ()>,
    wake: Notifier<Ipc>,
}

impl ControlPort {
    /// A port named `name` on `robot`'s request service `way`.
    pub fn open(
        node: &Node<Ipc>,
        robot: &str,
        way: Way,
        name: &str,
    ) -> Result<Self, ControlPortError> {
        let port_name = (!name.is_empty() && name.len() <= crate::control::MAX_CLIENT_NAME)
            .then(|| iceoryx2::prelude::PortName::new(name).ok())
            .flatten()
            .ok_or_else(|| ControlPortError::Name(name.to_owned()))?;
        let (requests, events) = request_services(node, robot, way, Role::Client)?;
        Ok(Self {
            robot: robot.to_owned(),
            seq: 0,
            client: requests
                .client_builder()
                .name(&port_name)
                .create()
                .map_err(|error| ControlPortError::Client { way, error })?,
            wake: events
                .notifier_builder()
                .create()
                .map_err(ControlPortError::Notifier)?,
        })
    }

    /// Sends `request`, wakes the gateway and waits for the answer.
    pub fn request(&mut self, request: &crate::control::Request) -> Result<Accepted, RequestError> {
        self.request_sent_at(request, monotonic())
    }

    /// Sends `request` as sent at `sent` (CLOCK_MONOTONIC; earlier than now for a command that
    /// was held up before it reached this port, such as a remote one), and waits for the
    /// answer.
    pub fn request_sent_at(
        &mut self,
        request: &crate::control::Request,
        sent: Duration,
    ) -> Result<Accepted, RequestError> {
        self.send(request, sent, "")
    }

    /// Sends a stop or release for remote peer `peer` (its client name, `remote:...`). Only
    /// the gateway's own zenoh bridge is heard speaking for a peer; from anyone else the field
    /// is ignored.
    pub fn request_for_peer(
        &mut self,
        request: &crate::control::Request,
        peer: &str,
    ) -> Result<Accepted, RequestError> {
        self.send(request, monotonic(), peer)
    }

    fn send(
        &mut self,
        request: &crate::control::Request,
        sent: Duration,
        peer: &str,
    ) -> Result<Accepted, RequestError> {
        self.seq += 1;
        let mut wire = request.encode(self.seq);
        wire.sent_ns = sent.as_nanos() as u64;
        wire.peer = crate::text::FixedText::new(peer);
        let pending = self.client.send_copy(wire).map_err(RequestError::Send)?;
        self.wake.notify().map_err(RequestError::Wake)?;
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        loop {
            // The clock is read before looking: a process that stood still past the deadline
            // (SIGSTOP, a loaded host) still takes the answer that came meanwhile, rather than
            // saying the gateway did not answer.
            let late = Instant::now() >= deadline;
            while let Some(response) = pending.receive().map_err(RequestError::Receive)? {
                if response.seq == self.seq {
                    return Ok(response.answer()?);
                }
            }
            if late {
                return Err(RequestError::NoAnswer {
                    robot: self.robot.clone(),
                    timeout: ANSWER_TIMEOUT,
                });
            }
            std::thread::sleep(Duration::from_micros(200));
        }
    }
}

/// The newest sample a subscriber holds, skipping older ones; `None` when it holds none.
pub fn latest<Payload: std::fmt::Debug + ZeroCopySend + Copy>(
    subscriber: &iceoryx2::port::subscriber::Subscriber<Ipc, Payload, ()>,
) -> Result<Option<Payload>, iceoryx2::port::ReceiveError> {
    let mut latest = None;
    while let Some(sample) = subscriber.receive()? {
        latest = Some(*sample);
    }
    Ok(latest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(unsafe_code)]
    fn payload_type_names_carry_the_layout_version() {
        use iceoryx2::prelude::ZeroCopySend;
        let suffix = format!(".v{LAYOUT_VERSION}");
        // SAFETY: `type_name` only returns the derive's constant string.
        for name in [
            unsafe { StatePayload::type_name() },
            unsafe { StatusPayload::type_name() },
            unsafe { ControlRequest::type_name() },
            unsafe { ControlResponse::type_name() },
        ] {
            assert!(name.ends_with(&suffix), "{name}");
        }
    }
}
