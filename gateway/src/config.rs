//! The gateway's configuration: one serde struct, read from TOML. Lookup: `--config FILE`, else
//! `$SCOUT_GATEWAY_CONFIG`, else the defaults; command-line flags override the file.

use scout_interface::robot::RobotName;
use std::path::{Path, PathBuf};
use std::time::Duration;

use scout_interface::Transport;
use scout_interface::remote::ZenohConfig;
use scout_protocol::model::Model;
use scout_protocol::version::Protocol;
use scout_sim::SimParams;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::arbiter::ArbiterConfig;
use crate::device::DeviceSpec;

/// The whole configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GatewayConfig {
    /// The robot's name: every iceoryx2 service and zenoh key carries it (checked as the
    /// configuration is read).
    pub name: RobotName,
    /// How the chassis is reached.
    pub transport: Option<Transport>,
    /// The tty or CAN interface; for `gs_usb`, the adapter's serial number (none: the only
    /// adapter plugged in).
    pub device: Option<String>,
    /// `gs_usb`: detach a kernel driver bound to the adapter (never done unasked).
    pub gs_usb_detach: bool,
    /// The chassis' protocol: `auto` tells it from the frames (CAN and slcan; RS232 is v1).
    pub protocol: ProtocolSetting,
    /// The model, for its speed limits and geometry (default: `scout` on v1, `scout2` on v2).
    #[serde(deserialize_with = "model_by_name")]
    pub model: Option<Model>,
    /// The fastest the chassis may turn, rad/s; on protocol v1 also the rate at 100 % angular
    /// command (protocol-notes 4.1; firmware differs). Default: the model's. On v2 the wire
    /// gets no more than the model's, whatever this says.
    pub max_angular: Option<f64>,
    /// Periods and limits of the control loop.
    pub timing: Timing,
    /// Who drives: ages, caps, rate limits, autonomy re-arming.
    pub arbiter: ArbiterConfig,
    /// Gap detection beyond the chassis' own reports.
    pub safety: SafetyConfig,
    /// The odometry's calibration: what the chassis reports, scaled to what the robot does.
    pub odometry: OdometryConfig,
    /// The battery: thresholds, what a critical one does, the estimate's curve.
    pub battery: BatteryConfig,
    /// The black box of the bus.
    pub blackbox: BlackBoxConfig,
    /// Remote peers through zenoh.
    pub zenoh: ZenohConfig,
    /// The simulated chassis (`transport = "sim"`): keys of the simulator's parameters
    /// (`scout-sim --params`), over the model's defaults.
    pub sim: toml::Table,
}

/// A `--protocol` or `protocol` that is none of [`ProtocolSetting::ALL`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("not a protocol setting: give auto, v1 or v2")]
pub struct UnknownProtocolSetting;

/// Which protocol the gateway speaks to the chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ProtocolSetting {
    /// Listen first and pick the protocol the chassis' feedback proves (nothing is sent until
    /// then); feedback of both, or of none, is an error that says what was seen.
    #[default]
    Auto,
    /// Protocol v1, the 2019 SCOUT (CAN and RS232).
    V1,
    /// Protocol v2, SCOUT 2.0 and SCOUT MINI firmware since 2020 (CAN only).
    V2,
}

