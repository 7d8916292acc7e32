//! Planar motion of the skid-steer base: a pose moved by linear and angular speed over a time
//! step. One copy for the gateway's odometry and the simulator's ground truth.

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

#[cfg(test)]
mod tests {
    use super::*;
    use core::f64::consts::PI;

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
