//! The Python package (`clients/python`) against real gateways: its pytest suite, with the
//! workspace's binaries. It needs a Python with the package installed (`.ci/run` makes one:
//! `target/python-client-venv`, or `$SCOUT_PYTHON_CLIENT`); without one the test skips saying
//! how to make it, unless `SCOUT_REQUIRE_PYTHON` is set (as in CI): then it fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use scout_system_tests::skip;

/// The Python with `scout` installed, or why there is none.
fn python() -> Result<PathBuf, String> {
    let repository = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the repository");
    let python = std::env::var_os("SCOUT_PYTHON_CLIENT").map_or_else(
        || repository.join("target/python-client-venv/bin/python"),
        PathBuf::from,
    );
    let how = "python3 -m venv target/python-client-venv && target/python-client-venv/bin/pip \
               install ./clients/python pytest mypy (again after changing the package)";
    match Command::new(&python)
        .args(["-c", "import scout, pytest"])
        .output()
    {
        Ok(output) if output.status.success() => Ok(python),
        Ok(output) => Err(format!(
            "{} has no scout or pytest ({}): {how}",
            python.display(),
            String::from_utf8_lossy(&output.stderr).trim()
        )),
        Err(error) => Err(format!("no {}: {error}; {how}", python.display())),
    }
}

#[test]
fn the_python_package_passes_its_tests_against_real_gateways() {
    let test = "python_package";
    let python = match python() {
        Ok(python) => python,
        Err(why) => {
            assert!(
                std::env::var_os("SCOUT_REQUIRE_PYTHON").is_none(),
                "{test}: {why}"
            );
            return skip(test, &why);
        }
    };
    let bin_dir = scout_system_tests::bin("scout-gateway")
        .parent()
        .expect("the binaries' directory")
        .to_owned();
    let tests = Path::new(env!("CARGO_MANIFEST_DIR")).join("../clients/python/tests");
    let child = Command::new(python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider"])
        .arg(&tests)
        .env("SCOUT_BIN_DIR", &bin_dir)
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start pytest");
    let output = scout_system_tests::wait_output(child, Duration::from_secs(600));
    let stdout = String::from_utf8_lossy(&output.stdout);
    eprintln!("{test}: {}", stdout.lines().last().unwrap_or(""));
    assert!(
        output.status.success(),
        "pytest failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
}
