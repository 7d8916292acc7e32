//! The one chassis state: received feedback in either protocol, link statistics and state, the
//! protocol the chassis speaks, odometry. Sans-IO: events and CLOCK_BOOTTIME times in, the
//! payload to publish out.

use std::time::Duration;

use scout_interface::state::{
    BatteryLevel, ChassisPayload, CommandPayload, LinkState, OdometryPayload, Received,
    StatePayload,
};
use scout_interface::{FixedText, Transport};
use scout_protocol::kinematics::{Pose, wrap_angle};
use scout_protocol::link::RxEvent;
use scout_protocol::model::{Model, Names, Sign};
use scout_protocol::sequence::{Continuity, SequenceTracker};
use scout_protocol::slcan::Slcan;
use scout_protocol::v2::MessageV2;
use scout_protocol::version::{Detection, IdsSeen, Protocol, ProtocolDetector};
use scout_protocol::{Counted, Direction, Message};
use tracing::{error, info, warn};

use crate::battery::BatteryMonitor;
use crate::config::{BatteryConfig, OdometryConfig};

/// No valid feedback for this long: the link is `silent`.
pub const SILENT_AFTER: Duration = Duration::from_millis(100);
/// Odometry does not integrate body rates across a gap longer than this (the speed over it is
/// unknown).
const MAX_ODOMETRY_STEP: Duration = Duration::from_millis(100);
/// The wheel odometers count across gaps up to this long (their distance is cumulative; the
/// heading over a longer gap is too uncertain to place it).
const MAX_ODOMETER_STEP: Duration = Duration::from_secs(1);
/// The body rates move the pose only while no odometer reading came for this long.
const ODOMETER_FRESH: Duration = Duration::from_millis(200);
/// With `auto`, how long after the port opened a protocol not yet told is an error worth
/// saying (what arrived, if anything): the chassis' command timeout, so that the
/// `chassis_silent` stop latched then says it.
pub const UNTOLD_AFTER: Duration = Duration::from_millis(500);

fn nanos(time: Duration) -> u64 {
    time.as_nanos() as u64
}

/// What the state tracker was told happened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Publish {
    /// Nothing worth publishing changed.
    No,
    /// The state changed: publish it.
    Yes,
}

/// What the port itself counts, from when it opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PortCounters {
    /// Bytes the stream decoder threw away while resynchronising (serial, slcan).
    pub discarded_bytes: u64,
    /// Frames the kernel dropped because its receive queue was full (SocketCAN).
    pub overflowed_frames: u64,
}

/// The chassis state and what keeps it up to date.
#[derive(Debug, Clone)]
pub struct StateTracker {
    state: StatePayload,
    sequence: SequenceTracker,
    detector: ProtocolDetector,
    /// The protocol the gateway was told to speak, if it was.
    fixed: Option<Protocol>,
    /// The protocol whose feedback is used on this port: the fixed one, or the detected one.
    protocol: Option<Protocol>,
    /// The configured model, if any (else the detected protocol's default).
    model: Option<Model>,
    /// Why nothing the chassis sends is used, when that is so.
    mismatch: Option<Mismatch>,
    /// With `auto`: why the protocol is not told yet, once that has lasted [`UNTOLD_AFTER`].
    untold: Option<Mismatch>,
    /// Every CAN id received on this port (the first few), for what to say when nothing tells
    /// the protocol.
    ids_heard: IdsSeen,
    /// When the port opened.
    opened_at: Option<Duration>,
    link_state: LinkState,
    last_feedback: Option<Duration>,
    foreign_commands_reported: bool,
    other_protocol_reported: bool,
    unknown_bits_reported: u16,
    /// The link's port counters when the current port opened: a new port counts from zero.
    counted_by_closed_ports: PortCounters,
    /// The yaw at the last odometer reading (v2): the heading of the next step is midway.
    yaw_at_odometer: f64,
    /// The protocol whose feedback the sections hold, kept across ports: a chassis of the
    /// other protocol behind a reopened port clears them.
    sections_from: Option<Protocol>,
    /// The slcan adapter's errors (BEL) since the last said, and when that was.
    adapter_errors: (u64, Option<Duration>),
    /// The odometry's calibration, applied as the pose is integrated.
    calibration: OdometryConfig,
    /// The battery's judge.
    battery: BatteryMonitor,
}

impl StateTracker {
    /// A tracker for `robot` on `transport`/`device`, before the port is open, speaking `fixed`
    /// or telling the protocol from the frames; `chassis` is the model and limits it drives
    /// by (`model` 0 when none was configured: the detected protocol's default is shown).
    pub fn new(
        robot: &str,
        transport: Transport,
        device: &str,
        fixed: Option<Protocol>,
        chassis: ChassisPayload,
    ) -> Self {
        let mut state = StatePayload {
            robot: FixedText::new(robot),
            chassis,
            ..StatePayload::default()
        };
        state.link.transport = transport.raw();
        state.link.device = FixedText::new(device);
        state.link.state = LinkState::Disconnected.raw();
        state.link.protocol = fixed.map_or(0, Protocol::raw);
        let model = chassis.model();
        let battery = BatteryMonitor::new(
            BatteryConfig::default(),
            model.unwrap_or(Model::Scout).battery(),
        );
        state.battery = battery.payload();
        if let (None, Some(protocol)) = (model, fixed) {
            state.chassis.model = Model::default_for(protocol).raw();
        }
        Self {
            state,
            sequence: SequenceTracker::new(),
            detector: ProtocolDetector::new(),
            fixed,
            protocol: fixed,
            model,
            mismatch: None,
            untold: None,
            ids_heard: IdsSeen::default(),
            opened_at: None,
            link_state: LinkState::Disconnected,
            last_feedback: None,
            foreign_commands_reported: false,
            other_protocol_reported: false,
            unknown_bits_reported: 0,
            counted_by_closed_ports: PortCounters::default(),
            yaw_at_odometer: 0.0,
            sections_from: fixed,
            adapter_errors: (0, None),
            calibration: OdometryConfig::default(),
            battery,
        }
        .with_calibration(OdometryConfig::default())
    }

    /// This tracker, judging the battery by `config`.
    pub fn with_battery(mut self, config: BatteryConfig) -> Self {
        let model = self.model.unwrap_or(Model::Scout);
        self.battery = BatteryMonitor::new(config, model.battery());
        self.state.battery = self.battery.payload();
        self
    }

