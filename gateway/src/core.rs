//! The gateway's sans-IO core: everything the gateway decides, with no port, no shared memory
//! and no clock. Events come in with the time they happened (`handle_*`: frames received, the
//! link opening or failing, client requests and deaths, shutdown); what to do comes out
//! (`poll_*`: frames to send, state and status to publish, when to open the port, the next
//! deadline). The driver ([`crate::driver`]) is the one piece that touches the port, iceoryx2 and
//! the clock, reading the clock once per iteration; tests drive the core on a virtual clock.
//!
//! Time is CLOCK_BOOTTIME as a [`Duration`] (the clock of every `*_ns` field).

use std::collections::{HashSet, VecDeque};
use std::time::Duration;

use scout_interface::control::{
    ControlRequest, ControlResponse, EventPayload, LightsControl, MAX_STATUS_STOPS, Rejection,
    Request, RequestKind, SourcePayload, StatusPayload, StopCause, StopPayload, UNKNOWN_UID,
};
use scout_interface::remote::REMOTE_PREFIX;
use scout_interface::robot::RobotName;
use scout_interface::services::Way;
use scout_interface::state::{BatteryLevel, ChassisPayload, LinkState, StatePayload};
use scout_interface::stop_socket;
use scout_interface::{FixedText, Transport};
use scout_protocol::link::{Outgoing, RxEvent};
use scout_protocol::sequence::RollingCounter;
use scout_protocol::units;
use scout_protocol::v2::{
    ControlModeV2, ErrorClearV2, LightsV2, MessageV2, MotionModeStateV2, MotionModeV2, MotionV2,
    SystemStateV2, VersionRequestForm,
};
use scout_protocol::version::Protocol;
use scout_protocol::{
    ChassisState, ControlMode, Counted, FaultClear, LightCommand, Message, MotionCommand, Severity,
    SystemStatus,
};
use tracing::{debug, info, warn};

use crate::arbiter::{
    Accepted, Answer, Arbiter, Caps, LightsSetting, Origin, Output, Sideways, Turning,
};
use crate::brake::ParkingBrake;
use crate::command_mode::CommandMode;
use crate::config::{GatewayConfig, OnCritical, SafetyConfig};
use crate::modes::Handshake;
use crate::state::{PortCounters, Publish, StateTracker};
use scout_protocol::model::{FourWheel, Model};

/// The state is published at least this often, frames or not: a subscriber sees that the
/// gateway lives while the chassis is silent, and a late subscriber gets the latest state fast.
pub const STATE_HEARTBEAT: Duration = Duration::from_millis(100);

/// The status is published at least this often, changes or not.
pub const STATUS_HEARTBEAT: Duration = Duration::from_secs(1);

/// The first wait before reopening a failed port; it doubles up to `reconnect_max_ms`.
pub const FIRST_BACKOFF: Duration = Duration::from_millis(50);

/// The chassis stops after this long without a valid motion command: feedback silent for
/// longer is a gap.
pub const CHASSIS_TIMEOUT: Duration = Duration::from_millis(500);

/// The longest time between two motion commands written to the port before the gateway
/// assumes the chassis may have timed out, and latches an `overrun` stop. The chassis counts
/// its 500 ms from the last frame it *received*; 100 ms of margin covers what lies between our
/// write and its count: the adapter's and kernel's queues (an slcan adapter's USB frames, a
/// CAN qdisc), the frame's time on the wire, and the chassis checking its timeout on its own
/// control cycle, whose phase we do not know. A stall shorter than this resumes; a longer one
/// stops the robot until a release and a new take.
pub const WIRE_GAP_LIMIT: Duration = Duration::from_millis(400);

/// The chassis reports its motion this often (v1 0x131, v2 0x221): the time each report
/// stands for when its reports are counted against the gateway's clock ([`ChassisClock`]).
pub const MOTION_REPORT_PERIOD: Duration = Duration::from_millis(20);

/// How long after a port opens its reports are not yet counted against the gateway's clock:
/// what the port held from before (a tty's buffer) arrives at once, and is no pause.
pub const REPORTS_SETTLE: Duration = Duration::from_secs(1);

/// How the previous gateway of this robot ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// It exited cleanly (or there was none): autonomy disarmed, no stop.
    Clean,
    /// It crashed or was killed: a `gateway_start` stop holds until released.
    AfterUncleanExit,
}

/// Something to publish, borrowed from the core (the payloads are copied once, into shared
/// memory).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Publication<'a> {
    /// The chassis state, stamped with its sequence number and time.
    State(&'a StatePayload),
    /// The arbiter's status, stamped.
    Status(&'a StatusPayload),
}

/// The port, as far as the core knows.
#[derive(Debug, Clone, PartialEq)]
enum Link {
    /// Open: frames go out.
    Open,
    /// Closed or never opened: open again at `reopen_at`.
    Closed {
        reopen_at: Duration,
        backoff: Duration,
        last_error: Option<String>,
    },
}

/// How the core is doing, for the log at exit and the benchmarks.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct CoreStats {
    /// Motion commands handed to the port.
    pub commands_sent: u64,
    /// Ticks whose deadline had passed by more than a period (skipped to stay on the grid).
    pub missed_ticks: u64,
    /// The latest a tick was handled after its deadline.
    pub max_lateness: Duration,
    /// Requests handled.
    pub requests: u64,
    /// Stops sent at once, out of the 20 ms schedule.
    pub urgent_stops: u64,
}

/// The gateway's decisions.
#[derive(Debug)]
pub struct Core {
    robot: RobotName,
    transport: Transport,
    max_linear: f64,
    max_angular: f64,
    /// The model driven by: whether it moves sideways.
    model: Model,
    /// The protocol the arbiter was last told the chassis moves sideways in (or not).
    sideways_for: Option<Option<Protocol>>,
    /// A Ranger's motion mode: what it reports, what was asked, whether it stands still.
    handshake: Handshake,
    /// A Hunter's parking brake: what it reports, what was asked, whether it stands still.
    brake: ParkingBrake,
    period: Duration,
    light_period: Duration,
    stop_cycles: u32,
    reconnect_max: Duration,
    tracker: StateTracker,
    arbiter: Arbiter,
    link: Link,
    opened_before: bool,
    motion_count: RollingCounter,
    light_count: RollingCounter,
    next_command: Duration,
    next_light: Duration,
    state_due: bool,
    last_state: Option<Duration>,
    status_due: bool,
    status: StatusPayload,
    last_status: Option<Duration>,
    /// Zero-speed cycles left before exit, once shutdown began.
    shutdown: Option<u32>,
    watched: HashSet<u128>,
    new_clients: Vec<u128>,
    stats: CoreStats,
    opened_at: Duration,
    last_lateness: Duration,
    safety: SafetyConfig,
    runaway: Runaway,
    chassis_clock: ChassisClock,
    /// When the last motion command was handed to the open port.
    last_motion_written: Option<Duration>,
    /// A protocol v2 chassis' command mode (0x421, 0x211).
    command_mode: CommandMode,
    /// Whether this port session asked a v2 chassis for its firmware versions.
    version_asked: bool,
    /// Frames that follow the one just handed out (v2's error clear after its motion
    /// command, standby after the last zero, the second version request).
    follow_up: VecDeque<Outgoing>,
    /// What a critical battery does.
    on_critical: OnCritical,
    /// The battery level last acted on.
    battery_level: BatteryLevel,
    /// Why the black box is to be saved, oldest first (a stop, a client's request).
    black_box_due: VecDeque<String>,
    /// The newest stop the black box was told of.
    black_box_stop_seen: u64,
    /// Whether there is a black box (`[blackbox] minutes` > 0).
    black_box_on: bool,
}

