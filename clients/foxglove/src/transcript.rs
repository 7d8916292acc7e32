//! The transcript: the gateway's states and statuses in, the messages of every channel out, with
//! their times. Sans-IO: the payloads and the clock offset are passed in; the recorder and the
//! live server write what it returns (one piece of code decides what a recording holds and what
//! the live view shows, so a recording replays like the live view).

use std::collections::VecDeque;

use serde_json::Value;

use scout_interface::json::{state_json, status_json};
use scout_interface::{LinkState, StatePayload, StatusPayload};

/// A state is written at least this often while states arrive, even without a new 0x131 (a
/// chassis that reports only 0x151 is still seen), ns.
const STATE_AT_LEAST_EVERY_NS: u64 = 1_000_000_000;
/// How many arbiter events are remembered to tell new ones from those already written.
const REMEMBERED_EVENTS: usize = 64;
/// Two events with the same text this close in time are the same event (its age in the status
/// is a float of ms), ns.
const SAME_EVENT_WITHIN_NS: u64 = 1_000_000;

/// One message for one channel.
#[derive(Debug, Clone, PartialEq)]
pub enum Entry {
    /// The chassis state (the `scout echo --json` schema; ages relative to `time_ns`).
    State(Value),
    /// A motion command as the gateway sent it on the wire, m/s and rad/s.
    Command {
        /// m/s.
        linear: f64,
        /// rad/s.
        angular: f64,
    },
    /// The odometry pose in the `odom` frame.
    Pose {
        /// m.
        x: f64,
        /// m.
        y: f64,
        /// rad.
        yaw: f64,
    },
    /// The arbiter's status (the `scout status --json` schema).
    Status(Value),
    /// One arbiter event (a stop, a release, a takeover...), as the gateway worded it.
    Event(String),
}

/// An entry and when it happened: ns since the Unix epoch (the gateway's CLOCK_BOOTTIME time,
/// shifted by the offset the transcript was made with).
#[derive(Debug, Clone, PartialEq)]
pub struct Timed {
    /// ns since the Unix epoch.
    pub time_ns: u64,
    /// What happened.
    pub entry: Entry,
}

/// Turns states and statuses into channel messages.
#[derive(Debug, Clone)]
pub struct Transcript {
    /// CLOCK_REALTIME minus CLOCK_BOOTTIME, ns (signed: a clock set before 1970 is absurd but
    /// must not panic).
    realtime_offset_ns: i128,
    /// Events before this CLOCK_BOOTTIME time are history the recording did not see happen.
    start_ns: u64,
    last_motion_ns: Option<u64>,
    last_link: Option<u8>,
    last_state_ns: Option<u64>,
    last_command_ns: Option<u64>,
    /// Events already written: CLOCK_BOOTTIME time and text.
    events: VecDeque<(u64, String)>,
}

impl Transcript {
    /// A transcript starting at CLOCK_BOOTTIME time `start_ns`, when CLOCK_REALTIME minus
    /// CLOCK_BOOTTIME was `realtime_offset_ns`.
    pub fn new(start_ns: u64, realtime_offset_ns: i128) -> Self {
        Self {
            realtime_offset_ns,
            start_ns,
            last_motion_ns: None,
            last_link: None,
            last_state_ns: None,
            last_command_ns: None,
            events: VecDeque::with_capacity(REMEMBERED_EVENTS),
        }
    }

    /// CLOCK_BOOTTIME `monotonic_ns` as ns since the Unix epoch (0 at the least).
    pub fn unix_ns(&self, monotonic_ns: u64) -> u64 {
        u64::try_from((i128::from(monotonic_ns) + self.realtime_offset_ns).max(0))
            .unwrap_or(u64::MAX)
    }

    fn timed(&self, monotonic_ns: u64, entry: Entry) -> Timed {
        Timed {
            time_ns: self.unix_ns(monotonic_ns),
            entry,
        }
    }

