//! Checks through a running gateway: its link state and counters, the chassis' state as it
//! publishes it, and the stops that hold the robot, without touching the port it owns.

use std::time::{Duration, Instant};

use scout_clients::client::{ClientError, Robot};
use scout_interface::json::status_json;
use scout_interface::services::{self, ServiceError};
use scout_interface::stop_socket::{Ask, StopClient};
use scout_interface::{LinkState, StatePayload};

use scout_protocol::ChassisState;
use scout_protocol::v2::{ControlModeV2, ErrorBitsV2, RcStateV2, SystemStateV2};
use scout_protocol::version::Protocol;

use crate::check::Check;
use crate::traffic::{chassis_checks, chassis_checks_v2};

/// The RC frame is sent only while the transmitter is on: an older one is stale.
const RC_FRESH: Duration = Duration::from_millis(500);

/// The chassis' own state as the gateway publishes it, read in its protocol.
fn chassis_state_checks(state: &StatePayload) -> Vec<Check> {
    let system = &state.system;
    match (state.protocol(), system.received.valid) {
        (Some(Protocol::V2), true) => {
            let system_v2 = SystemStateV2 {
                state: ChassisState::from_raw(system.state),
                control_mode: ControlModeV2::from_raw(system.control_mode),
                battery_decivolts: system.battery_decivolts,
                errors: ErrorBitsV2(system.fault_bits),
                reserved: 0,
                count: system.received.count,
            };
            let rc = &state.rc;
            let fresh = rc.received.valid
                && system.received.at_ns.saturating_sub(rc.received.at_ns)
                    <= RC_FRESH.as_nanos() as u64;
            let [swa, swb, swc, swd] = rc.switches();
            let [
                right_horizontal,
                right_vertical,
                left_vertical,
                left_horizontal,
                knob,
            ] = rc.sticks;
            let rc_v2 = fresh.then_some(RcStateV2 {
                swa,
                swb,
                swc,
                swd,
                right_horizontal,
                right_vertical,
                left_vertical,
                left_horizontal,
                knob,
                reserved: 0,
                count: rc.received.count,
            });
            chassis_checks_v2(&system_v2, rc_v2.as_ref())
        }
        (Some(Protocol::V1), true) => chassis_checks(Some(&system.status_v1())),
        (_, _) => chassis_checks(None),
    }
}

/// What the gateway of a robot said.
#[derive(Debug)]
pub struct GatewayReport {
    /// The checks.
    pub checks: Vec<Check>,
    /// The device it serves, as it names it.
    pub device: String,
}

/// Whether the error means no gateway of that name runs.
pub fn is_no_gateway(error: &ClientError) -> bool {
    matches!(error, ClientError::Service(ServiceError::NoGateway { .. }))
}

fn latest(
    subscriber: &scout_clients::client::StateSubscriber,
    limit: Duration,
) -> Result<Option<StatePayload>, ClientError> {
    let deadline = Instant::now() + limit;
    let mut newest = None;
    while Instant::now() < deadline {
        if let Some(state) = subscriber.next_timeout(Duration::from_millis(50))? {
            newest = Some(state);
            while let Some(state) = subscriber.try_next()? {
                newest = Some(state);
            }
            return Ok(newest);
        }
    }
    Ok(newest)
}

/// The pid of robot `robot`'s gateway, from a ping of its stop endpoint (which asks the arbiter
/// nothing).
fn gateway_pid(robot: &str) -> Option<u32> {
    let mut client = StopClient::new(robot, "scout-doctor").ok()?;
    let reply = client.request(Ask::Ping, Duration::from_millis(500)).ok()?;
    Some(reply.gateway_pid)
}

