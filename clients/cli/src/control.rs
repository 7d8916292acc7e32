//! The control subcommands: drive, estop, release, resume, lights, clear-fault, reset-odometry.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::Context;
use clap::Args;
use scout_clients::client::{ClientError, Robot};
use scout_clients::control::{ControlError, Controller, Lights, Stopper};
use scout_clients::interface::control::{StopPayload, UNKNOWN_UID};
use scout_clients::interface::control::{parse_fault_clear, parse_light_text};
use scout_clients::interface::stop_socket::StopSocketError;
use scout_clients::{Accepted, Class, DriveMode, ReleaseTarget, StopCause};
use scout_protocol::{Light, LightCommand};

use scout_clients::remote::{RemoteController, RemoteError, SessionSettings, peer_client_name};

use crate::{RemoteArgs, RobotArgs};

/// The drive loop's period: 50 Hz.
pub(crate) const DRIVE_PERIOD: Duration = Duration::from_millis(20);

/// A robot and this client's name.
#[derive(Debug, Args)]
pub struct ClientArgs {
    #[command(flatten)]
    robot: RobotArgs,
    /// This client's name, shown in the status and the gateway's audit log; with --remote,
    /// the peer name in the command keys (default `operator`), which your certificate's access
    /// control must allow.
    #[arg(long, value_name = "NAME")]
    client: Option<String>,
}

impl ClientArgs {
    fn name(&self, default_name: &str) -> String {
        self.client
            .clone()
            .unwrap_or_else(|| default_name.to_owned())
    }

    fn connect(&self, default_name: &str, class: Option<Class>) -> anyhow::Result<Controller> {
        let robot = Robot::connect(&self.robot.name)?;
        Ok(robot.controller(&self.name(default_name), class)?)
    }
}

/// The client name of the one-shot commands (estop, release, resume...): a person at a
/// terminal. The stops `scout estop` latches are owned by it.
pub use scout_clients::interface::control::OPERATOR;

#[derive(Debug, Args)]
pub struct DriveArgs {
    #[command(flatten)]
    client: ClientArgs,
    /// Linear speed, m/s (forward positive).
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.0)]
    linear: f64,
    /// Angular speed, rad/s (counter-clockwise positive).
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.0)]
    angular: f64,
    /// Sideways speed, m/s (leftward positive): a chassis that moves sideways only (the
    /// SCOUT MINI OMNI on protocol v2); any other refuses it.
    #[arg(long, allow_hyphen_values = true, default_value_t = 0.0)]
    lateral: f64,
    /// The motion mode to drive in, on a chassis that has them (a Ranger): dual_ackermann,
    /// parallel, spin, or park (with no speed: parks it). Default: the gateway picks it.
    #[arg(long, value_name = "MODE")]
    mode: Option<DriveMode>,
    /// How long to drive, s (default: until Ctrl-C).
    #[arg(long, value_name = "S")]
    duration: Option<f64>,
    /// The class to drive as.
    #[arg(long, default_value = "teleop")]
    class: Class,
    // With --remote: see --client.
    #[command(flatten)]
    remote: RemoteArgs,
}

/// A remote drive's life: after a partition, the output is zero once it ends.
pub const REMOTE_DRIVE_LIFE: Duration = Duration::from_millis(300);

/// The gateway's answer in words (`scout drive` prints it once per change, not per message).
pub fn describe(answer: &Result<Accepted, ControlError>) -> String {
    match answer {
        Ok(Accepted { clamped: false, .. }) => "accepted".into(),
        Ok(Accepted { clamped: true, .. }) => "accepted (clamped to the speed caps)".into(),
        Err(error) => error.to_string(),
    }
}

