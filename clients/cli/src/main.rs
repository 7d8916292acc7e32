//! `scout`: the command-line tool for a SCOUT chassis behind scout-gateway.
//!
//! Exit codes: README.md's "Exit codes" lists them, once; `exit_code` maps errors to them.
//! `scout ros2` runs the `scout-ros2` program, `scout record` and `scout foxglove` the
//! `scout-foxglove` program, `scout doctor` the `scout-doctor` program; each exits with that
//! program's code.

mod calibrate;
mod companion;
mod control;
mod decode;
mod echo;
mod router;
mod status;
mod teleop;

use std::io::ErrorKind;
use std::process::ExitCode;

use clap::{Args, Parser, Subcommand};
use scout_clients::failure;

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
    Decode(decode::DecodeArgs),
    /// Show the chassis state a gateway publishes: a live view, or JSON lines with --json;
    /// with --remote, `--name '*'` shows every robot.
    Echo(echo::EchoArgs),
    /// Drive at a speed at 50 Hz for a duration (or until Ctrl-C), then give up control.
    Drive(control::DriveArgs),
    /// Keyboard teleop: arrows or WASD change speed, space stops, e latches the e-stop, q quits.
    Teleop(teleop::TeleopArgs),
    /// Latch the safety stop: zero speed at once, until `scout release`.
    Estop(control::EstopArgs),
    /// Release stops: all of them (the default), `--own`, or `--owner NAME`; refused while a
    /// stop's cause persists. Nothing moves until clients take control again.
    Release(control::ReleaseArgs),
    /// Arm autonomy again after a teleop takeover, a stop or a release.
    Resume(control::ClientArgs),
    /// Set the lights: `--front MODE[:BRIGHTNESS] --rear MODE[:BRIGHTNESS]`, or `auto`.
    Lights(control::LightsArgs),
    /// Clear a chassis fault: send its code in the next 3 motion commands (`all`: every code).
    ClearFault(control::ClearFaultArgs),
    /// Show the arbiter's status: the stops and what to do, who drives, the output, autonomy,
    /// the clients.
    Status(status::StatusArgs),
    /// Reset the gateway's odometry to the origin.
    ResetOdometry(control::ClientArgs),
    /// Calibrate the odometry: the robot drives a straight distance and turns in place, you
    /// say what you measured, and the factors go into the gateway's configuration.
    Calibrate(calibrate::CalibrateArgs),
    /// The gateway's black box of the bus: `scout blackbox save` writes the last minutes of
    /// frames to disk now (the gateway's log names the file; `scout decode FILE` reads it).
    Blackbox(BlackboxArgs),
    /// Run a zenoh router for a fleet: gateways connect to it, remote readers read through it.
    Router(router::RouterArgs),
    /// Make the chassis a ROS 2 node: /odom, /tf, /battery_state, /joint_states, /diagnostics
    /// out; /cmd_vel through the arbiter; e-stop and release services (`scout ros2 --help`).
    ///
    /// Runs the `scout-ros2` program (found beside `scout`, else on PATH), which carries the ROS
    /// 2 middleware so that `scout` does not.
    #[command(disable_help_flag = true)]
    Ros2(companion::CompanionArgs),
    /// Record the state, the arbiter's status and events and every motion command to an MCAP
    /// file that Foxglove opens (`scout record --help`).
    ///
    /// Runs the `scout-foxglove` program (found beside `scout`, else on PATH).
    #[command(disable_help_flag = true)]
    Record(companion::CompanionArgs),
    /// Serve the robot live to Foxglove or Lichtblick over the Foxglove WebSocket protocol,
    /// the same channels as a recording (`scout foxglove --help`).
    ///
    /// Runs the `scout-foxglove` program (found beside `scout`, else on PATH).
    #[command(disable_help_flag = true)]
    Foxglove(companion::CompanionArgs),
    /// Serve the operator's web page: live state, stops, E-STOP and hold-to-drive on any phone
    /// or laptop, through the arbiter like every client (`scout web --help`). Runs the
    /// `scout-web` program.
    #[command(disable_help_flag = true)]
    Web(companion::CompanionArgs),
    /// Check the set-up in order (device, CAN interface, traffic, protocol, the chassis' e-stop,
    /// RC, faults and battery, the gateway and its stops) and say how to fix what fails (`scout
    /// doctor --help`).
    ///
    /// Runs the `scout-doctor` program (found beside `scout`, else on PATH).
    #[command(disable_help_flag = true)]
    Doctor(companion::CompanionArgs),
}

