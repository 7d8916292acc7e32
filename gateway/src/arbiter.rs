//! The command arbiter: who may drive, every tick, and what reaches the wheels. Sans-IO:
//! requests, gaps and time in; the motion output, the stops and an audit trail out.
//!
//! - **Stops stack.** Every stop is kept with its owner, cause, reason and time; motion only when
//!   none is left. A stop is never refused and its zero goes out at once. A stop is released by
//!   its owner (a client's name) or by an operator, never while its cause persists, and a
//!   release never restarts anything.
//! - **Gaps end control.** A gap (the gateway starting after an unclean exit, the link lost, the
//!   chassis silent, in e-stop, in fault, under RC, a tick overrun, a runaway, a CAN fault, a
//!   v2 chassis out of CAN command mode) latches a stop with its cause.
//! - **Control is taken, not inherited.** A client drives only under a lease it took
//!   (`take_control`); a stop, a gap, a release, a teleop takeover, staleness or the client's
//!   death revokes it, and the client must take control again.
//! - Priority among leases: teleop > autonomy; autonomy only while armed (`resume`).
//! - The output is capped, then rate-limited; only a stop skips the ramp.

use std::collections::VecDeque;
use std::time::Duration;

use scout_interface::control::{DriveMode, ReleaseTarget, StopCause};
use scout_protocol::FaultClear;
use scout_protocol::v2::MotionModeV2;
use serde::{Deserialize, Serialize};
use tracing::info;

use crate::share::TokenBucket;

/// The hard ceiling on any command's age: the chassis' own timeout.
pub const MAX_COMMAND_AGE: Duration = Duration::from_millis(500);
/// Motion commands that carry a requested fault-clear code.
pub const FAULT_CLEAR_FRAMES: u8 = 3;
/// The heartbeat periods a stop source may register.
pub const HEARTBEAT_PERIODS: std::ops::RangeInclusive<Duration> =
    Duration::from_millis(20)..=Duration::from_secs(10);
/// Stops kept one by one; past this, further owners' stops are merged into one entry.
pub const MAX_STOPS: usize = 256;
/// Stops a rejection names at most.
pub const DESCRIBED_STOPS: usize = 4;
/// Entries of the audit history kept for the status.
pub const HISTORY: usize = scout_interface::control::STATUS_EVENTS;
/// The owner of the stops the gateway latches for gaps.
pub const GATEWAY: &str = "gateway";
/// The owner of merged stops once [`MAX_STOPS`] are kept.
pub const OTHERS: &str = "(others)";
/// The name of a person's stops and releases (`scout estop`, `scout release`): only a process
/// with the operator role goes by it; another is named after its user (`uid-UID`).
pub use scout_interface::control::OPERATOR;
/// How far a command's stamp may lie after its arrival: the driver reads the clock once per
/// iteration, so a request sent while an iteration runs carries a stamp after that reading;
/// an iteration that runs longer than a command period is a stall.
pub const FUTURE_TOLERANCE: Duration = Duration::from_millis(20);
/// How far before a release or a loss of control a take-control may have been sent and still
/// be granted after it: a remote peer's send time is estimated from its fastest delivery, so a
/// take-control sent just after a release but delivered slower than that (jitter, a
/// millisecond stamp) seems sent before it. Beyond this it was sent before, and is outdated.
pub const OUTDATED_TOLERANCE: Duration = Duration::from_millis(100);
/// How long a new lease waits for its first command (at least its class's age): a client
/// drives once the answer reaches it, so over a slow link the first command comes a round
/// trip after the grant (600 ms on a 300 ms 4G link). A lease without a command moves nothing.
pub const FIRST_COMMAND_WITHIN: Duration = Duration::from_secs(1);

/// The most clients the arbiter tracks at once.
pub use scout_interface::control::MAX_CLIENTS as MAX_SOURCES;

pub use scout_interface::control::{
    Accepted, Answer, Class, LightsSetting, REJECTION_COUNTERS, Rejection, Request,
};

/// Speed caps, m/s and rad/s.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Caps {
    /// |linear| at most, m/s.
    pub linear: f64,
    /// |angular| at most, rad/s.
    pub angular: f64,
    /// |lateral| at most, m/s (`None`: the chassis' own; a chassis that does not move
    /// sideways refuses any, whatever the caps say: [`Sideways`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateral: Option<f64>,
}

/// Whether the chassis moves sideways: up to a speed, m/s, or not at all, and why not in the
/// words a refused client reads ("a scout2 does not move sideways").
#[derive(Debug, Clone, PartialEq)]
pub enum Sideways {
    /// Up to this speed either way, m/s.
    UpTo(f64),
    /// Not at all: a drive with a lateral speed is refused with this reason.
    Not(String),
}

impl Sideways {
    /// The fastest it goes sideways, m/s (0 when it does not).
    pub fn limit(&self) -> f64 {
        match self {
            Self::UpTo(limit) => *limit,
            Self::Not(_) => 0.0,
        }
    }
}

/// How tight the chassis turns: in place (skid-steer, tracks, two driven wheels, mecanum), only
/// while moving and no tighter than a radius (steered wheels: the Hunter), or in motion modes
/// (four steered wheels: the Rangers).
#[derive(Debug, Clone, PartialEq)]
pub enum Turning {
    /// Any yaw rate at any speed, standing still included.
    InPlace,
    /// Only while moving, at most `|linear| / min_radius`; a drive that turns standing still is
    /// refused with `in_place`, one that turns tighter is held to the radius (and says
    /// `clamped`).
    Radius {
        /// m.
        min_radius: f64,
        /// The refusal of a turn in place ("a hunter2 cannot turn in place...").
        in_place: String,
    },
    /// In one motion mode at a time ([`crate::modes`]): dual Ackermann no tighter than
    /// `min_radius`, parallel, or spinning in place. A drive no mode carries is brought to one
    /// (and says `clamped`); one the mode the chassis reports does not carry ramps to zero,
    /// the mode changes standing still ([`Output::mode`]), and it ramps up again once the
    /// chassis reports the new mode taken ([`Arbiter::set_motion_mode`]).
    Modes {
        /// m, dual Ackermann's tightest turn.
        min_radius: f64,
    },
}

impl Turning {
    /// The fastest turn at `linear` m/s, rad/s (`None`: as fast as the caps allow).
    fn limit(&self, linear: f64) -> Option<f64> {
        match self {
            Self::InPlace | Self::Modes { .. } => None,
            Self::Radius { min_radius, .. } => Some(linear.abs() / min_radius),
        }
    }
}

/// Rate limits, per second.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RateLimits {
    /// Speeding up, m/s².
    pub linear_acceleration: f64,
    /// Slowing down, m/s².
    pub linear_deceleration: f64,
    /// Turning faster, rad/s².
    pub angular_acceleration: f64,
    /// Turning slower, rad/s².
    pub angular_deceleration: f64,
    /// Speeding up sideways, m/s² (a chassis that moves sideways).
    #[serde(default = "default_lateral_acceleration")]
    pub lateral_acceleration: f64,
    /// Slowing down sideways, m/s².
    #[serde(default = "default_lateral_deceleration")]
    pub lateral_deceleration: f64,
}

