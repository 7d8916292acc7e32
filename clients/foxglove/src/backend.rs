//! The Foxglove SDK's server behind the front ([`crate::subprotocol`]), reachable from the front
//! alone. The SDK listens on a loopback TCP port of its own, which any local process could reach
//! directly, past the front's origin check, its client limit and its drop of clients that stop
//! reading. The front's connections leave from ports it binds first; a socket filter (classic
//! BPF) on the SDK's listening socket drops every packet that comes from another address or
//! port, so a connection from anyone else never completes its handshake. The listening socket is
//! found among this process's descriptors by its address and taken with `pidfd_getfd` (Linux
//! 5.6): where that cannot be done, the view says so and runs unguarded.

use std::collections::BTreeSet;
use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, TcpStream};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use rustix::process::{PidfdFlags, PidfdGetfdFlags};
use socket2::{Domain, SockFilter, Socket, Type};

/// The SDK's server, and the guard on its listening socket if it could be set.
#[derive(Debug)]
pub struct Backend {
    address: SocketAddrV4,
    guard: Option<Mutex<Guard>>,
}

/// The SDK's listening socket (a duplicate of its descriptor) and the ports the front's
/// connections leave from.
#[derive(Debug)]
struct Guard {
    listener: Socket,
    ports: BTreeSet<u16>,
}

impl Guard {
    /// Lets in only `ports`, from 127.0.0.1.
    fn apply(&self) -> io::Result<()> {
        let ports: Vec<u16> = self.ports.iter().copied().collect();
        self.listener.attach_filter(&program(&ports))
    }
}

/// Why the backend could not be guarded.
#[derive(Debug, thiserror::Error)]
pub enum GuardError {
    /// The server's address is not IPv4 loopback.
    #[error("the server listens on {0}, not on 127.0.0.1")]
    NotLoopback(SocketAddr),
    /// Its listening socket is not among this process's descriptors.
    #[error("no listening socket of {0} among this process's descriptors")]
    NotFound(SocketAddrV4),
    /// A system call failed.
    #[error("{what}")]
    Io {
        /// Which.
        what: &'static str,
        /// Why.
        #[source]
        source: io::Error,
    },
}

impl Backend {
    /// The SDK's server at `address`, guarded so that only [`Backend::connect`] reaches it.
    pub fn guard(address: SocketAddr) -> Result<Self, GuardError> {
        let SocketAddr::V4(address) = address else {
            return Err(GuardError::NotLoopback(address));
        };
        if *address.ip() != Ipv4Addr::LOCALHOST {
            return Err(GuardError::NotLoopback(SocketAddr::V4(address)));
        }
        let guard = Guard {
            listener: listening_socket(address)?,
            ports: BTreeSet::new(),
        };
        guard.apply().map_err(|source| GuardError::Io {
            what: "filtering the server's listening socket",
            source,
        })?;
        Ok(Self {
            address,
            guard: Some(Mutex::new(guard)),
        })
    }

    /// The SDK's server at `address`, unguarded: any local process may connect to it.
    pub fn unguarded(address: SocketAddr) -> Self {
        let address = match address {
            SocketAddr::V4(address) => address,
            SocketAddr::V6(_) => SocketAddrV4::new(Ipv4Addr::LOCALHOST, address.port()),
        };
        Self {
            address,
            guard: None,
        }
    }

    /// Whether only [`Backend::connect`] reaches the server.
    pub fn is_guarded(&self) -> bool {
        self.guard.is_some()
    }

    /// Connects to the server from a port let in for as long as the returned [`Permit`] lives.
    pub fn connect(self: &Arc<Self>, timeout: Duration) -> io::Result<(TcpStream, Permit)> {
        let socket = Socket::new(Domain::IPV4, Type::STREAM, None)?;
        socket.bind(&SocketAddr::from((Ipv4Addr::LOCALHOST, 0)).into())?;
        let port = socket
            .local_addr()?
            .as_socket()
            .map(|address| address.port())
            .ok_or_else(|| io::Error::other("the socket has no IP address"))?;
        let permit = Permit {
            backend: Arc::clone(self),
            port,
        };
        permit.allow(true)?;
        socket.connect_timeout(&SocketAddr::V4(self.address).into(), timeout)?;
        Ok((socket.into(), permit))
    }
}

/// A port the guard lets in; dropped, it no longer is.
#[derive(Debug)]
pub struct Permit {
    backend: Arc<Backend>,
    port: u16,
}

impl Permit {
    fn allow(&self, allowed: bool) -> io::Result<()> {
        let Some(guard) = &self.backend.guard else {
            return Ok(());
        };
        let mut guard = guard.lock().unwrap_or_else(PoisonError::into_inner);
        if allowed {
            guard.ports.insert(self.port);
        } else {
            guard.ports.remove(&self.port);
        }
        guard.apply()
    }
}

impl Drop for Permit {
    fn drop(&mut self) {
        if let Err(error) = self.allow(false) {
            tracing::warn!("closing port {} of the Foxglove server: {error}", self.port);
        }
    }
}

