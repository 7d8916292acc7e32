//! The zenoh contract: key expressions, the remote command JSON and what it asks for, the
//! permissions a gateway grants remote peers, and (with the `zenoh` feature) safe session
//! settings.

use serde::{Deserialize, Serialize};

use crate::control::{
    BadLight, Class, DriveMode, LightsSetting, ReleaseTarget, Request, UnknownName,
    parse_fault_clear, parse_light,
};
use crate::services::prefix;
use crate::services::{ControlPortError, RequestError};
use scout_protocol::{Light, LightCommand};
use std::time::Duration;

/// Default zenoh listen endpoint of a gateway: loopback only, and not 7447, the port of a ROS 2
/// router (rmw_zenohd) the gateway runs beside.
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7448";

/// The largest remote command payload accepted, bytes.
pub const MAX_COMMAND_BYTES: usize = 4096;

/// The prefix of a remote client's name in the status and the audit log.
pub const REMOTE_PREFIX: &str = "remote:";

/// The longest peer part of a remote client's name: the local name limit less
/// [`REMOTE_PREFIX`].
pub const MAX_REMOTE_CLIENT: usize = crate::control::MAX_CLIENT_NAME - REMOTE_PREFIX.len();

/// The local client name of remote peer `peer` (any name zenoh carries in a key chunk), as the
/// status, the audit log and the owner of its stops show it: `remote:` and the name, each byte
/// outside `A-Z a-z 0-9 . _ -` written `%XX`; when that is longer than [`MAX_REMOTE_CLIENT`]
/// bytes, its first 12 bytes, `~` and 12 hex digits of the FNV-1a 64-bit hash of the whole
/// name. Two names map to one only through a hash collision of 48 bits.
pub fn peer_client_name(peer: &str) -> String {
    let mut escaped = String::with_capacity(peer.len());
    for byte in peer.bytes() {
        if byte.is_ascii_alphanumeric() || matches!(byte, b'.' | b'_' | b'-') {
            escaped.push(char::from(byte));
        } else {
            escaped.push_str(&format!("%{byte:02X}"));
        }
    }
    if escaped.len() > MAX_REMOTE_CLIENT {
        let mut cut = 12;
        // Not inside a %XX.
        while escaped[..cut].rfind('%').is_some_and(|at| at + 3 > cut) {
            cut -= 1;
        }
        let hash = peer.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |hash, byte| {
            (hash ^ u64::from(byte)).wrapping_mul(0x0100_0000_01b3)
        });
        escaped = format!("{}~{:012x}", &escaped[..cut], hash >> 16);
    }
    format!("{REMOTE_PREFIX}{escaped}")
}

/// How fast a sender's clock may fall behind this host's, parts per million: the learned
/// offset rises at most this fast, so that over a long session a slow clock's commands do not
/// seem ever older (a quartz clock is off by up to 100 ppm: 360 ms an hour), while a link that
/// starts holding commands up is still seen (hiding 100 ms of it takes more than 8 minutes).
pub const MAX_CLOCK_DRIFT_PPM: u64 = 200;

/// The longest [`SenderClock`] lets its offset drift unseen: a sender silent longer is
/// forgotten by its owner (who makes a new clock for its next session).
const MAX_DRIFT_SPAN: Duration = Duration::from_secs(60);

/// How far below the fastest delivery seen a command's delay may be and still be learned: the
/// link got faster, or the sender's clock ran ahead. A stamp further ahead is from the future
/// (forged, or from another clock): refused and never learned, so that it cannot make the real
/// sender's commands seem late. A take-control that far ahead starts the clock anew.
pub const AHEAD_TOLERANCE: Duration = Duration::from_millis(100);

/// How far a drive's `seq` may jump past the last accepted one at once, besides one every
/// [`MIN_SEQ_PERIOD`] since that one arrived: a sender counts one a command, so a larger leap
/// is forged or stray, and would silence the real sender's next numbers.
pub const MAX_SEQ_LEAP: u64 = 64;

/// The shortest time between a sender's commands, as far as `seq` goes: the arbiter takes at
/// most 500 requests a second from one client (its default `request_rate_hz`).
pub const MIN_SEQ_PERIOD: Duration = Duration::from_millis(2);

/// A remote sender's clock as seen from this host, without a common clock: the least
/// (arrival - sent) seen is its offset plus the fastest delivery, and a command's age is how
/// much later than that it arrived. Sans-IO: times are passed in; nothing is learned until a
/// caller keeps what [`SenderClock::age`] returns.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SenderClock {
    /// The least (arrival - sent) seen, µs, allowed to rise by [`MAX_CLOCK_DRIFT_PPM`] since,
    /// and when it was last updated.
    offset: Option<(i128, Duration)>,
}

impl SenderClock {
    /// How much longer than the fastest delivery seen a command sent at `sent_ms` (the
    /// sender's clock, ms) and arriving at `now` (this host's clock) took, its age, and the
    /// clock once it is learned. The first command is age zero: it seeds the measure. A command
    /// that arrived faster than the fastest delivery by more than [`AHEAD_TOLERANCE`] is
    /// `Err(how far ahead)`.
    pub fn age(&self, now: Duration, sent_ms: u64) -> Result<(Duration, SenderClock), Duration> {
        let delay = now.as_micros() as i128 - i128::from(sent_ms) * 1000;
        let offset = match self.offset {
            Some((offset, at)) => {
                let since = now.saturating_sub(at).min(MAX_DRIFT_SPAN);
                let drift = since.as_micros() * u128::from(MAX_CLOCK_DRIFT_PPM) / 1_000_000;
                let offset = offset.saturating_add(i128::try_from(drift).unwrap_or(i128::MAX));
                let ahead = offset.saturating_sub(delay);
                if ahead > AHEAD_TOLERANCE.as_micros() as i128 {
                    return Err(Duration::from_micros(
                        u64::try_from(ahead).unwrap_or(u64::MAX),
                    ));
                }
                offset.min(delay)
            }
            None => delay,
        };
        let late = Duration::from_micros(u64::try_from(delay - offset).unwrap_or(u64::MAX));
        let learned = SenderClock {
            offset: Some((offset, now)),
        };
        Ok((late, learned))
    }
}

