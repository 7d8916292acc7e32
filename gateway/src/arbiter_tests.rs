//! Tests of the arbiter with a simulated clock, and property tests of its guarantees.

use std::time::Duration;

use proptest::prelude::*;
use scout_interface::control::{DriveMode, RejectionKind, ReleaseTarget, StopCause};
use scout_protocol::FaultClear;
use scout_protocol::units::{DEFAULT_MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED};

use super::*;

const TICK: Duration = Duration::from_millis(20);

const fn ms(millis: u64) -> Duration {
    Duration::from_millis(millis)
}

/// A client of user 1000.
fn client(name: &str, port: u128) -> Origin {
    user_client(name, port, Some(1000))
}

/// A client of user `uid`, as the kernel vouched for it (`None`: it could not say).
fn user_client(name: &str, port: u128, uid: Option<u32>) -> Origin {
    Origin {
        key: ClientKey {
            port,
            node: port,
            name: name.into(),
            uid,
        },
        operator: false,
        bridge: false,
    }
}

fn operator(name: &str, port: u128) -> Origin {
    Origin {
        operator: true,
        ..client(name, port)
    }
}

/// An arbiter on a simulated clock.
struct Bench {
    arbiter: Arbiter,
    now: Duration,
}

impl Bench {
    fn new() -> Self {
        Self::with(ArbiterConfig::default())
    }

    fn with(config: ArbiterConfig) -> Self {
        Self::chassis(config, None)
    }

    /// A chassis that moves sideways up to `lateral` m/s (the OMNI's 2.0).
    fn sideways(lateral: f64) -> Self {
        Self::chassis(ArbiterConfig::default(), Some(lateral))
    }

    fn chassis(config: ArbiterConfig, lateral: Option<f64>) -> Self {
        Self {
            arbiter: Arbiter::new(
                config,
                Caps {
                    linear: MAX_LINEAR_SPEED,
                    angular: DEFAULT_MAX_ANGULAR_SPEED,
                    lateral,
                },
                7,
            ),
            now: ms(1000),
        }
    }

    fn request(&mut self, who: &Origin, request: Request) -> Answer {
        self.arbiter
            .handle_request(self.now, who, request, self.now)
    }

    fn kind(&mut self, who: &Origin, request: Request) -> Option<RejectionKind> {
        self.request(who, request).err().map(|r| r.kind())
    }

    fn take(&mut self, who: &Origin, class: Class) -> u64 {
        self.request(who, Request::TakeControl { class })
            .expect("control taken")
            .lease
            .expect("a lease")
    }

    fn drive(&mut self, who: &Origin, lease: u64, linear: f64) -> Answer {
        self.drive_body(who, lease, linear, 0.0)
    }

    fn drive_body(&mut self, who: &Origin, lease: u64, linear: f64, lateral: f64) -> Answer {
        self.request(
            who,
            Request::Drive {
                lease,
                linear,
                lateral,
                angular: 0.0,
                ttl: None,
                mode: None,
            },
        )
    }

    /// Latches a stop; its id.
    fn stop(&mut self, who: &Origin, reason: &str) -> u64 {
        let answer = self.request(
            who,
            Request::Stop {
                reason: reason.into(),
            },
        );
        answer
            .expect("a stop is never refused")
            .stop
            .expect("a stop's id")
    }

    /// A release a moment after what came before (a stop at the same instant wins).
    fn release(&mut self, who: &Origin, target: ReleaseTarget) -> Answer {
        self.now += ms(1);
        self.release_at_once(who, target)
    }

    /// A release decided on what the status shows now.
    fn release_at_once(&mut self, who: &Origin, target: ReleaseTarget) -> Answer {
        let through = self.arbiter.newest_stop();
        self.request(who, Request::Release { target, through })
    }

    fn tick(&mut self) -> Output {
        let output = self.arbiter.poll_output(self.now, TICK);
        self.now += TICK;
        output
    }

    /// Drives as `who` under `lease` before every tick for `time`; returns the last output.
    fn run(&mut self, who: &Origin, lease: u64, linear: f64, time: Duration) -> Output {
        let end = self.now + time;
        let mut output = self.arbiter.output();
        while self.now < end {
            let _ = self.drive(who, lease, linear);
            output = self.tick();
        }
        output
    }

    fn idle(&mut self, time: Duration) -> Output {
        let end = self.now + time;
        let mut output = self.arbiter.output();
        while self.now < end {
            output = self.tick();
        }
        output
    }
}

#[test]
fn a_fresh_command_drives_with_the_acceleration_limit() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    assert_eq!(bench.drive(&joy, lease, 1.0), Ok(Accepted::default()));
    let first = bench.tick();
    assert!((first.linear - 0.02).abs() < 1e-12, "1 m/s² over 20 ms");
    assert!(first.limited);
    let output = bench.run(&joy, lease, 1.0, Duration::from_secs(2));
    assert_eq!(output.linear, 1.0);
    assert!(!output.limited);
}

#[test]
fn a_chassis_that_does_not_move_sideways_refuses_a_sideways_speed_and_says_why() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    let refused = bench
        .drive_body(&joy, lease, 0.5, 0.3)
        .expect_err("no sideways");
    assert_eq!(refused.kind(), RejectionKind::NotAllowed);
    assert!(
        refused.to_string().contains("does not move sideways"),
        "{refused}"
    );
    // Refused whole, not reshaped: the forward half of it did not drive either.
    assert_eq!(bench.idle(ms(100)).linear, 0.0);
    assert_eq!(
        bench.drive_body(&joy, lease, 0.5, 0.0),
        Ok(Accepted::default())
    );
    let output = bench.idle(ms(100));
    assert!(output.linear > 0.0 && output.lateral == 0.0, "{output:?}");
    // The gateway words the reason by model and protocol.
    bench
        .arbiter
        .set_sideways(Sideways::Not("a scout2 does not move sideways".into()));
    let refused = bench.drive_body(&joy, lease, 0.0, -0.1).expect_err("no");
    assert_eq!(refused.to_string(), "a scout2 does not move sideways");
}

/// A steered chassis with the Hunter's tightest turn (1.31 m).
fn steered() -> Bench {
    let mut bench = Bench::new();
    bench.arbiter.set_turning(Turning::Radius {
        min_radius: 1.31,
        in_place: "a hunter2 cannot turn in place".into(),
    });
    bench
}

fn turn(bench: &mut Bench, who: &Origin, lease: u64, linear: f64, angular: f64) -> Answer {
    bench.request(
        who,
        Request::Drive {
            lease,
            linear,
            lateral: 0.0,
            angular,
            ttl: None,
            mode: None,
        },
    )
}

#[test]
fn a_steered_chassis_refuses_a_turn_in_place_and_turns_no_tighter_than_it_can() {
    let mut bench = steered();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    let refused = turn(&mut bench, &joy, lease, 0.0, 0.3).expect_err("in place");
    assert_eq!(refused.kind(), RejectionKind::NotAllowed);
    assert_eq!(refused.to_string(), "a hunter2 cannot turn in place");
    assert_eq!(bench.tick(), Output::STOP, "refused whole");
    // Standing still without turning, and straight, are taken.
    turn(&mut bench, &joy, lease, 0.0, 0.0).expect("standing still");
    // Tighter than 1.31 m at 0.5 m/s (0.38 rad/s at most): held to the radius and said.
    let answer = turn(&mut bench, &joy, lease, 0.5, 1.0).expect("clamped");
    assert!(answer.clamped);
    let mut output = bench.tick();
    for _ in 0..100 {
        // While the speed ramps up from zero, so does the turn, never tighter.
        assert!(
            output.angular.abs() <= output.linear.abs() / 1.31 + 1e-12,
            "{output:?}"
        );
        let _ = turn(&mut bench, &joy, lease, 0.5, 1.0);
        output = bench.tick();
    }
    assert!((output.linear - 0.5).abs() < 1e-12);
    assert!((output.angular - 0.5 / 1.31).abs() < 1e-12, "{output:?}");
    // Slowing down tightens nothing: the turn slows with the speed.
    for _ in 0..40 {
        let _ = turn(&mut bench, &joy, lease, 0.0, 0.0);
        output = bench.tick();
        assert!(output.angular.abs() <= output.linear.abs() / 1.31 + 1e-12);
    }
    assert_eq!((output.linear, output.angular), (0.0, 0.0));
    // Any other chassis turns in place.
    let mut skid = Bench::new();
    let lease = skid.take(&joy, Class::Teleop);
    turn(&mut skid, &joy, lease, 0.0, 0.3).expect("in place");
}