/// The chassis' own time, told by its motion reports (one every [`MOTION_REPORT_PERIOD`]),
/// against the gateway's clock. Reports that stand for more time than the gateway's clock
/// moved were sent while that clock stood still: a paused VM whose clocks were restored, a
/// restored checkpoint, every clock of the host held back. Such a pause hides from the wire-gap
/// check (no time passed, as far as the host can tell) while the chassis timed out and braked.
#[derive(Debug, Clone, Copy, Default)]
struct ChassisClock {
    /// How far the reports run ahead of the gateway's clock: a leaky bucket that fills one
    /// period per report and drains at the gateway's pace.
    lead: Duration,
    /// The last report's arrival.
    last: Option<Duration>,
    /// Host time that passed, in the last gap between reports, beyond what the reports stood
    /// for: reports read at once right after (the backlog of a gateway that was starved of the
    /// CPU, while the clock moved) spend it rather than count as ahead. Each gap replaces it.
    credit: Duration,
}

impl ChassisClock {
    /// A motion report at `now`: how far the chassis' reports now run ahead.
    fn handle_report(&mut self, now: Duration) -> Duration {
        let drained = self
            .last
            .map_or(Duration::ZERO, |last| now.saturating_sub(last));
        let ahead = self.lead + MOTION_REPORT_PERIOD;
        if drained > ahead {
            self.credit = drained - ahead;
            self.lead = Duration::ZERO;
        } else {
            let extra = ahead - drained;
            let spent = extra.min(self.credit);
            self.credit -= spent;
            self.lead = extra - spent;
        }
        self.last = Some(now);
        self.lead
    }
}

/// Watching the chassis move or turn faster than commanded.
#[derive(Debug, Clone, Copy, Default)]
struct Runaway {
    linear: Envelope,
    /// Sideways, by the forward tolerance and braking.
    lateral: Envelope,
    angular: Envelope,
    /// When the feedback left an envelope.
    since: Option<Duration>,
    last: Option<Duration>,
}

/// How fast one axis may still be going, braking since its command dropped.
#[derive(Debug, Clone, Copy, Default)]
struct Envelope {
    limit: f64,
}

impl Envelope {
    /// Follows the command for `dt` s of braking at `braking`; whether `actual` is outside by
    /// more than `tolerance`, or goes the wrong way.
    fn outside(
        &mut self,
        command: f64,
        actual: f64,
        braking: f64,
        tolerance: f64,
        dt: f64,
    ) -> bool {
        self.limit = command.abs().max(self.limit - braking * dt);
        actual.abs() > self.limit + tolerance
            || (actual * command < 0.0 && actual.abs() > tolerance)
    }
}

impl Core {
    /// The core for `config`, talking to `device` over `transport`, starting at `now` after a
    /// `start`; `instance` tells this gateway's leases from another's.
    pub fn new(
        config: &GatewayConfig,
        transport: Transport,
        device: &str,
        now: Duration,
        start: Start,
        instance: u32,
    ) -> Self {
        let timing = &config.timing;
        let light_period_ms = match transport {
            Transport::Serial => timing.serial_light_period_ms,
            Transport::Slcan | Transport::Can | Transport::GsUsb | Transport::Sim => {
                timing.can_light_period_ms
            }
        };
        let mut chassis = ChassisPayload::new(config.limits_model(), config.max_angular());
        if config.model.is_none() {
            chassis.model = 0;
        }
        let fixed = config.fixed_protocol();
        Self {
            robot: config.name.clone(),
            transport,
            max_linear: config.max_linear(),
            max_angular: config.max_angular(),
            model: config.limits_model(),
            sideways_for: None,
            handshake: Handshake::default(),
            brake: ParkingBrake::default(),
            period: config.command_period(),
            light_period: Duration::from_millis(light_period_ms),
            stop_cycles: timing.stop_cycles,
            reconnect_max: Duration::from_millis(timing.reconnect_max_ms),
            tracker: StateTracker::new(&config.name, transport, device, fixed, chassis)
                .with_calibration(config.odometry)
                .with_battery(config.battery.clone()),
            arbiter: Self::new_arbiter(config, now, start, instance),
            link: Link::Closed {
                reopen_at: now,
                backoff: FIRST_BACKOFF,
                last_error: None,
            },
            opened_before: false,
            motion_count: RollingCounter::default(),
            light_count: RollingCounter::default(),
            next_command: now,
            next_light: now,
            state_due: true,
            last_state: None,
            status_due: true,
            status: StatusPayload::default(),
            last_status: None,
            shutdown: None,
            watched: HashSet::new(),
            new_clients: Vec::new(),
            stats: CoreStats::default(),
            opened_at: now,
            last_lateness: Duration::ZERO,
            safety: config.safety.clone(),
            runaway: Runaway::default(),
            chassis_clock: ChassisClock::default(),
            last_motion_written: None,
            command_mode: CommandMode::new(),
            version_asked: false,
            follow_up: VecDeque::new(),
            on_critical: config.battery.on_critical,
            battery_level: BatteryLevel::Unknown,
            black_box_due: VecDeque::new(),
            black_box_stop_seen: 0,
            black_box_on: config.blackbox.enabled(),
        }
    }

    /// Why the black box is to be saved now, if it is: a stop that latched (all but the start
    /// after an unclean exit, which holds nothing of this run yet), or a client asked.
    pub fn poll_black_box(&mut self) -> Option<String> {
        let newest = self.arbiter.newest_stop();
        if newest > self.black_box_stop_seen && self.black_box_on {
            let seen = self.black_box_stop_seen;
            self.black_box_stop_seen = newest;
            for stop in self.arbiter.stops() {
                if stop.id > seen && stop.cause != StopCause::GatewayStart {
                    self.black_box_due.push_back(format!(
                        "stop #{} by {} ({}): {}",
                        stop.id,
                        stop.owner,
                        stop.cause.name(),
                        stop.reason
                    ));
                }
            }
        }
        self.black_box_due.pop_front()
    }

    /// Acts on a change of the battery's level as configured: at critical, autonomy may be
    /// barred from taking control and its control ended; above it, the bar lifts (nothing
    /// restarts). Never touches a teleop.
    fn observe_battery(&mut self, now: Duration) {
        let battery = self.tracker.state().battery;
        let level = battery.level();
        if level == self.battery_level {
            return;
        }
        self.battery_level = level;
        self.status_due = true;
        let critical = level == BatteryLevel::Critical;
        let why = crate::battery::describe(&battery);
        match self.on_critical {
            OnCritical::Warn => {}
            OnCritical::RefuseAutonomy => {
                self.arbiter
                    .bar_autonomy(now, critical.then(|| why.clone()));
            }
            OnCritical::StopAutonomy => {
                self.arbiter
                    .bar_autonomy(now, critical.then(|| why.clone()));
                if critical {
                    self.arbiter.end_autonomy(now, &why);
                }
            }
        }
    }

    fn new_arbiter(config: &GatewayConfig, now: Duration, start: Start, instance: u32) -> Arbiter {
        let global = Caps {
            linear: config.max_linear(),
            angular: config.max_angular(),
            lateral: Some(config.max_lateral()),
        };
        let mut arbiter = Arbiter::new(config.arbiter.clone(), global, instance);
        arbiter.set_sideways(sideways(config.limits_model(), config.fixed_protocol()));
        arbiter.set_turning(turning(config.limits_model()));
        match start {
            Start::Clean => {}
            Start::AfterUncleanExit => arbiter.handle_gap(
                now,
                StopCause::GatewayStart,
                "the previous gateway exited uncleanly (crash or kill): check the robot, then release",
                false,
            ),
        }
        arbiter
    }

