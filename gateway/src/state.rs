//! The one chassis state: received feedback, link statistics and state, odometry. Sans-IO: events
//! and CLOCK_MONOTONIC times in, the payload to publish out.

use std::time::Duration;

use scout_interface::state::{CommandPayload, LinkState, OdometryPayload, Received, StatePayload};
use scout_interface::{FixedText, Transport};
use scout_protocol::kinematics::Pose;
use scout_protocol::link::RxEvent;
use scout_protocol::sequence::{Continuity, SequenceTracker};
use scout_protocol::slcan::Slcan;
use scout_protocol::version::{ProtocolVersion, VersionDetector};
use scout_protocol::{Counted, Direction, Message, MotionCommand};
use tracing::{error, info, warn};

/// No valid feedback for this long: the link is `silent`.
pub const SILENT_AFTER: Duration = Duration::from_millis(100);
/// Odometry does not integrate across a gap longer than this (the speed over it is unknown).
const MAX_ODOMETRY_STEP: Duration = Duration::from_millis(100);

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

/// The chassis state and what keeps it up to date.
#[derive(Debug, Clone)]
pub struct StateTracker {
    state: StatePayload,
    sequence: SequenceTracker,
    version: VersionDetector,
    link_state: LinkState,
    last_feedback: Option<Duration>,
    foreign_commands_reported: bool,
    /// The link's port counters when the current port opened: a new port counts from zero.
    counted_by_closed_ports: PortCounters,
}

/// What the port itself counts, from when it opened.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PortCounters {
    /// Bytes the stream decoder threw away while resynchronising (serial, slcan).
    pub discarded_bytes: u64,
    /// Frames the kernel dropped because its receive queue was full (SocketCAN).
    pub overflowed_frames: u64,
}

impl StateTracker {
    /// A tracker for `robot` on `transport`/`device`, before the port is open.
    pub fn new(robot: &str, transport: Transport, device: &str, max_angular: f64) -> Self {
        let mut state = StatePayload {
            robot: FixedText::new(robot),
            max_angular,
            ..StatePayload::default()
        };
        state.link.transport = transport.raw();
        state.link.device = FixedText::new(device);
        state.link.state = LinkState::Disconnected.raw();
        Self {
            state,
            sequence: SequenceTracker::new(),
            version: VersionDetector::new(),
            link_state: LinkState::Disconnected,
            last_feedback: None,
            foreign_commands_reported: false,
            counted_by_closed_ports: PortCounters::default(),
        }
    }

    /// When the last valid feedback came, since the port opened.
    pub fn last_feedback(&self) -> Option<Duration> {
        self.last_feedback
    }

