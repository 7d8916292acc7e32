//! `scout-gateway`: the one process that owns a SCOUT chassis port.
//!
//! Exit codes: 0 stopped by Ctrl-C or SIGTERM (after sending zero speed), 1 runtime error,
//! 2 usage or configuration error, or another gateway already owns the robot name or device.
//!
//! Under systemd (`Type=notify`, config/scout-gateway.service) it reports when it is ready and
//! when it stops, and its control loop pets the watchdog.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use clap::{ArgGroup, Parser};
use scout_bridge::Bridge;
use scout_gateway::config::{GatewayConfig, ProtocolSetting};
use scout_gateway::core::Start;
use scout_gateway::device::DeviceSpec;
use scout_gateway::driver::Driver;
use scout_gateway::lock::LockError;
use scout_gateway::run_dir::RunDirError;
use scout_gateway::stop_endpoint::StopEndpoint;
use scout_interface::Transport;
use scout_interface::failure::Failure;
use scout_interface::remote::Permission;
use scout_interface::robot::RobotName;
use scout_interface::services;
use scout_io::notify::ServiceManager;
use scout_protocol::model::Model;
use tracing::info;

/// The one process that owns a SCOUT chassis port: it decodes the chassis' feedback, publishes
/// the state to local processes (iceoryx2, zero-copy) and sends the motion command every 20 ms.
#[derive(Debug, Parser)]
#[command(version, about, group(ArgGroup::new("transport")))]
struct Cli {
    /// Use the simulated chassis, in-process.
    #[arg(long, group = "transport")]
    sim: bool,
    /// An RS232 port (115200 8N1), e.g. /dev/ttyUSB0.
    #[arg(long, group = "transport", value_name = "DEVICE")]
    serial: Option<PathBuf>,
    /// A serial-line CAN adapter (slcan), e.g. /dev/ttyACM0.
    #[arg(long, group = "transport", value_name = "DEVICE")]
    slcan: Option<PathBuf>,
    /// A SocketCAN interface at 500 kbit/s, e.g. can0.
    #[arg(long, group = "transport", value_name = "IFACE")]
    can: Option<String>,
    /// A gs_usb USB-CAN adapter (candleLight, CANable, AgileX's), driven in user space with no
    /// kernel CAN driver: the one with this serial number, else the only one plugged in.
    #[arg(long, group = "transport", value_name = "SERIAL", num_args = 0..=1, default_missing_value = "")]
    gs_usb: Option<String>,
    /// With --gs-usb: take the adapter from a kernel driver bound to it (its canN goes away).
    #[arg(long)]
    gs_usb_detach: bool,
    /// The robot's name: every iceoryx2 service and zenoh key carries it [default: scout].
    #[arg(long, value_name = "ROBOT")]
    name: Option<RobotName>,
    /// Configuration file (TOML); see config/scout-gateway.toml. Default: $SCOUT_GATEWAY_CONFIG.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// The chassis' protocol: auto tells it from the chassis' feedback before sending anything
    /// (CAN and slcan; RS232 is v1) [default: auto].
    #[arg(long, value_name = "PROTOCOL", value_parser = ProtocolSetting::parse)]
    protocol: Option<ProtocolSetting>,
    /// The model, for its speed limits and geometry; docs/chassis.md lists them (and a name
    /// that is none says them) [default: scout on v1, scout2 on v2].
    #[arg(long, value_name = "MODEL", value_parser = Model::parse)]
    model: Option<Model>,
    /// The fastest the chassis may turn, rad/s; on v1 also the rate at 100 % angular command
    /// [default: the model's, 0.5235 for the SCOUT].
    #[arg(long, value_name = "RAD_S")]
    max_angular: Option<f64>,
    /// Zenoh endpoint to listen on (repeatable) [default: tcp/127.0.0.1:7448].
    #[arg(long, value_name = "ENDPOINT")]
    zenoh_listen: Vec<String>,
    /// Zenoh endpoint to connect to, e.g. a router (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    zenoh_connect: Vec<String>,
    /// Zenoh configuration file (JSON5), for LAN, router, TLS and access control [default:
    /// $ZENOH_CONFIG].
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<String>,
    /// Remote peers may drive over links that authenticate nobody (plain udp/ or tcp/ beyond
    /// loopback): every network they reach is trusted.
    #[arg(long)]
    zenoh_trusted_network: bool,
    /// No zenoh: local clients only.
    #[arg(long)]
    no_zenoh: bool,
    /// Accept remote commands of these kinds (comma-separated: estop, teleop, autonomy,
    /// release, resume, lights, clear_fault).
    #[arg(long, value_name = "LIST", value_delimiter = ',')]
    remote_commands: Option<Vec<Permission>>,
}

