//! The SCOUT's battery as its manual gives it (and packs no source gives), and the rest-voltage
//! curve that turns a pack voltage into a state of charge (the gateway's estimate where no smart
//! battery reports one, and the simulator's truth).

/// What is known of a model's battery.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BatterySpec {
    /// Rated capacity, Ah (`None` where no source gives it).
    pub capacity_ah: Option<f64>,
    /// The charger's end-of-charge voltage, V (manual 3.2: "about 29.2 V").
    pub full_charge_volts: f64,
    /// The chassis beeps below this, V (manual 2.1: 22.5 V).
    pub warning_volts: f64,
    /// The chassis cuts the drives' power below this, V (manual 2.1: 22 V).
    pub cutoff_volts: f64,
    /// Pack voltage at rest against state of charge: (V, %), both rising.
    pub curve: &'static [(f64, f64)],
}

/// The rest (open-circuit) voltage of an 8-cell LiFePO4 pack against its state of charge, %.
///
/// The SCOUT manual gives 29.2 V full and a 22 V cut-off: 8 × 3.65 V is LiFePO4's charge
/// voltage and 8 × 2.75 V its usual protection voltage, so the pack is taken to be 8S LiFePO4.
/// From 24.0 V up, the points are the 8S rest-voltage chart of
/// <https://bestlifepo4batteries.com/v-lifepo4-battery-voltage-chart> (packs rested 30-60
/// min); below it the cell's knee falls steeply to the chassis' cut-off, which holds the last
/// few percent (placed at 4 % at 24.0 V, an assumption). docs/chassis.md says how good an
/// estimate from it is.
pub const LIFEPO4_8S_REST: &[(f64, f64)] = &[
    (22.0, 0.0),
    (24.0, 4.0),
    (24.4, 10.0),
    (24.6, 20.0),
    (24.8, 30.0),
    (25.0, 40.0),
    (25.2, 50.0),
    (25.4, 60.0),
    (25.6, 70.0),
    (26.0, 80.0),
    (26.3, 90.0),
    (26.7, 100.0),
];

/// The SCOUT and SCOUT 2.0 battery (manual 1.2, 2.1, 3.2: 24 V 30 Ah lithium).
pub const SCOUT_BATTERY: BatterySpec = BatterySpec {
    capacity_ah: Some(30.0),
    full_charge_volts: 29.2,
    warning_volts: 22.5,
    cutoff_volts: 22.0,
    curve: LIFEPO4_8S_REST,
};

/// The MINI's battery: its capacity is in no source this project has; the SCOUT's curve and
/// thresholds are assumed (the chassis' own warning bits are the same).
pub const SCOUT_MINI_BATTERY: BatterySpec = BatterySpec {
    capacity_ah: None,
    ..SCOUT_BATTERY
};

/// A pack no source gives (the Tracers', the Bunkers'): no curve, so no charge estimate (the
/// gateway reports the charge unknown, the chassis' own under-voltage bits still count) until
/// the configuration's `[battery]` gives one; no thresholds.
pub const UNKNOWN_BATTERY: BatterySpec = BatterySpec {
    capacity_ah: None,
    full_charge_volts: f64::NAN,
    warning_volts: f64::NAN,
    cutoff_volts: f64::NAN,
    curve: &[],
};

/// The state of charge, %, of a pack resting at `volts` by `curve` (linear between the points,
/// 0 below the first, 100 above the last; NaN for a NaN voltage).
pub fn percent_at(curve: &[(f64, f64)], volts: f64) -> f64 {
    interpolate(curve.iter().map(|&(v, p)| (v, p)), volts)
}

/// The rest voltage of a pack at `percent` by `curve` (the inverse of [`percent_at`], clamped
/// to the curve's ends).
pub fn volts_at(curve: &[(f64, f64)], percent: f64) -> f64 {
    interpolate(curve.iter().map(|&(v, p)| (p, v)), percent)
}

/// `y` at `x` along rising points, clamped to the ends.
fn interpolate(points: impl Iterator<Item = (f64, f64)> + Clone, x: f64) -> f64 {
    if x.is_nan() {
        return f64::NAN;
    }
    let mut previous: Option<(f64, f64)> = None;
    for (px, py) in points.clone() {
        if x <= px {
            return match previous {
                None => py,
                Some((qx, qy)) => qy + (py - qy) * (x - qx) / (px - qx),
            };
        }
        previous = Some((px, py));
    }
    previous.map_or(f64::NAN, |(_, y)| y)
}

/// Whether `curve` can be used: at least two points, finite, both columns strictly rising,
/// charge within 0..=100.
pub fn curve_is_valid(curve: &[(f64, f64)]) -> bool {
    curve.len() >= 2
        && curve
            .iter()
            .all(|&(v, p)| v.is_finite() && (0.0..=100.0).contains(&p))
        && curve.windows(2).all(|w| w[1].0 > w[0].0 && w[1].1 > w[0].1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_curve_is_valid_and_its_ends_are_the_manuals() {
        assert!(curve_is_valid(LIFEPO4_8S_REST));
        assert_eq!(percent_at(LIFEPO4_8S_REST, SCOUT_BATTERY.cutoff_volts), 0.0);
        assert_eq!(percent_at(LIFEPO4_8S_REST, 21.0), 0.0);
        assert_eq!(percent_at(LIFEPO4_8S_REST, 29.2), 100.0);
        assert!(percent_at(LIFEPO4_8S_REST, f64::NAN).is_nan());
        assert!(
            percent_at(UNKNOWN_BATTERY.curve, 25.0).is_nan(),
            "no estimate"
        );
    }

    #[test]
    fn points_and_midpoints() {
        assert_eq!(percent_at(LIFEPO4_8S_REST, 25.2), 50.0);
        assert!((percent_at(LIFEPO4_8S_REST, 25.1) - 45.0).abs() < 1e-9);
        assert!((volts_at(LIFEPO4_8S_REST, 45.0) - 25.1).abs() < 1e-9);
        assert_eq!(volts_at(LIFEPO4_8S_REST, 0.0), 22.0);
        assert_eq!(volts_at(LIFEPO4_8S_REST, 150.0), 26.7);
    }

    #[test]
    fn bad_curves_are_refused() {
        assert!(!curve_is_valid(&[(24.0, 0.0)]));
        assert!(!curve_is_valid(&[(24.0, 0.0), (23.0, 50.0)]));
        assert!(!curve_is_valid(&[(24.0, 0.0), (25.0, 0.0)]));
        assert!(!curve_is_valid(&[(24.0, 0.0), (25.0, 120.0)]));
        assert!(!curve_is_valid(&[(f64::NAN, 0.0), (25.0, 10.0)]));
    }
}
