//! What one page asks for, without I/O: its messages parsed, checked against its user's role,
//! its drives ordered and aged from the browser's clock (as the zenoh bridge ages a remote
//! peer's), its rate budgeted. Time in ([`Session::handle_message`]); what to ask the arbiter
//! out ([`Action`]). A stop is never refused for its rate or age.

use std::time::Duration;

use scout_interface::remote::{SenderTiming, TimingError};
use serde::Deserialize;

use crate::access::{Role, User};

/// The longest a page's drive command may live (the page sends 250 ms at 20 Hz).
pub const MAX_WEB_LIFE: Duration = Duration::from_millis(300);

/// The longest page message read, bytes.
pub const MAX_MESSAGE_BYTES: usize = 1024;

/// Messages other than stops a page may send per second, on average...
pub const RATE_PER_SECOND: u32 = 40;
/// ...and at once.
pub const RATE_BURST: u32 = 20;

/// The longest stop reason kept, bytes.
const MAX_REASON: usize = 96;

/// What a page sends (`op` names it).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "op", rename_all = "snake_case", deny_unknown_fields)]
pub enum Message {
    /// The E-STOP.
    Estop {
        /// Why, for the stop list.
        #[serde(default)]
        reason: Option<String>,
    },
    /// Release the user's own stops latched up to stop `through` (the newest the page showed).
    Release {
        /// The newest stop id the page showed.
        through: u64,
    },
    /// Take teleop control (a deliberate press).
    Take {},
    /// One drive command, while the control is held down.
    Drive {
        /// Rising per connection.
        seq: u64,
        /// The browser's clock when sent, ms (`performance.timeOrigin + performance.now()`).
        sent_ms: u64,
        /// m/s.
        linear: f64,
        /// m/s leftward (absent: 0; only a chassis that moves sideways takes another).
        #[serde(default)]
        lateral: f64,
        /// rad/s.
        angular: f64,
        /// Its life, ms (at most [`MAX_WEB_LIFE`]).
        #[serde(default)]
        ttl_ms: Option<u32>,
    },
    /// Let go: give up control.
    Relinquish {},
}

impl Message {
    /// Its `op`.
    pub fn op(&self) -> &'static str {
        match self {
            Message::Estop { .. } => "estop",
            Message::Release { .. } => "release",
            Message::Take {} => "take",
            Message::Drive { .. } => "drive",
            Message::Relinquish {} => "relinquish",
        }
    }

    /// The role it needs.
    fn needs(&self) -> Role {
        match self {
            Message::Estop { .. } | Message::Release { .. } => Role::Stop,
            Message::Take {} | Message::Drive { .. } | Message::Relinquish {} => Role::Drive,
        }
    }
}

/// What to ask the arbiter, as the page's user.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// Latch a stop owned by the user.
    Stop {
        /// Why.
        reason: String,
    },
    /// Release the user's own stops through `through`.
    Release {
        /// The newest stop the page showed.
        through: u64,
    },
    /// Take teleop control.
    TakeControl,
    /// Drive, as sent at `sent` on this host's clock, living `ttl`.
    Drive {
        /// m/s.
        linear: f64,
        /// m/s leftward.
        lateral: f64,
        /// rad/s.
        angular: f64,
        /// When the browser sent it, on this host's clock.
        sent: Duration,
        /// Its life.
        ttl: Duration,
    },
    /// Give up control.
    Relinquish,
}

/// Why a page's message is refused (told to the page and counted).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Refused {
    /// Not a message this server knows.
    #[error("not a page message: {0}")]
    Malformed(String),
    /// Longer than [`MAX_MESSAGE_BYTES`].
    #[error("a message of {0} bytes: at most {MAX_MESSAGE_BYTES}")]
    TooLarge(usize),
    /// The user's role does not allow it.
    #[error("{op} needs the {needs} role; {user} has {role}")]
    NotAllowed {
        /// The message's op.
        op: &'static str,
        /// The role it needs.
        needs: Role,
        /// The user.
        user: String,
        /// The user's role.
        role: Role,
    },
    /// Its order or its timing: a drive not newer than the last, a number or a stamp that
    /// leaps ahead, one held up past its life.
    #[error("drive not applied: {0}")]
    Timing(TimingError),
    /// Speeds not finite.
    #[error("speeds must be finite numbers")]
    NotFinite,
    /// Over the rate budget.
    #[error("more than {RATE_PER_SECOND} messages a second: slow down")]
    RateLimited,
}