    /// This tracker, integrating the odometry with `calibration`.
    pub fn with_calibration(mut self, calibration: OdometryConfig) -> Self {
        self.calibration = calibration;
        self.state.odometry.distance_scale = calibration.distance_scale;
        self.state.odometry.yaw_scale = calibration.yaw_scale;
        self
    }

    /// When the last valid feedback came, since the port opened.
    pub fn last_feedback(&self) -> Option<Duration> {
        self.last_feedback
    }

    /// The current link state.
    pub fn link_state(&self) -> LinkState {
        self.link_state
    }

    /// The protocol the gateway speaks on this port: the fixed one, or the detected one (none
    /// while listening, or after feedback of both).
    pub fn protocol(&self) -> Option<Protocol> {
        self.protocol
    }

    /// Why nothing the chassis sends is used, if that is so: a protocol mismatch, or with
    /// `auto` nothing that tells the protocol for [`UNTOLD_AFTER`].
    pub fn mismatch(&self) -> Option<&Mismatch> {
        self.mismatch.as_ref().or(self.untold.as_ref())
    }

    /// The state as it would be published now (sequence number and time not yet stamped).
    pub fn state(&self) -> &StatePayload {
        &self.state
    }

    /// Stamps the next sequence number and the time, and returns the state to publish.
    pub fn stamp(&mut self, now: Duration) -> &StatePayload {
        self.state.seq += 1;
        self.state.published_ns = nanos(now);
        &self.state
    }

    fn set_link_state(&mut self, state: LinkState) -> Publish {
        if self.link_state == state {
            return Publish::No;
        }
        info!("link {} -> {}", self.link_state.name(), state.name());
        self.link_state = state;
        self.state.link.state = state.raw();
        Publish::Yes
    }

    /// The port opened (again): counts restart, another chassis may be at the other end (with
    /// `auto`, its protocol is told anew).
    pub fn handle_connected(&mut self, now: Duration, reconnect: bool) -> Publish {
        self.sequence.reset();
        self.detector.reset();
        self.protocol = self.fixed;
        self.state.link.protocol = self.fixed.map_or(0, Protocol::raw);
        self.mismatch = None;
        self.untold = None;
        self.ids_heard = IdsSeen::default();
        self.opened_at = Some(now);
        self.other_protocol_reported = false;
        self.last_feedback = None;
        // Another chassis, or the same after a power cycle: its mode and wheels are said anew.
        self.state.motion.mode = 0;
        self.state.motion.mode_state = 0;
        self.state.motion.wheels_reported = 0;
        self.counted_by_closed_ports = PortCounters {
            discarded_bytes: self.state.link.discarded_bytes,
            overflowed_frames: self.state.link.overflowed_frames,
        };
        if reconnect {
            self.state.link.reconnects += 1;
        }
        self.set_link_state(LinkState::Silent)
    }

    /// The port failed or closed.
    pub fn handle_disconnected(&mut self) -> Publish {
        self.set_link_state(LinkState::Disconnected)
    }

    /// What the current port has counted since it opened (the link's counters add what the
    /// ports before it counted).
    pub fn set_port_counters(&mut self, port: PortCounters) {
        let before = self.counted_by_closed_ports;
        self.state.link.discarded_bytes = before.discarded_bytes + port.discarded_bytes;
        self.state.link.overflowed_frames = before.overflowed_frames + port.overflowed_frames;
    }

    /// A motion command went out at `linear` m/s and `angular` rad/s, as the wire carries them.
    pub fn handle_sent_motion(
        &mut self,
        (linear, lateral, angular): (f64, f64, f64),
        now: Duration,
    ) {
        self.state.link.tx_frames += 1;
        self.state.command = CommandPayload {
            linear,
            lateral,
            angular,
            at_ns: nanos(now),
        };
    }

    /// Some other frame was sent.
    pub fn handle_sent_other(&mut self) {
        self.state.link.tx_frames += 1;
    }

    /// The firmware versions were asked for: what answers comes anew.
    pub fn handle_version_requested(&mut self) {
        self.state.firmware = Default::default();
    }

    /// Resets odometry to the origin.
    pub fn reset_odometry(&mut self) -> Publish {
        let resets = self.state.odometry.resets + 1;
        self.state.odometry = OdometryPayload {
            resets,
            distance_scale: self.calibration.distance_scale,
            yaw_scale: self.calibration.yaw_scale,
            ..OdometryPayload::default()
        };
        self.yaw_at_odometer = 0.0;
        Publish::Yes
    }

    /// Time passes: the protocol is told, the link goes silent after 100 ms without feedback.
    pub fn poll(&mut self, now: Duration) -> Publish {
        if self.link_state == LinkState::Disconnected {
            return Publish::No;
        }
        let detection = self.detector.detection(now);
        match (self.fixed, self.protocol, detection) {
            (None, None, Detection::Found(protocol)) => {
                info!(
                    "the chassis speaks protocol {protocol} ({} seen, none of {}'s)",
                    self.detector.ids(protocol),
                    protocol.other()
                );
                self.use_protocol(protocol);
            }
            // Whenever it happens: before the protocol is told, or after (fixed, or told and
            // in use), another chassis or node joining the bus makes it unknown which chassis
            // the feedback describes.
            (_, _, Detection::Both) => self.set_mismatch(Mismatch {
                reason: "feedback of both protocols: see the gateway's log".into(),
                detail: format!(
                    "feedback of both protocols arrives (v1: {}; v2: {}): two chassis, or \
                     another node using their ids, on this bus; nothing is used until the port \
                     reopens",
                    self.detector.ids(Protocol::V1),
                    self.detector.ids(Protocol::V2)
                ),
            }),
            (Some(fixed), _, Detection::Found(other))
                if other != fixed && !self.detector.heard(fixed) =>
            {
                self.set_mismatch(Mismatch {
                    reason: format!("the chassis speaks {other}: use --protocol {other} or auto"),
                    detail: format!(
                        "the chassis speaks protocol {other} ({} seen), the gateway was started \
                         with --protocol {fixed}: start it with --protocol {other}, or auto",
                        self.detector.ids(other)
                    ),
                });
            }
            (None, None, Detection::Listening)
                if self.untold.is_none()
                    && self
                        .opened_at
                        .is_some_and(|at| now.saturating_sub(at) >= UNTOLD_AFTER) =>
            {
                let (reason, detail) = if self.ids_heard.is_empty() {
                    (
                        "nothing received: power, wiring, bitrate?".to_owned(),
                        format!(
                            "nothing received from the chassis in {} ms: is it on, CAN_H/CAN_L \
                             wired and terminated, the bus at 500 kbit/s? (`scout doctor`)",
                            UNTOLD_AFTER.as_millis()
                        ),
                    )
                } else {
                    (
                        format!("no v1 or v2 feedback; ids {}", self.ids_heard),
                        format!(
                            "the protocol is not told after {} ms: frames arrive (ids {}) but \
                             no chassis feedback of v1 (0x151, 0x200-0x203) or v2 (0x211, 0x221, \
                             0x251-0x264, 0x311); another device on this bus? (`scout doctor`)",
                            UNTOLD_AFTER.as_millis(),
                            self.ids_heard
                        ),
                    )
                };
                error!("{detail}");
                self.untold = Some(Mismatch { reason, detail });
            }
            (None, None, Detection::Listening) => {}
            _ => {}
        }
        if self.protocol.is_some() {
            self.untold = None;
        }
        if self.mismatch.is_some() {
            return self.set_link_state(LinkState::ProtocolMismatch);
        }
        let silent = self
            .last_feedback
            .is_none_or(|last| now.saturating_sub(last) >= SILENT_AFTER);
        if silent && self.link_state == LinkState::Ok {
            return self.set_link_state(LinkState::Silent);
        }
        Publish::No
    }

