//! The Python package (`clients/python`) against real gateways: its pytest suite, with the
//! workspace's binaries. It needs a Python with the package installed (`.ci/run` makes one:
//! `target/python-client-venv`, or `$SCOUT_PYTHON_CLIENT`); without one the test skips saying
//! how to make it, unless `SCOUT_REQUIRE_PYTHON` is set (as in CI): then it fails.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use iceoryx2::prelude::ZeroCopySend;
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
               install ./clients/python 'pytest==8.*' 'mypy==1.*' (again after changing the package)";
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
    let bin_dir = scout_system_tests::built_bin_dir();
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

/// The state payload of the layout before this one: a gateway built from an older release.
#[derive(Debug, Clone, Copy, Default, ZeroCopySend)]
#[type_name("scout::StatePayload.v5")]
#[repr(C)]
struct OlderState {
    seq: u64,
}

#[test]
fn a_gateway_of_another_interface_version_is_a_version_error_saying_what_the_cli_says() {
    let test = "python_version_error";
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
    // What an older gateway leaves in shared memory: the state services with its own layout.
    let name = scout_system_tests::robot_name("py-version");
    let service = scout_clients::interface::services::state_service(&name);
    let node = scout_clients::interface::services::node("older-gateway")
        .expect("an iceoryx2 node, in the shared-memory directory");
    let service_name: iceoryx2::prelude::ServiceName =
        service.as_str().try_into().expect("a service name");
    let _events = node
        .service_builder(&service_name)
        .event()
        .open_or_create()
        .expect("the event service");
    let _older = node
        .service_builder(&service_name)
        .publish_subscribe::<OlderState>()
        .open_or_create()
        .expect("an older state service");
    let (code, _, cli) = scout_system_tests::scout(&["status", "--name", &name]);
    assert_eq!(code, Some(1), "{cli}");
    assert!(cli.contains("another interface version"), "{cli}");
    let script = format!(
        "import scout\n\
         try:\n    scout.Robot.connect({name:?})\n\
         except scout.VersionError as error:\n    print('scout: ' + str(error))\n\
         else:\n    raise SystemExit('connected to another layout')\n"
    );
    let output = Command::new(python)
        .args(["-c", &script])
        .stdin(Stdio::null())
        .output()
        .expect("run python");
    let said = String::from_utf8_lossy(&output.stdout);
    assert!(
        output.status.success(),
        "{said}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert_eq!(said.trim(), cli.trim(), "the same message as the CLI");
}
