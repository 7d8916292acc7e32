//! The gateway's command line: usage and configuration errors exit 2 with a message that says
//! what to do. (These tests also make `cargo test --workspace` build the binary that the system
//! tests in tests/ run.)

use std::process::Command;

fn run(binary: &str, args: &[&str]) -> (Option<i32>, String) {
    let output = Command::new(binary)
        .args(args)
        .output()
        .expect("run the binary");
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

const GATEWAY: &str = env!("CARGO_BIN_EXE_scout-gateway");

#[test]
fn gateway_without_a_transport_says_which_to_give() {
    let (code, stderr) = run(GATEWAY, &[]);
    assert_eq!(code, Some(2));
    assert!(
        stderr.contains("no transport: use --sim, --serial DEVICE"),
        "{stderr}"
    );
}

#[test]
fn gateway_refuses_bad_values() {
    let (code, stderr) = run(GATEWAY, &["--sim", "--max-angular=-1"]);
    assert_eq!(code, Some(2));
    assert!(
        stderr.contains("max_angular must be a positive number"),
        "{stderr}"
    );
    let (code, stderr) = run(GATEWAY, &["--sim", "--name", "a/b"]);
    assert_eq!(code, Some(2));
    assert!(stderr.contains("robot name `a/b`"), "{stderr}");
    let (code, stderr) = run(GATEWAY, &["--sim", "--remote-commands", "everything"]);
    assert_eq!(code, Some(2));
    assert!(
        stderr.contains("unknown Permission `everything`: one of estop"),
        "{stderr}"
    );
    let (code, stderr) = run(GATEWAY, &["--config", "/nonexistent/scout.toml", "--sim"]);
    assert_eq!(code, Some(2));
    assert!(stderr.contains("/nonexistent/scout.toml"), "{stderr}");
}

#[test]
fn gateway_help_lists_the_transports() {
    let output = Command::new(GATEWAY).arg("--help").output().expect("run");
    assert_eq!(output.status.code(), Some(0));
    let help = String::from_utf8_lossy(&output.stdout);
    for flag in [
        "--sim",
        "--serial",
        "--slcan",
        "--can",
        "--name",
        "--config",
        "--no-zenoh",
    ] {
        assert!(help.contains(flag), "{flag} missing from --help");
    }
}
