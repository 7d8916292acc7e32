//! The battery judged from what the chassis offers: a smart battery's own report (v2's 0x361)
//! while it comes, else an estimate from the pack voltage under the measured load through the
//! model's rest-voltage curve; whether it charges; its level against the configured thresholds.
//! Sans-IO: the state and the time in, the battery section of the state out.

use std::collections::VecDeque;
use std::time::Duration;

use scout_interface::state::{
    BatteryLevel, BatteryPayload, BatterySource, LevelFrom, PowerStatus, StatePayload,
};
use scout_protocol::battery::{BatterySpec, percent_at};

use crate::config::BatteryConfig;

/// A smart battery's report is used while the last one is younger than this.
pub const BMS_FRESH: Duration = Duration::from_secs(5);
/// Motor currents older than this are not a load (the motor frames stopped).
const LOAD_FRESH: Duration = Duration::from_millis(200);
/// The voltage estimate's smoothing time constant: long against the wire's 0.1 V steps and a
/// drive's surges, short against a discharge.
const SMOOTHING: Duration = Duration::from_secs(20);
/// How far back the voltage's trend is read, and how often it is sampled.
const TREND_SPAN: Duration = Duration::from_secs(120);
const TREND_STEP: Duration = Duration::from_secs(10);
/// A rest voltage rising this much over [`TREND_SPAN`] with the motors idle is a charger.
const CHARGING_RISE_VOLTS: f64 = 0.15;
/// Motors drawing less than this in all are idle, A.
const IDLE_AMPS: f64 = 1.0;
/// A pack this close below its charge voltage has a charger on it (no LiFePO4 pack rests
/// there), V.
const ON_CHARGER_BELOW_FULL: f64 = 0.4;
/// A smart battery's current beyond this is charging or discharging, A.
const BMS_IDLE_AMPS: f64 = 0.5;
/// A level is left upward only this far above its threshold, %.
const HYSTERESIS_PERCENT: f64 = 2.0;
/// A level the chassis' own under-voltage bits raised holds this long after they clear (a pack
/// sagging under load sets and clears them with every surge).
const CHASSIS_HOLD: Duration = Duration::from_secs(30);

/// What changed in the battery that is worth saying.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LevelChange {
    /// The level before.
    pub from: BatteryLevel,
    /// The level now.
    pub to: BatteryLevel,
}

/// The battery judge of one gateway.
#[derive(Debug, Clone)]
pub struct BatteryMonitor {
    config: BatteryConfig,
    spec: BatterySpec,
    curve: Vec<(f64, f64)>,
    /// The smoothed rest-voltage estimate and when it was last updated.
    rest: Option<(f64, Duration)>,
    /// The rest voltage every [`TREND_STEP`] over [`TREND_SPAN`].
    trend: VecDeque<(Duration, f64)>,
    /// The level the chassis' bits last raised, and until when it holds.
    chassis_hold: Option<(BatteryLevel, Duration)>,
    payload: BatteryPayload,
}

impl BatteryMonitor {
    /// A monitor of a battery like `spec`, judged by `config` (its curve, if given, replaces the
    /// model's).
    pub fn new(config: BatteryConfig, spec: BatterySpec) -> Self {
        let curve = config.curve.clone().unwrap_or_else(|| spec.curve.to_vec());
        let payload = BatteryPayload {
            capacity_ah: config.capacity_ah.or(spec.capacity_ah).unwrap_or(f64::NAN),
            ..BatteryPayload::unknown(config.low_percent, config.critical_percent)
        };
        Self {
            config,
            spec,
            curve,
            rest: None,
            trend: VecDeque::new(),
            chassis_hold: None,
            payload,
        }
    }

    /// Forgets what it judged (another chassis behind the port).
    pub fn reset(&mut self) {
        *self = Self::new(self.config.clone(), self.spec);
    }

    /// The battery section as it stands.
    pub fn payload(&self) -> BatteryPayload {
        self.payload
    }

