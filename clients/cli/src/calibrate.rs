//! `scout calibrate`: the odometry's calibration, guided. The robot drives a straight distance
//! and turns in place (a Hunter, which cannot, on a circle) by its own odometry, each leg under
//! a teleop lease taken when the operator presses Enter (`scout estop` or Ctrl-C stops it at any
//! time); the operator says what was measured on the floor; the factors go into the gateway's
//! configuration, comments kept.

use std::f64::consts::TAU;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Args;
use scout_clients::Class;
use scout_clients::StatePayload;
use scout_clients::client::{Robot, StateSubscriber};
use scout_clients::control::{ControlError, Controller};
use scout_clients::interface::state::ODOMETRY_SCALE_RANGE;
use scout_protocol::kinematics::wrap_angle;
use scout_protocol::model::Model;

use crate::RobotArgs;
use crate::control::{DRIVE_PERIOD, ctrl_c};

/// Speeds below these are standing still.
const STILL_LINEAR: f64 = 0.005;
const STILL_ANGULAR: f64 = 0.005;
/// Standing still this long ends a leg.
const STILL_FOR: Duration = Duration::from_millis(500);

#[derive(Debug, Args)]
pub struct CalibrateArgs {
    #[command(flatten)]
    robot: RobotArgs,
    /// The gateway's configuration file: its `[odometry]` factors are written there (the rest
    /// of the file and its comments are kept); the gateway applies them at its next start.
    #[arg(long, value_name = "FILE")]
    config: PathBuf,
    /// How far to drive straight, m (by the odometry).
    #[arg(long, default_value_t = 2.0, value_name = "M")]
    distance: f64,
    /// How many turns in place, or on a circle for a chassis that turns only while moving (by
    /// the odometry).
    #[arg(long, default_value_t = 2.0, value_name = "N")]
    turns: f64,
    /// The speed straight ahead (and round the circle), m/s.
    #[arg(long, default_value_t = 0.3, value_name = "M_S")]
    speed: f64,
    /// The speed of the turns, rad/s (round a circle: at most what its tightest allows).
    #[arg(long, default_value_t = 0.4, value_name = "RAD_S")]
    turn_speed: f64,
    /// Say the factors, write nothing.
    #[arg(long)]
    dry_run: bool,
}

/// The new factors from what the odometry reported under the factors in force and what was
/// measured: the factor in force times measured over reported.
pub fn factor(in_force: f64, reported: f64, measured: f64) -> anyhow::Result<f64> {
    if !(reported.is_finite() && reported > 0.0 && measured.is_finite() && measured > 0.0) {
        bail!("measured ({measured}) and reported ({reported}) must be positive numbers");
    }
    let factor = in_force * measured / reported;
    if !ODOMETRY_SCALE_RANGE.contains(&factor) {
        bail!(
            "the factor would be {factor:.4}, outside {}..={}: more than a calibration is off \
             (the model, its gearbox, a wheel), or the measurement is; nothing written",
            ODOMETRY_SCALE_RANGE.start(),
            ODOMETRY_SCALE_RANGE.end()
        );
    }
    Ok(factor)
}

/// `text` (a gateway configuration) with `[odometry]`'s two factors set, everything else kept.
pub fn with_factors(text: &str, distance_scale: f64, yaw_scale: f64) -> anyhow::Result<String> {
    let mut document: toml_edit::DocumentMut = text
        .parse()
        .context("the configuration is not valid TOML")?;
    let odometry = document
        .entry("odometry")
        .or_insert_with(toml_edit::table)
        .as_table_mut()
        .context("`odometry` in the configuration is not a table")?;
    let rounded = |value: f64| (value * 10_000.0).round() / 10_000.0;
    odometry["distance_scale"] = toml_edit::value(rounded(distance_scale));
    odometry["yaw_scale"] = toml_edit::value(rounded(yaw_scale));
    Ok(document.to_string())
}

/// What the operator types, line by line, and the stop flag.
struct Operator<'a> {
    input: Box<dyn BufRead + 'a>,
    stop: &'a AtomicBool,
}

impl Operator<'_> {
    /// Asks on its own line (ending in `:`) and reads the answer.
    fn ask(&mut self, question: &str) -> anyhow::Result<String> {
        println!("{question}:");
        std::io::stdout().flush()?;
        let mut line = String::new();
        if self.input.read_line(&mut line)? == 0 || self.stop.load(Ordering::Relaxed) {
            bail!("no answer (end of input or Ctrl-C): nothing written");
        }
        Ok(line.trim().to_owned())
    }

    /// Asks for a positive number until one comes.
    fn number(&mut self, question: &str) -> anyhow::Result<f64> {
        loop {
            let answer = self.ask(question)?;
            match answer.parse::<f64>() {
                Ok(number) if number.is_finite() && number > 0.0 => return Ok(number),
                _ => println!("'{answer}' is not a positive number; again"),
            }
        }
    }
}