#[derive(Debug, Args)]
struct BlackboxArgs {
    #[command(subcommand)]
    action: BlackboxAction,
}

#[derive(Debug, Subcommand)]
enum BlackboxAction {
    /// Save the black box now (also done by the gateway on every stop it latches).
    Save(control::ClientArgs),
}

/// The robot to talk to.
#[derive(Debug, Args)]
struct RobotArgs {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout", value_name = "ROBOT")]
    name: String,
}

/// Through zenoh instead of on this host.
#[derive(Debug, Args)]
struct RemoteArgs {
    /// Through zenoh, connecting to this endpoint (the gateway's or a router's:
    /// tcp/HOST:PORT, tls/..., quic/HOST:PORT?mixed_rel=1, udp/...), instead of iceoryx2 on
    /// this host.
    #[arg(long, value_name = "ENDPOINT")]
    remote: Option<String>,
    /// Zenoh configuration file for --remote (TLS...) [default: $ZENOH_CONFIG].
    #[arg(long, value_name = "FILE", requires = "remote")]
    zenoh_config: Option<String>,
}

impl RemoteArgs {
    /// The zenoh session settings, if --remote was given.
    fn settings(&self) -> Option<scout_clients::remote::SessionSettings> {
        let endpoint = self.remote.clone()?;
        Some(scout_clients::remote::SessionSettings {
            config_file: self.zenoh_config.clone(),
            listen: Vec::new(),
            connect: vec![endpoint],
        })
    }
}

fn main() -> ExitCode {
    scout_man::exit_if_asked(<Cli as clap::CommandFactory>::command);
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Decode(args) => decode::run(&args),
        Command::Echo(args) => echo::run(&args),
        Command::Drive(args) => control::drive(&args),
        Command::Teleop(args) => teleop::run(&args),
        Command::Estop(args) => control::estop(&args),
        Command::Release(args) => control::release(&args),
        Command::Resume(args) => control::one_shot(&args, |c| c.resume()),
        Command::Lights(args) => control::lights(&args),
        Command::ClearFault(args) => control::clear_fault(&args),
        Command::Status(args) => status::run(&args),
        Command::ResetOdometry(args) => control::one_shot(&args, |c| c.reset_odometry()),
        Command::Calibrate(args) => calibrate::run(&args),
        Command::Blackbox(BlackboxArgs {
            action: BlackboxAction::Save(args),
        }) => control::one_shot(&args, |c| c.save_black_box()),
        Command::Router(args) => router::run(&args),
        Command::Ros2(args) => companion::run(companion::ROS2, &[], &args),
        Command::Record(args) => companion::run(companion::FOXGLOVE, &["record"], &args),
        Command::Foxglove(args) => companion::run(companion::FOXGLOVE, &["serve"], &args),
        Command::Web(args) => companion::run(companion::WEB, &[], &args),
        Command::Doctor(args) => companion::run(companion::DOCTOR, &[], &args),
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

/// Whether the error is a closed output pipe (`scout echo | head`): the reader's normal end.
fn is_broken_pipe(error: &anyhow::Error) -> bool {
    error.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|e| e.kind() == ErrorKind::BrokenPipe)
    })
}

/// The exit code for `error`: its kind's (`scout_clients::failure`), knowing this program's
/// own errors.
fn exit_code(error: &anyhow::Error) -> u8 {
    failure::exit_code(
        error.chain(),
        &[
            failure::kind_if::<status::Silent>,
            failure::kind_if::<echo::RemoteSilent>,
        ],
    )
}
