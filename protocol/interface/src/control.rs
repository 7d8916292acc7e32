//! Control: what a client asks of the gateway's arbiter and what it answers, typed
//! ([`Request`], [`Accepted`], [`Rejection`]) and on the wire ([`ControlRequest`],
//! [`ControlResponse`]); and the arbiter's status ([`StatusPayload`]). [`Request::encode`] and
//! [`Request::decode`] are the one place a request kind meets its bytes: both match every kind.

use std::time::Duration;

use iceoryx2::prelude::ZeroCopySend;
use scout_protocol::v2::MotionModeV2;
use scout_protocol::{FaultClear, Light, LightCommand, LightMode};

use crate::state::LightPayload;
use crate::text::FixedText;

/// The most clients the arbiter tracks at once, and so the most its status lists.
pub const MAX_CLIENTS: usize = 32;

/// The longest client name, bytes.
pub const MAX_CLIENT_NAME: usize = 32;

/// The longest stop reason, bytes (longer is cut).
pub const MAX_REASON: usize = 64;

/// A name that is not one of an enum's names.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown {what} `{found}`: one of {}", expected.join(", "))]
pub struct UnknownName {
    /// The enum.
    pub what: &'static str,
    /// What was given.
    pub found: String,
    /// The names it knows.
    pub expected: Vec<&'static str>,
}

wire_enum! {
    /// What a [`ControlRequest`] asks for (its `kind` byte).
    RequestKind {
        /// Drive at `linear`, `lateral`, `angular` under `lease` for `ttl_ms` (0: the class's
        /// maximum age).
        Drive = 1 => "drive",
        /// Latch a safety stop (`reason`), owned by this client's name.
        Stop = 2 => "stop",
        /// Release stops (`release_target`, `owner`).
        Release = 3 => "release",
        /// Arm autonomy.
        Resume = 4 => "resume",
        /// Set the lights (`lights`).
        Lights = 5 => "lights",
        /// Clear a fault (`fault_clear`: a code 1..8, or [`CLEAR_ALL_FAULTS`]).
        ClearFault = 6 => "clear_fault",
        /// Register (`heartbeat_ms` > 0) or drop (0) a heartbeat stop source; also a beat.
        Heartbeat = 7 => "heartbeat",
        /// Reset the gateway's odometry.
        ResetOdometry = 8 => "reset_odometry",
        /// Give up this client's control (never touches a stop).
        Relinquish = 9 => "relinquish",
        /// Take control as `class`: the answer carries the lease that drive commands name.
        TakeControl = 10 => "take_control",
        /// Save the gateway's black box of the bus to disk now.
        SaveBlackBox = 11 => "save_black_box",
    }
}

wire_enum! {
    /// Which stops a release names.
    ReleaseScope {
        /// The stops this client's name owns.
        Own = 0 => "own",
        /// The stops of the owner named in `owner` (an operator's, unless it is this client's).
        Owner = 1 => "owner",
        /// Every stop (operators only).
        All = 2 => "all",
    }
}

/// What a release names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ReleaseTarget {
    /// The stops this client's name owns.
    Own,
    /// The stops of this owner.
    Owner(String),
    /// Every stop.
    All,
}

wire_enum! {
    /// Why a stop holds the robot: a client asked, or the gateway found a gap (a time it lost
    /// control or knowledge of the chassis).
    StopCause {
        /// A client's stop.
        Client = 0 => "client",
        /// A heartbeat source went silent or died (a deadman).
        Heartbeat = 1 => "heartbeat",
        /// The gateway started after an unclean exit of the previous one.
        GatewayStart = 2 => "gateway_start",
        /// The port closed or failed.
        LinkLost = 3 => "link_lost",
        /// No feedback for longer than the chassis' command timeout, or none usable (a protocol
        /// mismatch: the chassis speaks another protocol, or both arrive).
        ChassisSilent = 4 => "chassis_silent",
        /// The chassis reports its e-stop.
        ChassisEstop = 5 => "chassis_estop",
        /// The chassis reports a fault or a latched protection.
        ChassisFault = 6 => "chassis_fault",
        /// The RC transmitter took over.
        RcOverride = 7 => "rc_override",
        /// A tick was late by more than the chassis' command timeout.
        Overrun = 8 => "overrun",
        /// The chassis moves faster than commanded, or the wrong way.
        Runaway = 9 => "runaway",
        /// The CAN bus or adapter failed (write errors, bus-off, error-passive).
        LinkFault = 10 => "link_fault",
        /// A protocol v2 chassis is not, or no longer, in CAN command mode: it did not take
        /// 0x421, or fell back to standby (the RC's own takeover is `rc_override`); or it
        /// changed how it is driven unasked (a Ranger's motion mode, a Hunter's parking brake
        /// locked during a drive).
        ChassisMode = 11 => "chassis_mode",
    }
}

wire_enum! {
    /// The motion mode a client asks a chassis that has them (a Ranger) to drive in; without
    /// one the gateway picks it from the velocity. On the wire: 0 none.
    DriveMode {
        /// Both axles steer: forward with or without a turn, no tighter than its circle.
        DualAckermann = 1 => "dual_ackermann",
        /// Every wheel at one angle: forward, sideways or diagonally, without a turn.
        Parallel = 2 => "parallel",
        /// Turning in place.
        Spin = 3 => "spin",
        /// The wheels set to hold it still: nothing moves.
        Park = 4 => "park",
    }
}

