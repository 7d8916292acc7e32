//! CAN frames: SCOUT messages to an 11-bit id and 8 data bytes (payload, count, checksum) and back.

use crate::message::{Counted, Message, MessageKind, PAYLOAD_LEN, Payload};

/// The data length of every SCOUT v1 frame.
pub const DLC: u8 = 8;

/// Position of the rolling count in the data bytes.
pub const COUNT: usize = 6;

/// Position of the checksum in the data bytes.
pub const CHECKSUM: usize = 7;

/// The largest standard (11-bit) CAN id.
pub const MAX_STANDARD_ID: u16 = 0x7FF;

/// A classic CAN data frame with a standard id, as any link (SocketCAN, slcan, candump text)
/// carries it. Only the first `len` bytes of `data` are meaningful.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct CanFrame {
    id: u16,
    len: u8,
    data: [u8; 8],
}

impl CanFrame {
    /// A frame, or `None` if `id` is not an 11-bit id or `data` is longer than 8 bytes.
    pub fn new(id: u16, data: &[u8]) -> Option<Self> {
        if id > MAX_STANDARD_ID || data.len() > 8 {
            return None;
        }
        let mut bytes = [0; 8];
        bytes[..data.len()].copy_from_slice(data);
        Some(Self {
            id,
            len: data.len() as u8,
            data: bytes,
        })
    }

    /// The 11-bit id.
    pub const fn id(&self) -> u16 {
        self.id
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.len)]
    }
}

/// The checksum of a frame with `id` whose data (count included, checksum excluded) is
/// `data_without_checksum`: id high + id low + DLC + data, mod 256, where the DLC counts the
/// checksum byte too.
pub fn checksum(id: u16, data_without_checksum: &[u8]) -> u8 {
    let dlc = data_without_checksum.len() as u8 + 1;
    let [id_high, id_low] = id.to_be_bytes();
    data_without_checksum.iter().fold(
        id_high.wrapping_add(id_low).wrapping_add(dlc),
        |sum, byte| sum.wrapping_add(*byte),
    )
}

/// Why a CAN frame is not a SCOUT v1 message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CanError {
    /// The id is not one SCOUT v1 uses.
    UnknownId {
        /// The id found.
        id: u16,
    },
    /// The frame does not carry 8 data bytes.
    BadLength {
        /// The id of the frame.
        id: u16,
        /// The length found.
        found: u8,
    },
    /// The checksum byte does not match the frame.
    Checksum {
        /// The id of the frame.
        id: u16,
        /// The checksum the frame should carry.
        expected: u8,
        /// The checksum it carries.
        found: u8,
    },
}

impl core::fmt::Display for CanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::UnknownId { id } => write!(f, "unknown CAN id 0x{id:03X} (not SCOUT v1)"),
            Self::BadLength { id, found } => {
                write!(f, "CAN id 0x{id:03X}: data length {found}, expected {DLC}")
            }
            Self::Checksum {
                id,
                expected,
                found,
            } => write!(
                f,
                "CAN id 0x{id:03X}: checksum 0x{found:02X}, expected 0x{expected:02X}"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CanError {}

/// The frame carrying `message` with rolling count `count`.
pub fn encode(message: &Message, count: u8) -> CanFrame {
    let id = message.kind().can_id();
    let mut data = [0; 8];
    data[..PAYLOAD_LEN].copy_from_slice(&message.payload());
    data[COUNT] = count;
    data[CHECKSUM] = checksum(id, &data[..CHECKSUM]);
    CanFrame { id, len: DLC, data }
}

/// The message a frame carries, after checking its id, length and checksum.
pub fn decode(frame: &CanFrame) -> Result<Counted, CanError> {
    let id = frame.id;
    let kind = MessageKind::from_can_id(id).ok_or(CanError::UnknownId { id })?;
    if frame.len != DLC {
        return Err(CanError::BadLength {
            id,
            found: frame.len,
        });
    }
    let expected = checksum(id, &frame.data[..CHECKSUM]);
    let found = frame.data[CHECKSUM];
    if expected != found {
        return Err(CanError::Checksum {
            id,
            expected,
            found,
        });
    }
    let mut payload: Payload = [0; PAYLOAD_LEN];
    payload.copy_from_slice(&frame.data[..PAYLOAD_LEN]);
    Ok(Counted {
        message: Message::parse(kind, &payload),
        count: frame.data[COUNT],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn notes_checksum_example() {
        // 0x01 + 0x30 + 0x08 + 0x01 + 0x0A = 0x44
        assert_eq!(
            checksum(0x130, &[0x01, 0x00, 0x0A, 0x00, 0x00, 0x00, 0x00]),
            0x44
        );
    }

    #[test]
    fn frame_rejects_what_is_not_a_standard_frame() {
        assert!(CanFrame::new(0x800, &[]).is_none());
        assert!(CanFrame::new(0x130, &[0; 9]).is_none());
    }

    #[test]
    fn decode_says_exactly_what_is_wrong() {
        let unknown = CanFrame::new(0x221, &[0; 8]).expect("frame");
        assert_eq!(decode(&unknown), Err(CanError::UnknownId { id: 0x221 }));
        let short = CanFrame::new(0x131, &[0; 7]).expect("frame");
        assert_eq!(
            decode(&short),
            Err(CanError::BadLength {
                id: 0x131,
                found: 7
            })
        );
        let bad = CanFrame::new(0x130, &[1, 0, 0x0A, 0, 0, 0, 0, 0x45]).expect("frame");
        assert_eq!(
            decode(&bad),
            Err(CanError::Checksum {
                id: 0x130,
                expected: 0x44,
                found: 0x45
            })
        );
    }
}
