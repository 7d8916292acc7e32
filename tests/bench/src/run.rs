//! The measurements, in order: state latency on three paths and with many subscribers, command
//! and e-stop latency (local and through zenoh), tick jitter idle, loaded and under a flood,
//! recovery, cost, both protocols side by side over slcan, and decode throughput; then the
//! table, the JSON and the plots.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context;
use scout_clients::client::{Robot, StateSubscriber};
use scout_clients::interface::state::LinkState;
use scout_clients::{Class, ReleaseTarget, monotonic_ns};
use serde_json::{Value, json};

use crate::figures::{Summary, Ticks, Trace, read_rows, round};
use crate::procs::{Gateway, Roles, Sim, bin_dir, command, ensure_built, usage};
use crate::roles::connect;

#[derive(Debug)]
pub struct Options {
    pub quick: bool,
    pub json: Option<PathBuf>,
    pub plots: Option<PathBuf>,
    pub client_priority: u8,
}

/// Window lengths and sample counts.
#[derive(Debug, Clone, Copy)]
struct Plan {
    window: f64,
    /// Alternating Rust and Python windows of the Python section.
    python_pairs: usize,
    commands: usize,
    stops: usize,
}

impl Plan {
    fn new(quick: bool) -> Self {
        if quick {
            Plan {
                window: 2.0,
                python_pairs: 1,
                commands: 10,
                stops: 5,
            }
        } else {
            Plan {
                window: 10.0,
                python_pairs: 3,
                commands: 100,
                stops: 50,
            }
        }
    }
}

/// Everything the run keeps for the report.
#[derive(Default)]
struct Report {
    json: serde_json::Map<String, Value>,
    rows: Vec<(String, String)>,
    /// Latency samples per path, µs, for the plots.
    paths: Vec<(String, Vec<f64>)>,
    /// Tick intervals per condition, ms, for the plots.
    ticks: Vec<(String, Ticks)>,
}

impl Report {
    fn latency(&mut self, key: &str, label: &str, samples: &[f64]) -> Summary {
        let summary = Summary::of(samples);
        insert(&mut self.json, key, summary.json());
        self.rows.push((format!("{label} (µs)"), summary.row()));
        summary
    }

    fn value(&mut self, key: &str, label: &str, value: f64) {
        insert(&mut self.json, key, json!(round(value)));
        self.rows.push((label.to_owned(), format!("{value:.2}")));
    }
}

/// Inserts `value` at a dotted `key`.
fn insert(map: &mut serde_json::Map<String, Value>, key: &str, value: Value) {
    match key.split_once('.') {
        Some((head, rest)) => {
            let entry = map
                .entry(head.to_owned())
                .or_insert_with(|| Value::Object(Default::default()));
            if let Value::Object(inner) = entry {
                insert(inner, rest, value);
            }
        }
        None => {
            map.insert(key.to_owned(), value);
        }
    }
}

fn progress(what: &str) {
    eprintln!("scout-bench: {what}");
}

fn us(ns: u64) -> f64 {
    ns as f64 / 1e3
}

/// The bench's scratch directory, removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(label: &str) -> anyhow::Result<Scratch> {
        let dir = std::env::temp_dir().join(format!("scout-bench-{}{label}", std::process::id()));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Scratch(dir))
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    fn text(&self, name: &str) -> String {
        self.path(name).to_string_lossy().into_owned()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // `$SCOUT_BENCH_KEEP` keeps the logs and traces for a look afterwards.
        if std::env::var_os("SCOUT_BENCH_KEEP").is_some() {
            eprintln!("scout-bench: kept {}", self.0.display());
            return;
        }
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// How the bench's chassis is reached: the simulator's firmware and the port in between.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Rig {
    /// Protocol v1 over RS232: the main run.
    SerialV1,
    /// Protocol v1 behind a serial-line CAN adapter.
    SlcanV1,
    /// Protocol v2 (SCOUT 2.0) behind a serial-line CAN adapter.
    SlcanV2,
    /// Protocol v1 on a CAN bus (`scout-sim --can BUS`), the gateway on `port` (its transport
    /// arguments): the bus itself, a USB adapter through the kernel's driver, or in user space.
    Can {
        /// The JSON key.
        key: &'static str,
        /// The table's name.
        label: &'static str,
        /// The simulator's interface.
        bus: String,
        /// The gateway's transport arguments.
        port: Vec<String>,
    },
}

impl Rig {
    /// The simulator's arguments for its firmware and port.
    fn sim_args(&self) -> Vec<&str> {
        match self {
            Self::SerialV1 => vec!["--serial"],
            Self::SlcanV1 => vec!["--slcan"],
            Self::SlcanV2 => vec!["--slcan", "--protocol", "v2", "--model", "scout2"],
            Self::Can { bus, .. } => vec!["--can", bus],
        }
    }

    /// Its key in the JSON and its name in the table.
    fn key_and_label(&self) -> (&'static str, &'static str) {
        match self {
            Self::SerialV1 => ("serial_v1", "v1, RS232"),
            Self::SlcanV1 => ("slcan_v1", "v1 (SCOUT), slcan"),
            Self::SlcanV2 => ("slcan_v2", "v2 (SCOUT 2.0), slcan"),
            Self::Can { key, label, .. } => (key, label),
        }
    }
}

/// The robot under test: the simulator on a pseudo-terminal behind a stable link, its gateway.
struct Bench {
    rig: Rig,
    /// SCHED_FIFO priority of the thread while it stops the robot (see [`Realtime`]).
    client_priority: u8,
    scratch: Scratch,
    name: String,
    sim: Sim,
    gateway: Option<Gateway>,
    endpoint: String,
    plan: Plan,
}

impl Bench {
    /// The simulator of `rig` (real-time, traced, behind a stable link) and no gateway yet.
    fn start(
        rig: Rig,
        name: String,
        endpoint: String,
        plan: Plan,
        priority: u8,
    ) -> anyhow::Result<Bench> {
        let scratch = Scratch::new(&match &rig {
            Rig::SerialV1 => String::new(),
            rig => format!("-{}", rig.key_and_label().0.replace('_', "-")),
        })?;
        let mut args = rig.sim_args();
        let (link, trace) = (scratch.text("chassis.tty"), scratch.text("chassis.trace"));
        args.extend(["--realtime-priority", "60", "--trace", &trace]);
        if !matches!(rig, Rig::Can { .. }) {
            args.extend(["--link", &link]);
        }
        let sim = Sim::start(&args)?;
        Ok(Bench {
            rig,
            client_priority: priority,
            name,
            endpoint,
            scratch,
            sim,
            gateway: None,
            plan,
        })
    }

    fn gateway_args(&self, zenoh: bool) -> Vec<String> {
        let mut args = match &self.rig {
            Rig::SerialV1 => vec!["--serial".to_owned(), self.scratch.text("chassis.tty")],
            Rig::SlcanV1 | Rig::SlcanV2 => {
                vec!["--slcan".to_owned(), self.scratch.text("chassis.tty")]
            }
            Rig::Can { port, .. } => port.clone(),
        };
        args.extend(["--name".to_owned(), self.name.clone()]);
        if zenoh {
            args.extend(
                [
                    "--zenoh-listen",
                    &self.endpoint,
                    "--remote-commands",
                    "estop,teleop,release",
                ]
                .map(str::to_owned),
            );
        } else {
            args.push("--no-zenoh".to_owned());
        }
        args
    }

    /// Starts a gateway and waits until it publishes a state with the link up.
    fn start_gateway(&mut self, zenoh: bool) -> anyhow::Result<StateSubscriber> {
        self.start_gateway_with(zenoh, &[])
    }

