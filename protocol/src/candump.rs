//! candump text: the screen (`can0  130   [8]  01 00 ..`), log (`(1554000000.123456) can0
//! 130#0100..`) and compact (`130#0100..`) formats.

use crate::can::{CanFrame, MAX_STANDARD_ID};

/// A timestamp as candump prints it: seconds and microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct Timestamp {
    /// Whole seconds.
    pub seconds: u64,
    /// Microseconds, 0..999999.
    pub micros: u32,
}

impl Timestamp {
    /// As a time since the clock's epoch (saturating).
    pub fn as_duration(self) -> core::time::Duration {
        core::time::Duration::from_secs(self.seconds)
            .saturating_add(core::time::Duration::from_micros(u64::from(self.micros)))
    }
}

/// One parsed candump line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Record<'a> {
    /// The `(seconds.micros)` prefix, when present.
    pub timestamp: Option<Timestamp>,
    /// The interface name, when present (`can0`).
    pub interface: Option<&'a str>,
    /// The frame.
    pub frame: CanFrame,
}

/// Why a line is not a candump line SCOUT can use.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CandumpError {
    /// Nothing but white space.
    Empty,
    /// The `(seconds.micros)` prefix is malformed.
    BadTimestamp,
    /// The id is not hex.
    BadId,
    /// An extended (29-bit) id; SCOUT v1 uses standard ids only.
    ExtendedId,
    /// A remote request or CAN FD frame; SCOUT v1 uses classic data frames only.
    NotDataFrame,
    /// The `[n]` length field is malformed or above 8.
    BadLength,
    /// A data byte is not two hex digits.
    BadData,
    /// The `[n]` length does not match the bytes on the line.
    LengthMismatch {
        /// The length field.
        declared: usize,
        /// The bytes found.
        found: usize,
    },
    /// Neither `ID#DATA` nor `IFACE ID [n] DATA`.
    UnknownFormat,
}

impl core::fmt::Display for CandumpError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::Empty => f.write_str("empty line"),
            Self::BadTimestamp => f.write_str("malformed timestamp, expected (seconds.micros)"),
            Self::BadId => f.write_str("CAN id is not hex"),
            Self::ExtendedId => f.write_str("extended CAN id: SCOUT v1 uses standard ids only"),
            Self::NotDataFrame => f.write_str("remote or CAN FD frame: SCOUT v1 uses data frames"),
            Self::BadLength => f.write_str("length field is not [0]..[8]"),
            Self::BadData => f.write_str("data byte is not two hex digits"),
            Self::LengthMismatch { declared, found } => {
                write!(f, "length field says {declared} bytes, line has {found}")
            }
            Self::UnknownFormat => f.write_str(
                "not a candump line: expected `ID#DATA`, `(TIME) IFACE ID#DATA` or `IFACE ID [N] DATA`",
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CandumpError {}

/// Parses a line in any of the three formats.
pub fn parse(line: &str) -> Result<Record<'_>, CandumpError> {
    let mut rest = line.trim();
    if rest.is_empty() {
        return Err(CandumpError::Empty);
    }
    let mut timestamp = None;
    if let Some(after) = rest.strip_prefix('(') {
        let (inside, after) = after.split_once(')').ok_or(CandumpError::BadTimestamp)?;
        timestamp = Some(parse_timestamp(inside)?);
        rest = after.trim_start();
    }
    let mut tokens = rest.split_ascii_whitespace();
    let first = tokens.next().ok_or(CandumpError::UnknownFormat)?;
    if first.contains('#') {
        return Ok(Record {
            timestamp,
            interface: None,
            frame: parse_compact(first)?,
        });
    }
    let second = tokens.next().ok_or(CandumpError::UnknownFormat)?;
    if second.contains('#') {
        return Ok(Record {
            timestamp,
            interface: Some(first),
            frame: parse_compact(second)?,
        });
    }
    let length = tokens.next().ok_or(CandumpError::UnknownFormat)?;
    if !length.starts_with('[') {
        return Err(CandumpError::UnknownFormat);
    }
    let declared = parse_length(length)?;
    let id = parse_id(second)?;
    let mut data = [0u8; 8];
    let mut found = 0;
    for token in tokens {
        if found == data.len() {
            return Err(CandumpError::LengthMismatch {
                declared,
                found: found + 1,
            });
        }
        data[found] = parse_byte(token)?;
        found += 1;
    }
    if found != declared {
        return Err(CandumpError::LengthMismatch { declared, found });
    }
    let frame = CanFrame::new(id, &data[..found]).ok_or(CandumpError::BadId)?;
    Ok(Record {
        timestamp,
        interface: Some(first),
        frame,
    })
}

