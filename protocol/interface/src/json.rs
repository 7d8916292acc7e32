//! The public JSON forms of the chassis state (`scout echo --json`, zenoh `scout/ROBOT/state`)
//! and of the arbiter's status (`scout status --json`, zenoh `scout/ROBOT/status`), and of one
//! decoded message (`scout decode --json`): the schemas the guides document (docs/operating.md,
//! docs/safety.md, docs/chassis.md), in one place.

use scout_protocol::units::MAX_LINEAR_SPEED;
use scout_protocol::v2::{LightsV2, MessageV2, MotionV2, VersionRequestForm};
use scout_protocol::version::Protocol;
use scout_protocol::{ChassisState, FaultClear, Light, Message};
use serde_json::{Map, Value, json};

use crate::control::{Class, LightsControl, RejectionKind, StatusPayload, StopCause, UNKNOWN_UID};
use crate::state::{BatteryLevel, LevelFrom, Received, StatePayload};

fn age_ms(at_ns: u64, now_ns: u64) -> f64 {
    now_ns.saturating_sub(at_ns) as f64 / 1e6
}

fn light_json(light: &Light) -> Value {
    json!({ "mode": light.mode.name(), "brightness": light.brightness })
}

/// The message's fields, named as docs/chassis.md documents them, in physical units.
pub fn message_fields(message: &Message, max_angular: f64) -> Value {
    match message {
        Message::MotionCommand(command) => json!({
            "control_mode": command.control_mode.name(),
            "fault_clear": command.fault_clear.name(),
            "linear": command.linear(MAX_LINEAR_SPEED),
            "angular": command.angular(max_angular),
            "linear_percent": command.linear_percent,
            "angular_percent": command.angular_percent,
        }),
        Message::LightCommand(lights) | Message::LightFeedback(lights) => json!({
            "enabled": lights.enabled,
            "front": light_json(&lights.front),
            "rear": light_json(&lights.rear),
        }),
        Message::SystemStatus(status) => json!({
            "state": status.state.name(),
            "control_mode": status.control_mode.name(),
            "battery_voltage": status.battery_voltage(),
            "fault_bits": status.faults.0,
            "faults": status.faults.iter().map(|f| f.name()).collect::<Vec<_>>(),
        }),
        Message::MotionFeedback(motion) => json!({
            "linear": motion.linear(),
            "angular": motion.angular(),
        }),
        Message::MotorFeedback(motor) => json!({
            "motor": motor.motor.number(),
            "current": motor.current(),
            "rpm": motor.rpm,
            "driver_temperature": motor.driver_temperature,
            "motor_temperature": motor.motor_temperature,
        }),
    }
}

