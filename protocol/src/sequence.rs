//! Rolling counts: the sender's counter and the receiver's per-kind gap tracker.

use crate::message::MessageKind;
use crate::v2::{self, MessageV2};

/// The sender's rolling count: 0, 1, ..., 255, 0, ...
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RollingCounter {
    next: u8,
}

impl RollingCounter {
    /// A counter whose first value is `first`.
    pub const fn starting_at(first: u8) -> Self {
        Self { next: first }
    }

    /// The count for the next frame, advancing the counter.
    pub fn next_count(&mut self) -> u8 {
        let count = self.next;
        self.next = self.next.wrapping_add(1);
        count
    }
}

/// What one received count says about the frames of its kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Continuity {
    /// The first frame of this kind: nothing to compare with.
    First,
    /// The count follows the previous one.
    InOrder,
    /// `lost` frames were missed between the previous count and this one.
    Gap {
        /// How many counts were skipped (1..=254).
        lost: u8,
    },
    /// The same count as the previous frame.
    Repeated,
}

/// The protocol v2 ids whose frames carry a rolling count, in slot order after v1's kinds.
const V2_COUNTED: [u16; 4] = [
    v2::id::LIGHT_COMMAND,
    v2::id::SYSTEM_STATE,
    v2::id::LIGHT_STATE,
    v2::id::RC_STATE,
];

const SLOTS: usize = MessageKind::COUNT + V2_COUNTED.len();

/// Tracks the rolling count of each message kind (v1) and of each counted v2 frame, and reports
/// gaps (lost frames).
#[derive(Debug, Clone)]
pub struct SequenceTracker {
    last: [Option<u8>; SLOTS],
    lost: u64,
}

impl Default for SequenceTracker {
    fn default() -> Self {
        Self {
            last: [None; SLOTS],
            lost: 0,
        }
    }
}

impl SequenceTracker {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records `count` for `kind`.
    pub fn observe(&mut self, kind: MessageKind, count: u8) -> Continuity {
        self.observe_slot(kind.index(), count)
    }

    /// Records the count of a protocol v2 frame; `None` for the frames that carry none.
    pub fn observe_v2(&mut self, message: &MessageV2) -> Option<Continuity> {
        let count = message.count()?;
        let index = V2_COUNTED.iter().position(|id| *id == message.can_id())?;
        Some(self.observe_slot(MessageKind::COUNT + index, count))
    }

    fn observe_slot(&mut self, index: usize, count: u8) -> Continuity {
        let slot = &mut self.last[index];
        let continuity = match *slot {
            None => Continuity::First,
            Some(last) => match count.wrapping_sub(last) {
                0 => Continuity::Repeated,
                1 => Continuity::InOrder,
                step => Continuity::Gap { lost: step - 1 },
            },
        };
        if let Continuity::Gap { lost } = continuity {
            self.lost += u64::from(lost);
        }
        *slot = Some(count);
        continuity
    }

    /// Forgets the previous counts (after a reconnect, the chassis' counts restart).
    pub fn reset(&mut self) {
        self.last = [None; SLOTS];
    }

    /// The total of lost frames reported so far.
    pub fn lost(&self) -> u64 {
        self.lost
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counter_wraps() {
        let mut counter = RollingCounter::starting_at(254);
        assert_eq!(
            [
                counter.next_count(),
                counter.next_count(),
                counter.next_count()
            ],
            [254, 255, 0]
        );
    }

    #[test]
    fn tracker_reports_gaps_per_kind() {
        let mut tracker = SequenceTracker::new();
        let status = MessageKind::SystemStatus;
        let motion = MessageKind::MotionFeedback;
        assert_eq!(tracker.observe(status, 254), Continuity::First);
        assert_eq!(tracker.observe(motion, 10), Continuity::First);
        assert_eq!(tracker.observe(status, 255), Continuity::InOrder);
        assert_eq!(tracker.observe(status, 0), Continuity::InOrder);
        assert_eq!(tracker.observe(status, 3), Continuity::Gap { lost: 2 });
        assert_eq!(tracker.observe(status, 3), Continuity::Repeated);
        assert_eq!(tracker.observe(motion, 11), Continuity::InOrder);
        assert_eq!(tracker.lost(), 2);
        tracker.reset();
        assert_eq!(tracker.observe(status, 100), Continuity::First);
    }

    #[test]
    fn v2_frames_with_a_count_are_tracked_apart_from_v1() {
        let mut tracker = SequenceTracker::new();
        let system = |count| {
            v2::decode(&crate::CanFrame::new(0x211, &[0, 0, 1, 3, 0, 0, 0, count]).expect("frame"))
                .expect("0x211")
        };
        let motion =
            v2::decode(&crate::CanFrame::new(0x221, &[0; 8]).expect("frame")).expect("0x221");
        assert_eq!(tracker.observe_v2(&system(7)), Some(Continuity::First));
        assert_eq!(
            tracker.observe(MessageKind::SystemStatus, 9),
            Continuity::First
        );
        assert_eq!(
            tracker.observe_v2(&system(10)),
            Some(Continuity::Gap { lost: 2 })
        );
        assert_eq!(tracker.observe_v2(&motion), None, "0x221 carries no count");
        assert_eq!(tracker.lost(), 2);
    }
}
