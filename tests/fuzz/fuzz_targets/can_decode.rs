//! Fuzzes the CAN decoders, v1 and v2: any id and up to 8 bytes; a decoded frame must re-encode
//! to a frame that decodes to the same message.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_protocol::{CanFrame, can, v2};

fuzz_target!(|input: &[u8]| {
    let Some((id_bytes, data)) = input.split_first_chunk::<2>() else { return };
    let id = u16::from_be_bytes(*id_bytes) & 0x7FF;
    let Some(frame) = CanFrame::new(id, &data[..data.len().min(8)]) else { return };
    if let Ok(counted) = can::decode(&frame) {
        let again = can::decode(&can::encode(&counted.message, counted.count));
        assert_eq!(again, Ok(counted));
    }
    if let Ok(message) = v2::decode(&frame) {
        assert_eq!(v2::decode(&message.encode()), Ok(message));
    }
});