/// Sideways as forward, by default.
const fn default_lateral_acceleration() -> f64 {
    1.0
}

const fn default_lateral_deceleration() -> f64 {
    2.0
}

/// The arbiter's settings (the gateway config's `[arbiter]` table).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ArbiterConfig {
    /// A teleop command's longest life, ms (at most 500).
    pub teleop_max_age_ms: u64,
    /// An autonomy command's longest life, ms (at most 500).
    pub autonomy_max_age_ms: u64,
    /// Re-arm autonomy by itself after a takeover, stop or release (default: explicit resume).
    pub auto_resume: bool,
    /// Caps for teleop, within the chassis' limits (default: the chassis' limits).
    pub teleop_caps: Option<Caps>,
    /// Caps for autonomy, within the chassis' limits (default: the chassis' limits).
    pub autonomy_caps: Option<Caps>,
    /// Acceleration and deceleration limits.
    pub limits: RateLimits,
    /// Requests a second one client may send, sustained (stops are never limited).
    pub request_rate_hz: f64,
    /// Requests one client may send in a burst above the sustained rate.
    pub request_burst: u32,
    /// Who has the operator role (may release others' stops and all stops): see
    /// [`OperatorConfig`].
    pub operators: OperatorConfig,
}

/// Who has the operator role, by the operating system's identity of the requesting process,
/// never by a name it chose: its executable is one of `programs` (the same file, by device and
/// inode: a copy elsewhere is not) run by the gateway's own user or root, or its user is one of
/// `uids`, or one of its groups is in `gids`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OperatorConfig {
    /// Executables whose processes are operators, as paths; a relative path is taken beside
    /// the gateway's own executable (default `["scout"]`: the `scout` tool installed with it).
    pub programs: Vec<String>,
    /// User ids whose processes are operators (real or effective).
    pub uids: Vec<u32>,
    /// Group ids whose members' processes are operators (primary or supplementary).
    pub gids: Vec<u32>,
}

impl Default for OperatorConfig {
    fn default() -> Self {
        Self {
            programs: vec!["scout".into()],
            uids: Vec::new(),
            gids: Vec::new(),
        }
    }
}

impl Default for ArbiterConfig {
    fn default() -> Self {
        Self {
            teleop_max_age_ms: 250,
            autonomy_max_age_ms: 500,
            auto_resume: false,
            teleop_caps: None,
            autonomy_caps: None,
            limits: RateLimits {
                linear_acceleration: 1.0,
                linear_deceleration: 2.0,
                angular_acceleration: 1.5,
                angular_deceleration: 3.0,
                lateral_acceleration: default_lateral_acceleration(),
                lateral_deceleration: default_lateral_deceleration(),
            },
            request_rate_hz: 500.0,
            request_burst: 50,
            operators: OperatorConfig::default(),
        }
    }
}

/// An arbiter setting out of range.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ArbiterConfigError {
    /// A command age limit beyond what the chassis waits.
    #[error("arbiter.{name} must be 1..={max} (the chassis stops after {max} ms), found {ms}")]
    CommandAge {
        /// The setting.
        name: &'static str,
        /// Its value, ms.
        ms: u64,
        /// The largest allowed, ms.
        max: u64,
    },
    /// A cap, limit or rate that is not positive.
    #[error("arbiter caps, limits, request_rate_hz and request_burst must be positive")]
    NotPositive,
}

impl ArbiterConfig {
    /// Checks the values; the error says which and why.
    pub fn validate(&self) -> Result<(), ArbiterConfigError> {
        for (name, ms) in [
            ("teleop_max_age_ms", self.teleop_max_age_ms),
            ("autonomy_max_age_ms", self.autonomy_max_age_ms),
        ] {
            if ms == 0 || ms > MAX_COMMAND_AGE.as_millis() as u64 {
                return Err(ArbiterConfigError::CommandAge {
                    name,
                    ms,
                    max: MAX_COMMAND_AGE.as_millis() as u64,
                });
            }
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let caps = [self.teleop_caps, self.autonomy_caps];
        let limits = self.limits;
        let all = caps
            .iter()
            .flatten()
            .flat_map(|c| [c.linear, c.angular, c.lateral.unwrap_or(1.0)])
            .chain([
                limits.linear_acceleration,
                limits.linear_deceleration,
                limits.angular_acceleration,
                limits.angular_deceleration,
                limits.lateral_acceleration,
                limits.lateral_deceleration,
                self.request_rate_hz,
            ]);
        if !all.into_iter().all(positive) || self.request_burst == 0 {
            return Err(ArbiterConfigError::NotPositive);
        }
        Ok(())
    }

    fn max_age(&self, class: Class) -> Duration {
        Duration::from_millis(match class {
            Class::Teleop => self.teleop_max_age_ms,
            Class::Autonomy => self.autonomy_max_age_ms,
        })
    }

    fn caps(&self, class: Class) -> Option<Caps> {
        match class {
            Class::Teleop => self.teleop_caps,
            Class::Autonomy => self.autonomy_caps,
        }
    }
}

/// Who sent a request, as the transport tells: its port, its process's node, the port's name.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ClientKey {
    /// The iceoryx2 client port (`UniqueClientId`): the identity.
    pub port: u128,
    /// The iceoryx2 node (process) of the port, for dead-process detection.
    pub node: u128,
    /// The port's name: the client's name in the status, the audit log and on its stops.
    pub name: String,
    /// Its user, as the kernel vouched for it (a datagram's credentials, a port's process's
    /// real uid; `None`: unknown): a stop belongs to its name and this user.
    pub uid: Option<u32>,
}

/// A request's sender and what it may do.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Origin {
    /// Who.
    pub key: ClientKey,
    /// May release others' stops and all stops (from the process's identity).
    pub operator: bool,
    /// The gateway's own zenoh bridge: its stops and releases name the remote peer they are
    /// sent for.
    pub bridge: bool,
}

/// The motion command for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    /// m/s, forward.
    pub linear: f64,
    /// m/s, leftward.
    pub lateral: f64,
    /// rad/s.
    pub angular: f64,
    /// The fault-clear code for byte 1.
    pub fault_clear: FaultClear,
    /// A cap or rate limit holds the output below what the selected client asked.
    pub limited: bool,
    /// The motion mode the chassis is to be in ([`Turning::Modes`]; `None`: any, or it has
    /// none). Another than the one it reports comes with zero speed: change to it standing still.
    pub mode: Option<MotionModeV2>,
    /// A client's fresh command asks to move, whatever holds the output back (a mode change,
    /// the brake, [`Arbiter::set_held`]): a Hunter's brake is released for it alone.
    pub drive: bool,
}

