//! `scout decode` as a user runs it: candump text or serial hex in, decoded lines out.

use std::time::Duration;

use scout_system_tests::{command, run_with_input};

const CAPTURE: &[u8] =
    include_bytes!("../../../protocol/tests/fixtures/scout-v1-capture-2019.candump");
const LIMIT: Duration = Duration::from_secs(30);

#[test]
fn decodes_the_whole_capture_from_stdin_as_json() {
    let mut scout = command("scout");
    scout.args(["decode", "--json"]);
    let output = run_with_input(scout, CAPTURE, LIMIT);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let lines: Vec<serde_json::Value> = String::from_utf8(output.stdout)
        .expect("utf-8")
        .lines()
        .map(|line| serde_json::from_str(line).expect("one JSON object a line"))
        .collect();
    assert_eq!(lines.len(), 2248);
    let status = lines
        .iter()
        .find(|l| l["id"] == "0x151")
        .expect("a status frame");
    assert_eq!(status["state"], "estop");
    assert_eq!(status["control_mode"], "rc");
    assert_eq!(status["battery_voltage"], 23.9);
    for line in &lines {
        assert!(line["name"].is_string() && line["count"].is_u64(), "{line}");
    }
}

#[test]
fn bad_lines_are_reported_with_their_number_and_the_rest_decoded() {
    let input = b"130#01000A0000000044\n130#01000A0000000045\n\nnot a frame\n(1554000000.123456) can0 130#010000000000003A\n5A A5 0A 55 01 02 00 0A 00 00 00 00 6B\n";
    let mut scout = command("scout");
    scout.arg("decode");
    let output = run_with_input(scout, input, LIMIT);
    assert_eq!(
        output.status.code(),
        Some(1),
        "bad lines make the exit code non-zero"
    );
    let stdout = String::from_utf8(output.stdout).expect("utf-8");
    assert_eq!(stdout.lines().count(), 3, "{stdout}");
    let stderr = String::from_utf8(output.stderr).expect("utf-8");
    assert!(
        stderr.contains("line 2: CAN id 0x130: checksum 0x45, expected 0x44"),
        "{stderr}"
    );
    assert!(stderr.contains("line 4: not a candump line"), "{stderr}");
}

#[test]
fn frames_as_arguments() {
    let mut scout = command("scout");
    scout.args(["decode", "  can0  131   [8]  00 96 FF 38 00 00 05 0C"]);
    let output = run_with_input(scout, b"", LIMIT);
    let stdout = String::from_utf8(output.stdout).expect("utf-8");
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(
        stdout.trim(),
        "0x131 motion_feedback count=5 linear=0.150 angular=-0.200"
    );
}

#[test]
fn protocol_v2_frames_by_their_ids_and_forced() {
    // A Bunker Mini 2.0 in e-stop before 0x421 (protocol-v2-notes 8), and the host taking CAN
    // control, then a v1 frame.
    let lines = "(1700000000.000100) can0 211#0100010000800000\n\
                 (1700000000.000200) can0 421#01\n\
                 (1700000000.000300) can0 130#01000A0000000044\n";
    let mut scout = command("scout");
    scout.args(["decode", "--json"]);
    let output = run_with_input(scout, lines.as_bytes(), LIMIT);
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let frames: Vec<serde_json::Value> = String::from_utf8(output.stdout)
        .expect("utf-8")
        .lines()
        .map(|line| serde_json::from_str(line).expect("JSON"))
        .collect();
    assert_eq!(frames.len(), 3);
    assert_eq!(frames[0]["protocol"], 2);
    assert_eq!(frames[0]["name"], "system_state");
    assert_eq!(frames[0]["state"], "estop");
    assert_eq!(frames[0]["unknown_error_bits"], 0x80);
    assert_eq!(frames[1]["name"], "control_mode");
    assert_eq!(frames[1]["control_mode"], "can");
    assert_eq!(frames[2]["protocol"], 1);
    assert_eq!(frames[2]["timestamp"], 1_700_000_000.000_3);

    // Forced to v1, the v2 frames are reported and the exit code says so.
    let mut scout = command("scout");
    scout.args(["decode", "--protocol", "v1"]);
    let output = run_with_input(scout, lines.as_bytes(), LIMIT);
    assert_eq!(output.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("line 1: unknown CAN id 0x211 (not SCOUT v1)"),
        "{stderr}"
    );
}
