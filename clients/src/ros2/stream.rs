//! When a cmd_vel stream may take control of the chassis (sans-IO: times, the messages'
//! publisher and sequence number, and the arbiter's answers in; what to ask the arbiter out).
//!
//! ROS publishers stream `Twist` messages and know nothing of leases, so the bridge takes
//! control for them, and only on a deliberate act: a stream that **starts**, its first message
//! after a pause. A pause is silence of at least `new_after` and at least [`PAUSE_PERIODS`]
//! times the stream's own shortest recent interval (a 2 Hz stream pauses only after 1.5 s),
//! with no message lost in it: a message whose publisher's sequence number jumped continues the
//! stream (the network dropped it for a while: a router outage, a Wi-Fi gap), it does not start
//! one. A stream that was going when the bridge started, or that goes on across a stop, a
//! takeover, a release, a resume or a refusal, never takes control again by itself: its sender
//! must pause first. A zero twist never takes control (it asks for no motion), nor does a
//! speed that is not a finite number.

use std::collections::VecDeque;
use std::time::Duration;

use super::msgs::PlanarTwist;

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

/// Who sent a message, as its rmw_zenoh attachment says: the publisher's GID and its sequence
/// number. Only used to tell a pause from lost messages, never to grant anything.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Origin {
    pub gid: [u8; 16],
    pub sequence: i64,
}

/// One cmd_vel topic's stream.
#[derive(Debug, Clone)]
pub struct CmdVelStream {
    new_after: Duration,
    last: Duration,
    last_origin: Option<Origin>,
    recent: VecDeque<Duration>,
    holding: bool,
    /// Lost (or refused) control: waiting for a pause.
    blocked: bool,
    /// The current message starts a stream and asks for motion.
    starts: bool,
    asked: Option<Action>,
}

