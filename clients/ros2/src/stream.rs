//! When a cmd_vel stream may take control of the chassis (sans-IO: arrival times, the
//! messages' publisher, sequence number and source time, and the arbiter's answers in; what
//! to ask the arbiter out).
//!
//! ROS publishers stream `Twist` messages and know nothing of leases, so the bridge takes
//! control for them, and only on a deliberate act: a stream that **starts**, its first message
//! after a **pause**. A pause is silence both as the messages arrive and on the publisher's own
//! clock (a frozen router or a starved bridge delivers a burst late: no pause), with none of
//! that publisher's messages lost (a sequence number that jumps is a network gap, not a pause),
//! of at least [`PAUSE_PERIODS`] times the median of the recent intervals (a slow stream's
//! pause is longer) and at least:
//! - [`Pauses::new_stream`] (500 ms) for a stream that let its control lapse by its own
//!   silence: a new press of a teleop key;
//! - [`Pauses::blocked`] (2 s) for a stream that went on across a stop, a takeover, a release,
//!   a resume or a refusal, or that may have been going when the bridge started: a controller's
//!   stall is not a pause.
//!
//! A zero twist never takes control (it asks for no motion), nor does a NaN. A stream slower
//! than one message per [`Pauses::blocked`] cannot be told from separate commands.

use std::collections::VecDeque;
use std::time::Duration;

use crate::msgs::PlanarTwist;

/// A pause is at least this many times the stream's shortest recent interval.
pub const PAUSE_PERIODS: u32 = 3;
/// The intervals the stream's rate is judged on.
const RECENT_INTERVALS: usize = 8;

/// What to ask the arbiter for a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Take control, then (on acceptance) drive.
    Take,
    /// Drive under the control held.
    Drive,
    /// Nothing: the message is dropped, for this reason.
    Ignore(Ignored),
}

/// Why a message does not reach the arbiter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ignored {
    /// The stream went on across a loss of control (or was going when the bridge started):
    /// it must pause first.
    MidStream,
    /// A zero twist without control: there is nothing to stop.
    Zero,
    /// A speed that is NaN or infinite.
    NotFinite,
}

impl Ignored {
    pub fn reason(self) -> &'static str {
        match self {
            Ignored::MidStream => {
                "the stream went on across a stop, takeover, release, resume or refusal (or was \
                 going when the bridge started): stop publishing for a moment, then publish again"
            }
            Ignored::Zero => "a zero twist without control asks for nothing",
            Ignored::NotFinite => "a speed is NaN or infinite",
        }
    }
}

/// How the arbiter answered the last [`Action`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    Accepted,
    /// Refused because this client holds no control (revoked, stale, never taken).
    LostControl,
    /// Refused for any other reason (stopped, held by another client, autonomy disarmed, a
    /// bad value).
    Refused,
}

/// Who sent a message and when, as its rmw_zenoh attachment says: the publisher's GID, its
/// sequence number and its clock. Only used to tell a pause from lost or delayed messages,
/// never to grant anything.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Origin {
    pub gid: [u8; 16],
    pub sequence: i64,
    /// The publisher's source time, ns (compared only with its own earlier times).
    pub sent_ns: i64,
}

/// The pause thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pauses {
    /// A stream that let its control lapse by its own silence starts again after this.
    pub new_stream: Duration,
    /// A stream that went on across a loss of control (or was going at the start) starts
    /// again only after this.
    pub blocked: Duration,
}

/// What the stream keeps of one publisher.
#[derive(Debug, Clone)]
struct Record {
    sequence: i64,
    sent_ns: i64,
    /// Its recent intervals on its own clock.
    intervals: VecDeque<Duration>,
    used: Duration,
}

/// Publishers remembered per topic; the least recently heard is forgotten past this.
const PUBLISHERS: usize = 16;

/// The median of recent intervals (robust to one bunched pair or one late message).
fn median(intervals: &VecDeque<Duration>) -> Duration {
    let mut sorted: Vec<Duration> = intervals.iter().copied().collect();
    sorted.sort();
    sorted.get(sorted.len() / 2).copied().unwrap_or_default()
}

fn push(intervals: &mut VecDeque<Duration>, interval: Duration) {
    if intervals.len() == RECENT_INTERVALS {
        intervals.pop_front();
    }
    intervals.push_back(interval);
}