/// Why a remote sender's command is refused for its order or its timing.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TimingError {
    /// A drive whose `seq` is not above the last one's.
    #[error("out of order: seq {seq} after {last} (duplicated or reordered)")]
    OutOfOrder {
        /// Its seq.
        seq: u64,
        /// The last seq accepted.
        last: u64,
    },
    /// A drive whose `seq` leaps further ahead than the sender can have counted.
    #[error(
        "seq {seq} leaps too far past {last} (at most {allowed} by now): forged or from another \
         sender; take control again to count anew"
    )]
    Leap {
        /// Its seq.
        seq: u64,
        /// The last seq accepted.
        last: u64,
        /// The most it could be.
        allowed: u64,
    },
    /// A stamp ahead of the sender's clock as learned: from the future.
    #[error(
        "sent_ms is {ahead_ms} ms ahead of this sender's clock as learned: forged, or the \
         sender's clock jumped; take control again to learn it anew"
    )]
    Ahead {
        /// How far ahead, ms.
        ahead_ms: u128,
    },
    /// A command the network held up past its life.
    #[error(
        "held up {} ms on the way, past its life of {} ms",
        late.as_millis(),
        life.as_millis()
    )]
    Late {
        /// How much longer than the fastest delivery it took.
        late: Duration,
        /// Its life.
        life: Duration,
    },
}

impl TimingError {
    /// Its name in counters.
    pub fn kind(&self) -> &'static str {
        match self {
            TimingError::OutOfOrder { .. } => "out_of_order",
            TimingError::Leap { .. } => "leap",
            TimingError::Ahead { .. } => "ahead",
            TimingError::Late { .. } => "late",
        }
    }
}

/// A remote sender's commands as this host sees them: their order (`seq`) and their clock.
/// Sans-IO. Nothing is learned from a command until it is accepted ([`SenderTiming::accept`]):
/// a refused one, forged or stray, changes nothing. The zenoh bridge and `scout web` check
/// remote drives with it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SenderTiming {
    clock: SenderClock,
    /// The last drive accepted in this session: its `seq`, and when it arrived.
    last: Option<(u64, Duration)>,
}

/// A command that passed [`SenderTiming::check`]: when it was sent, and what accepting it
/// teaches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[must_use = "a checked command teaches nothing until it is accepted"]
pub struct Checked {
    /// When it was sent, on this host's clock (its arrival less its age).
    pub sent: Duration,
    next: SenderTiming,
}

impl SenderTiming {
    /// Checks a command sent at `sent_ms` (the sender's clock) that arrived at `now`: a drive
    /// with its `seq`, a take-control without. Refused: a `seq` not above the last accepted
    /// one, or leaping past it by more than [`MAX_SEQ_LEAP`] plus one a [`MIN_SEQ_PERIOD`]; a
    /// stamp from the future ([`AHEAD_TOLERANCE`]); a command older than `life`. A
    /// take-control from the future is no error: it starts the clock anew (the sender's
    /// clock jumped: a reboot, another machine). Nor is the first drive of a control session:
    /// a take-control held up on its way (a stalled link or host) taught a delay its drives do
    /// not have, and would refuse every one until control was taken again. Nothing is learned
    /// here.
    pub fn check(
        &self,
        now: Duration,
        seq: Option<u64>,
        sent_ms: u64,
        life: Duration,
    ) -> Result<Checked, TimingError> {
        let mut next = *self;
        if let Some(seq) = seq {
            if let Some((last, at)) = self.last {
                if seq <= last {
                    return Err(TimingError::OutOfOrder { seq, last });
                }
                let since = now.saturating_sub(at).as_nanos() / MIN_SEQ_PERIOD.as_nanos();
                let since = u64::try_from(since).unwrap_or(u64::MAX);
                let allowed = last.saturating_add(MAX_SEQ_LEAP).saturating_add(since);
                if seq > allowed {
                    return Err(TimingError::Leap { seq, last, allowed });
                }
            }
            next.last = Some((seq, now));
        }
        let (late, clock) = match self.clock.age(now, sent_ms) {
            Ok(aged) => aged,
            Err(_) if seq.is_none() || self.last.is_none() => SenderClock::default()
                .age(now, sent_ms)
                .unwrap_or((Duration::ZERO, SenderClock::default())),
            Err(ahead) => {
                return Err(TimingError::Ahead {
                    ahead_ms: ahead.as_millis(),
                });
            }
        };
        if late > life {
            return Err(TimingError::Late { late, life });
        }
        next.clock = clock;
        Ok(Checked {
            sent: now.saturating_sub(late),
            next,
        })
    }

    /// Learns what a command accepted teaches: its `seq` and its clock.
    pub fn accept(&mut self, checked: Checked) {
        *self = checked.next;
    }

    /// The `seq` of the last drive accepted in this session.
    pub fn last_seq(&self) -> Option<u64> {
        self.last.map(|(seq, _)| seq)
    }

    /// A new control session: its drives count anew (the clock stays: the same sender; a
    /// take-control's stamp was already checked against it).
    pub fn new_session(&mut self) {
        self.last = None;
    }
}

