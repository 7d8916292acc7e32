//! Tests of the arbiter with a simulated clock, and property tests of its guarantees.

use std::time::Duration;

use proptest::prelude::*;
use scout_protocol::FaultClear;

use super::*;

const TICK: Duration = Duration::from_millis(20);

const fn ms(millis: u64) -> Duration {
    Duration::from_millis(millis)
}

fn client(name: &str, node: u128) -> ClientKey {
    ClientKey {
        name: name.into(),
        node,
    }
}

fn drive(class: Class, linear: f64, angular: f64) -> Request {
    Request::Drive {
        class,
        linear,
        angular,
        ttl: None,
    }
}

fn arbiter() -> Arbiter {
    Arbiter::new(ArbiterConfig::default(), DEFAULT_MAX_ANGULAR_SPEED)
}

/// Runs ticks from `from` for `duration`, sending `request` from `who` before each tick.
fn run(
    arbiter: &mut Arbiter,
    who: &ClientKey,
    request: Option<Request>,
    from: Duration,
    duration: Duration,
) -> (Duration, Output) {
    let mut now = from;
    let mut output = arbiter.output();
    while now < from + duration {
        if let Some(request) = &request {
            let _ = arbiter.handle_request(now, who, request.clone());
        }
        output = arbiter.poll_output(now, TICK);
        now += TICK;
    }
    (now, output)
}

#[test]
fn a_fresh_command_drives_with_the_acceleration_limit() {
    let mut arbiter = arbiter();
    let auto = client("planner", 1);
    assert_eq!(
        arbiter.handle_request(ms(0), &auto, drive(Class::Autonomy, 1.0, 0.0)),
        Ok(Accepted { clamped: false })
    );
    let first = arbiter.poll_output(ms(0), TICK);
    assert!((first.linear - 0.02).abs() < 1e-12, "1 m/s² over 20 ms");
    assert!(first.limited);
    let (_, output) = run(
        &mut arbiter,
        &auto,
        Some(drive(Class::Autonomy, 1.0, 0.0)),
        ms(20),
        ms(1200),
    );
    assert!((output.linear - 1.0).abs() < 1e-9);
    assert!(!output.limited);
}

#[test]
fn teleop_overrides_autonomy_and_disarms_it() {
    let mut arbiter = arbiter();
    let auto = client("planner", 1);
    let teleop = client("joystick", 2);
    arbiter
        .handle_request(ms(0), &auto, drive(Class::Autonomy, 0.5, 0.0))
        .expect("autonomy drives");
    assert_eq!(
        arbiter
            .selected(ms(0))
            .map(|(s, c)| (s.key.name.as_str(), c)),
        Some(("planner", Class::Autonomy))
    );
    arbiter
        .handle_request(ms(20), &teleop, drive(Class::Teleop, 0.0, 0.1))
        .expect("teleop drives");
    assert_eq!(
        arbiter
            .selected(ms(20))
            .map(|(s, c)| (s.key.name.as_str(), c)),
        Some(("joystick", Class::Teleop))
    );
    assert!(!arbiter.autonomy_armed());
    assert_eq!(
        arbiter.handle_request(ms(40), &auto, drive(Class::Autonomy, 0.5, 0.0)),
        Err(Rejection::AutonomyDisarmed)
    );
    // Teleop goes stale: no silent fall-back to autonomy.
    let (now, output) = run(&mut arbiter, &teleop, None, ms(40), ms(2000));
    assert_eq!(arbiter.selected(now), None);
    assert_eq!((output.linear, output.angular), (0.0, 0.0));
    arbiter
        .handle_request(now, &auto, Request::Resume)
        .expect("resume");
    arbiter
        .handle_request(now, &auto, drive(Class::Autonomy, 0.5, 0.0))
        .expect("autonomy again");
    assert_eq!(arbiter.selected(now).map(|(_, c)| c), Some(Class::Autonomy));
}

