//! Fuzzes the CAN decoder: any id and up to 8 bytes; a decoded frame must re-encode to itself.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_protocol::{CanFrame, can};

fuzz_target!(|input: &[u8]| {
    let Some((id_bytes, data)) = input.split_first_chunk::<2>() else { return };
    let id = u16::from_be_bytes(*id_bytes) & 0x7FF;
    let Some(frame) = CanFrame::new(id, &data[..data.len().min(8)]) else { return };
    if let Ok(counted) = can::decode(&frame) {
        let again = can::decode(&can::encode(&counted.message, counted.count));
        assert_eq!(again, Ok(counted));
    }
});
