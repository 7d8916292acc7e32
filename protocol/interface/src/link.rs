//! What protects a zenoh link: each endpoint's kind (this host only, plain, inside a tunnel,
//! TLS with or without mutual authentication), and the gateway's rule that remote peers drive
//! only over links that authenticate them.
//!
//! The rule is sans-IO: [`Protection::of`] classifies an [`Endpoint`] given what the host knows
//! ([`Host`]: its interfaces, which of them are tunnels, and where a connection would leave),
//! and [`check`] decides. [`Host::this`] reads the host's interfaces (getifaddrs, sysfs).

use std::collections::BTreeSet;
use std::fmt;
use std::net::IpAddr;

use crate::remote::{Permission, RemoteCommands};

/// A zenoh endpoint, as far as its protection goes: `PROTO/ADDRESS[?META][#CONFIG]`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Endpoint {
    /// The whole endpoint, as given.
    pub text: String,
    /// The protocol (`tcp`, `udp`, `tls`, `quic`, `ws`, `unixsock-stream`, ...).
    pub protocol: String,
    /// The host part of the address, without brackets (an IP address, a name, or a path).
    pub host: String,
    /// `#iface=NAME`: the interface zenoh binds the link to.
    pub iface: Option<String>,
    /// `#enable_mtls=true|false` on the endpoint itself.
    pub mtls: Option<bool>,
    /// `udp/...?rel=1`: zenoh 1.10 runs a QUIC connection without encryption underneath (and
    /// with `mixed_rel=1` puts best-effort messages in its datagrams), see [`PACED_DRIVES`].
    pub quic_underneath: bool,
}

/// Why a drive lane should not be `udp/...?rel=1`.
pub const PACED_DRIVES: &str = "`?rel=1` on udp/ makes zenoh run QUIC underneath, without \
     encryption: its congestion control holds drives back after a loss (29-32 % of the time at \
     the drive through 100 ms and 10 % loss, against 99-100 % over plain udp/). Drop `?rel=1` \
     (and `mixed_rel`) from the endpoint (docs/remote.md: which link)";

/// An endpoint that is not `PROTO/ADDRESS`.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{0}` is not a zenoh endpoint (PROTOCOL/ADDRESS, e.g. udp/10.8.0.1:7448)")]
pub struct BadEndpoint(pub String);

impl Endpoint {
    /// Parses `text`.
    pub fn parse(text: &str) -> Result<Self, BadEndpoint> {
        let bad = || BadEndpoint(text.to_owned());
        let (locator, config) = text.split_once('#').unwrap_or((text, ""));
        let (locator, metadata) = locator.split_once('?').unwrap_or((locator, ""));
        let (protocol, address) = locator.split_once('/').ok_or_else(bad)?;
        if protocol.is_empty() || address.is_empty() {
            return Err(bad());
        }
        let host = if protocol.starts_with("unix") {
            address.to_owned()
        } else if let Some(rest) = address.strip_prefix('[') {
            rest.split_once(']').ok_or_else(bad)?.0.to_owned()
        } else {
            address
                .rsplit_once(':')
                .map_or(address, |(h, _)| h)
                .to_owned()
        };
        let mut endpoint = Self {
            text: text.to_owned(),
            protocol: protocol.to_ascii_lowercase(),
            host,
            iface: None,
            mtls: None,
            quic_underneath: false,
        };
        endpoint.quic_underneath =
            endpoint.protocol == "udp" && metadata.split(';').any(|pair| pair == "rel=1");
        for pair in config.split(';').filter(|p| !p.is_empty()) {
            match pair.split_once('=') {
                Some(("iface", name)) => endpoint.iface = Some(name.to_owned()),
                Some(("enable_mtls", value)) => endpoint.mtls = Some(value == "true"),
                _ => {}
            }
        }
        Ok(endpoint)
    }

    /// The host as an IP address, `localhost` as loopback; `None` for a name or a path.
    pub fn ip(&self) -> Option<IpAddr> {
        if self.host.eq_ignore_ascii_case("localhost") {
            return Some(IpAddr::from([127, 0, 0, 1]));
        }
        self.host.parse().ok()
    }
}

