//! A protocol v2 chassis' command mode, as the gateway takes and watches it (protocol-v2-notes 5):
//! the chassis starts in standby and obeys 0x111 only after the host sends 0x421 `[01]` and its
//! 0x211 reports CAN command mode. Sans-IO: the reported mode and time in; when to send 0x421,
//! and the losses that stop the robot, out.
//!
//! The rules, which keep v2 as safe as v1:
//! - 0x421 `[01]` goes out only when a client is about to drive (the arbiter has selected one:
//!   it took control, no stop holds the robot), never at start-up or after a reconnect.
//! - It is repeated every [`REQUEST_REPEAT`] until 0x211 reports CAN mode; if that does not
//!   happen within [`TAKE_TIMEOUT`], the take failed: a stop says so and what to check.
//! - Once held, any other mode but the RC's (standby, UART, unknown) is a loss: a stop. The RC
//!   taking over is the RC stop of both protocols, and the gateway never fights it: no 0x421
//!   while the RC holds the chassis, and none after it lets go until a release and a new take.

use std::time::Duration;

use scout_protocol::v2::ControlModeV2;

/// How often 0x421 `[01]` is repeated until the chassis reports CAN mode (its 0x211 comes every
/// 100 ms, so one lost frame costs one repeat).
pub const REQUEST_REPEAT: Duration = Duration::from_millis(200);

/// How long the chassis has to report CAN mode after the first 0x421 `[01]`.
pub const TAKE_TIMEOUT: Duration = Duration::from_millis(1000);

