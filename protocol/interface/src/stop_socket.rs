//! The stop endpoint beside iceoryx2: stops and releases as datagrams on a Unix socket in the
//! abstract namespace (`@scout/ROBOT/stop`), so that stopping needs no shared memory (a full
//! `/dev/shm` cannot keep a stop from latching), no client slot and no set-up. The gateway
//! reads the sender's pid, uid and gid from the kernel (`SCM_CREDENTIALS`), never from the
//! datagram. Binding the address is also the one-gateway-per-robot lock: the kernel frees it
//! when its holder dies.
//!
//! The datagrams, little-endian, as named byte ranges ([`request`], [`reply`]); [`parse`] /
//! `emit` are sans-IO, [`StopClient`] is the client's I/O.

use std::os::fd::{AsRawFd, OwnedFd};
use std::time::{Duration, Instant};

use nix::errno::Errno;
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::socket::{
    AddressFamily, MsgFlags, SockFlag, SockType, UnixAddr, bind, recv, sendto, setsockopt, socket,
    sockopt,
};

use crate::LAYOUT_VERSION;
use crate::control::{
    Accepted, MAX_CLIENT_NAME, MAX_REASON, Rejected, Rejection, RejectionKind, ReleaseScope,
    ReleaseTarget, Request,
};

/// The abstract socket name of `robot`'s stop endpoint (without the leading NUL).
pub fn address(robot: &str) -> String {
    format!("{}/stop", crate::services::prefix(robot))
}

/// Binds a non-blocking datagram socket to the abstract `address`: a claim on a name that one
/// process holds on this host (in its network namespace) and the kernel frees when that process
/// dies, even by SIGKILL. `EADDRINUSE`: another process holds it.
pub fn claim(address: &str) -> Result<OwnedFd, Errno> {
    let socket = socket(
        AddressFamily::Unix,
        SockType::Datagram,
        SockFlag::SOCK_CLOEXEC | SockFlag::SOCK_NONBLOCK,
        None,
    )?;
    bind(
        socket.as_raw_fd(),
        &UnixAddr::new_abstract(address.as_bytes())?,
    )?;
    Ok(socket)
}

/// The request datagram's fields.
pub mod request {
    use std::ops::Range;
    /// `SCST`.
    pub const MAGIC: Range<usize> = 0..4;
    /// [`crate::LAYOUT_VERSION`] as a byte.
    pub const VERSION: usize = 4;
    /// [`super::Kind`].
    pub const KIND: usize = 5;
    /// [`crate::control::ReleaseScope`], for release.
    pub const SCOPE: usize = 6;
    /// The sender's request number (u64).
    pub const SEQ: Range<usize> = 8..16;
    /// For release: the newest stop id the sender saw (u64).
    pub const THROUGH: Range<usize> = 16..24;
    /// The client's name, UTF-8, NUL-padded.
    pub const NAME: Range<usize> = 24..56;
    /// For release of one owner's stops: the owner, UTF-8, NUL-padded.
    pub const OWNER: Range<usize> = 56..88;
    /// For stop: why, UTF-8, NUL-padded.
    pub const REASON: Range<usize> = 88..152;
    /// The whole datagram.
    pub const LEN: usize = 152;
}

/// The reply datagram's fields.
pub mod reply {
    use std::ops::Range;
    /// `SCSA`.
    pub const MAGIC: Range<usize> = 0..4;
    /// [`crate::LAYOUT_VERSION`] as a byte.
    pub const VERSION: usize = 4;
    /// 1 accepted, 0 rejected.
    pub const ACCEPTED: usize = 5;
    /// The [`crate::control::RejectionKind`] byte; 0xFF when accepted.
    pub const CODE: usize = 6;
    /// The request's number (u64).
    pub const SEQ: Range<usize> = 8..16;
    /// For an accepted stop: its id; for a ping: the newest stop latched, held or released
    /// (the status' `newest_stop`) (u64, 0: none).
    pub const STOP: Range<usize> = 16..24;
    /// The gateway's pid (u32).
    pub const PID: Range<usize> = 24..28;
    /// Why it was rejected, UTF-8, to the end of the datagram.
    pub const REASON: usize = 28;
    /// The longest reason.
    pub const MAX_REASON: usize = 160;
    /// The longest datagram.
    pub const MAX_LEN: usize = REASON + MAX_REASON;
}

