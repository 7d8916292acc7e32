//! A state logger: one CSV line per state update, with the gateway's receive times, to a file or
//! standard output. Blocks on the gateway's notifications; never polls.
//!
//! ```sh
//! cargo run --release -p scout-clients --example logger -- --count 500 > scout.csv
//! ```

use std::io::Write;
use std::time::Duration;

use clap::Parser;
use scout_clients::client::Robot;
use scout_clients::monotonic_ns;

#[derive(Debug, Parser)]
struct Args {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout")]
    name: String,
    /// Stop after this many lines.
    #[arg(long)]
    count: Option<u64>,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let robot = Robot::connect(&args.name)?;
    let states = robot.subscribe()?;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    writeln!(
        out,
        "seq,latency_us,link,battery_v,linear_mps,angular_radps,x_m,y_m,yaw_rad,rx_frames,checksum_errors,dropped_frames"
    )?;
    let mut written = 0;
    while args.count.is_none_or(|count| written < count) {
        let Some(state) = states.next_timeout(Duration::from_secs(3))? else {
            anyhow::bail!("no state from gateway '{}' for 3 s", args.name);
        };
        let latency_us = monotonic_ns().saturating_sub(state.published_ns) / 1000;
        let motion = state.motion;
        writeln!(
            out,
            "{},{latency_us},{},{:.1},{:.3},{:.3},{:.4},{:.4},{:.4},{},{},{}",
            state.seq,
            state.link.state().name(),
            state.system.battery_voltage(),
            motion.linear(),
            motion.angular(),
            state.odometry.x,
            state.odometry.y,
            state.odometry.yaw,
            state.link.rx_frames,
            state.link.checksum_errors,
            state.link.dropped_frames,
        )?;
        written += 1;
    }
    Ok(())
}
