//! `scout status`: the arbiter's status, as text or as one JSON object (the schema in docs/safety.md).
//!
//! The text is rendered from the very JSON object `--json` prints, so the two cannot disagree,
//! and the rendering tolerates any JSON: missing fields show as `?`, unknown ones are ignored.

use std::process::ExitCode;
use std::time::Duration;

use clap::Args;
use scout_clients::client::Robot;
use scout_clients::failure::{Failure, FailureKind};
use scout_clients::interface::json::status_json;
use scout_clients::interface::state::LevelFrom;
use scout_clients::monotonic_ns;
use serde_json::Value;

use scout_clients::remote::{ANSWER_TIMEOUT, RemoteStates, SessionSettings};

use crate::echo::RemoteSilent;
use crate::{RemoteArgs, RobotArgs};

/// The gateway publishes no status.
#[derive(Debug, thiserror::Error)]
#[error("gateway '{0}' published no status within 2 s: is it running (not stopped)?")]
pub struct Silent(pub String);

#[derive(Debug, Args)]
pub struct StatusArgs {
    #[command(flatten)]
    robot: RobotArgs,
    /// The status as one JSON object (the schema in docs/safety.md).
    #[arg(long)]
    json: bool,
    // With --remote, the status also lists each remote peer's link quality (`links`).
    #[command(flatten)]
    remote: RemoteArgs,
}

/// How long `--remote` waits for the status (the gateway publishes it each second).
const REMOTE_WAIT: Duration = Duration::from_secs(3);

pub fn run(args: &StatusArgs) -> anyhow::Result<ExitCode> {
    let json = match (args.remote.settings(), &args.remote.remote) {
        (Some(settings), Some(endpoint)) => remote(&args.robot.name, &settings, endpoint)?,
        _ => {
            let robot = Robot::connect(&args.robot.name)?;
            let status = robot
                .status()?
                .latest(Duration::from_secs(2))?
                .ok_or_else(|| Silent(args.robot.name.clone()))?;
            status_json(&status, monotonic_ns())
        }
    };
    if args.json {
        println!("{json}");
    } else {
        print!("{}", render(&json));
    }
    Ok(ExitCode::SUCCESS)
}

/// `--remote`: the status through zenoh, with the remote peers' link quality (`links`) from the
/// gateway's information query.
fn remote(robot: &str, settings: &SessionSettings, endpoint: &str) -> anyhow::Result<Value> {
    let reader = RemoteStates::connect_status(settings, robot)?;
    let silent = || RemoteSilent {
        what: "status",
        robot: robot.to_owned(),
        endpoint: endpoint.to_owned(),
        timeout: REMOTE_WAIT,
    };
    let mut json = reader.next_timeout(REMOTE_WAIT)?.ok_or_else(silent)?;
    let info = reader.info(robot, ANSWER_TIMEOUT)?.ok_or_else(|| {
        anyhow::anyhow!(
            "robot '{robot}' published its status through {endpoint} but did not answer \
             scout/{robot}/info within {ANSWER_TIMEOUT:?}: does the access control allow \
             querying it?"
        )
    })?;
    json["links"] = info["links"].clone();
    Ok(json)
}

/// How many of the latest events the text shows (the status keeps 16).
const EVENTS_SHOWN: usize = 5;

/// The status for people, one `label    text` line each, from the JSON object of `--json`.
/// `low: 18 %, charge soon` (nothing before a gateway that reports the battery).
fn battery(battery: &Value) -> Option<String> {
    let level = battery["level"].as_str()?;
    let mut charge = battery["percent"]
        .as_f64()
        .map_or_else(|| "charge unknown".to_owned(), |p| format!("{p:.0} %"));
    // The level is the chassis' own when its under-voltage bits set it: said, so that a
    // critical battery at 35 % is no riddle.
    if let Some(why) = battery["level_from"]
        .as_str()
        .and_then(|from| from.parse::<LevelFrom>().ok())
        .map(LevelFrom::words)
        .filter(|why| !why.is_empty())
    {
        charge = format!("{charge} ({why})");
    }
    Some(match level {
        "low" => format!("LOW: {charge}, charge soon"),
        "critical" => format!(
            "CRITICAL: {charge}, charge now (what the gateway does: docs/chassis.md, Battery)"
        ),
        "unknown" => "not reported yet".to_owned(),
        _ => format!("{level}: {charge}"),
    })
}

