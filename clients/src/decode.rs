//! `scout decode`: one input line (candump text or serial hex) to decoded frames, as text or JSON,
//! in protocol v1 or v2 (a CAN frame tells which by its id, or a flag forces one).

use scout_protocol::serial::{Pull, StreamDecoder};
use scout_protocol::v2::{self, MessageV2};
use scout_protocol::{CanFrame, Counted, MessageKind, can, candump};
use serde_json::{Value, json};

pub use scout_interface::json::{message_fields, message_fields_v2};

/// Which protocol CAN frames are read in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Protocol {
    /// By the frame's id: v1's ids (0x130, 0x131, 0x140, 0x141, 0x151, 0x200-0x203) as v1, v2's
    /// as v2 (the two sets do not overlap for a SCOUT).
    #[default]
    Auto,
    /// Protocol v1 only (the 2019 SCOUT; also every serial frame).
    V1,
    /// Protocol v2 only (SCOUT 2.0, SCOUT MINI).
    V2,
}

/// The message of one frame, in its protocol.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FrameMessage {
    /// Protocol v1, with its rolling count.
    V1(Counted),
    /// Protocol v2.
    V2(MessageV2),
}

/// Which link a line came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// A candump line.
    Can,
    /// Serial frames as hex.
    Serial,
}

impl Link {
    fn name(self) -> &'static str {
        match self {
            Self::Can => "can",
            Self::Serial => "serial",
        }
    }
}

/// One decoded frame and where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedFrame {
    /// The link.
    pub link: Link,
    /// The candump interface, when the line named one.
    pub interface: Option<String>,
    /// The candump timestamp in seconds, when the line had one.
    pub timestamp: Option<f64>,
    /// The message.
    pub message: FrameMessage,
}