    fn use_protocol(&mut self, protocol: Protocol) {
        if let Some(model) = self.model
            && !model.speaks(protocol)
        {
            self.set_mismatch(Mismatch {
                reason: format!("not a {model}: it speaks protocol {protocol}"),
                detail: format!(
                    "the chassis speaks protocol {protocol}, which a {model} does not: nothing \
                     it sends is used and nothing is driven until the port reopens. Check which \
                     chassis is on this port, and --model (docs/chassis.md)"
                ),
            });
        }
        self.protocol = Some(protocol);
        self.state.link.protocol = protocol.raw();
        if self.sections_from.is_some_and(|from| from != protocol) {
            // Another chassis: nothing the one before reported is shown as this one's (its
            // system bits would read as the other protocol's, its odometers, RC, battery and
            // firmware would stay forever).
            info!("the chassis behind the port changed protocol: its sections start empty");
            let state = &mut self.state;
            state.system = Default::default();
            state.motion = Default::default();
            state.motors = Default::default();
            state.lights = Default::default();
            state.odometer = Default::default();
            state.rc = Default::default();
            state.bms = Default::default();
            state.firmware = Default::default();
            self.battery.reset();
            state.battery = self.battery.payload();
        }
        self.sections_from = Some(protocol);
        if self.model.is_none() {
            // The protocol's default model: its geometry (the limits are the same for both).
            let max_angular = self.state.chassis.max_angular;
            self.state.chassis = ChassisPayload::new(Model::default_for(protocol), max_angular);
        }
    }

    /// Feedback that says the chassis is not the model the gateway drives by (the configured
    /// one, or the protocol's default): nothing it sends is used and motion stops, as for a
    /// protocol mismatch, until the port reopens. A chassis of another model driven with a
    /// SCOUT's command moves otherwise than its clients ask (a Ranger Mini 2 told a yaw rate
    /// in the SCOUT's field takes its spin geometry and does not turn; a Hunter steers by a steering
    /// angle, not a yaw rate).
    fn check_model(&mut self, sign: Sign) {
        let model = self
            .model
            .unwrap_or(Model::default_for(self.protocol.unwrap_or(Protocol::V2)));
        if model.may_send(sign) {
            return;
        }
        self.set_mismatch(Mismatch {
            reason: format!("not a {model}: it sends {}", sign.short()),
            detail: format!(
                "the chassis sends {}, which a {model} does not: it looks like {}. The gateway \
                 drives these models only ({Names}): driven with their command, another \
                 chassis moves otherwise than its clients ask. Nothing it sends is used and \
                 nothing is driven until the port reopens: check which chassis is on this \
                 port, and --model (docs/chassis.md)",
                sign.short(),
                sign.suggests(),
            ),
        });
    }

    fn set_mismatch(&mut self, mismatch: Mismatch) {
        if self.mismatch.is_none() {
            error!("{}", mismatch.detail);
            self.mismatch = Some(mismatch);
        }
    }

    /// Whether feedback of `protocol` is used now; frames of a protocol that is not are
    /// counted as rejected, once the chassis' protocol is known.
    fn accepts(&mut self, protocol: Protocol, id: u16) -> Accept {
        if self.mismatch.is_some() {
            // Said once in the log with what was seen; the link state says it since.
            return Accept::Reject;
        }
        match self.protocol {
            Some(ours) if ours == protocol => match (protocol, self.fixed) {
                // Until a 0x151 proves v1, ids v2 shares (0x131, 0x141) may mean something else.
                (Protocol::V1, _) if !self.detector.heard(Protocol::V1) => Accept::Count,
                _ => Accept::Use,
            },
            Some(ours) => {
                if !self.other_protocol_reported {
                    warn!(
                        "a protocol {protocol} frame (0x{id:03X}) on a protocol {ours} link: \
                         another node on the bus, or another chassis; counted as rejected"
                    );
                    self.other_protocol_reported = true;
                }
                Accept::Reject
            }
            None => Accept::Count,
        }
    }