#[test]
fn sideways_is_capped_ramped_and_stopped_as_forward_is() {
    let mut bench = Bench::sideways(2.0);
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    let answer = bench.drive_body(&joy, lease, 0.0, 3.0).expect("sideways");
    assert!(answer.clamped, "3 m/s is beyond the chassis' 2");
    let first = bench.tick();
    assert!(
        (first.lateral - 0.02).abs() < 1e-12,
        "1 m/s² over 20 ms: {first:?}"
    );
    assert!(first.limited);
    let mut output = first;
    for _ in 0..150 {
        let _ = bench.drive_body(&joy, lease, 0.0, -3.0);
        output = bench.tick();
    }
    assert_eq!(output.lateral, -2.0, "capped the other way too");
    // A class's own cap holds sideways too.
    let capped = ArbiterConfig {
        teleop_caps: Some(Caps {
            linear: 1.0,
            angular: 0.5,
            lateral: Some(0.4),
        }),
        ..ArbiterConfig::default()
    };
    let mut slow = Bench::chassis(capped, Some(2.0));
    let lease_slow = slow.take(&joy, Class::Teleop);
    for _ in 0..100 {
        let _ = slow.drive_body(&joy, lease_slow, 0.0, 1.0);
        output = slow.tick();
    }
    assert_eq!(output.lateral, 0.4);
    // A stop is zero on every axis at once.
    bench.stop(&joy, "person");
    let stopped = bench.tick();
    assert_eq!(
        (stopped.linear, stopped.lateral, stopped.angular),
        (0.0, 0.0, 0.0)
    );
    // A chassis that stops moving sideways (another protocol) is not driven sideways on.
    let mut omni = Bench::sideways(2.0);
    let lease = omni.take(&joy, Class::Teleop);
    for _ in 0..50 {
        let _ = omni.drive_body(&joy, lease, 0.0, 1.0);
        omni.tick();
    }
    omni.arbiter.set_sideways(Sideways::Not("v1".into()));
    assert_eq!(omni.tick().lateral, 0.0);
}

#[test]
fn nothing_drives_without_taking_control() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    assert_eq!(
        bench.kind(
            &joy,
            Request::Drive {
                lease: 0,
                linear: 1.0,
                lateral: 0.0,
                angular: 0.0,
                ttl: None,
                mode: None,
            }
        ),
        Some(RejectionKind::NoControl)
    );
    let lease = bench.take(&joy, Class::Teleop);
    let other = client("other", 2);
    assert_eq!(
        bench.drive(&other, lease, 1.0).map_err(|r| r.kind()),
        Err(RejectionKind::NoControl),
        "a lease belongs to the port that took it"
    );
    assert_eq!(bench.idle(ms(200)).linear, 0.0);
}

#[test]
fn autonomy_starts_disarmed_and_needs_a_resume() {
    let mut bench = Bench::new();
    let planner = client("planner", 1);
    assert_eq!(
        bench.kind(
            &planner,
            Request::TakeControl {
                class: Class::Autonomy
            }
        ),
        Some(RejectionKind::AutonomyDisarmed)
    );
    bench
        .request(&operator("op", 9), Request::Resume)
        .expect("resume");
    let lease = bench.take(&planner, Class::Autonomy);
    assert!(
        bench
            .run(&planner, lease, 0.5, Duration::from_secs(1))
            .linear
            > 0.4
    );
}

#[test]
fn a_teleop_takeover_revokes_autonomy_which_must_take_control_again() {
    let mut bench = Bench::new();
    let (planner, joy) = (client("planner", 1), client("joy", 2));
    bench.request(&planner, Request::Resume).expect("resume");
    let auto = bench.take(&planner, Class::Autonomy);
    bench.run(&planner, auto, 0.5, Duration::from_secs(1));
    let teleop = bench.take(&joy, Class::Teleop);
    let revoked = bench.drive(&planner, auto, 0.5).expect_err("revoked");
    assert_eq!(revoked.kind(), RejectionKind::Revoked);
    assert!(
        revoked.to_string().contains("teleop joy took over"),
        "{revoked}"
    );
    bench.run(&joy, teleop, 0.0, ms(500));
    bench
        .request(&joy, Request::Relinquish)
        .expect("relinquish");
    // Resume re-arms autonomy, but its old stream stays refused: it must take control again.
    bench.request(&planner, Request::Resume).expect("resume");
    assert_eq!(
        bench.drive(&planner, auto, 0.5).map_err(|r| r.kind()),
        Err(RejectionKind::Revoked)
    );
    assert_eq!(bench.idle(ms(500)).linear, 0.0);
    let again = bench.take(&planner, Class::Autonomy);
    assert!(
        bench
            .run(&planner, again, 0.5, Duration::from_secs(1))
            .linear
            > 0.4
    );
}

#[test]
fn a_class_is_held_until_relinquished_or_stale() {
    let mut bench = Bench::new();
    let (first, second) = (client("first", 1), client("second", 2));
    let lease = bench.take(&first, Class::Teleop);
    bench.run(&first, lease, 0.3, ms(200));
    let held = bench.request(
        &second,
        Request::TakeControl {
            class: Class::Teleop,
        },
    );
    assert_eq!(
        held,
        Err(Rejection::Held {
            class: Class::Teleop,
            holder: "first".into()
        })
    );
    // Silent for longer than the teleop age (250 ms): the lease ends.
    bench.idle(ms(300));
    let stale = bench.drive(&first, lease, 0.3).expect_err("stale lease");
    assert!(stale.to_string().contains("stale"), "{stale}");
    bench.take(&second, Class::Teleop);
}

#[test]
fn a_command_lives_from_when_it_was_sent() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    let drive = Request::Drive {
        lease,
        linear: 0.5,
        lateral: 0.0,
        angular: 0.0,
        ttl: Some(ms(100)),
        mode: None,
    };
    // Queued for 150 ms (a stalled gateway): past its 100 ms life on arrival.
    let late = bench
        .arbiter
        .handle_request(bench.now, &joy, drive.clone(), bench.now - ms(150));
    assert_eq!(late.map_err(|r| r.kind()), Err(RejectionKind::Stale));
    // Sent 80 ms ago: accepted, but it expires 20 ms from now, not 100.
    bench
        .arbiter
        .handle_request(bench.now, &joy, drive, bench.now - ms(80))
        .expect("in time");
    assert!(bench.tick().linear > 0.0);
    assert_eq!(
        bench
            .arbiter
            .selected(bench.now + ms(5))
            .map(|(s, _)| s.key.port),
        None
    );
}

/// A take-control stamped `ago` before now.
fn take_sent(bench: &mut Bench, who: &Origin, class: Class, ago: Duration) -> Answer {
    let sent = bench.now - ago;
    bench
        .arbiter
        .handle_request(bench.now, who, Request::TakeControl { class }, sent)
}

