//! A Hunter's parking brake, without I/O: released (0x131 `[00]`) only for a client's drive,
//! and nothing moves until the chassis reports it released (0x211 byte 6); locked again
//! (0x131 `[01]`) once nobody has driven for [`IDLE_FOR`] and the chassis stands still.
//!
//! The vendor documents the two commands and the report (ugv_sdk `SetBrakeMode`; the Hunter
//! 2.0 protocol sheet: "speed control needs the brake released"; its manual: "it need to
//! unlock parking by command before running"), not when each is to be sent: its drivers send
//! neither. When is this module's decision.

use std::time::Duration;

use scout_protocol::v2::{BrakeV2, MotionV2};

use crate::modes::{REQUEST_WAIT, Velocity};
use crate::standstill::Standstill;

/// How long nobody must have asked to drive, standing still, before the brake is locked: a
/// pause between two commands (a teleop's key let go and pressed again) keeps it released.
pub const IDLE_FOR: Duration = Duration::from_secs(1);

/// The parking brake as the gateway works it, sans-IO: what the chassis reports (0x211,
/// 0x221), what was sent and whether a client drives in; whether the wheels may be driven,
/// and what to ask for (0x131), out. A release is asked again every [`REQUEST_WAIT`] while a
/// client wants to drive and the chassis has not reported it; a lock once an idle time, only
/// with the chassis in CAN command mode (not while its RC holds it), and once (a chassis that
/// does not take it is not asked again until the next drive, nor is one someone released by
/// hand). A request unanswered in its wait leaves the brake in doubt: nothing is driven until
/// the chassis answers the next one. Locked unasked during a drive, after it reported the
/// brake released for it, is reported once: a stop.
#[derive(Debug, Clone, Default)]
pub struct ParkingBrake {
    /// 0x211 byte 6 as last reported, since the port opened.
    reported: Option<BrakeV2>,
    /// Whether the chassis last said it is in CAN command mode (0x211 byte 1).
    commanded: bool,
    /// What was asked last, and when (cleared when the chassis reports it, or the wait ends).
    pending: Option<(BrakeV2, Duration)>,
    /// What was asked last, kept, and when it was last sent.
    asked: Option<BrakeV2>,
    asked_at: Option<Duration>,
    /// A request went unanswered: the brake may be on its way to what was asked, whatever
    /// the chassis reports; cleared when it answers one.
    doubt: bool,
    /// An unanswered request not yet said (for the log), and whether one was said since the
    /// chassis last answered.
    unanswered: Option<BrakeV2>,
    said: bool,
    /// The chassis reported the brake released after the gateway asked it for a drive.
    released_for_drive: bool,
    /// When a client last asked to drive.
    driven_at: Option<Duration>,
    /// Whether it stands still.
    standstill: Standstill,
}

impl ParkingBrake {
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

    /// 0x211 at `now`: byte 6 and whether the chassis is in CAN command mode. Returns
    /// `Some(why)` when the chassis locked the brake it had reported released for a drive
    /// while a client drives (its RC, a fault, its own doing): a stop's reason.
    pub fn handle_report(
        &mut self,
        now: Duration,
        brake: BrakeV2,
        commanded: bool,
    ) -> Option<String> {
        self.expire(now);
        self.commanded = commanded;
        let before = self.reported.replace(brake);
        if self.pending.is_some_and(|(asked, _)| asked == brake) {
            self.pending = None;
        }
        // What was asked last, taken (late or not): no doubt left. A report that only says
        // what the chassis said before the ask proves nothing until a whole wait has passed
        // since it (a lock of the gateway's may still be on its way).
        let changed = before != Some(brake);
        let waited = self.asked_at.is_none_or(|at| now >= at + REQUEST_WAIT);
        if self.asked == Some(brake) && (changed || waited || !self.doubt) {
            self.doubt = false;
            self.said = false;
            self.unanswered = None;
        }
        if brake == BrakeV2::Released && self.asked == Some(BrakeV2::Released) && !self.doubt {
            self.released_for_drive = true;
        }
        let driving = self.driven_at.is_some_and(|at| now < at + IDLE_FOR);
        let locked_unasked = before == Some(BrakeV2::Released)
            && brake != BrakeV2::Released
            && std::mem::replace(&mut self.released_for_drive, brake == BrakeV2::Released)
            && driving;
        locked_unasked.then(|| {
            format!(
                "the chassis locked its parking brake unasked (0x211 byte 6 says {brake}): check \
                 who locked it (its RC, a fault), then release the stop and take control again"
            )
        })
    }

