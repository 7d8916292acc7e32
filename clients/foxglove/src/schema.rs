//! The JSON schemas of the JSON channels (the state, the status, the command): what Foxglove
//! shows and completes in its message paths. They describe the schemas `scout echo --json` and
//! `scout status --json` print (the tables of docs/operating.md and docs/safety.md); tests walk real messages against them.

use serde_json::{Value, json};

fn number() -> Value {
    json!({ "type": "number" })
}

fn integer() -> Value {
    json!({ "type": "integer" })
}

fn string() -> Value {
    json!({ "type": "string" })
}

fn boolean() -> Value {
    json!({ "type": "boolean" })
}

fn object(properties: Value) -> Value {
    json!({ "type": "object", "properties": properties })
}

/// An object that is `null` until its first message.
fn nullable(properties: Value) -> Value {
    json!({ "type": ["object", "null"], "properties": properties })
}

fn light() -> Value {
    object(json!({ "mode": string(), "brightness": integer() }))
}

fn nullable_of(kind: &str) -> Value {
    json!({ "type": [kind, "null"] })
}

/// `scout.State`: the chassis state, the same keys in both protocols (`null` where a
/// protocol has no such field).
pub fn state() -> Value {
    let link = object(json!({
        "state": string(), "transport": string(), "device": string(),
        "protocol": nullable_of("string"),
        "rx_frames": integer(), "checksum_errors": integer(), "dropped_frames": integer(),
        "rejected_frames": integer(), "overflowed_frames": integer(),
        "discarded_bytes": integer(), "tx_frames": integer(), "reconnects": integer(),
    }));
    let chassis = object(json!({
        "model": nullable_of("string"), "max_linear": number(), "max_angular": number(),
        "max_lateral": number(), "track": number(), "wheel_radius": number(), "gear_ratio": number(),
    }));
    let system = nullable(json!({
        "state": string(), "control_mode": string(), "battery_voltage": number(),
        "fault_bits": integer(), "faults": { "type": "array", "items": string() },
        "unknown_fault_bits": integer(), "brake": nullable_of("string"), "age_ms": number(),
    }));
    let motion = nullable(json!({
        "linear": number(), "angular": number(), "lateral": number(), "steering": number(),
        "mode": nullable_of("string"), "mode_changing": boolean(),
        "wheel_angles": { "type": ["array", "null"], "items": number() },
        "wheel_speeds": { "type": ["array", "null"], "items": number() },
        "age_ms": number(),
    }));
    let motor = nullable(json!({
        "motor": integer(), "current": number(), "rpm": integer(),
        "driver_temperature": nullable_of("integer"), "motor_temperature": nullable_of("integer"),
        "pulses": nullable_of("integer"), "driver_voltage": nullable_of("number"),
        "driver_state": { "type": ["array", "null"], "items": string() },
        "driver_state_bits": nullable_of("integer"), "age_ms": number(),
    }));
    let lights = nullable(json!({
        "enabled": boolean(), "front": light(), "rear": light(), "age_ms": number(),
    }));
    let odometer = nullable(json!({ "left": number(), "right": number(), "age_ms": number() }));
    let rc = nullable(json!({
        "swa": string(), "swb": string(), "swc": string(), "swd": string(),
        "right_horizontal": integer(), "right_vertical": integer(), "left_vertical": integer(),
        "left_horizontal": integer(), "knob": integer(), "age_ms": number(),
    }));
    let bms = nullable(json!({
        "charge_percent": integer(), "health_percent": integer(), "voltage": number(),
        "current": number(), "temperature": number(),
        "alarms": { "type": ["array", "null"], "items": integer() }, "age_ms": number(),
    }));
    let battery = object(json!({
        "source": string(), "percent": nullable_of("number"), "status": string(),
        "level": string(), "level_from": string(), "voltage": nullable_of("number"),
        "current": nullable_of("number"),
        "health_percent": nullable_of("number"), "temperature": nullable_of("number"),
        "capacity_ah": nullable_of("number"), "low_percent": nullable_of("number"),
        "critical_percent": nullable_of("number"),
    }));
    let firmware = nullable(json!({ "text": string(), "age_ms": number() }));
    let odometry = object(json!({
        "x": number(), "y": number(), "yaw": number(), "distance": number(),
        "resets": integer(), "distance_scale": number(), "yaw_scale": number(),
        "rotation": number(),
    }));
    json!({
        "title": "scout.State",
        "description": "The chassis state, as `scout echo --json` prints it; ages relative to the message's log time",
        "type": "object",
        "properties": {
            "robot": string(), "seq": integer(), "age_ms": number(), "link": link,
            "chassis": chassis, "system": system, "motion": motion, "lights": lights,
            "motors": { "type": "array", "items": motor }, "odometer": odometer, "rc": rc,
            "bms": bms, "battery": battery, "firmware": firmware, "odometry": odometry, "command": command(),
        },
    })
}