/// The key of the state JSON (publication and queryable).
pub fn state_key(robot: &str) -> String {
    format!("{}/state", prefix(robot))
}

/// The key of the arbiter status JSON.
pub fn status_key(robot: &str) -> String {
    format!("{}/status", prefix(robot))
}

/// The liveliness token of a running gateway.
pub fn alive_key(robot: &str) -> String {
    format!("{}/alive", prefix(robot))
}

/// The key of the gateway information queryable.
pub fn info_key(robot: &str) -> String {
    format!("{}/info", prefix(robot))
}

/// The key of the remote peers' link quality, published each second ([`LinkQuality`] list).
pub fn links_key(robot: &str) -> String {
    format!("{}/links", prefix(robot))
}

/// How one remote peer's drive commands fare on their way to the arbiter, as the gateway sees
/// them: published on [`links_key`] and in the information queryable's `links`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LinkQuality {
    /// The peer's client name (`remote:...`).
    pub peer: String,
    /// Drive commands received from it (put or queried) since the gateway keeps it (from its
    /// first granted command on).
    pub received: u64,
    /// Of them, accepted by the arbiter.
    pub accepted: u64,
    /// Refused as held up on the way past their life ("dropped as old").
    pub late: u64,
    /// Refused as repeated or older than one already let through (duplicated or reordered).
    pub reordered: u64,
    /// Refused because it held no control (never taken, or ended by a stop, a gap, a release
    /// or a takeover): it must take control again.
    pub no_control: u64,
    /// Sequence numbers skipped: lost on the way, or (on the fast lane) replaced by a newer
    /// one before the bridge read them (the `drives_superseded` counter counts those).
    pub lost: u64,
    /// How much longer than the peer's fastest delivery its drives took, ms: the median of the
    /// last [`LINK_AGES`] received.
    pub age_p50_ms: Option<u64>,
    /// The same, 99th percentile.
    pub age_p99_ms: Option<u64>,
    /// Since the last command of any kind from the peer, ms.
    pub last_seen_ms: u64,
}

/// The drive ages [`LinkQuality`]'s percentiles are taken over.
pub const LINK_AGES: usize = 256;

/// The key expression of every remote command: `scout/ROBOT/cmd/KIND/PEER`.
pub fn command_keys(robot: &str) -> String {
    format!("{}/cmd/**", prefix(robot))
}

/// The key of one remote command from `peer`. The peer's name is part of the key, not of the
/// payload, so that zenoh's access control binds it to the peer's certificate: a peer may query
/// only the keys of its own name.
pub fn command_key(robot: &str, kind: RemoteKind, peer: &str) -> String {
    format!("{}/cmd/{kind}/{peer}", prefix(robot))
}

