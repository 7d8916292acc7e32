//! slcan (Lawicel) ASCII lines: the set-up commands and frames a serial-line CAN adapter speaks.
//!
//! Both sides are covered: the host's commands (`S6`, `O`, `C`, `Z1`, `tIIILDD..`) and the
//! adapter's answers (`\r` OK, `\a` error, `z\r`/`Z\r` transmit OK, `tIIILDD..[TTTT]` frames).

use crate::can::CanFrame;

/// The line terminator.
pub const CR: u8 = b'\r';

/// The adapter's error answer (BEL), a token of its own.
pub const BEL: u8 = 0x07;

/// The longest line either side sends: `T` + 8 id digits + DLC + 16 data digits + 4 timestamp
/// digits + CR.
pub const MAX_LINE: usize = 31;

/// A CAN bit rate selected by `S0`..`S8`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Bitrate(u8);

impl Bitrate {
    /// The SCOUT's 500 kbit/s (`S6`).
    pub const SCOUT: Bitrate = Bitrate(6);

    const RATES: [u32; 9] = [
        10_000, 20_000, 50_000, 100_000, 125_000, 250_000, 500_000, 800_000, 1_000_000,
    ];

    /// The rate of code `S<index>`, or `None` past 8.
    pub const fn from_index(index: u8) -> Option<Self> {
        if index <= 8 { Some(Self(index)) } else { None }
    }

    /// The digit after `S`.
    pub const fn index(self) -> u8 {
        self.0
    }

    /// Bits per second.
    pub const fn bits_per_second(self) -> u32 {
        Self::RATES[self.0 as usize]
    }
}

/// One slcan line (or the BEL token), from either side.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Slcan {
    /// Empty line: the adapter's OK.
    Ack,
    /// BEL: the adapter's error.
    Nack,
    /// `z` or `Z`: the adapter sent the frame (standard or extended).
    TransmitAck {
        /// `Z`: for an extended frame.
        extended: bool,
    },
    /// `tIIILDD..` with an optional 4-digit timestamp: a standard frame to send (host) or
    /// received (adapter).
    Frame {
        /// The frame.
        frame: CanFrame,
        /// Milliseconds 0..59999, when the adapter's timestamps are on.
        timestamp: Option<u16>,
    },
    /// `TIIIIIIIILDD..`: an extended frame. SCOUT v1 uses none; kept so it can be counted.
    ExtendedFrame {
        /// The 29-bit id.
        id: u32,
    },
    /// `Sn`: set the bit rate.
    SetBitrate(Bitrate),
    /// `O`: open the channel.
    Open,
    /// `C`: close the channel.
    Close,
    /// `Z0` / `Z1`: timestamps off / on.
    Timestamps(bool),
    /// Any other command letter (`V`, `N`, `F`, ...), with the line's length.
    Other {
        /// The command letter.
        command: u8,
    },
}

/// Why a line is not valid slcan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlcanError {
    /// A character that should be a hex digit is not.
    BadHex {
        /// Its position in the line.
        position: usize,
    },
    /// The DLC digit is above 8.
    BadDlc {
        /// The digit's value.
        found: u8,
    },
    /// The line is not as long as its DLC says (data, optional 4-digit timestamp).
    BadFrameLength {
        /// The line's length.
        found: usize,
    },
    /// `S` with no digit 0..8.
    BadBitrate,
    /// A standard id above 0x7FF or an extended one above 0x1FFFFFFF.
    BadId,
    /// The line is longer than any slcan line.
    TooLong,
}