pub fn drive(args: &DriveArgs) -> anyhow::Result<ExitCode> {
    let duration = match args.duration {
        Some(s) if s.is_finite() && s >= 0.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => anyhow::bail!("--duration must be a non-negative number of seconds, found {s}"),
        None => None,
    };
    if let Some(settings) = args.remote.settings() {
        return drive_remote(args, &settings, duration);
    }
    let name = format!("drive-{}", std::process::id());
    let mut controller = args.client.connect(&name, Some(args.class))?;
    controller.take_control()?;
    let stop = ctrl_c()?;
    let start = Instant::now();
    let mut next = start;
    let mut last: Option<String> = None;
    let mut last_answer = Ok(Accepted::default());
    while !stop.load(Ordering::Relaxed) && duration.is_none_or(|d| start.elapsed() < d) {
        let answer = match args.mode {
            Some(mode) => {
                controller.drive_in_mode(mode, args.linear, args.lateral, args.angular, None)
            }
            None => controller.drive_body(args.linear, args.lateral, args.angular, None),
        };
        match &answer {
            Err(ControlError::NoAnswer { .. } | ControlError::Client(_)) => {
                return Err(answer.map(|_| ()).unwrap_err().into());
            }
            // Control ended (a stop, a gap, a release, a takeover): never taken back by itself.
            Err(error) if error.lost_control() => {
                println!("{error}");
                return Err(answer.map(|_| ()).unwrap_err().into());
            }
            _ => {}
        }
        let text = describe(&answer);
        if last.as_deref() != Some(text.as_str()) {
            println!("{text}");
            last = Some(text);
        }
        last_answer = answer;
        next += DRIVE_PERIOD;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    // Stop the robot before leaving: zero speed, then give the control back. Control that
    // ended meanwhile (a stall of this program past the class's age, a stop) is said, and is
    // no success: the robot stopped before it was asked to.
    let zero = controller.drive(0.0, 0.0);
    controller.relinquish().context("giving up control")?;
    if let Err(error) = zero
        && error.lost_control()
    {
        println!("{error}");
        return Err(error.into());
    }
    match last_answer {
        Err(rejected @ ControlError::Rejected(_)) => Err(rejected.into()),
        _ => Ok(ExitCode::SUCCESS),
    }
}

/// A flag Ctrl-C (and SIGTERM) raises: the drive loops end on it, stopping the robot first.
pub(crate) fn ctrl_c() -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    Ok(stop)
}

