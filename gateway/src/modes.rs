//! A Ranger's motion modes, without I/O: the mode a body velocity needs, whether the mode the
//! chassis is in carries it, how a velocity no mode carries is brought to one, and the
//! handshake that changes the mode ([`Handshake`]).
//!
//! Mode selection as the vendor's driver does it (agilexrobotics/ranger_ros2
//! `ranger_messenger.cpp` `TwistCmdCallback`): sideways is parallel, a turn tighter than the
//! minimum radius spins in place, anything else is dual Ackermann. What differs: a drive
//! straight ahead stays in parallel mode when the chassis is in it (no stop to change to dual
//! Ackermann for the wheels to point the way they already do), and a velocity is only ever
//! carried in a mode the chassis reports it is in (0x291), never while it changes.

use std::time::Duration;

use scout_protocol::v2::{MotionModeStateV2, MotionModeV2, MotionV2};

use crate::standstill::Standstill;

/// A body velocity: m/s forward, m/s leftward, rad/s counter-clockwise.
pub type Velocity = (f64, f64, f64);

/// Below this a speed (m/s) or a yaw rate (rad/s) is zero: half of the wire's unit, what rounds
/// to nothing in 0x111. Noise in a client's command never asks for a mode change.
pub const RESOLUTION: f64 = 0.0005;

/// The mode that carries `velocity` (`None` for zero, which every mode carries).
pub fn wanted(velocity: Velocity) -> Option<MotionModeV2> {
    let (linear, lateral, angular) = velocity;
    if lateral != 0.0 {
        Some(MotionModeV2::Parallel)
    } else if linear != 0.0 {
        Some(MotionModeV2::DualAckermann)
    } else if angular != 0.0 {
        Some(MotionModeV2::Spin)
    } else {
        None
    }
}

/// Whether a chassis in `mode` moves at `velocity`: dual Ackermann forward with or without
/// a turn, parallel forward and sideways without one, spin a turn in place; park, side slip
/// (which this gateway never asks for) and a mode no source names carry nothing but zero.
pub fn carries(mode: MotionModeV2, (linear, lateral, angular): Velocity) -> bool {
    match mode {
        MotionModeV2::DualAckermann => lateral == 0.0 && (angular == 0.0 || linear != 0.0),
        MotionModeV2::Parallel => angular == 0.0,
        MotionModeV2::Spin => linear == 0.0 && lateral == 0.0,
        MotionModeV2::Park | MotionModeV2::SideSlip | MotionModeV2::Unknown(_) => {
            linear == 0.0 && lateral == 0.0 && angular == 0.0
        }
    }
}

/// `velocity` as one mode carries it, within `caps` (m/s forward, m/s sideways, rad/s; the
/// wheels no faster than the forward cap): below [`RESOLUTION`] a component is zero; sideways
/// keeps its direction, scaled once to every cap, and drops the turn (parallel mode does not
/// turn); a turn tighter than `min_radius` m spins in place and drops the forward speed (as
/// the vendor's driver does). Whatever changed is the caller's to answer as clamped.
pub fn one_mode(velocity: Velocity, min_radius: f64, caps: Velocity) -> Velocity {
    let quiet = |value: f64| if value.abs() < RESOLUTION { 0.0 } else { value };
    let (linear, lateral, angular) = (quiet(velocity.0), quiet(velocity.1), quiet(velocity.2));
    let (linear_cap, lateral_cap, angular_cap) = caps;
    if lateral != 0.0 {
        let scale = [
            linear_cap / linear.abs(),
            lateral_cap / lateral.abs(),
            linear_cap / linear.hypot(lateral),
        ]
        .into_iter()
        .fold(1.0, f64::min);
        return (linear * scale, lateral * scale, 0.0);
    }
    let linear = linear.clamp(-linear_cap, linear_cap);
    let angular = angular.clamp(-angular_cap, angular_cap);
    if linear.abs() < min_radius * angular.abs() {
        (0.0, 0.0, angular)
    } else {
        (linear, 0.0, angular)
    }
}