fn render(json: &Value) -> String {
    let mut lines = Lines::default();
    lines.push("robot", text(&json["robot"]));
    let stops: &[Value] = json["stops"].as_array().map_or(&[], Vec::as_slice);
    let listed = stops.len();
    let total = json["stop_total"]
        .as_u64()
        .map_or(listed, |total| usize::try_from(total).unwrap_or(usize::MAX))
        .max(listed);
    let latched = json["latched"].as_bool().unwrap_or(total > 0);
    if latched {
        lines.push("latched", format!("YES: {total} stop(s)"));
    } else {
        lines.push("latched", "no".into());
    }
    for stop in stops {
        lines.push("stop", stop_line(stop));
    }
    if total > listed {
        let more = total - listed;
        lines.push(
            "stop",
            format!("... and {more} more stop(s) not listed (the status lists the first {listed})"),
        );
    }
    if latched {
        lines.push("what to do", what_to_do(stops, total > listed));
    }
    lines.push("driving", driving(&json["selected"]));
    lines.push("output", output(&json["output"]));
    let autonomy = match json["autonomy_armed"].as_bool() {
        Some(true) => "armed".into(),
        Some(false) => "disarmed: `scout resume` arms it".into(),
        None => "?".into(),
    };
    lines.push("autonomy", autonomy);
    if let Some(battery) = battery(&json["battery"]) {
        lines.push("battery", battery);
    }
    if !json["lights"].is_null() {
        lines.push("lights", text(&json["lights"]));
    }
    lines.push("tick", tick(&json["tick"]));
    let sources: &[Value] = json["sources"].as_array().map_or(&[], Vec::as_slice);
    if sources.is_empty() {
        lines.push("clients", "none".into());
    }
    for source in sources {
        lines.push("client", source_line(source));
    }
    for link in json["links"].as_array().map_or(&[][..], Vec::as_slice) {
        lines.push("link", link_line(link));
    }
    lines.push("rejected", rejections(&json["rejections"]));
    let events: &[Value] = json["events"].as_array().map_or(&[], Vec::as_slice);
    for event in &events[events.len().saturating_sub(EVENTS_SHOWN)..] {
        lines.push(
            "event",
            format!(
                "{} ago  {}",
                seconds(&event["age_ms"]),
                text(&event["event"])
            ),
        );
    }
    lines.0
}

/// The rendered text, one labelled line at a time.
#[derive(Debug, Default)]
struct Lines(String);

impl Lines {
    fn push(&mut self, label: &str, text: String) {
        self.0.push_str(&format!("{label:<9} {text}\n"));
    }
}

/// A text field for a terminal: control characters (a client's name or reason could hold an
/// escape sequence) are shown escaped; a missing field is `?`.
fn text(value: &Value) -> String {
    match value {
        Value::String(text) => clean(text),
        Value::Null => "?".into(),
        other => clean(&other.to_string()),
    }
}

fn clean(text: &str) -> String {
    text.chars()
        .map(|c| {
            if c.is_control() {
                c.escape_default().to_string()
            } else {
                c.to_string()
            }
        })
        .collect()
}

/// A duration in ms as seconds: `12.3 s`.
fn seconds(ms: &Value) -> String {
    ms.as_f64()
        .map_or_else(|| "? s".into(), |ms| format!("{:.1} s", ms / 1000.0))
}

