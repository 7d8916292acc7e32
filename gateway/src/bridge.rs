//! The zenoh bridge: the gateway's state, status, liveliness and information for remote peers,
//! and (opt-in) remote commands. It runs on a thread of its own as an ordinary local client of
//! the gateway (iceoryx2 subscriber and controller), so nothing on the network can slow the
//! control thread: it reads the latest state when it publishes, and older states are dropped.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use scout_clients::client::Robot;
use scout_clients::control::{Accepted, ControlError, Controller, Lights};
use scout_clients::ipc::{Class, StatusPayload, monotonic_ns};
use scout_clients::remote::{
    self, MAX_COMMAND_BYTES, RemoteAnswer, RemoteCommand, RemoteLight, SessionSettings,
};
use scout_clients::state::{state_json, status_json};
use scout_protocol::{FaultClear, Light, LightCommand, LightMode};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use tracing::{error, info, warn};
use zenoh::Wait;
use zenoh::bytes::Encoding;
use zenoh::qos::CongestionControl;
use zenoh::query::Query;

/// The `[zenoh]` table of the gateway configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZenohConfig {
    /// Publish to remote peers at all.
    pub enabled: bool,
    /// A zenoh configuration file (JSON5) for LAN, router, TLS and access control set-ups;
    /// `$ZENOH_CONFIG` when unset. Without one: peer mode, multicast scouting off.
    pub config_file: Option<String>,
    /// Listen endpoints; default `tcp/127.0.0.1:7447` when there is no configuration file.
    pub listen: Vec<String>,
    /// Endpoints to connect to (a zenoh router, for a fleet).
    pub connect: Vec<String>,
    /// State publications per second.
    pub state_rate_hz: f64,
    /// Remote commands.
    pub remote_commands: RemoteCommands,
}

/// Remote commands: off by default; when on, only the listed kinds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RemoteCommands {
    /// Accept commands from remote peers.
    pub enabled: bool,
    /// What remote peers may do: `estop`, `teleop`, `autonomy` (drive as that class),
    /// `release`, `resume`, `lights`, `clear_fault`.
    pub allowed: Vec<String>,
}

/// The names `allowed` may hold.
pub const REMOTE_PERMISSIONS: [&str; 7] = [
    "estop",
    "teleop",
    "autonomy",
    "release",
    "resume",
    "lights",
    "clear_fault",
];

impl Default for RemoteCommands {
    fn default() -> Self {
        Self {
            enabled: false,
            allowed: vec!["estop".into()],
        }
    }
}

impl Default for ZenohConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            config_file: None,
            listen: Vec::new(),
            connect: Vec::new(),
            state_rate_hz: 50.0,
            remote_commands: RemoteCommands::default(),
        }
    }
}

impl ZenohConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.state_rate_hz.is_finite() && (0.1..=1000.0).contains(&self.state_rate_hz)) {
            return Err(format!(
                "zenoh.state_rate_hz must be 0.1..1000, found {}",
                self.state_rate_hz
            ));
        }
        if let Some(unknown) = self
            .remote_commands
            .allowed
            .iter()
            .find(|a| !REMOTE_PERMISSIONS.contains(&a.as_str()))
        {
            return Err(format!(
                "zenoh.remote_commands.allowed: unknown `{unknown}` (one of {})",
                REMOTE_PERMISSIONS.join(", ")
            ));
        }
        Ok(())
    }

    /// The session settings, with the gateway's default listen endpoint.
    pub fn session(&self) -> SessionSettings {
        let no_file = self.config_file.is_none() && std::env::var_os("ZENOH_CONFIG").is_none();
        let listen = if self.listen.is_empty() && no_file {
            vec![remote::DEFAULT_LISTEN.to_owned()]
        } else {
            self.listen.clone()
        };
        SessionSettings {
            config_file: self.config_file.clone(),
            listen,
            connect: self.connect.clone(),
        }
    }
}

