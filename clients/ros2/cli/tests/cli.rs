//! The `scout-ros2` command line: exit codes and the settings it prints. (This test also makes
//! `cargo test --workspace` build the `scout-ros2` binary that `scout ros2` runs in the system
//! tests.)

use std::process::Command;

const SCOUT_ROS2: &str = env!("CARGO_BIN_EXE_scout-ros2");

fn run(args: &[&str]) -> (Option<i32>, String, String) {
    let output = Command::new(SCOUT_ROS2)
        .args(args)
        .env_remove("ROS_DOMAIN_ID")
        .env_remove("RMW_IMPLEMENTATION")
        .output()
        .expect("run scout-ros2");
    (
        output.status.code(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(run(&["--no-such-flag"]).0, Some(2));
    let (code, _, stderr) = run(&["--node", "scout-1", "--print-config"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("scout-1"), "{stderr}");
}

#[test]
fn print_config_shows_the_settings_in_effect() {
    let (code, stdout, stderr) = run(&["--print-config", "--domain", "17", "--node", "base"]);
    assert_eq!(code, Some(0), "{stderr}");
    let settings: toml::Table = toml::from_str(&stdout).expect("TOML settings");
    assert_eq!(settings["domain"].as_integer(), Some(17), "{stdout}");
    assert_eq!(settings["node"].as_str(), Some("base"), "{stdout}");
}