/// Where the gateway stands with the chassis' command mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Holding {
    /// Not asked for (since the start, a loss or a reconnect).
    Idle,
    /// 0x421 `[01]` sent first at `since`, last at `last_sent`.
    Requested {
        since: Duration,
        last_sent: Duration,
    },
    /// The chassis reported CAN mode after a request.
    Held,
}

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
    /// The mode the last 0x211 reported.
    reported: Option<ControlModeV2>,
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
            holding: Holding::Idle,
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
        self.reported
    }

    /// The port opened again: another chassis, or the same one after a power cycle.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// A 0x211 reported `mode` at `now`.
    pub fn handle_reported(&mut self, mode: ControlModeV2) -> Option<ModeLost> {
        self.reported = Some(mode);
        match (self.holding, mode) {
            // The RC has the top authority: let go at once (its own stop is the RC override).
            (_, ControlModeV2::Rc) => {
                self.holding = Holding::Idle;
                None
            }
            (Holding::Requested { .. } | Holding::Held, ControlModeV2::Can) => {
                self.holding = Holding::Held;
                None
            }
            (Holding::Held, ControlModeV2::Standby | ControlModeV2::Uart)
            | (Holding::Held, ControlModeV2::Unknown(_)) => {
                self.holding = Holding::Idle;
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
            (Holding::Idle, _) | (Holding::Requested { .. }, _) => None,
        }
    }

    /// Whether to send 0x421 `[01]` at `now`: `wanted` says a client is about to drive. A
    /// request the chassis does not answer in time is a loss.
    pub fn poll(&mut self, now: Duration, wanted: bool) -> Result<bool, ModeLost> {
        match self.holding {
            Holding::Idle if wanted && self.reported != Some(ControlModeV2::Rc) => {
                self.holding = Holding::Requested {
                    since: now,
                    last_sent: now,
                };
                Ok(true)
            }
            Holding::Idle | Holding::Held => Ok(false),
            Holding::Requested { since, .. } if now.saturating_sub(since) > TAKE_TIMEOUT => {
                self.holding = Holding::Idle;
                let reported = self.reported.map_or("no 0x211 at all".to_owned(), |mode| {
                    format!("it reports {}", mode.name())
                });
                let short = self.reported.map_or("no 0x211", ControlModeV2::name);
                Err(ModeLost {
                    reason: format!("0x421 not taken in 1 s ({short}): RC SWB, SWA up? e-stops?"),
                    detail: format!(
                        "the chassis did not enter CAN command mode within {} ms of 0x421: \
                         {reported}; with the RC transmitter on, its SWB must be up, SWA up and \
                         the e-stops released",
                        TAKE_TIMEOUT.as_millis()
                    ),
                })
            }
            Holding::Requested { since, last_sent }
                if now.saturating_sub(last_sent) >= REQUEST_REPEAT =>
            {
                self.holding = Holding::Requested {
                    since,
                    last_sent: now,
                };
                Ok(true)
            }
            Holding::Requested { .. } => Ok(false),
        }
    }

    /// When [`CommandMode::poll`] next has something to do, if anything.
    pub fn poll_timeout(&self) -> Option<Duration> {
        match self.holding {
            Holding::Requested { since, last_sent } => Some(
                (last_sent + REQUEST_REPEAT).min(since + TAKE_TIMEOUT + Duration::from_millis(1)),
            ),
            Holding::Idle | Holding::Held => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const fn ms(n: u64) -> Duration {
        Duration::from_millis(n)
    }

    #[test]
    fn nothing_is_asked_until_a_client_drives() {
        let mut mode = CommandMode::new();
        assert_eq!(mode.handle_reported(ControlModeV2::Standby), None);
        for t in 0..100 {
            assert_eq!(mode.poll(ms(t * 20), false), Ok(false));
        }
        assert!(!mode.is_held());
    }

    #[test]
    fn a_take_is_asked_repeated_and_held_when_reported() {
        let mut mode = CommandMode::new();
        assert_eq!(mode.poll(ms(1000), true), Ok(true), "0x421 at once");
        assert_eq!(mode.poll(ms(1100), true), Ok(false));
        assert_eq!(mode.poll(ms(1200), true), Ok(true), "repeated");
        assert_eq!(
            mode.handle_reported(ControlModeV2::Standby),
            None,
            "not yet"
        );
        assert_eq!(mode.handle_reported(ControlModeV2::Can), None);
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
        mode.handle_reported(ControlModeV2::Standby);
        assert_eq!(mode.poll(ms(0), true), Ok(true));
        let mut sent = 1;
        let mut t = 0;
        let lost = loop {
            t += 10;
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
    fn falling_back_to_standby_while_held_is_a_loss_and_nothing_is_asked_again() {
        let mut mode = CommandMode::new();
        mode.poll(ms(0), true).expect("asked");
        mode.handle_reported(ControlModeV2::Can);
        let lost = mode
            .handle_reported(ControlModeV2::Standby)
            .expect("a loss");
        assert!(
            lost.detail.contains("left CAN command mode"),
            "{}",
            lost.detail
        );
        assert!(lost.reason.len() <= 64, "{}", lost.reason);
        assert!(!mode.is_held());
        // The caller stops the robot, so no client is selected: nothing is sent.
        assert_eq!(mode.poll(ms(40), false), Ok(false));
        assert_eq!(
            mode.handle_reported(ControlModeV2::Unknown(9)),
            None,
            "idle"
        );
    }

    #[test]
    fn the_rc_is_never_fought() {
        let mut mode = CommandMode::new();
        mode.poll(ms(0), true).expect("asked");
        assert_eq!(
            mode.handle_reported(ControlModeV2::Rc),
            None,
            "the RC stop, not ours"
        );
        for t in 1..200 {
            assert_eq!(
                mode.poll(ms(t * 20), true),
                Ok(false),
                "no 0x421 while the RC holds it"
            );
        }
        // The RC lets go: standby. Still nothing until the caller asks again.
        mode.handle_reported(ControlModeV2::Standby);
        assert_eq!(mode.poll(ms(5000), false), Ok(false));
        assert_eq!(mode.poll(ms(5020), true), Ok(true), "a new take asks again");
    }

    #[test]
    fn a_reset_forgets_the_hold() {
        let mut mode = CommandMode::new();
        mode.poll(ms(0), true).expect("asked");
        mode.handle_reported(ControlModeV2::Can);
        mode.reset();
        assert!(!mode.is_held() && mode.reported().is_none());
        assert_eq!(mode.handle_reported(ControlModeV2::Can), None);
        assert!(
            !mode.is_held(),
            "a mode the gateway did not ask for is not held"
        );
    }
}