#[test]
fn a_class_is_held_until_released_or_stale() {
    let mut arbiter = arbiter();
    let (a, b) = (client("a", 1), client("b", 2));
    arbiter
        .handle_request(ms(0), &a, drive(Class::Teleop, 0.2, 0.0))
        .expect("a holds teleop");
    assert_eq!(
        arbiter.handle_request(ms(10), &b, drive(Class::Teleop, 0.2, 0.0)),
        Err(Rejection::Held {
            class: Class::Teleop,
            holder: "a".into()
        })
    );
    assert_eq!(
        Rejection::Held {
            class: Class::Teleop,
            holder: "a".into()
        }
        .to_string(),
        "teleop held by a"
    );
    // Stale after 250 ms (the teleop maximum age): b may take it.
    arbiter
        .handle_request(ms(260), &b, drive(Class::Teleop, 0.2, 0.0))
        .expect("a went stale");
    arbiter
        .handle_request(ms(280), &b, Request::Release)
        .expect("release");
    arbiter
        .handle_request(ms(300), &a, drive(Class::Teleop, 0.2, 0.0))
        .expect("b released");
}

#[test]
fn freshness_is_the_shorter_of_ttl_and_class_age() {
    let mut arbiter = arbiter();
    let auto = client("planner", 1);
    let request = Request::Drive {
        class: Class::Autonomy,
        linear: 0.3,
        angular: 0.0,
        ttl: Some(ms(100)),
    };
    arbiter
        .handle_request(ms(0), &auto, request)
        .expect("drive");
    assert!(arbiter.selected(ms(99)).is_some());
    assert!(arbiter.selected(ms(100)).is_none(), "the TTL");
    let request = Request::Drive {
        class: Class::Autonomy,
        linear: 0.3,
        angular: 0.0,
        ttl: Some(ms(5000)),
    };
    arbiter
        .handle_request(ms(200), &auto, request)
        .expect("drive");
    assert!(arbiter.selected(ms(699)).is_some());
    assert!(arbiter.selected(ms(700)).is_none(), "the class's 500 ms");
}

#[test]
fn stop_latches_at_once_and_release_does_not_restart_motion() {
    let mut arbiter = arbiter();
    let teleop = client("joystick", 1);
    let safety = client("safety", 2);
    let (now, output) = run(
        &mut arbiter,
        &teleop,
        Some(drive(Class::Teleop, 1.0, 0.0)),
        ms(0),
        ms(1000),
    );
    assert!(output.linear > 0.9);
    arbiter
        .handle_request(
            now,
            &safety,
            Request::Stop {
                reason: "person ahead".into(),
            },
        )
        .expect("stop");
    assert!(
        arbiter.take_urgent_stop(),
        "the caller sends zero now, not at the next tick"
    );
    assert!(!arbiter.take_urgent_stop());
    assert_eq!(arbiter.output().linear, 0.0, "no ramp for the stop");
    assert_eq!(
        arbiter.handle_request(now, &teleop, drive(Class::Teleop, 1.0, 0.0)),
        Err(Rejection::Latched {
            by: "safety".into()
        })
    );
    let (now, output) = run(&mut arbiter, &teleop, None, now, ms(2000));
    assert_eq!(output.linear, 0.0);
    assert_eq!(arbiter.latch().map(|l| l.by.as_str()), Some("safety"));
    arbiter
        .handle_request(now, &teleop, Request::Release)
        .expect("release");
    let (now, output) = run(&mut arbiter, &teleop, None, now, ms(500));
    assert_eq!(output.linear, 0.0, "release alone does not move");
    let (_, output) = run(
        &mut arbiter,
        &teleop,
        Some(drive(Class::Teleop, 0.5, 0.0)),
        now,
        ms(1000),
    );
    assert!(output.linear > 0.4, "a new command after the release moves");
}