/// The exit code for usage, configuration and ownership errors.
const USAGE: u8 = Failure::Usage.exit_code();

fn main() -> ExitCode {
    scout_man::exit_if_asked(<Cli as clap::CommandFactory>::command);
    let cli = Cli::parse();
    let _log = scout_io::logging::init();
    let config = match configure(&cli) {
        Ok(config) => config,
        Err(error) => {
            eprintln!("scout-gateway: {error:#}");
            return ExitCode::from(USAGE);
        }
    };
    if let Err(error) = scout_bridge::check_links(&config.zenoh) {
        eprintln!("scout-gateway: {error:#}");
        return ExitCode::from(USAGE);
    }
    // The stop endpoint first: binding it is the robot name's lock on this host.
    let (spec, endpoint) = match config
        .validate()
        .map_err(anyhow::Error::from)
        .and_then(|spec| Ok((spec, StopEndpoint::bind(&config.name)?)))
    {
        Ok(owned) => owned,
        Err(error) => {
            eprintln!("scout-gateway: {error:#}");
            return ExitCode::from(USAGE);
        }
    };
    match serve(config, spec, endpoint) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error)
            if error.downcast_ref::<LockError>().is_some()
                || error.downcast_ref::<RunDirError>().is_some() =>
        {
            eprintln!("scout-gateway: {error:#}");
            ExitCode::from(USAGE)
        }
        Err(error) => {
            eprintln!("scout-gateway: error: {error:#}");
            ExitCode::FAILURE
        }
    }
}

fn configure(cli: &Cli) -> anyhow::Result<GatewayConfig> {
    let mut config = GatewayConfig::load(cli.config.as_deref())?;
    if let Some(name) = &cli.name {
        config.name = name.clone();
    }
    if let Some(max_angular) = cli.max_angular {
        config.max_angular = Some(max_angular);
    }
    if let Some(protocol) = cli.protocol {
        config.protocol = protocol;
    }
    if let Some(model) = cli.model {
        config.model = Some(model);
    }
    if !cli.zenoh_listen.is_empty() {
        config.zenoh.listen = cli.zenoh_listen.clone();
    }
    if !cli.zenoh_connect.is_empty() {
        config.zenoh.connect = cli.zenoh_connect.clone();
    }
    if let Some(file) = &cli.zenoh_config {
        config.zenoh.config_file = Some(file.clone());
    }
    if cli.no_zenoh {
        config.zenoh.enabled = false;
    }
    if cli.zenoh_trusted_network {
        config.zenoh.trusted_network = true;
    }
    if let Some(allowed) = &cli.remote_commands {
        config.zenoh.remote_commands.enabled = true;
        config.zenoh.remote_commands.allowed = allowed.clone();
    }
    let device = |path: &PathBuf| Some(path.display().to_string());
    let (transport, device) = match (cli.sim, &cli.serial, &cli.slcan, &cli.can) {
        (true, ..) => (Some(Transport::Sim), None),
        (_, Some(path), ..) => (Some(Transport::Serial), device(path)),
        (_, _, Some(path), _) => (Some(Transport::Slcan), device(path)),
        (_, _, _, Some(interface)) => (Some(Transport::Can), Some(interface.clone())),
        _ => match &cli.gs_usb {
            Some(serial) => (Some(Transport::GsUsb), Some(serial.clone())),
            None => (config.transport, config.device.clone()),
        },
    };
    if cli.gs_usb_detach {
        config.gs_usb_detach = true;
    }
    config.transport = transport;
    config.device = device;
    Ok(config)
}

