//! A protocol v2 chassis' command mode, as the gateway takes and watches it (protocol-v2-notes 5):
//! the chassis starts in standby and obeys 0x111 only after the host sends 0x421 `[01]` and its
//! 0x211 reports CAN command mode. Sans-IO: the reported mode and time in; when to send 0x421,
//! and the losses that stop the robot, out.
//!
//! The rules, which keep v2 as safe as v1:
//! - 0x421 `[01]` goes out only when a client is about to drive (the arbiter has selected one:
//!   it took control, no stop holds the robot), never at start-up or after a reconnect, and
//!   only on a 0x211 at most [`REPORT_FRESH`] old that does not report the RC: the gateway
//!   never asks for a mode it cannot see.
//! - It is repeated every [`REQUEST_REPEAT`] while the client still wants to drive, and only
//!   when a 0x211 since the last request says the chassis is still not in CAN mode, and every
//!   0x211 since the first request came (none lost: an RC episode the gateway did not see
//!   could lie in a gap, and a repeat after it would take the chassis from the person who
//!   just let go of it). If CAN mode is not reported within [`TAKE_TIMEOUT`], the take failed:
//!   a stop says so and what to check.
//! - A client that no longer wants to drive (a stop, a release) ends the request: nothing more
//!   is sent.
//! - Once held, any other mode but the RC's (standby, UART, unknown) is a loss: a stop. The RC
//!   taking over is the RC stop of both protocols, and the gateway never fights it: no 0x421
//!   while the RC holds the chassis, and none after it lets go until a release and a new take.

use std::time::Duration;

use scout_protocol::v2::ControlModeV2;

/// How often 0x421 `[01]` is repeated until the chassis reports CAN mode (its 0x211 comes every
/// 100 ms, so one lost frame costs one repeat).
pub const REQUEST_REPEAT: Duration = Duration::from_millis(200);

/// How long the chassis has to report CAN mode after the first 0x421 `[01]`; also how long a
/// client may want to drive while no 0x211 tells the mode (the chassis sends other feedback).
pub const TAKE_TIMEOUT: Duration = Duration::from_millis(1000);

/// How old the last 0x211 may be for the gateway to act on the mode it reported; two 0x211
/// further apart than this have a gap between them (two or more lost: 0x211 comes every
/// 100 ms).
pub const REPORT_FRESH: Duration = Duration::from_millis(250);

/// Where the gateway stands with the chassis' command mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Holding {
    /// Not asked for (since the start, a loss or a reconnect); a client has wanted to drive
    /// since `wanted_since` without a fresh 0x211 to act on.
    Idle { wanted_since: Option<Duration> },
    /// 0x421 `[01]` sent first at `since`, last at `last_sent`; `answered`: a 0x211 came since
    /// the last one; `gap`: some 0x211 since the first was lost.
    Requested {
        since: Duration,
        last_sent: Duration,
        answered: bool,
        gap: bool,
    },
    /// The chassis reported CAN mode after a request.
    Held,
}

const IDLE: Holding = Holding::Idle { wanted_since: None };

/// A loss of the command mode: the robot must stop until a release and a new take.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ModeLost {
    /// The stop's reason: what happened and what to check, short enough for the status (64
    /// bytes).
    pub reason: String,
    /// The same at length, for the log.
    pub detail: String,
}

/// The command mode of one port session.
#[derive(Debug, Clone)]
pub struct CommandMode {
    holding: Holding,
    /// The mode the last 0x211 reported, and when.
    reported: Option<(ControlModeV2, Duration)>,
}

impl Default for CommandMode {
    fn default() -> Self {
        Self::new()
    }
}

impl CommandMode {
    /// Nothing asked, nothing reported.
    pub fn new() -> Self {
        Self {
            holding: IDLE,
            reported: None,
        }
    }

    /// Whether the chassis is known to be in CAN mode at the gateway's request.
    pub fn is_held(&self) -> bool {
        self.holding == Holding::Held
    }