const REQUEST_MAGIC: &[u8; 4] = b"SCST";
const REPLY_MAGIC: &[u8; 4] = b"SCSA";

wire_enum! {
    /// What a stop datagram asks for.
    Kind {
        /// Who holds this robot's name? Answered with the gateway's pid and the newest stop's
        /// id; changes nothing.
        Ping = 0 => "ping",
        /// Latch a stop owned by the sender's name.
        Stop = 2 => "stop",
        /// Release stops.
        Release = 3 => "release",
    }
}

/// What a stop datagram asks for, decoded.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ask {
    /// Who holds the name.
    Ping,
    /// Latch a stop.
    Stop {
        /// Why.
        reason: String,
    },
    /// Release the stops `target` names, latched no later than `through`.
    Release {
        /// Which.
        target: ReleaseTarget,
        /// The newest stop id the sender saw.
        through: u64,
    },
}

impl Ask {
    /// The arbiter request it makes (`None` for a ping, which asks the arbiter nothing).
    pub fn request(&self) -> Option<Request> {
        match self {
            Self::Ping => None,
            Self::Stop { reason } => Some(Request::Stop {
                reason: reason.clone(),
            }),
            Self::Release { target, through } => Some(Request::Release {
                target: target.clone(),
                through: *through,
            }),
        }
    }
}

/// One request datagram.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StopRequest {
    /// The sender's request number, echoed in the reply.
    pub seq: u64,
    /// The sender's name (`None`: missing or not UTF-8; the gateway names it by its pid).
    pub name: Option<String>,
    /// What it asks.
    pub ask: Ask,
}

/// A datagram that is not a request, and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ParseError {
    /// Not this protocol at all.
    #[error("not a scout stop datagram ({0} bytes without the SCST magic)")]
    NotOurs(usize),
    /// Ours, but malformed: the reason, and the request number when it could be read.
    #[error("malformed stop datagram: {why}")]
    Malformed {
        /// The request number, when present.
        seq: Option<u64>,
        /// What is wrong.
        why: String,
    },
}

fn text(bytes: &[u8]) -> Option<String> {
    let end = bytes.iter().position(|b| *b == 0).unwrap_or(bytes.len());
    std::str::from_utf8(&bytes[..end]).ok().map(str::to_owned)
}

fn put_text(field: &mut [u8], value: &str) {
    let mut end = value.len().min(field.len());
    while !value.is_char_boundary(end) {
        end -= 1;
    }
    field[..end].copy_from_slice(&value.as_bytes()[..end]);
}

fn u64_at(bytes: &[u8], range: std::ops::Range<usize>) -> u64 {
    let mut raw = [0; 8];
    raw.copy_from_slice(&bytes[range]);
    u64::from_le_bytes(raw)
}

