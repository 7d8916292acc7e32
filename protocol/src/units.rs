//! Physical units to the wire's whole percent and back.

/// The chassis' maximum linear speed, m/s (100 % of 0x130 byte 2).
pub const MAX_LINEAR_SPEED: f64 = 1.5;

/// The default maximum angular speed, rad/s (100 % of 0x130 byte 3). Firmware differs: keep it
/// configurable (protocol-notes 4.1). The vendor's figure, not pi/6 (0.52360).
#[allow(clippy::approx_constant)]
pub const DEFAULT_MAX_ANGULAR_SPEED: f64 = 0.5235;

/// A speed that cannot be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnitError {
    /// The speed was NaN.
    NotANumber,
    /// The speed was infinite.
    Infinite,
    /// The maximum speed to scale by was not finite and positive.
    BadMaximum,
}

impl core::fmt::Display for UnitError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            Self::NotANumber => "speed is NaN",
            Self::Infinite => "speed is infinite",
            Self::BadMaximum => "maximum speed must be finite and positive",
        })
    }
}

#[cfg(feature = "std")]
impl std::error::Error for UnitError {}

/// A speed as whole percent of `max`, rounded to nearest (half away from zero) and clamped to
/// -100..=100. Returns the percent and whether clamping changed it.
pub fn speed_to_percent(speed: f64, max: f64) -> Result<(i8, bool), UnitError> {
    if speed.is_nan() {
        return Err(UnitError::NotANumber);
    }
    if speed.is_infinite() {
        return Err(UnitError::Infinite);
    }
    if !(max.is_finite() && max > 0.0) {
        return Err(UnitError::BadMaximum);
    }
    let percent = speed / max * 100.0;
    let clamped = percent.clamp(-100.0, 100.0);
    let rounded = if clamped >= 0.0 {
        clamped + 0.5
    } else {
        clamped - 0.5
    };
    // `as` truncates toward zero, so adding one half first rounds half away from zero.
    Ok((rounded as i8, clamped != percent))
}

/// The speed that `percent` of `max` stands for.
pub fn percent_to_speed(percent: i8, max: f64) -> f64 {
    f64::from(percent) * max / 100.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn rounds_to_nearest_not_toward_zero() {
        // The vendor SDK truncates 0.1 m/s to 6 %; 6.67 % rounds to 7.
        assert_eq!(speed_to_percent(0.1, MAX_LINEAR_SPEED), Ok((7, false)));
        assert_eq!(speed_to_percent(-0.1, MAX_LINEAR_SPEED), Ok((-7, false)));
        assert_eq!(speed_to_percent(0.15, MAX_LINEAR_SPEED), Ok((10, false)));
        assert_eq!(speed_to_percent(0.0075, MAX_LINEAR_SPEED), Ok((1, false)));
    }

    #[test]
    fn clamps_and_says_so() {
        assert_eq!(speed_to_percent(2.0, MAX_LINEAR_SPEED), Ok((100, true)));
        assert_eq!(
            speed_to_percent(-9.0, DEFAULT_MAX_ANGULAR_SPEED),
            Ok((-100, true))
        );
        assert_eq!(speed_to_percent(1.5, MAX_LINEAR_SPEED), Ok((100, false)));
    }

    #[test]
    fn rejects_what_is_not_a_speed() {
        assert_eq!(speed_to_percent(f64::NAN, 1.5), Err(UnitError::NotANumber));
        assert_eq!(
            speed_to_percent(f64::INFINITY, 1.5),
            Err(UnitError::Infinite)
        );
        assert_eq!(
            speed_to_percent(f64::NEG_INFINITY, 1.5),
            Err(UnitError::Infinite)
        );
        assert_eq!(speed_to_percent(1.0, 0.0), Err(UnitError::BadMaximum));
    }

    #[test]
    fn manual_example_ten_percent_angular() {
        assert!((percent_to_speed(10, DEFAULT_MAX_ANGULAR_SPEED) - 0.05235).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn percent_round_trips(percent in -100i8..=100) {
            let speed = percent_to_speed(percent, DEFAULT_MAX_ANGULAR_SPEED);
            prop_assert_eq!(speed_to_percent(speed, DEFAULT_MAX_ANGULAR_SPEED), Ok((percent, false)));
        }

        #[test]
        fn any_finite_speed_encodes_within_range(speed in proptest::num::f64::ANY) {
            match speed_to_percent(speed, MAX_LINEAR_SPEED) {
                Ok((percent, _)) => prop_assert!((-100..=100).contains(&percent)),
                Err(_) => prop_assert!(!speed.is_finite()),
            }
        }
    }
}
