//! The port itself, when no gateway holds it: the device file (exists, readable and writable by
//! this user), opening it with the gateway's own code and lock, and listening to it. Nothing is
//! ever sent to the chassis (an slcan adapter gets its set-up lines, as from the gateway).

use std::io::ErrorKind;
use std::os::unix::fs::{FileTypeExt, MetadataExt};
use std::path::Path;
use std::time::{Duration, Instant};

use nix::unistd::{AccessFlags, Group, access};
use scout_gateway::device::{DeviceSpec, OpenError};
use scout_gateway::lock::LockError;

use crate::check::Check;
use crate::traffic::Traffic;

/// What opening the port found.
#[derive(Debug)]
pub enum Opened {
    /// Listened to: the tally.
    Listened(Box<Traffic>),
    /// A gateway holds it (its pid, if it wrote one).
    Held(Option<u32>),
    /// It could not be opened (the check says why).
    Failed,
}

/// The device file of a tty: it exists, is a character device, and this user may read and write
/// it.
pub fn tty_checks(path: &Path) -> Vec<Check> {
    let metadata = match std::fs::metadata(path) {
        Ok(metadata) => metadata,
        Err(error) if error.kind() == ErrorKind::NotFound => {
            return vec![Check::fail(
                "device",
                format!("no {}", path.display()),
                "plug the adapter in; `ls -l /dev/serial/by-id/` names USB serial adapters \
                 (use that path: it survives re-plugging); `dmesg | tail` shows what the kernel \
                 saw",
            )];
        }
        Err(error) => {
            return vec![Check::fail(
                "device",
                format!("{}: {error}", path.display()),
                "check the path",
            )];
        }
    };
    if !metadata.file_type().is_char_device() {
        return vec![Check::fail(
            "device",
            format!("{} is not a character device (a tty)", path.display()),
            "name the serial device, e.g. /dev/ttyUSB0",
        )];
    }
    if access(path, AccessFlags::R_OK | AccessFlags::W_OK).is_err() {
        let group = Group::from_gid(nix::unistd::Gid::from_raw(metadata.gid()))
            .ok()
            .flatten()
            .map_or_else(|| format!("gid {}", metadata.gid()), |group| group.name);
        return vec![Check::fail(
            "device",
            format!(
                "{} is not readable and writable by this user (mode {:o}, group {group})",
                path.display(),
                metadata.mode() & 0o777
            ),
            format!(
                "sudo usermod -aG {group} $USER, then log out and in again (or run the gateway \
                 as its service user)"
            ),
        )];
    }
    vec![Check::pass(
        "device",
        format!(
            "{} exists and this user may read and write it",
            path.display()
        ),
    )]
}