fn stop_line(stop: &Value) -> String {
    let id = match &stop["id"] {
        Value::Number(id) => format!("#{id} "),
        Value::String(id) => format!("#{} ", clean(id)),
        _ => String::new(),
    };
    let reason = match &stop["reason"] {
        Value::String(reason) => format!("{reason:?}"),
        Value::Null => "(no reason)".into(),
        other => text(other),
    };
    let persists = if stop["persists"] == true {
        "  (cause persists: cannot be released yet)"
    } else {
        ""
    };
    format!(
        "{id}{}  {}  {reason}  {} ago{persists}",
        text(&stop["owner"]),
        text(&stop["cause"]),
        seconds(&stop["age_ms"]),
    )
}

/// What must happen before the robot can move again.
fn what_to_do(stops: &[Value], unlisted: bool) -> String {
    let mut first: Vec<String> = Vec::new();
    for stop in stops.iter().filter(|stop| stop["persists"] == true) {
        let hint = persisting(stop);
        if !first.contains(&hint) {
            first.push(hint);
        }
    }
    if !first.is_empty() {
        return format!("first: {}; then `scout release`", first.join("; "));
    }
    let mut text = if stops.iter().any(|stop| stop["cause"] == "gateway_start") {
        "check the robot (the previous gateway exited uncleanly), then `scout release`".to_owned()
    } else {
        "`scout release`".to_owned()
    };
    if unlisted {
        text.push_str(" (a stop not listed may still persist: a refused release names it)");
    }
    text.push_str("; then take control again to drive (nothing restarts by itself)");
    text
}

/// What must clear before a stop whose cause persists can be released.
fn persisting(stop: &Value) -> String {
    match stop["cause"].as_str() {
        Some("chassis_estop") => "the chassis e-stop is still pressed".into(),
        Some("rc_override") => "RC transmitter still in control".into(),
        Some("link_lost" | "link_fault") => "link still lost".into(),
        Some("chassis_silent") => "chassis still silent".into(),
        Some("chassis_fault") => {
            "chassis fault still reported: clear it with `scout clear-fault`".into()
        }
        Some("heartbeat") => format!("heartbeat source still silent ({})", text(&stop["owner"])),
        _ => format!(
            "the cause {} of {}'s stop is still there",
            text(&stop["cause"]),
            text(&stop["owner"])
        ),
    }
}

fn driving(selected: &Value) -> String {
    match selected {
        Value::Null => "nobody".into(),
        selected => format!(
            "{} ({})",
            text(&selected["client"]),
            text(&selected["class"])
        ),
    }
}

fn output(output: &Value) -> String {
    let speed = |value: &Value, unit: &str| {
        value
            .as_f64()
            .map_or_else(|| format!("? {unit}"), |v| format!("{v:.3} {unit}"))
    };
    let mut text_out = format!(
        "{}  {}",
        speed(&output["linear"], "m/s"),
        speed(&output["angular"], "rad/s")
    );
    if output["limited"] == true {
        text_out.push_str("  (limited)");
    }
    match &output["fault_clear"] {
        Value::Null => {}
        Value::String(code) if code == "none" => {}
        code => text_out.push_str(&format!("  clearing fault {}", text(code))),
    }
    text_out
}

fn tick(tick: &Value) -> String {
    let ms = |value: &Value| {
        value
            .as_f64()
            .map_or_else(|| "?".into(), |v| format!("{v:.1}"))
    };
    format!(
        "latest {} ms late, worst {} ms, {} missed",
        ms(&tick["lateness_ms"]),
        ms(&tick["max_lateness_ms"]),
        text(&tick["missed"]),
    )
}

fn source_line(source: &Value) -> String {
    let class = match &source["class"] {
        Value::Null => "-".into(),
        class => text(class),
    };
    let mut line = format!("{}  {class}", text(&source["client"]));
    if source["holding"] == true {
        line.push_str("  holds control");
    }
    if let Some(period) = source["heartbeat_ms"].as_f64() {
        line.push_str(&format!("  heartbeat {period} ms"));
    }
    line.push_str(&format!(
        "  {} requests, last {} ago",
        text(&source["requests"]),
        seconds(&source["age_ms"])
    ));
    line
}

