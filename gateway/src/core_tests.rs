//! The gateway core wired to the simulator's chassis model on a virtual clock (after quinn-proto's
//! test `Pair`): both sans-IO, so minutes of robot time run in milliseconds, deterministically.
//! These are the control loop's behaviour tests: the 20 ms grid and skipped ticks, the stop sent
//! out of schedule, light repetition, reconnect backoff, state and status publication, shutdown.
//! Every scenario about motion and safety runs against a chassis of each protocol (v1 and v2
//! firmware, `both_protocols!`); v2's command mode, detection and mismatch have their own.

use std::time::Duration;

use proptest::prelude::*;
use scout_interface::control::{
    Accepted, ControlRequest, DriveMode, Rejected, RejectionKind, ReleaseTarget, Request, StopCause,
};
use scout_interface::services::Way;
use scout_interface::state::{BatteryLevel, LinkState};
use scout_interface::{Class, LightsSetting, StatePayload, StatusPayload, Transport};
use scout_protocol::link::{Outgoing, RxEvent};
use scout_protocol::model::{Drive, Model};
use scout_protocol::units::MAX_LINEAR_SPEED;
use scout_protocol::v2::{
    BrakeV2, ControlModeV2, ErrorBitsV2, MessageV2, MotionModeV2, MotionV2, SystemStateV2,
};
use scout_protocol::version::Protocol;
use scout_protocol::{Counted, Light, LightCommand, LightMode, Message, MotionFeedback};
use scout_sim::chassis::{Injection, Protection};
use scout_sim::{Chassis, Feedback, SimParams};

use crate::arbiter::{ClientKey, Origin};
use crate::config::{GatewayConfig, OnCritical, ProtocolSetting};
use crate::core::{
    CHASSIS_TIMEOUT, Core, FIRST_BACKOFF, Publication, STATE_HEARTBEAT, STATUS_HEARTBEAT, Start,
    WIRE_GAP_LIMIT,
};

const TICK: Duration = Duration::from_millis(20);

const fn ms(millis: u64) -> Duration {
    Duration::from_millis(millis)
}

/// A client of the core: its name, port id (its node's too) and whether it is an operator.
#[derive(Debug, Clone, Copy)]
struct Client(&'static str, u128, bool);

impl Client {
    fn origin(self) -> Origin {
        Origin {
            key: ClientKey {
                port: self.1,
                node: self.1,
                name: self.0.to_owned(),
                uid: Some(1000),
            },
            operator: self.2,
            bridge: false,
        }
    }
}

const TELEOP: Client = Client("joystick", 1, false);
const AUTONOMY: Client = Client("planner", 2, false);
const OFFICER: Client = Client("officer", 3, false);
const OPERATOR: Client = Client("operator", 4, true);

/// A motion command as it went out, in m/s and rad/s, whatever the protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Motion {
    linear: f64,
    angular: f64,
}

/// A configuration that speaks `protocol`.
fn config(protocol: Protocol) -> GatewayConfig {
    GatewayConfig {
        protocol: match protocol {
            Protocol::V1 => ProtocolSetting::V1,
            Protocol::V2 => ProtocolSetting::V2,
        },
        ..GatewayConfig::default()
    }
}

/// The core and a simulated chassis on one virtual clock.
struct Pair {
    /// The time of the next step.
    now: Duration,
    core: Core,
    chassis: Chassis,
    /// The virtual time at which the chassis model's clock reads zero.
    epoch: Duration,
    /// Whether opening the port succeeds.
    plugged: bool,
    /// Whether the port is open.
    open: bool,
    /// Whether the chassis' feedback reaches the core (off: a silent chassis).
    feedback: bool,
    /// Whether 0x421 reaches the chassis (off: a chassis that never takes the command mode).
    mode_requests: bool,
    /// Frames that reached the chassis, with when.
    sent: Vec<(Duration, Outgoing)>,
    states: Vec<(Duration, StatePayload)>,
    statuses: Vec<(Duration, StatusPayload)>,
    open_attempts: Vec<Duration>,
    seq: u64,
    leases: std::collections::HashMap<u128, u64>,
}

impl Pair {
    /// A v1 gateway and chassis on `transport`.
    fn new(transport: Transport) -> Self {
        Self::with_config(transport, &config(Protocol::V1))
    }

    /// A gateway and a simulated chassis speaking `protocol`, in-process.
    fn of(protocol: Protocol) -> Self {
        Self::with_config(Transport::Sim, &config(protocol))
    }

    fn with_config(transport: Transport, config: &GatewayConfig) -> Self {
        Self::starting(transport, config, Start::Clean)
    }

    fn starting(transport: Transport, config: &GatewayConfig, start: Start) -> Self {
        let firmware = config.fixed_protocol().unwrap_or(Protocol::V1);
        Self::with_firmware(firmware, transport, config, start)
    }

    /// A gateway configured by `config` and a chassis whose firmware speaks `firmware`.
    fn with_firmware(
        firmware: Protocol,
        transport: Transport,
        config: &GatewayConfig,
        start: Start,
    ) -> Self {
        // Far from zero, as CLOCK_BOOTTIME is: nothing may assume time starts at zero.
        let start_time = Duration::from_secs(1000);
        let model = config.model.unwrap_or(Model::default_for(firmware));
        let chassis = Chassis::new(SimParams::for_model(model), transport);
        let mut chassis = match firmware {
            Protocol::V1 => chassis,
            Protocol::V2 => chassis.with_protocol_v2(),
        };
        let _ = chassis.poll_feedback(Duration::ZERO);
        let mut pair = Self {
            now: start_time,
            core: Core::new(config, transport, "simulator", start_time, start, 1),
            chassis,
            epoch: start_time,
            plugged: true,
            open: false,
            feedback: true,
            mode_requests: true,
            sent: Vec::new(),
            states: Vec::new(),
            statuses: Vec::new(),
            open_attempts: Vec::new(),
            seq: 0,
            leases: std::collections::HashMap::new(),
        };
        pair.step();
        pair
    }

    /// One driver iteration at `now`, then the clock moves to the next event.
    fn step(&mut self) {
        let now = self.now;
        if self.open
            && let Some(feedback) = self.chassis.poll_feedback(now - self.epoch)
            && self.feedback
        {
            match feedback {
                Feedback::V1(batch) => {
                    for counted in batch {
                        self.core.handle_rx(now, &RxEvent::Message(counted));
                    }
                }
                Feedback::V2(frames) => {
                    for message in frames {
                        self.core.handle_rx(now, &RxEvent::V2(message));
                    }
                }
            }
        }
        if self.core.poll_open(now) {
            self.open_attempts.push(now);
            if self.plugged {
                self.open = true;
                self.core.handle_opened(now);
            } else {
                self.core.handle_open_failed(now, "no such device");
            }
        }
        while let Some(frame) = self.core.poll_transmit(now) {
            assert!(self.open, "a frame while the port is closed: {frame:?}");
            let at = now - self.epoch;
            match frame {
                Outgoing::V1(counted) => {
                    self.chassis.handle_message(at, counted);
                }
                Outgoing::V2(MessageV2::ControlMode(_)) if !self.mode_requests => {}
                Outgoing::V2(message) => {
                    self.chassis.handle_v2(at, message);
                }
            }
            self.sent.push((now, frame));
        }
        while let Some(publication) = self.core.poll_publish(now) {
            match publication {
                Publication::State(state) => self.states.push((now, *state)),
                Publication::Status(status) => self.statuses.push((now, *status)),
            }
        }
        let mut next = self.core.poll_timeout();
        if self.open {
            next = next.min(self.chassis.next_feedback_at() + self.epoch);
        }
        self.now = next.max(now + Duration::from_micros(1));
    }

    /// Runs every step up to and including `time` from now.
    fn run(&mut self, time: Duration) {
        let end = self.now + time;
        while self.now <= end {
            self.step();
        }
    }

    /// Steps until `done` holds, for at most `limit` of robot time.
    fn run_until(&mut self, limit: Duration, done: impl Fn(&Self) -> bool) {
        let end = self.now + limit;
        while !done(self) {
            assert!(self.now <= end, "not within {limit:?}");
            self.step();
        }
    }

    /// Moves the clock on without stepping, as a stalled driver would.
    fn stall(&mut self, time: Duration) {
        self.now += time;
    }

    /// Every clock of the host stands still for `time` (a paused VM whose clocks were
    /// restored, a restored checkpoint) while the chassis runs on: it gets no command meanwhile,
    /// and its reports wait in the port, read at once when the host runs again.
    fn freeze_host_clocks(&mut self, time: Duration) {
        let start = self.now - self.epoch;
        let mut waiting = Vec::new();
        let mut at = start;
        while at < start + time {
            waiting.extend(self.chassis.poll_feedback(at));
            at += ms(1);
        }
        self.epoch -= time;
        for feedback in waiting {
            match feedback {
                Feedback::V1(batch) => {
                    for counted in batch {
                        self.core.handle_rx(self.now, &RxEvent::Message(counted));
                    }
                }
                Feedback::V2(frames) => {
                    for message in frames {
                        self.core.handle_rx(self.now, &RxEvent::V2(message));
                    }
                }
            }
        }
    }

    /// A request from `client` at the current time, answered at once; the next step (at the
    /// same time) carries out what it caused.
    fn request(&mut self, client: Client, request: &Request) -> Result<Accepted, Rejected> {
        self.seq += 1;
        let mut wire: ControlRequest = request.encode(self.seq);
        wire.sent_ns = self.now.as_nanos() as u64;
        let way = match request {
            Request::Stop { .. } => Way::Stop,
            _ => Way::Control,
        };
        let answer = self
            .core
            .handle_request(self.now, &client.origin(), way, &wire)
            .answer();
        self.step();
        answer
    }

    /// Takes control as `class` for `client`: the deliberate act.
    fn take(&mut self, client: Client, class: Class) -> Result<u64, Rejected> {
        let lease = self.request(client, &Request::TakeControl { class })?.lease;
        let lease = lease.expect("a lease");
        self.leases.insert(client.1, lease);
        Ok(lease)
    }

    /// Drives under the lease `client` holds (none: 0, which the core refuses).
    fn send_drive(&mut self, client: Client, linear: f64) -> Result<Accepted, Rejected> {
        let lease = self.leases.get(&client.1).copied().unwrap_or(0);
        self.request(
            client,
            &Request::Drive {
                lease,
                linear,
                lateral: 0.0,
                angular: 0.0,
                ttl: None,
                mode: None,
            },
        )
    }

    /// Drives, taking control first if `client` holds none.
    fn drive(&mut self, client: Client, class: Class, linear: f64) -> Result<Accepted, Rejected> {
        if !self.leases.contains_key(&client.1) {
            self.take(client, class)?;
        }
        let answer = self.send_drive(client, linear);
        if answer.as_ref().is_err_and(|r| {
            matches!(
                r.kind,
                Some(RejectionKind::Revoked | RejectionKind::NoControl)
            )
        }) {
            self.leases.remove(&client.1);
        }
        answer
    }

    /// Drives under the lease it had, never taking control again, every 20 ms for `time`:
    /// a client that keeps streaming across whatever happens. Returns the answers.
    fn keep_streaming(
        &mut self,
        client: Client,
        linear: f64,
        time: Duration,
    ) -> Vec<Result<Accepted, Rejected>> {
        let end = self.now + time;
        let mut answers = Vec::new();
        while self.now < end {
            answers.push(self.send_drive(client, linear));
            let next = self.now + TICK;
            while self.now < next {
                self.step();
            }
        }
        answers
    }

    fn stops(&self) -> Vec<(String, StopCause)> {
        self.core
            .arbiter()
            .stops()
            .iter()
            .map(|stop| (stop.owner.clone(), stop.cause))
            .collect()
    }

    /// Drives as `client` every 20 ms for `time`.
    fn stream(&mut self, client: Client, class: Class, linear: f64, time: Duration) {
        let end = self.now + time;
        while self.now < end {
            self.drive(client, class, linear).expect("drive accepted");
            let next = self.now + TICK;
            while self.now < next {
                self.step();
            }
        }
    }

    fn unplug(&mut self) {
        self.plugged = false;
        self.open = false;
        self.core
            .handle_link_failed(self.now, "reading: device disconnected");
        self.step();
    }

    fn motion_commands(&self) -> Vec<(Duration, Motion)> {
        let max_angular = self.chassis.params().max_angular;
        self.sent
            .iter()
            .filter_map(|(at, frame)| match frame {
                Outgoing::V1(Counted {
                    message: Message::MotionCommand(command),
                    ..
                }) => Some((
                    *at,
                    Motion {
                        linear: command.linear(MAX_LINEAR_SPEED),
                        angular: command.angular(max_angular),
                    },
                )),
                Outgoing::V2(MessageV2::MotionCommand(command)) => Some((
                    *at,
                    Motion {
                        linear: command.linear(),
                        angular: command.angular(),
                    },
                )),
                Outgoing::V1(_) | Outgoing::V2(_) => None,
            })
            .collect()
    }