/// A protocol v2 message's fields, in physical units (m/s, rad/s, V, A, m), every bit kept:
/// named bits as names, the rest as `unknown_*` numbers.
pub fn message_fields_v2(message: &MessageV2) -> Value {
    let lights = |l: &LightsV2| {
        json!({
            "host_control": l.host_control,
            "front": { "mode": l.front_mode.name(), "brightness": l.front_brightness },
            "rear": { "mode": l.rear_mode.name(), "brightness": l.rear_brightness },
        })
    };
    let motion = |m: &MotionV2| {
        json!({
            "linear": m.linear(),
            "angular": m.angular(),
            "lateral": m.lateral(),
            "steering": f64::from(m.steering_mrad) / 1000.0,
        })
    };
    let text = |bytes: &[u8; 8]| -> String {
        bytes
            .iter()
            .map(|&b| {
                if (32..=126).contains(&b) {
                    b as char
                } else {
                    ' '
                }
            })
            .collect()
    };
    let version = |v: u16| format!("{}.{}", v >> 8, v & 0xFF);
    match message {
        MessageV2::MotionCommand(m) | MessageV2::MotionState(m) => motion(m),
        MessageV2::LightCommand(l) | MessageV2::LightState(l) => lights(l),
        MessageV2::ControlMode(mode) => json!({ "control_mode": mode.name(), "raw": mode.raw() }),
        MessageV2::SetMotionMode(mode) => json!({ "motion_mode": mode.name(), "raw": mode.raw() }),
        MessageV2::Brake(brake) => json!({ "brake": brake.name(), "raw": brake.raw() }),
        MessageV2::MotionModeState(state) => json!({
            "motion_mode": state.mode.name(),
            "raw": state.mode.raw(),
            "changing": state.changing != 0,
        }),
        MessageV2::MotorAngles(wheels) => json!({ "steering": wheels.si() }),
        MessageV2::MotorSpeeds(wheels) => json!({ "speeds": wheels.si() }),
        MessageV2::ErrorClear(code) => json!({ "clear": code.name(), "raw": code.raw() }),
        MessageV2::VersionRequest(form) => json!({
            "form": match form {
                VersionRequestForm::Binary => "binary",
                VersionRequestForm::Text => "text",
            }
        }),
        MessageV2::SystemState(state) => json!({
            "state": state.state.name(),
            "control_mode": state.control_mode.name(),
            "control_mode_raw": state.control_mode.raw(),
            "battery_voltage": state.battery_voltage(),
            "error_bits": state.errors.0,
            "errors": state.errors.names().collect::<Vec<_>>(),
            "unknown_error_bits": state.errors.unknown(),
            // Reserved on a SCOUT; a Hunter's parking brake (0 released, 1 locked).
            "byte_6": state.reserved,
        }),
        MessageV2::RcState(rc) => json!({
            "swa": rc.swa.name(),
            "swb": rc.swb.name(),
            "swc": rc.swc.name(),
            "swd": rc.swd.name(),
            "right_horizontal": rc.right_horizontal,
            "right_vertical": rc.right_vertical,
            "left_vertical": rc.left_vertical,
            "left_horizontal": rc.left_horizontal,
            "knob": rc.knob,
        }),
        MessageV2::ActuatorHigh(a) => json!({
            "motor": a.motor,
            "rpm": a.rpm,
            "current": a.current(),
            "pulses": a.pulses,
        }),
        MessageV2::ActuatorLow(a) => json!({
            "motor": a.motor,
            "driver_voltage": a.driver_voltage(),
            "driver_temperature": a.driver_temperature,
            "motor_temperature": a.motor_temperature,
            "driver_state_bits": a.driver_state.0,
            "driver_state": a.driver_state.names().collect::<Vec<_>>(),
            "unknown_driver_state_bits": a.driver_state.unknown(),
        }),
        MessageV2::Odometer(o) => json!({
            "left": f64::from(o.left_mm) / 1000.0,
            "right": f64::from(o.right_mm) / 1000.0,
        }),
        MessageV2::Version(v) => json!({
            "controller_hardware": version(v.controller_hardware),
            "driver_hardware": version(v.driver_hardware),
            "controller_software": version(v.controller_software),
            "driver_software": version(v.driver_software),
        }),
        MessageV2::VersionText(bytes) => json!({ "text": text(bytes) }),
        MessageV2::Bms(b) => json!({
            "charge_percent": b.charge_percent,
            "health_percent": b.health_percent,
            "voltage": f64::from(b.decivolts) / 10.0,
            "current": f64::from(b.deciamps) / 10.0,
            "temperature": f64::from(b.decidegrees) / 10.0,
        }),
        MessageV2::BmsAlarm(bytes) => json!({ "bytes": bytes.to_vec() }),
    }
}

/// `age_ms` of a frame received at `received`, or `None` before the first one.
fn age(received: &Received, now_ns: u64) -> Option<f64> {
    received.valid.then(|| age_ms(received.at_ns, now_ns))
}

/// `fields` with their `age_ms`, or `null` before the first frame.
fn section(received: &Received, now_ns: u64, fields: impl FnOnce() -> Value) -> Value {
    let Some(age) = age(received, now_ns) else {
        return Value::Null;
    };
    let mut fields = fields();
    if let Value::Object(object) = &mut fields {
        object.insert("age_ms".into(), age.into());
    }
    fields
}

fn motor_json(state: &StatePayload, index: usize, now_ns: u64) -> Value {
    let motor = &state.motors[index];
    let v2 = state.protocol() == Some(Protocol::V2);
    let driver = motor.driver_received.valid;
    section(&motor.received, now_ns, || {
        let state_bits = motor.driver_state();
        json!({
            "motor": index + 1,
            "current": motor.current(),
            "rpm": motor.rpm,
            "driver_temperature": driver.then_some(motor.driver_temperature),
            "motor_temperature": driver.then_some(motor.motor_temperature),
            "pulses": v2.then_some(motor.pulses),
            "driver_voltage": (v2 && driver).then(|| f64::from(motor.driver_decivolts) / 10.0),
            "driver_state": (v2 && driver).then(|| state_bits.names().collect::<Vec<_>>()),
            "driver_state_bits": (v2 && driver).then_some(state_bits.0),
        })
    })
}