impl Output {
    /// Zero speed, nothing to clear.
    pub const STOP: Output = Output {
        linear: 0.0,
        lateral: 0.0,
        angular: 0.0,
        fault_clear: FaultClear::None,
        limited: false,
        mode: None,
        drive: false,
    };
}

/// A stop that holds the robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stop {
    /// Its id: stops are numbered from 1 as they latch; a stop latched again (same owner and
    /// cause) takes a new id, so a release decided before it does not clear it.
    pub id: u64,
    /// A client's name, or [`GATEWAY`] for a gap.
    pub owner: String,
    /// Why it holds.
    pub cause: StopCause,
    /// In words.
    pub reason: String,
    /// When it latched.
    pub at: Duration,
    /// Latched by an operator: only an operator releases it, whatever name another client
    /// takes.
    pub by_operator: bool,
    /// The user that latched it, as the kernel vouched (`None`: unknown, or the gateway's own):
    /// besides an operator, only a client of this user under the owner's name releases it.
    pub uid: Option<u32>,
    /// For a heartbeat stop: the source's port, while the cause is its silence.
    source: Option<u128>,
}

impl Stop {
    /// Whether a non-operator going by its owner's name, of user `uid`, may release it: only a
    /// stop no operator latched, latched by that very user, known (a stop of a user the kernel
    /// did not name is an operator's to release). An operator releases any.
    fn releasable_by(&self, uid: Option<u32>) -> bool {
        !self.by_operator && uid.is_some() && self.uid == uid
    }
}

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "#{} {} ({}): {}",
            self.id, self.owner, self.cause, self.reason
        )
    }
}

/// A stop to latch.
#[derive(Debug, Clone, Copy)]
struct Latch<'a> {
    owner: &'a str,
    cause: StopCause,
    reason: &'a str,
    /// For a heartbeat stop: the source's port, while the cause is its silence.
    source: Option<u128>,
    by_operator: bool,
    uid: Option<u32>,
}

/// A command a client sent under its lease.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Command {
    linear: f64,
    lateral: f64,
    angular: f64,
    /// The motion mode the client named (a Ranger).
    mode: Option<MotionModeV2>,
    clamped: bool,
    expires: Duration,
}

/// Control a client took.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Lease {
    id: u64,
    class: Class,
    /// When it was granted or last took a command: it ends its class's age after that (the
    /// first command may take [`FIRST_COMMAND_WITHIN`]).
    heard: Duration,
    command: Option<Command>,
}

/// A heartbeat stop source's registration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Heartbeat {
    period: Duration,
    /// It missed a beat and has not beaten since: its stop cannot be released.
    silent: bool,
}

/// One client the arbiter knows.
#[derive(Debug, Clone, PartialEq)]
pub struct Source {
    /// Who.
    pub key: ClientKey,
    lease: Option<Lease>,
    /// Why its last lease ended.
    revoked: Option<String>,
    /// When its control last ended other than by its own relinquish (a stop, a takeover, a
    /// lapse): a take-control it sent before then is outdated.
    lost_control: Option<Duration>,
    heartbeat: Option<Heartbeat>,
    budget: TokenBucket,
    /// When it last sent a request.
    pub last_seen: Duration,
    /// Requests it sent.
    pub requests: u64,
}

impl Source {
    /// Its heartbeat period, if registered.
    pub fn heartbeat(&self) -> Option<Duration> {
        self.heartbeat.map(|h| h.period)
    }

    /// The class of its lease.
    pub fn class(&self) -> Option<Class> {
        self.lease.map(|lease| lease.class)
    }

    /// Its lease's id.
    pub fn lease(&self) -> Option<u64> {
        self.lease.map(|lease| lease.id)
    }

    fn fresh_command(&self, now: Duration) -> Option<Command> {
        self.lease
            .and_then(|lease| lease.command)
            .filter(|command| now < command.expires)
    }
}

/// The arbiter.
#[derive(Debug, Clone)]
pub struct Arbiter {
    config: ArbiterConfig,
    global: Caps,
    sideways: Sideways,
    turning: Turning,
    /// The motion mode the chassis reports it is settled in ([`Turning::Modes`]).
    settled: Option<MotionModeV2>,
    /// Whether the gateway may take the chassis out of it (its own park, not someone else's).
    may_leave: bool,
    /// The chassis cannot move yet (its brake not reported released): the output is zero.
    held: bool,
    stops: Vec<Stop>,
    /// The gap causes present now: their stops cannot be released.
    present: Vec<StopCause>,
    autonomy_armed: bool,
    sources: Vec<Source>,
    output: Output,
    /// When the last command that drove the output ends its life: past it the output is zero
    /// at once, not ramped (nothing moves on a command longer than it asked).
    motion_until: Duration,
    fault_clears: VecDeque<(FaultClear, u8)>,
    lights: Option<LightsSetting>,
    rejections: [u64; REJECTION_COUNTERS],
    urgent_stop: bool,
    newest_stop: u64,
    /// When a release last left no stop: a take-control sent before then is outdated.
    released: Option<Duration>,
    next_lease: u64,
    history: VecDeque<(Duration, String)>,
    /// Why autonomy may not take control now (a critical battery), if it may not.
    autonomy_barred: Option<String>,
}

impl Arbiter {
    /// An arbiter with `config` for a chassis that may go at most as fast as `global` says
    /// (`global.lateral` `None` or 0: it does not move sideways; [`Arbiter::set_sideways`] says
    /// why in the refusals). `instance` tells this gateway's leases from another's. Autonomy
    /// starts disarmed.
    pub fn new(config: ArbiterConfig, global: Caps, instance: u32) -> Self {
        let sideways = match global.lateral {
            Some(limit) if limit > 0.0 => Sideways::UpTo(limit),
            _ => Sideways::Not(
                "this chassis does not move sideways: send a lateral speed of 0".into(),
            ),
        };
        Self {
            config,
            global,
            sideways,
            turning: Turning::InPlace,
            settled: None,
            may_leave: false,
            held: false,
            stops: Vec::new(),
            present: Vec::new(),
            autonomy_armed: false,
            sources: Vec::new(),
            output: Output::STOP,
            motion_until: Duration::ZERO,
            fault_clears: VecDeque::new(),
            lights: None,
            rejections: [0; REJECTION_COUNTERS],
            urgent_stop: false,
            newest_stop: 0,
            released: None,
            next_lease: (u64::from(instance) << 32) | 1,
            history: VecDeque::with_capacity(HISTORY),
            autonomy_barred: None,
        }
    }

    /// Whether the chassis moves sideways from now on (the protocol it speaks decides it for
    /// some models). A command already taken goes no faster sideways than this allows.
    pub fn set_sideways(&mut self, sideways: Sideways) {
        self.sideways = sideways;
    }

    /// How tight the chassis turns (the model decides it).
    pub fn set_turning(&mut self, turning: Turning) {
        self.turning = turning;
    }