    /// [`Bench::start_gateway`] with `extra` arguments.
    fn start_gateway_with(
        &mut self,
        zenoh: bool,
        extra: &[String],
    ) -> anyhow::Result<StateSubscriber> {
        let mut args = self.gateway_args(zenoh);
        args.extend_from_slice(extra);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let log = self.scratch.path("gateway.log");
        self.gateway = Some(Gateway::start(&args, &log)?);
        let states = match connect(&self.name) {
            Ok(robot) => robot.subscribe()?,
            // Why it did not come up is in its log: said with the error.
            Err(error) => {
                let exited = self.gateway.as_mut().and_then(Gateway::exited);
                let text = std::fs::read_to_string(&log).unwrap_or_default();
                let lines: Vec<&str> = text.lines().collect();
                let tail = lines[lines.len().saturating_sub(20)..].join("\n");
                anyhow::bail!(
                    "{error}; the gateway {}; its log ends:\n{tail}",
                    exited.map_or("still runs".to_owned(), |status| format!("ended: {status}"))
                );
            }
        };
        wait_state(&states, |state| state.link.state() == LinkState::Ok)?;
        Ok(states)
    }

    /// `scout release --name NAME`, as an operator.
    fn release_all(&self) -> anyhow::Result<()> {
        let status = command("scout")?
            .args(["release", "--name", &self.name])
            .stdout(std::process::Stdio::null())
            .status()?;
        anyhow::ensure!(status.success(), "scout release failed");
        Ok(())
    }
}

/// Waits up to 20 s for a state that satisfies `wanted`.
fn wait_state(
    states: &StateSubscriber,
    wanted: impl Fn(&scout_clients::StatePayload) -> bool,
) -> anyhow::Result<scout_clients::StatePayload> {
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        if let Some(state) = states.next_timeout(Duration::from_millis(100))?
            && wanted(&state)
        {
            return Ok(state);
        }
    }
    anyhow::bail!("the state never became what the bench waited for (20 s)")
}

pub fn run(options: &Options) -> anyhow::Result<()> {
    ensure_built()?;
    let plan = Plan::new(options.quick);
    let port = std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port();
    progress("starting the simulator and the gateway");
    let mut bench = Bench::start(
        Rig::SerialV1,
        format!("bench-{}", std::process::id()),
        format!("tcp/127.0.0.1:{port}"),
        plan,
        options.client_priority,
    )?;
    let mut report = Report::default();
    let states = bench.start_gateway(true)?;

    state_latency(&mut bench, &mut report)?;
    ros2_dds(&mut bench, &mut report)?;
    python_client(&mut bench, &mut report)?;
    command_latency(&mut bench, &mut report, &states)?;
    remote_latency(&mut bench, &mut report, &states)?;
    ticks(&mut bench, &mut report, &states)?;
    stop_endpoint_flood(&mut bench, &mut report, &states)?;
    watchers(&mut bench, &mut report)?;
    recovery(&mut bench, &mut report, states)?;
    cost(&mut bench, &mut report)?;
    let plan = bench.plan;
    if let Some(gateway) = bench.gateway.take() {
        gateway.kill();
    }
    drop(bench);
    for rig in [Rig::SlcanV1, Rig::SlcanV2] {
        protocol(rig, plan, options.client_priority, &mut report)?;
    }
    black_box(plan, options.client_priority, &mut report)?;
    black_box_write(&mut report)?;
    decode_throughput(&mut report);

    finish(options, report)
}

/// `scout-bench usb`: the chassis on a CAN bus reached three ways in one run (see
/// `crate::usb`): the bus itself, a gs_usb adapter through the kernel's driver, and the same
/// adapter in user space.
pub fn usb(options: &Options) -> anyhow::Result<()> {
    let plan = Plan::new(options.quick);
    progress("loading the modules, the bus and the emulated gs_usb adapter");
    let set = crate::usb::Set::set_up()?;
    let mut report = Report::default();
    for rig in set.rigs() {
        protocol(rig, plan, options.client_priority, &mut report)?;
    }
    drop(set);
    finish(options, report)
}

