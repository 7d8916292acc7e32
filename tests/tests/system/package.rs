//! The Debian package (`tests/release/deb`), made from this build's binaries: what it holds,
//! lintian, and installing, upgrading, removing and purging it in a throwaway root (never this
//! machine's own system), where its programs run and systemd accepts its unit as installed.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use scout_system_tests::{TempDir, robot_name, skip};

const TEST: &str = "the_debian_package_installs_upgrades_and_purges_in_a_throwaway_root";
/// CI sets it where it installed dpkg-dev, lintian and systemd: the test then fails rather
/// than skip.
const REQUIRE: &str = "SCOUT_REQUIRE_PACKAGE_CHECKS";
const CONFFILE: &str = "etc/scout/scout-gateway.toml";

fn script() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("release/deb")
}

fn run(command: &mut Command) -> Output {
    let output = command
        .output()
        .unwrap_or_else(|e| panic!("run {command:?}: {e}"));
    assert!(
        output.status.success(),
        "{command:?} failed ({}):\n{}{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

fn text(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// Why the checks cannot run here, if they cannot.
fn missing_tools() -> Option<String> {
    if !nix::unistd::geteuid().is_root() {
        return Some("not root: the throwaway root's files must belong to root".into());
    }
    let missing: Vec<&str> = ["dpkg-deb", "dpkg", "lintian", "systemd-analyze", "objdump"]
        .into_iter()
        .filter(|tool| {
            !Command::new("sh")
                .args(["-c", &format!("command -v {tool}")])
                .output()
                .is_ok_and(|o| o.status.success())
        })
        .collect();
    (!missing.is_empty()).then(|| {
        format!(
            "{} missing (apt-get install dpkg-dev lintian systemd binutils)",
            missing.join(", ")
        )
    })
}

/// The package of revision `revision`, made in `out`.
fn package(out: &Path, revision: u32) -> PathBuf {
    let bin_dir = scout_system_tests::built_bin_dir();
    let arch = text(&run(Command::new("dpkg").arg("--print-architecture")));
    let made = run(Command::new(script())
        .arg(&bin_dir)
        .arg(arch.trim())
        .arg(out)
        .env("DEB_REVISION", revision.to_string())
        .env("DEB_COMPRESSION", "gzip")
        .env("DEB_LEVEL", "1"));
    PathBuf::from(text(&made).trim())
}

/// `dpkg` on the throwaway root `root`: maintainer scripts run outside a chroot with
/// `DPKG_ROOT` set; the dependencies (libc6, systemd) are this host's, not the root's.
fn dpkg(root: &Path, args: &[&str]) -> Output {
    run(Command::new("dpkg")
        .arg(format!("--root={}", root.display()))
        .args([
            "--force-script-chrootless",
            "--force-depends",
            "--force-confold",
        ])
        .args(args))
}

#[test]
fn the_debian_package_installs_upgrades_and_purges_in_a_throwaway_root() {
    if let Some(why) = missing_tools() {
        assert!(std::env::var_os(REQUIRE).is_none(), "{TEST}: {why}");
        skip(TEST, &why);
        return;
    }
    let dir = TempDir::new(&robot_name("deb"));
    let first = package(&dir.path().join("1"), 1);

    // What it holds: every program and its manual page, the unit, the configuration as a
    // conffile, the glibc floor.
    let listing = text(&run(Command::new("dpkg-deb").arg("--contents").arg(&first)));
    let programs = text(&run(Command::new(script()).arg("--programs")));
    for file in programs
        .split_whitespace()
        .flat_map(|program| {
            [
                format!("./usr/bin/{program}"),
                format!("./usr/share/man/man1/{program}.1.gz"),
            ]
        })
        .chain(
            // A subcommand's page, as git's.
            ["./usr/share/man/man1/scout-status.1.gz"].map(str::to_owned),
        )
        .chain(
            [
                "./usr/lib/systemd/system/scout-gateway.service",
                "./usr/lib/sysusers.d/scout-gateway.conf",
                "./usr/lib/tmpfiles.d/scout-gateway.conf",
                "./usr/lib/systemd/network/80-scout-can.network",
                "./usr/share/doc/scout-gateway/copyright",
                "./usr/share/doc/scout-gateway/examples/zenoh-wireguard-gateway.json5",
                "./usr/share/doc/scout-gateway/examples/zenoh-wireguard-operator.json5",
                "./usr/share/doc/scout-gateway/examples/zenoh-tls-gateway.json5",
                "./etc/scout/scout-gateway.toml",
            ]
            .map(str::to_owned),
        )
    {
        assert!(
            listing.lines().any(|line| line.ends_with(&file)),
            "{file} not in the package:\n{listing}"
        );
    }
    let depends = text(&run(Command::new("dpkg-deb")
        .args(["--field"])
        .arg(&first)
        .arg("Depends")));
    assert!(depends.starts_with("libc6 (>= 2."), "{depends}");

    // lintian: no error (warnings are printed).
    let lint = Command::new("lintian")
        .arg(&first)
        .output()
        .expect("run lintian");
    let lint_out = String::from_utf8_lossy(&lint.stdout);
    eprintln!("lintian:\n{lint_out}");
    assert!(
        !lint_out.lines().any(|line| line.starts_with("E:")),
        "lintian found errors:\n{lint_out}"
    );
    // Every program has its manual page, and lintian finds nothing wrong in them.
    let about_pages: Vec<&str> = lint_out
        .lines()
        .filter(|line| line.contains("manual-page") || line.contains("manpage"))
        .collect();
    assert!(
        about_pages.is_empty(),
        "lintian about the manual pages:\n{}",
        about_pages.join("\n")
    );

    // Installed into an empty root with a dpkg database of its own.
    let root = dir.path().join("root");
    for sub in ["var/lib/dpkg/info", "var/lib/dpkg/updates", "etc"] {
        std::fs::create_dir_all(root.join(sub)).expect("make the throwaway root");
    }
    std::fs::write(root.join("var/lib/dpkg/status"), "").expect("dpkg status");
    std::fs::write(root.join("etc/passwd"), "root:x:0:0:root:/root:/bin/sh\n").expect("passwd");
    std::fs::write(root.join("etc/group"), "root:x:0:\ndialout:x:20:\n").expect("group");
    dpkg(&root, &["--install", &first.to_string_lossy()]);

    // Its programs run (scout-ros2 too, but it speaks DDS: only inside a network namespace,
    // which `--version` does not need to reach).
    for program in programs.split_whitespace().filter(|p| *p != "scout-ros2") {
        run(Command::new(root.join("usr/bin").join(program)).arg("--version"));
    }
    // The user, in dialout, and its run directory.
    let passwd = std::fs::read_to_string(root.join("etc/passwd")).expect("passwd");
    let user = passwd
        .lines()
        .find(|line| line.starts_with("scout:"))
        .unwrap_or_else(|| panic!("no user scout:\n{passwd}"));
    let uid: u32 = user
        .split(':')
        .nth(2)
        .and_then(|u| u.parse().ok())
        .expect("uid");
    let group = std::fs::read_to_string(root.join("etc/group")).expect("group");
    assert!(
        group
            .lines()
            .any(|line| line.starts_with("dialout:") && line.ends_with("scout")),
        "scout is not in dialout:\n{group}"
    );
    let run_dir = std::fs::metadata(root.join("var/lib/scout")).expect("the run directory");
    assert_eq!(std::os::unix::fs::MetadataExt::uid(&run_dir), uid);
    // The shared memory's directory: the gateway user's, its group's members are the clients.
    let ipc = std::fs::metadata(root.join("run/scout")).expect("the shared-memory directory");
    assert_eq!(std::os::unix::fs::MetadataExt::uid(&ipc), uid);
    assert_eq!(std::os::unix::fs::MetadataExt::mode(&ipc) & 0o7777, 0o770);

    // systemd accepts the unit as installed (its ExecStart in the root), with not one warning;
    // the units it names (network-online.target...) are this host's.
    let units = root.join("usr/lib/systemd/system");
    run(Command::new("cp")
        .arg("-rn")
        .arg("/usr/lib/systemd/system/.")
        .arg(&units));
    let verify = run(Command::new("systemd-analyze")
        .arg("verify")
        .arg(format!("--root={}", root.display()))
        .arg("scout-gateway.service"));
    let complaints = String::from_utf8_lossy(&verify.stderr);
    assert!(
        complaints.trim().is_empty(),
        "systemd-analyze verify: {complaints}"
    );
    // Its confinement holds (docs/operating.md gives the figure, and what it leaves open).
    let security = run(Command::new("systemd-analyze")
        .args(["security", "--offline=true"])
        .arg(format!("--root={}", root.display()))
        .arg(units.join("scout-gateway.service")));
    let rating = String::from_utf8_lossy(&security.stdout);
    let exposure: f64 = rating
        .lines()
        .find_map(|line| line.split("Overall exposure level for").nth(1))
        .and_then(|rest| rest.split(':').nth(1))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|number| number.parse().ok())
        .unwrap_or_else(|| panic!("no exposure level in: {rating}"));
    assert!(
        exposure <= 3.0,
        "systemd-analyze security: {exposure}\n{rating}"
    );

    // The operator changes the configuration; an upgrade keeps the change.
    let conffile = root.join(CONFFILE);
    let mut changed = std::fs::read_to_string(&conffile).expect("the configuration");
    changed.push_str("\n# changed by the operator\n");
    std::fs::write(&conffile, &changed).expect("change the configuration");
    let second = package(&dir.path().join("2"), 2);
    dpkg(&root, &["--install", &second.to_string_lossy()]);
    let status = text(&dpkg(&root, &["--status", "scout-gateway"]));
    let version = format!("Version: {}-2", env!("CARGO_PKG_VERSION"));
    assert!(status.lines().any(|line| line == version), "{status}");
    assert!(
        status.contains("/etc/scout/scout-gateway.toml"),
        "not a conffile: {status}"
    );
    assert_eq!(
        std::fs::read_to_string(&conffile).expect("the configuration"),
        changed,
        "the upgrade replaced the operator's configuration"
    );

    // Removed: the programs go, the configuration and the run directory stay.
    dpkg(&root, &["--remove", "scout-gateway"]);
    assert!(!root.join("usr/bin/scout-gateway").exists());
    assert!(conffile.exists(), "remove took the configuration");
    assert!(root.join("var/lib/scout").exists());
    // Purged: both go; the user stays (files may still belong to it), as Debian keeps them.
    dpkg(&root, &["--purge", "scout-gateway"]);
    assert!(!conffile.exists(), "purge left the configuration");
    assert!(
        !root.join("var/lib/scout").exists(),
        "purge left the run directory"
    );
}