impl ProtocolSetting {
    /// Every setting, by its name in the file and on the command line.
    pub const ALL: [(Self, &'static str); 3] =
        [(Self::Auto, "auto"), (Self::V1, "v1"), (Self::V2, "v2")];

    /// The setting called `name` (`auto`, `v1`, `v2`).
    pub fn parse(name: &str) -> Result<Self, UnknownProtocolSetting> {
        Self::ALL
            .into_iter()
            .find(|(_, known)| *known == name)
            .map(|(setting, _)| setting)
            .ok_or(UnknownProtocolSetting)
    }

    /// The protocol it fixes, if it fixes one.
    pub const fn fixed(self) -> Option<Protocol> {
        match self {
            Self::Auto => None,
            Self::V1 => Some(Protocol::V1),
            Self::V2 => Some(Protocol::V2),
        }
    }
}

/// Periods and limits of the control loop.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Timing {
    /// The motion command period, ms (the chassis expects 20).
    pub command_period_ms: u64,
    /// The light command period on CAN and slcan, ms (the manual's 25).
    pub can_light_period_ms: u64,
    /// The light command period on serial, ms (well inside the chassis' 500 ms light timeout).
    pub serial_light_period_ms: u64,
    /// Zero-speed commands sent after Ctrl-C or SIGTERM before the port is released.
    pub stop_cycles: u32,
    /// The longest wait between attempts to reopen a failed port, ms.
    pub reconnect_max_ms: u64,
    /// Real-time (SCHED_FIFO) priority of the control thread, 1..=99, so that the tick holds
    /// when other processes load every core; 0 leaves it at normal priority. Without the right
    /// (root, CAP_SYS_NICE or an rtprio limit) the gateway runs at normal priority and says so.
    pub realtime_priority: u8,
}

impl Default for Timing {
    fn default() -> Self {
        Self {
            command_period_ms: 20,
            can_light_period_ms: 25,
            serial_light_period_ms: 100,
            stop_cycles: 5,
            reconnect_max_ms: 1000,
            realtime_priority: 50,
        }
    }
}

/// Gap detection beyond the chassis' own reports: the runaway check.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SafetyConfig {
    /// How much faster than commanded (beyond braking) the chassis may go, m/s.
    pub runaway_tolerance: f64,
    /// For how long, ms, before it is a runaway.
    pub runaway_time_ms: u64,
    /// The braking the chassis manages at least after a command drops, m/s².
    pub runaway_braking: f64,
    /// How much faster than commanded (beyond braking) the chassis may turn, rad/s.
    pub runaway_angular_tolerance: f64,
    /// The angular braking the chassis manages at least after a command drops, rad/s².
    pub runaway_angular_braking: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            runaway_tolerance: 0.3,
            runaway_time_ms: 500,
            runaway_braking: 0.5,
            runaway_angular_tolerance: 0.15,
            runaway_angular_braking: 0.5,
        }
    }
}

/// The odometry's calibration, applied to the pose every client reads (measured on the robot:
/// docs/chassis.md). 1.0 each: the chassis' reports as they are.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OdometryConfig {
    /// The distance the robot travels over the distance the chassis reports (its speed, its
    /// wheel odometers): 1.05 when it goes 5 % farther than reported.
    pub distance_scale: f64,
    /// The turn the robot makes over the turn the chassis reports (its yaw rate): 0.794 when
    /// it reports 1.26 times its real rotation.
    pub yaw_scale: f64,
}

pub use scout_interface::state::ODOMETRY_SCALE_RANGE;

impl Default for OdometryConfig {
    fn default() -> Self {
        Self {
            distance_scale: 1.0,
            yaw_scale: 1.0,
        }
    }
}

/// What the gateway does while the battery is critical (docs/chassis.md, "Battery"). None of
/// them stops a teleop: an operator driving the robot to its charger keeps driving.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OnCritical {
    /// Warn only (status, log, `/diagnostics`, Foxglove).
    Warn,
    /// Warn, and refuse autonomy a new take of control; a running autonomy drives on.
    RefuseAutonomy,
    /// Warn, refuse autonomy a take, and end autonomy's control (its output ramps to zero; it
    /// must take control again once the battery is above critical).
    StopAutonomy,
}

/// The black box of the bus (docs/chassis.md, "The black box").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BlackBoxConfig {
    /// How many minutes of frames it keeps (0: no black box).
    pub minutes: f64,
    /// At most this many frames (48 bytes each in memory), whatever the minutes.
    pub max_frames: usize,
    /// Where the files go (default: `blackbox` in the run directory, `$SCOUT_RUN_DIR`).
    pub dir: Option<PathBuf>,
    /// How many of the robot's files to keep (the oldest go).
    pub keep: usize,
    /// At most one file this often, s: later causes wait and share the next file.
    pub min_interval_s: f64,
}

impl Default for BlackBoxConfig {
    fn default() -> Self {
        Self {
            minutes: 5.0,
            max_frames: 250_000,
            dir: None,
            keep: 20,
            min_interval_s: 60.0,
        }
    }
}

impl BlackBoxConfig {
    /// Whether there is a black box (`minutes` > 0).
    pub fn enabled(&self) -> bool {
        self.minutes > 0.0
    }

