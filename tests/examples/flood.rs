//! A flooding client, for the system tests and the benchmark: sends control requests as fast
//! as `--hz` allows for `--seconds`, each waiting for its answer, and prints how many were
//! accepted and refused. `flood --name ROBOT --hz 1000 --seconds 3`.

use std::time::{Duration, Instant};

use scout_clients::client::Robot;
use scout_clients::{ReleaseTarget, Request};

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let value = |flag: &str, default: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1).cloned())
            .unwrap_or_else(|| default.to_owned())
    };
    let robot = Robot::connect(&value("--name", "scout"))?;
    let hz: f64 = value("--hz", "1000").parse()?;
    let seconds: f64 = value("--seconds", "3").parse()?;
    let name = format!("flood-{}", std::process::id());
    let mut controller = robot.controller(&name, None)?;
    let period = Duration::from_secs_f64(1.0 / hz);
    let end = Instant::now() + Duration::from_secs_f64(seconds);
    let (mut accepted, mut refused) = (0u64, 0u64);
    let mut next = Instant::now();
    let requests = [
        Request::Resume,
        Request::Release {
            target: ReleaseTarget::Own,
        },
        Request::Relinquish,
    ];
    let mut i = 0;
    while Instant::now() < end {
        match controller.request(&requests[i % requests.len()]) {
            Ok(_) => accepted += 1,
            Err(_) => refused += 1,
        }
        i += 1;
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    println!("{accepted} accepted, {refused} refused");
    Ok(())
}