    fn light_commands(&self) -> Vec<Duration> {
        self.sent
            .iter()
            .filter(|(_, frame)| {
                matches!(
                    frame,
                    Outgoing::V1(Counted {
                        message: Message::LightCommand(_),
                        ..
                    }) | Outgoing::V2(MessageV2::LightCommand(_))
                )
            })
            .map(|(at, _)| *at)
            .collect()
    }

    /// What `pick` takes of the v2 frames sent other than motion commands, with when.
    fn v2_sent<T>(&self, pick: impl Fn(MessageV2) -> Option<T>) -> Vec<(Duration, T)> {
        self.v2_others()
            .into_iter()
            .filter_map(|(at, message)| pick(message).map(|taken| (at, taken)))
            .collect()
    }

    /// The v2 motion commands (0x111) sent, with when.
    fn v2_motion_commands(&self) -> Vec<(Duration, MotionV2)> {
        self.sent
            .iter()
            .filter_map(|(at, frame)| match frame {
                Outgoing::V2(MessageV2::MotionCommand(command)) => Some((*at, *command)),
                Outgoing::V1(_) | Outgoing::V2(_) => None,
            })
            .collect()
    }

    /// The v2 frames sent other than motion commands, with when.
    fn v2_others(&self) -> Vec<(Duration, MessageV2)> {
        self.sent
            .iter()
            .filter_map(|(at, frame)| match frame {
                Outgoing::V2(MessageV2::MotionCommand(_)) | Outgoing::V1(_) => None,
                Outgoing::V2(message) => Some((*at, *message)),
            })
            .collect()
    }

    /// Feeds the core motion feedback in the chassis' protocol, as if it came from the port.
    fn inject_motion(&mut self, linear_mm_s: i16, angular_mrad_s: i16, count: u8) {
        let event = match self.core.link_protocol() {
            Some(Protocol::V2) => RxEvent::V2(MessageV2::MotionState(MotionV2 {
                linear_mm_s,
                angular_mrad_s,
                ..MotionV2::default()
            })),
            Some(Protocol::V1) | None => RxEvent::Message(Counted {
                message: Message::MotionFeedback(MotionFeedback {
                    linear_mm_s,
                    angular_mrad_s,
                }),
                count,
            }),
        };
        self.core.handle_rx(self.now, &event);
    }

    /// Feeds the core a system state in the chassis' protocol (the chassis in CAN mode).
    fn inject_system(&mut self, state: u8, count: u8) {
        let protocol = self.core.link_protocol().unwrap_or(Protocol::V1);
        let event = system_state(
            protocol,
            scout_protocol::ChassisState::from_raw(state),
            count,
        );
        self.core.handle_rx(self.now, &event);
    }

    /// The reason of the stop of `cause` in the last status published.
    fn stop_reason(&self, cause: StopCause) -> String {
        let status = self.statuses().last().expect("a status").1;
        let stop = status
            .stops()
            .iter()
            .find(|stop| stop.cause == cause.raw())
            .map(|stop| stop.reason.as_str().to_owned());
        stop.unwrap_or_else(|| panic!("no {} stop in {:?}", cause.name(), status.stops()))
    }

    fn states(&self) -> Vec<(Duration, StatePayload)> {
        self.states.clone()
    }

    fn statuses(&self) -> Vec<(Duration, StatusPayload)> {
        self.statuses.clone()
    }

    fn last_state(&self) -> StatePayload {
        self.states().last().expect("a state was published").1
    }
}

fn intervals(times: &[Duration]) -> Vec<Duration> {
    times.windows(2).map(|pair| pair[1] - pair[0]).collect()
}

fn motion_commands_go_out_on_the_20_ms_grid_for_ten_minutes(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.run(Duration::from_secs(600));
    let times: Vec<Duration> = pair.motion_commands().iter().map(|(at, _)| *at).collect();
    assert!(times.len() > 30_000, "{}", times.len());
    assert!(intervals(&times).iter().all(|gap| *gap == TICK));
    assert_eq!(pair.core.stats().missed_ticks, 0);
    let chassis = pair.chassis.stats().motion_command_intervals;
    assert_eq!(chassis.max_ms, 20.0);
    assert_eq!(pair.last_state().link.state(), LinkState::Ok);
}

fn a_late_tick_is_sent_once_and_the_missed_ones_are_skipped(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.run(ms(100));
    let grid = pair.core.poll_timeout();
    pair.now = grid;
    pair.stall(ms(75));
    pair.step();
    pair.run(ms(100));
    let times: Vec<Duration> = pair.motion_commands().iter().map(|(at, _)| *at).collect();
    let late = times
        .iter()
        .position(|at| *at == grid + ms(75))
        .expect("sent late");
    // One command for the late tick, then back on the grid: no burst.
    assert_eq!(times[late + 1], grid + ms(80));
    assert_eq!(times[late - 1], grid - TICK);
    let stats = pair.core.stats();
    assert_eq!((stats.missed_ticks, stats.max_lateness), (3, ms(75)));
}

fn a_stop_goes_on_the_wire_at_once_not_at_the_next_tick(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    pair.run(ms(7));
    let asked = pair.now;
    pair.request(
        OFFICER,
        &Request::Stop {
            reason: "person ahead".into(),
        },
    )
    .expect("a stop is accepted");
    let (at, command) = pair
        .motion_commands()
        .into_iter()
        .find(|(at, _)| *at >= asked)
        .expect("a command after the stop");
    assert_eq!(at, asked, "sent in the same iteration as the request");
    assert_eq!((command.linear, command.angular), (0.0, 0.0));
    assert_eq!(pair.core.stats().urgent_stops, 1);
    let status = pair.statuses().last().expect("status").1;
    assert!(status.stopped());
    assert_eq!(status.stops()[0].owner.as_str(), "officer");
}

fn teleop_drives_the_chassis_and_a_stale_stream_stops_at_its_life(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(3));
    let moving = pair.chassis.actual().linear;
    assert!((moving - 0.5).abs() < 0.02, "{moving}");
    assert!((pair.last_state().motion.linear() - 0.5).abs() < 0.02);
    // The last command (a lost link): it holds for its life (teleop 250 ms), then zero goes
    // on the wire at the next tick, not ramped.
    let last = pair.now;
    pair.drive(TELEOP, Class::Teleop, 0.5)
        .expect("drive accepted");
    pair.run(Duration::from_secs(2));
    assert_eq!(pair.chassis.actual().linear, 0.0);
    let after: Vec<_> = (pair.motion_commands().into_iter())
        .filter(|(at, _)| *at >= last)
        .collect();
    let (zero_at, _) = *after
        .iter()
        .find(|(_, command)| command.linear == 0.0)
        .expect("a zero");
    assert!(
        zero_at >= last + ms(250) && zero_at <= last + ms(250) + TICK,
        "zero {:?} after the last command",
        zero_at - last
    );
    for (at, command) in after {
        let expected = if at < zero_at { 0.5 } else { 0.0 };
        assert!(
            (command.linear - expected).abs() < 0.01,
            "{command:?} at {at:?}"
        );
    }
}

fn a_dead_client_loses_control_at_once(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.request(AUTONOMY, &Request::Resume).expect("resume");
    pair.stream(AUTONOMY, Class::Autonomy, 0.4, Duration::from_secs(2));
    let dead_at = pair.now;
    pair.core.handle_client_gone(dead_at, AUTONOMY.1);
    pair.run(ms(40));
    let status = pair.statuses().last().expect("status").1;
    assert_eq!(status.selected_class, 0, "nobody selected after the death");
    pair.run(Duration::from_secs(1));
    assert_eq!(pair.chassis.actual().linear, 0.0);
}

#[test]
fn lights_repeat_every_25_ms_on_can_and_every_100_ms_on_serial() {
    let lights = Request::Lights(LightsSetting::Manual(LightCommand {
        enabled: true,
        front: Light {
            mode: LightMode::On,
            brightness: 100,
        },
        rear: Light::default(),
    }));
    for (transport, period) in [(Transport::Can, ms(25)), (Transport::Serial, ms(100))] {
        let mut pair = Pair::new(transport);
        pair.run(ms(200));
        assert!(
            pair.light_commands().is_empty(),
            "none before a client asks"
        );
        pair.request(OFFICER, &lights).expect("lights");
        pair.run(Duration::from_secs(2));
        let times = pair.light_commands();
        assert!(times.len() >= 19, "{transport}: {}", times.len());
        assert!(
            intervals(&times).iter().all(|gap| *gap == period),
            "{transport}"
        );
        assert_eq!(
            pair.last_state().lights.feedback().front.mode,
            LightMode::On
        );
    }
}

fn a_failed_port_is_reopened_with_a_doubling_backoff(protocol: Protocol) {
    let mut config = config(protocol);
    config.timing.reconnect_max_ms = 400;
    let mut pair = Pair::with_config(Transport::Sim, &config);
    pair.run(ms(100));
    assert_eq!(pair.last_state().link.state(), LinkState::Ok);
    let failed = pair.now;
    pair.unplug();
    assert_eq!(pair.last_state().link.state(), LinkState::Disconnected);
    pair.run(Duration::from_secs(2));
    let attempts: Vec<Duration> = pair.open_attempts[1..]
        .iter()
        .map(|at| *at - failed)
        .collect();
    assert_eq!(
        &attempts[..6],
        [ms(50), ms(150), ms(350), ms(750), ms(1150), ms(1550)],
        "50 ms, then doubling up to the 400 ms maximum"
    );
    assert!(pair.motion_commands().iter().all(|(at, _)| *at < failed));
    pair.plugged = true;
    pair.run(Duration::from_secs(1));
    let state = pair.last_state();
    assert_eq!(state.link.state(), LinkState::Ok);
    assert_eq!(state.link.reconnects, 1);
    assert_eq!(FIRST_BACKOFF, ms(50));
}

fn state_is_published_per_feedback_on_link_changes_and_every_100_ms_while_silent(
    protocol: Protocol,
) {
    let mut pair = Pair::of(protocol);
    pair.run(Duration::from_secs(1));
    let frames = pair.last_state().link.rx_frames;
    assert!(frames >= 7 * 49, "{frames}");
    // The chassis sends its 7 frames together every 20 ms: one publication carries them.
    let times: Vec<Duration> = pair.states().iter().map(|(at, _)| *at).collect();
    assert!(times.len() >= 50, "{}", times.len());
    assert!(intervals(&times[1..]).iter().all(|gap| *gap == TICK));
    // The chassis goes quiet: `silent` after 100 ms, then the state every 100 ms.
    pair.feedback = false;
    let quiet = pair.now;
    pair.run(Duration::from_secs(1));
    let after: Vec<(Duration, StatePayload)> = pair
        .states()
        .into_iter()
        .filter(|(at, _)| *at > quiet)
        .collect();
    let silent_at = after
        .iter()
        .find(|(_, s)| s.link.state() == LinkState::Silent)
        .expect("silent")
        .0;
    assert!(silent_at - quiet <= ms(120), "{:?}", silent_at - quiet);
    let times: Vec<Duration> = after.iter().map(|(at, _)| *at).collect();
    assert!(intervals(&times).iter().all(|gap| *gap <= STATE_HEARTBEAT));
    assert!(times.len() >= 9, "{}", times.len());
    let seqs: Vec<u64> = after.iter().map(|(_, s)| s.seq).collect();
    assert!(seqs.windows(2).all(|w| w[1] == w[0] + 1));
}

fn status_is_published_on_change_and_once_a_second(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.run(Duration::from_secs(5));
    // From the first feedback on (the battery is known then: a change).
    let idle: Vec<_> = pair
        .statuses()
        .into_iter()
        .skip_while(|(_, status)| status.battery_level == BatteryLevel::Unknown.raw())
        .collect();
    let times: Vec<Duration> = idle.iter().map(|(at, _)| *at).collect();
    assert!((5..=7).contains(&times.len()), "{}", times.len());
    assert!(
        intervals(&times)
            .iter()
            .all(|gap| *gap >= STATUS_HEARTBEAT - TICK)
    );
    let asked = pair.now;
    pair.request(
        OFFICER,
        &Request::Stop {
            reason: "test".into(),
        },
    )
    .expect("stop");
    let changed = pair
        .statuses()
        .into_iter()
        .find(|(at, s)| *at >= asked && s.stopped());
    assert_eq!(
        changed.map(|(at, _)| at),
        Some(asked),
        "published with the change"
    );
}

fn odometry_reset_is_answered_and_published(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    assert!(pair.last_state().odometry.x > 0.5);
    pair.request(OFFICER, &Request::ResetOdometry)
        .expect("reset");
    let state = pair.last_state();
    assert_eq!(state.odometry.resets, 1);
    assert!(
        state.odometry.x < 0.011,
        "at most one 20 ms step at 0.5 m/s since"
    );
}

fn shutdown_sends_zero_for_the_configured_cycles_then_finishes(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    pair.core.handle_shutdown();
    let began = pair.now;
    pair.run_until(Duration::from_secs(1), |pair| pair.core.is_finished());
    let after: Vec<Motion> = pair
        .motion_commands()
        .into_iter()
        .filter(|(at, _)| *at >= began)
        .map(|(_, command)| command)
        .collect();
    assert_eq!(after.len(), 5);
    assert!(after.iter().all(|c| c.linear == 0.0 && c.angular == 0.0));
}