#[test]
fn a_take_control_sent_before_a_release_is_outdated_after_it() {
    let mut bench = Bench::new();
    let (joy, officer) = (client("joy", 1), operator("officer", 2));
    bench.stop(&officer, "check the robot");
    bench.idle(ms(100));
    // The peer asked for control 150 ms before the release: held up in the network (or sent
    // while the stop held), it arrives after.
    bench
        .release(&officer, ReleaseTarget::All)
        .expect("released");
    let outdated = take_sent(&mut bench, &joy, Class::Teleop, ms(150)).expect_err("outdated");
    assert_eq!(outdated.kind(), RejectionKind::Outdated);
    assert!(
        outdated
            .to_string()
            .contains("150 ms before the stops were released"),
        "{outdated}"
    );
    assert_eq!(
        bench.arbiter.rejections()[usize::from(RejectionKind::Outdated.raw())],
        1
    );
    assert_eq!(bench.arbiter.selected(bench.now), None);
    // Sent just before the release as far as its stamp tells (a remote peer's send time is an
    // estimate): granted, as one sent after it.
    bench.idle(ms(20));
    take_sent(&mut bench, &joy, Class::Teleop, ms(20) + OUTDATED_TOLERANCE)
        .expect("within the tolerance");
}

#[test]
fn a_take_control_sent_before_control_lapsed_is_outdated() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    bench.run(&joy, lease, 0.3, ms(100));
    // A partition: the drives stop arriving and the lease lapses (teleop age 250 ms).
    bench.idle(ms(600));
    assert_eq!(
        bench.drive(&joy, lease, 0.3).map_err(|r| r.kind()),
        Err(RejectionKind::Revoked)
    );
    // A take-control sent during the partition arrives as it heals, after the lapse.
    let outdated = take_sent(&mut bench, &joy, Class::Teleop, ms(500)).expect_err("outdated");
    assert_eq!(outdated.kind(), RejectionKind::Outdated);
    assert!(
        outdated.to_string().contains("this client lost control"),
        "{outdated}"
    );
    take_sent(&mut bench, &joy, Class::Teleop, ms(0)).expect("sent after the lapse");
}

#[test]
fn a_relinquish_or_a_lease_still_held_outdates_nothing() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    // Held: a repeated take-control returns the lease, whatever its stamp.
    let again = take_sent(&mut bench, &joy, Class::Teleop, ms(200)).expect("still held");
    assert_eq!(again.lease, Some(lease));
    // Given up on purpose: the client's own order stands, as it sent it.
    bench
        .request(&joy, Request::Relinquish)
        .expect("relinquished");
    bench.idle(ms(20));
    take_sent(&mut bench, &joy, Class::Teleop, ms(100)).expect("its own order");
}

#[test]
fn stops_stack_and_each_owner_releases_its_own() {
    let mut bench = Bench::new();
    let (joy, officer, guard) = (
        client("joy", 1),
        client("safety-officer", 2),
        client("lidar-guard", 3),
    );
    let lease = bench.take(&joy, Class::Teleop);
    bench.run(&joy, lease, 0.8, Duration::from_secs(1));
    bench.stop(&officer, "person ahead");
    assert!(bench.arbiter.take_urgent_stop(), "zero goes out at once");
    bench.stop(&guard, "obstacle");
    assert_eq!(bench.arbiter.stops().len(), 2, "both stops are kept");
    assert_eq!(bench.tick(), Output::STOP, "no ramp for a stop");
    // Neither a stranger nor the other owner clears a stop that is not theirs.
    let stranger = client("random-user", 4);
    assert_eq!(
        bench
            .release(&stranger, ReleaseTarget::All)
            .map_err(|r| r.kind()),
        Err(RejectionKind::NotAllowed)
    );
    assert_eq!(
        bench
            .release(&stranger, ReleaseTarget::Owner("safety-officer".into()))
            .map_err(|r| r.kind()),
        Err(RejectionKind::NotAllowed)
    );
    let refused = bench
        .release(&stranger, ReleaseTarget::Own)
        .expect_err("nothing of its own");
    assert!(
        refused
            .to_string()
            .contains("safety-officer (client): person ahead"),
        "{refused}"
    );
    bench
        .release(&officer, ReleaseTarget::Own)
        .expect("own stop");
    assert_eq!(bench.arbiter.stops().len(), 1);
    assert_eq!(
        bench.run(&joy, lease, 0.8, ms(200)),
        Output::STOP,
        "still held by lidar-guard"
    );
    bench.release(&guard, ReleaseTarget::Own).expect("own stop");
    assert!(bench.arbiter.stops().is_empty());
    // Release never restarts anything: the teleop that kept streaming stays revoked.
    let revoked = bench.drive(&joy, lease, 0.8).expect_err("revoked");
    assert!(revoked.to_string().contains("safety-officer"), "{revoked}");
    assert_eq!(bench.idle(ms(500)).linear, 0.0);
    let again = bench.take(&joy, Class::Teleop);
    assert!(bench.run(&joy, again, 0.8, ms(500)).linear > 0.0);
}

#[test]
fn an_operator_releases_anyone_and_everything() {
    let mut bench = Bench::new();
    bench.stop(&client("a", 1), "x");
    bench.stop(&client("b", 2), "y");
    let op = operator("operator", 3);
    bench
        .release(&op, ReleaseTarget::Owner("a".into()))
        .expect("an operator releases a's stop");
    assert_eq!(bench.arbiter.stops().len(), 1);
    bench.release(&op, ReleaseTarget::All).expect("and all");
    assert!(bench.arbiter.stops().is_empty());
}

#[test]
fn a_release_is_refused_while_the_cause_persists() {
    let mut bench = Bench::new();
    let op = operator("operator", 1);
    bench
        .arbiter
        .handle_gap(bench.now, StopCause::ChassisEstop, "e-stop pressed", true);
    let refused = bench
        .release(&op, ReleaseTarget::All)
        .expect_err("e-stop still pressed");
    assert_eq!(refused.kind(), RejectionKind::CausePersists);
    assert!(refused.to_string().contains("e-stop pressed"), "{refused}");
    bench
        .arbiter
        .handle_gap_cleared(bench.now, StopCause::ChassisEstop);
    bench
        .release(&op, ReleaseTarget::All)
        .expect("released once the e-stop is up");
}

#[test]
fn a_release_clears_only_the_stops_its_sender_saw() {
    let mut bench = Bench::new();
    let officer = client("officer", 1);
    let op = operator("op", 3);
    bench.stop(&officer, "first");
    // The operator reads the status (the newest stop is the officer's), then a guard stops
    // 0.2 ms before the operator's release arrives: the guard's stop survives.
    let seen = bench.arbiter.newest_stop();
    bench.now += Duration::from_micros(200);
    bench.stop(&client("guard", 2), "person ahead");
    bench.now += Duration::from_micros(200);
    bench
        .request(
            &op,
            Request::Release {
                target: ReleaseTarget::All,
                through: seen,
            },
        )
        .expect("what it saw is released");
    let left: Vec<&str> = bench
        .arbiter
        .stops()
        .iter()
        .map(|s| s.owner.as_str())
        .collect();
    assert_eq!(left, ["guard"]);
    // The same for one owner: the officer stops again after the release was decided.
    let seen = bench.arbiter.newest_stop();
    bench.stop(&officer, "again");
    let refused = bench
        .request(
            &op,
            Request::Release {
                target: ReleaseTarget::Owner("officer".into()),
                through: seen,
            },
        )
        .expect_err("the officer's stop is newer than what the operator saw");
    assert!(refused.to_string().contains("look again"), "{refused}");
    assert_eq!(bench.arbiter.stops().len(), 2);
    // A stop latched again by its owner takes a new id: a release decided before it leaves it.
    bench.now += ms(5);
    let seen = bench.arbiter.newest_stop();
    bench.stop(&client("guard", 2), "still there");
    assert!(
        bench
            .request(
                &officer,
                Request::Release {
                    target: ReleaseTarget::Own,
                    through: seen,
                }
            )
            .is_ok()
    );
    let left: Vec<&str> = bench
        .arbiter
        .stops()
        .iter()
        .map(|s| s.owner.as_str())
        .collect();
    assert_eq!(left, ["guard"]);
    let refreshed = bench
        .request(
            &op,
            Request::Release {
                target: ReleaseTarget::Owner("guard".into()),
                through: seen,
            },
        )
        .expect_err("refreshed after the decision");
    assert_eq!(refreshed.kind(), RejectionKind::NotAllowed);
}