    /// 0x211 byte 6 as last reported since the port opened.
    pub fn reported(&self) -> Option<BrakeV2> {
        self.reported
    }

    /// Whether the wheels may be driven at `now`: the chassis reports the brake released,
    /// nothing is asked of it, and no unanswered request left it in doubt.
    pub fn released(&mut self, now: Duration) -> bool {
        self.expire(now);
        self.pending.is_none() && !self.doubt && self.reported == Some(BrakeV2::Released)
    }

    /// A request the chassis did not answer in [`REQUEST_WAIT`]: `Some(why)` the first time
    /// since it last answered one, for the log.
    pub fn poll_unanswered(&mut self, now: Duration) -> Option<String> {
        self.expire(now);
        let asked = self.unanswered.take()?;
        if std::mem::replace(&mut self.said, true) {
            return None;
        }
        let reported = self.reported.map_or("nothing", BrakeV2::name);
        Some(format!(
            "the chassis has not reported its parking brake {asked} {} ms after 0x131 (0x211 \
             byte 6 says {reported}){}",
            REQUEST_WAIT.as_millis(),
            match asked {
                BrakeV2::Released =>
                    ": nothing moves until it does; check that its RC is off \
                                      and its firmware reports the brake",
                BrakeV2::Locked | BrakeV2::Unknown(_) => "",
            }
        ))
    }

    /// What to ask for now (sent as 0x131), with `output` going out and `drive` saying whether
    /// a client asks to move ([`crate::arbiter::Output::drive`]): a release for a drive, a lock
    /// once idle and standing still in CAN command mode; nothing before the chassis has
    /// reported its brake, nor while a request is pending.
    pub fn poll_request(
        &mut self,
        now: Duration,
        drive: bool,
        output: Velocity,
    ) -> Option<BrakeV2> {
        if drive {
            self.driven_at = Some(now);
        }
        self.expire(now);
        let reported = self.reported?;
        if self.pending.is_some() {
            return None;
        }
        // Nothing about the brake before a client's first drive since the port opened.
        let idle = self.driven_at.is_some_and(|at| now >= at + IDLE_FOR);
        let wanted = if drive {
            BrakeV2::Released
        } else if idle
            && self.commanded
            && self.standstill.is_still(now, output)
            && self.asked != Some(BrakeV2::Locked)
        {
            BrakeV2::Locked
        } else {
            return None;
        };
        self.released_for_drive &= wanted == BrakeV2::Released;
        if reported == wanted && !self.doubt {
            // Already so (a chassis that starts locked, one released before): nothing to ask.
            if wanted == BrakeV2::Released && self.asked != Some(BrakeV2::Released) {
                self.released_for_drive = true;
            }
            self.asked = Some(wanted);
            return None;
        }
        self.pending = Some((wanted, now));
        self.asked = Some(wanted);
        self.asked_at = Some(now);
        Some(wanted)
    }