/// Prints the table and writes the JSON and plots asked for.
fn finish(options: &Options, mut report: Report) -> anyhow::Result<()> {
    insert(
        &mut report.json,
        "client_priority",
        json!(options.client_priority),
    );
    print_table(&report, options.quick);
    if let Some(path) = &options.json {
        let text = serde_json::to_string_pretty(&Value::Object(report.json.clone()))?;
        std::fs::write(path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
        progress(&format!("figures written to {}", path.display()));
    }
    if let Some(dir) = &options.plots {
        crate::plot::draw(dir, &report.paths, &report.ticks)?;
        progress(&format!("plots drawn in {}", dir.display()));
    }
    Ok(())
}

/// One protocol behind one transport, for comparison: the state's latency to an iceoryx2
/// subscriber, drive and e-stop latency to the chassis, and the motion command's interval idle;
/// in the JSON under the rig's key, in the table after its name.
fn protocol(rig: Rig, plan: Plan, priority: u8, report: &mut Report) -> anyhow::Result<()> {
    let (key, label) = rig.key_and_label();
    progress(&format!("{label}: the simulator and a gateway"));
    let name = format!("bench-{key}-{}", std::process::id());
    let mut bench = Bench::start(rig, name, String::new(), plan, priority)?;
    let states = bench.start_gateway(false)?;
    let mut figures = Report::default();
    progress(&format!("{label}: state latency"));
    let window = bench.plan.window.to_string();
    let mut roles = Roles::default();
    let out = bench.scratch.text("iox-1-0");
    roles.spawn(&["subscribe", &bench.name, &out, &window])?;
    roles.wait()?;
    let one = iceoryx2_latencies(&bench, 1, &trace(&bench)?)?;
    figures.latency("state_latency_us", "state, iceoryx2", &one.end_to_end);
    command_latency(&mut bench, &mut figures, &states)?;
    progress(&format!("{label}: motion command interval, idle"));
    let from = monotonic_ns();
    std::thread::sleep(Duration::from_secs_f64(bench.plan.window));
    let ticks = trace(&bench)?.ticks(from, monotonic_ns());
    let json = ticks.json();
    figures.rows.push((
        "motion command interval, idle (ms)".into(),
        format!(
            "mean {} / p99 dev {} / max {} ({})",
            json["mean"], json["p99_dev"], json["max"], json["n"]
        ),
    ));
    insert(&mut figures.json, "tick_interval_ms", json);
    for (what, value) in figures.rows {
        report.rows.push((format!("{label}: {what}"), value));
    }
    insert(&mut report.json, key, Value::Object(figures.json));
    if let Some(gateway) = bench.gateway.take() {
        gateway.kill();
    }
    Ok(())
}

/// What the black box costs the tick: the motion command's interval at the chassis with the
/// black box off, and on while `scout blackbox save` writes it every 2 s (the main run's idle
/// figure is with it on, not saving). In the JSON under `black_box`.
fn black_box(plan: Plan, priority: u8, report: &mut Report) -> anyhow::Result<()> {
    for (key, label, minutes, saving) in [
        ("off", "black box off", 0, false),
        ("saving", "black box on, saved every 2 s", 5, true),
    ] {
        progress(&format!("tick jitter: {label}"));
        let name = format!("bench-blackbox-{key}-{}", std::process::id());
        let mut bench = Bench::start(Rig::SerialV1, name, String::new(), plan, priority)?;
        let config = bench.scratch.path("gateway.toml");
        let dir = bench.scratch.path("blackbox");
        std::fs::write(
            &config,
            format!(
                "[blackbox]\nminutes = {minutes}\nmin_interval_s = 0\ndir = \"{}\"\n",
                dir.display()
            ),
        )?;
        let extra = ["--config".to_owned(), config.display().to_string()];
        bench.start_gateway_with(false, &extra)?;
        let from = monotonic_ns();
        let end = std::time::Instant::now() + Duration::from_secs_f64(bench.plan.window);
        while std::time::Instant::now() < end {
            if saving {
                let status = command("scout")?
                    .args(["blackbox", "save", "--name", &bench.name])
                    .stdout(std::process::Stdio::null())
                    .status()?;
                anyhow::ensure!(status.success(), "scout blackbox save failed");
            }
            std::thread::sleep(Duration::from_secs(2).min(end - std::time::Instant::now()));
        }
        let ticks = trace(&bench)?.ticks(from, monotonic_ns());
        let json = ticks.json();
        report.rows.push((
            format!("0x130 interval, {label} (ms)"),
            format!(
                "mean {} / p99 dev {} / max {} / >25 ms {} ({})",
                json["mean"], json["p99_dev"], json["max"], json["over_25"], json["n"]
            ),
        ));
        insert(&mut report.json, &format!("black_box.{key}"), json);
        if let Some(gateway) = bench.gateway.take() {
            gateway.kill();
        }
    }
    Ok(())
}

/// Reads the main simulator's trace (flushed every feedback period).
fn trace(bench: &Bench) -> anyhow::Result<Trace> {
    std::thread::sleep(Duration::from_millis(60));
    Trace::read(&bench.scratch.path("chassis.trace"))
}

/// End-to-end latencies (µs) of recordings whose first column is when a state was seen: from
/// the last feedback the simulator wrote before. A subscriber's first sample (the history, from
/// before it subscribed) is left out.
fn seen_latencies(rows: &[Vec<u64>], trace: &Trace) -> Vec<f64> {
    rows.iter()
        .skip(1)
        .filter_map(|row| {
            let seen = *row.first()?;
            let written = trace.feedback_before(seen)?;
            Some(us(seen - written))
        })
        .collect()
}

/// The iceoryx2 recordings `iox-COUNT-*`: end to end from the batch the gateway read, and its
/// parts (written to read, read to published, published to seen).
struct Split {
    end_to_end: Vec<f64>,
    link: Vec<f64>,
    gateway: Vec<f64>,
    delivery: Vec<f64>,
}

fn iceoryx2_latencies(bench: &Bench, count: usize, trace: &Trace) -> anyhow::Result<Split> {
    let mut split = Split {
        end_to_end: Vec::new(),
        link: Vec::new(),
        gateway: Vec::new(),
        delivery: Vec::new(),
    };
    for i in 0..count {
        let rows = read_rows(&bench.scratch.path(&format!("iox-{count}-{i}")))?;
        for row in rows.iter().skip(1) {
            let &[seen, read, published] = row.as_slice() else {
                continue;
            };
            let Some(written) = trace.feedback_before(read) else {
                continue;
            };
            if read < written || published < read || seen < published {
                continue;
            }
            split.end_to_end.push(us(seen - written));
            split.link.push(us(read - written));
            split.gateway.push(us(published - read));
            split.delivery.push(us(seen - published));
        }
    }
    Ok(split)
}

/// A frame written by the simulator to a decoded state in another process: through the
/// gateway and iceoryx2 (split into link, gateway and delivery), through the gateway and zenoh,
/// and read from the port directly; then 8 and 32 iceoryx2 subscribers.
fn state_latency(bench: &mut Bench, report: &mut Report) -> anyhow::Result<()> {
    let window = bench.plan.window.to_string();
    progress("state latency: iceoryx2, zenoh and a direct read of the port, at once");
    let direct_sim = Sim::start(&[
        "--serial",
        "--realtime-priority",
        "60",
        "--trace",
        &bench.scratch.text("direct.trace"),
    ])?;
    let mut roles = Roles::default();
    let (name, endpoint) = (bench.name.clone(), bench.endpoint.clone());
    let out = |file: &str| bench.scratch.text(file);
    roles.spawn(&["subscribe", &name, &out("iox-1-0"), &window])?;
    roles.spawn(&["zenoh-subscribe", &name, &endpoint, &out("zenoh"), &window])?;
    roles.spawn(&["direct", &direct_sim.port, &out("direct"), &window])?;
    roles.wait()?;
    direct_sim.quit()?;
    for count in [8, 32] {
        progress(&format!(
            "state latency: {count} iceoryx2 subscriber processes"
        ));
        for i in 0..count {
            roles.spawn(&[
                "subscribe",
                &name,
                &out(&format!("iox-{count}-{i}")),
                &window,
            ])?;
        }
        roles.wait()?;
    }
    let trace = trace(bench)?;
    let direct_trace = Trace::read(&bench.scratch.path("direct.trace"))?;
    let one = iceoryx2_latencies(bench, 1, &trace)?;
    let zenoh = seen_latencies(&read_rows(&bench.scratch.path("zenoh"))?, &trace);
    let direct = seen_latencies(&read_rows(&bench.scratch.path("direct"))?, &direct_trace);
    report.latency(
        "state_latency_us.iceoryx2",
        "state, iceoryx2",
        &one.end_to_end,
    );
    report.latency("state_latency_us.zenoh", "state, zenoh", &zenoh);
    report.latency(
        "state_latency_us.direct",
        "state, direct read (floor)",
        &direct,
    );
    report.latency(
        "link_part_us",
        "  of which link (written to read)",
        &one.link,
    );
    report.latency(
        "gateway_part_us",
        "  of which gateway (read to published)",
        &one.gateway,
    );
    report.latency(
        "delivery_part_us",
        "  of which delivery (published to seen)",
        &one.delivery,
    );
    report.paths.push(("direct read".into(), direct));
    report.paths.push(("iceoryx2".into(), one.end_to_end));
    report.paths.push(("zenoh".into(), zenoh));
    for count in [8, 32] {
        let split = iceoryx2_latencies(bench, count, &trace)?;
        report.latency(
            &format!("state_latency_us.iceoryx2_{count}"),
            &format!("state, iceoryx2, {count} subscribers"),
            &split.end_to_end,
        );
        if count == 32 {
            report
                .paths
                .push(("iceoryx2, 32 subscribers".into(), split.end_to_end));
        }
    }
    Ok(())
}

/// State to a real rclpy subscriber over DDS: `scout ros2 --middleware dds` and rclpy (from
/// `$SCOUT_RCLPY_KILTED`) in a network namespace of the bench's own, /odom from the simulator's
/// write to rclpy's callback, and the bridge's CPU and memory at the state's 50 Hz. Skipped,
/// saying why, without rclpy or a network namespace (root).
fn ros2_dds(bench: &mut Bench, report: &mut Report) -> anyhow::Result<()> {
    let Some(python) = std::env::var_os("SCOUT_RCLPY_KILTED") else {
        progress("ROS 2 over DDS: skipped (set SCOUT_RCLPY_KILTED to a venv's python with rclpy)");
        return Ok(());
    };
    let namespace = match scout_system_tests::NetNs::create() {
        Ok(namespace) => namespace,
        Err(why) => {
            progress(&format!("ROS 2 over DDS: skipped ({why})"));
            return Ok(());
        }
    };
    progress("state latency: ROS 2 over DDS (scout ros2 and rclpy in a network namespace)");
    let domain = (std::process::id() % 200 + 10).to_string();
    let log = std::fs::File::create(bench.scratch.path("ros2.log"))?;
    let mut bridge = namespace
        .command(bin_dir()?.join("scout-ros2"))
        .args([
            "--name",
            &bench.name,
            "--middleware",
            "dds",
            "--domain",
            &domain,
        ])
        .env("RUST_LOG", "warn")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(log)
        .spawn()
        .context("starting scout-ros2 in the network namespace")?;
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("ros2_odom_subscriber.py");
    let mut subscriber = namespace
        .command(&python)
        .arg(script)
        .arg(bench.scratch.path("ros2-dds"))
        .arg(bench.plan.window.to_string())
        .env("ROS_DOMAIN_ID", &domain)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .context("starting the rclpy subscriber")?;
    // The bridge's cost over the subscriber's window, from its first message (after discovery).
    let mut first = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(subscriber.stdout.take().context("its output")?),
        &mut first,
    )?;
    let pid = i32::try_from(bridge.id())?;
    let (cpu_before, _) = usage(pid)?;
    let start = Instant::now();
    let status = subscriber.wait()?;
    let (cpu_after, rss) = usage(pid)?;
    let percent = (cpu_after - cpu_before) / start.elapsed().as_secs_f64() * 100.0;
    let _ = bridge.kill();
    let _ = bridge.wait();
    anyhow::ensure!(
        status.success(),
        "the rclpy subscriber failed ({status}); the bridge's log: {}",
        bench.scratch.text("ros2.log")
    );
    let trace = trace(bench)?;
    let dds = seen_latencies(&read_rows(&bench.scratch.path("ros2-dds"))?, &trace);
    report.latency(
        "state_latency_us.ros2_dds",
        "state, ROS 2 over DDS (rclpy /odom)",
        &dds,
    );
    report.value(
        "ros2_bridge_cpu_percent",
        "scout ros2 over DDS, CPU, % of a core, 50 Hz",
        percent,
    );
    report.value(
        "ros2_bridge_rss_mb",
        "scout ros2 over DDS, resident memory, MB",
        rss,
    );
    report.paths.push(("ROS 2 DDS (rclpy)".into(), dds));
    Ok(())
}

