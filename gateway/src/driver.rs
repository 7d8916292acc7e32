//! The driver: the one thread that does the gateway's I/O around the sans-IO [`Core`]. Each
//! iteration reads the clock once, feeds the core what arrived (port input, client requests,
//! client deaths, a stop signal), carries out what it polls out (frames to the port, state and
//! status to iceoryx2, opening the port) and waits in `ppoll` on the port and the clients'
//! wake-up event until the core's next deadline.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::BackpressureStrategy;
use iceoryx2::prelude::CallbackProgression;
use iceoryx2::service::port_factory::PortFactory;
use scout_interface::control::{ControlRequest, ControlResponse, Rejection, StatusPayload};
use scout_interface::robot::{Program, RobotName};
use scout_interface::services::{self, ControlService, Ipc, Role, Way, monotonic};
use scout_interface::state::{LinkState, StatePayload};
use scout_interface::stop_socket::{Ask, ParseError, StopReply};
use scout_protocol::can;
use scout_protocol::link::RxEvent;
use tracing::{debug, error, info, warn};

use crate::arbiter::{Answer, ClientKey, GATEWAY, OPERATOR, OTHERS, Origin};
use crate::blackbox::{Direction, Recorder};
use crate::config::GatewayConfig;
use crate::core::{Core, Publication, Start};
use crate::device::{Device, DeviceSpec, OpenError};
use crate::identity::{Operators, ProcessIdentity};
use crate::monitor::NodeMonitor;
use crate::share::UserShares;
use crate::state::PortCounters;
use crate::stop_endpoint::{Received, StopEndpoint};
use crate::wait::Ready;
use scout_interface::remote::REMOTE_PREFIX;

/// The gateway's iceoryx2 side: the node and the ports it owns.
struct Endpoints {
    state: Publisher<Ipc, StatePayload, ()>,
    state_notifier: Notifier<Ipc>,
    status: Publisher<Ipc, StatusPayload, ()>,
    control: RequestServer,
    stop: RequestServer,
    wake: Listener<Ipc>,
    // Dropped last: the ports above belong to it.
    _node: Node<Ipc>,
}

impl Endpoints {
    fn create(robot: &RobotName) -> anyhow::Result<Self> {
        match services::remove_dead_nodes() {
            Ok(removed) if removed.is_empty() => {}
            Ok(removed) => info!(
                "removed the stale iceoryx2 resources of {} dead process(es): {}",
                removed.len(),
                removed.join(", ")
            ),
            Err(error) => warn!("cleaning up after dead processes failed: {error}"),
        }
        let node = services::gateway_node(&robot.node(Program::Gateway))
            .context("creating the iceoryx2 node")?;
        // The state service last: once it exists, clients find every service.
        let status = services::status_services(&node, robot, Role::Gateway)?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .context("creating the status publisher")?;
        let stop = RequestServer::create(&node, robot, Way::Stop)?;
        let control = RequestServer::create(&node, robot, Way::Control)?;
        let (_, control_events) =
            services::request_services(&node, robot, Way::Control, Role::Gateway)?;
        let wake = control_events
            .listener_builder()
            .create()
            .context("creating the control listener")?;
        let (state, events) = services::state_services(&node, robot, Role::Gateway)?;
        let state = state
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .max_loaned_samples(2)
            .create()
            .context("creating the state publisher")?;
        let state_notifier = events
            .notifier_builder()
            .create()
            .context("creating the state notifier")?;
        Ok(Self {
            state,
            state_notifier,
            status,
            control,
            stop,
            wake,
            _node: node,
        })
    }

    /// Publishes into a loaned sample (and wakes the state's subscribers). Never blocks: a full
    /// subscriber queue drops its oldest sample.
    fn publish(&self, publication: &Publication<'_>) -> anyhow::Result<()> {
        match publication {
            Publication::State(state) => {
                let sample = self
                    .state
                    .loan_uninit()
                    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
                // Stamped as it goes out: subscribers measure delivery from here.
                let state = StatePayload {
                    published_ns: services::monotonic_ns(),
                    ..**state
                };
                sample
                    .write_payload(state)
                    .send()
                    .map_err(|e| anyhow::anyhow!("sending the state: {e:?}"))?;
                self.state_notifier
                    .notify()
                    .map_err(|e| anyhow::anyhow!("notifying the subscribers: {e:?}"))?;
            }
            Publication::Status(status) => {
                let sample = self
                    .status
                    .loan_uninit()
                    .map_err(|e| anyhow::anyhow!("{e:?}"))?;
                sample
                    .write_payload(**status)
                    .send()
                    .map_err(|e| anyhow::anyhow!("sending the status: {e:?}"))?;
            }
        }
        Ok(())
    }
}

