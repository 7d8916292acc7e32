//! The control loop: the one thread that owns the port, the 20 ms command schedule and the state.
//! It reads feedback until the next deadline, sends 0x130 on an absolute monotonic schedule,
//! publishes the state zero-copy, and reopens the port when it fails.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use std::collections::HashSet;

use anyhow::Context;
use iceoryx2::node::Node;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::prelude::BackpressureStrategy;
use scout_clients::ipc::{
    self, ControlRequest, ControlResponse, Ipc, LinkState, Role, StatePayload, StatusPayload,
    TransportKind,
};
use scout_protocol::sequence::RollingCounter;
use scout_protocol::units::{self, MAX_LINEAR_SPEED};
use scout_protocol::{Counted, LightCommand, Message, MotionCommand};
use tracing::{debug, error, info, warn};

use crate::arbiter::{Arbiter, LightsSetting, Output};
use crate::config::GatewayConfig;
use crate::device::{Device, DeviceSpec, OpenError};
use crate::link::RxEvent;
use crate::monitor::NodeMonitor;
use crate::requests::{self, Action};
use crate::state::{Publish, StateTracker};

/// The state is published at least this often, frames or not: a subscriber sees that the
/// gateway lives while the chassis is silent, and a late subscriber gets the latest state fast.
const HEARTBEAT: Duration = Duration::from_millis(100);

/// The first wait before reopening a failed port; it doubles up to `reconnect_max_ms`.
const FIRST_BACKOFF: Duration = Duration::from_millis(50);

/// The status is published at least this often, changes or not.
const STATUS_HEARTBEAT: Duration = Duration::from_secs(1);

/// The iceoryx2 side: the node and the ports the gateway owns.
struct Ports {
    publisher: Publisher<Ipc, StatePayload, ()>,
    notifier: Notifier<Ipc>,
    status: Publisher<Ipc, StatusPayload, ()>,
    server: Server<Ipc, ControlRequest, (), ControlResponse, ()>,
    wake: Listener<Ipc>,
    // Dropped last: the ports above belong to it.
    _node: Node<Ipc>,
}

impl Ports {
    fn create(robot: &str) -> anyhow::Result<Self> {
        let removed = ipc::remove_dead_nodes();
        if removed > 0 {
            info!("removed the stale iceoryx2 resources of {removed} dead process(es)");
        }
        let node =
            ipc::node(&format!("scout-gateway-{robot}")).context("creating the iceoryx2 node")?;
        // The state service last: once it exists, clients find every service.
        let status = ipc::status_services(&node, robot, Role::Gateway)?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .context("creating the status publisher")?;
        let (control, control_events) = ipc::control_services(&node, robot, Role::Gateway)?;
        let server = control
            .server_builder()
            .create()
            .context("creating the control server")?;
        let wake = control_events
            .listener_builder()
            .create()
            .context("creating the control listener")?;
        let (state, events) = ipc::state_services(&node, robot, Role::Gateway)?;
        let publisher = state
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .max_loaned_samples(2)
            .create()
            .context("creating the state publisher")?;
        let notifier = events
            .notifier_builder()
            .create()
            .context("creating the state notifier")?;
        Ok(Self {
            publisher,
            notifier,
            status,
            server,
            wake,
            _node: node,
        })
    }

    /// Publishes `state` into a loaned sample and wakes the subscribers. Never blocks: a full
    /// subscriber queue drops its oldest sample.
    fn publish(&self, state: &StatePayload) -> anyhow::Result<()> {
        let sample = self
            .publisher
            .loan_uninit()
            .context("loaning a state sample")?;
        sample
            .write_payload(*state)
            .send()
            .context("sending the state")?;
        self.notifier
            .notify()
            .context("notifying the subscribers")?;
        Ok(())
    }

    fn publish_status(&self, status: &StatusPayload) -> anyhow::Result<()> {
        let sample = self
            .status
            .loan_uninit()
            .context("loaning a status sample")?;
        sample
            .write_payload(*status)
            .send()
            .context("sending the status")?;
        Ok(())
    }
}

/// How the loop is doing, for the log at exit.
#[derive(Debug, Default, Clone, Copy)]
struct LoopStats {
    commands_sent: u64,
    /// Ticks whose deadline had passed by more than a period (skipped to stay on the grid).
    missed_ticks: u64,
    max_lateness: Duration,
    publish_errors: u64,
    requests: u64,
    urgent_stops: u64,
}

