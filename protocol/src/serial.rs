//! RS232 frames: `5A A5 | len | type | id | 6 payload bytes | frame_id | checksum`, 13 bytes, and a
//! streaming decoder that resynchronises after garbage.

use crate::message::{Counted, Direction, Message, MessageKind, PAYLOAD_LEN, Payload};

/// Bytes in every serial frame.
pub const FRAME_LEN: usize = 13;

/// Start of frame.
pub const SOF: [u8; 2] = [0x5A, 0xA5];

/// The only valid `len` byte: the bytes between SOF and checksum.
pub const LENGTH: u8 = 0x0A;

/// Type byte of a host-to-chassis command.
pub const TYPE_COMMAND: u8 = 0x55;

/// Type byte of a chassis-to-host feedback.
pub const TYPE_FEEDBACK: u8 = 0xAA;

/// Field positions in a frame.
mod field {
    use core::ops::Range;
    pub const SOF: Range<usize> = 0..2;
    pub const LENGTH: usize = 2;
    pub const TYPE: usize = 3;
    pub const ID: usize = 4;
    pub const PAYLOAD: Range<usize> = 5..11;
    pub const COUNT: usize = 11;
    pub const CHECKSUM: usize = 12;
}

/// The sum of `bytes` mod 256: the checksum of the 12 bytes before it.
pub fn checksum(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |sum, byte| sum.wrapping_add(*byte))
}

const fn type_byte(direction: Direction) -> u8 {
    match direction {
        Direction::Command => TYPE_COMMAND,
        Direction::Feedback => TYPE_FEEDBACK,
    }
}

/// The frame carrying `message` with rolling count `count`.
pub fn encode(message: &Message, count: u8) -> [u8; FRAME_LEN] {
    let kind = message.kind();
    let mut frame = [0; FRAME_LEN];
    frame[field::SOF].copy_from_slice(&SOF);
    frame[field::LENGTH] = LENGTH;
    frame[field::TYPE] = type_byte(kind.direction());
    frame[field::ID] = kind.serial_id();
    frame[field::PAYLOAD].copy_from_slice(&message.payload());
    frame[field::COUNT] = count;
    frame[field::CHECKSUM] = checksum(&frame[..field::CHECKSUM]);
    frame
}

/// Why bytes that started like a frame were rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SerialError {
    /// A whole frame given to [`decode`] does not start with `5A A5`.
    BadStart {
        /// The first two bytes.
        found: [u8; 2],
    },
    /// The length byte was not 0x0A (rejected before buffering the rest).
    BadLength {
        /// The length byte found.
        found: u8,
    },
    /// The type byte was neither 0x55 (command) nor 0xAA (feedback).
    UnknownType {
        /// The type byte found.
        found: u8,
    },
    /// The (type, id) pair is not one the protocol uses.
    UnknownId {
        /// The type byte.
        frame_type: u8,
        /// The id byte.
        id: u8,
    },
    /// The checksum byte does not match the 12 bytes before it.
    Checksum {
        /// The checksum the frame should carry.
        expected: u8,
        /// The checksum it carries.
        found: u8,
    },
}

impl core::fmt::Display for SerialError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::BadStart {
                found: [first, second],
            } => write!(
                f,
                "serial frame starts {first:02X} {second:02X}, expected 5A A5"
            ),
            Self::BadLength { found } => {
                write!(
                    f,
                    "serial frame length 0x{found:02X}, expected 0x{LENGTH:02X}"
                )
            }
            Self::UnknownType { found } => write!(
                f,
                "serial frame type 0x{found:02X}, expected 0x{TYPE_COMMAND:02X} or 0x{TYPE_FEEDBACK:02X}"
            ),
            Self::UnknownId { frame_type, id } => {
                write!(
                    f,
                    "serial frame type 0x{frame_type:02X} has no id 0x{id:02X}"
                )
            }
            Self::Checksum { expected, found } => {
                write!(
                    f,
                    "serial frame checksum 0x{found:02X}, expected 0x{expected:02X}"
                )
            }
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for SerialError {}

/// Checks a complete 13-byte frame and decodes it.
pub fn decode(frame: &[u8; FRAME_LEN]) -> Result<Counted, SerialError> {
    match check_prefix(frame) {
        Prefix::Complete(counted) => Ok(counted),
        Prefix::Invalid(error) => Err(error),
        Prefix::NotStart => Err(SerialError::BadStart {
            found: [frame[0], frame[1]],
        }),
        // check_prefix asks for more bytes only while it holds fewer than FRAME_LEN.
        Prefix::Incomplete => unreachable!("a whole frame is never incomplete"),
    }
}

