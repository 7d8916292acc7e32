//! The release's quick-start check (`tests/release/smoke`, which `tests/release/build` runs on
//! every architecture's programs), on this build's programs: so that the check a release relies
//! on is itself checked on every change.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use scout_system_tests::{IpcDomain, TempDir, robot_name, wait_output};

#[test]
fn the_release_quick_start_check_passes_on_this_builds_programs() {
    let test = "release_smoke";
    let domain = IpcDomain::new(&robot_name(test));
    let run_dir = TempDir::new(&robot_name(test));
    let bin_dir = scout_system_tests::built_bin_dir();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("release/smoke");
    // The script bounds every step (60 s for the first state, 10 s of silence for the others),
    // and the whole run is bounded here too.
    let child = Command::new(&script)
        .arg(&bin_dir)
        .env(domain.env().0, domain.env().1)
        .env("SCOUT_RUN_DIR", run_dir.path())
        .env_remove("RUNNER")
        .env_remove("PYTHON")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("run {}: {e}", script.display()));
    let output = wait_output(child, Duration::from_secs(180));
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{test}: {} failed ({}):\n{stdout}{}",
        script.display(),
        output.status,
        String::from_utf8_lossy(&output.stderr)
    );
    for step in [
        "state read",
        "moved the chassis",
        "latched",
        "stopped the gateway with 0",
    ] {
        assert!(stdout.contains(step), "{test}: no '{step}' in:\n{stdout}");
    }
}
