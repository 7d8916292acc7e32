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
use scout_clients::failure::{Failure, FailureKind};
use scout_clients::remote::{RemoteStates, SessionSettings};

use crate::{RemoteArgs, RobotArgs};

#[derive(Debug, Args)]
pub struct EchoArgs {
    #[command(flatten)]
    robot: RobotArgs,
    /// One JSON object per state update (the schema in docs/operating.md).
    #[arg(long)]
    json: bool,
    /// Exit after N updates.
    #[arg(long, value_name = "N")]
    count: Option<u64>,
    /// Give up when no update arrives for this many seconds.
    #[arg(long, default_value_t = 3.0, value_name = "S")]
    timeout: f64,
    // With --remote, `--name '*'` shows every robot.
    #[command(flatten)]
    remote: RemoteArgs,
}

pub fn run(args: &EchoArgs) -> anyhow::Result<ExitCode> {
    if !(args.timeout.is_finite() && args.timeout > 0.0) {
        anyhow::bail!("--timeout must be a positive number of seconds");
    }
    let timeout = Duration::from_secs_f64(args.timeout);
    if let (Some(settings), Some(endpoint)) = (args.remote.settings(), &args.remote.remote) {
        return remote(args, &settings, endpoint, timeout);
    }
    let robot = Robot::connect(&args.robot.name)?;
    let subscriber = robot.subscribe()?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    // Ctrl-C and SIGTERM end it normally (exit 0), after the line or view being written.
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    if args.json || !std::io::IsTerminal::is_terminal(&std::io::stdout()) {
        echo_json(
            &subscriber,
            args.count,
            timeout,
            &|| stop.load(Ordering::Relaxed),
            &mut out,
        )?;
        return Ok(ExitCode::SUCCESS);
    }
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

/// No state through zenoh within the timeout.
#[derive(Debug, thiserror::Error)]
#[error(
    "no {what} from robot '{robot}' through {endpoint} for {timeout:?}: is the gateway running with zenoh, and reachable?"
)]
pub struct RemoteSilent {
    /// What did not arrive: `state`, `status`.
    pub what: &'static str,
    pub robot: String,
    pub endpoint: String,
    pub timeout: Duration,
}

/// `--remote`: the state JSON through zenoh, one line per update (the JSON itself with --json,
/// a summary otherwise).
fn remote(
    args: &EchoArgs,
    settings: &SessionSettings,
    endpoint: &str,
    timeout: Duration,
) -> anyhow::Result<ExitCode> {
    let states = RemoteStates::connect(settings, &args.robot.name)?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut printed = 0;
    while args.count.is_none_or(|count| printed < count) {
        let Some(state) = states.next_timeout(timeout)? else {
            return Err(RemoteSilent {
                what: "state",
                robot: args.robot.name.clone(),
                endpoint: endpoint.to_owned(),
                timeout,
            }
            .into());
        };
        if args.json {
            writeln!(out, "{state}")?;
        } else {
            writeln!(
                out,
                "{} seq {} link {} battery {} V linear {} m/s angular {} rad/s",
                state["robot"].as_str().unwrap_or("?"),
                state["seq"],
                state["link"]["state"].as_str().unwrap_or("?"),
                state["system"]["battery_voltage"],
                state["motion"]["linear"],
                state["motion"]["angular"],
            )?;
        }
        out.flush()?;
        printed += 1;
    }
    Ok(ExitCode::SUCCESS)
}

/// A gateway silent through zenoh is as good as gone (or unreachable).
impl FailureKind for RemoteSilent {
    fn kind(&self) -> Failure {
        Failure::NoGateway
    }
}
