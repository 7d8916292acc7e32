//! The `scout` command line: exit codes and messages. (This test also makes `cargo test
//! --workspace` build the `scout` binary that the system tests in tests/ run.)

use std::process::Command;

const SCOUT: &str = env!("CARGO_BIN_EXE_scout");

fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let output = Command::new(SCOUT).args(args).output().expect("run scout");
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(run(&[]).0, Some(2));
    assert_eq!(run(&["drive", "--class", "pilot"]).0, Some(2));
    assert_eq!(run(&["lights", "--front", "disco"]).0, Some(2));
}

#[test]
fn decode_exit_codes() {
    let (code, stdout, _) = run(&["decode", "130#01000A0000000044"]);
    assert_eq!(code, Some(0));
    assert!(
        stdout.starts_with("0x130 motion_command count=0 control_mode=can"),
        "{stdout}"
    );
    let (code, _, stderr) = run(&["decode", "130#01000A0000000045"]);
    assert_eq!(code, Some(1));
    assert!(stderr.contains("checksum 0x45, expected 0x44"), "{stderr}");
}

#[test]
fn commands_without_a_gateway_exit_3_and_say_how_to_start_one() {
    let name = format!("cli-nobody-{}", std::process::id());
    for command in ["status", "estop", "release", "resume", "reset-odometry"] {
        let (code, _, stderr) = run(&[command, "--name", &name]);
        assert_eq!(code, Some(3), "{command}: {stderr}");
        assert!(
            stderr.contains(&format!("scout-gateway --name {name} --sim")),
            "{command}: {stderr}"
        );
    }
}