    /// Whether 0x421 `[01]` was sent and not yet answered.
    pub fn is_requested(&self) -> bool {
        matches!(self.holding, Holding::Requested { .. })
    }

    /// The mode the last 0x211 reported.
    pub fn reported(&self) -> Option<ControlModeV2> {
        self.reported.map(|(mode, _)| mode)
    }

    /// The port opened again: another chassis, or the same one after a power cycle.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// A 0x211 reported `mode` at `now`.
    pub fn handle_reported(&mut self, mode: ControlModeV2, now: Duration) -> Option<ModeLost> {
        let gap = self
            .reported
            .is_some_and(|(_, at)| now.saturating_sub(at) > REPORT_FRESH);
        self.reported = Some((mode, now));
        if let Holding::Requested {
            since, last_sent, ..
        } = self.holding
        {
            let had_gap = matches!(self.holding, Holding::Requested { gap: true, .. });
            self.holding = Holding::Requested {
                since,
                last_sent,
                answered: true,
                gap: had_gap || gap,
            };
        }
        match (self.holding, mode) {
            // The RC has the top authority: let go at once (its own stop is the RC override).
            (_, ControlModeV2::Rc) => {
                self.holding = IDLE;
                None
            }
            (Holding::Requested { .. } | Holding::Held, ControlModeV2::Can) => {
                self.holding = Holding::Held;
                None
            }
            (Holding::Held, ControlModeV2::Standby | ControlModeV2::Uart)
            | (Holding::Held, ControlModeV2::Unknown(_)) => {
                self.holding = IDLE;
                Some(ModeLost {
                    reason: format!("left CAN mode for {}: check RC SWB, e-stops", mode.name()),
                    detail: format!(
                        "the chassis left CAN command mode: it reports {} (0x211 byte 1 = {}); \
                         check the RC's SWB and the e-stops, then release and take control again",
                        mode.name(),
                        mode.raw()
                    ),
                })
            }
            // Not asked for yet, or still waiting for the answer.
            (Holding::Idle { .. }, _) | (Holding::Requested { .. }, _) => None,
        }
    }

    /// The mode the last 0x211 reported, if it is at most [`REPORT_FRESH`] old at `now`.
    fn fresh(&self, now: Duration) -> Option<ControlModeV2> {
        self.reported
            .filter(|(_, at)| now.saturating_sub(*at) <= REPORT_FRESH)
            .map(|(mode, _)| mode)
    }