/// Why a remote command was refused: its key, its payload, the gateway's permissions, its
/// timing, or the arbiter. The text is what the peer reads in the answer's `reason`.
#[derive(Debug, thiserror::Error)]
pub enum CommandError {
    /// The key is not `scout/ROBOT/cmd/KIND/PEER`.
    #[error("`{0}` is not scout/ROBOT/cmd/KIND/PEER: name yourself in the key")]
    Key(String),
    /// The key names no command this gateway knows.
    #[error("unknown command `{}`: one of {}", .0.found, .0.expected.join(", "))]
    Kind(UnknownName),
    /// The key's peer name is empty.
    #[error("the peer name in the key is empty: scout/ROBOT/cmd/KIND/PEER")]
    NoPeer,
    /// The query carries no payload.
    #[error("no payload: send the command as JSON")]
    NoPayload,
    /// The payload is longer than a command may be.
    #[error("payload of {size} bytes exceeds {max}")]
    TooLarge {
        /// Its size.
        size: usize,
        /// The most allowed.
        max: usize,
    },
    /// The payload is not a command's JSON.
    #[error("invalid JSON: {0}")]
    Json(String),
    /// A field the command needs is missing (the text says which and how to give it).
    #[error("{0}")]
    Missing(&'static str),
    /// `class` is not a class's name.
    #[error(transparent)]
    Class(UnknownName),
    /// `mode` is not a motion mode's name.
    #[error(transparent)]
    Mode(UnknownName),
    /// The command needs control the peer does not hold (the text says what to do).
    #[error("{0}")]
    NoControl(&'static str),
    /// A light that is not one.
    #[error(transparent)]
    Light(#[from] BadLight),
    /// `fault` is not a fault's name.
    #[error(transparent)]
    Fault(UnknownName),
    /// The gateway does not grant this permission.
    #[error(
        "remote `{permission}` is not allowed on this gateway (zenoh.remote_commands.allowed: {allowed})"
    )]
    NotAllowed {
        /// What the command needs.
        permission: Permission,
        /// What the gateway grants, in words.
        allowed: String,
    },
    /// Every remote peer the gateway keeps holds control: a new one waits until one lets go.
    #[error("{max} remote peers hold control already: try again once one lets go")]
    TooManyPeers {
        /// The most peers kept.
        max: usize,
    },
    /// Its order or its timing (a drive's `seq`, a stamp ahead or held up).
    #[error(transparent)]
    Timing(#[from] TimingError),
    /// The peer's control port could not be opened.
    #[error(transparent)]
    Port(#[from] ControlPortError),
    /// The arbiter refused it, or the gateway did not answer.
    #[error(transparent)]
    Request(#[from] RequestError),
}

/// A command key's kind and peer, or why it is not one.
pub fn parse_command_key(key: &str) -> Result<(RemoteKind, &str), CommandError> {
    // Exactly five chunks: a longer key (`scout/R/cmd/a/b/cmd/release/x`) names no peer.
    let chunks: Vec<&str> = key.split('/').collect();
    let [_, _, "cmd", kind, peer] = chunks[..] else {
        return Err(CommandError::Key(key.to_owned()));
    };
    let kind = kind.parse().map_err(CommandError::Kind)?;
    if peer.is_empty() {
        return Err(CommandError::NoPeer);
    }
    Ok((kind, peer))
}

wire_enum! {
    /// The remote commands: the last chunk of the command's key.
    RemoteKind {
        /// Drive under the control this peer took (permission: its class).
        Drive = 1 => "drive",
        /// Latch the safety stop.
        Estop = 2 => "estop",
        /// Release the stop.
        Release = 3 => "release",
        /// Arm autonomy.
        Resume = 4 => "resume",
        /// Set the lights.
        Lights = 5 => "lights",
        /// Clear a fault.
        ClearFault = 6 => "clear-fault",
        /// Take control as `class` (permission: the class).
        TakeControl = 7 => "take-control",
        /// Give up control.
        Relinquish = 8 => "relinquish",
    }
}

wire_enum! {
    /// What a gateway may allow remote peers (`zenoh.remote_commands.allowed`).
    Permission {
        /// Latch the stop.
        Estop = 1 => "estop",
        /// Drive as teleop.
        Teleop = 2 => "teleop",
        /// Drive as autonomy.
        Autonomy = 3 => "autonomy",
        /// Release the stop.
        Release = 4 => "release",
        /// Arm autonomy.
        Resume = 5 => "resume",
        /// Set the lights.
        Lights = 6 => "lights",
        /// Clear a fault.
        ClearFault = 7 => "clear_fault",
    }
}

/// A remote command's JSON payload (every field optional but those its command needs).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RemoteCommand {
    /// drive: the peer's own command number, rising by at least one per command (a repeated
    /// or older number is refused: duplicated or reordered). estop: with `sent_ms`, names the
    /// e-stop: its copies (the same numbers) latch it once.
    pub seq: Option<u64>,
    /// drive: the peer's clock when it sent the command, ms (any epoch; the bridge learns the
    /// offset, and a command held up by the network for longer than its life is refused).
    /// estop: with `seq`, names the e-stop (never checked for age: a stop is never refused).
    pub sent_ms: Option<u64>,
    /// take-control: `teleop` or `autonomy`.
    pub class: Option<String>,
    /// drive: m/s.
    pub linear: Option<f64>,
    /// drive: rad/s.
    pub angular: Option<f64>,
    /// drive: m/s leftward (absent: 0; only a chassis that moves sideways takes another).
    /// Left out when absent, as an older gateway refuses a field it does not know.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lateral: Option<f64>,
    /// drive: the command's life, ms.
    pub ttl_ms: Option<u32>,
    /// drive: the motion mode to drive in, on a chassis that has them (`dual_ackermann`,
    /// `parallel`, `spin`, `park`; absent: the gateway picks it). Left out when absent.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mode: Option<String>,
    /// estop: why.
    pub reason: Option<String>,
    /// release: the newest stop id the peer saw in the status (`newest_stop`): a stop latched
    /// after it survives. Without it, every stop of the peer's own.
    pub through: Option<u64>,
    /// lights: hand them back to the chassis.
    pub auto: Option<bool>,
    /// lights: front `{ "mode": "custom", "brightness": 40 }`.
    pub front: Option<RemoteLight>,
    /// lights: rear.
    pub rear: Option<RemoteLight>,
    /// clear-fault: a fault-clear name (`driver_overtemp`...) or `all`.
    pub fault: Option<String>,
}

/// One light in a remote lights command.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RemoteLight {
    /// off, on, breath, custom.
    pub mode: String,
    /// 0..100.
    #[serde(default)]
    pub brightness: u8,
}

impl RemoteCommand {
    /// The request a command of `kind` makes and the permission it needs, for a peer that
    /// holds control as `class` (if it does); the error says what is missing or wrong.
    pub fn request(
        &self,
        kind: RemoteKind,
        control: Option<(u64, Class)>,
    ) -> Result<(Permission, Request), CommandError> {
        let permission = |class: Class| match class {
            Class::Teleop => Permission::Teleop,
            Class::Autonomy => Permission::Autonomy,
        };
        Ok(match kind {
            RemoteKind::TakeControl => {
                let class: Class = self
                    .class
                    .as_deref()
                    .ok_or(CommandError::Missing(
                        "take-control needs `class`: teleop or autonomy",
                    ))?
                    .parse()
                    .map_err(CommandError::Class)?;
                (permission(class), Request::TakeControl { class })
            }
            RemoteKind::Drive => {
                let (lease, class) = control.ok_or(CommandError::NoControl(
                    "no control: send take-control first (cmd/take-control/PEER)",
                ))?;
                let (Some(linear), Some(angular)) = (self.linear, self.angular) else {
                    return Err(CommandError::Missing(
                        "drive needs `linear` and `angular` numbers",
                    ));
                };
                let ttl = self.ttl_ms.map(|ms| Duration::from_millis(u64::from(ms)));
                let mode = self
                    .mode
                    .as_deref()
                    .map(str::parse::<DriveMode>)
                    .transpose()
                    .map_err(CommandError::Mode)?;
                (
                    permission(class),
                    Request::Drive {
                        lease,
                        linear,
                        lateral: self.lateral.unwrap_or(0.0),
                        angular,
                        ttl,
                        mode,
                    },
                )
            }
            RemoteKind::Relinquish => {
                let (_, class) = control.ok_or(CommandError::NoControl("no control to give up"))?;
                (permission(class), Request::Relinquish)
            }
            RemoteKind::Estop => {
                let reason = self.reason.clone().unwrap_or_else(|| "remote estop".into());
                (Permission::Estop, Request::Stop { reason })
            }
            RemoteKind::Release => (
                Permission::Release,
                Request::Release {
                    target: ReleaseTarget::Own,
                    through: self.through.unwrap_or(u64::MAX),
                },
            ),
            RemoteKind::Resume => (Permission::Resume, Request::Resume),
            RemoteKind::Lights => (Permission::Lights, Request::Lights(self.lights()?)),
            RemoteKind::ClearFault => {
                let fault = (self.fault.as_deref())
                    .ok_or(CommandError::Missing("clear-fault needs `fault`"))?;
                let fault = parse_fault_clear(fault).map_err(CommandError::Fault)?;
                (Permission::ClearFault, Request::ClearFault(fault))
            }
        })
    }

    fn lights(&self) -> Result<LightsSetting, BadLight> {
        if self.auto == Some(true) {
            return Ok(LightsSetting::Auto);
        }
        let light = |light: &Option<RemoteLight>| match light {
            None => Ok(Light::default()),
            Some(light) => parse_light(&light.mode, light.brightness),
        };
        Ok(LightsSetting::Manual(LightCommand {
            enabled: true,
            front: light(&self.front)?,
            rear: light(&self.rear)?,
        }))
    }
}

/// The answer to a remote command.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RemoteAnswer {
    /// Accepted or rejected.
    pub accepted: bool,
    /// Accepted with a speed clamped to the caps.
    #[serde(default)]
    pub clamped: bool,
    /// Why it was rejected.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    /// Rejected because the peer holds no control (never took it, or a stop, a gap, a
    /// release or a takeover ended it): only a take-control, sent on purpose, gives it back.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub lost_control: bool,
    /// For an e-stop: the id of the stop it latched (or refreshed), as the status lists it;
    /// a release naming it (`through`) releases it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stop: Option<u64>,
}

impl RemoteAnswer {
    /// The acceptance the arbiter gave.
    pub fn accepted(accepted: &crate::control::Accepted) -> Self {
        Self {
            accepted: true,
            clamped: accepted.clamped,
            reason: None,
            lost_control: false,
            stop: accepted.stop,
        }
    }