/// `SECONDS.MICROS` (up to six fraction digits), as in candump's log prefix without its
/// parentheses.
pub fn parse_timestamp(text: &str) -> Result<Timestamp, CandumpError> {
    let (seconds, fraction) = text
        .trim()
        .split_once('.')
        .ok_or(CandumpError::BadTimestamp)?;
    let all_digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    if !all_digits(seconds) || !all_digits(fraction) || fraction.len() > 6 {
        return Err(CandumpError::BadTimestamp);
    }
    let seconds = seconds.parse().map_err(|_| CandumpError::BadTimestamp)?;
    let micros: u32 = fraction.parse().map_err(|_| CandumpError::BadTimestamp)?;
    Ok(Timestamp {
        seconds,
        micros: micros * 10u32.pow(6 - fraction.len() as u32),
    })
}

fn parse_id(text: &str) -> Result<u16, CandumpError> {
    if text.len() > 3 {
        return if text.len() == 8 && u32::from_str_radix(text, 16).is_ok() {
            Err(CandumpError::ExtendedId)
        } else {
            Err(CandumpError::BadId)
        };
    }
    let id = u16::from_str_radix(text, 16).map_err(|_| CandumpError::BadId)?;
    if id > MAX_STANDARD_ID {
        return Err(CandumpError::BadId);
    }
    Ok(id)
}

fn parse_length(text: &str) -> Result<usize, CandumpError> {
    let digits = text
        .strip_prefix('[')
        .and_then(|t| t.strip_suffix(']'))
        .ok_or(CandumpError::BadLength)?;
    match digits.parse::<usize>() {
        Ok(length) if length <= 8 => Ok(length),
        _ => Err(CandumpError::BadLength),
    }
}

fn parse_byte(text: &str) -> Result<u8, CandumpError> {
    if text.len() != 2 {
        return Err(CandumpError::BadData);
    }
    u8::from_str_radix(text, 16).map_err(|_| CandumpError::BadData)
}

fn parse_compact(text: &str) -> Result<CanFrame, CandumpError> {
    let (id, data) = text.split_once('#').ok_or(CandumpError::UnknownFormat)?;
    if data.starts_with(['#', 'R', 'r']) {
        return Err(CandumpError::NotDataFrame);
    }
    let id = parse_id(id)?;
    let hex = data.as_bytes();
    if !hex.len().is_multiple_of(2) || hex.len() > 16 {
        return Err(CandumpError::BadData);
    }
    let mut bytes = [0u8; 8];
    for (index, pair) in hex.chunks(2).enumerate() {
        let pair = core::str::from_utf8(pair).map_err(|_| CandumpError::BadData)?;
        bytes[index] = parse_byte(pair)?;
    }
    CanFrame::new(id, &bytes[..hex.len() / 2]).ok_or(CandumpError::BadId)
}

/// Formats a frame in candump's compact format (`130#01000A0000000044`).
#[derive(Debug, Clone, Copy)]
pub struct Compact<'a>(pub &'a CanFrame);

impl core::fmt::Display for Compact<'_> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:03X}#", self.0.id())?;
        self.0
            .data()
            .iter()
            .try_for_each(|byte| write!(f, "{byte:02X}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manual_forward() -> CanFrame {
        CanFrame::new(0x130, &[0x01, 0x00, 0x0A, 0x00, 0x00, 0x00, 0x00, 0x44]).expect("frame")
    }

    #[test]
    fn parses_the_three_formats_of_the_notes() {
        let screen = parse("  can0  130   [8]  01 00 0A 00 00 00 00 44").expect("screen");
        assert_eq!(
            screen,
            Record {
                timestamp: None,
                interface: Some("can0"),
                frame: manual_forward()
            }
        );
        let log = parse("(1554000000.123456) can0 130#01000A0000000044").expect("log");
        assert_eq!(
            log.timestamp,
            Some(Timestamp {
                seconds: 1_554_000_000,
                micros: 123_456
            })
        );
        assert_eq!(log.interface, Some("can0"));
        assert_eq!(log.frame, manual_forward());
        let compact = parse("130#01000A0000000044").expect("compact");
        assert_eq!(
            compact,
            Record {
                timestamp: None,
                interface: None,
                frame: manual_forward()
            }
        );
    }

    #[test]
    fn formats_compact() {
        assert_eq!(
            Compact(&manual_forward()).to_string(),
            "130#01000A0000000044"
        );
    }

    #[test]
    fn reports_why_a_line_is_bad() {
        assert_eq!(parse("   "), Err(CandumpError::Empty));
        assert_eq!(parse("130#R"), Err(CandumpError::NotDataFrame));
        assert_eq!(parse("12345678#00"), Err(CandumpError::ExtendedId));
        assert_eq!(parse("130#0"), Err(CandumpError::BadData));
        assert_eq!(
            parse("can0 130 [8] 01 02"),
            Err(CandumpError::LengthMismatch {
                declared: 8,
                found: 2
            })
        );
        assert_eq!(parse("can0 130 [9] 01"), Err(CandumpError::BadLength));
        assert_eq!(parse("(12) can0 130#00"), Err(CandumpError::BadTimestamp));
        assert_eq!(parse("hello"), Err(CandumpError::UnknownFormat));
        assert_eq!(parse("can0 XYZ [0]"), Err(CandumpError::BadId));
        assert_eq!(parse("not a frame"), Err(CandumpError::UnknownFormat));
    }
}