/// Which way a link goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Direction {
    /// The gateway listens: the address is one of this host's (or every one of them).
    Listen,
    /// The gateway connects out: the link leaves through the interface its route takes.
    Connect,
}

/// What protects a link, weakest last.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Protection {
    /// Only this host reaches it: a loopback address, a Unix socket.
    Local,
    /// Every peer proves who it is: TLS or QUIC with mutual authentication (certificates).
    MutualTls,
    /// An interface that admits only machines holding its key (WireGuard, or one the
    /// configuration names as authenticated).
    Tunnel {
        /// The interface.
        interface: String,
    },
    /// Encrypted, and the robot proves itself, but peers do not (TLS or QUIC without mutual
    /// authentication).
    ServerTls,
    /// Nobody proves anything: `tcp/`, `udp/`, `ws/` beyond loopback.
    Plain {
        /// Where it is reachable from, in words (an interface, every interface, a host name).
        reach: String,
    },
}

impl Protection {
    /// Whether the link admits only peers that proved who they are (or this host's own).
    pub fn authenticates_peers(&self) -> bool {
        match self {
            Self::Local | Self::MutualTls | Self::Tunnel { .. } => true,
            Self::ServerTls | Self::Plain { .. } => false,
        }
    }

    /// Classifies `endpoint`, going `direction`, on `host`; `mtls` is the zenoh configuration's
    /// `transport/link/tls/enable_mtls`.
    pub fn of(endpoint: &Endpoint, direction: Direction, host: &Host, mtls: bool) -> Self {
        let protocol = endpoint.protocol.as_str();
        if protocol.starts_with("unix") {
            return Self::Local;
        }
        let ip = endpoint.ip();
        if ip.is_some_and(|ip| ip.is_loopback()) {
            return Self::Local;
        }
        if matches!(protocol, "tls" | "quic") {
            return if endpoint.mtls.unwrap_or(mtls) {
                Self::MutualTls
            } else {
                Self::ServerTls
            };
        }
        // Bound to an interface, or through the one that holds (or routes to) the address.
        let bound = endpoint.iface.is_some();
        let interface = endpoint.iface.clone().or_else(|| match (ip, direction) {
            (Some(ip), _) if ip.is_unspecified() => None,
            (Some(ip), Direction::Listen) => host.interface_of(ip).map(str::to_owned),
            (Some(ip), Direction::Connect) => host.route_to(ip).map(str::to_owned),
            (None, _) => None,
        });
        match interface {
            // Linux takes a datagram for any of its addresses from any interface (the weak
            // host model): a machine beside the robot that sends to the tunnel's address over
            // the LAN reaches a socket bound to that address without any key. Only a socket
            // bound to the tunnel's interface takes nothing else.
            Some(interface)
                if host.is_tunnel(&interface) && !bound && direction == Direction::Listen =>
            {
                Self::Plain {
                    reach: format!(
                        "every interface: the address is {interface}'s, but Linux takes \
                         datagrams for it from any network; bind the link to the tunnel with \
                         #iface={interface}"
                    ),
                }
            }
            Some(interface) if host.is_tunnel(&interface) => Self::Tunnel { interface },
            Some(interface) if interface == "lo" => Self::Local,
            Some(interface) => Self::Plain {
                reach: format!("interface {interface}"),
            },
            None if ip.is_some_and(|ip| ip.is_unspecified()) => Self::Plain {
                reach: "every interface".into(),
            },
            None => Self::Plain {
                reach: format!("`{}`, an address on no interface known here", endpoint.host),
            },
        }
    }
}

impl fmt::Display for Protection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Local => f.write_str("this host only"),
            Self::MutualTls => f.write_str("TLS with mutual authentication (certificates)"),
            Self::Tunnel { interface } => {
                write!(f, "inside the authenticated tunnel {interface}")
            }
            Self::ServerTls => {
                f.write_str("TLS without client certificates: peers unauthenticated")
            }
            Self::Plain { reach } => write!(f, "plain, no authentication, reachable on {reach}"),
        }
    }
}