/// The gateway's control loop.
pub struct ControlLoop {
    config: GatewayConfig,
    spec: DeviceSpec,
    start: Instant,
    device: Option<Device>,
    tracker: StateTracker,
    arbiter: Arbiter,
    ports: Ports,
    monitor: NodeMonitor,
    watched_nodes: HashSet<u128>,
    status: StatusPayload,
    last_status: Duration,
    motion_count: RollingCounter,
    light_count: RollingCounter,
    next_command: Duration,
    next_light: Duration,
    reopen_at: Duration,
    backoff: Duration,
    opened_before: bool,
    last_open_error: Option<String>,
    events: Vec<RxEvent>,
    buffer: Box<[u8; 4096]>,
    last_publish: Duration,
    stats: LoopStats,
}

impl std::fmt::Debug for ControlLoop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ControlLoop")
            .field("spec", &self.spec)
            .finish_non_exhaustive()
    }
}

impl ControlLoop {
    /// Sets up the iceoryx2 services for `config.name`; the port is opened by [`ControlLoop::run`].
    pub fn new(config: GatewayConfig, spec: DeviceSpec) -> anyhow::Result<Self> {
        let ports = Ports::create(&config.name)?;
        let tracker =
            StateTracker::new(&config.name, spec.kind(), &spec.name(), config.max_angular);
        let arbiter = Arbiter::new(config.arbiter.clone(), config.max_angular);
        let monitor = NodeMonitor::start().context("starting the client monitor thread")?;
        Ok(Self {
            tracker,
            arbiter,
            ports,
            monitor,
            watched_nodes: HashSet::new(),
            status: StatusPayload::default(),
            last_status: Duration::ZERO,
            spec,
            start: Instant::now(),
            device: None,
            motion_count: RollingCounter::default(),
            light_count: RollingCounter::default(),
            next_command: Duration::ZERO,
            next_light: Duration::ZERO,
            reopen_at: Duration::ZERO,
            backoff: FIRST_BACKOFF,
            opened_before: false,
            last_open_error: None,
            events: Vec::with_capacity(64),
            buffer: Box::new([0; 4096]),
            last_publish: Duration::ZERO,
            stats: LoopStats::default(),
            config,
        })
    }

    fn now(&self) -> Duration {
        self.start.elapsed()
    }

    /// The light command to repeat: what clients asked for last (`auto`: host control off), or
    /// none before anyone asked.
    fn lights(&self) -> Option<LightCommand> {
        self.arbiter.lights().map(|setting| match setting {
            LightsSetting::Manual(lights) => lights,
            LightsSetting::Auto => LightCommand::default(),
        })
    }

    fn light_period(&self) -> Duration {
        Duration::from_millis(match self.spec.kind() {
            TransportKind::Serial => self.config.timing.serial_light_period_ms,
            _ => self.config.timing.can_light_period_ms,
        })
    }

    /// Runs until `stop` is set, then sends zero speed for `stop_cycles` more cycles and returns.
    pub fn run(&mut self, stop: &AtomicBool) -> anyhow::Result<()> {
        let period = self.config.command_period();
        self.publish();
        let mut stopping: Option<u32> = None;
        loop {
            let now = self.now();
            if stopping.is_none() && stop.load(Ordering::Relaxed) {
                let cycles = self.config.timing.stop_cycles;
                info!("stopping: sending zero speed for {cycles} more cycles");
                stopping = Some(cycles);
            }
            if self.device.is_none() && now >= self.reopen_at {
                self.open(now)?;
            }
            // The status can change with a request, a client's death or a tick, nothing else.
            let mut status_due = self.handle_requests(now) > 0;
            while let Some(node) = self.monitor.try_gone() {
                self.watched_nodes.remove(&node);
                self.arbiter.handle_node_gone(now, node);
                status_due = true;
            }
            if self.arbiter.take_urgent_stop() {
                // The stop goes on the wire now, not at the next tick.
                self.stats.urgent_stops += 1;
                self.send_motion(&Output::STOP, now);
            }
            if now >= self.next_command {
                if stopping == Some(0) || (stopping.is_some() && self.device.is_none()) {
                    break;
                }
                let output = if stopping.is_some() {
                    Output::STOP
                } else {
                    self.arbiter.poll_output(now, period)
                };
                self.send_motion(&output, now);
                self.advance_schedule(now, period);
                status_due = true;
                if let Some(left) = stopping.as_mut() {
                    *left -= 1;
                }
            }
            if self.lights().is_some() && now >= self.next_light {
                self.send_lights(now);
            }
            if status_due {
                self.publish_status(now);
            }
            let publish = self.tracker.poll(ipc::monotonic_ns());
            self.publish_if(publish);
            if self.now().saturating_sub(self.last_publish) >= HEARTBEAT {
                self.publish();
            }
            let deadline = if self.lights().is_some() {
                self.next_command.min(self.next_light)
            } else {
                self.next_command
            };
            self.wait_for_input(deadline);
        }
        self.device = None;
        let stats = self.stats;
        info!(
            "stopped: {} motion commands sent ({} out of schedule for a stop), {} ticks missed, \
             worst lateness {:?}, {} requests, {} publish errors",
            stats.commands_sent,
            stats.urgent_stops,
            stats.missed_ticks,
            stats.max_lateness,
            stats.requests,
            stats.publish_errors
        );
        Ok(())
    }

