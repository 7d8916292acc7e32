//! Whether the chassis stands still, without I/O: what it reports (0x221) and what was sent to
//! it. A Ranger changes its mode and a Hunter locks its brake only standing still.

use std::time::Duration;

use scout_protocol::v2::MotionV2;

use crate::modes::Velocity;

/// How long the chassis must have reported standing still, and nothing been sent that moves it,
/// before it counts as standing still.
pub const STILL_FOR: Duration = Duration::from_millis(100);
/// What counts as standing still in 0x221's speed and rate fields, mm/s or mrad/s.
pub const STILL_WITHIN: u16 = 5;

/// What the chassis last reported of its motion, and when it or the gateway last moved it.
#[derive(Debug, Clone, Default)]
pub struct Standstill {
    /// The last 0x221 said standing still.
    still: bool,
    /// When the chassis last reported moving, or a command that moves it went out.
    moved_at: Option<Duration>,
}

impl Standstill {
    /// 0x221 as received (every field as it came: where a Ranger Mini 2.0 reports its spin rate
    /// is the vendor driver's reading, not a chassis'; a steered chassis' angle is not motion).
    pub fn handle_motion_state(&mut self, now: Duration, motion: &MotionV2) {
        self.still = [
            motion.linear_mm_s,
            motion.angular_mrad_s,
            motion.lateral_mm_s,
        ]
        .iter()
        .all(|value| value.unsigned_abs() <= STILL_WITHIN);
        if !self.still {
            self.moved_at = Some(now);
        }
    }

    /// A motion command went out at `sent` (forward, sideways, yaw rate).
    pub fn handle_sent(&mut self, now: Duration, sent: Velocity) {
        if sent != (0.0, 0.0, 0.0) {
            self.moved_at = Some(now);
        }
    }

    /// Whether the chassis stands still at `now` with `output` going out: it said so, and
    /// neither it nor a command moved it for [`STILL_FOR`].
    pub fn is_still(&self, now: Duration, output: Velocity) -> bool {
        self.still
            && output == (0.0, 0.0, 0.0)
            && self.moved_at.is_none_or(|at| now >= at + STILL_FOR)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn still_once_reported_still_and_nothing_moved_it_for_a_while() {
        let mut standstill = Standstill::default();
        let zero = (0.0, 0.0, 0.0);
        assert!(!standstill.is_still(Duration::ZERO, zero), "not reported");
        let moving = MotionV2 {
            linear_mm_s: 6,
            ..MotionV2::default()
        };
        standstill.handle_motion_state(10 * MS, &moving);
        assert!(!standstill.is_still(500 * MS, zero));
        standstill.handle_motion_state(20 * MS, &MotionV2::default());
        // From the last report of moving.
        assert!(!standstill.is_still(109 * MS, zero));
        assert!(standstill.is_still(110 * MS, zero));
        assert!(
            !standstill.is_still(120 * MS, (0.0, 0.0, 0.1)),
            "moving out"
        );
        standstill.handle_sent(130 * MS, (0.01, 0.0, 0.0));
        assert!(!standstill.is_still(229 * MS, zero));
        assert!(standstill.is_still(230 * MS, zero));
        // A steered chassis' wheel angle is not motion.
        let steered = MotionV2 {
            steering_mrad: 400,
            ..MotionV2::default()
        };
        standstill.handle_motion_state(240 * MS, &steered);
        assert!(standstill.is_still(240 * MS, zero));
    }
}