/// What the host knows of its interfaces: the addresses each holds, which are tunnels, and
/// the interface each destination's route leaves through.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Host {
    /// Each address of each interface.
    pub addresses: Vec<(IpAddr, String)>,
    /// The interfaces that authenticate their peers: WireGuard ones, and those the
    /// configuration names.
    pub tunnels: BTreeSet<String>,
    /// The interface the route to each destination looked up leaves through.
    pub routes: Vec<(IpAddr, String)>,
}

impl Host {
    /// The interface that holds `ip`.
    pub fn interface_of(&self, ip: IpAddr) -> Option<&str> {
        self.addresses
            .iter()
            .find(|(address, _)| *address == ip)
            .map(|(_, name)| name.as_str())
    }

    /// The interface the route to `ip` leaves through, as looked up.
    pub fn route_to(&self, ip: IpAddr) -> Option<&str> {
        self.routes
            .iter()
            .find(|(to, _)| *to == ip)
            .map(|(_, name)| name.as_str())
    }

    /// Whether `interface` authenticates its peers.
    pub fn is_tunnel(&self, interface: &str) -> bool {
        self.tunnels.contains(interface)
    }
}

/// A link the gateway's zenoh would use, and what protects it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Link {
    /// The endpoint, as configured.
    pub endpoint: String,
    /// Listened on or connected to.
    pub direction: Direction,
    /// What protects it.
    pub protection: Protection,
}

/// The remote commands that let a peer move the robot or undo a stop: everything but `estop`.
pub fn risky(commands: &RemoteCommands) -> Vec<Permission> {
    if !commands.enabled {
        return Vec::new();
    }
    let mut risky: Vec<Permission> = (commands.allowed.iter())
        .copied()
        .filter(|permission| *permission != Permission::Estop)
        .collect();
    risky.dedup();
    risky
}

/// Remote peers may command the robot over a link that authenticates nobody.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "refusing to take remote commands ({allowed}) over {links}: anyone who reaches it could \
     command as any peer name. Safe choices: listen on a WireGuard interface, bound to it (e.g. \
     --zenoh-listen udp/10.8.0.1:7448#iface=wg0, config/zenoh-wireguard-gateway.json5), or TLS or QUIC \
     with mutual authentication (config/zenoh-tls-gateway.json5), or allow remote e-stops only \
     (--remote-commands estop); name another authenticating interface in \
     [zenoh] authenticated_interfaces; on a network you trust, say so with \
     --zenoh-trusted-network ([zenoh] trusted_network = true). See docs/remote.md"
)]
pub struct Unprotected {
    /// The risky commands allowed, comma-separated.
    pub allowed: String,
    /// The unprotected links, in words.
    pub links: String,
}

/// What the gateway's remote commands may go over: `Ok` with the links to warn of (those that
/// authenticate nobody, when the network is declared trusted), or why it refuses to start.
pub fn check(
    links: &[Link],
    commands: &RemoteCommands,
    trusted_network: bool,
) -> Result<Vec<Link>, Unprotected> {
    let risky = risky(commands);
    let open: Vec<Link> = (links.iter())
        .filter(|link| !link.protection.authenticates_peers())
        .cloned()
        .collect();
    if risky.is_empty() || open.is_empty() {
        return Ok(Vec::new());
    }
    if trusted_network {
        return Ok(open);
    }
    let names: Vec<&str> = risky.iter().map(|p| p.name()).collect();
    let links: Vec<String> = (open.iter())
        .map(|link| format!("{} ({})", link.endpoint, link.protection))
        .collect();
    Err(Unprotected {
        allowed: names.join(", "),
        links: links.join(" and "),
    })
}