impl DriveMode {
    /// The chassis' mode (0x141, 0x291).
    pub const fn motion_mode(self) -> MotionModeV2 {
        match self {
            Self::DualAckermann => MotionModeV2::DualAckermann,
            Self::Parallel => MotionModeV2::Parallel,
            Self::Spin => MotionModeV2::Spin,
            Self::Park => MotionModeV2::Park,
        }
    }
}

wire_enum! {
    /// A controlling client's class: teleop overrides autonomy.
    Class {
        /// A person driving: overrides autonomy.
        Teleop = 1 => "teleop",
        /// A program driving.
        Autonomy = 2 => "autonomy",
    }
}

/// `fault_clear` value asking for every fault-clear code in turn.
pub const CLEAR_ALL_FAULTS: u8 = 0xFF;

/// The lights a client asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LightsSetting {
    /// Hand the lights back to the chassis' own logic.
    Auto,
    /// Host-controlled front and rear (brightness 0..100 matters in custom mode).
    Manual(LightCommand),
}

/// What a client asks of the gateway.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// Take control as `class`; the answer's lease is what drive commands name.
    TakeControl {
        /// The class to drive as.
        class: Class,
    },
    /// Drive at this body velocity (ROS conventions: m/s forward, m/s leftward, rad/s
    /// counter-clockwise) for at most `ttl` (`None`: the class's maximum age), under a lease
    /// from [`Request::TakeControl`]. Only a chassis that moves sideways takes a `lateral`
    /// other than zero.
    Drive {
        /// The lease.
        lease: u64,
        /// m/s, forward.
        linear: f64,
        /// m/s, leftward.
        lateral: f64,
        /// rad/s.
        angular: f64,
        /// The command's life.
        ttl: Option<Duration>,
        /// The motion mode to drive in (a Ranger; `None`: the gateway picks it).
        mode: Option<DriveMode>,
    },
    /// Latch a safety stop, owned by this client's name.
    Stop {
        /// Why, for the status and the audit log.
        reason: String,
    },
    /// Release the stops `target` names that latched no later than stop `through`: the
    /// newest stop its sender saw (the status' `newest_stop`). A stop latched after the sender
    /// looked survives. A release ends whatever control this client holds.
    Release {
        /// Which stops.
        target: ReleaseTarget,
        /// The newest stop id the sender saw.
        through: u64,
    },
    /// Give up this client's control; stops are left alone.
    Relinquish,
    /// Arm autonomy.
    Resume,
    /// Set the lights (last writer wins).
    Lights(LightsSetting),
    /// Send this fault-clear code (`None`: every code in turn), each in 3 motion commands.
    ClearFault(Option<FaultClear>),
    /// Register (period > 0) or drop (zero) a heartbeat: a missed beat latches the stop. Every
    /// request from the client is a beat.
    Heartbeat {
        /// The longest gap between two requests.
        period: Duration,
    },
    /// Reset the gateway's odometry to the origin.
    ResetOdometry,
    /// Save the black box of the bus (the last minutes of frames) to disk.
    SaveBlackBox,
}

impl Request {
    /// Its kind.
    pub fn kind(&self) -> RequestKind {
        match self {
            Self::TakeControl { .. } => RequestKind::TakeControl,
            Self::Drive { .. } => RequestKind::Drive,
            Self::Stop { .. } => RequestKind::Stop,
            Self::Release { .. } => RequestKind::Release,
            Self::Relinquish => RequestKind::Relinquish,
            Self::Resume => RequestKind::Resume,
            Self::Lights(_) => RequestKind::Lights,
            Self::ClearFault(_) => RequestKind::ClearFault,
            Self::Heartbeat { .. } => RequestKind::Heartbeat,
            Self::ResetOdometry => RequestKind::ResetOdometry,
            Self::SaveBlackBox => RequestKind::SaveBlackBox,
        }
    }

    /// The request on the wire, numbered `seq` (`sent_ns` is the sender's to fill).
    pub fn encode(&self, seq: u64) -> ControlRequest {
        let mut wire = ControlRequest {
            kind: self.kind().raw(),
            seq,
            ..ControlRequest::default()
        };
        match self {
            Self::TakeControl { class } => wire.class = class.raw(),
            Self::Drive {
                lease,
                linear,
                lateral,
                angular,
                ttl,
                mode,
            } => {
                wire.mode = mode.map_or(0, DriveMode::raw);
                wire.lease = *lease;
                wire.linear = *linear;
                wire.lateral = *lateral;
                wire.angular = *angular;
                wire.ttl_ms = ttl.map_or(0, |ttl| {
                    ttl.as_millis().clamp(1, u128::from(u32::MAX)) as u32
                });
            }
            Self::Stop { reason } => wire.reason = FixedText::new(reason),
            Self::Release { target, through } => {
                wire.through = *through;
                let scope = match target {
                    ReleaseTarget::Own => ReleaseScope::Own,
                    ReleaseTarget::Owner(owner) => {
                        wire.owner = FixedText::new(owner);
                        ReleaseScope::Owner
                    }
                    ReleaseTarget::All => ReleaseScope::All,
                };
                wire.release_scope = scope.raw();
            }
            Self::Lights(LightsSetting::Auto) => wire.lights.auto = 1,
            Self::Lights(LightsSetting::Manual(command)) => {
                wire.lights.front = LightPayload::new(command.front);
                wire.lights.rear = LightPayload::new(command.rear);
            }
            Self::ClearFault(code) => {
                wire.fault_clear = code.map_or(CLEAR_ALL_FAULTS, FaultClear::raw);
            }
            Self::Heartbeat { period } => {
                wire.heartbeat_ms = period.as_millis().min(u128::from(u32::MAX)) as u32;
            }
            Self::Relinquish | Self::Resume | Self::ResetOdometry | Self::SaveBlackBox => {}
        }
        wire
    }