    /// The motion mode the chassis reports it is settled in (0x291), `None` while it changes
    /// ([`Turning::Modes`]), and whether the gateway may take it out of it
    /// ([`crate::modes::Handshake::may_leave`]). Nothing moves in a mode until the chassis
    /// reports it taken; a drive in one it may not leave is refused.
    pub fn set_motion_mode(&mut self, settled: Option<MotionModeV2>, may_leave: bool) {
        self.settled = settled;
        self.may_leave = may_leave;
    }

    /// Whether the chassis cannot move yet (a Hunter's parking brake, until it reports it
    /// released): the output stays zero, and ramps up from zero once it can. A held drive
    /// still says [`Output::drive`], which is what releases the brake.
    pub fn set_held(&mut self, held: bool) {
        self.held = held;
    }

    /// Bars autonomy from taking control while `why` holds (a critical battery), or lifts the
    /// bar. A bar ends no lease and lifting it starts nothing: a running autonomy drives on
    /// (see [`Arbiter::end_autonomy`]), a refused one must take control again.
    pub fn bar_autonomy(&mut self, now: Duration, why: Option<String>) {
        if self.autonomy_barred == why {
            return;
        }
        match &why {
            Some(why) => self.audit(now, format!("autonomy may not take control: {why}")),
            None => self.audit(now, "autonomy may take control again".into()),
        }
        self.autonomy_barred = why;
    }

    /// Ends autonomy's control (its output ramps to zero; it must take control again).
    pub fn end_autonomy(&mut self, now: Duration, why: &str) {
        self.revoke(now, Some(Class::Autonomy), why);
    }

    /// The stops that hold the robot, oldest first.
    pub fn stops(&self) -> &[Stop] {
        &self.stops
    }

    /// The id of the newest stop latched so far (0: none yet).
    pub fn newest_stop(&self) -> u64 {
        self.newest_stop
    }

    /// Whether a stop's cause persists (it cannot be released yet).
    pub fn persists(&self, stop: &Stop) -> bool {
        match stop.cause {
            StopCause::Heartbeat => stop.source.is_some_and(|port| {
                self.sources
                    .iter()
                    .any(|s| s.key.port == port && s.heartbeat.is_some_and(|h| h.silent))
            }),
            StopCause::Client
            | StopCause::GatewayStart
            | StopCause::Overrun
            | StopCause::Runaway
            | StopCause::ChassisMode => false,
            StopCause::LinkLost
            | StopCause::ChassisSilent
            | StopCause::ChassisEstop
            | StopCause::ChassisFault
            | StopCause::RcOverride
            | StopCause::LinkFault => self.present.contains(&stop.cause),
        }
    }

    /// Whether a gap's cause is present now.
    pub fn present(&self, cause: StopCause) -> bool {
        self.present.contains(&cause)
    }

    /// Whether autonomy may drive.
    pub fn autonomy_armed(&self) -> bool {
        self.autonomy_armed
    }

    /// The clients it knows.
    pub fn sources(&self) -> &[Source] {
        &self.sources
    }

    /// Rejections so far, indexed by [`Rejection::kind`].
    pub fn rejections(&self) -> &[u64; REJECTION_COUNTERS] {
        &self.rejections
    }

    /// The lights clients asked for, if any did.
    pub fn lights(&self) -> Option<LightsSetting> {
        self.lights
    }

    /// The last output.
    pub fn output(&self) -> Output {
        self.output
    }

    /// The latest events, oldest first, with when.
    pub fn history(&self) -> impl Iterator<Item = &(Duration, String)> {
        self.history.iter()
    }

    /// Counts a request refused before it reached the arbiter (malformed on the wire).
    pub fn count_rejection(&mut self, rejection: &Rejection) {
        self.rejections[usize::from(rejection.kind().raw())] += 1;
    }

    /// Whether a stop latched since the last call: the caller sends zero at once, not at the
    /// next tick.
    pub fn take_urgent_stop(&mut self) -> bool {
        std::mem::take(&mut self.urgent_stop)
    }

    /// The source sending, by class, if one holds a lease with a fresh command and no stop
    /// holds the robot.
    pub fn selected(&self, now: Duration) -> Option<(&Source, Class)> {
        if !self.stops.is_empty() {
            return None;
        }
        let holder = |class: Class| {
            self.sources
                .iter()
                .find(|s| s.class() == Some(class) && s.fresh_command(now).is_some())
                .map(|s| (s, class))
        };
        holder(Class::Teleop).or_else(|| {
            if self.autonomy_armed {
                holder(Class::Autonomy)
            } else {
                None
            }
        })
    }

    /// Records an event: the audit log and the status' history.
    fn audit(&mut self, now: Duration, event: String) {
        info!("audit t={:.3}s: {event}", now.as_secs_f64());
        if self.history.len() == HISTORY {
            self.history.pop_front();
        }
        self.history.push_back((now, event));
    }

    /// Handles one request at `now` from `origin`, sent at `sent` by the sender's clock (the
    /// same CLOCK_BOOTTIME on one host).
    pub fn handle_request(
        &mut self,
        now: Duration,
        origin: &Origin,
        request: Request,
        sent: Duration,
    ) -> Answer {
        self.expire(now);
        let answer = self.answer(now, origin, request, sent);
        if let Err(rejection) = &answer {
            self.count_rejection(rejection);
        }
        answer
    }

    /// The one match over the request kinds: stops and releases as they come, everything else
    /// once its sender has a client slot and budget ([`Arbiter::admit`]).
    fn answer(
        &mut self,
        now: Duration,
        origin: &Origin,
        request: Request,
        sent: Duration,
    ) -> Answer {
        let accepted = Ok(Accepted::default());
        match request {
            // Never refused, never limited, never needs a client slot.
            Request::Stop { reason } => self.client_stop(now, origin, &reason),
            // Never needs a client slot either: with every slot taken, stops can still go.
            Request::Release { target, through } => self.release(now, origin, &target, through),
            Request::TakeControl { class } => {
                let index = self.admit(now, origin)?;
                self.take_control(now, index, class, sent)
            }
            Request::Drive {
                lease,
                linear,
                lateral,
                angular,
                ttl,
                mode,
            } => {
                let index = self.admit(now, origin)?;
                let mode = mode.map(DriveMode::motion_mode);
                self.drive(
                    now,
                    index,
                    lease,
                    (linear, lateral, angular, mode),
                    ttl,
                    sent,
                )
            }
            Request::Relinquish => {
                let index = self.admit(now, origin)?;
                self.end_lease(now, index, "relinquished");
                accepted
            }
            Request::Resume => {
                self.admit(now, origin)?;
                if !self.stops.is_empty() {
                    return Err(self.latched());
                }
                if !self.autonomy_armed {
                    self.audit(now, format!("autonomy armed by {}", origin.key.name));
                }
                self.autonomy_armed = true;
                accepted
            }
            Request::Lights(setting) => {
                self.admit(now, origin)?;
                self.lights = Some(setting);
                accepted
            }
            Request::ClearFault(code) => {
                self.admit(now, origin)?;
                let codes = match code {
                    None => FaultClear::ALL.to_vec(),
                    Some(FaultClear::None) => {
                        return Err(Rejection::Malformed("no fault to clear".into()));
                    }
                    Some(code) => vec![code],
                };
                self.audit(now, format!("{} clears faults {codes:?}", origin.key.name));
                self.fault_clears = codes
                    .into_iter()
                    .map(|code| (code, FAULT_CLEAR_FRAMES))
                    .collect();
                accepted
            }
            Request::Heartbeat { period } => {
                let index = self.admit(now, origin)?;
                self.heartbeat(now, index, period)
            }
            // The state tracker resets the odometry, the driver saves the black box; to the
            // arbiter they are beats.
            Request::ResetOdometry | Request::SaveBlackBox => {
                self.admit(now, origin)?;
                accepted
            }
        }
    }

