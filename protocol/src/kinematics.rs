//! Planar motion: a pose moved by a body velocity over a time step, and a steered model's
//! yaw rate and steering angles. One copy for the gateway's odometry and mapping and the
//! simulator's ground truth.

/// A pose in the plane: metres and radians (yaw in -pi..pi).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct Pose {
    /// m.
    pub x: f64,
    /// m.
    pub y: f64,
    /// rad, -pi..pi.
    pub yaw: f64,
}

impl Pose {
    /// Moves the pose at `linear` m/s and `angular` rad/s for `dt` seconds, along the heading
    /// at the middle of the step (exact for constant speeds up to second order).
    pub fn step(&mut self, linear: f64, angular: f64, dt: f64) {
        self.step_body(linear, 0.0, angular, dt);
    }

    /// Moves the pose at a body velocity (`linear` m/s forward, `lateral` m/s leftward,
    /// `angular` rad/s) for `dt` seconds, along the heading at the middle of the step.
    pub fn step_body(&mut self, linear: f64, lateral: f64, angular: f64, dt: f64) {
        let mid_yaw = self.yaw + angular * dt / 2.0;
        let (sin, cos) = mid_yaw.sin_cos();
        self.x += (linear * cos - lateral * sin) * dt;
        self.y += (linear * sin + lateral * cos) * dt;
        self.yaw = wrap_angle(self.yaw + angular * dt);
    }
}

/// `angle` brought into -pi..pi.
pub fn wrap_angle(angle: f64) -> f64 {
    use core::f64::consts::PI;
    (angle + PI).rem_euclid(2.0 * PI) - PI
}

/// Front-wheel Ackermann steering, as the Hunter's vendor driver does it (agilexrobotics/
/// hunter_ros2 `hunter_messenger.hpp`: `ConvertCentralAngleToInner`,
/// `ConvertInnerAngleToCentral`, the bicycle model's yaw rate `v / L * tan(delta)`), checked
/// against that source. The central angle is the bicycle model's; the inner wheel is the one
/// on the inside of the turn, the angle 0x111 and 0x221 carry. Angles are positive to the
/// left; a yaw rate is counter-clockwise, so backing up with the wheels to the left turns
/// clockwise.
impl crate::model::Steering {
    /// The tightest turn, m: the rear axle's radius at the widest central angle.
    pub fn min_radius(&self) -> f64 {
        self.wheelbase / self.max_central.tan()
    }

    /// The fastest yaw rate at `linear` m/s, rad/s (none standing still).
    pub fn max_yaw_rate(&self, linear: f64) -> f64 {
        linear.abs() / self.min_radius()
    }

    /// The yaw rate at `linear` m/s with the central angle `central`, rad/s.
    pub fn yaw_rate(&self, linear: f64, central: f64) -> f64 {
        linear * central.tan() / self.wheelbase
    }

    /// The central angle that turns at `angular` rad/s at `linear` m/s, within the widest
    /// (straight ahead standing still, where no angle turns).
    pub fn central_for(&self, linear: f64, angular: f64) -> f64 {
        if linear == 0.0 {
            return 0.0;
        }
        (angular * self.wheelbase / linear)
            .atan()
            .clamp(-self.max_central, self.max_central)
    }

    /// The inner wheel's angle for the central angle `central`.
    pub fn inner_from_central(&self, central: f64) -> f64 {
        let magnitude = central.abs();
        if magnitude == 0.0 {
            return 0.0;
        }
        let radius = self.wheelbase / magnitude.tan();
        let inner = (self.wheelbase / (radius - self.track / 2.0)).atan();
        inner.copysign(central)
    }

    /// The central angle for the inner wheel's angle `inner`.
    pub fn central_from_inner(&self, inner: f64) -> f64 {
        let magnitude = inner.abs();
        if magnitude == 0.0 {
            return 0.0;
        }
        let radius = self.wheelbase / magnitude.tan() + self.track / 2.0;
        (self.wheelbase / radius).atan().copysign(inner)
    }

    /// The yaw rate at `linear` m/s with the inner wheel at `inner` rad.
    pub fn yaw_rate_from_inner(&self, linear: f64, inner: f64) -> f64 {
        self.yaw_rate(linear, self.central_from_inner(inner))
    }