/// Reads a request datagram. A datagram with the magic whose kind byte says stop is a stop
/// whatever else is wrong with it (another version, a short or garbled body): a stop is never
/// refused; only its reason says what was wrong.
pub fn parse(bytes: &[u8]) -> Result<StopRequest, ParseError> {
    if bytes.len() < request::KIND + 1 || bytes[request::MAGIC] != *REQUEST_MAGIC {
        return Err(ParseError::NotOurs(bytes.len()));
    }
    let kind = Kind::from_raw(bytes[request::KIND]);
    let whole = bytes.len() == request::LEN && bytes[request::VERSION] == LAYOUT_VERSION as u8;
    if !whole {
        let why = if bytes.len() == request::LEN {
            format!(
                "interface version {}, this gateway speaks {LAYOUT_VERSION}",
                bytes[request::VERSION]
            )
        } else {
            format!("{} bytes, not {}", bytes.len(), request::LEN)
        };
        let seq = (bytes.len() >= request::SEQ.end).then(|| u64_at(bytes, request::SEQ));
        return match kind {
            Some(Kind::Stop) => Ok(StopRequest {
                seq: seq.unwrap_or(0),
                name: None,
                ask: Ask::Stop {
                    reason: format!("malformed stop datagram: {why}"),
                },
            }),
            Some(Kind::Ping | Kind::Release) | None => Err(ParseError::Malformed { seq, why }),
        };
    }
    let seq = u64_at(bytes, request::SEQ);
    let malformed = |why: String| ParseError::Malformed {
        seq: Some(seq),
        why,
    };
    let name = text(&bytes[request::NAME]).filter(|name| !name.is_empty());
    let ask = match kind {
        Some(Kind::Ping) => Ask::Ping,
        Some(Kind::Stop) => Ask::Stop {
            reason: match text(&bytes[request::REASON]).as_deref() {
                None => "a stop whose reason is not UTF-8".into(),
                Some("") => "no reason given".into(),
                Some(reason) => reason.to_owned(),
            },
        },
        Some(Kind::Release) => {
            let target = match ReleaseScope::from_raw(bytes[request::SCOPE]) {
                Some(ReleaseScope::Own) => ReleaseTarget::Own,
                Some(ReleaseScope::All) => ReleaseTarget::All,
                Some(ReleaseScope::Owner) => match text(&bytes[request::OWNER]) {
                    Some(owner) if !owner.is_empty() => ReleaseTarget::Owner(owner),
                    _ => return Err(malformed("release of an owner names no owner".into())),
                },
                None => {
                    return Err(malformed(format!(
                        "release scope {} is not 0..2",
                        bytes[request::SCOPE]
                    )));
                }
            };
            if name.is_none() {
                return Err(malformed(
                    "a release names its sender (1 to 32 bytes)".into(),
                ));
            }
            Ask::Release {
                target,
                through: u64_at(bytes, request::THROUGH),
            }
        }
        None => {
            return Err(malformed(format!(
                "unknown kind {} (0 ping, 2 stop, 3 release)",
                bytes[request::KIND]
            )));
        }
    };
    Ok(StopRequest { seq, name, ask })
}

impl StopRequest {
    /// The datagram.
    pub fn emit(&self) -> [u8; request::LEN] {
        let mut bytes = [0; request::LEN];
        bytes[request::MAGIC].copy_from_slice(REQUEST_MAGIC);
        bytes[request::VERSION] = LAYOUT_VERSION as u8;
        bytes[request::SEQ].copy_from_slice(&self.seq.to_le_bytes());
        put_text(
            &mut bytes[request::NAME],
            self.name.as_deref().unwrap_or(""),
        );
        let kind = match &self.ask {
            Ask::Ping => Kind::Ping,
            Ask::Stop { reason } => {
                put_text(&mut bytes[request::REASON], reason);
                Kind::Stop
            }
            Ask::Release { target, through } => {
                bytes[request::THROUGH].copy_from_slice(&through.to_le_bytes());
                bytes[request::SCOPE] = match target {
                    ReleaseTarget::Own => ReleaseScope::Own,
                    ReleaseTarget::Owner(owner) => {
                        put_text(&mut bytes[request::OWNER], owner);
                        ReleaseScope::Owner
                    }
                    ReleaseTarget::All => ReleaseScope::All,
                }
                .raw();
                Kind::Release
            }
        };
        bytes[request::KIND] = kind.raw();
        bytes
    }
}

/// One reply datagram.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StopReply {
    /// The request's number.
    pub seq: u64,
    /// The answer.
    pub answer: Result<Accepted, Rejected>,
    /// The gateway's pid.
    pub gateway_pid: u32,
}

impl StopReply {
    /// The reply to request `seq` with `answer`, from gateway `pid`.
    pub fn new(seq: u64, answer: &Result<Accepted, Rejection>, gateway_pid: u32) -> Self {
        Self {
            seq,
            answer: answer.clone().map_err(|rejection| Rejected {
                kind: Some(rejection.kind()),
                reason: rejection.to_string(),
            }),
            gateway_pid,
        }
    }

    /// The datagram; returns its bytes and their length.
    pub fn emit(&self) -> ([u8; reply::MAX_LEN], usize) {
        let mut bytes = [0; reply::MAX_LEN];
        bytes[reply::MAGIC].copy_from_slice(REPLY_MAGIC);
        bytes[reply::VERSION] = LAYOUT_VERSION as u8;
        bytes[reply::SEQ].copy_from_slice(&self.seq.to_le_bytes());
        bytes[reply::PID].copy_from_slice(&self.gateway_pid.to_le_bytes());
        let mut len = reply::REASON;
        match &self.answer {
            Ok(accepted) => {
                bytes[reply::ACCEPTED] = 1;
                bytes[reply::CODE] = 0xFF;
                bytes[reply::STOP].copy_from_slice(&accepted.stop.unwrap_or(0).to_le_bytes());
            }
            Err(rejected) => {
                bytes[reply::CODE] = rejected.kind.map_or(0xFE, RejectionKind::raw);
                let field = &mut bytes[reply::REASON..];
                put_text(field, &rejected.reason);
                len += field.iter().position(|b| *b == 0).unwrap_or(field.len());
            }
        }
        (bytes, len)
    }