    /// One thing received from the port at `now`.
    pub fn handle_rx(&mut self, event: &RxEvent, now: Duration) -> Publish {
        let id = match event {
            RxEvent::Message(counted) => Some(counted.message.kind().can_id()),
            RxEvent::V2(message) => Some(message.can_id()),
            RxEvent::Rejected(rejected) => rejected.can_id(),
            RxEvent::Slcan(_) => None,
        };
        if let Some(id) = id {
            self.ids_heard.insert(id);
        }
        match event {
            RxEvent::Message(counted) => {
                self.detector.observe(counted.message.kind().can_id(), now);
                self.handle_message(counted, now)
            }
            RxEvent::V2(message) => {
                self.detector.observe(message.can_id(), now);
                self.handle_v2(message, now)
            }
            RxEvent::Rejected(rejected) => {
                if let Some(id) = rejected.can_id() {
                    self.detector.observe(id, now);
                    if let Some(sign) = Sign::of_v2_id(id) {
                        self.check_model(sign);
                    }
                }
                if rejected.is_checksum() {
                    self.state.link.checksum_errors += 1;
                } else {
                    self.state.link.rejected_frames += 1;
                }
                Publish::No
            }
            RxEvent::Slcan(Slcan::Nack) => {
                // At most once a second, with how many: a burst of line noise is one line.
                self.adapter_errors.0 += 1;
                if self
                    .adapter_errors
                    .1
                    .is_none_or(|at| now.saturating_sub(at) >= Duration::from_secs(1))
                {
                    warn!(
                        "the slcan adapter answered with an error (BEL), {} since the last \
                         such message: a command it did not take (`scout doctor` checks the \
                         adapter)",
                        self.adapter_errors.0
                    );
                    self.adapter_errors = (0, Some(now));
                }
                Publish::No
            }
            RxEvent::Slcan(_) => Publish::No,
        }
    }

    fn foreign_command(&mut self, name: &str, id: u16) -> Publish {
        if !self.foreign_commands_reported {
            warn!(
                "another host sends {name} (0x{id:03X}) on the bus: two programs are commanding \
                 the chassis"
            );
            self.foreign_commands_reported = true;
        }
        self.state.link.rejected_frames += 1;
        Publish::No
    }

    fn handle_message(&mut self, counted: &Counted, now: Duration) -> Publish {
        let kind = counted.message.kind();
        if kind.direction() == Direction::Command {
            return self.foreign_command(kind.name(), kind.can_id());
        }
        let accept = self.accepts(Protocol::V1, kind.can_id());
        if accept == Accept::Reject {
            self.state.link.rejected_frames += 1;
            return Publish::No;
        }
        self.state.link.rx_frames += 1;
        if let Continuity::Gap { lost } = self.sequence.observe(kind, counted.count) {
            self.state.link.dropped_frames += u64::from(lost);
        }
        if accept == Accept::Count {
            return Publish::No;
        }
        self.last_feedback = Some(now);
        if let Message::MotionFeedback(motion) = &counted.message {
            self.integrate_rates((motion.linear(), 0.0, motion.angular()), now, true);
        }
        let received = Received {
            valid: true,
            count: counted.count,
            at_ns: nanos(now),
        };
        self.state.store(&counted.message, received);
        if let Message::SystemStatus(_) = &counted.message {
            self.judge_battery(now);
        }
        self.set_link_state(LinkState::Ok);
        Publish::Yes
    }

    /// Judges the battery after a system state or a smart battery's report, and says a change
    /// of its level.
    fn judge_battery(&mut self, now: Duration) {
        let change = self.battery.update(&self.state, now);
        self.state.battery = self.battery.payload();
        if let Some(change) = change {
            let said = self.battery.describe();
            match change.to {
                BatteryLevel::Low | BatteryLevel::Critical if change.to > change.from => {
                    warn!("{said}: charge the battery")
                }
                _ => info!("{said}"),
            }
        }
    }

    fn handle_v2(&mut self, message: &MessageV2, now: Duration) -> Publish {
        if message.is_command() {
            return self.foreign_command(message.name(), message.can_id());
        }
        if let Some(sign) = Sign::of_v2_message(message) {
            self.check_model(sign);
        }
        let accept = self.accepts(Protocol::V2, message.can_id());
        if accept == Accept::Reject {
            self.state.link.rejected_frames += 1;
            return Publish::No;
        }
        self.state.link.rx_frames += 1;
        if let Some(Continuity::Gap { lost }) = self.sequence.observe_v2(message) {
            self.state.link.dropped_frames += u64::from(lost);
        }
        if accept == Accept::Count {
            return Publish::No;
        }
        self.last_feedback = Some(now);
        match message {
            MessageV2::MotionState(motion) => {
                let translate = !self.odometer_fresh(now);
                let rates = (motion.linear(), motion.lateral(), motion.angular());
                self.integrate_rates(rates, now, translate);
            }
            MessageV2::Odometer(odometer) if self.odometer_rolls_forward() => {
                self.integrate_odometer(odometer.left_mm, odometer.right_mm, now);
            }
            MessageV2::SystemState(system) => {
                let unknown = system.errors.unknown();
                if unknown != 0 && unknown != self.unknown_bits_reported {
                    warn!(
                        "the chassis reports error bits no source names: 0x{unknown:04X} (shown \
                         as unknown_bit_N in the state, not acted on)"
                    );
                    self.unknown_bits_reported = unknown;
                }
            }
            _ => {}
        }
        let received = Received {
            valid: true,
            count: message.count().unwrap_or(0),
            at_ns: nanos(now),
        };
        self.state.store_v2(message, received);
        if let MessageV2::SystemState(_) | MessageV2::Bms(_) = message {
            self.judge_battery(now);
        }
        self.set_link_state(LinkState::Ok);
        Publish::Yes
    }

    /// Whether the wheel odometers (0x311) measure forward motion: not on a Ranger, whose
    /// wheels roll sideways in parallel mode and round its centre spinning (its motion state
    /// is integrated instead, as its vendor driver does).
    fn odometer_rolls_forward(&self) -> bool {
        self.model.and_then(Model::four_wheel).is_none()
    }

    fn odometer_fresh(&self, now: Duration) -> bool {
        if !self.odometer_rolls_forward() {
            return false;
        }
        let odometer = &self.state.odometer.received;
        odometer.valid && now.saturating_sub(Duration::from_nanos(odometer.at_ns)) <= ODOMETER_FRESH
    }

