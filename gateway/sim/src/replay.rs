//! Replaying a gateway's black box: the frames it read from the chassis (`rx` lines), sent
//! again with their original spacing in place of the model's feedback, so that an incident can
//! be re-run against a gateway. Sans-IO: the file's text in, the frames due at a time out.

use std::time::Duration;

use scout_protocol::CanFrame;
use scout_protocol::candump;

/// Why a black box cannot be replayed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ReplayError {
    /// A line is neither a comment nor a candump log line.
    #[error("line {line}: {reason}: a black box line is `(SECONDS.MICROS) rx|tx ID#DATA ...`")]
    BadLine {
        /// Its number, from 1.
        line: usize,
        /// What is wrong.
        reason: String,
    },
    /// Nothing read from the chassis in it.
    #[error("no `rx` frame in the file: nothing to replay")]
    Empty,
}

/// The chassis' side of a black box, and how far it has been played.
#[derive(Debug, Clone)]
pub struct Replay {
    /// Each frame with its time after the first.
    frames: Vec<(Duration, CanFrame)>,
    next: usize,
}

impl Replay {
    /// The `rx` frames of a black box's text (`tx` lines, what the gateway wrote, are left out:
    /// the gateway under test writes its own).
    pub fn parse(text: &str) -> Result<Self, ReplayError> {
        let mut frames = Vec::new();
        let mut first: Option<Duration> = None;
        for (index, line) in text.lines().enumerate() {
            let trimmed = line.trim();
            if trimmed.is_empty() || trimmed.starts_with('#') {
                continue;
            }
            let bad = |reason: String| ReplayError::BadLine {
                line: index + 1,
                reason,
            };
            let record = candump::parse(trimmed).map_err(|error| bad(error.to_string()))?;
            let timestamp = record
                .timestamp
                .ok_or_else(|| bad("no (SECONDS.MICROS) time".into()))?;
            match record.interface {
                Some("rx") => {}
                Some("tx") => continue,
                other => return Err(bad(format!("interface {other:?} is neither rx nor tx"))),
            }
            // The boot clock where the line has it (a stepped wall clock would stall or burst
            // the replay), else the wall clock.
            let at = match trimmed
                .split_ascii_whitespace()
                .find_map(|token| token.strip_prefix("boot="))
            {
                Some(boot) => candump::parse_timestamp(boot)
                    .map_err(|_| bad(format!("boot={boot} is no time")))?,
                None => timestamp,
            }
            .as_duration();
            let first = *first.get_or_insert(at);
            frames.push((at.saturating_sub(first), record.frame));
        }
        if frames.is_empty() {
            return Err(ReplayError::Empty);
        }
        Ok(Self { frames, next: 0 })
    }

    /// The frames due `elapsed` after the replay began, each once.
    pub fn due(&mut self, elapsed: Duration) -> &[(Duration, CanFrame)] {
        let start = self.next;
        while self
            .frames
            .get(self.next)
            .is_some_and(|(at, _)| *at <= elapsed)
        {
            self.next += 1;
        }
        &self.frames[start..self.next]
    }

    /// Whether every frame was played.
    pub fn finished(&self) -> bool {
        self.next == self.frames.len()
    }

    /// How long the replay lasts.
    pub fn length(&self) -> Duration {
        self.frames.last().map_or(Duration::ZERO, |(at, _)| *at)
    }

    /// How many frames it has.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether it has none (never: [`Replay::parse`] refuses that).
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::any;

    const BOX: &str = "\
# scout-gateway black box of 'r1'
(1764280000.000000) rx 151#0000F5000000005A boot=10.000000
(1764280000.010000) tx 130#0100000000000000 boot=10.010000

(1764280000.020000) rx 131#000000000000015E boot=10.020000
";

    #[test]
    fn the_rx_frames_play_with_their_spacing_once() {
        let mut replay = Replay::parse(BOX).expect("a black box");
        assert_eq!(
            (replay.len(), replay.length()),
            (2, Duration::from_millis(20))
        );
        assert_eq!(replay.due(Duration::ZERO).len(), 1);
        assert!(replay.due(Duration::from_millis(19)).is_empty());
        let due = replay.due(Duration::from_millis(25));
        assert_eq!(due.len(), 1);
        assert_eq!(due[0].1.id(), 0x131);
        assert!(replay.finished());
        assert!(replay.due(Duration::from_secs(9)).is_empty());
    }

    #[test]
    fn the_boot_clock_spaces_the_frames_when_the_wall_clock_stepped() {
        let text = "(1764280000.000000) rx 151#00 boot=10.000000\n\
                    (1700000000.000000) rx 131#00 boot=10.020000\n";
        let mut replay = Replay::parse(text).expect("a black box");
        assert_eq!(replay.length(), Duration::from_millis(20));
        assert_eq!(replay.due(Duration::from_millis(20)).len(), 2);
        let error = Replay::parse("(1.000000) rx 151#00 boot=x\n").expect_err("bad boot");
        assert!(error.to_string().contains("boot=x is no time"), "{error}");
    }

    #[test]
    fn bad_files_say_which_line() {
        let error = Replay::parse("# ok\n(1.0) rx 151#00\nnonsense\n").expect_err("bad");
        assert!(error.to_string().starts_with("line 3:"), "{error}");
        let error = Replay::parse("151#00\n").expect_err("no time");
        assert!(
            error.to_string().contains("no (SECONDS.MICROS) time"),
            "{error}"
        );
        assert_eq!(
            Replay::parse("(1.000000) tx 130#00\n").expect_err("empty"),
            ReplayError::Empty
        );
        let error = Replay::parse("(1.000000) can0 151#00\n").expect_err("can0");
        assert!(error.to_string().contains("neither rx nor tx"), "{error}");
    }

    proptest::proptest! {
        /// Whatever the file holds, parsing it and playing it never panics, and every frame
        /// comes out once (in the file's order).
        #[test]
        fn any_file_parses_or_says_why(
            lines in proptest::collection::vec(
                (any::<u64>(), 0u32..1_000_000, proptest::bool::ANY, 0u16..0x800, proptest::collection::vec(any::<u8>(), 0..9)),
                0..20,
            ),
            noise in ".{0,40}",
        ) {
            use proptest::prelude::*;
            let mut text: String = lines
                .iter()
                .map(|(seconds, micros, rx, id, data)| {
                    let hex: String = data.iter().map(|b| format!("{b:02X}")).collect();
                    let way = if *rx { "rx" } else { "tx" };
                    format!("({seconds}.{micros:06}) {way} {id:03X}#{hex}\n")
                })
                .collect();
            text.push_str(&noise);
            if let Ok(mut replay) = Replay::parse(&text) {
                let total = replay.len();
                prop_assert_eq!(replay.due(Duration::MAX).len(), total);
                prop_assert!(replay.finished());
            }
        }
    }
}
