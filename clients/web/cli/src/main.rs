//! `scout-web` (run as `scout web`): the operator's page for a robot, on any phone or laptop
//! (see the `scout_web` library).
//!
//! Exit codes: 0 Ctrl-C or SIGTERM ended it; 1 something failed (reading the gateway); 2 usage
//! error (also: a bad users file, an address that cannot be listened on, one beyond loopback
//! without TLS, a certificate or key that cannot be read or made); 3 no gateway with that name
//! runs.

use std::io::Write;
use std::net::{IpAddr, SocketAddr};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::Parser;
use scout_clients::failure::{self, Failure, FailureKind};
use scout_web::access::{Role, User, Users, new_token};
use scout_web::qr;
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
    /// token). Without it: one user, `operator`, role drive, with a new token each start (or
    /// the one of --token-file).
    #[arg(long, value_name = "FILE", conflicts_with = "token_file")]
    users: Option<PathBuf>,
    /// Keep the `operator` user's token in FILE (made with a new token, mode 0600, if missing):
    /// a bookmarked link keeps working across restarts of scout web.
    #[arg(long, value_name = "FILE")]
    token_file: Option<PathBuf>,
}

/// The users file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct UsersFile {
    users: Vec<User>,
}

fn main() -> ExitCode {
    scout_man::exit_if_asked(<Cli as clap::CommandFactory>::command);
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
                token: match &cli.token_file {
                    Some(path) => kept_token(path)?,
                    None => {
                        new_token().map_err(|error| anyhow::anyhow!("no random token: {error}"))?
                    }
                },
            }],
            true,
        ),
    };
    let users = Users::new(users).map_err(|error| Usage(error.to_string()))?;
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
    let urls: Vec<String> = page_hosts(server.address(), &interface_addresses())
        .iter()
        .map(|host| format!("{scheme}://{host}/"))
        .collect();
    let url = &urls[0];
    if made {
        let user = &users.all()[0];
        let link = format!("{url}#token={}", user.token);
        println!(
            "scout web for robot {} on {url}: open {link} (user {}, role {}; {})",
            cli.name,
            user.name,
            user.role,
            match &cli.token_file {
                Some(path) => format!("the token kept in {}", path.display()),
                None => "a new token each start: --token-file FILE keeps one".to_owned(),
            }
        );
        for other in &urls[1..] {
            println!("  or {other}#token={}", user.token);
        }
        // For a phone's camera; only on a terminal (not into a log).
        if std::io::IsTerminal::is_terminal(&std::io::stdout())
            && let Some(lines) = qr::terminal_lines(&link)
        {
            println!("or scan it with the phone:");
            for line in lines {
                println!("{line}");
            }
        }
    } else {
        println!(
            "scout web for robot {} on {url}: open {url}#token=TOKEN with a token of {}",
            cli.name,
            cli.users
                .as_ref()
                .map_or(String::new(), |path| path.display().to_string())
        );
        for other in &urls[1..] {
            println!("  or {other}#token=TOKEN");
        }
    }
    std::io::stdout().flush()?;
    server.run(stop)?;
    Ok(())
}

/// The token kept in `path`: read, or made (mode 0600, the directory made too) when the file is
/// missing. A file others may read is refused: the token is the page's key.
fn kept_token(path: &std::path::Path) -> anyhow::Result<String> {
    use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
    match std::fs::symlink_metadata(path) {
        Ok(metadata) => {
            if metadata.mode() & 0o077 != 0 || !metadata.is_file() {
                return Err(Usage(format!(
                    "{}: a token file must be a file only its owner can read (chmod 600 {})",
                    path.display(),
                    path.display()
                ))
                .into());
            }
            let token = std::fs::read_to_string(path)
                .map_err(|error| Usage(format!("reading {}: {error}", path.display())))?;
            Ok(token.trim().to_owned())
        }
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => {
            let token = new_token().map_err(|error| anyhow::anyhow!("no random token: {error}"))?;
            if let Some(dir) = path.parent().filter(|dir| !dir.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .map_err(|error| Usage(format!("making {}: {error}", dir.display())))?;
            }
            let mut file = std::fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .mode(0o600)
                .open(path)
                .map_err(|error| Usage(format!("making {}: {error}", path.display())))?;
            writeln!(file, "{token}")
                .map_err(|error| Usage(format!("writing {}: {error}", path.display())))?;
            Ok(token)
        }
        Err(error) => Err(Usage(format!("reading {}: {error}", path.display())).into()),
    }
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
    if listen.ip().is_unspecified() {
        names.extend(interface_addresses().iter().map(IpAddr::to_string));
    } else if !listen.ip().is_loopback() {
        names.push(listen.ip().to_string());
    }
    names
}

