//! A Ranger's motion modes, without I/O: the mode a body velocity needs, whether the mode the
//! chassis is in carries it, and how a velocity no mode carries is brought to one.
//!
//! Mode selection as the vendor's driver does it (agilexrobotics/ranger_ros2
//! `ranger_messenger.cpp` `TwistCmdCallback`): sideways is parallel, a turn tighter than the
//! minimum radius spins in place, anything else is dual Ackermann. What differs: a drive
//! straight ahead stays in parallel mode when the chassis is in it (no stop to change to dual
//! Ackermann for the wheels to point the way they already do), and a velocity is only ever
//! carried in a mode the chassis reports it is in (0x291), never while it changes.

use scout_protocol::v2::MotionModeV2;

/// A body velocity: m/s forward, m/s leftward, rad/s counter-clockwise.
pub type Velocity = (f64, f64, f64);

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

/// `velocity` as one mode carries it, the wheels no faster than `speed` m/s: sideways keeps
/// its direction and drops the turn (parallel mode does not turn); a turn tighter than
/// `min_radius` m spins in place and drops the forward speed (as the vendor's driver does).
/// Whatever changed is the caller's to answer as clamped.
pub fn one_mode(velocity: Velocity, min_radius: f64, speed: f64) -> Velocity {
    match velocity {
        (linear, lateral, _) if lateral != 0.0 => {
            let wheels = linear.hypot(lateral);
            let scale = if wheels > speed { speed / wheels } else { 1.0 };
            (linear * scale, lateral * scale, 0.0)
        }
        (linear, _, angular) if linear.abs() < min_radius * angular.abs() => (0.0, 0.0, angular),
        (linear, _, angular) => (linear, 0.0, angular),
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

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const RADIUS: f64 = 0.4764;

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
        assert_eq!(one_mode((0.1, 0.0, 1.0), RADIUS, 1.5), (0.0, 0.0, 1.0));
        assert_eq!(one_mode((0.5, 0.0, 1.0), RADIUS, 1.5), (0.5, 0.0, 1.0));
        assert_eq!(one_mode((0.3, 0.4, 0.5), RADIUS, 1.5), (0.3, 0.4, 0.0));
        let (linear, lateral, _) = one_mode((1.5, 1.5, 0.0), RADIUS, 1.5);
        assert!((linear.hypot(lateral) - 1.5).abs() < 1e-12 && linear == lateral);
        // Straight ahead goes on in parallel mode.
        assert!(carries(MotionModeV2::Parallel, (0.5, 0.0, 0.0)));
        assert!(!carries(MotionModeV2::DualAckermann, (0.0, 0.0, 0.5)));
        assert!(!carries(MotionModeV2::Park, (0.1, 0.0, 0.0)));
    }

    proptest! {
        #[test]
        fn one_mode_is_carried_by_the_mode_it_wants_and_changing_moves_nothing(
            linear in -2.0f64..2.0,
            lateral in prop_oneof![Just(0.0), -2.0f64..2.0],
            angular in prop_oneof![Just(0.0), -5.0f64..5.0],
            mode in 0u8..6,
        ) {
            let velocity = one_mode((linear, lateral, angular), RADIUS, 1.5);
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