/// Counts of what remote peers sent.
#[derive(Debug, Clone, Copy, Default, Serialize)]
struct Counters {
    commands_accepted: u64,
    commands_rejected: u64,
    commands_ignored_disabled: u64,
    puts_ignored: u64,
    state_queries: u64,
    info_queries: u64,
}

/// The running bridge thread.
#[derive(Debug)]
pub struct Bridge {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Bridge {
    /// Starts the bridge for `robot`; `info` is the static part of the information queryable.
    pub fn start(robot: String, config: ZenohConfig, info: Value) -> std::io::Result<Self> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let thread = std::thread::Builder::new()
            .name("zenoh-bridge".into())
            .spawn(move || {
                if let Err(error) = run(&robot, &config, info, &flag) {
                    error!(
                        "zenoh bridge stopped: {error:#}; the gateway goes on without remote peers"
                    );
                }
            })?;
        Ok(Self {
            stop,
            thread: Some(thread),
        })
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn zenoh_error(error: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("{error}")
}

fn run(
    robot_name: &str,
    config: &ZenohConfig,
    mut info: Value,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let settings = config.session();
    let session = settings.open("peer").map_err(|e| {
        anyhow::anyhow!(
            "{e} (listen {:?}: give --zenoh-listen tcp/127.0.0.1:PORT, or --no-zenoh)",
            settings.listen
        )
    })?;
    let robot = Robot::connect(robot_name)?;
    let states = robot.subscribe()?;
    let statuses = robot.status()?;
    let json_publisher = |key: String| {
        session
            .declare_publisher(key)
            .encoding(Encoding::APPLICATION_JSON)
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(zenoh_error)
    };
    let state_publisher = json_publisher(remote::state_key(robot_name))?;
    let status_publisher = json_publisher(remote::status_key(robot_name))?;
    let _alive = session
        .liveliness()
        .declare_token(remote::alive_key(robot_name))
        .wait()
        .map_err(zenoh_error)?;
    let state_queries = session
        .declare_queryable(remote::state_key(robot_name))
        .wait()
        .map_err(zenoh_error)?;
    let info_queries = session
        .declare_queryable(remote::info_key(robot_name))
        .wait()
        .map_err(zenoh_error)?;
    let command_queries = session
        .declare_queryable(remote::command_keys(robot_name))
        .wait()
        .map_err(zenoh_error)?;
    let command_puts = session
        .declare_subscriber(remote::command_keys(robot_name))
        .wait()
        .map_err(zenoh_error)?;
    info!(
        "zenoh: publishing scout/{robot_name}/{{state,status,alive,info}}, listening on {:?}, remote commands {}",
        settings.listen,
        if config.remote_commands.enabled {
            format!("on ({})", config.remote_commands.allowed.join(", "))
        } else {
            "off".into()
        }
    );
    let period = Duration::from_secs_f64(1.0 / config.state_rate_hz);
    let mut commands = RemoteControl::new(&robot, &config.remote_commands);
    let mut counters = Counters::default();
    let mut latest_state: Option<String> = None;
    let mut last_status: Option<StatusPayload> = None;
    let mut next_state = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        let now = Instant::now();
        if now >= next_state {
            next_state += period;
            if next_state < now {
                next_state = now + period;
            }
            if let Some(state) = states.try_latest()? {
                let json = state_json(&state, monotonic_ns()).to_string();
                if let Err(error) = state_publisher.put(json.clone()).wait() {
                    warn!("zenoh: publishing the state failed: {error}");
                }
                latest_state = Some(json);
            }
        }
        if let Some(status) = statuses.latest(Duration::ZERO)?
            && last_status.is_none_or(|last| last.seq != status.seq)
        {
            if let Err(error) = status_publisher
                .put(status_json(&status, monotonic_ns()).to_string())
                .wait()
            {
                warn!("zenoh: publishing the status failed: {error}");
            }
            last_status = Some(status);
        }
        while let Ok(Some(query)) = state_queries.try_recv() {
            counters.state_queries += 1;
            if let Some(state) = &latest_state {
                reply(&query, state.clone());
            }
        }
        while let Ok(Some(query)) = info_queries.try_recv() {
            counters.info_queries += 1;
            if let Value::Object(object) = &mut info {
                object.insert(
                    "counters".into(),
                    serde_json::to_value(counters).unwrap_or(Value::Null),
                );
            }
            reply(&query, info.to_string());
        }
        while let Ok(Some(query)) = command_queries.try_recv() {
            let answer = commands.handle(&query, &mut counters);
            reply(&query, serde_json::to_string(&answer).unwrap_or_default());
        }
        while let Ok(Some(_)) = command_puts.try_recv() {
            counters.puts_ignored += 1;
        }
        std::thread::sleep(
            next_state
                .saturating_duration_since(Instant::now())
                .min(Duration::from_millis(2)),
        );
    }
    Ok(())
}

fn reply(query: &Query, payload: String) {
    if let Err(error) = query
        .reply(query.key_expr().clone(), payload)
        .encoding(Encoding::APPLICATION_JSON)
        .wait()
    {
        warn!("zenoh: replying to {} failed: {error}", query.key_expr());
    }
}

/// Remote commands: each remote client gets a controller of its own, named `remote:CLIENT`, so
/// the arbiter treats it like a local one (freshness, limits, priority).
struct RemoteControl<'a> {
    robot: &'a Robot,
    config: &'a RemoteCommands,
    controllers: HashMap<(String, Option<Class>), Controller>,
}

