//! The command arbiter: which client drives, every tick, and what reaches the wheels. Sans-IO:
//! requests and time in, the motion output and status out.
//!
//! Priority: a latched safety stop > teleop > autonomy. The stop latches at once from any client
//! and holds until an explicit release; release never restarts motion by itself. Within a class
//! the holder keeps control until it releases, goes stale or its process dies. Commands live for
//! their TTL or the class's maximum age, whichever is shorter. After a teleop takeover, a stop or
//! a release, autonomy stays disarmed until `resume`. The output is capped, then rate-limited;
//! only the stop skips the ramp.

use std::collections::VecDeque;
use std::time::Duration;

use scout_protocol::FaultClear;
use scout_protocol::units::{DEFAULT_MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED};
use serde::{Deserialize, Serialize};
use tracing::info;

/// The hard ceiling on any command's age: the chassis' own timeout.
pub const MAX_COMMAND_AGE: Duration = Duration::from_millis(500);
/// The heartbeat periods a stop source may register.
pub const HEARTBEAT_PERIODS: std::ops::RangeInclusive<Duration> =
    Duration::from_millis(20)..=Duration::from_secs(10);
/// Motion commands that carry a requested fault-clear code.
pub const FAULT_CLEAR_FRAMES: u8 = 3;
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
    /// Caps for teleop, within the global ones.
    pub teleop_caps: Caps,
    /// Caps for autonomy, within the global ones.
    pub autonomy_caps: Caps,
    /// Acceleration and deceleration limits.
    pub limits: RateLimits,
}

impl Default for ArbiterConfig {
    fn default() -> Self {
        Self {
            teleop_max_age_ms: 250,
            autonomy_max_age_ms: 500,
            auto_resume: false,
            teleop_caps: Caps {
                linear: MAX_LINEAR_SPEED,
                angular: DEFAULT_MAX_ANGULAR_SPEED,
            },
            autonomy_caps: Caps {
                linear: MAX_LINEAR_SPEED,
                angular: DEFAULT_MAX_ANGULAR_SPEED,
            },
            limits: RateLimits {
                linear_acceleration: 1.0,
                linear_deceleration: 2.0,
                angular_acceleration: 1.5,
                angular_deceleration: 3.0,
            },
        }
    }
}

impl ArbiterConfig {
    /// Checks the values; the error says which and why.
    pub fn validate(&self) -> Result<(), String> {
        for (name, ms) in [
            ("teleop_max_age_ms", self.teleop_max_age_ms),
            ("autonomy_max_age_ms", self.autonomy_max_age_ms),
        ] {
            if ms == 0 || ms > MAX_COMMAND_AGE.as_millis() as u64 {
                return Err(format!(
                    "arbiter.{name} must be 1..={max} (the chassis stops after {max} ms), found {ms}",
                    max = MAX_COMMAND_AGE.as_millis()
                ));
            }
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let caps = [self.teleop_caps, self.autonomy_caps];
        let limits = self.limits;
        let all = caps.iter().flat_map(|c| [c.linear, c.angular]).chain([
            limits.linear_acceleration,
            limits.linear_deceleration,
            limits.angular_acceleration,
            limits.angular_deceleration,
        ]);
        if all.into_iter().all(positive) {
            Ok(())
        } else {
            Err("arbiter caps and limits must be positive numbers".into())
        }
    }

    fn max_age(&self, class: Class) -> Duration {
        Duration::from_millis(match class {
            Class::Teleop => self.teleop_max_age_ms,
            Class::Autonomy => self.autonomy_max_age_ms,
        })
    }

    fn caps(&self, class: Class) -> Caps {
        match class {
            Class::Teleop => self.teleop_caps,
            Class::Autonomy => self.autonomy_caps,
        }
    }
}

/// Who sent a request: the client's name and its iceoryx2 node (process).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct ClientKey {
    /// The name the client gave.
    pub name: String,
    /// Its iceoryx2 node id, for dead-process detection.
    pub node: u128,
}

/// The motion command for one tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Output {
    /// m/s.
    pub linear: f64,
    /// rad/s.
    pub angular: f64,
    /// The fault-clear code for byte 1.
    pub fault_clear: FaultClear,
    /// A cap or rate limit holds the output below what the selected client asked.
    pub limited: bool,
}