    /// Checks a request from the wire; the rejection says what is wrong.
    pub fn decode(wire: &ControlRequest) -> Result<Self, Rejection> {
        let kind = RequestKind::from_raw(wire.kind).ok_or(Rejection::UnknownRequest(wire.kind))?;
        Ok(match kind {
            RequestKind::TakeControl => Self::TakeControl {
                class: Class::from_raw(wire.class).ok_or(Rejection::UnknownClass(wire.class))?,
            },
            RequestKind::Drive => Self::Drive {
                lease: wire.lease,
                linear: wire.linear,
                lateral: wire.lateral,
                angular: wire.angular,
                ttl: (wire.ttl_ms > 0).then(|| Duration::from_millis(u64::from(wire.ttl_ms))),
                mode: match wire.mode {
                    0 => None,
                    raw => Some(DriveMode::from_raw(raw).ok_or_else(|| {
                        Rejection::Malformed(format!(
                            "unknown motion mode {raw} (dual_ackermann, parallel, spin or park)"
                        ))
                    })?),
                },
            },
            RequestKind::Stop => Self::Stop {
                reason: match wire.reason.as_str() {
                    "" => "no reason given".to_owned(),
                    reason => reason.to_owned(),
                },
            },
            RequestKind::Release => Self::Release {
                through: wire.through,
                target: match ReleaseScope::from_raw(wire.release_scope) {
                    Some(ReleaseScope::Own) => ReleaseTarget::Own,
                    Some(ReleaseScope::Owner) => {
                        ReleaseTarget::Owner(wire.owner.as_str().to_owned())
                    }
                    Some(ReleaseScope::All) => ReleaseTarget::All,
                    None => {
                        return Err(Rejection::Malformed(format!(
                            "release scope {} is not 0..2",
                            wire.release_scope
                        )));
                    }
                },
            },
            RequestKind::Relinquish => Self::Relinquish,
            RequestKind::Resume => Self::Resume,
            RequestKind::Lights => Self::Lights(decode_lights(&wire.lights)?),
            RequestKind::ClearFault => Self::ClearFault(match wire.fault_clear {
                CLEAR_ALL_FAULTS => None,
                raw => match FaultClear::from_raw(raw) {
                    FaultClear::None | FaultClear::Unknown(_) => {
                        return Err(Rejection::Malformed(format!(
                            "fault-clear code {raw} is not 1..8"
                        )));
                    }
                    code => Some(code),
                },
            }),
            RequestKind::Heartbeat => Self::Heartbeat {
                period: Duration::from_millis(u64::from(wire.heartbeat_ms)),
            },
            RequestKind::ResetOdometry => Self::ResetOdometry,
            RequestKind::SaveBlackBox => Self::SaveBlackBox,
        })
    }
}

/// A light as a client may ask for it: a known mode and brightness 0..100.
pub fn check_light(which: &str, mode: LightMode, brightness: u8) -> Result<(), Rejection> {
    if let LightMode::Unknown(raw) = mode {
        return Err(Rejection::Malformed(format!(
            "{which} light mode {raw} is not 0..3"
        )));
    }
    if brightness > 100 {
        return Err(Rejection::Malformed(format!(
            "{which} brightness {brightness} is above 100"
        )));
    }
    Ok(())
}

/// A light a client wrote that is not one.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BadLight {
    /// Not a mode's name.
    #[error("light mode `{0}`: off, on, breath or custom")]
    Mode(String),
    /// Not 0..100.
    #[error("brightness `{0}` is not 0..100")]
    Brightness(String),
}

/// A light from its mode's name (`off`, `on`, `breath`, `custom`) and brightness 0..100.
pub fn parse_light(mode: &str, brightness: u8) -> Result<Light, BadLight> {
    let mode = LightMode::from_name(mode).ok_or_else(|| BadLight::Mode(mode.to_owned()))?;
    if brightness > 100 {
        return Err(BadLight::Brightness(brightness.to_string()));
    }
    Ok(Light { mode, brightness })
}

/// A light as `scout lights`, the Python package and remote peers write it: `MODE[:BRIGHTNESS]`
/// (`off`, `on`, `breath`, `custom`; brightness 0..100, 100 when left out).
pub fn parse_light_text(text: &str) -> Result<Light, BadLight> {
    let (mode, brightness) = text.split_once(':').unwrap_or((text, "100"));
    let brightness = brightness
        .parse::<u8>()
        .map_err(|_| BadLight::Brightness(brightness.to_owned()))?;
    parse_light(mode, brightness)
}

