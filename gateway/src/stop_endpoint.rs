//! The gateway's end of the stop endpoint ([`scout_interface::stop_socket`]): it binds the
//! robot's abstract socket address, which is also the lock that one gateway serves a robot name
//! on this host whatever its environment (the kernel frees it when the gateway dies), and reads
//! stop and release datagrams with their sender's pid, uid and gid from the kernel.

use std::io::IoSliceMut;
use std::os::fd::{AsFd, AsRawFd, BorrowedFd, OwnedFd};
use std::time::Duration;

use nix::errno::Errno;
use nix::sys::socket::{
    ControlMessageOwned, MsgFlags, SockaddrLike, UnixAddr, UnixCredentials, recvmsg, sendto,
    setsockopt, sockopt,
};
use scout_interface::stop_socket::{self, ParseError, StopClient, StopReply, StopRequest};

/// Why the endpoint could not be bound.
#[derive(Debug, thiserror::Error)]
pub enum BindError {
    /// Another gateway serves this robot name on this host.
    #[error(
        "robot '{robot}' is already served by another scout-gateway on this host{}: stop it first, or give this one another --name",
        holder.map(|pid| format!(" (pid {pid})")).unwrap_or_default()
    )]
    Held {
        /// The robot.
        robot: String,
        /// The holder's pid, if it answered.
        holder: Option<u32>,
    },
    /// The socket failed.
    #[error("the stop socket @{address}: {errno}")]
    Io {
        /// The abstract address.
        address: String,
        /// Why.
        errno: Errno,
    },
}

/// A datagram that arrived, with who sent it.
#[derive(Debug)]
pub struct Received {
    /// The sender's pid as the kernel vouches for it (0: no credentials came).
    pub pid: u32,
    /// The sender's user id.
    pub uid: u32,
    /// Where to answer (`None`: the sender has no address; it gets no answer).
    pub from: Option<UnixAddr>,
    /// What it asked.
    pub request: Result<StopRequest, ParseError>,
}

/// The bound endpoint.
#[derive(Debug)]
pub struct StopEndpoint {
    socket: OwnedFd,
    /// Replies that could not be sent (the client's queue full, or it left).
    pub replies_lost: u64,
}

/// The most bytes read of one datagram; a longer one is cut (and so malformed).
const MAX_DATAGRAM: usize = 512;

impl StopEndpoint {
    /// Binds `robot`'s address; refused when another gateway holds it.
    pub fn bind(robot: &str) -> Result<Self, BindError> {
        let address = stop_socket::address(robot);
        let io = |errno| BindError::Io {
            address: address.clone(),
            errno,
        };
        match stop_socket::claim(&address) {
            Ok(socket) => {
                setsockopt(&socket, sockopt::PassCred, &true).map_err(io)?;
                Ok(Self {
                    socket,
                    replies_lost: 0,
                })
            }
            Err(Errno::EADDRINUSE) => Err(BindError::Held {
                robot: robot.to_owned(),
                holder: holder_pid(robot),
            }),
            Err(errno) => Err(io(errno)),
        }
    }