impl Output {
    /// Zero speed, nothing to clear.
    pub const STOP: Output = Output {
        linear: 0.0,
        angular: 0.0,
        fault_clear: FaultClear::None,
        limited: false,
    };
}

/// A command a client sent.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Command {
    class: Class,
    linear: f64,
    angular: f64,
    clamped: bool,
    expires: Duration,
}

/// One client the arbiter knows.
#[derive(Debug, Clone, PartialEq)]
pub struct Source {
    /// Who.
    pub key: ClientKey,
    /// The class it holds, if it holds one.
    pub holding: Option<Class>,
    command: Option<Command>,
    heartbeat: Option<Duration>,
    /// When it last sent a request.
    pub last_seen: Duration,
    /// Requests it sent.
    pub requests: u64,
}

impl Source {
    /// Its heartbeat period, if registered.
    pub fn heartbeat(&self) -> Option<Duration> {
        self.heartbeat
    }

    /// The class of its last command.
    pub fn class(&self) -> Option<Class> {
        self.command.map(|c| c.class)
    }

    fn fresh_command(&self, now: Duration) -> Option<Command> {
        self.command.filter(|command| now < command.expires)
    }
}

/// The latched stop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Latch {
    /// Who latched it.
    pub by: String,
    /// Why.
    pub reason: String,
    /// When.
    pub at: Duration,
}

/// The arbiter.
#[derive(Debug, Clone)]
pub struct Arbiter {
    config: ArbiterConfig,
    global: Caps,
    latch: Option<Latch>,
    autonomy_armed: bool,
    sources: Vec<Source>,
    output: Output,
    fault_clears: VecDeque<(FaultClear, u8)>,
    lights: Option<LightsSetting>,
    rejections: [u64; REJECTION_COUNTERS],
    urgent_stop: bool,
}

impl Arbiter {
    /// An arbiter with `config` for a chassis whose maximum angular speed is `max_angular`.
    pub fn new(config: ArbiterConfig, max_angular: f64) -> Self {
        Self {
            config,
            global: Caps {
                linear: MAX_LINEAR_SPEED,
                angular: max_angular,
            },
            latch: None,
            autonomy_armed: true,
            sources: Vec::new(),
            output: Output::STOP,
            fault_clears: VecDeque::new(),
            lights: None,
            rejections: [0; REJECTION_COUNTERS],
            urgent_stop: false,
        }
    }