    /// The current link state.
    pub fn link_state(&self) -> LinkState {
        self.link_state
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

    /// The port opened (again): counts restart, another chassis may be at the other end.
    pub fn handle_connected(&mut self, reconnect: bool) -> Publish {
        self.sequence.reset();
        self.version.reset();
        self.last_feedback = None;
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

    /// A motion command was sent.
    pub fn handle_sent_motion(&mut self, command: &MotionCommand, now: Duration) {
        self.state.link.tx_frames += 1;
        self.state.command = CommandPayload {
            linear: command.linear(),
            angular: command.angular(self.state.max_angular),
            at_ns: nanos(now),
        };
    }

    /// Some other frame was sent.
    pub fn handle_sent_other(&mut self) {
        self.state.link.tx_frames += 1;
    }

    /// Resets odometry to the origin.
    pub fn reset_odometry(&mut self) -> Publish {
        let resets = self.state.odometry.resets + 1;
        self.state.odometry = OdometryPayload {
            resets,
            ..OdometryPayload::default()
        };
        Publish::Yes
    }

    /// Time passes: the link goes silent after 100 ms without feedback, and a v2 chassis is
    /// recognised.
    pub fn poll(&mut self, now: Duration) -> Publish {
        if self.link_state == LinkState::Disconnected {
            return Publish::No;
        }
        if self.version.version(now) == ProtocolVersion::V2 {
            if self.link_state != LinkState::ProtocolV2 {
                error!(
                    "the chassis speaks protocol v2, not supported by this gateway (v1 only): \
                     nothing it sends is published"
                );
            }
            return self.set_link_state(LinkState::ProtocolV2);
        }
        let silent = self
            .last_feedback
            .is_none_or(|last| now.saturating_sub(last) >= SILENT_AFTER);
        if silent && self.link_state == LinkState::Ok {
            return self.set_link_state(LinkState::Silent);
        }
        Publish::No
    }

    /// One thing received from the port at `now`.
    pub fn handle_rx(&mut self, event: &RxEvent, now: Duration) -> Publish {
        match event {
            RxEvent::Message(counted) => {
                self.version.observe(counted.message.kind().can_id(), now);
                self.handle_message(counted, now)
            }
            RxEvent::V2(message) => {
                // A protocol v2 chassis: its frames tell the version, and are not ours to use.
                self.version.observe(message.can_id(), now);
                self.state.link.rejected_frames += 1;
                Publish::No
            }
            RxEvent::Rejected(rejected) => {
                if let Some(id) = rejected.can_id() {
                    self.version.observe(id, now);
                }
                if rejected.is_checksum() {
                    self.state.link.checksum_errors += 1;
                } else {
                    self.state.link.rejected_frames += 1;
                }
                Publish::No
            }
            RxEvent::Slcan(Slcan::Nack) => {
                warn!("the slcan adapter answered with an error (BEL)");
                Publish::No
            }
            RxEvent::Slcan(_) => Publish::No,
        }
    }

    fn handle_message(&mut self, counted: &Counted, now: Duration) -> Publish {
        let kind = counted.message.kind();
        if kind.direction() == Direction::Command {
            if !self.foreign_commands_reported {
                warn!(
                    "another host sends {} (0x{:03X}) on the bus: two programs are commanding \
                     the chassis",
                    kind.name(),
                    kind.can_id()
                );
                self.foreign_commands_reported = true;
            }
            self.state.link.rejected_frames += 1;
            return Publish::No;
        }
        self.state.link.rx_frames += 1;
        if let Continuity::Gap { lost } = self.sequence.observe(kind, counted.count) {
            self.state.link.dropped_frames += u64::from(lost);
        }
        if self.version.version(now) != ProtocolVersion::V1 {
            // Until a 0x151 proves v1, ids that v2 shares (0x131, 0x141) may mean something else.
            return Publish::No;
        }
        self.last_feedback = Some(now);
        if let Message::MotionFeedback(motion) = &counted.message {
            self.integrate_odometry(motion.linear(), motion.angular(), now);
        }
        let received = Received {
            valid: true,
            count: counted.count,
            at_ns: nanos(now),
        };
        self.state.store(&counted.message, received);
        self.set_link_state(LinkState::Ok);
        Publish::Yes
    }

    fn integrate_odometry(&mut self, linear: f64, angular: f64, now: Duration) {
        let previous = self.state.motion;
        if !previous.received.valid {
            return;
        }
        let step = now.saturating_sub(Duration::from_nanos(previous.received.at_ns));
        if step.is_zero() || step > MAX_ODOMETRY_STEP {
            return;
        }
        let dt = step.as_secs_f64();
        // Trapezoid between the previous and this feedback.
        let prior = previous.feedback();
        let v = (prior.linear() + linear) / 2.0;
        let w = (prior.angular() + angular) / 2.0;
        let odometry = &mut self.state.odometry;
        let mut pose = Pose {
            x: odometry.x,
            y: odometry.y,
            yaw: odometry.yaw,
        };
        pose.step(v, w, dt);
        (odometry.x, odometry.y, odometry.yaw) = (pose.x, pose.y, pose.yaw);
        odometry.distance += (v * dt).abs();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_protocol::link::RxError;
    use scout_protocol::units::DEFAULT_MAX_ANGULAR_SPEED;
    use scout_protocol::{ChassisState, ControlMode, FaultBits, MotionFeedback, SystemStatus, can};

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

    fn connected() -> StateTracker {
        let mut tracker =
            StateTracker::new("test", Transport::Can, "vcan0", DEFAULT_MAX_ANGULAR_SPEED);
        assert_eq!(tracker.handle_connected(false), Publish::Yes);
        tracker
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
    fn protocol_v2_is_recognised_and_not_published() {
        let mut tracker = connected();
        let v2 = can::CanError::UnknownId { id: 0x221 };
        tracker.handle_rx(&RxEvent::Rejected(RxError::Can(v2)), Duration::ZERO);
        assert_eq!(tracker.handle_rx(&motion(0, 500, 0), ms(1)), Publish::No);
        assert_eq!(tracker.poll(ms(999)), Publish::No);
        assert_eq!(tracker.poll(ms(1000)), Publish::Yes);
        assert_eq!(tracker.link_state(), LinkState::ProtocolV2);
        assert!(!tracker.state().motion.received.valid);
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
    fn commands_from_another_host_are_counted_not_applied() {
        let mut tracker = connected();
        let command = RxEvent::Message(Counted {
            message: Message::MotionCommand(MotionCommand::stop(ControlMode::Can)),
            count: 0,
        });
        assert_eq!(tracker.handle_rx(&command, ms(1)), Publish::No);
        assert_eq!(tracker.state().link.rejected_frames, 1);
    }
}