#[cfg(target_os = "linux")]
impl Host {
    /// This host's interfaces and their addresses (getifaddrs), the WireGuard ones among them
    /// (sysfs `DEVTYPE=wireguard`) and `named` as tunnels too, and the interface the route to
    /// each of `destinations` leaves through.
    pub fn this(named: &[String], destinations: &[IpAddr]) -> Self {
        let mut host = Self::default();
        if let Ok(interfaces) = nix::ifaddrs::getifaddrs() {
            for interface in interfaces {
                let ip = interface.address.as_ref().and_then(|address| {
                    (address.as_sockaddr_in().map(|a| IpAddr::V4(a.ip())))
                        .or_else(|| address.as_sockaddr_in6().map(|a| IpAddr::V6(a.ip())))
                });
                if let Some(ip) = ip {
                    host.addresses.push((ip, interface.interface_name.clone()));
                }
                if is_wireguard(&interface.interface_name) {
                    host.tunnels.insert(interface.interface_name);
                }
            }
        }
        host.tunnels.extend(named.iter().cloned());
        for destination in destinations {
            if let Some(interface) = host.route_source(*destination) {
                host.routes.push((*destination, interface));
            }
        }
        host
    }

    /// The interface a datagram to `destination` would leave through: the kernel's route
    /// lookup (a UDP socket connected, never sent on), then the interface holding the source
    /// address it chose.
    fn route_source(&self, destination: IpAddr) -> Option<String> {
        let bind: IpAddr = match destination {
            IpAddr::V4(_) => IpAddr::from([0, 0, 0, 0]),
            IpAddr::V6(_) => IpAddr::from([0u16; 8]),
        };
        let socket = std::net::UdpSocket::bind((bind, 0)).ok()?;
        socket.connect((destination, 9)).ok()?;
        let source = socket.local_addr().ok()?.ip();
        self.interface_of(source).map(str::to_owned)
    }
}