    /// Raises a gap when `cause` appears, and lets its stop be released when it goes.
    fn set_condition(&mut self, now: Duration, cause: StopCause, present: bool, detail: &str) {
        if present == self.arbiter.present(cause) {
            return;
        }
        if present {
            self.arbiter.handle_gap(now, cause, detail, true);
        } else {
            self.arbiter.handle_gap_cleared(now, cause);
        }
        self.status_due = true;
    }

    /// The chassis' own state, in either protocol: e-stop, faults and RC are gaps while they
    /// last. `faults` are the set bits' names and severities.
    fn observe_chassis(
        &mut self,
        now: Duration,
        state: ChassisState,
        faults: impl Iterator<Item = (&'static str, Severity)>,
        rc: bool,
    ) {
        let estop = state == ChassisState::EStop;
        self.set_condition(
            now,
            StopCause::ChassisEstop,
            estop,
            "the chassis is in e-stop",
        );
        let abnormal = match state {
            ChassisState::Normal | ChassisState::EStop => None,
            ChassisState::Exception | ChassisState::Unknown(_) => Some(state.name()),
        };
        let faults: Vec<&str> = faults
            .filter(|(_, severity)| matches!(severity, Severity::Fault | Severity::Protection))
            .map(|(name, _)| name)
            .chain(abnormal)
            .collect();
        let detail = format!("the chassis reports {}", faults.join(", "));
        self.set_condition(now, StopCause::ChassisFault, !faults.is_empty(), &detail);
        self.set_condition(
            now,
            StopCause::RcOverride,
            rc,
            "the RC transmitter took over",
        );
    }

    /// A v1 system status (0x151).
    fn observe_system(&mut self, now: Duration, status: &SystemStatus) {
        let faults = status.faults.iter().map(|f| (f.name(), f.severity()));
        let rc = status.control_mode == ControlMode::Rc;
        self.observe_chassis(now, status.state, faults, rc);
    }

    /// A v2 system state (0x211): as v1's, plus the command mode the gateway took.
    fn observe_system_v2(&mut self, now: Duration, system: &SystemStateV2) {
        let rc = system.control_mode == ControlModeV2::Rc;
        self.observe_chassis(now, system.state, system.errors.faults(), rc);
        if let Some(lost) = self.command_mode.handle_reported(system.control_mode, now) {
            warn!("{}", lost.detail);
            self.arbiter
                .handle_gap(now, StopCause::ChassisMode, &lost.reason, false);
            self.status_due = true;
        }
        if self.model.parking_brake() {
            self.observe_brake(now, system);
        }
    }

    /// A Hunter's 0x211 byte 6: the arbiter drives only once the chassis reports its brake
    /// released; locked unasked during a drive latches a stop.
    fn observe_brake(&mut self, now: Duration, system: &SystemStateV2) {
        let brake = system.brake();
        if self.brake.reported() != Some(brake) {
            info!("the chassis' parking brake is {brake} (0x211 byte 6)");
            self.status_due = true;
        }
        let commanded = system.control_mode == ControlModeV2::Can;
        if let Some(why) = self.brake.handle_report(now, brake, commanded) {
            warn!("{why}");
            self.arbiter
                .handle_gap(now, StopCause::ChassisMode, &why, false);
        }
        self.arbiter.set_held(!self.brake.released(now));
    }

    /// A motion report at `now`: reports that stand for more time than the gateway's clock
    /// moved, by more than [`WIRE_GAP_LIMIT`], show a pause of the host's clocks (the chassis
    /// may have braked by its timeout meanwhile): an `overrun`, as a stall the clock saw is.
    fn observe_report(&mut self, now: Duration) {
        if now.saturating_sub(self.opened_at) < REPORTS_SETTLE {
            self.chassis_clock = ChassisClock::default();
            return;
        }
        let lead = self.chassis_clock.handle_report(now);
        if lead > WIRE_GAP_LIMIT {
            let detail = format!(
                "the chassis reported {} ms of motion faster than this host's clock moved: the \
                 host's clocks stood still (a paused VM, a restored checkpoint), and the chassis \
                 may have stopped by its {} ms timeout",
                lead.as_millis(),
                CHASSIS_TIMEOUT.as_millis()
            );
            warn!("{detail}");
            self.arbiter
                .handle_gap(now, StopCause::Overrun, &detail, false);
            self.status_due = true;
            self.chassis_clock = ChassisClock::default();
        }
    }

    /// The chassis moving or turning faster than commanded (beyond what braking explains), or
    /// the wrong way, for longer than the configured time, is a runaway.
    fn observe_motion(&mut self, now: Duration, (linear, lateral, angular): (f64, f64, f64)) {
        let quiet = [
            StopCause::ChassisEstop,
            StopCause::RcOverride,
            StopCause::ChassisFault,
        ]
        .iter()
        .any(|cause| self.arbiter.present(*cause));
        let command = self.tracker.state().command;
        let dt = self
            .runaway
            .last
            .map_or(0.0, |last| now.saturating_sub(last).as_secs_f64().min(0.1));
        self.runaway.last = Some(now);
        let safety = &self.safety;
        let linear_away = self.runaway.linear.outside(
            command.linear,
            linear,
            safety.runaway_braking,
            safety.runaway_tolerance,
            dt,
        );
        let lateral_away = self.runaway.lateral.outside(
            command.lateral,
            lateral,
            safety.runaway_braking,
            safety.runaway_tolerance,
            dt,
        );
        let angular_away = self.runaway.angular.outside(
            command.angular,
            angular,
            safety.runaway_angular_braking,
            safety.runaway_angular_tolerance,
            dt,
        );
        if quiet || !(linear_away || lateral_away || angular_away) {
            self.runaway.since = None;
            return;
        }
        let since = *self.runaway.since.get_or_insert(now);
        if now - since >= Duration::from_millis(safety.runaway_time_ms) {
            let detail = if lateral_away {
                format!(
                    "the chassis moves sideways at {lateral:.2} m/s against a command of {:.2} m/s",
                    command.lateral
                )
            } else {
                format!(
                    "the chassis moves at {linear:.2} m/s, {angular:.2} rad/s against a command \
                     of {:.2} m/s, {:.2} rad/s",
                    command.linear, command.angular
                )
            };
            self.arbiter
                .handle_gap(now, StopCause::Runaway, &detail, false);
            self.runaway.since = None;
            self.status_due = true;
        }
    }

    /// The link state now.
    pub fn link_state(&self) -> LinkState {
        self.tracker.link_state()
    }

    /// The protocol spoken on the current port: the fixed one, or the detected one.
    pub fn link_protocol(&self) -> Option<Protocol> {
        self.tracker.protocol()
    }

    /// How the core is doing.
    pub fn stats(&self) -> CoreStats {
        self.stats
    }

    /// The arbiter, for inspection.
    pub fn arbiter(&self) -> &Arbiter {
        &self.arbiter
    }

    /// Whether the port was ever open (a first open refused is fatal, a later one is retried).
    pub fn has_opened(&self) -> bool {
        self.opened_before
    }

    /// Whether the driver should try to open the port now.
    pub fn poll_open(&self, now: Duration) -> bool {
        matches!(self.link, Link::Closed { reopen_at, .. } if now >= reopen_at)
            && self.shutdown.is_none()
    }

    /// The port opened.
    pub fn handle_opened(&mut self, now: Duration) {
        info!("{} {} open", self.transport, self.device());
        self.link = Link::Open;
        self.opened_at = now;
        self.chassis_clock = ChassisClock::default();
        // A new port: the time it was closed is the link's gap, not the wire's.
        self.last_motion_written = None;
        // Perhaps another chassis, or the same one after a power cycle: nothing held, nothing
        // asked.
        self.command_mode.reset();
        self.version_asked = false;
        self.follow_up.clear();
        self.handshake.reset();
        self.arbiter.set_motion_mode(None, false);
        self.brake.reset();
        self.arbiter.set_held(self.model.parking_brake());
        let reconnect = std::mem::replace(&mut self.opened_before, true);
        let publish = self.tracker.handle_connected(now, reconnect);
        self.publish_if(publish);
        self.next_command = self.next_command.max(now);
    }

    /// Opening the port failed with `error`: try again after the backoff.
    pub fn handle_open_failed(&mut self, now: Duration, error: &str) {
        let Link::Closed {
            reopen_at,
            backoff,
            last_error,
        } = &mut self.link
        else {
            return;
        };
        if last_error.as_deref() == Some(error) {
            debug!(
                "still cannot open {}",
                self.tracker.state().link.device.as_str()
            );
        } else {
            warn!(
                "cannot open {} {}: {error}; retrying every {:?} at most",
                self.transport,
                self.tracker.state().link.device.as_str(),
                self.reconnect_max
            );
            *last_error = Some(error.to_owned());
        }
        *reopen_at = now + *backoff;
        *backoff = (*backoff * 2).min(self.reconnect_max);
    }

    /// The port failed (`what`: reading or writing, and why): it is closed and reopened soon.
    pub fn handle_link_failed(&mut self, now: Duration, what: &str) {
        self.close(now, StopCause::LinkLost, what);
    }

    /// The CAN bus or adapter failed (a write refused for a full buffer, bus-off,
    /// error-passive): the port is closed, dropping what was queued, and reopened soon.
    pub fn handle_link_fault(&mut self, now: Duration, what: &str) {
        self.close(now, StopCause::LinkFault, what);
    }

    fn close(&mut self, now: Duration, cause: StopCause, what: &str) {
        if self.link == Link::Open {
            warn!("{} {}: {what}; reopening", self.transport, self.device());
            let detail = format!("{} {}: {what}", self.transport, self.device());
            self.set_condition(now, cause, true, &detail);
        }
        self.link = Link::Closed {
            reopen_at: now + FIRST_BACKOFF,
            backoff: FIRST_BACKOFF * 2,
            last_error: None,
        };
        let publish = self.tracker.handle_disconnected();
        self.publish_if(publish);
    }

    /// Something arrived from the port.
    pub fn handle_rx(&mut self, now: Duration, event: &RxEvent) {
        if let RxEvent::V2(MessageV2::MotionState(motion)) = event {
            if self.model.four_wheel().is_some() {
                self.handshake.handle_motion_state(now, motion);
            }
            if self.model.parking_brake() {
                self.brake.handle_motion_state(now, motion);
            }
        }
        let driven = as_driven(self.model, self.handshake.reported(), event);
        let event = driven.as_ref().unwrap_or(event);
        let publish = self.tracker.handle_rx(event, now);
        self.publish_if(publish);
        if publish == Publish::No || self.tracker.link_state() != LinkState::Ok {
            return;
        }
        for cause in [
            StopCause::LinkLost,
            StopCause::LinkFault,
            StopCause::ChassisSilent,
        ] {
            self.set_condition(now, cause, false, "");
        }
        self.observe_battery(now);
        match event {
            RxEvent::Message(counted) => match &counted.message {
                Message::SystemStatus(status) => self.observe_system(now, status),
                Message::MotionFeedback(motion) => {
                    self.observe_report(now);
                    self.observe_motion(now, (motion.linear(), 0.0, motion.angular()));
                }
                Message::MotorFeedback(_)
                | Message::LightFeedback(_)
                | Message::MotionCommand(_)
                | Message::LightCommand(_) => {}
            },
            RxEvent::V2(message) => match message {
                MessageV2::SystemState(system) => self.observe_system_v2(now, system),
                MessageV2::MotionState(motion) => {
                    self.observe_report(now);
                    let rates = (motion.linear(), motion.lateral(), motion.angular());
                    self.observe_motion(now, rates);
                }
                MessageV2::MotionModeState(mode) => self.observe_motion_mode(now, *mode),
                MessageV2::MotionCommand(_)
                | MessageV2::LightCommand(_)
                | MessageV2::ControlMode(_)
                | MessageV2::ErrorClear(_)
                | MessageV2::VersionRequest(_)
                | MessageV2::LightState(_)
                | MessageV2::RcState(_)
                | MessageV2::ActuatorHigh(_)
                | MessageV2::ActuatorLow(_)
                | MessageV2::SetMotionMode(_)
                | MessageV2::Brake(_)
                | MessageV2::MotorAngles(_)
                | MessageV2::MotorSpeeds(_)
                | MessageV2::Odometer(_)
                | MessageV2::Version(_)
                | MessageV2::VersionText(_)
                | MessageV2::Bms(_)
                | MessageV2::BmsAlarm(_) => {}
            },
            RxEvent::Rejected(_) | RxEvent::Slcan(_) => {}
        }
    }

    /// A Ranger's 0x291: the arbiter drives only in the mode it reports settled, nothing while
    /// it changes; a mode it takes unasked latches a stop.
    fn observe_motion_mode(&mut self, now: Duration, mode: MotionModeStateV2) {
        if self.model.four_wheel().is_none() {
            return;
        }
        if self.handshake.is_news(&mode) {
            match mode.settled() {
                Some(settled) => info!("the chassis is in {settled} mode"),
                None => info!("the chassis is changing to {} mode", mode.mode),
            }
            self.status_due = true;
        }
        if let Some(why) = self.handshake.handle_report(now, mode) {
            warn!("{why}");
            self.arbiter
                .handle_gap(now, StopCause::ChassisMode, &why, false);
        }
        self.arbiter
            .set_motion_mode(self.handshake.settled(now), self.handshake.may_leave());
    }

    /// What the current port has counted since it opened: bytes the stream decoder threw
    /// away, frames the kernel dropped.
    pub fn handle_port_counters(&mut self, port: PortCounters) {
        self.tracker.set_port_counters(port);
    }

    /// A client's request, from `origin` (as the transport tells) on request service `way`;
    /// every request gets an answer, and a stop is never refused.
    pub fn handle_request(
        &mut self,
        now: Duration,
        origin: &Origin,
        way: Way,
        wire: &ControlRequest,
    ) -> ControlResponse {
        // One copy out of the client's shared memory, which it can still write: every check
        // below reads the copy.
        let wire = *wire;
        self.stats.requests += 1;
        self.status_due = true;
        if self.watched.insert(origin.key.node) {
            self.new_clients.push(origin.key.node);
        }
        let origin = &speaking_for(origin, &wire);
        let client = &origin.key;
        let decoded = match (way, RequestKind::from_raw(wire.kind)) {
            (Way::Stop, Some(RequestKind::Stop | RequestKind::Release)) | (Way::Control, _) => {
                Request::decode(&wire)
            }
            (Way::Stop, _) => Err(Rejection::Malformed(
                "the stop service takes stops and releases only: send the rest on the control \
                 service"
                    .into(),
            )),
        };
        let sent = Duration::from_nanos(wire.sent_ns);
        let answer = match decoded {
            Ok(Request::SaveBlackBox) if !self.black_box_on => {
                let rejection = Rejection::NotAllowed {
                    why: "this gateway keeps no black box ([blackbox] minutes = 0)".into(),
                };
                self.arbiter.count_rejection(&rejection);
                Err(rejection)
            }
            Ok(request) => {
                let reset_odometry = request == Request::ResetOdometry;
                let save_black_box = request == Request::SaveBlackBox;
                let answer = self.arbiter.handle_request(now, origin, request, sent);
                if save_black_box && answer.is_ok() {
                    info!("black box save asked by {}", client.name);
                    self.black_box_due
                        .push_back(format!("asked by {}", client.name));
                }
                if reset_odometry && answer.is_ok() {
                    info!("odometry reset by {}", client.name);
                    let publish = self.tracker.reset_odometry();
                    self.publish_if(publish);
                }
                answer
            }
            Err(rejection) => {
                self.arbiter.count_rejection(&rejection);
                Err(rejection)
            }
        };
        if let Err(rejection) = &answer {
            debug!("rejected {} from {}: {rejection}", wire.kind, client.name);
        }
        ControlResponse::new(wire.seq, &answer)
    }

    /// A datagram on the stop endpoint, from `origin` (named by the datagram, identified by
    /// the kernel's credentials): a stop, a release, or a ping that changes nothing. Such a
    /// sender holds no slot and is not watched: stops and releases need neither.
    pub fn handle_stop_datagram(
        &mut self,
        now: Duration,
        origin: &Origin,
        ask: &stop_socket::Ask,
    ) -> Answer {
        // A ping changes nothing; its answer names the newest stop, so that a client without
        // shared memory (no status to read) can still release what it saw.
        let Some(request) = ask.request() else {
            return Ok(Accepted {
                stop: Some(self.arbiter.newest_stop()).filter(|id| *id != 0),
                ..Accepted::default()
            });
        };
        self.stats.requests += 1;
        self.status_due = true;
        let answer = self.arbiter.handle_request(now, origin, request, now);
        if let Err(rejection) = &answer {
            debug!("rejected a datagram from {}: {rejection}", origin.key.name);
        }
        answer
    }

    /// Counts a datagram on the stop endpoint that was refused before the arbiter.
    pub fn count_datagram_rejection(&mut self, rejection: &Rejection) {
        self.arbiter.count_rejection(rejection);
        self.status_due = true;
    }

    /// A client process died.
    pub fn handle_client_gone(&mut self, now: Duration, node: u128) {
        self.watched.remove(&node);
        self.arbiter.handle_node_gone(now, node);
        self.status_due = true;
    }

    /// Ctrl-C or SIGTERM: send zero speed for the configured cycles, then finish.
    pub fn handle_shutdown(&mut self) {
        if self.shutdown.is_none() {
            info!(
                "stopping: sending zero speed for {} more cycles",
                self.stop_cycles
            );
            self.shutdown = Some(self.stop_cycles);
        }
    }

    /// Whether shutdown is complete: the zero cycles (and on v2 the standby after them) went
    /// out, or there is no port to send on, or no protocol to send in.
    pub fn is_finished(&self) -> bool {
        match self.shutdown {
            None => false,
            Some(left) => {
                (left == 0 && self.follow_up.is_empty())
                    || self.link != Link::Open
                    || self.tracker.protocol().is_none()
            }
        }
    }

    /// A client process the driver should watch for death.
    pub fn poll_new_client(&mut self) -> Option<u128> {
        self.new_clients.pop()
    }

    /// The next frame to send now, if any: a stop at once, the motion command when its tick is
    /// due, the light command when its period is due; on protocol v2 also the command mode
    /// (0x421) when a client is about to drive, the error clear, the version request and
    /// standby at exit. Call until `None`; a frame that fails to go out is reported with
    /// [`Core::handle_link_failed`].
    pub fn poll_transmit(&mut self, now: Duration) -> Option<Outgoing> {
        self.check_wire_gap(now);
        if self.link != Link::Open {
            self.follow_up.clear();
        }
        if let Some(frame) = self.follow_up.pop_front() {
            self.tracker.handle_sent_other();
            return Some(frame);
        }
        if self.arbiter.take_urgent_stop() {
            self.stats.urgent_stops += 1;
            if let Some(frame) = self.motion(&Output::STOP, now) {
                // Subscribers (a safety monitor) see the stop on the wire at once.
                self.state_due = true;
                return Some(frame);
            }
        }
        if let Some(frame) = self.poll_command_mode(now) {
            return Some(frame);
        }
        if now >= self.next_command {
            self.check_silence(now);
            // A gap found at this tick stops this very frame, not the next one.
            self.advance_schedule(now);
            let output = match self.shutdown.as_mut() {
                Some(left) => {
                    *left = left.saturating_sub(1);
                    Output::STOP
                }
                None => {
                    self.update_sideways();
                    if self.model.four_wheel().is_some() {
                        self.arbiter.set_motion_mode(
                            self.handshake.settled(now),
                            self.handshake.may_leave(),
                        );
                    }
                    if self.model.parking_brake() {
                        self.arbiter.set_held(!self.brake.released(now));
                    }
                    self.arbiter.poll_output(now, self.period)
                }
            };
            self.status_due = true;
            if let Some(frame) = self.motion(&output, now) {
                if let Outgoing::V2(_) = frame {
                    self.follow_up_v2(&output, now);
                }
                return Some(frame);
            }
        }
        if let Some(frame) = self.poll_version_request() {
            return Some(frame);
        }
        if let Some(lights) = self.lights()
            && now >= self.next_light
        {
            self.next_light += self.light_period;
            if self.next_light <= now {
                self.next_light = now + self.light_period;
            }
            if self.link == Link::Open
                && let Some(protocol) = self.tracker.protocol()
            {
                self.tracker.handle_sent_other();
                let count = self.light_count.next_count();
                return Some(match protocol {
                    Protocol::V1 => Outgoing::V1(Counted {
                        message: Message::LightCommand(lights),
                        count,
                    }),
                    Protocol::V2 => Outgoing::V2(MessageV2::LightCommand(LightsV2 {
                        host_control: u8::from(lights.enabled),
                        front_mode: lights.front.mode,
                        front_brightness: lights.front.brightness,
                        rear_mode: lights.rear.mode,
                        rear_brightness: lights.rear.brightness,
                        reserved: [0; 2],
                        count,
                    })),
                });
            }
        }
        None
    }

    /// Protocol v2: 0x421 `[01]` when a client is about to drive and the chassis is not in CAN
    /// mode at the gateway's request; a take the chassis does not answer latches a stop.
    fn poll_command_mode(&mut self, now: Duration) -> Option<Outgoing> {
        if self.link != Link::Open
            || self.shutdown.is_some()
            || self.tracker.protocol() != Some(Protocol::V2)
        {
            return None;
        }
        let wanted = self.arbiter.selected(now).is_some();
        match self.command_mode.poll(now, wanted) {
            Ok(true) => {
                info!("taking the chassis' CAN command mode (0x421 [01])");
                self.tracker.handle_sent_other();
                Some(Outgoing::V2(MessageV2::ControlMode(ControlModeV2::Can)))
            }
            Ok(false) => None,
            Err(lost) => {
                warn!("{}", lost.detail);
                self.arbiter
                    .handle_gap(now, StopCause::ChassisMode, &lost.reason, false);
                self.status_due = true;
                None
            }
        }
    }

    /// Protocol v2: what follows a motion command in the same tick (the error clear the
    /// output asks for; standby after the last zero at exit).
    fn follow_up_v2(&mut self, output: &Output, now: Duration) {
        if let Some(code) = error_clear_v2(output.fault_clear) {
            self.follow_up
                .push_back(Outgoing::V2(MessageV2::ErrorClear(code)));
        }
        // A Ranger asked for another mode: only standing still, not while it changes; nothing
        // moves until it has taken it.
        let velocity = (output.linear, output.lateral, output.angular);
        if self.model.four_wheel().is_some()
            && let Some(wanted) = self.handshake.poll_request(now, output.mode, velocity)
        {
            debug!("asking the chassis for {wanted} mode (0x141)");
            self.follow_up
                .push_back(Outgoing::V2(MessageV2::SetMotionMode(wanted)));
        }
        // A Hunter's brake: released for a client's drive, locked once idle standing still.
        if self.model.parking_brake() {
            if let Some(why) = self.brake.poll_unanswered(now) {
                warn!("{why}");
            }
            if let Some(brake) = self.brake.poll_request(now, output.drive, velocity) {
                debug!("asking the chassis for its parking brake {brake} (0x131)");
                self.follow_up
                    .push_back(Outgoing::V2(MessageV2::Brake(brake)));
            }
        }
        if self.shutdown == Some(0) {
            info!("leaving the chassis in standby (0x421 [00])");
            self.follow_up
                .push_back(Outgoing::V2(MessageV2::ControlMode(ControlModeV2::Standby)));
        }
    }

    /// Protocol v2: both forms of the version request, once a port session, when the chassis
    /// has spoken (its answer lands in the state's `firmware`).
    fn poll_version_request(&mut self) -> Option<Outgoing> {
        if self.version_asked
            || self.link != Link::Open
            || self.shutdown.is_some()
            || self.tracker.protocol() != Some(Protocol::V2)
            || !self.tracker.state().system.received.valid
        {
            return None;
        }
        self.version_asked = true;
        self.tracker.handle_version_requested();
        self.tracker.handle_sent_other();
        self.follow_up
            .push_back(Outgoing::V2(MessageV2::VersionRequest(
                VersionRequestForm::Text,
            )));
        Some(Outgoing::V2(MessageV2::VersionRequest(
            VersionRequestForm::Binary,
        )))
    }

    /// The next state or status to publish now, if any. Call until `None`.
    pub fn poll_publish(&mut self, now: Duration) -> Option<Publication<'_>> {
        let publish = self.tracker.poll(now);
        self.publish_if(publish);
        let heartbeat = self
            .last_state
            .is_none_or(|last| now.saturating_sub(last) >= STATE_HEARTBEAT);
        if self.state_due || heartbeat {
            self.state_due = false;
            self.last_state = Some(now);
            return Some(Publication::State(self.tracker.stamp(now)));
        }
        if std::mem::take(&mut self.status_due) {
            let status = self.status(now);
            let heartbeat = self
                .last_status
                .is_none_or(|last| now.saturating_sub(last) >= STATUS_HEARTBEAT);
            if status.differs_from(&self.status) || heartbeat {
                self.last_status = Some(now);
                self.status = StatusPayload {
                    seq: self.status.seq + 1,
                    published_ns: now.as_nanos() as u64,
                    ..status
                };
                return Some(Publication::Status(&self.status));
            }
        }
        None
    }

