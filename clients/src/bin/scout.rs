//! `scout`: the command-line tool for a SCOUT chassis.
//!
//! Exit codes: 0 success; 1 the command ran but something failed (a line `scout decode` could
//! not decode, an I/O error); 2 usage error; 3 no gateway with that name is running, or it
//! stopped answering.

use std::io::{BufRead, BufWriter, ErrorKind, Write};
use std::process::ExitCode;

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Parser, Subcommand};
use scout_clients::client::{ClientError, Robot};
use scout_clients::decode::{decode_line, frame_json, frame_text};
use scout_clients::echo::{EchoError, echo_json, echo_live};
use scout_clients::ipc::ServiceError;
use scout_protocol::units::DEFAULT_MAX_ANGULAR_SPEED;

/// Command-line tool for an AgileX SCOUT chassis.
#[derive(Debug, Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Decode candump lines (screen, log or compact format) or serial frames as hex.
    ///
    /// Reads the lines given as arguments, or standard input when there are none:
    /// `candump can0 | scout decode`. Prints one line (or JSON object) per frame; a bad line is
    /// reported on standard error with its line number and the rest is still decoded.
    Decode(DecodeArgs),
    /// Show the chassis state a gateway publishes: a live view, or JSON lines with --json.
    Echo(EchoArgs),
    /// Reset the gateway's odometry to the origin.
    ResetOdometry(RobotArgs),
}

#[derive(Debug, Args)]
struct RobotArgs {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout", value_name = "ROBOT")]
    name: String,
}

#[derive(Debug, Args)]
struct EchoArgs {
    #[command(flatten)]
    robot: RobotArgs,
    /// One JSON object per state update (the schema in the README).
    #[arg(long)]
    json: bool,
    /// Exit after N updates.
    #[arg(long, value_name = "N")]
    count: Option<u64>,
    /// Give up when no update arrives for this many seconds.
    #[arg(long, default_value_t = 3.0, value_name = "S")]
    timeout: f64,
}

#[derive(Debug, Args)]
struct DecodeArgs {
    /// One JSON object per frame instead of text.
    #[arg(long)]
    json: bool,
    /// The chassis' maximum angular speed in rad/s (100 % of a command's angular byte).
    #[arg(long, default_value_t = DEFAULT_MAX_ANGULAR_SPEED)]
    max_angular: f64,
    /// Lines to decode; standard input when none.
    lines: Vec<String>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Decode(args) => decode(&args),
        Command::Echo(args) => echo(&args),
        Command::ResetOdometry(args) => Robot::connect(&args.name)
            .and_then(|robot| robot.reset_odometry())
            .map(|()| ExitCode::SUCCESS)
            .map_err(Into::into),
    };
    match result {
        Ok(code) => code,
        Err(error) if is_broken_pipe(&error) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("scout: {error:#}");
            ExitCode::from(exit_code(&error))
        }
    }
}

/// Exit code 3 when the gateway is missing or silent, 1 for anything else.
fn exit_code(error: &anyhow::Error) -> u8 {
    let no_gateway = error.chain().any(|cause| {
        matches!(
            cause.downcast_ref(),
            Some(ClientError::Service(ServiceError::NoGateway { .. }))
        ) || matches!(cause.downcast_ref(), Some(ServiceError::NoGateway { .. }))
            || matches!(cause.downcast_ref(), Some(EchoError::Idle(_)))
    });
    if no_gateway { 3 } else { 1 }
}

fn echo(args: &EchoArgs) -> anyhow::Result<ExitCode> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        anyhow::bail!("--timeout must be a positive number of seconds");
    }
    let timeout = Duration::from_secs_f64(args.timeout);
    let robot = Robot::connect(&args.robot.name)?;
    let subscriber = robot.subscribe()?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    if args.json || !std::io::IsTerminal::is_terminal(&std::io::stdout()) {
        echo_json(&subscriber, args.count, timeout, &mut out)?;
        return Ok(ExitCode::SUCCESS);
    }
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    // Hide the cursor while drawing; show it again on every way out.
    write!(out, "\x1b[?25l")?;
    let result = echo_live(
        &subscriber,
        args.count,
        timeout,
        &|| stop.load(Ordering::Relaxed),
        &mut out,
    );
    write!(out, "\x1b[?25h")?;
    out.flush()?;
    result?;
    Ok(ExitCode::SUCCESS)
}

fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error
        .downcast_ref::<std::io::Error>()
        .is_some_and(|e| e.kind() == ErrorKind::BrokenPipe)
}

fn decode(args: &DecodeArgs) -> anyhow::Result<ExitCode> {
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let mut bad_lines = 0usize;
    let mut decode_one = |number: usize, line: &str| -> anyhow::Result<()> {
        if line.trim().is_empty() {
            return Ok(());
        }
        match decode_line(line) {
            Ok(frames) => {
                for frame in frames {
                    if args.json {
                        writeln!(out, "{}", frame_json(&frame, args.max_angular))?;
                    } else {
                        writeln!(out, "{}", frame_text(&frame, args.max_angular))?;
                    }
                }
            }
            Err(error) => {
                bad_lines += 1;
                eprintln!("scout decode: line {number}: {error}: {}", line.trim());
            }
        }
        Ok(())
    };
    if args.lines.is_empty() {
        for (index, line) in std::io::stdin().lock().lines().enumerate() {
            let line = line.context("reading standard input")?;
            decode_one(index + 1, &line)?;
        }
    } else {
        for (index, line) in args.lines.iter().enumerate() {
            decode_one(index + 1, line)?;
        }
    }
    out.flush()?;
    if bad_lines > 0 {
        eprintln!("scout decode: {bad_lines} line(s) could not be decoded");
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}
