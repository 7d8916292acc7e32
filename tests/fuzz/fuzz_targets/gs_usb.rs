//! Fuzzes everything read from a gs_usb USB-CAN adapter: host frames (with and without
//! timestamps), the device config and the bit-timing constants, and the bit timing computed
//! from any constants. A decoded frame must encode back to the same bytes.
#![no_main]

use libfuzzer_sys::fuzz_target;
use scout_protocol::gs_usb::{BitTiming, BtConst, DeviceConfig, HostFrame, frame};

fuzz_target!(|input: &[u8]| {
    for timestamped in [false, true] {
        if let Ok(decoded) = HostFrame::decode(input, timestamped) {
            let _ = decoded.received();
            let (bytes, len) = decoded.encode();
            // Byte 11 is reserved: the decoder ignores it, the encoder writes zero.
            let mut expected = input[..len].to_vec();
            expected[frame::FLAGS + 1] = 0;
            assert_eq!(bytes[..len], expected[..]);
        }
    }
    let _ = DeviceConfig::decode(input);
    if let Ok(constants) = BtConst::decode(input) {
        for bitrate in [125_000, 250_000, 500_000, 1_000_000] {
            if let Ok(timing) = BitTiming::for_bitrate(&constants, bitrate) {
                assert!(timing.sample_point() <= BitTiming::SAMPLE_POINT);
                let rate = timing.bitrate(constants.clock_hz);
                assert!(u64::from(rate.abs_diff(bitrate)) * 100 <= u64::from(bitrate));
            }
        }
    }
});
