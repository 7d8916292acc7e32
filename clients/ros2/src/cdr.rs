//! CDR (little endian, XCDR1 as ROS 2 uses it) for exactly the messages the ROS 2 bridge speaks:
//! a writer that aligns each primitive to its size from the start of the payload, and a reader
//! for the two it receives.

/// The 4-byte encapsulation header: CDR little endian, no options.
pub const ENCAPSULATION: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// Writes one CDR payload, the encapsulation header first.
#[derive(Debug, Default)]
pub struct Writer {
    bytes: Vec<u8>,
}

impl Writer {
    pub fn new() -> Self {
        Self {
            bytes: ENCAPSULATION.to_vec(),
        }
    }

    /// Pads to a multiple of `n` counted from the end of the encapsulation header.
    fn align(&mut self, n: usize) {
        let offset = self.bytes.len() - ENCAPSULATION.len();
        let padding = (n - offset % n) % n;
        self.bytes.extend(std::iter::repeat_n(0, padding));
    }

    pub fn u8(&mut self, value: u8) -> &mut Self {
        self.bytes.push(value);
        self
    }

    pub fn bool(&mut self, value: bool) -> &mut Self {
        self.u8(u8::from(value))
    }

    pub fn i32(&mut self, value: i32) -> &mut Self {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
        self
    }

    pub fn u32(&mut self, value: u32) -> &mut Self {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
        self
    }

    pub fn f32(&mut self, value: f32) -> &mut Self {
        self.align(4);
        self.bytes.extend_from_slice(&value.to_le_bytes());
        self
    }

    pub fn f64(&mut self, value: f64) -> &mut Self {
        self.align(8);
        self.bytes.extend_from_slice(&value.to_le_bytes());
        self
    }

    /// A string: its length with the terminating NUL, the bytes, the NUL.
    pub fn string(&mut self, value: &str) -> &mut Self {
        self.u32(value.len() as u32 + 1);
        self.bytes.extend_from_slice(value.as_bytes());
        self.bytes.push(0);
        self
    }

    /// A sequence's length; its elements follow.
    pub fn sequence(&mut self, len: usize) -> &mut Self {
        self.u32(len as u32)
    }

    pub fn f64s(&mut self, values: &[f64]) -> &mut Self {
        for value in values {
            self.f64(*value);
        }
        self
    }

    pub fn finish(self) -> Vec<u8> {
        self.bytes
    }
}

/// Why a received payload could not be read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CdrError {
    #[error("not CDR little endian (encapsulation {0:02x?})")]
    Encapsulation([u8; 2]),
    #[error("payload ends at byte {0}, before the message does")]
    Truncated(usize),
    #[error("{0} bytes follow the message")]
    Trailing(usize),
    #[error("not a message of the topic's type: {0}")]
    Malformed(String),
}

/// Reads a CDR payload, the encapsulation header first.
#[derive(Debug)]
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8]) -> Result<Self, CdrError> {
        match bytes {
            _ if bytes.len() < ENCAPSULATION.len() => Err(CdrError::Truncated(bytes.len())),
            [0x00, 0x01, _, _, ..] => Ok(Self {
                bytes: &bytes[ENCAPSULATION.len()..],
                at: 0,
            }),
            [a, b, ..] => Err(CdrError::Encapsulation([*a, *b])),
            _ => Err(CdrError::Truncated(bytes.len())),
        }
    }

    fn take<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        self.at += (N - self.at % N) % N;
        let end = self.at + N;
        let chunk = self
            .bytes
            .get(self.at..end)
            .ok_or(CdrError::Truncated(self.bytes.len() + ENCAPSULATION.len()))?;
        self.at = end;
        Ok(chunk.try_into().expect("N bytes"))
    }

    pub fn u8(&mut self) -> Result<u8, CdrError> {
        self.take::<1>().map(|[byte]| byte)
    }

    pub fn i32(&mut self) -> Result<i32, CdrError> {
        self.take::<4>().map(i32::from_le_bytes)
    }

    pub fn u32(&mut self) -> Result<u32, CdrError> {
        self.take::<4>().map(u32::from_le_bytes)
    }

    pub fn f64(&mut self) -> Result<f64, CdrError> {
        self.take::<8>().map(f64::from_le_bytes)
    }

    pub fn f32(&mut self) -> Result<f32, CdrError> {
        self.take::<4>().map(f32::from_le_bytes)
    }

    /// Checks that nothing but alignment padding (less than 8 bytes) follows what was read.
    pub fn finish(&self) -> Result<(), CdrError> {
        match self.bytes.len() - self.at.min(self.bytes.len()) {
            left if left < 8 => Ok(()),
            left => Err(CdrError::Trailing(left)),
        }
    }

    /// Reads a string (its terminating NUL dropped; bytes not UTF-8 replaced).
    pub fn string(&mut self) -> Result<String, CdrError> {
        let start = self.at + (4 - self.at % 4) % 4 + 4;
        self.skip_string()?;
        let bytes = &self.bytes[start.min(self.at)..self.at];
        let text = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        Ok(String::from_utf8_lossy(text).into_owned())
    }

    /// Skips a string.
    pub fn skip_string(&mut self) -> Result<(), CdrError> {
        let len = self.u32()? as usize;
        let end = self
            .at
            .checked_add(len)
            .ok_or(CdrError::Truncated(usize::MAX))?;
        if end > self.bytes.len() {
            return Err(CdrError::Truncated(self.bytes.len() + ENCAPSULATION.len()));
        }
        self.at = end;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_align_from_the_payload_start() {
        let mut writer = Writer::new();
        writer.u8(1).f64(2.0).string("ab").u32(3);
        let bytes = writer.finish();
        assert_eq!(&bytes[..4], &ENCAPSULATION);
        // u8 at 0, f64 at 8, string length at 16, "ab\0" at 20, u32 at 24.
        assert_eq!(bytes.len(), 4 + 28);
        assert_eq!(&bytes[4 + 16..4 + 23], &[3, 0, 0, 0, b'a', b'b', 0]);
        let mut reader = Reader::new(&bytes).expect("header");
        assert_eq!(reader.take::<1>().expect("u8"), [1]);
        assert_eq!(reader.f64().expect("f64"), 2.0);
        reader.skip_string().expect("string");
        assert_eq!(reader.u32().expect("u32"), 3);
        assert!(reader.u32().is_err(), "past the end");
    }

    #[test]
    fn a_big_endian_or_short_payload_is_refused() {
        assert_eq!(
            Reader::new(&[0, 0, 0, 0]).err(),
            Some(CdrError::Encapsulation([0, 0]))
        );
        assert!(Reader::new(&[0]).is_err());
        let mut reader = Reader::new(&[0, 1, 0, 0, 1, 2]).expect("header");
        assert!(reader.f64().is_err());
    }
}
