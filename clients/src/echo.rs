//! `scout echo`: the chassis state as a live terminal view, or one JSON object per update.

use std::io::Write;
use std::time::{Duration, Instant};

use serde_json::Value;

use scout_interface::failure::{Failure, FailureKind};

use scout_interface::StatePayload;
use scout_interface::json::state_json;
use scout_interface::services::monotonic_ns;

use iceoryx2::port::listener::ListenerWaitError;

use crate::client::{ClientError, StateSubscriber};

/// How often the live view redraws.
const REDRAW: Duration = Duration::from_millis(100);

/// Prints `count` updates (or forever, until `stop` returns true) as JSON lines; returns how
/// many were printed.
pub fn echo_json(
    subscriber: &StateSubscriber,
    count: Option<u64>,
    idle_timeout: Duration,
    stop: &dyn Fn() -> bool,
    out: &mut dyn Write,
) -> Result<u64, EchoError> {
    let mut printed = 0;
    while !stop() && count.is_none_or(|count| printed < count) {
        let Some(state) = next(subscriber, idle_timeout, stop)? else {
            break;
        };
        writeln!(out, "{}", state_json(&state, monotonic_ns()))?;
        out.flush()?;
        printed += 1;
    }
    Ok(printed)
}

/// Redraws the state in place on a terminal until `count` updates or `stop` returns true.
pub fn echo_live(
    subscriber: &StateSubscriber,
    count: Option<u64>,
    idle_timeout: Duration,
    stop: &dyn Fn() -> bool,
    out: &mut dyn Write,
) -> Result<u64, EchoError> {
    let mut seen = 0;
    let mut last_draw = Instant::now() - REDRAW;
    let mut latest = None;
    while !stop() && count.is_none_or(|count| seen < count) {
        let Some(state) = next(subscriber, idle_timeout, stop)? else {
            break;
        };
        latest = Some(state);
        seen += 1;
        if last_draw.elapsed() >= REDRAW {
            if let Some(state) = &latest {
                draw(state, out)?;
            }
            last_draw = Instant::now();
        }
    }
    if let Some(state) = &latest {
        draw(state, out)?;
    }
    Ok(seen)
}

/// Why echo stopped.
#[derive(Debug, thiserror::Error)]
pub enum EchoError {
    /// The gateway connection failed.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// No state arrived in time.
    #[error("no state from the gateway for {0:?}: is it stopped (SIGSTOP) or overloaded?")]
    Idle(Duration),
    /// Writing the output failed (a closed pipe is the reader's normal end, not an error).
    #[error("writing the output")]
    Io(#[source] std::io::Error),
}

/// A gateway fallen silent is as good as gone.
impl FailureKind for EchoError {
    fn kind(&self) -> Failure {
        match self {
            Self::Client(error) => error.kind(),
            Self::Idle(_) => Failure::NoGateway,
            Self::Io(_) => Failure::Failed,
        }
    }
}

impl From<std::io::Error> for EchoError {
    fn from(error: std::io::Error) -> Self {
        Self::Io(error)
    }
}

/// The next state, or `None` once `stop` says so: a signal (Ctrl-C) wakes the wait, and a
/// stop asked for is no error, even when the gateway fell silent meanwhile.
fn next(
    subscriber: &StateSubscriber,
    idle_timeout: Duration,
    stop: &dyn Fn() -> bool,
) -> Result<Option<StatePayload>, EchoError> {
    let deadline = Instant::now() + idle_timeout;
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match subscriber.next_timeout(left) {
            Ok(Some(state)) => return Ok(Some(state)),
            _ if stop() => return Ok(None),
            Ok(None) => return Err(EchoError::Idle(idle_timeout)),
            // Woken by a signal whose handler has not said stop (yet): wait on.
            Err(ClientError::Wait(ListenerWaitError::InterruptSignal)) => {}
            Err(error) => return Err(error.into()),
        }
    }
}

fn number(value: &Value, decimals: usize) -> String {
    value
        .as_f64()
        .map_or_else(|| "-".into(), |v| format!("{v:.decimals$}"))
}