    /// The socket, to wait on.
    pub fn fd(&self) -> BorrowedFd<'_> {
        self.socket.as_fd()
    }

    /// The next datagram waiting, without blocking.
    pub fn try_receive(&self) -> Option<Received> {
        let mut buffer = [0u8; MAX_DATAGRAM];
        let mut cmsg = nix::cmsg_space!(UnixCredentials);
        let (len, from, credentials) = {
            let mut iov = [IoSliceMut::new(&mut buffer)];
            let message = match recvmsg::<UnixAddr>(
                self.socket.as_raw_fd(),
                &mut iov,
                Some(&mut cmsg),
                MsgFlags::MSG_DONTWAIT,
            ) {
                Ok(message) => message,
                Err(Errno::EAGAIN | Errno::EINTR) => return None,
                Err(errno) => {
                    tracing::debug!("reading the stop socket failed: {errno}");
                    return None;
                }
            };
            let credentials = message.cmsgs().ok().and_then(|mut cmsgs| {
                cmsgs.find_map(|cmsg| match cmsg {
                    ControlMessageOwned::ScmCredentials(credentials) => Some(credentials),
                    _ => None,
                })
            });
            // An unnamed (unbound) sender cannot be answered. Its address may come back shorter
            // than the family field: look at the length only (nix's accessors assert on it).
            let from = message
                .address
                .filter(|address| address.len() as usize > std::mem::size_of::<u16>());
            (message.bytes, from, credentials)
        };
        Some(Received {
            pid: credentials.map_or(0, |c| c.pid().unsigned_abs()),
            uid: credentials.map_or(u32::MAX, |c| c.uid()),
            from,
            request: stop_socket::parse(&buffer[..len]),
        })
    }

    /// Answers `to` without blocking; a reply that cannot go is counted, never waited for.
    /// Each reply leaves from a socket of its own: a reply its client never reads stays charged
    /// to that socket's send buffer, so clients that never read cannot use up the endpoint's
    /// and starve everyone else's answers.
    pub fn reply(&mut self, to: Option<&UnixAddr>, reply: &StopReply) {
        let sent = to.is_some_and(|to| {
            let (bytes, len) = reply.emit();
            nix::sys::socket::socket(
                nix::sys::socket::AddressFamily::Unix,
                nix::sys::socket::SockType::Datagram,
                nix::sys::socket::SockFlag::SOCK_CLOEXEC
                    | nix::sys::socket::SockFlag::SOCK_NONBLOCK,
                None,
            )
            .and_then(|socket| {
                sendto(
                    socket.as_raw_fd(),
                    &bytes[..len],
                    to,
                    MsgFlags::MSG_DONTWAIT,
                )
            })
            .is_ok()
        });
        if !sent {
            self.replies_lost += 1;
            if self.replies_lost.is_power_of_two() {
                tracing::warn!(
                    "{} stop-endpoint replies could not be sent (the client left, never reads, \
                     or has no address); their stops and releases were carried out",
                    self.replies_lost
                );
            }
        }
    }
}

