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
    fn v2_motion_commands_round_trip_within_a_thousandth(linear in -30.0f64..30.0, angular in -30.0f64..30.0, lateral in -30.0f64..30.0) {
        use scout_protocol::v2::{MessageV2, MotionV2, decode};
        let command = MotionV2::from_si(linear, angular).with_lateral(lateral);
        prop_assert!((command.linear() - linear).abs() <= 0.0005 + 1e-9);
        prop_assert!((command.angular() - angular).abs() <= 0.0005 + 1e-9);
        prop_assert!((command.lateral() - lateral).abs() <= 0.0005 + 1e-9);
        // Sideways is bytes 4-5, big-endian mm/s (the vendor SDK's MotionCommandFrame).
        let frame = MessageV2::MotionCommand(command).encode();
        prop_assert_eq!(i16::from_be_bytes([frame.data()[4], frame.data()[5]]), command.lateral_mm_s);
        prop_assert_eq!(decode(&MessageV2::MotionCommand(command).encode()), Ok(MessageV2::MotionCommand(command)));
    }

    /// Held within limits, a command is never beyond them on the wire, and a rate within them
    /// moves by less than a unit.
    #[test]
    fn v2_commands_within_limits_never_exceed_them(
        linear in -30.0f64..30.0, angular in -30.0f64..30.0, lateral in -30.0f64..30.0,
        steering in -2.0f64..2.0,
        limits in (0.0f64..30.0, 0.0f64..30.0, 0.0f64..30.0, 0.0f64..1.6),
    ) {
        use scout_protocol::v2::MotionV2;
        let (max_linear, max_angular, max_lateral, max_steering) = limits;
        let clamp = |value: f64, limit: f64| value.clamp(-limit, limit);
        let command = MotionV2::from_si(clamp(linear, max_linear), clamp(angular, max_angular))
            .with_lateral(clamp(lateral, max_lateral))
            .with_steering(clamp(steering, max_steering))
            .within(max_linear, max_angular, max_lateral, max_steering);
        prop_assert!(command.steering().abs() <= max_steering + 1e-9);
        prop_assert!(command.linear().abs() <= max_linear + 1e-9);
        prop_assert!(command.angular().abs() <= max_angular + 1e-9);
        prop_assert!(command.lateral().abs() <= max_lateral + 1e-9);
        prop_assert!((command.angular() - clamp(angular, max_angular)).abs() <= 0.001 + 1e-9);
        prop_assert_eq!(MotionV2::from_si(0.0, 0.0).within(max_linear, max_angular, max_lateral, max_steering), MotionV2::default());
    }
}

mod gs_usb {
    //! The USB-CAN adapters' protocol: host frames both ways, decoding any bytes, and the bit
    //! timing against an exhaustive search.
    use proptest::prelude::*;
    use scout_protocol::CanFrame;
    use scout_protocol::gs_usb::{BitTiming, BtConst, HostFrame, RX_ECHO_ID, Received};

    fn any_standard_frame() -> impl Strategy<Value = CanFrame> {
        (0u16..0x800, proptest::collection::vec(any::<u8>(), 0..=8))
            .prop_map(|(id, data)| CanFrame::new(id, &data).expect("a valid frame"))
    }

    fn any_received() -> impl Strategy<Value = Received> {
        prop_oneof![
            any_standard_frame().prop_map(Received::Frame),
            (0..RX_ECHO_ID).prop_map(Received::Echo),
            (0x800u32..0x2000_0000).prop_map(|id| Received::Foreign(id | 0x8000_0000)),
            (0u32..0x2000_0000, any::<[u8; 8]>())
                .prop_map(|(class, data)| Received::BusError { class, data }),
        ]
    }

    /// The adapter's host frame for `received`, as an adapter builds it.
    fn adapter_frame(received: Received, channel: u8, timestamp_us: Option<u32>) -> HostFrame {
        let (echo_id, can_id, len, data) = match received {
            Received::Frame(frame) => {
                let mut data = [0; 8];
                data[..frame.data().len()].copy_from_slice(frame.data());
                (
                    RX_ECHO_ID,
                    u32::from(frame.id()),
                    frame.data().len() as u8,
                    data,
                )
            }
            Received::Echo(echo_id) => (echo_id, 0x130, 8, [0; 8]),
            Received::Foreign(can_id) => (RX_ECHO_ID, can_id, 0, [0; 8]),
            Received::BusError { class, data } => (RX_ECHO_ID, class | 0x2000_0000, 8, data),
        };
        HostFrame {
            echo_id,
            can_id,
            len,
            channel,
            flags: 0,
            data,
            timestamp_us,
        }
    }

    /// (rate error, sample-point error, fewer quanta): what the timing search minimises.
    fn quality(timing: &BitTiming, constants: &BtConst, bitrate: u32) -> (u64, u32, i64) {
        let quanta = 1 + timing.prop_seg + timing.phase_seg1 + timing.phase_seg2;
        let rate = u64::from(constants.clock_hz) / u64::from(timing.brp * quanta);
        (
            rate.abs_diff(u64::from(bitrate)),
            875 - timing.sample_point(),
            -i64::from(quanta),
        )
    }

