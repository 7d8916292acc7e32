//! Text in a fixed buffer: shared-memory payloads cannot hold a `String`.

use iceoryx2::prelude::ZeroCopySend;

/// Text of at most `N` bytes. Longer text is cut at a character boundary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[repr(C)]
pub struct FixedText<const N: usize> {
    len: u16,
    bytes: [u8; N],
}

impl<const N: usize> FixedText<N> {
    /// The most bytes it holds.
    pub const CAPACITY: usize = N;

    /// Empty text.
    pub const fn empty() -> Self {
        Self {
            len: 0,
            bytes: [0; N],
        }
    }

    /// `text`, cut to fit.
    pub fn new(text: &str) -> Self {
        let mut end = text.len().min(N);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0; N];
        bytes[..end].copy_from_slice(&text.as_bytes()[..end]);
        Self {
            len: end as u16,
            bytes,
        }
    }

    /// The text (empty if the bytes are not UTF-8, which [`FixedText::new`] never produces).
    pub fn as_str(&self) -> &str {
        let len = usize::from(self.len).min(N);
        std::str::from_utf8(&self.bytes[..len]).unwrap_or("")
    }
}

impl<const N: usize> Default for FixedText<N> {
    fn default() -> Self {
        Self::empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_text_cuts_at_a_character_boundary() {
        assert_eq!(FixedText::<4>::new("scout").as_str(), "scou");
        assert_eq!(FixedText::<4>::new("ab\u{e9}\u{e9}").as_str(), "ab\u{e9}");
        assert_eq!(FixedText::<8>::new("").as_str(), "");
    }
}