/// `scout drive --remote`: take control through zenoh, put a drive every 20 ms on the fast
/// lane (one in ten queried, whose answer says whether control holds), then give control back.
fn drive_remote(
    args: &DriveArgs,
    settings: &SessionSettings,
    duration: Option<Duration>,
) -> anyhow::Result<ExitCode> {
    let peer = args.client.name(OPERATOR);
    let mut controller = RemoteController::connect(settings, &args.client.robot.name, &peer)?;
    controller.take_control(args.class)?;
    println!(
        "control taken as {} ({})",
        peer_client_name(&peer),
        args.class
    );
    let stop = ctrl_c()?;
    let start = Instant::now();
    let mut next = start;
    let mut last: Option<String> = None;
    while !stop.load(Ordering::Relaxed) && duration.is_none_or(|d| start.elapsed() < d) {
        let (linear, lateral, angular) = (args.linear, args.lateral, args.angular);
        let answer = match args.mode {
            Some(mode) => {
                controller.drive_in_mode(mode, linear, lateral, angular, REMOTE_DRIVE_LIFE)
            }
            None => controller.drive_body(linear, lateral, angular, REMOTE_DRIVE_LIFE),
        };
        match answer {
            Ok(Some(answer)) => {
                let text = match (&answer.reason, answer.clamped) {
                    (Some(reason), _) => reason.clone(),
                    (None, true) => "accepted (clamped to the speed caps)".into(),
                    (None, false) => "accepted".into(),
                };
                if last.as_deref() != Some(text.as_str()) {
                    println!("{text}");
                    last = Some(text);
                }
            }
            Ok(None) => {}
            // Control ended (a stop, a gap, a release, a takeover): never taken back by itself.
            Err(error @ RemoteError::Refused { .. }) => {
                println!("{error}");
                return Err(error.into());
            }
            Err(error) => return Err(error.into()),
        }
        next += DRIVE_PERIOD;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let _ = controller.drive(0.0, 0.0, REMOTE_DRIVE_LIFE);
    controller.relinquish().context("giving up control")?;
    Ok(ExitCode::SUCCESS)
}

#[derive(Debug, Args)]
pub struct EstopArgs {
    #[command(flatten)]
    client: ClientArgs,
    /// Why (shown in the status and the audit log).
    #[arg(long, default_value = "scout estop")]
    reason: String,
    // With --remote: see --client.
    #[command(flatten)]
    remote: RemoteArgs,
}

/// Latches a stop through the stop endpoint: no iceoryx2, no shared memory, no client slot, so
/// that nothing on the host (a full `/dev/shm`, every slot taken) can keep it from latching.
pub fn estop(args: &EstopArgs) -> anyhow::Result<ExitCode> {
    let name = args.client.name(OPERATOR);
    let robot = &args.client.robot.name;
    if let Some(settings) = args.remote.settings() {
        let answer = RemoteController::connect(&settings, robot, &name)?.stop(&args.reason)?;
        println!(
            "stop{} latched, owned by {}: `scout release --remote` to release it",
            answer.stop.map(|id| format!(" #{id}")).unwrap_or_default(),
            peer_client_name(&name)
        );
        return Ok(ExitCode::SUCCESS);
    }
    let accepted = match Stopper::new(robot, &name)?.stop(&args.reason) {
        // No stop endpoint here: maybe this process lives in another network namespace than
        // the gateway; its iceoryx2 services tell (no gateway at all: exit 3).
        Err(ControlError::Stop(StopSocketError::NoGateway { .. })) => {
            Robot::connect(robot)?.stopper(&name)?.stop(&args.reason)?
        }
        other => other?,
    };
    println!(
        "stop #{} latched, owned by {name}: `scout release` to release it",
        accepted.stop.unwrap_or(0)
    );
    Ok(ExitCode::SUCCESS)
}

#[derive(Debug, Args)]
pub struct ReleaseArgs {
    #[command(flatten)]
    client: ClientArgs,
    /// Release only this client's own stops (by default every stop: `scout` is an operator).
    #[arg(long, conflicts_with = "owner")]
    own: bool,
    /// Release only the stops of this owner (a client's name, or `gateway` for gaps); not
    /// with --remote (a remote peer releases only its own).
    #[arg(long, value_name = "NAME", conflicts_with = "remote")]
    owner: Option<String>,
    /// Release only stops up to this id (as `scout status` lists them); default: the newest in
    /// the status read now, which this command prints. A stop latched after it survives.
    #[arg(long, value_name = "ID")]
    through: Option<u64>,
    // With --remote: see --client.
    #[command(flatten)]
    remote: RemoteArgs,
}

/// Releases what the status shows now (or up to `--through`): a stop latched after the status
/// was read survives, and is printed as still holding.
pub fn release(args: &ReleaseArgs) -> anyhow::Result<ExitCode> {
    if let Some(settings) = args.remote.settings() {
        let name = args.client.name(OPERATOR);
        RemoteController::connect(&settings, &args.client.robot.name, &name)?
            .release(args.through)?;
        println!(
            "released the stops of {}{}: nothing moves until a client takes control again",
            peer_client_name(&name),
            args.through
                .map(|id| format!(" up to #{id}"))
                .unwrap_or_default()
        );
        return Ok(ExitCode::SUCCESS);
    }
    let target = match (&args.owner, args.own) {
        (Some(owner), _) => ReleaseTarget::Owner(owner.clone()),
        (None, true) => ReleaseTarget::Own,
        (None, false) => ReleaseTarget::All,
    };
    let name = args.client.name(OPERATOR);
    let robot_name = &args.client.robot.name;
    let connected = Robot::connect(robot_name).and_then(|robot| Ok((robot.status()?, robot)));
    let (statuses, robot) = match connected {
        Ok(connected) => connected,
        Err(error) if error.no_shared_memory() => {
            return release_without_shared_memory(args, target, &name, &error);
        }
        Err(error) => return Err(error.into()),
    };
    let status = statuses
        .latest(Duration::from_secs(2))?
        .ok_or_else(|| crate::status::Silent(robot_name.clone()))?;
    let through = args.through.unwrap_or(status.newest_stop);
    if !status.stopped() {
        println!("nothing to release: no stop holds the robot");
        return Ok(ExitCode::SUCCESS);
    }
    let unlisted = (status.stop_total as usize).saturating_sub(status.stops().len());
    if unlisted > 0 {
        println!("{unlisted} more stops than the status lists: all up to #{through} are named");
    }
    let named: Vec<StopPayload> = (status.stops().iter())
        .filter(|stop| stop.id <= through)
        .filter(|stop| match &target {
            ReleaseTarget::Own => stop.owner.as_str() == name,
            ReleaseTarget::Owner(owner) => stop.owner.as_str() == owner,
            ReleaseTarget::All => true,
        })
        .copied()
        .collect();
    let answer = robot.stopper(&name)?.release(target, through);
    if answer.is_ok() {
        // What the gateway did, from its next status: one name may hold stops of several users,
        // and a release takes only those its sender may release.
        match statuses.latest(Duration::from_secs(2))? {
            Some(after) => {
                for stop in &named {
                    let kept = after.stops().iter().any(|left| left.id == stop.id);
                    println!("{}", stop_line(stop, kept));
                }
            }
            None => println!("(no status since: `scout status` shows what holds)"),
        }
    }
    println!("{}", describe(&answer));
    answer?;
    Ok(ExitCode::SUCCESS)
}

/// This process's user (the owner of `/proc/self`).
fn own_uid() -> Option<u32> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata("/proc/self").ok().map(|m| m.uid())
}