/// A fault-clear request from a name: a fault-clear code's name (`driver_overtemp`, `-` or `_`)
/// or `all` (`None`).
pub fn parse_fault_clear(name: &str) -> Result<Option<FaultClear>, UnknownName> {
    let name = name.replace('-', "_");
    if name == "all" {
        return Ok(None);
    }
    FaultClear::from_name(&name)
        .filter(|code| *code != FaultClear::None)
        .map(Some)
        .ok_or_else(|| UnknownName {
            what: "fault",
            found: name,
            expected: (FaultClear::ALL.iter().map(|c| c.name()))
                .filter(|n| *n != FaultClear::None.name())
                .chain(["all"])
                .collect(),
        })
}

fn decode_lights(wire: &LightsRequest) -> Result<LightsSetting, Rejection> {
    match wire.auto {
        0 => {}
        1 => return Ok(LightsSetting::Auto),
        other => {
            return Err(Rejection::Malformed(format!(
                "lights `auto` byte {other} is not 0 or 1"
            )));
        }
    }
    let front = wire.front.light();
    let rear = wire.rear.light();
    check_light("front", front.mode, front.brightness)?;
    check_light("rear", rear.mode, rear.brightness)?;
    Ok(LightsSetting::Manual(LightCommand {
        enabled: true,
        front,
        rear,
    }))
}

wire_enum! {
    /// The kinds of rejection, each a counter in the status.
    RejectionKind {
        /// A speed was NaN or infinite.
        NotFinite = 0 => "not_finite",
        /// The class byte names no class.
        UnknownClass = 1 => "unknown_class",
        /// The request kind byte names no request.
        UnknownRequest = 2 => "unknown_request",
        /// The request is malformed.
        Malformed = 3 => "malformed",
        /// The safety stop is latched.
        Latched = 4 => "latched",
        /// Another client holds the class.
        Held = 5 => "held",
        /// Autonomy must be resumed first.
        AutonomyDisarmed = 6 => "autonomy_disarmed",
        /// The arbiter tracks too many clients.
        TooManyClients = 7 => "too_many_clients",
        /// The client holds no control: take control first.
        NoControl = 8 => "no_control",
        /// The client's control was revoked (a gap, a stop, a release, a takeover, staleness).
        Revoked = 9 => "revoked",
        /// The command is older than its life on arrival.
        Stale = 10 => "stale",
        /// The client sends faster than the gateway's request rate limit.
        RateLimited = 11 => "rate_limited",
        /// The client may not do that (a release of another owner's stops without the operator role).
        NotAllowed = 12 => "not_allowed",
        /// The cause of a stop persists: it cannot be released yet.
        CausePersists = 13 => "cause_persists",
        /// The command is stamped later than its arrival: another clock than this host's.
        Future = 14 => "future",
        /// A take-control sent before control ended (a release, a lapse, a revocation) arrived
        /// after it: what was decided before is not applied after.
        Outdated = 15 => "outdated",
    }
}

/// The client name of a person's one-shot commands (`scout estop`, `scout release`): the
/// gateway lets only a process with the operator role go by it.
pub const OPERATOR: &str = "operator";

/// Rejection counters in a status: one per [`RejectionKind`].
pub const REJECTION_COUNTERS: usize = 16;
const _: () = assert!(RejectionKind::ALL.len() == REJECTION_COUNTERS);

/// Why a request was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum Rejection {
    /// A speed was NaN or infinite.
    NotFinite,
    /// The class byte names no class.
    UnknownClass(u8),
    /// The request kind byte names no request.
    UnknownRequest(u8),
    /// The request is malformed, with what is wrong.
    Malformed(String),
    /// Stops hold the robot.
    Latched {
        /// The stops, as owner (cause): reason.
        stops: String,
    },
    /// Another client holds the class.
    Held {
        /// The class.
        class: Class,
        /// Its holder.
        holder: String,
    },
    /// Autonomy must be resumed first.
    AutonomyDisarmed,
    /// The arbiter tracks too many clients.
    TooManyClients,
    /// The client holds no control.
    NoControl,
    /// The client's control was revoked.
    Revoked {
        /// Why.
        cause: String,
    },
    /// The command arrived older than its life.
    Stale {
        /// Its age on arrival.
        age: Duration,
        /// Its life.
        life: Duration,
    },
    /// Too many requests from this client.
    RateLimited {
        /// The sustained rate allowed, requests per second.
        rate: f64,
    },
    /// The client may not do that.
    NotAllowed {
        /// Why, and what holds the robot.
        why: String,
    },
    /// A stop's cause persists.
    CausePersists {
        /// The stops that cannot be released yet, with their causes.
        stops: String,
    },
    /// The command was stamped later than it arrived, beyond the tolerance.
    Future {
        /// By how much.
        ahead: Duration,
    },
    /// A take-control was sent before an end of control it arrived after.
    Outdated {
        /// What ended control (`the stops were released`, `its control lapsed`).
        ended: String,
        /// How long before that end it was sent.
        by: Duration,
    },
}