    /// One state, in the order the gateway published them. Writes the state on each new 0x131
    /// (stamped when it arrived), on a change of the link's state and at least once a second;
    /// the pose with it; and each motion command the gateway sent since the last state.
    pub fn handle_state(&mut self, state: &StatePayload, out: &mut Vec<Timed>) {
        let command = &state.command;
        if command.at_ns != 0 && self.last_command_ns != Some(command.at_ns) {
            self.last_command_ns = Some(command.at_ns);
            out.push(self.timed(
                command.at_ns,
                Entry::Command {
                    linear: command.linear,
                    angular: command.angular,
                },
            ));
        }
        let motion = &state.motion.received;
        let new_motion = motion.valid && self.last_motion_ns != Some(motion.at_ns);
        let link_changed = self.last_link != Some(state.link.state);
        let due = self
            .last_state_ns
            .is_none_or(|last| state.published_ns.saturating_sub(last) >= STATE_AT_LEAST_EVERY_NS);
        if !(new_motion || link_changed || due) {
            return;
        }
        let at_ns = if new_motion {
            self.last_motion_ns = Some(motion.at_ns);
            motion.at_ns
        } else {
            state.published_ns
        };
        self.last_link = Some(state.link.state);
        self.last_state_ns = Some(state.published_ns);
        out.push(self.timed(at_ns, Entry::State(state_json(state, at_ns))));
        if state.link.state() == LinkState::Ok || new_motion {
            let odometry = &state.odometry;
            out.push(self.timed(
                at_ns,
                Entry::Pose {
                    x: odometry.x,
                    y: odometry.y,
                    yaw: odometry.yaw,
                },
            ));
        }
    }