#[test]
fn a_release_with_nothing_latched_changes_nothing() {
    let mut bench = Bench::new();
    let op = operator("op", 3);
    bench.request(&op, Request::Resume).expect("armed");
    bench
        .release(&op, ReleaseTarget::All)
        .expect("nothing to do");
    assert!(bench.arbiter.autonomy_armed(), "no release, no disarm");
}

#[test]
fn an_operators_stop_is_released_only_by_an_operator_whatever_the_name() {
    let mut bench = Bench::new();
    bench.stop(&operator("operator", 3), "scout estop");
    let impostor = client("operator", 4);
    let refused = bench
        .release(&impostor, ReleaseTarget::Own)
        .expect_err("a library client named operator");
    assert!(
        refused.to_string().contains("latched by an operator"),
        "{refused}"
    );
    bench
        .release(&impostor, ReleaseTarget::Owner("operator".into()))
        .expect_err("by owner either");
    assert_eq!(bench.arbiter.stops().len(), 1);
    bench
        .release(
            &operator("someone", 5),
            ReleaseTarget::Owner("operator".into()),
        )
        .expect("another operator may");
}

#[test]
fn an_operators_stop_keeps_its_reason_and_owner_against_anyone_of_its_name() {
    let mut bench = Bench::new();
    let person = bench.stop(&operator("guard", 3), "person ahead");
    let impostor = client("guard", 4);
    let theirs = bench.stop(&impostor, "impostor reason");
    assert_ne!(theirs, person, "a stop of its own");
    let stops = bench.arbiter.stops();
    assert_eq!(stops.len(), 2);
    let kept = stops.iter().find(|s| s.by_operator).expect("the person's");
    assert_eq!(
        (kept.id, kept.owner.as_str(), kept.reason.as_str()),
        (person, "guard", "person ahead")
    );
    // The impostor releases its own stop, never the person's.
    bench
        .release(&impostor, ReleaseTarget::Own)
        .expect("its own stop");
    let left: Vec<u64> = bench.arbiter.stops().iter().map(|s| s.id).collect();
    assert_eq!(left, [person]);
    // An operator latching again under the name refreshes the person's stop.
    let again = bench.stop(&operator("guard", 5), "still there");
    let stops = bench.arbiter.stops();
    assert_eq!(stops.len(), 1);
    assert_eq!(
        (stops[0].id, stops[0].reason.as_str()),
        (again, "still there")
    );
}

#[test]
fn a_stop_belongs_to_its_name_and_the_user_that_latched_it() {
    let mut bench = Bench::new();
    // A monitor running as root latches as `guard`; another user takes the same name.
    let root_guard = user_client("guard", 1, Some(0));
    let other = user_client("guard", 2, Some(1001));
    let monitors = bench.stop(&root_guard, "person ahead");
    for target in [ReleaseTarget::Own, ReleaseTarget::Owner("guard".into())] {
        let refused = bench
            .release(&other, target)
            .expect_err("another user's stop under the same name");
        assert_eq!(refused.kind(), RejectionKind::NotAllowed);
        assert!(
            refused.to_string().contains("another user (uid 0)"),
            "{refused}"
        );
    }
    assert_eq!(bench.arbiter.stops().len(), 1);
    // Its own stop under that name is a stop of its own, which it releases alone.
    let others = bench.stop(&other, "its own");
    assert_ne!(others, monitors);
    let stops = bench.arbiter.stops();
    assert_eq!(stops.len(), 2);
    assert_eq!(
        stops
            .iter()
            .find(|s| s.id == monitors)
            .map(|s| s.reason.as_str()),
        Some("person ahead"),
        "the root monitor's stop keeps its reason"
    );
    bench.release(&other, ReleaseTarget::Own).expect("its own");
    let left: Vec<(u64, Option<u32>)> = bench
        .arbiter
        .stops()
        .iter()
        .map(|s| (s.id, s.uid))
        .collect();
    assert_eq!(left, [(monitors, Some(0))]);
    // The monitor itself, restarted (another port, the same user), releases it.
    bench
        .release(&user_client("guard", 3, Some(0)), ReleaseTarget::Own)
        .expect("the monitor's own stop");
    assert!(bench.arbiter.stops().is_empty());
    // An operator releases anyone's, of any user.
    bench.stop(&root_guard, "again");
    bench
        .release(
            &operator("operator", 4),
            ReleaseTarget::Owner("guard".into()),
        )
        .expect("an operator");
}

#[test]
fn a_stop_of_a_user_the_kernel_did_not_name_is_an_operators_to_release() {
    let mut bench = Bench::new();
    let unknown = user_client("guard", 1, None);
    bench.stop(&unknown, "from a process whose user could not be read");
    for who in [unknown, user_client("guard", 2, None), client("guard", 3)] {
        bench
            .release(&who, ReleaseTarget::Own)
            .expect_err("nobody can show it is theirs");
    }
    bench
        .release(&operator("operator", 4), ReleaseTarget::All)
        .expect("an operator");
}

#[test]
fn a_command_stamped_in_the_future_is_refused_and_counted() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    let drive = Request::Drive {
        lease,
        linear: 0.5,
        lateral: 0.0,
        angular: 0.0,
        ttl: None,
        mode: None,
    };
    let ahead = bench.now + Duration::from_secs(10);
    let refused = bench
        .arbiter
        .handle_request(bench.now, &joy, drive.clone(), ahead)
        .expect_err("ten seconds ahead");
    assert_eq!(refused.kind(), RejectionKind::Future);
    assert!(
        refused.to_string().contains("10000 ms after its arrival"),
        "{refused}"
    );
    assert_eq!(
        bench.arbiter.rejections()[usize::from(RejectionKind::Future.raw())],
        1
    );
    // Within the tolerance (a request sent while the iteration ran): taken as sent now.
    let slightly = bench.now + FUTURE_TOLERANCE;
    bench
        .arbiter
        .handle_request(bench.now, &joy, drive, slightly)
        .expect("within the tolerance");
    bench.tick();
    // It lives from now, not from its stamp: it expires within its life.
    let output = bench.idle(ms(500));
    assert_eq!(output.linear, 0.0, "{output:?}");
}

#[test]
fn a_stop_is_never_refused_even_with_every_slot_taken() {
    let mut bench = Bench::new();
    for port in 0..MAX_SOURCES as u128 {
        let heartbeat = Request::Heartbeat {
            period: Duration::from_secs(10),
        };
        bench
            .request(&client(&format!("c{port}"), port), heartbeat)
            .expect("registered");
    }
    let late = client("late", 1000);
    assert_eq!(
        bench.kind(
            &late,
            Request::TakeControl {
                class: Class::Teleop
            }
        ),
        Some(RejectionKind::TooManyClients)
    );
    bench.stop(&late, "emergency");
    assert_eq!(bench.arbiter.stops()[0].owner, "late");
}