    /// Judges the battery anew from `state` (after a system state or a smart battery's report
    /// was stored) at `now`. Returns the level change, if any.
    pub fn update(&mut self, state: &StatePayload, now: Duration) -> Option<LevelChange> {
        let bms = &state.bms;
        let bms_fresh = bms.received.valid
            && now.saturating_sub(Duration::from_nanos(bms.received.at_ns)) < BMS_FRESH;
        let faults = state.faults();
        let has = |name: &str| faults.iter().any(|fault| fault.name == name);
        let (chassis_warns, chassis_cut) = (
            has("battery_undervoltage_warning"),
            has("battery_undervoltage_fault"),
        );
        if bms_fresh {
            let current = f64::from(bms.deciamps) / 10.0;
            let percent = f64::from(bms.charge_percent.min(100));
            self.payload.source = BatterySource::Bms.raw();
            self.payload.percent = percent;
            self.payload.voltage = f64::from(bms.decivolts) / 10.0;
            self.payload.current = current;
            self.payload.health_percent = f64::from(bms.health_percent.min(100));
            self.payload.temperature = f64::from(bms.decidegrees) / 10.0;
            self.payload.status = if current > BMS_IDLE_AMPS {
                PowerStatus::Charging
            } else if current < -BMS_IDLE_AMPS {
                PowerStatus::Discharging
            } else if percent >= 100.0 {
                PowerStatus::Full
            } else {
                PowerStatus::NotCharging
            }
            .raw();
        } else if state.system.received.valid {
            self.estimate(state, now);
        }
        self.judge(chassis_warns, chassis_cut, now)
    }

    /// The estimate from the voltage: the pack's rest voltage is the measured one plus the
    /// drop across its resistance at the motors' current, smoothed; the charge is the curve's.
    fn estimate(&mut self, state: &StatePayload, now: Duration) {
        let volts = state.system.battery_voltage();
        let load: f64 = state
            .motors
            .iter()
            .filter(|motor| {
                motor.received.valid
                    && now.saturating_sub(Duration::from_nanos(motor.received.at_ns)) < LOAD_FRESH
            })
            .map(|motor| motor.current().abs())
            .sum();
        let measured = volts + load * self.config.internal_resistance_ohm;
        let rest = match self.rest {
            None => measured,
            Some((rest, at)) => {
                let dt = now.saturating_sub(at).as_secs_f64();
                rest + (measured - rest) * dt / (SMOOTHING.as_secs_f64() + dt)
            }
        };
        self.rest = Some((rest, now));
        if self
            .trend
            .back()
            .is_none_or(|(at, _)| now.saturating_sub(*at) >= TREND_STEP)
        {
            self.trend.push_back((now, rest));
            while self
                .trend
                .front()
                .is_some_and(|(at, _)| now.saturating_sub(*at) > TREND_SPAN)
            {
                self.trend.pop_front();
            }
        }
        let rise = self.trend.front().map_or(0.0, |(_, first)| rest - first);
        let on_charger = rest >= self.spec.full_charge_volts - ON_CHARGER_BELOW_FULL;
        let status = if on_charger && rise.abs() < CHARGING_RISE_VOLTS / 3.0 {
            PowerStatus::Full
        } else if on_charger || (rise >= CHARGING_RISE_VOLTS && load < IDLE_AMPS) {
            PowerStatus::Charging
        } else {
            PowerStatus::Discharging
        };
        self.payload.source = BatterySource::Voltage.raw();
        self.payload.percent = percent_at(&self.curve, rest);
        self.payload.voltage = volts;
        self.payload.current = f64::NAN;
        self.payload.health_percent = f64::NAN;
        self.payload.temperature = f64::NAN;
        self.payload.status = status.raw();
    }