/// State to a Python subscriber (the `scout` package, from `$SCOUT_PYTHON_CLIENT`) against a
/// Rust iceoryx2 subscriber under the same load, in alternating windows (Rust, then Python,
/// `plan.python_pairs` times; each alone: two subscribers woken by one state wait for each other
/// on two cores), so drift of the shared machine within the run falls on both alike: end to end
/// from the simulator's write, the delivery part (published to seen), the p50 ratio of every
/// pair and of the pooled samples; and the Python process' CPU (every thread) and memory at
/// 50 Hz. Skipped, saying why, without that Python.
fn python_client(bench: &mut Bench, report: &mut Report) -> anyhow::Result<()> {
    let Some(interpreter) = std::env::var_os("SCOUT_PYTHON_CLIENT") else {
        progress(
            "Python client: skipped (set SCOUT_PYTHON_CLIENT to a venv's python with the scout \
             package: pip install ./clients/python)",
        );
        return Ok(());
    };
    let pairs = bench.plan.python_pairs;
    progress(&format!(
        "state latency: a Rust iceoryx2 subscriber and the Python package, each alone, {pairs} \
         alternating windows each"
    ));
    let (mut rust, mut python) = (Vec::new(), Vec::new());
    let (mut rust_delivery, mut python_delivery) = (Vec::new(), Vec::new());
    let mut ratios = Vec::new();
    let mut costs = Vec::new();
    for pair in 0..pairs {
        let rust_file = format!("iox-beside-python-{pair}");
        let python_file = format!("python-{pair}");
        let mut roles = Roles::default();
        roles.spawn(&[
            "subscribe",
            &bench.name,
            &bench.scratch.text(&rust_file),
            &bench.plan.window.to_string(),
        ])?;
        roles.wait()?;
        costs.push(python_window(bench, &interpreter, &python_file)?);
        let trace = trace(bench)?;
        let rust_rows = read_rows(&bench.scratch.path(&rust_file))?;
        let python_rows = read_rows(&bench.scratch.path(&python_file))?;
        let (rust_seen, python_seen) = (
            seen_latencies(&rust_rows, &trace),
            seen_latencies(&python_rows, &trace),
        );
        ratios.push(Summary::of(&python_seen).p50 / Summary::of(&rust_seen).p50);
        rust.extend(rust_seen);
        python.extend(python_seen);
        rust_delivery.extend(delivery(&rust_rows, 2));
        python_delivery.extend(delivery(&python_rows, 1));
    }
    let python_p50 = report
        .latency(
            "state_latency_us.python",
            "state, Python (scout package, next())",
            &python,
        )
        .p50;
    let rust_p50 = report
        .latency(
            "state_latency_us.iceoryx2_beside_python",
            "state, iceoryx2 (Rust), alternating windows",
            &rust,
        )
        .p50;
    report.latency(
        "python_delivery_us",
        "  Python: published to seen",
        &python_delivery,
    );
    report.latency(
        "iceoryx2_delivery_beside_python_us",
        "  Rust: published to seen",
        &rust_delivery,
    );
    report.value(
        "python_to_rust_p50_ratio",
        "Python p50 / Rust p50, pooled windows",
        python_p50 / rust_p50,
    );
    insert(
        &mut report.json,
        "python_to_rust_p50_ratio_per_pair",
        json!(ratios.iter().map(|ratio| round(*ratio)).collect::<Vec<_>>()),
    );
    report.rows.push((
        "Python p50 / Rust p50, each pair of windows".into(),
        ratios
            .iter()
            .map(|ratio| format!("{ratio:.2}"))
            .collect::<Vec<_>>()
            .join(", "),
    ));
    let mean = |field: &str| {
        costs
            .iter()
            .map(|cost| cost[field].as_f64().unwrap_or(f64::NAN))
            .sum::<f64>()
            / costs.len() as f64
    };
    report.value(
        "python_client_cpu_percent",
        "Python subscriber, CPU, % of a core, 50 Hz",
        mean("cpu_percent"),
    );
    report.value(
        "python_client_rss_mb",
        "Python subscriber, resident memory, MB",
        mean("rss_mb"),
    );
    report.paths.push(("Python (scout package)".into(), python));
    Ok(())
}

/// One window of `python_state_subscriber.py`, its rows in the scratch file `file`; returns its
/// cost line (its CPU over the window and its memory, measured by itself).
fn python_window(bench: &Bench, python: &std::ffi::OsStr, file: &str) -> anyhow::Result<Value> {
    let script =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("python_state_subscriber.py");
    let mut subscriber = std::process::Command::new(python)
        .arg(script)
        .arg(&bench.name)
        .arg(bench.scratch.path(file))
        .arg(bench.plan.window.to_string())
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .context("starting the Python subscriber")?;
    let mut output = std::io::BufReader::new(subscriber.stdout.take().context("its output")?);
    let mut first = String::new();
    std::io::BufRead::read_line(&mut output, &mut first)?;
    anyhow::ensure!(
        first.trim() == "receiving",
        "the Python subscriber did not start"
    );
    let mut cost = String::new();
    std::io::BufRead::read_line(&mut output, &mut cost)?;
    let status = subscriber.wait()?;
    anyhow::ensure!(status.success(), "the Python subscriber failed ({status})");
    serde_json::from_str(&cost).context("the Python subscriber's cost line")
}

/// Published-to-seen latencies (µs) of a subscriber's rows: the first column is when a state was
/// seen, column `published` when the gateway published it; the first row (the history) skipped.
fn delivery(rows: &[Vec<u64>], published: usize) -> Vec<f64> {
    rows.iter()
        .skip(1)
        .filter_map(|row| {
            let (seen, published) = (*row.first()?, *row.get(published)?);
            (seen >= published).then(|| us(seen - published))
        })
        .collect()
}

