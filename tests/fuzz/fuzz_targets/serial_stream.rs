//! Fuzzes the serial stream decoder with any bytes; its counts must stay consistent.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_protocol::serial::{self, Pull, StreamDecoder};

fuzz_target!(|input: &[u8]| {
    let mut decoder = StreamDecoder::new();
    let mut frames = 0u64;
    for byte in input {
        if let Pull::Frame(counted) = decoder.push(*byte) {
            frames += 1;
            let bytes = serial::encode(&counted.message, counted.count);
            assert_eq!(serial::decode(&bytes), Ok(counted));
        }
    }
    let stats = decoder.stats();
    assert_eq!(stats.frames, frames);
    assert!(stats.discarded_bytes + frames * serial::FRAME_LEN as u64 <= input.len() as u64);
});