    /// A rejection with `reason`.
    pub fn rejected(reason: impl Into<String>) -> Self {
        Self {
            accepted: false,
            clamped: false,
            reason: Some(reason.into()),
            lost_control: false,
            stop: None,
        }
    }

    /// The rejection of a command for `error`.
    pub fn refused(error: &CommandError) -> Self {
        Self {
            lost_control: error.lost_control(),
            ..Self::rejected(error.to_string())
        }
    }
}

impl CommandError {
    /// Whether the peer holds no control (see [`RemoteAnswer::lost_control`]).
    pub fn lost_control(&self) -> bool {
        match self {
            Self::NoControl(_) => true,
            Self::Request(RequestError::Rejected(rejected)) => rejected.lost_control(),
            _ => false,
        }
    }
}

/// The `[zenoh]` table of the gateway configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZenohConfig {
    /// Publish to remote peers at all.
    pub enabled: bool,
    /// A zenoh configuration file (JSON5) for LAN, router, TLS and access control set-ups;
    /// `$ZENOH_CONFIG` when unset. Without one: peer mode, multicast scouting off.
    pub config_file: Option<String>,
    /// Listen endpoints; default `tcp/127.0.0.1:7448` when there is no configuration file.
    pub listen: Vec<String>,
    /// Endpoints to connect to (a zenoh router, for a fleet).
    pub connect: Vec<String>,
    /// State publications per second.
    pub state_rate_hz: f64,
    /// Remote commands.
    pub remote_commands: RemoteCommands,
    /// Interfaces that admit only authenticated machines, beside WireGuard ones (recognised by
    /// themselves): remote peers may drive over links through them.
    pub authenticated_interfaces: Vec<String>,
    /// Declares every network the links reach trusted: remote peers may then drive over links
    /// that authenticate nobody (plain `udp/` or `tcp/` beyond loopback), with a warning.
    pub trusted_network: bool,
}

/// Remote commands: off by default; when on, only the listed kinds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RemoteCommands {
    /// Accept commands from remote peers.
    pub enabled: bool,
    /// What remote peers may do: `estop`, `teleop`, `autonomy` (drive as that class),
    /// `release`, `resume`, `lights`, `clear_fault`.
    pub allowed: Vec<Permission>,
}

impl RemoteCommands {
    /// The remote commands allowed, by name, comma-separated.
    pub fn allowed_names(&self) -> String {
        let names: Vec<&str> = self.allowed.iter().map(|p| p.name()).collect();
        names.join(", ")
    }
}

impl Default for RemoteCommands {
    fn default() -> Self {
        Self {
            enabled: false,
            allowed: vec![Permission::Estop],
        }
    }
}

impl Default for ZenohConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            config_file: None,
            listen: Vec::new(),
            connect: Vec::new(),
            state_rate_hz: 50.0,
            remote_commands: RemoteCommands::default(),
            authenticated_interfaces: Vec::new(),
            trusted_network: false,
        }
    }
}

/// A `[zenoh]` value out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("zenoh.state_rate_hz must be 0.1..1000, found {0}")]
pub struct BadStateRate(pub f64);

impl ZenohConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), BadStateRate> {
        if self.state_rate_hz.is_finite() && (0.1..=1000.0).contains(&self.state_rate_hz) {
            Ok(())
        } else {
            Err(BadStateRate(self.state_rate_hz))
        }
    }

    /// The session settings, with the gateway's default listen endpoint.
    pub fn session(&self) -> SessionSettings {
        let no_file = self.config_file.is_none() && std::env::var_os("ZENOH_CONFIG").is_none();
        let listen = if self.listen.is_empty() && no_file {
            vec![DEFAULT_LISTEN.to_owned()]
        } else {
            self.listen.clone()
        };
        SessionSettings {
            config_file: self.config_file.clone(),
            listen,
            connect: self.connect.clone(),
        }
    }
}