    /// When the core next has something to do, if nothing comes in before.
    pub fn poll_timeout(&self) -> Duration {
        let mut deadline = self.next_command;
        if let Some(at) = self.command_mode.poll_timeout() {
            deadline = deadline.min(at);
        }
        if self.lights().is_some() {
            deadline = deadline.min(self.next_light);
        }
        if let Link::Closed { reopen_at, .. } = self.link
            && self.shutdown.is_none()
        {
            deadline = deadline.min(reopen_at);
        }
        if let Some(last) = self.last_state {
            deadline = deadline.min(last + STATE_HEARTBEAT);
        }
        deadline
    }

    /// Feedback silent for longer than the chassis' command timeout is a gap, and so at once is
    /// a protocol mismatch (nothing the chassis sends is used).
    fn check_silence(&mut self, now: Duration) {
        if self.link != Link::Open {
            return;
        }
        if self.tracker.link_state() == LinkState::ProtocolMismatch
            && let Some(mismatch) = self.tracker.mismatch()
        {
            let reason = mismatch.reason.clone();
            self.set_condition(now, StopCause::ChassisSilent, true, &reason);
            return;
        }
        let since = self
            .tracker
            .last_feedback()
            .unwrap_or(self.opened_at)
            .max(self.opened_at);
        if now.saturating_sub(since) > CHASSIS_TIMEOUT {
            let silent_ms = now.saturating_sub(since).as_millis();
            let detail = match self.tracker.mismatch() {
                Some(mismatch) => mismatch.reason.clone(),
                None => format!("no feedback from the chassis for {silent_ms} ms"),
            };
            self.set_condition(now, StopCause::ChassisSilent, true, &detail);
        }
    }