    /// The latched stop, if any.
    pub fn latch(&self) -> Option<&Latch> {
        self.latch.as_ref()
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

    /// Counts a request refused before it reached the arbiter (malformed on the wire).
    pub fn count_rejection(&mut self, rejection: &Rejection) {
        self.rejections[usize::from(rejection.kind().raw())] += 1;
    }

    /// Whether a stop latched since the last call: the caller sends zero at once, not at the
    /// next tick.
    pub fn take_urgent_stop(&mut self) -> bool {
        std::mem::take(&mut self.urgent_stop)
    }

    /// The source sending, by class, if one holds it with a fresh command.
    pub fn selected(&self, now: Duration) -> Option<(&Source, Class)> {
        if self.latch.is_some() {
            return None;
        }
        let holder = |class: Class| {
            self.sources
                .iter()
                .find(|s| s.holding == Some(class) && s.fresh_command(now).is_some())
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

    /// Handles one request at `now`.
    pub fn handle_request(
        &mut self,
        now: Duration,
        client: &ClientKey,
        request: Request,
    ) -> Answer {
        self.expire(now);
        let answer = self.decide(now, client, request);
        if let Err(rejection) = &answer {
            self.count_rejection(rejection);
        }
        answer
    }

    fn decide(&mut self, now: Duration, client: &ClientKey, request: Request) -> Answer {
        let index = self.source_index(client, now)?;
        self.sources[index].last_seen = now;
        self.sources[index].requests += 1;
        let accepted = Ok(Accepted { clamped: false });
        match request {
            Request::Stop { reason } => {
                self.latch_stop(now, &client.name, &reason);
                accepted
            }
            Request::Drive {
                class,
                linear,
                angular,
                ttl,
            } => self.drive(now, index, class, linear, angular, ttl),
            Request::Release => {
                if let Some(latch) = self.latch.take() {
                    info!(
                        "{}: stop released by {} (latched by {}: {})",
                        secs(now),
                        client.name,
                        latch.by,
                        latch.reason
                    );
                    for source in &mut self.sources {
                        source.command = None;
                    }
                }
                let source = &mut self.sources[index];
                if let Some(class) = source.holding.take() {
                    info!(
                        "{}: {} {} released control",
                        secs(now),
                        class.name(),
                        client.name
                    );
                }
                source.command = None;
                self.disarm_autonomy(now, "a release");
                accepted
            }
            Request::Relinquish => {
                let source = &mut self.sources[index];
                if let Some(class) = source.holding.take() {
                    info!(
                        "{}: {} {} relinquished control",
                        secs(now),
                        class.name(),
                        client.name
                    );
                }
                source.command = None;
                accepted
            }
            Request::Resume => {
                if let Some(latch) = &self.latch {
                    return Err(Rejection::Latched {
                        by: latch.by.clone(),
                    });
                }
                if !self.autonomy_armed {
                    info!("{}: autonomy armed by {}", secs(now), client.name);
                }
                self.autonomy_armed = true;
                accepted
            }
            Request::Lights(setting) => {
                self.lights = Some(setting);
                accepted
            }
            Request::ClearFault(code) => {
                let codes = match code {
                    None => FaultClear::ALL.to_vec(),
                    Some(FaultClear::None) => {
                        return Err(Rejection::Malformed("no fault to clear".into()));
                    }
                    Some(code) => vec![code],
                };
                info!("{}: {} clears faults {codes:?}", secs(now), client.name);
                self.fault_clears = codes
                    .into_iter()
                    .map(|code| (code, FAULT_CLEAR_FRAMES))
                    .collect();
                accepted
            }
            Request::Heartbeat { period } => {
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
                        info!(
                            "{}: {} is a heartbeat stop source ({period:?})",
                            secs(now),
                            client.name
                        );
                    }
                    self.sources[index].heartbeat = Some(period);
                }
                accepted
            }
            // The state tracker resets the odometry; to the arbiter it is a beat.
            Request::ResetOdometry => accepted,
        }
    }

    fn drive(
        &mut self,
        now: Duration,
        index: usize,
        class: Class,
        linear: f64,
        angular: f64,
        ttl: Option<Duration>,
    ) -> Answer {
        if !(linear.is_finite() && angular.is_finite()) {
            return Err(Rejection::NotFinite);
        }
        if let Some(latch) = &self.latch {
            return Err(Rejection::Latched {
                by: latch.by.clone(),
            });
        }
        if class == Class::Autonomy && !self.autonomy_armed {
            return Err(Rejection::AutonomyDisarmed);
        }
        if let Some(holder) = self
            .sources
            .iter()
            .enumerate()
            .find(|(i, s)| *i != index && s.holding == Some(class))
            .map(|(_, s)| s)
        {
            return Err(Rejection::Held {
                class,
                holder: holder.key.name.clone(),
            });
        }
        let caps = self.config.caps(class);
        let (linear_cap, angular_cap) = (
            caps.linear.min(self.global.linear),
            caps.angular.min(self.global.angular),
        );
        let clamped_linear = linear.clamp(-linear_cap, linear_cap);
        let clamped_angular = angular.clamp(-angular_cap, angular_cap);
        let clamped = clamped_linear != linear || clamped_angular != angular;
        let age = ttl.map_or(self.config.max_age(class), |ttl| {
            ttl.min(self.config.max_age(class))
        });
        let source = &mut self.sources[index];
        if let Some(previous) = source.holding.filter(|held| *held != class) {
            info!(
                "{}: {} switches from {} to {}",
                secs(now),
                source.key.name,
                previous.name(),
                class.name()
            );
        }
        if source.holding != Some(class) {
            info!(
                "{}: {} {} takes control",
                secs(now),
                class.name(),
                source.key.name
            );
        }
        source.holding = Some(class);
        source.command = Some(Command {
            class,
            linear: clamped_linear,
            angular: clamped_angular,
            clamped,
            expires: now + age,
        });
        if class == Class::Teleop {
            let name = source.key.name.clone();
            self.disarm_autonomy(now, &format!("teleop {name} took over"));
        }
        Ok(Accepted { clamped })
    }

    fn latch_stop(&mut self, now: Duration, by: &str, reason: &str) {
        if self.latch.is_none() {
            info!("{}: STOP latched by {by}: {reason}", secs(now));
            self.latch = Some(Latch {
                by: by.to_owned(),
                reason: reason.to_owned(),
                at: now,
            });
        }
        for source in &mut self.sources {
            source.holding = None;
            source.command = None;
        }
        self.output = Output::STOP;
        self.urgent_stop = true;
        self.disarm_autonomy(now, "the stop");
    }

    fn disarm_autonomy(&mut self, now: Duration, why: &str) {
        if self.autonomy_armed && !self.config.auto_resume {
            info!(
                "{}: autonomy disarmed after {why}: resume to re-arm",
                secs(now)
            );
            self.autonomy_armed = false;
        }
    }

    fn source_index(&mut self, client: &ClientKey, now: Duration) -> Result<usize, Rejection> {
        if client.name.is_empty() {
            return Err(Rejection::Malformed("client name is empty".into()));
        }
        if let Some(index) = self.sources.iter().position(|s| s.key == *client) {
            return Ok(index);
        }
        if self.sources.len() >= MAX_SOURCES {
            // Forget the quietest client that holds nothing and keeps no heartbeat.
            let idle = self
                .sources
                .iter()
                .enumerate()
                .filter(|(_, s)| s.holding.is_none() && s.heartbeat.is_none())
                .min_by_key(|(_, s)| s.last_seen)
                .map(|(i, _)| i)
                .ok_or(Rejection::TooManyClients)?;
            self.sources.swap_remove(idle);
        }
        self.sources.push(Source {
            key: client.clone(),
            holding: None,
            command: None,
            heartbeat: None,
            last_seen: now,
            requests: 0,
        });
        Ok(self.sources.len() - 1)
    }

    /// The client processes of `node` are gone (dead-process detection): their control is
    /// released at once, and a heartbeat source among them latches the stop.
    pub fn handle_node_gone(&mut self, now: Duration, node: u128) {
        let gone: Vec<Source> = self
            .sources
            .iter()
            .filter(|s| s.key.node == node)
            .cloned()
            .collect();
        self.sources.retain(|s| s.key.node != node);
        for source in gone {
            if let Some(class) = source.holding {
                info!(
                    "{}: {} {} died: control released",
                    secs(now),
                    class.name(),
                    source.key.name
                );
                self.disarm_autonomy(now, "a driving client died");
            }
            if source.heartbeat.is_some() {
                self.latch_stop(now, &source.key.name, "heartbeat source died");
            }
        }
    }

    /// Drops stale holds and latches the stop for missed heartbeats.
    fn expire(&mut self, now: Duration) {
        let mut missed = Vec::new();
        for source in &mut self.sources {
            if let Some(class) = source.holding
                && source.fresh_command(now).is_none()
            {
                info!(
                    "{}: {} {} went stale: control released",
                    secs(now),
                    class.name(),
                    source.key.name
                );
                source.holding = None;
            }
            if let Some(period) = source.heartbeat
                && now.saturating_sub(source.last_seen) > period
            {
                source.heartbeat = None;
                missed.push((source.key.name.clone(), period));
            }
        }
        for (name, period) in missed {
            self.latch_stop(
                now,
                &name,
                &format!("heartbeat missed (period {} ms)", period.as_millis()),
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
        if self.latch.is_some() {
            self.output = Output {
                fault_clear,
                ..Output::STOP
            };
            return self.output;
        }
        let target = self
            .selected(now)
            .and_then(|(source, _)| source.fresh_command(now));
        let (linear, angular, clamped) =
            target.map_or((0.0, 0.0, false), |c| (c.linear, c.angular, c.clamped));
        let dt = period.as_secs_f64();
        let limits = self.config.limits;
        let next_linear = ramp(
            self.output.linear,
            linear,
            limits.linear_acceleration,
            limits.linear_deceleration,
            dt,
        );
        let next_angular = ramp(
            self.output.angular,
            angular,
            limits.angular_acceleration,
            limits.angular_deceleration,
            dt,
        );
        self.output = Output {
            linear: next_linear,
            angular: next_angular,
            fault_clear,
            limited: clamped || next_linear != linear || next_angular != angular,
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

fn secs(now: Duration) -> String {
    format!("t={:.3}s", now.as_secs_f64())
}

#[cfg(test)]
#[path = "arbiter_tests.rs"]
mod tests;