    /// The directory of the files, made if missing and checked as the run directory is
    /// ([`crate::run_dir::private`]).
    pub fn dir(&self) -> Result<PathBuf, crate::run_dir::RunDirError> {
        let dir = match &self.dir {
            Some(dir) => dir.clone(),
            None => crate::run_dir::prepare()?.join("blackbox"),
        };
        crate::run_dir::private(&dir)?;
        Ok(dir)
    }

    fn validate(&self) -> Result<(), ConfigError> {
        if !(0.0..=60.0).contains(&self.minutes) {
            return Err(ConfigError::Invalid(format!(
                "blackbox.minutes must be within 0..=60 (0: off), found {}",
                self.minutes
            )));
        }
        if !(0.0..=3600.0).contains(&self.min_interval_s) {
            return Err(ConfigError::Invalid(format!(
                "blackbox.min_interval_s must be within 0..=3600, found {}",
                self.min_interval_s
            )));
        }
        if self.max_frames == 0 || self.keep == 0 {
            return Err(ConfigError::Invalid(
                "blackbox.max_frames and blackbox.keep must be positive".into(),
            ));
        }
        Ok(())
    }
}

/// The battery's thresholds and estimate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BatteryConfig {
    /// At or below this charge the battery is `low`: a warning, %.
    pub low_percent: f64,
    /// At or below this charge the battery is `critical`: an error, and `on_critical`, %.
    pub critical_percent: f64,
    /// What a critical battery does.
    pub on_critical: OnCritical,
    /// The pack's resistance with its wiring, ohm: the voltage estimate adds back the drop at
    /// the motors' current (an assumption for the SCOUT's pack: measure yours, docs/chassis.md).
    pub internal_resistance_ohm: f64,
    /// The pack's rest voltage against charge, `[[volts, percent], ...]` rising (default: the
    /// model's, scout-protocol `battery`).
    pub curve: Option<Vec<(f64, f64)>>,
    /// Rated capacity, Ah (default: the model's, where known).
    pub capacity_ah: Option<f64>,
}

impl Default for BatteryConfig {
    fn default() -> Self {
        Self {
            low_percent: 20.0,
            critical_percent: 10.0,
            on_critical: OnCritical::RefuseAutonomy,
            internal_resistance_ohm: 0.06,
            curve: None,
            capacity_ah: None,
        }
    }
}

impl BatteryConfig {
    /// Why the settings cannot be used, if they cannot.
    fn validate(&self) -> Result<(), ConfigError> {
        let invalid = |why: String| Err(ConfigError::Invalid(why));
        let (low, critical) = (self.low_percent, self.critical_percent);
        if !(0.0..=100.0).contains(&critical) || !(0.0..=100.0).contains(&low) || critical > low {
            return invalid(format!(
                "battery.critical_percent ({critical}) and battery.low_percent ({low}) must be \
                 percentages with critical at most low"
            ));
        }
        if !(0.0..=1.0).contains(&self.internal_resistance_ohm) {
            return invalid(format!(
                "battery.internal_resistance_ohm must be within 0..=1 ohm, found {}",
                self.internal_resistance_ohm
            ));
        }
        if let Some(curve) = &self.curve
            && !scout_protocol::battery::curve_is_valid(curve)
        {
            return invalid(
                "battery.curve must be at least two [volts, percent] pairs, both rising, \
                        the percent within 0..=100"
                    .into(),
            );
        }
        if let Some(capacity) = self.capacity_ah
            && !(capacity.is_finite() && capacity > 0.0)
        {
            return invalid(format!(
                "battery.capacity_ah must be positive, found {capacity}"
            ));
        }
        Ok(())
    }
}

impl Default for GatewayConfig {
    fn default() -> Self {
        Self {
            name: RobotName::new("scout").expect("a valid robot name"),
            transport: None,
            device: None,
            gs_usb_detach: false,
            protocol: ProtocolSetting::Auto,
            model: None,
            max_angular: None,
            timing: Timing::default(),
            arbiter: ArbiterConfig::default(),
            safety: SafetyConfig::default(),
            odometry: OdometryConfig::default(),
            battery: BatteryConfig::default(),
            blackbox: BlackBoxConfig::default(),
            zenoh: ZenohConfig::default(),
            sim: toml::Table::new(),
        }
    }
}