    fn device(&self) -> &str {
        self.tracker.state().link.device.as_str()
    }

    fn publish_if(&mut self, publish: Publish) {
        if publish == Publish::Yes {
            self.state_due = true;
        }
    }

    /// Moves the deadline one period on, on the absolute grid; a deadline missed by more than a
    /// period is skipped rather than sent late in a burst.
    fn advance_schedule(&mut self, now: Duration) {
        let lateness = now.saturating_sub(self.next_command);
        self.last_lateness = lateness;
        self.stats.max_lateness = self.stats.max_lateness.max(lateness);
        self.next_command += self.period;
        while self.next_command <= now {
            self.next_command += self.period;
            self.stats.missed_ticks += 1;
        }
    }

    /// No motion command written for longer than [`WIRE_GAP_LIMIT`] while the port is open (the
    /// gateway stalled: frozen, starved of CPU, swapped out): the chassis may have timed out and
    /// braked, so nothing resumes without a release and a new take. Checked before the next
    /// frame is made, so that frame is already a stop; once per gap.
    fn check_wire_gap(&mut self, now: Duration) {
        let Some(last) = self.last_motion_written else {
            return;
        };
        let gap = now.saturating_sub(last);
        if self.link == Link::Open && gap > WIRE_GAP_LIMIT {
            let detail = format!(
                "no motion command written for {} ms: the chassis may have stopped by its \
                 {} ms timeout",
                gap.as_millis(),
                CHASSIS_TIMEOUT.as_millis()
            );
            self.arbiter
                .handle_gap(now, StopCause::Overrun, &detail, false);
            self.status_due = true;
            self.last_motion_written = None;
        }
    }