/// A request service's server, and what its dynamic configuration tells of each client port.
struct RequestServer {
    way: Way,
    service: ControlService,
    server: Server<Ipc, ControlRequest, (), ControlResponse, ()>,
}

impl RequestServer {
    fn create(node: &Node<Ipc>, robot: &str, way: Way) -> anyhow::Result<Self> {
        let (service, _) = services::request_services(node, robot, way, Role::Gateway)?;
        let server = service.server_builder().create().map_err(|error| {
            anyhow::anyhow!(
                "creating the {way:?} server of robot '{robot}' failed ({error:?}): another \
                     scout-gateway serves this robot name (in another network namespace or \
                     container?); stop it, or give this one another --name"
            )
        })?;
        Ok(Self {
            way,
            service,
            server,
        })
    }

    /// Who sent a request: the port, its node and its name as iceoryx2 records them, and the
    /// operator role from its process's identity.
    fn origin(&self, port: u128, operators: &Operators) -> Origin {
        let mut key = ClientKey {
            port,
            node: 0,
            name: String::new(),
            uid: None,
        };
        let mut pid = None;
        self.service.dynamic_config().list_clients(|client| {
            if client.client_id.value() != port {
                return CallbackProgression::Continue;
            }
            key.node = client.node_id.value();
            key.name = client.client_name.as_str().to_owned();
            pid = client.node_id.pid::<Ipc>().ok().map(|pid| pid.value());
            CallbackProgression::Stop
        });
        let pid = pid.and_then(|pid| u32::try_from(pid).ok());
        let in_this_process = pid == Some(std::process::id());
        let bridge = in_this_process && key.name == REMOTE_PREFIX;
        let identity = pid.filter(|_| !in_this_process).map(ProcessIdentity::of);
        let operator = identity
            .as_ref()
            .is_some_and(|identity| operators.is_operator(identity));
        // The bridge in this process is of the gateway's own user.
        let uid = match identity {
            _ if in_this_process => Some(nix::unistd::getuid().as_raw()),
            Some(identity) => identity.uids.first().copied(),
            None => None,
        };
        let claim = Claim {
            pid,
            node: key.node,
            uid,
            in_this_process,
            operator,
        };
        key.name = client_name(&key.name, &claim);
        key.uid = uid;
        Origin {
            key,
            operator,
            bridge,
        }
    }
}

/// What the transport and the OS tell of a client, against the name it chose.
#[derive(Debug, Clone, Copy)]
struct Claim {
    /// Its process.
    pid: Option<u32>,
    /// Its iceoryx2 node (0: none).
    node: u128,
    /// Its user.
    uid: Option<u32>,
    /// It is the gateway's own process (the zenoh bridge).
    in_this_process: bool,
    /// It has the operator role.
    operator: bool,
}

/// The name a client goes by: the one it chose, unless that is reserved. Empty, the gateway's
/// own, merged stops' or a remote peer's (which only the bridge in this process speaks for):
/// `client-PID`, the same for every port of one process, so that such a client can still
/// release its own stops. [`OPERATOR`] without the operator role: `uid-UID`, its user's, so
/// that another user's `scout estop` is that user's stop, never one that any client calling
/// itself `operator` may release.
fn client_name(chosen: &str, claim: &Claim) -> String {
    if chosen == OPERATOR
        && !claim.operator
        && let Some(uid) = claim.uid
    {
        return format!("uid-{uid}");
    }
    let reserved = chosen.is_empty()
        || chosen == GATEWAY
        || chosen == OTHERS
        || (chosen == OPERATOR && !claim.operator)
        || (chosen.starts_with(REMOTE_PREFIX) && !claim.in_this_process);
    if !reserved {
        return chosen.to_owned();
    }
    match claim.pid {
        Some(pid) => format!("client-{pid}"),
        None => format!(
            "client-node-{:x}",
            (claim.node as u64) ^ ((claim.node >> 64) as u64)
        ),
    }
}

