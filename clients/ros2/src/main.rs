//! `scout ros2`: the chassis as a ROS 2 node over rmw_zenoh (see `scout_clients::ros2`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::Context;
use clap::Args;
use scout_clients::ros2::bridge::{self, BridgeError};
use scout_clients::ros2::config::Ros2Config;
use scout_clients::ros2::rmw::Distro;
use tracing_subscriber::EnvFilter;

use crate::RobotArgs;

#[derive(Debug, Args)]
pub struct Ros2Args {
    #[command(flatten)]
    robot: RobotArgs,
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
    /// Speak to ROS 2 Humble (no type hashes).
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
            config.distro = Distro::Humble;
        }
        if self.zenoh_config.is_some() {
            config.zenoh_config = self.zenoh_config.clone();
        }
        config.validate()?;
        Ok(config)
    }
}

pub fn run(args: &Ros2Args) -> anyhow::Result<ExitCode> {
    let config = args.settings()?;
    if args.print_config {
        print!(
            "{}",
            toml::to_string(&config).context("writing the settings")?
        );
        return Ok(ExitCode::SUCCESS);
    }
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_target(false)
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .init();
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    match bridge::run(&args.robot.name, &config, &stop) {
        Ok(()) => Ok(ExitCode::SUCCESS),
        Err(BridgeError::Client(error)) => Err(error.into()),
        Err(BridgeError::Control(error)) => Err(error.into()),
        Err(error) => Err(error.into()),
    }
}