    /// Tells the arbiter whether the chassis moves sideways in the protocol it speaks now.
    fn update_sideways(&mut self) {
        let protocol = self.tracker.protocol();
        if self.sideways_for != Some(protocol) {
            self.sideways_for = Some(protocol);
            self.arbiter.set_sideways(sideways(self.model, protocol));
        }
    }

    /// `output` as a motion command in the chassis' protocol (on v1 in the link's control
    /// mode), if the port is open and the protocol known.
    fn motion(&mut self, output: &Output, now: Duration) -> Option<Outgoing> {
        if self.link != Link::Open {
            return None;
        }
        let (frame, sent) = match self.tracker.protocol()? {
            Protocol::V1 => {
                let percent = |speed: f64, max: f64| {
                    units::speed_to_percent(speed, max).map_or(0, |(p, _)| p)
                };
                let command = MotionCommand {
                    control_mode: self.transport.control_mode(),
                    fault_clear: output.fault_clear,
                    linear_percent: percent(output.linear, self.max_linear),
                    angular_percent: percent(output.angular, self.max_angular),
                };
                let counted = Counted {
                    message: Message::MotionCommand(command),
                    count: self.motion_count.next_count(),
                };
                // v1 has no lateral field in any source: the arbiter refuses sideways on v1.
                (
                    Outgoing::V1(counted),
                    (
                        command.linear(self.max_linear),
                        0.0,
                        command.angular(self.max_angular),
                    ),
                )
            }
            Protocol::V2 => {
                // No yaw rate beyond the model's, whatever the configuration says (a larger
                // `max_angular` is the v1 percent scale of a firmware that differs).
                let max_angular = self.max_angular.min(self.model.limits().angular);
                // The arbiter caps in floating point; on the wire a cap that is not a whole
                // unit would round up past the model's limit (0.5235 rad/s to 524 mrad/s).
                let within = |command: MotionV2, steering: f64| {
                    command.within(
                        self.max_linear,
                        max_angular,
                        self.model.limits().lateral,
                        steering,
                    )
                };
                match (self.model.four_wheel(), self.model.steering()) {
                    (Some(ranger), _) => {
                        let settled = self.handshake.settled(now);
                        let limits = (self.max_linear, max_angular);
                        let (command, sent) = four_wheel_command(&ranger, settled, output, limits);
                        self.handshake.handle_sent(now, sent);
                        (Outgoing::V2(MessageV2::MotionCommand(command)), sent)
                    }
                    // A steered chassis takes a speed and its inner wheel's angle, never a
                    // yaw rate (vendor SDK `hunter_base.hpp`: angular 0, steering in 6-7).
                    (None, Some(steering)) => {
                        // Nothing moves with the brake not reported released, whatever the
                        // output.
                        let (linear, angular) =
                            match self.model.parking_brake() && !self.brake.released(now) {
                                true => (0.0, 0.0),
                                false => (output.linear, output.angular),
                            };
                        let central = steering.central_for(linear, angular);
                        let command = within(
                            MotionV2::from_si(linear, 0.0)
                                .with_steering(steering.inner_from_central(central)),
                            steering.max_inner,
                        );
                        let angular =
                            steering.yaw_rate_from_inner(command.linear(), command.steering());
                        self.brake
                            .handle_sent(now, (command.linear(), 0.0, angular));
                        (
                            Outgoing::V2(MessageV2::MotionCommand(command)),
                            (command.linear(), 0.0, angular),
                        )
                    }
                    (None, None) => {
                        let command = within(
                            MotionV2::from_si(output.linear, output.angular)
                                .with_lateral(output.lateral),
                            0.0,
                        );
                        (
                            Outgoing::V2(MessageV2::MotionCommand(command)),
                            (command.linear(), command.lateral(), command.angular()),
                        )
                    }
                }
            }
        };
        self.stats.commands_sent += 1;
        self.last_motion_written = Some(now);
        self.tracker.handle_sent_motion(sent, now);
        Some(frame)
    }