/// Remote clients kept at once; the oldest is forgotten past this.
const MAX_REMOTE_CLIENTS: usize = 16;

impl<'a> RemoteControl<'a> {
    fn new(robot: &'a Robot, config: &'a RemoteCommands) -> Self {
        Self {
            robot,
            config,
            controllers: HashMap::new(),
        }
    }

    fn allowed(&self, permission: &str) -> Result<(), String> {
        if self.config.allowed.iter().any(|a| a == permission) {
            Ok(())
        } else {
            Err(format!(
                "remote `{permission}` is not allowed on this gateway (zenoh.remote_commands.allowed: {})",
                self.config.allowed.join(", ")
            ))
        }
    }

    fn handle(&mut self, query: &Query, counters: &mut Counters) -> RemoteAnswer {
        if !self.config.enabled {
            counters.commands_ignored_disabled += 1;
            return RemoteAnswer::rejected(
                "remote commands are disabled on this gateway (zenoh.remote_commands.enabled)",
            );
        }
        let answer = self.decide(query);
        if answer.accepted {
            counters.commands_accepted += 1;
        } else {
            counters.commands_rejected += 1;
        }
        answer
    }

    fn decide(&mut self, query: &Query) -> RemoteAnswer {
        let kind = query
            .key_expr()
            .as_str()
            .rsplit('/')
            .next()
            .unwrap_or("")
            .to_owned();
        let Some(payload) = query.payload() else {
            return RemoteAnswer::rejected("no payload: send the command as JSON");
        };
        if payload.len() > MAX_COMMAND_BYTES {
            return RemoteAnswer::rejected(format!(
                "payload of {} bytes exceeds {MAX_COMMAND_BYTES}",
                payload.len()
            ));
        }
        let command: RemoteCommand = match serde_json::from_slice(&payload.to_bytes()) {
            Ok(command) => command,
            Err(error) => return RemoteAnswer::rejected(format!("invalid JSON: {error}")),
        };
        if command.client.is_empty() || command.client.len() > 24 {
            return RemoteAnswer::rejected("`client` must be 1 to 24 bytes");
        }
        match self.execute(&kind, &command) {
            Ok(Accepted { clamped }) => RemoteAnswer {
                accepted: true,
                clamped,
                reason: None,
            },
            Err(reason) => RemoteAnswer::rejected(reason),
        }
    }