/// A configuration that cannot be used, with what to do.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("reading {path}: {error}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// The file is not valid TOML for this struct.
    #[error("{path}: {error}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        error: Box<toml::de::Error>,
    },
    /// An arbiter setting is out of range.
    #[error(transparent)]
    Arbiter(#[from] crate::arbiter::ArbiterConfigError),
    /// A value is out of range or missing.
    #[error("{0}")]
    Invalid(String),
}

impl GatewayConfig {
    /// Reads `path`, or `$SCOUT_GATEWAY_CONFIG` when `path` is `None`, or the defaults.
    pub fn load(path: Option<&Path>) -> Result<Self, ConfigError> {
        let from_env = std::env::var_os("SCOUT_GATEWAY_CONFIG").map(PathBuf::from);
        let Some(path) = path.map(Path::to_path_buf).or(from_env) else {
            return Ok(Self::default());
        };
        let text = std::fs::read_to_string(&path).map_err(|error| ConfigError::Read {
            path: path.clone(),
            error,
        })?;
        toml::from_str(&text).map_err(|error| ConfigError::Parse {
            path,
            error: Box::new(error),
        })
    }

    /// Checks every value; returns the device to open.
    pub fn validate(&self) -> Result<DeviceSpec, ConfigError> {
        if let Some(max_angular) = self.max_angular
            && !(max_angular.is_finite() && max_angular > 0.0)
        {
            return Err(ConfigError::Invalid(format!(
                "max_angular must be a positive number of rad/s, found {max_angular}"
            )));
        }
        if self.transport == Some(Transport::Serial) && self.protocol == ProtocolSetting::V2 {
            return Err(ConfigError::Invalid(
                "protocol v2 travels on CAN only (no vendor code speaks v2 over RS232): use \
                 --slcan, --can or --gs-usb, or --protocol v1 for a v1 chassis on RS232"
                    .into(),
            ));
        }
        if !(5..=100).contains(&self.timing.command_period_ms) {
            return Err(ConfigError::Invalid(format!(
                "timing.command_period_ms must be 5..100 (the chassis stops after 500 ms), found {}",
                self.timing.command_period_ms
            )));
        }
        if self.timing.realtime_priority > 99 {
            return Err(ConfigError::Invalid(format!(
                "timing.realtime_priority must be 0 (off) or 1..=99, found {}",
                self.timing.realtime_priority
            )));
        }
        self.arbiter.validate()?;
        let safety = &self.safety;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !([
            safety.runaway_tolerance,
            safety.runaway_braking,
            safety.runaway_angular_tolerance,
            safety.runaway_angular_braking,
        ]
        .into_iter()
        .all(positive)
            && safety.runaway_time_ms > 0)
        {
            return Err(ConfigError::Invalid(
                "safety.runaway_tolerance, runaway_braking, runaway_angular_tolerance, \
                 runaway_angular_braking and runaway_time_ms must be positive"
                    .into(),
            ));
        }
        for (key, scale) in [
            ("distance_scale", self.odometry.distance_scale),
            ("yaw_scale", self.odometry.yaw_scale),
        ] {
            if !ODOMETRY_SCALE_RANGE.contains(&scale) {
                return Err(ConfigError::Invalid(format!(
                    "odometry.{key} must be within {}..={} (measured over reported), found \
                     {scale}: check the model and its geometry first",
                    ODOMETRY_SCALE_RANGE.start(),
                    ODOMETRY_SCALE_RANGE.end()
                )));
            }
        }
        if let (Some(model), Some(protocol)) = (self.model, self.fixed_protocol())
            && !model.speaks(protocol)
        {
            return Err(ConfigError::Invalid(format!(
                "a {model} does not speak protocol {protocol} (RS232 is v1 alone): connect it \
                 by CAN and give --protocol v2 or auto"
            )));
        }
        self.battery.validate()?;
        self.blackbox.validate()?;
        self.zenoh
            .validate()
            .map_err(|error| ConfigError::Invalid(error.to_string()))?;
        let device = || {
            self.device.clone().ok_or_else(|| {
                ConfigError::Invalid("no device: give --serial, --slcan or --can with a device, or `device` in the config".into())
            })
        };
        Ok(match self.transport {
            None => {
                return Err(ConfigError::Invalid(
                    "no transport: use --sim, --serial DEVICE, --slcan DEVICE, --can IFACE or --gs-usb [SERIAL] (or `transport` in the config)".into(),
                ));
            }
            Some(Transport::Serial) => DeviceSpec::Serial(device()?.into()),
            Some(Transport::Slcan) => DeviceSpec::Slcan(device()?.into()),
            Some(Transport::Can) => DeviceSpec::Can(device()?),
            Some(Transport::GsUsb) => DeviceSpec::GsUsb {
                serial: self.device.clone().filter(|serial| !serial.is_empty()),
                detach: self.gs_usb_detach,
            },
            Some(Transport::Sim) => {
                let protocol = self.fixed_protocol().unwrap_or(Protocol::V1);
                let model = self.model.unwrap_or(Model::default_for(protocol));
                let params = SimParams {
                    max_angular: self.max_angular(),
                    ..SimParams::for_model(model)
                }
                .with_overrides(&self.sim)
                .map_err(|error| ConfigError::Invalid(format!("[sim]: {error}")))?;
                DeviceSpec::Sim {
                    params: Box::new(params),
                    protocol,
                }
            }
        })
    }

