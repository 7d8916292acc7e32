//! `scout-bench soak MINUTES`: churns clients against a gateway on the simulator for a given time
//! (controllers that take, drive and give up control, stops and releases, clients killed by
//! SIGKILL and stopped by SIGSTOP, a request flood) and samples the gateway's resident memory,
//! open files and threads, and the shared-memory files, every 10 s. It prints each one's first
//! and last value and its slope per hour after the warm-up ([`WARM_UP`]: the black box's ring
//! full, every service made), so that a long run says "flat" with a number.

use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use anyhow::Context;
use serde_json::json;

use crate::procs::{self, Gateway, Sim};

/// What the slopes leave out: the black box's ring filling (the gateway's default `[blackbox]
/// minutes`, 5: the simulator's frames fill it in that time, up to 12 MB, as designed), every
/// service and the first clients' made (the first rounds), and a minute more.
const WARM_UP: Duration = Duration::from_secs(6 * 60);

/// The samples the slopes are taken over, and what they leave out, in words: those after the
/// warm-up; in a run too short to have three of them, those after the first fifth (saying so).
fn after_warm_up(samples: &[Sample]) -> (&[Sample], String) {
    let warm = WARM_UP.as_secs_f64();
    let from = samples.partition_point(|sample| sample.at < warm);
    if samples.len().saturating_sub(from) >= 3 {
        (
            &samples[from..],
            format!("after the warm-up of {} min", WARM_UP.as_secs() / 60),
        )
    } else {
        (
            &samples[samples.len() / 5..],
            format!(
                "after the first fifth: shorter than the {} min warm-up, mostly warm-up",
                WARM_UP.as_secs() / 60
            ),
        )
    }
}