impl CmdVelStream {
    /// A stream first heard at `now`: a message within `new_after` of `now` continues a stream
    /// that may have been going before.
    pub fn new(now: Duration, new_after: Duration) -> Self {
        Self {
            new_after,
            last: now,
            last_origin: None,
            recent: VecDeque::with_capacity(RECENT_INTERVALS),
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

    /// The silence that counts as a pause now.
    pub fn pause(&self) -> Duration {
        let shortest = self.recent.iter().min().copied().unwrap_or_default();
        self.new_after.max(shortest * PAUSE_PERIODS)
    }

    /// A message from `origin` arrived at `now`: what to ask the arbiter.
    pub fn handle_twist(&mut self, now: Duration, origin: Origin, twist: PlanarTwist) -> Action {
        let gap = now.saturating_sub(self.last);
        let lost = self.last_origin.is_some_and(|last| {
            last.gid == origin.gid && origin.sequence != last.sequence.wrapping_add(1)
        });
        let starts = gap >= self.pause() && !lost;
        // The stream's rate, from the intervals between its messages (not from the start).
        if self.last_origin.is_some() {
            if self.recent.len() == RECENT_INTERVALS {
                self.recent.pop_front();
            }
            self.recent.push_back(gap);
        }
        self.last = self.last.max(now);
        self.last_origin = Some(origin);
        if starts {
            self.blocked = false;
        }
        let finite = twist.linear.is_finite() && twist.angular.is_finite();
        let zero = twist.linear == 0.0 && twist.angular == 0.0;
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

    const NEW: Duration = Duration::from_millis(500);

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    const GO: PlanarTwist = PlanarTwist {
        linear: 0.5,
        angular: 0.0,
    };
    const ZERO: PlanarTwist = PlanarTwist {
        linear: 0.0,
        angular: 0.0,
    };

    /// One publisher: its GID and the next sequence number.
    struct Publisher(u8, i64);

    impl Publisher {
        fn send(&mut self, stream: &mut CmdVelStream, at_ms: u64, twist: PlanarTwist) -> Action {
            self.1 += 1;
            let origin = Origin {
                gid: [self.0; 16],
                sequence: self.1,
            };
            stream.handle_twist(ms(at_ms), origin, twist)
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

    const MID: Action = Action::Ignore(Ignored::MidStream);

    #[test]
    fn a_stream_going_when_the_bridge_starts_waits_for_a_pause() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), NEW), Publisher(1, 0));
        for t in (20..2000).step_by(20) {
            assert_eq!(nav.send(&mut stream, t, GO), MID);
        }
        assert_eq!(nav.send(&mut stream, 2600, GO), Action::Take);
        taken(&mut stream);
        assert_eq!(nav.send(&mut stream, 2620, GO), Action::Drive);
    }

    #[test]
    fn a_stream_that_goes_on_across_a_stop_never_takes_control_again() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), NEW), Publisher(1, 0));
        assert_eq!(nav.send(&mut stream, 1000, GO), Action::Take);
        taken(&mut stream);
        // The stop revokes the lease; the stream goes on, through the release and after.
        assert_eq!(nav.send(&mut stream, 1020, GO), Action::Drive);
        assert_eq!(stream.handle_answer(Outcome::LostControl), None);
        for t in (1040..5000).step_by(20) {
            assert_eq!(nav.send(&mut stream, t, GO), MID);
        }
        // Zeros mid-stream (a collision monitor's, a controller passing through zero) do not
        // re-arm it either.
        assert_eq!(
            nav.send(&mut stream, 5000, ZERO),
            Action::Ignore(Ignored::Zero)
        );
        assert_eq!(nav.send(&mut stream, 5020, GO), MID);
        // A pause, then motion: a deliberate act.
        assert_eq!(nav.send(&mut stream, 5600, GO), Action::Take);
    }

    #[test]
    fn a_slow_stream_pauses_only_for_several_of_its_periods() {
        let (mut stream, mut slow) = (CmdVelStream::new(ms(0), NEW), Publisher(1, 0));
        assert_eq!(slow.send(&mut stream, 1000, GO), Action::Take);
        taken(&mut stream);
        assert_eq!(slow.send(&mut stream, 1500, GO), Action::Drive);
        assert_eq!(stream.handle_answer(Outcome::Accepted), None);
        // At 2 Hz, a pause is 1.5 s.
        assert_eq!(stream.pause(), ms(1500));
        assert_eq!(slow.send(&mut stream, 2000, GO), Action::Drive);
        assert_eq!(stream.handle_answer(Outcome::LostControl), None);
        for t in (2500..6000).step_by(500) {
            assert_eq!(slow.send(&mut stream, t, GO), MID);
        }
        assert_eq!(slow.send(&mut stream, 7100, GO), Action::Take);
    }

    #[test]
    fn messages_lost_on_the_way_are_no_pause() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), NEW), Publisher(1, 0));
        assert_eq!(nav.send(&mut stream, 1000, GO), Action::Take);
        taken(&mut stream);
        // The router goes away for 3 s; the publisher goes on; the lease lapses.
        nav.lose(150);
        assert_eq!(nav.send(&mut stream, 4000, GO), Action::Drive);
        assert_eq!(stream.handle_answer(Outcome::LostControl), None);
        assert_eq!(nav.send(&mut stream, 4020, GO), MID);
        // Another publisher after a pause may start a stream.
        let mut teleop = Publisher(2, 0);
        assert_eq!(teleop.send(&mut stream, 5000, GO), Action::Take);
    }

    #[test]
    fn a_refused_take_waits_for_a_pause_too() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), NEW), Publisher(1, 0));
        assert_eq!(nav.send(&mut stream, 1000, GO), Action::Take);
        assert_eq!(stream.handle_answer(Outcome::Refused), None);
        assert_eq!(nav.send(&mut stream, 1020, GO), MID);
        assert_eq!(nav.send(&mut stream, 1600, GO), Action::Take);
    }

    #[test]
    fn a_new_stream_takes_control_again_when_the_old_lease_lapsed() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), NEW), Publisher(1, 0));
        nav.send(&mut stream, 1000, GO);
        taken(&mut stream);
        assert_eq!(nav.send(&mut stream, 3000, GO), Action::Drive);
        assert_eq!(
            stream.handle_answer(Outcome::LostControl),
            Some(Action::Take)
        );
        taken(&mut stream);
        assert!(stream.holding());
    }

    #[test]
    fn no_number_takes_control() {
        let (mut stream, mut nav) = (CmdVelStream::new(ms(0), NEW), Publisher(1, 0));
        let nan = PlanarTwist {
            linear: f64::NAN,
            angular: 0.0,
        };
        assert_eq!(
            nav.send(&mut stream, 1000, nan),
            Action::Ignore(Ignored::NotFinite)
        );
    }

    /// A message `after_ms` after the one before, from publisher 0 or 1, with `lost` messages
    /// of that publisher lost before it; a zero twist or motion.
    fn event() -> impl Strategy<Value = (u64, u8, i64, bool)> {
        (
            prop_oneof![0u64..100, 0u64..3000],
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
        /// Whatever the arbiter answers: control is taken only by a message that follows a
        /// pause (at least `NEW` and three times the shortest of the last 8 intervals, no
        /// message of its publisher lost) since control was last lost or refused; never by a
        /// zero; never at the bridge's start mid-stream. And a stream that starts does take it.
        #[test]
        fn control_is_taken_only_after_a_pause(
            events in proptest::collection::vec(event(), 1..200),
            outcomes in proptest::collection::vec(outcome(), 400),
        ) {
            let mut stream = CmdVelStream::new(ms(0), NEW);
            let mut outcomes = outcomes.into_iter().cycle();
            let (mut now, mut last) = (ms(0), ms(0));
            let mut sequences = [0i64; 2];
            let mut last_publisher = None;
            let mut intervals: Vec<Duration> = Vec::new();
            // The model: a pause since control was last lost or refused.
            let mut eligible = false;
            for (after_ms, publisher, lost, zero) in events {
                now += ms(after_ms);
                sequences[usize::from(publisher)] += 1 + lost;
                let shortest = intervals.iter().rev().take(8).min().copied().unwrap_or_default();
                let pause = now - last >= NEW.max(shortest * 3)
                    && !(last_publisher == Some(publisher) && lost > 0);
                if last_publisher.is_some() {
                    intervals.push(now - last);
                }
                last = now;
                last_publisher = Some(publisher);
                if pause {
                    eligible = true;
                }
                let holding = stream.holding();
                let twist = if zero { ZERO } else { GO };
                let origin = Origin {
                    gid: [publisher; 16],
                    sequence: sequences[usize::from(publisher)],
                };
                let mut action = stream.handle_twist(now, origin, twist);
                if pause && !zero && !holding {
                    prop_assert_eq!(action, Action::Take, "a new stream did not take control");
                }
                while action != Action::Ignore(Ignored::MidStream)
                    && action != Action::Ignore(Ignored::Zero)
                {
                    if action == Action::Take {
                        prop_assert!(eligible, "took control mid-stream at {:?}", now);
                        prop_assert!(!zero, "a zero took control");
                    }
                    let outcome = outcomes.next().unwrap_or(Outcome::Accepted);
                    let next = stream.handle_answer(outcome);
                    match (action, outcome) {
                        (Action::Take, Outcome::Accepted) => {}
                        (Action::Take, _) => eligible = false,
                        (Action::Drive, Outcome::LostControl) if next != Some(Action::Take) => {
                            eligible = false;
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