/// `scout.Command`: a motion command as the gateway sent it.
pub fn command() -> Value {
    json!({
        "title": "scout.Command",
        "description": "A motion command as the gateway sent it (m/s, m/s leftward, rad/s)",
        "type": "object",
        "properties": { "linear": number(), "lateral": number(), "angular": number() },
    })
}

/// `scout.Status`: the arbiter's status.
pub fn status() -> Value {
    let stop = object(json!({
        "id": integer(), "owner": string(), "cause": string(), "reason": string(),
        "age_ms": number(), "persists": boolean(),
        "uid": { "type": ["integer", "null"] }, "by_operator": boolean(),
    }));
    let source = object(json!({
        "client": string(), "class": { "type": ["string", "null"] }, "holding": boolean(),
        "lease": { "type": ["integer", "null"] }, "heartbeat_ms": { "type": ["number", "null"] },
        "requests": integer(), "age_ms": number(), "uid": { "type": ["integer", "null"] },
    }));
    json!({
        "title": "scout.Status",
        "description": "The arbiter's status, as `scout status --json` prints it",
        "type": "object",
        "properties": {
            "robot": string(), "seq": integer(), "age_ms": number(), "latched": boolean(),
            "stop_total": integer(), "newest_stop": integer(),
            "stops": { "type": "array", "items": stop },
            "selected": nullable(json!({ "client": string(), "class": string() })),
            "output": object(json!({
                "linear": number(), "lateral": number(), "angular": number(),
                "fault_clear": string(), "limited": boolean(),
            })),
            "autonomy_armed": boolean(),
            "battery": object(json!({
                "level": string(), "percent": nullable_of("number"), "level_from": string(),
            })),
            "lights": string(),
            "sources": { "type": "array", "items": source },
            "rejections": { "type": "object", "additionalProperties": integer() },
            "tick": object(json!({
                "lateness_ms": number(), "max_lateness_ms": number(), "missed": integer(),
            })),
            "events": { "type": "array", "items": object(json!({
                "age_ms": number(), "event": string(),
            })) },
        },
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use scout_interface::FixedText;
    use scout_interface::control::{EventPayload, SourcePayload, StopPayload};
    use scout_interface::json::{state_json, status_json};
    use scout_interface::state::Received;
    use scout_interface::{StatePayload, StatusPayload};
    use scout_protocol::version::Protocol;

    fn type_matches(schema: &Value, value: &Value) -> bool {
        let names: Vec<&str> = match &schema["type"] {
            Value::String(name) => vec![name.as_str()],
            Value::Array(names) => names.iter().filter_map(Value::as_str).collect(),
            _ => return true,
        };
        names.iter().any(|name| match *name {
            "object" => value.is_object(),
            "array" => value.is_array(),
            "string" => value.is_string(),
            "boolean" => value.is_boolean(),
            "null" => value.is_null(),
            "integer" => value.is_u64() || value.is_i64(),
            "number" => value.is_number(),
            other => panic!("a type the walk does not know: {other}"),
        })
    }

    /// Every value in `value` is described by `schema`, with its type; returns the paths that
    /// are not.
    pub(crate) fn undescribed(schema: &Value, value: &Value, path: &str) -> Vec<String> {
        let mut wrong = Vec::new();
        if !type_matches(schema, value) {
            wrong.push(format!("{path}: {value} is not {}", schema["type"]));
            return wrong;
        }
        match value {
            Value::Object(fields) => {
                for (key, field) in fields {
                    let field_schema = schema["properties"]
                        .get(key)
                        .or_else(|| schema.get("additionalProperties"));
                    match field_schema {
                        Some(field_schema) => {
                            wrong.extend(undescribed(
                                field_schema,
                                field,
                                &format!("{path}.{key}"),
                            ));
                        }
                        None => wrong.push(format!("{path}.{key} is not in the schema")),
                    }
                }
            }
            Value::Array(items) => {
                for (index, item) in items.iter().enumerate() {
                    wrong.extend(undescribed(
                        &schema["items"],
                        item,
                        &format!("{path}[{index}]"),
                    ));
                }
            }
            Value::Null | Value::Bool(_) | Value::Number(_) | Value::String(_) => {}
        }
        wrong
    }

    /// A state with every message of `protocol` received.
    pub(crate) fn full_state_of(protocol: Protocol) -> StatePayload {
        let mut state = full_state();
        state.link.protocol = protocol.raw();
        if protocol == Protocol::V2 {
            let received = state.system.received;
            for motor in &mut state.motors {
                motor.driver_received = received;
            }
            state.odometer.received = received;
            state.rc.received = received;
            state.bms.received = received;
            state.bms.alarms_received = received;
            state.firmware.received = received;
        }
        state
    }

    /// A state with every message received.
    pub(crate) fn full_state() -> StatePayload {
        let received = Received {
            valid: true,
            count: 3,
            at_ns: 5_000_000,
        };
        let mut state = StatePayload {
            seq: 9,
            published_ns: 6_000_000,
            robot: FixedText::new("scout"),
            ..StatePayload::default()
        };
        state.system.received = received;
        state.system.fault_bits = 0x0101;
        state.motion.received = received;
        for motor in &mut state.motors {
            motor.received = received;
        }
        state.lights.received = received;
        state
    }

    #[test]
    fn the_state_schema_describes_every_field_of_a_full_and_an_empty_state() {
        let schema = state();
        for value in [
            state_json(&full_state(), 6_000_000),
            state_json(&full_state_of(Protocol::V1), 6_000_000),
            state_json(&full_state_of(Protocol::V2), 6_000_000),
            state_json(&StatePayload::default(), 0),
        ] {
            assert_eq!(undescribed(&schema, &value, "state"), Vec::<String>::new());
        }
    }

    #[test]
    fn the_status_schema_describes_every_field() {
        let mut status = StatusPayload {
            stop_total: 1,
            event_count: 1,
            source_count: 1,
            selected_class: 1,
            selected_client: FixedText::new("joy"),
            ..StatusPayload::default()
        };
        status.stops[0] = StopPayload {
            id: 1,
            owner: FixedText::new("safety"),
            ..StopPayload::default()
        };
        status.sources[0] = SourcePayload {
            client: FixedText::new("joy"),
            class: 1,
            lease: 3,
            heartbeat_ms: 500,
            ..SourcePayload::default()
        };
        status.events[0] = EventPayload {
            age_ms: 1.0,
            text: FixedText::new("stop 1 latched by safety"),
        };
        let schema = super::status();
        for value in [
            status_json(&status, 0),
            status_json(&StatusPayload::default(), 0),
        ] {
            assert_eq!(undescribed(&schema, &value, "status"), Vec::<String>::new());
        }
    }
}