impl core::fmt::Display for SlcanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::BadHex { position } => write!(f, "slcan: not a hex digit at position {position}"),
            Self::BadDlc { found } => write!(f, "slcan: data length {found} above 8"),
            Self::BadFrameLength { found } => {
                write!(
                    f,
                    "slcan: frame line of {found} characters does not match its length"
                )
            }
            Self::BadBitrate => f.write_str("slcan: bit rate command needs a digit 0..8"),
            Self::BadId => f.write_str("slcan: CAN id out of range"),
            Self::TooLong => write!(f, "slcan: line longer than {MAX_LINE} characters"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for SlcanError {}

fn hex_value(line: &[u8], position: usize) -> Result<u8, SlcanError> {
    let digit = line
        .get(position)
        .copied()
        .ok_or(SlcanError::BadFrameLength { found: line.len() })?;
    (digit as char)
        .to_digit(16)
        .map(|value| value as u8)
        .ok_or(SlcanError::BadHex { position })
}

fn hex_number(line: &[u8], positions: core::ops::Range<usize>) -> Result<u32, SlcanError> {
    positions.into_iter().try_fold(0u32, |value, position| {
        Ok(value << 4 | u32::from(hex_value(line, position)?))
    })
}

/// Parses one line without its terminator (an empty slice is the adapter's OK).
pub fn parse(line: &[u8]) -> Result<Slcan, SlcanError> {
    if line.len() > MAX_LINE {
        return Err(SlcanError::TooLong);
    }
    let Some((&command, rest)) = line.split_first() else {
        return Ok(Slcan::Ack);
    };
    Ok(match (command, rest) {
        (BEL, []) => Slcan::Nack,
        (b't', _) => parse_standard_frame(line)?,
        (b'T', rest) if rest.len() > 1 => {
            let id = hex_number(line, 1..9)?;
            if id > 0x1FFF_FFFF {
                return Err(SlcanError::BadId);
            }
            Slcan::ExtendedFrame { id }
        }
        (b'z', []) => Slcan::TransmitAck { extended: false },
        (b'Z', []) => Slcan::TransmitAck { extended: true },
        (b'Z', [b'0']) => Slcan::Timestamps(false),
        (b'Z', [b'1']) => Slcan::Timestamps(true),
        (b'S', [digit]) => {
            let index = digit.wrapping_sub(b'0');
            Slcan::SetBitrate(Bitrate::from_index(index).ok_or(SlcanError::BadBitrate)?)
        }
        (b'S', _) => return Err(SlcanError::BadBitrate),
        (b'O', []) => Slcan::Open,
        (b'C', []) => Slcan::Close,
        (command, _) => Slcan::Other { command },
    })
}

fn parse_standard_frame(line: &[u8]) -> Result<Slcan, SlcanError> {
    const DATA: usize = 5;
    let id = hex_number(line, 1..4)? as u16;
    let dlc = hex_value(line, 4)?;
    if dlc > 8 {
        return Err(SlcanError::BadDlc { found: dlc });
    }
    let data_end = DATA + 2 * usize::from(dlc);
    let timestamp = match line.len().checked_sub(data_end) {
        Some(0) => None,
        Some(4) => Some(hex_number(line, data_end..data_end + 4)? as u16),
        _ => return Err(SlcanError::BadFrameLength { found: line.len() }),
    };
    let mut data = [0u8; 8];
    for (index, byte) in data[..usize::from(dlc)].iter_mut().enumerate() {
        let position = DATA + 2 * index;
        *byte = hex_value(line, position)? << 4 | hex_value(line, position + 1)?;
    }
    let frame = CanFrame::new(id, &data[..usize::from(dlc)]).ok_or(SlcanError::BadId)?;
    Ok(Slcan::Frame { frame, timestamp })
}

/// One encoded line, terminator included.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Line {
    bytes: [u8; MAX_LINE],
    len: usize,
}

impl Line {
    fn new() -> Self {
        Self {
            bytes: [0; MAX_LINE],
            len: 0,
        }
    }

    fn push(&mut self, byte: u8) {
        self.bytes[self.len] = byte;
        self.len += 1;
    }

    fn push_hex(&mut self, value: u32, digits: u32) {
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        for shift in (0..digits).rev() {
            self.push(HEX[(value >> (4 * shift) & 0xF) as usize]);
        }
    }

    /// The bytes to write.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes[..self.len]
    }
}

impl AsRef<[u8]> for Line {
    fn as_ref(&self) -> &[u8] {
        self.as_bytes()
    }
}

impl core::fmt::Debug for Line {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "Line({:?})", self.as_bytes().escape_ascii())
    }
}

/// The bytes of `message`: a line ended by CR, or BEL alone for [`Slcan::Nack`].
pub fn encode(message: &Slcan) -> Line {
    let mut line = Line::new();
    match *message {
        Slcan::Ack => {}
        Slcan::Nack => {
            line.push(BEL);
            return line;
        }
        Slcan::TransmitAck { extended } => line.push(if extended { b'Z' } else { b'z' }),
        Slcan::Frame { frame, timestamp } => {
            line.push(b't');
            line.push_hex(u32::from(frame.id()), 3);
            line.push_hex(frame.data().len() as u32, 1);
            for byte in frame.data() {
                line.push_hex(u32::from(*byte), 2);
            }
            if let Some(timestamp) = timestamp {
                line.push_hex(u32::from(timestamp), 4);
            }
        }
        Slcan::ExtendedFrame { id } => {
            line.push(b'T');
            line.push_hex(id, 8);
            line.push(b'0');
        }
        Slcan::SetBitrate(rate) => {
            line.push(b'S');
            line.push(b'0' + rate.index());
        }
        Slcan::Open => line.push(b'O'),
        Slcan::Close => line.push(b'C'),
        Slcan::Timestamps(on) => {
            line.push(b'Z');
            line.push(if on { b'1' } else { b'0' });
        }
        Slcan::Other { command } => line.push(command),
    }
    line.push(CR);
    line
}

