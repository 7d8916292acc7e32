//! Protocol v1 or v2: tells the chassis' protocol from the CAN ids of the feedback it sends
//! (protocol-v2-notes 4), passively: nothing is sent to find out.

use core::time::Duration;

/// How long the feedback of one protocol must go on, with none of the other's, before a
/// detector calls the bus (a v1 chassis sends 0x151 every 20 ms, a v2 one 0x221 every 20 ms).
pub const DETECTION_WINDOW: Duration = Duration::from_millis(300);

listed! {
/// The chassis protocols this project speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Protocol {
    /// Protocol v1: the 2019 SCOUT (CAN and RS232; 0x130/0x131/0x151..., checksums).
    V1,
    /// Protocol v2: SCOUT 2.0, SCOUT MINI and MINI OMNI firmware since 2020 (CAN only).
    V2,
}
}

impl Protocol {
    /// `v1` or `v2`.
    pub const fn name(self) -> &'static str {
        match self {
            Self::V1 => "v1",
            Self::V2 => "v2",
        }
    }

    /// The protocol called `name` ([`Protocol::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|protocol| protocol.name() == name)
    }

    /// The byte that stands for it in shared memory (0 stands for "not known yet").
    pub const fn raw(self) -> u8 {
        match self {
            Self::V1 => 1,
            Self::V2 => 2,
        }
    }

    /// The protocol of a byte from [`Protocol::raw`] (`None` for 0 and unknown bytes).
    pub const fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            1 => Some(Self::V1),
            2 => Some(Self::V2),
            _ => None,
        }
    }

    /// The other one.
    pub const fn other(self) -> Self {
        match self {
            Self::V1 => Self::V2,
            Self::V2 => Self::V1,
        }
    }

    const fn index(self) -> usize {
        match self {
            Self::V1 => 0,
            Self::V2 => 1,
        }
    }
}

impl core::fmt::Display for Protocol {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// The protocol a chassis-to-host id proves, if it proves one: v1's system status and motor
/// feedback (0x151, 0x200..=0x203) never appear on a v2 bus, and v2's feedback ids (0x211,
/// 0x221, 0x231, 0x241, 0x251..=0x254, 0x261..=0x264, 0x311) never on a v1 bus. Host commands
/// (another host's, of either protocol) and the ids both protocols use (0x131, 0x141) prove
/// nothing.
pub const fn protocol_of_feedback_id(id: u16) -> Option<Protocol> {
    match id {
        0x151 | 0x200..=0x203 => Some(Protocol::V1),
        0x211 | 0x221 | 0x231 | 0x241 | 0x251..=0x254 | 0x261..=0x264 | 0x311 => Some(Protocol::V2),
        _ => None,
    }
}

/// What a detector has heard so far.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Detection {
    /// Nothing that proves a protocol yet, or not for [`DETECTION_WINDOW`].
    Listening,
    /// One protocol's feedback, and none of the other's, for [`DETECTION_WINDOW`].
    Found(Protocol),
    /// Feedback of both protocols: two chassis, or another node using their ids.
    Both,
}

/// The distinct ids of one protocol seen, the first [`IdsSeen::CAPACITY`] of them (for
/// messages; fixed size, no allocation).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct IdsSeen {
    ids: [u16; Self::CAPACITY],
    len: usize,
}

impl IdsSeen {
    /// How many distinct ids are kept.
    pub const CAPACITY: usize = 8;

    /// Keeps `id` if it is new and there is room.
    pub fn insert(&mut self, id: u16) {
        if !self.as_slice().contains(&id) && self.len < Self::CAPACITY {
            self.ids[self.len] = id;
            self.len += 1;
        }
    }

    /// The ids, in the order first seen.
    pub fn as_slice(&self) -> &[u16] {
        &self.ids[..self.len]
    }

    /// Whether none was seen.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl core::fmt::Display for IdsSeen {
    /// `0x211, 0x221` (or `none`).
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.is_empty() {
            return f.write_str("none");
        }
        for (i, id) in self.as_slice().iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            write!(f, "0x{id:03X}")?;
        }
        Ok(())
    }
}