#[test]
fn resume_is_refused_while_latched() {
    let mut arbiter = arbiter();
    let any = client("x", 1);
    arbiter
        .handle_request(
            ms(0),
            &any,
            Request::Stop {
                reason: "test".into(),
            },
        )
        .expect("stop");
    assert_eq!(
        arbiter.handle_request(ms(1), &any, Request::Resume),
        Err(Rejection::Latched { by: "x".into() })
    );
}

#[test]
fn a_missed_heartbeat_latches_the_stop() {
    let mut arbiter = arbiter();
    let remote = client("deadman", 1);
    arbiter
        .handle_request(ms(0), &remote, Request::Heartbeat { period: ms(100) })
        .expect("register");
    arbiter
        .handle_request(ms(90), &remote, Request::Heartbeat { period: ms(100) })
        .expect("beat");
    arbiter.poll_output(ms(180), TICK);
    assert!(arbiter.latch().is_none());
    arbiter.poll_output(ms(191), TICK);
    let latch = arbiter.latch().expect("latched");
    assert_eq!(latch.by, "deadman");
    assert!(
        latch.reason.contains("heartbeat missed"),
        "{}",
        latch.reason
    );
}

#[test]
fn a_dead_driving_client_releases_at_once() {
    let mut arbiter = arbiter();
    let auto = client("planner", 7);
    let (now, output) = run(
        &mut arbiter,
        &auto,
        Some(drive(Class::Autonomy, 1.0, 0.0)),
        ms(0),
        ms(1500),
    );
    assert!(output.linear > 0.9);
    arbiter.handle_node_gone(now, 7);
    assert!(
        arbiter.selected(now).is_none(),
        "no waiting for the command to age"
    );
    let next = arbiter.poll_output(now, TICK);
    assert!(
        (output.linear - next.linear - 0.04).abs() < 1e-9,
        "ramps down at 2 m/s²"
    );
    assert!(arbiter.sources().is_empty());
}

#[test]
fn a_dead_heartbeat_source_latches() {
    let mut arbiter = arbiter();
    let remote = client("deadman", 3);
    arbiter
        .handle_request(ms(0), &remote, Request::Heartbeat { period: ms(200) })
        .expect("register");
    arbiter.handle_node_gone(ms(10), 3);
    assert_eq!(
        arbiter.latch().map(|l| l.reason.as_str()),
        Some("heartbeat source died")
    );
}

#[test]
fn bad_values_are_rejected_and_counted_big_ones_clamped() {
    let mut arbiter = arbiter();
    let who = client("fuzzer", 1);
    for (linear, angular) in [
        (f64::NAN, 0.0),
        (0.0, f64::INFINITY),
        (f64::NEG_INFINITY, f64::NAN),
    ] {
        assert_eq!(
            arbiter.handle_request(ms(0), &who, drive(Class::Teleop, linear, angular)),
            Err(Rejection::NotFinite)
        );
    }
    assert_eq!(
        arbiter.rejections()[usize::from(Rejection::NotFinite.kind().raw())],
        3
    );
    assert_eq!(
        arbiter.handle_request(ms(0), &who, drive(Class::Teleop, 1e9, -1e9)),
        Ok(Accepted { clamped: true })
    );
    let (_, output) = run(
        &mut arbiter,
        &who,
        Some(drive(Class::Teleop, 1e9, -1e9)),
        ms(0),
        ms(3000),
    );
    assert!((output.linear - MAX_LINEAR_SPEED).abs() < 1e-9);
    assert!((output.angular + DEFAULT_MAX_ANGULAR_SPEED).abs() < 1e-9);
    assert!(output.limited, "clamping is flagged");
    assert!(matches!(
        arbiter.handle_request(ms(0), &client("", 2), Request::Resume),
        Err(Rejection::Malformed(_))
    ));
}

