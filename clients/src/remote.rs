//! The zenoh side: key expressions, safe session configuration, remote command payloads, and a
//! remote reader for `scout echo --remote`.

use std::path::Path;
use std::time::Duration;

use serde::{Deserialize, Serialize};
use zenoh::Wait;

/// Default zenoh listen endpoint of a gateway: loopback only.
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7447";

/// The largest remote command payload accepted, bytes.
pub const MAX_COMMAND_BYTES: usize = 4096;

/// The key of the state JSON (publication and queryable).
pub fn state_key(robot: &str) -> String {
    format!("scout/{robot}/state")
}

/// The key of the arbiter status JSON.
pub fn status_key(robot: &str) -> String {
    format!("scout/{robot}/status")
}

/// The liveliness token of a running gateway.
pub fn alive_key(robot: &str) -> String {
    format!("scout/{robot}/alive")
}

/// The key of the gateway information queryable.
pub fn info_key(robot: &str) -> String {
    format!("scout/{robot}/info")
}

/// The key prefix of remote commands: `scout/ROBOT/cmd/KIND`.
pub fn command_keys(robot: &str) -> String {
    format!("scout/{robot}/cmd/**")
}

/// The key of one remote command.
pub fn command_key(robot: &str, kind: &str) -> String {
    format!("scout/{robot}/cmd/{kind}")
}

/// Why a zenoh session could not be configured or opened.
#[derive(Debug, thiserror::Error)]
pub enum RemoteError {
    /// The configuration (file or value) is invalid.
    #[error("zenoh configuration: {0}")]
    Config(String),
    /// The session did not open.
    #[error("zenoh session: {0}")]
    Open(String),
    /// Subscribing failed.
    #[error("zenoh: {0}")]
    Zenoh(String),
}

/// Where a zenoh session comes from.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SessionSettings {
    /// A zenoh configuration file (JSON5) for LAN, router and TLS set-ups; `$ZENOH_CONFIG` when
    /// empty. Without one: peer mode, multicast scouting off.
    pub config_file: Option<String>,
    /// Endpoints to listen on (the default: `tcp/127.0.0.1:7447` for a gateway, none for a reader).
    pub listen: Vec<String>,
    /// Endpoints to connect to (a router, another gateway).
    pub connect: Vec<String>,
}

impl SessionSettings {
    /// The zenoh configuration in `mode` (`peer` or `client`): the file if any, else safe
    /// defaults; the endpoints given here override the file's.
    pub fn config(&self, mode: &str) -> Result<zenoh::Config, RemoteError> {
        let file = self
            .config_file
            .clone()
            .or_else(|| std::env::var("ZENOH_CONFIG").ok());
        let mut config = match file.filter(|f| !f.is_empty()) {
            Some(file) => zenoh::Config::from_file(Path::new(&file))
                .map_err(|e| RemoteError::Config(format!("{file}: {e}")))?,
            None => {
                let mut config = zenoh::Config::default();
                insert(&mut config, "mode", &format!("\"{mode}\""))?;
                insert(&mut config, "scouting/multicast/enabled", "false")?;
                insert(&mut config, "scouting/gossip/enabled", "false")?;
                config
            }
        };
        if !self.listen.is_empty() {
            insert(&mut config, "listen/endpoints", &json_list(&self.listen))?;
        }
        if !self.connect.is_empty() {
            insert(&mut config, "connect/endpoints", &json_list(&self.connect))?;
        }
        Ok(config)
    }

    /// Opens a session.
    pub fn open(&self, mode: &str) -> Result<zenoh::Session, RemoteError> {
        let config = self.config(mode)?;
        zenoh::open(config)
            .wait()
            .map_err(|e| RemoteError::Open(e.to_string()))
    }
}

fn insert(config: &mut zenoh::Config, key: &str, value: &str) -> Result<(), RemoteError> {
    config
        .insert_json5(key, value)
        .map_err(|e| RemoteError::Config(format!("{key} = {value}: {e}")))
}

fn json_list(items: &[String]) -> String {
    serde_json::to_string(items).unwrap_or_else(|_| "[]".into())
}

/// A remote command's JSON payload (every field optional but those its command needs).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RemoteCommand {
    /// The sender's name, shown (prefixed `remote:`) in the status and the audit log.
    pub client: String,
    /// drive: `teleop` or `autonomy`.
    pub class: Option<String>,
    /// drive: m/s.
    pub linear: Option<f64>,
    /// drive: rad/s.
    pub angular: Option<f64>,
    /// drive: the command's life, ms.
    pub ttl_ms: Option<u32>,
    /// estop: why.
    pub reason: Option<String>,
    /// lights: hand them back to the chassis.
    pub auto: Option<bool>,
    /// lights: front `{ "mode": "custom", "brightness": 40 }`.
    pub front: Option<RemoteLight>,
    /// lights: rear.
    pub rear: Option<RemoteLight>,
    /// clear-fault: a fault-clear name (`driver_overtemp`...) or `all`.
    pub fault: Option<String>,
}

/// One light in a remote lights command.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RemoteLight {
    /// off, on, breath, custom.
    pub mode: String,
    /// 0..100.
    #[serde(default)]
    pub brightness: u8,
}

/// The answer to a remote command.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct RemoteAnswer {
    /// Accepted or rejected.
    pub accepted: bool,
    /// Accepted with a speed clamped to the caps.
    #[serde(default)]
    pub clamped: bool,
    /// Why it was rejected.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
}

impl RemoteAnswer {
    /// A rejection with `reason`.
    pub fn rejected(reason: impl Into<String>) -> Self {
        Self {
            accepted: false,
            clamped: false,
            reason: Some(reason.into()),
        }
    }
}

/// Reads state JSON from gateways through zenoh (`scout echo --remote`).
pub struct RemoteStates {
    _session: zenoh::Session,
    subscriber:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
}

impl std::fmt::Debug for RemoteStates {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteStates").finish_non_exhaustive()
    }
}

impl RemoteStates {
    /// Connects as a zenoh client to `endpoints` and subscribes to the state of `robot` (`*` for
    /// every robot).
    pub fn connect(settings: &SessionSettings, robot: &str) -> Result<Self, RemoteError> {
        let session = settings.open("client")?;
        let subscriber = session
            .declare_subscriber(state_key(robot))
            .wait()
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
        Ok(Self {
            _session: session,
            subscriber,
        })
    }

    /// The next state JSON, waiting at most `timeout`.
    pub fn next_timeout(
        &self,
        timeout: Duration,
    ) -> Result<Option<serde_json::Value>, RemoteError> {
        let Some(sample) = self
            .subscriber
            .recv_timeout(timeout)
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?
        else {
            return Ok(None);
        };
        let text = sample
            .payload()
            .try_to_string()
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
        serde_json::from_str(&text)
            .map(Some)
            .map_err(|e| RemoteError::Zenoh(format!("state is not JSON: {e}")))
    }
}