/// The checks of robot `robot`'s gateway over `window`; `Err` when it cannot be reached.
pub fn inspect(robot: &str, window: Duration) -> Result<GatewayReport, ClientError> {
    let connection = Robot::connect(robot)?;
    let subscriber = connection.subscribe()?;
    let status = connection.status()?;
    let mut checks = Vec::new();
    let Some(first) = latest(&subscriber, Duration::from_secs(1))? else {
        checks.push(Check::fail(
            "gateway",
            format!("the gateway of robot {robot} publishes no state"),
            "it is stopped (SIGSTOP) or stuck: see its log (`journalctl -u scout-gateway`), \
             restart it",
        ));
        return Ok(GatewayReport {
            checks,
            device: String::new(),
        });
    };
    let started = Instant::now();
    let mut last = first;
    while started.elapsed() < window {
        if let Some(state) = latest(&subscriber, window.saturating_sub(started.elapsed()))? {
            last = state;
        }
    }
    let elapsed = started.elapsed().as_secs_f64().max(1e-3);
    let link = &last.link;
    let transport = link.transport().map_or("unknown", |t| t.name());
    let device = link.device.as_str().to_owned();
    checks.push(Check::pass(
        "gateway",
        format!(
            "scout-gateway{} serves robot {robot} on {transport} {device}",
            gateway_pid(robot).map_or_else(String::new, |pid| format!(" (pid {pid})"))
        ),
    ));
    checks.push(match link.state() {
        LinkState::Ok => Check::pass("link", "ok: feedback arrives"),
        LinkState::Silent => Check::fail(
            "link",
            "silent: the gateway receives no feedback",
            "is the chassis on and wired? `scout doctor` with the port (after stopping the \
             gateway) listens to it directly",
        ),
        LinkState::Disconnected => Check::fail(
            "link",
            format!("disconnected: the gateway cannot use {device} and keeps reopening it"),
            "see the gateway's log for the reason (`journalctl -u scout-gateway`): a device \
             unplugged, a CAN interface down",
        ),
        LinkState::ProtocolMismatch => Check::fail(
            "link",
            "protocol mismatch: the chassis speaks another protocol than the gateway was started \
             with, or feedback of both protocols arrives",
            "start the gateway with --protocol auto (the default), or with the protocol its log \
             names; `scout status` shows the stop's reason",
        ),
    });
    let frames = link.rx_frames.saturating_sub(first.link.rx_frames);
    checks.push(if frames > 0 {
        Check::pass(
            "traffic",
            format!(
                "{frames} frames in {elapsed:.1} s ({:.0}/s)",
                frames as f64 / elapsed
            ),
        )
    } else {
        Check::fail(
            "traffic",
            format!("no frame in {elapsed:.1} s"),
            "the chassis sends nothing: power, wiring, bitrate (see link)",
        )
    });
    let grew = |now: u64, then: u64| now.saturating_sub(then);
    let errors = [
        (
            "checksum errors",
            grew(link.checksum_errors, first.link.checksum_errors),
        ),
        (
            "dropped",
            grew(link.dropped_frames, first.link.dropped_frames),
        ),
        (
            "rejected",
            grew(link.rejected_frames, first.link.rejected_frames),
        ),
        (
            "overflowed",
            grew(link.overflowed_frames, first.link.overflowed_frames),
        ),
    ];
    let bad: u64 = errors.iter().map(|(_, n)| n).sum();
    let described = errors
        .iter()
        .map(|(what, n)| format!("{n} {what}"))
        .collect::<Vec<_>>()
        .join(", ");
    checks.push(if bad == 0 {
        Check::pass("errors", format!("none in {elapsed:.1} s"))
    } else {
        Check::warn(
            "errors",
            format!("in {elapsed:.1} s: {described}"),
            "noise, another device, or a slow reader: check wiring and termination; \
             `scout status` and the gateway's log tell more",
        )
    });
    checks.extend(chassis_state_checks(&last));
    if let Some(payload) = status.latest(Duration::from_secs(1))? {
        let json = status_json(&payload, services::monotonic_ns());
        let stops = json["stops"].as_array().cloned().unwrap_or_default();
        checks.push(if stops.is_empty() {
            Check::pass("stops", "no stop holds the robot")
        } else {
            let described = stops
                .iter()
                .map(|stop| {
                    format!(
                        "#{} by {} ({}): {}{}",
                        stop["id"],
                        stop["owner"].as_str().unwrap_or("?"),
                        stop["cause"].as_str().unwrap_or("?"),
                        stop["reason"].as_str().unwrap_or(""),
                        if stop["persists"] == true {
                            " [its cause persists]"
                        } else {
                            ""
                        }
                    )
                })
                .collect::<Vec<_>>()
                .join("; ");
            Check::warn(
                "stops",
                format!("{} stop(s) hold the robot: {described}", stops.len()),
                "remove each cause, then `scout release` (nothing moves until a client takes \
                 control again)",
            )
        });
    }
    Ok(GatewayReport { checks, device })
}
