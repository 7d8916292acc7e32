//! The processes the bench starts: the simulator, the gateway, and its own roles, found beside
//! its executable and killed when dropped.

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::Receiver;
use std::time::Duration;

use anyhow::Context;

/// The directory of the bench's executable, where cargo puts the other binaries too.
pub fn bin_dir() -> anyhow::Result<PathBuf> {
    let exe = std::env::current_exe().context("finding the bench's executable")?;
    Ok(exe
        .parent()
        .context("the executable's directory")?
        .to_path_buf())
}

/// Builds the gateway, the simulator and `scout` with this profile when run by cargo (`cargo
/// run` builds only the bench), and checks they are there.
pub fn ensure_built() -> anyhow::Result<()> {
    let dir = bin_dir()?;
    if let Ok(cargo) = std::env::var("CARGO") {
        eprintln!("building scout-gateway, scout-sim, scout, scout-ros2 and scout-foxglove...");
        let mut build = Command::new(cargo);
        build.args([
            "build",
            "--quiet",
            "-p",
            "scout-gateway-daemon",
            "-p",
            "scout-sim",
            "-p",
            "scout-clients",
            "-p",
            "scout-ros2",
            "-p",
            "scout-foxglove",
            "--bins",
        ]);
        if dir.ends_with("release") {
            build.arg("--release");
        }
        anyhow::ensure!(
            build.status().context("running cargo build")?.success(),
            "building the gateway and the simulator failed"
        );
    }
    for name in ["scout-gateway", "scout-sim", "scout", "scout-foxglove"] {
        anyhow::ensure!(
            dir.join(name).exists(),
            "{} is missing: run `cargo build --release --workspace --bins` first",
            dir.join(name).display()
        );
    }
    Ok(())
}

/// A command for workspace binary `name`, quiet (`$SCOUT_BENCH_LOG`, e.g. `info`, for more in
/// the scratch directory's logs).
pub fn command(name: &str) -> anyhow::Result<Command> {
    command_through(&[], name)
}

/// [`command`] through `wrapper` (see [`through`]).
pub fn command_through(wrapper: &[&str], name: &str) -> anyhow::Result<Command> {
    let mut command = through(wrapper, bin_dir()?.join(name));
    let level = std::env::var("SCOUT_BENCH_LOG").unwrap_or_else(|_| "warn".into());
    command.env("RUST_LOG", level);
    Ok(command)
}

/// `program` run through `wrapper` (a program and its arguments that runs it as its child:
/// nsenter, a profiler), or directly when `wrapper` is empty.
fn through(wrapper: &[&str], program: impl AsRef<std::ffi::OsStr>) -> Command {
    match wrapper.split_first() {
        Some((wrapper, rest)) => {
            let mut command = Command::new(wrapper);
            command.args(rest).arg(program);
            command
        }
        None => Command::new(program),
    }
}

/// A running `scout-sim`.
#[derive(Debug)]
pub struct Sim {
    child: Child,
    stdin: ChildStdin,
    lines: Receiver<String>,
    pub port: String,
}

impl Sim {
    pub fn start(args: &[&str]) -> anyhow::Result<Sim> {
        let mut child = command("scout-sim")?
            .args(args)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .context("starting scout-sim")?;
        let stdin = child.stdin.take().context("scout-sim stdin")?;
        let stdout = child.stdout.take().context("scout-sim stdout")?;
        let (sender, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(stdout).lines() {
                let Ok(line) = line else { return };
                if sender.send(line).is_err() {
                    return;
                }
            }
        });
        let mut sim = Sim {
            child,
            stdin,
            lines,
            port: String::new(),
        };
        sim.port = sim.next_port_line()?;
        Ok(sim)
    }

    /// Waits for the next `TRANSPORT PATH` line (the port, after a start or an unplug).
    pub fn next_port_line(&mut self) -> anyhow::Result<String> {
        loop {
            let line = self
                .lines
                .recv_timeout(Duration::from_secs(10))
                .context("scout-sim announced no port within 10 s")?;
            if let Some((_, path)) = line.split_once(' ')
                && !line.starts_with('{')
            {
                return Ok(path.to_owned());
            }
        }
    }

    pub fn send(&mut self, command: &str) -> anyhow::Result<()> {
        writeln!(self.stdin, "{command}")?;
        Ok(self.stdin.flush()?)
    }

    /// How it ended, if it did (its exit status, or the signal that killed it).
    pub fn exited(&mut self) -> Option<std::process::ExitStatus> {
        self.child.try_wait().ok().flatten()
    }

    /// Quits, so that its trace is complete.
    pub fn quit(mut self) -> anyhow::Result<()> {
        self.send("quit")?;
        let _ = self.child.wait();
        Ok(())
    }
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A running `scout-gateway`, its log in a file.
#[derive(Debug)]
pub struct Gateway {
    child: Child,
}