/// `velocity` in the mode a client named, within `caps` and `min_radius` as [`one_mode`]
/// brings it (below [`RESOLUTION`] zero; sideways scaled once to every cap; dual Ackermann no
/// tighter than `min_radius`), or why that mode cannot carry it: a client that names a mode is
/// told what the mode does not do, never driven in another.
pub fn in_mode(
    mode: MotionModeV2,
    velocity: Velocity,
    min_radius: f64,
    caps: Velocity,
) -> Result<Velocity, String> {
    let quiet = |value: f64| if value.abs() < RESOLUTION { 0.0 } else { value };
    let (linear, lateral, angular) = (quiet(velocity.0), quiet(velocity.1), quiet(velocity.2));
    let (linear_cap, _, angular_cap) = caps;
    let refused = |what: &str| Err(format!("{mode} mode {what}"));
    match mode {
        MotionModeV2::DualAckermann if lateral != 0.0 => {
            refused("does not move sideways: ask parallel mode, or no mode")
        }
        MotionModeV2::DualAckermann if linear == 0.0 && angular != 0.0 => {
            refused("does not turn in place: ask spin mode, or no mode")
        }
        MotionModeV2::DualAckermann => {
            let linear = linear.clamp(-linear_cap, linear_cap);
            let limit = (linear.abs() / min_radius).min(angular_cap);
            Ok((linear, 0.0, angular.clamp(-limit, limit)))
        }
        MotionModeV2::Parallel if angular != 0.0 => {
            refused("does not turn: ask without a yaw rate, or no mode")
        }
        MotionModeV2::Parallel => Ok(one_mode((linear, lateral, 0.0), min_radius, caps)),
        MotionModeV2::Spin if linear != 0.0 || lateral != 0.0 => {
            refused("turns in place: ask without a forward or sideways speed, or no mode")
        }
        MotionModeV2::Spin => Ok((0.0, 0.0, angular.clamp(-angular_cap, angular_cap))),
        MotionModeV2::Park if (linear, lateral, angular) != (0.0, 0.0, 0.0) => {
            refused("holds the robot still: ask zero velocity, or another mode to move")
        }
        MotionModeV2::Park => Ok((0.0, 0.0, 0.0)),
        MotionModeV2::SideSlip | MotionModeV2::Unknown(_) => {
            refused("is not one the gateway drives in (dual_ackermann, parallel, spin, park)")
        }
    }
}

/// `output` as the chassis in `settled` (`None`: changing, or not reported yet) carries it this
/// tick: in dual Ackermann no tighter than `min_radius` at the speed it goes now, in parallel
/// without a turn, spinning without moving off; changing, nothing at all.
pub fn hold(output: Velocity, settled: Option<MotionModeV2>, min_radius: f64) -> Velocity {
    let (linear, lateral, angular) = output;
    match settled {
        Some(MotionModeV2::DualAckermann) => {
            let limit = linear.abs() / min_radius;
            (linear, 0.0, angular.clamp(-limit, limit))
        }
        Some(MotionModeV2::Parallel) => (linear, lateral, 0.0),
        Some(MotionModeV2::Spin) => (0.0, 0.0, angular),
        Some(MotionModeV2::Park | MotionModeV2::SideSlip | MotionModeV2::Unknown(_)) | None => {
            (0.0, 0.0, 0.0)
        }
    }
}

/// How long a chassis may take to say it is changing to a mode asked for (0x291): meanwhile
/// nothing moves, and nothing is asked again.
pub const REQUEST_WAIT: Duration = Duration::from_millis(500);