    /// The front left and right wheels' angles with the inner wheel at `inner` rad: the inner
    /// one at `inner`, the outer one on the same circle, less steered.
    pub fn front_wheels(&self, inner: f64) -> (f64, f64) {
        let magnitude = inner.abs();
        if magnitude == 0.0 {
            return (0.0, 0.0);
        }
        let radius = self.wheelbase / magnitude.tan() + self.track / 2.0;
        let outer = (self.wheelbase / (radius + self.track / 2.0))
            .atan()
            .copysign(inner);
        if inner > 0.0 {
            (inner, outer)
        } else {
            (outer, inner)
        }
    }
}

/// Four-wheel steering in its modes (the Rangers), from the geometry: in dual Ackermann both
/// axles steer mirrored, so the turn's centre is abreast of the body's centre and the inner
/// wheels sit half the wheelbase ahead of and behind it, half the track inside the body's
/// circle: tan(inner) = (wheelbase / 2) / (radius - track / 2), the angle 0x111 carries
/// (agilexrobotics/ranger_ros2 `CalculateSteeringAngle`, checked against it; its odometry
/// reads the angle back with a front-wheel model instead, which is where its owners see half
/// of every rotation lost, ranger_ros2#21). In parallel mode every wheel points one way, the
/// body moves that way without turning. Angles are positive to the left, as for the Hunter.
impl crate::model::FourWheel {
    /// Dual Ackermann's tightest turn, m: the body centre's radius with the inner wheels at
    /// their widest (0.4764 m for a Ranger Mini, the source's `min_turn_radius`).
    pub fn min_radius(&self) -> f64 {
        self.wheelbase / 2.0 / self.max_inner.tan() + self.track / 2.0
    }

    /// Dual Ackermann: the inner wheels' angle that turns at `angular` rad/s at `linear` m/s,
    /// within the widest (straight ahead when either is zero).
    pub fn inner_for(&self, linear: f64, angular: f64) -> f64 {
        if linear == 0.0 || angular == 0.0 {
            return 0.0;
        }
        let radius = linear / angular;
        let inside = radius.abs() - self.track / 2.0;
        let magnitude = if inside <= 0.0 {
            self.max_inner
        } else {
            (self.wheelbase / 2.0 / inside).atan().min(self.max_inner)
        };
        magnitude.copysign(radius)
    }

    /// Dual Ackermann: the yaw rate at `linear` m/s with the inner wheels at `inner` rad.
    pub fn yaw_rate_from_inner(&self, linear: f64, inner: f64) -> f64 {
        let magnitude = inner.abs();
        if magnitude == 0.0 {
            return 0.0;
        }
        let radius = self.wheelbase / 2.0 / magnitude.tan() + self.track / 2.0;
        (linear / radius).copysign(linear * inner)
    }

    /// Parallel mode: the wheels' speed and angle that move the body `linear` m/s forward and
    /// `lateral` m/s leftward. The angle stays within a quarter turn, the speed is negative
    /// backing up; straight sideways points the wheels left and drives them at `lateral`.
    pub fn parallel_for(&self, linear: f64, lateral: f64) -> (f64, f64) {
        let angle = if linear == 0.0 {
            if lateral == 0.0 {
                return (0.0, 0.0);
            }
            core::f64::consts::FRAC_PI_2
        } else {
            (lateral / linear).atan()
        };
        let speed = if linear == 0.0 {
            lateral
        } else {
            linear.hypot(lateral).copysign(linear)
        };
        (speed, angle.clamp(-self.max_parallel, self.max_parallel))
    }

    /// Parallel mode: the body's forward and leftward speeds, m/s, with the wheels at `speed`
    /// m/s and `angle` rad.
    pub fn body_from_parallel(&self, speed: f64, angle: f64) -> (f64, f64) {
        let (sin, cos) = angle.sin_cos();
        (speed * cos, speed * sin)
    }