/// The newest state, waiting for the first.
fn newest(
    states: &StateSubscriber,
    last: &mut Option<StatePayload>,
) -> anyhow::Result<StatePayload> {
    let deadline = Instant::now() + Duration::from_secs(2);
    loop {
        if let Some(state) = states.try_latest()? {
            *last = Some(state);
        }
        if let Some(state) = *last {
            return Ok(state);
        }
        if Instant::now() > deadline {
            bail!("no state from the gateway within 2 s: is it running?");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// How the turns are driven: in place at `turn_speed`, or, on a model that turns only while
/// moving (a Hunter), forward at `speed` on a circle a little wider than its tightest (or wider
/// still, for a `turn_speed` below what that circle takes). Returns (linear, angular) and what
/// to tell the operator.
pub fn turning(model: Option<Model>, speed: f64, turn_speed: f64) -> ((f64, f64), String) {
    match model.and_then(|model| Some((model, model.steering()?))) {
        Some((model, steering)) => {
            let angular = turn_speed.min(0.95 * steering.max_yaw_rate(speed));
            let radius = speed / angular;
            let how = format!(
                "on a circle of {radius:.1} m radius to its left at {speed} m/s, {:.0} s a \
                 turn (a {} turns only while moving: clear a circle of {:.0} m across)",
                std::f64::consts::TAU / angular,
                model.name(),
                (2.0 * radius + 1.0).ceil()
            );
            ((speed, angular), how)
        }
        None => ((0.0, turn_speed), "in place".to_owned()),
    }
}

/// One leg: drives `speeds` (linear, angular) until `progress` (from the odometry, going at
/// `rate` a second) reaches `target`, then zero until the robot stands still; returns the
/// progress then. Ends on a lost control (`scout estop`), Ctrl-C, an odometry reset, or twice
/// the time the leg should take, with an error, the robot stopped.
fn leg(
    controller: &mut Controller,
    states: &StateSubscriber,
    (speeds, rate): ((f64, f64), f64),
    target: f64,
    mut progress: impl FnMut(&StatePayload) -> f64,
    stop: &AtomicBool,
) -> anyhow::Result<f64> {
    let mut last = None;
    let expected = Duration::from_secs_f64(target / rate);
    let limit = Instant::now() + expected * 2 + Duration::from_secs(5);
    let resets = newest(states, &mut last)?.odometry.resets;
    let mut next = Instant::now();
    let mut driving = true;
    let mut still_since: Option<Instant> = None;
    loop {
        let state = newest(states, &mut last)?;
        let done = progress(&state);
        if done >= target {
            driving = false;
        }
        let (linear, angular) = if driving { speeds } else { (0.0, 0.0) };
        if stop.load(Ordering::Relaxed) || Instant::now() > limit {
            let _ = controller.drive(0.0, 0.0);
            bail!(
                "stopped (Ctrl-C, or not at the mark after {:.0} s, twice the time it should \
                 take: is the robot stuck?): nothing written",
                (expected * 2 + Duration::from_secs(5)).as_secs_f64()
            );
        }
        if state.odometry.resets != resets {
            let _ = controller.drive(0.0, 0.0);
            bail!("the odometry was reset during the leg (scout reset-odometry?): nothing written");
        }
        match controller.drive(linear, angular) {
            Err(error @ ControlError::Rejected(_)) if error.lost_control() => {
                return Err(anyhow::Error::from(error)
                    .context("the robot was stopped (exit 4); nothing written"));
            }
            Err(error) => return Err(error.into()),
            Ok(_) => {}
        }
        let still = state.motion.linear().abs() < STILL_LINEAR
            && state.motion.angular().abs() < STILL_ANGULAR;
        if !driving && still {
            let since = *still_since.get_or_insert_with(Instant::now);
            if since.elapsed() >= STILL_FOR {
                return Ok(progress(&state));
            }
        } else {
            still_since = None;
        }
        next += DRIVE_PERIOD;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
}

/// Takes control for one leg when the operator presses Enter.
fn take(robot: &Robot, operator: &mut Operator<'_>, what: &str) -> anyhow::Result<Controller> {
    operator.ask(&format!(
        "press Enter to {what} (`scout estop` or Ctrl-C stops it at any time)"
    ))?;
    let mut controller = robot.controller("calibrate", Some(Class::Teleop))?;
    controller
        .take_control()
        .context("taking control as teleop")?;
    Ok(controller)
}

fn check(args: &CalibrateArgs) -> anyhow::Result<()> {
    let checks = [
        ("--distance", args.distance, 0.2..=50.0),
        ("--turns", args.turns, 0.25..=10.0),
        ("--speed", args.speed, 0.05..=1.0),
        ("--turn-speed", args.turn_speed, 0.05..=1.5),
    ];
    for (flag, value, range) in checks {
        if !range.contains(&value) {
            bail!(
                "{flag} must be within {}..={}, found {value}",
                range.start(),
                range.end()
            );
        }
    }
    Ok(())
}

fn read_config(path: &Path) -> anyhow::Result<String> {
    let text = std::fs::read_to_string(path).with_context(|| {
        format!(
            "reading {}: give the file the gateway reads (its --config, or \
             /etc/scout/scout-gateway.toml as packaged)",
            path.display()
        )
    })?;
    // Refuse a file that will not take the factors before the robot moves.
    with_factors(&text, 1.0, 1.0)?;
    Ok(text)
}

/// Writes `text` to `path` through a file beside it, so that the gateway never reads half.
fn write_config(path: &Path, text: &str) -> anyhow::Result<()> {
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".calibrate");
    let temporary = PathBuf::from(temporary);
    std::fs::write(&temporary, text).with_context(|| format!("writing {}", temporary.display()))?;
    std::fs::rename(&temporary, path).with_context(|| format!("replacing {}", path.display()))
}

pub fn run(args: &CalibrateArgs) -> anyhow::Result<ExitCode> {
    check(args)?;
    let text = read_config(&args.config)?;
    let stop = ctrl_c()?;
    let stdin = std::io::stdin();
    let mut operator = Operator {
        input: Box::new(stdin.lock()),
        stop: &stop,
    };
    let robot = Robot::connect(&args.robot.name)?;
    let states = robot.subscribe()?;
    let mut last = None;
    let state = newest(&states, &mut last)?;
    let (distance_scale, yaw_scale) = (state.odometry.distance_scale, state.odometry.yaw_scale);
    let (turn, how) = turning(state.chassis.model(), args.speed, args.turn_speed);
    println!(
        "calibrating {}'s odometry (factors in force: distance_scale {distance_scale}, \
         yaw_scale {yaw_scale}): it drives {:.2} m straight ahead at {} m/s, then turns {} \
         time(s) {how}. Clear the way, and mark the floor at its front edge.",
        args.robot.name, args.distance, args.speed, args.turns
    );

    let mut controller = take(&robot, &mut operator, "drive straight")?;
    let start = newest(&states, &mut None)?.odometry.distance;
    let reported = leg(
        &mut controller,
        &states,
        ((args.speed, 0.0), args.speed),
        args.distance,
        |state| state.odometry.distance - start,
        &stop,
    )?;
    controller.relinquish().context("giving up control")?;
    let measured = operator.number(&format!(
        "distance? How far did it go, in metres, measured on the floor (the odometry says \
         {reported:.3} m)"
    ))?;
    let new_distance = factor(distance_scale, reported, measured)?;

    println!("now mark its heading on the floor (a line along its side)");
    let mut controller = take(&robot, &mut operator, &format!("turn {how}"))?;
    let mut previous = newest(&states, &mut None)?.odometry.yaw;
    let mut turned = 0.0;
    let reported_turn = leg(
        &mut controller,
        &states,
        (turn, turn.1),
        args.turns * TAU,
        |state| {
            turned += wrap_angle(state.odometry.yaw - previous);
            previous = state.odometry.yaw;
            turned
        },
        &stop,
    )?;
    controller.relinquish().context("giving up control")?;
    let measured_turn = operator.number(&format!(
        "turn? How far did it turn, in degrees, by the mark (360 a turn; the odometry says \
         {:.0})",
        reported_turn.to_degrees()
    ))?;
    let new_yaw = factor(yaw_scale, reported_turn, measured_turn.to_radians())?;

    println!("distance_scale = {new_distance:.4}\nyaw_scale = {new_yaw:.4}");
    if args.dry_run {
        println!("--dry-run: {} not written", args.config.display());
        return Ok(ExitCode::SUCCESS);
    }
    // Read again: the file may have been edited while the robot drove.
    let text = std::fs::read_to_string(&args.config).unwrap_or(text);
    write_config(&args.config, &with_factors(&text, new_distance, new_yaw)?)?;
    println!(
        "written to {}: restart the gateway to apply them ({})",
        args.config.display(),
        restart_hint(&args.robot.name)
    );
    Ok(ExitCode::SUCCESS)
}

/// How to restart the gateway of `robot`: through its systemd unit when it runs as one (its
/// control group is the unit's), else by hand.
fn restart_hint(robot: &str) -> String {
    let command = scout_clients::control::Stopper::new(robot, "calibrate")
        .ok()
        .and_then(|mut stopper| stopper.gateway_pid().ok())
        .and_then(|pid| std::fs::read_to_string(format!("/proc/{pid}/cgroup")).ok())
        .and_then(|cgroup| restart_command(&cgroup));
    command.unwrap_or_else(|| "stop it with Ctrl-C or SIGTERM, and start it again".to_owned())
}

/// The command that restarts the systemd service a `/proc/PID/cgroup` text puts its process in
/// (the process is the service's own, not in a scope or slice below it), if any.
fn restart_command(cgroup: &str) -> Option<String> {
    let path = cgroup.lines().find_map(|line| line.strip_prefix("0::"))?;
    let unit = path.rsplit('/').next()?;
    if !unit.ends_with(".service") {
        return None;
    }
    Some(if path.contains("/user@") {
        format!("systemctl --user restart {unit}")
    } else {
        format!("sudo systemctl restart {unit}")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_chassis_that_turns_only_while_moving_turns_on_a_circle() {
        assert_eq!(
            turning(Some(Model::Scout2), 0.3, 0.4),
            ((0.0, 0.4), "in place".to_owned())
        );
        assert_eq!(turning(None, 0.3, 0.4).0, (0.0, 0.4));
        let ((linear, angular), how) = turning(Some(Model::HunterSe), 0.3, 0.4);
        // A little wider than its tightest circle (1.571 m), which the gateway would hold it to.
        let radius = linear / angular;
        assert!(
            linear == 0.3 && (radius - 1.571 / 0.95).abs() < 0.001,
            "{radius}"
        );
        assert!(
            how.starts_with("on a circle of 1.7 m radius to its left at 0.3 m/s, 35 s a turn"),
            "{how}"
        );
        assert!(how.ends_with("clear a circle of 5 m across)"), "{how}");
        // A slower turn asked: a wider circle.
        let ((_, angular), _) = turning(Some(Model::Hunter2), 0.3, 0.1);
        assert_eq!(angular, 0.1);
    }

    #[test]
    fn the_restart_command_comes_from_the_control_group() {
        assert_eq!(
            restart_command("0::/system.slice/scout-gateway.service\n").as_deref(),
            Some("sudo systemctl restart scout-gateway.service")
        );
        assert_eq!(
            restart_command(
                "0::/user.slice/user-1000.slice/user@1000.service/app.slice/scout.service\n"
            )
            .as_deref(),
            Some("systemctl --user restart scout.service")
        );
        // A terminal's, or a program of a desktop session: by hand.
        for cgroup in [
            "0::/user.slice/user-1000.slice/session-3.scope\n",
            "0::/user.slice/user-1000.slice/user@1000.service/app.slice/app-term-1.scope\n",
        ] {
            assert_eq!(restart_command(cgroup), None, "{cgroup}");
        }
    }

    #[test]
    fn the_factor_is_the_one_in_force_times_measured_over_reported() {
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        assert!(close(factor(1.0, 1.9, 2.0).expect("ok"), 2.0 / 1.9));
        // Reported with 1.05 in force: the raw report was 1.9 / 1.05.
        assert!(close(factor(1.05, 1.9, 2.0).expect("ok"), 1.05 * 2.0 / 1.9));
        let error = factor(1.0, 1.0, 3.0).expect_err("out of range").to_string();
        assert!(error.contains("outside 0.5..=2"), "{error}");
        assert!(factor(1.0, 0.0, 1.0).is_err());
        assert!(factor(1.0, 1.0, f64::NAN).is_err());
    }

    #[test]
    fn the_factors_replace_their_keys_and_keep_the_rest() {
        let text = "# the robot\nname = \"r1\"\n\n[odometry]\n# measured 2026-11\n\
                    distance_scale = 1.0\nyaw_scale = 1.0\n\n[arbiter]\nteleop_age_ms = 250\n";
        let written = with_factors(text, 1.052_631_5, 0.793_650_7).expect("written");
        assert!(written.contains("# the robot\nname = \"r1\""), "{written}");
        assert!(written.contains("# measured 2026-11"), "{written}");
        assert!(written.contains("distance_scale = 1.0526\n"), "{written}");
        assert!(written.contains("yaw_scale = 0.7937\n"), "{written}");
        assert!(
            written.contains("[arbiter]\nteleop_age_ms = 250"),
            "{written}"
        );
        let fresh = with_factors("name = \"r1\"\n", 1.1, 0.9).expect("a new table");
        assert!(
            fresh.contains("[odometry]\ndistance_scale = 1.1\nyaw_scale = 0.9"),
            "{fresh}"
        );
        assert!(with_factors("odometry = 3\n", 1.0, 1.0).is_err());
        assert!(with_factors("[[broken", 1.0, 1.0).is_err());
    }
}
