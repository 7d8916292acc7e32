//! `scout-foxglove` (run as `scout record` and `scout foxglove`): MCAP recordings and the live
//! Foxglove WebSocket view of a robot (see the `scout_foxglove` library).
//!
//! Exit codes: 0 done (the duration passed, or Ctrl-C or SIGTERM closed the file or the
//! server); 1 something failed (writing the file, reading the gateway); 2 usage error (also: the
//! output exists without --force, the address cannot be listened on); 3 no gateway with that
//! name runs.

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use clap::{Args, Parser, Subcommand};
use scout_clients::failure::{self, Failure, FailureKind};
use scout_foxglove::live::{Live, LiveError, LiveOptions};
use scout_foxglove::origin::OriginPolicy;
use scout_foxglove::record::{RecordError, RecordOptions, record};
use scout_foxglove::source::SourceError;
use tracing_subscriber::EnvFilter;

/// The chassis in Foxglove: MCAP recordings and a live Foxglove WebSocket view.
#[derive(Debug, Parser)]
#[command(name = "scout-foxglove", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Record the state, the arbiter's status and events, and every motion command to MCAP.
    Record(RecordArgs),
    /// Serve the same channels live to Foxglove or Lichtblick (Foxglove WebSocket protocol).
    Serve(ServeArgs),
}

/// `scout record`.
#[derive(Debug, Args)]
struct RecordArgs {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout", value_name = "ROBOT")]
    name: String,
    /// The MCAP file to write (with --ros2: the bag, a directory).
    #[arg(long, short, value_name = "FILE.mcap")]
    output: PathBuf,
    /// Write ROS 2 messages (/odom, /tf, /battery_state, /joint_states, /diagnostics and the
    /// commands sent on ~/cmd_vel_sent: CDR with their definitions) into a rosbag2 bag, for
    /// `ros2 bag` and Foxglove's ROS panels, instead of the Foxglove channels.
    #[arg(long)]
    ros2: bool,
    /// With --ros2: the topics, namespace and frames as this `scout ros2` settings file names
    /// them [default: scout ros2's defaults].
    #[arg(long, value_name = "FILE.toml", requires = "ros2")]
    ros2_config: Option<PathBuf>,
    /// Stop after this many seconds [default: at Ctrl-C or SIGTERM].
    #[arg(long, value_name = "SECONDS")]
    duration: Option<f64>,
    /// Replace the file if it exists.
    #[arg(long)]
    force: bool,
}

/// `scout foxglove`.
#[derive(Debug, Args)]
struct ServeArgs {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout", value_name = "ROBOT")]
    name: String,
    /// The address to listen on (port 0: any free port, printed at start). Another address
    /// than 127.0.0.1 lets anyone who reaches it watch the robot.
    #[arg(long, default_value = "127.0.0.1:8765", value_name = "ADDR:PORT")]
    listen: SocketAddr,
    /// Offer the service /scout/estop: it latches a stop owned by --owner, through the
    /// gateway's stop path. Off by default (the view is read-only).
    #[arg(long)]
    estop: bool,
    /// Offer the service /scout/release, releasing --owner's stops (and no one else's). Off by
    /// default.
    #[arg(long)]
    allow_release: bool,
    /// The owner of the stops /scout/estop latches.
    #[arg(long, default_value = "foxglove", value_name = "NAME")]
    owner: String,
    /// Let web pages of ORIGIN connect (repeatable; exactly as the browser sends it, e.g.
    /// https://app.foxglove.dev; `null` for pages loaded from files or sandboxed; `*` for any).
    /// Without it only clients that send no Origin (desktop apps, libraries) and this
    /// machine's pages (localhost, 127.x.x.x, [::1], file://) may connect.
    #[arg(long = "allow-origin", value_name = "ORIGIN")]
    allow_origins: Vec<String>,
}

fn main() -> ExitCode {
    scout_man::exit_if_asked(<Cli as clap::CommandFactory>::command);
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            // The SDK's own info lines name its internal server's port, which is not the one to
            // connect to (the front's is printed): warnings and errors only.
            EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| EnvFilter::new("info,foxglove=warn")),
        )
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .init();
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    if let Err(error) = ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed)) {
        eprintln!("scout-foxglove: cannot handle Ctrl-C: {error}");
        return ExitCode::FAILURE;
    }
    let result = match cli.command {
        Command::Record(args) => run_record(&args, &stop),
        Command::Serve(args) => serve(&args, &stop),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("scout-foxglove: {error:#}");
            ExitCode::from(exit_code(&error))
        }
    }
}

fn run_record(args: &RecordArgs, stop: &AtomicBool) -> anyhow::Result<()> {
    let duration = match args.duration {
        None => None,
        Some(seconds) if seconds.is_finite() && seconds > 0.0 => {
            Some(Duration::from_secs_f64(seconds))
        }
        Some(seconds) => anyhow::bail!(Usage(format!(
            "--duration {seconds}: give a number of seconds above 0"
        ))),
    };
    let ros2 = if args.ros2 {
        Some(
            scout_ros2::config::Ros2Config::load(args.ros2_config.as_deref())
                .map_err(|error| Usage(error.to_string()))?,
        )
    } else {
        None
    };
    let options = RecordOptions {
        robot: args.name.clone(),
        output: args.output.clone(),
        ros2,
        duration,
        force: args.force,
        progress: true,
    };
    let summary = record(&options, stop)?;
    println!(
        "wrote {}: {} messages on {} channels in {:.1} s, {:.2} MB{}",
        summary.file.display(),
        summary.messages,
        summary.channels,
        summary.duration.as_secs_f64(),
        summary.bytes as f64 / 1e6,
        if summary.missed_states > 0 {
            format!(
                " ({} states lost: the recorder fell behind)",
                summary.missed_states
            )
        } else {
            String::new()
        }
    );
    Ok(())
}

fn serve(args: &ServeArgs, stop: &AtomicBool) -> anyhow::Result<()> {
    let options = LiveOptions {
        robot: args.name.clone(),
        listen: args.listen,
        estop: args.estop,
        allow_release: args.allow_release,
        owner: args.owner.clone(),
        origins: OriginPolicy::new(&args.allow_origins),
    };
    let live = Live::start(&options)?;
    let url = format!("ws://{}", live.address());
    println!(
        "Foxglove WebSocket for robot {} on {url}: in Foxglove or Lichtblick, Open connection, \
         Foxglove WebSocket, {url}{}",
        args.name,
        match (args.estop, args.allow_release) {
            (false, false) => " (read-only)".to_owned(),
            (estop, release) => format!(
                " (services:{}{})",
                if estop { " /scout/estop" } else { "" },
                if release { " /scout/release" } else { "" }
            ),
        }
    );
    std::io::stdout().flush()?;
    live.run(stop)?;
    Ok(())
}

/// A usage error found after parsing.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Usage(String);

impl FailureKind for Usage {
    fn kind(&self) -> Failure {
        Failure::Usage
    }
}

/// The exit code for `error`: its kind's (`scout_clients::failure`), knowing this program's
/// own errors.
fn exit_code(error: &anyhow::Error) -> u8 {
    failure::exit_code(
        error.chain(),
        &[
            failure::kind_if::<Usage>,
            failure::kind_if::<RecordError>,
            failure::kind_if::<LiveError>,
            failure::kind_if::<SourceError>,
        ],
    )
}