/// One remote peer's drive commands as the gateway's zenoh bridge counted them.
fn link_line(link: &Value) -> String {
    let share = match (link["accepted"].as_f64(), link["received"].as_f64()) {
        (Some(accepted), Some(received)) if received > 0.0 => {
            format!(" ({:.0} %)", 100.0 * accepted / received)
        }
        _ => String::new(),
    };
    let ms = |value: &Value| match value.as_u64() {
        Some(ms) => format!("{ms} ms"),
        None => "?".into(),
    };
    format!(
        "{}  accepted {} of {} drives{share}  late {}  reordered {}  lost {}  no control {}  \
         age p50 {} p99 {}  seen {} ago",
        text(&link["peer"]),
        text(&link["accepted"]),
        text(&link["received"]),
        text(&link["late"]),
        text(&link["reordered"]),
        text(&link["lost"]),
        text(&link["no_control"]),
        ms(&link["age_p50_ms"]),
        ms(&link["age_p99_ms"]),
        seconds(&link["last_seen_ms"]),
    )
}

/// The non-zero rejection counters, in the schema's order.
fn rejections(rejections: &Value) -> String {
    let counted: Vec<String> = rejections
        .as_object()
        .into_iter()
        .flatten()
        .filter(|(_, count)| count.as_f64().is_some_and(|count| count > 0.0))
        .map(|(kind, count)| format!("{} {count}", clean(kind)))
        .collect();
    if counted.is_empty() {
        "none".into()
    } else {
        counted.join(", ")
    }
}

