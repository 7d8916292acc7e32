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
use scout_interface::control::{ControlRequest, ControlResponse, StatusPayload};
use scout_interface::services::{self, Ipc, Role, monotonic};
use scout_interface::state::{LinkState, StatePayload};
use tracing::{debug, error, info, warn};

use crate::config::GatewayConfig;
use crate::core::{Core, Publication};
use crate::device::{Device, DeviceSpec, OpenError};
use crate::monitor::NodeMonitor;
use crate::wait::Ready;

/// The gateway's iceoryx2 side: the node and the ports it owns.
struct Endpoints {
    state: Publisher<Ipc, StatePayload, ()>,
    state_notifier: Notifier<Ipc>,
    status: Publisher<Ipc, StatusPayload, ()>,
    server: Server<Ipc, ControlRequest, (), ControlResponse, ()>,
    wake: Listener<Ipc>,
    // Dropped last: the ports above belong to it.
    _node: Node<Ipc>,
}

impl Endpoints {
    fn create(robot: &str) -> anyhow::Result<Self> {
        match services::remove_dead_nodes() {
            Ok(0) => {}
            Ok(removed) => {
                info!("removed the stale iceoryx2 resources of {removed} dead process(es)")
            }
            Err(error) => warn!("listing iceoryx2 nodes to clean up failed: {error:?}"),
        }
        let node = services::node(&format!("scout-gateway-{robot}"))
            .context("creating the iceoryx2 node")?;
        // The state service last: once it exists, clients find every service.
        let status = services::status_services(&node, robot, Role::Gateway)?
            .publisher_builder()
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .context("creating the status publisher")?;
        let (control, control_events) = services::control_services(&node, robot, Role::Gateway)?;
        let server = control
            .server_builder()
            .create()
            .context("creating the control server")?;
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
            server,
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
                sample
                    .write_payload(**state)
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

/// The gateway's control thread.
pub struct Driver {
    spec: DeviceSpec,
    core: Core,
    device: Option<Device>,
    endpoints: Endpoints,
    monitor: NodeMonitor,
    buffer: Box<[u8; 4096]>,
    publish_errors: u64,
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
    pub fn new(config: &GatewayConfig, spec: DeviceSpec) -> anyhow::Result<Self> {
        let endpoints = Endpoints::create(&config.name)?;
        let core = Core::new(config, spec.transport(), &spec.name(), monotonic());
        let monitor = NodeMonitor::start().context("starting the client monitor thread")?;
        Ok(Self {
            spec,
            core,
            device: None,
            endpoints,
            monitor,
            buffer: Box::new([0; 4096]),
            publish_errors: 0,
        })
    }

    /// The link state now.
    pub fn link_state(&self) -> LinkState {
        self.core.link_state()
    }

    /// Runs until `stop` is set, then sends zero speed for the configured cycles and returns.
    pub fn run(&mut self, stop: &AtomicBool) -> anyhow::Result<()> {
        let mut ready = Ready::default();
        loop {
            let now = monotonic();
            self.receive(now, ready.port);
            if stop.load(Ordering::Relaxed) {
                self.core.handle_shutdown();
            }
            self.handle_requests(now, ready.wake);
            while let Some(node) = self.monitor.try_gone() {
                self.core.handle_client_gone(now, node);
            }
            while let Some(node) = self.core.poll_new_client() {
                self.monitor.watch(node);
            }
            if self.core.poll_open(now) {
                self.open(now)?;
            }
            self.transmit(now);
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
            if self.core.is_finished() {
                break;
            }
            ready = self.wait(now, self.core.poll_timeout());
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

    /// Feeds the core what the port delivered.
    fn receive(&mut self, now: Duration, readable: bool) {
        let Some(device) = self.device.as_mut() else {
            return;
        };
        let core = &mut self.core;
        let result = device.receive(now, readable, &mut self.buffer[..], |event| {
            core.handle_rx(now, &event);
        });
        core.handle_discarded_bytes(device.discarded_bytes());
        if let Err(error) = result {
            self.device = None;
            self.core
                .handle_link_failed(now, &format!("reading: {error}"));
        }
    }

    /// Answers every waiting request.
    fn handle_requests(&mut self, now: Duration, woken: bool) {
        if woken && let Err(error) = self.endpoints.wake.try_wait(|_| {}) {
            debug!("draining the wake-up event failed: {error:?}");
        }
        loop {
            let active = match self.endpoints.server.receive() {
                Ok(Some(active)) => active,
                Ok(None) => break,
                Err(error) => {
                    warn!("receiving control requests failed: {error:?}");
                    break;
                }
            };
            let response = self.core.handle_request(now, active.payload());
            if let Err(error) = active.send_copy(response) {
                debug!("answering request {} failed: {error:?}", response.seq);
            }
        }
    }

    /// Sends every frame the core has for the port now.
    fn transmit(&mut self, now: Duration) {
        while let Some(frame) = self.core.poll_transmit(now) {
            let Some(device) = self.device.as_mut() else {
                return;
            };
            if let Err(error) = device.send(&frame, now) {
                self.device = None;
                self.core
                    .handle_link_failed(now, &format!("writing: {error}"));
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
        let result = match self.device.as_ref() {
            Some(device) => device.wait(now, deadline, &self.endpoints.wake),
            None => crate::wait::wait(None, &self.endpoints.wake, deadline.saturating_sub(now)),
        };
        result.unwrap_or_else(|error| {
            debug!("waiting failed: {error}");
            std::thread::sleep(deadline.saturating_sub(now).min(Duration::from_millis(1)));
            Ready::default()
        })
    }
}