/// What a buffered prefix of a frame is so far.
enum Prefix {
    /// The first bytes are not `5A A5`: garbage to skip.
    NotStart,
    /// Valid so far; more bytes needed.
    Incomplete,
    /// A valid start, then a rejected field.
    Invalid(SerialError),
    /// A whole valid frame.
    Complete(Counted),
}

fn check_prefix(bytes: &[u8]) -> Prefix {
    if bytes.iter().zip(SOF).any(|(byte, sof)| *byte != sof) {
        return Prefix::NotStart;
    }
    if let Some(&found) = bytes.get(field::LENGTH)
        && found != LENGTH
    {
        return Prefix::Invalid(SerialError::BadLength { found });
    }
    let direction = match bytes.get(field::TYPE) {
        None => return Prefix::Incomplete,
        Some(&TYPE_COMMAND) => Direction::Command,
        Some(&TYPE_FEEDBACK) => Direction::Feedback,
        Some(&found) => return Prefix::Invalid(SerialError::UnknownType { found }),
    };
    let Some(&id) = bytes.get(field::ID) else {
        return Prefix::Incomplete;
    };
    let Some(kind) = MessageKind::from_serial(direction, id) else {
        return Prefix::Invalid(SerialError::UnknownId {
            frame_type: bytes[field::TYPE],
            id,
        });
    };
    if bytes.len() < FRAME_LEN {
        return Prefix::Incomplete;
    }
    let expected = checksum(&bytes[..field::CHECKSUM]);
    let found = bytes[field::CHECKSUM];
    if expected != found {
        return Prefix::Invalid(SerialError::Checksum { expected, found });
    }
    let mut payload: Payload = [0; PAYLOAD_LEN];
    payload.copy_from_slice(&bytes[field::PAYLOAD]);
    Prefix::Complete(Counted {
        message: Message::parse(kind, &payload),
        count: bytes[field::COUNT],
    })
}

/// What the decoder has after a byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pull {
    /// Nothing yet: more bytes are needed.
    NeedMore,
    /// A whole, valid frame.
    Frame(Counted),
    /// Bytes that started like a frame were rejected (and discarded); decoding goes on.
    Rejected(SerialError),
}

/// Counts kept by [`StreamDecoder`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SerialStats {
    /// Valid frames decoded.
    pub frames: u64,
    /// Frames rejected for their checksum.
    pub checksum_errors: u64,
    /// Frames rejected for their length byte.
    pub length_errors: u64,
    /// Frames rejected for their type or id byte.
    pub unknown_ids: u64,
    /// Bytes thrown away: garbage before a start of frame and the bytes of rejected frames.
    pub discarded_bytes: u64,
}

/// A streaming serial decoder: push bytes in, pull frames out. Fixed 13-byte buffer, no
/// allocation. It resynchronises on `5A A5` after garbage or a rejected frame, rescanning the
/// bytes it already holds so that a frame starting inside a rejected one is not lost.
#[derive(Debug, Clone, Default)]
pub struct StreamDecoder {
    buffer: [u8; FRAME_LEN],
    buffered: usize,
    stats: SerialStats,
}