/// Why a line could not be decoded.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LineError {
    /// Not a candump line.
    #[error(transparent)]
    Candump(#[from] candump::CandumpError),
    /// A CAN frame that is not a valid SCOUT v1 frame.
    #[error(transparent)]
    Can(#[from] can::CanError),
    /// A CAN frame that is not a valid SCOUT v2 frame.
    #[error(transparent)]
    V2(#[from] v2::V2Error),
    /// An id of neither protocol.
    #[error("unknown CAN id 0x{0:03X} (neither SCOUT v1 nor v2)")]
    UnknownId(u16),
    /// Serial hex with a rejected frame.
    #[error(transparent)]
    Serial(#[from] scout_protocol::serial::SerialError),
    /// Serial hex that does not end on a frame boundary.
    #[error("{0} trailing byte(s) are not a whole serial frame")]
    SerialTrailing(usize),
}

/// Serial frames as hex: `5A A5 0A ..` or `5AA50A..`, any number of whole frames.
fn serial_hex(line: &str) -> Option<Vec<u8>> {
    let digits: String = line.chars().filter(|c| !c.is_ascii_whitespace()).collect();
    let looks_serial = digits.len() >= 4
        && digits.len().is_multiple_of(2)
        && digits[..4].eq_ignore_ascii_case("5AA5")
        && digits.bytes().all(|b| b.is_ascii_hexdigit());
    looks_serial.then(|| {
        (0..digits.len())
            .step_by(2)
            .filter_map(|i| u8::from_str_radix(&digits[i..i + 2], 16).ok())
            .collect()
    })
}

/// A CAN frame in `protocol`.
fn decode_can(frame: &CanFrame, protocol: Protocol) -> Result<FrameMessage, LineError> {
    let id = frame.id();
    match protocol {
        Protocol::V1 => Ok(FrameMessage::V1(can::decode(frame)?)),
        Protocol::V2 => Ok(FrameMessage::V2(v2::decode(frame)?)),
        Protocol::Auto if MessageKind::from_can_id(id).is_some() => {
            Ok(FrameMessage::V1(can::decode(frame)?))
        }
        Protocol::Auto if v2::is_v2_id(id) => Ok(FrameMessage::V2(v2::decode(frame)?)),
        Protocol::Auto => Err(LineError::UnknownId(id)),
    }
}

/// Decodes one line: serial hex if it starts with `5A A5` (always protocol v1), else candump
/// text in any format, its frame in `protocol`.
pub fn decode_line(line: &str, protocol: Protocol) -> Result<Vec<DecodedFrame>, LineError> {
    if let Some(bytes) = serial_hex(line) {
        let mut decoder = StreamDecoder::new();
        let mut frames = Vec::new();
        for byte in bytes {
            match decoder.push(byte) {
                Pull::NeedMore => {}
                Pull::Frame(counted) => frames.push(DecodedFrame {
                    link: Link::Serial,
                    interface: None,
                    timestamp: None,
                    message: FrameMessage::V1(counted),
                }),
                Pull::Rejected(error) => return Err(error.into()),
            }
        }
        let unused = bytes_unused(line, &frames);
        if unused > 0 {
            return Err(LineError::SerialTrailing(unused));
        }
        return Ok(frames);
    }
    let record = candump::parse(line)?;
    let message = decode_can(&record.frame, protocol)?;
    Ok(vec![DecodedFrame {
        link: Link::Can,
        interface: record.interface.map(str::to_owned),
        timestamp: record
            .timestamp
            .map(|t| t.seconds as f64 + f64::from(t.micros) / 1_000_000.0),
        message,
    }])
}

fn bytes_unused(line: &str, frames: &[DecodedFrame]) -> usize {
    let digits = line.chars().filter(char::is_ascii_hexdigit).count();
    (digits / 2).saturating_sub(frames.len() * scout_protocol::serial::FRAME_LEN)
}

impl FrameMessage {
    /// The CAN id.
    pub fn can_id(&self) -> u16 {
        match self {
            Self::V1(counted) => counted.message.kind().can_id(),
            Self::V2(message) => message.can_id(),
        }
    }

    /// The message's name.
    pub fn name(&self) -> &'static str {
        match self {
            Self::V1(counted) => counted.message.kind().name(),
            Self::V2(message) => message.name(),
        }
    }

    /// The protocol's number.
    pub fn protocol(&self) -> u8 {
        match self {
            Self::V1(_) => 1,
            Self::V2(_) => 2,
        }
    }

    /// The rolling count, where the frame carries one (every v1 frame; v2's 0x121, 0x211,
    /// 0x231 and 0x241).
    pub fn count(&self) -> Option<u8> {
        match self {
            Self::V1(counted) => Some(counted.count),
            Self::V2(MessageV2::LightCommand(lights) | MessageV2::LightState(lights)) => {
                Some(lights.count)
            }
            Self::V2(MessageV2::SystemState(state)) => Some(state.count),
            Self::V2(MessageV2::RcState(rc)) => Some(rc.count),
            Self::V2(_) => None,
        }
    }

    /// The fields, in physical units.
    pub fn fields(&self, max_angular: f64) -> Value {
        match self {
            Self::V1(counted) => message_fields(&counted.message, max_angular),
            Self::V2(message) => message_fields_v2(message),
        }
    }
}

/// The JSON object of one frame: `id`, `name`, `protocol`, `count` (`null` for a v2 frame
/// without one), `link`, optional `interface` and `timestamp`, then the message's fields.
pub fn frame_json(frame: &DecodedFrame, max_angular: f64) -> Value {
    let message = &frame.message;
    let mut object = json!({
        "id": format!("0x{:03X}", message.can_id()),
        "name": message.name(),
        "protocol": message.protocol(),
        "count": message.count(),
        "link": frame.link.name(),
    });
    if let (Value::Object(object), Value::Object(fields)) =
        (&mut object, message.fields(max_angular))
    {
        if let Some(interface) = &frame.interface {
            object.insert("interface".into(), interface.clone().into());
        }
        if let Some(timestamp) = frame.timestamp {
            object.insert("timestamp".into(), timestamp.into());
        }
        object.extend(fields);
    }
    object
}

/// One human-readable line: `0x151 system_status count=228 state=estop ...` (a v2 frame's name
/// is marked `v2`, its count given where it has one).
pub fn frame_text(frame: &DecodedFrame, max_angular: f64) -> String {
    let message = &frame.message;
    let mut text = format!("0x{:03X} {}", message.can_id(), message.name());
    if message.protocol() == 2 {
        text.push_str(" v2");
    }
    if let Some(count) = message.count() {
        text.push_str(&format!(" count={count}"));
    }
    if let Value::Object(fields) = message.fields(max_angular) {
        for (key, value) in fields {
            text.push(' ');
            text.push_str(&key);
            text.push('=');
            text.push_str(&text_value(&value));
        }
    }
    text
}

fn text_value(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        Value::Number(n) => match n.as_f64() {
            Some(f) if !(n.is_i64() || n.is_u64()) => format!("{f:.3}"),
            _ => n.to_string(),
        },
        Value::Array(items) if items.is_empty() => "none".into(),
        Value::Array(items) => items.iter().map(text_value).collect::<Vec<_>>().join(","),
        Value::Object(fields) => fields
            .values()
            .map(text_value)
            .collect::<Vec<_>>()
            .join(":"),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_protocol::units::DEFAULT_MAX_ANGULAR_SPEED;

    #[test]
    fn status_json_has_the_documented_fields() {
        let frames = decode_line("  can1  151   [8]  01 00 00 EF 00 3C E4 6A", Protocol::Auto)
            .expect("valid");
        let json = frame_json(&frames[0], DEFAULT_MAX_ANGULAR_SPEED);
        assert_eq!(json["id"], "0x151");
        assert_eq!(json["name"], "system_status");
        assert_eq!(json["count"], 0xE4);
        assert_eq!(json["state"], "estop");
        assert_eq!(json["control_mode"], "rc");
        assert_eq!(json["battery_voltage"], 23.9);
        assert_eq!(json["fault_bits"], 0x3C);
        assert_eq!(
            json["faults"],
            json!([
                "motor_1_comm_fault",
                "motor_2_comm_fault",
                "motor_3_comm_fault",
                "motor_4_comm_fault"
            ])
        );
        assert_eq!(json["interface"], "can1");
    }

    #[test]
    fn command_json_is_in_physical_units() {
        let frames = decode_line("130#01000A0000000044", Protocol::Auto).expect("valid");
        let json = frame_json(&frames[0], DEFAULT_MAX_ANGULAR_SPEED);
        assert_eq!(json["control_mode"], "can");
        assert_eq!(json["fault_clear"], "none");
        assert_eq!(json["linear"], 0.15);
        assert_eq!(json["angular"], 0.0);
    }

    #[test]
    fn serial_hex_with_or_without_spaces() {
        for line in [
            "5A A5 0A 55 01 02 00 0A 00 00 00 00 6B",
            "5aa50a55010200 0a000000006b",
        ] {
            let frames = decode_line(line, Protocol::Auto).expect("valid");
            assert_eq!(frames.len(), 1);
            assert_eq!(frames[0].link, Link::Serial);
            assert_eq!(
                frame_json(&frames[0], DEFAULT_MAX_ANGULAR_SPEED)["control_mode"],
                "serial"
            );
        }
    }

    #[test]
    fn bad_lines_say_why() {
        assert_eq!(
            decode_line("130#01000A0000000045", Protocol::Auto)
                .expect_err("bad checksum")
                .to_string(),
            "CAN id 0x130: checksum 0x45, expected 0x44"
        );
        assert_eq!(
            decode_line("5A A5 0A 55 01 02 00 0A 00 00 00 00", Protocol::Auto)
                .expect_err("short")
                .to_string(),
            "12 trailing byte(s) are not a whole serial frame"
        );
        assert!(decode_line("hello world", Protocol::Auto).is_err());
        assert_eq!(
            decode_line("2F0#00", Protocol::Auto)
                .expect_err("neither")
                .to_string(),
            "unknown CAN id 0x2F0 (neither SCOUT v1 nor v2)"
        );
        assert_eq!(
            decode_line("211#00", Protocol::Auto)
                .expect_err("short")
                .to_string(),
            "CAN id 0x211: data length 1, expected 8"
        );
    }

    #[test]
    fn v2_frames_are_told_by_their_ids_or_forced() {
        // A Bunker Mini's 0x211 in e-stop before 0x421 (protocol-v2-notes 8, C1).
        let frames =
            decode_line("can0  211   [8]  01 00 01 00 00 80 00 00", Protocol::Auto).expect("valid");
        let json = frame_json(&frames[0], DEFAULT_MAX_ANGULAR_SPEED);
        assert_eq!(json["protocol"], 2);
        assert_eq!(json["name"], "system_state");
        assert_eq!(json["state"], "estop");
        assert_eq!(json["control_mode"], "standby");
        assert_eq!(json["battery_voltage"], 25.6);
        assert_eq!(json["errors"], json!([]));
        assert_eq!(json["unknown_error_bits"], 0x80);
        assert_eq!(json["count"], 0);
        assert_eq!(
            frame_text(&frames[0], DEFAULT_MAX_ANGULAR_SPEED),
            "0x211 system_state v2 count=0 state=estop control_mode=standby control_mode_raw=0 \
             battery_voltage=25.600 error_bits=128 errors=none unknown_error_bits=128 byte_6=0"
        );
        let motion = decode_line("111#0096000000000000", Protocol::Auto).expect("valid");
        let json = frame_json(&motion[0], DEFAULT_MAX_ANGULAR_SPEED);
        assert_eq!(
            (json["linear"].as_f64(), json["count"].is_null()),
            (Some(0.15), true)
        );
        // Forced: a v2 id read as v1 is an unknown id, and the other way round.
        assert!(decode_line("111#0096000000000000", Protocol::V1).is_err());
        assert!(decode_line("130#01000A0000000044", Protocol::V2).is_err());
        assert_eq!(
            frame_json(
                &decode_line("130#01000A0000000044", Protocol::V1).expect("v1")[0],
                DEFAULT_MAX_ANGULAR_SPEED
            )["protocol"],
            1
        );
    }

    #[test]
    fn text_line_reads_well() {
        let frames =
            decode_line("can1 141 [8] 00 00 00 02 0F 00 E2 3D", Protocol::Auto).expect("valid");
        assert_eq!(
            frame_text(&frames[0], DEFAULT_MAX_ANGULAR_SPEED),
            "0x141 light_feedback count=226 enabled=false front=off:0 rear=breath:15"
        );
    }
}