/// A gateway that publishes no status is as good as gone.
impl FailureKind for Silent {
    fn kind(&self) -> Failure {
        Failure::NoGateway
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use serde_json::json;

    /// A status as `status_json` writes it: nobody drives, nothing holds.
    fn idle() -> Value {
        json!({
            "robot": "scout",
            "seq": 12,
            "age_ms": 3.5,
            "latched": false,
            "stop_total": 0,
            "stops": [],
            "selected": null,
            "output": {"linear": 0.0, "angular": 0.0, "fault_clear": "none", "limited": false},
            "autonomy_armed": false,
            "lights": "chassis",
            "sources": [],
            "rejections": {"not_finite": 0, "latched": 0, "rate_limited": 0},
            "tick": {"lateness_ms": 0.12, "max_lateness_ms": 2.5, "missed": 0},
            "events": [],
        })
    }

    fn stop(owner: &str, cause: &str, reason: &str, age_ms: f64, persists: bool) -> Value {
        json!({
            "owner": owner, "cause": cause, "reason": reason, "age_ms": age_ms,
            "persists": persists,
        })
    }

    fn latched(stops: Vec<Value>, total: usize) -> Value {
        let mut json = idle();
        json["latched"] = true.into();
        json["stop_total"] = total.into();
        json["stops"] = stops.into();
        json
    }

    /// The lines of `text` that start with `label`.
    fn labelled<'a>(text: &'a str, label: &str) -> Vec<&'a str> {
        let prefix = format!("{label:<9} ");
        text.lines()
            .filter(|line| line.starts_with(&prefix))
            .collect()
    }

    #[test]
    fn not_latched() {
        let text = render(&idle());
        assert!(text.contains("robot     scout\n"), "{text}");
        assert!(text.contains("latched   no\n"), "{text}");
        assert!(!text.contains("stop "), "{text}");
        assert!(!text.contains("what to do"), "{text}");
        assert!(text.contains("driving   nobody\n"), "{text}");
        assert!(
            text.contains("output    0.000 m/s  0.000 rad/s\n"),
            "{text}"
        );
        assert!(
            text.contains("autonomy  disarmed: `scout resume` arms it\n"),
            "{text}"
        );
        assert!(text.contains("clients   none\n"), "{text}");
        assert!(text.contains("rejected  none\n"), "{text}");
        assert!(
            text.contains("tick      latest 0.1 ms late, worst 2.5 ms, 0 missed\n"),
            "{text}"
        );
    }

    #[test]
    fn latched_with_stops_one_of_which_persists() {
        let json = latched(
            vec![
                stop("operator", "client", "person ahead", 12_345.0, false),
                stop("gateway", "chassis_estop", "chassis e-stop", 4_000.0, true),
                stop("lidar-guard", "client", "obstacle", 1_000.0, false),
            ],
            3,
        );
        let text = render(&json);
        assert!(text.contains("latched   YES: 3 stop(s)\n"), "{text}");
        let stops = labelled(&text, "stop");
        assert_eq!(stops.len(), 3, "{text}");
        assert_eq!(
            stops[0],
            "stop      operator  client  \"person ahead\"  12.3 s ago"
        );
        assert_eq!(
            stops[1],
            "stop      gateway  chassis_estop  \"chassis e-stop\"  4.0 s ago  \
             (cause persists: cannot be released yet)"
        );
        assert!(!stops[2].contains("persists"), "{text}");
        let todo = labelled(&text, "what to do");
        assert_eq!(
            todo,
            ["what to do first: the chassis e-stop is still pressed; then `scout release`"]
        );
    }

    #[test]
    fn latched_with_nothing_persisting_says_release() {
        let json = latched(vec![stop("operator", "client", "", 10.0, false)], 1);
        let text = render(&json);
        assert!(text.contains("latched   YES: 1 stop(s)\n"), "{text}");
        let todo = labelled(&text, "what to do");
        assert_eq!(todo.len(), 1, "{text}");
        assert!(todo[0].starts_with("what to do `scout release`;"), "{text}");
        let restarted = latched(
            vec![stop(
                "gateway",
                "gateway_start",
                "unclean exit",
                10.0,
                false,
            )],
            1,
        );
        let text = render(&restarted);
        assert!(
            text.contains("what to do check the robot (the previous gateway exited uncleanly), then `scout release`"),
            "{text}"
        );
    }

    #[test]
    fn every_persisting_cause_names_what_must_clear() {
        let cases = [
            ("chassis_estop", "the chassis e-stop is still pressed"),
            ("rc_override", "RC transmitter still in control"),
            ("link_lost", "link still lost"),
            ("link_fault", "link still lost"),
            ("chassis_silent", "chassis still silent"),
            (
                "chassis_fault",
                "chassis fault still reported: clear it with `scout clear-fault`",
            ),
            ("heartbeat", "heartbeat source still silent (handheld)"),
            (
                "a_new_cause",
                "the cause a_new_cause of handheld's stop is still there",
            ),
        ];
        for (cause, hint) in cases {
            let json = latched(vec![stop("handheld", cause, "why", 1.0, true)], 1);
            let text = render(&json);
            assert!(
                text.contains(&format!("what to do first: {hint}; then `scout release`\n")),
                "{cause}: {text}"
            );
        }
        // Two persisting causes, one of them twice: each named once, in order.
        let json = latched(
            vec![
                stop("gateway", "link_lost", "port closed", 3.0, true),
                stop("gateway", "chassis_silent", "no feedback", 2.0, true),
                stop("gateway", "link_fault", "ENOBUFS", 1.0, true),
            ],
            3,
        );
        assert!(
            render(&json).contains(
                "what to do first: link still lost; chassis still silent; then `scout release`\n"
            ),
            "{}",
            render(&json)
        );
    }

    #[test]
    fn more_stops_than_listed() {
        let stops: Vec<Value> = (0..16)
            .map(|i| stop(&format!("guard-{i}"), "client", "stacked", 100.0, false))
            .collect();
        let text = render(&latched(stops, 20));
        assert!(text.contains("latched   YES: 20 stop(s)\n"), "{text}");
        assert_eq!(labelled(&text, "stop").len(), 17, "{text}");
        assert!(
            text.contains("... and 4 more stop(s) not listed (the status lists the first 16)"),
            "{text}"
        );
        assert!(
            text.contains("a stop not listed may still persist"),
            "{text}"
        );
    }

    #[test]
    fn driving_client_output_and_autonomy() {
        let mut json = idle();
        json["selected"] = json!({"client": "drive-42", "class": "teleop"});
        json["output"] = json!({
            "linear": 0.3, "angular": -0.25, "fault_clear": "driver_overtemp", "limited": true,
        });
        json["autonomy_armed"] = true.into();
        let text = render(&json);
        assert!(text.contains("driving   drive-42 (teleop)\n"), "{text}");
        assert!(
            text.contains(
                "output    0.300 m/s  -0.250 rad/s  (limited)  clearing fault driver_overtemp\n"
            ),
            "{text}"
        );
        assert!(text.contains("autonomy  armed\n"), "{text}");
    }

    #[test]
    fn the_battery_line_says_what_to_do_when_low() {
        let mut json = idle();
        assert!(
            !render(&json).contains("battery"),
            "an older gateway: no line"
        );
        for (battery, line) in [
            (
                json!({"level": "ok", "percent": 64.4}),
                "battery   ok: 64 %\n",
            ),
            (
                json!({"level": "low", "percent": 18.0}),
                "battery   LOW: 18 %, charge soon\n",
            ),
            (
                json!({"level": "unknown", "percent": null}),
                "battery   not reported yet\n",
            ),
        ] {
            json["battery"] = battery;
            let text = render(&json);
            assert!(text.contains(line), "{text}");
        }
        json["battery"] = json!({"level": "critical", "percent": 7.0});
        assert!(render(&json).contains("battery   CRITICAL: 7 %, charge now"));
        // The chassis' cut-off sets the level: said beside a charge that would not.
        json["battery"] =
            json!({"level": "critical", "percent": 35.0, "level_from": "chassis_cutoff"});
        assert!(
            render(&json).contains(
                "battery   CRITICAL: 35 % (the chassis cut the drives off for battery under-voltage), charge now"
            ),
            "{}",
            render(&json)
        );
    }

    #[test]
    fn remote_links_one_line_per_peer() {
        let mut json = idle();
        assert!(labelled(&render(&json), "link").is_empty());
        json["links"] = json!([
            {"peer": "remote:operator", "received": 200, "accepted": 170, "late": 9,
             "reordered": 1, "no_control": 0, "lost": 20, "age_p50_ms": 12, "age_p99_ms": 140,
             "last_seen_ms": 40},
            {"peer": "remote:laptop\u{1b}[2J", "received": 0, "accepted": 0, "late": 0,
             "reordered": 0, "no_control": 3, "lost": 0, "age_p50_ms": null,
             "age_p99_ms": null, "last_seen_ms": 2500},
        ]);
        let text = render(&json);
        assert_eq!(
            labelled(&text, "link"),
            [
                "link      remote:operator  accepted 170 of 200 drives (85 %)  late 9  \
                 reordered 1  lost 20  no control 0  age p50 12 ms p99 140 ms  seen 0.0 s ago",
                "link      remote:laptop\\u{1b}[2J  accepted 0 of 0 drives  late 0  reordered 0  \
                 lost 0  no control 3  age p50 ? p99 ?  seen 2.5 s ago",
            ]
        );
    }

    #[test]
    fn sources_rejections_and_events() {
        let mut json = idle();
        json["sources"] = json!([
            {"client": "drive-42", "class": "teleop", "holding": true, "lease": 7,
             "heartbeat_ms": null, "requests": 120, "age_ms": 12.0},
            {"client": "handheld", "class": null, "holding": false, "lease": null,
             "heartbeat_ms": 200, "requests": 5, "age_ms": 1500.0},
        ]);
        json["rejections"] = json!({"not_finite": 3, "latched": 0, "rate_limited": 12});
        json["events"] = (0..8)
            .map(|i| json!({"age_ms": f64::from(8 - i) * 1000.0, "event": format!("event {i}")}))
            .collect();
        let text = render(&json);
        let clients = labelled(&text, "client");
        assert_eq!(
            clients,
            [
                "client    drive-42  teleop  holds control  120 requests, last 0.0 s ago",
                "client    handheld  -  heartbeat 200 ms  5 requests, last 1.5 s ago",
            ]
        );
        assert!(!text.contains("clients   none"), "{text}");
        assert!(
            text.contains("rejected  not_finite 3, rate_limited 12\n"),
            "{text}"
        );
        let events = labelled(&text, "event");
        assert_eq!(events.len(), EVENTS_SHOWN, "{text}");
        assert_eq!(events[0], "event     5.0 s ago  event 3");
        assert_eq!(events[4], "event     1.0 s ago  event 7");
    }

    #[test]
    fn new_and_missing_fields_and_control_characters() {
        let mut first = stop("operator", "client", "bad\u{1b}[2Jreason", 1.0, false);
        first["id"] = 7.into();
        first["something_new"] = "ignored".into();
        let mut json = latched(vec![first, json!({})], 2);
        json["newest_stop"] = 7.into();
        json["sources"] = json!([{"client": "evil\u{1b}]0;title\u{7}"}]);
        let text = render(&json);
        assert!(!text.contains('\u{1b}'), "{text:?}");
        assert!(!text.contains('\u{7}'), "{text:?}");
        let stops = labelled(&text, "stop");
        assert_eq!(
            stops[0],
            "stop      #7 operator  client  \"bad\\u{1b}[2Jreason\"  0.0 s ago"
        );
        assert_eq!(stops[1], "stop      ?  ?  (no reason)  ? s ago");
        // Everything missing: still one line per label, nothing invented.
        let text = render(&json!({}));
        assert!(text.contains("latched   no\n"), "{text}");
        assert!(text.contains("driving   nobody\n"), "{text}");
        assert!(text.contains("output    ? m/s  ? rad/s\n"), "{text}");
        assert!(text.contains("autonomy  ?\n"), "{text}");
        // `latched` missing but stops counted: latched.
        let text = render(&json!({"stop_total": 2}));
        assert!(text.contains("latched   YES: 2 stop(s)\n"), "{text}");
    }

    fn any_json() -> impl Strategy<Value = Value> {
        let leaf = prop_oneof![
            Just(Value::Null),
            any::<bool>().prop_map(Value::from),
            any::<i64>().prop_map(Value::from),
            any::<u64>().prop_map(Value::from),
            any::<f64>().prop_map(Value::from),
            ".{0,12}".prop_map(Value::from),
        ];
        leaf.prop_recursive(3, 24, 6, |inner| {
            prop_oneof![
                prop::collection::vec(inner.clone(), 0..6).prop_map(Value::from),
                prop::collection::btree_map(
                    prop_oneof![
                        Just("stops".to_owned()),
                        Just("cause".to_owned()),
                        Just("persists".to_owned()),
                        Just("owner".to_owned()),
                        Just("age_ms".to_owned()),
                        ".{0,6}".prop_map(String::from),
                    ],
                    inner,
                    0..6
                )
                .prop_map(|map| Value::Object(map.into_iter().collect())),
            ]
        })
    }

    /// Every top-level key the text reads.
    const KEYS: [&str; 14] = [
        "robot",
        "battery",
        "latched",
        "stop_total",
        "stops",
        "selected",
        "output",
        "autonomy_armed",
        "lights",
        "sources",
        "rejections",
        "tick",
        "events",
        "id",
    ];

    proptest! {
        #[test]
        fn never_panics_on_any_json(value in any_json()) {
            let _ = render(&value);
        }

        #[test]
        fn never_panics_with_any_field_replaced(
            key in 0..KEYS.len(),
            value in any_json(),
            stop_key in prop_oneof![
                Just("owner"), Just("cause"), Just("reason"), Just("age_ms"),
                Just("persists"), Just("id"),
            ],
            stop_value in any_json(),
        ) {
            let mut json = latched(
                vec![stop("operator", "heartbeat", "why", 1.0, true)],
                u64::MAX as usize,
            );
            json[KEYS[key]] = value;
            if let Some(first) = json["stops"].get_mut(0)
                && first.is_object()
            {
                first[stop_key] = stop_value;
            }
            let text = render(&json);
            prop_assert!(text.contains("latched"));
        }
    }
}