/// The state JSON's top-level keys, in the order docs/operating.md documents them.
pub const STATE_KEYS: [&str; 16] = [
    "robot", "seq", "age_ms", "link", "chassis", "system", "motion", "lights", "motors",
    "odometer", "rc", "bms", "battery", "firmware", "odometry", "command",
];

/// One top-level field of the state JSON ([`STATE_KEYS`]), or `None` for a key the schema does
/// not have. `now_ns` (CLOCK_BOOTTIME) sets the ages. A client that reads a few fields makes
/// only those; [`state_json`] is all of them. The same keys in both protocols: a field a
/// protocol does not have is `null`.
pub fn state_field(state: &StatePayload, key: &str, now_ns: u64) -> Option<Value> {
    Some(match key {
        "robot" => state.robot.as_str().into(),
        "seq" => state.seq.into(),
        "age_ms" => age_ms(state.published_ns, now_ns).into(),
        "link" => {
            let link = &state.link;
            json!({
                "state": link.state().name(),
                "transport": link.transport().map_or("unknown", |t| t.name()),
                "device": link.device.as_str(),
                "protocol": link.protocol().map(Protocol::name),
                "rx_frames": link.rx_frames,
                "checksum_errors": link.checksum_errors,
                "dropped_frames": link.dropped_frames,
                "rejected_frames": link.rejected_frames,
                "overflowed_frames": link.overflowed_frames,
                "discarded_bytes": link.discarded_bytes,
                "tx_frames": link.tx_frames,
                "reconnects": link.reconnects,
            })
        }
        "chassis" => {
            let chassis = &state.chassis;
            json!({
                "model": chassis.model().map(|model| model.name()),
                "max_linear": chassis.max_linear,
                "max_angular": chassis.max_angular,
                "max_lateral": chassis.max_lateral,
                "track": chassis.track,
                "wheel_radius": chassis.wheel_radius,
                "gear_ratio": chassis.gear_ratio,
            })
        }
        "system" => {
            let system = &state.system;
            section(&system.received, now_ns, || {
                json!({
                    "state": ChassisState::from_raw(system.state).name(),
                    "control_mode": state.control_mode_name().unwrap_or("unknown"),
                    "battery_voltage": system.battery_voltage(),
                    "fault_bits": system.fault_bits,
                    "faults": state.faults().iter().map(|f| f.name).collect::<Vec<_>>(),
                    "unknown_fault_bits": state.unknown_fault_bits(),
                    // A Hunter's parking brake (0x211 byte 6); null on a model without one.
                    "brake": state
                        .chassis
                        .model()
                        .filter(|model| model.parking_brake())
                        .map(|_| system.brake().name()),
                })
            })
        }
        "motion" => {
            let motion = &state.motion;
            section(&motion.received, now_ns, || {
                json!({
                    "linear": motion.linear(),
                    "angular": motion.angular(),
                    "lateral": motion.lateral(),
                    "steering": motion.steering(),
                    "mode": motion.mode().map(|(mode, _)| mode.name()),
                    "mode_changing": motion.mode().is_some_and(|(_, changing)| changing),
                    "wheel_angles": motion.wheel_angles(),
                    "wheel_speeds": motion.wheel_speeds(),
                })
            })
        }
        "lights" => {
            let lights = &state.lights;
            section(&lights.received, now_ns, || {
                let lights = lights.feedback();
                json!({
                    "enabled": lights.enabled,
                    "front": light_json(&lights.front),
                    "rear": light_json(&lights.rear),
                })
            })
        }
        "motors" => (0..state.motors.len())
            .map(|index| motor_json(state, index, now_ns))
            .collect::<Vec<_>>()
            .into(),
        "odometer" => {
            let odometer = &state.odometer;
            section(&odometer.received, now_ns, || {
                json!({
                    "left": f64::from(odometer.left_mm) / 1000.0,
                    "right": f64::from(odometer.right_mm) / 1000.0,
                })
            })
        }
        "rc" => {
            let rc = &state.rc;
            section(&rc.received, now_ns, || {
                let [swa, swb, swc, swd] = rc.switches();
                let [
                    right_horizontal,
                    right_vertical,
                    left_vertical,
                    left_horizontal,
                    knob,
                ] = rc.sticks;
                json!({
                    "swa": swa.name(),
                    "swb": swb.name(),
                    "swc": swc.name(),
                    "swd": swd.name(),
                    "right_horizontal": right_horizontal,
                    "right_vertical": right_vertical,
                    "left_vertical": left_vertical,
                    "left_horizontal": left_horizontal,
                    "knob": knob,
                })
            })
        }
        "bms" => {
            let bms = &state.bms;
            section(&bms.received, now_ns, || {
                json!({
                    "charge_percent": bms.charge_percent,
                    "health_percent": bms.health_percent,
                    "voltage": f64::from(bms.decivolts) / 10.0,
                    "current": f64::from(bms.deciamps) / 10.0,
                    "temperature": f64::from(bms.decidegrees) / 10.0,
                    "alarms": bms.alarms_received.valid.then(|| bms.alarms.to_vec()),
                })
            })
        }
        "battery" => {
            let battery = &state.battery;
            let known = |value: f64| value.is_finite().then_some(value);
            json!({
                "source": battery.source().name(),
                "percent": battery.percent(),
                "status": battery.status().name(),
                "level": battery.level().name(),
                "level_from": battery.level_from().name(),
                "voltage": known(battery.voltage),
                "current": known(battery.current),
                "health_percent": known(battery.health_percent),
                "temperature": known(battery.temperature),
                "capacity_ah": known(battery.capacity_ah),
                "low_percent": known(battery.low_percent),
                "critical_percent": known(battery.critical_percent),
            })
        }
        "firmware" => {
            let firmware = &state.firmware;
            section(
                &firmware.received,
                now_ns,
                || json!({ "text": firmware.text.as_str().trim_end() }),
            )
        }
        "odometry" => json!({
            "x": state.odometry.x,
            "y": state.odometry.y,
            "yaw": state.odometry.yaw,
            "distance": state.odometry.distance,
            "rotation": state.odometry.rotation,
            "resets": state.odometry.resets,
            "distance_scale": state.odometry.distance_scale,
            "yaw_scale": state.odometry.yaw_scale,
        }),
        "command" => json!({
            "linear": state.command.linear,
            "lateral": state.command.lateral,
            "angular": state.command.angular,
        }),
        _ => return None,
    })
}