    /// Integrates the body rates since the previous motion feedback: the heading and any
    /// sideways motion (the OMNI's; no wheel odometer measures it), and the forward motion too
    /// when `translate` (no wheel odometer does it).
    fn integrate_rates(
        &mut self,
        (linear, lateral, angular): (f64, f64, f64),
        now: Duration,
        translate: bool,
    ) {
        let previous = self.state.motion;
        if !previous.received.valid {
            return;
        }
        let step = now.saturating_sub(Duration::from_nanos(previous.received.at_ns));
        if step.is_zero() || step > MAX_ODOMETRY_STEP {
            return;
        }
        let dt = step.as_secs_f64();
        // Trapezoid between the previous and this feedback, calibrated.
        let v = (previous.linear() + linear) / 2.0 * self.calibration.distance_scale;
        let w = (previous.angular() + angular) / 2.0 * self.calibration.yaw_scale;
        let vy = (previous.lateral() + lateral) / 2.0 * self.calibration.distance_scale;
        let odometry = &mut self.state.odometry;
        odometry.rotation += (w * dt).abs();
        let mut pose = Pose {
            x: odometry.x,
            y: odometry.y,
            yaw: odometry.yaw,
        };
        let forward = if translate { v } else { 0.0 };
        pose.step_body(forward, vy, w, dt);
        (odometry.x, odometry.y, odometry.yaw) = (pose.x, pose.y, pose.yaw);
        odometry.distance += forward.hypot(vy) * dt;
        if translate {
            self.yaw_at_odometer = odometry.yaw;
        }
    }

    /// Moves the position by the wheel odometers' mean advance since the previous reading,
    /// along the heading midway between then and now. A step longer than
    /// [`MAX_ODOMETER_STEP`], or farther than the chassis can go in it (a counter reset by a
    /// power cycle, a wrap), only takes the new reading as the reference.
    fn integrate_odometer(&mut self, left_mm: i32, right_mm: i32, now: Duration) {
        let previous = self.state.odometer;
        let yaw = self.state.odometry.yaw;
        let start_yaw = std::mem::replace(&mut self.yaw_at_odometer, yaw);
        if !previous.received.valid {
            return;
        }
        let step = now.saturating_sub(Duration::from_nanos(previous.received.at_ns));
        if step > MAX_ODOMETER_STEP {
            return;
        }
        let scale = self.calibration.distance_scale;
        let advance = |now: i32, then: i32| f64::from(now.wrapping_sub(then)) / 1000.0 * scale;
        let (left, right) = (
            advance(left_mm, previous.left_mm),
            advance(right_mm, previous.right_mm),
        );
        let reach = self.state.chassis.max_linear * 2.0 * step.as_secs_f64().max(0.02) + 0.05;
        if left.abs() > reach || right.abs() > reach {
            warn!(
                "the wheel odometers jumped by {left:.3} m and {right:.3} m in {} ms (a chassis \
                 power cycle?): odometry continues from the new reading",
                step.as_millis()
            );
            return;
        }
        let distance = (left + right) / 2.0;
        let heading = start_yaw + wrap_angle(yaw - start_yaw) / 2.0;
        let odometry = &mut self.state.odometry;
        odometry.x += distance * heading.cos();
        odometry.y += distance * heading.sin();
        odometry.distance += distance.abs();
    }
}

/// Why nothing the chassis sends is used.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mismatch {
    /// For the stop's reason (at most 64 bytes).
    pub reason: String,
    /// At length, with the ids seen, for the log.
    pub detail: String,
}

