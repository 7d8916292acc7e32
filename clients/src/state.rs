//! The public JSON forms of the chassis state (`scout echo --json`) and of the arbiter's status
//! (`scout status --json`); zenoh carries the same.

use scout_protocol::{FaultClear, Message, Motor};
use serde_json::{Value, json};

use crate::decode::message_fields;
use crate::ipc::{
    Class, LinkState, REJECTION_NAMES, Received, StatePayload, StatusPayload, TransportKind,
};

fn age_ms(at_ns: u64, now_ns: u64) -> f64 {
    now_ns.saturating_sub(at_ns) as f64 / 1e6
}

/// The fields of a received message plus its `age_ms`, or `null` before the first one.
fn received_fields(received: Received, message: Message, max_angular: f64, now_ns: u64) -> Value {
    if !received.valid {
        return Value::Null;
    }
    let mut fields = message_fields(&message, max_angular);
    if let Value::Object(object) = &mut fields {
        object.insert("age_ms".into(), age_ms(received.at_ns, now_ns).into());
    }
    fields
}

/// The state as the README documents it. `now_ns` (CLOCK_MONOTONIC) sets the ages.
pub fn state_json(state: &StatePayload, now_ns: u64) -> Value {
    let link = &state.link;
    let max_angular = state.max_angular;
    let motors: Vec<Value> = Motor::ALL
        .into_iter()
        .map(|motor| {
            let payload = &state.motors[motor.index()];
            let message = Message::MotorFeedback(payload.feedback(motor));
            received_fields(payload.received, message, max_angular, now_ns)
        })
        .collect();
    json!({
        "robot": state.robot.as_str(),
        "seq": state.seq,
        "age_ms": age_ms(state.published_ns, now_ns),
        "link": {
            "state": LinkState::from_raw(link.state).name(),
            "transport": TransportKind::from_raw(link.transport).map_or("unknown", TransportKind::name),
            "device": link.device.as_str(),
            "rx_frames": link.rx_frames,
            "checksum_errors": link.checksum_errors,
            "dropped_frames": link.dropped_frames,
            "rejected_frames": link.rejected_frames,
            "discarded_bytes": link.discarded_bytes,
            "tx_frames": link.tx_frames,
            "reconnects": link.reconnects,
        },
        "system": received_fields(
            state.system.received,
            Message::SystemStatus(state.system.status()),
            max_angular,
            now_ns,
        ),
        "motion": received_fields(
            state.motion.received,
            Message::MotionFeedback(state.motion.feedback()),
            max_angular,
            now_ns,
        ),
        "motors": motors,
        "lights": received_fields(
            state.lights.received,
            Message::LightFeedback(state.lights.feedback()),
            max_angular,
            now_ns,
        ),
        "odometry": {
            "x": state.odometry.x,
            "y": state.odometry.y,
            "yaw": state.odometry.yaw,
            "distance": state.odometry.distance,
            "resets": state.odometry.resets,
        },
        "command": { "linear": state.command.linear, "angular": state.command.angular },
    })
}

fn class_name(raw: u8) -> Value {
    Class::from_raw(raw).map_or(Value::Null, |class| class.name().into())
}

/// The arbiter's status as the README documents it.
pub fn status_json(status: &StatusPayload, now_ns: u64) -> Value {
    let latched_by = if status.latched {
        json!({
            "client": status.latched_by.as_str(),
            "reason": status.latched_reason.as_str(),
            "age_ms": status.latched_age_ms,
        })
    } else {
        Value::Null
    };
    let selected = match Class::from_raw(status.selected_class) {
        Some(class) => json!({ "client": status.selected_client.as_str(), "class": class.name() }),
        None => Value::Null,
    };
    let sources: Vec<Value> = status.sources
        [..usize::from(status.source_count).min(status.sources.len())]
        .iter()
        .map(|source| {
            json!({
                "client": source.client.as_str(),
                "class": class_name(source.class),
                "holding": source.holding,
                "heartbeat_ms": (source.heartbeat_ms > 0).then_some(source.heartbeat_ms),
                "requests": source.requests,
                "age_ms": source.age_ms,
            })
        })
        .collect();
    let rejections: serde_json::Map<String, Value> = REJECTION_NAMES
        .iter()
        .zip(status.rejections)
        .map(|(name, count)| ((*name).to_owned(), count.into()))
        .collect();
    let lights = match status.lights {
        1 => "auto",
        2 => "manual",
        _ => "chassis",
    };
    json!({
        "robot": status.robot.as_str(),
        "seq": status.seq,
        "age_ms": age_ms(status.published_ns, now_ns),
        "latched": status.latched,
        "latched_by": latched_by,
        "selected": selected,
        "output": {
            "linear": status.output_linear,
            "angular": status.output_angular,
            "fault_clear": FaultClear::from_raw(status.output_fault_clear).name(),
            "limited": status.limited,
        },
        "autonomy_armed": status.autonomy_armed,
        "lights": lights,
        "sources": sources,
        "rejections": rejections,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ipc::{FixedText, SystemPayload};
    use scout_protocol::{ChassisState, ControlMode, FaultBits, SystemStatus};

    #[test]
    fn status_schema_has_the_documented_fields() {
        let status = StatusPayload {
            latched: true,
            latched_by: FixedText::new("safety"),
            selected_class: 0,
            autonomy_armed: false,
            ..StatusPayload::default()
        };
        let json = status_json(&status, 0);
        assert_eq!(json["latched"], true);
        assert_eq!(json["latched_by"]["client"], "safety");
        assert_eq!(json["selected"], Value::Null);
        assert_eq!(json["autonomy_armed"], false);
        assert_eq!(json["rejections"]["not_finite"], 0);
        let driving = StatusPayload {
            selected_class: Class::Teleop as u8,
            selected_client: FixedText::new("joy"),
            ..StatusPayload::default()
        };
        assert_eq!(
            status_json(&driving, 0)["selected"],
            json!({"client": "joy", "class": "teleop"})
        );
    }

    #[test]
    fn schema_has_the_documented_fields() {
        let mut state = StatePayload {
            seq: 7,
            robot: FixedText::new("scout"),
            ..Default::default()
        };
        state.system = SystemPayload::new(
            &SystemStatus {
                state: ChassisState::EStop,
                control_mode: ControlMode::Rc,
                battery_decivolts: 239,
                faults: FaultBits(0x3C),
            },
            Received {
                valid: true,
                count: 1,
                at_ns: 1_000_000,
            },
        );
        let json = state_json(&state, 3_000_000);
        assert_eq!(json["robot"], "scout");
        assert_eq!(json["seq"], 7);
        assert_eq!(json["link"]["state"], "ok");
        assert_eq!(json["link"]["transport"], "serial");
        assert_eq!(json["system"]["state"], "estop");
        assert_eq!(json["system"]["control_mode"], "rc");
        assert_eq!(json["system"]["battery_voltage"], 23.9);
        assert_eq!(json["system"]["fault_bits"], 0x3C);
        assert_eq!(json["system"]["faults"][0], "motor_1_comm_fault");
        assert_eq!(json["system"]["age_ms"], 2.0);
        assert_eq!(json["motion"], Value::Null, "not received yet");
        assert_eq!(json["motors"].as_array().map(Vec::len), Some(4));
        assert!(json["odometry"]["x"].is_number());
    }
}