/// The state as docs/operating.md documents it. `now_ns` (CLOCK_BOOTTIME) sets the ages.
pub fn state_json(state: &StatePayload, now_ns: u64) -> Value {
    let fields: Map<String, Value> = STATE_KEYS
        .iter()
        .filter_map(|key| Some(((*key).to_owned(), state_field(state, key, now_ns)?)))
        .collect();
    Value::Object(fields)
}

fn class_name(raw: u8) -> Value {
    Class::from_raw(raw).map_or(Value::Null, |class| class.name().into())
}

/// The arbiter's status as docs/safety.md documents it.
pub fn status_json(status: &StatusPayload, now_ns: u64) -> Value {
    let stops: Vec<Value> = status
        .stops()
        .iter()
        .map(|stop| {
            json!({
                "id": stop.id,
                "owner": stop.owner.as_str(),
                "cause": StopCause::from_raw(stop.cause).map_or("unknown", StopCause::name),
                "reason": stop.reason.as_str(),
                "age_ms": stop.age_ms,
                "persists": stop.persists,
                "uid": (stop.uid != UNKNOWN_UID).then_some(stop.uid),
                "by_operator": stop.by_operator,
            })
        })
        .collect();
    let events: Vec<Value> = status
        .events()
        .iter()
        .map(|event| json!({ "age_ms": event.age_ms, "event": event.text.as_str() }))
        .collect();
    let selected = match Class::from_raw(status.selected_class) {
        Some(class) => json!({ "client": status.selected_client.as_str(), "class": class.name() }),
        None => Value::Null,
    };
    let sources: Vec<Value> = status
        .sources()
        .iter()
        .map(|source| {
            json!({
                "client": source.client.as_str(),
                "class": class_name(source.class),
                "holding": source.holding,
                "lease": (source.lease != 0).then_some(source.lease),
                "heartbeat_ms": (source.heartbeat_ms > 0).then_some(source.heartbeat_ms),
                "requests": source.requests,
                "age_ms": source.age_ms,
                "uid": (source.uid != UNKNOWN_UID).then_some(source.uid),
            })
        })
        .collect();
    let rejections: Map<String, Value> = RejectionKind::ALL
        .iter()
        .map(|kind| {
            let count = status.rejections[usize::from(kind.raw())];
            (kind.name().to_owned(), count.into())
        })
        .collect();
    let lights = LightsControl::from_raw(status.lights).unwrap_or(LightsControl::Chassis);
    json!({
        "robot": status.robot.as_str(),
        "seq": status.seq,
        "age_ms": age_ms(status.published_ns, now_ns),
        "latched": status.stopped(),
        "stop_total": status.stop_total,
        "newest_stop": status.newest_stop,
        "stops": stops,
        "selected": selected,
        "output": {
            "linear": status.output_linear,
            "lateral": status.output_lateral,
            "angular": status.output_angular,
            "fault_clear": FaultClear::from_raw(status.output_fault_clear).name(),
            "limited": status.limited,
        },
        "autonomy_armed": status.autonomy_armed,
        "battery": {
            "level": BatteryLevel::from_raw(status.battery_level)
                .unwrap_or(BatteryLevel::Unknown)
                .name(),
            "percent": status.battery_percent.is_finite().then_some(status.battery_percent),
            "level_from": LevelFrom::from_raw(status.battery_level_from)
                .unwrap_or(LevelFrom::None)
                .name(),
        },
        "lights": lights.name(),
        "sources": sources,
        "rejections": rejections,
        "tick": {
            "lateness_ms": status.tick_lateness_ms,
            "max_lateness_ms": status.tick_max_lateness_ms,
            "missed": status.ticks_missed,
        },
        "events": events,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::text::FixedText;
    use scout_protocol::model::Model;
    use scout_protocol::{ChassisState, ControlMode, FaultBits, SystemStatus};

    #[test]
    fn status_schema_has_the_documented_fields() {
        let mut status = StatusPayload {
            stop_total: 1,
            selected_class: 0,
            autonomy_armed: false,
            ..StatusPayload::default()
        };
        status.stops[0].owner = FixedText::new("safety");
        status.stops[0].cause = StopCause::ChassisEstop.raw();
        let json = status_json(&status, 0);
        assert_eq!(json["latched"], true);
        assert_eq!(json["stops"][0]["owner"], "safety");
        assert_eq!(json["stops"][0]["cause"], "chassis_estop");
        assert_eq!(json["selected"], Value::Null);
        assert_eq!(json["autonomy_armed"], false);
        assert_eq!(json["lights"], "chassis");
        assert_eq!(json["rejections"]["not_finite"], 0);
        assert_eq!(
            json["rejections"].as_object().map(Map::len),
            Some(crate::control::REJECTION_COUNTERS)
        );
        let driving = StatusPayload {
            selected_class: Class::Teleop.raw(),
            selected_client: FixedText::new("joy"),
            ..StatusPayload::default()
        };
        assert_eq!(
            status_json(&driving, 0)["selected"],
            json!({"client": "joy", "class": "teleop"})
        );
    }

    #[test]
    fn state_schema_has_the_documented_fields() {
        let mut state = StatePayload {
            seq: 7,
            robot: FixedText::new("scout"),
            ..Default::default()
        };
        state.link.protocol = Protocol::V1.raw();
        state.store(
            &Message::SystemStatus(SystemStatus {
                state: ChassisState::EStop,
                control_mode: ControlMode::Rc,
                battery_decivolts: 239,
                faults: FaultBits(0x3C),
            }),
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
        assert_eq!(json["lights"], Value::Null, "not received yet");
        assert_eq!(json["motors"].as_array().map(Vec::len), Some(4));
        assert!(json["odometry"]["x"].is_number());
        assert!(json["command"]["linear"].is_number());
        assert_eq!(json["link"]["protocol"], "v1");
        for key in ["odometer", "rc", "bms", "firmware"] {
            assert_eq!(json[key], Value::Null, "{key}: v2 only");
        }
        let keys: Vec<&str> = json
            .as_object()
            .expect("object")
            .keys()
            .map(String::as_str)
            .collect();
        assert_eq!(keys, STATE_KEYS);
    }

    /// The v2 message of a frame of `id` carrying `data`.
    fn frame(id: u16, data: [u8; 8]) -> MessageV2 {
        scout_protocol::v2::decode(&scout_protocol::CanFrame::new(id, &data).expect("frame"))
            .expect("v2")
    }

    #[test]
    fn a_v2_state_has_the_same_keys_and_its_own_values() {
        let mut state = StatePayload::default();
        state.link.protocol = Protocol::V2.raw();
        let received = Received {
            valid: true,
            count: 0,
            at_ns: 1_000_000,
        };
        state.store_v2(&frame(0x211, [0, 3, 1, 3, 0x02, 0x81, 0, 7]), received);
        state.store_v2(&frame(0x221, [0, 0x96, 0xFF, 0xCE, 0, 0, 0, 0]), received);
        state.store_v2(&frame(0x251, [0, 100, 0, 15, 0, 0, 1, 0]), received);
        state.store_v2(
            &frame(0x311, [0, 0, 3, 0xE8, 0xFF, 0xFF, 0xFC, 0x18]),
            received,
        );
        let json = state_json(&state, 2_000_000);
        assert_eq!(json["link"]["protocol"], "v2");
        assert_eq!(json["system"]["control_mode"], "rc");
        assert_eq!(json["system"]["battery_voltage"], 25.9);
        assert_eq!(
            json["system"]["faults"],
            json!(["battery_undervoltage_fault", "unknown_bit_7", "host_comm"])
        );
        assert_eq!(json["system"]["unknown_fault_bits"], 0x80);
        assert_eq!(json["motion"]["linear"], 0.15);
        assert_eq!(json["motion"]["angular"], -0.05);
        assert_eq!(json["motors"][0]["rpm"], 100);
        assert_eq!(json["motors"][0]["pulses"], 256);
        assert_eq!(
            json["motors"][0]["driver_temperature"],
            Value::Null,
            "no 0x261 yet"
        );
        assert_eq!(json["motors"][1], Value::Null);
        assert_eq!(json["odometer"]["left"], 1.0);
        assert_eq!(json["odometer"]["right"], -1.0);
        assert_eq!(json["odometer"]["age_ms"], 1.0);
        let keys: Vec<&str> = json
            .as_object()
            .expect("object")
            .keys()
            .map(String::as_str)
            .collect();
        assert_eq!(keys, STATE_KEYS);
        // Not a Ranger, not a Hunter: no wheels, no brake.
        assert_eq!(json["motion"]["wheel_angles"], Value::Null);
        assert_eq!(json["system"]["brake"], Value::Null);
    }

    #[test]
    fn a_rangers_wheels_and_a_hunters_brake_are_in_the_state() {
        let received = Received {
            valid: true,
            count: 0,
            at_ns: 1_000_000,
        };
        let mut ranger = StatePayload {
            chassis: crate::state::ChassisPayload::new(Model::RangerMini3, 4.8),
            ..StatePayload::default()
        };
        ranger.store_v2(&frame(0x221, [0; 8]), received);
        ranger.store_v2(
            &frame(0x271, [0x01, 0xF4, 0xFE, 0x0C, 0, 0, 0, 0]),
            received,
        );
        let json = state_json(&ranger, 2_000_000);
        assert_eq!(json["motion"]["wheel_angles"], json!([0.5, -0.5, 0.0, 0.0]));
        assert_eq!(json["motion"]["wheel_speeds"], Value::Null, "no 0x281 yet");
        ranger.store_v2(&frame(0x281, [0x01, 0xF4, 0, 0, 0, 0, 0, 0]), received);
        let json = state_json(&ranger, 2_000_000);
        assert_eq!(json["motion"]["wheel_speeds"], json!([0.5, 0.0, 0.0, 0.0]));
        assert_eq!(json["system"], Value::Null);
        let mut hunter = StatePayload {
            chassis: crate::state::ChassisPayload::new(Model::Hunter2, 1.146),
            ..StatePayload::default()
        };
        hunter.store_v2(&frame(0x211, [0, 1, 0x00, 0xFA, 0, 0, 1, 7]), received);
        assert_eq!(state_json(&hunter, 2_000_000)["system"]["brake"], "locked");
        hunter.store_v2(&frame(0x211, [0, 1, 0x00, 0xFA, 0, 0, 0, 8]), received);
        assert_eq!(
            state_json(&hunter, 2_000_000)["system"]["brake"],
            "released"
        );
    }
}