/// Waits until the gateway sends `wanted` (by the state's last command), up to 20 s.
fn wait_command(states: &StateSubscriber, wanted: impl Fn(f64) -> bool) -> anyhow::Result<()> {
    wait_state(states, |state| wanted(state.command.linear)).map(|_| ())
}

/// One way of driving and stopping: locally through iceoryx2, or a remote peer through zenoh.
trait Commander {
    fn take(&mut self) -> anyhow::Result<()>;
    fn drive(&mut self, linear: f64) -> anyhow::Result<()>;
    fn stop(&mut self) -> anyhow::Result<()>;
    fn release(&mut self) -> anyhow::Result<()>;
}

struct Local {
    driver: scout_clients::control::Controller,
    safety: scout_clients::control::Controller,
    /// Asks the gateway for its newest stop (a ping of the stop endpoint).
    stopper: scout_clients::control::Stopper,
    /// The id of the bench's last stop: its release names it.
    last_stop: u64,
}

impl Commander for Local {
    fn take(&mut self) -> anyhow::Result<()> {
        match self.driver.take_control() {
            Ok(_) => Ok(()),
            // A stop the gateway latched itself (the simulator starved of CPU on a loaded
            // machine, say: chassis_silent): said, released as the robot's operator would
            // (the bench is this gateway's operator), and tried once more.
            Err(error) if error.rejection() == Some(scout_clients::RejectionKind::Latched) => {
                progress(&format!(
                    "{error}: the gateway stopped the robot during the bench; released, once"
                ));
                let through = self.stopper.newest_stop()?.unwrap_or(u64::MAX);
                self.safety.release(ReleaseTarget::All, through)?;
                self.driver.take_control()?;
                Ok(())
            }
            Err(error) => Err(error.into()),
        }
    }
    fn drive(&mut self, linear: f64) -> anyhow::Result<()> {
        match self.driver.drive(linear, 0.0) {
            Ok(_) => Ok(()),
            // The bench sends nothing while it waits for the robot to come to rest: on a loaded
            // machine that wait can outlast the class's age, and the gateway ends the control
            // as it should. Said, and taken again on purpose (this sample's figure includes
            // the take).
            Err(error) if error.rejection() == Some(scout_clients::RejectionKind::Revoked) => {
                progress(&format!("{error}: taken again"));
                self.take()?;
                self.driver.drive(linear, 0.0)?;
                Ok(())
            }
            Err(error) => Err(error.into()),
        }
    }
    fn stop(&mut self) -> anyhow::Result<()> {
        self.last_stop = self.safety.stop("bench")?.stop.unwrap_or(0);
        Ok(())
    }
    fn release(&mut self) -> anyhow::Result<()> {
        self.safety.release(ReleaseTarget::Own, self.last_stop)?;
        Ok(())
    }
}

struct Remote {
    session: zenoh::Session,
    name: String,
    seq: u64,
}

impl Remote {
    fn query(&self, kind: &str, payload: String) -> anyhow::Result<()> {
        use zenoh::Wait;
        let replies = self
            .session
            .get(format!("scout/{}/cmd/{kind}/bench", self.name))
            .payload(payload)
            .timeout(Duration::from_secs(5))
            .wait()
            .map_err(|error| anyhow::anyhow!("querying {kind}: {error}"))?;
        let reply = replies
            .recv()
            .map_err(|_| anyhow::anyhow!("no answer to the remote {kind}"))?;
        let sample = reply
            .result()
            .map_err(|error| anyhow::anyhow!("remote {kind}: {error:?}"))?;
        let answer: Value = serde_json::from_slice(&sample.payload().to_bytes())?;
        anyhow::ensure!(
            answer["accepted"] == true,
            "remote {kind} refused: {answer}"
        );
        Ok(())
    }
}

impl Commander for Remote {
    fn take(&mut self) -> anyhow::Result<()> {
        let sent_ms = monotonic_ns() / 1_000_000;
        self.query(
            "take-control",
            format!(r#"{{"class":"teleop","sent_ms":{sent_ms}}}"#),
        )
    }
    fn drive(&mut self, linear: f64) -> anyhow::Result<()> {
        self.seq += 1;
        let sent_ms = monotonic_ns() / 1_000_000;
        let payload = format!(
            r#"{{"seq":{},"sent_ms":{sent_ms},"linear":{linear},"angular":0.0,"ttl_ms":500}}"#,
            self.seq
        );
        self.query("drive", payload)
    }
    fn stop(&mut self) -> anyhow::Result<()> {
        self.query("estop", r#"{"reason":"bench"}"#.into())
    }
    fn release(&mut self) -> anyhow::Result<()> {
        self.query("release", "{}".into())
    }
}

/// `drive` to the first frame carrying it at the chassis, `count` times: returns the request
/// times.
fn drive_samples(
    commander: &mut dyn Commander,
    states: &StateSubscriber,
    count: usize,
) -> anyhow::Result<Vec<u64>> {
    commander.take()?;
    let mut sent = Vec::new();
    for _ in 0..count {
        wait_command(states, |linear| linear == 0.0)?;
        // A random phase against the 20 ms grid: 25 to 45 ms after the robot came to rest.
        let jitter = (monotonic_ns().wrapping_mul(6364136223846793005) >> 33) % 20_000;
        std::thread::sleep(Duration::from_micros(25_000 + jitter));
        sent.push(monotonic_ns());
        commander.drive(0.3)?;
        wait_command(states, |linear| linear > 0.0)?;
        commander.drive(0.0)?;
    }
    wait_command(states, |linear| linear == 0.0)?;
    Ok(sent)
}

/// The calling thread under SCHED_FIFO while it lives: the bench's stops play a safety
/// monitor deployed as real-time as the gateway, so that its own scheduling under the loads the
/// bench makes is not counted as the gateway's latency. Never held while processes are started
/// (they would inherit it).
struct Realtime;

impl Realtime {
    fn new(priority: u8) -> Realtime {
        scout_io::raise_priority(priority, "the bench's stopping thread");
        Realtime
    }
}

impl Drop for Realtime {
    fn drop(&mut self) {
        use thread_priority::{
            NormalThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
            set_thread_priority_and_policy, thread_native_id,
        };
        let _ = set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Crossplatform(0u8.try_into().expect("priority 0")),
            ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Other),
        );
    }
}

/// A stop while driving to the first zero frame at the chassis, `count` times: returns the
/// request times.
fn stop_samples(
    commander: &mut dyn Commander,
    states: &StateSubscriber,
    count: usize,
    priority: u8,
) -> anyhow::Result<Vec<Stop>> {
    let _realtime = Realtime::new(priority);
    let mut sent = Vec::new();
    for _ in 0..count {
        commander.take()?;
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            commander.drive(0.3)?;
            if states
                .try_latest()?
                .is_some_and(|state| state.command.linear > 0.05)
            {
                break;
            }
            anyhow::ensure!(Instant::now() < deadline, "the robot never drove");
            std::thread::sleep(Duration::from_millis(20));
        }
        let at = monotonic_ns();
        commander.stop()?;
        let answered = monotonic_ns();
        let zero = wait_state(states, |state| state.command.linear == 0.0)?;
        sent.push(Stop {
            at,
            answered,
            zero_sent: zero.command.at_ns,
        });
        commander.release()?;
    }
    Ok(sent)
}

