//! `scout-web` (run as `scout web`): the operator's page for a robot, on any phone or laptop
//! (see the `scout_web` library).
//!
//! Exit codes: 0 Ctrl-C or SIGTERM ended it; 1 something failed (reading the gateway); 2 usage
//! error (also: a bad users file, an address that cannot be listened on, one beyond loopback
//! without TLS, a certificate or key that cannot be read or made); 3 no gateway with that name
//! runs.

use std::io::Write;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;
use scout_clients::failure::{self, Failure};
use scout_web::access::{Role, User, Users, new_token};
use scout_web::server::{Server, WebError, WebOptions};
use scout_web::tls::{self, TlsError};
use serde::Deserialize;
use tracing_subscriber::EnvFilter;

/// The operator's page: live state, stops, E-STOP and hold-to-drive, through the gateway's
/// arbiter like every client. Open the link it prints.
#[derive(Debug, Parser)]
#[command(name = "scout-web", version, about)]
struct Cli {
    /// The robot (gateway) name.
    #[arg(long, default_value = "scout", value_name = "ROBOT")]
    name: String,
    /// The address to listen on (port 0: any free port, printed at start). Another address
    /// than loopback (0.0.0.0: every interface) needs TLS.
    #[arg(long, default_value = "127.0.0.1:8090", value_name = "ADDR:PORT")]
    listen: SocketAddr,
    /// Serve over TLS with a self-signed certificate kept in DIR (made there on first start;
    /// its SHA-256 fingerprint is printed, to compare with what the browser shows).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["tls_cert", "tls_key"])]
    tls_self_signed: Option<PathBuf>,
    /// Serve over TLS with this certificate chain (PEM; with --tls-key).
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    tls_cert: Option<PathBuf>,
    /// The certificate's private key (PEM; with --tls-cert).
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    tls_key: Option<PathBuf>,
    /// The users (a TOML file of [[users]] with name, role = "view", "stop" or "drive", and
    /// token). Without it: one user, `operator`, role drive, with a new token each start.
    #[arg(long, value_name = "FILE")]
    users: Option<PathBuf>,
}

/// The users file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct UsersFile {
    users: Vec<User>,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
        )
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr)
        .init();
    let stop = Arc::new(AtomicBool::new(false));
    let on_signal = Arc::clone(&stop);
    if let Err(error) = ctrlc::set_handler(move || on_signal.store(true, Ordering::Relaxed)) {
        eprintln!("scout-web: cannot handle Ctrl-C: {error}");
        return ExitCode::FAILURE;
    }
    match run(&cli, &stop) {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("scout-web: {error:#}");
            ExitCode::from(exit_code(&error))
        }
    }
}

fn run(cli: &Cli, stop: &AtomicBool) -> anyhow::Result<()> {
    let (users, made) = match &cli.users {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .map_err(|error| Usage(format!("reading {}: {error}", path.display())))?;
            let file: UsersFile = toml::from_str(&text)
                .map_err(|error| Usage(format!("{}: {error}", path.display())))?;
            (file.users, false)
        }
        None => (
            vec![User {
                name: "operator".into(),
                role: Role::Drive,
                token: new_token().map_err(|error| anyhow::anyhow!("no random token: {error}"))?,
            }],
            true,
        ),
    };
    let users = Users::new(users).map_err(Usage)?;
    let tls = match (&cli.tls_self_signed, &cli.tls_cert, &cli.tls_key) {
        (Some(dir), _, _) => Some(tls::self_signed(dir, &certificate_names(cli.listen))?),
        (None, Some(cert), Some(key)) => Some(tls::from_files(cert, key)?),
        _ => None,
    };
    let server = Server::bind(WebOptions {
        robot: cli.name.clone(),
        listen: cli.listen,
        users: users.clone(),
        tls: tls.clone(),
    })?;
    if let Some(tls) = &tls {
        println!(
            "TLS certificate{} SHA-256 {}: the browser shows it; accept the certificate only if they match",
            if tls.made { " (made just now)" } else { "" },
            tls.fingerprint
        );
    }
    let scheme = if tls.is_some() { "https" } else { "http" };
    let url = format!("{scheme}://{}/", server.address());
    if made {
        let user = &users.all()[0];
        println!(
            "scout web for robot {} on {url}: open {url}#token={} (user {}, role {}; a new token each start)",
            cli.name, user.token, user.name, user.role
        );
    } else {
        println!(
            "scout web for robot {} on {url}: open {url}#token=TOKEN with a token of {}",
            cli.name,
            cli.users
                .as_ref()
                .map_or(String::new(), |path| path.display().to_string())
        );
    }
    std::io::stdout().flush()?;
    server.run(stop)?;
    Ok(())
}

/// The names a self-signed certificate is made for: this host's name, localhost, and the
/// address listened on (when it is one address).
fn certificate_names(listen: SocketAddr) -> Vec<String> {
    let mut names = vec!["localhost".to_owned(), "127.0.0.1".to_owned()];
    if let Ok(host) = std::fs::read_to_string("/etc/hostname") {
        let host = host.trim();
        if !host.is_empty() {
            names.push(host.to_owned());
            names.push(format!("{host}.local"));
        }
    }
    if !listen.ip().is_unspecified() && !listen.ip().is_loopback() {
        names.push(listen.ip().to_string());
    }
    names
}

/// A usage error found after parsing.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Usage(String);

/// The exit code for `error`: its kind's (`scout_clients::failure`), knowing this program's
/// own errors.
fn exit_code(error: &anyhow::Error) -> u8 {
    failure::exit_code(error.chain(), |cause| {
        if cause.downcast_ref::<Usage>().is_some() || cause.downcast_ref::<TlsError>().is_some() {
            return Some(Failure::Usage);
        }
        match cause.downcast_ref::<WebError>() {
            Some(WebError::Listen { .. } | WebError::NeedsTls(_)) => Some(Failure::Usage),
            Some(WebError::Gateway(error)) => Some(error.kind()),
            None => None,
        }
    })
}