#[test]
fn a_missed_heartbeat_latches_and_holds_while_the_source_is_silent() {
    let mut bench = Bench::new();
    let remote = client("handheld", 1);
    let op = operator("operator", 2);
    bench
        .request(&remote, Request::Heartbeat { period: ms(100) })
        .expect("registered");
    bench.idle(ms(200));
    let stop = &bench.arbiter.stops()[0];
    assert_eq!(
        (stop.owner.as_str(), stop.cause),
        ("handheld", StopCause::Heartbeat)
    );
    // The deadman holds: nobody releases it while the source is silent.
    assert_eq!(
        bench.release(&op, ReleaseTarget::All).map_err(|r| r.kind()),
        Err(RejectionKind::CausePersists)
    );
    bench.idle(ms(500));
    assert_eq!(bench.arbiter.stops().len(), 1, "latched once, not per tick");
    // The source beats again: now it can be released, and it still guards afterwards.
    bench
        .request(&remote, Request::Heartbeat { period: ms(100) })
        .expect("beat");
    bench.release(&op, ReleaseTarget::All).expect("released");
    bench.arbiter.handle_node_gone(bench.now, 1);
    assert_eq!(bench.arbiter.stops()[0].reason, "heartbeat source died");
}

/// A drive sent `ago` before now.
fn drive_sent(bench: &mut Bench, who: &Origin, lease: u64, linear: f64, ago: Duration) -> Answer {
    let drive = Request::Drive {
        lease,
        linear,
        lateral: 0.0,
        angular: 0.0,
        ttl: None,
        mode: None,
    };
    bench
        .arbiter
        .handle_request(bench.now, who, drive, bench.now - ago)
}

#[test]
fn a_silent_senders_output_is_zero_at_its_commands_life_not_ramped_after() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    bench.run(&joy, lease, 1.0, Duration::from_secs(2));
    // The last drive was sent one tick ago; it lives 250 ms (the teleop age) from then.
    let last = bench.now - TICK;
    let mut outputs = Vec::new();
    while bench.now < last + ms(300) {
        outputs.push((bench.now, bench.tick().linear));
    }
    for (at, linear) in outputs {
        if at < last + ms(250) {
            assert_eq!(linear, 1.0, "the command holds within its life (at {at:?})");
        } else {
            assert_eq!(linear, 0.0, "zero at once past its life (at {at:?})");
        }
    }
}

#[test]
fn a_ramp_after_letting_go_ends_at_the_last_commands_life() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    bench.run(&joy, lease, 1.5, Duration::from_secs(3));
    let last = bench.now - TICK;
    bench.request(&joy, Request::Relinquish).expect("let go");
    let mut previous = 1.5;
    while bench.now < last + ms(250) {
        let linear = bench.tick().linear;
        assert!(linear < previous && linear > 0.0, "ramps down at the limit");
        previous = linear;
    }
    assert!(previous > 0.5, "2 m/s² takes 750 ms from 1.5 m/s");
    assert_eq!(bench.tick().linear, 0.0, "but not past the command's life");
}

#[test]
fn control_lasts_the_class_age_from_the_last_arrival_however_late_the_commands() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    // Every drive arrives 100 ms after it was sent: each lives 150 ms more.
    for _ in 0..50 {
        drive_sent(&mut bench, &joy, lease, 0.3, ms(100)).expect("in its life");
        bench.tick();
    }
    assert_eq!(bench.arbiter.output().linear, 0.3);
    // 200 ms without a drive: the last one's life ends, the output is zero, control holds.
    assert_eq!(bench.idle(ms(200)).linear, 0.0);
    drive_sent(&mut bench, &joy, lease, 0.3, ms(100)).expect("control held");
    assert!(bench.tick().linear > 0.0, "drives again, ramping up");
    // Silent for the teleop age after the last arrival: control ends.
    bench.idle(ms(260));
    let refused = drive_sent(&mut bench, &joy, lease, 0.3, ms(0)).expect_err("lapsed");
    assert_eq!(refused.kind(), RejectionKind::Revoked, "{refused}");
}

#[test]
fn a_new_lease_waits_a_slow_links_round_trip_for_its_first_command() {
    let mut bench = Bench::new();
    let (slow, idle) = (client("slow", 1), client("idle", 2));
    let lease = bench.take(&slow, Class::Teleop);
    // The answer travels back 300 ms, the first drive 300 ms forward (aged against the
    // fastest delivery, so younger than that).
    bench.idle(ms(600));
    drive_sent(&mut bench, &slow, lease, 0.3, ms(50)).expect("still held");
    // From then on the teleop age counts.
    bench.idle(ms(260));
    assert_eq!(
        bench.drive(&slow, lease, 0.3).map_err(|r| r.kind()),
        Err(RejectionKind::Revoked)
    );
    // A lease that never drives ends after FIRST_COMMAND_WITHIN, having moved nothing.
    bench.take(&idle, Class::Teleop);
    assert_eq!(bench.idle(FIRST_COMMAND_WITHIN - TICK).linear, 0.0);
    assert!(bench.arbiter.sources.iter().any(|s| s.class().is_some()));
    bench.idle(TICK * 2);
    assert!(bench.arbiter.sources.iter().all(|s| s.class().is_none()));
}

#[test]
fn a_dead_driving_client_loses_control_at_once() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    bench.run(&joy, lease, 1.0, Duration::from_secs(2));
    bench.arbiter.handle_node_gone(bench.now, 1);
    assert!(bench.arbiter.selected(bench.now).is_none());
    assert_eq!(
        bench.idle(Duration::from_secs(1)).linear,
        0.0,
        "ramps to zero"
    );
    assert!(
        bench.arbiter.stops().is_empty(),
        "a dead driver is not a stop"
    );
}

#[test]
fn a_gap_ends_every_lease_and_disarms_autonomy() {
    let mut bench = Bench::new();
    let (planner, joy) = (client("planner", 1), client("joy", 2));
    bench.request(&planner, Request::Resume).expect("resume");
    let auto = bench.take(&planner, Class::Autonomy);
    bench.run(&planner, auto, 0.5, Duration::from_secs(1));
    bench
        .arbiter
        .handle_gap(bench.now, StopCause::LinkLost, "port gone", true);
    assert!(bench.arbiter.take_urgent_stop());
    assert!(!bench.arbiter.autonomy_armed());
    bench
        .arbiter
        .handle_gap_cleared(bench.now, StopCause::LinkLost);
    bench
        .release(&operator("op", 3), ReleaseTarget::All)
        .expect("released");
    let refused = bench.drive(&planner, auto, 0.5).expect_err("revoked");
    assert!(refused.to_string().contains("link_lost"), "{refused}");
    assert_eq!(
        bench.kind(
            &joy,
            Request::Drive {
                lease: auto,
                linear: 0.1,
                lateral: 0.0,
                angular: 0.0,
                ttl: None,
                mode: None,
            }
        ),
        Some(RejectionKind::NoControl)
    );
    assert_eq!(bench.idle(ms(500)).linear, 0.0);
}

#[test]
fn bad_values_are_rejected_and_counted_big_ones_clamped() {
    let mut bench = Bench::new();
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    for linear in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
        assert_eq!(bench.drive(&joy, lease, linear), Err(Rejection::NotFinite));
    }
    assert_eq!(
        bench.arbiter.rejections()[usize::from(RejectionKind::NotFinite.raw())],
        3
    );
    let clamped = bench.drive(&joy, lease, 100.0).expect("clamped");
    assert!(clamped.clamped);
    let output = bench.run(&joy, lease, 100.0, Duration::from_secs(3));
    assert_eq!(output.linear, MAX_LINEAR_SPEED);
}