    /// The level from the charge (with hysteresis) and the chassis' own under-voltage bits.
    fn judge(
        &mut self,
        chassis_warns: bool,
        chassis_cut: bool,
        now: Duration,
    ) -> Option<LevelChange> {
        let from = self.payload.level();
        let percent = self.payload.percent;
        let (low, critical) = (self.config.low_percent, self.config.critical_percent);
        let by_charge = if percent.is_nan() {
            BatteryLevel::Unknown
        } else {
            // Leaving a level upward takes the hysteresis; entering one does not.
            let margin = |level: BatteryLevel| {
                if from >= level {
                    HYSTERESIS_PERCENT
                } else {
                    0.0
                }
            };
            if percent <= critical + margin(BatteryLevel::Critical) {
                BatteryLevel::Critical
            } else if percent <= low + margin(BatteryLevel::Low) {
                BatteryLevel::Low
            } else {
                BatteryLevel::Ok
            }
        };
        let raised = if chassis_cut {
            BatteryLevel::Critical
        } else if chassis_warns {
            BatteryLevel::Low
        } else {
            BatteryLevel::Unknown
        };
        if raised != BatteryLevel::Unknown {
            let held = self
                .chassis_hold
                .filter(|(_, until)| now < *until)
                .map_or(raised, |(level, _)| level.max(raised));
            self.chassis_hold = Some((held, now + CHASSIS_HOLD));
        }
        let by_chassis = self
            .chassis_hold
            .filter(|(_, until)| now < *until)
            .map_or(BatteryLevel::Unknown, |(level, _)| level);
        let to = by_charge.max(by_chassis);
        let level_from = if to == BatteryLevel::Unknown {
            LevelFrom::None
        } else if by_chassis > by_charge {
            match by_chassis {
                BatteryLevel::Critical => LevelFrom::ChassisCutoff,
                _ => LevelFrom::ChassisWarning,
            }
        } else {
            LevelFrom::Charge
        };
        self.payload.level = to.raw();
        self.payload.level_from = level_from.raw();
        (to != from).then_some(LevelChange { from, to })
    }

    /// Why the battery is at its level, for logs, refusals and diagnostics.
    pub fn describe(&self) -> String {
        describe(&self.payload)
    }
}

