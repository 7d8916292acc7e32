//! Control requests on the wire to the arbiter's typed requests, and its answers and status back.

use std::time::Duration;

use scout_clients::ipc::{
    self, CLEAR_ALL_FAULTS, Class, ControlRequest, ControlResponse, FixedText, LightPayload,
    RequestKind, SourcePayload, StatusPayload,
};
use scout_protocol::{FaultClear, Light, LightCommand, LightMode};

use crate::arbiter::{Answer, Arbiter, ClientKey, LightsSetting, Rejection, Request};

/// What a valid request asks of the gateway.
#[derive(Debug, Clone, PartialEq)]
pub enum Action {
    /// A request for the arbiter.
    Arbiter(Request),
    /// Reset the odometry.
    ResetOdometry,
}

/// Who sent a request.
pub fn client_key(request: &ControlRequest) -> ClientKey {
    ClientKey {
        name: request.client.as_str().to_owned(),
        node: ipc::node_from_halves(request.node),
    }
}

/// Checks a request from the wire; the rejection says what is wrong.
pub fn decode(request: &ControlRequest) -> Result<Action, Rejection> {
    let kind =
        RequestKind::from_raw(request.kind).ok_or(Rejection::UnknownRequest(request.kind))?;
    Ok(Action::Arbiter(match kind {
        RequestKind::Drive => Request::Drive {
            class: Class::from_raw(request.class).ok_or(Rejection::UnknownClass(request.class))?,
            linear: request.linear,
            angular: request.angular,
            ttl: (request.ttl_ms > 0).then(|| Duration::from_millis(u64::from(request.ttl_ms))),
        },
        RequestKind::Stop => Request::Stop {
            reason: match request.reason.as_str() {
                "" => "no reason given".to_owned(),
                reason => reason.to_owned(),
            },
        },
        RequestKind::Release => Request::Release,
        RequestKind::Relinquish => Request::Relinquish,
        RequestKind::Resume => Request::Resume,
        RequestKind::Lights => Request::Lights(lights(&request.lights)?),
        RequestKind::ClearFault => Request::ClearFault(match request.fault_clear {
            CLEAR_ALL_FAULTS => FaultClear::ALL.to_vec(),
            raw => match FaultClear::from_raw(raw) {
                FaultClear::None | FaultClear::Unknown(_) => {
                    return Err(Rejection::Malformed(format!(
                        "fault-clear code {raw} is not 1..8"
                    )));
                }
                code => vec![code],
            },
        }),
        RequestKind::Heartbeat => Request::Heartbeat {
            period: Duration::from_millis(u64::from(request.heartbeat_ms)),
        },
        RequestKind::ResetOdometry => return Ok(Action::ResetOdometry),
    }))
}

fn lights(request: &ipc::LightsRequest) -> Result<LightsSetting, Rejection> {
    if request.auto {
        return Ok(LightsSetting::Auto);
    }
    let light = |which: &str, payload: LightPayload| match LightMode::from_raw(payload.mode) {
        LightMode::Unknown(raw) => Err(Rejection::Malformed(format!(
            "{which} light mode {raw} is not 0..3"
        ))),
        _ if payload.brightness > 100 => Err(Rejection::Malformed(format!(
            "{which} brightness {} is above 100",
            payload.brightness
        ))),
        mode => Ok(Light {
            mode,
            brightness: payload.brightness,
        }),
    };
    Ok(LightsSetting::Manual(LightCommand {
        enabled: true,
        front: light("front", request.front)?,
        rear: light("rear", request.rear)?,
    }))
}

/// The answer on the wire.
pub fn response(seq: u64, answer: &Answer) -> ControlResponse {
    match answer {
        Ok(accepted) => ControlResponse {
            seq,
            accepted: true,
            clamped: accepted.clamped,
            code: 0xFF,
            reason: FixedText::empty(),
        },
        Err(rejection) => ControlResponse {
            seq,
            accepted: false,
            clamped: false,
            code: rejection.code() as u8,
            reason: FixedText::new(&rejection.to_string()),
        },
    }
}