/// One cmd_vel topic's stream.
#[derive(Debug, Clone)]
pub struct CmdVelStream {
    pauses: Pauses,
    last: Duration,
    /// Arrival intervals on the topic (any publisher), after the first message.
    arrivals: VecDeque<Duration>,
    heard: bool,
    publishers: Vec<([u8; 16], Record)>,
    holding: bool,
    /// Lost (or refused) control: waiting for a pause of [`Pauses::blocked`].
    blocked: bool,
    /// The current message starts a stream and asks for motion.
    starts: bool,
    asked: Option<Action>,
}

impl CmdVelStream {
    /// A stream first heard at `now`; it counts as going already (blocked) until a pause.
    pub fn new(now: Duration, pauses: Pauses) -> Self {
        Self {
            pauses,
            last: now,
            arrivals: VecDeque::with_capacity(RECENT_INTERVALS),
            heard: false,
            publishers: Vec::new(),
            holding: false,
            blocked: true,
            starts: false,
            asked: None,
        }
    }

    /// Whether the bridge believes it holds control for this stream.
    pub fn holding(&self) -> bool {
        self.holding
    }

    /// The silence that counts as a pause now, for intervals whose median is `median`.
    fn threshold(&self, median: Duration) -> Duration {
        let base = if self.blocked {
            self.pauses.blocked
        } else {
            self.pauses.new_stream
        };
        base.max(median * PAUSE_PERIODS)
    }

    /// Whether a message arriving at `now` from `origin` follows a pause: silence on the topic
    /// as it arrives and, for a publisher heard before, on its own clock, with none of its
    /// messages lost.
    fn follows_pause(&self, now: Duration, origin: Origin) -> bool {
        let arrival_gap = now.saturating_sub(self.last);
        if arrival_gap < self.threshold(median(&self.arrivals)) {
            return false;
        }
        match self.publishers.iter().find(|(gid, _)| *gid == origin.gid) {
            None => true,
            Some((_, record)) => {
                let sent_gap = Duration::from_nanos(
                    u64::try_from(origin.sent_ns.saturating_sub(record.sent_ns)).unwrap_or(0),
                );
                origin.sequence == record.sequence.wrapping_add(1)
                    && sent_gap >= self.threshold(median(&record.intervals))
            }
        }
    }

    fn remember(&mut self, now: Duration, origin: Origin) {
        if self.heard {
            push(&mut self.arrivals, now.saturating_sub(self.last));
        }
        self.heard = true;
        self.last = self.last.max(now);
        let index = match self
            .publishers
            .iter()
            .position(|(gid, _)| *gid == origin.gid)
        {
            Some(index) => {
                let record = &mut self.publishers[index].1;
                let sent_gap = origin.sent_ns.saturating_sub(record.sent_ns);
                push(
                    &mut record.intervals,
                    Duration::from_nanos(u64::try_from(sent_gap).unwrap_or(0)),
                );
                index
            }
            None => {
                if self.publishers.len() == PUBLISHERS
                    && let Some(oldest) = (0..PUBLISHERS).min_by_key(|&i| self.publishers[i].1.used)
                {
                    self.publishers.swap_remove(oldest);
                }
                self.publishers.push((
                    origin.gid,
                    Record {
                        sequence: origin.sequence,
                        sent_ns: origin.sent_ns,
                        intervals: VecDeque::with_capacity(RECENT_INTERVALS),
                        used: now,
                    },
                ));
                self.publishers.len() - 1
            }
        };
        let record = &mut self.publishers[index].1;
        record.sequence = origin.sequence;
        record.sent_ns = origin.sent_ns;
        record.used = now;
    }

    /// A message from `origin` arrived at `now`: what to ask the arbiter.
    pub fn handle_twist(&mut self, now: Duration, origin: Origin, twist: PlanarTwist) -> Action {
        let starts = self.follows_pause(now, origin);
        self.remember(now, origin);
        if starts {
            self.blocked = false;
        }
        let speeds = [twist.linear, twist.lateral, twist.angular];
        let finite = speeds.iter().all(|speed| speed.is_finite());
        let zero = speeds.iter().all(|speed| *speed == 0.0);
        self.starts = starts && finite && !zero;
        let action = if !finite {
            Action::Ignore(Ignored::NotFinite)
        } else if self.holding {
            Action::Drive
        } else if zero {
            Action::Ignore(Ignored::Zero)
        } else if self.blocked {
            Action::Ignore(Ignored::MidStream)
        } else {
            Action::Take
        };
        self.asked = Some(action);
        action
    }