/// A mode change as the gateway makes it with a Ranger, sans-IO: what the chassis reports
/// (0x291, 0x221) and what was sent in; the mode the arbiter may drive in, and when to ask
/// for another (0x141), out. A mode is asked for only standing still ([`Standstill`]), in a
/// mode the gateway may leave (never park, side slip or one no source names: someone put it
/// there), at most once a [`REQUEST_WAIT`]; from the ask until the chassis says it took it, or
/// the wait ends, the arbiter drives in no mode. A mode the chassis takes unasked is reported
/// once.
#[derive(Debug, Clone, Default)]
pub struct Handshake {
    /// 0x291 as last reported, since the port opened.
    reported: Option<MotionModeStateV2>,
    /// The mode asked for last, and when (cleared when the chassis reports taking it, or the
    /// wait ends).
    pending: Option<(MotionModeV2, Duration)>,
    /// The mode asked for last, kept until the wait ends: a report of taking it meanwhile is
    /// no surprise.
    asked: Option<MotionModeV2>,
    /// The mode the chassis took while the gateway's request for it was pending: the
    /// gateway's own (a park it may leave), until the chassis takes another unasked.
    ours: Option<MotionModeV2>,
    /// Whether it stands still.
    standstill: Standstill,
}

impl Handshake {
    /// A new port: nothing reported, nothing asked.
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// 0x221 as received.
    pub fn handle_motion_state(&mut self, now: Duration, motion: &MotionV2) {
        self.standstill.handle_motion_state(now, motion);
    }

    /// A motion command went out at `sent` (forward, sideways, yaw rate).
    pub fn handle_sent(&mut self, now: Duration, sent: Velocity) {
        self.standstill.handle_sent(now, sent);
    }

    /// 0x291 at `now`. Returns `Some(why)` when the chassis left the mode it was in (settled
    /// or changing to) for one the gateway did not ask for (its RC, its own doing): a stop's
    /// reason.
    pub fn handle_report(&mut self, now: Duration, report: MotionModeStateV2) -> Option<String> {
        self.expire(now);
        let before = self.reported.replace(report);
        if self.pending.is_some_and(|(mode, _)| mode == report.mode) {
            self.pending = None;
            self.ours = Some(report.mode);
        }
        let left = before.map(|before| before.mode);
        let unasked = match left {
            Some(left) if left != report.mode && self.asked != Some(report.mode) => Some(left),
            _ => None,
        };
        // Taken and settled: no longer asked (the same mode later, unasked, is a change).
        if report.settled().is_some() && self.asked == Some(report.mode) && self.pending.is_none() {
            self.asked = None;
        }
        match unasked {
            Some(left) => {
                // Someone else's mode now: what the gateway asked before no longer holds (a
                // park of its own the RC left and came back to is the RC's).
                self.asked = None;
                self.ours = None;
                Some(format!(
                    "the chassis left {left} mode for {} mode unasked (0x291): check who \
                     changed it (its RC), then release the stop and take control again",
                    report.mode
                ))
            }
            _ => None,
        }
    }

    /// 0x291 as last reported since the port opened.
    pub fn reported(&self) -> Option<MotionModeStateV2> {
        self.reported
    }

    /// Whether 0x291 says something new (its mode, or whether it changes), for the log.
    pub fn is_news(&self, report: &MotionModeStateV2) -> bool {
        self.reported.map(|r| (r.mode, r.changing != 0))
            != Some((report.mode, report.changing != 0))
    }

    /// The mode the arbiter may drive in at `now`: the one the chassis reports settled in,
    /// none while it changes, before it has said, or while a mode asked for is pending.
    pub fn settled(&mut self, now: Duration) -> Option<MotionModeV2> {
        self.expire(now);
        match self.pending {
            Some(_) => None,
            None => self.reported.and_then(|report| report.settled()),
        }
    }