fn serve(config: GatewayConfig, spec: DeviceSpec, endpoint: StopEndpoint) -> anyhow::Result<()> {
    services::quiet_iceoryx2_logs();
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C / SIGTERM handler")?;
    info!(
        "scout-gateway {}: robot '{}', {} on {}, state on iceoryx2 service '{}' (up to {} subscribers)",
        env!("CARGO_PKG_VERSION"),
        config.name,
        spec.transport(),
        spec.name(),
        services::state_service(&config.name),
        services::MAX_SUBSCRIBERS,
    );
    // systemd (Type=notify): told when the services are up and when shutdown begins; the
    // driver pets the watchdog from its loop.
    let mut service_manager = ServiceManager::from_env();
    if service_manager.is_present() {
        match service_manager.pet_interval() {
            Some(interval) => info!("under systemd: watchdog petted every {interval:?}"),
            None => info!("under systemd, no watchdog"),
        }
    }
    let status = format!(
        "robot '{}', {} on {}",
        config.name,
        spec.transport(),
        spec.name()
    );
    let bridge_config = config.zenoh.clone();
    let info = config.info(spec.transport(), &spec.name());
    let robot = config.name.clone();
    let marker = RunningMarker::new(&config.name)?;
    let start = marker.start()?;
    if start == Start::AfterUncleanExit {
        tracing::warn!(
            "the previous gateway of '{}' exited uncleanly: a gateway_start stop holds until released (scout release)",
            config.name
        );
    }
    if let Some(why) = config.max_angular_beyond_model() {
        tracing::warn!("{why}");
    }
    let mut driver = Driver::new(&config, spec, start, endpoint)?;
    // After the driver's services exist; dropped (stopped and joined) after it ends.
    let _bridge = if bridge_config.enabled {
        Some(
            Bridge::start(robot, bridge_config, info)
                .context("starting the zenoh bridge thread")?,
        )
    } else {
        info!("zenoh off: local clients only");
        None
    };
    service_manager.ready(&status);
    let result = driver.run(&stop);
    service_manager.stopping();
    result?;
    marker.clean_exit();
    Ok(())
}

/// A file that exists while a gateway of the robot runs: found at start, it tells that the
/// previous one did not exit cleanly (crash, kill, power loss of the host). It lives in the run
/// directory, which only the gateway's user can change, and is made exclusively, never through
/// a link.
struct RunningMarker {
    path: PathBuf,
}

impl RunningMarker {
    fn new(robot: &RobotName) -> anyhow::Result<Self> {
        let dir = scout_gateway::run_dir::prepare()?;
        Ok(Self {
            path: dir.join(robot.running_marker()),
        })
    }

    /// How the previous gateway ended; marks this one as running.
    fn start(&self) -> anyhow::Result<Start> {
        use std::io::Write;
        let start = match std::fs::symlink_metadata(&self.path) {
            Ok(_) => Start::AfterUncleanExit,
            Err(error) if error.kind() == std::io::ErrorKind::NotFound => Start::Clean,
            Err(error) => {
                return Err(error).with_context(|| format!("reading {}", self.path.display()));
            }
        };
        if start == Start::AfterUncleanExit {
            // Removed, not followed, whatever it is.
            std::fs::remove_file(&self.path)
                .with_context(|| format!("removing {}", self.path.display()))?;
        }
        scout_gateway::run_dir::create_new(&self.path)
            .and_then(|mut file| write!(file, "{}", std::process::id()))
            .with_context(|| format!("writing {}", self.path.display()))?;
        Ok(start)
    }

    fn clean_exit(&self) {
        if let Err(error) = std::fs::remove_file(&self.path) {
            tracing::warn!("removing {}: {error}", self.path.display());
        }
    }
}