impl Rejection {
    /// Its kind: the counter it counts in.
    pub fn kind(&self) -> RejectionKind {
        match self {
            Self::NotFinite => RejectionKind::NotFinite,
            Self::UnknownClass(_) => RejectionKind::UnknownClass,
            Self::UnknownRequest(_) => RejectionKind::UnknownRequest,
            Self::Malformed(_) => RejectionKind::Malformed,
            Self::Latched { .. } => RejectionKind::Latched,
            Self::Held { .. } => RejectionKind::Held,
            Self::AutonomyDisarmed => RejectionKind::AutonomyDisarmed,
            Self::TooManyClients => RejectionKind::TooManyClients,
            Self::NoControl => RejectionKind::NoControl,
            Self::Revoked { .. } => RejectionKind::Revoked,
            Self::Stale { .. } => RejectionKind::Stale,
            Self::RateLimited { .. } => RejectionKind::RateLimited,
            Self::NotAllowed { .. } => RejectionKind::NotAllowed,
            Self::CausePersists { .. } => RejectionKind::CausePersists,
            Self::Future { .. } => RejectionKind::Future,
            Self::Outdated { .. } => RejectionKind::Outdated,
        }
    }
}

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::NotFinite => f.write_str("speed is NaN or infinite"),
            Self::UnknownClass(raw) => write!(f, "unknown class {raw} (teleop or autonomy)"),
            Self::UnknownRequest(raw) => write!(f, "unknown request kind {raw}"),
            Self::Malformed(what) => write!(f, "malformed request: {what}"),
            Self::Latched { stops } => write!(f, "stopped by {stops}: release first"),
            Self::Held { class, holder } => write!(f, "{class} held by {holder}"),
            Self::AutonomyDisarmed => f.write_str(
                "autonomy disarmed (after a teleop takeover, stop or release): resume first",
            ),
            Self::TooManyClients => write!(f, "too many clients (at most {MAX_CLIENTS})"),
            Self::NoControl => f.write_str("no control: take control first"),
            Self::Revoked { cause } => {
                write!(f, "control revoked ({cause}): take control again to drive")
            }
            Self::Stale { age, life } => write!(
                f,
                "command {} ms old on arrival, past its life of {} ms",
                age.as_millis(),
                life.as_millis()
            ),
            Self::RateLimited { rate } => {
                write!(f, "too many requests (at most {rate} a second per client)")
            }
            Self::NotAllowed { why } => f.write_str(why),
            Self::CausePersists { stops } => write!(f, "cannot release yet: {stops}"),
            Self::Future { ahead } => write!(
                f,
                "command stamped {} ms after its arrival: stamp it with this host's CLOCK_BOOTTIME",
                ahead.as_millis()
            ),
            Self::Outdated { ended, by } => write!(
                f,
                "take-control sent {} ms before {ended}: a decision from before is not applied \
                 after it; take control again",
                by.as_millis()
            ),
        }
    }
}

/// The answer to an accepted request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Accepted {
    /// A speed was beyond the caps and was clamped.
    pub clamped: bool,
    /// For a take-control: the lease that drive commands name.
    pub lease: Option<u64>,
    /// For a stop: the id of the stop it latched (or refreshed).
    pub stop: Option<u64>,
}

/// Every request gets one.
pub type Answer = Result<Accepted, Rejection>;

/// A rejection as the client sees it: its kind and the gateway's wording.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{reason}")]
pub struct Rejected {
    /// The kind (`None`: a kind this client version does not know).
    pub kind: Option<RejectionKind>,
    /// Why, as the gateway words it.
    pub reason: String,
}

impl Rejected {
    /// Whether the client lost (or never had) control: it must take control again, a
    /// deliberate act no library does by itself.
    pub fn lost_control(&self) -> bool {
        matches!(
            self.kind,
            Some(RejectionKind::Revoked | RejectionKind::NoControl)
        )
    }
}

impl ControlResponse {
    /// The answer to request `seq` on the wire.
    pub fn new(seq: u64, answer: &Answer) -> Self {
        match answer {
            Ok(accepted) => Self {
                seq,
                accepted: true,
                clamped: accepted.clamped,
                code: 0xFF,
                lease: accepted.lease.unwrap_or(0),
                stop: accepted.stop.unwrap_or(0),
                reason: FixedText::empty(),
            },
            Err(rejection) => Self {
                seq,
                accepted: false,
                clamped: false,
                code: rejection.kind().raw(),
                lease: 0,
                stop: 0,
                reason: FixedText::new(&rejection.to_string()),
            },
        }
    }

    /// The answer it carries.
    pub fn answer(&self) -> Result<Accepted, Rejected> {
        if self.accepted {
            Ok(Accepted {
                clamped: self.clamped,
                lease: (self.lease != 0).then_some(self.lease),
                stop: (self.stop != 0).then_some(self.stop),
            })
        } else {
            Err(Rejected {
                kind: RejectionKind::from_raw(self.code),
                reason: self.reason.as_str().to_owned(),
            })
        }
    }
}

/// The lights of a request: `auto` hands them back to the chassis; otherwise the raw modes
/// (0 off, 1 on, 2 breath, 3 custom) and brightness 0..100.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
pub struct LightsRequest {
    /// Hand the lights back to the chassis: 1; 0 sets `front` and `rear`. A byte, not a `bool`:
    /// the gateway reads it from the client's shared memory, where any byte may stand.
    pub auto: u8,
    /// Front light.
    pub front: LightPayload,
    /// Rear light.
    pub rear: LightPayload,
}