impl Gateway {
    pub fn start(args: &[&str], log: &Path) -> anyhow::Result<Gateway> {
        Self::start_through(&[], args, log)
    }

    /// [`Gateway::start`] through `wrapper` (a program and its arguments that runs the gateway
    /// as its child, e.g. a profiler).
    pub fn start_through(wrapper: &[&str], args: &[&str], log: &Path) -> anyhow::Result<Gateway> {
        let log =
            std::fs::File::create(log).with_context(|| format!("creating {}", log.display()))?;
        let child = command_through(wrapper, "scout-gateway")?
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(log)
            .spawn()
            .context("starting scout-gateway")?;
        Ok(Gateway { child })
    }

    pub fn pid(&self) -> i32 {
        self.child.id() as i32
    }

    /// How it ended, if it did (its exit status, or the signal that killed it).
    pub fn exited(&mut self) -> Option<std::process::ExitStatus> {
        self.child.try_wait().ok().flatten()
    }

    pub fn kill(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Processes of the bench's own roles, waited for together.
#[derive(Debug, Default)]
pub struct Roles {
    children: Vec<Child>,
}

impl Roles {
    /// Starts `scout-bench ROLE ARGS`.
    pub fn spawn(&mut self, args: &[&str]) -> anyhow::Result<()> {
        self.spawn_through(&[], args)
    }

    /// Starts `WRAPPER... scout-bench ROLE ARGS` (`nice`, `setpriv`...).
    pub fn spawn_through(&mut self, wrapper: &[&str], args: &[&str]) -> anyhow::Result<()> {
        let child = through(wrapper, std::env::current_exe()?)
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .spawn()
            .with_context(|| format!("starting scout-bench {}", args.join(" ")))?;
        self.children.push(child);
        Ok(())
    }

    /// Waits for every one; a failure is an error.
    pub fn wait(&mut self) -> anyhow::Result<()> {
        for mut child in self.children.drain(..) {
            let status = child.wait()?;
            anyhow::ensure!(status.success(), "a bench process failed: {status}");
        }
        Ok(())
    }
}

impl Drop for Roles {
    fn drop(&mut self) {
        for child in &mut self.children {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// CPU time (user + system) of process `pid`, s, and its resident memory, MB.
pub fn usage(pid: i32) -> anyhow::Result<(f64, f64)> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat"))?;
    // Fields after the command name in parentheses: utime and stime are the 14th and 15th.
    let after = stat.rsplit_once(')').context("/proc/PID/stat")?.1;
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks: f64 = fields[11].parse::<f64>()? + fields[12].parse::<f64>()?;
    let hz = nix::unistd::sysconf(nix::unistd::SysconfVar::CLK_TCK)?.unwrap_or(100) as f64;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let rss_kb: f64 = status
        .lines()
        .find_map(|line| line.strip_prefix("VmRSS:"))
        .and_then(|value| value.split_whitespace().next())
        .and_then(|kb| kb.parse().ok())
        .unwrap_or(0.0);
    Ok((ticks / hz, rss_kb / 1024.0))
}