/// One stop: when it was requested, answered, and when the gateway sent the zero command.
struct Stop {
    at: u64,
    answered: u64,
    zero_sent: u64,
}

/// The stops' latencies to the chassis, and to the gateway's zero and the answer, as figures.
fn report_stops(report: &mut Report, key: &str, label: &str, trace: &Trace, stops: &[Stop]) {
    let times: Vec<u64> = stops.iter().map(|stop| stop.at).collect();
    report.latency(
        key,
        label,
        &to_chassis(trace, &times, |linear| linear == 0.0),
    );
    let gateway: Vec<f64> = stops
        .iter()
        .map(|stop| us(stop.zero_sent.saturating_sub(stop.at)))
        .collect();
    report.latency(
        &format!("{key}_to_gateway_send"),
        "  of which to the gateway sending the zero",
        &gateway,
    );
    let answered: Vec<f64> = stops
        .iter()
        .map(|stop| us(stop.answered - stop.at))
        .collect();
    report.latency(&format!("{key}_answered"), "  the stop's answer", &answered);
}

/// Latencies (µs) from each request time to the first command at the chassis satisfying
/// `wanted`.
fn to_chassis(trace: &Trace, sent: &[u64], wanted: impl Fn(f64) -> bool + Copy) -> Vec<f64> {
    sent.iter()
        .filter_map(|&at| {
            trace
                .first_command_after(at, wanted)
                .map(|read| us(read - at))
        })
        .collect()
}

/// The share of drives whose value was on the first motion command after the request: sent at
/// the next tick of the 20 ms grid, not one later.
fn on_next_tick(trace: &Trace, sent: &[u64]) -> f64 {
    let next = sent
        .iter()
        .filter(|&&at| {
            trace.first_command_after(at, |_| true) == trace.first_command_after(at, |l| l > 0.0)
        })
        .count();
    100.0 * next as f64 / sent.len().max(1) as f64
}

fn local(robot: &Robot) -> anyhow::Result<Local> {
    Ok(Local {
        driver: robot.controller("bench-driver", Some(Class::Teleop))?,
        safety: robot.controller("bench-safety", None)?,
        stopper: robot.stopper("bench-safety")?,
        last_stop: 0,
    })
}

/// Drives through a local controller and stops with `scout estop` started cold: a process that
/// opened nothing before, as a person at a terminal or a script would; `scout release` after.
struct ColdEstop<'a> {
    local: &'a mut Local,
    name: String,
}

impl ColdEstop<'_> {
    fn scout(&self, args: &[&str]) -> anyhow::Result<()> {
        let output = command("scout")?
            .args(args)
            .args(["--name", &self.name])
            .output()
            .context("running scout")?;
        anyhow::ensure!(
            output.status.success(),
            "scout {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&output.stderr)
        );
        Ok(())
    }
}

impl Commander for ColdEstop<'_> {
    fn take(&mut self) -> anyhow::Result<()> {
        self.local.take()
    }
    fn drive(&mut self, linear: f64) -> anyhow::Result<()> {
        self.local.drive(linear)
    }
    fn stop(&mut self) -> anyhow::Result<()> {
        self.scout(&["estop", "--reason", "bench cold"])
    }
    fn release(&mut self) -> anyhow::Result<()> {
        self.scout(&["release"])
    }
}

/// A client's drive to the chassis (at the next tick) and a stop to the wire (at once).
fn command_latency(
    bench: &mut Bench,
    report: &mut Report,
    states: &StateSubscriber,
) -> anyhow::Result<()> {
    progress("command latency: drive and e-stop, local");
    let robot = connect(&bench.name)?;
    let mut local = local(&robot)?;
    let drives = drive_samples(&mut local, states, bench.plan.commands)?;
    let stops = stop_samples(&mut local, states, bench.plan.stops, bench.client_priority)?;
    // At normal priority: the process it starts would inherit real-time scheduling.
    let cold = stop_samples(
        &mut ColdEstop {
            local: &mut local,
            name: bench.name.clone(),
        },
        states,
        bench.plan.stops,
        0,
    )?;
    let trace = trace(bench)?;
    report.latency(
        "command_latency_us",
        "drive to the chassis (next 20 ms tick)",
        &to_chassis(&trace, &drives, |linear| linear > 0.0),
    );
    report.value(
        "command_on_next_tick_percent",
        "  drives that went out on the very next tick (%)",
        on_next_tick(&trace, &drives),
    );
    report_stops(
        report,
        "estop_latency_us",
        "e-stop to the chassis (pre-made stopper)",
        &trace,
        &stops,
    );
    report_stops(
        report,
        "estop_cold_latency_us",
        "e-stop from `scout estop` started cold, launch to the chassis",
        &trace,
        &cold,
    );
    Ok(())
}

/// The same through zenoh remote commands.
fn remote_latency(
    bench: &mut Bench,
    report: &mut Report,
    states: &StateSubscriber,
) -> anyhow::Result<()> {
    use zenoh::Wait;
    progress("command latency: drive and e-stop, a zenoh peer");
    let settings = scout_clients::remote::SessionSettings {
        config_file: Some(String::new()),
        listen: Vec::new(),
        connect: vec![bench.endpoint.clone()],
    };
    let session = zenoh::open(settings.config("client")?)
        .wait()
        .map_err(|error| anyhow::anyhow!("opening a zenoh session: {error}"))?;
    let mut remote = Remote {
        session,
        name: bench.name.clone(),
        seq: 0,
    };
    let drives = drive_samples(&mut remote, states, bench.plan.commands)?;
    let stops = stop_samples(&mut remote, states, bench.plan.stops, bench.client_priority)?;
    let trace = trace(bench)?;
    report.latency(
        "remote_command_latency_us",
        "drive through zenoh to the chassis",
        &to_chassis(&trace, &drives, |linear| linear > 0.0),
    );
    report.value(
        "remote_command_on_next_tick_percent",
        "  remote drives that went out on the very next tick (%)",
        on_next_tick(&trace, &drives),
    );
    report_stops(
        report,
        "remote_estop_latency_us",
        "e-stop through zenoh to the chassis",
        &trace,
        &stops,
    );
    Ok(())
}

/// The intervals between motion commands at the chassis: idle, with both cores hogged, and
/// under 16 clients flooding requests at 1 kHz (and the e-stop latency then).
fn ticks(bench: &mut Bench, report: &mut Report, states: &StateSubscriber) -> anyhow::Result<()> {
    let window = bench.plan.window;
    let seconds = window.to_string();
    let span = Duration::from_secs_f64(window);
    progress("tick jitter: idle");
    let from = monotonic_ns();
    std::thread::sleep(span);
    let idle = (from, monotonic_ns());

    progress("tick jitter: both cores loaded by two CPU hogs");
    let mut roles = Roles::default();
    for _ in 0..2 {
        roles.spawn(&["hog", &seconds])?;
    }
    std::thread::sleep(Duration::from_millis(200));
    let from = monotonic_ns();
    std::thread::sleep(span.saturating_sub(Duration::from_millis(400)));
    let loaded = (from, monotonic_ns());
    roles.wait()?;

    progress("tick jitter: 16 clients flooding requests at 1 kHz, then e-stops during it");
    let flood_seconds = (window * 2.0 + 10.0).to_string();
    for _ in 0..16 {
        roles.spawn(&["flood", &bench.name, "1000", &flood_seconds])?;
    }
    std::thread::sleep(Duration::from_secs(1));
    let from = monotonic_ns();
    std::thread::sleep(span);
    let flood = (from, monotonic_ns());
    let robot = connect(&bench.name)?;
    let mut local = local(&robot)?;
    let stops = stop_samples(&mut local, states, bench.plan.stops, bench.client_priority)?;
    drop(roles);

    let trace = trace(bench)?;
    report_stops(
        report,
        "estop_latency_flood_us",
        "e-stop to the chassis during the flood",
        &trace,
        &stops,
    );
    for (key, label, (from, to)) in [
        ("idle", "idle", idle),
        ("loaded", "both cores loaded", loaded),
        ("flood", "request flood", flood),
    ] {
        let ticks = trace.ticks(from, to);
        let json = ticks.json();
        report.rows.push((
            format!("0x130 interval, {label} (ms)"),
            format!(
                "mean {} / p99 dev {} / max {} / >25 ms {} / >40 ms {} ({})",
                json["mean"],
                json["p99_dev"],
                json["max"],
                json["over_25"],
                json["over_40"],
                json["n"]
            ),
        ));
        insert(&mut report.json, &format!("tick_interval_ms.{key}"), json);
        report.ticks.push((label.to_owned(), ticks));
    }
    Ok(())
}

