//! `scout-foxglove` as users run it, without a gateway: its usage errors and exit codes. (With
//! gateways: `tests/tests/system/foxglove.rs`.)

use std::process::Command;

fn scout_foxglove(args: &[&str]) -> (Option<i32>, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_scout-foxglove"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("run scout-foxglove");
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

#[test]
fn a_duration_that_is_not_a_positive_number_is_a_usage_error() {
    for duration in ["0", "-1", "NaN", "inf"] {
        let (code, stderr) = scout_foxglove(&[
            "record",
            "--output",
            "/nonexistent/never.mcap",
            "--duration",
            duration,
        ]);
        assert_eq!(code, Some(2), "{duration}: {stderr}");
    }
}

#[test]
fn no_gateway_of_that_name_is_exit_3_and_says_so() {
    let name = format!("foxglove-cli-none-{}", std::process::id());
    let file = std::env::temp_dir().join(format!("{name}.mcap"));
    let (code, stderr) = scout_foxglove(&[
        "record",
        "--name",
        &name,
        "--output",
        file.to_str().expect("utf-8"),
    ]);
    assert_eq!(code, Some(3), "{stderr}");
    assert!(stderr.contains(&name), "{stderr}");
    assert!(!file.exists(), "no gateway leaves no file");
    let (code, stderr) = scout_foxglove(&["serve", "--name", &name, "--listen", "127.0.0.1:0"]);
    assert_eq!(code, Some(3), "{stderr}");
}