/// What becomes of a valid feedback frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Accept {
    /// It is the chassis' protocol: used.
    Use,
    /// Its protocol is not known to be the chassis' yet: counted, not used.
    Count,
    /// It is the other protocol's: rejected.
    Reject,
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_protocol::link::RxError;
    use scout_protocol::v2::{ControlModeV2, ErrorBitsV2, MotionV2, OdometerV2, SystemStateV2};
    use scout_protocol::{
        ChassisState, ControlMode, FaultBits, MotionCommand, MotionFeedback, SystemStatus, can,
    };

    fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    fn status(count: u8) -> RxEvent {
        RxEvent::Message(Counted {
            message: Message::SystemStatus(SystemStatus {
                state: ChassisState::Normal,
                control_mode: ControlMode::Can,
                battery_decivolts: 250,
                faults: FaultBits::NONE,
            }),
            count,
        })
    }

    fn motion(count: u8, linear_mm_s: i16, angular_mrad_s: i16) -> RxEvent {
        RxEvent::Message(Counted {
            message: Message::MotionFeedback(MotionFeedback {
                linear_mm_s,
                angular_mrad_s,
            }),
            count,
        })
    }

    fn system_v2(count: u8) -> RxEvent {
        RxEvent::V2(MessageV2::SystemState(SystemStateV2 {
            state: ChassisState::Normal,
            control_mode: ControlModeV2::Standby,
            battery_decivolts: 259,
            errors: ErrorBitsV2(0),
            reserved: 0,
            count,
        }))
    }

    fn motion_v2(linear_mm_s: i16, angular_mrad_s: i16) -> RxEvent {
        RxEvent::V2(MessageV2::MotionState(MotionV2 {
            linear_mm_s,
            angular_mrad_s,
            ..MotionV2::default()
        }))
    }

    fn odometer(left_mm: i32, right_mm: i32) -> RxEvent {
        RxEvent::V2(MessageV2::Odometer(OdometerV2 { left_mm, right_mm }))
    }

    fn connected_with(fixed: Option<Protocol>) -> StateTracker {
        let chassis = ChassisPayload::new(Model::Scout, Model::Scout.limits().angular);
        let mut tracker = StateTracker::new("test", Transport::Can, "vcan0", fixed, chassis);
        assert_eq!(
            tracker.handle_connected(Duration::ZERO, false),
            Publish::Yes
        );
        tracker
    }

    fn connected() -> StateTracker {
        connected_with(Some(Protocol::V1))
    }

    #[test]
    fn link_goes_ok_then_silent_after_100_ms() {
        let mut tracker = connected();
        assert_eq!(tracker.link_state(), LinkState::Silent);
        assert_eq!(tracker.handle_rx(&status(0), ms(10)), Publish::Yes);
        assert_eq!(tracker.link_state(), LinkState::Ok);
        assert_eq!(tracker.poll(ms(109)), Publish::No);
        assert_eq!(tracker.poll(ms(110)), Publish::Yes);
        assert_eq!(tracker.link_state(), LinkState::Silent);
        tracker.handle_rx(&status(1), ms(200));
        assert_eq!(tracker.link_state(), LinkState::Ok);
        assert_eq!(tracker.handle_disconnected(), Publish::Yes);
        assert_eq!(
            tracker.poll(ms(900)),
            Publish::No,
            "disconnected stays disconnected"
        );
    }

    #[test]
    fn counts_errors_and_gaps() {
        let mut tracker = connected();
        tracker.handle_rx(&status(10), ms(1));
        tracker.handle_rx(&status(13), ms(2));
        let bad = can::CanError::Checksum {
            id: 0x151,
            expected: 1,
            found: 2,
        };
        tracker.handle_rx(&RxEvent::Rejected(RxError::Can(bad)), ms(3));
        tracker.handle_rx(&RxEvent::Rejected(RxError::ForeignFrame(5)), ms(4));
        let link = tracker.state().link;
        assert_eq!((link.rx_frames, link.dropped_frames), (2, 2));
        assert_eq!((link.checksum_errors, link.rejected_frames), (1, 1));
    }

    #[test]
    fn nothing_is_applied_before_a_status_proves_v1() {
        let mut tracker = connected();
        assert_eq!(tracker.handle_rx(&motion(0, 500, 0), ms(1)), Publish::No);
        assert!(!tracker.state().motion.received.valid);
        tracker.handle_rx(&status(0), ms(2));
        assert_eq!(tracker.handle_rx(&motion(1, 500, 0), ms(3)), Publish::Yes);
        assert!(tracker.state().motion.received.valid);
    }

    #[test]
    fn a_v2_chassis_on_a_v1_gateway_is_a_mismatch_and_nothing_is_used() {
        let mut tracker = connected();
        tracker.handle_rx(&motion_v2(500, 0), Duration::ZERO);
        assert_eq!(tracker.handle_rx(&system_v2(0), ms(1)), Publish::No);
        assert_eq!(tracker.poll(ms(299)), Publish::No);
        assert_eq!(tracker.poll(ms(300)), Publish::Yes);
        assert_eq!(tracker.link_state(), LinkState::ProtocolMismatch);
        let why = tracker.mismatch().expect("a reason");
        assert!(
            why.detail.contains("--protocol v2") && why.detail.contains("0x221"),
            "{why:?}"
        );
        assert!(why.reason.len() <= 64 && why.reason.contains("--protocol v2"));
        assert!(!tracker.state().motion.received.valid);
        assert_eq!(tracker.state().link.rejected_frames, 2);
        // A reconnect starts over.
        tracker.handle_connected(Duration::ZERO, true);
        assert_eq!(tracker.link_state(), LinkState::Silent);
        assert!(tracker.mismatch().is_none());
    }

    #[test]
    fn auto_tells_v2_uses_it_and_rejects_v1_afterwards() {
        let mut tracker = connected_with(None);
        assert_eq!(tracker.state().link.protocol, 0);
        assert_eq!(tracker.state().chassis.model, Model::Scout.raw());
        tracker.handle_rx(&system_v2(0), Duration::ZERO);
        assert_eq!(tracker.protocol(), None, "listening");
        assert!(!tracker.state().system.received.valid);
        tracker.poll(ms(300));
        assert_eq!(tracker.protocol(), Some(Protocol::V2));
        assert_eq!(tracker.state().link.protocol(), Some(Protocol::V2));
        assert_eq!(tracker.handle_rx(&system_v2(1), ms(310)), Publish::Yes);
        assert_eq!(tracker.link_state(), LinkState::Ok);
        assert_eq!(tracker.state().system.battery_decivolts, 259);
        assert_eq!(tracker.handle_rx(&status(0), ms(320)), Publish::No);
        assert_eq!(tracker.state().link.rejected_frames, 1);
        tracker.handle_rx(&odometer(1000, 1000), ms(330));
        assert!(tracker.state().odometer.received.valid);
        // The same chassis after a reconnect: what it reported stays until it reports anew.
        tracker.handle_connected(ms(400), true);
        tracker.handle_rx(&system_v2(0), ms(400));
        tracker.poll(ms(700));
        assert_eq!(tracker.protocol(), Some(Protocol::V2));
        assert!(tracker.state().odometer.received.valid);
        // Another chassis after a reconnect is told anew, and nothing of the one before is
        // shown as its.
        tracker.handle_connected(ms(800), true);
        assert_eq!(tracker.protocol(), None);
        tracker.handle_rx(&status(0), ms(800));
        tracker.poll(ms(1100));
        assert_eq!(tracker.protocol(), Some(Protocol::V1));
        let state = tracker.state();
        assert!(!state.odometer.received.valid, "{:?}", state.odometer);
        assert!(!state.system.received.valid, "v2 bits are not v1's");
        assert_eq!(state.system.battery_decivolts, 0);
        tracker.handle_rx(&status(1), ms(1110));
        assert!(tracker.state().system.received.valid);
    }

    #[test]
    fn a_chassis_on_a_protocol_its_model_does_not_speak_is_not_driven() {
        let chassis = ChassisPayload::new(Model::Tracer, Model::Tracer.limits().angular);
        let mut tracker = StateTracker::new("t", Transport::Can, "can0", None, chassis);
        tracker.handle_connected(Duration::ZERO, false);
        tracker.handle_rx(&status(0), Duration::ZERO);
        tracker.poll(ms(300));
        assert_eq!(tracker.link_state(), LinkState::ProtocolMismatch);
        let why = tracker.mismatch().expect("said").clone();
        assert_eq!(why.reason, "not a tracer: it speaks protocol v1");
        // On v2 it is driven.
        let mut tracker = StateTracker::new("t", Transport::Can, "can0", None, chassis);
        tracker.handle_connected(Duration::ZERO, false);
        tracker.handle_rx(&system_v2(0), Duration::ZERO);
        tracker.poll(ms(300));
        assert!(tracker.mismatch().is_none());
        assert_eq!(tracker.state().chassis.model(), Some(Model::Tracer));
    }

    #[test]
    fn auto_with_a_configured_model_keeps_it() {
        let chassis = ChassisPayload::new(Model::ScoutMini, 2.5235);
        let mut tracker = StateTracker::new("t", Transport::Can, "can0", None, chassis);
        tracker.handle_connected(Duration::ZERO, false);
        tracker.handle_rx(&system_v2(0), Duration::ZERO);
        tracker.poll(ms(300));
        assert_eq!(tracker.state().chassis.model(), Some(Model::ScoutMini));
        let chassis = ChassisPayload {
            model: 0,
            ..ChassisPayload::new(Model::Scout, Model::Scout.limits().angular)
        };
        let mut tracker = StateTracker::new("t", Transport::Can, "can0", None, chassis);
        tracker.handle_connected(Duration::ZERO, false);
        tracker.handle_rx(&system_v2(0), Duration::ZERO);
        tracker.poll(ms(300));
        assert_eq!(tracker.state().chassis.model(), Some(Model::Scout2));
        let told = tracker.state().chassis;
        assert_eq!(
            told.track,
            Model::Scout2.geometry().track,
            "its geometry too"
        );
        assert_eq!(told.wheel_radius, Model::Scout2.geometry().wheel_radius);
    }

    #[test]
    fn feedback_of_both_protocols_is_a_mismatch_that_says_what_was_seen() {
        let mut tracker = connected_with(None);
        tracker.handle_rx(&status(0), Duration::ZERO);
        tracker.handle_rx(&odometer(0, 0), ms(100));
        tracker.poll(ms(500));
        assert_eq!(tracker.link_state(), LinkState::ProtocolMismatch);
        assert_eq!(tracker.protocol(), None);
        let why = tracker.mismatch().expect("a reason");
        assert!(
            why.detail.contains("0x151") && why.detail.contains("0x311"),
            "{why:?}"
        );
        assert!(why.reason.len() <= 64);
    }

    #[test]
    fn v2_commands_from_another_host_are_counted_not_applied() {
        let mut tracker = connected_with(Some(Protocol::V2));
        let command = RxEvent::V2(MessageV2::MotionCommand(MotionV2::from_si(0.5, 0.0)));
        assert_eq!(tracker.handle_rx(&command, ms(1)), Publish::No);
        assert_eq!(tracker.state().link.rejected_frames, 1);
        assert_eq!(tracker.state().link.rx_frames, 0);
    }

    #[test]
    fn odometry_integrates_motion_feedback_and_resets() {
        let mut tracker = connected();
        tracker.handle_rx(&status(0), Duration::ZERO);
        // 1 m/s for 1 s in 20 ms steps, then a quarter turn in place.
        for i in 0..=50u8 {
            tracker.handle_rx(&motion(i, 1000, 0), ms(u64::from(i) * 20));
        }
        let odometry = tracker.state().odometry;
        assert!((odometry.x - 1.0).abs() < 1e-9 && odometry.y.abs() < 1e-9);
        // A gap longer than 100 ms is not integrated.
        tracker.handle_rx(&motion(51, 1000, 0), ms(2000));
        assert!((tracker.state().odometry.x - 1.0).abs() < 1e-9);
        for i in 1..=50u8 {
            tracker.handle_rx(&motion(51 + i, 0, 1571), ms(2000 + u64::from(i) * 20));
        }
        assert!((tracker.state().odometry.yaw - 1.571).abs() < 0.02);
        tracker.reset_odometry();
        let odometry = tracker.state().odometry;
        assert_eq!(
            (odometry.x, odometry.y, odometry.yaw, odometry.resets),
            (0.0, 0.0, 0.0, 1)
        );
    }

    #[test]
    fn the_calibration_scales_the_distance_and_the_turn_on_both_protocols() {
        // The chassis reports 0.95 of its distance and 1.26 times its turn.
        let calibration = OdometryConfig {
            distance_scale: 1.0 / 0.95,
            yaw_scale: 1.0 / 1.26,
        };
        let mut tracker = connected().with_calibration(calibration);
        tracker.handle_rx(&status(0), Duration::ZERO);
        // v1: 1 m in 1 s, reported as 0.95 m/s; then a quarter turn reported as 1.26 of one.
        for i in 0..=50u8 {
            tracker.handle_rx(&motion(i, 950, 0), ms(u64::from(i) * 20));
        }
        let odometry = tracker.state().odometry;
        assert!((odometry.x - 1.0).abs() < 1e-9, "{odometry:?}");
        assert!((odometry.distance - 1.0).abs() < 1e-9, "{odometry:?}");
        for i in 1..=50u8 {
            tracker.handle_rx(&motion(50 + i, 0, 1979), ms(1000 + u64::from(i) * 20));
        }
        assert!((tracker.state().odometry.yaw - 1.571).abs() < 0.02);
        // v2: the odometers report 19 mm a step for 20 mm travelled.
        let mut tracker = connected_with(Some(Protocol::V2)).with_calibration(calibration);
        for i in 0..=50u64 {
            let mm = i as i32 * 19;
            tracker.handle_rx(&motion_v2(950, 0), ms(i * 20));
            tracker.handle_rx(&odometer(mm, mm), ms(i * 20));
        }
        let odometry = tracker.state().odometry;
        assert!((odometry.x - 1.0).abs() < 1e-9, "{odometry:?}");
    }

    #[test]
    fn on_v2_the_odometers_move_the_position_and_the_rates_turn_it() {
        let mut tracker = connected_with(Some(Protocol::V2));
        // The body rates say 2 m/s, the odometers 1 m/s: the odometers win.
        for i in 0..=50u64 {
            let t = ms(i * 20);
            let mm = i as i32 * 20;
            tracker.handle_rx(&motion_v2(2000, 0), t);
            tracker.handle_rx(&odometer(1000 + mm, -500 + mm), t);
        }
        let odometry = tracker.state().odometry;
        assert!((odometry.x - 1.0).abs() < 1e-9, "{odometry:?}");
        assert!((odometry.distance - 1.0).abs() < 1e-9);
        // Frames lost: the odometers' distance still counts, the rates' heading holds.
        tracker.handle_rx(&odometer(1000 + 1500, -500 + 1500), ms(1500));
        assert!((tracker.state().odometry.x - 1.5).abs() < 1e-9);
        // A quarter turn on the spot, then 1 m along the new heading.
        let mut t = 1500;
        for _ in 0..50 {
            t += 20;
            tracker.handle_rx(&motion_v2(0, 1571), ms(t));
            tracker.handle_rx(&odometer(2500, 1000), ms(t));
        }
        for i in 1..=50 {
            t += 20;
            tracker.handle_rx(&motion_v2(1000, 0), ms(t));
            tracker.handle_rx(&odometer(2500 + i * 20, 1000 + i * 20), ms(t));
        }
        let odometry = tracker.state().odometry;
        assert!((odometry.yaw - 1.571).abs() < 0.03, "{odometry:?}");
        assert!(
            (odometry.x - 1.5).abs() < 0.05 && (odometry.y - 1.0).abs() < 0.05,
            "{odometry:?}"
        );
        // A jump (the chassis power-cycled and its odometers restarted): not a step.
        t += 20;
        tracker.handle_rx(&odometer(0, 0), ms(t));
        let after = tracker.state().odometry;
        assert_eq!((after.x, after.y), (odometry.x, odometry.y));
        t += 20;
        tracker.handle_rx(&odometer(20, 20), ms(t));
        assert!(
            tracker.state().odometry.distance > after.distance,
            "counts from the new reading"
        );
    }

    #[test]
    fn feedback_no_scout_sends_stops_the_drive_and_says_what_chassis_it_looks_like() {
        let on_v2 = |model: Model| {
            let chassis = ChassisPayload::new(model, model.limits().angular);
            let mut tracker =
                StateTracker::new("test", Transport::Can, "can0", Some(Protocol::V2), chassis);
            tracker.handle_connected(Duration::ZERO, false);
            tracker.handle_rx(&motion_v2(300, 100), ms(10));
            tracker.poll(ms(20));
            assert_eq!(
                tracker.link_state(),
                LinkState::Ok,
                "{model}: a SCOUT's feedback"
            );
            tracker
        };
        let unknown = |id| RxEvent::Rejected(RxError::Can(can::CanError::UnknownId { id }));
        let motion = |lateral_mm_s, steering_mrad| {
            RxEvent::V2(MessageV2::MotionState(MotionV2 {
                linear_mm_s: 300,
                lateral_mm_s,
                steering_mrad,
                ..MotionV2::default()
            }))
        };
        // A Hunter 2.0's brake as it starts: locked.
        let braked = || {
            let RxEvent::V2(MessageV2::SystemState(system)) = system_v2(7) else {
                unreachable!()
            };
            RxEvent::V2(MessageV2::SystemState(SystemStateV2 {
                reserved: 1,
                ..system
            }))
        };
        for model in Model::ALL {
            for (event, sign) in [
                (unknown(0x271), Sign::SteeringAngles),
                (unknown(0x291), Sign::MotionMode),
                (motion(0, 200), Sign::Steering),
                (motion(-150, 0), Sign::Lateral),
                (braked(), Sign::ParkingBrake),
            ] {
                let mut tracker = on_v2(model);
                tracker.handle_rx(&event, ms(30));
                tracker.poll(ms(40));
                if model.may_send(sign) {
                    assert_eq!(tracker.link_state(), LinkState::Ok, "{model} {sign:?}");
                    assert!(tracker.mismatch().is_none());
                    continue;
                }
                assert_eq!(
                    tracker.link_state(),
                    LinkState::ProtocolMismatch,
                    "{model} {sign:?}"
                );
                let why = tracker.mismatch().expect("said").clone();
                assert!(
                    why.reason.len() <= 64
                        && why.reason.contains(model.name())
                        && why.reason.contains(sign.short()),
                    "{why:?}"
                );
                assert!(why.detail.contains(sign.suggests()), "{why:?}");
                // Nothing it sends is used until the port reopens; then it is judged again.
                let used = tracker.state().link.rx_frames;
                assert_eq!(tracker.handle_rx(&motion_v2(300, 0), ms(50)), Publish::No);
                assert_eq!(tracker.state().link.rx_frames, used);
                tracker.handle_connected(ms(60), false);
                assert!(tracker.mismatch().is_none(), "a new port");
                tracker.handle_rx(&event, ms(70));
                tracker.poll(ms(80));
                assert_eq!(tracker.link_state(), LinkState::ProtocolMismatch);
            }
        }
        // Only the OMNI moves sideways; nothing of the SCOUT family steers.
        assert!(Model::ScoutMiniOmni.may_send(Sign::Lateral));
        assert!(!Model::ScoutMiniOmni.may_send(Sign::Steering));
        // A brake reported tells a Hunter 2.0 from a Hunter SE, and is judged nowhere else
        // (0x211 byte 6 is reserved there).
        for model in Model::ALL {
            let se = model == Model::HunterSe;
            assert_eq!(model.may_send(Sign::ParkingBrake), !se, "{model}");
        }
        assert!(!Model::Scout2.sends(Sign::ParkingBrake));
    }

    #[test]
    fn commands_from_another_host_are_counted_not_applied() {
        let mut tracker = connected();
        let command = RxEvent::Message(Counted {
            message: Message::MotionCommand(MotionCommand::stop(ControlMode::Can)),
            count: 0,
        });
        assert_eq!(tracker.handle_rx(&command, ms(1)), Publish::No);
        assert_eq!(tracker.state().link.rejected_frames, 1);
    }

    #[test]
    fn auto_says_what_arrived_when_nothing_tells_the_protocol() {
        let mut tracker = connected_with(None);
        tracker.poll(UNTOLD_AFTER - ms(1));
        assert!(tracker.mismatch().is_none());
        tracker.poll(UNTOLD_AFTER);
        let why = tracker.mismatch().expect("said").clone();
        assert!(
            why.reason.contains("nothing received") && why.reason.len() <= 64,
            "{why:?}"
        );
        // Frames that tell nothing (v1's and v2's shared ids, another node's).
        let mut tracker = connected_with(None);
        tracker.handle_rx(&motion(0, 0, 0), ms(10));
        tracker.handle_rx(
            &RxEvent::Rejected(RxError::Can(can::CanError::UnknownId { id: 0x2F0 })),
            ms(20),
        );
        tracker.poll(UNTOLD_AFTER);
        let why = tracker.mismatch().expect("said").clone();
        assert!(
            why.reason.contains("0x131, 0x2F0") && why.reason.len() <= 64,
            "{why:?}"
        );
        assert_eq!(
            tracker.link_state(),
            LinkState::Silent,
            "not a mismatch: nothing to use yet"
        );
        // The chassis speaks at last: told, and the reason is gone.
        tracker.handle_rx(&status(0), UNTOLD_AFTER + ms(10));
        tracker.poll(UNTOLD_AFTER + ms(400));
        assert_eq!(tracker.protocol(), Some(Protocol::V1));
        assert!(tracker.mismatch().is_none());
    }
}