    /// Whether to ask for `wanted` (the arbiter's [`crate::arbiter::Output::mode`]) now, with
    /// `output` going out: only another mode than the one reported settled, one the gateway may
    /// leave, standing still, nothing pending. A `Some` is sent as 0x141 and is pending.
    pub fn poll_request(
        &mut self,
        now: Duration,
        wanted: Option<MotionModeV2>,
        output: Velocity,
    ) -> Option<MotionModeV2> {
        let wanted = wanted?;
        self.expire(now);
        // Nothing asked before the chassis has said its mode: a park it is in already would
        // pass for one the gateway asked for.
        let leavable = match self.reported {
            None => false,
            Some(report) => match report.settled() {
                Some(mode) => mode != wanted && self.may_leave(),
                None => false,
            },
        };
        if !leavable || !self.standstill.is_still(now, output) || self.pending.is_some() {
            return None;
        }
        self.pending = Some((wanted, now));
        self.asked = Some(wanted);
        Some(wanted)
    }

    /// Whether the gateway may take the chassis out of the mode it reports settled in: one it
    /// drives in ([`leavable`]), or park when the chassis took it at a client's request through
    /// the gateway.
    pub fn may_leave(&self) -> bool {
        self.reported
            .and_then(|report| report.settled())
            .is_some_and(|mode| leavable(mode) || self.ours == Some(mode))
    }

    /// A request the chassis did not take within [`REQUEST_WAIT`] is over: taking it later
    /// is a change unasked.
    fn expire(&mut self, now: Duration) {
        if self.pending.is_some_and(|(_, at)| now >= at + REQUEST_WAIT) {
            self.pending = None;
            self.asked = None;
        }
    }
}