    /// The arbiter's answer to the last action: the next action for the same message, if any.
    pub fn handle_answer(&mut self, outcome: Outcome) -> Option<Action> {
        let asked = self.asked.take()?;
        let next = match (asked, outcome) {
            (Action::Take, Outcome::Accepted) => {
                self.holding = true;
                Some(Action::Drive)
            }
            (Action::Take, Outcome::LostControl | Outcome::Refused) => {
                self.holding = false;
                self.blocked = true;
                None
            }
            (Action::Drive, Outcome::Accepted) => None,
            // A stream that starts may find its old control lapsed: it takes control anew.
            (Action::Drive, Outcome::LostControl) if self.starts => {
                self.holding = false;
                Some(Action::Take)
            }
            (Action::Drive, Outcome::LostControl) => {
                self.holding = false;
                self.blocked = true;
                None
            }
            (Action::Drive, Outcome::Refused) | (Action::Ignore(_), _) => None,
        };
        self.starts = false;
        self.asked = next;
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const PAUSES: Pauses = Pauses {
        new_stream: Duration::from_millis(500),
        blocked: Duration::from_millis(2000),
    };

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    const GO: PlanarTwist = PlanarTwist {
        linear: 0.5,
        lateral: 0.0,
        angular: 0.0,
    };
    const ZERO: PlanarTwist = PlanarTwist {
        linear: 0.0,
        lateral: 0.0,
        angular: 0.0,
    };

    /// One publisher: its GID and the next sequence number; it stamps what it sends with the
    /// arrival time plus `delay_ms` (a late delivery).
    struct Publisher(u8, i64);

    impl Publisher {
        fn send_late(
            &mut self,
            stream: &mut CmdVelStream,
            sent_ms: u64,
            delay_ms: u64,
            twist: PlanarTwist,
        ) -> Action {
            self.1 += 1;
            let origin = Origin {
                gid: [self.0; 16],
                sequence: self.1,
                sent_ns: ms(sent_ms).as_nanos() as i64,
            };
            stream.handle_twist(ms(sent_ms + delay_ms), origin, twist)
        }

        fn send(&mut self, stream: &mut CmdVelStream, at_ms: u64, twist: PlanarTwist) -> Action {
            self.send_late(stream, at_ms, 0, twist)
        }

        /// Messages the network lost.
        fn lose(&mut self, count: i64) {
            self.1 += count;
        }
    }

    fn taken(stream: &mut CmdVelStream) {
        assert_eq!(stream.handle_answer(Outcome::Accepted), Some(Action::Drive));
        assert_eq!(stream.handle_answer(Outcome::Accepted), None);
    }

    /// A stream holding control at `at_ms`, stopped (its control revoked) at the next message.
    fn stopped(stream: &mut CmdVelStream, publisher: &mut Publisher, at_ms: u64) {
        assert_eq!(publisher.send(stream, at_ms, GO), Action::Take);
        taken(stream);
        assert_eq!(publisher.send(stream, at_ms + 50, GO), Action::Drive);
        assert_eq!(stream.handle_answer(Outcome::LostControl), None);
    }

    const MID: Action = Action::Ignore(Ignored::MidStream);

    #[test]
    fn sideways_alone_is_a_speed_and_not_a_number_sideways_is_ignored() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        let sideways = PlanarTwist {
            linear: 0.0,
            lateral: 0.3,
            angular: 0.0,
        };
        assert_eq!(nav.send(&mut stream, 3000, sideways), Action::Take);
        taken(&mut stream);
        let nan = PlanarTwist {
            lateral: f64::NAN,
            ..sideways
        };
        assert_eq!(
            nav.send(&mut stream, 3020, nan),
            Action::Ignore(Ignored::NotFinite)
        );
    }