/// How many processes flood the stop endpoint in [`stop_endpoint_flood`] (the review's case).
const ENDPOINT_FLOODERS: usize = 8;

/// [`ENDPOINT_FLOODERS`] processes at nice 19 flooding the stop endpoint with garbage, as
/// another user where the bench runs as root (`nobody`, if it can run this binary), else as
/// this one: what it costs the gateway (its CPU, % of a core, against the same window idle;
/// the endpoint serves 1 ms of datagrams and rests 4 ms, so about 20 % at most), and a stop's
/// latency meanwhile through the same endpoint.
fn stop_endpoint_flood(
    bench: &mut Bench,
    report: &mut Report,
    states: &StateSubscriber,
) -> anyhow::Result<()> {
    let pid = bench
        .gateway
        .as_ref()
        .map(Gateway::pid)
        .context("a gateway")?;
    let window = Duration::from_secs_f64(bench.plan.window);
    let cpu = |span: Duration| -> anyhow::Result<f64> {
        let (before, _) = usage(pid)?;
        let start = Instant::now();
        std::thread::sleep(span);
        let (after, _) = usage(pid)?;
        Ok((after - before) / start.elapsed().as_secs_f64() * 100.0)
    };
    progress("stop endpoint: the gateway's CPU idle");
    let idle = cpu(window)?;
    let other_user = nix::unistd::geteuid().is_root() && runnable_by_others()?;
    let wrapper: &[&str] = if other_user {
        &[
            "setpriv",
            "--reuid=65534",
            "--regid=65534",
            "--clear-groups",
            "nice",
            "-n",
            "19",
        ]
    } else {
        &["nice", "-n", "19"]
    };
    let who = if other_user {
        "user nobody"
    } else {
        "this user"
    };
    progress(&format!(
        "stop endpoint: {ENDPOINT_FLOODERS} flooders of garbage ({who}, nice 19), then e-stops during it"
    ));
    let seconds = (bench.plan.window * 3.0 + 20.0).to_string();
    let mut roles = Roles::default();
    for _ in 0..ENDPOINT_FLOODERS {
        roles.spawn_through(
            wrapper,
            &["datagram-flood", &bench.name, &seconds, "--garbage"],
        )?;
    }
    std::thread::sleep(Duration::from_secs(1));
    let flooded = cpu(window)?;
    // The e-stops are this user's: measured only beside another user's flood (past a user's
    // share its releases go unanswered, and the bench releases after each stop).
    let stops = if other_user {
        let robot = connect(&bench.name)?;
        let mut local = local(&robot)?;
        stop_samples(&mut local, states, bench.plan.stops, bench.client_priority)?
    } else {
        progress("stop endpoint: no e-stops measured (the flooders are this user: run as root)");
        Vec::new()
    };
    drop(roles);
    report.value(
        "gateway_cpu_percent_endpoint_idle",
        "gateway CPU, % of a core, before the stop-endpoint flood",
        idle,
    );
    report.value(
        "gateway_cpu_percent_endpoint_flood",
        &format!("gateway CPU, % of a core, {ENDPOINT_FLOODERS} flooders of {who}"),
        flooded,
    );
    if !stops.is_empty() {
        let trace = trace(bench)?;
        report_stops(
            report,
            "estop_latency_endpoint_flood_us",
            "e-stop to the chassis during the stop-endpoint flood",
            &trace,
            &stops,
        );
    }
    Ok(())
}

/// Whether every other user can run this binary (every directory above it lets them in).
fn runnable_by_others() -> anyhow::Result<bool> {
    use std::os::unix::fs::PermissionsExt;
    let exe = std::env::current_exe()?;
    Ok(exe.ancestors().all(|path| {
        std::fs::metadata(path).is_ok_and(|metadata| metadata.permissions().mode() & 0o001 != 0)
    }))
}

/// Two `scout record` and a Foxglove client on `scout foxglove` attached at once: what each
/// costs, how fast a recording grows, and the 0x130 intervals meanwhile (as idle, if they cost
/// the gateway nothing).
fn watchers(bench: &mut Bench, report: &mut Report) -> anyhow::Result<()> {
    use crate::watchers::{Client, cpu, live_view, percent, recorder};
    progress("watchers: two scout record and a Foxglove client on scout foxglove");
    let files = [
        bench.scratch.path("one.mcap"),
        bench.scratch.path("two.mcap"),
    ];
    let recorders = [
        recorder(&bench.name, &files[0])?,
        recorder(&bench.name, &files[1])?,
    ];
    let (server, url) = live_view(&bench.name)?;
    let client = Client::connect(&url)?;
    // The first chunks are written and the client has subscribed.
    std::thread::sleep(Duration::from_secs(2));
    let size = |path: &std::path::Path| std::fs::metadata(path).map_or(0, |m| m.len());
    let (bytes_before, messages_before) = (size(&files[0]), client.messages());
    let recorder_before = cpu(recorders[0].pid())?;
    let server_before = cpu(server.pid())?;
    let from = monotonic_ns();
    let start = Instant::now();
    std::thread::sleep(Duration::from_secs_f64(bench.plan.window));
    let to = monotonic_ns();
    let elapsed = start.elapsed().as_secs_f64();
    let recorder_percent = percent(recorders[0].pid(), recorder_before, start)?;
    let server_percent = percent(server.pid(), server_before, start)?;
    let grown = size(&files[0]).saturating_sub(bytes_before) as f64;
    let received = client.messages() - messages_before;
    client.finish()?;
    drop(recorders);
    drop(server);

    report.value(
        "record_cpu_percent",
        "scout record CPU, % of a core (50 Hz)",
        recorder_percent,
    );
    report.value(
        "record_mb_per_minute",
        "scout record file growth, MB a minute (50 Hz, zstd)",
        grown / elapsed * 60.0 / 1e6,
    );
    report.value(
        "foxglove_cpu_percent",
        "scout foxglove CPU, % of a core, one client on every channel",
        server_percent,
    );
    report.value(
        "foxglove_messages_per_second",
        "  messages a second to that client",
        received as f64 / elapsed,
    );
    let trace = trace(bench)?;
    let ticks = trace.ticks(from, to);
    let json = ticks.json();
    report.rows.push((
        "0x130 interval, two recorders and a Foxglove client (ms)".to_owned(),
        format!(
            "mean {} / p99 dev {} / max {} / >25 ms {} / >40 ms {} ({})",
            json["mean"], json["p99_dev"], json["max"], json["over_25"], json["over_40"], json["n"]
        ),
    ));
    insert(&mut report.json, "tick_interval_ms.watchers", json);
    report
        .ticks
        .push(("two recorders and a Foxglove client".to_owned(), ticks));
    Ok(())
}

