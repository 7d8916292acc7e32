//! Gateway benchmark: `cargo run --release -p scout-system-tests --example gateway_bench`.
//! Runs scout-sim on a serial pseudo-terminal and scout-gateway on it, then prints figures:
//! the 0x130 cadence as the chassis sees it, state delivery latency to a subscriber process,
//! the round trip of a control request, and how fast a stop reaches the wire.

use std::time::{Duration, Instant};

use scout_clients::{Class, ReleaseTarget, monotonic_ns};
use scout_system_tests::{Gateway, Sim, connect, robot_name};

fn percentiles(mut samples: Vec<f64>) -> String {
    samples.sort_by(f64::total_cmp);
    let at = |q: f64| samples[((samples.len() as f64 * q) as usize).min(samples.len() - 1)];
    format!(
        "n {:>5}  p50 {:>8.3}  p99 {:>8.3}  max {:>8.3}",
        samples.len(),
        at(0.5),
        at(0.99),
        samples.last().copied().unwrap_or(0.0)
    )
}

fn main() -> anyhow::Result<()> {
    let name = robot_name("bench");
    let sim = Sim::start(&["--serial"]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe()?;

    // State delivery: publication (gateway clock) to reception in this process, same clock.
    let mut delivery_ms = Vec::new();
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        if let Some(state) = states.next_timeout(Duration::from_millis(100))? {
            delivery_ms.push(monotonic_ns().saturating_sub(state.published_ns) as f64 / 1e6);
        }
    }

    // Control round trip: a drive request until its answer.
    let mut driver = robot.controller("bench-driver", Some(Class::Teleop))?;
    driver.take_control()?;
    let mut round_trip_ms = Vec::new();
    for _ in 0..500 {
        let sent = Instant::now();
        driver.drive(0.2, 0.0)?;
        round_trip_ms.push(sent.elapsed().as_secs_f64() * 1e3);
        std::thread::sleep(Duration::from_millis(10));
    }

    // Stop to wire: the stop request until the gateway has sent a zero command.
    let mut safety = robot.controller("bench-safety", None)?;
    let mut stop_ms = Vec::new();
    for _ in 0..30 {
        for _ in 0..25 {
            driver.drive(0.3, 0.0)?;
            std::thread::sleep(Duration::from_millis(20));
        }
        while states.try_next()?.is_some() {}
        let sent_ns = monotonic_ns();
        safety.stop("bench")?;
        loop {
            let state = states.next_timeout(Duration::from_secs(1))?.expect("state");
            if state.command.at_ns > sent_ns && state.command.linear == 0.0 {
                stop_ms.push((state.command.at_ns - sent_ns) as f64 / 1e6);
                break;
            }
        }
        safety.release(ReleaseTarget::Own)?;
        driver.take_control()?;
    }
    driver.relinquish()?;
    let stats = sim.quit();
    let intervals = &stats["motion_command_intervals"];

    println!("scout-gateway benchmark (serial pseudo-terminal, scout-sim), times in ms");
    println!(
        "0x130 interval at the chassis   n {:>5}  mean {:>7.3}  p99 {:>8.3}  max {:>8.3}",
        intervals["count"],
        intervals["mean_ms"].as_f64().unwrap_or(0.0),
        intervals["p99_ms"].as_f64().unwrap_or(0.0),
        intervals["max_ms"].as_f64().unwrap_or(0.0)
    );
    println!(
        "state publish -> subscriber     {}",
        percentiles(delivery_ms)
    );
    println!(
        "drive request -> answer         {}",
        percentiles(round_trip_ms)
    );
    println!("stop request -> zero on wire    {}", percentiles(stop_ms));
    println!(
        "checksum failures at the chassis {}",
        stats["checksum_failures"]
    );
    Ok(())
}
