//! An autonomy client that drives a square by odometry: straight for `--side` metres, a
//! quarter turn in place, repeated `--sides` times, then gives up control.
//!
//! ```sh
//! cargo run --release --bin scout-gateway -- --sim &
//! cargo run --release --bin scout -- resume      # autonomy starts disarmed
//! cargo run --release -p scout-clients --example square -- --side 1.0
//! ```

use std::f64::consts::FRAC_PI_2;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use clap::Parser;
use scout_clients::client::{Robot, StateSubscriber};
use scout_clients::control::Controller;
use scout_clients::{Class, StatePayload};

#[derive(Debug, Parser)]
struct Args {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout")]
    name: String,
    /// Side length, m.
    #[arg(long, default_value_t = 1.0)]
    side: f64,
    /// How many sides to drive.
    #[arg(long, default_value_t = 4)]
    sides: u32,
    /// Driving speed, m/s.
    #[arg(long, default_value_t = 0.5)]
    speed: f64,
    /// Turning rate, rad/s.
    #[arg(long, default_value_t = 0.45)]
    turn_rate: f64,
}

/// Commands go out at 50 Hz.
const PERIOD: Duration = Duration::from_millis(20);
/// Give up a leg that takes longer than this.
const LEG_TIMEOUT: Duration = Duration::from_secs(60);

fn wrap(angle: f64) -> f64 {
    use std::f64::consts::PI;
    (angle + PI).rem_euclid(2.0 * PI) - PI
}

/// Drives with `command` until `done` says the leg is over, slowing near the end.
fn leg(
    controller: &mut Controller,
    states: &StateSubscriber,
    mut command: impl FnMut(&StatePayload) -> Option<(f64, f64)>,
) -> anyhow::Result<StatePayload> {
    let start = Instant::now();
    let mut latest = states
        .next_timeout(Duration::from_secs(1))?
        .context("no state from the gateway")?;
    loop {
        if start.elapsed() > LEG_TIMEOUT {
            bail!("leg took longer than {LEG_TIMEOUT:?}");
        }
        latest = states.try_latest()?.unwrap_or(latest);
        let Some((linear, angular)) = command(&latest) else {
            return Ok(latest);
        };
        controller.drive(linear, angular)?;
        std::thread::sleep(PERIOD);
    }
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Robot::connect(&args.name)?;
    let states = robot.subscribe()?;
    let mut controller = robot.controller("square", Some(Class::Autonomy))?;
    // Autonomy drives only once an operator armed it (`scout resume`), under control it takes.
    controller.take_control()?;
    for side in 1..=args.sides {
        let start = leg(&mut controller, &states, |_| None)?.odometry;
        // Straight: the remaining distance sets the speed, down to a creep near the end.
        let end = leg(&mut controller, &states, |s| {
            let travelled = (s.odometry.x - start.x).hypot(s.odometry.y - start.y);
            let left = args.side - travelled;
            (left > 0.005).then(|| (args.speed.min(left * 3.0).max(0.05), 0.0))
        })?;
        println!(
            "side {side}: at x {:.3} y {:.3}",
            end.odometry.x, end.odometry.y
        );
        let heading = wrap(start.yaw + FRAC_PI_2);
        let end = leg(&mut controller, &states, |s| {
            let left = wrap(heading - s.odometry.yaw);
            (left > 0.005).then(|| (0.0, args.turn_rate.min(left * 3.0).max(0.05)))
        })?;
        println!("turn {side}: yaw {:.3} rad", end.odometry.yaw);
    }
    controller.drive(0.0, 0.0)?;
    controller.relinquish()?;
    let last = states
        .next_timeout(Duration::from_secs(1))?
        .context("no state")?
        .odometry;
    println!(
        "done at x {:.3} y {:.3} yaw {:.3}",
        last.x, last.y, last.yaw
    );
    Ok(())
}
