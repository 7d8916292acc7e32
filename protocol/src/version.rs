//! Protocol v1 or v2: tells the chassis' protocol from the CAN ids it sends (protocol-notes 6).

use core::time::Duration;

/// How long v2 traffic must go on without a v1 system status before the bus is called v2.
pub const DETECTION_WINDOW: Duration = Duration::from_secs(1);

/// The v1 id that protocol v2 never sends.
const V1_SYSTEM_STATUS: u16 = 0x151;

/// Ids only protocol v2 uses (0x131 and 0x141 exist in both and prove nothing).
pub fn is_v2_only_id(id: u16) -> bool {
    matches!(id, 0x111 | 0x211 | 0x221 | 0x231 | 0x241 | 0x251..=0x258 | 0x261..=0x268 | 0x311 | 0x421)
}

/// What the bus speaks, as far as the ids seen tell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProtocolVersion {
    /// Not enough seen yet.
    Unknown,
    /// Protocol v1 (0x151 seen): supported.
    V1,
    /// Protocol v2: v2-only ids and no 0x151 for [`DETECTION_WINDOW`]. Not supported.
    V2,
}

/// Watches the ids of received frames; time comes in as an argument (any monotonic origin).
#[derive(Debug, Clone, Copy, Default)]
pub struct VersionDetector {
    v1_seen: bool,
    first_v2_at: Option<Duration>,
}

impl VersionDetector {
    /// A detector that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records a frame with `id` received at `now`.
    pub fn observe(&mut self, id: u16, now: Duration) {
        if id == V1_SYSTEM_STATUS {
            self.v1_seen = true;
        } else if is_v2_only_id(id) && self.first_v2_at.is_none() {
            self.first_v2_at = Some(now);
        }
    }

    /// The verdict at `now`.
    pub fn version(&self, now: Duration) -> ProtocolVersion {
        match self.first_v2_at {
            _ if self.v1_seen => ProtocolVersion::V1,
            Some(first) if now.saturating_sub(first) >= DETECTION_WINDOW => ProtocolVersion::V2,
            _ => ProtocolVersion::Unknown,
        }
    }

    /// Forgets everything (after a reconnect: another chassis may be on the other end).
    pub fn reset(&mut self) {
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const fn ms(millis: u64) -> Duration {
        Duration::from_millis(millis)
    }

    #[test]
    fn status_frame_means_v1() {
        let mut detector = VersionDetector::new();
        detector.observe(0x131, ms(0));
        assert_eq!(detector.version(ms(0)), ProtocolVersion::Unknown);
        detector.observe(0x151, ms(10));
        assert_eq!(detector.version(ms(5000)), ProtocolVersion::V1);
    }

    #[test]
    fn v2_ids_without_status_for_a_second_mean_v2() {
        let mut detector = VersionDetector::new();
        detector.observe(0x221, ms(100));
        detector.observe(0x131, ms(120));
        assert_eq!(detector.version(ms(1099)), ProtocolVersion::Unknown);
        assert_eq!(detector.version(ms(1100)), ProtocolVersion::V2);
        detector.reset();
        assert_eq!(detector.version(ms(5000)), ProtocolVersion::Unknown);
    }

    #[test]
    fn shared_ids_prove_nothing() {
        let mut detector = VersionDetector::new();
        for t in 0..100 {
            detector.observe(0x131, ms(t * 20));
            detector.observe(0x141, ms(t * 20));
        }
        assert_eq!(detector.version(ms(5000)), ProtocolVersion::Unknown);
    }
}