#[test]
fn fault_clear_goes_out_in_three_commands_then_stops() {
    let mut arbiter = arbiter();
    let who = client("operator", 1);
    let one = Request::ClearFault(Some(FaultClear::DriverOverTemp));
    arbiter.handle_request(ms(0), &who, one).expect("clear");
    let codes: Vec<FaultClear> = (0..5)
        .map(|i| arbiter.poll_output(ms(i * 20), TICK).fault_clear)
        .collect();
    use FaultClear::{DriverOverTemp as T, None as N};
    assert_eq!(codes, [T, T, T, N, N]);
    arbiter
        .handle_request(ms(100), &who, Request::ClearFault(None))
        .expect("clear all");
    let codes: Vec<FaultClear> = (0..26)
        .map(|i| arbiter.poll_output(ms(120 + i * 20), TICK).fault_clear)
        .collect();
    let mut expected: Vec<FaultClear> = FaultClear::ALL.iter().flat_map(|c| [*c; 3]).collect();
    expected.extend([N, N]);
    assert_eq!(codes, expected);
}

#[test]
fn lights_last_writer_wins() {
    let mut arbiter = arbiter();
    let on = LightsSetting::Manual(scout_protocol::LightCommand {
        enabled: true,
        ..Default::default()
    });
    arbiter
        .handle_request(ms(0), &client("a", 1), Request::Lights(on))
        .expect("lights");
    arbiter
        .handle_request(ms(1), &client("b", 2), Request::Lights(LightsSetting::Auto))
        .expect("auto");
    assert_eq!(arbiter.lights(), Some(LightsSetting::Auto));
}

#[test]
fn auto_resume_keeps_autonomy_armed() {
    let config = ArbiterConfig {
        auto_resume: true,
        ..ArbiterConfig::default()
    };
    let mut arbiter = Arbiter::new(config, DEFAULT_MAX_ANGULAR_SPEED);
    arbiter
        .handle_request(ms(0), &client("t", 1), drive(Class::Teleop, 0.1, 0.0))
        .expect("teleop");
    assert!(arbiter.autonomy_armed());
}

#[test]
fn config_is_checked() {
    assert!(ArbiterConfig::default().validate().is_ok());
    let too_old = ArbiterConfig {
        teleop_max_age_ms: 600,
        ..ArbiterConfig::default()
    };
    assert!(too_old.validate().expect_err("600 ms").contains("1..=500"));
}

/// A random request from one of four clients (two per class).
fn any_step() -> impl Strategy<Value = (u8, Request, u64)> {
    let speed = prop_oneof![
        4 => -2.0f64..2.0,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => -1e6f64..1e6,
    ];
    let request = prop_oneof![
        8 => (any::<bool>(), speed.clone(), speed, proptest::option::of(0u64..700)).prop_map(
            |(teleop, linear, angular, ttl)| Request::Drive {
                class: if teleop { Class::Teleop } else { Class::Autonomy },
                linear,
                angular,
                ttl: ttl.map(Duration::from_millis),
            }
        ),
        1 => Just(Request::Stop { reason: "prop".into() }),
        1 => Just(Request::Release),
        1 => Just(Request::Relinquish),
        1 => Just(Request::Resume),
    ];
    (0u8..4, request, 0u64..60)
}