/// Whether the kernel says `interface` is a WireGuard interface.
#[cfg(target_os = "linux")]
fn is_wireguard(interface: &str) -> bool {
    if interface.contains('/') || interface.starts_with('.') {
        return false;
    }
    std::fs::read_to_string(format!("/sys/class/net/{interface}/uevent"))
        .is_ok_and(|uevent| uevent.lines().any(|line| line == "DEVTYPE=wireguard"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn endpoint(text: &str) -> Endpoint {
        Endpoint::parse(text).expect("an endpoint")
    }

    fn robot() -> Host {
        Host {
            addresses: vec![
                ("127.0.0.1".parse().unwrap(), "lo".into()),
                ("192.168.1.20".parse().unwrap(), "wlan0".into()),
                ("10.8.0.1".parse().unwrap(), "wg0".into()),
            ],
            tunnels: ["wg0".to_owned()].into(),
            routes: vec![
                ("10.8.0.2".parse().unwrap(), "wg0".into()),
                ("192.168.1.5".parse().unwrap(), "wlan0".into()),
            ],
        }
    }

    fn listen(text: &str) -> Protection {
        Protection::of(&endpoint(text), Direction::Listen, &robot(), false)
    }

    #[test]
    fn endpoints_parse_with_their_config() {
        let e = endpoint("udp/[::1]:7448?rel=1;mixed_rel=1#iface=wg0;enable_mtls=true");
        assert_eq!(
            (
                e.protocol.as_str(),
                e.host.as_str(),
                e.iface.as_deref(),
                e.mtls
            ),
            ("udp", "::1", Some("wg0"), Some(true))
        );
        assert!(e.quic_underneath);
        assert!(!endpoint("udp/10.8.0.1:7448#iface=wg0").quic_underneath);
        assert!(!endpoint("quic/10.8.0.1:7448?rel=1").quic_underneath);
        assert_eq!(
            endpoint("tcp/localhost:7448").ip(),
            "127.0.0.1".parse().ok()
        );
        assert_eq!(endpoint("unixsock-stream//run/z.sock").host, "/run/z.sock");
        assert_eq!(endpoint("tcp/robot.local:7448").ip(), None);
        for bad in ["", "udp", "udp/", "/1.2.3.4:5", "udp/[::1:7448"] {
            assert!(Endpoint::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn each_kind_of_link_is_told_apart() {
        assert_eq!(listen("udp/127.0.0.1:7448"), Protection::Local);
        assert_eq!(listen("tcp/[::1]:7448"), Protection::Local);
        assert_eq!(listen("unixsock-stream//run/scout.sock"), Protection::Local);
        assert_eq!(
            listen("udp/10.8.0.1:7448#iface=wg0"),
            Protection::Tunnel {
                interface: "wg0".into()
            }
        );
        // The tunnel's address, not bound to it: reachable from the LAN (weak host model).
        assert!(matches!(
            listen("udp/10.8.0.1:7448"),
            Protection::Plain { reach } if reach.contains("#iface=wg0")
        ));
        assert_eq!(
            listen("udp/0.0.0.0:7448"),
            Protection::Plain {
                reach: "every interface".into()
            }
        );
        assert_eq!(
            listen("udp/0.0.0.0:7448#iface=wg0"),
            Protection::Tunnel {
                interface: "wg0".into()
            }
        );
        assert_eq!(
            listen("udp/192.168.1.20:7448"),
            Protection::Plain {
                reach: "interface wlan0".into()
            }
        );
        assert!(matches!(
            listen("tcp/robot.local:7448"),
            Protection::Plain { .. }
        ));
        assert_eq!(listen("quic/0.0.0.0:7448"), Protection::ServerTls);
        assert_eq!(
            listen("tls/0.0.0.0:7448#enable_mtls=true"),
            Protection::MutualTls
        );
        let mtls = Protection::of(
            &endpoint("quic/[::]:7448"),
            Direction::Listen,
            &robot(),
            true,
        );
        assert_eq!(mtls, Protection::MutualTls);
        let connect = |text| Protection::of(&endpoint(text), Direction::Connect, &robot(), false);
        assert_eq!(
            connect("udp/10.8.0.2:7448"),
            Protection::Tunnel {
                interface: "wg0".into()
            }
        );
        assert!(matches!(
            connect("tcp/192.168.1.5:7447"),
            Protection::Plain { .. }
        ));
    }

    fn commands(allowed: &[Permission]) -> RemoteCommands {
        RemoteCommands {
            enabled: true,
            allowed: allowed.to_vec(),
        }
    }

    fn link(text: &str) -> Link {
        Link {
            endpoint: text.into(),
            direction: Direction::Listen,
            protection: listen(text),
        }
    }

    #[test]
    fn only_estop_goes_over_a_link_that_authenticates_nobody() {
        let open = [link("udp/127.0.0.1:7448"), link("udp/0.0.0.0:7447")];
        assert_eq!(
            check(&open, &commands(&[Permission::Estop]), false),
            Ok(vec![])
        );
        let off = RemoteCommands {
            enabled: false,
            allowed: vec![Permission::Teleop],
        };
        assert_eq!(check(&open, &off, false), Ok(vec![]));
        for risky in [
            Permission::Teleop,
            Permission::Autonomy,
            Permission::Release,
            Permission::Resume,
            Permission::Lights,
            Permission::ClearFault,
        ] {
            let error =
                check(&open, &commands(&[Permission::Estop, risky]), false).expect_err("refused");
            assert_eq!(error.allowed, risky.name());
            assert_eq!(
                error.links,
                "udp/0.0.0.0:7447 (plain, no authentication, reachable on every interface)"
            );
            assert!(error.to_string().contains("--zenoh-trusted-network"));
            // Declared trusted: allowed, and the open link is returned to warn of.
            let warned = check(&open, &commands(&[risky]), true).expect("trusted");
            assert_eq!(warned, vec![open[1].clone()]);
        }
        let safe = [
            link("udp/127.0.0.1:7448"),
            link("udp/10.8.0.1:7448#iface=wg0"),
            link("tls/0.0.0.0:7448#enable_mtls=true"),
        ];
        let all = commands(&[Permission::Teleop, Permission::Release]);
        assert_eq!(check(&safe, &all, false), Ok(vec![]));
        assert!(check(&[link("quic/0.0.0.0:7448")], &all, false).is_err());
    }

    #[test]
    fn this_host_has_a_loopback_interface_and_routes_to_it() {
        let host = Host::this(&["wgx".into()], &["127.0.0.1".parse().unwrap()]);
        assert_eq!(host.interface_of("127.0.0.1".parse().unwrap()), Some("lo"));
        assert_eq!(host.route_to("127.0.0.1".parse().unwrap()), Some("lo"));
        assert!(host.is_tunnel("wgx") && !host.is_tunnel("lo"));
    }
}
