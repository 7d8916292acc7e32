//! `scout echo`: the chassis state, live or as JSON lines.

use std::io::Write;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use scout_clients::client::Robot;
use scout_clients::echo::{echo_json, echo_live};

use crate::RobotArgs;

#[derive(Debug, Args)]
pub struct EchoArgs {
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

pub fn run(args: &EchoArgs) -> anyhow::Result<ExitCode> {
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