/// A request from a client to the gateway's arbiter.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("scout::ControlRequest.v14")]
#[repr(C)]
pub struct ControlRequest {
    /// [`RequestKind`] as `u8`.
    pub kind: u8,
    /// [`Class`] byte (0: none), for drive.
    pub class: u8,
    /// Fault-clear code, for clear-fault.
    pub fault_clear: u8,
    /// Lights, for lights.
    pub lights: LightsRequest,
    /// [`ReleaseScope`] byte, for release.
    pub release_scope: u8,
    /// [`DriveMode`] byte (0: none, the gateway picks), for drive.
    pub mode: u8,
    /// The owner whose stops a release names.
    pub owner: FixedText<MAX_CLIENT_NAME>,
    /// The remote peer a stop or release is sent for: read only from the gateway's own zenoh
    /// bridge (identified by the transport), ignored from anyone else.
    pub peer: FixedText<MAX_CLIENT_NAME>,
    /// For release: the newest stop id its sender saw (the status' `newest_stop`); stops
    /// latched after it are not released.
    pub through: u64,
    /// The client's own request number.
    pub seq: u64,
    /// The lease a drive command belongs to.
    pub lease: u64,
    /// CLOCK_BOOTTIME time the client sent it, ns (a command older than its life on arrival is
    /// refused).
    pub sent_ns: u64,
    /// m/s, forward, for drive.
    pub linear: f64,
    /// m/s, leftward, for drive.
    pub lateral: f64,
    /// rad/s, for drive.
    pub angular: f64,
    /// The command's life, ms (0: the class's maximum age), for drive.
    pub ttl_ms: u32,
    /// The heartbeat period, ms, for heartbeat.
    pub heartbeat_ms: u32,
    /// Why, for stop.
    pub reason: FixedText<MAX_REASON>,
}

/// The gateway's answer to one request.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[type_name("scout::ControlResponse.v14")]
#[repr(C)]
pub struct ControlResponse {
    /// The request's `seq`.
    pub seq: u64,
    /// Accepted (true) or rejected.
    pub accepted: bool,
    /// Accepted, but a speed beyond the caps was clamped.
    pub clamped: bool,
    /// The [`RejectionKind`] byte; 0xFF when accepted.
    pub code: u8,
    /// For an accepted take-control: the lease (0: none).
    pub lease: u64,
    /// For an accepted stop: the id of the stop it latched or refreshed (0: none).
    pub stop: u64,
    /// Why it was rejected.
    pub reason: FixedText<160>,
}

wire_enum! {
    /// Who controls the lights, as the status reports it.
    LightsControl {
        /// No client has asked: the chassis' own logic.
        Chassis = 0 => "chassis",
        /// A client handed them back to the chassis.
        Auto = 1 => "auto",
        /// A client set them.
        Manual = 2 => "manual",
    }
}

impl LightsControl {
    /// The control of a client's setting (`None`: nobody asked).
    pub fn of(setting: Option<LightsSetting>) -> Self {
        match setting {
            None => Self::Chassis,
            Some(LightsSetting::Auto) => Self::Auto,
            Some(LightsSetting::Manual(_)) => Self::Manual,
        }
    }
}

/// Stops listed in a status (more are counted in `stop_total`).
pub const MAX_STATUS_STOPS: usize = 16;
/// Recent events kept in a status.
pub const STATUS_EVENTS: usize = 16;

/// One stop in the arbiter's status.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct StopPayload {
    /// Its id: stops are numbered from 1 in the order they latched.
    pub id: u64,
    /// Who set it: a client's name, or `gateway` for a gap.
    pub owner: FixedText<MAX_CLIENT_NAME>,
    /// [`StopCause`] byte.
    pub cause: u8,
    /// Whether its cause persists (it cannot be released yet).
    pub persists: bool,
    /// Why.
    pub reason: FixedText<MAX_REASON>,
    /// How long ago, ms.
    pub age_ms: f64,
    /// The user that latched it, as the kernel vouched ([`UNKNOWN_UID`]: unknown, or the
    /// gateway): besides an operator, only that user, under the owner's name, releases it.
    pub uid: u32,
    /// An operator latched it: only an operator releases it.
    pub by_operator: bool,
}

/// A user id the kernel did not give (the overflow uid's value).
pub const UNKNOWN_UID: u32 = u32::MAX;

/// One entry of the status' recent history.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct EventPayload {
    /// How long ago, ms.
    pub age_ms: f64,
    /// What happened, with who and why.
    pub text: FixedText<120>,
}

/// One client in the arbiter's status.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
pub struct SourcePayload {
    /// The client's name.
    pub client: FixedText<MAX_CLIENT_NAME>,
    /// [`Class`] byte of its lease (0: none).
    pub class: u8,
    /// Whether it holds a lease now.
    pub holding: bool,
    /// Its heartbeat period, ms (0: none).
    pub heartbeat_ms: u32,
    /// Its lease (0: none).
    pub lease: u64,
    /// Requests it sent.
    pub requests: u64,
    /// How long ago it last sent a request, ms.
    pub age_ms: f64,
    /// Its user, as the kernel vouched ([`UNKNOWN_UID`]: unknown).
    pub uid: u32,
}