/// Opens `spec` as the gateway does (taking its lock) and listens for `window`.
pub fn listen(spec: &DeviceSpec, window: Duration, checks: &mut Vec<Check>) -> Opened {
    let started = Instant::now();
    let clock = |at: Instant| at.duration_since(started);
    let mut device = match spec.open(Duration::ZERO) {
        Ok(device) => device,
        Err(OpenError::Owned(LockError::Held { holder, .. })) => return Opened::Held(holder),
        Err(OpenError::Owned(error @ (LockError::Io { .. } | LockError::RunDir(_)))) => {
            checks.push(Check::fail(
                "port",
                error.to_string(),
                "the gateway's lock directory must be writable: set SCOUT_RUN_DIR or fix its \
                 permissions",
            ));
            return Opened::Failed;
        }
        Err(OpenError::Io(error)) => {
            // A gateway of another run directory holds the tty without holding this lock: its
            // exclusive open refuses ours, whatever the error's kind says.
            let holders = match spec {
                DeviceSpec::Serial(path) | DeviceSpec::Slcan(path) => holders_of(path),
                DeviceSpec::Can(_) | DeviceSpec::GsUsb { .. } | DeviceSpec::Sim { .. } => {
                    Vec::new()
                }
            };
            let fix = match (holders.is_empty(), error.kind()) {
                (false, _) => format!(
                    "held by {} (a gateway of another run directory or user takes no lock \
                     here): stop it, or check its robot with `scout doctor --name ROBOT`",
                    holders.join(", ")
                ),
                (true, ErrorKind::PermissionDenied) => "this user may not open it: add it to the \
                     device's group (dialout), or run as the gateway's user"
                    .into(),
                (true, ErrorKind::NotFound) if !Path::new(&spec.name()).exists() => {
                    "the device or interface is gone: plug it in".into()
                }
                (true, _) => "another program may hold it (`fuser -v DEVICE` tells which: a \
                     ModemManager or a terminal program)"
                    .into(),
            };
            checks.push(Check::fail(
                "port",
                format!("opening {}: {error}", spec.name()),
                fix,
            ));
            return Opened::Failed;
        }
        Err(OpenError::GsUsb(error)) => {
            checks.push(Check::fail(
                "port",
                error.to_string(),
                "the `usb.adapter` checks above say what is plugged in and who holds it",
            ));
            return Opened::Failed;
        }
    };
    checks.push(Check::pass(
        "port",
        format!("opened {} (no gateway holds it)", spec.name()),
    ));
    let mut traffic = Traffic::new();
    let mut buffer = [0_u8; 4096];
    // The window counts from the open, and what arrived is read once more after it ends: a
    // doctor the host stalls past its window (a loaded Jetson) still counts what the kernel
    // queued meanwhile, rather than reporting a silent bus.
    let deadline = Instant::now() + window;
    loop {
        let ended = Instant::now() >= deadline;
        let now = clock(Instant::now());
        let result = device.receive(now, true, &mut buffer, |event| traffic.handle(&event, now));
        if let Err(error) = result {
            checks.push(Check::fail(
                "port.read",
                format!("reading {}: {error}", spec.name()),
                "a CAN bus-off or error-passive controller (see can.state), or the adapter was \
                 unplugged",
            ));
            break;
        }
        if ended {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    traffic.discarded_bytes = device.discarded_bytes();
    Opened::Listened(Box::new(traffic))
}

/// The processes that have `device` open, as "NAME (pid N, robot R)" (the robot from a
/// gateway's `--name`), gateways first: what `fuser` would say, read from `/proc/PID/fd` (only
/// the processes this user may look at).
pub fn holders_of(device: &Path) -> Vec<String> {
    let Ok(device) = std::fs::canonicalize(device) else {
        return Vec::new();
    };
    let Ok(processes) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    let mut holders = Vec::new();
    for process in processes.flatten() {
        let Some(pid) = process
            .file_name()
            .to_str()
            .and_then(|pid| pid.parse::<u32>().ok())
        else {
            continue;
        };
        if pid == std::process::id() {
            continue;
        }
        let Ok(fds) = std::fs::read_dir(process.path().join("fd")) else {
            continue;
        };
        let holds = fds
            .flatten()
            .any(|fd| std::fs::read_link(fd.path()).is_ok_and(|target| target == device));
        if holds {
            holders.push(describe_process(pid));
        }
    }
    holders.sort_by_key(|holder| !holder.starts_with("scout-gateway"));
    holders
}

/// "NAME (pid N)", with ", robot R" for a process given `--name R` (a gateway).
fn describe_process(pid: u32) -> String {
    let name = std::fs::read_to_string(format!("/proc/{pid}/comm"))
        .map(|comm| comm.trim().to_owned())
        .unwrap_or_else(|_| "a process".into());
    let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
    let args: Vec<String> = cmdline
        .split(|byte| *byte == 0)
        .map(|arg| String::from_utf8_lossy(arg).into_owned())
        .collect();
    let robot = args
        .iter()
        .enumerate()
        .find_map(|(at, arg)| match arg.as_str() {
            "--name" => args.get(at + 1).cloned(),
            _ => arg.strip_prefix("--name=").map(str::to_owned),
        });
    match robot {
        Some(robot) => format!("{name} (pid {pid}, robot {robot})"),
        None => format!("{name} (pid {pid})"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_process_holding_a_device_is_named_with_its_robot() {
        let file = std::env::temp_dir().join(format!("scout-doctor-held-{}", std::process::id()));
        std::fs::write(&file, b"").expect("file");
        let held = std::fs::File::open(&file).expect("open");
        let mut holder = std::process::Command::new("sh")
            .args(["-c", "exec sleep 30", "--name", "ignored"])
            .stdin(held)
            .spawn()
            .expect("sh");
        let deadline = Instant::now() + Duration::from_secs(5);
        let expected = format!("sleep (pid {})", holder.id());
        let mut seen = holders_of(&file);
        while !seen.contains(&expected) && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
            seen = holders_of(&file);
        }
        let _ = holder.kill();
        let _ = holder.wait();
        let _ = std::fs::remove_file(&file);
        assert!(seen.contains(&expected), "{seen:?}");
        assert!(holders_of(Path::new("/nonexistent/tty")).is_empty());
    }
}