/// Control requests handled per iteration at most: a flood cannot hold up the tick.
const MAX_REQUESTS_PER_ITERATION: usize = 64;

/// Stop-endpoint datagrams handled per iteration at most, and the time they may take: the rest
/// wait until the endpoint has rested ([`DATAGRAM_REST`]). Each costs a few tens of µs within
/// its user's share (its sender's identity is read from procfs, bounded: [`crate::identity`]),
/// a few µs past it (refused unread and unanswered, unless a stop); one user's flood is
/// refused at its share ([`UserShares`]) while the others' stops are read.
const MAX_DATAGRAMS_PER_ITERATION: usize = 64;
/// See [`MAX_DATAGRAMS_PER_ITERATION`].
const DATAGRAM_BUDGET: Duration = Duration::from_millis(1);
/// How long the stop endpoint rests after a full budget: a flood costs the control thread (a
/// real-time thread under the unit) at most [`DATAGRAM_BUDGET`] in every budget and rest, 20 %
/// of a core, whoever floods; a stop queued meanwhile latches after at most this, within a
/// tick. Senders wait in the kernel's queue for the endpoint (first come, first served).
const DATAGRAM_REST: Duration = Duration::from_millis(4);

/// The client key of a stop-endpoint sender: no iceoryx2 port, so a number of its own.
const DATAGRAM_PORT: u128 = 1 << 127;

/// The gateway's control thread.
pub struct Driver {
    spec: DeviceSpec,
    core: Core,
    device: Option<Device>,
    endpoints: Endpoints,
    monitor: NodeMonitor,
    buffer: Box<[u8; 4096]>,
    publish_errors: u64,
    operators: Operators,
    stop_endpoint: StopEndpoint,
    shares: UserShares,
    origins: std::collections::HashMap<u128, Origin>,
    backlog: bool,
    /// Until when the stop endpoint rests after a full budget of datagrams.
    datagrams_rest_until: Option<Duration>,
    realtime_priority: u8,
    service_manager: scout_io::notify::ServiceManager,
    /// The black box of the bus (none when configured off).
    black_box: Option<Recorder>,
}

impl std::fmt::Debug for Driver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Driver")
            .field("spec", &self.spec)
            .finish_non_exhaustive()
    }
}

impl Driver {
    /// Sets up the iceoryx2 services for `config.name`; the port is opened by [`Driver::run`].
    /// `stop_endpoint` is the robot's bound stop socket (taken first: it is the name's lock).
    pub fn new(
        config: &GatewayConfig,
        spec: DeviceSpec,
        start: Start,
        stop_endpoint: StopEndpoint,
    ) -> anyhow::Result<Self> {
        let endpoints = Endpoints::create(&config.name)?;
        let now = monotonic();
        let instance = std::process::id() ^ (now.subsec_nanos() << 8);
        let core = Core::new(config, spec.transport(), &spec.name(), now, start, instance);
        let monitor = NodeMonitor::start().context("starting the client monitor thread")?;
        Ok(Self {
            spec,
            core,
            device: None,
            endpoints,
            monitor,
            buffer: Box::new([0; 4096]),
            publish_errors: 0,
            operators: Operators::for_this_gateway(&config.arbiter.operators),
            stop_endpoint,
            shares: UserShares::new(config.arbiter.request_rate_hz, config.arbiter.request_burst),
            origins: std::collections::HashMap::new(),
            backlog: false,
            datagrams_rest_until: None,
            realtime_priority: config.timing.realtime_priority,
            service_manager: scout_io::notify::ServiceManager::from_env(),
            black_box: Recorder::start(&config.blackbox, &config.name.to_string())
                .context("starting the black box thread")?,
        })
    }

    /// The link state now.
    pub fn link_state(&self) -> LinkState {
        self.core.link_state()
    }

    /// Runs until `stop` is set, then sends zero speed for the configured cycles and returns.
    pub fn run(&mut self, stop: &AtomicBool) -> anyhow::Result<()> {
        let result = self.run_loop(stop);
        if let (Err(error), Some(black_box)) = (&result, &mut self.black_box) {
            black_box.save(format!("the gateway failed: {error:#}"));
        }
        result
    }

