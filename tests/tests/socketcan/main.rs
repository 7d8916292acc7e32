//! SocketCAN end to end: the gateway and the simulator on a virtual CAN bus of each test's own,
//! can-utils as the independent peer, CAN faults, a gs_usb adapter emulated on USB (through the
//! kernel's driver and in user space), and zenoh over a lossy, partitioned network, plain and
//! inside a WireGuard tunnel.
//!
//! Each test needs to create network interfaces (root, the `vcan` and `sch_netem` modules).
//! Where it cannot, it prints why and skips, and `socketcan_tests_in_a_vm` runs this whole
//! binary inside a micro-VM whose kernel can (`tests/vm/run`). `SCOUT_TEST_CAN=can0` runs them
//! on a real interface instead (`--test-threads 1`; see docs/development.md).

mod bus;
mod can_utils;
mod doctor;
mod faults;
mod gs_usb;
mod netem;
mod netem_bench;
mod wireguard;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

use scout_system_tests::skip;

/// How long a test waits for one expected event: generous, as the VM emulates its CPU.
pub const LIMIT: Duration = Duration::from_secs(30);

/// Set inside the VM, where the tests below run instead of skipping.
const IN_VM: &str = "SCOUT_IN_VM";

/// Names a real CAN interface to run the tests on instead of vcan interfaces of their own
/// (one test at a time: they share it).
const REAL_INTERFACE: &str = "SCOUT_TEST_CAN";

/// The CAN interface of one test: a vcan interface of its own, up, deleted when dropped; or the
/// real interface `SCOUT_TEST_CAN` names, left as it is.
#[derive(Debug)]
pub struct Bus {
    name: String,
    real: bool,
}

impl Bus {
    /// A new vcan interface for `test` (or the real one), or `None` (with the reason printed)
    /// where none can be made.
    pub fn create(test: &str) -> Option<Bus> {
        static NEXT: AtomicUsize = AtomicUsize::new(0);
        if let Some(name) = std::env::var_os(REAL_INTERFACE) {
            return Some(Bus {
                name: name.to_string_lossy().into_owned(),
                real: true,
            });
        }
        let name = format!(
            "sc{}x{}",
            std::process::id() % 100_000,
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        let bus = Bus { name, real: false };
        match bus.add() {
            Ok(()) => Some(bus),
            Err(reason) => {
                skip(
                    test,
                    &format!(
                        "cannot create a vcan interface here ({reason}); \
                         socketcan_tests_in_a_vm runs this test in a VM"
                    ),
                );
                None
            }
        }
    }

    /// The interface's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether it is a real interface (which tests cannot delete or inject error frames into).
    pub fn is_real(&self) -> bool {
        self.real
    }

    /// Creates the interface and sets it up.
    pub fn add(&self) -> Result<(), String> {
        ip(&["link", "add", &self.name, "type", "vcan"])?;
        self.set_up(true)
    }

    /// `ip link set NAME up` or `down`.
    pub fn set_up(&self, up: bool) -> Result<(), String> {
        ip(&["link", "set", &self.name, if up { "up" } else { "down" }])
    }

    /// Deletes the interface, as when a USB adapter is unplugged.
    pub fn delete(&self) -> Result<(), String> {
        ip(&["link", "del", &self.name])
    }
}

impl Drop for Bus {
    fn drop(&mut self) {
        if !self.real {
            let _ = self.delete();
        }
    }
}

/// Runs `ip ARGS`, returning its complaint when it fails.
pub fn ip(args: &[&str]) -> Result<(), String> {
    run("ip", args)
}

/// Runs `tc ARGS`, returning its complaint when it fails.
pub fn tc(args: &[&str]) -> Result<(), String> {
    run("tc", args)
}

fn run(program: &str, args: &[&str]) -> Result<(), String> {
    let output = Command::new(program)
        .args(args)
        .output()
        .map_err(|error| format!("{program}: {error}"))?;
    if output.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`{program} {}`: {}",
            args.join(" "),
            String::from_utf8_lossy(&output.stderr).trim()
        ))
    }
}

/// Whether can-utils is installed, printing why `test` skips if not.
pub fn can_utils(test: &str) -> bool {
    let found = ["candump", "cansend", "cangen"].iter().all(|tool| {
        std::env::var_os("PATH")
            .is_some_and(|path| std::env::split_paths(&path).any(|dir| dir.join(tool).exists()))
    });
    if !found {
        skip(
            test,
            "can-utils is not installed (apt-get install can-utils)",
        );
    }
    found
}

fn vm_runner() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("vm/run")
}

/// Runs this test binary inside the VM where this kernel cannot make vcan interfaces.
#[test]
fn socketcan_tests_in_a_vm() {
    const TEST: &str = "socketcan_tests_in_a_vm";
    if std::env::var_os(IN_VM).is_some() {
        return;
    }
    let probe = Bus {
        name: format!("scprobe{}", std::process::id() % 100_000),
        real: false,
    };
    if std::env::var_os(REAL_INTERFACE).is_some() || probe.add().is_ok() {
        skip(
            TEST,
            "this kernel has vcan: the SocketCAN tests ran directly",
        );
        return;
    }
    let check = Command::new(vm_runner())
        .arg("--check")
        .output()
        .expect("run tests/vm/run --check");
    if !check.status.success() {
        let why = String::from_utf8_lossy(&check.stdout).trim().to_owned();
        // CI sets it where it installed the VM's packages: a VM that cannot run is a failure.
        assert!(
            std::env::var_os("SCOUT_REQUIRE_VM").is_none(),
            "{TEST}: no VM here: {why}"
        );
        skip(TEST, &why);
        return;
    }
    // Built here, on the host: inside, the emulated CPU would take an hour to compile them.
    scout_system_tests::bin("scout-gateway");
    let exe = std::env::current_exe().expect("this test binary");
    let status = Command::new(vm_runner())
        .args(["--timeout", "900", "--"])
        .arg("env")
        .arg(format!("{IN_VM}=1"))
        .arg(exe)
        .args(["--skip", TEST, "--test-threads", "1", "--color", "never"])
        .status()
        .expect("run tests/vm/run");
    assert!(
        status.success(),
        "the SocketCAN tests failed inside the VM ({status}): their output is above"
    );
}