fn malformed_requests_are_answered_and_counted(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    let wire = ControlRequest {
        kind: 200,
        ..ControlRequest::default()
    };
    let fuzzer = Client("fuzzer", 66, false).origin();
    let answer = pair
        .core
        .handle_request(pair.now, &fuzzer, Way::Control, &wire)
        .answer();
    assert!(
        answer
            .expect_err("refused")
            .reason
            .contains("unknown request kind 200")
    );
    pair.step();
    let status = pair.statuses().last().expect("status").1;
    let unknown = scout_interface::RejectionKind::UnknownRequest;
    assert_eq!(status.rejections[usize::from(unknown.raw())], 1);
}

/// Something that happens to a running gateway.
#[derive(Debug, Clone)]
enum Event {
    Wait(u64),
    Drive(usize, f64),
    Stop(usize),
    Release(usize),
    Resume(usize),
    Dies(usize),
    Stall(u64),
}

const CLIENTS: [(Client, Class); 3] = [
    (Client("teleop", 11, false), Class::Teleop),
    (Client("autonomy", 12, false), Class::Autonomy),
    (Client("safety", 13, true), Class::Teleop),
];

fn event() -> impl Strategy<Value = Event> {
    prop_oneof![
        (1u64..200).prop_map(Event::Wait),
        (0usize..3, -1.5f64..1.5).prop_map(|(c, v)| Event::Drive(c, v)),
        (0usize..3).prop_map(Event::Stop),
        (0usize..3).prop_map(Event::Release),
        (0usize..3).prop_map(Event::Resume),
        (0usize..3).prop_map(Event::Dies),
        (1u64..80).prop_map(Event::Stall),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Whatever clients do: commands stay on the 20 ms grid (a late tick is sent once and the
    /// grid resumes), a stop is on the wire in the iteration that took it, and nothing moves
    /// while the stop is latched.
    #[test]
    fn the_schedule_and_the_stop_hold_under_any_requests(
        protocol in prop_oneof![Just(Protocol::V1), Just(Protocol::V2)],
        events in prop::collection::vec(event(), 1..60),
    ) {
        let mut pair = Pair::of(protocol);
        let mut stops = Vec::new();
        let mut stalls = Vec::new();
        for event in events {
            match event {
                Event::Wait(millis) => pair.run(ms(millis)),
                Event::Drive(c, linear) => {
                    let (client, class) = CLIENTS[c];
                    let _ = pair.drive(client, class, linear);
                }
                Event::Stop(c) => {
                    stops.push(pair.now);
                    pair.request(CLIENTS[c].0, &Request::Stop { reason: "p".into() }).expect("a stop is never refused");
                }
                Event::Release(c) => { let _ = pair.request(CLIENTS[c].0, &Request::Release { target: ReleaseTarget::All, through: u64::MAX }); }
                Event::Resume(c) => { let _ = pair.request(CLIENTS[c].0, &Request::Resume); }
                Event::Dies(c) => {
                    pair.core.handle_client_gone(pair.now, CLIENTS[c].0.1);
                    pair.leases.remove(&CLIENTS[c].0.1);
                }
                Event::Stall(millis) => {
                    stalls.push(pair.now);
                    pair.stall(ms(millis));
                }
            }
        }
        pair.run(ms(100));
        let commands = pair.motion_commands();
        for stop in &stops {
            let zero = commands.iter().find(|(at, c)| at == stop && c.linear == 0.0);
            prop_assert!(zero.is_some(), "no zero command at the stop's time {stop:?}");
        }
        // Stops between ticks only shorten the gaps: every gap is at most a tick, or has a stall.
        let mut ticks: Vec<Duration> = commands.iter().map(|(at, _)| *at).collect();
        ticks.dedup();
        for pair in ticks.windows(2) {
            let stalled = stalls.iter().any(|at| *at >= pair[0] && *at < pair[1]);
            prop_assert!(pair[1] - pair[0] <= TICK || stalled, "gap {:?} at {:?}", pair[1] - pair[0], pair[0]);
        }
        for status in pair.statuses().iter().map(|(_, s)| s).filter(|s| s.stopped()) {
            prop_assert_eq!(status.output_linear, 0.0);
        }
    }
}

/// The chassis' actual speed stays at zero from `pair.now` for `time`.
fn stays_still(pair: &mut Pair, client: Client, time: Duration) {
    let answers = pair.keep_streaming(client, 0.5, time);
    assert!(
        answers.iter().all(Result::is_err),
        "the old stream is refused"
    );
    assert_eq!(
        pair.chassis.actual().linear,
        0.0,
        "the chassis does not move"
    );
    let moving = pair
        .motion_commands()
        .into_iter()
        .rev()
        .take(10)
        .any(|(_, command)| command.linear != 0.0);
    assert!(!moving, "only zero commands go out");
}

/// Releases every stop as the operator and checks that still nothing moves.
fn release_and_check_nothing_restarts(pair: &mut Pair, client: Client) {
    pair.request(
        OPERATOR,
        &Request::Release {
            target: ReleaseTarget::All,
            through: u64::MAX,
        },
    )
    .expect("the operator releases once the causes are gone");
    assert!(pair.stops().is_empty());
    stays_still(pair, client, Duration::from_secs(1));
    // A deliberate take of control, and it drives again.
    pair.leases.remove(&client.1);
    pair.stream(client, Class::Teleop, 0.5, Duration::from_secs(2));
    assert!(pair.chassis.actual().linear > 0.3);
}

fn a_link_lost_and_back_does_not_restart_a_streaming_client(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    pair.unplug();
    assert_eq!(pair.stops(), [("gateway".into(), StopCause::LinkLost)]);
    let refused = pair.send_drive(TELEOP, 0.5).expect_err("revoked");
    assert!(refused.reason.contains("link_lost"), "{}", refused.reason);
    // The chassis stopped by its own timeout; the port comes back.
    pair.keep_streaming(TELEOP, 0.5, Duration::from_secs(1));
    pair.plugged = true;
    pair.run_until(Duration::from_secs(3), |p| {
        p.last_state().link.state() == LinkState::Ok
    });
    stays_still(&mut pair, TELEOP, Duration::from_secs(2));
    release_and_check_nothing_restarts(&mut pair, TELEOP);
}

fn a_silent_chassis_is_a_gap_that_holds_until_it_speaks_again(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    pair.feedback = false;
    pair.keep_streaming(TELEOP, 0.5, CHASSIS_TIMEOUT + ms(100));
    assert_eq!(pair.stops(), [("gateway".into(), StopCause::ChassisSilent)]);
    let refused = pair
        .request(
            OPERATOR,
            &Request::Release {
                target: ReleaseTarget::All,
                through: u64::MAX,
            },
        )
        .expect_err("the chassis is still silent");
    assert_eq!(refused.kind, Some(RejectionKind::CausePersists));
    pair.feedback = true;
    stays_still(&mut pair, TELEOP, Duration::from_secs(1));
    release_and_check_nothing_restarts(&mut pair, TELEOP);
}

fn a_chassis_estop_episode_does_not_restart_motion(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::EStop(true));
    pair.keep_streaming(TELEOP, 0.5, ms(200));
    let causes: Vec<StopCause> = pair.stops().into_iter().map(|(_, cause)| cause).collect();
    assert!(causes.contains(&StopCause::ChassisEstop), "{causes:?}");
    let held = pair
        .request(
            OPERATOR,
            &Request::Release {
                target: ReleaseTarget::All,
                through: u64::MAX,
            },
        )
        .expect_err("the e-stop is still pressed");
    assert_eq!(held.kind, Some(RejectionKind::CausePersists));
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::EStop(false));
    pair.chassis.inject(
        at,
        Injection::MotorCommFault(scout_protocol::Motor::ALL[0], false),
    );
    for motor in scout_protocol::Motor::ALL {
        pair.chassis
            .inject(at, Injection::MotorCommFault(motor, false));
    }
    pair.request(OPERATOR, &Request::ClearFault(None))
        .expect("clear the latched comm faults");
    stays_still(&mut pair, TELEOP, Duration::from_secs(2));
    release_and_check_nothing_restarts(&mut pair, TELEOP);
}

fn rc_and_latched_protections_are_gaps(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.3, Duration::from_secs(1));
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::Rc(true));
    pair.run(ms(100));
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::RcOverride))
    );
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::Rc(false));
    pair.chassis
        .inject(at, Injection::Protect(Protection::DriverOvertemp));
    pair.run(ms(100));
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::ChassisFault))
    );
    let status = pair.statuses().last().expect("status").1;
    let fault = status
        .stops()
        .iter()
        .find(|s| s.cause == StopCause::ChassisFault.raw())
        .expect("listed");
    assert!(fault.persists, "the protection is still latched");
    // v2's error word has one bit for a driver's protections.
    let named = match protocol {
        Protocol::V1 => "driver_overtemp_protection",
        Protocol::V2 => "motor_driver",
    };
    assert!(
        fault.reason.as_str().contains(named),
        "{}",
        fault.reason.as_str()
    );
}

fn after_an_unclean_exit_the_gateway_starts_stopped(protocol: Protocol) {
    let config = config(protocol);
    let mut pair = Pair::starting(Transport::Sim, &config, Start::AfterUncleanExit);
    assert_eq!(pair.stops(), [("gateway".into(), StopCause::GatewayStart)]);
    let refused = pair.take(TELEOP, Class::Teleop).expect_err("stopped");
    assert_eq!(refused.kind, Some(RejectionKind::Latched));
    pair.run(Duration::from_secs(1));
    assert_eq!(pair.chassis.actual().linear, 0.0);
    release_and_check_nothing_restarts(&mut pair, TELEOP);
    // A clean start: no stop, but autonomy disarmed until a resume.
    let mut clean = Pair::of(protocol);
    assert!(clean.stops().is_empty());
    let disarmed = clean.take(AUTONOMY, Class::Autonomy).expect_err("disarmed");
    assert_eq!(disarmed.kind, Some(RejectionKind::AutonomyDisarmed));
}

fn a_tick_later_than_the_chassis_timeout_is_an_overrun(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    pair.now = pair.core.poll_timeout();
    pair.stall(CHASSIS_TIMEOUT + ms(100));
    pair.step();
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::Overrun))
    );
    let status = pair.statuses().last().expect("status").1;
    assert!(
        status.tick_max_lateness_ms >= 600.0,
        "{}",
        status.tick_max_lateness_ms
    );
}

fn a_pause_every_host_clock_hides_shows_in_the_chassis_reports(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    // The review's case: both clocks held back 2 s; the chassis braked by its own timeout.
    pair.freeze_host_clocks(Duration::from_secs(2));
    assert_eq!(pair.chassis.actual().linear, 0.0, "the chassis braked");
    let before = pair.motion_commands().len();
    let answers = pair.keep_streaming(TELEOP, 0.5, ms(500));
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::Overrun)),
        "{:?}",
        pair.stops()
    );
    assert!(answers.iter().all(Result::is_err), "the stream is revoked");
    let after = &pair.motion_commands()[before..];
    assert!(
        after.iter().all(|(_, command)| command.linear == 0.0),
        "nothing moves after the pause: {after:?}"
    );
    assert_eq!(pair.chassis.actual().linear, 0.0);
    // A pause shorter than the chassis' timeout is a burst, not a gap: it drives on.
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    pair.freeze_host_clocks(ms(200));
    pair.stream(TELEOP, Class::Teleop, 0.5, ms(300));
    assert!(pair.stops().is_empty(), "{:?}", pair.stops());
}

/// Streams, freezes the gateway for `stall` (SIGSTOP, starved of CPU) at `phase` into a tick,
/// and streams on; returns whether an overrun latched, the largest gap between two motion
/// commands written, and whether a command after the stall moved the robot.
fn stall_and_stream_on(
    protocol: Protocol,
    stall: Duration,
    phase: Duration,
) -> (bool, Duration, bool) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    pair.now += phase;
    pair.step();
    pair.stall(stall);
    let before = pair.motion_commands().len();
    let answers = pair.keep_streaming(TELEOP, 0.5, ms(300));
    let after = pair.motion_commands();
    let times: Vec<Duration> = after.iter().map(|(at, _)| *at).collect();
    let widest = intervals(&times).into_iter().max().unwrap_or_default();
    let moved_after = after[before..]
        .iter()
        .any(|(_, command)| command.linear != 0.0);
    let overrun = pair
        .stops()
        .contains(&("gateway".into(), StopCause::Overrun));
    assert!(
        !overrun || answers.iter().all(Result::is_err),
        "after an overrun every command is refused"
    );
    (overrun, widest, moved_after)
}

fn a_stall_that_may_have_let_the_chassis_time_out_latches_an_overrun(protocol: Protocol) {
    // The review's SIGSTOP of 487-497 ms: wire gaps of 500-511 ms, and the old speed resumed.
    for stall in [410, 450, 487, 497, 600] {
        let (overrun, widest, moved) = stall_and_stream_on(protocol, ms(stall), ms(7));
        assert!(
            overrun,
            "a {stall} ms stall (a {widest:?} wire gap) latches"
        );
        assert!(!moved, "nothing moves after a {stall} ms stall");
    }
    // An ordinary stall (the review saw 109 ms) resumes.
    let (overrun, widest, moved) = stall_and_stream_on(protocol, ms(109), ms(7));
    assert!(!overrun && moved, "{widest:?}");
}