/// This process's listening TCP socket at `address`, as a descriptor of its own.
fn listening_socket(address: SocketAddrV4) -> Result<Socket, GuardError> {
    let io = |what| move |source| GuardError::Io { what, source };
    let me = rustix::process::pidfd_open(rustix::process::getpid(), PidfdFlags::empty())
        .map_err(|errno| io("pidfd_open")(errno.into()))?;
    let fds = std::fs::read_dir("/proc/self/fd").map_err(io("listing /proc/self/fd"))?;
    for fd in fds.flatten() {
        let is_socket = std::fs::read_link(fd.path())
            .is_ok_and(|target| target.to_string_lossy().starts_with("socket:"));
        let Some(number) = fd.file_name().to_str().and_then(|n| n.parse::<i32>().ok()) else {
            continue;
        };
        if !is_socket {
            continue;
        }
        let Ok(duplicate) = rustix::process::pidfd_getfd(&me, number, PidfdGetfdFlags::empty())
        else {
            continue;
        };
        let socket = Socket::from(duplicate);
        let bound = socket.local_addr().ok().and_then(|a| a.as_socket());
        let listening = socket.peer_addr().is_err() && socket.r#type().ok() == Some(Type::STREAM);
        if bound == Some(SocketAddr::V4(address)) && listening {
            return Ok(socket);
        }
    }
    Err(GuardError::NotFound(address))
}

// Classic BPF, as the kernel's `linux/filter.h` numbers it.
const BPF_LD: u16 = 0x00;
const BPF_W: u16 = 0x00;
const BPF_H: u16 = 0x08;
const BPF_ABS: u16 = 0x20;
const BPF_JMP: u16 = 0x05;
const BPF_JEQ: u16 = 0x10;
const BPF_K: u16 = 0x00;
const BPF_RET: u16 = 0x06;
/// Loads relative to the network (IP) header; a TCP socket's filter sees the TCP header at 0.
const SKF_NET_OFF: i32 = -0x10_0000;

/// A socket filter that accepts TCP segments from 127.0.0.1 and one of `ports` (at most 250),
/// and drops every other.
fn program(ports: &[u16]) -> Vec<SockFilter> {
    instructions(ports)
        .into_iter()
        .map(|(code, jt, jf, k)| SockFilter::new(code, jt, jf, k))
        .collect()
}

/// [`program`]'s instructions: (code, jump if true, jump if false, constant).
fn instructions(ports: &[u16]) -> Vec<(u16, u8, u8, u32)> {
    let ports = &ports[..ports.len().min(250)];
    let drop_at = 3 + ports.len();
    let accept_at = drop_at + 1;
    let mut program = vec![
        // The IPv4 source address.
        (BPF_LD | BPF_W | BPF_ABS, 0, 0, (SKF_NET_OFF + 12) as u32),
        (
            BPF_JMP | BPF_JEQ | BPF_K,
            0,
            (drop_at - 2) as u8,
            u32::from(Ipv4Addr::LOCALHOST),
        ),
        // The TCP source port.
        (BPF_LD | BPF_H | BPF_ABS, 0, 0, 0),
    ];
    for (at, port) in ports.iter().enumerate() {
        let jump = (accept_at - (3 + at) - 1) as u8;
        program.push((BPF_JMP | BPF_JEQ | BPF_K, jump, 0, u32::from(*port)));
    }
    program.push((BPF_RET | BPF_K, 0, 0, 0));
    program.push((BPF_RET | BPF_K, 0, 0, u32::MAX));
    program
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::TcpListener;

    /// A connection to `to` from a socket of its own, waiting at most 300 ms.
    fn stranger(to: SocketAddr) -> io::Result<TcpStream> {
        TcpStream::connect_timeout(&to, Duration::from_millis(300))
    }

    #[test]
    fn only_the_fronts_ports_reach_the_guarded_server() {
        let server = TcpListener::bind("127.0.0.1:0").expect("listen");
        let address = server.local_addr().expect("address");
        let early = stranger(address).expect("unguarded, anyone connects");
        let (accepted, _) = server.accept().expect("accepted");
        drop((accepted, early));
        let backend = Arc::new(Backend::guard(address).expect("guarded"));
        assert!(backend.is_guarded());
        let refused = stranger(address).expect_err("a stranger is dropped");
        assert!(
            matches!(
                refused.kind(),
                io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
            ),
            "{refused:?}"
        );
        let (stream, permit) = backend
            .connect(Duration::from_secs(2))
            .expect("the front connects");
        let (accepted, from) = server.accept().expect("accepted");
        assert_eq!(from, stream.local_addr().expect("local"));
        drop((accepted, stream, permit));
        // Its port is closed again once the permit is gone.
        assert!(backend.guard.as_ref().is_some_and(|guard| {
            guard
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .ports
                .is_empty()
        }));
        stranger(address).expect_err("still dropped");
    }

    #[test]
    fn a_server_not_on_loopback_or_not_listening_is_not_guarded() {
        let v6 = SocketAddr::from((std::net::Ipv6Addr::LOCALHOST, 1));
        assert!(matches!(
            Backend::guard(v6),
            Err(GuardError::NotLoopback(_))
        ));
        let nobody = SocketAddr::from((Ipv4Addr::LOCALHOST, 1));
        assert!(matches!(
            Backend::guard(nobody),
            Err(GuardError::NotFound(_))
        ));
        assert!(!Backend::unguarded(nobody).is_guarded());
    }

    #[test]
    fn the_program_jumps_to_accept_from_each_port_and_drops_the_rest() {
        let jeq = BPF_JMP | BPF_JEQ | BPF_K;
        assert_eq!(
            instructions(&[40_000, 40_001]),
            [
                (0x20, 0, 0, 0xFFF0_000C),
                (jeq, 0, 3, 0x7F00_0001),
                (0x28, 0, 0, 0),
                (jeq, 2, 0, 40_000),
                (jeq, 1, 0, 40_001),
                (BPF_RET, 0, 0, 0),
                (BPF_RET, 0, 0, u32::MAX),
            ]
        );
        // No port: everything is dropped.
        assert_eq!(instructions(&[])[1], (jeq, 0, 1, 0x7F00_0001));
        assert_eq!(instructions(&[])[3], (BPF_RET, 0, 0, 0));
    }
}