    /// Whether to send 0x421 `[01]` at `now`: `wanted` says a client is about to drive. A
    /// request the chassis does not answer in time is a loss, and so is a client wanting to
    /// drive for [`TAKE_TIMEOUT`] while no 0x211 tells the mode.
    pub fn poll(&mut self, now: Duration, wanted: bool) -> Result<bool, ModeLost> {
        match self.holding {
            Holding::Held => Ok(false),
            Holding::Idle { .. } | Holding::Requested { .. } if !wanted => {
                // A stop or a release: whatever was asked is not asked any more.
                self.holding = IDLE;
                Ok(false)
            }
            Holding::Idle { wanted_since } => match self.fresh(now) {
                // The RC's own stop holds the robot; nothing is asked of the chassis.
                Some(ControlModeV2::Rc) => Ok(false),
                Some(
                    ControlModeV2::Can
                    | ControlModeV2::Standby
                    | ControlModeV2::Uart
                    | ControlModeV2::Unknown(_),
                ) => {
                    self.holding = Holding::Requested {
                        since: now,
                        last_sent: now,
                        answered: false,
                        gap: false,
                    };
                    Ok(true)
                }
                None => {
                    let since = wanted_since.unwrap_or(now);
                    self.holding = Holding::Idle {
                        wanted_since: Some(since),
                    };
                    if now.saturating_sub(since) <= TAKE_TIMEOUT {
                        return Ok(false);
                    }
                    self.holding = IDLE;
                    let last = self.reported.map_or("none at all".to_owned(), |(_, at)| {
                        format!("the last {} ms ago", now.saturating_sub(at).as_millis())
                    });
                    Err(ModeLost {
                        reason: "no 0x211 (system state): the command mode is unknown".into(),
                        detail: format!(
                            "a client wants to drive, but no system state (0x211) from the \
                             chassis tells its command mode ({last}), so 0x421 is not sent: \
                             is a v2 chassis at the other end? (`scout doctor`)"
                        ),
                    })
                }
            },
            Holding::Requested { since, gap, .. } if now.saturating_sub(since) > TAKE_TIMEOUT => {
                self.holding = IDLE;
                let answer = self
                    .reported
                    .filter(|(_, at)| *at > since)
                    .map(|(mode, _)| mode);
                let (short, reported) = match (answer, gap) {
                    (_, true) => (
                        "0x211 lost".to_owned(),
                        "system states (0x211) were lost meanwhile, so it was not asked again \
                         (an RC episode may lie in the gap)"
                            .to_owned(),
                    ),
                    (Some(mode), false) => (
                        mode.name().to_owned(),
                        format!("it reports {}", mode.name()),
                    ),
                    (None, false) => (
                        "no 0x211".to_owned(),
                        "no system state (0x211) came since".to_owned(),
                    ),
                };
                Err(ModeLost {
                    reason: format!("0x421 not taken in 1 s ({short}): RC SWB, SWA up? e-stops?"),
                    detail: format!(
                        "the chassis did not enter CAN command mode within {} ms of 0x421: \
                         {reported}; with the RC transmitter on, its SWB must be up, SWA up and \
                         the e-stops released; then release and take control again",
                        TAKE_TIMEOUT.as_millis()
                    ),
                })
            }
            Holding::Requested {
                since,
                last_sent,
                answered: true,
                gap: false,
            } if now.saturating_sub(last_sent) >= REQUEST_REPEAT => {
                self.holding = Holding::Requested {
                    since,
                    last_sent: now,
                    answered: false,
                    gap: false,
                };
                Ok(true)
            }
            Holding::Requested { .. } => Ok(false),
        }
    }

    /// When [`CommandMode::poll`] next has something to do, if anything.
    pub fn poll_timeout(&self) -> Option<Duration> {
        let after_timeout = Duration::from_millis(1);
        match self.holding {
            Holding::Requested {
                since, last_sent, ..
            } => Some((last_sent + REQUEST_REPEAT).min(since + TAKE_TIMEOUT + after_timeout)),
            Holding::Idle {
                wanted_since: Some(since),
            } => Some(since + TAKE_TIMEOUT + after_timeout),
            Holding::Idle { wanted_since: None } | Holding::Held => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    /// The chassis' 0x211 every 100 ms from `from` up to `to`, reporting `mode`, with the
    /// gateway polling every 20 ms meanwhile (`wanted`); returns how many 0x421 went out.
    fn run(
        mode: &mut CommandMode,
        reported: ControlModeV2,
        from: u64,
        to: u64,
        wanted: bool,
    ) -> Result<usize, ModeLost> {
        let mut sent = 0;
        for t in (from..to).step_by(20) {
            if t % 100 == 0 {
                assert_eq!(mode.handle_reported(reported, ms(t)), None, "at {t} ms");
            }
            if mode.poll(ms(t), wanted)? {
                sent += 1;
            }
        }
        Ok(sent)
    }

    #[test]
    fn nothing_is_asked_until_a_client_drives() {
        let mut mode = CommandMode::new();
        assert_eq!(
            run(&mut mode, ControlModeV2::Standby, 0, 2000, false),
            Ok(0)
        );
        assert!(!mode.is_held());
        assert_eq!(mode.poll_timeout(), None);
    }

    #[test]
    fn a_take_is_asked_repeated_and_held_when_reported() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(1000));
        assert_eq!(mode.poll(ms(1000), true), Ok(true), "0x421 at once");
        assert_eq!(mode.poll(ms(1100), true), Ok(false));
        assert_eq!(
            mode.handle_reported(ControlModeV2::Standby, ms(1100)),
            None,
            "not yet"
        );
        assert_eq!(mode.poll(ms(1200), true), Ok(true), "repeated");
        assert_eq!(mode.handle_reported(ControlModeV2::Can, ms(1200)), None);
        assert!(mode.is_held());
        assert_eq!(
            mode.poll(ms(1400), true),
            Ok(false),
            "held: nothing more to send"
        );
        assert_eq!(mode.poll_timeout(), None);
    }