/// A suspend of the host (a laptop's lid, a robot computer's power saving) as the gateway's
/// clock (CLOCK_BOOTTIME, which counts it) shows it: the clock skips 2 s between two iterations
/// while the client, on the same clock, streams on at once after it. The chassis stopped by its
/// own timeout meanwhile: a stop latches and nothing moves until a release and a new take.
fn a_suspend_of_the_host_is_a_gap_and_moves_nothing(protocol: Protocol) {
    for phase in [ms(0), ms(7), ms(19)] {
        let (overrun, widest, moved) = stall_and_stream_on(protocol, ms(2000), phase);
        assert!(overrun, "a suspend (a {widest:?} wire gap) latches");
        assert!(!moved, "nothing moves after a suspend");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    /// Any stall at any phase: a wire gap the chassis could have timed out on (over
    /// WIRE_GAP_LIMIT) always latches, and only a gap over it does.
    #[test]
    fn every_wire_gap_beyond_the_limit_latches(
        protocol in prop_oneof![Just(Protocol::V1), Just(Protocol::V2)],
        stall_ms in 0u64..900,
        phase_us in 0u64..20_000,
    ) {
        let (overrun, widest, moved) =
            stall_and_stream_on(protocol, ms(stall_ms), Duration::from_micros(phase_us));
        prop_assert_eq!(overrun, widest > WIRE_GAP_LIMIT, "stall {} ms, widest gap {:?}", stall_ms, widest);
        if widest >= CHASSIS_TIMEOUT {
            prop_assert!(overrun && !moved);
        }
    }
}

/// Whether feedback of `linear_mm_s` and `angular_mrad_s`, while nothing is commanded, for
/// longer than the runaway time, latches a runaway.
fn feedback_latches_a_runaway(protocol: Protocol, linear_mm_s: i16, angular_mrad_s: i16) -> bool {
    let mut pair = Pair::of(protocol);
    pair.run(ms(200));
    pair.feedback = false;
    for i in 0..40u8 {
        pair.inject_motion(linear_mm_s, angular_mrad_s, 100 + i);
        pair.now += TICK;
        pair.step();
    }
    pair.stops()
        .contains(&("gateway".into(), StopCause::Runaway))
}

fn a_chassis_faster_than_commanded_is_a_runaway(protocol: Protocol) {
    assert!(feedback_latches_a_runaway(protocol, 1000, 0), "1 m/s");
    // The review's case: still turning at 0.27 rad/s long after the command fell to zero.
    assert!(feedback_latches_a_runaway(protocol, 0, 270), "0.27 rad/s");
    assert!(feedback_latches_a_runaway(protocol, 0, -270), "-0.27 rad/s");
    // Within the tolerances: no runaway.
    assert!(!feedback_latches_a_runaway(protocol, 200, 100));
}

fn a_can_fault_latches_and_the_first_command_after_recovery_is_zero(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    let failed = pair.now;
    pair.open = false;
    pair.core.handle_link_fault(
        pair.now,
        "writing: No buffer space available (os error 105)",
    );
    pair.run(Duration::from_secs(1));
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::LinkFault))
    );
    let (_, first) = pair
        .motion_commands()
        .into_iter()
        .find(|(at, _)| *at > failed)
        .expect("commands after the reopen");
    assert_eq!(first.linear, 0.0);
}

fn a_stop_comes_through_the_stop_service_with_every_control_slot_taken(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    for port in 100..100 + scout_interface::control::MAX_CLIENTS as u128 {
        let client = Client("holder", port, false);
        pair.request(
            client,
            &Request::Heartbeat {
                period: Duration::from_secs(10),
            },
        )
        .expect("registered");
    }
    let late = Client("late-guard", 999, false);
    let full = pair.take(late, Class::Teleop).expect_err("table full");
    assert_eq!(full.kind, Some(RejectionKind::TooManyClients));
    pair.request(
        late,
        &Request::Stop {
            reason: "emergency".into(),
        },
    )
    .expect("never refused");
    assert_eq!(pair.stops(), [("late-guard".into(), StopCause::Client)]);
    // The stop service takes stops and releases only.
    let wire = Request::Resume.encode(1);
    let answer = pair
        .core
        .handle_request(pair.now, &late.origin(), Way::Stop, &wire)
        .answer();
    assert!(
        answer
            .expect_err("not a stop")
            .reason
            .contains("stops and releases only")
    );
}

fn the_frame_after_an_overrun_is_already_zero(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    let stalled = pair.core.poll_timeout();
    pair.now = stalled;
    pair.stall(CHASSIS_TIMEOUT + ms(100));
    pair.step();
    let (_, first) = pair
        .motion_commands()
        .into_iter()
        .find(|(at, _)| *at > stalled)
        .expect("a command after the stall");
    assert_eq!(first.linear, 0.0, "no motion after the chassis timed out");
}

fn a_chassis_exception_state_is_a_gap(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.run(ms(100));
    pair.feedback = false;
    pair.inject_system(2, 200);
    pair.step();
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::ChassisFault)),
        "{:?}",
        pair.stops()
    );
}

/// The 0x421 frames sent, with the mode each asked for.
fn mode_requests(pair: &Pair) -> Vec<(Duration, ControlModeV2)> {
    pair.v2_sent(|message| match message {
        MessageV2::ControlMode(mode) => Some(mode),
        _ => None,
    })
}

#[test]
fn v2_the_command_mode_is_taken_only_when_a_client_drives_and_before_its_first_motion() {
    let mut pair = Pair::of(Protocol::V2);
    pair.run(Duration::from_secs(2));
    assert!(mode_requests(&pair).is_empty(), "nothing taken at start-up");
    assert_eq!(pair.chassis.stats().control_mode, "standby");
    assert!(pair.motion_commands().iter().all(|(_, c)| c.linear == 0.0));
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    let requests = mode_requests(&pair);
    assert_eq!(requests.len(), 1, "one request, answered: {requests:?}");
    let (asked, mode) = requests[0];
    assert_eq!(mode, ControlModeV2::Can);
    let first_motion = pair
        .sent
        .iter()
        .position(|(_, frame)| {
            matches!(frame, Outgoing::V2(MessageV2::MotionCommand(c)) if c.linear_mm_s != 0)
        })
        .expect("it drove");
    let request = pair
        .sent
        .iter()
        .position(|(at, frame)| {
            *at == asked && matches!(frame, Outgoing::V2(MessageV2::ControlMode(_)))
        })
        .expect("sent");
    assert!(
        request < first_motion,
        "0x421 before the first motion on the wire"
    );
    assert!((pair.chassis.actual().linear - 0.5).abs() < 0.02);
    assert_eq!(
        pair.last_state().system.control_mode,
        ControlModeV2::Can.raw()
    );
    assert!(pair.stops().is_empty());
}

#[test]
fn v2_a_chassis_that_does_not_take_the_mode_latches_a_stop_that_says_what_to_check() {
    let mut pair = Pair::of(Protocol::V2);
    pair.mode_requests = false;
    pair.run(ms(500));
    pair.take(TELEOP, Class::Teleop).expect("take");
    let answers = pair.keep_streaming(TELEOP, 0.5, Duration::from_secs(2));
    assert!(answers.iter().any(Result::is_err), "revoked by the stop");
    assert_eq!(
        pair.stops(),
        [("gateway".to_owned(), StopCause::ChassisMode)]
    );
    let reason = pair.stop_reason(StopCause::ChassisMode);
    assert!(
        reason.contains("standby") && reason.contains("SWB"),
        "{reason}"
    );
    let requests = mode_requests(&pair);
    assert!(
        (5..=6).contains(&requests.len()),
        "repeated within the second: {requests:?}"
    );
    assert_eq!(pair.chassis.actual().linear, 0.0);
    // Fixed (SWB up): a release and a new take drive.
    pair.mode_requests = true;
    release_and_check_nothing_restarts(&mut pair, TELEOP);
}

#[test]
fn v2_standby_while_driving_stops_and_nothing_takes_the_mode_again_by_itself() {
    let mut pair = Pair::of(Protocol::V2);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::Standby);
    let lost_at = pair.now;
    pair.keep_streaming(TELEOP, 0.5, ms(300));
    assert_eq!(
        pair.stops(),
        [("gateway".to_owned(), StopCause::ChassisMode)]
    );
    stays_still(&mut pair, TELEOP, Duration::from_secs(2));
    assert!(
        mode_requests(&pair).iter().all(|(at, _)| *at < lost_at),
        "no 0x421 after the loss without a release and a new take"
    );
    release_and_check_nothing_restarts(&mut pair, TELEOP);
    assert_eq!(mode_requests(&pair).len(), 2, "the new take asked again");
}

#[test]
fn v2_the_rc_is_never_fought() {
    let mut pair = Pair::of(Protocol::V2);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::Rc(true));
    let rc_at = pair.now;
    pair.keep_streaming(TELEOP, 0.5, ms(300));
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::RcOverride))
    );
    // Clients keep trying to take control and drive while the RC holds the chassis.
    for _ in 0..50 {
        pair.leases.remove(&TELEOP.1);
        let _ = pair.drive(TELEOP, Class::Teleop, 0.5);
        pair.run(TICK);
    }
    assert!(
        mode_requests(&pair).iter().all(|(at, _)| *at < rc_at),
        "no 0x421 while the RC holds the chassis"
    );
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::Rc(false));
    pair.run(ms(300));
    assert_eq!(
        pair.chassis.stats().control_mode,
        "standby",
        "the RC left it in standby"
    );
    stays_still(&mut pair, TELEOP, Duration::from_secs(1));
    release_and_check_nothing_restarts(&mut pair, TELEOP);
}

#[test]
fn v2_exit_sends_zero_then_leaves_the_chassis_in_standby() {
    let mut pair = Pair::of(Protocol::V2);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    pair.core.handle_shutdown();
    let began = pair.now;
    pair.run_until(Duration::from_secs(1), |pair| pair.core.is_finished());
    let after: Vec<&Outgoing> = pair
        .sent
        .iter()
        .filter(|(at, _)| *at >= began)
        .map(|(_, frame)| frame)
        .collect();
    let zero = Outgoing::V2(MessageV2::MotionCommand(MotionV2::default()));
    let standby = Outgoing::V2(MessageV2::ControlMode(ControlModeV2::Standby));
    assert_eq!(after, [&zero, &zero, &zero, &zero, &zero, &standby]);
    assert_eq!(pair.chassis.stats().control_mode, "standby");
}

#[test]
fn v2_firmware_versions_are_asked_once_and_published() {
    let mut pair = Pair::of(Protocol::V2);
    pair.run(Duration::from_secs(1));
    let requests: Vec<MessageV2> = pair
        .v2_others()
        .into_iter()
        .map(|(_, message)| message)
        .filter(|message| matches!(message, MessageV2::VersionRequest(_)))
        .collect();
    assert_eq!(requests.len(), 2, "both forms, once: {requests:?}");
    let state = pair.last_state();
    assert!(state.firmware.received.valid);
    assert!(
        state.firmware.text.as_str().contains("scout-sim v2"),
        "{:?}",
        state.firmware.text.as_str()
    );
    assert!(
        state.firmware.versions.as_str().contains("sw 2.3"),
        "both forms answered, kept apart"
    );
}

#[test]
fn v2_lights_and_error_clears_go_out_as_v2_frames() {
    let mut pair = Pair::of(Protocol::V2);
    pair.run(ms(300));
    pair.request(
        OFFICER,
        &Request::Lights(LightsSetting::Manual(LightCommand {
            enabled: true,
            front: Light {
                mode: LightMode::Custom,
                brightness: 40,
            },
            rear: Light::default(),
        })),
    )
    .expect("lights");
    pair.run(ms(500));
    let lights = pair.light_commands();
    assert!(intervals(&lights).iter().all(|gap| *gap == ms(25)));
    let state = pair.last_state();
    assert!(state.lights.enabled);
    assert_eq!(state.lights.feedback().front.brightness, 40);
    let at = pair.now - pair.epoch;
    pair.chassis.inject(
        at,
        Injection::MotorCommFault(scout_protocol::Motor::ALL[1], true),
    );
    pair.run(ms(300));
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::ChassisFault))
    );
    pair.request(
        OPERATOR,
        &Request::ClearFault(Some(scout_protocol::FaultClear::Motor2Comm)),
    )
    .expect("clear");
    pair.run(ms(300));
    let clears: Vec<MessageV2> = pair
        .v2_others()
        .into_iter()
        .map(|(_, message)| message)
        .filter(|message| matches!(message, MessageV2::ErrorClear(_)))
        .collect();
    assert!(!clears.is_empty());
    assert!(
        clears
            .iter()
            .all(|c| *c == MessageV2::ErrorClear(scout_protocol::v2::ErrorClearV2::Motor2))
    );
    assert_eq!(pair.last_state().faults(), [], "cleared on the chassis");
}