/// A figure of a sample, and its label.
type Metric = (&'static str, fn(&Sample) -> f64);

/// One sample of the gateway's resources.
#[derive(Debug, Clone, Copy)]
struct Sample {
    /// Since the start, s.
    at: f64,
    rss_mb: f64,
    /// The kernel's split of it (`/proc/PID/status`): anonymous memory (the heap, stacks),
    /// shared memory (iceoryx2's segments the gateway touched), mapped files.
    rss_anon_mb: f64,
    rss_shmem_mb: f64,
    rss_file_mb: f64,
    open_files: f64,
    threads: f64,
    shm_files: f64,
}

fn sample(pid: i32, at: f64) -> anyhow::Result<Sample> {
    let (_, rss_mb) = procs::usage(pid)?;
    let open_files = std::fs::read_dir(format!("/proc/{pid}/fd"))?.count() as f64;
    let status = std::fs::read_to_string(format!("/proc/{pid}/status"))?;
    let field = |name: &str| {
        (status.lines())
            .find_map(|line| line.strip_prefix(name))
            .and_then(|value| {
                value
                    .trim()
                    .trim_end_matches("kB")
                    .trim()
                    .parse::<f64>()
                    .ok()
            })
            .unwrap_or(0.0)
    };
    let threads = field("Threads:");
    let (rss_anon_mb, rss_shmem_mb, rss_file_mb) = (
        field("RssAnon:") / 1024.0,
        field("RssShmem:") / 1024.0,
        field("RssFile:") / 1024.0,
    );
    let shm_files = std::fs::read_dir("/dev/shm").map_or(0, |dir| dir.count()) as f64;
    Ok(Sample {
        at,
        rss_mb,
        rss_anon_mb,
        rss_shmem_mb,
        rss_file_mb,
        open_files,
        threads,
        shm_files,
    })
}

/// The least-squares slope of `points` (x in s), per hour.
fn slope_per_hour(points: &[(f64, f64)]) -> f64 {
    let n = points.len() as f64;
    if n < 2.0 {
        return 0.0;
    }
    let mean_x = points.iter().map(|(x, _)| x).sum::<f64>() / n;
    let mean_y = points.iter().map(|(_, y)| y).sum::<f64>() / n;
    let cov: f64 = points
        .iter()
        .map(|(x, y)| (x - mean_x) * (y - mean_y))
        .sum();
    let var: f64 = points.iter().map(|(x, _)| (x - mean_x).powi(2)).sum();
    if var == 0.0 { 0.0 } else { cov / var * 3600.0 }
}

/// `scout ARGS` in the background, quiet.
fn scout(args: &[&str]) -> anyhow::Result<Child> {
    procs::command("scout")?
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .context("starting scout")
}

/// One round of churn, about two seconds long.
fn churn(name: &str, round: u64) -> anyhow::Result<()> {
    let client = format!("soak-{}", round % 50);
    // A controller that takes control, drives and gives it up.
    let mut drive = scout(&[
        "drive",
        "--name",
        name,
        "--linear",
        "0.2",
        "--duration",
        "1",
        "--client",
        &client,
    ])?;
    // One killed while it drives (a dead client), one stopped (a stalled client).
    let mut killed = scout(&["drive", "--name", name, "--linear", "0.1"])?;
    let mut stopped = scout(&["status", "--name", name, "--json"])?;
    let stopped_pid = nix::unistd::Pid::from_raw(stopped.id() as i32);
    let _ = nix::sys::signal::kill(stopped_pid, nix::sys::signal::Signal::SIGSTOP);
    // A burst of requests from a client of its own.
    let exe = std::env::current_exe()?;
    let mut flood = std::process::Command::new(exe)
        .args(["flood", name, "200", "1"])
        .stdout(Stdio::null())
        .spawn()?;
    std::thread::sleep(Duration::from_millis(600));
    let _ = killed.kill();
    let _ = killed.wait();
    let _ = nix::sys::signal::kill(stopped_pid, nix::sys::signal::Signal::SIGKILL);
    let _ = stopped.wait();
    let _ = drive.wait();
    let _ = flood.wait();
    // A person's stop and release.
    scout(&["estop", "--name", name, "--reason", "soak"])?.wait()?;
    scout(&["release", "--name", name])?.wait()?;
    Ok(())
}

/// The process named `name` among `pid`'s children, waited for up to 10 s (a wrapper starts it).
fn child_named(pid: i32, name: &str) -> anyhow::Result<i32> {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let children =
            std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children")).unwrap_or_default();
        for child in children.split_whitespace() {
            let comm = std::fs::read_to_string(format!("/proc/{child}/comm")).unwrap_or_default();
            if comm.trim() == name {
                return Ok(child.parse()?);
            }
        }
        anyhow::ensure!(
            Instant::now() < deadline,
            "no {name} started under process {pid} within 10 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The gateway under heaptrack: its data file, then what it says.
struct HeapProfile {
    /// The data file's path without heaptrack's suffix (`.zst` or `.gz`).
    output: std::path::PathBuf,
}

impl HeapProfile {
    fn new(scratch: &Path) -> anyhow::Result<Self> {
        let found = std::process::Command::new("heaptrack")
            .arg("--version")
            .output()
            .is_ok_and(|output| output.status.success());
        anyhow::ensure!(
            found,
            "--heap-profile runs the gateway under heaptrack, which is not installed: apt install heaptrack"
        );
        Ok(Self {
            output: scratch.join("gateway-heap"),
        })
    }

    /// The wrapper the gateway runs under.
    fn wrapper(&self) -> Vec<String> {
        vec![
            "heaptrack".into(),
            "-o".into(),
            self.output.display().to_string(),
        ]
    }

    /// Prints the live heap's first and last size and slope after the warm-up (from heaptrack's
    /// massif snapshots), and the call sites of what the gateway still held when it exited:
    /// with a bounded warm-up (the black box's ring) left out, what grew.
    fn report(&self, warm_up: f64) -> anyhow::Result<()> {
        let data = ["zst", "gz"]
            .iter()
            .map(|suffix| self.output.with_extension(suffix))
            .find(|path| path.exists())
            .with_context(|| format!("heaptrack wrote no {}.zst", self.output.display()))?;
        let massif = self.output.with_extension("massif");
        let printed = std::process::Command::new("heaptrack_print")
            .arg("-f")
            .arg(&data)
            .args([
                "-p", "0", "-a", "0", "-T", "0", "-l", "1", "-n", "8", "-s", "2",
            ])
            .arg("-M")
            .arg(&massif)
            .output()
            .context("running heaptrack_print")?;
        let text = String::from_utf8_lossy(&printed.stdout);
        let snapshots = massif_heap(&std::fs::read_to_string(&massif).unwrap_or_default());
        if let (Some(first), Some(last)) = (snapshots.first(), snapshots.last()) {
            let settled: Vec<(f64, f64)> = (snapshots.iter())
                .filter(|(at, _)| *at >= warm_up)
                .map(|(at, bytes)| (*at, bytes / 1e6))
                .collect();
            println!(
                "heap (heaptrack, {} snapshots): {:.2} MB at {:.0} s, {:.2} MB at {:.0} s; slope {:+.3} MB per hour after the warm-up",
                snapshots.len(),
                first.1 / 1e6,
                first.0,
                last.1 / 1e6,
                last.0,
                slope_per_hour(&settled)
            );
        }
        // The leaks section: what the gateway held at its clean exit, by call site, each with
        // the innermost frames of its backtrace.
        println!(
            "what the gateway held at its exit, by call site (heaptrack_print -l), top {HELD_SITES}:"
        );
        let mut sites = 0;
        let mut frames = 0;
        for line in text
            .lines()
            .skip_while(|line| !line.starts_with("MEMORY LEAKS"))
        {
            if line.contains(" leaked over ") && line.ends_with("from:") {
                sites += 1;
                frames = 0;
                if sites > HELD_SITES {
                    break;
                }
                println!("{line}");
            } else if sites > 0 && line.starts_with("    ") && frames < HELD_FRAMES {
                frames += 1;
                println!("{line}");
            }
        }
        for line in text.lines().filter(|line| {
            line.starts_with("peak heap memory consumption")
                || line.starts_with("total memory leaked")
                || line.starts_with("total runtime")
        }) {
            println!("{line}");
        }
        println!(
            "the data file, for heaptrack_gui or heaptrack_print: {}",
            data.display()
        );
        Ok(())
    }
}

/// The call sites of held memory a heap profile prints, and the frames of each.
const HELD_SITES: usize = 8;
const HELD_FRAMES: usize = 16;

/// (time in s, heap bytes) of each snapshot of a massif file as heaptrack_print writes it
/// (`time=` in its `time_unit`, s or ms; `mem_heap_B=`).
fn massif_heap(massif: &str) -> Vec<(f64, f64)> {
    let mut snapshots = Vec::new();
    let mut time = None;
    let mut unit = 1.0;
    for line in massif.lines() {
        if let Some(value) = line.strip_prefix("time_unit:") {
            unit = if value.trim() == "ms" { 1e-3 } else { 1.0 };
        } else if let Some(value) = line.strip_prefix("time=") {
            time = value.trim().parse::<f64>().ok().map(|t| t * unit);
        } else if let (Some(value), Some(at)) = (line.strip_prefix("mem_heap_B="), time)
            && let Ok(bytes) = value.trim().parse::<f64>()
        {
            snapshots.push((at, bytes));
        }
    }
    snapshots
}

/// Runs the soak for `minutes`, writing the figures as JSON to `json` if given, the gateway
/// under heaptrack if `heap_profile`.
pub fn soak(minutes: f64, json_out: Option<&Path>, heap_profile: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        minutes.is_finite() && minutes > 0.0,
        "give a positive number of minutes"
    );
    procs::ensure_built()?;
    let scratch = std::env::temp_dir().join(format!("scout-soak-{}", std::process::id()));
    std::fs::create_dir_all(&scratch)?;
    let name = format!("soak-{}", std::process::id());
    let mut sim = Sim::start(&["--serial"])?;
    let log = scratch.join("gateway.log");
    let profile = heap_profile
        .then(|| HeapProfile::new(&scratch))
        .transpose()?;
    let wrapper = profile
        .as_ref()
        .map(HeapProfile::wrapper)
        .unwrap_or_default();
    let wrapper: Vec<&str> = wrapper.iter().map(String::as_str).collect();
    let mut gateway = Gateway::start_through(
        &wrapper,
        &["--serial", &sim.port, "--name", &name, "--no-zenoh"],
        &log,
    )?;
    // The gateway itself, under its wrapper if any.
    let pid = if profile.is_some() {
        child_named(gateway.pid(), "scout-gateway")?
    } else {
        gateway.pid()
    };
    crate::roles::connect(&name)?;
    let started = Instant::now();
    let end = started + Duration::from_secs_f64(minutes * 60.0);
    let mut samples = vec![sample(pid, 0.0)?];
    let mut next_sample = started + Duration::from_secs(10);
    let mut round = 0;
    eprintln!("soak: {minutes} min of churn against robot {name}, a sample every 10 s");
    while Instant::now() < end {
        // The subject gone, the soak says how and stops: churning on against nothing would
        // only print that no gateway runs, round after round.
        if let Some(status) = gateway.exited() {
            anyhow::bail!(
                "the gateway ended after {round} rounds ({status}); the last lines of its log ({}):\n{}",
                log.display(),
                last_lines(&log, 20)
            );
        }
        if let Some(status) = sim.exited() {
            anyhow::bail!("the simulator ended after {round} rounds ({status})");
        }
        churn(&name, round)?;
        round += 1;
        if Instant::now() >= next_sample {
            next_sample += Duration::from_secs(10);
            samples.push(sample(pid, started.elapsed().as_secs_f64())?);
        }
    }
    samples.push(sample(pid, started.elapsed().as_secs_f64())?);
    let (settled, which) = after_warm_up(&samples);
    let metrics: [Metric; 7] = [
        ("resident memory, MB", |s| s.rss_mb),
        ("  of it anonymous (heap, stacks), MB", |s| s.rss_anon_mb),
        ("  of it shared memory, MB", |s| s.rss_shmem_mb),
        ("  of it mapped files, MB", |s| s.rss_file_mb),
        ("open files", |s| s.open_files),
        ("threads", |s| s.threads),
        ("files in /dev/shm", |s| s.shm_files),
    ];
    println!("| after {minutes} min, {round} rounds | first | last | slope per hour ({which}) |");
    println!("|---|---|---|---|");
    let mut figures = serde_json::Map::new();
    for (label, value) in metrics {
        let points: Vec<(f64, f64)> = settled.iter().map(|s| (s.at, value(s))).collect();
        let (first, last) = (value(&samples[0]), value(&samples[samples.len() - 1]));
        let slope = slope_per_hour(&points);
        println!("| {label} | {first:.2} | {last:.2} | {slope:+.3} |");
        figures.insert(
            label.to_owned(),
            json!({ "first": first, "last": last, "slope_per_hour": slope }),
        );
    }
    if let Some(path) = json_out {
        let report =
            json!({ "minutes": minutes, "rounds": round, "slopes": which, "figures": figures });
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(profile) = &profile {
        // A clean exit, so that what it still holds is told apart from what it freed; then
        // heaptrack writes its file.
        nix::sys::signal::kill(
            nix::unistd::Pid::from_raw(pid),
            nix::sys::signal::Signal::SIGTERM,
        )?;
        let deadline = Instant::now() + Duration::from_secs(120);
        while gateway.exited().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(200));
        }
        profile.report(WARM_UP.as_secs_f64())?;
        // The data file stays for heaptrack_gui; the rest of the scratch directory goes.
        drop(gateway);
        drop(sim);
        return Ok(());
    }
    drop(gateway);
    drop(sim);
    let _ = std::fs::remove_dir_all(&scratch);
    Ok(())
}

/// The last `count` lines of the file at `path` (what can be read of it).
fn last_lines(path: &Path, count: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(count)..].join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_slopes_leave_the_warm_up_out_or_say_they_could_not() {
        let at = |minutes: f64| Sample {
            at: minutes * 60.0,
            rss_mb: 0.0,
            rss_anon_mb: 0.0,
            rss_shmem_mb: 0.0,
            rss_file_mb: 0.0,
            open_files: 0.0,
            threads: 0.0,
            shm_files: 0.0,
        };
        let long: Vec<Sample> = (0..=60).map(|m| at(f64::from(m))).collect();
        let (settled, which) = after_warm_up(&long);
        assert_eq!(settled[0].at, 360.0);
        assert!(which.contains("warm-up of 6 min"), "{which}");
        let short: Vec<Sample> = (0..=10).map(|m| at(f64::from(m) / 2.0)).collect();
        let (settled, which) = after_warm_up(&short);
        assert_eq!(settled.len(), 9);
        assert!(which.contains("first fifth"), "{which}");
    }

    #[test]
    fn the_heap_comes_from_each_massif_snapshot() {
        let massif = "desc: heaptrack\ntime_unit: ms\nsnapshot=0\n#-----------\ntime=0\n\
                      mem_heap_B=1000\nmem_heap_extra_B=0\nsnapshot=1\ntime=2500\n\
                      mem_heap_B=3000\nheap_tree=peak\n";
        assert_eq!(massif_heap(massif), [(0.0, 1000.0), (2.5, 3000.0)]);
        let seconds = massif.replace("time_unit: ms", "time_unit: s");
        assert_eq!(massif_heap(&seconds)[1], (2500.0, 3000.0));
        assert!(massif_heap("").is_empty());
    }

    #[test]
    fn the_slope_is_per_hour_and_flat_for_a_constant() {
        let rising: Vec<(f64, f64)> = (0..10)
            .map(|i| (f64::from(i) * 60.0, f64::from(i)))
            .collect();
        assert!((slope_per_hour(&rising) - 60.0).abs() < 1e-9);
        let flat: Vec<(f64, f64)> = (0..10).map(|i| (f64::from(i), 5.0)).collect();
        assert_eq!(slope_per_hour(&flat), 0.0);
        assert_eq!(slope_per_hour(&[(1.0, 1.0)]), 0.0);
    }
}