    #[test]
    fn a_take_the_chassis_does_not_answer_is_a_loss_with_what_to_check() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        assert_eq!(mode.poll(ms(0), true), Ok(true));
        let mut sent = 1;
        let mut t = 0;
        let lost = loop {
            t += 10;
            if t % 100 == 0 {
                mode.handle_reported(ControlModeV2::Standby, ms(t));
            }
            match mode.poll(ms(t), true) {
                Ok(true) => sent += 1,
                Ok(false) => {}
                Err(lost) => break lost,
            }
        };
        assert!(t > TAKE_TIMEOUT.as_millis() as u64 && t <= 1010, "{t}");
        assert_eq!(sent, 6, "every 200 ms within the second");
        assert!(lost.detail.contains("standby") && lost.detail.contains("SWB"));
        assert!(
            lost.reason.len() <= 64 && lost.reason.contains("SWB"),
            "{}",
            lost.reason
        );
        assert_eq!(mode.poll(ms(t + 20), false), Ok(false), "idle again");
    }

    #[test]
    fn nothing_is_asked_before_a_0x211_tells_the_mode() {
        let mut mode = CommandMode::new();
        for t in (0..1000).step_by(20) {
            assert_eq!(mode.poll(ms(t), true), Ok(false), "no 0x211 yet at {t} ms");
        }
        // The first one comes: a standby chassis is asked at once.
        mode.handle_reported(ControlModeV2::Standby, ms(1000));
        assert_eq!(mode.poll(ms(1000), true), Ok(true));
        // One that reports the RC is not asked.
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Rc, ms(0));
        assert_eq!(mode.poll(ms(10), true), Ok(false));
        // Nor is one whose last 0x211 is stale.
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        assert_eq!(mode.poll(ms(300), true), Ok(false));
    }

    #[test]
    fn a_client_wanting_to_drive_while_no_0x211_comes_is_told_why_nothing_moves() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        let mut t = 500;
        let lost = loop {
            match mode.poll(ms(t), true) {
                Ok(sent) => assert!(!sent, "nothing sent on a stale mode"),
                Err(lost) => break lost,
            }
            assert!(mode.poll_timeout().is_some(), "a deadline to wake for");
            t += 20;
        };
        assert!(t > 1500 && t <= 1520, "{t}");
        assert!(
            lost.reason.len() <= 64 && lost.reason.contains("0x211"),
            "{}",
            lost.reason
        );
        assert!(lost.detail.contains("ms ago"), "{}", lost.detail);
    }

    #[test]
    fn a_stop_or_release_ends_the_request() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        assert_eq!(mode.poll(ms(0), true), Ok(true));
        // The client is stopped: the chassis keeps reporting standby, nothing more goes out
        // and no take timeout is said on top of the stop.
        assert_eq!(
            run(&mut mode, ControlModeV2::Standby, 100, 3000, false),
            Ok(0)
        );
        assert!(!mode.is_requested());
        assert_eq!(mode.poll_timeout(), None);
    }

    #[test]
    fn after_a_gap_in_the_0x211_nothing_is_asked_again() {
        // The request went out; the chassis' 0x211 stopped for 400 ms (an RC episode the
        // gateway could not see may lie there), then it reports standby: not asked again.
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        assert_eq!(mode.poll(ms(0), true), Ok(true));
        assert_eq!(
            mode.poll(ms(200), true),
            Ok(false),
            "no answer yet: no repeat"
        );
        assert_eq!(mode.handle_reported(ControlModeV2::Standby, ms(400)), None);
        let mut t = 400;
        let lost = loop {
            if t % 100 == 0 {
                mode.handle_reported(ControlModeV2::Standby, ms(t));
            }
            match mode.poll(ms(t), true) {
                Ok(sent) => assert!(!sent, "asked again after a gap at {t} ms"),
                Err(lost) => break lost,
            }
            t += 20;
        };
        assert!(lost.reason.contains("0x211 lost"), "{}", lost.reason);
        assert!(lost.reason.len() <= 64, "{}", lost.reason);
        // Without an answer since the request, the reason says so, not an older report.
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        assert_eq!(mode.poll(ms(0), true), Ok(true));
        let lost = mode.poll(ms(1001), true).expect_err("timed out");
        assert!(lost.reason.contains("(no 0x211)"), "{}", lost.reason);
        assert!(lost.reason.len() <= 64, "{}", lost.reason);
        assert!(!lost.detail.contains("standby"), "{}", lost.detail);
    }

    #[test]
    fn after_a_gap_a_reported_can_mode_is_held() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        assert_eq!(mode.poll(ms(0), true), Ok(true));
        mode.handle_reported(ControlModeV2::Can, ms(400));
        assert!(
            mode.is_held(),
            "only the gateway's 0x421 puts it in CAN mode"
        );
    }

    #[test]
    fn falling_back_to_standby_while_held_is_a_loss_and_nothing_is_asked_again() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        mode.poll(ms(0), true).expect("asked");
        mode.handle_reported(ControlModeV2::Can, ms(100));
        let lost = mode
            .handle_reported(ControlModeV2::Standby, ms(200))
            .expect("a loss");
        assert!(
            lost.detail.contains("left CAN command mode"),
            "{}",
            lost.detail
        );
        assert!(lost.reason.len() <= 64, "{}", lost.reason);
        assert!(!mode.is_held());
        // The caller stops the robot, so no client is selected: nothing is sent.
        assert_eq!(mode.poll(ms(240), false), Ok(false));
        assert_eq!(
            mode.handle_reported(ControlModeV2::Unknown(9), ms(300)),
            None,
            "idle"
        );
    }

    #[test]
    fn the_rc_is_never_fought() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        mode.poll(ms(0), true).expect("asked");
        assert_eq!(
            mode.handle_reported(ControlModeV2::Rc, ms(100)),
            None,
            "the RC stop, not ours"
        );
        // Even were a client still selected, nothing is sent while the RC holds it.
        assert_eq!(run(&mut mode, ControlModeV2::Rc, 200, 4000, true), Ok(0));
        // The RC lets go: standby. Still nothing until the caller asks again.
        mode.handle_reported(ControlModeV2::Standby, ms(5000));
        assert_eq!(mode.poll(ms(5000), false), Ok(false));
        assert_eq!(mode.poll(ms(5020), true), Ok(true), "a new take asks again");
    }

    #[test]
    fn a_reset_forgets_the_hold() {
        let mut mode = CommandMode::new();
        mode.handle_reported(ControlModeV2::Standby, ms(0));
        mode.poll(ms(0), true).expect("asked");
        mode.handle_reported(ControlModeV2::Can, ms(100));
        mode.reset();
        assert!(!mode.is_held() && mode.reported().is_none());
        assert_eq!(mode.handle_reported(ControlModeV2::Can, ms(200)), None);
        assert!(
            !mode.is_held(),
            "a mode the gateway did not ask for is not held"
        );
    }
}