    #[test]
    fn a_stream_going_when_the_bridge_starts_waits_for_a_long_pause() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        for t in (20..3000).step_by(20) {
            assert_eq!(nav.send(&mut stream, t, GO), MID);
        }
        // Half a second is not enough for a stream that may have been going.
        assert_eq!(nav.send(&mut stream, 3600, GO), MID);
        assert_eq!(nav.send(&mut stream, 5700, GO), Action::Take);
        taken(&mut stream);
        assert_eq!(nav.send(&mut stream, 5720, GO), Action::Drive);
    }

    #[test]
    fn a_slow_stream_going_when_the_bridge_starts_never_starts() {
        for period in [500, 1000] {
            let (mut stream, mut slow) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
            for t in (100..20_000).step_by(period) {
                assert_eq!(slow.send(&mut stream, t as u64, GO), MID, "{period} ms");
            }
        }
    }

    #[test]
    fn a_stream_that_goes_on_across_a_stop_never_takes_control_again() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        stopped(&mut stream, &mut nav, 3000);
        for t in (3100..6000).step_by(20) {
            assert_eq!(nav.send(&mut stream, t, GO), MID);
        }
        // Zeros mid-stream (a collision monitor's) and a controller's stall do not re-arm it.
        assert_eq!(
            nav.send(&mut stream, 6000, ZERO),
            Action::Ignore(Ignored::Zero)
        );
        assert_eq!(nav.send(&mut stream, 6020, GO), MID);
        assert_eq!(nav.send(&mut stream, 6800, GO), MID);
        // A long pause, then motion: a deliberate act.
        assert_eq!(nav.send(&mut stream, 9000, GO), Action::Take);
    }

    #[test]
    fn a_burst_delivered_late_is_no_pause() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        stopped(&mut stream, &mut nav, 3000);
        for t in (3100..4000).step_by(50) {
            assert_eq!(nav.send(&mut stream, t, GO), MID);
        }
        // The router freezes for 3 s: the messages sent meanwhile arrive late, all at once.
        for t in (4000..7000).step_by(50) {
            assert_eq!(nav.send_late(&mut stream, t, 7000 - t, GO), MID);
        }
    }

    #[test]
    fn messages_lost_on_the_way_are_no_pause_whoever_comes_first() {
        let (mut stream, mut a) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        let mut b = Publisher(2, 0);
        stopped(&mut stream, &mut a, 3000);
        for t in (3100..4000).step_by(50) {
            assert_eq!(b.send(&mut stream, t, GO), MID);
            assert_eq!(a.send(&mut stream, t + 25, GO), MID);
        }
        // The router goes away for 3 s; both publishers go on.
        a.lose(60);
        b.lose(60);
        assert_eq!(a.send(&mut stream, 7000, GO), MID);
        assert_eq!(b.send(&mut stream, 7025, GO), MID);
    }

    #[test]
    fn a_slow_stream_pauses_only_for_several_of_its_periods() {
        let (mut stream, mut slow) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        assert_eq!(slow.send(&mut stream, 3000, GO), Action::Take);
        taken(&mut stream);
        for t in [4000, 5000, 6000] {
            assert_eq!(slow.send(&mut stream, t, GO), Action::Drive);
            assert_eq!(stream.handle_answer(Outcome::Accepted), None);
        }
        assert_eq!(slow.send(&mut stream, 7000, GO), Action::Drive);
        assert_eq!(stream.handle_answer(Outcome::LostControl), None);
        // One bunched pair does not shorten its pause.
        assert_eq!(slow.send(&mut stream, 7020, GO), MID);
        for t in (8000..14_000).step_by(1000) {
            assert_eq!(slow.send(&mut stream, t, GO), MID);
        }
        assert_eq!(slow.send(&mut stream, 17_100, GO), Action::Take);
    }

    #[test]
    fn a_refused_take_waits_for_a_pause_too() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        assert_eq!(nav.send(&mut stream, 3000, GO), Action::Take);
        assert_eq!(stream.handle_answer(Outcome::Refused), None);
        assert_eq!(nav.send(&mut stream, 3020, GO), MID);
        assert_eq!(nav.send(&mut stream, 5100, GO), Action::Take);
    }

    #[test]
    fn a_key_pressed_again_takes_control_again_after_its_lease_lapsed() {
        let (mut stream, mut keys) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        keys.send(&mut stream, 3000, GO);
        taken(&mut stream);
        // The key released (the lease goes stale), pressed again 0.8 s later.
        assert_eq!(keys.send(&mut stream, 3800, GO), Action::Drive);
        assert_eq!(
            stream.handle_answer(Outcome::LostControl),
            Some(Action::Take)
        );
        taken(&mut stream);
        assert!(stream.holding());
    }

    #[test]
    fn no_number_takes_control() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), PAUSES), Publisher(1, 0));
        let nan = PlanarTwist {
            linear: f64::NAN,
            lateral: 0.0,
            angular: 0.0,
        };
        assert_eq!(
            nav.send(&mut stream, 3000, nan),
            Action::Ignore(Ignored::NotFinite)
        );
    }

    /// A message arriving `after_ms` after the one before, sent `sent_ms` after its
    /// publisher's previous one, from publisher 0 or 1, with `lost` of its messages lost
    /// before it; a zero twist or motion.
    fn event() -> impl Strategy<Value = (u64, u64, u8, i64, bool)> {
        (
            prop_oneof![0u64..100, 0u64..4000],
            prop_oneof![0u64..100, 0u64..4000],
            0u8..2,
            prop_oneof![4 => Just(0i64), 1 => 1i64..20],
            proptest::bool::weighted(0.15),
        )
    }

    fn outcome() -> impl Strategy<Value = Outcome> {
        prop_oneof![
            Just(Outcome::Accepted),
            Just(Outcome::LostControl),
            Just(Outcome::Refused)
        ]
    }

    proptest! {
        /// Whatever the arbiter answers and however the messages arrive, control is taken
        /// only after a pause (silence on arrival and, for a publisher heard before, on its
        /// own clock with none of its messages lost) of at least the blocked pause since
        /// control was last lost or refused and since the start; never by a zero. And a
        /// message after a long pause everywhere does take control.
        #[test]
        fn control_is_taken_only_after_a_pause(
            events in proptest::collection::vec(event(), 1..200),
            outcomes in proptest::collection::vec(outcome(), 400),
        ) {
            let mut stream = CmdVelStream::new(ms(0), PAUSES);
            let mut outcomes = outcomes.into_iter().cycle();
            let (mut now, mut last) = (ms(0), ms(0));
            // Per publisher: sequence number and source time of its last message.
            let mut sent: [Option<(i64, u64)>; 2] = [None, None];
            let mut sequences = [0i64; 2];
            let mut clocks = [0u64; 2];
            // The model: blocked since the start or a loss, as the bridge promises.
            let mut blocked = true;
            for (after_ms, sent_after_ms, publisher, lost, zero) in events {
                let p = usize::from(publisher);
                now += ms(after_ms);
                sequences[p] += 1 + lost;
                clocks[p] += sent_after_ms;
                let arrival_gap = now - last;
                let own = sent[p].map(|(sequence, at)| (sequences[p] == sequence + 1, clocks[p] - at));
                let gap = |least: Duration| {
                    arrival_gap >= least
                        && own.is_none_or(|(continuous, sent_gap)| continuous && ms(sent_gap) >= least)
                };
                let needed = if blocked { PAUSES.blocked } else { PAUSES.new_stream };
                let may_start = gap(needed);
                let surely_starts = gap(ms(30_000));
                last = now;
                sent[p] = Some((sequences[p], clocks[p]));
                let holding = stream.holding();
                let twist = if zero { ZERO } else { GO };
                let origin = Origin {
                    gid: [publisher; 16],
                    sequence: sequences[p],
                    sent_ns: ms(clocks[p]).as_nanos() as i64,
                };
                let mut action = stream.handle_twist(now, origin, twist);
                if surely_starts && !zero && !holding {
                    prop_assert_eq!(action, Action::Take, "a new stream did not take control");
                }
                if may_start {
                    blocked = false;
                }
                while let Action::Take | Action::Drive = action {
                    if action == Action::Take {
                        prop_assert!(!blocked, "took control without a pause at {:?}", now);
                        prop_assert!(!zero, "a zero took control");
                    }
                    let outcome = outcomes.next().unwrap_or(Outcome::Accepted);
                    let next = stream.handle_answer(outcome);
                    match (action, outcome) {
                        (Action::Take, Outcome::Accepted) => {}
                        (Action::Take, _) => blocked = true,
                        (Action::Drive, Outcome::LostControl) if next != Some(Action::Take) => {
                            blocked = true;
                        }
                        _ => {}
                    }
                    match next {
                        Some(next) => action = next,
                        None => break,
                    }
                }
            }
        }
    }
}
