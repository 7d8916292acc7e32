//! `scout-ros2` (run as `scout ros2`): the chassis as a ROS 2 node (see the `scout_ros2` library).
//!
//! Exit codes: 0 stopped by Ctrl-C or SIGTERM; 1 something failed (no ROS 2 router to connect
//! to, zenoh failed); 2 usage error, a bad setting, or another bridge serves the robot on that
//! ROS domain; 3 no gateway with that name runs, or it stopped answering.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use clap::Parser;
use scout_clients::failure;
use scout_clients::interface::robot::RobotName;
use scout_ros2::bridge::{self, BridgeError};
use scout_ros2::config::{Middleware, Ros2Config, Ros2ConfigError};
use scout_ros2::rmw::Distro;
use tracing::info;
use tracing_subscriber::EnvFilter;

/// Make the chassis a ROS 2 node: /odom, /tf, /battery_state, /joint_states, /diagnostics out;
/// /cmd_vel through the gateway's arbiter; e-stop and release services.
#[derive(Debug, Parser)]
#[command(name = "scout ros2", version, about)]
pub struct Ros2Args {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout", value_name = "ROBOT")]
    name: RobotName,
    /// The ROS 2 middleware: `dds` (Fast DDS, Cyclone DDS: ROS 2's default) or `zenoh`
    /// (rmw_zenoh) [default: the file's, else as $RMW_IMPLEMENTATION says].
    #[arg(long, value_name = "MIDDLEWARE", value_parser = ["dds", "zenoh"])]
    middleware: Option<String>,
    /// Settings file (TOML): node, namespace, frames, topics, cmd_vel classes, Humble mode.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// The ROS 2 router (rmw_zenohd) to connect to, repeatable [default: tcp/127.0.0.1:7447].
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// The ROS domain [default: the file's, else 0].
    #[arg(long, value_name = "ID", env = "ROS_DOMAIN_ID")]
    domain: Option<u32>,
    /// The node's namespace, e.g. /robot1.
    #[arg(long, value_name = "NS")]
    namespace: Option<String>,
    /// The node's name [default: scout].
    #[arg(long, value_name = "NAME")]
    node: Option<String>,
    /// Do not publish odom -> base_link on /tf (robot_localization publishes it).
    #[arg(long)]
    no_tf: bool,
    /// Speak to ROS 2 Humble (over zenoh no type hashes, over DDS 24-byte GIDs) [default: as
    /// $ROS_DISTRO says].
    #[arg(long)]
    humble: bool,
    /// A zenoh configuration file (JSON5) instead of client mode towards --connect.
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<String>,
    /// Print the settings in effect (TOML) and exit.
    #[arg(long)]
    print_config: bool,
}

impl Ros2Args {
    fn settings(&self) -> anyhow::Result<Ros2Config> {
        let mut config = Ros2Config::load(self.config.as_deref())?;
        if !self.connect.is_empty() {
            config.connect = self.connect.clone();
        }
        if let Some(domain) = self.domain {
            config.domain = domain;
        }
        if let Some(namespace) = &self.namespace {
            config.namespace = namespace.trim_end_matches('/').to_owned();
        }
        if let Some(node) = &self.node {
            config.node = node.clone();
        }
        if self.no_tf {
            config.publish_tf = false;
        }
        if self.humble {
            config.distro = Some(Distro::Humble);
        }
        if self.zenoh_config.is_some() {
            config.zenoh_config = self.zenoh_config.clone();
        }
        match self.middleware.as_deref() {
            Some("dds") => config.middleware = Some(Middleware::Dds),
            Some("zenoh") => config.middleware = Some(Middleware::Zenoh),
            Some(_) | None => {}
        }
        config.validate()?;
        Ok(config)
    }
}

impl Ros2Args {
    /// A zenoh-only setting given on the command line while the middleware is DDS is a usage
    /// error, not a setting silently ignored (`--connect` with DDS started DDS and never
    /// connected).
    fn check_middleware(&self, middleware: Middleware, why: &str) -> Result<(), Ros2ConfigError> {
        let zenoh_only = [
            ("--connect", !self.connect.is_empty()),
            ("--zenoh-config", self.zenoh_config.is_some()),
        ];
        match (middleware, zenoh_only.iter().find(|(_, given)| *given)) {
            (Middleware::Dds, Some((setting, _))) => Err(Ros2ConfigError::OtherMiddlewares {
                setting,
                middleware: middleware.name(),
                why: why.to_owned(),
            }),
            (Middleware::Dds | Middleware::Zenoh, _) => Ok(()),
        }
    }
}

fn main() -> ExitCode {
    scout_man::exit_if_asked(<Ros2Args as clap::CommandFactory>::command);
    let args = Ros2Args::parse();
    match run(&args) {
        Ok(code) => code,
        Err(error) => {
            eprintln!("scout ros2: {error:#}");
            ExitCode::from(exit_code(&error))
        }
    }
}

/// The exit code for `error`: its kind's (`scout_clients::failure`), knowing this program's
/// own errors.
fn exit_code(error: &anyhow::Error) -> u8 {
    failure::exit_code(
        error.chain(),
        &[
            failure::kind_if::<Ros2ConfigError>,
            failure::kind_if::<BridgeError>,
        ],
    )
}

fn run(args: &Ros2Args) -> anyhow::Result<ExitCode> {
    let config = args.settings()?;
    if args.print_config {
        print!(
            "{}",
            toml::to_string(&config).context("writing the settings")?
        );
        return Ok(ExitCode::SUCCESS);
    }
    let (middleware, why) = match config.middleware {
        Some(middleware) => (
            middleware,
            "chosen in the settings or with --middleware".into(),
        ),
        None => {
            Middleware::from_rmw_implementation(std::env::var("RMW_IMPLEMENTATION").ok().as_deref())
        }
    };
    args.check_middleware(middleware, &why)?;
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_target(false)
        .with_env_filter(
            // RustDDS' UDP sender warns of every datagram over 1500 bytes, which /diagnostics (2.2
            // kB, fragmented by IP where the MTU is smaller) is once a second, for good. Its
            // errors still show.
            EnvFilter::try_from_default_env().unwrap_or_else(|_| {
                EnvFilter::new("info,rustdds=warn,rustdds::network::udp_sender=error")
            }),
        )
        .init();
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    info!("scout ros2: speaking {} ({why})", middleware.name());
    let mut config = config;
    let (distro, why) = match config.distro {
        Some(distro) => (distro, "chosen in the settings or with --humble".into()),
        None => Distro::from_ros_distro(std::env::var("ROS_DISTRO").ok().as_deref()),
    };
    info!("scout ros2: to ROS 2 {} and later ({why})", distro.name());
    config.distro = Some(distro);
    match bridge::run(&args.name, &config, middleware, &stop) {
        Ok(()) => Ok(ExitCode::SUCCESS),
        Err(BridgeError::Client(error)) => Err(error.into()),
        Err(BridgeError::Control(error)) => Err(error.into()),
        Err(error) => Err(error.into()),
    }
}
