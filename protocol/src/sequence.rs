//! Rolling counts: the sender's counter and the receiver's per-kind gap tracker.

use crate::message::MessageKind;

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

/// Tracks the rolling count of each message kind and reports gaps (lost frames).
#[derive(Debug, Clone, Default)]
pub struct SequenceTracker {
    last: [Option<u8>; MessageKind::COUNT],
    lost: u64,
}

impl SequenceTracker {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records `count` for `kind`.
    pub fn observe(&mut self, kind: MessageKind, count: u8) -> Continuity {
        let slot = &mut self.last[kind.index()];
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
        self.last = [None; MessageKind::COUNT];
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
}