/// The arbiter's status, published on every change and at least once a second.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("scout::StatusPayload.v14")]
#[repr(C)]
pub struct StatusPayload {
    /// Rises by one with every publication.
    pub seq: u64,
    /// CLOCK_BOOTTIME time of publication, ns.
    pub published_ns: u64,
    /// The robot's name.
    pub robot: FixedText<32>,
    /// How many stops hold the robot (motion only at zero).
    pub stop_total: u32,
    /// The id of the newest stop latched since the gateway started (0: none yet): a release
    /// names it as the newest it saw.
    pub newest_stop: u64,
    /// The first [`MAX_STATUS_STOPS`] of them, oldest first.
    pub stops: [StopPayload; MAX_STATUS_STOPS],
    /// [`Class`] byte of the selected source (0: none).
    pub selected_class: u8,
    /// The selected client.
    pub selected_client: FixedText<MAX_CLIENT_NAME>,
    /// The output, m/s.
    pub output_linear: f64,
    /// The output, m/s leftward.
    pub output_lateral: f64,
    /// The output, rad/s.
    pub output_angular: f64,
    /// The fault-clear code going out.
    pub output_fault_clear: u8,
    /// A cap or rate limit is active.
    pub limited: bool,
    /// Autonomy may drive.
    pub autonomy_armed: bool,
    /// [`crate::state::BatteryLevel`] byte.
    pub battery_level: u8,
    /// [`crate::state::LevelFrom`] byte: what set the level.
    pub battery_level_from: u8,
    /// The battery's charge, % (NaN: unknown).
    pub battery_percent: f64,
    /// [`LightsControl`] byte.
    pub lights: u8,
    /// How many entries of `sources` are used.
    pub source_count: u8,
    /// The known clients.
    pub sources: [SourcePayload; MAX_CLIENTS],
    /// Rejections, indexed by [`RejectionKind::raw`].
    pub rejections: [u64; REJECTION_COUNTERS],
    /// The latest motion command's lateness behind its tick when it was sent, ms.
    pub tick_lateness_ms: f64,
    /// The worst lateness since the gateway started, ms.
    pub tick_max_lateness_ms: f64,
    /// Ticks missed (skipped to stay on the grid) since the gateway started.
    pub ticks_missed: u64,
    /// How many entries of `events` are used.
    pub event_count: u8,
    /// The latest events, oldest first.
    pub events: [EventPayload; STATUS_EVENTS],
}

impl StatusPayload {
    /// Whether two statuses differ in more than the passing of time and request counts.
    pub fn differs_from(&self, other: &StatusPayload) -> bool {
        let timeless = |s: &StatusPayload| {
            let mut s = *s;
            s.seq = 0;
            s.published_ns = 0;
            s.tick_lateness_ms = 0.0;
            s.tick_max_lateness_ms = 0.0;
            s.ticks_missed = 0;
            // Unknown is unknown, not a change (NaN equals nothing).
            if s.battery_percent.is_nan() {
                s.battery_percent = -1.0;
            }
            for stop in &mut s.stops {
                stop.age_ms = 0.0;
            }
            for event in &mut s.events {
                event.age_ms = 0.0;
            }
            for source in &mut s.sources {
                source.age_ms = 0.0;
                source.requests = 0;
            }
            s
        };
        timeless(self) != timeless(other)
    }

    /// The listed clients.
    pub fn sources(&self) -> &[SourcePayload] {
        &self.sources[..usize::from(self.source_count).min(MAX_CLIENTS)]
    }

    /// The listed stops.
    pub fn stops(&self) -> &[StopPayload] {
        &self.stops[..(self.stop_total as usize).min(MAX_STATUS_STOPS)]
    }

    /// The recent events, oldest first.
    pub fn events(&self) -> &[EventPayload] {
        &self.events[..usize::from(self.event_count).min(STATUS_EVENTS)]
    }