    /// Answers every waiting request.
    /// Answers every waiting request; returns how many there were.
    fn handle_requests(&mut self, now: Duration) -> usize {
        let _ = self.ports.wake.try_wait(|_| {});
        let mut handled = 0;
        loop {
            let active = match self.ports.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => break,
                Err(error) => {
                    warn!("receiving control requests failed: {error}");
                    break;
                }
            };
            self.stats.requests += 1;
            handled += 1;
            let request = *active.payload();
            let client = requests::client_key(&request);
            if self.watched_nodes.insert(client.node) {
                self.monitor.watch(client.node);
            }
            let answer = match requests::decode(&request) {
                Ok(Action::Arbiter(decoded)) => self.arbiter.handle_request(now, &client, decoded),
                Ok(Action::ResetOdometry) => {
                    info!("odometry reset by {}", client.name);
                    let publish = self.tracker.reset_odometry();
                    self.publish_if(publish);
                    Ok(crate::arbiter::Accepted { clamped: false })
                }
                Err(rejection) => {
                    self.arbiter.count_rejection(&rejection);
                    Err(rejection)
                }
            };
            if let Err(rejection) = &answer {
                debug!(
                    "rejected {} from {}: {rejection}",
                    request.kind, client.name
                );
            }
            if let Err(error) = active.send_copy(requests::response(request.seq, &answer)) {
                debug!("answering {} failed: {error}", client.name);
            }
        }
        handled
    }

    fn publish_status(&mut self, now: Duration) {
        let status = requests::status(&self.arbiter, &self.config.name, now);
        if !requests::changed(&status, &self.status)
            && now.saturating_sub(self.last_status) < STATUS_HEARTBEAT
        {
            return;
        }
        self.last_status = now;
        let seq = self.status.seq + 1;
        self.status = StatusPayload {
            seq,
            published_ns: ipc::monotonic_ns(),
            ..status
        };
        if let Err(error) = self.ports.publish_status(&self.status) {
            self.stats.publish_errors += 1;
            debug!("publishing the status failed: {error:#}");
        }
    }

    /// Moves the deadline one period on, on the absolute grid; a deadline missed by more than a
    /// period is skipped rather than sent late in a burst.
    fn advance_schedule(&mut self, now: Duration, period: Duration) {
        let lateness = now - self.next_command;
        self.stats.max_lateness = self.stats.max_lateness.max(lateness);
        self.next_command += period;
        while self.next_command <= now {
            self.next_command += period;
            self.stats.missed_ticks += 1;
        }
    }

    /// Sends `output` as a motion command in the link's control mode.
    fn send_motion(&mut self, output: &Output, now: Duration) {
        if self.device.is_none() {
            return;
        }
        let percent =
            |speed: f64, max: f64| units::speed_to_percent(speed, max).map_or(0, |(p, _)| p);
        let command = MotionCommand {
            control_mode: self.spec.control_mode(),
            fault_clear: output.fault_clear,
            linear_percent: percent(output.linear, MAX_LINEAR_SPEED),
            angular_percent: percent(output.angular, self.config.max_angular),
        };
        let counted = Counted {
            message: Message::MotionCommand(command),
            count: self.motion_count.next_count(),
        };
        if self.send(&counted, now) {
            self.stats.commands_sent += 1;
            self.tracker
                .handle_sent_motion(&command, ipc::monotonic_ns());
        }
    }

    fn send_lights(&mut self, now: Duration) {
        let period = self.light_period();
        self.next_light += period;
        if self.next_light <= now {
            self.next_light = now + period;
        }
        let (Some(lights), Some(_)) = (self.lights(), self.device.as_ref()) else {
            return;
        };
        let counted = Counted {
            message: Message::LightCommand(lights),
            count: self.light_count.next_count(),
        };
        if self.send(&counted, now) {
            self.tracker.handle_sent_other();
        }
    }

    /// Sends on the open device; on failure, closes it. Returns whether it was sent.
    fn send(&mut self, counted: &Counted, now: Duration) -> bool {
        let Some(device) = self.device.as_mut() else {
            return false;
        };
        match device.send(counted, now) {
            Ok(()) => true,
            Err(error) => {
                self.fail(&format!("writing: {error}"));
                false
            }
        }
    }

    /// Reads until `deadline` (or sleeps, while disconnected), handling every event.
    fn wait_for_input(&mut self, deadline: Duration) {
        let now = self.now();
        let timeout = deadline.saturating_sub(now);
        let Some(device) = self.device.as_mut() else {
            let nap = timeout.min(self.reopen_at.saturating_sub(now));
            if let Err(error) = crate::wait::wait(None, &self.ports.wake, nap) {
                debug!("waiting failed: {error}");
                std::thread::sleep(nap);
            }
            return;
        };
        let start = self.start;
        let mut events = std::mem::take(&mut self.events);
        events.clear();
        let result = device.receive(
            &mut self.buffer[..],
            timeout,
            &self.ports.wake,
            || start.elapsed(),
            |event| {
                events.push(event);
            },
        );
        let discarded = device.discarded_bytes();
        let now_ns = ipc::monotonic_ns();
        for event in &events {
            let publish = self.tracker.handle_rx(event, now_ns);
            self.publish_if(publish);
        }
        self.tracker.set_discarded_bytes(discarded);
        self.events = events;
        if let Err(error) = result {
            self.fail(&format!("reading: {error}"));
        }
    }

    /// Opens the device. Another gateway owning it at the first attempt is fatal (this one
    /// should not have started); later, it is one more reason to retry.
    fn open(&mut self, now: Duration) -> anyhow::Result<()> {
        match self.spec.open(now) {
            Err(OpenError::Owned(owned)) if !self.opened_before => return Err(owned.into()),
            Ok(device) => {
                info!("{} {} open", self.spec.kind().name(), self.spec.name());
                self.device = Some(device);
                self.backoff = FIRST_BACKOFF;
                self.last_open_error = None;
                let reconnect = self.opened_before;
                self.opened_before = true;
                let publish = self.tracker.handle_connected(reconnect);
                self.publish_if(publish);
            }
            Err(error) => {
                let message = error.to_string();
                if self.last_open_error.as_deref() != Some(message.as_str()) {
                    warn!(
                        "cannot open {} {}: {message}; retrying every {} ms at most",
                        self.spec.kind().name(),
                        self.spec.name(),
                        self.config.timing.reconnect_max_ms
                    );
                    self.last_open_error = Some(message);
                } else {
                    debug!("still cannot open {}", self.spec.name());
                }
                self.reopen_at = now + self.backoff;
                let max = Duration::from_millis(self.config.timing.reconnect_max_ms);
                self.backoff = (self.backoff * 2).min(max);
            }
        }
        Ok(())
    }

    fn fail(&mut self, what: &str) {
        if self.device.take().is_some() {
            warn!(
                "{} {}: {what}; reopening",
                self.spec.kind().name(),
                self.spec.name()
            );
        }
        self.reopen_at = self.now() + FIRST_BACKOFF;
        self.backoff = FIRST_BACKOFF * 2;
        let publish = self.tracker.handle_disconnected();
        self.publish_if(publish);
    }

    fn publish_if(&mut self, publish: Publish) {
        if publish == Publish::Yes {
            self.publish();
        }
    }

    fn publish(&mut self) {
        self.last_publish = self.now();
        let state = *self.tracker.stamp(ipc::monotonic_ns());
        if let Err(error) = self.ports.publish(&state) {
            self.stats.publish_errors += 1;
            if self.stats.publish_errors.is_power_of_two() {
                error!(
                    "publishing the state failed ({} times): {error:#}",
                    self.stats.publish_errors
                );
            }
        }
    }

    /// The link state now.
    pub fn link_state(&self) -> LinkState {
        self.tracker.link_state()
    }
}
