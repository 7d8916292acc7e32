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
