//! How messages travel on each transport (serial, slcan, SocketCAN, the in-process simulator):
//! messages to bytes or CAN frames, and received bytes back to messages. Shared by the gateway
//! and the simulator; fixed buffers, no allocation.

use crate::serial::{self, StreamDecoder};
use crate::slcan::{self, LineDecoder, Slcan};
use crate::v2::{self, MessageV2};
use crate::version::Protocol;
use crate::{CanFrame, ControlMode, Counted, MessageKind, can};

listed! {
/// How the chassis is reached: the one transport enum of the project (configuration, state,
/// framing, control mode).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
#[cfg_attr(feature = "serde", serde(rename_all = "snake_case"))]
pub enum Transport {
    /// RS232, 13-byte frames.
    Serial,
    /// A serial-line CAN adapter speaking slcan.
    Slcan,
    /// A SocketCAN interface.
    Can,
    /// A gs_usb USB-CAN adapter driven in user space (no kernel CAN driver).
    GsUsb,
    /// The simulated chassis in the same process: messages are handed over unframed, in CAN's
    /// control mode.
    Sim,
}
}

impl Transport {
    /// The control mode every motion command on this transport must carry.
    pub const fn control_mode(self) -> ControlMode {
        match self {
            Self::Serial => ControlMode::Serial,
            Self::Slcan | Self::Can | Self::GsUsb | Self::Sim => ControlMode::Can,
        }
    }

    /// The name used in logs, JSON and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Serial => "serial",
            Self::Slcan => "slcan",
            Self::Can => "can",
            Self::GsUsb => "gs_usb",
            Self::Sim => "sim",
        }
    }

    /// The byte that stands for it in shared memory.
    pub const fn raw(self) -> u8 {
        match self {
            Self::Serial => 0,
            Self::Slcan => 1,
            Self::Can => 2,
            Self::Sim => 3,
            Self::GsUsb => 4,
        }
    }

    /// The transport of a byte from [`Transport::raw`].
    pub const fn from_raw(raw: u8) -> Option<Self> {
        match raw {
            0 => Some(Self::Serial),
            1 => Some(Self::Slcan),
            2 => Some(Self::Can),
            3 => Some(Self::Sim),
            4 => Some(Self::GsUsb),
            _ => None,
        }
    }
}

impl core::fmt::Display for Transport {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why received bytes or a frame were rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxError {
    /// A CAN frame (SocketCAN or slcan) that is not a valid SCOUT v1 frame.
    Can(can::CanError),
    /// A CAN frame with a protocol v2 id that is not a valid v2 frame.
    V2(v2::V2Error),
    /// A rejected serial frame.
    Serial(serial::SerialError),
    /// A malformed slcan line.
    Slcan(slcan::SlcanError),
    /// An extended-id, remote or error CAN frame (SCOUT v1 sends only standard data frames).
    ForeignFrame(u32),
    /// Bytes from a gs_usb adapter that are no host frame.
    GsUsb(crate::gs_usb::Error),
}

impl core::fmt::Display for RxError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Can(error) => error.fmt(f),
            Self::V2(error) => error.fmt(f),
            Self::Serial(error) => error.fmt(f),
            Self::Slcan(error) => error.fmt(f),
            Self::GsUsb(error) => error.fmt(f),
            Self::ForeignFrame(id) => write!(
                f,
                "extended, remote or error CAN frame 0x{id:08X} (SCOUT v1 sends standard data frames)"
            ),
        }
    }
}

impl core::error::Error for RxError {}

impl From<can::CanError> for RxError {
    fn from(error: can::CanError) -> Self {
        Self::Can(error)
    }
}

impl From<serial::SerialError> for RxError {
    fn from(error: serial::SerialError) -> Self {
        Self::Serial(error)
    }
}

impl From<slcan::SlcanError> for RxError {
    fn from(error: slcan::SlcanError) -> Self {
        Self::Slcan(error)
    }
}

impl RxError {
    /// Whether the frame was rejected for its checksum.
    pub fn is_checksum(&self) -> bool {
        matches!(
            self,
            Self::Can(can::CanError::Checksum { .. })
                | Self::Serial(serial::SerialError::Checksum { .. })
        )
    }

    /// The CAN id of the rejected frame, where it had one.
    pub fn can_id(&self) -> Option<u16> {
        match *self {
            Self::Can(
                can::CanError::UnknownId { id }
                | can::CanError::BadLength { id, .. }
                | can::CanError::Checksum { id, .. },
            ) => Some(id),
            Self::V2(v2::V2Error::UnknownId { id } | v2::V2Error::BadLength { id, .. }) => Some(id),
            Self::Serial(_) | Self::Slcan(_) | Self::GsUsb(_) | Self::ForeignFrame(_) => None,
        }
    }
}

/// One thing received from the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxEvent {
    /// A valid message.
    Message(Counted),
    /// A valid protocol v2 frame (a SCOUT 2.0 or MINI; v2's ids and v1's do not overlap).
    V2(MessageV2),
    /// Bytes or a frame rejected, with the reason.
    Rejected(RxError),
    /// An slcan line that is not a frame: adapter set-up commands and answers.
    Slcan(Slcan),
}