    /// The light command to repeat: what clients asked for last (`auto`: host control off), or
    /// none before anyone asked.
    fn lights(&self) -> Option<LightCommand> {
        self.arbiter.lights().map(|setting| match setting {
            LightsSetting::Manual(lights) => lights,
            LightsSetting::Auto => LightCommand::default(),
        })
    }

    /// The arbiter's status at `now`, without the sequence number and publication time.
    fn status(&self, now: Duration) -> StatusPayload {
        let arbiter = &self.arbiter;
        let mut status = StatusPayload {
            robot: FixedText::new(&self.robot),
            ..StatusPayload::default()
        };
        status.stop_total = arbiter.stops().len() as u32;
        status.newest_stop = arbiter.newest_stop();
        for (slot, stop) in status.stops.iter_mut().zip(arbiter.stops()) {
            *slot = StopPayload {
                id: stop.id,
                owner: FixedText::new(&stop.owner),
                cause: stop.cause.raw(),
                persists: arbiter.persists(stop),
                reason: FixedText::new(&stop.reason),
                age_ms: millis(now.saturating_sub(stop.at)),
                uid: stop.uid.unwrap_or(UNKNOWN_UID),
                by_operator: stop.by_operator,
            };
        }
        debug_assert!(status.stops().len() <= MAX_STATUS_STOPS);
        for (slot, (at, text)) in status.events.iter_mut().zip(arbiter.history()) {
            *slot = EventPayload {
                age_ms: millis(now.saturating_sub(*at)),
                text: FixedText::new(text),
            };
            status.event_count += 1;
        }
        status.tick_lateness_ms = millis(self.last_lateness);
        status.tick_max_lateness_ms = millis(self.stats.max_lateness);
        status.ticks_missed = self.stats.missed_ticks;
        if let Some((source, class)) = arbiter.selected(now) {
            status.selected_class = class.raw();
            status.selected_client = FixedText::new(&source.key.name);
        }
        let output = arbiter.output();
        status.output_linear = output.linear;
        status.output_lateral = output.lateral;
        status.output_angular = output.angular;
        status.output_fault_clear = output.fault_clear.raw();
        status.limited = output.limited;
        status.autonomy_armed = arbiter.autonomy_armed();
        let battery = self.tracker.state().battery;
        status.battery_level = battery.level;
        status.battery_level_from = battery.level_from;
        // Whole percent: the estimate's every wiggle is no change of the status.
        status.battery_percent = battery.percent.round();
        status.lights = LightsControl::of(arbiter.lights()).raw();
        for (slot, source) in status.sources.iter_mut().zip(arbiter.sources()) {
            *slot = SourcePayload {
                client: FixedText::new(&source.key.name),
                class: source.class().map_or(0, |class| class.raw()),
                holding: source.lease().is_some(),
                lease: source.lease().unwrap_or(0),
                heartbeat_ms: source.heartbeat().map_or(0, |p| p.as_millis() as u32),
                requests: source.requests,
                age_ms: millis(now.saturating_sub(source.last_seen)),
                uid: source.key.uid.unwrap_or(UNKNOWN_UID),
            };
            status.source_count += 1;
        }
        status.rejections = *arbiter.rejections();
        status
    }
}

/// The origin a request speaks for: the zenoh bridge's stops and releases are a remote peer's
/// (`remote:PEER`, as the bridge names it from the command's key, which zenoh's access control
/// binds to the peer); anyone else's `peer` field is ignored.
fn speaking_for(origin: &Origin, wire: &ControlRequest) -> Origin {
    let peer = wire.peer.as_str();
    if !origin.bridge || !peer.starts_with(REMOTE_PREFIX) || peer.len() == REMOTE_PREFIX.len() {
        return origin.clone();
    }
    let mut speaking = origin.clone();
    speaking.key.name = peer.to_owned();
    speaking.operator = false;
    speaking
}

fn millis(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1000.0
}

/// The 0x441 code for a v1 fault-clear request: a motor's communication fault clears that
/// motor's error; any other code clears every error (v2 has no finer codes); none sends none.
fn error_clear_v2(code: FaultClear) -> Option<ErrorClearV2> {
    Some(match code {
        FaultClear::None => return None,
        FaultClear::Motor1Comm => ErrorClearV2::Motor1,
        FaultClear::Motor2Comm => ErrorClearV2::Motor2,
        FaultClear::Motor3Comm => ErrorClearV2::Motor3,
        FaultClear::Motor4Comm => ErrorClearV2::Motor4,
        FaultClear::BatteryUnderVoltage
        | FaultClear::BatteryOverVoltage
        | FaultClear::DriverOverTemp
        | FaultClear::MotorOverCurrent
        | FaultClear::Unknown(_) => ErrorClearV2::All,
    })
}