/// A client drives; something cuts the gateway from the chassis; how long until state flows
/// again, and how long the chassis kept moving (its own ground truth).
fn recovery(bench: &mut Bench, report: &mut Report, states: StateSubscriber) -> anyhow::Result<()> {
    progress("recovery: the gateway killed (SIGKILL) and started again");
    drop(states);
    // A real client process streaming 0.3 m/s, until the robot moves.
    let driving = |bench: &Bench| -> anyhow::Result<std::process::Child> {
        let driver = command("scout")?
            .args([
                "drive",
                "--name",
                &bench.name,
                "--linear",
                "0.3",
                "--client",
                "bench-streamer",
            ])
            .stdin(std::process::Stdio::null())
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .context("starting scout drive")?;
        let states = connect(&bench.name)?.subscribe()?;
        wait_state(&states, |state| f64::from(state.motion.linear_mm_s) > 200.0)?;
        Ok(driver)
    };
    let mut driver = driving(bench)?;
    let killed = monotonic_ns();
    if let Some(gateway) = bench.gateway.take() {
        gateway.kill();
    }
    let states = bench.start_gateway(true)?;
    let restarted = monotonic_ns();
    let _ = driver.kill();
    let _ = driver.wait();
    bench.release_all()?;
    wait_state(&states, |_| true)?;

    progress("recovery: the chassis unplugged for 1 s");
    let mut driver = driving(bench)?;
    let unplugged = monotonic_ns();
    bench.sim.send("unplug 1000")?;
    bench.sim.next_port_line()?;
    let back = monotonic_ns();
    wait_state(&states, |state| {
        state.published_ns > back && state.link.state() == LinkState::Ok
    })?;
    let reconnected = monotonic_ns();
    let _ = driver.kill();
    let _ = driver.wait();
    bench.release_all()?;

    let trace = trace(bench)?;
    let ms = |ns: u64| ns as f64 / 1e6;
    report.value(
        "recovery_ms.restart",
        "gateway SIGKILL to a new gateway's state (ms)",
        ms(restarted - killed),
    );
    report.value(
        "recovery_ms.reconnect",
        "port back to link ok (ms)",
        ms(reconnected - back),
    );
    if let Some(rest) = trace.at_rest_after(killed) {
        report.value(
            "chassis_moving_ms.restart",
            "  chassis kept moving after the kill (ms)",
            ms(rest - killed),
        );
    }
    if let Some(rest) = trace.at_rest_after(unplugged) {
        report.value(
            "chassis_moving_ms.reconnect",
            "  chassis kept moving after the unplug (ms)",
            ms(rest - unplugged),
        );
    }
    Ok(())
}

/// Gateway CPU and memory at steady state with 8 subscribers, zenoh on, then off.
fn cost(bench: &mut Bench, report: &mut Report) -> anyhow::Result<()> {
    let seconds = bench.plan.window.to_string();
    for zenoh in [true, false] {
        progress(&format!(
            "cost: 8 subscribers, zenoh {}",
            if zenoh { "on" } else { "off" }
        ));
        if !zenoh {
            if let Some(gateway) = bench.gateway.take() {
                gateway.kill();
            }
            bench.start_gateway(false)?;
        }
        let pid = bench
            .gateway
            .as_ref()
            .map(Gateway::pid)
            .context("a gateway")?;
        let mut roles = Roles::default();
        for i in 0..8 {
            roles.spawn(&[
                "subscribe",
                &bench.name,
                &bench.scratch.text(&format!("cost-{i}")),
                &seconds,
            ])?;
        }
        std::thread::sleep(Duration::from_millis(500));
        let (cpu_before, _) = usage(pid)?;
        let start = Instant::now();
        std::thread::sleep(Duration::from_secs_f64(bench.plan.window - 1.0));
        let (cpu_after, rss) = usage(pid)?;
        let percent = (cpu_after - cpu_before) / start.elapsed().as_secs_f64() * 100.0;
        roles.wait()?;
        let suffix = if zenoh { "" } else { "_no_zenoh" };
        let label = if zenoh { "zenoh on" } else { "zenoh off" };
        report.value(
            &format!("gateway_cpu_percent{suffix}"),
            &format!("gateway CPU, % of a core, {label}"),
            percent,
        );
        report.value(
            &format!("gateway_rss_mb{suffix}"),
            &format!("gateway resident memory, MB, {label}"),
            rss,
        );
    }
    Ok(())
}

/// The protocol crate's CAN decode over the bundled capture of a real chassis.
/// How long the black box's thread works to save a full default box (5 minutes of a v1
/// chassis: 7 frames read and one written every 20 ms) and how big it is: the thread's work,
/// never the tick's.
fn black_box_write(report: &mut Report) -> anyhow::Result<()> {
    use scout_gateway::blackbox::{Direction, Recorded, Ring};
    let span = Duration::from_secs(300);
    let mut ring = Ring::new(span, 400_000);
    let frame =
        scout_protocol::CanFrame::new(0x151, &[0, 1, 0, 0xF5, 0, 0, 7, 0x5A]).context("a frame")?;
    let periods = span.as_millis() as u64 / 20;
    for period in 0..periods {
        for index in 0..8u64 {
            let at = Duration::from_millis(period * 20) + Duration::from_micros(index * 100);
            ring.push(Recorded {
                boot: at,
                wall: Duration::from_secs(1_764_280_000) + at,
                direction: if index == 7 {
                    Direction::Tx
                } else {
                    Direction::Rx
                },
                frame,
            });
        }
    }
    let path = std::env::temp_dir().join(format!("scout-bench-box-{}.log", std::process::id()));
    let start = Instant::now();
    {
        let file = std::fs::File::create(&path)?;
        let mut out = std::io::BufWriter::with_capacity(64 * 1024, file);
        ring.write_to(&mut out, &["a bench".to_owned()])?;
        std::io::Write::flush(&mut out)?;
    }
    let elapsed = start.elapsed();
    let size = std::fs::metadata(&path)?.len();
    let _ = std::fs::remove_file(&path);
    report.value(
        "black_box_save_ms",
        "black box, a full 5 min saved: the thread's time (ms)",
        elapsed.as_secs_f64() * 1000.0,
    );
    report.value(
        "black_box_file_mb",
        "black box, a full 5 min saved: the file (MB)",
        size as f64 / 1e6,
    );
    Ok(())
}

fn decode_throughput(report: &mut Report) {
    use scout_protocol::{can, candump};
    const CAPTURE: &str =
        include_str!("../../../protocol/tests/fixtures/scout-v1-capture-2019.candump");
    let frames: Vec<_> = CAPTURE
        .lines()
        .filter_map(|line| candump::parse(line).ok().map(|record| record.frame))
        .collect();
    let rounds = 2000;
    let start = Instant::now();
    for _ in 0..rounds {
        for frame in &frames {
            let _ = std::hint::black_box(can::decode(std::hint::black_box(frame)));
        }
    }
    let per_second = (frames.len() * rounds) as f64 / start.elapsed().as_secs_f64();
    report.value(
        "decode_frames_per_second",
        "CAN decode, frames/s (protocol crate)",
        per_second,
    );
}

fn print_table(report: &Report, quick: bool) {
    println!("## scout-bench{}", if quick { " --quick" } else { "" });
    println!();
    println!("Latencies as p50 / p99 / p99.9 / max (samples).");
    println!();
    println!("| what | figures |");
    println!("|---|---|");
    for (what, figures) in &report.rows {
        println!("| {what} | {figures} |");
    }
}