    /// Whether any stop holds the robot.
    pub fn stopped(&self) -> bool {
        self.stop_total > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn wire(kind: u8) -> ControlRequest {
        ControlRequest {
            kind,
            ..ControlRequest::default()
        }
    }

    #[test]
    fn malformed_requests_are_rejected_with_the_reason() {
        assert_eq!(
            Request::decode(&wire(99)),
            Err(Rejection::UnknownRequest(99))
        );
        let drive = ControlRequest {
            class: 7,
            ..wire(RequestKind::TakeControl.raw())
        };
        assert_eq!(Request::decode(&drive), Err(Rejection::UnknownClass(7)));
        let clear = ControlRequest {
            fault_clear: 9,
            ..wire(RequestKind::ClearFault.raw())
        };
        assert!(matches!(
            Request::decode(&clear),
            Err(Rejection::Malformed(_))
        ));
        let mut lights = wire(RequestKind::Lights.raw());
        lights.lights.front = LightPayload {
            mode: 1,
            brightness: 101,
        };
        let Err(Rejection::Malformed(why)) = Request::decode(&lights) else {
            panic!("bad brightness accepted")
        };
        assert_eq!(why, "front brightness 101 is above 100");
        let mode = ControlRequest {
            mode: 9,
            ..wire(RequestKind::Drive.raw())
        };
        let Err(Rejection::Malformed(why)) = Request::decode(&mode) else {
            panic!("an unknown mode accepted")
        };
        assert_eq!(
            why,
            "unknown motion mode 9 (dual_ackermann, parallel, spin or park)"
        );
    }

    #[test]
    fn an_empty_stop_reason_is_named() {
        let stop = Request::Stop {
            reason: String::new(),
        }
        .encode(1);
        assert_eq!(
            Request::decode(&stop),
            Ok(Request::Stop {
                reason: "no reason given".into()
            })
        );
    }

    fn light() -> impl Strategy<Value = Light> {
        (0u8..4, 0u8..=100).prop_map(|(mode, brightness)| Light {
            mode: LightMode::from_raw(mode),
            brightness,
        })
    }

    fn request() -> impl Strategy<Value = Request> {
        let class = prop::sample::select(Class::ALL.to_vec());
        let speed = -10.0f64..10.0;
        let target = prop_oneof![
            Just(ReleaseTarget::Own),
            Just(ReleaseTarget::All),
            "[a-z:-]{1,32}".prop_map(ReleaseTarget::Owner),
        ];
        prop_oneof![
            class.prop_map(|class| Request::TakeControl { class }),
            (
                any::<u64>(),
                speed.clone(),
                speed.clone(),
                speed,
                prop::option::of(1u64..100_000),
                prop::option::of(prop::sample::select(DriveMode::ALL.to_vec())),
            )
                .prop_map(|(lease, linear, lateral, angular, ttl, mode)| {
                    Request::Drive {
                        lease,
                        linear,
                        lateral,
                        angular,
                        ttl: ttl.map(Duration::from_millis),
                        mode,
                    }
                }),
            "[a-z ]{1,64}".prop_map(|reason| Request::Stop { reason }),
            (target, any::<u64>())
                .prop_map(|(target, through)| Request::Release { target, through }),
            Just(Request::Relinquish),
            Just(Request::Resume),
            Just(Request::Lights(LightsSetting::Auto)),
            (light(), light()).prop_map(|(front, rear)| Request::Lights(LightsSetting::Manual(
                LightCommand {
                    enabled: true,
                    front,
                    rear
                }
            ))),
            prop::option::of(prop::sample::select(FaultClear::ALL.to_vec()))
                .prop_map(Request::ClearFault),
            (0u64..100_000).prop_map(|ms| Request::Heartbeat {
                period: Duration::from_millis(ms)
            }),
            Just(Request::ResetOdometry),
            Just(Request::SaveBlackBox),
        ]
    }

    proptest! {
        #[test]
        fn every_request_round_trips(request in request(), seq in any::<u64>()) {
            let wire = request.encode(seq);
            prop_assert_eq!(wire.seq, seq);
            prop_assert_eq!(Request::decode(&wire), Ok(request));
        }

        #[test]
        fn any_bytes_decode_or_are_rejected_with_a_reason(
            kind in any::<u8>(), class in any::<u8>(), fault in any::<u8>(),
            front in any::<(u8, u8)>(), auto in any::<u8>(), scope in any::<u8>(),
        ) {
            let mut wire = wire(kind);
            wire.class = class;
            wire.release_scope = scope;
            wire.fault_clear = fault;
            wire.lights.auto = auto;
            wire.lights.front = LightPayload { mode: front.0, brightness: front.1 };
            if let Err(rejection) = Request::decode(&wire) {
                prop_assert!(!rejection.to_string().is_empty());
            }
        }
    }

    #[test]
    fn every_kind_has_a_request() {
        // Request::kind is exhaustive over Request; this checks the other way round.
        let kinds: Vec<RequestKind> = [
            Request::TakeControl {
                class: Class::Teleop,
            },
            Request::Drive {
                lease: 1,
                linear: 0.0,
                lateral: 0.0,
                angular: 0.0,
                ttl: None,
                mode: None,
            },
            Request::Stop { reason: "x".into() },
            Request::Release {
                target: ReleaseTarget::Own,
                through: 1,
            },
            Request::Relinquish,
            Request::Resume,
            Request::Lights(LightsSetting::Auto),
            Request::ClearFault(None),
            Request::Heartbeat {
                period: Duration::ZERO,
            },
            Request::ResetOdometry,
            Request::SaveBlackBox,
        ]
        .iter()
        .map(Request::kind)
        .collect();
        for kind in RequestKind::ALL {
            assert!(kinds.contains(kind), "{kind} has no request");
        }
    }

    #[test]
    fn rejections_carry_their_kind_to_the_client() {
        let answer: Answer = Err(Rejection::Held {
            class: Class::Teleop,
            holder: "joy".into(),
        });
        let wire = ControlResponse::new(5, &answer);
        assert_eq!(
            wire.answer(),
            Err(Rejected {
                kind: Some(RejectionKind::Held),
                reason: "teleop held by joy".into()
            })
        );
        assert_eq!(
            ControlResponse::new(
                6,
                &Ok(Accepted {
                    clamped: true,
                    lease: Some(7),
                    stop: Some(9),
                })
            )
            .answer(),
            Ok(Accepted {
                clamped: true,
                lease: Some(7),
                stop: Some(9),
            })
        );
    }

    #[test]
    fn lights_and_fault_names_parse() {
        assert_eq!(
            parse_light("custom", 40),
            Ok(Light {
                mode: LightMode::Custom,
                brightness: 40
            })
        );
        assert_eq!(
            parse_light("on", 101),
            Err(BadLight::Brightness("101".into()))
        );
        assert!(parse_light("disco", 1).is_err());
        assert_eq!(parse_fault_clear("all"), Ok(None));
        assert_eq!(
            parse_fault_clear("driver-overtemp"),
            Ok(Some(FaultClear::DriverOverTemp))
        );
        assert!(parse_fault_clear("none").is_err());
    }

    #[test]
    fn names_parse_back() {
        assert_eq!("autonomy".parse::<Class>(), Ok(Class::Autonomy));
        let error = "pilot".parse::<Class>().unwrap_err();
        assert_eq!(
            error.to_string(),
            "unknown Class `pilot`: one of teleop, autonomy"
        );
    }
}
