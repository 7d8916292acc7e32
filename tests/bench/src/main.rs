//! `scout-bench`: measures the gateway beside the alternatives in one run and prints a Markdown
//! table (JSON with `--json FILE`, plots with `--plots DIR`). See BENCHMARKS.md.
//!
//! Exit codes: 0 measured; 1 a step failed (the message says which); 2 usage.

mod figures;
mod plot;
mod procs;
mod roles;
mod run;
mod soak;
mod usb;
mod watchers;

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// Measures scout-gateway: state latency through iceoryx2, zenoh and a direct read of the port,
/// command and e-stop latency, tick jitter idle, loaded and under a request flood, recovery,
/// cost, and decode throughput.
#[derive(Debug, Parser)]
#[command(version)]
struct Cli {
    /// Short windows and few samples (under a minute): checks the bench works.
    #[arg(long)]
    quick: bool,
    /// Write the figures as JSON to FILE.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    /// Draw PNG plots into DIR.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    /// SCHED_FIFO priority of the bench's requesting thread, which plays a safety monitor
    /// (0: normal scheduling, as an ordinary client).
    #[arg(long, value_name = "N", default_value_t = 40)]
    client_priority: u8,
    #[command(subcommand)]
    role: Option<Role>,
}

/// The bench's own child processes.
#[derive(Debug, Subcommand)]
enum Role {
    /// An iceoryx2 state subscriber.
    #[command(hide = true)]
    Subscribe {
        name: String,
        out: PathBuf,
        seconds: f64,
    },
    /// A zenoh state subscriber.
    #[command(hide = true)]
    ZenohSubscribe {
        name: String,
        endpoint: String,
        out: PathBuf,
        seconds: f64,
    },
    /// A process reading the port itself.
    #[command(hide = true)]
    Direct {
        port: PathBuf,
        out: PathBuf,
        seconds: f64,
    },
    /// Burns a core.
    #[command(hide = true)]
    Hog { seconds: f64 },
    /// Churns clients against a gateway on the simulator for MINUTES (controllers taking and
    /// giving up control, stops and releases, clients killed and stopped, a request flood) and
    /// prints the slopes of the gateway's memory, open files, threads and /dev/shm files.
    Soak {
        minutes: f64,
        /// Write the figures as JSON to FILE.
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// Run the gateway under heaptrack (apt install heaptrack) and print its heap's slope and
        /// the call sites of what it still holds at the end: the top growers of a long run.
        #[arg(long)]
        heap_profile: bool,
    },
    /// A gs_usb USB-CAN adapter emulated on USB in front of the simulated chassis' CAN bus:
    /// the gateway on the bus itself, through the kernel's driver, and in user space
    /// (--gs-usb), measured alike in one run. Needs root and the modules the project's VM has:
    /// `tests/vm/run -- target/release/scout-bench usb`.
    Usb,
    /// Control requests as fast as `hz`.
    #[command(hide = true)]
    Flood { name: String, hz: f64, seconds: f64 },
    /// Stop-endpoint datagrams (releases) as fast as they go, from a process of `mappings`
    /// memory mappings (what makes its `/proc/PID/maps` long).
    #[command(hide = true)]
    DatagramFlood {
        name: String,
        seconds: f64,
        #[arg(long, default_value_t = 0)]
        mappings: usize,
        /// Garbage (not the endpoint's magic) instead of releases.
        #[arg(long)]
        garbage: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.role {
        Some(Role::Subscribe { name, out, seconds }) => roles::subscribe(&name, &out, seconds),
        Some(Role::ZenohSubscribe {
            name,
            endpoint,
            out,
            seconds,
        }) => roles::zenoh_subscribe(&name, &endpoint, &out, seconds),
        Some(Role::Direct { port, out, seconds }) => roles::direct(&port, &out, seconds),
        Some(Role::Hog { seconds }) => {
            roles::hog(seconds);
            Ok(())
        }
        Some(Role::Flood { name, hz, seconds }) => roles::flood(&name, hz, seconds),
        Some(Role::Usb) => run::usb(&run::Options {
            quick: cli.quick,
            json: cli.json,
            plots: cli.plots,
            client_priority: cli.client_priority,
        }),
        Some(Role::Soak {
            minutes,
            json,
            heap_profile,
        }) => soak::soak(minutes, json.as_deref(), heap_profile),
        Some(Role::DatagramFlood {
            name,
            seconds,
            mappings,
            garbage,
        }) => roles::datagram_flood(&name, seconds, mappings, garbage),
        None => run::run(&run::Options {
            quick: cli.quick,
            json: cli.json,
            plots: cli.plots,
            client_priority: cli.client_priority,
        }),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("scout-bench: {error:#}");
            ExitCode::FAILURE
        }
    }
}