    /// The protocol the gateway speaks from the start, if it is fixed: RS232 is v1 whatever
    /// `auto` would say (only v1 has an RS232 framing), and the simulated chassis speaks what
    /// the gateway made it speak (`auto`: v1, or v2 for a model that speaks v2 alone).
    pub fn fixed_protocol(&self) -> Option<Protocol> {
        match (self.transport, self.protocol.fixed()) {
            (_, Some(protocol)) => Some(protocol),
            (Some(Transport::Serial), None) => Some(Protocol::V1),
            (Some(Transport::Sim), None) => Some(
                match self.model.is_some_and(|model| !model.speaks(Protocol::V1)) {
                    true => Protocol::V2,
                    false => Protocol::V1,
                },
            ),
            (Some(Transport::Slcan | Transport::Can | Transport::GsUsb) | None, None) => None,
        }
    }

    /// The model whose limits the gateway drives by: the configured one, else the default
    /// of the fixed protocol, else the 2019 SCOUT's (the defaults of both protocols share
    /// their limits).
    pub fn limits_model(&self) -> Model {
        self.model.unwrap_or(Model::default_for(
            self.fixed_protocol().unwrap_or(Protocol::V1),
        ))
    }

    /// The fastest the chassis may turn, rad/s: the configured value or the model's.
    pub fn max_angular(&self) -> f64 {
        self.max_angular
            .unwrap_or(self.limits_model().limits().angular)
    }

    /// What to warn of a `max_angular` above the model's: on protocol v2 the wire gets no
    /// more than the model's, so the arbiter takes asks up to it that the chassis never gets.
    pub fn max_angular_beyond_model(&self) -> Option<String> {
        let (configured, model) = (self.max_angular?, self.limits_model());
        let limit = model.limits().angular;
        (configured > limit).then(|| {
            format!(
                "max_angular {configured} rad/s is above the {model}'s {limit}: on protocol v2 \
                 the chassis gets at most {limit} rad/s (a client asking more is answered as \
                 taken and gets that); on v1 it is the rate of 100 % angular command. Remove it \
                 unless your v1 firmware turns faster"
            )
        })
    }

    /// The fastest the chassis may go, m/s: the model's.
    pub fn max_linear(&self) -> f64 {
        self.limits_model().limits().linear
    }

    /// The fastest the chassis may go sideways, m/s: the model's (0: it does not).
    pub fn max_lateral(&self) -> f64 {
        self.limits_model().limits().lateral
    }

    /// The motion command period.
    pub fn command_period(&self) -> Duration {
        Duration::from_millis(self.timing.command_period_ms)
    }

    /// What the zenoh `info` queryable tells about this gateway.
    pub fn info(&self, transport: Transport, device: &str) -> Value {
        json!({
            "robot": self.name,
            "version": env!("CARGO_PKG_VERSION"),
            "transport": transport.name(),
            "device": device,
            "protocol": match self.protocol {
                ProtocolSetting::Auto => "auto",
                ProtocolSetting::V1 => "v1",
                ProtocolSetting::V2 => "v2",
            },
            "model": self.model.map(Model::name),
            "max_linear": self.max_linear(),
            "max_angular": self.max_angular(),
            "arbiter": self.arbiter,
            "state_rate_hz": self.zenoh.state_rate_hz,
            "remote_commands": {
                "enabled": self.zenoh.remote_commands.enabled,
                "allowed": self.zenoh.remote_commands.allowed,
            },
        })
    }
}