#[test]
fn the_model_sets_the_limits_a_v2_chassis_is_driven_by() {
    for (model, fastest) in [(Model::Scout2, 1.5), (Model::ScoutMini, 2.5)] {
        let mut config = config(Protocol::V2);
        config.model = Some(model);
        config.arbiter.limits.linear_acceleration = 5.0;
        let mut pair = Pair::with_config(Transport::Sim, &config);
        let answer = pair.drive(TELEOP, Class::Teleop, 2.5).expect("accepted");
        assert_eq!(answer.clamped, fastest < 2.5, "{model}");
        pair.stream(TELEOP, Class::Teleop, 2.5, Duration::from_secs(4));
        let top = pair
            .motion_commands()
            .iter()
            .map(|(_, c)| c.linear)
            .fold(0.0, f64::max);
        assert_eq!(top, fastest, "{model}");
        let state = pair.last_state();
        assert_eq!(state.chassis.model(), Some(model));
        assert!((state.motion.linear() - fastest).abs() < 0.05, "{model}");
    }
}

#[test]
fn with_auto_nothing_goes_out_until_the_protocol_is_told_then_it_drives() {
    for firmware in Protocol::ALL {
        let config = GatewayConfig::default();
        let mut pair = Pair::with_firmware(firmware, Transport::Can, &config, Start::Clean);
        pair.run(ms(250));
        assert!(
            pair.sent.is_empty(),
            "{firmware}: listening: {:?}",
            pair.sent
        );
        assert_eq!(pair.core.link_protocol(), None);
        pair.run(ms(200));
        assert_eq!(pair.core.link_protocol(), Some(firmware));
        assert_eq!(pair.last_state().link.protocol(), Some(firmware));
        assert!(
            pair.sent
                .iter()
                .all(|(_, frame)| frame.protocol() == firmware)
        );
        pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
        assert!(
            (pair.chassis.actual().linear - 0.5).abs() < 0.02,
            "{firmware}"
        );
    }
}

#[test]
fn a_chassis_that_steers_its_wheels_is_not_driven_as_a_scout() {
    let mut pair = Pair::with_firmware(
        Protocol::V2,
        Transport::Can,
        &config(Protocol::V2),
        Start::Clean,
    );
    pair.run(ms(200));
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(1));
    assert!((pair.chassis.actual().linear - 0.5).abs() < 0.02);
    // A Ranger's motion-mode feedback (0x291) arrives: the drive stops at once, and stays.
    let unknown = scout_protocol::can::CanError::UnknownId {
        id: scout_protocol::v2::id::MOTION_MODE_STATE,
    };
    pair.core.handle_rx(
        pair.now,
        &RxEvent::Rejected(scout_protocol::link::RxError::Can(unknown)),
    );
    pair.run(ms(100));
    assert_eq!(pair.last_state().link.state(), LinkState::ProtocolMismatch);
    let reason = pair.stop_reason(StopCause::ChassisSilent);
    assert!(reason.contains("not a scout2"), "{reason}");
    let refused = pair.take(TELEOP, Class::Teleop).expect_err("stopped");
    assert_eq!(refused.kind, Some(RejectionKind::Latched));
    pair.run(ms(400));
    assert_eq!(pair.chassis.actual().linear, 0.0);
}

#[test]
fn a_chassis_of_the_other_protocol_moves_nothing_and_the_stop_says_why() {
    for firmware in Protocol::ALL {
        let gateway = firmware.other();
        let mut pair =
            Pair::with_firmware(firmware, Transport::Can, &config(gateway), Start::Clean);
        pair.run(ms(400));
        assert_eq!(pair.last_state().link.state(), LinkState::ProtocolMismatch);
        pair.run(ms(400));
        let reason = pair.stop_reason(StopCause::ChassisSilent);
        assert!(
            reason.contains(&format!("--protocol {firmware}")),
            "{reason}"
        );
        let refused = pair.take(TELEOP, Class::Teleop).expect_err("stopped");
        assert_eq!(refused.kind, Some(RejectionKind::Latched));
        assert!(
            pair.sent
                .iter()
                .all(|(_, frame)| frame.protocol() == gateway)
        );
        assert_eq!(pair.chassis.actual().linear, 0.0);
    }
}

/// A system state in `protocol` (v1's 0x151, v2's 0x211: either proves its protocol), the
/// chassis in CAN mode.
fn system_state(protocol: Protocol, state: scout_protocol::ChassisState, count: u8) -> RxEvent {
    match protocol {
        Protocol::V1 => RxEvent::Message(Counted {
            message: Message::SystemStatus(scout_protocol::SystemStatus {
                state,
                control_mode: scout_protocol::ControlMode::Can,
                battery_decivolts: 250,
                faults: scout_protocol::FaultBits::NONE,
            }),
            count,
        }),
        Protocol::V2 => RxEvent::V2(MessageV2::SystemState(SystemStateV2 {
            state,
            control_mode: ControlModeV2::Can,
            battery_decivolts: 250,
            errors: ErrorBitsV2(0),
            reserved: 0,
            count,
        })),
    }
}

#[test]
fn the_other_protocol_joining_the_bus_while_driving_stops_at_once_and_nothing_is_used() {
    for firmware in Protocol::ALL {
        for config in [config(firmware), GatewayConfig::default()] {
            let what = format!("{firmware} chassis, --protocol {:?}", config.protocol);
            let mut pair = Pair::with_firmware(firmware, Transport::Can, &config, Start::Clean);
            pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
            assert!(pair.chassis.actual().linear > 0.4, "{what}: drives");
            // Another chassis (or a node using its ids) of the other protocol joins.
            let joined = pair.now;
            let proof = system_state(firmware.other(), scout_protocol::ChassisState::Normal, 0);
            pair.core.handle_rx(joined, &proof);
            let answers = pair.keep_streaming(TELEOP, 0.5, ms(100));
            assert!(answers.iter().any(Result::is_err), "{what}: revoked");
            let first_zero = pair
                .motion_commands()
                .into_iter()
                .find(|(at, command)| *at >= joined && command.linear == 0.0)
                .map(|(at, _)| at)
                .expect("a zero command");
            assert!(
                first_zero - joined <= TICK,
                "{what}: the stop went out {:?} after",
                first_zero - joined
            );
            assert_eq!(
                pair.last_state().link.state(),
                LinkState::ProtocolMismatch,
                "{what}"
            );
            let stop = pair.stop_reason(StopCause::ChassisSilent);
            assert!(stop.contains("both protocols"), "{what}: {stop}");
            // Nothing the bus says is used any more, and nothing moves until the port reopens.
            let rejected = pair.last_state().link.rejected_frames;
            pair.run(ms(200));
            assert!(pair.last_state().link.rejected_frames > rejected, "{what}");
            let refused = pair.take(TELEOP, Class::Teleop).expect_err("stopped");
            assert_eq!(refused.kind, Some(RejectionKind::Latched), "{what}");
            pair.run(Duration::from_secs(1));
            assert_eq!(pair.chassis.actual().linear, 0.0, "{what}");
        }
    }
}

#[test]
fn v2_a_stop_while_the_mode_is_asked_ends_the_asking() {
    let mut pair = Pair::of(Protocol::V2);
    pair.mode_requests = false;
    pair.run(ms(500));
    pair.take(TELEOP, Class::Teleop).expect("take");
    pair.keep_streaming(TELEOP, 0.5, ms(100));
    assert_eq!(mode_requests(&pair).len(), 1);
    pair.request(
        OFFICER,
        &Request::Stop {
            reason: "person ahead".into(),
        },
    )
    .expect("a stop is accepted");
    let stopped = pair.now;
    pair.mode_requests = true;
    pair.keep_streaming(TELEOP, 0.5, Duration::from_secs(2));
    assert!(
        mode_requests(&pair).iter().all(|(at, _)| *at < stopped),
        "no 0x421 after the stop: {:?}",
        mode_requests(&pair)
    );
    assert_eq!(pair.chassis.stats().control_mode, "standby");
    assert_eq!(
        pair.stops(),
        [("officer".to_owned(), StopCause::Client)],
        "no take timeout said on top of the stop"
    );
}

#[test]
fn v2_an_rc_episode_hidden_in_lost_feedback_is_not_followed_by_a_take() {
    let mut pair = Pair::of(Protocol::V2);
    pair.mode_requests = false;
    pair.run(ms(500));
    pair.take(TELEOP, Class::Teleop).expect("take");
    pair.keep_streaming(TELEOP, 0.5, ms(40));
    assert_eq!(mode_requests(&pair).len(), 1, "asked");
    // The feedback is lost for 400 ms (less than the chassis timeout), and meanwhile a person
    // switches the RC on and off again: the chassis is in standby after it.
    pair.feedback = false;
    pair.keep_streaming(TELEOP, 0.5, ms(100));
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::Rc(true));
    pair.keep_streaming(TELEOP, 0.5, ms(150));
    let at = pair.now - pair.epoch;
    pair.chassis.inject(at, Injection::Rc(false));
    pair.keep_streaming(TELEOP, 0.5, ms(150));
    pair.feedback = true;
    pair.mode_requests = true;
    pair.keep_streaming(TELEOP, 0.5, Duration::from_secs(2));
    assert_eq!(
        mode_requests(&pair).len(),
        1,
        "not asked again after the gap"
    );
    assert_eq!(pair.chassis.stats().control_mode, "standby");
    assert_eq!(pair.chassis.actual().linear, 0.0);
    assert_eq!(
        pair.stops(),
        [("gateway".to_owned(), StopCause::ChassisMode)]
    );
    let reason = pair.stop_reason(StopCause::ChassisMode);
    assert!(reason.contains("0x211 lost"), "{reason}");
}

#[test]
fn v2_nothing_is_asked_before_the_chassis_reports_its_mode() {
    // The RC holds the chassis from power-on; a client is taking control as the port opens.
    let mut pair = Pair::of(Protocol::V2);
    pair.chassis.inject(Duration::ZERO, Injection::Rc(true));
    pair.take(TELEOP, Class::Teleop).expect("take at once");
    pair.keep_streaming(TELEOP, 0.5, Duration::from_secs(1));
    assert!(
        mode_requests(&pair).is_empty(),
        "no 0x421 before a 0x211 said the RC holds it: {:?}",
        mode_requests(&pair)
    );
    assert!(
        pair.stops()
            .contains(&("gateway".into(), StopCause::RcOverride))
    );
    assert_eq!(pair.chassis.stats().control_mode, "rc");
}

#[test]
fn with_auto_a_chassis_that_says_nothing_is_a_stop_that_says_so() {
    let mut pair = Pair::with_firmware(
        Protocol::V1,
        Transport::Can,
        &GatewayConfig::default(),
        Start::Clean,
    );
    pair.feedback = false;
    pair.run(ms(700));
    let reason = pair.stop_reason(StopCause::ChassisSilent);
    assert!(reason.contains("nothing received"), "{reason}");
    assert!(
        pair.sent.is_empty(),
        "nothing sent while the protocol is not told"
    );
}

/// Runs each scenario against a chassis of each protocol: `on_v1::NAME` and `on_v2::NAME`.
/// A critical battery under each policy: a teleop is never touched; autonomy is refused a take
/// (and with `stop-autonomy` loses control); a recharged battery restarts nothing.
fn a_critical_battery_bars_autonomy_and_never_teleop(protocol: Protocol) {
    for policy in [OnCritical::RefuseAutonomy, OnCritical::StopAutonomy] {
        let mut config = config(protocol);
        config.battery.on_critical = policy;
        let mut pair = Pair::with_config(Transport::Can, &config);
        pair.request(AUTONOMY, &Request::Resume).expect("resume");
        pair.stream(AUTONOMY, Class::Autonomy, 0.4, Duration::from_secs(1));
        // The pack runs down to 24.2 V at rest (7 %): critical once the estimate has
        // followed it down.
        let at = pair.now - pair.epoch;
        pair.chassis.inject(at, Injection::Battery(24.2));
        let mut refused = None;
        for _ in 0..(60 * 50) {
            if pair.last_state().battery.level() == BatteryLevel::Critical {
                break;
            }
            if let Err(rejected) = pair.drive(AUTONOMY, Class::Autonomy, 0.4) {
                refused = Some(rejected);
                break;
            }
            pair.run(TICK);
        }
        for _ in 0..5 {
            if let Err(rejected) = pair.drive(AUTONOMY, Class::Autonomy, 0.4) {
                refused.get_or_insert(rejected);
            }
        }
        assert_eq!(pair.last_state().battery.level(), BatteryLevel::Critical);
        match policy {
            OnCritical::StopAutonomy => {
                let refused = refused.expect("autonomy lost control");
                assert!(refused.reason.contains("battery critical"), "{refused:?}");
                pair.run(Duration::from_secs(2));
                assert_eq!(
                    pair.chassis.actual().linear,
                    0.0,
                    "autonomy's output ramped to zero"
                );
            }
            OnCritical::RefuseAutonomy | OnCritical::Warn => {
                assert!(
                    refused.is_none(),
                    "a running autonomy drives on: {refused:?}"
                );
                // Its take again (a client reconnecting) keeps the control it holds.
                pair.take(AUTONOMY, Class::Autonomy)
                    .expect("a held lease is no new take");
                pair.request(AUTONOMY, &Request::Relinquish)
                    .expect("relinquish");
                pair.leases.remove(&AUTONOMY.1);
            }
        }
        let barred = pair
            .take(AUTONOMY, Class::Autonomy)
            .expect_err("no new autonomy on a critical battery");
        assert_eq!(barred.kind, Some(RejectionKind::NotAllowed), "{barred:?}");
        assert!(barred.reason.contains("battery critical"), "{barred:?}");
        let status = pair.statuses().last().expect("status").1;
        assert_eq!(status.battery_level, BatteryLevel::Critical.raw());
        // The teleop drives it home.
        pair.stream(TELEOP, Class::Teleop, 0.3, Duration::from_secs(1));
        assert!(
            pair.chassis.actual().linear > 0.2,
            "{:?}",
            pair.chassis.actual()
        );
        pair.request(TELEOP, &Request::Relinquish)
            .expect("relinquish");
        pair.leases.remove(&TELEOP.1);
        // Charged: the bar lifts, nothing moves until autonomy takes control again.
        let at = pair.now - pair.epoch;
        pair.chassis.inject(at, Injection::Battery(26.0));
        pair.run(Duration::from_secs(90));
        assert_eq!(pair.last_state().battery.level(), BatteryLevel::Ok);
        assert_eq!(pair.chassis.actual().linear, 0.0, "nothing restarted");
        // (The teleop's take disarmed autonomy, as any teleop takeover does.)
        pair.request(AUTONOMY, &Request::Resume).expect("resume");
        pair.take(AUTONOMY, Class::Autonomy)
            .expect("autonomy may take again");
    }
}