    /// Reads a reply datagram.
    pub fn parse(bytes: &[u8]) -> Result<Self, ParseError> {
        if bytes.len() < reply::REASON || bytes[reply::MAGIC] != *REPLY_MAGIC {
            return Err(ParseError::NotOurs(bytes.len()));
        }
        let seq = u64_at(bytes, reply::SEQ);
        if bytes[reply::VERSION] != LAYOUT_VERSION as u8 {
            return Err(ParseError::Malformed {
                seq: Some(seq),
                why: format!(
                    "the gateway speaks interface version {}, this program {LAYOUT_VERSION}",
                    bytes[reply::VERSION]
                ),
            });
        }
        let mut pid = [0; 4];
        pid.copy_from_slice(&bytes[reply::PID]);
        let answer = match bytes[reply::ACCEPTED] {
            1 => Ok(Accepted {
                stop: Some(u64_at(bytes, reply::STOP)).filter(|id| *id != 0),
                ..Accepted::default()
            }),
            0 => Err(Rejected {
                kind: RejectionKind::from_raw(bytes[reply::CODE]),
                reason: String::from_utf8_lossy(&bytes[reply::REASON..]).into_owned(),
            }),
            other => {
                return Err(ParseError::Malformed {
                    seq: Some(seq),
                    why: format!("accepted byte {other} is not 0 or 1"),
                });
            }
        };
        Ok(Self {
            seq,
            answer,
            gateway_pid: u32::from_le_bytes(pid),
        })
    }
}

/// Why a stop datagram got no answer.
#[derive(Debug, thiserror::Error)]
pub enum StopSocketError {
    /// Nothing is bound at the robot's address.
    #[error(
        "no gateway named '{robot}' is running: start one with `scout-gateway --name {robot} --sim` (or --serial/--slcan/--can DEVICE)"
    )]
    NoGateway {
        /// The robot.
        robot: String,
    },
    /// No answer in time.
    #[error("no answer from gateway '{robot}' within {timeout:?}: is it running (not stopped)?")]
    NoAnswer {
        /// The robot.
        robot: String,
        /// How long it waited.
        timeout: Duration,
    },
    /// The gateway answered something this program cannot read.
    #[error("gateway '{robot}': {error}")]
    Reply {
        /// The robot.
        robot: String,
        /// What was wrong.
        error: ParseError,
    },
    /// The socket failed.
    #[error("the stop socket of gateway '{robot}': {errno}")]
    Io {
        /// The robot.
        robot: String,
        /// The error.
        errno: Errno,
    },
}

/// A client's end of a robot's stop endpoint: a datagram socket bound to an address of its
/// own (so the gateway can answer), made ahead of time so that a stop costs one `sendto`.
#[derive(Debug)]
pub struct StopClient {
    robot: String,
    name: String,
    socket: OwnedFd,
    gateway: UnixAddr,
    seq: u64,
}

impl StopClient {
    /// A client named `name` (1 to 32 bytes) of `robot`'s stop endpoint. Makes no contact:
    /// the first request finds out whether a gateway runs.
    pub fn new(robot: &str, name: &str) -> Result<Self, StopSocketError> {
        let io = |errno| StopSocketError::Io {
            robot: robot.to_owned(),
            errno,
        };
        if name.is_empty() || name.len() > MAX_CLIENT_NAME {
            return Err(io(Errno::EINVAL));
        }
        // Blocking, so that a send to a full endpoint waits in the kernel's queue of senders
        // (served in turn: a flood's senders wait in it too) for at most the request's timeout.
        let socket = socket(
            AddressFamily::Unix,
            SockType::Datagram,
            SockFlag::SOCK_CLOEXEC,
            None,
        )
        .map_err(io)?;
        // An address of its own in the abstract namespace, chosen by the kernel.
        bind(socket.as_raw_fd(), &UnixAddr::new_unnamed()).map_err(io)?;
        let gateway = UnixAddr::new_abstract(address(robot).as_bytes()).map_err(io)?;
        Ok(Self {
            robot: robot.to_owned(),
            name: name.to_owned(),
            socket,
            gateway,
            seq: 0,
        })
    }