    /// A request from a client that needs a slot: its slot (made if new), one request taken
    /// from its budget, and a beat of its heartbeat. Returns its index.
    fn admit(&mut self, now: Duration, origin: &Origin) -> Result<usize, Rejection> {
        let index = self.source_index(&origin.key, now)?;
        self.spend(index, now)?;
        let source = &mut self.sources[index];
        source.last_seen = now;
        source.requests += 1;
        if let Some(heartbeat) = source.heartbeat.as_mut() {
            heartbeat.silent = false;
        }
        Ok(index)
    }

    /// Registers (or, with a zero period, deregisters) client `index` as a heartbeat stop source.
    fn heartbeat(&mut self, now: Duration, index: usize, period: Duration) -> Answer {
        if period.is_zero() {
            self.sources[index].heartbeat = None;
        } else if !HEARTBEAT_PERIODS.contains(&period) {
            return Err(Rejection::Malformed(format!(
                "heartbeat period must be {:?} to {:?}",
                HEARTBEAT_PERIODS.start(),
                HEARTBEAT_PERIODS.end()
            )));
        } else {
            if self.sources[index].heartbeat.is_none() {
                let name = &self.sources[index].key.name;
                let event = format!("{name} is a heartbeat stop source ({period:?})");
                self.audit(now, event);
            }
            self.sources[index].heartbeat = Some(Heartbeat {
                period,
                silent: false,
            });
        }
        Ok(Accepted::default())
    }

    /// A client's stop, owned by its name: never refused. The answer carries its id.
    fn client_stop(&mut self, now: Duration, origin: &Origin, reason: &str) -> Answer {
        let id = self.latch(
            now,
            Latch {
                owner: &origin.key.name,
                cause: StopCause::Client,
                reason,
                source: None,
                by_operator: origin.operator,
                uid: origin.key.uid,
            },
        );
        Ok(Accepted {
            stop: Some(id),
            ..Accepted::default()
        })
    }

    /// The rejection that lists what holds the robot.
    fn latched(&self) -> Rejection {
        Rejection::Latched {
            stops: self.describe(self.stops.iter()),
        }
    }