/// The black box is due on every stop that latches and on a client's request, once each.
fn the_black_box_is_due_on_a_stop_and_on_request(protocol: Protocol) {
    let mut pair = Pair::of(protocol);
    pair.run(ms(200));
    assert_eq!(pair.core.poll_black_box(), None, "nothing yet");
    pair.request(
        OFFICER,
        &Request::Stop {
            reason: "a test".into(),
        },
    )
    .expect("stop");
    let due = pair.core.poll_black_box().expect("due on the stop");
    assert!(
        due.starts_with("stop #1 by officer (client): a test"),
        "{due}"
    );
    assert_eq!(pair.core.poll_black_box(), None, "once");
    pair.request(TELEOP, &Request::SaveBlackBox).expect("save");
    assert_eq!(
        pair.core.poll_black_box().as_deref(),
        Some("asked by joystick")
    );
    assert_eq!(pair.core.poll_black_box(), None);
}

macro_rules! both_protocols {
    ($($name:ident),+ $(,)?) => {
        mod on_v1 {
            $(#[test]
            fn $name() {
                super::$name(scout_protocol::version::Protocol::V1);
            })+
        }
        mod on_v2 {
            $(#[test]
            fn $name() {
                super::$name(scout_protocol::version::Protocol::V2);
            })+
        }
    };
}

both_protocols!(
    motion_commands_go_out_on_the_20_ms_grid_for_ten_minutes,
    a_late_tick_is_sent_once_and_the_missed_ones_are_skipped,
    a_stop_goes_on_the_wire_at_once_not_at_the_next_tick,
    teleop_drives_the_chassis_and_a_stale_stream_stops_at_its_life,
    a_dead_client_loses_control_at_once,
    a_critical_battery_bars_autonomy_and_never_teleop,
    the_black_box_is_due_on_a_stop_and_on_request,
    state_is_published_per_feedback_on_link_changes_and_every_100_ms_while_silent,
    status_is_published_on_change_and_once_a_second,
    odometry_reset_is_answered_and_published,
    shutdown_sends_zero_for_the_configured_cycles_then_finishes,
    malformed_requests_are_answered_and_counted,
    a_link_lost_and_back_does_not_restart_a_streaming_client,
    a_silent_chassis_is_a_gap_that_holds_until_it_speaks_again,
    a_chassis_estop_episode_does_not_restart_motion,
    rc_and_latched_protections_are_gaps,
    a_tick_later_than_the_chassis_timeout_is_an_overrun,
    a_can_fault_latches_and_the_first_command_after_recovery_is_zero,
    a_stop_comes_through_the_stop_service_with_every_control_slot_taken,
    the_frame_after_an_overrun_is_already_zero,
    a_failed_port_is_reopened_with_a_doubling_backoff,
    after_an_unclean_exit_the_gateway_starts_stopped,
    a_stall_that_may_have_let_the_chassis_time_out_latches_an_overrun,
    a_pause_every_host_clock_hides_shows_in_the_chassis_reports,
    a_suspend_of_the_host_is_a_gap_and_moves_nothing,
    a_chassis_faster_than_commanded_is_a_runaway,
    a_chassis_exception_state_is_a_gap,
);

impl Pair {
    /// Drives sideways at `lateral` m/s (and forward at `linear`) under `client`'s lease every
    /// 20 ms for `time`; the first refusal, if any.
    fn stream_body(
        &mut self,
        client: Client,
        (linear, lateral): (f64, f64),
        time: Duration,
    ) -> Result<(), Rejected> {
        if !self.leases.contains_key(&client.1) {
            self.take(client, Class::Teleop)?;
        }
        let lease = self.leases[&client.1];
        let end = self.now + time;
        while self.now < end {
            let drive = Request::Drive {
                lease,
                linear,
                lateral,
                angular: 0.0,
                ttl: None,
                mode: None,
            };
            self.request(client, &drive)?;
            let next = self.now + TICK;
            while self.now < next {
                self.step();
            }
        }
        Ok(())
    }
}

#[test]
fn the_omni_moves_sideways_on_v2_and_its_odometry_follows() {
    let omni = GatewayConfig {
        model: Some(Model::ScoutMiniOmni),
        ..config(Protocol::V2)
    };
    let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &omni, Start::Clean);
    pair.run(ms(200));
    pair.stream_body(TELEOP, (0.0, 0.4), Duration::from_secs(2))
        .expect("sideways accepted");
    // On the wire: 0x111's lateral field (bytes 4-5, mm/s); the chassis moves left.
    assert_eq!(
        pair.chassis.stats().last_command.map(|c| c.lateral),
        Some(0.4)
    );
    assert!((pair.chassis.actual().lateral - 0.4).abs() < 0.02);
    let state = pair.last_state();
    assert!(
        (state.command.lateral - 0.4).abs() < 1e-9,
        "{:?}",
        state.command
    );
    let odometry = state.odometry;
    let truth = pair.chassis.pose();
    assert!(truth.y > 0.5, "{truth:?}");
    assert!(
        (odometry.y - truth.y).abs() < 0.05 * truth.y && odometry.x.abs() < 0.02,
        "odometry {odometry:?} against the chassis' {truth:?}"
    );
    // A stop: zero on every axis at once.
    pair.request(
        TELEOP,
        &Request::Stop {
            reason: "person".into(),
        },
    )
    .expect("stop");
    pair.run(ms(40));
    assert_eq!(pair.last_state().command.lateral, 0.0);
}

#[test]
fn sideways_is_refused_where_the_chassis_or_its_protocol_cannot() {
    for (model, protocol, says) in [
        (
            Model::Scout2,
            Protocol::V2,
            "a scout2 does not move sideways",
        ),
        (
            Model::ScoutMini,
            Protocol::V2,
            "a scout-mini does not move sideways",
        ),
        (
            Model::ScoutMiniOmni,
            Protocol::V1,
            "moves sideways on protocol v2 only",
        ),
    ] {
        let gateway = GatewayConfig {
            model: Some(model),
            ..config(protocol)
        };
        let mut pair = Pair::with_firmware(protocol, Transport::Can, &gateway, Start::Clean);
        pair.run(ms(200));
        let refused = pair
            .stream_body(TELEOP, (0.3, 0.2), ms(100))
            .expect_err("refused");
        assert_eq!(refused.kind, Some(RejectionKind::NotAllowed), "{model}");
        assert!(refused.reason.contains(says), "{model}: {}", refused.reason);
        pair.run(ms(200));
        assert_eq!(pair.chassis.actual().linear, 0.0, "{model}: refused whole");
    }
}

/// Drives at `velocity` (forward, sideways, yaw rate) as teleop under `lease` for `ticks`
/// ticks, the command taken or clamped, never refused; keeps in `most` the largest of each
/// field sent (forward, yaw-rate field, sideways field, steering field).
fn drive_ticks(
    pair: &mut Pair,
    lease: u64,
    (linear, lateral, angular): (f64, f64, f64),
    ticks: u32,
    most: &mut [f64; 4],
) {
    for _ in 0..ticks {
        let drive = Request::Drive {
            lease,
            linear,
            lateral,
            angular,
            ttl: None,
            mode: None,
        };
        if let Err(refused) = pair.request(TELEOP, &drive) {
            panic!("capped, not refused: {refused:?}");
        }
        let next = pair.now + TICK;
        while pair.now < next {
            pair.step();
        }
        let sent = pair.chassis.stats().last_command.expect("commands");
        for (most, sent) in
            most.iter_mut()
                .zip([sent.linear, sent.angular, sent.lateral, sent.steering])
        {
            *most = most.max(sent.abs());
        }
    }
}

/// A person's stop: the very next frame is zero on every field.
fn stops_at_once_on_every_field(pair: &mut Pair, model: Model) {
    pair.request(
        TELEOP,
        &Request::Stop {
            reason: "person".into(),
        },
    )
    .expect("stop");
    pair.step();
    let sent = pair.chassis.stats().last_command.expect("commands");
    assert_eq!(
        (sent.linear, sent.angular, sent.lateral, sent.steering),
        (0.0, 0.0, 0.0, 0.0),
        "{model}: a stop at once"
    );
}

/// For every model on v2: asked far beyond its limits on every axis it moves, what goes on the
/// wire is at most its limits (a limit off the wire's unit rounds down: the SCOUT's 0.5235
/// rad/s is 523 mrad/s), a steered one never gets a yaw rate in the yaw-rate field and its
/// wheels never beyond their widest angle, and a stop is zero on every field at once.
#[test]
fn no_model_receives_more_than_its_limits_and_a_stop_is_zero_on_every_field() {
    // The Rangers' fields depend on their mode: a_ranger_changes_mode_standing_still_... .
    for model in Model::ALL
        .into_iter()
        .filter(|model| model.speaks(Protocol::V2) && model.four_wheel().is_none())
    {
        let gateway = GatewayConfig {
            model: Some(model),
            ..config(Protocol::V2)
        };
        let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &gateway, Start::Clean);
        pair.run(ms(200));
        let limits = model.limits();
        let steering = model.steering();
        let lease = pair.take(TELEOP, Class::Teleop).expect("a lease");
        // linear, yaw-rate field, lateral, steering field.
        let mut most = [0.0_f64; 4];
        // One axis at a time, then all three (a chassis that does everything at once at its
        // limits draws more than the simulated pack gives). A steered chassis turns only
        // while it moves.
        let lateral = if limits.lateral > 0.0 { 40.0 } else { 0.0 };
        let turning = if steering.is_some() { 40.0 } else { 0.0 };
        for (linear, lateral, angular, ticks) in [
            (turning, 0.0, 40.0, 100),
            (0.0, 0.0, 0.0, 100),
            (-40.0, 0.0, 0.0, 175),
            (0.0, 0.0, 0.0, 175),
            (0.0, lateral, 0.0, 125),
            (0.0, 0.0, 0.0, 125),
            (40.0, -lateral, -40.0, 25),
        ] {
            drive_ticks(
                &mut pair,
                lease,
                (linear, lateral, angular),
                ticks,
                &mut most,
            );
        }
        let [linear, angular, lateral, steered] = most;
        assert!(
            linear <= limits.linear && linear > limits.linear - 0.001,
            "{model}: {most:?} against {limits:?}"
        );
        assert!(
            lateral <= limits.lateral && lateral > limits.lateral - 0.001,
            "{model}: {most:?} against {limits:?}"
        );
        match steering {
            Some(steering) => {
                assert_eq!(angular, 0.0, "{model}: no yaw rate in the yaw-rate field");
                let widest = steering.inner_from_central(steering.max_central);
                assert!(
                    steered <= steering.max_inner && steered > widest - 0.001,
                    "{model}: {most:?} against {steering:?}"
                );
            }
            None => {
                assert!(
                    angular <= limits.angular && angular > limits.angular - 0.001,
                    "{model}: {most:?} against {limits:?}"
                );
                assert_eq!(steered, 0.0, "{model}: nothing in the steering field");
            }
        }
        stops_at_once_on_every_field(&mut pair, model);
    }
}

/// What a client does to a chassis of any model, for the property test below.
#[derive(Debug, Clone)]
enum Ask {
    /// Nothing for this long, ms.
    Wait(u64),
    /// Streams a velocity (forward, sideways, yaw rate), perhaps in a named mode, for so many
    /// ticks; takes control first when it holds none.
    Drive((f64, f64, f64), Option<DriveMode>, u32),
    /// A person's stop.
    Stop,
    /// The operator releases every stop.
    Release,
}