/// The pid of the gateway serving `robot`, if it answers a ping.
fn holder_pid(robot: &str) -> Option<u32> {
    let mut client = StopClient::new(robot, "scout-gateway").ok()?;
    client
        .request(stop_socket::Ask::Ping, Duration::from_millis(500))
        .ok()
        .map(|reply| reply.gateway_pid)
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_interface::control::Accepted;
    use scout_interface::stop_socket::{Ask, StopRequest};

    /// The next datagram, waiting at most 2 s for it.
    fn receive_within(endpoint: &StopEndpoint) -> Received {
        let deadline = std::time::Instant::now() + Duration::from_secs(2);
        loop {
            if let Some(received) = endpoint.try_receive() {
                return received;
            }
            assert!(std::time::Instant::now() < deadline, "no datagram");
            std::thread::sleep(Duration::from_millis(1));
        }
    }

    fn robot(tag: &str) -> String {
        format!("ep-{tag}-{}", std::process::id())
    }

    #[test]
    fn a_second_bind_is_refused_with_the_holders_pid() {
        let robot = robot("twice");
        let mut first = StopEndpoint::bind(&robot).expect("first bind");
        let answering = std::thread::scope(|scope| {
            let answer = scope.spawn(|| StopEndpoint::bind(&robot));
            // Answer the second one's ping.
            let deadline = std::time::Instant::now() + Duration::from_secs(2);
            while std::time::Instant::now() < deadline {
                if let Some(received) = first.try_receive() {
                    let seq = received.request.as_ref().map_or(0, |r| r.seq);
                    let reply = StopReply::new(seq, &Ok(Accepted::default()), 4242);
                    first.reply(received.from.as_ref(), &reply);
                    break;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            answer.join().expect("no panic")
        });
        match answering {
            Err(BindError::Held { holder, .. }) => assert_eq!(holder, Some(4242)),
            other => panic!("expected Held, got {other:?}"),
        }
        drop(first);
        StopEndpoint::bind(&robot).expect("free again once the holder is gone");
    }

    #[test]
    fn datagrams_carry_the_senders_pid_and_are_answered() {
        let robot = robot("creds");
        let mut endpoint = StopEndpoint::bind(&robot).expect("bind");
        let mut client = StopClient::new(&robot, "guard").expect("client");
        std::thread::scope(|scope| {
            let asked = scope.spawn(move || {
                client.request(
                    Ask::Stop {
                        reason: "obstacle".into(),
                    },
                    Duration::from_secs(2),
                )
            });
            let received = receive_within(&endpoint);
            assert_eq!(received.pid, std::process::id());
            let request = received.request.expect("parsed");
            assert_eq!(request.name.as_deref(), Some("guard"));
            let answer = Ok(Accepted {
                stop: Some(3),
                ..Accepted::default()
            });
            endpoint.reply(
                received.from.as_ref(),
                &StopReply::new(request.seq, &answer, 1),
            );
            let reply = asked.join().expect("no panic").expect("answered");
            assert_eq!(reply.answer.expect("accepted").stop, Some(3));
        });
    }

    #[test]
    fn an_unbound_sender_is_read_and_not_answered() {
        use std::os::unix::net::UnixDatagram;
        let robot = robot("unbound");
        let mut endpoint = StopEndpoint::bind(&robot).expect("bind");
        let sender = UnixDatagram::unbound().expect("socket");
        let address = std::os::unix::net::SocketAddr::from_abstract_name(
            stop_socket::address(&robot).as_bytes(),
        )
        .expect("address");
        use std::os::linux::net::SocketAddrExt;
        for datagram in [
            &b"x"[..],
            &[],
            &StopRequest {
                seq: 1,
                name: Some("anon".into()),
                ask: Ask::Stop {
                    reason: "unbound".into(),
                },
            }
            .emit(),
        ] {
            sender.send_to_addr(datagram, &address).expect("send");
            let received = receive_within(&endpoint);
            assert!(received.from.is_none());
            endpoint.reply(None, &StopReply::new(1, &Ok(Accepted::default()), 1));
        }
        assert_eq!(endpoint.replies_lost, 3);
    }

    #[test]
    fn clients_that_never_read_their_replies_do_not_starve_the_others() {
        use std::os::linux::net::SocketAddrExt;
        use std::os::unix::net::UnixDatagram;
        let robot = robot("hogs");
        let mut endpoint = StopEndpoint::bind(&robot).expect("bind");
        let address = std::os::unix::net::SocketAddr::from_abstract_name(
            stop_socket::address(&robot).as_bytes(),
        )
        .expect("address");
        let ping = StopRequest {
            seq: 1,
            name: Some("hog".into()),
            ask: Ask::Ping,
        }
        .emit();
        // 40 bound sockets, 20 pings each, never reading an answer.
        let hogs: Vec<UnixDatagram> = (0..40)
            .map(|i| {
                let name = format!("{robot}-hog-{i}");
                UnixDatagram::bind_addr(
                    &std::os::unix::net::SocketAddr::from_abstract_name(name.as_bytes())
                        .expect("address"),
                )
                .expect("socket")
            })
            .collect();
        for hog in &hogs {
            for _ in 0..20 {
                let _ = hog.send_to_addr(&ping, &address);
                while let Some(received) = endpoint.try_receive() {
                    let reply = StopReply::new(1, &Ok(Accepted::default()), 1);
                    endpoint.reply(received.from.as_ref(), &reply);
                }
            }
        }
        // A client that reads gets its answer.
        let mut client = StopClient::new(&robot, "guard").expect("client");
        std::thread::scope(|scope| {
            let asked = scope.spawn(move || client.stop("x", Duration::from_secs(2)));
            let deadline = std::time::Instant::now() + Duration::from_secs(2);
            while !asked.is_finished() && std::time::Instant::now() < deadline {
                while let Some(received) = endpoint.try_receive() {
                    let seq = received.request.as_ref().map_or(0, |r| r.seq);
                    let reply = StopReply::new(seq, &Ok(Accepted::default()), 1);
                    endpoint.reply(received.from.as_ref(), &reply);
                }
                std::thread::sleep(Duration::from_millis(1));
            }
            asked
                .join()
                .expect("no panic")
                .expect("answered despite the hogs");
        });
        drop(hogs);
    }

    #[test]
    fn no_gateway_is_said_at_once() {
        let mut client = StopClient::new(&robot("nobody"), "guard").expect("client");
        let error = client
            .stop("x", Duration::from_secs(5))
            .expect_err("nobody there");
        assert!(error.to_string().contains("no gateway named"), "{error}");
    }
}