    /// The stops in words, the first [`DESCRIBED_STOPS`] of them: a rejection's text stays short
    /// (and cheap to make) however many stops hold.
    fn describe<'a>(&self, stops: impl Iterator<Item = &'a Stop>) -> String {
        let mut listed = Vec::new();
        let mut more = 0;
        for stop in stops {
            if listed.len() < DESCRIBED_STOPS {
                listed.push(stop.to_string());
            } else {
                more += 1;
            }
        }
        if more > 0 {
            listed.push(format!("and {more} more (scout status)"));
        }
        listed.join("; ")
    }

    /// Grants `class` to client `index` if no stop holds, autonomy is armed (for autonomy) and
    /// no other client holds it, unless the request was sent (at `sent`) before a release or
    /// before the client lost control (by more than [`OUTDATED_TOLERANCE`]): a take-control
    /// held up in the network across a stop or a partition is a decision from before it, never
    /// applied after.
    fn take_control(
        &mut self,
        now: Duration,
        index: usize,
        class: Class,
        sent: Duration,
    ) -> Answer {
        if !self.stops.is_empty() {
            return Err(self.latched());
        }
        if class == Class::Autonomy && !self.autonomy_armed {
            return Err(Rejection::AutonomyDisarmed);
        }
        // Autonomy never waits behind a teleop holder to drive the moment teleop lets go.
        if class == Class::Autonomy
            && let Some(teleop) = self
                .sources
                .iter()
                .enumerate()
                .find(|(i, s)| *i != index && s.class() == Some(Class::Teleop))
                .map(|(_, s)| s)
        {
            return Err(Rejection::Held {
                class: Class::Teleop,
                holder: teleop.key.name.clone(),
            });
        }
        if let Some(holder) = self
            .sources
            .iter()
            .enumerate()
            .find(|(i, s)| *i != index && s.class() == Some(class))
            .map(|(_, s)| s)
        {
            return Err(Rejection::Held {
                class,
                holder: holder.key.name.clone(),
            });
        }
        if let Some(lease) = self.sources[index].lease.filter(|l| l.class == class) {
            return Ok(Accepted {
                lease: Some(lease.id),
                ..Accepted::default()
            });
        }
        // A new autonomy take only: one that holds control keeps it (and its take again).
        if class == Class::Autonomy
            && let Some(why) = &self.autonomy_barred
        {
            return Err(Rejection::NotAllowed { why: why.clone() });
        }
        let ends = [
            (self.released, "the stops were released"),
            (self.sources[index].lost_control, "this client lost control"),
        ];
        if let Some((at, ended)) = ends
            .into_iter()
            .filter_map(|(at, ended)| {
                at.filter(|at| sent + OUTDATED_TOLERANCE < *at)
                    .map(|at| (at, ended))
            })
            .max_by_key(|(at, _)| *at)
        {
            return Err(Rejection::Outdated {
                ended: ended.to_owned(),
                by: at - sent,
            });
        }
        let id = self.next_lease;
        self.next_lease = self.next_lease.wrapping_add(1).max(1);
        let source = &mut self.sources[index];
        source.lease = Some(Lease {
            id,
            class,
            heard: now,
            command: None,
        });
        source.revoked = None;
        let name = source.key.name.clone();
        self.audit(
            now,
            format!("{name} takes control as {class} (lease {id:x})"),
        );
        if class == Class::Teleop {
            self.disarm_autonomy(now, &format!("teleop {name} took over"));
        }
        Ok(Accepted {
            lease: Some(id),
            ..Accepted::default()
        })
    }

    fn drive(
        &mut self,
        now: Duration,
        index: usize,
        lease_id: u64,
        (linear, lateral, angular, mode): (f64, f64, f64, Option<MotionModeV2>),
        ttl: Option<Duration>,
        sent: Duration,
    ) -> Answer {
        if !linear.is_finite() || !lateral.is_finite() || !angular.is_finite() {
            return Err(Rejection::NotFinite);
        }
        let source = &self.sources[index];
        let Some(lease) = source.lease.filter(|lease| lease.id == lease_id) else {
            return Err(match &source.revoked {
                Some(cause) => Rejection::Revoked {
                    cause: cause.clone(),
                },
                None => Rejection::NoControl,
            });
        };
        let class = lease.class;
        let life = ttl.map_or(self.config.max_age(class), |ttl| {
            ttl.min(self.config.max_age(class))
        });
        // A command lives from when it was sent, not from when it was read; a stamp after its
        // arrival is another clock's (or a lie), and would make the command live longer.
        if sent > now + FUTURE_TOLERANCE {
            return Err(Rejection::Future { ahead: sent - now });
        }
        let sent = sent.min(now);
        let age = now - sent;
        if age > life {
            return Err(Rejection::Stale { age, life });
        }
        // What the chassis cannot do is refused, never reshaped into something else.
        let lateral_cap = match &self.sideways {
            Sideways::Not(why) if lateral != 0.0 => {
                return Err(Rejection::NotAllowed { why: why.clone() });
            }
            Sideways::Not(_) => 0.0,
            Sideways::UpTo(limit) => *limit,
        };
        if let Turning::Radius { in_place, .. } = &self.turning
            && angular != 0.0
            && linear == 0.0
        {
            return Err(Rejection::NotAllowed {
                why: in_place.clone(),
            });
        }
        if mode.is_some() && !matches!(self.turning, Turning::Modes { .. }) {
            return Err(Rejection::NotAllowed {
                why: "this chassis has no motion modes (a Ranger's): drive without one".into(),
            });
        }
        // A chassis someone parked (or put in a mode the gateway does not drive in) is not
        // taken out of it by a client's drive.
        if let (Turning::Modes { .. }, Some(mode)) = (&self.turning, self.settled)
            && !self.may_leave
            && (linear, lateral, angular) != (0.0, 0.0, 0.0)
        {
            return Err(Rejection::NotAllowed {
                why: format!(
                    "the chassis is in {mode} mode (0x291), which the gateway does not take it \
                     out of: change its mode on the chassis (its RC) to drive"
                ),
            });
        }
        let caps = self.config.caps(class).unwrap_or(self.global);
        let (linear_cap, angular_cap, lateral_cap) = (
            caps.linear.min(self.global.linear),
            caps.angular.min(self.global.angular),
            caps.lateral.map_or(lateral_cap, |cap| cap.min(lateral_cap)),
        );
        let clamped_linear = linear.clamp(-linear_cap, linear_cap);
        let clamped_lateral = lateral.clamp(-lateral_cap, lateral_cap);
        // No tighter than the chassis turns at the speed it may go.
        let angular_cap = self
            .turning
            .limit(clamped_linear)
            .map_or(angular_cap, |limit| limit.min(angular_cap));
        let clamped_angular = angular.clamp(-angular_cap, angular_cap);
        // Four steered wheels move in one mode at a time: the one named, or one that carries
        // the velocity.
        let caps = (linear_cap, lateral_cap, angular_cap);
        let (clamped_linear, clamped_lateral, clamped_angular) = match (&self.turning, mode) {
            (Turning::Modes { min_radius }, Some(mode)) => {
                crate::modes::in_mode(mode, (linear, lateral, angular), *min_radius, caps)
                    .map_err(|why| Rejection::NotAllowed { why })?
            }
            (Turning::Modes { min_radius }, None) => {
                crate::modes::one_mode((linear, lateral, angular), *min_radius, caps)
            }
            (Turning::InPlace | Turning::Radius { .. }, _) => {
                (clamped_linear, clamped_lateral, clamped_angular)
            }
        };
        let clamped =
            clamped_linear != linear || clamped_lateral != lateral || clamped_angular != angular;
        if let Some(lease) = self.sources[index].lease.as_mut() {
            lease.heard = now;
            lease.command = Some(Command {
                linear: clamped_linear,
                lateral: clamped_lateral,
                angular: clamped_angular,
                mode,
                clamped,
                expires: sent + life,
            });
        }
        Ok(Accepted {
            clamped,
            ..Accepted::default()
        })
    }

    /// Releases the stops `target` names that latched no later than `through` (the newest
    /// stop the sender saw). Needs no client slot and touches no lease: every lease ended when
    /// the stops latched. With nothing latched it does nothing.
    fn release(
        &mut self,
        now: Duration,
        origin: &Origin,
        target: &ReleaseTarget,
        through: u64,
    ) -> Answer {
        if self.stops.is_empty() {
            return Ok(Accepted::default());
        }
        let name = &origin.key.name;
        // The gateway's and merged stops belong to no client: only an operator releases them.
        let reserved = name == GATEWAY || name == OTHERS;
        let own = !reserved
            && match target {
                ReleaseTarget::Own => true,
                ReleaseTarget::Owner(owner) => owner == name,
                ReleaseTarget::All => false,
            };
        if !own && !origin.operator {
            return Err(Rejection::NotAllowed {
                why: format!(
                    "only an operator releases others' stops (this is {name}); held by: {}",
                    self.describe(self.stops.iter())
                ),
            });
        }
        let owner = match target {
            ReleaseTarget::Owner(owner) => owner.as_str(),
            ReleaseTarget::Own | ReleaseTarget::All => name.as_str(),
        };
        // Whose stops the target names, at any time: a non-operator's own are those of its
        // name that its user latched.
        let uid = origin.key.uid;
        let targeted = |stop: &Stop| match target {
            ReleaseTarget::Own | ReleaseTarget::Owner(_) => {
                stop.owner == owner && (origin.operator || stop.releasable_by(uid))
            }
            ReleaseTarget::All => true,
        };
        let named = |stop: &Stop| targeted(stop) && stop.id <= through;
        if !self.stops.iter().any(named) {
            let why = if let Some(newer) = self.stops.iter().find(|stop| targeted(stop)) {
                format!(
                    "stop #{} ({newer}) latched after the status this release was decided on \
                     (newest seen: #{through}): look again, then release",
                    newer.id
                )
            } else if let Some(theirs) = self.stops.iter().find(|stop| stop.owner == owner) {
                let by = match theirs.uid {
                    _ if theirs.by_operator => "an operator".to_owned(),
                    Some(latcher) => format!("another user (uid {latcher})"),
                    None => "a user the kernel did not name".to_owned(),
                };
                format!(
                    "the stops of {owner} were latched by {by}: only that user or an operator \
                     releases them (this is uid {})",
                    uid.map_or_else(|| "unknown".to_owned(), |uid| uid.to_string())
                )
            } else {
                format!(
                    "no stop of {owner} to release; held by: {}",
                    self.describe(self.stops.iter())
                )
            };
            return Err(Rejection::NotAllowed { why });
        }
        let persisting: Vec<&Stop> = self
            .stops
            .iter()
            .filter(|stop| named(stop) && self.persists(stop))
            .collect();
        if !persisting.is_empty() {
            return Err(Rejection::CausePersists {
                stops: format!(
                    "{} (the cause persists)",
                    self.describe(persisting.into_iter())
                ),
            });
        }
        let (released, kept): (Vec<Stop>, Vec<Stop>) =
            std::mem::take(&mut self.stops).into_iter().partition(named);
        self.stops = kept;
        if self.stops.is_empty() {
            self.released = Some(now);
        }
        for stop in &released {
            self.audit(now, format!("stop #{} released by {name}: {stop}", stop.id));
        }
        self.disarm_autonomy(now, "a release");
        Ok(Accepted::default())
    }

    fn end_lease(&mut self, now: Duration, index: usize, why: &str) {
        let source = &mut self.sources[index];
        if let Some(lease) = source.lease.take() {
            source.revoked = Some(why.to_owned());
            let name = source.key.name.clone();
            self.audit(
                now,
                format!("{} {name} gave up control ({why})", lease.class),
            );
        }
    }

    /// Ends every lease (of `class`, or all): its holder must take control again.
    fn revoke(&mut self, now: Duration, class: Option<Class>, why: &str) {
        let mut ended = Vec::new();
        for source in &mut self.sources {
            if let Some(lease) = source.lease
                && class.is_none_or(|class| lease.class == class)
            {
                source.lease = None;
                source.revoked = Some(why.to_owned());
                source.lost_control = Some(now);
                ended.push(format!("{} {}", lease.class, source.key.name));
            }
        }
        if !ended.is_empty() {
            self.audit(
                now,
                format!("control revoked ({why}): {}", ended.join(", ")),
            );
        }
    }

    /// Latches a stop: zero at once, every lease revoked, autonomy disarmed. The same owner and
    /// cause again refreshes the reason and takes a new id. Returns the stop's id.
    fn latch(&mut self, now: Duration, latch: Latch<'_>) -> u64 {
        self.newest_stop += 1;
        let id = self.newest_stop;
        self.urgent_stop = true;
        self.output = Output::STOP;
        let Latch {
            owner,
            cause,
            reason,
            source,
            by_operator,
            uid,
        } = latch;
        let why = format!("{owner} ({cause}): {reason}");
        // Past MAX_STOPS, a new owner's stop merges into one entry. A stop an operator latched
        // is latched again only by an operator: anyone else under that name gets a stop of
        // its own, and the operator's keeps its reason.
        // A stop of another user under this name is not this one's either: it gets its own
        // (merged stops are an operator's to release whoever latched them: one entry).
        let known = |stops: &[Stop], owner: &str| {
            stops.iter().position(|stop| {
                stop.owner == owner
                    && stop.cause == cause
                    && (by_operator || (!stop.by_operator && (stop.uid == uid || owner == OTHERS)))
            })
        };
        let owner = match known(&self.stops, owner) {
            None if self.stops.len() >= MAX_STOPS => OTHERS,
            _ => owner,
        };
        match known(&self.stops, owner) {
            Some(index) => {
                let stop = &mut self.stops[index];
                stop.id = id;
                stop.reason = reason.to_owned();
                stop.source = source;
                if by_operator && !stop.by_operator {
                    stop.by_operator = true;
                    stop.uid = uid;
                }
                self.audit(now, format!("STOP #{id} latched again by {why}"));
            }
            None => {
                self.stops.push(Stop {
                    id,
                    owner: owner.to_owned(),
                    cause,
                    reason: reason.to_owned(),
                    at: now,
                    by_operator,
                    uid,
                    source,
                });
                self.audit(now, format!("STOP #{id} latched by {why}"));
            }
        }
        self.revoke(now, None, &format!("stop by {why}"));
        self.disarm_autonomy(now, "the stop");
        id
    }

    /// A gap: the gateway lost control or knowledge of the chassis. Latches a stop owned by the
    /// gateway with `cause`; while `present`, the cause persists and the stop cannot be
    /// released.
    pub fn handle_gap(&mut self, now: Duration, cause: StopCause, detail: &str, present: bool) {
        if present && !self.present.contains(&cause) {
            self.present.push(cause);
        }
        self.latch(
            now,
            Latch {
                owner: GATEWAY,
                cause,
                reason: detail,
                source: None,
                by_operator: false,
                uid: None,
            },
        );
    }

    /// A gap's cause is gone: its stop can be released (it is not released by itself).
    pub fn handle_gap_cleared(&mut self, now: Duration, cause: StopCause) {
        if let Some(at) = self.present.iter().position(|c| *c == cause) {
            self.present.swap_remove(at);
            self.audit(now, format!("{cause} cleared: the stop can be released"));
        }
    }

    fn disarm_autonomy(&mut self, now: Duration, why: &str) {
        if self.autonomy_armed && !self.config.auto_resume {
            self.audit(
                now,
                format!("autonomy disarmed after {why}: resume to re-arm"),
            );
            self.autonomy_armed = false;
        }
        self.revoke(
            now,
            Some(Class::Autonomy),
            &format!("autonomy disarmed after {why}"),
        );
    }

    fn source_index(&mut self, client: &ClientKey, now: Duration) -> Result<usize, Rejection> {
        if let Some(index) = self.sources.iter().position(|s| s.key.port == client.port) {
            return Ok(index);
        }
        if self.sources.len() >= MAX_SOURCES {
            // Forget the quietest client that holds nothing and keeps no heartbeat.
            let idle = self
                .sources
                .iter()
                .enumerate()
                .filter(|(_, s)| s.lease.is_none() && s.heartbeat.is_none())
                .min_by_key(|(_, s)| s.last_seen)
                .map(|(i, _)| i)
                .ok_or(Rejection::TooManyClients)?;
            self.sources.swap_remove(idle);
        }
        self.sources.push(Source {
            key: client.clone(),
            lease: None,
            revoked: None,
            lost_control: None,
            heartbeat: None,
            budget: TokenBucket::full(f64::from(self.config.request_burst), now),
            last_seen: now,
            requests: 0,
        });
        Ok(self.sources.len() - 1)
    }

    /// Takes one request from the source's budget, or refuses it.
    fn spend(&mut self, index: usize, now: Duration) -> Result<(), Rejection> {
        let (rate, burst) = (
            self.config.request_rate_hz,
            f64::from(self.config.request_burst),
        );
        if self.sources[index].budget.take(now, rate, burst) {
            Ok(())
        } else {
            Err(Rejection::RateLimited { rate })
        }
    }

    /// The client processes of `node` are gone (dead-process detection): their control ends at
    /// once, and a heartbeat source among them latches a stop.
    pub fn handle_node_gone(&mut self, now: Duration, node: u128) {
        let gone: Vec<Source> = self
            .sources
            .iter()
            .filter(|s| s.key.node == node)
            .cloned()
            .collect();
        self.sources.retain(|s| s.key.node != node);
        for source in gone {
            if let Some(lease) = source.lease {
                self.audit(
                    now,
                    format!("{} {} died: control ended", lease.class, source.key.name),
                );
                self.disarm_autonomy(now, "a driving client died");
            }
            if source.heartbeat.is_some() {
                self.latch(
                    now,
                    Latch {
                        owner: &source.key.name,
                        cause: StopCause::Heartbeat,
                        reason: "heartbeat source died",
                        source: None,
                        by_operator: false,
                        uid: source.key.uid,
                    },
                );
            }
        }
    }

    /// Ends stale leases and latches a stop for each newly missed heartbeat.
    fn expire(&mut self, now: Duration) {
        let mut stale = Vec::new();
        let mut missed = Vec::new();
        for (index, source) in self.sources.iter_mut().enumerate() {
            if let Some(lease) = source.lease {
                // Control lasts the class's age from the last command's arrival, however old
                // the command was when it came: a link whose every command comes late but
                // within its life drives on; the command itself still stops at its own life.
                let age = self.config.max_age(lease.class);
                let quiet = match lease.command {
                    Some(_) => age,
                    None => age.max(FIRST_COMMAND_WITHIN),
                };
                if now >= lease.heard + quiet {
                    stale.push(index);
                }
            }
            if let Some(heartbeat) = source.heartbeat.as_mut()
                && !heartbeat.silent
                && now.saturating_sub(source.last_seen) > heartbeat.period
            {
                heartbeat.silent = true;
                missed.push((source.key.clone(), heartbeat.period));
            }
        }
        for index in stale {
            self.end_lease(now, index, "stale: no command within its class's age");
            self.sources[index].lost_control = Some(now);
        }
        for (key, period) in missed {
            let reason = format!("heartbeat missed (period {} ms)", period.as_millis());
            self.latch(
                now,
                Latch {
                    owner: &key.name,
                    cause: StopCause::Heartbeat,
                    reason: &reason,
                    source: Some(key.port),
                    by_operator: false,
                    uid: key.uid,
                },
            );
        }
    }

    /// The motion command for the tick at `now`, `period` after the previous one.
    pub fn poll_output(&mut self, now: Duration, period: Duration) -> Output {
        self.expire(now);
        let fault_clear = match self.fault_clears.front_mut() {
            Some((code, left)) => {
                let code = *code;
                *left -= 1;
                if *left == 0 {
                    self.fault_clears.pop_front();
                }
                code
            }
            None => FaultClear::None,
        };
        // Nothing is selected while a stop holds.
        let target = self
            .selected(now)
            .and_then(|(source, _)| source.fresh_command(now));
        if let Some(command) = target {
            self.motion_until = command.expires;
        }
        // A stop skips the ramp; so does the end of the life of the command that last drove
        // the output (its sender went silent, or let go and the ramp outlasted it): nothing
        // moves on a command longer than its sender asked.
        if !self.stops.is_empty() || (target.is_none() && now >= self.motion_until) {
            self.output = Output {
                fault_clear,
                ..Output::STOP
            };
            return self.output;
        }
        let (linear, lateral, angular, named, clamped) = target
            .map_or((0.0, 0.0, 0.0, None, false), |c| {
                (c.linear, c.lateral, c.angular, c.mode, c.clamped)
            });
        // Sideways no faster than the chassis goes now (it may have stopped being able to).
        let sideways = self.sideways.limit();
        let (lateral, clamped) = (
            lateral.clamp(-sideways, sideways),
            clamped || lateral.abs() > sideways,
        );
        // In motion modes: a drive the mode the chassis is in does not carry (or in another
        // mode than the one the client named) ramps to zero, asking for the mode that does
        // (changed standing still).
        let target = (linear, lateral, angular);
        let drive = target != (0.0, 0.0, 0.0);
        let ((linear, lateral, angular), mode) = match self.turning {
            Turning::Modes { .. } => match self.settled {
                Some(mode)
                    if named.is_none_or(|named| named == mode)
                        && crate::modes::carries(mode, target) =>
                {
                    (target, Some(mode))
                }
                settled => (
                    (0.0, 0.0, 0.0),
                    named.or_else(|| crate::modes::wanted(target)).or(settled),
                ),
            },
            Turning::InPlace | Turning::Radius { .. } => (target, None),
        };
        let clamped = clamped || (linear, lateral, angular) != target;
        let dt = period.as_secs_f64();
        let limits = self.config.limits;
        let next_linear = ramp(
            self.output.linear,
            linear,
            limits.linear_acceleration,
            limits.linear_deceleration,
            dt,
        );
        let next_lateral = ramp(
            self.output.lateral.clamp(-sideways, sideways),
            lateral,
            limits.lateral_acceleration,
            limits.lateral_deceleration,
            dt,
        );
        let next_angular = ramp(
            self.output.angular,
            angular,
            limits.angular_acceleration,
            limits.angular_deceleration,
            dt,
        );
        // A steered chassis turns only as tight as it can at the speed it goes now: while the
        // speed ramps, so does the turn.
        let next_angular = self
            .turning
            .limit(next_linear)
            .map_or(next_angular, |limit| next_angular.clamp(-limit, limit));
        // In motion modes, only what the mode the chassis is in carries: nothing while it
        // changes (the ramp starts again from zero).
        let (next_linear, next_lateral, next_angular) = match self.turning {
            Turning::Modes { min_radius } => crate::modes::hold(
                (next_linear, next_lateral, next_angular),
                self.settled,
                min_radius,
            ),
            Turning::InPlace | Turning::Radius { .. } => (next_linear, next_lateral, next_angular),
        };
        let (next_linear, next_lateral, next_angular) = match self.held {
            true => (0.0, 0.0, 0.0),
            false => (next_linear, next_lateral, next_angular),
        };
        self.output = Output {
            linear: next_linear,
            lateral: next_lateral,
            angular: next_angular,
            fault_clear,
            limited: clamped
                || next_linear != linear
                || next_lateral != lateral
                || next_angular != angular,
            mode,
            drive,
        };
        self.output
    }
}

/// One step from `current` toward `target`: at most `deceleration * dt` toward zero (stopping at
/// zero before a reversal) and at most `acceleration * dt` away from it.
fn ramp(current: f64, target: f64, acceleration: f64, deceleration: f64, dt: f64) -> f64 {
    let same_direction = target != 0.0 && target.signum() == current.signum();
    let braking = current != 0.0 && !(same_direction && target.abs() >= current.abs());
    if braking {
        let floor = if same_direction { target } else { 0.0 };
        let step = (current - floor).abs().min(deceleration * dt);
        current - current.signum() * step
    } else {
        let step = (target - current).abs().min(acceleration * dt);
        current + (target - current).signum() * step
    }
}

#[cfg(test)]
#[path = "arbiter_tests.rs"]
mod tests;