/// Splits a byte stream into slcan messages: lines end at CR, BEL stands alone, LF is ignored.
/// Fixed buffer, no allocation; an over-long line is reported once and skipped to its CR.
#[derive(Debug, Clone)]
pub struct LineDecoder {
    buffer: [u8; MAX_LINE],
    len: usize,
    overflowed: bool,
}

impl Default for LineDecoder {
    fn default() -> Self {
        Self {
            buffer: [0; MAX_LINE],
            len: 0,
            overflowed: false,
        }
    }
}

impl LineDecoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds one byte; returns a message when it ends one.
    pub fn push(&mut self, byte: u8) -> Option<Result<Slcan, SlcanError>> {
        match byte {
            BEL => Some(Ok(Slcan::Nack)),
            b'\n' => None,
            CR => {
                let line = &self.buffer[..self.len];
                let result = if self.overflowed {
                    Err(SlcanError::TooLong)
                } else {
                    parse(line)
                };
                self.len = 0;
                self.overflowed = false;
                Some(result)
            }
            _ if self.len == MAX_LINE => {
                self.overflowed = true;
                None
            }
            _ => {
                self.buffer[self.len] = byte;
                self.len += 1;
                None
            }
        }
    }

    /// Drops a partial line (after a reconnect).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(id: u16, data: &[u8]) -> CanFrame {
        CanFrame::new(id, data).expect("valid frame")
    }

    #[test]
    fn encodes_the_manual_example_as_a_t_line() {
        let line = encode(&Slcan::Frame {
            frame: frame(0x130, &[0x01, 0x00, 0x0A, 0x00, 0x00, 0x00, 0x00, 0x44]),
            timestamp: None,
        });
        assert_eq!(line.as_bytes(), b"t130801000A0000000044\r");
    }

    #[test]
    fn parses_adapter_answers_and_setup_commands() {
        assert_eq!(parse(b""), Ok(Slcan::Ack));
        assert_eq!(parse(b"z"), Ok(Slcan::TransmitAck { extended: false }));
        assert_eq!(parse(b"Z"), Ok(Slcan::TransmitAck { extended: true }));
        assert_eq!(parse(b"S6"), Ok(Slcan::SetBitrate(Bitrate::SCOUT)));
        assert_eq!(Bitrate::SCOUT.bits_per_second(), 500_000);
        assert_eq!(parse(b"S9"), Err(SlcanError::BadBitrate));
        assert_eq!(parse(b"O"), Ok(Slcan::Open));
        assert_eq!(parse(b"C"), Ok(Slcan::Close));
        assert_eq!(parse(b"Z1"), Ok(Slcan::Timestamps(true)));
        assert_eq!(parse(b"V"), Ok(Slcan::Other { command: b'V' }));
        assert_eq!(
            parse(b"T1234567880"),
            Ok(Slcan::ExtendedFrame { id: 0x1234_5678 })
        );
    }

    #[test]
    fn parses_frames_with_and_without_timestamp() {
        let expected = frame(0x151, &[1, 0, 0, 0xEF, 0, 0x3C, 0xE4, 0x6A]);
        assert_eq!(
            parse(b"t1518010000EF003CE46A"),
            Ok(Slcan::Frame {
                frame: expected,
                timestamp: None
            })
        );
        assert_eq!(
            parse(b"t1518010000ef003ce46a1A2B"),
            Ok(Slcan::Frame {
                frame: expected,
                timestamp: Some(0x1A2B)
            })
        );
        assert_eq!(
            parse(b"t1300"),
            Ok(Slcan::Frame {
                frame: frame(0x130, &[]),
                timestamp: None
            })
        );
    }

    #[test]
    fn rejects_malformed_frames_with_the_reason() {
        assert_eq!(parse(b"t13090000"), Err(SlcanError::BadDlc { found: 9 }));
        assert_eq!(
            parse(b"t1302AA"),
            Err(SlcanError::BadFrameLength { found: 7 })
        );
        assert_eq!(parse(b"t13G1AA"), Err(SlcanError::BadHex { position: 3 }));
        assert_eq!(parse(b"t8001AA"), Err(SlcanError::BadId));
    }

    #[test]
    fn line_decoder_splits_on_cr_and_bel() {
        let mut decoder = LineDecoder::new();
        let out: Vec<_> = b"\x07z\rt1300\r"
            .iter()
            .filter_map(|b| decoder.push(*b))
            .collect();
        assert_eq!(
            out,
            [
                Ok(Slcan::Nack),
                Ok(Slcan::TransmitAck { extended: false }),
                Ok(Slcan::Frame {
                    frame: frame(0x130, &[]),
                    timestamp: None
                })
            ]
        );
        let long: Vec<_> = [b'x'; 40]
            .iter()
            .chain(b"\rO\r")
            .filter_map(|b| decoder.push(*b))
            .collect();
        assert_eq!(long, [Err(SlcanError::TooLong), Ok(Slcan::Open)]);
    }
}
