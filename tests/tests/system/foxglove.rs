//! `scout record` and `scout foxglove` against a real gateway on the simulator: MCAP files read
//! back with the Python `mcap` package (whole, cut by SIGINT, by `--duration`, by SIGKILL), and
//! the live view read by a Foxglove WebSocket client written with `websockets`
//! (`foxglove_ws_client.py`): channels, rates, the stop service through the gateway's stop path.
//!
//! A `--ros2` recording is read by rosbags and mcap-ros2-support (`ros2_bag_check.py`).
//!
//! They need `python3` (or `$SCOUT_PYTHON`) with `mcap` and `websockets` (and, for the bag,
//! `rosbags` and `mcap-ros2-support`; `.ci/run` installs them). Without them the tests skip,
//! saying why, unless `SCOUT_REQUIRE_FOXGLOVE_CHECKS` is set (as in CI): then they fail.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use scout_system_tests::{
    Background, Gateway, Sim, TempDir, chassis_stays_still, comes_to_rest, command, connect,
    drive_until_moving, release_all, robot_name, run_with_input, scout, skip, wait_for_state,
    wait_for_status,
};
use serde_json::Value;

fn python() -> String {
    std::env::var("SCOUT_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// Why the checks cannot run here, if they cannot; panics instead where they are required.
fn checks_missing(test: &str) -> Option<String> {
    modules_missing(
        test,
        "mcap, websockets, zstandard",
        "mcap==1.6.0 websockets==17.4",
    )
}

/// [`checks_missing`] for the checks of a ROS 2 bag.
fn bag_checks_missing(test: &str) -> Option<String> {
    modules_missing(
        test,
        "mcap, rosbags, mcap_ros2",
        "mcap==1.6.0 rosbags==0.11.* mcap-ros2-support==0.5.*",
    )
}

/// Why Python `modules` cannot be imported (pip's `packages` would bring them), if they
/// cannot; panics instead where the checks are required.
fn modules_missing(test: &str, modules: &str, packages: &str) -> Option<String> {
    let why = match Command::new(python())
        .args(["-c", &format!("import {modules}")])
        .output()
    {
        Ok(output) if output.status.success() => return None,
        Ok(output) => format!(
            "{} lacks one of {modules} ({}): pip install {packages}",
            python(),
            String::from_utf8_lossy(&output.stderr).trim()
        ),
        Err(error) => format!("no {}: {error}", python()),
    };
    assert!(
        std::env::var_os("SCOUT_REQUIRE_FOXGLOVE_CHECKS").is_none(),
        "{test}: {why}"
    );
    skip(test, &why);
    Some(why)
}

fn script(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/system")
        .join(name)
}

/// The report of `mcap_check.py` on `file`.
fn mcap_report(file: &Path, truncated: bool) -> Value {
    let mut args = vec![file.as_os_str()];
    if truncated {
        args.push(std::ffi::OsStr::new("--truncated"));
    }
    script_report("mcap_check.py", &args)
}

/// The JSON report the Python script `name` prints for `args`; panics, with what it said,
/// when it fails.
fn script_report<S: AsRef<std::ffi::OsStr>>(name: &str, args: &[S]) -> Value {
    let mut check = Command::new(python());
    check.arg(script(name)).args(args);
    let output = run_with_input(check, b"", Duration::from_secs(60));
    assert!(
        output.status.success(),
        "{name} failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("a JSON report")
}

/// `scout record --name NAME --output FILE ARGS` in the background, its output collected.
fn recorder(name: &str, file: &Path, args: &[&str]) -> Background {
    let mut record = command("scout");
    record
        .args(["record", "--name", name, "--output"])
        .arg(file)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null());
    Background::spawn(record)
}

fn file_size(file: &Path) -> u64 {
    std::fs::metadata(file).map_or(0, |metadata| metadata.len())
}

/// Waits at most `limit` until `file` has grown `times` times.
fn wait_growth(file: &Path, times: u32, limit: Duration) {
    let deadline = Instant::now() + limit;
    let mut size = file_size(file);
    let mut grown = 0;
    while grown < times {
        assert!(
            Instant::now() < deadline,
            "{} did not grow {times} times",
            file.display()
        );
        std::thread::sleep(Duration::from_millis(50));
        let now = file_size(file);
        if now > size {
            grown += 1;
            size = now;
        }
    }
}

/// How many chunks of the MCAP file `bytes` are whole: a chunk being written has its length still
/// the writer's placeholder (all ones), and a growing file may end inside a record.
fn whole_chunks(bytes: &[u8]) -> usize {
    const MAGIC: usize = 8;
    const CHUNK: u8 = 0x06;
    let mut at = MAGIC;
    let mut chunks = 0;
    while let Some(head) = bytes.get(at..at + 9) {
        let length = u64::from_le_bytes(head[1..].try_into().expect("eight bytes"));
        let end = usize::try_from(length)
            .ok()
            .and_then(|length| (at + 9).checked_add(length));
        match end {
            Some(end) if end <= bytes.len() => {
                chunks += usize::from(head[0] == CHUNK);
                at = end;
            }
            _ => break,
        }
    }
    chunks
}

/// Waits at most `limit` until `file` holds `chunks` whole chunks (the recorder closes and syncs
/// one a second). The file's growth says less: a chunk's header goes out when it is opened.
fn wait_chunks(file: &Path, chunks: usize, limit: Duration) {
    let deadline = Instant::now() + limit;
    while whole_chunks(&std::fs::read(file).unwrap_or_default()) < chunks {
        assert!(
            Instant::now() < deadline,
            "{} did not close {chunks} chunks",
            file.display()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn topic<'a>(report: &'a Value, name: &str) -> &'a Value {
    let topic = &report["topics"][name];
    assert!(topic.is_object(), "no {name} in {report}");
    topic
}

/// Messages a second on `topic`, from its count and first and last log times.
fn rate(topic: &Value) -> f64 {
    let count = topic["count"].as_f64().expect("count");
    let span = (topic["last_ns"].as_f64().expect("last")
        - topic["first_ns"].as_f64().expect("first"))
        / 1e9;
    (count - 1.0) / span
}

#[test]
fn a_recording_holds_every_channel_with_schemas_and_closes_with_its_index_on_sigint() {
    let test = "record_sigint";
    if checks_missing(test).is_some() {
        return;
    }
    let name = robot_name("record");
    let dir = TempDir::new(&name);
    let file = dir.path().join("drive.mcap");
    let mut sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status reader");
    let mut recorder = recorder(&name, &file, &[]);
    wait_growth(&file, 1, Duration::from_secs(10));

    // Drive, latch a stop, release it: commands, stops and events to record.
    let driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.4", "--duration", "60"],
        Duration::from_secs(10),
    );
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--reason", "recorded stop"]);
    assert_eq!(code, Some(0), "{stderr}");
    comes_to_rest(&mut sim, Duration::from_secs(5));
    chassis_stays_still(&mut sim, Duration::from_millis(300));
    drop(driver);
    release_all(&name);
    wait_for_status(&status, Duration::from_secs(5), |s| s["latched"] == false);
    wait_chunks(&file, 1, Duration::from_secs(10));

    recorder.signal(Signal::SIGINT);
    assert_eq!(
        recorder.wait_exit(Duration::from_secs(10)),
        Some(0),
        "SIGINT is a clean end"
    );
    let report = mcap_report(&file, false);
    assert_eq!(report["summary"], true, "a summary section: {report}");
    assert_eq!(report["compression"], serde_json::json!(["zstd"]));
    assert!(
        report["chunks"].as_u64() >= Some(2),
        "a chunk a second: {report}"
    );
    assert_eq!(report["metadata"]["scout"]["robot"], name.as_str());

    let expected = [
        ("/scout/state", "scout.State", "jsonschema", "json"),
        ("/scout/command", "scout.Command", "jsonschema", "json"),
        ("/scout/status", "scout.Status", "jsonschema", "json"),
        ("/scout/events", "foxglove.Log", "protobuf", "protobuf"),
        (
            "/scout/pose",
            "foxglove.PoseInFrame",
            "protobuf",
            "protobuf",
        ),
        ("/tf", "foxglove.FrameTransform", "protobuf", "protobuf"),
    ];
    let mut total = 0;
    for (name, schema, schema_encoding, encoding) in expected {
        let topic = topic(&report, name);
        assert_eq!(topic["schema"], schema, "{name}: {topic}");
        assert_eq!(topic["schema_encoding"], schema_encoding, "{name}");
        assert_eq!(topic["encoding"], encoding, "{name}");
        assert_eq!(topic["in_order"], true, "{name}: log times never go back");
        assert_eq!(
            report["channel_message_counts"][name], topic["count"],
            "{name}: the statistics agree"
        );
        total += topic["count"].as_u64().expect("count");
    }
    assert_eq!(report["message_count"].as_u64(), Some(total));

    let state = topic(&report, "/scout/state");
    let state_rate = rate(state);
    assert!(
        (40.0..=60.0).contains(&state_rate),
        "the state at the chassis' 50 Hz: {state_rate:.1}"
    );
    assert_eq!(state["last"]["robot"], name.as_str());
    assert!(
        state["last"]["system"]["battery_voltage"].as_f64() > Some(20.0),
        "{state}"
    );
    let pose = topic(&report, "/scout/pose");
    assert_eq!(pose["count"], state["count"], "a pose with each state");
    let command = topic(&report, "/scout/command");
    let command_rate = rate(command);
    assert!(
        (40.0..=60.0).contains(&command_rate),
        "every command at 50 Hz: {command_rate:.1}"
    );
    assert!(
        topic(&report, "/scout/events")["count"].as_u64() >= Some(3),
        "takeover, stop, release"
    );
    let last_status = &topic(&report, "/scout/status")["last"];
    assert_eq!(last_status["latched"], false, "{last_status}");
    let log_times_are_unix_now = state["first_ns"].as_f64().map(|ns| ns / 1e9);
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("after 1970")
        .as_secs_f64();
    assert!(
        log_times_are_unix_now.is_some_and(|first| (now - 120.0..now).contains(&first)),
        "log times are Unix times: {log_times_are_unix_now:?}, now {now}"
    );
}

#[test]
fn a_recording_with_a_duration_ends_by_itself_and_one_cut_by_sigkill_reads_up_to_its_last_chunk() {
    let test = "record_cut";
    if checks_missing(test).is_some() {
        return;
    }
    let name = robot_name("record-cut");
    let dir = TempDir::new(&name);
    let sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    connect(&name);

    // --duration: exits 0 on its own, prints what it wrote.
    let timed = dir.path().join("timed.mcap");
    let mut record = command("scout");
    record
        .args(["record", "--name", &name, "--duration", "2", "--output"])
        .arg(&timed);
    let output = run_with_input(record, b"", Duration::from_secs(20));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(
        output.status.code(),
        Some(0),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(
        stdout.starts_with(&format!("wrote {}", timed.display())),
        "{stdout}"
    );
    let report = mcap_report(&timed, false);
    assert_eq!(report["summary"], true);
    let states = topic(&report, "/scout/state")["count"]
        .as_u64()
        .expect("count");
    assert!((80..=120).contains(&states), "2 s at 50 Hz: {states}");

    // The same file again: refused (exit 2), untouched.
    let size = file_size(&timed);
    let (code, _, stderr) = scout(&[
        "record",
        "--name",
        &name,
        "--duration",
        "1",
        "--output",
        timed.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("exists") && stderr.contains("--force"),
        "{stderr}"
    );
    assert_eq!(file_size(&timed), size);

    // SIGKILL: no summary, but every synced chunk reads.
    let cut = dir.path().join("cut.mcap");
    let mut recorder = recorder(&name, &cut, &[]);
    wait_chunks(&cut, 2, Duration::from_secs(15));
    recorder.signal(Signal::SIGKILL);
    recorder.wait_exit(Duration::from_secs(5));
    let whole = mcap_report(&cut, false);
    assert_eq!(
        whole["summary"], false,
        "a killed recorder wrote no summary: {whole}"
    );
    let report = mcap_report(&cut, true);
    let states = topic(&report, "/scout/state");
    assert!(
        states["count"].as_u64() >= Some(50),
        "at least a second of states: {report}"
    );
    assert_eq!(states["in_order"], true);
    assert_eq!(
        states["last"]["robot"],
        name.as_str(),
        "the last message read is whole"
    );
    drop(sim);
}

/// The report of `ros2_bag_check.py` on the bag `dir`.
fn bag_report(dir: &Path) -> Value {
    script_report("ros2_bag_check.py", &[dir])
}

#[test]
fn a_ros2_recording_is_a_bag_rosbags_reads_every_message_of() {
    let test = "record_ros2";
    if bag_checks_missing(test).is_some() {
        return;
    }
    let name = robot_name("record-ros2");
    let dir = TempDir::new(&name);
    let bag = dir.path().join("drive");
    let file = bag.join("drive_0.mcap");
    let mut sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    let states = connect(&name).subscribe().expect("subscribe");
    let mut recording = recorder(&name, &bag, &["--ros2"]);
    wait_growth(&file, 1, Duration::from_secs(10));
    let driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.4", "--duration", "60"],
        Duration::from_secs(10),
    );
    // Far enough for the recorded odometry to show it, then a chunk closed while driving.
    wait_for_state(&states, Duration::from_secs(10), |s| {
        s["odometry"]["x"].as_f64() > Some(0.1)
    });
    let closed = whole_chunks(&std::fs::read(&file).unwrap_or_default());
    wait_chunks(&file, closed + 1, Duration::from_secs(10));
    drop(driver);
    recording.signal(Signal::SIGINT);
    assert_eq!(recording.wait_exit(Duration::from_secs(10)), Some(0));

    let report = bag_report(&bag);
    assert_eq!(report["storage"], "mcap", "{report}");
    for (topic, kind) in [
        ("/odom", "nav_msgs/msg/Odometry"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/battery_state", "sensor_msgs/msg/BatteryState"),
        ("/joint_states", "sensor_msgs/msg/JointState"),
        ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
        ("/scout/cmd_vel_sent", "geometry_msgs/msg/Twist"),
    ] {
        let read = &report["topics"][topic];
        assert_eq!(read["type"], kind, "{topic}: {report}");
        // Every message the metadata counts is decoded twice: by rosbags' own Humble and Jazzy
        // types, and by mcap-ros2-support with the definitions in the file.
        let count = read["metadata_count"].as_u64().expect("count");
        assert!(count > 0, "{topic}: {read}");
        assert_eq!(read["rosbags_count"], count, "{topic}: {read}");
        assert_eq!(read["mcap_ros2_count"], count, "{topic}: {read}");
    }
    let topics = &report["topics"];
    assert!(topics["/odom"]["max_x"].as_f64() > Some(0.05), "{report}");
    assert_eq!(topics["/odom"]["frame_id"], "odom");
    assert_eq!(topics["/odom"]["child_frame_id"], "base_link");
    assert!(
        topics["/scout/cmd_vel_sent"]["max_linear"].as_f64() >= Some(0.3),
        "{report}"
    );
    assert!(
        topics["/battery_state"]["voltage"].as_f64() > Some(20.0),
        "{report}"
    );
    assert_eq!(topics["/battery_state"]["present"], true);
    assert_eq!(
        topics["/joint_states"]["names"].as_array().map(Vec::len),
        Some(4)
    );
    assert!(
        topics["/diagnostics"]["names"]
            .as_array()
            .is_some_and(|names| names.contains(&"scout: recorder".into())),
        "{report}"
    );

    // Cut by SIGKILL: the metadata of the last second's sync, and the MCAP file read as a
    // stream up to its last whole chunk (`mcap recover` makes it whole for rosbags).
    let cut = dir.path().join("cut");
    let mut killed = recorder(&name, &cut, &["--ros2"]);
    wait_chunks(&cut.join("cut_0.mcap"), 2, Duration::from_secs(15));
    killed.signal(Signal::SIGKILL);
    killed.wait_exit(Duration::from_secs(5));
    let metadata = std::fs::read_to_string(cut.join("metadata.yaml")).expect("metadata.yaml");
    let report = mcap_report(&cut.join("cut_0.mcap"), true);
    let odom = topic(&report, "/odom");
    assert_eq!(odom["schema"], "nav_msgs/msg/Odometry");
    assert_eq!(odom["schema_encoding"], "ros2msg");
    assert_eq!(odom["encoding"], "cdr");
    assert!(
        odom["count"].as_u64() >= Some(25),
        "half a second of odometry: {report}"
    );
    // The metadata was rewritten with a sync (at the start it counts nothing), and counts no
    // more than the file holds.
    let counted: u64 = metadata
        .split("name: /odom\n")
        .nth(1)
        .and_then(|rest| {
            rest.lines()
                .find_map(|line| line.trim().strip_prefix("message_count: "))
        })
        .and_then(|count| count.parse().ok())
        .unwrap_or_else(|| panic!("no count of /odom in {metadata}"));
    assert!(
        counted > 0 && Some(counted) <= odom["count"].as_u64(),
        "{counted} counted, {} read: {metadata}",
        odom["count"]
    );
    drop(sim);
}

#[test]
fn no_gateway_is_exit_3_and_leaves_no_file() {
    let name = robot_name("record-none");
    let dir = TempDir::new(&name);
    let file = dir.path().join("none.mcap");
    let (code, _, stderr) = scout(&[
        "record",
        "--name",
        &name,
        "--output",
        file.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, Some(3), "{stderr}");
    assert!(!file.exists());
    let (code, _, stderr) = scout(&["foxglove", "--name", &name, "--listen", "127.0.0.1:0"]);
    assert_eq!(code, Some(3), "{stderr}");
}

/// `scout foxglove --name NAME --listen 127.0.0.1:0 ARGS` and the URL it prints.
fn live_view(name: &str, args: &[&str]) -> (Background, String) {
    let mut serve = command("scout");
    serve
        .args(["foxglove", "--name", name, "--listen", "127.0.0.1:0"])
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null());
    let mut child = serve.spawn().expect("start scout foxglove");
    let stdout = child.stdout.take().expect("stdout");
    let mut line = String::new();
    BufReader::new(stdout)
        .read_line(&mut line)
        .expect("the first line");
    let url = line
        .split_whitespace()
        .find(|word| word.starts_with("ws://"))
        .map(|url| url.trim_end_matches(':').to_owned())
        .unwrap_or_else(|| panic!("no URL in {line:?}"));
    (Background::from_child(child), url)
}

fn ws_client(url: &str, seconds: &str, calls: &[(&str, &str)]) -> Value {
    let mut args = vec![url, seconds];
    for (service, request) in calls {
        args.extend(["--call", *service, *request]);
    }
    script_report("foxglove_ws_client.py", &args)
}

#[test]
fn the_live_view_serves_the_same_channels_at_the_state_rate_and_is_read_only_by_default() {
    let test = "foxglove_live";
    if checks_missing(test).is_some() {
        return;
    }
    let name = robot_name("foxglove");
    let sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    connect(&name);
    let (_server, url) = live_view(&name, &[]);
    let report = ws_client(&url, "3", &[]);
    assert_eq!(report["subprotocol"], "foxglove.websocket.v1");
    assert_eq!(report["server_info"]["name"], format!("scout {name}"));
    let capabilities = report["server_info"]["capabilities"]
        .as_array()
        .expect("capabilities");
    assert!(
        !capabilities
            .iter()
            .any(|c| c == "services" || c == "clientPublish"),
        "read-only: {capabilities:?}"
    );
    for (topic, schema) in [
        ("/scout/state", "scout.State"),
        ("/scout/command", "scout.Command"),
        ("/scout/status", "scout.Status"),
        ("/scout/events", "foxglove.Log"),
        ("/scout/pose", "foxglove.PoseInFrame"),
        ("/tf", "foxglove.FrameTransform"),
    ] {
        assert_eq!(
            report["channels"][topic]["schemaName"], schema,
            "{topic}: {report}"
        );
    }
    let states = report["messages"]["/scout/state"].as_u64().expect("states");
    // 3 s at 50 Hz, less what the subscription's start took.
    assert!(
        (100..=160).contains(&states),
        "/scout/state at about 50 Hz: {states}"
    );
    assert_eq!(
        report["last"]["/scout/state"]["body"]["robot"],
        name.as_str()
    );
    assert!(report["messages"]["/tf"].as_u64() >= Some(100));
    assert!(report["services"].as_object().is_some_and(|s| s.is_empty()));
}

#[test]
fn the_live_views_estop_is_a_stop_of_its_owner_shown_with_its_cause_and_released_only_as_configured()
 {
    let test = "foxglove_estop";
    if checks_missing(test).is_some() {
        return;
    }
    let name = robot_name("foxglove-estop");
    let mut sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status reader");
    let (_server, url) = live_view(&name, &["--estop", "--owner", "console"]);

    let driver = drive_until_moving(
        &mut sim,
        &name,
        &["--linear", "0.4", "--duration", "60"],
        Duration::from_secs(10),
    );
    let report = ws_client(
        &url,
        "0.5",
        &[
            ("/scout/estop", r#"{"reason": "operator saw a person"}"#),
            ("/scout/release", "{}"),
        ],
    );
    assert!(
        report["server_info"]["capabilities"]
            .as_array()
            .is_some_and(|c| c.iter().any(|c| c == "services"))
    );
    let answer = &report["responses"]["1"]["body"];
    assert_eq!(answer["success"], true, "{report}");
    assert!(answer["stop"].as_u64() >= Some(1), "{answer}");
    assert!(
        report["failures"]["2"]
            .as_str()
            .is_some_and(|why| why.contains("no service /scout/release")),
        "release is not offered without --allow-release: {report}"
    );
    let latched = wait_for_status(&status, Duration::from_secs(5), |s| s["latched"] == true);
    let stop = &latched["stops"][0];
    assert_eq!(stop["owner"], "console", "{latched}");
    assert!(
        stop["reason"]
            .as_str()
            .is_some_and(|r| r.contains("operator saw a person")),
        "{stop}"
    );
    comes_to_rest(&mut sim, Duration::from_secs(5));
    chassis_stays_still(&mut sim, Duration::from_millis(500));
    let shown = report["statuses"].as_array().expect("statuses");
    assert!(
        shown.iter().any(|s| s["message"]
            .as_str()
            .is_some_and(|m| m.starts_with("STOP #") && m.contains("by console (client)"))),
        "the stop is shown with its owner and cause: {shown:?}"
    );
    drop(driver);

    // With --allow-release, a second view releases its owner's stop, through the newest stop
    // its caller saw (a release that does not say is refused, saying how); motion does not
    // restart.
    let stop_id = answer["stop"].as_u64().expect("the stop's id");
    let (_releaser, url) = live_view(&name, &["--allow-release", "--owner", "console"]);
    let through = format!(r#"{{"through": {stop_id}}}"#);
    let report = ws_client(
        &url,
        "1",
        &[("/scout/release", "{}"), ("/scout/release", &through)],
    );
    let refused = &report["responses"]["1"]["body"];
    assert_eq!(refused["success"], false, "{report}");
    assert!(
        refused["message"]
            .as_str()
            .is_some_and(|m| m.contains("through")),
        "{refused}"
    );
    assert_eq!(
        report["responses"]["2"]["body"]["success"], true,
        "{report}"
    );
    wait_for_status(&status, Duration::from_secs(5), |s| s["latched"] == false);
    chassis_stays_still(&mut sim, Duration::from_millis(500));
}

/// The status line a WebSocket handshake to `url` gets, with `origin` as its Origin header.
fn handshake_status(url: &str, origin: Option<&str>) -> String {
    use std::io::{Read, Write};
    let address = url.trim_start_matches("ws://");
    let mut stream = std::net::TcpStream::connect(address).expect("connect");
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    let origin = origin.map_or(String::new(), |origin| format!("Origin: {origin}\r\n"));
    let head = format!(
        "GET / HTTP/1.1\r\nHost: {address}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\
         Sec-WebSocket-Protocol: foxglove.websocket.v1\r\n{origin}\r\n"
    );
    stream.write_all(head.as_bytes()).expect("send the head");
    let mut answer = Vec::new();
    let mut chunk = [0u8; 1024];
    while !answer.windows(4).any(|w| w == b"\r\n\r\n") {
        match stream.read(&mut chunk) {
            Ok(0) | Err(_) => break,
            Ok(n) => answer.extend_from_slice(&chunk[..n]),
        }
    }
    let answer = String::from_utf8_lossy(&answer).into_owned();
    answer.lines().next().unwrap_or_default().to_owned()
}

/// A web page of another origin cannot open the live view (a page at `http://evil.example`
/// open in a browser on the robot got the channels and, with `--estop`, latched stops);
/// clients without an Origin and this machine's pages can, and `--allow-origin` lets one in.
#[test]
fn the_live_view_refuses_web_pages_of_other_origins() {
    let name = robot_name("foxglove-origin");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let _robot = connect(&name);
    let (_server, url) = live_view(&name, &["--estop"]);
    for origin in ["http://evil.example", "null", "https://app.foxglove.dev"] {
        let status = handshake_status(&url, Some(origin));
        assert!(status.contains(" 403 "), "{origin}: {status}");
    }
    for origin in [
        None,
        Some("http://localhost:8080"),
        Some("http://127.0.0.1:3000"),
    ] {
        let status = handshake_status(&url, origin);
        assert!(status.contains(" 101 "), "{origin:?}: {status}");
    }
    let (_allowing, url) = live_view(&name, &["--allow-origin", "https://app.foxglove.dev"]);
    let status = handshake_status(&url, Some("https://app.foxglove.dev"));
    assert!(status.contains(" 101 "), "{status}");
    let status = handshake_status(&url, Some("http://evil.example"));
    assert!(status.contains(" 403 "), "{status}");
}

/// The TCP ports process `pid` listens on, from `/proc/net/tcp` and its descriptors.
fn listening_ports(pid: u32) -> Vec<u16> {
    let inodes: Vec<String> = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .map(|fds| {
            fds.flatten()
                .filter_map(|fd| std::fs::read_link(fd.path()).ok())
                .filter_map(|target| {
                    let target = target.to_string_lossy().into_owned();
                    Some(
                        target
                            .strip_prefix("socket:[")?
                            .strip_suffix(']')?
                            .to_owned(),
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    let table = std::fs::read_to_string("/proc/net/tcp").unwrap_or_default();
    table
        .lines()
        .skip(1)
        .filter_map(|line| {
            let fields: Vec<&str> = line.split_whitespace().collect();
            let (local, state, inode) = (fields.get(1)?, fields.get(3)?, fields.get(9)?);
            let port = u16::from_str_radix(local.split(':').nth(1)?, 16).ok()?;
            (*state == "0A" && inodes.iter().any(|i| i == inode)).then_some(port)
        })
        .collect()
}

/// The Foxglove SDK's server listens on a loopback port of its own behind the front: no local
/// process reaches it directly (30 connections made there bypassed the front's client limit and
/// origin check), while the front's connections do.
#[test]
fn the_server_behind_the_live_views_front_is_reachable_from_the_front_alone() {
    let name = robot_name("foxglove-backend");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let _robot = connect(&name);
    let (server, url) = live_view(&name, &["--estop"]);
    let front: u16 = url
        .rsplit(':')
        .next()
        .and_then(|port| port.parse().ok())
        .expect("the front's port");
    let behind: Vec<u16> = listening_ports(server.pid())
        .into_iter()
        .filter(|port| *port != front)
        .collect();
    assert_eq!(behind.len(), 1, "one server behind the front: {behind:?}");
    let direct = std::net::TcpStream::connect_timeout(
        &std::net::SocketAddr::from(([127, 0, 0, 1], behind[0])),
        Duration::from_millis(500),
    );
    assert!(direct.is_err(), "reached the server directly: {direct:?}");
    let status = handshake_status(&url, None);
    assert!(status.contains(" 101 "), "through the front: {status}");
}