/// Where a zenoh session comes from.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SessionSettings {
    /// A zenoh configuration file (JSON5) for LAN, router and TLS set-ups; `$ZENOH_CONFIG` when
    /// empty. Without one: peer mode, multicast scouting off.
    pub config_file: Option<String>,
    /// Endpoints to listen on (the default: `tcp/127.0.0.1:7448` for a gateway, none for a reader).
    pub listen: Vec<String>,
    /// Endpoints to connect to (a router, another gateway).
    pub connect: Vec<String>,
}

/// Why a zenoh session could not be configured or opened.
#[cfg(feature = "zenoh")]
#[derive(Debug, thiserror::Error)]
pub enum RemoteError {
    /// The configuration (file or value) is invalid.
    #[error("zenoh configuration: {0}")]
    Config(String),
    /// The session did not open.
    #[error("zenoh session: {0}")]
    Open(String),
    /// Subscribing or declaring failed.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// The gateway refused a command.
    #[error("{command} refused: {}", .answer.reason.as_deref().unwrap_or("no reason given"))]
    Refused {
        /// What was refused.
        command: RemoteKind,
        /// The gateway's answer.
        answer: RemoteAnswer,
    },
    /// No gateway answered a command.
    #[error(
        "no answer to {command} within {timeout:?}: is the gateway running with remote commands on, and reachable?"
    )]
    NoAnswer {
        /// What was sent.
        command: RemoteKind,
        /// How long the answer was awaited.
        timeout: Duration,
    },
}

#[cfg(feature = "zenoh")]
impl SessionSettings {
    /// The zenoh configuration in `mode` (`peer` or `client`): the file if any, else safe
    /// defaults; the endpoints given here override the file's.
    pub fn config(&self, mode: &str) -> Result<zenoh::Config, RemoteError> {
        let file = self
            .config_file
            .clone()
            .or_else(|| std::env::var("ZENOH_CONFIG").ok());
        let mut config = match file.filter(|f| !f.is_empty()) {
            Some(file) => zenoh::Config::from_file(std::path::Path::new(&file))
                .map_err(|e| RemoteError::Config(format!("{file}: {e}")))?,
            None => {
                let mut config = zenoh::Config::default();
                insert(&mut config, "mode", &format!("\"{mode}\""))?;
                insert(&mut config, "scouting/multicast/enabled", "false")?;
                insert(&mut config, "scouting/gossip/enabled", "false")?;
                config
            }
        };
        if !self.listen.is_empty() {
            insert(&mut config, "listen/endpoints", &json_list(&self.listen))?;
        }
        if !self.connect.is_empty() {
            insert(&mut config, "connect/endpoints", &json_list(&self.connect))?;
        }
        Ok(config)
    }

    /// The links a session with these settings opens in `mode` (its listen and connect
    /// endpoints, zenoh's default listener included), and what protects each, on this host;
    /// `tunnels` names interfaces to count as authenticated beside WireGuard ones.
    pub fn links(
        &self,
        mode: &str,
        tunnels: &[String],
    ) -> Result<Vec<crate::link::Link>, RemoteError> {
        use crate::link::{Direction, Endpoint, Host, Link, Protection};
        let config = self.config(mode)?;
        // A configuration file's own mode decides which of zenoh's defaults apply.
        let mode = config_value::<String>(&config, "mode").unwrap_or_else(|| mode.to_owned());
        let mode = mode.as_str();
        let mut endpoints = Vec::new();
        for (key, direction) in [
            ("listen/endpoints", Direction::Listen),
            ("connect/endpoints", Direction::Connect),
        ] {
            for text in configured_endpoints(&config, key, mode) {
                let mut endpoint = Endpoint::parse(&text)
                    .map_err(|error| RemoteError::Config(error.to_string()))?;
                resolve(&mut endpoint);
                endpoints.push((endpoint, direction));
            }
        }
        let mtls = config_value(&config, "transport/link/tls/enable_mtls").unwrap_or(false);
        let destinations: Vec<std::net::IpAddr> = (endpoints.iter())
            .filter(|(_, direction)| *direction == Direction::Connect)
            .filter_map(|(endpoint, _)| endpoint.ip())
            .collect();
        let host = Host::this(tunnels, &destinations);
        Ok(endpoints
            .into_iter()
            .map(|(endpoint, direction)| Link {
                protection: Protection::of(&endpoint, direction, &host, mtls),
                endpoint: endpoint.text,
                direction,
            })
            .collect())
    }

    /// Opens a session (never from inside a current-thread tokio runtime: `wait` blocks).
    pub fn open(&self, mode: &str) -> Result<zenoh::Session, RemoteError> {
        use zenoh::Wait;
        let config = self.config(mode)?;
        zenoh::open(config)
            .wait()
            .map_err(|e| RemoteError::Open(e.to_string()))
    }
}

#[cfg(feature = "zenoh")]
fn insert(config: &mut zenoh::Config, key: &str, value: &str) -> Result<(), RemoteError> {
    config
        .insert_json5(key, value)
        .map_err(|e| RemoteError::Config(format!("{key} = {value}: {e}")))
}

/// The value at `key` of a zenoh configuration, if set and of type `T`.
#[cfg(feature = "zenoh")]
fn config_value<T: serde::de::DeserializeOwned>(config: &zenoh::Config, key: &str) -> Option<T> {
    let json = config.get_json(key).ok()?;
    serde_json::from_str::<Option<T>>(&json).ok().flatten()
}

