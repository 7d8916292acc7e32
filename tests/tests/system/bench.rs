//! `scout-bench --quick`: the benchmark runs end to end and writes every figure it promises. It
//! checks that the bench works, never how fast anything is.

use std::time::Duration;

use scout_system_tests::{command, run_with_input};

#[test]
fn the_quick_bench_runs_and_writes_its_figures() {
    let dir = std::env::temp_dir().join(format!("scout-bench-test-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch directory");
    let json = dir.join("figures.json");
    let mut bench = command("scout-bench");
    // Its own cargo build is for `cargo run`; here the test build made the binaries.
    bench
        .env_remove("CARGO")
        .args(["--quick", "--client-priority", "0", "--json"])
        .arg(&json);
    let output = run_with_input(bench, b"", Duration::from_secs(240));
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    let table = String::from_utf8_lossy(&output.stdout);
    assert!(table.contains("| state, iceoryx2 (µs) |"), "{table}");
    let figures: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).expect("the JSON file"))
            .expect("JSON");
    let summary = ["p50", "p99", "max"];
    let mut expected: Vec<(String, &[&str])> = Vec::new();
    for path in ["iceoryx2", "zenoh", "direct", "iceoryx2_8", "iceoryx2_32"] {
        expected.push((
            format!("/state_latency_us/{path}"),
            &["p50", "p99", "p999", "max", "n"],
        ));
    }
    for key in [
        "gateway_part_us",
        "command_latency_us",
        "estop_latency_us",
        "estop_latency_flood_us",
    ] {
        expected.push((format!("/{key}"), &summary));
    }
    for condition in ["idle", "loaded", "flood"] {
        expected.push((
            format!("/tick_interval_ms/{condition}"),
            &["mean", "p99_dev", "max", "over_25", "over_40"],
        ));
    }
    for black_box in ["off", "saving"] {
        expected.push((
            format!("/black_box/{black_box}"),
            &["mean", "p99_dev", "max", "over_25"],
        ));
    }
    for (pointer, fields) in expected {
        for field in fields {
            let value = figures.pointer(&format!("{pointer}/{field}"));
            assert!(
                value.is_some_and(serde_json::Value::is_number),
                "{pointer}/{field} missing: {figures}"
            );
        }
        assert!(
            figures.pointer(&format!("{pointer}/n")).is_none()
                || figures
                    .pointer(&format!("{pointer}/n"))
                    .and_then(serde_json::Value::as_u64)
                    > Some(0),
            "{pointer} has no samples: {figures}"
        );
    }
    for pointer in [
        "/recovery_ms/restart",
        "/recovery_ms/reconnect",
        "/gateway_cpu_percent",
        "/gateway_rss_mb",
        "/black_box_save_ms",
        "/black_box_file_mb",
    ] {
        assert!(
            figures
                .pointer(pointer)
                .is_some_and(serde_json::Value::is_number),
            "{pointer} missing: {figures}"
        );
    }
    let _ = std::fs::remove_dir_all(dir);
}
