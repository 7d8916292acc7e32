//! Property tests: every message round-trips on both links; the serial decoder recovers every
//! intact frame from any split and any garbage, and never panics. Protocol v2: every message
//! round-trips, every telemetry frame byte for byte, and no frame panics the decoder.

use proptest::prelude::*;
use scout_protocol::serial::{self, StreamDecoder};
use scout_protocol::{Counted, Message, MessageKind, can, slcan};

fn any_message() -> impl Strategy<Value = Message> {
    (0..MessageKind::COUNT, any::<[u8; 6]>())
        .prop_map(|(index, payload)| Message::parse(MessageKind::ALL[index], &payload))
}

fn any_counted() -> impl Strategy<Value = Counted> {
    (any_message(), any::<u8>()).prop_map(|(message, count)| Counted { message, count })
}

/// Garbage that cannot itself start a frame (a random `5A A5 0A` prefix followed by a valid
/// type, id and a matching checksum is a valid frame, not garbage).
fn garbage() -> impl Strategy<Value = Vec<u8>> {
    proptest::collection::vec(any::<u8>(), 0..40).prop_filter("not a frame start", |bytes| {
        !bytes.windows(3).any(|w| w == [0x5A, 0xA5, 0x0A])
    })
}

proptest! {
    #[test]
    fn can_round_trip(counted in any_counted()) {
        let frame = can::encode(&counted.message, counted.count);
        prop_assert_eq!(can::decode(&frame), Ok(counted));
    }

    #[test]
    fn serial_round_trip(counted in any_counted()) {
        let bytes = serial::encode(&counted.message, counted.count);
        prop_assert_eq!(serial::decode(&bytes), Ok(counted));
    }

    #[test]
    fn slcan_round_trip(counted in any_counted(), timestamp in proptest::option::of(0u16..60000)) {
        let frame = can::encode(&counted.message, counted.count);
        let line = slcan::encode(&slcan::Slcan::Frame { frame, timestamp });
        let (last, body) = line.as_bytes().split_last().expect("line");
        prop_assert_eq!(*last, slcan::CR);
        prop_assert_eq!(slcan::parse(body), Ok(slcan::Slcan::Frame { frame, timestamp }));
    }

    #[test]
    fn can_decode_never_panics(id in 0u16..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
        let frame = scout_protocol::CanFrame::new(id, &data).expect("valid frame");
        let _ = can::decode(&frame);
    }

    #[test]
    fn serial_decoder_recovers_every_frame_byte_by_byte(
        frames in proptest::collection::vec((any_counted(), garbage()), 1..12),
    ) {
        let mut stream = Vec::new();
        for (counted, garbage) in &frames {
            stream.extend_from_slice(garbage);
            stream.extend_from_slice(&serial::encode(&counted.message, counted.count));
        }
        let mut decoder = StreamDecoder::new();
        let decoded: Vec<Counted> = stream
            .iter()
            .filter_map(|byte| match decoder.push(*byte) {
                serial::Pull::Frame(counted) => Some(counted),
                _ => None,
            })
            .collect();
        let expected: Vec<Counted> = frames.iter().map(|(counted, _)| *counted).collect();
        prop_assert_eq!(decoded, expected);
        let garbage_len: usize = frames.iter().map(|(_, g)| g.len()).sum();
        prop_assert_eq!(decoder.stats().discarded_bytes as usize, garbage_len);
        prop_assert_eq!(decoder.stats().frames as usize, frames.len());
    }

    #[test]
    fn serial_decoder_survives_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let mut decoder = StreamDecoder::new();
        let results = decoder.push_all(&bytes).count();
        let stats = decoder.stats();
        prop_assert!(results as u64 >= stats.frames);
        prop_assert!(stats.discarded_bytes <= bytes.len() as u64);
    }

    #[test]
    fn slcan_line_decoder_survives_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        let mut decoder = slcan::LineDecoder::new();
        for byte in bytes {
            let _ = decoder.push(byte);
        }
    }

    #[test]
    fn candump_parse_never_panics(line in "\\PC{0,60}") {
        let _ = scout_protocol::candump::parse(&line);
    }
}

/// Any protocol v2 message: the frame of a v2 id with any data, decoded.
fn any_v2_message() -> impl Strategy<Value = scout_protocol::v2::MessageV2> {
    use scout_protocol::v2::{decode, is_v2_id};
    let ids: Vec<u16> = (0..0x800).filter(|id| is_v2_id(*id)).collect();
    (
        proptest::sample::select(ids),
        any::<[u8; 8]>(),
        any::<bool>(),
    )
        .prop_filter_map("a v2 frame", |(id, data, short)| {
            let data = if short { &data[..1] } else { &data[..] };
            decode(&scout_protocol::CanFrame::new(id, data)?).ok()
        })
}

proptest! {
    #[test]
    fn v2_round_trip(message in any_v2_message()) {
        let frame = message.encode();
        prop_assert_eq!(scout_protocol::v2::decode(&frame), Ok(message));
        prop_assert_eq!(frame.id(), message.can_id());
    }

    #[test]
    fn v2_telemetry_frames_round_trip_byte_for_byte(id in 0x211u16..0x400, data in any::<[u8; 8]>()) {
        // Every eight-byte frame the chassis sends is kept whole: no bit is lost or guessed.
        let Some(frame) = scout_protocol::CanFrame::new(id, &data) else { return Ok(()) };
        if let Ok(message) = scout_protocol::v2::decode(&frame) {
            prop_assert!(!message.is_command());
            prop_assert_eq!(message.encode(), frame);
        }
    }

    #[test]
    fn v2_decode_never_panics(id in 0u16..0x800, data in proptest::collection::vec(any::<u8>(), 0..=8)) {
        let frame = scout_protocol::CanFrame::new(id, &data).expect("valid frame");
        let _ = scout_protocol::v2::decode(&frame);
    }

    #[test]
    fn v2_motion_commands_round_trip_within_a_thousandth(linear in -30.0f64..30.0, angular in -30.0f64..30.0) {
        use scout_protocol::v2::{MessageV2, MotionV2, decode};
        let command = MotionV2::from_si(linear, angular);
        prop_assert!((command.linear() - linear).abs() <= 0.0005 + 1e-9);
        prop_assert!((command.angular() - angular).abs() <= 0.0005 + 1e-9);
        prop_assert_eq!(decode(&MessageV2::MotionCommand(command).encode()), Ok(MessageV2::MotionCommand(command)));
    }
}