/// The endpoints under `key` (`listen/endpoints`, `connect/endpoints`) for `mode`: a list, or
/// a list per mode (zenoh's defaults are: a peer listens on `tcp/[::]:0`, every interface).
#[cfg(feature = "zenoh")]
fn configured_endpoints(config: &zenoh::Config, key: &str, mode: &str) -> Vec<String> {
    let value = config_value::<serde_json::Value>(config, key).unwrap_or_default();
    let list = match &value {
        serde_json::Value::Object(per_mode) => per_mode.get(mode).cloned().unwrap_or_default(),
        other => other.clone(),
    };
    (list.as_array().into_iter().flatten())
        .filter_map(|endpoint| endpoint.as_str().map(str::to_owned))
        .collect()
}

/// A host name in `endpoint` replaced by the first address it resolves to (a name that does
/// not resolve stays, and counts as reachable from anywhere).
#[cfg(feature = "zenoh")]
fn resolve(endpoint: &mut crate::link::Endpoint) {
    use std::net::ToSocketAddrs;
    if endpoint.ip().is_some() || endpoint.protocol.starts_with("unix") {
        return;
    }
    if let Some(address) = (endpoint.host.as_str(), 0)
        .to_socket_addrs()
        .ok()
        .and_then(|mut addresses| addresses.next())
    {
        endpoint.host = address.ip().to_string();
    }
}