/// A stop a release named: released, or kept and why (another user's, an operator's).
fn stop_line(stop: &StopPayload, kept: bool) -> String {
    let cause = StopCause::from_raw(stop.cause).map_or("unknown", StopCause::name);
    let why = if !kept {
        String::new()
    } else if stop.by_operator {
        " (an operator's)".to_owned()
    } else if stop.persists {
        " (its cause persists)".to_owned()
    } else if stop.uid != UNKNOWN_UID && Some(stop.uid) != own_uid() {
        format!(" (user {}'s)", stop.uid)
    } else {
        String::new()
    };
    format!(
        "{} #{} {} ({cause}): {}{why}",
        if kept { "kept" } else { "released" },
        stop.id,
        stop.owner.as_str(),
        stop.reason.as_str()
    )
}

/// A release with no shared memory to read the status from (a full `/dev/shm`): through the
/// stop endpoint alone, up to `--through` or the newest stop the gateway names (its ping's
/// answer). The stops cannot be listed first, so this says so.
fn release_without_shared_memory(
    args: &ReleaseArgs,
    target: ReleaseTarget,
    name: &str,
    why: &ClientError,
) -> anyhow::Result<ExitCode> {
    eprintln!("scout: {why}");
    let mut stopper = Stopper::new(&args.client.robot.name, name)?;
    let through = match args.through {
        Some(through) => through,
        None => match stopper.newest_stop()? {
            Some(newest) => newest,
            None => {
                println!("nothing to release: no stop was ever latched");
                return Ok(ExitCode::SUCCESS);
            }
        },
    };
    println!(
        "releasing through the stop endpoint, without listing the stops (that needs shared \
         memory): every stop up to #{through} that this release names"
    );
    let answer = stopper.release(target, through);
    println!("{}", describe(&answer));
    answer?;
    Ok(ExitCode::SUCCESS)
}

/// Sends one request and prints the answer.
pub fn one_shot(
    args: &ClientArgs,
    request: impl FnOnce(&mut Controller) -> Result<Accepted, ControlError>,
) -> anyhow::Result<ExitCode> {
    let mut controller = args.connect(OPERATOR, None)?;
    let answer = request(&mut controller);
    println!("{}", describe(&answer));
    answer?;
    Ok(ExitCode::SUCCESS)
}

#[derive(Debug, Args)]
pub struct LightsArgs {
    #[command(flatten)]
    client: ClientArgs,
    /// Front light: off, on, breath or custom, with `:BRIGHTNESS` 0..100 (default 100).
    #[arg(long, value_name = "MODE[:BRIGHTNESS]", value_parser = parse_light_text)]
    front: Option<Light>,
    /// Rear light, as --front.
    #[arg(long, value_name = "MODE[:BRIGHTNESS]", value_parser = parse_light_text)]
    rear: Option<Light>,
    /// `auto`: hand the lights back to the chassis.
    #[arg(value_parser = ["auto"])]
    auto: Option<String>,
}

pub fn lights(args: &LightsArgs) -> anyhow::Result<ExitCode> {
    let lights = match (&args.auto, args.front, args.rear) {
        (Some(_), None, None) => Lights::Auto,
        (Some(_), ..) => anyhow::bail!("`auto` takes no --front or --rear"),
        (None, None, None) => anyhow::bail!("give --front and/or --rear, or `auto`"),
        (None, front, rear) => Lights::Manual(LightCommand {
            enabled: true,
            front: front.unwrap_or_default(),
            rear: rear.unwrap_or_default(),
        }),
    };
    one_shot(&args.client, |controller| controller.lights(lights))
}

#[derive(Debug, Args)]
pub struct ClearFaultArgs {
    #[command(flatten)]
    client: ClientArgs,
    /// battery_undervoltage, battery_overvoltage, motor_1_comm .. motor_4_comm,
    /// driver_overtemp, motor_overcurrent, or all.
    kind: String,
}

pub fn clear_fault(args: &ClearFaultArgs) -> anyhow::Result<ExitCode> {
    let code = parse_fault_clear(&args.kind)?;
    one_shot(&args.client, |controller| controller.clear_fault(code))
}