    fn run_loop(&mut self, stop: &AtomicBool) -> anyhow::Result<()> {
        scout_io::raise_priority(self.realtime_priority, "control thread");
        let mut ready = Ready::default();
        loop {
            let now = monotonic();
            self.service_manager.pet(now);
            self.receive(now, ready.port);
            // What the port brought goes out before the requests are served.
            self.publish(now);
            if stop.load(Ordering::Relaxed) {
                self.core.handle_shutdown();
            }
            self.handle_requests(now);
            while let Some(node) = self.monitor.try_gone() {
                self.core.handle_client_gone(now, node);
            }
            while let Some(node) = self.core.poll_new_client() {
                self.monitor.watch(node);
            }
            if self.core.poll_open(now) {
                self.open(now)?;
            }
            self.transmit();
            self.publish(now);
            if let Some(black_box) = &mut self.black_box {
                while let Some(why) = self.core.poll_black_box() {
                    black_box.save(why);
                }
                black_box.hand_over();
            }
            if self.core.is_finished() {
                break;
            }
            let deadline = match self.datagrams_rest_until {
                _ if self.backlog => now,
                Some(until) => until.min(self.core.poll_timeout()),
                None => self.core.poll_timeout(),
            };
            ready = self.wait(now, deadline);
        }
        self.device = None;
        let stats = self.core.stats();
        info!(
            "stopped: {} motion commands sent ({} out of schedule for a stop), {} ticks missed, \
             worst lateness {:?}, {} requests, {} publish errors",
            stats.commands_sent,
            stats.urgent_stops,
            stats.missed_ticks,
            stats.max_lateness,
            stats.requests,
            self.publish_errors
        );
        Ok(())
    }

    /// Publishes what the core has to publish now.
    fn publish(&mut self, now: Duration) {
        while let Some(publication) = self.core.poll_publish(now) {
            if let Err(error) = self.endpoints.publish(&publication) {
                self.publish_errors += 1;
                if self.publish_errors.is_power_of_two() {
                    error!(
                        "publishing failed ({} times): {error:#}",
                        self.publish_errors
                    );
                }
            }
        }
    }

    /// Feeds the core what the port delivered.
    fn receive(&mut self, now: Duration, readable: bool) {
        let Some(device) = self.device.as_mut() else {
            return;
        };
        let core = &mut self.core;
        let black_box = self.black_box.as_ref();
        let result = device.receive(now, readable, &mut self.buffer[..], |event| {
            if let Some(black_box) = black_box {
                let frame = match &event {
                    RxEvent::Message(counted) => Some(can::encode(&counted.message, counted.count)),
                    RxEvent::V2(message) => Some(message.encode()),
                    RxEvent::Rejected(_) | RxEvent::Slcan(_) => None,
                };
                if let Some(frame) = frame {
                    black_box.record(Direction::Rx, frame, now);
                }
            }
            core.handle_rx(now, &event);
        });
        core.handle_port_counters(PortCounters {
            discarded_bytes: device.discarded_bytes(),
            overflowed_frames: device.overflowed_frames(),
        });
        if let Err(error) = result {
            self.device = None;
            let what = format!("reading: {error}");
            if scout_io::is_bus_fault(&error) {
                self.core.handle_link_fault(now, &what);
            } else {
                self.core.handle_link_failed(now, &what);
            }
        }
    }

    /// Answers every waiting stop, then at most [`MAX_REQUESTS_PER_ITERATION`] control
    /// requests (the rest wait for the next iteration, after the tick), looking for stops again
    /// before each one: a stop waits for one control request at most, never for a batch.
    fn handle_requests(&mut self, now: Duration) {
        // Drained every iteration, not only when `ppoll` saw it readable: iceoryx2 sends no
        // wake-up while it believes one is pending, and a notification that raced with the
        // last drain can leave it believing so with the socket empty; then only draining
        // (cheap: an atomic and a non-blocking read) makes clients wake the gateway again.
        if let Err(error) = self.endpoints.wake.try_wait(|_| {}) {
            debug!("draining the wake-up event failed: {error:?}");
        }
        if self.datagrams_rest_until.is_none_or(|until| now >= until) {
            let more = self.serve_datagrams(now);
            self.datagrams_rest_until = more.then(|| monotonic() + DATAGRAM_REST);
        }
        let mut stops_waiting = self.serve_stops(now);
        let mut requests_waiting = false;
        for _ in 0..MAX_REQUESTS_PER_ITERATION {
            requests_waiting = self.serve(now, Way::Control, 1);
            if !requests_waiting {
                break;
            }
            stops_waiting = self.serve_stops(now);
        }
        self.backlog = stops_waiting || requests_waiting;
    }