fn ask() -> impl Strategy<Value = Ask> {
    let speed = -8.0f64..8.0;
    let sideways = prop_oneof![3 => Just(0.0), 1 => -8.0f64..8.0];
    let mode = prop_oneof![
        3 => Just(None),
        1 => prop::sample::select(DriveMode::ALL).prop_map(Some),
    ];
    prop_oneof![
        1 => (1u64..400).prop_map(Ask::Wait),
        4 => ((speed.clone(), sideways, speed), mode, 1u32..80)
            .prop_map(|(velocity, mode, ticks)| Ask::Drive(velocity, mode, ticks)),
        1 => Just(Ask::Stop),
        1 => Just(Ask::Release),
    ]
}

/// The most each field of 0x111 may carry on `model`, as its mapping lays the fields out
/// (forward, yaw-rate field, sideways field, steering field): its limits where they go, zero
/// where nothing does.
fn wire_limits(model: Model) -> [f64; 4] {
    let limits = model.limits();
    match (model.drive(), model.steering(), model.four_wheel()) {
        (Drive::Ackermann, Some(steering), _) => [limits.linear, 0.0, 0.0, steering.max_inner],
        (Drive::FourWheelSteering, _, Some(four)) => {
            let widest = four.max_inner.max(four.max_parallel);
            match four.spin_in_lateral {
                true => [limits.linear, 0.0, limits.angular, widest],
                false => [limits.linear, limits.angular, 0.0, widest],
            }
        }
        (Drive::Mecanum, ..) => [limits.linear, limits.angular, limits.lateral, 0.0],
        (Drive::SkidSteer | Drive::Differential | Drive::Tracked, ..) => {
            [limits.linear, limits.angular, 0.0, 0.0]
        }
        (Drive::Ackermann | Drive::FourWheelSteering, ..) => {
            unreachable!("{model}: a steered model without its steering")
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    /// For every model on v2, whatever a client asks (any velocity on every axis, far beyond
    /// the limits, in any named mode, with stops and releases between) and whatever the
    /// configuration's `max_angular`: no 0x111 carries more
    /// than the model's limits in any field as its mapping lays them out (a steered one no yaw
    /// rate in the yaw-rate field), the frame a stop is sent with is zero on every field, a
    /// Ranger gets no motion while it changes mode and a Hunter none while its brake is locked.
    #[test]
    fn no_model_receives_more_than_its_limits_whatever_a_client_asks(
        model in prop::sample::select(Model::ALL.to_vec()),
        asks in prop::collection::vec(ask(), 1..30),
        generous in any::<bool>(),
    ) {
        // A configured `max_angular` beyond the model's (v1's percent scale) changes nothing.
        let max_angular = generous.then_some(model.limits().angular * 3.0);
        let gateway = GatewayConfig { model: Some(model), max_angular, ..config(Protocol::V2) };
        let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &gateway, Start::Clean);
        pair.run(ms(200));
        let mut stops = Vec::new();
        for ask in asks {
            match ask {
                Ask::Wait(millis) => pair.run(ms(millis)),
                Ask::Drive((linear, lateral, angular), mode, ticks) => {
                    let lease = match pair.leases.get(&TELEOP.1) {
                        Some(lease) => *lease,
                        None => match pair.take(TELEOP, Class::Teleop) {
                            Ok(lease) => lease,
                            Err(_) => continue,
                        },
                    };
                    for _ in 0..ticks {
                        let drive = Request::Drive { lease, linear, lateral, angular, ttl: None, mode };
                        let answer = pair.request(TELEOP, &drive);
                        if answer.is_err_and(|r| matches!(r.kind, Some(RejectionKind::Revoked | RejectionKind::NoControl))) {
                            pair.leases.remove(&TELEOP.1);
                            break;
                        }
                        let next = pair.now + TICK;
                        while pair.now < next {
                            pair.step();
                        }
                    }
                }
                Ask::Stop => {
                    stops.push(pair.now);
                    pair.request(TELEOP, &Request::Stop { reason: "person".into() }).expect("a stop is never refused");
                }
                Ask::Release => {
                    let _ = pair.request(OPERATOR, &Request::Release { target: ReleaseTarget::All, through: u64::MAX });
                }
            }
        }
        pair.run(ms(100));
        let most = wire_limits(model);
        let sent = pair.v2_motion_commands();
        for (at, command) in &sent {
            let fields = [command.linear_mm_s, command.angular_mrad_s, command.lateral_mm_s, command.steering_mrad];
            for (field, (value, most)) in fields.into_iter().zip(most).enumerate() {
                prop_assert!(
                    f64::from(value).abs() / 1000.0 <= most,
                    "{}: field {} of {:?} at {:?} beyond {:?}", model, field, command, at, most
                );
            }
        }
        for stop in &stops {
            let at_stop = sent.iter().find(|(at, _)| at == stop).map(|(_, command)| *command);
            prop_assert_eq!(at_stop, Some(MotionV2::default()), "{}: the stop at {:?}", model, stop);
        }
        let ignored = pair.chassis.stats().ignored;
        prop_assert_eq!(ignored.mode_changing, 0, "{}: motion while changing mode", model);
        prop_assert_eq!(ignored.brake_locked, 0, "{}: motion while braked", model);
    }
}

/// Each Hunter driven round a circle: the wire carries its speed and inner wheel's angle, it
/// refuses to turn in place, and the gateway's odometry (the yaw rate it derives from the
/// steering angle the chassis reports) follows the chassis' pose.
#[test]
fn each_hunter_steers_by_its_wheels_and_its_odometry_follows() {
    for model in Model::ALL
        .into_iter()
        .filter(|model| model.drive() == Drive::Ackermann)
    {
        a_hunter_steers_by_its_wheels_and_its_odometry_follows(model);
    }
}

fn a_hunter_steers_by_its_wheels_and_its_odometry_follows(model: Model) {
    let hunter = GatewayConfig {
        model: Some(model),
        ..config(Protocol::V2)
    };
    let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &hunter, Start::Clean);
    pair.run(ms(200));
    let lease = pair.take(TELEOP, Class::Teleop).expect("a lease");
    let turn = |linear: f64, angular: f64| Request::Drive {
        lease,
        linear,
        lateral: 0.0,
        angular,
        ttl: None,
        mode: None,
    };
    let refused = pair.request(TELEOP, &turn(0.0, 0.3)).expect_err("in place");
    assert_eq!(refused.kind, Some(RejectionKind::NotAllowed));
    assert!(
        refused
            .reason
            .starts_with(&format!("a {model} cannot turn in place")),
        "{}",
        refused.reason
    );
    // 0.5 m/s at 0.25 rad/s: a 2 m radius, wider than its tightest; 10 s, most of a circle.
    for _ in 0..500 {
        pair.request(TELEOP, &turn(0.5, 0.25)).expect("a turn");
        let next = pair.now + TICK;
        while pair.now < next {
            pair.step();
        }
    }
    let sent = pair.chassis.stats().last_command.expect("commands");
    let steering = model.steering().expect("steered");
    let inner = steering.inner_from_central((0.25_f64 * steering.wheelbase / 0.5).atan());
    assert_eq!(
        sent.angular, 0.0,
        "{model}: no yaw rate in the yaw-rate field"
    );
    assert!(
        (sent.steering - inner).abs() < 0.001,
        "{model}: {sent:?}: {inner}"
    );
    let state = pair.last_state();
    assert!(
        (state.motion.angular() - 0.25).abs() < 0.005,
        "{model}: the yaw rate derived from the reported angle: {:?}",
        state.motion
    );
    let (odometry, truth) = (state.odometry, pair.chassis.pose());
    assert!(truth.yaw.abs() > 1.0 || truth.y > 1.0, "{model}: {truth:?}");
    let error = (odometry.x - truth.x).hypot(odometry.y - truth.y);
    assert!(
        error < 0.02 * 5.0,
        "{model}: odometry {odometry:?} against the chassis' {truth:?}"
    );
    // Straight on at once, then the other way at its tightest: the wheels take their time to
    // turn, which is no runaway.
    for (linear, angular) in [(0.5, 0.0), (1.0, -2.0), (-0.5, 0.0)] {
        for _ in 0..150 {
            pair.request(TELEOP, &turn(linear, angular))
                .expect("driving on");
            let next = pair.now + TICK;
            while pair.now < next {
                pair.step();
            }
        }
    }
    assert!(
        pair.chassis.actual().linear < -0.4,
        "{model}: {:?}",
        pair.chassis.actual()
    );
}

/// Drives under `lease` at `velocity` (forward, sideways, yaw rate) every 20 ms for `ticks`,
/// never taking control again; returns the answers.
fn stream_velocity(
    pair: &mut Pair,
    lease: u64,
    (linear, lateral, angular): (f64, f64, f64),
    ticks: u32,
) -> Vec<Result<Accepted, Rejected>> {
    (0..ticks)
        .map(|_| {
            let drive = Request::Drive {
                lease,
                linear,
                lateral,
                angular,
                ttl: None,
                mode: None,
            };
            let answer = pair.request(TELEOP, &drive);
            let next = pair.now + TICK;
            while pair.now < next {
                pair.step();
            }
            answer
        })
        .collect()
}

/// For every model on v2, driven on the axes it moves on (sideways where it moves sideways,
/// forward with a turn elsewhere): a lost link stops it, a client that keeps streaming across
/// the loss, the reconnection and the operator's release moves nothing on any axis (the wire
/// zero on every field), and only a new take of control drives it again.
#[test]
fn on_every_model_a_gap_and_a_release_restart_nothing_on_any_axis() {
    for model in Model::ALL
        .into_iter()
        .filter(|model| model.speaks(Protocol::V2))
    {
        let gateway = GatewayConfig {
            model: Some(model),
            ..config(Protocol::V2)
        };
        let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &gateway, Start::Clean);
        pair.run(ms(200));
        let velocity = if model.limits().lateral > 0.0 {
            (0.0, 0.4, 0.0)
        } else {
            (0.5, 0.0, 0.3)
        };
        let moving = |pair: &Pair| {
            let actual = pair.chassis.actual();
            actual.linear.abs() + actual.lateral.abs() + actual.angular.abs() > 0.2
        };
        let still = |pair: &Pair, why: &str| {
            let actual = pair.chassis.actual();
            let sent = pair.chassis.stats().last_command.expect("commands");
            assert_eq!(
                (actual.linear, actual.lateral, actual.angular),
                (0.0, 0.0, 0.0),
                "{model}: {why}"
            );
            assert_eq!(
                (sent.linear, sent.lateral, sent.angular),
                (0.0, 0.0, 0.0),
                "{model}: {why}: the wire"
            );
        };
        let lease = pair.take(TELEOP, Class::Teleop).expect("a lease");
        stream_velocity(&mut pair, lease, velocity, 150);
        assert!(moving(&pair), "{model}: {:?}", pair.chassis.actual());
        pair.unplug();
        assert_eq!(
            pair.stops(),
            [("gateway".into(), StopCause::LinkLost)],
            "{model}"
        );
        stream_velocity(&mut pair, lease, velocity, 50);
        pair.plugged = true;
        pair.run_until(Duration::from_secs(3), |p| {
            p.last_state().link.state() == LinkState::Ok
        });
        let answers = stream_velocity(&mut pair, lease, velocity, 100);
        assert!(answers.iter().all(Result::is_err), "{model}: refused");
        still(&pair, "after the link came back");
        pair.request(
            OPERATOR,
            &Request::Release {
                target: ReleaseTarget::All,
                through: u64::MAX,
            },
        )
        .expect("released");
        let answers = stream_velocity(&mut pair, lease, velocity, 100);
        assert!(answers.iter().all(Result::is_err), "{model}: revoked");
        still(&pair, "after the release");
        let lease = pair.take(TELEOP, Class::Teleop).expect("taken again");
        stream_velocity(&mut pair, lease, velocity, 200);
        assert!(
            moving(&pair),
            "{model}: a new take drives: {:?}",
            pair.chassis.actual()
        );
    }
}

/// The 0x131 frames sent, with when.
fn brake_requests(pair: &Pair) -> Vec<(Duration, BrakeV2)> {
    pair.v2_sent(|message| match message {
        MessageV2::Brake(brake) => Some(brake),
        _ => None,
    })
}