    fn execute(&mut self, kind: &str, command: &RemoteCommand) -> Result<Accepted, String> {
        let rejected = |e: ControlError| e.to_string();
        match kind {
            "drive" => {
                let class_name = command
                    .class
                    .as_deref()
                    .ok_or("drive needs `class`: teleop or autonomy")?;
                let class: Class = class_name.parse()?;
                self.allowed(class.name())?;
                let (Some(linear), Some(angular)) = (command.linear, command.angular) else {
                    return Err("drive needs `linear` and `angular` numbers".into());
                };
                let ttl = command
                    .ttl_ms
                    .map(|ms| Duration::from_millis(u64::from(ms)));
                self.controller(&command.client, Some(class))?
                    .drive_for(linear, angular, ttl)
                    .map_err(rejected)
            }
            "estop" => {
                self.allowed("estop")?;
                let reason = command
                    .reason
                    .clone()
                    .unwrap_or_else(|| "remote estop".into());
                self.controller(&command.client, None)?
                    .stop(&reason)
                    .map_err(rejected)
            }
            "release" => {
                self.allowed("release")?;
                self.controller(&command.client, None)?
                    .release()
                    .map_err(rejected)
            }
            "resume" => {
                self.allowed("resume")?;
                self.controller(&command.client, None)?
                    .resume()
                    .map_err(rejected)
            }
            "lights" => {
                self.allowed("lights")?;
                let lights = remote_lights(command)?;
                self.controller(&command.client, None)?
                    .lights(lights)
                    .map_err(rejected)
            }
            "clear-fault" => {
                self.allowed("clear_fault")?;
                let fault = command
                    .fault
                    .as_deref()
                    .ok_or("clear-fault needs `fault`")?;
                let code = match fault {
                    "all" => None,
                    name => Some(
                        FaultClear::from_name(name)
                            .filter(|c| *c != FaultClear::None)
                            .ok_or_else(|| format!("unknown fault `{name}`"))?,
                    ),
                };
                self.controller(&command.client, None)?
                    .clear_fault(code)
                    .map_err(rejected)
            }
            other => Err(format!(
                "unknown command `{other}`: drive, estop, release, resume, lights or clear-fault"
            )),
        }
    }

    fn controller(
        &mut self,
        client: &str,
        class: Option<Class>,
    ) -> Result<&mut Controller, String> {
        let key = (client.to_owned(), class);
        if !self.controllers.contains_key(&key) {
            if self.controllers.len() >= MAX_REMOTE_CLIENTS
                && let Some(oldest) = self.controllers.keys().next().cloned()
            {
                self.controllers.remove(&oldest);
            }
            let controller = self
                .robot
                .controller(&format!("remote:{client}"), class)
                .map_err(|e| e.to_string())?;
            self.controllers.insert(key.clone(), controller);
        }
        self.controllers
            .get_mut(&key)
            .ok_or_else(|| "controller vanished".into())
    }
}

fn remote_lights(command: &RemoteCommand) -> Result<Lights, String> {
    if command.auto == Some(true) {
        return Ok(Lights::Auto);
    }
    let light = |light: &Option<RemoteLight>| -> Result<Light, String> {
        let Some(light) = light else {
            return Ok(Light::default());
        };
        let mode = LightMode::from_name(&light.mode)
            .ok_or_else(|| format!("light mode `{}`: off, on, breath or custom", light.mode))?;
        if light.brightness > 100 {
            return Err(format!("brightness {} is above 100", light.brightness));
        }
        Ok(Light {
            mode,
            brightness: light.brightness,
        })
    };
    Ok(Lights::Manual(LightCommand {
        enabled: true,
        front: light(&command.front)?,
        rear: light(&command.rear)?,
    }))
}

/// The static part of the information queryable.
pub fn info(
    robot: &str,
    transport: &str,
    device: &str,
    config: &crate::config::GatewayConfig,
) -> Value {
    json!({
        "robot": robot,
        "version": env!("CARGO_PKG_VERSION"),
        "transport": transport,
        "device": device,
        "max_linear": scout_protocol::units::MAX_LINEAR_SPEED,
        "max_angular": config.max_angular,
        "arbiter": config.arbiter,
        "state_rate_hz": config.zenoh.state_rate_hz,
        "remote_commands": {
            "enabled": config.zenoh.remote_commands.enabled,
            "allowed": config.zenoh.remote_commands.allowed,
        },
    })
}