impl Refused {
    /// Its kind, a word for counting and logs.
    pub fn kind(&self) -> &'static str {
        match self {
            Refused::Malformed(_) => "malformed",
            Refused::TooLarge(_) => "too_large",
            Refused::NotAllowed { .. } => "not_allowed",
            Refused::Timing(timing) => timing.kind(),
            Refused::NotFinite => "not_finite",
            Refused::RateLimited => "rate_limited",
        }
    }
}

/// One page's session.
#[derive(Debug)]
pub struct Session {
    user: User,
    /// Its drives' order and its clock.
    timing: SenderTiming,
    /// Messages left, in thousandths, and when last refilled.
    budget: (u64, Duration),
    /// It took control and has not given it up.
    holding: bool,
    /// Messages refused, by kind.
    refused: std::collections::BTreeMap<&'static str, u64>,
}

impl Session {
    /// A session of `user`, opened at `now`.
    pub fn new(user: User, now: Duration) -> Session {
        Session {
            user,
            timing: SenderTiming::default(),
            budget: (u64::from(RATE_BURST) * 1000, now),
            holding: false,
            refused: std::collections::BTreeMap::new(),
        }
    }

    /// Its user.
    pub fn user(&self) -> &User {
        &self.user
    }

    /// A message from the page, arrived at `now`: what to ask the arbiter, or why not.
    pub fn handle_message(&mut self, now: Duration, text: &str) -> Result<Action, Refused> {
        let handled = self.handle(now, text);
        if let Err(refused) = &handled {
            *self.refused.entry(refused.kind()).or_default() += 1;
        }
        handled
    }

