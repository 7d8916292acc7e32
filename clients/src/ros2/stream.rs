//! When a cmd_vel stream may take control of the chassis (sans-IO: times and the arbiter's
//! answers in, what to ask the arbiter out).
//!
//! ROS publishers stream `Twist` messages and know nothing of leases, so the bridge takes
//! control for them, and only on a deliberate act: a stream that **starts** (its first message
//! after [`CmdVelStream::new`]'s silence) or a stream that **comes back to zero** (the sender
//! let go of the stick, or the planner finished). A stream that was already going when the
//! bridge started, or that goes on across a stop, a takeover, a release or a refusal, never
//! takes control again by itself: its sender must pause or send a zero first. A zero twist
//! never takes control (it asks for no motion).

use std::time::Duration;

use super::msgs::PlanarTwist;

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
    /// it must pause or send a zero first.
    MidStream,
    /// A zero twist without control: there is nothing to stop.
    Zero,
}

impl Ignored {
    pub fn reason(self) -> &'static str {
        match self {
            Ignored::MidStream => {
                "the stream went on across a stop, takeover, release or refusal (or was going \
                 when the bridge started): pause it or send a zero twist, then publish again"
            }
            Ignored::Zero => "a zero twist without control asks for nothing",
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

/// One cmd_vel topic's stream.
#[derive(Debug, Clone)]
pub struct CmdVelStream {
    new_after: Duration,
    last: Duration,
    holding: bool,
    /// Lost (or refused) control: waiting for a pause or a zero.
    blocked: bool,
    /// The current message starts a stream (it follows a pause) and is not a zero.
    starts: bool,
    asked: Option<Action>,
}

impl CmdVelStream {
    /// A stream first heard at `now`: messages within `new_after` of each other (and of `now`)
    /// are one stream.
    pub fn new(now: Duration, new_after: Duration) -> Self {
        Self {
            new_after,
            last: now,
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

    /// A message arrived at `now`: what to ask the arbiter.
    pub fn handle_twist(&mut self, now: Duration, twist: PlanarTwist) -> Action {
        let zero = twist.linear == 0.0 && twist.angular == 0.0;
        let starts = now.saturating_sub(self.last) >= self.new_after;
        self.last = self.last.max(now);
        if starts || zero {
            self.blocked = false;
        }
        self.starts = starts && !zero;
        let action = if self.holding {
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

    fn go() -> PlanarTwist {
        PlanarTwist {
            linear: 0.5,
            angular: 0.0,
        }
    }

    fn zero() -> PlanarTwist {
        PlanarTwist {
            linear: 0.0,
            angular: 0.0,
        }
    }

    #[test]
    fn a_stream_going_when_the_bridge_starts_waits_for_a_pause() {
        let mut stream = CmdVelStream::new(ms(0), NEW);
        for t in (20..2000).step_by(20) {
            assert_eq!(
                stream.handle_twist(ms(t), go()),
                Action::Ignore(Ignored::MidStream)
            );
        }
        assert_eq!(stream.handle_twist(ms(2600), go()), Action::Take);
        assert_eq!(stream.handle_answer(Outcome::Accepted), Some(Action::Drive));
        assert_eq!(stream.handle_answer(Outcome::Accepted), None);
        assert_eq!(stream.handle_twist(ms(2620), go()), Action::Drive);
    }

    #[test]
    fn a_stream_that_goes_on_across_a_stop_never_takes_control_again() {
        let mut stream = CmdVelStream::new(ms(0), NEW);
        assert_eq!(stream.handle_twist(ms(1000), go()), Action::Take);
        stream.handle_answer(Outcome::Accepted);
        stream.handle_answer(Outcome::Accepted);
        // The stop revokes the lease; the stream goes on, through the release and after.
        assert_eq!(stream.handle_twist(ms(1020), go()), Action::Drive);
        assert_eq!(stream.handle_answer(Outcome::LostControl), None);
        for t in (1040..5000).step_by(20) {
            assert_eq!(
                stream.handle_twist(ms(t), go()),
                Action::Ignore(Ignored::MidStream)
            );
        }
        // A zero (the sender let go), then motion: a deliberate act.
        assert_eq!(
            stream.handle_twist(ms(5000), zero()),
            Action::Ignore(Ignored::Zero)
        );
        assert_eq!(stream.handle_twist(ms(5020), go()), Action::Take);
    }

    #[test]
    fn a_refused_take_waits_for_a_pause_too() {
        let mut stream = CmdVelStream::new(ms(0), NEW);
        assert_eq!(stream.handle_twist(ms(1000), go()), Action::Take);
        assert_eq!(stream.handle_answer(Outcome::Refused), None);
        assert_eq!(
            stream.handle_twist(ms(1020), go()),
            Action::Ignore(Ignored::MidStream)
        );
        assert_eq!(stream.handle_twist(ms(1600), go()), Action::Take);
    }

    #[test]
    fn a_new_stream_takes_control_again_when_the_old_lease_lapsed() {
        let mut stream = CmdVelStream::new(ms(0), NEW);
        stream.handle_twist(ms(1000), go());
        stream.handle_answer(Outcome::Accepted);
        stream.handle_answer(Outcome::Accepted);
        assert_eq!(stream.handle_twist(ms(3000), go()), Action::Drive);
        assert_eq!(
            stream.handle_answer(Outcome::LostControl),
            Some(Action::Take)
        );
        assert_eq!(stream.handle_answer(Outcome::Accepted), Some(Action::Drive));
        assert_eq!(stream.handle_answer(Outcome::Accepted), None);
        assert!(stream.holding());
    }

    /// A message `after_ms` after the one before; a zero twist or motion.
    fn event() -> impl Strategy<Value = (u64, bool)> {
        (0u64..1200, proptest::bool::weighted(0.15))
    }

    fn outcome() -> impl Strategy<Value = Outcome> {
        prop_oneof![
            Just(Outcome::Accepted),
            Just(Outcome::LostControl),
            Just(Outcome::Refused)
        ]
    }

    proptest! {
        /// Whatever the arbiter answers, control is taken only by a message that starts a
        /// stream (a pause of `NEW` before it) or follows a zero since control was last lost
        /// or refused; never by a zero; and never at the bridge's start mid-stream.
        #[test]
        fn control_is_taken_only_after_a_pause_or_a_zero(
            events in proptest::collection::vec(event(), 1..200),
            outcomes in proptest::collection::vec(outcome(), 400),
        ) {
            let mut stream = CmdVelStream::new(ms(0), NEW);
            let mut outcomes = outcomes.into_iter().cycle();
            let (mut now, mut last) = (ms(0), ms(0));
            // The model: a pause or a zero since control was last lost or refused.
            let mut eligible = false;
            for event in events {
                {
                    let (after_ms, zero) = event;
                    {
                        now += ms(after_ms);
                        let starts = now - last >= NEW;
                        last = now;
                        if starts || zero {
                            eligible = true;
                        }
                        let holding = stream.holding();
                        let twist = if zero { self::zero() } else { go() };
                        let mut action = stream.handle_twist(now, twist);
                        if starts && !zero && !holding {
                            prop_assert_eq!(action, Action::Take, "a new stream did not take control");
                        }
                        loop {
                            if action == Action::Take {
                                prop_assert!(eligible, "took control mid-stream at {:?}", now);
                                prop_assert!(!zero, "a zero took control");
                            }
                            let Action::Ignore(_) = action else {
                                let outcome = outcomes.next().unwrap_or(Outcome::Accepted);
                                let next = stream.handle_answer(outcome);
                                match (action, outcome) {
                                    (Action::Take, Outcome::Accepted) => {}
                                    (Action::Take, _) => eligible = false,
                                    (Action::Drive, Outcome::LostControl)
                                        if next != Some(Action::Take) => eligible = false,
                                    _ => {}
                                }
                                match next {
                                    Some(next) => {
                                        action = next;
                                        continue;
                                    }
                                    None => break,
                                }
                            };
                            break;
                        }
                    }
                }
            }
        }
    }
}
