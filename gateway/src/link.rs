//! Link framing shared by the gateway and the simulator: messages to the bytes or CAN frames of
//! each transport (serial, slcan, SocketCAN) and received bytes back to messages.

use scout_protocol::serial::{self, StreamDecoder};
use scout_protocol::slcan::{self, LineDecoder, Slcan};
use scout_protocol::{CanFrame, ControlMode, Counted, Message, can};

/// How the chassis is reached.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Transport {
    /// RS232, 13-byte frames.
    Serial,
    /// A serial-line CAN adapter speaking slcan.
    Slcan,
    /// A SocketCAN interface.
    Can,
}

impl Transport {
    /// The control mode every motion command on this transport must carry.
    pub const fn control_mode(self) -> ControlMode {
        match self {
            Self::Serial => ControlMode::Serial,
            Self::Slcan | Self::Can => ControlMode::Can,
        }
    }

    /// The name used in logs, JSON and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Serial => "serial",
            Self::Slcan => "slcan",
            Self::Can => "can",
        }
    }
}

impl std::fmt::Display for Transport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Why received bytes or a frame were rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum RxError {
    /// A CAN frame (SocketCAN or slcan) that is not a valid SCOUT v1 frame.
    #[error("{0}")]
    Can(#[from] can::CanError),
    /// A rejected serial frame.
    #[error("{0}")]
    Serial(#[from] serial::SerialError),
    /// A malformed slcan line.
    #[error("{0}")]
    Slcan(#[from] slcan::SlcanError),
    /// An extended-id, remote or error CAN frame (SCOUT v1 sends only standard data frames).
    #[error("extended, remote or error CAN frame 0x{0:08X} (SCOUT v1 sends standard data frames)")]
    ForeignFrame(u32),
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
            _ => None,
        }
    }
}

/// One thing received from the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RxEvent {
    /// A valid message.
    Message(Counted),
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

/// Decodes one CAN frame.
pub fn decode_can(frame: &CanFrame) -> RxEvent {
    can::decode(frame).map_err(RxError::from).into()
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
    /// The decoder for `transport`, or `None` for SocketCAN (which carries whole frames).
    pub fn new(transport: Transport) -> Option<Self> {
        match transport {
            Transport::Serial => Some(Self::Serial(StreamDecoder::new())),
            Transport::Slcan => Some(Self::Slcan(LineDecoder::new())),
            Transport::Can => None,
        }
    }

    /// Feeds received bytes, calling `on_event` for each event they complete.
    pub fn push(&mut self, bytes: &[u8], mut on_event: impl FnMut(RxEvent)) {
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
                        Some(Ok(Slcan::Frame { frame, .. })) => on_event(decode_can(&frame)),
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

/// Appends the bytes that carry `message` with `count` on a byte-stream transport.
pub fn encode_stream(transport: Transport, message: &Message, count: u8, out: &mut Vec<u8>) {
    match transport {
        Transport::Serial => out.extend_from_slice(&serial::encode(message, count)),
        Transport::Slcan | Transport::Can => {
            let frame = can::encode(message, count);
            out.extend_from_slice(
                slcan::encode(&Slcan::Frame {
                    frame,
                    timestamp: None,
                })
                .as_bytes(),
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_protocol::MotionCommand;

    fn round_trip(transport: Transport) -> Vec<RxEvent> {
        let message = Message::MotionCommand(MotionCommand {
            linear_percent: 10,
            ..MotionCommand::stop(transport.control_mode())
        });
        let mut bytes = Vec::new();
        encode_stream(transport, &message, 7, &mut bytes);
        let mut framing = StreamFraming::new(transport).expect("stream transport");
        let mut events = Vec::new();
        framing.push(&bytes, |event| events.push(event));
        assert_eq!(events, [RxEvent::Message(Counted { message, count: 7 })]);
        events
    }

    #[test]
    fn stream_transports_round_trip() {
        round_trip(Transport::Serial);
        round_trip(Transport::Slcan);
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