    /// Latches a stop owned by this client's name; the answer carries its id.
    pub fn stop(&mut self, reason: &str, timeout: Duration) -> Result<StopReply, StopSocketError> {
        let reason = cut(reason, MAX_REASON);
        self.request(
            Ask::Stop {
                reason: reason.to_owned(),
            },
            timeout,
        )
    }

    /// Sends `ask` and waits at most `timeout` for the answer. A full queue at the gateway is
    /// waited on, in turn with every other sender, until the deadline.
    pub fn request(&mut self, ask: Ask, timeout: Duration) -> Result<StopReply, StopSocketError> {
        let robot = self.robot.clone();
        let io = |errno| StopSocketError::Io {
            robot: robot.clone(),
            errno,
        };
        self.seq += 1;
        let datagram = StopRequest {
            seq: self.seq,
            name: Some(self.name.clone()),
            ask,
        }
        .emit();
        let deadline = Instant::now() + timeout;
        let fd = self.socket.as_raw_fd();
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let wait =
                nix::sys::time::TimeVal::new(left.as_secs() as _, left.subsec_micros().max(1) as _);
            setsockopt(&self.socket, sockopt::SendTimeout, &wait).map_err(io)?;
            match sendto(fd, &datagram, &self.gateway, MsgFlags::empty()) {
                Ok(_) => break,
                Err(Errno::ECONNREFUSED | Errno::ENOENT) => {
                    return Err(StopSocketError::NoGateway { robot });
                }
                Err(Errno::EINTR) if Instant::now() < deadline => {}
                Err(Errno::EAGAIN | Errno::EINTR) => return Err(self.no_answer(timeout)),
                Err(errno) => return Err(io(errno)),
            }
        }
        let mut buffer = [0u8; reply::MAX_LEN];
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(self.no_answer(timeout));
            }
            let mut fds = [PollFd::new(
                std::os::fd::AsFd::as_fd(&self.socket),
                PollFlags::POLLIN,
            )];
            let wait = PollTimeout::try_from(left.as_millis().clamp(1, 60_000) as i32)
                .unwrap_or(PollTimeout::MAX);
            match poll(&mut fds, wait) {
                Ok(_) | Err(Errno::EINTR) => {}
                Err(errno) => return Err(io(errno)),
            }
            // Without waiting: the socket blocks for sends only.
            match recv(fd, &mut buffer, MsgFlags::MSG_DONTWAIT) {
                Ok(len) => match StopReply::parse(&buffer[..len]) {
                    Ok(reply) if reply.seq == self.seq => return Ok(reply),
                    // An answer to an earlier request that timed out.
                    Ok(_) | Err(ParseError::NotOurs(_)) => {}
                    Err(error) => {
                        return Err(StopSocketError::Reply { robot, error });
                    }
                },
                Err(Errno::EAGAIN | Errno::EINTR) => {}
                Err(errno) => return Err(io(errno)),
            }
        }
    }

    fn no_answer(&self, timeout: Duration) -> StopSocketError {
        StopSocketError::NoAnswer {
            robot: self.robot.clone(),
            timeout,
        }
    }
}