/// Watches the ids of received frames; time comes in as an argument (any monotonic origin).
#[derive(Debug, Clone, Copy, Default)]
pub struct ProtocolDetector {
    first: [Option<Duration>; 2],
    ids: [IdsSeen; 2],
}

impl ProtocolDetector {
    /// A detector that has heard nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Records a frame with `id` received at `now`.
    pub fn observe(&mut self, id: u16, now: Duration) {
        if let Some(protocol) = protocol_of_feedback_id(id) {
            let i = protocol.index();
            self.first[i].get_or_insert(now);
            self.ids[i].insert(id);
        }
    }

    /// Whether feedback of `protocol` was heard.
    pub fn heard(&self, protocol: Protocol) -> bool {
        self.first[protocol.index()].is_some()
    }

    /// The ids of `protocol` heard.
    pub fn ids(&self, protocol: Protocol) -> IdsSeen {
        self.ids[protocol.index()]
    }

    /// The verdict at `now`.
    pub fn detection(&self, now: Duration) -> Detection {
        match self.first {
            [Some(_), Some(_)] => Detection::Both,
            [Some(first), None] if now.saturating_sub(first) >= DETECTION_WINDOW => {
                Detection::Found(Protocol::V1)
            }
            [None, Some(first)] if now.saturating_sub(first) >= DETECTION_WINDOW => {
                Detection::Found(Protocol::V2)
            }
            _ => Detection::Listening,
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
    fn v1_feedback_for_the_window_means_v1() {
        let mut detector = ProtocolDetector::new();
        detector.observe(0x131, ms(0));
        assert!(!detector.heard(Protocol::V1), "0x131 is in both protocols");
        detector.observe(0x151, ms(10));
        detector.observe(0x200, ms(11));
        assert_eq!(detector.detection(ms(309)), Detection::Listening);
        assert_eq!(detector.detection(ms(310)), Detection::Found(Protocol::V1));
        assert_eq!(detector.ids(Protocol::V1).as_slice(), [0x151, 0x200]);
    }

    #[test]
    fn v2_feedback_for_the_window_means_v2() {
        let mut detector = ProtocolDetector::new();
        detector.observe(0x221, ms(100));
        detector.observe(0x141, ms(120));
        assert_eq!(detector.detection(ms(399)), Detection::Listening);
        assert_eq!(detector.detection(ms(400)), Detection::Found(Protocol::V2));
        detector.reset();
        assert_eq!(detector.detection(ms(5000)), Detection::Listening);
    }

    #[test]
    fn both_protocols_heard_is_a_verdict_of_its_own() {
        let mut detector = ProtocolDetector::new();
        detector.observe(0x151, ms(0));
        detector.observe(0x311, ms(900));
        assert_eq!(detector.detection(ms(900)), Detection::Both);
        let v2 = detector.ids(Protocol::V2);
        assert_eq!(std::format!("{v2}"), "0x311");
    }

    #[test]
    fn host_commands_and_shared_ids_prove_nothing() {
        let mut detector = ProtocolDetector::new();
        for t in 0..100 {
            for id in [0x130, 0x131, 0x140, 0x141, 0x111, 0x121, 0x421, 0x441] {
                detector.observe(id, ms(t * 20));
            }
        }
        assert_eq!(detector.detection(ms(5000)), Detection::Listening);
        assert_eq!(std::format!("{}", detector.ids(Protocol::V1)), "none");
    }

    #[test]
    fn ids_kept_are_distinct_and_bounded() {
        let mut detector = ProtocolDetector::new();
        for id in [
            0x251, 0x251, 0x252, 0x253, 0x254, 0x261, 0x262, 0x263, 0x264, 0x311,
        ] {
            detector.observe(id, ms(0));
        }
        let ids = detector.ids(Protocol::V2);
        assert_eq!(ids.as_slice().len(), IdsSeen::CAPACITY);
        assert_eq!(ids.as_slice()[..2], [0x251, 0x252]);
    }

    #[test]
    fn names_round_trip() {
        for protocol in Protocol::ALL {
            assert_eq!(Protocol::from_name(protocol.name()), Some(protocol));
            assert_eq!(protocol.other().other(), protocol);
            assert_eq!(Protocol::from_raw(protocol.raw()), Some(protocol));
        }
        assert_eq!(Protocol::from_name("v3"), None);
    }
}