#[test]
fn a_flooding_client_is_rate_limited() {
    let mut bench = Bench::new();
    let flood = client("flood", 1);
    let answers: Vec<Answer> = (0..60)
        .map(|_| bench.request(&flood, Request::Resume))
        .collect();
    let limited = answers
        .iter()
        .filter(|a| matches!(a, Err(Rejection::RateLimited { .. })))
        .count();
    assert_eq!(limited, 10, "a burst of 50, then refused");
    bench.now += ms(10);
    assert!(
        bench.request(&flood, Request::Resume).is_ok(),
        "refilled at 500 a second"
    );
    bench.stop(&flood, "a stop is never limited");
}

#[test]
fn fault_clear_goes_out_in_three_commands_then_stops() {
    let mut bench = Bench::new();
    let who = client("operator", 1);
    bench
        .request(&who, Request::ClearFault(Some(FaultClear::DriverOverTemp)))
        .expect("clear");
    let codes: Vec<FaultClear> = (0..5).map(|_| bench.tick().fault_clear).collect();
    use FaultClear::{DriverOverTemp as T, None as N};
    assert_eq!(codes, [T, T, T, N, N]);
    bench
        .request(&who, Request::ClearFault(None))
        .expect("clear all");
    let codes: Vec<FaultClear> = (0..26).map(|_| bench.tick().fault_clear).collect();
    let mut expected: Vec<FaultClear> = FaultClear::ALL.iter().flat_map(|c| [*c; 3]).collect();
    expected.extend([N, N]);
    assert_eq!(codes, expected);
}

#[test]
fn lights_last_writer_wins() {
    let mut bench = Bench::new();
    assert_eq!(bench.arbiter.lights(), None);
    bench
        .request(&client("a", 1), Request::Lights(LightsSetting::Auto))
        .expect("lights");
    assert_eq!(bench.arbiter.lights(), Some(LightsSetting::Auto));
}

#[test]
fn auto_resume_keeps_autonomy_armed_but_not_its_lease() {
    let mut bench = Bench::with(ArbiterConfig {
        auto_resume: true,
        ..ArbiterConfig::default()
    });
    let planner = client("planner", 1);
    bench.request(&planner, Request::Resume).expect("resume");
    let lease = bench.take(&planner, Class::Autonomy);
    bench.take(&client("joy", 2), Class::Teleop);
    assert!(bench.arbiter.autonomy_armed());
    assert_eq!(
        bench.drive(&planner, lease, 0.5).map_err(|r| r.kind()),
        Err(RejectionKind::Revoked)
    );
}

#[test]
fn config_is_checked() {
    assert!(ArbiterConfig::default().validate().is_ok());
    let too_old = ArbiterConfig {
        teleop_max_age_ms: 600,
        ..ArbiterConfig::default()
    };
    assert!(
        too_old
            .validate()
            .expect_err("600 ms")
            .to_string()
            .contains("1..=500")
    );
    let no_rate = ArbiterConfig {
        request_rate_hz: 0.0,
        ..ArbiterConfig::default()
    };
    assert!(no_rate.validate().is_err());
}

/// One thing that happens to the arbiter.
#[derive(Debug, Clone)]
enum Step {
    /// A take-control sent this many ms before it arrives.
    Take(usize, Class, u8),
    Drive(usize, f64, f64),
    /// The chassis stops (`false`) or starts (`true`) moving sideways.
    Sideways(bool),
    Stop(usize),
    Release(usize, bool),
    Relinquish(usize),
    Resume(usize),
    Gap(bool),
    GapCleared,
    Dies(usize),
    Ticks(u8),
}

fn any_step() -> impl Strategy<Value = Step> {
    let who = 0usize..4;
    let class = prop::sample::select(Class::ALL.to_vec());
    prop_oneof![
        (who.clone(), class, prop_oneof![Just(0u8), 0u8..250])
            .prop_map(|(w, c, d)| Step::Take(w, c, d)),
        (
            who.clone(),
            -3.0f64..3.0,
            prop_oneof![Just(0.0), -3.0f64..3.0]
        )
            .prop_map(|(w, v, vy)| Step::Drive(w, v, vy)),
        any::<bool>().prop_map(Step::Sideways),
        who.clone().prop_map(Step::Stop),
        (who.clone(), any::<bool>()).prop_map(|(w, all)| Step::Release(w, all)),
        who.clone().prop_map(Step::Relinquish),
        who.clone().prop_map(Step::Resume),
        any::<bool>().prop_map(Step::Gap),
        Just(Step::GapCleared),
        who.prop_map(Step::Dies),
        (1u8..30).prop_map(Step::Ticks),
    ]
}