    /// One status, in the order the gateway published them: the status, then each event in it
    /// not written before that happened after the transcript started, oldest first.
    pub fn handle_status(&mut self, status: &StatusPayload, out: &mut Vec<Timed>) {
        out.push(self.timed(
            status.published_ns,
            Entry::Status(status_json(status, status.published_ns)),
        ));
        for event in status.events() {
            let ago_ns = if event.age_ms.is_finite() && event.age_ms > 0.0 {
                (event.age_ms * 1e6) as u64
            } else {
                0
            };
            let at_ns = status.published_ns.saturating_sub(ago_ns);
            let text = event.text.as_str();
            if at_ns.saturating_add(SAME_EVENT_WITHIN_NS) < self.start_ns {
                continue;
            }
            let seen = self.events.iter().any(|(seen_at, seen_text)| {
                seen_at.abs_diff(at_ns) < SAME_EVENT_WITHIN_NS && seen_text == text
            });
            if seen {
                continue;
            }
            if self.events.len() == REMEMBERED_EVENTS {
                self.events.pop_front();
            }
            self.events.push_back((at_ns, text.to_owned()));
            out.push(self.timed(at_ns, Entry::Event(text.to_owned())));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_interface::FixedText;
    use scout_interface::control::EventPayload;
    use scout_interface::state::Received;

    const MS: u64 = 1_000_000;

    fn state(published_ms: u64, motion_ms: Option<u64>, command_ms: u64) -> StatePayload {
        let mut state = StatePayload {
            published_ns: published_ms * MS,
            ..StatePayload::default()
        };
        state.link.state = LinkState::Ok.raw();
        if let Some(at) = motion_ms {
            state.motion.received = Received {
                valid: true,
                count: 0,
                at_ns: at * MS,
            };
            state.motion.linear_mm_s = 500;
        }
        state.command.at_ns = command_ms * MS;
        state.command.linear = 0.5;
        state.odometry.x = 1.5;
        state
    }

    fn kinds(out: &[Timed]) -> Vec<&'static str> {
        out.iter()
            .map(|timed| match timed.entry {
                Entry::State(_) => "state",
                Entry::Command { .. } => "command",
                Entry::Pose { .. } => "pose",
                Entry::Status(_) => "status",
                Entry::Event(_) => "event",
            })
            .collect()
    }

    #[test]
    fn a_state_is_written_on_each_new_motion_frame_stamped_when_it_arrived() {
        let offset = 1_700_000_000_000 * MS as i128;
        let mut transcript = Transcript::new(0, offset);
        let mut out = Vec::new();
        transcript.handle_state(&state(100, Some(99), 90), &mut out);
        assert_eq!(kinds(&out), ["command", "state", "pose"]);
        assert_eq!(out[0].time_ns, 90 * MS + offset as u64);
        assert_eq!(out[1].time_ns, 99 * MS + offset as u64);
        let Entry::State(json) = &out[1].entry else {
            unreachable!()
        };
        assert_eq!(json["motion"]["linear"], 0.5);
        assert_eq!(
            json["motion"]["age_ms"], 0.0,
            "ages are relative to the entry's time"
        );
        assert_eq!(
            out[2].entry,
            Entry::Pose {
                x: 1.5,
                y: 0.0,
                yaw: 0.0
            }
        );

        // Other frames (0x151, motors) publish states with the same 0x131 and command: nothing.
        out.clear();
        transcript.handle_state(&state(101, Some(99), 90), &mut out);
        transcript.handle_state(&state(102, Some(99), 90), &mut out);
        assert!(out.is_empty(), "{out:?}");

        // A new command, then a new 0x131.
        transcript.handle_state(&state(110, Some(99), 110), &mut out);
        transcript.handle_state(&state(119, Some(119), 110), &mut out);
        assert_eq!(kinds(&out), ["command", "state", "pose"]);
    }

    #[test]
    fn without_motion_frames_a_state_is_written_on_a_link_change_and_once_a_second() {
        let mut transcript = Transcript::new(0, 0);
        let mut out = Vec::new();
        transcript.handle_state(&state(100, None, 0), &mut out);
        assert_eq!(kinds(&out), ["state", "pose"], "the first state");
        out.clear();
        transcript.handle_state(&state(600, None, 0), &mut out);
        assert!(out.is_empty());
        let mut silent = state(700, None, 0);
        silent.link.state = LinkState::Silent.raw();
        transcript.handle_state(&silent, &mut out);
        assert_eq!(
            kinds(&out),
            ["state"],
            "the link went silent: no pose from a silent link"
        );
        assert_eq!(out[0].time_ns, 700 * MS);
        out.clear();
        silent.published_ns = 1_600 * MS;
        transcript.handle_state(&silent, &mut out);
        assert!(out.is_empty());
        silent.published_ns = 1_700 * MS;
        transcript.handle_state(&silent, &mut out);
        assert_eq!(kinds(&out), ["state"], "a second later");
    }

    fn status(published_ms: u64, events: &[(f64, &str)]) -> StatusPayload {
        let mut status = StatusPayload {
            published_ns: published_ms * MS,
            event_count: events.len() as u8,
            ..StatusPayload::default()
        };
        for (slot, (age_ms, text)) in status.events.iter_mut().zip(events) {
            *slot = EventPayload {
                age_ms: *age_ms,
                text: FixedText::new(text),
            };
        }
        status
    }

    #[test]
    fn each_event_is_written_once_and_history_from_before_the_start_is_not() {
        let mut transcript = Transcript::new(1_000 * MS, 0);
        let mut out = Vec::new();
        transcript.handle_status(
            &status(1_500, &[(900.0, "old"), (200.0, "stop 1 by a")]),
            &mut out,
        );
        assert_eq!(kinds(&out), ["status", "event"]);
        assert_eq!(out[1].entry, Entry::Event("stop 1 by a".into()));
        assert_eq!(out[1].time_ns, 1_300 * MS);
        out.clear();
        // The same events a moment later (their ages grew), then one more.
        transcript.handle_status(
            &status(
                2_000,
                &[
                    (1_400.0, "old"),
                    (700.000_4, "stop 1 by a"),
                    (10.0, "release"),
                ],
            ),
            &mut out,
        );
        assert_eq!(kinds(&out), ["status", "event"]);
        assert_eq!(out[1].entry, Entry::Event("release".into()));
        assert_eq!(out[1].time_ns, 1_990 * MS);
        out.clear();
        // The same text again later is another event.
        transcript.handle_status(&status(3_000, &[(5.0, "release")]), &mut out);
        assert_eq!(kinds(&out), ["status", "event"]);
    }

    #[test]
    fn absurd_ages_and_clocks_do_not_panic() {
        let mut transcript = Transcript::new(u64::MAX, i128::from(i64::MIN));
        let mut out = Vec::new();
        transcript.handle_status(
            &status(
                u64::MAX / MS,
                &[(f64::NAN, "a"), (f64::INFINITY, "b"), (-1.0, "c")],
            ),
            &mut out,
        );
        transcript.handle_state(
            &state(u64::MAX / MS, Some(u64::MAX / MS), u64::MAX / MS),
            &mut out,
        );
        assert!(!out.is_empty());
        assert_eq!(
            Transcript::new(0, i128::from(i64::MIN)).unix_ns(5),
            0,
            "before 1970: 0"
        );
        assert_eq!(
            Transcript::new(0, i128::MAX / 2).unix_ns(5),
            u64::MAX,
            "beyond: the most"
        );
    }
}