/// The `HOST:PORT`s the page is reached at: the address listened on, or, listening on every
/// interface, each of this computer's `interfaces` (an IPv4 wildcard: their IPv4 ones), else
/// `localhost`.
fn page_hosts(listen: SocketAddr, interfaces: &[IpAddr]) -> Vec<String> {
    if !listen.ip().is_unspecified() {
        return vec![listen.to_string()];
    }
    let hosts: Vec<String> = interfaces
        .iter()
        .filter(|ip| listen.is_ipv6() || ip.is_ipv4())
        .map(|ip| SocketAddr::new(*ip, listen.port()).to_string())
        .collect();
    if hosts.is_empty() {
        vec![format!("localhost:{}", listen.port())]
    } else {
        hosts
    }
}

/// This computer's addresses another may reach: of the interfaces that are up and running, all
/// but loopback and link-local ones, IPv4 first.
fn interface_addresses() -> Vec<IpAddr> {
    use nix::net::if_::InterfaceFlags;
    let Ok(interfaces) = nix::ifaddrs::getifaddrs() else {
        return Vec::new();
    };
    let mut addresses: Vec<IpAddr> = interfaces
        // Up and connected (a bridge with nothing behind it is up, not running).
        .filter(|interface| {
            interface
                .flags
                .contains(InterfaceFlags::IFF_UP | InterfaceFlags::IFF_RUNNING)
        })
        .filter_map(|interface| interface.address)
        .filter_map(|address| {
            (address.as_sockaddr_in().map(|v4| IpAddr::V4(v4.ip())))
                .or_else(|| address.as_sockaddr_in6().map(|v6| IpAddr::V6(v6.ip())))
        })
        .filter(|ip| reachable_from_another(*ip))
        .collect();
    addresses.sort_by_key(IpAddr::is_ipv6);
    addresses.dedup();
    addresses
}

/// Whether `ip` is one another computer may use to reach this one: not loopback, not the
/// wildcard, not link-local (which needs a scope a link cannot carry).
fn reachable_from_another(ip: IpAddr) -> bool {
    match ip {
        IpAddr::V4(v4) => !(v4.is_loopback() || v4.is_unspecified() || v4.is_link_local()),
        IpAddr::V6(v6) => !(v6.is_loopback() || v6.is_unspecified() || v6.is_unicast_link_local()),
    }
}

/// A usage error found after parsing.
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Usage(String);

impl FailureKind for Usage {
    fn kind(&self) -> Failure {
        Failure::Usage
    }
}

/// The exit code for `error`: its kind's (`scout_clients::failure`), knowing this program's
/// own errors.
fn exit_code(error: &anyhow::Error) -> u8 {
    failure::exit_code(
        error.chain(),
        &[
            failure::kind_if::<Usage>,
            failure::kind_if::<TlsError>,
            failure::kind_if::<WebError>,
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_address_is_its_own_link_every_interface_each_of_its_own() {
        let ours: [IpAddr; 3] = [
            "192.168.1.23".parse().unwrap(),
            "10.0.0.7".parse().unwrap(),
            "fd00::7".parse().unwrap(),
        ];
        let listen = |text: &str| text.parse::<SocketAddr>().unwrap();
        assert_eq!(
            page_hosts(listen("127.0.0.1:8090"), &ours),
            ["127.0.0.1:8090"]
        );
        assert_eq!(page_hosts(listen("10.0.0.7:443"), &ours), ["10.0.0.7:443"]);
        assert_eq!(
            page_hosts(listen("0.0.0.0:8090"), &ours),
            ["192.168.1.23:8090", "10.0.0.7:8090"]
        );
        assert_eq!(
            page_hosts(listen("[::]:8090"), &ours),
            ["192.168.1.23:8090", "10.0.0.7:8090", "[fd00::7]:8090"]
        );
        assert_eq!(page_hosts(listen("0.0.0.0:8090"), &[]), ["localhost:8090"]);
    }

    #[test]
    fn only_addresses_another_computer_can_use_are_offered() {
        for (ip, offered) in [
            ("192.168.1.23", true),
            ("fd00::7", true),
            ("127.0.0.1", false),
            ("::1", false),
            ("169.254.3.4", false),
            ("fe80::1", false),
            ("0.0.0.0", false),
        ] {
            assert_eq!(reachable_from_another(ip.parse().unwrap()), offered, "{ip}");
        }
    }
}