/// A model by its name, refused with [`Model::parse`]'s message (which lists every name).
fn model_by_name<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Model>, D::Error> {
    let name: Option<String> = serde::Deserialize::deserialize(d)?;
    name.map(|name| Model::parse(&name).map_err(serde::de::Error::custom))
        .transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn protocol_setting_names_are_the_ones_serde_reads_and_writes() {
        #[derive(Debug, Serialize, Deserialize)]
        struct File {
            protocol: ProtocolSetting,
        }
        for (setting, name) in ProtocolSetting::ALL {
            let text = toml::to_string(&File { protocol: setting }).expect("serializes");
            assert_eq!(text.trim(), format!("protocol = \"{name}\""));
            let read: File = toml::from_str(&text).expect("parses");
            assert_eq!(read.protocol, setting);
            assert_eq!(ProtocolSetting::parse(name), Ok(setting));
        }
    }

    #[test]
    fn the_battery_section_reads_and_bad_settings_say_which() {
        let config: GatewayConfig = toml::from_str(
            "transport = \"sim\"\n[battery]\nlow_percent = 30\ncritical_percent = 15\n\
             on_critical = \"stop-autonomy\"\ncurve = [[20.0, 0.0], [28.0, 100.0]]\n",
        )
        .expect("a battery section");
        assert_eq!(config.battery.on_critical, OnCritical::StopAutonomy);
        assert_eq!(config.battery.curve, Some(vec![(20.0, 0.0), (28.0, 100.0)]));
        assert!(config.validate().is_ok());
        for (battery, says) in [
            (
                BatteryConfig {
                    critical_percent: 40.0,
                    ..BatteryConfig::default()
                },
                "critical at most low",
            ),
            (
                BatteryConfig {
                    curve: Some(vec![(28.0, 0.0), (20.0, 100.0)]),
                    ..BatteryConfig::default()
                },
                "both rising",
            ),
            (
                BatteryConfig {
                    internal_resistance_ohm: f64::NAN,
                    ..BatteryConfig::default()
                },
                "internal_resistance_ohm",
            ),
        ] {
            let config = GatewayConfig {
                transport: Some(Transport::Sim),
                battery,
                ..GatewayConfig::default()
            };
            let error = config.validate().expect_err(says).to_string();
            assert!(error.contains(says), "{error}");
        }
    }

    #[test]
    fn odometry_scales_outside_their_range_are_refused_saying_which() {
        for (distance_scale, yaw_scale, refused) in [
            (1.0, 1.0, None),
            (0.95, 1.0 / 1.26, None),
            (0.0, 1.0, Some("distance_scale")),
            (1.0, 2.5, Some("yaw_scale")),
            (f64::NAN, 1.0, Some("distance_scale")),
        ] {
            let config = GatewayConfig {
                transport: Some(Transport::Sim),
                odometry: OdometryConfig {
                    distance_scale,
                    yaw_scale,
                },
                ..GatewayConfig::default()
            };
            match (config.validate(), refused) {
                (Ok(_), None) => {}
                (Err(error), Some(key)) => assert!(error.to_string().contains(key), "{error}"),
                (result, _) => panic!("{distance_scale} {yaw_scale}: {result:?}"),
            }
        }
    }

    #[test]
    fn the_example_config_parses() {
        let text = include_str!("../../config/scout-gateway.toml");
        let config: GatewayConfig = toml::from_str(text).expect("example config");
        assert_eq!(config.name, "scout");
        assert!(matches!(config.validate(), Ok(DeviceSpec::Serial(_))));
        // "else the defaults below": the example shows the defaults, apart from the device.
        let defaults = GatewayConfig {
            transport: config.transport,
            device: config.device.clone(),
            zenoh: ZenohConfig {
                listen: config.zenoh.listen.clone(),
                ..ZenohConfig::default()
            },
            sim: config.sim.clone(),
            ..GatewayConfig::default()
        };
        assert_eq!(config, defaults);
    }

    #[test]
    fn unknown_keys_and_bad_values_are_refused() {
        assert!(toml::from_str::<GatewayConfig>("nmae = \"x\"").is_err());
        let config = GatewayConfig {
            transport: Some(Transport::Sim),
            max_angular: Some(-1.0),
            ..Default::default()
        };
        assert!(
            config
                .validate()
                .expect_err("negative")
                .to_string()
                .contains("max_angular")
        );
        let config = GatewayConfig {
            transport: Some(Transport::Serial),
            ..Default::default()
        };
        assert!(
            config
                .validate()
                .expect_err("no device")
                .to_string()
                .contains("no device")
        );
        let config = GatewayConfig {
            transport: Some(Transport::Serial),
            device: Some("/dev/ttyUSB0".into()),
            protocol: ProtocolSetting::V2,
            ..Default::default()
        };
        let error = config.validate().expect_err("v2 on RS232").to_string();
        assert!(error.contains("CAN only"), "{error}");
        let config: GatewayConfig =
            toml::from_str("transport = \"sim\"\n[sim]\nbatery_voltage = 24.0").expect("toml");
        let error = config
            .validate()
            .expect_err("a misspelt sim key")
            .to_string();
        assert!(
            error.contains("[sim]") && error.contains("batery_voltage"),
            "{error}"
        );
    }

    #[test]
    fn the_model_sets_the_limits_and_the_simulated_chassis() {
        let config: GatewayConfig = toml::from_str(
            "transport = \"sim\"\nprotocol = \"v2\"\nmodel = \"scout-mini\"\n[sim]\nbattery_voltage = 24.0",
        )
        .expect("toml");
        assert_eq!((config.max_linear(), config.max_angular()), (3.0, 2.5235));
        let Ok(DeviceSpec::Sim { params, protocol }) = config.validate() else {
            panic!("a simulated chassis")
        };
        assert_eq!(protocol, Protocol::V2);
        assert_eq!((params.max_linear, params.battery_voltage), (3.0, 24.0));
        assert_eq!(params.track_width, Model::ScoutMini.geometry().track);
        let serial = GatewayConfig {
            transport: Some(Transport::Serial),
            ..Default::default()
        };
        assert_eq!(serial.fixed_protocol(), Some(Protocol::V1), "RS232 is v1");
        assert_eq!(GatewayConfig::default().fixed_protocol(), None);
        assert_eq!(GatewayConfig::default().max_linear(), 1.5);
        let faster = GatewayConfig {
            max_angular: Some(0.7),
            ..Default::default()
        };
        let warned = faster
            .max_angular_beyond_model()
            .expect("above the SCOUT's");
        assert!(warned.starts_with("max_angular 0.7 rad/s is above the scout's 0.5235"));
        assert_eq!(GatewayConfig::default().max_angular_beyond_model(), None);
        for (name, model) in [
            ("scout2", Model::Scout2),
            ("scout-mini-omni", Model::ScoutMiniOmni),
            ("hunter-se", Model::HunterSe),
        ] {
            let config: GatewayConfig =
                toml::from_str(&format!("model = \"{name}\"")).expect("model names");
            assert_eq!(config.model, Some(model));
        }
    }

    #[test]
    fn an_unknown_model_or_one_on_a_protocol_it_does_not_speak_is_refused() {
        let refused = toml::from_str::<GatewayConfig>("model = \"hunter3\"")
            .expect_err("no such model")
            .to_string();
        assert!(
            refused.contains("not a model: give one of scout,"),
            "{refused}"
        );
        let tracer = |transport: &str, protocol: &str| {
            toml::from_str::<GatewayConfig>(&format!(
                "transport = \"{transport}\"\ndevice = \"x\"\nprotocol = \"{protocol}\"\n\
                 model = \"tracer\""
            ))
            .expect("toml")
        };
        let Ok(DeviceSpec::Sim { protocol, params }) = tracer("sim", "auto").validate() else {
            panic!("a simulated tracer")
        };
        assert_eq!(protocol, Protocol::V2, "a Tracer speaks v2 alone");
        assert_eq!(params.track_width, Model::Tracer.geometry().track);
        for (transport, protocol) in [("serial", "auto"), ("slcan", "v1"), ("sim", "v1")] {
            let Err(ConfigError::Invalid(why)) = tracer(transport, protocol).validate() else {
                panic!("a tracer on {transport} {protocol}")
            };
            assert!(why.contains("a tracer does not speak protocol v1"), "{why}");
        }
        assert!(tracer("slcan", "auto").validate().is_ok());
    }
}
