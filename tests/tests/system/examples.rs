//! The client examples against a gateway with the simulated chassis.

use std::time::Duration;

use scout_system_tests::{Gateway, connect, example, robot_name, run_with_input};

#[test]
fn square_example_drives_back_near_its_start() {
    let name = robot_name("square");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    let (code, _, stderr) = scout_system_tests::scout(&["resume", "--name", &name]);
    assert_eq!(code, Some(0), "{stderr}");
    let mut square = example("square");
    square.args([
        "--name",
        &name,
        "--side",
        "0.4",
        "--sides",
        "4",
        "--speed",
        "0.6",
        "--turn-rate",
        "0.5",
    ]);
    let output = run_with_input(square, b"", Duration::from_secs(90));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let done = stdout.lines().last().expect("a last line");
    let numbers: Vec<f64> = done
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    let [x, y, yaw] = numbers[..] else {
        panic!("{done}")
    };
    assert!(x.hypot(y) < 0.05, "back within 5 cm of the start: {done}");
    assert!(yaw.abs() < 0.1, "{done}");
}

#[test]
fn logger_example_writes_csv() {
    let name = robot_name("logger");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    let mut logger = example("logger");
    logger.args(["--name", &name, "--count", "20"]);
    let output = run_with_input(logger, b"", Duration::from_secs(20));
    assert!(
        output.status.success(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    let stdout = String::from_utf8_lossy(&output.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 21);
    assert!(lines[0].starts_with("seq,latency_us,link"));
    assert!(
        lines[1..]
            .iter()
            .all(|l| l.split(',').count() == 12 && l.contains(",ok,")),
        "{stdout}"
    );
}