/// How tight a chassis of `model` turns: a steered one only while moving, no tighter than its
/// smallest circle; a Ranger in its motion modes; every other in place.
pub fn turning(model: Model) -> Turning {
    if let Some(ranger) = model.four_wheel() {
        return Turning::Modes {
            min_radius: ranger.min_radius(),
        };
    }
    match model.steering() {
        None => Turning::InPlace,
        Some(steering) => {
            let min_radius = steering.min_radius();
            Turning::Radius {
                min_radius,
                in_place: format!(
                    "a {model} cannot turn in place: it steers its front wheels and turns only \
                     while moving, on a circle of {min_radius:.2} m radius at the tightest; \
                     drive forward or backward to turn"
                ),
            }
        }
    }
}

/// A Ranger's 0x111 for `output` in the mode it reports `settled` (zero in any other, and
/// while it changes), and the body velocity that command makes. `limits` are the gateway's
/// (m/s, rad/s). Dual Ackermann: the speed and the inner wheels' angle; parallel: the wheels'
/// speed and angle; spin: the yaw rate, in bytes 2-3 or, on a Mini 2.0, 4-5.
fn four_wheel_command(
    ranger: &FourWheel,
    settled: Option<MotionModeV2>,
    output: &Output,
    (linear, angular): (f64, f64),
) -> (MotionV2, (f64, f64, f64)) {
    let velocity = (output.linear, output.lateral, output.angular);
    let carried = settled.filter(|settled| crate::modes::carries(*settled, velocity));
    match carried {
        Some(MotionModeV2::DualAckermann) => {
            let inner = ranger.inner_for(output.linear, output.angular);
            let command = MotionV2::from_si(output.linear, 0.0)
                .with_steering(inner)
                .within(linear, 0.0, 0.0, ranger.max_inner);
            let yaw = ranger.yaw_rate_from_inner(command.linear(), command.steering());
            (command, (command.linear(), 0.0, yaw))
        }
        Some(MotionModeV2::Parallel) => {
            let (speed, angle) = ranger.parallel_for(output.linear, output.lateral);
            let command = MotionV2::from_si(speed, 0.0).with_steering(angle).within(
                linear,
                0.0,
                0.0,
                ranger.max_parallel,
            );
            let (forward, leftward) =
                ranger.body_from_parallel(command.linear(), command.steering());
            (command, (forward, leftward, 0.0))
        }
        Some(MotionModeV2::Spin) => {
            let command = if ranger.spin_in_lateral {
                MotionV2::from_si(0.0, 0.0)
                    .with_lateral(output.angular)
                    .within(0.0, 0.0, angular, 0.0)
            } else {
                MotionV2::from_si(0.0, output.angular).within(0.0, angular, 0.0, 0.0)
            };
            let yaw = if ranger.spin_in_lateral {
                command.lateral()
            } else {
                command.angular()
            };
            (command, (0.0, 0.0, yaw))
        }
        Some(MotionModeV2::Park | MotionModeV2::SideSlip | MotionModeV2::Unknown(_)) | None => {
            (MotionV2::default(), (0.0, 0.0, 0.0))
        }
    }
}

/// A steered chassis' motion state as the rest of the gateway reads it: a body velocity (the
/// Hunter reports a steering angle where a SCOUT reports a yaw rate, and its vendor driver
/// derives the yaw rate so too; a Ranger reports its wheels' speed and angle in the mode
/// `mode` it last said it is in, its spin rate in bytes 2-3 as its vendor driver reads it).
/// Any other event as it came.
fn as_driven(model: Model, mode: Option<MotionModeStateV2>, event: &RxEvent) -> Option<RxEvent> {
    let RxEvent::V2(MessageV2::MotionState(motion)) = event else {
        return None;
    };
    if let Some(ranger) = model.four_wheel() {
        let (linear, lateral, angular) = match mode.map(|mode| mode.mode) {
            Some(MotionModeV2::DualAckermann) => (
                motion.linear(),
                0.0,
                ranger.yaw_rate_from_inner(motion.linear(), motion.steering()),
            ),
            Some(MotionModeV2::Parallel) => {
                let (forward, leftward) =
                    ranger.body_from_parallel(motion.linear(), motion.steering());
                (forward, leftward, 0.0)
            }
            // The vendor's driver reads the spin rate in bytes 2-3 on every Ranger; a Mini 2.0,
            // commanded in bytes 4-5, may report it there too (unverified): either is read.
            Some(MotionModeV2::Spin) if ranger.spin_in_lateral && motion.angular_mrad_s == 0 => {
                (0.0, 0.0, motion.lateral())
            }
            Some(MotionModeV2::Spin) => (0.0, 0.0, motion.angular()),
            Some(MotionModeV2::Park | MotionModeV2::SideSlip | MotionModeV2::Unknown(_)) | None => {
                (motion.linear(), motion.lateral(), motion.angular())
            }
        };
        return Some(RxEvent::V2(MessageV2::MotionState(
            MotionV2::from_si(linear, angular)
                .with_lateral(lateral)
                .with_steering(motion.steering()),
        )));
    }
    let steering = model.steering()?;
    let angular = steering.yaw_rate_from_inner(motion.linear(), motion.steering());
    Some(RxEvent::V2(MessageV2::MotionState(MotionV2 {
        angular_mrad_s: MotionV2::from_si(0.0, angular).angular_mrad_s,
        ..*motion
    })))
}

/// Whether a chassis of `model` speaking `protocol` (`None`: not known yet) moves sideways.
/// Only the SCOUT MINI OMNI does, and only on v2: no source gives a lateral field in v1's
/// motion command (vendor SDK `agilex_protocol_v1.h`: bytes 4-5 reserved).
pub fn sideways(model: Model, protocol: Option<Protocol>) -> Sideways {
    let limit = model.limits().lateral;
    match protocol {
        _ if limit <= 0.0 => Sideways::Not(format!(
            "a {model} does not move sideways: send a lateral speed of 0"
        )),
        Some(Protocol::V1) => Sideways::Not(format!(
            "a {model} moves sideways on protocol v2 only (v1's command has no sideways \
             field): run its gateway with --protocol v2"
        )),
        Some(Protocol::V2) | None => Sideways::UpTo(limit),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn a_starved_gateways_backlog_is_no_lead_a_frozen_clock_is() {
        let mut clock = ChassisClock::default();
        let mut now = Duration::from_secs(10);
        for _ in 0..50 {
            now += MOTION_REPORT_PERIOD;
            assert!(clock.handle_report(now) <= MOTION_REPORT_PERIOD);
        }
        // The gateway starved of the CPU for 450 ms while the clock moved: the 22 reports that
        // queued meanwhile are read at once, and stand for no more than the time that passed.
        now += 450 * MS;
        for _ in 0..22 {
            assert!(clock.handle_report(now) <= MOTION_REPORT_PERIOD);
        }
        // Every clock of the host held back: 30 reports in no time run 600 ms ahead.
        let mut lead = Duration::ZERO;
        for _ in 0..30 {
            lead = clock.handle_report(now);
        }
        assert!(lead > WIRE_GAP_LIMIT, "{lead:?}");
    }
}