/// Whether the gateway may take the chassis out of `mode` by itself: the modes it drives in,
/// not park, side slip or one no source names (someone put it there).
pub fn leavable(mode: MotionModeV2) -> bool {
    match mode {
        MotionModeV2::DualAckermann | MotionModeV2::Parallel | MotionModeV2::Spin => true,
        MotionModeV2::Park | MotionModeV2::SideSlip | MotionModeV2::Unknown(_) => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const RADIUS: f64 = 0.4764;
    const CAPS: Velocity = (1.5, 1.5, 4.8);
    const MS: Duration = Duration::from_millis(1);

    fn report(mode: MotionModeV2, changing: bool) -> MotionModeStateV2 {
        MotionModeStateV2::new(mode, changing)
    }

    fn still() -> MotionV2 {
        MotionV2::default()
    }

    #[test]
    fn a_mode_is_asked_standing_still_and_nothing_moves_until_it_is_taken() {
        let mut handshake = Handshake::default();
        let zero = (0.0, 0.0, 0.0);
        // Nothing reported yet: no mode to drive in; asked once standing still.
        assert_eq!(handshake.settled(Duration::ZERO), None);
        assert_eq!(
            handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false)),
            None
        );
        assert_eq!(
            handshake.settled(Duration::ZERO),
            Some(MotionModeV2::DualAckermann)
        );
        let spin = Some(MotionModeV2::Spin);
        // Not reported still yet, then still but a moving command went out just now.
        assert_eq!(handshake.poll_request(Duration::ZERO, spin, zero), None);
        handshake.handle_motion_state(10 * MS, &still());
        handshake.handle_sent(20 * MS, (0.02, 0.0, 0.0));
        assert_eq!(handshake.poll_request(40 * MS, spin, zero), None);
        assert_eq!(
            handshake.poll_request(120 * MS, spin, (0.01, 0.0, 0.0)),
            None
        );
        assert_eq!(handshake.poll_request(120 * MS, spin, zero), spin);
        // Pending: no mode to drive in, even the one still reported, and no second ask.
        assert_eq!(handshake.settled(140 * MS), None);
        assert_eq!(handshake.poll_request(140 * MS, spin, zero), None);
        assert_eq!(
            handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false)),
            None
        );
        assert_eq!(handshake.settled(160 * MS), None);
        // Taken: changing, then settled.
        assert_eq!(
            handshake.handle_report(Duration::ZERO, report(MotionModeV2::Spin, true)),
            None
        );
        assert_eq!(handshake.settled(180 * MS), None);
        assert_eq!(
            handshake.handle_report(Duration::ZERO, report(MotionModeV2::Spin, false)),
            None
        );
        assert_eq!(handshake.settled(200 * MS), spin);
        // Unasked: the chassis leaves spin for parallel by itself.
        let why = handshake
            .handle_report(Duration::ZERO, report(MotionModeV2::Parallel, false))
            .expect("unasked");
        assert!(
            why.starts_with("the chassis left spin mode for parallel mode unasked"),
            "{why}"
        );
        // Parked by someone: never left by the gateway.
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::Park, false));
        assert_eq!(handshake.poll_request(1000 * MS, spin, zero), None);
    }

    #[test]
    fn a_mode_the_chassis_does_not_take_is_asked_again_after_the_wait() {
        let mut handshake = Handshake::default();
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false));
        handshake.handle_motion_state(Duration::ZERO, &still());
        let parallel = Some(MotionModeV2::Parallel);
        let zero = (0.0, 0.0, 0.0);
        assert_eq!(handshake.poll_request(200 * MS, parallel, zero), parallel);
        assert_eq!(handshake.settled(699 * MS), None);
        assert_eq!(handshake.poll_request(699 * MS, parallel, zero), None);
        // The wait over: the reported mode is driven in again, and asked again.
        assert_eq!(
            handshake.settled(700 * MS),
            Some(MotionModeV2::DualAckermann)
        );
        assert_eq!(handshake.poll_request(700 * MS, parallel, zero), parallel);
    }

    #[test]
    fn the_vendors_selection() {
        assert_eq!(wanted((0.5, 0.2, 0.0)), Some(MotionModeV2::Parallel));
        assert_eq!(wanted((0.0, -0.2, 0.0)), Some(MotionModeV2::Parallel));
        assert_eq!(wanted((0.0, 0.0, 1.0)), Some(MotionModeV2::Spin));
        assert_eq!(wanted((0.5, 0.0, 0.5)), Some(MotionModeV2::DualAckermann));
        assert_eq!(wanted((0.5, 0.0, 0.0)), Some(MotionModeV2::DualAckermann));
        assert_eq!(wanted((0.0, 0.0, 0.0)), None);
        // Turning faster than it drives (ranger_ros2#23: its wheels at 45 degrees, not moving):
        // a spin in place, said to be clamped.
        assert_eq!(one_mode((0.1, 0.0, 1.0), RADIUS, CAPS), (0.0, 0.0, 1.0));
        assert_eq!(one_mode((0.5, 0.0, 1.0), RADIUS, CAPS), (0.5, 0.0, 1.0));
        assert_eq!(one_mode((0.3, 0.4, 0.5), RADIUS, CAPS), (0.3, 0.4, 0.0));
        let (linear, lateral, _) = one_mode((1.5, 1.5, 0.0), RADIUS, CAPS);
        assert!((linear.hypot(lateral) - 1.5).abs() < 1e-12 && linear == lateral);
        // One scale for both axes: the direction asked (3:1) kept under a sideways cap.
        let (linear, lateral, _) = one_mode((3.0, 1.0, 0.0), RADIUS, (1.5, 0.2, 4.8));
        assert!(
            (linear / lateral - 3.0).abs() < 1e-9 && lateral <= 0.2,
            "{linear} {lateral}"
        );
        // Noise below the wire's unit asks for no mode.
        assert_eq!(one_mode((0.5, 1e-12, 1e-9), RADIUS, CAPS), (0.5, 0.0, 0.0));
        // Straight ahead goes on in parallel mode.
        assert!(carries(MotionModeV2::Parallel, (0.5, 0.0, 0.0)));
        assert!(!carries(MotionModeV2::DualAckermann, (0.0, 0.0, 0.5)));
        assert!(!carries(MotionModeV2::Park, (0.1, 0.0, 0.0)));
    }

    #[test]
    fn a_named_mode_carries_what_it_does_and_says_what_it_does_not() {
        use MotionModeV2::*;
        let ahead = (0.5, 0.0, 0.0);
        assert_eq!(in_mode(Parallel, ahead, RADIUS, CAPS), Ok(ahead));
        assert_eq!(in_mode(DualAckermann, ahead, RADIUS, CAPS), Ok(ahead));
        // Held to its circle, as without a mode.
        let (_, _, angular) = in_mode(DualAckermann, (0.1, 0.0, 1.0), RADIUS, CAPS).expect("held");
        assert!((angular - 0.1 / RADIUS).abs() < 1e-12, "{angular}");
        assert_eq!(
            in_mode(Spin, (0.0, 0.0, 9.0), RADIUS, CAPS),
            Ok((0.0, 0.0, 4.8))
        );
        assert_eq!(
            in_mode(Park, (0.0, 0.0, 0.0), RADIUS, CAPS),
            Ok((0.0, 0.0, 0.0))
        );
        for (mode, velocity, why) in [
            (Parallel, (0.5, 0.0, 0.2), "parallel mode does not turn"),
            (
                DualAckermann,
                (0.5, 0.2, 0.0),
                "dual_ackermann mode does not move sideways",
            ),
            (
                DualAckermann,
                (0.0, 0.0, 0.5),
                "dual_ackermann mode does not turn in place",
            ),
            (Spin, (0.1, 0.0, 0.5), "spin mode turns in place"),
            (Park, (0.1, 0.0, 0.0), "park mode holds the robot still"),
            (
                SideSlip,
                (0.0, 0.1, 0.0),
                "side_slip mode is not one the gateway drives in",
            ),
        ] {
            let refused = in_mode(mode, velocity, RADIUS, CAPS).expect_err("refused");
            assert!(refused.starts_with(why), "{refused}");
        }
    }

    #[test]
    fn park_is_left_only_when_the_gateway_asked_for_it() {
        let mut handshake = Handshake::default();
        let zero = (0.0, 0.0, 0.0);
        handshake.handle_motion_state(Duration::ZERO, &still());
        // Someone parked it: not left.
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::Park, false));
        assert!(!handshake.may_leave());
        let ahead = Some(MotionModeV2::DualAckermann);
        assert_eq!(handshake.poll_request(200 * MS, ahead, zero), None);
        // Out of it by its RC, then parked by a client's request through the gateway: left.
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false));
        assert!(handshake.may_leave());
        let park = Some(MotionModeV2::Park);
        assert_eq!(handshake.poll_request(400 * MS, park, zero), park);
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::Park, false));
        assert!(handshake.may_leave());
        // Out of it by its RC and parked again by it: the RC's park, not left.
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::Parallel, false));
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::Park, false));
        assert!(!handshake.may_leave());
        // Parked by a client again: left for a drive.
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false));
        assert_eq!(handshake.poll_request(600 * MS, park, zero), park);
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::Park, false));
        assert_eq!(handshake.poll_request(800 * MS, ahead, zero), ahead);
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false));
        // A park asked and not taken within the wait, then one the RC makes: the RC's.
        assert_eq!(handshake.poll_request(1000 * MS, park, zero), park);
        assert_eq!(
            handshake.settled(1500 * MS),
            Some(MotionModeV2::DualAckermann)
        );
        let why = handshake
            .handle_report(Duration::ZERO, report(MotionModeV2::Park, false))
            .expect("a park the gateway no longer waits for is unasked");
        assert!(why.contains("for park mode unasked"), "{why}");
        assert!(!handshake.may_leave());
    }

    #[test]
    fn a_change_the_rc_makes_mid_change_is_unasked_and_an_old_ask_is_forgotten() {
        let mut handshake = Handshake::default();
        let zero = (0.0, 0.0, 0.0);
        handshake.handle_motion_state(Duration::ZERO, &still());
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false));
        let spin = Some(MotionModeV2::Spin);
        assert_eq!(handshake.poll_request(200 * MS, spin, zero), spin);
        assert_eq!(
            handshake.handle_report(220 * MS, report(MotionModeV2::Spin, true)),
            None
        );
        // The RC parks it while it changes: unasked.
        let why = handshake
            .handle_report(240 * MS, report(MotionModeV2::Park, true))
            .expect("unasked mid-change");
        assert!(
            why.contains("left spin mode for park mode unasked"),
            "{why}"
        );
        // A spin taken and settled is no longer asked: the RC setting spin later is a change.
        let mut handshake = Handshake::default();
        handshake.handle_motion_state(Duration::ZERO, &still());
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::DualAckermann, false));
        assert_eq!(handshake.poll_request(200 * MS, spin, zero), spin);
        handshake.handle_report(220 * MS, report(MotionModeV2::Spin, true));
        handshake.handle_report(400 * MS, report(MotionModeV2::Spin, false));
        assert!(
            handshake
                .handle_report(600 * MS, report(MotionModeV2::DualAckermann, false))
                .is_some()
        );
        assert!(
            handshake
                .handle_report(800 * MS, report(MotionModeV2::Spin, false))
                .is_some()
        );
    }

    #[test]
    fn nothing_is_asked_before_the_chassis_says_its_mode() {
        let mut handshake = Handshake::default();
        handshake.handle_motion_state(Duration::ZERO, &still());
        let park = Some(MotionModeV2::Park);
        assert_eq!(
            handshake.poll_request(200 * MS, park, (0.0, 0.0, 0.0)),
            None
        );
        // The RC had parked it: not the gateway's park.
        handshake.handle_report(Duration::ZERO, report(MotionModeV2::Park, false));
        assert!(!handshake.may_leave());
    }

    proptest! {
        #[test]
        fn a_named_mode_carries_whatever_it_takes_within_the_caps(
            linear in prop_oneof![Just(0.0), -2.0f64..2.0],
            lateral in prop_oneof![Just(0.0), -2.0f64..2.0],
            angular in prop_oneof![Just(0.0), -6.0f64..6.0],
            mode in 0u8..6,
        ) {
            let mode = MotionModeV2::from_raw(mode);
            if let Ok(velocity) = in_mode(mode, (linear, lateral, angular), RADIUS, CAPS) {
                prop_assert!(carries(mode, velocity), "{velocity:?} in {mode}");
                prop_assert!(velocity.0.hypot(velocity.1) <= CAPS.0 + 1e-9, "{velocity:?}");
                prop_assert!(velocity.2.abs() <= CAPS.2 + 1e-9, "{velocity:?}");
            }
        }

        #[test]
        fn one_mode_is_carried_by_the_mode_it_wants_and_changing_moves_nothing(
            linear in -2.0f64..2.0,
            lateral in prop_oneof![Just(0.0), -2.0f64..2.0],
            angular in prop_oneof![Just(0.0), -5.0f64..5.0],
            mode in 0u8..6,
        ) {
            let velocity = one_mode((linear, lateral, angular), RADIUS, CAPS);
            match wanted(velocity) {
                Some(mode) => prop_assert!(carries(mode, velocity), "{velocity:?} in {mode}"),
                None => prop_assert_eq!(velocity, (0.0, 0.0, 0.0)),
            }
            prop_assert!(velocity.0.hypot(velocity.1) <= 1.5 + 1e-9 || velocity.1 == 0.0);
            // Whatever a settled mode lets through, it carries; changing lets nothing through.
            let mode = MotionModeV2::from_raw(mode);
            let held = hold((linear, lateral, angular), Some(mode), RADIUS);
            prop_assert!(carries(mode, held) || held == (0.0, 0.0, 0.0), "{held:?} in {mode}");
            prop_assert_eq!(hold((linear, lateral, angular), None, RADIUS), (0.0, 0.0, 0.0));
        }
    }
}