/// `battery critical: 8 % (estimated from 24.2 V)`: the level, the charge and where it came
/// from, and what set the level when the charge did not (`...; the chassis cut the drives off
/// for battery under-voltage`). The state, the status and the audit say the same.
pub fn describe(battery: &BatteryPayload) -> String {
    let level = battery.level().name();
    let charge = if battery.percent.is_nan() {
        "charge unknown".to_owned()
    } else {
        format!("{:.0} %", battery.percent)
    };
    let judged = match battery.source() {
        BatterySource::Bms => format!("battery {level}: {charge} (smart battery)"),
        BatterySource::Voltage => format!(
            "battery {level}: {charge} (estimated from {:.1} V)",
            battery.voltage
        ),
        BatterySource::None => format!("battery {level}: nothing reported"),
    };
    match battery.level_from().words() {
        "" => judged,
        why => format!("{judged}; {why}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use scout_interface::state::Received;
    use scout_protocol::battery::SCOUT_BATTERY;
    use scout_protocol::version::Protocol;

    fn secs(s: f64) -> Duration {
        Duration::from_secs_f64(s)
    }

    fn received(now: Duration) -> Received {
        Received {
            valid: true,
            count: 0,
            at_ns: now.as_nanos() as u64,
        }
    }

    fn v1_state(volts: f64, amps_per_motor: f64, now: Duration) -> StatePayload {
        let mut state = StatePayload::default();
        state.link.protocol = Protocol::V1.raw();
        state.system.received = received(now);
        state.system.battery_decivolts = (volts * 10.0).round() as u16;
        for motor in &mut state.motors {
            motor.received = received(now);
            motor.current_deciamps = (amps_per_motor * 10.0).round() as i16;
        }
        state
    }

    fn monitor() -> BatteryMonitor {
        BatteryMonitor::new(BatteryConfig::default(), SCOUT_BATTERY)
    }

    /// Feeds `volts` under `amps` per motor every 20 ms for `seconds`, from `start`.
    fn feed(
        monitor: &mut BatteryMonitor,
        start: f64,
        seconds: f64,
        volts: impl Fn(f64) -> f64,
        amps: f64,
    ) -> Vec<LevelChange> {
        let mut changes = Vec::new();
        let steps = (seconds / 0.02) as u32;
        for step in 0..steps {
            let t = start + f64::from(step) * 0.02;
            changes.extend(monitor.update(&v1_state(volts(t), amps, secs(t)), secs(t)));
        }
        changes
    }

    #[test]
    fn nothing_reported_is_unknown_and_nan() {
        let monitor = monitor();
        let battery = monitor.payload();
        assert_eq!(battery.source(), BatterySource::None);
        assert_eq!(battery.level(), BatteryLevel::Unknown);
        assert!(battery.percent.is_nan() && battery.current.is_nan());
        assert_eq!(battery.capacity_ah, 30.0);
    }

    #[test]
    fn a_resting_v1_pack_reads_its_curve() {
        let mut monitor = monitor();
        feed(&mut monitor, 0.0, 1.0, |_| 25.2, 0.0);
        let battery = monitor.payload();
        assert_eq!(battery.source(), BatterySource::Voltage);
        assert!((battery.percent - 50.0).abs() < 1e-6, "{battery:?}");
        assert_eq!(battery.status(), PowerStatus::Discharging);
        assert_eq!(battery.level(), BatteryLevel::Ok);
        assert!(
            battery.current.is_nan(),
            "a v1 chassis measures no pack current"
        );
    }

    #[test]
    fn the_drop_under_load_is_put_back() {
        // 4 motors at 5 A through 0.06 ohm: 1.2 V below rest.
        let mut monitor = monitor();
        feed(&mut monitor, 0.0, 1.0, |_| 24.0, 5.0);
        assert!((monitor.payload().percent - 50.0).abs() < 1e-6);
        assert_eq!(
            monitor.payload().voltage,
            24.0,
            "the voltage shown is measured"
        );
    }

    #[test]
    fn a_surge_moves_the_estimate_little() {
        let mut monitor = monitor();
        feed(&mut monitor, 0.0, 1.0, |_| 25.2, 0.0);
        // A hard start: 1 V lower for a second, motors at 20 A unreported.
        feed(&mut monitor, 1.0, 1.0, |_| 24.2, 0.0);
        let percent = monitor.payload().percent;
        assert!(percent > 45.0, "{percent}");
    }

    #[test]
    fn low_then_critical_then_back_with_hysteresis() {
        // A curve of 1 % per 0.1 V, the wire's step: 22 V is 20 % (low), 21 V 10 % (critical).
        let config = BatteryConfig {
            curve: Some(vec![(20.0, 0.0), (30.0, 100.0)]),
            ..BatteryConfig::default()
        };
        let mut monitor = BatteryMonitor::new(config, SCOUT_BATTERY);
        let changes = feed(&mut monitor, 0.0, 1.0, |_| 22.0, 0.0);
        assert_eq!(
            changes,
            [LevelChange {
                from: BatteryLevel::Unknown,
                to: BatteryLevel::Low
            }]
        );
        // Down to 9 %, slowly: critical once.
        let changes = feed(&mut monitor, 1.0, 200.0, |_| 20.9, 0.0);
        assert_eq!(
            changes,
            [LevelChange {
                from: BatteryLevel::Low,
                to: BatteryLevel::Critical
            }]
        );
        // 11 % is not enough to leave critical; 13 % is.
        feed(&mut monitor, 201.0, 200.0, |_| 21.1, 0.0);
        assert_eq!(monitor.payload().level(), BatteryLevel::Critical);
        feed(&mut monitor, 401.0, 200.0, |_| 21.3, 0.0);
        assert_eq!(monitor.payload().level(), BatteryLevel::Low);
    }

    #[test]
    fn the_chassis_bits_raise_the_level_and_hold_it_through_a_flicker() {
        let mut monitor = monitor();
        let mut state = v1_state(26.0, 0.0, secs(0.0));
        state.system.fault_bits = scout_protocol::Fault::BatteryUndervoltageWarning.mask();
        monitor.update(&state, secs(0.0));
        assert_eq!(monitor.payload().level(), BatteryLevel::Low);
        // A full pack judged low: the words say the chassis set it, not the charge.
        assert_eq!(monitor.payload().level_from(), LevelFrom::ChassisWarning);
        let said = monitor.describe();
        assert!(
            said.starts_with("battery low: ")
                && said.ends_with("the chassis warns of battery under-voltage"),
            "{said}"
        );
        // The warning flickers off under a surge's end: the level holds.
        state.system.fault_bits = 0;
        let changes: Vec<_> = (1..100)
            .filter_map(|i| monitor.update(&state, secs(f64::from(i) * 0.2)))
            .collect();
        assert!(changes.is_empty(), "{changes:?}");
        assert_eq!(monitor.payload().level(), BatteryLevel::Low);
        state.system.fault_bits = scout_protocol::Fault::BatteryUndervoltageFault.mask();
        monitor.update(&state, secs(20.0));
        assert_eq!(monitor.payload().level(), BatteryLevel::Critical);
        assert_eq!(monitor.payload().level_from(), LevelFrom::ChassisCutoff);
        // 30 s after the bits clear, the charge alone judges again.
        state.system.fault_bits = 0;
        monitor.update(&state, secs(49.0));
        assert_eq!(monitor.payload().level(), BatteryLevel::Critical);
        monitor.update(&state, secs(51.0));
        assert_eq!(monitor.payload().level(), BatteryLevel::Ok);
        assert_eq!(monitor.payload().level_from(), LevelFrom::Charge);
    }

    #[test]
    fn a_rising_rest_voltage_with_idle_motors_is_charging_and_the_top_full() {
        let mut monitor = monitor();
        // A charger lifting the pack 0.1 V a minute.
        feed(&mut monitor, 0.0, 200.0, |t| 25.0 + 0.1 * t / 60.0, 0.0);
        assert_eq!(monitor.payload().status(), PowerStatus::Charging);
        // Held at the charge voltage: full.
        feed(&mut monitor, 200.0, 400.0, |_| 29.2, 0.0);
        assert_eq!(monitor.payload().status(), PowerStatus::Full);
        assert_eq!(monitor.payload().percent, 100.0);
        // The charger gone, the robot driving: discharging.
        feed(&mut monitor, 600.0, 200.0, |_| 25.0, 3.0);
        assert_eq!(monitor.payload().status(), PowerStatus::Discharging);
    }

    #[test]
    fn a_smart_battery_is_believed_while_it_reports() {
        let mut monitor = monitor();
        let mut state = v1_state(25.0, 0.0, secs(0.0));
        state.link.protocol = Protocol::V2.raw();
        state.bms.received = received(secs(0.0));
        state.bms.charge_percent = 87;
        state.bms.health_percent = 96;
        state.bms.decivolts = 262;
        state.bms.deciamps = 52;
        state.bms.decidegrees = 281;
        monitor.update(&state, secs(0.0));
        let battery = monitor.payload();
        assert_eq!(battery.source(), BatterySource::Bms);
        assert_eq!(
            (battery.percent, battery.health_percent, battery.voltage),
            (87.0, 96.0, 26.2)
        );
        assert_eq!((battery.current, battery.temperature), (5.2, 28.1));
        assert_eq!(battery.status(), PowerStatus::Charging);
        state.bms.deciamps = -30;
        monitor.update(&state, secs(1.0));
        assert_eq!(monitor.payload().status(), PowerStatus::Discharging);
        state.bms.deciamps = 0;
        state.bms.charge_percent = 100;
        monitor.update(&state, secs(2.0));
        assert_eq!(monitor.payload().status(), PowerStatus::Full);
        // Its reports stop: the voltage takes over.
        state.system.received = received(secs(10.0));
        monitor.update(&state, secs(10.0));
        assert_eq!(monitor.payload().source(), BatterySource::Voltage);
        assert!((monitor.payload().percent - 40.0).abs() < 1e-6);
    }

    #[test]
    fn a_configured_curve_replaces_the_models() {
        let config = BatteryConfig {
            curve: Some(vec![(20.0, 0.0), (30.0, 100.0)]),
            ..BatteryConfig::default()
        };
        let mut monitor = BatteryMonitor::new(config, SCOUT_BATTERY);
        monitor.update(&v1_state(25.0, 0.0, secs(0.0)), secs(0.0));
        assert!((monitor.payload().percent - 50.0).abs() < 1e-6);
    }

    #[test]
    fn describe_says_level_charge_and_source() {
        let mut monitor = monitor();
        monitor.update(&v1_state(24.4, 0.0, secs(0.0)), secs(0.0));
        assert_eq!(
            monitor.describe(),
            "battery critical: 10 % (estimated from 24.4 V)"
        );
    }

    proptest::proptest! {
        /// Whatever the chassis reports, the charge stays a percentage and a critical charge
        /// is a critical level (the chassis' bits may raise a level, never lower one).
        #[test]
        fn the_charge_is_a_percentage_and_the_level_consistent(
            reports in proptest::collection::vec(
                (0u16..400, -300i16..300, proptest::option::of((0u8..=255, -600i16..600)), 0u16..4),
                1..80,
            )
        ) {
            let mut monitor = monitor();
            for (step, (decivolts, deciamps, bms, bits)) in reports.into_iter().enumerate() {
                let now = secs(step as f64 * 0.5);
                let mut state = v1_state(0.0, 0.0, now);
                state.system.battery_decivolts = decivolts;
                state.system.fault_bits = bits;
                for motor in &mut state.motors {
                    motor.current_deciamps = deciamps;
                }
                if let Some((charge, current)) = bms {
                    state.link.protocol = Protocol::V2.raw();
                    state.bms.received = received(now);
                    state.bms.charge_percent = charge;
                    state.bms.deciamps = current;
                }
                monitor.update(&state, now);
                let battery = monitor.payload();
                proptest::prop_assert!((0.0..=100.0).contains(&battery.percent), "{battery:?}");
                proptest::prop_assert!(battery.level() != BatteryLevel::Unknown);
                if battery.percent <= battery.critical_percent {
                    proptest::prop_assert_eq!(battery.level(), BatteryLevel::Critical);
                }
                // What set the level is named: the charge (within its hysteresis), or the
                // chassis' bits; and the words say the same.
                let by_charge = |margin: f64| {
                    if battery.percent <= battery.critical_percent + margin {
                        BatteryLevel::Critical
                    } else if battery.percent <= battery.low_percent + margin {
                        BatteryLevel::Low
                    } else {
                        BatteryLevel::Ok
                    }
                };
                let (lower, upper) = (by_charge(0.0), by_charge(HYSTERESIS_PERCENT));
                match battery.level_from() {
                    LevelFrom::Charge => proptest::prop_assert!(
                        lower <= battery.level() && battery.level() <= upper,
                        "{battery:?}"
                    ),
                    LevelFrom::ChassisWarning => {
                        proptest::prop_assert_eq!(battery.level(), BatteryLevel::Low);
                    }
                    LevelFrom::ChassisCutoff => {
                        proptest::prop_assert_eq!(battery.level(), BatteryLevel::Critical);
                    }
                    LevelFrom::None => proptest::prop_assert!(false, "a level without a cause"),
                }
                let said = monitor.describe();
                let prefix = format!("battery {}:", battery.level().name());
                proptest::prop_assert!(said.starts_with(&prefix), "{}", said);
                let why = battery.level_from().words();
                proptest::prop_assert!(why.is_empty() || said.ends_with(why), "{}", said);
            }
        }
    }
}