fn draw(state: &StatePayload, out: &mut dyn Write) -> std::io::Result<()> {
    let json = state_json(state, monotonic_ns());
    let link = &json["link"];
    let system = &json["system"];
    let motion = &json["motion"];
    let odometry = &json["odometry"];
    let text = |v: &Value| v.as_str().unwrap_or("-").to_owned();
    let faults = system["faults"]
        .as_array()
        .map(|f| {
            f.iter()
                .filter_map(Value::as_str)
                .collect::<Vec<_>>()
                .join(", ")
        })
        .filter(|f| !f.is_empty())
        .unwrap_or_else(|| "none".into());
    // Clear the screen and go home, then draw.
    write!(out, "\x1b[2J\x1b[H")?;
    let chassis = &json["chassis"];
    writeln!(
        out,
        "robot {}   seq {}   {} on protocol {} ({} m/s, {} rad/s at most)",
        text(&json["robot"]),
        json["seq"],
        text(&chassis["model"]),
        text(&link["protocol"]),
        number(&chassis["max_linear"], 2),
        number(&chassis["max_angular"], 4),
    )?;
    writeln!(
        out,
        "link  {} ({} {})  rx {}  tx {}  checksum errors {}  dropped {}  rejected {}  overflowed {}  reconnects {}",
        text(&link["state"]),
        text(&link["transport"]),
        text(&link["device"]),
        link["rx_frames"],
        link["tx_frames"],
        link["checksum_errors"],
        link["dropped_frames"],
        link["rejected_frames"],
        link["overflowed_frames"],
        link["reconnects"],
    )?;
    writeln!(
        out,
        "chassis  {}  mode {}  battery {} V  faults: {faults}",
        text(&system["state"]),
        text(&system["control_mode"]),
        number(&system["battery_voltage"], 1),
    )?;
    let battery = &json["battery"];
    writeln!(
        out,
        "battery  {} %  {}  {} (from {})",
        number(&battery["percent"], 0),
        text(&battery["status"]),
        text(&battery["level"]),
        text(&battery["source"]),
    )?;
    writeln!(
        out,
        "motion   linear {} m/s  angular {} rad/s   (commanded {} m/s, {} rad/s)",
        number(&motion["linear"], 3),
        number(&motion["angular"], 3),
        number(&json["command"]["linear"], 3),
        number(&json["command"]["angular"], 3),
    )?;
    writeln!(out, "motor  current A    rpm   driver C  motor C")?;
    for motor in json["motors"].as_array().into_iter().flatten() {
        writeln!(
            out,
            "  {}    {:>8} {:>7} {:>9} {:>8}",
            motor["motor"],
            number(&motor["current"], 1),
            number(&motor["rpm"], 0),
            number(&motor["driver_temperature"], 0),
            number(&motor["motor_temperature"], 0),
        )?;
    }
    let lights = &json["lights"];
    let light = |l: &Value| format!("{} {}%", text(&l["mode"]), l["brightness"]);
    writeln!(
        out,
        "lights   {}  front {}  rear {}",
        if lights["enabled"].as_bool() == Some(true) {
            "host"
        } else {
            "chassis"
        },
        light(&lights["front"]),
        light(&lights["rear"]),
    )?;
    writeln!(
        out,
        "odometry x {} m  y {} m  yaw {} rad  distance {} m",
        number(&odometry["x"], 3),
        number(&odometry["y"], 3),
        number(&odometry["yaw"], 3),
        number(&odometry["distance"], 2),
    )?;
    // What only a protocol v2 chassis reports.
    let odometer = &json["odometer"];
    if !odometer.is_null() {
        writeln!(
            out,
            "odometer left {} m  right {} m",
            number(&odometer["left"], 3),
            number(&odometer["right"], 3),
        )?;
    }
    let rc = &json["rc"];
    if !rc.is_null() {
        writeln!(
            out,
            "rc       SWA {}  SWB {}  SWC {}  SWD {}",
            text(&rc["swa"]),
            text(&rc["swb"]),
            text(&rc["swc"]),
            text(&rc["swd"]),
        )?;
    }
    let bms = &json["bms"];
    if !bms.is_null() {
        writeln!(
            out,
            "bms      {}%  {} V  {} A  {} C",
            bms["charge_percent"],
            number(&bms["voltage"], 1),
            number(&bms["current"], 1),
            number(&bms["temperature"], 1),
        )?;
    }
    for form in ["versions", "text"] {
        if let Some(firmware) = json["firmware"][form].as_str() {
            writeln!(out, "firmware {firmware}")?;
        }
    }
    out.flush()
}