    /// Answers the datagrams waiting on the stop endpoint (bounded in number and time), each
    /// stop's zero on the wire before the next is read; returns whether more may wait.
    fn serve_datagrams(&mut self, now: Duration) -> bool {
        let started = monotonic();
        for _ in 0..MAX_DATAGRAMS_PER_ITERATION {
            if monotonic().saturating_sub(started) > DATAGRAM_BUDGET {
                return true;
            }
            let Some(received) = self.stop_endpoint.try_receive() else {
                return false;
            };
            if let Some((seq, answer)) = self.serve_datagram(now, &received) {
                let reply = StopReply::new(seq, &answer, std::process::id());
                self.stop_endpoint.reply(received.from.as_ref(), &reply);
            }
        }
        true
    }

    /// One datagram, and its answer (none: past its user's share). Every datagram, garbage
    /// included, is taken from its user's share first. Within it the sender's identity is read
    /// (the operator role, and so the name `operator`); past it, a stop still latches, as a
    /// non-operator's (named `uid-UID` if it claimed `operator`), and anything else is counted
    /// as rate limited and dropped unanswered: a flood costs no identity and no reply.
    fn serve_datagram(&mut self, now: Duration, received: &Received) -> Option<(u64, Answer)> {
        let within_share = self.shares.admit(now, received.uid);
        let rate_limited = || Rejection::RateLimited {
            rate: self.shares.rate(),
        };
        let request = match &received.request {
            Ok(request) => request,
            Err(_) if !within_share => {
                self.core.count_datagram_rejection(&rate_limited());
                return None;
            }
            Err(error) => {
                let seq = match error {
                    ParseError::Malformed { seq, .. } => seq.unwrap_or(0),
                    ParseError::NotOurs(_) => 0,
                };
                let rejection = Rejection::Malformed(error.to_string());
                self.core.count_datagram_rejection(&rejection);
                return Some((seq, Err(rejection)));
            }
        };
        let is_stop = matches!(request.ask, Ask::Stop { .. });
        if !within_share && !is_stop {
            self.core.count_datagram_rejection(&rate_limited());
            return None;
        }
        let pid = (received.pid != 0).then_some(received.pid);
        let needs_identity = within_share && !matches!(request.ask, Ask::Ping);
        let identity = pid.filter(|_| needs_identity).map(ProcessIdentity::of);
        let operator = identity
            .as_ref()
            .is_some_and(|identity| self.operators.is_operator(identity));
        let chosen = request.name.as_deref().unwrap_or("");
        let claim = Claim {
            pid,
            node: 0,
            uid: (received.uid != u32::MAX).then_some(received.uid),
            in_this_process: false,
            operator,
        };
        let origin = Origin {
            key: ClientKey {
                port: DATAGRAM_PORT | u128::from(received.pid),
                node: 0,
                name: client_name(chosen, &claim),
                uid: claim.uid,
            },
            operator,
            bridge: false,
        };
        let answer = self.core.handle_stop_datagram(now, &origin, &request.ask);
        if is_stop {
            self.transmit();
        }
        Some((request.seq, answer))
    }

    /// Answers the waiting stops, bounded (a flood of stops cannot hold up the zero frame), and
    /// sends their zero before anything else is read; returns whether more stops wait.
    fn serve_stops(&mut self, now: Duration) -> bool {
        let waiting = self.serve(now, Way::Stop, services::MAX_STOPPERS);
        self.transmit();
        waiting
    }