#[cfg(feature = "zenoh")]
fn json_list(items: &[String]) -> String {
    serde_json::Value::from(items.to_vec()).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn command(json: &str) -> RemoteCommand {
        serde_json::from_str(json).expect("valid command JSON")
    }

    #[test]
    fn commands_map_to_requests_and_permissions() {
        let take = command(r#"{"class":"teleop"}"#).request(RemoteKind::TakeControl, None);
        assert_eq!(
            take.ok(),
            Some((
                Permission::Teleop,
                Request::TakeControl {
                    class: Class::Teleop
                }
            ))
        );
        let drive = command(r#"{"linear":0.5,"angular":0}"#);
        assert_eq!(
            drive
                .request(RemoteKind::Drive, Some((9, Class::Autonomy)))
                .ok(),
            Some((
                Permission::Autonomy,
                Request::Drive {
                    lease: 9,
                    linear: 0.5,
                    lateral: 0.0,
                    angular: 0.0,
                    ttl: None,
                    mode: None,
                }
            ))
        );
        let spin = command(r#"{"linear":0,"angular":0.5,"mode":"spin"}"#)
            .request(RemoteKind::Drive, Some((9, Class::Teleop)));
        assert!(
            matches!(
                spin,
                Ok((
                    Permission::Teleop,
                    Request::Drive {
                        mode: Some(DriveMode::Spin),
                        ..
                    }
                ))
            ),
            "{spin:?}"
        );
        let bogus = command(r#"{"linear":0,"angular":0,"mode":"crab"}"#)
            .request(RemoteKind::Drive, Some((9, Class::Teleop)))
            .expect_err("an unknown mode");
        assert!(bogus.to_string().contains("crab"), "{bogus}");
        let stop = command("{}").request(RemoteKind::Estop, None);
        assert_eq!(
            stop.ok(),
            Some((
                Permission::Estop,
                Request::Stop {
                    reason: "remote estop".into()
                }
            ))
        );
        let release = command("{}").request(RemoteKind::Release, None);
        assert_eq!(
            release.ok(),
            Some((
                Permission::Release,
                Request::Release {
                    target: ReleaseTarget::Own,
                    through: u64::MAX,
                }
            )),
            "a remote peer releases only its own stops"
        );
        let clear = command(r#"{"fault":"all"}"#).request(RemoteKind::ClearFault, None);
        assert_eq!(
            clear.ok(),
            Some((Permission::ClearFault, Request::ClearFault(None)))
        );
    }

    #[test]
    fn bad_commands_say_what_is_wrong() {
        let uncontrolled = command(r#"{"linear":1,"angular":0}"#);
        assert!(
            uncontrolled
                .request(RemoteKind::Drive, None)
                .unwrap_err()
                .to_string()
                .contains("take-control")
        );
        let classless = command("{}");
        assert!(
            classless
                .request(RemoteKind::TakeControl, None)
                .unwrap_err()
                .to_string()
                .contains("class")
        );
        let dim = command(r#"{"front":{"mode":"on","brightness":101}}"#);
        assert!(
            dim.request(RemoteKind::Lights, None)
                .unwrap_err()
                .to_string()
                .contains("not 0..100")
        );
        assert!(
            serde_json::from_str::<RemoteCommand>(r#"{"client":"someone"}"#).is_err(),
            "identity is not a payload field"
        );
        assert_eq!("clear-fault".parse(), Ok(RemoteKind::ClearFault));
        assert_eq!("clear_fault".parse(), Ok(Permission::ClearFault));
    }

    proptest::proptest! {
        /// Whatever a network peer sends, parsing answers (a request or a reason), never panics.
        #[test]
        fn any_key_and_payload_is_answered(key in ".{0,80}", payload in ".{0,200}", lease in proptest::option::of(0u64..3)) {
            let _ = parse_command_key(&key);
            if let Ok(command) = serde_json::from_str::<RemoteCommand>(&payload) {
                for kind in RemoteKind::ALL {
                    let _ = command.request(*kind, lease.map(|l| (l, Class::Teleop)));
                }
            }
        }
    }

    proptest::proptest! {
        /// Whatever a sender (or a forger beside it) sends: what is accepted rises by a
        /// plausible step, is neither from the future nor older than its life, and what is
        /// refused teaches nothing.
        #[test]
        fn accepted_commands_rise_plausibly_and_refused_ones_teach_nothing(
            commands in proptest::collection::vec(
                (0u64..200, proptest::option::of(0u64..400), 0u64..10_000), 1..80)
        ) {
            let life = Duration::from_millis(250);
            let mut timing = SenderTiming::default();
            let mut now = Duration::from_secs(100);
            let mut last: Option<(u64, Duration)> = None;
            let mut fastest: Option<i128> = None;
            for (step, seq, sent_ms) in commands {
                now += Duration::from_millis(step);
                let before = timing;
                match timing.check(now, seq, sent_ms, life) {
                    Ok(checked) => {
                        proptest::prop_assert!(checked.sent <= now && now - checked.sent <= life);
                        let delay = now.as_millis() as i128 - i128::from(sent_ms);
                        if let (Some(seq), Some((last_seq, at))) = (seq, last) {
                            proptest::prop_assert!(seq > last_seq);
                            let since = ((now - at).as_millis() / MIN_SEQ_PERIOD.as_millis()) as u64;
                            proptest::prop_assert!(seq <= last_seq + MAX_SEQ_LEAP + since);
                        }
                        // Within a control session: its first drive, like a take-control,
                        // may start the clock anew.
                        if let (Some(_), Some(fastest), Some(_)) = (seq, fastest, last) {
                            proptest::prop_assert!(delay + AHEAD_TOLERANCE.as_millis() as i128 + 1 >= fastest, "learned a stamp from the future");
                        }
                        timing.accept(checked);
                        if let Some(seq) = seq {
                            last = Some((seq, now));
                        } else {
                            last = None;
                        }
                        fastest = Some(fastest.map_or(delay, |f: i128| f.min(delay)));
                    }
                    Err(_) => proptest::prop_assert_eq!(timing, before, "a refusal taught something"),
                }
            }
        }
    }

    #[test]
    fn peer_names_map_to_client_names() {
        assert_eq!(peer_client_name("laptop"), "remote:laptop");
        let exact = "a".repeat(MAX_REMOTE_CLIENT);
        assert_eq!(peer_client_name(&exact), format!("remote:{exact}"));
        assert_eq!(peer_client_name("opérateur"), "remote:op%C3%A9rateur");
        let long = peer_client_name(&"b".repeat(26));
        assert_eq!(long, format!("remote:{}~{}", "b".repeat(12), &long[20..]));
        assert_eq!(long.len(), crate::control::MAX_CLIENT_NAME);
        assert_ne!(
            long,
            peer_client_name(&"b".repeat(27)),
            "the hash tells them apart"
        );
        // A cut never splits an escape.
        let accented = peer_client_name(&"é".repeat(20));
        assert!(accented.starts_with("remote:%C3%A9%C3%A9~"), "{accented}");
    }

    proptest::proptest! {
        /// Any peer name maps to a valid client name: 32 bytes at most, ASCII, prefixed.
        #[test]
        fn any_peer_name_maps_to_a_client_name(peer in ".{1,200}") {
            let name = peer_client_name(&peer);
            proptest::prop_assert!(name.len() <= crate::control::MAX_CLIENT_NAME);
            proptest::prop_assert!(name.is_ascii());
            proptest::prop_assert!(name.starts_with(REMOTE_PREFIX));
        }
    }

    #[test]
    fn the_peer_comes_from_the_key() {
        assert_eq!(
            parse_command_key("scout/alpha/cmd/estop/laptop").ok(),
            Some((RemoteKind::Estop, "laptop"))
        );
        assert!(parse_command_key("scout/alpha/cmd/estop").is_err());
        assert!(parse_command_key("scout/alpha/cmd/a/b/cmd/release/nested").is_err());
        assert!(parse_command_key("scout/alpha/cmd/fly/laptop").is_err());
        assert_eq!(
            command_key("alpha", RemoteKind::Drive, "op"),
            "scout/alpha/cmd/drive/op"
        );
    }

    #[cfg(feature = "zenoh")]
    #[test]
    fn a_sessions_links_come_from_its_settings_or_its_file_and_zenohs_defaults() {
        use crate::link::{Direction, Protection};
        let dir = std::env::temp_dir().join(format!("scout-links-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let file = dir.join("peer.json5");
        // A file that names no listener: zenoh's peer default, every interface.
        std::fs::write(
            &file,
            r#"{ mode: "peer", connect: { endpoints: ["tcp/127.0.0.1:7449"] } }"#,
        )
        .expect("write");
        let settings = SessionSettings {
            config_file: Some(file.display().to_string()),
            ..SessionSettings::default()
        };
        let links = settings.links("peer", &[]).expect("links");
        let summary: Vec<(&str, Direction, bool)> = (links.iter())
            .map(|l| {
                (
                    l.endpoint.as_str(),
                    l.direction,
                    l.protection.authenticates_peers(),
                )
            })
            .collect();
        assert_eq!(
            summary,
            [
                ("tcp/[::]:0", Direction::Listen, false),
                ("tcp/127.0.0.1:7449", Direction::Connect, true),
            ]
        );
        assert_eq!(
            links[0].protection,
            Protection::Plain {
                reach: "every interface".into()
            }
        );
        // Endpoints given override the file's.
        let settings = SessionSettings {
            listen: vec!["udp/localhost:7448".into()],
            ..settings
        };
        let links = settings.links("peer", &[]).expect("links");
        assert_eq!(links[0].endpoint, "udp/localhost:7448");
        assert_eq!(links[0].protection, Protection::Local);
        let _ = std::fs::remove_dir_all(dir);
    }
}
