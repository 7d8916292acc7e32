//! `scout router`: a zenoh router for a fleet, so that gateways on several hosts (or several
//! robots on one host) and remote readers meet in one place.

use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use clap::Args;
use scout_clients::remote::SessionSettings;

#[derive(Debug, Args)]
pub struct RouterArgs {
    /// Endpoint to listen on (repeatable) [default: tcp/127.0.0.1:7448].
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Another router to connect to (repeatable).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// Zenoh configuration file (JSON5; TLS, access control) [default: $ZENOH_CONFIG].
    #[arg(long, value_name = "FILE")]
    zenoh_config: Option<String>,
}

pub fn run(args: &RouterArgs) -> anyhow::Result<ExitCode> {
    let no_file = args.zenoh_config.is_none() && std::env::var_os("ZENOH_CONFIG").is_none();
    let listen = if args.listen.is_empty() && no_file {
        vec![scout_clients::remote::DEFAULT_LISTEN.to_owned()]
    } else {
        args.listen.clone()
    };
    let settings = SessionSettings {
        config_file: args.zenoh_config.clone(),
        listen,
        connect: args.connect.clone(),
    };
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    let _session = settings.open("router")?;
    eprintln!(
        "scout router: listening on {:?} (Ctrl-C to stop)",
        settings.listen
    );
    while !stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(100));
    }
    Ok(ExitCode::SUCCESS)
}
