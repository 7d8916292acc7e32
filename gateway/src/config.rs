//! The gateway's configuration: one serde struct, read from TOML. Lookup: `--config FILE`, else
//! `$SCOUT_GATEWAY_CONFIG`, else the defaults; command-line flags override the file.

use std::path::{Path, PathBuf};
use std::time::Duration;

use scout_bridge::ZenohConfig;
use scout_interface::Transport;
use scout_protocol::units::{DEFAULT_MAX_ANGULAR_SPEED, MAX_LINEAR_SPEED};
use scout_sim::SimParams;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

use crate::arbiter::ArbiterConfig;
use crate::device::DeviceSpec;

/// The whole configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GatewayConfig {
    /// The robot's name: every iceoryx2 service and zenoh key carries it.
    pub name: String,
    /// How the chassis is reached.
    pub transport: Option<Transport>,
    /// The tty or CAN interface.
    pub device: Option<String>,
    /// rad/s at 100 % angular command (protocol-notes 4.1; firmware differs).
    pub max_angular: f64,
    /// Periods and limits of the control loop.
    pub timing: Timing,
    /// Who drives: ages, caps, rate limits, autonomy re-arming.
    pub arbiter: ArbiterConfig,
    /// Gap detection beyond the chassis' own reports.
    pub safety: SafetyConfig,
    /// Remote peers through zenoh.
    pub zenoh: ZenohConfig,
    /// The simulated chassis (`transport = "sim"`).
    pub sim: SimParams,
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

impl Default for GatewayConfig {
    fn default() -> Self {
        Self {
            name: "scout".into(),
            transport: None,
            device: None,
            max_angular: DEFAULT_MAX_ANGULAR_SPEED,
            timing: Timing::default(),
            arbiter: ArbiterConfig::default(),
            safety: SafetyConfig::default(),
            zenoh: ZenohConfig::default(),
            sim: SimParams::default(),
        }
    }
}

/// A configuration that cannot be used, with what to do.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("reading {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not valid TOML for this struct.
    #[error("{path}: {source}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        source: Box<toml::de::Error>,
    },
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
        let text = std::fs::read_to_string(&path).map_err(|source| ConfigError::Read {
            path: path.clone(),
            source,
        })?;
        toml::from_str(&text).map_err(|source| ConfigError::Parse {
            path,
            source: Box::new(source),
        })
    }

    /// Checks every value; returns the device to open.
    pub fn validate(&self) -> Result<DeviceSpec, ConfigError> {
        scout_interface::services::check_robot_name(&self.name)
            .map_err(|error| ConfigError::Invalid(error.to_string()))?;
        if !(self.max_angular.is_finite() && self.max_angular > 0.0) {
            return Err(ConfigError::Invalid(format!(
                "max_angular must be a positive number of rad/s, found {}",
                self.max_angular
            )));
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
        self.arbiter.validate().map_err(ConfigError::Invalid)?;
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
                    "no transport: use --sim, --serial DEVICE, --slcan DEVICE or --can IFACE (or `transport` in the config)".into(),
                ));
            }
            Some(Transport::Serial) => DeviceSpec::Serial(device()?.into()),
            Some(Transport::Slcan) => DeviceSpec::Slcan(device()?.into()),
            Some(Transport::Can) => DeviceSpec::Can(device()?),
            Some(Transport::Sim) => DeviceSpec::Sim(SimParams {
                max_angular: self.max_angular,
                ..self.sim.clone()
            }),
        })
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
            "max_linear": MAX_LINEAR_SPEED,
            "max_angular": self.max_angular,
            "arbiter": self.arbiter,
            "state_rate_hz": self.zenoh.state_rate_hz,
            "remote_commands": {
                "enabled": self.zenoh.remote_commands.enabled,
                "allowed": self.zenoh.remote_commands.allowed,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
            max_angular: -1.0,
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
    }
}