impl StreamDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// The counts so far.
    pub fn stats(&self) -> SerialStats {
        self.stats
    }

    /// Drops any partial frame (after a reconnect), counting its bytes as discarded.
    pub fn reset(&mut self) {
        self.stats.discarded_bytes += self.buffered as u64;
        self.buffered = 0;
    }

    /// Feeds one byte.
    pub fn push(&mut self, byte: u8) -> Pull {
        self.buffer[self.buffered] = byte;
        self.buffered += 1;
        let mut rejected = None;
        loop {
            match check_prefix(&self.buffer[..self.buffered]) {
                Prefix::Incomplete => break,
                Prefix::Complete(counted) => {
                    self.buffered = 0;
                    self.stats.frames += 1;
                    return Pull::Frame(counted);
                }
                Prefix::NotStart => self.skip_to_next_start(),
                Prefix::Invalid(error) => {
                    if rejected.is_some() {
                        // Report one rejection per byte; the rest is rechecked with the next one.
                        break;
                    }
                    self.count(error);
                    rejected = Some(error);
                    self.skip_to_next_start();
                }
            }
            if self.buffered == 0 {
                break;
            }
        }
        rejected.map_or(Pull::NeedMore, Pull::Rejected)
    }

    /// Feeds `bytes`, yielding every frame and rejection they complete.
    pub fn push_all<'a>(
        &'a mut self,
        bytes: &'a [u8],
    ) -> impl Iterator<Item = Result<Counted, SerialError>> + 'a {
        bytes.iter().filter_map(move |byte| match self.push(*byte) {
            Pull::NeedMore => None,
            Pull::Frame(counted) => Some(Ok(counted)),
            Pull::Rejected(error) => Some(Err(error)),
        })
    }

    fn count(&mut self, error: SerialError) {
        match error {
            SerialError::BadStart { .. } | SerialError::BadLength { .. } => {
                self.stats.length_errors += 1;
            }
            SerialError::UnknownType { .. } | SerialError::UnknownId { .. } => {
                self.stats.unknown_ids += 1;
            }
            SerialError::Checksum { .. } => self.stats.checksum_errors += 1,
        }
    }

    /// Drops the first buffered byte and everything up to the next possible start of frame.
    fn skip_to_next_start(&mut self) {
        let held = &self.buffer[1..self.buffered];
        let skip = 1 + held
            .iter()
            .position(|byte| *byte == SOF[0])
            .unwrap_or(held.len());
        self.buffer.copy_within(skip..self.buffered, 0);
        self.buffered -= skip;
        self.stats.discarded_bytes += skip as u64;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::{ControlMode, MotionCommand};

    const MANUAL_FORWARD: [u8; FRAME_LEN] = [
        0x5A, 0xA5, 0x0A, 0x55, 0x01, 0x02, 0x00, 0x0A, 0x00, 0x00, 0x00, 0x00, 0x6B,
    ];

    fn frames(decoder: &mut StreamDecoder, bytes: &[u8]) -> Vec<Result<Counted, SerialError>> {
        decoder.push_all(bytes).collect()
    }

    #[test]
    fn bad_length_is_rejected_at_the_third_byte() {
        let mut decoder = StreamDecoder::new();
        assert_eq!(decoder.push(0x5A), Pull::NeedMore);
        assert_eq!(decoder.push(0xA5), Pull::NeedMore);
        assert_eq!(
            decoder.push(0xFF),
            Pull::Rejected(SerialError::BadLength { found: 0xFF })
        );
        assert_eq!(decoder.stats().length_errors, 1);
        assert_eq!(decoder.stats().discarded_bytes, 3);
    }

    #[test]
    fn garbage_before_a_frame_is_discarded_and_counted() {
        let mut decoder = StreamDecoder::new();
        let mut bytes = vec![0x00, 0x5A, 0x13, 0xA5];
        bytes.extend_from_slice(&MANUAL_FORWARD);
        let decoded = frames(&mut decoder, &bytes);
        assert_eq!(decoded.len(), 1);
        let counted = decoded[0].expect("frame");
        assert_eq!(
            counted.message,
            Message::MotionCommand(MotionCommand {
                linear_percent: 10,
                ..MotionCommand::stop(ControlMode::Serial)
            })
        );
        assert_eq!(decoder.stats().discarded_bytes, 4);
    }

    #[test]
    fn a_frame_inside_a_rejected_one_is_recovered() {
        let mut decoder = StreamDecoder::new();
        // A truncated frame whose missing bytes are the start of a real one.
        let mut bytes = MANUAL_FORWARD[..7].to_vec();
        bytes.extend_from_slice(&MANUAL_FORWARD);
        let decoded = frames(&mut decoder, &bytes);
        assert!(
            matches!(decoded[0], Err(SerialError::Checksum { .. })),
            "{decoded:?}"
        );
        assert!(decoded[1..].iter().all(Result::is_ok), "{decoded:?}");
        assert_eq!(decoder.stats().frames, 1);
        assert_eq!(decoder.stats().checksum_errors, 1);
    }

    #[test]
    fn unknown_type_and_id_are_rejected() {
        let mut decoder = StreamDecoder::new();
        let decoded = frames(
            &mut decoder,
            &[0x5A, 0xA5, 0x0A, 0x11, 0x5A, 0xA5, 0x0A, 0x55, 0x09],
        );
        assert_eq!(
            decoded,
            [
                Err(SerialError::UnknownType { found: 0x11 }),
                Err(SerialError::UnknownId {
                    frame_type: 0x55,
                    id: 0x09
                })
            ]
        );
    }
}
