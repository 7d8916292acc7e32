//! `scout-doctor` (run as `scout doctor`): checks a SCOUT set-up in order; each check prints
//! its verdict and, when it fails, the fix.
//!
//! Exit codes: 0 every check passed (warnings included); 1 a check failed; 2 usage error.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use clap::{ArgGroup, Parser};
use scout_doctor::check::{self, Check};
use scout_doctor::doctor::{self, Options};
use scout_gateway::device::DeviceSpec;
use scout_interface::failure::Failure;

/// Check a SCOUT set-up: the device, the CAN interface, the traffic and protocol, the chassis'
/// state (e-stop, RC, faults, battery), the gateway and its stops, zenoh when asked.
///
/// A port a gateway holds is checked through that gateway, never opened twice. Exit codes: 0
/// every check passed (warnings included), 1 a check failed, 2 usage error.
#[derive(Debug, Parser)]
#[command(name = "scout doctor", version, about)]
#[command(group(ArgGroup::new("port").args(["serial", "slcan", "can", "gs_usb"])))]
struct Args {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout", value_name = "ROBOT")]
    name: String,
    /// An RS232 port to check (115200 8N1).
    #[arg(long, value_name = "DEV")]
    serial: Option<PathBuf>,
    /// A serial-line CAN adapter to check.
    #[arg(long, value_name = "DEV")]
    slcan: Option<PathBuf>,
    /// A SocketCAN interface to check.
    #[arg(long, value_name = "IFACE")]
    can: Option<String>,
    /// A gs_usb USB-CAN adapter to check in user space (as scout-gateway --gs-usb): the one
    /// with this serial number, else the only one.
    #[arg(long, value_name = "SERIAL", num_args = 0..=1, default_missing_value = "")]
    gs_usb: Option<String>,
    /// One JSON object per check, one per line.
    #[arg(long)]
    json: bool,
    /// Also read the robot's state through zenoh from this endpoint (a gateway's or a router's,
    /// e.g. tcp/127.0.0.1:7448) and measure the link, as a remote peer would.
    #[arg(long, value_name = "ENDPOINT")]
    zenoh: Option<String>,
    /// The zenoh configuration file for --zenoh (TLS certificates) [default: $ZENOH_CONFIG].
    #[arg(long, value_name = "FILE", requires = "zenoh")]
    zenoh_config: Option<String>,
    /// How long to listen to the port or the gateway, seconds.
    #[arg(long, default_value_t = 1.5, value_name = "SECONDS")]
    listen: f64,
}

fn main() -> ExitCode {
    scout_man::exit_if_asked(<Args as clap::CommandFactory>::command);
    let args = Args::parse();
    if !(args.listen.is_finite() && (0.1..=60.0).contains(&args.listen)) {
        eprintln!(
            "scout doctor: --listen {}: give 0.1 to 60 seconds",
            args.listen
        );
        return ExitCode::from(Failure::Usage.exit_code());
    }
    let port = match (&args.serial, &args.slcan, &args.can) {
        (Some(path), _, _) => Some(DeviceSpec::Serial(path.clone())),
        (_, Some(path), _) => Some(DeviceSpec::Slcan(path.clone())),
        (_, _, Some(interface)) => Some(DeviceSpec::Can(interface.clone())),
        (None, None, None) => args.gs_usb.as_ref().map(|serial| DeviceSpec::GsUsb {
            serial: Some(serial.clone()).filter(|s| !s.is_empty()),
            detach: false,
        }),
    };
    let options = Options {
        robot: args.name.clone(),
        port,
        window: Duration::from_secs_f64(args.listen),
        zenoh: args.zenoh.clone(),
        zenoh_config: args.zenoh_config.clone(),
    };
    let mut stdout = std::io::stdout();
    let mut print = |check: &Check| {
        let line = if args.json {
            check.json().to_string()
        } else {
            check.line()
        };
        // A closed output (`scout doctor | head`) ends the report, not the checks.
        let _ = writeln!(stdout, "{line}");
        let _ = stdout.flush();
    };
    let checks = doctor::run(&options, &mut print);
    let code = check::exit_code(&checks);
    if !args.json {
        let failed = checks
            .iter()
            .filter(|c| c.verdict == check::Verdict::Fail)
            .count();
        let warned = checks
            .iter()
            .filter(|c| c.verdict == check::Verdict::Warn)
            .count();
        println!(
            "{} checks: {failed} failed, {warned} warnings",
            checks.len()
        );
    }
    ExitCode::from(code)
}
