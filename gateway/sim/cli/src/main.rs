//! `scout-sim`: a simulated SCOUT chassis on a pseudo-terminal (serial or slcan) or a SocketCAN
//! interface, with fault injection from stdin or a script.
//!
//! Exit codes: 0 normal exit (quit, Ctrl-C, SIGTERM), 1 runtime error (port could not be
//! created or opened), 2 usage error.

use std::io::BufRead;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Sender, channel};

use anyhow::Context;
use clap::{ArgGroup, Parser, ValueEnum};
use scout_protocol::Transport;
use scout_protocol::model::Model;
use scout_sim::SimParams;
use scout_sim::replay::Replay;
use scout_sim::run::{Protocol, SimOptions, run};
use scout_sim::script::{self, SimCommand};

/// A simulated AgileX SCOUT chassis: protocol v1 (the 2019 SCOUT), or v2 (SCOUT 2.0, SCOUT
/// MINI: CAN only, standby at power-on until the host sends 0x421 [01]).
///
/// With --serial or --slcan it creates a pseudo-terminal and prints its path as the first line of
/// standard output (`serial /dev/pts/N` or `slcan /dev/pts/N`); with --can it uses a SocketCAN
/// interface. Fault injection commands are read from standard input (type `help`); a statistics
/// JSON line is printed on `stats` and at exit.
#[derive(Debug, Parser)]
#[command(version, about, group(ArgGroup::new("transport").required(true)))]
struct Cli {
    /// Speak the RS232 protocol (13-byte frames) on a new pseudo-terminal.
    #[arg(long, group = "transport")]
    serial: bool,
    /// Be a serial-line CAN adapter (slcan) with the chassis behind it, on a new pseudo-terminal.
    #[arg(long, group = "transport")]
    slcan: bool,
    /// Use this SocketCAN interface (e.g. vcan0).
    #[arg(long, group = "transport", value_name = "IFACE")]
    can: Option<String>,
    /// Keep a symbolic link at PATH pointing at the pseudo-terminal (stable across `unplug`).
    #[arg(long, value_name = "PATH")]
    link: Option<PathBuf>,
    /// Record the wire in FILE with CLOCK_BOOTTIME times, for benchmarks (`F NS` feedback
    /// written, `C NS LINEAR ANGULAR` motion command read, `A NS LINEAR` actual speed changed).
    #[arg(long, value_name = "FILE")]
    trace: Option<PathBuf>,
    /// Run the simulator's loop under SCHED_FIFO at this priority (1-99; needs CAP_SYS_NICE),
    /// so that a loaded host delays the gateway, not the simulated chassis measuring it.
    #[arg(long, value_name = "N", default_value_t = 0)]
    realtime_priority: u8,
    /// Run fault-injection commands from FILE (with `wait MS` lines) as well as from stdin.
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,
    /// Chassis parameters (TOML; keys as in SimParams, e.g. `max_angular = 0.7853`).
    #[arg(long, value_name = "FILE")]
    params: Option<PathBuf>,
    /// The maximum angular speed in rad/s (overrides the parameter file).
    #[arg(long)]
    max_angular: Option<f64>,
    /// The firmware's protocol.
    #[arg(long, value_enum, default_value_t = ProtocolArg::V1)]
    protocol: ProtocolArg,
    /// The model: its speed limits (v2 firmware clamps commands to them), geometry and
    /// actuators [default: scout with v1, scout2 with v2]. A parameter file overrides what it
    /// sets. docs/chassis.md lists the models (and a name that is none says them).
    #[arg(long, value_name = "MODEL", value_parser = Model::parse)]
    model: Option<Model>,
    /// Seed for `garbage`.
    #[arg(long, default_value_t = 0x5C07)]
    seed: u64,
    /// Replay a gateway's black box (`scout blackbox save`, or saved on a stop): the frames it
    /// read from the chassis go out again with their spacing, instead of the model's feedback;
    /// the chassis falls silent after the last.
    #[arg(long, value_name = "FILE")]
    replay: Option<PathBuf>,
}

/// `--protocol`.
#[derive(Debug, Clone, Copy, ValueEnum)]
enum ProtocolArg {
    /// Protocol v1.
    V1,
    /// Protocol v2.
    V2,
}

fn main() -> ExitCode {
    scout_man::exit_if_asked(<Cli as clap::CommandFactory>::command);
    let cli = Cli::parse();
    if matches!(cli.protocol, ProtocolArg::V2) && cli.serial {
        eprintln!(
            "scout-sim: protocol v2 is CAN only (the vendor SDK implements no v2 over RS232): use \
             --slcan or --can"
        );
        return ExitCode::from(2);
    }
    if let Some(model) = cli.model
        && matches!(cli.protocol, ProtocolArg::V1)
        && !model.speaks(Protocol::V1)
    {
        eprintln!(
            "scout-sim: a {model} speaks protocol v2 alone: add --protocol v2 (with --slcan or \
             --can)"
        );
        return ExitCode::from(2);
    }
    let _log = scout_io::logging::init();
    match simulate(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("scout-sim: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn simulate(cli: Cli) -> anyhow::Result<()> {
    let transport = match (&cli.can, cli.slcan) {
        (Some(_), _) => Transport::Can,
        (None, true) => Transport::Slcan,
        (None, false) => Transport::Serial,
    };
    let protocol = match cli.protocol {
        ProtocolArg::V1 => Protocol::V1,
        ProtocolArg::V2 => Protocol::V2,
    };
    let model = cli.model.unwrap_or(Model::default_for(protocol));
    let base = SimParams::for_model(model);
    let mut params = match &cli.params {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            with_file(&base, &text).with_context(|| format!("parsing {}", path.display()))?
        }
        None => base,
    };
    if let Some(max_angular) = cli.max_angular {
        params.max_angular = max_angular;
    }
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C / SIGTERM handler")?;

    let (commands, received) = channel();
    let from_stdin = commands.clone();
    std::thread::spawn(move || feed(std::io::stdin().lock(), &from_stdin));
    if let Some(path) = &cli.script {
        let file =
            std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
        std::thread::spawn(move || feed(std::io::BufReader::new(file), &commands));
    }
    let replay = match &cli.replay {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("reading {}", path.display()))?;
            let replay = Replay::parse(&text).with_context(|| format!("in {}", path.display()))?;
            eprintln!(
                "scout-sim: replaying {} frames ({:.1} s) from {}",
                replay.len(),
                replay.length().as_secs_f64(),
                path.display()
            );
            Some(replay)
        }
        None => None,
    };
    let options = SimOptions {
        replay,
        transport,
        protocol,
        can_interface: cli.can,
        link: cli.link,
        params,
        seed: cli.seed,
        trace: cli.trace,
        realtime_priority: cli.realtime_priority,
    };
    run(options, &received, &stop, &mut std::io::stdout().lock())
}

/// `base` with the keys a parameter file sets replaced.
fn with_file(base: &SimParams, text: &str) -> anyhow::Result<SimParams> {
    let file: toml::Table = toml::from_str(text)?;
    Ok(base.with_overrides(&file)?)
}

/// Sends each command of `input` to the simulator, sleeping on `wait` lines.
fn feed(input: impl BufRead, commands: &Sender<SimCommand>) {
    for line in input.lines() {
        let Ok(line) = line else { return };
        match script::parse(&line) {
            Ok(Some(SimCommand::Wait(duration))) => std::thread::sleep(duration),
            Ok(Some(command)) => {
                if commands.send(command).is_err() {
                    return;
                }
            }
            Ok(None) => {}
            Err(error) => eprintln!("scout-sim: {error}"),
        }
    }
}