    /// Answers at most `limit` requests of `way`; returns whether more are waiting.
    fn serve(&mut self, now: Duration, way: Way, limit: usize) -> bool {
        let endpoint = match way {
            Way::Control => &self.endpoints.control,
            Way::Stop => &self.endpoints.stop,
        };
        for _ in 0..limit {
            let active = match endpoint.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => return false,
                Err(error) => {
                    warn!("receiving {:?} requests failed: {error:?}", endpoint.way);
                    return false;
                }
            };
            let port = active.origin().value();
            let origin = match self.origins.get(&port) {
                Some(origin) => origin.clone(),
                None => {
                    let origin = endpoint.origin(port, &self.operators);
                    if self.origins.len() > 4 * services::MAX_STOPPERS {
                        self.origins.clear();
                    }
                    self.origins.insert(port, origin.clone());
                    origin
                }
            };
            let response = self
                .core
                .handle_request(now, &origin, way, active.payload());
            if let Err(error) = active.send_copy(response) {
                debug!("answering request {} failed: {error:?}", response.seq);
            }
        }
        true
    }

    /// Sends every frame the core has for the port now. The clock is read again here: a stall
    /// (SIGSTOP, starved of CPU) since the iteration read it must not send a frame made for
    /// before the stall; the core sees the gap first, and latches.
    fn transmit(&mut self) {
        let now = monotonic();
        while let Some(frame) = self.core.poll_transmit(now) {
            let Some(device) = self.device.as_mut() else {
                return;
            };
            let sent = device.send(&frame, now);
            if let (Ok(()), Some(black_box)) = (&sent, &self.black_box) {
                black_box.record(Direction::Tx, frame.can_frame(), now);
            }
            if let Err(error) = sent {
                self.device = None;
                let what = format!("writing: {error}");
                // A full CAN transmit queue, a downed interface, frames nothing acknowledges:
                // the bus or adapter failed.
                if scout_io::is_bus_fault(&error) {
                    self.core.handle_link_fault(now, &what);
                } else {
                    self.core.handle_link_failed(now, &what);
                }
            }
        }
    }

    /// Opens the device. Another gateway owning it at the first attempt is fatal (this one
    /// should not have started); later, it is one more reason to retry.
    fn open(&mut self, now: Duration) -> anyhow::Result<()> {
        match self.spec.open(now) {
            Ok(device) => {
                self.device = Some(device);
                self.core.handle_opened(now);
            }
            Err(OpenError::Owned(owned)) if !self.core.has_opened() => return Err(owned.into()),
            Err(error) => self.core.handle_open_failed(now, &error.to_string()),
        }
        Ok(())
    }

    /// Waits for input or a wake-up until `deadline` (`now` is this iteration's clock).
    fn wait(&mut self, now: Duration, deadline: Duration) -> Ready {
        // A resting endpoint is not watched: its queue would wake the wait at once.
        let stops = (self.datagrams_rest_until.is_none()).then(|| self.stop_endpoint.fd());
        let result = match self.device.as_ref() {
            Some(device) => device.wait(now, deadline, &self.endpoints.wake, stops),
            None => crate::wait::wait(
                None,
                &self.endpoints.wake,
                stops,
                deadline.saturating_sub(now),
            ),
        };
        result.unwrap_or_else(|error| {
            debug!("waiting failed: {error}");
            std::thread::sleep(deadline.saturating_sub(now).min(Duration::from_millis(1)));
            Ready::default()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn claim(operator: bool, uid: Option<u32>) -> Claim {
        Claim {
            pid: Some(42),
            node: 0,
            uid,
            in_this_process: false,
            operator,
        }
    }

    #[test]
    fn the_operator_name_is_an_operators_only() {
        assert_eq!(client_name(OPERATOR, &claim(true, Some(0))), OPERATOR);
        assert_eq!(client_name(OPERATOR, &claim(false, Some(1001))), "uid-1001");
        assert_eq!(client_name(OPERATOR, &claim(false, None)), "client-42");
        assert_eq!(client_name("guard", &claim(false, Some(1001))), "guard");
    }

    #[test]
    fn reserved_names_become_the_process() {
        for reserved in ["", GATEWAY, OTHERS, REMOTE_PREFIX] {
            assert_eq!(client_name(reserved, &claim(true, Some(0))), "client-42");
        }
        let bridge = Claim {
            in_this_process: true,
            ..claim(false, None)
        };
        let peer = format!("{REMOTE_PREFIX}laptop");
        assert_eq!(client_name(&peer, &bridge), peer);
    }
}