proptest! {
    /// After any gap, stop or release, nothing moves until no stop is left and a client has
    /// taken control again, with a take-control sent after it; while a stop holds, the output
    /// is exactly zero; the output is always finite and within the caps, changes per tick
    /// within the ramp outside a stop (or drops to zero at once), and is zero once every
    /// command accepted has lived its life.
    #[test]
    fn no_motion_after_a_gap_stop_or_release_without_a_new_take(steps in prop::collection::vec(any_step(), 1..120)) {
        // A chassis that moves sideways, every axis under the same rules.
        let mut bench = Bench::sideways(2.0);
        let mut sideways = true;
        let clients: Vec<Origin> = (0..4u128)
            .map(|i| if i == 3 { operator("op", i) } else { client(&format!("c{i}"), i) })
            .collect();
        let mut leases = [0u64; 4];
        let mut blocked_at = 0usize;
        let mut blocked_time = Duration::ZERO;
        let mut taken_at: [Option<usize>; 4] = [None; 4];
        let mut classes = [Class::Teleop; 4];
        // The end of the life of the longest-lived command accepted so far.
        let mut newest_life = Duration::ZERO;
        for (index, step) in steps.into_iter().enumerate() {
            let index = index + 1;
            match step {
                Step::Take(w, class, delay) => {
                    let sent = bench.now.saturating_sub(ms(u64::from(delay)));
                    let answer = bench.arbiter.handle_request(bench.now, &clients[w], Request::TakeControl { class }, sent);
                    if let Ok(Accepted { lease: Some(lease), .. }) = answer {
                        if lease != leases[w] {
                            prop_assert!(sent + OUTDATED_TOLERANCE >= blocked_time, "a take-control sent before the last gap, stop or release granted control");
                        }
                        leases[w] = lease;
                        classes[w] = class;
                        taken_at[w] = Some(index);
                    }
                }
                Step::Sideways(on) => {
                    sideways = on;
                    bench.arbiter.set_sideways(if on { Sideways::UpTo(2.0) } else { Sideways::Not("no".into()) });
                }
                Step::Drive(w, v, vy) => {
                    let answer = bench.drive_body(&clients[w], leases[w], v, vy);
                    if !sideways && vy != 0.0 {
                        prop_assert!(answer.is_err(), "sideways taken by a chassis that does not move sideways");
                    }
                    if answer.is_ok() {
                        newest_life = newest_life.max(bench.now + bench.arbiter.config.max_age(classes[w]));
                    }
                }
                Step::Stop(w) => {
                    bench.stop(&clients[w], "p");
                    (blocked_at, blocked_time) = (index, bench.now);
                }
                Step::Release(w, all) => {
                    let target = if all { ReleaseTarget::All } else { ReleaseTarget::Own };
                    let before = bench.arbiter.stops().len();
                    if bench.release(&clients[w], target).is_ok() && bench.arbiter.stops().len() < before {
                        (blocked_at, blocked_time) = (index, bench.now);
                    }
                }
                Step::Relinquish(w) => { let _ = bench.request(&clients[w], Request::Relinquish); }
                Step::Resume(w) => { let _ = bench.request(&clients[w], Request::Resume); }
                Step::Gap(present) => {
                    bench.arbiter.handle_gap(bench.now, StopCause::LinkLost, "gap", present);
                    (blocked_at, blocked_time) = (index, bench.now);
                }
                Step::GapCleared => bench.arbiter.handle_gap_cleared(bench.now, StopCause::LinkLost),
                Step::Dies(w) => bench.arbiter.handle_node_gone(bench.now, clients[w].key.node),
                Step::Ticks(n) => {
                    for _ in 0..n {
                        let before = bench.arbiter.output();
                        let stopped = !bench.arbiter.stops().is_empty();
                        let at = bench.now;
                        let output = bench.tick();
                        prop_assert!(output.linear.is_finite() && output.angular.is_finite() && output.lateral.is_finite());
                        prop_assert!(output.linear.abs() <= MAX_LINEAR_SPEED);
                        let sideways_cap = if sideways { 2.0 } else { 0.0 };
                        prop_assert!(output.lateral.abs() <= sideways_cap);
                        let moving = output.linear != 0.0 || output.lateral != 0.0 || output.angular != 0.0;
                        if stopped {
                            prop_assert!(!moving, "a stop is zero on every axis");
                        } else if moving {
                            prop_assert!((output.linear - before.linear).abs() <= 2.0 * 0.02 + 1e-9);
                            prop_assert!(!sideways || (output.lateral - before.lateral).abs() <= 2.0 * 0.02 + 1e-9);
                        }
                        if moving {
                            prop_assert!(at < newest_life, "moving past the life of every command accepted");
                            // Slowing down on every axis that moves is no start.
                            let slows = |now: f64, then: f64| now == 0.0 || now.abs() < then.abs();
                            let retaken = taken_at.iter().flatten().any(|at| *at > blocked_at)
                                || (slows(output.linear, before.linear)
                                    && slows(output.lateral, before.lateral));
                            prop_assert!(retaken, "moving with no take of control since the last gap, stop or release");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn ramp_moves_toward_the_target(current in -2.0f64..2.0, target in -2.0f64..2.0) {
        let next = ramp(current, target, 1.0, 2.0, 0.02);
        prop_assert!((next - target).abs() <= (current - target).abs() + 1e-12);
        prop_assert!((next - current).abs() <= 0.04 + 1e-12);
    }
}

#[test]
fn the_gateways_stops_are_released_only_by_an_operator() {
    let mut bench = Bench::new();
    bench
        .arbiter
        .handle_gap(bench.now, StopCause::Overrun, "late", false);
    let impostor = client(GATEWAY, 1);
    assert_eq!(
        bench
            .release(&impostor, ReleaseTarget::Own)
            .map_err(|r| r.kind()),
        Err(RejectionKind::NotAllowed)
    );
    bench
        .release(&operator("op", 2), ReleaseTarget::All)
        .expect("released");
}

#[test]
fn autonomy_cannot_wait_behind_a_teleop_holder() {
    let mut bench = Bench::new();
    let (joy, planner) = (client("joy", 1), client("planner", 2));
    bench.take(&joy, Class::Teleop);
    bench.request(&planner, Request::Resume).expect("resume");
    assert_eq!(
        bench.kind(
            &planner,
            Request::TakeControl {
                class: Class::Autonomy
            }
        ),
        Some(RejectionKind::Held)
    );
}

/// One act of the release property: a stop by client `who` (of four names, two of them taken
/// by both an operator and a non-operator), or a release by `who` with a view `lag` stops old.
#[derive(Debug, Clone)]
enum Act {
    Stop(usize),
    Release(usize, u8, u64),
}

fn any_act() -> impl Strategy<Value = Act> {
    prop_oneof![
        (0usize..8).prop_map(Act::Stop),
        (0usize..8, 0u8..3, 0u64..4).prop_map(|(who, target, lag)| Act::Release(who, target, lag)),
    ]
}

proptest! {
    /// Whatever names clients take and whenever releases arrive: a release never clears a stop
    /// latched after the view it was decided on, and a non-operator never clears a stop an
    /// operator latched, nor anyone else's, nor latches over an operator's.
    #[test]
    fn releases_clear_only_what_their_sender_saw_and_may_release(acts in prop::collection::vec(any_act(), 1..60)) {
        let mut bench = Bench::new();
        // Operators and non-operators under the same names ("operator", "guard").
        let who = [
            operator("operator", 1), client("operator", 2),
            operator("guard", 3), client("guard", 4),
            client("planner", 5), client("gateway", 6),
            user_client("guard", 7, Some(1001)), user_client("guard", 8, None),
        ];
        for act in acts {
            bench.now += ms(1);
            match act {
                Act::Stop(w) => {
                    let before: Vec<Stop> = bench.arbiter.stops().to_vec();
                    bench.stop(&who[w], &format!("by {w}"));
                    if !who[w].operator {
                        // An operator's stop, and another user's, keeps its id, owner and reason
                        // against anyone else.
                        let others = |s: &&Stop| s.by_operator || s.uid != who[w].key.uid;
                        for stop in before.iter().filter(others) {
                            prop_assert!(bench.arbiter.stops().contains(stop), "{stop} was rewritten");
                        }
                    }
                }
                Act::Release(w, target, lag) => {
                    let origin = &who[w];
                    let target = match target {
                        0 => ReleaseTarget::Own,
                        1 => ReleaseTarget::Owner("operator".into()),
                        _ => ReleaseTarget::All,
                    };
                    let through = bench.arbiter.newest_stop().saturating_sub(lag);
                    let before: Vec<Stop> = bench.arbiter.stops().to_vec();
                    let _ = bench.request(origin, Request::Release { target, through });
                    let after = bench.arbiter.stops();
                    for stop in before.iter().filter(|s| !after.contains(s)) {
                        prop_assert!(stop.id <= through, "released #{} seen through #{}", stop.id, through);
                        if !origin.operator {
                            prop_assert!(!stop.by_operator, "a non-operator released an operator's stop");
                            prop_assert_eq!(&stop.owner, &origin.key.name, "a non-operator released another's stop");
                            prop_assert!(stop.uid.is_some() && stop.uid == origin.key.uid, "a non-operator released another user's stop");
                        }
                    }
                }
            }
        }
    }
}

proptest! {
    /// Whatever a client asks of a steered chassis: the output never turns tighter than its
    /// radius, never turns standing still, and a turn in place is refused whole.
    #[test]
    fn a_steered_chassis_never_turns_tighter_than_it_can(asks in prop::collection::vec((-2.0f64..2.0, -2.0f64..2.0, 1u8..20), 1..40)) {
        let mut bench = steered();
        let joy = client("joy", 1);
        let lease = bench.take(&joy, Class::Teleop);
        for (linear, angular, ticks) in asks {
            // Standing still now and then.
            let linear = if linear.abs() < 0.2 { 0.0 } else { linear };
            let answer = turn(&mut bench, &joy, lease, linear, angular);
            if linear == 0.0 && angular != 0.0 {
                prop_assert!(answer.is_err(), "a turn in place was taken");
            }
            for _ in 0..ticks {
                let output = bench.tick();
                prop_assert!(output.angular.abs() <= output.linear.abs() / 1.31 + 1e-12, "{output:?}");
            }
        }
    }
}

#[test]
fn a_parked_chassis_in_motion_modes_refuses_a_drive_and_stands_still() {
    let mut bench = Bench::sideways(1.5);
    bench
        .arbiter
        .set_turning(Turning::Modes { min_radius: 0.4764 });
    bench
        .arbiter
        .set_motion_mode(Some(MotionModeV2::Park), false);
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    let refused = bench.drive_body(&joy, lease, 0.3, 0.0).expect_err("parked");
    assert_eq!(refused.kind(), RejectionKind::NotAllowed);
    assert!(
        refused
            .to_string()
            .starts_with("the chassis is in park mode (0x291)"),
        "{refused}"
    );
    assert_eq!(
        bench.drive_body(&joy, lease, 0.0, 0.0),
        Ok(Accepted::default())
    );
    let output = bench.tick();
    assert_eq!(
        (output.linear, output.lateral, output.angular),
        (0.0, 0.0, 0.0)
    );
    assert_eq!(
        output.mode,
        Some(MotionModeV2::Park),
        "no other mode asked for"
    );
}

/// A client that names a mode is driven in it (not in another that would carry its
/// velocity), told what the mode does not do, and may park the chassis; a chassis without
/// modes refuses a named one.
#[test]
fn a_named_mode_is_the_one_driven_in_and_what_it_cannot_do_is_refused() {
    let mut bench = Bench::sideways(1.5);
    bench
        .arbiter
        .set_turning(Turning::Modes { min_radius: 0.4764 });
    bench
        .arbiter
        .set_motion_mode(Some(MotionModeV2::DualAckermann), true);
    let joy = client("joy", 1);
    let lease = bench.take(&joy, Class::Teleop);
    let drive = |linear: f64, angular: f64, mode: DriveMode| Request::Drive {
        lease,
        linear,
        lateral: 0.0,
        angular,
        ttl: None,
        mode: Some(mode),
    };
    // Straight ahead, which dual Ackermann carries, named parallel: nothing moves until the
    // chassis is in parallel mode, which is asked for.
    bench
        .request(&joy, drive(0.5, 0.0, DriveMode::Parallel))
        .expect("taken");
    let output = bench.tick();
    assert_eq!(
        (output.linear, output.mode),
        (0.0, Some(MotionModeV2::Parallel))
    );
    bench
        .arbiter
        .set_motion_mode(Some(MotionModeV2::Parallel), true);
    bench
        .request(&joy, drive(0.5, 0.0, DriveMode::Parallel))
        .expect("taken");
    let output = bench.tick();
    assert!(output.linear > 0.0, "{output:?}");
    assert_eq!(output.mode, Some(MotionModeV2::Parallel));
    // What the mode does not do is refused, saying so.
    let refused = bench
        .request(&joy, drive(0.5, 0.3, DriveMode::Parallel))
        .expect_err("a turn in parallel mode");
    assert_eq!(refused.kind(), RejectionKind::NotAllowed);
    assert!(
        refused
            .to_string()
            .starts_with("parallel mode does not turn"),
        "{refused}"
    );
    // Parking: asked once the output is at zero (the drive ramps down first).
    let output = (0..50)
        .map(|_| {
            bench
                .request(&joy, drive(0.0, 0.0, DriveMode::Park))
                .expect("taken");
            bench.tick()
        })
        .last()
        .expect("ticks");
    assert_eq!(
        (output.linear, output.mode),
        (0.0, Some(MotionModeV2::Park))
    );
    // No modes: refused.
    let mut plain = Bench::new();
    let lease = plain.take(&joy, Class::Teleop);
    let refused = plain
        .request(
            &joy,
            Request::Drive {
                lease,
                linear: 0.5,
                lateral: 0.0,
                angular: 0.0,
                ttl: None,
                mode: Some(DriveMode::DualAckermann),
            },
        )
        .expect_err("no modes");
    assert!(
        refused
            .to_string()
            .starts_with("this chassis has no motion modes"),
        "{refused}"
    );
}

proptest! {
    /// Whatever a client asks of a chassis in motion modes (a Ranger), with the chassis taking
    /// a mode some ticks after it is asked for standing still: every tick's output is what the
    /// mode it reports carries, and nothing while it changes.
    #[test]
    fn a_chassis_in_motion_modes_moves_only_in_the_mode_it_reports(
        asks in prop::collection::vec((
            -2.0f64..2.0,
            prop_oneof![Just(0.0), -2.0f64..2.0],
            prop_oneof![Just(0.0), -5.0f64..5.0],
            1u8..40,
        ), 1..30),
        change in 1u8..60,
    ) {
        let mut bench = Bench::sideways(1.5);
        bench.arbiter.set_turning(Turning::Modes { min_radius: 0.4764 });
        let mut settled = Some(MotionModeV2::DualAckermann);
        let mut changing: Option<(MotionModeV2, u8)> = None;
        bench.arbiter.set_motion_mode(settled, true);
        let joy = client("joy", 1);
        let lease = bench.take(&joy, Class::Teleop);
        for (linear, lateral, angular, ticks) in asks {
            for _ in 0..ticks {
                let drive = Request::Drive { lease, linear, lateral, angular, ttl: None, mode: None };
                bench.request(&joy, drive).expect("taken or clamped, never refused");
                let output = bench.tick();
                let velocity = (output.linear, output.lateral, output.angular);
                match settled {
                    Some(mode) => prop_assert!(
                        crate::modes::carries(mode, velocity),
                        "{velocity:?} in {mode}"
                    ),
                    None => prop_assert_eq!(velocity, (0.0, 0.0, 0.0), "while changing"),
                }
                // The chassis: takes the mode asked for once still, `change` ticks later.
                match changing.as_mut() {
                    Some((mode, left)) => {
                        *left -= 1;
                        if *left == 0 {
                            settled = Some(*mode);
                            changing = None;
                        }
                    }
                    // As the core asks (`Core::follow_up_v2`): with the output at zero.
                    None => {
                        if let Some(wanted) = output.mode
                            && Some(wanted) != settled
                            && velocity == (0.0, 0.0, 0.0)
                        {
                            settled = None;
                            changing = Some((wanted, change));
                        }
                    }
                }
                bench.arbiter.set_motion_mode(settled, true);
            }
        }
    }
}

proptest! {
    /// Whatever a client asks, and whenever the chassis holds (a Hunter's brake not reported
    /// released): every held tick's output is zero on every field and still says a drive is
    /// asked (which is what releases the brake); once released, the output ramps up from zero,
    /// never jumping past one tick's acceleration.
    #[test]
    fn a_held_chassis_gets_zero_and_ramps_up_from_it_once_released(
        asks in prop::collection::vec((-2.0f64..2.0, -2.0f64..2.0, 1u8..20, any::<bool>()), 1..30),
    ) {
        let mut bench = Bench::new();
        let joy = client("joy", 1);
        let lease = bench.take(&joy, Class::Teleop);
        let mut before = 0.0_f64;
        let acceleration = ArbiterConfig::default().limits.linear_acceleration;
        for (linear, angular, ticks, held) in asks {
            bench.arbiter.set_held(held);
            for _ in 0..ticks {
                let drive = Request::Drive { lease, linear, lateral: 0.0, angular, ttl: None, mode: None };
                bench.request(&joy, drive).expect("taken or clamped, never refused");
                let output = bench.tick();
                prop_assert_eq!(output.drive, linear != 0.0 || angular != 0.0);
                if held {
                    prop_assert_eq!((output.linear, output.lateral, output.angular), (0.0, 0.0, 0.0));
                }
                let step = (output.linear - before).abs();
                prop_assert!(
                    output.linear.abs() <= before.abs() || step <= acceleration * TICK.as_secs_f64() + 1e-9,
                    "{before} to {}", output.linear
                );
                before = output.linear;
            }
        }
    }
}