    /// Each wheel's angle (rad, within a quarter turn) and speed (m/s, negative rolling
    /// backwards) when the body moves at `linear` m/s forward, `lateral` m/s leftward and
    /// `angular` rad/s, in the order front left, front right, rear left, rear right (the
    /// simulator's: which wheel 0x271 and 0x281 name first, no source says). Each wheel rolls
    /// along its own velocity as a point of the rigid body: the same in every mode.
    pub fn wheels(&self, linear: f64, lateral: f64, angular: f64) -> [(f64, f64); 4] {
        let (x, y) = (self.wheelbase / 2.0, self.track / 2.0);
        [(x, y), (x, -y), (-x, y), (-x, -y)].map(|(x, y)| {
            let (forward, leftward) = (linear - angular * y, lateral + angular * x);
            let speed = forward.hypot(leftward);
            match (forward, leftward) {
                (0.0, 0.0) => (0.0, 0.0),
                (0.0, _) => (core::f64::consts::FRAC_PI_2, leftward),
                _ => ((leftward / forward).atan(), speed.copysign(forward)),
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;

    #[test]
    fn a_hunters_outer_front_wheel_is_on_the_inner_ones_circle() {
        let hunter = crate::model::Model::Hunter2
            .steering()
            .expect("a steered model");
        assert_eq!(hunter.front_wheels(0.0), (0.0, 0.0));
        let (left, right) = hunter.front_wheels(0.4);
        assert!(left == 0.4 && right > 0.0 && right < left, "{left} {right}");
        // Both wheels' axes meet the rear axle's line at one point (the turn's centre).
        let centre = |angle: f64, side: f64| hunter.wheelbase / angle.tan() + side;
        let track = hunter.track / 2.0;
        assert!((centre(left, track) - centre(right, -track)).abs() < 1e-9);
        assert_eq!(hunter.front_wheels(-0.4), (-right, -0.4));
    }

    #[test]
    fn the_hunters_steering_is_its_vendors() {
        let hunter = crate::model::Model::Hunter2
            .steering()
            .expect("a steered model");
        // The widest central angle is about the widest inner one (0.58 rad in the source).
        let inner = hunter.inner_from_central(hunter.max_central);
        assert!((inner - 0.573).abs() < 0.001, "{inner}");
        assert!(inner <= hunter.max_inner);
        for central in [-0.461, -0.2, -0.01, 0.0, 0.003, 0.3, 0.461] {
            let back = hunter.central_from_inner(hunter.inner_from_central(central));
            assert!((back - central).abs() < 1e-12, "{central}: {back}");
        }
        // Its limits: 1.31 m at the tightest, 1.146 rad/s at 1.5 m/s there.
        assert!((hunter.min_radius() - 1.309).abs() < 0.001);
        let limits = crate::model::Model::Hunter2.limits();
        assert!((hunter.max_yaw_rate(limits.linear) - limits.angular).abs() < 0.001);
        // Left forward, right backward; nothing standing still.
        assert!(hunter.central_for(0.5, 0.2) > 0.0);
        assert!(hunter.central_for(-0.5, 0.2) < 0.0);
        assert_eq!(hunter.central_for(0.0, 0.2), 0.0);
        let central = hunter.central_for(0.5, 0.2);
        assert!((hunter.yaw_rate(0.5, central) - 0.2).abs() < 1e-12);
        assert!((hunter.yaw_rate(-0.5, hunter.central_for(-0.5, 0.2)) - 0.2).abs() < 1e-12);
        // Tighter than it turns: the widest angle.
        assert_eq!(hunter.central_for(0.1, 5.0), hunter.max_central);
    }

    #[test]
    fn the_hunter_ses_steering_is_its_manuals() {
        let model = crate::model::Model::HunterSe;
        let se = model.steering().expect("a steered model");
        // Its widest central angle is its manual's widest inner one (0.4 rad), within a mrad
        // and never beyond.
        let inner = se.inner_from_central(se.max_central);
        assert!(inner <= se.max_inner && inner > 0.399, "{inner}");
        // 1.571 m at the tightest; 3.054 rad/s at 4.8 m/s there.
        assert!(
            (se.min_radius() - 1.571).abs() < 0.001,
            "{}",
            se.min_radius()
        );
        let limits = model.limits();
        assert!((se.max_yaw_rate(limits.linear) - limits.angular).abs() < 0.001);
        assert!(se.max_yaw_rate(limits.linear) >= limits.angular);
    }

    #[test]
    fn each_rangers_wheel_points_where_its_mode_says() {
        let ranger = crate::model::Model::RangerMini3
            .four_wheel()
            .expect("a four-wheel-steered model");
        // Dual Ackermann turning left: the front left wheel at the inner angle the command
        // carries, the rear ones mirrored, the outer ones wider apart and faster.
        let inner = ranger.inner_for(0.5, 0.5);
        let [fl, fr, rl, rr] = ranger.wheels(0.5, 0.0, 0.5);
        assert!(
            (fl.0 - inner).abs() < 1e-12 && (rl.0 + inner).abs() < 1e-12,
            "{fl:?} {rl:?}"
        );
        assert!(
            fr.0 < fl.0 && (rr.0 + fr.0).abs() < 1e-12 && fr.1 > fl.1,
            "{fr:?} {fl:?}"
        );
        // Parallel: every wheel at one angle and speed.
        let (speed, angle) = ranger.parallel_for(0.3, 0.3);
        for wheel in ranger.wheels(0.3, 0.3, 0.0) {
            assert!((wheel.0 - angle).abs() < 1e-12 && (wheel.1 - speed).abs() < 1e-12);
        }
        // Spin: tangent to the circle about the centre, the wheels' speeds equal.
        let spin = ranger.wheels(0.0, 0.0, 1.0);
        let corner = (ranger.wheelbase / 2.0).hypot(ranger.track / 2.0);
        for (angle, speed) in spin {
            assert!((speed.abs() - corner).abs() < 1e-12, "{spin:?}");
            assert!(angle.abs() > 0.5 && angle.abs() < 1.2, "{spin:?}");
        }
        assert_eq!(ranger.wheels(0.0, 0.0, 0.0), [(0.0, 0.0); 4]);
    }

    #[test]
    fn the_rangers_modes_are_its_geometry() {
        let ranger = crate::model::Model::RangerMini3
            .four_wheel()
            .expect("a four-wheel-steered model");
        // The source's min_turn_radius, from its widest inner angle.
        assert!(
            (ranger.min_radius() - 0.4764).abs() < 0.0005,
            "{}",
            ranger.min_radius()
        );
        // ranger_ros2 CalculateSteeringAngle: atan((L/2) / (R - W/2)), signed by v x w.
        let inner = ranger.inner_for(0.5, 0.5);
        assert!((inner - (0.247f64 / (1.0 - 0.182)).atan()).abs() < 1e-12);
        assert!(ranger.inner_for(-0.5, 0.5) < 0.0 && ranger.inner_for(0.5, -0.5) < 0.0);
        assert!(ranger.inner_for(-0.5, -0.5) > 0.0);
        assert_eq!(ranger.inner_for(0.0, 0.5), 0.0);
        assert_eq!(ranger.inner_for(0.1, 5.0), ranger.max_inner);
        for (linear, angular) in [
            (0.5, 0.5),
            (-0.5, 0.5),
            (0.3, -0.2),
            (-1.0, -2.0),
            (1.5, 0.1),
        ] {
            let back = ranger.yaw_rate_from_inner(linear, ranger.inner_for(linear, angular));
            assert!((back - angular).abs() < 1e-9, "{linear} {angular}: {back}");
        }
        // Parallel: any direction, the wheels within a quarter turn.
        for (linear, lateral) in [
            (0.3, 0.4),
            (-0.3, 0.4),
            (0.3, -0.4),
            (-0.3, -0.4),
            (0.0, 0.5),
            (0.0, -0.5),
            (0.5, 0.0),
        ] {
            let (speed, angle) = ranger.parallel_for(linear, lateral);
            assert!(angle.abs() <= ranger.max_parallel);
            let (x, y) = ranger.body_from_parallel(speed, angle);
            assert!(
                (x - linear).abs() < 1e-3 && (y - lateral).abs() < 1e-3,
                "{linear} {lateral}: {x} {y}"
            );
        }
        assert_eq!(ranger.parallel_for(0.0, 0.0), (0.0, 0.0));
    }

    #[test]
    fn straight_and_turning_steps() {
        let mut pose = Pose::default();
        pose.step(1.0, 0.0, 0.5);
        assert!((pose.x - 0.5).abs() < 1e-12 && pose.y.abs() < 1e-12);
        let mut circle = Pose::default();
        for _ in 0..1000 {
            circle.step(1.0, 1.0, 2.0 * PI / 1000.0);
        }
        assert!(circle.x.abs() < 1e-6 && circle.y.abs() < 1e-6, "{circle:?}");
    }

    #[test]
    fn sideways_is_leftward_of_the_heading() {
        let mut pose = Pose {
            yaw: PI / 2.0,
            ..Pose::default()
        };
        // Facing +y, leftward is -x.
        pose.step_body(0.0, 1.0, 0.0, 0.5);
        assert!(
            (pose.x + 0.5).abs() < 1e-12 && pose.y.abs() < 1e-12,
            "{pose:?}"
        );
        // Sideways while turning closes a circle as forward does.
        let mut circle = Pose::default();
        for _ in 0..1000 {
            circle.step_body(0.0, 1.0, 1.0, 2.0 * PI / 1000.0);
        }
        assert!(circle.x.abs() < 1e-6 && circle.y.abs() < 1e-6, "{circle:?}");
    }

    #[test]
    fn angles_wrap_into_minus_pi_to_pi() {
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert_eq!(wrap_angle(0.25), 0.25);
    }
}