impl From<Result<Counted, RxError>> for RxEvent {
    fn from(result: Result<Counted, RxError>) -> Self {
        match result {
            Ok(counted) => Self::Message(counted),
            Err(error) => Self::Rejected(error),
        }
    }
}

/// Decodes one CAN frame: a v1 id as v1 (checksum and all), a v2 id as v2, anything else is
/// an unknown id.
pub fn decode_can(frame: &CanFrame) -> RxEvent {
    let id = frame.id();
    if MessageKind::from_can_id(id).is_none() && v2::is_v2_id(id) {
        return match v2::decode(frame) {
            Ok(message) => RxEvent::V2(message),
            Err(error) => RxEvent::Rejected(RxError::V2(error)),
        };
    }
    can::decode(frame).map_err(RxError::from).into()
}

/// Decodes one CAN frame as a protocol v2 chassis hears it from its host: every v2 id as v2.
/// The ids both protocols use mean the host's v2 commands here (0x141 sets a Ranger's motion
/// mode; as v1 it is light feedback, which no host sends).
pub fn decode_can_v2(frame: &CanFrame) -> RxEvent {
    if v2::is_v2_id(frame.id()) {
        return match v2::decode(frame) {
            Ok(message) => RxEvent::V2(message),
            Err(error) => RxEvent::Rejected(RxError::V2(error)),
        };
    }
    decode_can(frame)
}

/// The decoder of a byte-stream transport (serial or slcan). Fixed buffers, no allocation.
#[derive(Debug, Clone)]
pub enum StreamFraming {
    /// 13-byte serial frames.
    Serial(StreamDecoder),
    /// slcan lines.
    Slcan(LineDecoder),
}

impl StreamFraming {
    /// The decoder for `transport`, or `None` for SocketCAN and the simulator (which carry
    /// whole frames or messages).
    pub fn new(transport: Transport) -> Option<Self> {
        match transport {
            Transport::Serial => Some(Self::Serial(StreamDecoder::new())),
            Transport::Slcan => Some(Self::Slcan(LineDecoder::new())),
            Transport::Can | Transport::GsUsb | Transport::Sim => None,
        }
    }

    /// Feeds received bytes, calling `on_event` for each event they complete.
    pub fn push(&mut self, bytes: &[u8], on_event: impl FnMut(RxEvent)) {
        self.push_with(bytes, decode_can, on_event);
    }

    /// As [`StreamFraming::push`], each CAN frame decoded by `decode` ([`decode_can_v2`] for a
    /// v2 chassis).
    pub fn push_with(
        &mut self,
        bytes: &[u8],
        decode: fn(&CanFrame) -> RxEvent,
        mut on_event: impl FnMut(RxEvent),
    ) {
        match self {
            Self::Serial(decoder) => {
                for result in decoder.push_all(bytes) {
                    on_event(result.map_err(RxError::from).into());
                }
            }
            Self::Slcan(decoder) => {
                for byte in bytes {
                    match decoder.push(*byte) {
                        None => {}
                        Some(Ok(Slcan::Frame { frame, .. })) => on_event(decode(&frame)),
                        Some(Ok(Slcan::ExtendedFrame { id })) => {
                            on_event(RxEvent::Rejected(RxError::ForeignFrame(id)));
                        }
                        Some(Ok(other)) => on_event(RxEvent::Slcan(other)),
                        Some(Err(error)) => on_event(RxEvent::Rejected(error.into())),
                    }
                }
            }
        }
    }

    /// Drops any partial frame or line (after a reconnect).
    pub fn reset(&mut self) {
        match self {
            Self::Serial(decoder) => decoder.reset(),
            Self::Slcan(decoder) => decoder.reset(),
        }
    }

    /// Bytes discarded by the serial decoder (slcan discards whole lines, counted as rejections).
    pub fn discarded_bytes(&self) -> u64 {
        match self {
            Self::Serial(decoder) => decoder.stats().discarded_bytes,
            Self::Slcan(_) => 0,
        }
    }
}

/// A frame the host sends, in the chassis' protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outgoing {
    /// A protocol v1 message with its rolling count.
    V1(Counted),
    /// A protocol v2 message (its count, where it has one, is a field).
    V2(MessageV2),
}

impl Outgoing {
    /// The CAN frame that carries it.
    pub fn can_frame(&self) -> CanFrame {
        match self {
            Self::V1(counted) => can::encode(&counted.message, counted.count),
            Self::V2(message) => message.encode(),
        }
    }

    /// The protocol it belongs to.
    pub const fn protocol(&self) -> Protocol {
        match self {
            Self::V1(_) => Protocol::V1,
            Self::V2(_) => Protocol::V2,
        }
    }
}

/// Protocol v2 has no RS232 framing that any vendor code implements: a v2 frame cannot go out
/// on a serial link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoSerialFraming;