/// A Hunter's parking brake (the simulated one starts locked, as the vendor's manual says a
/// Hunter must be released before it runs): nothing asks to release it until a client drives,
/// nothing moves until the chassis reports it released, it is locked once nobody drives and
/// the chassis stands still, a lock the chassis makes during a drive is a stop a client that
/// keeps streaming does not get past, and a release of that stop releases no brake.
#[test]
fn a_hunters_brake_is_released_only_for_a_drive_and_locked_when_idle() {
    let hunter = GatewayConfig {
        model: Some(Model::Hunter2),
        ..config(Protocol::V2)
    };
    let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &hunter, Start::Clean);
    pair.run(Duration::from_secs(2));
    assert!(brake_requests(&pair).is_empty(), "nothing asked at start");
    assert_eq!(pair.chassis.stats().brake, "locked");
    let lease = pair.take(TELEOP, Class::Teleop).expect("a lease");
    let ahead = Request::Drive {
        lease,
        linear: 0.5,
        lateral: 0.0,
        angular: 0.0,
        ttl: None,
        mode: None,
    };
    pair.request(TELEOP, &ahead).expect("a drive");
    let asked_at = pair.now;
    pair.run_until(ms(500), |pair| pair.chassis.stats().brake == "released");
    let released = brake_requests(&pair);
    assert_eq!(released.len(), 1, "{released:?}");
    assert_eq!(released[0].1, BrakeV2::Released);
    // Nothing moving went out before the ask, nor reached the chassis with its brake locked.
    let first_moving = pair
        .motion_commands()
        .into_iter()
        .filter(|(at, motion)| *at >= asked_at && motion.linear != 0.0)
        .map(|(at, _)| at)
        .min();
    assert!(
        first_moving.is_none_or(|first| first > released[0].0),
        "{first_moving:?}"
    );
    assert_eq!(pair.chassis.stats().ignored.brake_locked, 0);
    for _ in 0..100 {
        pair.request(TELEOP, &ahead).expect("driving");
        let next = pair.now + TICK;
        while pair.now < next {
            pair.step();
        }
    }
    assert!(
        pair.chassis.actual().linear > 0.4,
        "{:?}",
        pair.chassis.actual()
    );
    // The drive ends: the chassis stops, and a second later the brake is locked.
    pair.run(Duration::from_secs(3));
    assert_eq!(pair.chassis.stats().brake, "locked");
    let asked: Vec<BrakeV2> = brake_requests(&pair).into_iter().map(|(_, b)| b).collect();
    assert_eq!(asked, [BrakeV2::Released, BrakeV2::Locked]);
    // Driving again, the chassis (its RC, a fault) locks the brake: a stop, and a client that
    // keeps streaming stays still, its brake locked.
    pair.leases.remove(&TELEOP.1);
    pair.stream(TELEOP, Class::Teleop, 0.5, Duration::from_secs(2));
    assert!(pair.chassis.actual().linear > 0.4);
    let at = pair.now - pair.epoch;
    pair.chassis
        .handle_v2(at, MessageV2::Brake(BrakeV2::Locked));
    pair.keep_streaming(TELEOP, 0.5, ms(300));
    assert_eq!(
        pair.stops(),
        [("gateway".to_owned(), StopCause::ChassisMode)]
    );
    let reason = pair.stop_reason(StopCause::ChassisMode);
    assert!(
        reason.starts_with("the chassis locked its parking brake unasked"),
        "{reason}"
    );
    let before = brake_requests(&pair).len();
    pair.keep_streaming(TELEOP, 0.5, Duration::from_secs(2));
    assert_eq!(pair.chassis.actual().linear, 0.0);
    assert_eq!(pair.chassis.stats().brake, "locked");
    // Released by the operator: nothing released, nothing moves, until a client takes control
    // and drives.
    release_and_check_nothing_restarts(&mut pair, TELEOP);
    let asked: Vec<BrakeV2> = brake_requests(&pair)[before..]
        .iter()
        .map(|(_, b)| *b)
        .collect();
    assert_eq!(asked, [BrakeV2::Released], "only for the new drive");
}

/// No model without a parking brake is ever sent 0x131.
#[test]
fn only_a_model_with_a_brake_is_sent_one() {
    for model in Model::ALL
        .into_iter()
        .filter(|model| model.speaks(Protocol::V2) && !model.parking_brake())
    {
        let gateway = GatewayConfig {
            model: Some(model),
            ..config(Protocol::V2)
        };
        let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &gateway, Start::Clean);
        pair.run(ms(200));
        let lease = pair.take(TELEOP, Class::Teleop).expect("a lease");
        let mut most = [0.0; 4];
        drive_ticks(&mut pair, lease, (0.5, 0.0, 0.0), 100, &mut most);
        pair.run(Duration::from_secs(2));
        assert!(brake_requests(&pair).is_empty(), "{model}");
        assert!(most[0] > 0.4, "{model} drove: {most:?}");
    }
}

/// A client names a Ranger's mode: straight ahead in parallel mode (which the gateway would
/// not pick for it), then park; a drive without a mode afterwards takes it out of the park the
/// client asked for, and nothing moved while it changed.
#[test]
fn a_ranger_drives_in_the_mode_a_client_names_and_parks_when_asked() {
    let ranger = GatewayConfig {
        model: Some(Model::RangerMini3),
        ..config(Protocol::V2)
    };
    let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &ranger, Start::Clean);
    pair.run(ms(200));
    let lease = pair.take(TELEOP, Class::Teleop).expect("a lease");
    let drive = |pair: &mut Pair, linear: f64, mode: Option<DriveMode>, ticks: u32| {
        for _ in 0..ticks {
            let request = Request::Drive {
                lease,
                linear,
                lateral: 0.0,
                angular: 0.0,
                ttl: None,
                mode,
            };
            pair.request(TELEOP, &request).expect("taken");
            let next = pair.now + TICK;
            while pair.now < next {
                pair.step();
            }
        }
    };
    drive(&mut pair, 0.4, Some(DriveMode::Parallel), 150);
    let stats = pair.chassis.stats();
    assert_eq!(stats.motion_mode, "parallel");
    assert!(stats.actual.linear > 0.3, "{:?}", stats.actual);
    drive(&mut pair, 0.0, Some(DriveMode::Park), 150);
    assert_eq!(pair.chassis.stats().motion_mode, "park");
    drive(&mut pair, 0.4, None, 150);
    let stats = pair.chassis.stats();
    assert_eq!(stats.motion_mode, "dual_ackermann");
    assert!(stats.actual.linear > 0.3, "{:?}", stats.actual);
    assert_eq!(
        (stats.ignored.mode_changing, stats.mode_changes_refused),
        (0, 0)
    );
    assert!(pair.stops().is_empty(), "{:?}", pair.stops());
}

/// A Ranger driven forward with a turn, sideways, spinning and beyond its limits: the mode
/// changes only standing still (the simulated firmware counts a change asked while moving),
/// nothing moves it while it reports a change (it counts motion received then), each mode's
/// fields are where its vendor puts them (the Mini 2.0's spin rate in bytes 4-5), no field
/// goes beyond the model's limits, a stop is zero on every field at once, and the gateway's
/// odometry follows the chassis' pose through every mode.
#[test]
fn a_ranger_changes_mode_standing_still_and_never_moves_while_it_changes() {
    for model in [Model::RangerMini2, Model::RangerMini3] {
        let ranger = GatewayConfig {
            model: Some(model),
            ..config(Protocol::V2)
        };
        let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &ranger, Start::Clean);
        pair.run(ms(200));
        let four_wheel = model.four_wheel().expect("a Ranger");
        let limits = model.limits();
        let lease = pair.take(TELEOP, Class::Teleop).expect("a lease");
        // linear, yaw-rate field, lateral, steering field, over everything sent.
        let mut most = [0.0_f64; 4];
        let mut drive = |pair: &mut Pair, velocity: (f64, f64, f64), ticks: u32| {
            drive_ticks(pair, lease, velocity, ticks, &mut most);
        };
        let close = |what: &str, actual: f64, wanted: f64| {
            assert!(
                (actual - wanted).abs() < 0.02,
                "{model}: {what} {actual}, not {wanted}"
            );
        };
        // Dual Ackermann, the mode it starts in: forward on a 1 m circle.
        drive(&mut pair, (0.5, 0.0, 0.5), 200);
        let actual = pair.chassis.actual();
        close("dual Ackermann yaw rate", actual.angular, 0.5);
        let sent = pair.chassis.stats().last_command.expect("commands");
        close("inner angle", sent.steering, four_wheel.inner_for(0.5, 0.5));
        assert_eq!(
            (sent.angular, sent.lateral),
            (0.0, 0.0),
            "{model}: {sent:?}"
        );
        // Sideways: to a standstill, to parallel mode, then sideways.
        drive(&mut pair, (0.0, 0.4, 0.0), 250);
        assert_eq!(pair.chassis.stats().motion_mode, "parallel", "{model}");
        close("sideways", pair.chassis.actual().lateral, 0.4);
        // Forward and sideways at once, in the same mode.
        drive(&mut pair, (0.3, -0.3, 0.0), 150);
        let actual = pair.chassis.actual();
        close("diagonal forward", actual.linear, 0.3);
        close("diagonal sideways", actual.lateral, -0.3);
        // Turning in place: spin mode.
        drive(&mut pair, (0.0, 0.0, 1.0), 250);
        assert_eq!(pair.chassis.stats().motion_mode, "spin", "{model}");
        assert_eq!(
            pair.last_state().motion.mode(),
            Some((MotionModeV2::Spin, false)),
            "{model}: the state says the mode"
        );
        close("spin", pair.chassis.actual().angular, 1.0);
        let sent = pair.chassis.stats().last_command.expect("commands");
        let (spin_field, other) = if four_wheel.spin_in_lateral {
            (sent.lateral, sent.angular)
        } else {
            (sent.angular, sent.lateral)
        };
        assert_eq!(other, 0.0, "{model}: {sent:?}");
        close("spin field", spin_field, 1.0);
        // The other way round: spinning clockwise, backing up on a circle to the right, backing
        // up diagonally to the left; the dual Ackermann angle never past its own widest.
        drive(&mut pair, (0.0, 0.0, -0.8), 200);
        close("clockwise spin", pair.chassis.actual().angular, -0.8);
        for _ in 0..250 {
            drive(&mut pair, (-0.4, 0.0, 0.4), 1);
            let sent = pair.chassis.stats().last_command.expect("commands");
            assert!(
                sent.steering.abs() <= four_wheel.max_inner,
                "{model}: {sent:?}"
            );
        }
        let actual = pair.chassis.actual();
        close("backing up", actual.linear, -0.4);
        close("backing up, turning", actual.angular, 0.4);
        drive(&mut pair, (-0.3, 0.2, 0.0), 300);
        let actual = pair.chassis.actual();
        close("backing up diagonally", actual.linear, -0.3);
        close("to the left", actual.lateral, 0.2);
        // The odometry followed every mode.
        let (odometry, truth) = (pair.last_state().odometry, pair.chassis.pose());
        let error = (odometry.x - truth.x).hypot(odometry.y - truth.y);
        assert!(
            error < 0.05,
            "{model}: odometry {odometry:?}, truth {truth:?}"
        );
        assert!(
            scout_protocol::kinematics::wrap_angle(odometry.yaw - truth.yaw).abs() < 0.05,
            "{model}: odometry {odometry:?}, truth {truth:?}"
        );
        // Beyond its limits on every axis (a turn faster than it drives spins in place).
        for velocity in [
            (40.0, 0.0, 0.0),
            (0.0, 0.0, 40.0),
            (0.0, 40.0, 0.0),
            (40.0, 0.0, 40.0),
        ] {
            drive(&mut pair, velocity, 300);
        }
        let [linear, angular, lateral, steering] = most;
        let spin_most = if four_wheel.spin_in_lateral {
            lateral
        } else {
            angular
        };
        assert!(
            linear <= limits.linear && linear > limits.linear - 0.001,
            "{model}: {most:?}"
        );
        assert!(
            spin_most <= limits.angular && spin_most > limits.angular - 0.001,
            "{model}: {most:?}"
        );
        let widest = four_wheel.max_inner.max(four_wheel.max_parallel);
        assert!(steering <= widest, "{model}: {most:?}");
        if four_wheel.spin_in_lateral {
            assert_eq!(
                angular, 0.0,
                "{model}: the Mini 2.0's yaw-rate field stays zero"
            );
        } else {
            assert_eq!(lateral, 0.0, "{model}: {most:?}");
        }
        let stats = pair.chassis.stats();
        assert_eq!(
            stats.ignored.mode_changing, 0,
            "{model}: motion while changing"
        );
        assert_eq!(
            stats.mode_changes_refused, 0,
            "{model}: a change asked while moving"
        );
        assert!(stats.mode_changes >= 4, "{model}: {}", stats.mode_changes);
        stops_at_once_on_every_field(&mut pair, model);
    }
}

#[test]
fn an_omni_drifting_sideways_uncommanded_is_a_runaway() {
    let omni = GatewayConfig {
        model: Some(Model::ScoutMiniOmni),
        ..config(Protocol::V2)
    };
    let latches = |lateral_mm_s: i16| {
        let mut pair = Pair::with_firmware(Protocol::V2, Transport::Can, &omni, Start::Clean);
        pair.run(ms(200));
        pair.feedback = false;
        for _ in 0..40 {
            let drift = MotionV2 {
                lateral_mm_s,
                ..MotionV2::default()
            };
            pair.core
                .handle_rx(pair.now, &RxEvent::V2(MessageV2::MotionState(drift)));
            pair.now += TICK;
            pair.step();
        }
        (pair
            .stops()
            .contains(&("gateway".into(), StopCause::Runaway)))
        .then(|| pair.stop_reason(StopCause::Runaway))
    };
    let reason = latches(-800).expect("0.8 m/s sideways, nothing commanded");
    assert!(reason.contains("moves sideways at -0.80 m/s"), "{reason}");
    assert_eq!(latches(100), None, "within the tolerance");
}