    fn expire(&mut self, now: Duration) {
        if let Some((asked, at)) = self.pending
            && now >= at + REQUEST_WAIT
        {
            self.pending = None;
            self.doubt = true;
            self.unanswered = Some(asked);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: Duration = Duration::from_millis(1);
    const ZERO: Velocity = (0.0, 0.0, 0.0);

    fn still(brake: &mut ParkingBrake, now: Duration) {
        brake.handle_motion_state(now, &MotionV2::default());
    }

    /// A 0x211 in CAN command mode.
    fn report(brake: &mut ParkingBrake, now: Duration, state: BrakeV2) -> Option<String> {
        brake.handle_report(now, state, true)
    }

    #[test]
    fn released_only_for_a_drive_and_nothing_moves_until_reported() {
        let mut brake = ParkingBrake::default();
        // Nothing reported: nothing driven, nothing asked.
        assert!(!brake.released(Duration::ZERO));
        assert_eq!(brake.poll_request(Duration::ZERO, true, ZERO), None);
        assert_eq!(report(&mut brake, Duration::ZERO, BrakeV2::Locked), None);
        still(&mut brake, Duration::ZERO);
        // Nobody drives: a locked brake stays so, and nothing is asked.
        assert_eq!(brake.poll_request(2000 * MS, false, ZERO), None);
        assert!(!brake.released(2000 * MS));
        // A client drives: released, and nothing moves until the chassis says so.
        assert_eq!(
            brake.poll_request(2020 * MS, true, ZERO),
            Some(BrakeV2::Released)
        );
        assert_eq!(brake.poll_request(2040 * MS, true, ZERO), None, "pending");
        assert!(!brake.released(2040 * MS));
        assert_eq!(report(&mut brake, 2100 * MS, BrakeV2::Locked), None);
        assert!(!brake.released(2100 * MS));
        assert_eq!(report(&mut brake, 2120 * MS, BrakeV2::Released), None);
        assert!(brake.released(2120 * MS));
        brake.handle_sent(2140 * MS, (0.3, 0.0, 0.0));
        assert_eq!(brake.poll_request(2140 * MS, true, (0.3, 0.0, 0.0)), None);
        // The drive ends: released while the chassis moves and for a second after the drive,
        // then locked standing still.
        assert_eq!(brake.poll_request(3000 * MS, false, ZERO), None);
        still(&mut brake, 3100 * MS);
        assert_eq!(brake.poll_request(3139 * MS, false, ZERO), None);
        assert_eq!(
            brake.poll_request(3140 * MS, false, ZERO),
            Some(BrakeV2::Locked)
        );
        assert!(!brake.released(3140 * MS), "a lock is pending");
        assert_eq!(report(&mut brake, 3200 * MS, BrakeV2::Locked), None);
        assert!(!brake.released(3200 * MS));
    }

    #[test]
    fn locked_unasked_during_a_drive_is_a_stop_and_unanswered_asks_are_said() {
        let mut brake = ParkingBrake::default();
        report(&mut brake, Duration::ZERO, BrakeV2::Locked);
        still(&mut brake, Duration::ZERO);
        assert_eq!(
            brake.poll_request(20 * MS, true, ZERO),
            Some(BrakeV2::Released)
        );
        // Not answered: held (as the core asks first, every tick), said once, asked again.
        assert!(!brake.released(520 * MS));
        let why = brake.poll_unanswered(520 * MS).expect("unanswered");
        assert!(
            why.starts_with("the chassis has not reported its parking brake released 500 ms"),
            "{why}"
        );
        assert_eq!(
            brake.poll_request(520 * MS, true, ZERO),
            Some(BrakeV2::Released)
        );
        assert!(!brake.released(1020 * MS));
        assert_eq!(brake.poll_unanswered(1020 * MS), None, "said once");
        assert_eq!(
            brake.poll_request(1020 * MS, true, ZERO),
            Some(BrakeV2::Released)
        );
        report(&mut brake, 1100 * MS, BrakeV2::Released);
        assert!(brake.released(1100 * MS));
        // Answered (after a third ask's wait ran out): nothing more to say.
        assert_eq!(brake.poll_unanswered(1100 * MS), None);
        assert_eq!(brake.poll_request(1120 * MS, true, ZERO), None);
        let why = report(&mut brake, 1140 * MS, BrakeV2::Locked).expect("unasked");
        assert!(
            why.starts_with("the chassis locked its parking brake unasked"),
            "{why}"
        );
        assert!(!brake.released(1160 * MS));
    }

    #[test]
    fn a_lock_answered_late_holds_the_next_drive_and_is_no_stop() {
        let mut brake = ParkingBrake::default();
        report(&mut brake, Duration::ZERO, BrakeV2::Released);
        still(&mut brake, Duration::ZERO);
        assert_eq!(
            brake.poll_request(Duration::ZERO, true, ZERO),
            None,
            "released already"
        );
        assert_eq!(
            brake.poll_request(1000 * MS, false, ZERO),
            Some(BrakeV2::Locked)
        );
        // A drive while the lock is pending, past its wait: in doubt, held, released asked.
        assert_eq!(brake.poll_request(1050 * MS, true, ZERO), None);
        assert!(!brake.released(1500 * MS), "in doubt");
        assert_eq!(
            brake.poll_request(1500 * MS, true, ZERO),
            Some(BrakeV2::Released)
        );
        // A report of released made before the chassis saw the ask proves nothing.
        assert_eq!(report(&mut brake, 1520 * MS, BrakeV2::Released), None);
        assert!(!brake.released(1520 * MS), "still in doubt");
        // The lock lands late: the gateway's own, no stop; then the release.
        assert_eq!(report(&mut brake, 1600 * MS, BrakeV2::Locked), None);
        assert!(!brake.released(1600 * MS));
        assert_eq!(report(&mut brake, 1700 * MS, BrakeV2::Released), None);
        assert!(brake.released(1700 * MS));
    }

    #[test]
    fn a_lock_is_asked_only_in_command_mode_and_one_after_the_drive_is_no_stop() {
        let mut brake = ParkingBrake::default();
        report(&mut brake, Duration::ZERO, BrakeV2::Locked);
        still(&mut brake, Duration::ZERO);
        assert_eq!(
            brake.poll_request(20 * MS, true, ZERO),
            Some(BrakeV2::Released)
        );
        report(&mut brake, 100 * MS, BrakeV2::Released);
        // The drive ended; the RC holds the chassis: no lock asked of it.
        brake.handle_report(1500 * MS, BrakeV2::Released, false);
        assert_eq!(brake.poll_request(1500 * MS, false, ZERO), None);
        // Someone locks it by hand after the drive: not a stop.
        assert_eq!(brake.handle_report(1600 * MS, BrakeV2::Locked, false), None);
    }

    #[test]
    fn a_lock_not_taken_or_undone_by_hand_is_not_asked_again_until_the_next_drive() {
        let mut brake = ParkingBrake::default();
        report(&mut brake, Duration::ZERO, BrakeV2::Released);
        still(&mut brake, Duration::ZERO);
        // Nothing about the brake before a first drive.
        assert_eq!(brake.poll_request(Duration::ZERO, false, ZERO), None);
        assert_eq!(brake.poll_request(900 * MS, false, ZERO), None);
        assert_eq!(
            brake.poll_request(Duration::ZERO, true, ZERO),
            None,
            "released already"
        );
        assert_eq!(
            brake.poll_request(1000 * MS, false, ZERO),
            Some(BrakeV2::Locked)
        );
        assert_eq!(brake.poll_request(2000 * MS, false, ZERO), None);
        report(&mut brake, 2000 * MS, BrakeV2::Locked);
        // Released by someone (its RC, by hand) while nobody drives: not a stop, not fought.
        assert_eq!(report(&mut brake, 2100 * MS, BrakeV2::Released), None);
        assert_eq!(brake.poll_request(5000 * MS, false, ZERO), None);
        // A drive (the late lock answered the doubt; released by hand already), then idle
        // again: locked again.
        assert_eq!(brake.poll_request(5020 * MS, true, ZERO), None);
        assert!(brake.released(5020 * MS));
        assert_eq!(
            brake.poll_request(6020 * MS, false, ZERO),
            Some(BrakeV2::Locked)
        );
    }
}