/// The arbiter's status at `now`, without the sequence number and publication time.
pub fn status(arbiter: &Arbiter, robot: &str, now: Duration) -> StatusPayload {
    let mut status = StatusPayload {
        robot: FixedText::new(robot),
        ..StatusPayload::default()
    };
    if let Some(latch) = arbiter.latch() {
        status.latched = true;
        status.latched_by = FixedText::new(&latch.by);
        status.latched_reason = FixedText::new(&latch.reason);
        status.latched_age_ms = millis(now.saturating_sub(latch.at));
    }
    if let Some((source, class)) = arbiter.selected(now) {
        status.selected_class = class as u8;
        status.selected_client = FixedText::new(&source.key.name);
    }
    let output = arbiter.output();
    status.output_linear = output.linear;
    status.output_angular = output.angular;
    status.output_fault_clear = output.fault_clear.raw();
    status.limited = output.limited;
    status.autonomy_armed = arbiter.autonomy_armed();
    status.lights = match arbiter.lights() {
        None => 0,
        Some(LightsSetting::Auto) => 1,
        Some(LightsSetting::Manual(_)) => 2,
    };
    let sources = arbiter.sources().iter().take(status.sources.len());
    for (slot, source) in status.sources.iter_mut().zip(sources) {
        *slot = SourcePayload {
            client: FixedText::new(&source.key.name),
            class: source.class().map_or(0, |class| class as u8),
            holding: source.holding.is_some(),
            heartbeat_ms: source.heartbeat().map_or(0, |p| p.as_millis() as u32),
            requests: source.requests,
            age_ms: millis(now.saturating_sub(source.last_seen)),
        };
        status.source_count += 1;
    }
    status.rejections = *arbiter.rejections();
    status
}

/// Whether two statuses differ in more than the passing of time.
pub fn changed(a: &StatusPayload, b: &StatusPayload) -> bool {
    let timeless = |s: &StatusPayload| {
        let mut s = *s;
        s.seq = 0;
        s.published_ns = 0;
        s.latched_age_ms = 0.0;
        for source in &mut s.sources {
            source.age_ms = 0.0;
            source.requests = 0;
        }
        s
    };
    timeless(a) != timeless(b)
}

fn millis(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1000.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(kind: u8) -> ControlRequest {
        ControlRequest {
            kind,
            client: FixedText::new("t"),
            ..ControlRequest::default()
        }
    }

    #[test]
    fn malformed_requests_are_rejected_with_the_reason() {
        assert_eq!(decode(&request(99)), Err(Rejection::UnknownRequest(99)));
        let drive = ControlRequest {
            class: 7,
            ..request(RequestKind::Drive as u8)
        };
        assert_eq!(decode(&drive), Err(Rejection::UnknownClass(7)));
        let clear = ControlRequest {
            fault_clear: 9,
            ..request(RequestKind::ClearFault as u8)
        };
        assert!(matches!(decode(&clear), Err(Rejection::Malformed(_))));
        let mut lights = request(RequestKind::Lights as u8);
        lights.lights.front = LightPayload {
            mode: 1,
            brightness: 101,
        };
        let Err(Rejection::Malformed(why)) = decode(&lights) else {
            panic!("bad brightness accepted")
        };
        assert_eq!(why, "front brightness 101 is above 100");
    }

    #[test]
    fn requests_decode_to_the_arbiter_requests() {
        let drive = ControlRequest {
            class: Class::Teleop as u8,
            linear: 0.5,
            ttl_ms: 100,
            ..request(RequestKind::Drive as u8)
        };
        assert_eq!(
            decode(&drive),
            Ok(Action::Arbiter(Request::Drive {
                class: Class::Teleop,
                linear: 0.5,
                angular: 0.0,
                ttl: Some(Duration::from_millis(100)),
            }))
        );
        let all = ControlRequest {
            fault_clear: CLEAR_ALL_FAULTS,
            ..request(RequestKind::ClearFault as u8)
        };
        assert_eq!(
            decode(&all),
            Ok(Action::Arbiter(Request::ClearFault(
                FaultClear::ALL.to_vec()
            )))
        );
        assert_eq!(
            decode(&request(RequestKind::ResetOdometry as u8)),
            Ok(Action::ResetOdometry)
        );
    }

    #[test]
    fn rejections_name_their_counter() {
        let answer: Answer = Err(Rejection::Held {
            class: Class::Teleop,
            holder: "joy".into(),
        });
        let wire = response(5, &answer);
        assert!(!wire.accepted);
        assert_eq!(ipc::REJECTION_NAMES[usize::from(wire.code)], "held");
        assert_eq!(wire.reason.as_str(), "teleop held by joy");
    }
}