impl core::fmt::Display for NoSerialFraming {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("protocol v2 frames travel on CAN only (no RS232 framing)")
    }
}

impl core::error::Error for NoSerialFraming {}

/// Appends the bytes that carry `frame` on a byte-stream transport: a serial frame on serial,
/// an slcan line on every CAN transport.
pub fn encode_stream(
    transport: Transport,
    frame: &Outgoing,
    out: &mut impl Extend<u8>,
) -> Result<(), NoSerialFraming> {
    match (transport, frame) {
        (Transport::Serial, Outgoing::V1(counted)) => {
            out.extend(serial::encode(&counted.message, counted.count));
        }
        (Transport::Serial, Outgoing::V2(_)) => return Err(NoSerialFraming),
        (Transport::Slcan | Transport::Can | Transport::GsUsb | Transport::Sim, frame) => {
            let line = slcan::encode(&Slcan::Frame {
                frame: frame.can_frame(),
                timestamp: None,
            });
            out.extend(line.as_bytes().iter().copied());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Message, MotionCommand};
    use std::vec::Vec;

    fn round_trip(transport: Transport) -> Vec<RxEvent> {
        let message = Message::MotionCommand(MotionCommand {
            linear_percent: 10,
            ..MotionCommand::stop(transport.control_mode())
        });
        let mut bytes = Vec::new();
        encode_stream(
            transport,
            &Outgoing::V1(Counted { message, count: 7 }),
            &mut bytes,
        )
        .expect("v1 has every framing");
        let mut framing = StreamFraming::new(transport).expect("stream transport");
        let mut events = Vec::new();
        framing.push(&bytes, |event| events.push(event));
        assert_eq!(events, [RxEvent::Message(Counted { message, count: 7 })]);
        events
    }

    #[test]
    fn raw_values_round_trip() {
        for transport in Transport::ALL {
            assert_eq!(Transport::from_raw(transport.raw()), Some(transport));
        }
        assert_eq!(Transport::from_raw(5), None);
    }

    #[test]
    fn stream_transports_round_trip() {
        round_trip(Transport::Serial);
        round_trip(Transport::Slcan);
    }

    #[test]
    fn v2_frames_go_out_on_slcan_and_never_on_serial() {
        let take = Outgoing::V2(MessageV2::ControlMode(v2::ControlModeV2::Can));
        let mut line = Vec::new();
        encode_stream(Transport::Slcan, &take, &mut line).expect("slcan carries v2");
        assert_eq!(line, b"t42180100000000000000\r");
        assert_eq!(take.can_frame().data(), [1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(take.protocol(), Protocol::V2);
        let mut bytes = Vec::new();
        assert_eq!(
            encode_stream(Transport::Serial, &take, &mut bytes),
            Err(NoSerialFraming)
        );
        assert!(bytes.is_empty());
    }

    #[test]
    fn can_frames_decode_in_the_protocol_their_id_belongs_to() {
        let v1 = crate::can::encode(
            &Message::MotionCommand(MotionCommand::stop(ControlMode::Can)),
            3,
        );
        assert!(matches!(decode_can(&v1), RxEvent::Message(_)));
        let take = CanFrame::new(0x421, &[1]).expect("frame");
        assert_eq!(
            decode_can(&take),
            RxEvent::V2(MessageV2::ControlMode(v2::ControlModeV2::Can))
        );
        let short = CanFrame::new(0x211, &[0; 7]).expect("frame");
        let RxEvent::Rejected(error) = decode_can(&short) else {
            panic!("a short 0x211 is rejected")
        };
        assert_eq!(error.can_id(), Some(0x211));
        assert!(!error.is_checksum());
        let unknown = CanFrame::new(0x2F0, &[0; 8]).expect("frame");
        assert_eq!(
            decode_can(&unknown),
            RxEvent::Rejected(RxError::Can(can::CanError::UnknownId { id: 0x2F0 }))
        );
        // Over slcan too.
        let mut framing = StreamFraming::new(Transport::Slcan).expect("stream transport");
        let mut events = Vec::new();
        framing.push(b"t421101\r", |event| events.push(event));
        assert_eq!(
            events.last(),
            Some(&RxEvent::V2(MessageV2::ControlMode(v2::ControlModeV2::Can)))
        );
    }

    #[test]
    fn slcan_setup_lines_and_errors_are_events() {
        let mut framing = StreamFraming::new(Transport::Slcan).expect("stream transport");
        let mut events = Vec::new();
        framing.push(b"S6\rO\rt1308010000000000003B\r", |event| {
            events.push(event)
        });
        assert_eq!(
            events[0],
            RxEvent::Slcan(Slcan::SetBitrate(slcan::Bitrate::SCOUT))
        );
        assert_eq!(events[1], RxEvent::Slcan(Slcan::Open));
        let RxEvent::Rejected(error) = events[2] else {
            panic!("{events:?}")
        };
        assert!(error.is_checksum());
        assert_eq!(error.can_id(), Some(0x130));
    }
}