proptest! {
    /// Whatever the clients send: the output is finite and within the caps; outside a stop it
    /// changes by no more than the rate limits per tick; latched means zero; the selected source
    /// is fresh, allowed, and of the highest class present.
    #[test]
    fn guarantees_hold_for_any_request_sequence(steps in proptest::collection::vec(any_step(), 1..200)) {
        let config = ArbiterConfig::default();
        let limits = config.limits;
        let mut arbiter = Arbiter::new(config, DEFAULT_MAX_ANGULAR_SPEED);
        let clients: Vec<ClientKey> = (0..4u8).map(|i| client(&format!("c{i}"), u128::from(i))).collect();
        let mut now = Duration::ZERO;
        let mut previous = arbiter.output();
        for (who, request, wait_ms) in steps {
            let _ = arbiter.handle_request(now, &clients[usize::from(who)], request);
            let stopped_now = arbiter.take_urgent_stop();
            if let Some((source, class)) = arbiter.selected(now) {
                prop_assert!(arbiter.latch().is_none());
                prop_assert_eq!(source.holding, Some(class));
                prop_assert!(source.fresh_command(now).is_some());
                prop_assert!(class == Class::Teleop || arbiter.autonomy_armed());
                if class == Class::Autonomy {
                    let teleop_fresh = arbiter.sources().iter().any(|s| {
                        s.holding == Some(Class::Teleop) && s.fresh_command(now).is_some()
                    });
                    prop_assert!(!teleop_fresh, "autonomy selected over a fresh teleop");
                }
            }
            let output = arbiter.poll_output(now, TICK);
            prop_assert!(output.linear.is_finite() && output.angular.is_finite());
            prop_assert!(output.linear.abs() <= MAX_LINEAR_SPEED + 1e-12);
            prop_assert!(output.angular.abs() <= DEFAULT_MAX_ANGULAR_SPEED + 1e-12);
            if arbiter.latch().is_some() {
                prop_assert_eq!((output.linear, output.angular), (0.0, 0.0));
            } else if !stopped_now {
                let dt = TICK.as_secs_f64();
                let linear_step = limits.linear_acceleration.max(limits.linear_deceleration) * dt;
                let angular_step = limits.angular_acceleration.max(limits.angular_deceleration) * dt;
                prop_assert!((output.linear - previous.linear).abs() <= linear_step + 1e-12);
                prop_assert!((output.angular - previous.angular).abs() <= angular_step + 1e-12);
            }
            previous = output;
            now += Duration::from_millis(wait_ms);
        }
    }

    /// After a release, nothing moves until a client sends a new drive command.
    #[test]
    fn no_motion_after_release_without_a_new_command(ticks in 1usize..100) {
        let mut arbiter = arbiter();
        let who = client("x", 1);
        let (now, _) = run(&mut arbiter, &who, Some(drive(Class::Teleop, 1.0, 0.3)), ms(0), ms(1000));
        arbiter.handle_request(now, &who, Request::Stop { reason: "p".into() }).expect("stop");
        arbiter.handle_request(now, &who, Request::Release).expect("release");
        let mut t = now;
        for _ in 0..ticks {
            let output = arbiter.poll_output(t, TICK);
            prop_assert_eq!((output.linear, output.angular), (0.0, 0.0));
            t += TICK;
        }
    }

    /// The ramp never overshoots the target and never reverses in one step faster than allowed.
    #[test]
    fn ramp_moves_toward_the_target(current in -2.0f64..2.0, target in -2.0f64..2.0) {
        let next = ramp(current, target, 1.0, 2.0, 0.02);
        prop_assert!((next - target).abs() <= (current - target).abs() + 1e-12);
        prop_assert!((next - current).abs() <= 0.04 + 1e-12);
        if current != 0.0 && next != 0.0 {
            prop_assert!(next.signum() == current.signum(), "stops at zero before reversing");
        }
    }
}

#[test]
fn relinquish_leaves_the_stop_alone() {
    let mut arbiter = arbiter();
    let (driver, safety) = (client("driver", 1), client("safety", 2));
    arbiter
        .handle_request(ms(0), &driver, drive(Class::Teleop, 0.5, 0.0))
        .expect("drive");
    arbiter
        .handle_request(
            ms(10),
            &safety,
            Request::Stop {
                reason: "test".into(),
            },
        )
        .expect("stop");
    arbiter
        .handle_request(ms(20), &driver, Request::Relinquish)
        .expect("relinquish");
    assert!(
        arbiter.latch().is_some(),
        "a client giving up control does not release the stop"
    );
    arbiter
        .handle_request(ms(30), &safety, Request::Release)
        .expect("release");
    arbiter
        .handle_request(ms(40), &driver, drive(Class::Teleop, 0.5, 0.0))
        .expect("drive");
    arbiter
        .handle_request(ms(50), &driver, Request::Relinquish)
        .expect("relinquish");
    assert!(arbiter.selected(ms(50)).is_none());
}