    /// Every prescaler, segment 1 and segment 2 the constants allow, the best kept.
    fn exhaustive(c: &BtConst, bitrate: u32) -> Option<(u64, u32, i64)> {
        let mut best = None;
        let mut brp = c.brp_min.div_ceil(c.brp_inc) * c.brp_inc;
        // A larger prescaler leaves fewer than 3 quanta a bit: no rate within 1 % of it.
        while brp <= c.brp_max
            && u64::from(brp) * 3 * u64::from(bitrate) <= u64::from(c.clock_hz) * 2
        {
            for tseg1 in c.tseg1_min..=c.tseg1_max {
                for tseg2 in c.tseg2_min..=c.tseg2_max {
                    let quanta = 1 + tseg1 + tseg2;
                    let sample_point = 1000 * (quanta - tseg2) / quanta;
                    if sample_point > 875 {
                        continue;
                    }
                    let rate = u64::from(c.clock_hz) / u64::from(brp * quanta);
                    let key = (
                        rate.abs_diff(u64::from(bitrate)),
                        875 - sample_point,
                        -i64::from(quanta),
                    );
                    if best.is_none_or(|b| key < b) {
                        best = Some(key);
                    }
                }
            }
            brp += c.brp_inc;
        }
        best.filter(|&(rate_error, _, _)| rate_error * 100 <= u64::from(bitrate))
    }

    fn any_constants() -> impl Strategy<Value = BtConst> {
        (
            prop_oneof![
                Just(8_000_000u32),
                Just(16_000_000),
                Just(24_000_000),
                Just(40_000_000),
                Just(48_000_000),
                Just(80_000_000),
                Just(170_000_000),
                1_000_000u32..200_000_000,
            ],
            (1u32..=4, 0u32..=28),
            (1u32..=2, 0u32..=14),
            1u32..=16,
            (1u32..=4, 0u32..=300, 1u32..=4),
        )
            .prop_map(
                |(
                    clock_hz,
                    (t1, t1_span),
                    (t2, t2_span),
                    sjw_max,
                    (brp_min, brp_span, brp_inc),
                )| BtConst {
                    features: 0,
                    clock_hz,
                    tseg1_min: t1,
                    tseg1_max: t1 + t1_span,
                    tseg2_min: t2,
                    tseg2_max: t2 + t2_span,
                    sjw_max,
                    brp_min,
                    brp_max: brp_min + brp_span,
                    brp_inc,
                },
            )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        #[test]
        fn the_bit_timing_is_as_good_as_an_exhaustive_search_and_within_the_constants(
            c in any_constants(),
            bitrate in prop_oneof![Just(125_000u32), Just(250_000), Just(500_000), Just(1_000_000)],
        ) {
            match (BitTiming::for_bitrate(&c, bitrate), exhaustive(&c, bitrate)) {
                (Ok(timing), Some(best)) => {
                    prop_assert_eq!(quality(&timing, &c, bitrate), best, "{:?}", timing);
                    let tseg1 = timing.prop_seg + timing.phase_seg1;
                    prop_assert!((c.tseg1_min..=c.tseg1_max).contains(&tseg1));
                    prop_assert!((c.tseg2_min..=c.tseg2_max).contains(&timing.phase_seg2));
                    prop_assert!((1..=c.sjw_max).contains(&timing.sjw));
                    prop_assert!((c.brp_min..=c.brp_max).contains(&timing.brp));
                    prop_assert_eq!(timing.brp % c.brp_inc, 0);
                    prop_assert_eq!(BitTiming::decode(&timing.encode()), Ok(timing));
                }
                (Err(_), None) => {}
                (got, best) => prop_assert!(false, "got {:?}, the exhaustive search {:?}", got, best),
            }
        }

        #[test]
        fn adapter_frames_round_trip(
            received in any_received(),
            channel in any::<u8>(),
            timestamp_us in proptest::option::of(any::<u32>()),
        ) {
            let frame = adapter_frame(received, channel, timestamp_us);
            let (bytes, len) = frame.encode();
            let decoded = HostFrame::decode(&bytes[..len], timestamp_us.is_some()).expect("decodes");
            prop_assert_eq!(decoded, frame);
            prop_assert_eq!(decoded.received(), received);
        }

        #[test]
        fn host_frames_carry_their_can_frame(frame in any_standard_frame(), echo_id in 0..RX_ECHO_ID, channel in any::<u8>()) {
            let host = HostFrame::transmit(&frame, channel, echo_id);
            let (bytes, len) = host.encode();
            let decoded = HostFrame::decode(&bytes[..len], false).expect("decodes");
            prop_assert_eq!(decoded.can_frame(), Some(frame));
            prop_assert_eq!(decoded.received(), Received::Echo(echo_id));
        }

        #[test]
        fn host_frame_decode_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..64), timestamped in any::<bool>()) {
            if let Ok(frame) = HostFrame::decode(&bytes, timestamped) {
                // Length codes 9-15 are 8 bytes (classic CAN), never more.
                prop_assert!(frame.len <= 15);
                if let Received::Frame(can) = frame.received() {
                    prop_assert!(can.data().len() <= 8);
                }
            }
        }
    }
}