fn cut(text: &str, max: usize) -> &str {
    let mut end = text.len().min(max);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A stop from `guard`, number 7, reason `obstacle`, byte by byte.
    fn golden_stop() -> Vec<u8> {
        let mut bytes = vec![0u8; request::LEN];
        bytes[0..4].copy_from_slice(b"SCST");
        bytes[4] = LAYOUT_VERSION as u8;
        bytes[5] = 2;
        bytes[8] = 7;
        bytes[24..29].copy_from_slice(b"guard");
        bytes[88..96].copy_from_slice(b"obstacle");
        bytes
    }

    #[test]
    fn a_stop_datagram_matches_its_golden_bytes() {
        let request = StopRequest {
            seq: 7,
            name: Some("guard".into()),
            ask: Ask::Stop {
                reason: "obstacle".into(),
            },
        };
        assert_eq!(request.emit().to_vec(), golden_stop());
        assert_eq!(parse(&golden_stop()), Ok(request));
    }

    #[test]
    fn a_release_carries_the_newest_stop_seen() {
        let request = StopRequest {
            seq: 1,
            name: Some("operator".into()),
            ask: Ask::Release {
                target: ReleaseTarget::Owner("lidar".into()),
                through: 0x0102,
            },
        };
        let bytes = request.emit();
        assert_eq!(bytes[request::KIND], 3);
        assert_eq!(bytes[request::SCOPE], 1);
        assert_eq!(&bytes[16..18], &[0x02, 0x01]);
        assert_eq!(&bytes[56..61], b"lidar");
        assert_eq!(parse(&bytes), Ok(request));
    }

    #[test]
    fn a_stop_is_a_stop_however_malformed() {
        let mut short = golden_stop();
        short.truncate(20);
        let parsed = parse(&short).expect("a stop");
        assert!(matches!(parsed.ask, Ask::Stop { ref reason } if reason.contains("20 bytes")));
        let mut old = golden_stop();
        old[request::VERSION] = 1;
        let parsed = parse(&old).expect("a stop");
        assert!(matches!(parsed.ask, Ask::Stop { ref reason } if reason.contains("version 1")));
        let mut garbled = golden_stop();
        garbled[request::NAME.start] = 0xFF;
        garbled[request::REASON.start] = 0xFF;
        let parsed = parse(&garbled).expect("a stop");
        assert_eq!(parsed.name, None);
        assert!(matches!(parsed.ask, Ask::Stop { ref reason } if reason.contains("UTF-8")));
    }

    #[test]
    fn other_datagrams_are_refused_with_the_reason() {
        assert_eq!(parse(b"hello"), Err(ParseError::NotOurs(5)));
        let mut release = golden_stop();
        release[request::KIND] = 3;
        release[request::SCOPE] = 9;
        let error = parse(&release).expect_err("bad scope");
        assert!(error.to_string().contains("scope 9"), "{error}");
        release[request::SCOPE] = 0;
        release[request::NAME].fill(0);
        let error = parse(&release).expect_err("nameless release");
        assert!(error.to_string().contains("names its sender"), "{error}");
    }

    #[test]
    fn replies_round_trip() {
        let accepted = StopReply {
            seq: 3,
            answer: Ok(Accepted {
                stop: Some(12),
                ..Accepted::default()
            }),
            gateway_pid: 4242,
        };
        let (bytes, len) = accepted.emit();
        assert_eq!(len, reply::REASON);
        assert_eq!(StopReply::parse(&bytes[..len]), Ok(accepted));
        let rejected = StopReply::new(
            4,
            &Err(Rejection::NotAllowed {
                why: "only an operator".into(),
            }),
            1,
        );
        let (bytes, len) = rejected.emit();
        assert_eq!(StopReply::parse(&bytes[..len]), Ok(rejected));
    }

    fn ask() -> impl Strategy<Value = Ask> {
        let target = prop_oneof![
            Just(ReleaseTarget::Own),
            Just(ReleaseTarget::All),
            "[a-z:-]{1,32}".prop_map(ReleaseTarget::Owner),
        ];
        prop_oneof![
            Just(Ask::Ping),
            "[a-z ]{1,64}".prop_map(|reason| Ask::Stop { reason }),
            (target, any::<u64>()).prop_map(|(target, through)| Ask::Release { target, through }),
        ]
    }

    proptest! {
        #[test]
        fn requests_round_trip(seq in any::<u64>(), name in "[a-z0-9-]{1,32}", ask in ask()) {
            let request = StopRequest { seq, name: Some(name), ask };
            prop_assert_eq!(parse(&request.emit()), Ok(request));
        }

        /// Any bytes parse or are refused with a reason; a stop is never refused.
        #[test]
        fn any_bytes_parse_or_are_refused(bytes in proptest::collection::vec(any::<u8>(), 0..200), kind in any::<u8>()) {
            let mut bytes = bytes;
            if bytes.len() > request::KIND {
                bytes[..4].copy_from_slice(REQUEST_MAGIC);
                bytes[request::KIND] = kind;
            }
            match parse(&bytes) {
                Ok(_) => {}
                Err(error) => {
                    prop_assert!(!error.to_string().is_empty());
                    prop_assert!(kind != Kind::Stop.raw() || bytes.len() <= request::KIND);
                }
            }
            let _ = StopReply::parse(&bytes);
        }
    }
}