    /// The messages refused so far, by kind (each kind once, counted).
    pub fn refused(&self) -> impl Iterator<Item = (&'static str, u64)> + '_ {
        self.refused.iter().map(|(kind, count)| (*kind, *count))
    }

    fn handle(&mut self, now: Duration, text: &str) -> Result<Action, Refused> {
        if text.len() > MAX_MESSAGE_BYTES {
            return Err(Refused::TooLarge(text.len()));
        }
        let message: Message =
            serde_json::from_str(text).map_err(|error| Refused::Malformed(error.to_string()))?;
        if self.user.role < message.needs() {
            return Err(Refused::NotAllowed {
                op: message.op(),
                needs: message.needs(),
                user: self.user.name.clone(),
                role: self.user.role,
            });
        }
        let drive = match message {
            Message::Estop { reason } => {
                let mut reason = reason.unwrap_or_default();
                if reason.trim().is_empty() {
                    reason = "E-STOP on the web page".into();
                }
                while reason.len() > MAX_REASON {
                    reason.pop();
                }
                return Ok(Action::Stop { reason });
            }
            Message::Release { through } => {
                self.spend(now)?;
                return Ok(Action::Release { through });
            }
            Message::Take {} => {
                self.spend(now)?;
                self.holding = true;
                self.timing.new_session();
                return Ok(Action::TakeControl);
            }
            Message::Relinquish {} => {
                self.spend(now)?;
                self.holding = false;
                return Ok(Action::Relinquish);
            }
            Message::Drive {
                seq,
                sent_ms,
                linear,
                lateral,
                angular,
                ttl_ms,
            } => (seq, sent_ms, (linear, lateral, angular), ttl_ms),
        };
        self.spend(now)?;
        let (seq, sent_ms, (linear, lateral, angular), ttl_ms) = drive;
        if !(linear.is_finite() && lateral.is_finite() && angular.is_finite()) {
            return Err(Refused::NotFinite);
        }
        let ttl = ttl_ms.map_or(MAX_WEB_LIFE, |ms| {
            Duration::from_millis(u64::from(ms)).min(MAX_WEB_LIFE)
        });
        let checked = (self.timing)
            .check(now, Some(seq), sent_ms, ttl)
            .map_err(Refused::Timing)?;
        self.timing.accept(checked);
        Ok(Action::Drive {
            linear,
            lateral,
            angular,
            sent: checked.sent,
            ttl,
        })
    }

    /// The page went away (closed, or its connection dropped): give up control if held.
    pub fn handle_close(&mut self) -> Option<Action> {
        std::mem::take(&mut self.holding).then_some(Action::Relinquish)
    }

    /// Takes one message from the budget at `now`.
    fn spend(&mut self, now: Duration) -> Result<(), Refused> {
        let (left, at) = self.budget;
        let refill = now.saturating_sub(at).as_millis() as u64 * u64::from(RATE_PER_SECOND);
        let left = (left + refill).min(u64::from(RATE_BURST) * 1000);
        self.budget = (left, now.max(at));
        if left < 1000 {
            return Err(Refused::RateLimited);
        }
        self.budget.0 = left - 1000;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const MS: Duration = Duration::from_millis(1);
    const ESTOP: &str = r#"{"op":"estop"}"#;

    fn session(role: Role) -> Session {
        Session::new(
            User {
                name: "alice".into(),
                role,
                token: "0123456789abcdef".into(),
            },
            Duration::ZERO,
        )
    }

    fn drive(seq: u64, sent_ms: u64) -> String {
        format!(
            r#"{{"op":"drive","seq":{seq},"sent_ms":{sent_ms},"linear":0.4,"angular":0,"ttl_ms":250}}"#
        )
    }

    #[test]
    fn drives_are_aged_from_the_fastest_delivery_and_late_ones_refused() {
        let mut page = session(Role::Drive);
        let now = 10_000 * MS;
        assert_eq!(
            page.handle_message(now, r#"{"op":"take"}"#),
            Ok(Action::TakeControl)
        );
        // The browser's clock is 5 s ahead; the first drive seeds the measure.
        let first = page
            .handle_message(now, &drive(1, 15_000))
            .expect("applied");
        assert_eq!(
            first,
            Action::Drive {
                linear: 0.4,
                lateral: 0.0,
                angular: 0.0,
                sent: now,
                ttl: 250 * MS
            }
        );
        // 50 ms later, sent 50 ms later: on time.
        assert!(
            page.handle_message(now + 50 * MS, &drive(2, 15_050))
                .is_ok()
        );
        // Held up 200 ms: still alive, sent as of 200 ms ago (less the 60 µs the offset may
        // rise in 300 ms: 200 ppm).
        match page.handle_message(now + 300 * MS, &drive(3, 15_100)) {
            Ok(Action::Drive { sent, .. }) => {
                assert!(sent.abs_diff(now + 100 * MS) < MS, "{sent:?}")
            }
            other => panic!("{other:?}"),
        }
        // Held up 260 ms: past its 250 ms life, and not learned.
        assert!(matches!(
            page.handle_message(now + 410 * MS, &drive(4, 15_150)),
            Err(Refused::Timing(TimingError::Late { life, .. })) if life == 250 * MS
        ));
        // Repeated or older: refused.
        assert_eq!(
            page.handle_message(now + 420 * MS, &drive(3, 15_160)),
            Err(Refused::Timing(TimingError::OutOfOrder { seq: 3, last: 3 }))
        );
        // The refused 4 moved nothing: a fresh 4 drives.
        assert!(
            page.handle_message(now + 430 * MS, &drive(4, 15_420))
                .is_ok()
        );
    }

    #[test]
    fn refusals_are_counted_by_kind() {
        let mut page = session(Role::View);
        assert_eq!(page.refused().count(), 0);
        for text in ["{", "nonsense", r#"{"op":"take"}"#, &drive(1, 0)] {
            assert!(page.handle_message(Duration::ZERO, text).is_err());
        }
        assert!(page.handle_message(Duration::ZERO, ESTOP).is_err());
        assert_eq!(
            page.refused().collect::<Vec<_>>(),
            [("malformed", 2), ("not_allowed", 3)]
        );
    }

    #[test]
    fn a_longer_life_than_allowed_is_cut_to_it() {
        let mut page = session(Role::Drive);
        let text = r#"{"op":"drive","seq":1,"sent_ms":0,"linear":0,"angular":0,"ttl_ms":60000}"#;
        match page.handle_message(Duration::ZERO, text) {
            Ok(Action::Drive { ttl, .. }) => assert_eq!(ttl, MAX_WEB_LIFE),
            other => panic!("{other:?}"),
        }
        let absent = r#"{"op":"drive","seq":2,"sent_ms":0,"linear":0,"angular":0}"#;
        match page.handle_message(Duration::ZERO, absent) {
            Ok(Action::Drive { ttl, .. }) => assert_eq!(ttl, MAX_WEB_LIFE),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn roles_bound_what_a_page_may_do() {
        let mut viewer = session(Role::View);
        for text in [ESTOP, r#"{"op":"release","through":3}"#, r#"{"op":"take"}"#] {
            assert!(
                matches!(
                    viewer.handle_message(Duration::ZERO, text),
                    Err(Refused::NotAllowed { .. })
                ),
                "{text}"
            );
        }
        let mut stopper = session(Role::Stop);
        assert_eq!(
            stopper.handle_message(Duration::ZERO, r#"{"op":"estop","reason":"cone"}"#),
            Ok(Action::Stop {
                reason: "cone".into()
            })
        );
        assert_eq!(
            stopper.handle_message(Duration::ZERO, r#"{"op":"release","through":3}"#),
            Ok(Action::Release { through: 3 })
        );
        assert!(matches!(
            stopper.handle_message(Duration::ZERO, &drive(1, 0)),
            Err(Refused::NotAllowed { .. })
        ));
    }

    #[test]
    fn a_stop_is_never_rate_limited_and_others_are() {
        let mut page = session(Role::Drive);
        let mut refused = 0;
        for seq in 1..=100 {
            if page.handle_message(Duration::ZERO, &drive(seq, 0)) == Err(Refused::RateLimited) {
                refused += 1;
            }
        }
        assert_eq!(refused, 100 - RATE_BURST as usize);
        assert!(matches!(
            page.handle_message(Duration::ZERO, ESTOP),
            Ok(Action::Stop { .. })
        ));
        // A second later the budget is back.
        assert!(
            page.handle_message(Duration::from_secs(1), &drive(101, 1000))
                .is_ok()
        );
    }

    #[test]
    fn closing_a_page_that_holds_control_gives_it_up_once() {
        let mut page = session(Role::Drive);
        assert_eq!(page.handle_close(), None);
        page.handle_message(Duration::ZERO, r#"{"op":"take"}"#)
            .expect("take");
        assert_eq!(page.handle_close(), Some(Action::Relinquish));
        assert_eq!(page.handle_close(), None);
    }

    #[test]
    fn bad_messages_say_why() {
        let mut page = session(Role::Drive);
        for text in [
            "",
            "{}",
            r#"{"op":"fly"}"#,
            r#"{"op":"take","x":1}"#,
            r#"{"op":"drive","seq":1}"#,
        ] {
            assert!(
                matches!(
                    page.handle_message(Duration::ZERO, text),
                    Err(Refused::Malformed(_))
                ),
                "{text}"
            );
        }
        let huge = format!(r#"{{"op":"estop","reason":"{}"}}"#, "x".repeat(2000));
        assert!(matches!(
            page.handle_message(Duration::ZERO, &huge),
            Err(Refused::TooLarge(_))
        ));
        let long = format!(r#"{{"op":"estop","reason":"{}"}}"#, "é".repeat(200));
        match page.handle_message(Duration::ZERO, &long) {
            Ok(Action::Stop { reason }) => assert!(reason.len() <= MAX_REASON),
            other => panic!("{other:?}"),
        }
        let not_finite = r#"{"op":"drive","seq":1,"sent_ms":0,"linear":1e999,"angular":0}"#;
        assert!(page.handle_message(Duration::ZERO, not_finite).is_err());
        let sideways =
            r#"{"op":"drive","seq":2,"sent_ms":0,"linear":0,"lateral":1e999,"angular":0}"#;
        assert!(page.handle_message(Duration::ZERO, sideways).is_err());
    }

    #[test]
    fn a_drive_carries_its_sideways_speed_and_zero_without_one() {
        let mut page = session(Role::Drive);
        page.handle_message(Duration::ZERO, r#"{"op":"take"}"#)
            .expect("taken");
        let sideways = r#"{"op":"drive","seq":1,"sent_ms":0,"linear":0,"lateral":-0.3,"angular":0,"ttl_ms":250}"#;
        assert!(matches!(
            page.handle_message(Duration::ZERO, sideways),
            Ok(Action::Drive { lateral, .. }) if lateral == -0.3
        ));
        assert!(matches!(
            page.handle_message(Duration::ZERO, &drive(2, 0)),
            Ok(Action::Drive { lateral, .. }) if lateral == 0.0
        ));
    }

    proptest! {
        /// Whatever a page sends, in any order and timing: nothing panics, no drive out of order
        /// or older than its life is applied, and a stop is always passed on.
        #[test]
        fn no_late_or_reordered_drive_is_ever_applied(
            steps in proptest::collection::vec((0u64..400, 0u64..6, 0u64..400, any::<bool>()), 1..60)
        ) {
            let mut page = session(Role::Drive);
            let mut now = Duration::ZERO;
            let mut applied: Option<u64> = None;
            let mut seq = 0;
            for (gap, seq_step, sent_ms, stop) in steps {
                now += Duration::from_millis(gap);
                if stop {
                    let stopped = page.handle_message(now, ESTOP);
                    prop_assert!(matches!(stopped, Ok(Action::Stop { .. })), "{:?}", stopped);
                    continue;
                }
                seq += seq_step;
                if let Ok(Action::Drive { sent, ttl, .. }) = page.handle_message(now, &drive(seq, sent_ms)) {
                    prop_assert!(applied.is_none_or(|last| seq > last));
                    applied = Some(seq);
                    prop_assert!(now - sent <= ttl);
                }
            }
        }
    }
}
