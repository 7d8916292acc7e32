//! `scout decode`: one input line (candump text or serial hex) to decoded frames, as text or JSON.

use scout_protocol::serial::{Pull, StreamDecoder};
use scout_protocol::{Counted, can, candump};
use serde_json::{Value, json};

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
    /// The message and its rolling count.
    pub counted: Counted,
}

/// Why a line could not be decoded.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum LineError {
    /// Not a candump line.
    #[error("{0}")]
    Candump(#[from] candump::CandumpError),
    /// A CAN frame that is not a valid SCOUT v1 frame.
    #[error("{0}")]
    Can(#[from] can::CanError),
    /// Serial hex with a rejected frame.
    #[error("{0}")]
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

/// Decodes one line: serial hex if it starts with `5A A5`, else candump text in any format.
pub fn decode_line(line: &str) -> Result<Vec<DecodedFrame>, LineError> {
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
                    counted,
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
    let counted = can::decode(&record.frame)?;
    Ok(vec![DecodedFrame {
        link: Link::Can,
        interface: record.interface.map(str::to_owned),
        timestamp: record
            .timestamp
            .map(|t| t.seconds as f64 + f64::from(t.micros) / 1_000_000.0),
        counted,
    }])
}

fn bytes_unused(line: &str, frames: &[DecodedFrame]) -> usize {
    let digits = line.chars().filter(char::is_ascii_hexdigit).count();
    (digits / 2).saturating_sub(frames.len() * scout_protocol::serial::FRAME_LEN)
}

pub use scout_interface::json::message_fields;

/// The JSON object of one frame: `id`, `name`, `count`, `link`, optional `interface` and
/// `timestamp`, then the message's fields.
pub fn frame_json(frame: &DecodedFrame, max_angular: f64) -> Value {
    let message = &frame.counted.message;
    let mut object = json!({
        "id": format!("0x{:03X}", message.kind().can_id()),
        "name": message.kind().name(),
        "count": frame.counted.count,
        "link": frame.link.name(),
    });
    if let (Value::Object(object), Value::Object(fields)) =
        (&mut object, message_fields(message, max_angular))
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

/// One human-readable line: `0x151 system_status count=228 state=estop ...`.
pub fn frame_text(frame: &DecodedFrame, max_angular: f64) -> String {
    let message = &frame.counted.message;
    let mut text = format!(
        "0x{:03X} {} count={}",
        message.kind().can_id(),
        message.kind().name(),
        frame.counted.count
    );
    if let Value::Object(fields) = message_fields(message, max_angular) {
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
        let frames = decode_line("  can1  151   [8]  01 00 00 EF 00 3C E4 6A").expect("valid");
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
        let frames = decode_line("130#01000A0000000044").expect("valid");
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
            let frames = decode_line(line).expect("valid");
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
            decode_line("130#01000A0000000045")
                .expect_err("bad checksum")
                .to_string(),
            "CAN id 0x130: checksum 0x45, expected 0x44"
        );
        assert_eq!(
            decode_line("5A A5 0A 55 01 02 00 0A 00 00 00 00")
                .expect_err("short")
                .to_string(),
            "12 trailing byte(s) are not a whole serial frame"
        );
        assert!(decode_line("hello world").is_err());
    }

    #[test]
    fn text_line_reads_well() {
        let frames = decode_line("can1 141 [8] 00 00 00 02 0F 00 E2 3D").expect("valid");
        assert_eq!(
            frame_text(&frames[0], DEFAULT_MAX_ANGULAR_SPEED),
            "0x141 light_feedback count=226 enabled=false front=off:0 rear=breath:15"
        );
    }
}
