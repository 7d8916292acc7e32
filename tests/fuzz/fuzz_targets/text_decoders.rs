//! Fuzzes the text decoders: candump lines and the slcan line decoder.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_protocol::{candump, slcan};

fuzz_target!(|input: &[u8]| {
    if let Ok(text) = core::str::from_utf8(input) {
        let _ = candump::parse(text);
    }
    let mut lines = slcan::LineDecoder::new();
    for byte in input {
        if let Some(Ok(message)) = lines.push(*byte) {
            let _ = slcan::encode(&message);
        }
    }
});
