//! scout-bridge: the gateway's zenoh bridge. State, status, liveliness and information for
//! remote peers, and (opt-in) remote commands. It runs on a thread of its own as an ordinary
//! local client of the gateway (iceoryx2 subscriber and control ports, nothing more), so nothing
//! on the network can slow the control thread: it reads the latest state when it publishes, and
//! older states are dropped.

use std::collections::hash_map::Entry;
use std::collections::{HashMap, HashSet};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use scout_interface::control::{Accepted, Request, StatusPayload};
use scout_interface::json::{state_json, status_json};
use scout_interface::remote::{
    self, CommandError, MAX_COMMAND_BYTES, Permission, REMOTE_PREFIX, RemoteAnswer, RemoteKind,
    peer_client_name,
};
pub use scout_interface::remote::{BadStateRate, RemoteCommands, ZenohConfig};
use scout_interface::robot::{Program, RobotName};
use scout_interface::services::{self, ControlPort, Role, Way, monotonic_ns};
use serde::Serialize;
use serde_json::Value;
use tracing::{debug, error, info, warn};
use zenoh::Wait;
use zenoh::bytes::Encoding;
use zenoh::qos::CongestionControl;
use zenoh::query::Query;

mod estops;
mod rules;

use estops::EstopCopies;
use rules::{Rules, Via};

/// Counts of what remote peers sent.
#[derive(Debug, Clone, Copy, Default, Serialize)]
struct Counters {
    commands_accepted: u64,
    commands_rejected: u64,
    commands_ignored_disabled: u64,
    /// Puts other than drives (or any put while remote commands are off): commands that
    /// change who drives or whether the robot may move are queries, answered.
    puts_ignored: u64,
    /// Drives put on the fast lane that the rules and the arbiter let through.
    drives_put_accepted: u64,
    /// Drives put on the fast lane refused (their reasons are the queries'; a put has no
    /// answer to carry them).
    drives_put_rejected: u64,
    /// Drives put on the fast lane dropped before the bridge got to them: a peer without
    /// control's replaced by its newer one, the oldest of a controlling peer's past
    /// [`MAX_QUEUED_DRIVES`] waiting, any from a key past [`MAX_WAITING_DRIVES`].
    drives_superseded: u64,
    state_queries: u64,
    info_queries: u64,
    /// Queries dropped unanswered because the query thread was [`MAX_QUEUED_QUERIES`] behind.
    queries_dropped: u64,
    /// Of the commands, remote e-stops latched (or answered as copies of one that had).
    estops_accepted: u64,
    /// Of those, copies of an e-stop already latched (the same `seq` and `sent_ms` from the
    /// same peer): answered as that stop, not latched again.
    estops_copies: u64,
    /// Remote e-stops refused (not allowed, or a key that names no peer).
    estops_rejected: u64,
    /// Remote e-stops answered `disabled`.
    estops_ignored_disabled: u64,
    /// E-stops dropped unanswered because [`MAX_QUEUED_ESTOPS`] were waiting.
    estops_dropped: u64,
}

/// The running bridge thread.
#[derive(Debug)]
pub struct Bridge {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Bridge {
    /// Starts the bridge for `robot`; `info` is the static part of the information queryable.
    pub fn start(robot: RobotName, config: ZenohConfig, info: Value) -> std::io::Result<Self> {
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

/// Refuses remote commands that move the robot (or undo a stop) over links that authenticate
/// nobody, unless the configuration declares the network trusted (then each such link is
/// warned of); see [`scout_interface::link`].
pub fn check_links(config: &ZenohConfig) -> anyhow::Result<()> {
    if !config.enabled || scout_interface::link::risky(&config.remote_commands).is_empty() {
        return Ok(());
    }
    let links = config
        .session()
        .links("peer", &config.authenticated_interfaces)?;
    for link in &links {
        if scout_interface::link::Endpoint::parse(&link.endpoint).is_ok_and(|e| e.quic_underneath) {
            tracing::warn!(
                "remote drives over {}: {}",
                link.endpoint,
                scout_interface::link::PACED_DRIVES
            );
        }
    }
    for link in
        scout_interface::link::check(&links, &config.remote_commands, config.trusted_network)?
    {
        tracing::warn!(
            "remote peers may command this robot ({}) over {} ({}): the network is declared trusted (zenoh.trusted_network)",
            config.remote_commands.allowed_names(),
            link.endpoint,
            link.protection
        );
    }
    Ok(())
}

fn zenoh_error(error: impl std::fmt::Display) -> anyhow::Error {
    anyhow::anyhow!("{error}")
}

fn run(
    robot_name: &RobotName,
    config: &ZenohConfig,
    info: Value,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let settings = config.session();
    let session = settings.open("peer").map_err(|e| {
        anyhow::anyhow!(
            "{e} (listen {:?}: give --zenoh-listen tcp/127.0.0.1:PORT, or --no-zenoh)",
            settings.listen
        )
    })?;
    let _alive = session
        .liveliness()
        .declare_token(remote::alive_key(robot_name))
        .wait()
        .map_err(zenoh_error)?;
    info!(
        "zenoh: publishing scout/{robot_name}/{{state,status,alive,info,links}}, listening on {:?}, remote commands {}",
        settings.listen,
        if config.remote_commands.enabled {
            format!("on ({})", config.remote_commands.allowed_names())
        } else {
            "off".into()
        }
    );
    // Two threads, each blocked on its own input: the state goes out as the gateway publishes
    // it, and a query (an e-stop) is served as it arrives, neither waiting for the other.
    let latest_state = std::sync::Mutex::new(None);
    let failed = AtomicBool::new(false);
    let halt = || stop.load(Ordering::Relaxed) || failed.load(Ordering::Relaxed);
    let give_up = |result: anyhow::Result<()>| {
        if result.is_err() {
            failed.store(true, Ordering::Relaxed);
        }
        result
    };
    std::thread::scope(|scope| {
        let queries = std::thread::Builder::new()
            .name("zenoh-queries".into())
            .spawn_scoped(scope, || {
                give_up(serve_queries(
                    robot_name,
                    config,
                    info,
                    &session,
                    &latest_state,
                    &halt,
                ))
            })?;
        let forwarded = give_up(forward_state(
            robot_name,
            config,
            &session,
            &latest_state,
            &halt,
        ));
        let served = queries
            .join()
            .map_err(|_| anyhow::anyhow!("the query thread panicked"))?;
        forwarded.and(served)
    })
}

/// Publishes each new state (at most about `state_rate_hz`) and each new status, woken by the
/// gateway's notification.
fn forward_state(
    robot_name: &RobotName,
    config: &ZenohConfig,
    session: &zenoh::Session,
    latest_state: &std::sync::Mutex<Option<String>>,
    halt: &dyn Fn() -> bool,
) -> anyhow::Result<()> {
    let node = services::node(&robot_name.node(Program::Bridge))
        .map_err(|e| anyhow::anyhow!("creating the bridge's iceoryx2 node: {e}"))?;
    let (state_service, state_events) = services::state_services(&node, robot_name, Role::Client)?;
    let states = state_service
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("subscribing to the state: {e:?}"))?;
    let new_state = state_events
        .listener_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("listening for new states: {e:?}"))?;
    let statuses = services::status_services(&node, robot_name, Role::Client)?
        .subscriber_builder()
        .create()
        .map_err(|e| anyhow::anyhow!("subscribing to the status: {e:?}"))?;
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
    // A quarter period of slack, so that the chassis' jittered 50 Hz is not held back at the
    // default 50 Hz.
    let period = Duration::from_secs_f64(1.0 / config.state_rate_hz) * 3 / 4;
    let mut last_status: Option<StatusPayload> = None;
    let mut next_state = Instant::now();
    while !halt() {
        let now = Instant::now();
        if now >= next_state
            && let Some(state) = services::latest(&states)
                .map_err(|e| anyhow::anyhow!("receiving the state: {e:?}"))?
        {
            next_state = now + period;
            let json = state_json(&state, monotonic_ns()).to_string();
            if let Err(error) = state_publisher.put(json.clone()).wait() {
                warn!("zenoh: publishing the state failed: {error}");
            }
            if let Ok(mut latest) = latest_state.lock() {
                *latest = Some(json);
            }
        }
        if let Some(status) = services::latest(&statuses)
            .map_err(|e| anyhow::anyhow!("receiving the status: {e:?}"))?
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
        // Until the next state (or the rate allows the held one), at most 100 ms to see a
        // stop; a status change comes with a state.
        let wait = if next_state > now {
            next_state - now
        } else {
            Duration::from_millis(100)
        };
        if let Err(error) = new_state.timed_wait(|_| {}, wait) {
            debug!("waiting for a new state failed: {error:?}");
            std::thread::sleep(wait);
        }
    }
    Ok(())
}

/// Answers queries as they arrive: remote e-stops in a lane of their own, on a thread of their
/// own; remote commands, the latest state and the information on this one.
fn serve_queries(
    robot_name: &RobotName,
    config: &ZenohConfig,
    mut info: Value,
    session: &zenoh::Session,
    latest_state: &std::sync::Mutex<Option<String>>,
    halt: &(dyn Fn() -> bool + Sync),
) -> anyhow::Result<()> {
    // Two lanes, each through a channel to block on. The zenoh callback only sorts by key
    // (no allocation per peer, no I/O): an e-stop never waits behind other queries. A query
    // that finds its lane full is dropped unanswered and counted.
    let (estop_sender, estops) = std::sync::mpsc::sync_channel::<Estop>(MAX_QUEUED_ESTOPS);
    let (sender, inbox) = std::sync::mpsc::sync_channel::<Work>(MAX_QUEUED_QUERIES);
    let dropped = Arc::new(Dropped::default());
    let drives = Arc::new(DriveSlots::default());
    let queryable = |key: String, asked: Asked| {
        let (sender, estop_sender, dropped) =
            (sender.clone(), estop_sender.clone(), Arc::clone(&dropped));
        session
            .declare_queryable(key)
            .callback(move |query| {
                let estop = matches!(asked, Asked::Command)
                    && matches!(
                        remote::parse_command_key(query.key_expr().as_str()),
                        Ok((RemoteKind::Estop, _))
                    );
                if estop {
                    if estop_sender.try_send(Estop::Query(query)).is_err() {
                        dropped.estops.fetch_add(1, Ordering::Relaxed);
                    }
                } else if (sender.try_send(Work::Query(asked, query, services::monotonic())))
                    .is_err()
                {
                    dropped.queries.fetch_add(1, Ordering::Relaxed);
                }
            })
            .wait()
            .map_err(zenoh_error)
    };
    let _state_queries = queryable(remote::state_key(robot_name), Asked::State)?;
    let _info_queries = queryable(remote::info_key(robot_name), Asked::Info)?;
    let _command_queries = queryable(remote::command_keys(robot_name), Asked::Command)?;
    // The fast lane: drives put (not queried) wait in [`DriveSlots`], stamped with their
    // arrival; the command thread is woken once for however many arrive meanwhile.
    // An e-stop put goes to the e-stop lane, beside the e-stop queries: a peer sends both, and
    // whichever arrives first latches (the second refreshes the same stop).
    let _command_puts = {
        let (sender, estop_sender, drives, dropped, enabled) = (
            sender.clone(),
            estop_sender.clone(),
            Arc::clone(&drives),
            Arc::clone(&dropped),
            config.remote_commands.enabled,
        );
        session
            .declare_subscriber(remote::command_keys(robot_name))
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let put = sample.kind() == zenoh::sample::SampleKind::Put;
                let kind = remote::parse_command_key(key).ok().map(|(kind, _)| kind);
                if put && kind == Some(RemoteKind::Estop) {
                    let payload = (sample.payload().len() <= MAX_COMMAND_BYTES)
                        .then(|| sample.payload().to_bytes().into_owned());
                    let estop = Estop::Put {
                        key: key.to_owned(),
                        payload,
                    };
                    if estop_sender.try_send(estop).is_err() {
                        dropped.estops.fetch_add(1, Ordering::Relaxed);
                    }
                    return;
                }
                if !(enabled && put && kind == Some(RemoteKind::Drive)) {
                    drives.ignored.fetch_add(1, Ordering::Relaxed);
                    return;
                }
                // Past the limit only its first bytes are kept: enough for the rules to
                // refuse it as oversized.
                let payload = sample.payload().to_bytes();
                let payload = payload[..payload.len().min(MAX_COMMAND_BYTES + 1)].to_vec();
                if drives.put(key, services::monotonic(), payload) {
                    // The first waiting drive wakes the thread; a full inbox wakes it anyway.
                    let _ = sender.try_send(Work::Drives);
                }
            })
            .wait()
            .map_err(zenoh_error)?
    };
    let estop_counters = Arc::new(EstopCounters::default());
    std::thread::scope(|scope| {
        let estop_lane = std::thread::Builder::new()
            .name("zenoh-estops".into())
            .spawn_scoped(scope, {
                let estop_counters = &estop_counters;
                move || serve_estops(robot_name, config, &estops, estop_counters, halt)
            })?;
        let node = services::node(&robot_name.node(Program::BridgeCommands))
            .map_err(|e| anyhow::anyhow!("creating the bridge's iceoryx2 node: {e}"))?;
        let mut commands = RemoteControl::new(&node, robot_name, config, Arc::clone(&drives))?;
        let mut counters = Counters::default();
        let links = session
            .declare_publisher(remote::links_key(robot_name))
            .encoding(Encoding::APPLICATION_JSON)
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(zenoh_error)?;
        let mut next_links = Instant::now();
        while !halt() {
            if Instant::now() >= next_links {
                next_links = Instant::now() + LINKS_PERIOD;
                let quality = commands.rules.links(services::monotonic());
                if !quality.is_empty()
                    && let Err(error) = links.put(serde_json::to_string(&quality)?).wait()
                {
                    warn!("zenoh: publishing the link quality failed: {error}");
                }
            }
            counters.puts_ignored = drives.ignored.load(Ordering::Relaxed);
            counters.drives_superseded = drives.superseded.load(Ordering::Relaxed);
            counters.queries_dropped = dropped.queries.load(Ordering::Relaxed);
            counters.estops_dropped = dropped.estops.load(Ordering::Relaxed);
            let (asked, query, arrived) = match inbox.recv_timeout(Duration::from_millis(100)) {
                Ok(Work::Query(asked, query, arrived)) => (asked, query, arrived),
                Ok(Work::Drives) => {
                    for (key, (arrived, payload)) in drives.take() {
                        commands.handle_put(arrived, &key, &payload, &mut counters);
                    }
                    continue;
                }
                Err(_) => continue,
            };
            match asked {
                Asked::State => {
                    counters.state_queries += 1;
                    let latest = latest_state.lock().ok().and_then(|latest| latest.clone());
                    if let Some(state) = latest {
                        reply(&query, state);
                    }
                }
                Asked::Info => {
                    counters.info_queries += 1;
                    if let Value::Object(object) = &mut info {
                        object.insert(
                            "counters".into(),
                            serde_json::to_value(estop_counters.merged(counters))
                                .unwrap_or(Value::Null),
                        );
                        let now = services::monotonic();
                        object.insert(
                            "links".into(),
                            serde_json::to_value(commands.rules.links(now)).unwrap_or(Value::Null),
                        );
                        // The clock remote commands are aged by: `scout doctor` estimates the
                        // offset of its own from it.
                        object.insert("now_ms".into(), (now.as_millis() as u64).into());
                    }
                    reply(&query, info.to_string());
                }
                Asked::Command => {
                    let answer = commands.handle(arrived, &query, &mut counters);
                    reply(&query, serde_json::to_string(&answer).unwrap_or_default());
                }
            }
        }
        estop_lane
            .join()
            .map_err(|_| anyhow::anyhow!("the e-stop thread panicked"))?
    })
}

/// What the command thread is woken for.
enum Work {
    /// A query to answer, and when it arrived (commands are aged from their arrival, not
    /// from when this thread got to them).
    Query(Asked, Query, Duration),
    /// Drives put on the fast lane wait in [`DriveSlots`].
    Drives,
}

/// Drives put on the fast lane, with their arrival on this host's clock; and what the lane
/// counted. The keys of peers that hold control always find a place, and go first: peers that
/// hold nothing (a flood of names) never hold up or push out the drives of the one that drives.
/// A holder's drives wait in arrival order, up to [`MAX_QUEUED_DRIVES`], so that a burst that
/// arrives together (a link that held datagrams back, then let them go) reaches the arbiter
/// whole and in order, each aged from its own arrival; the others keep only their newest.
#[derive(Debug, Default)]
struct DriveSlots {
    waiting: std::sync::Mutex<Waiting>,
    /// The drive keys of the peers that hold control, as the command thread last saw them.
    holders: std::sync::Mutex<HashSet<String>>,
    superseded: std::sync::atomic::AtomicU64,
    ignored: std::sync::atomic::AtomicU64,
}

/// A drive waiting: when it arrived, and its payload.
type WaitingDrive = (Duration, Vec<u8>);

/// The drives waiting: of peers that hold control, in arrival order per key; of the others,
/// the newest per key.
#[derive(Debug, Default)]
struct Waiting {
    holders: HashMap<String, std::collections::VecDeque<WaitingDrive>>,
    others: HashMap<String, WaitingDrive>,
}

/// Keys of peers without control waiting at once; a drive from yet another such key is
/// dropped (and counted as superseded): that many peers at once is a flood, not a teleop.
const MAX_WAITING_DRIVES: usize = 64;

/// Drives of one peer that holds control waiting at once (160 ms of a 50 Hz teleop); past it
/// the oldest is dropped (and counted as superseded): the bridge is that far behind, and the
/// newest matter.
const MAX_QUEUED_DRIVES: usize = 8;

impl DriveSlots {
    /// Keeps `payload` as a drive on `key` waiting (behind the key's others if its peer holds
    /// control, in their place if not); whether the thread must be woken (no drive was waiting).
    fn put(&self, key: &str, arrived: Duration, payload: Vec<u8>) -> bool {
        let holder = self
            .holders
            .lock()
            .is_ok_and(|holders| holders.contains(key));
        let Ok(mut waiting) = self.waiting.lock() else {
            return false;
        };
        let wake = waiting.holders.is_empty() && waiting.others.is_empty();
        if holder {
            let queue = waiting.holders.entry(key.to_owned()).or_default();
            if queue.len() >= MAX_QUEUED_DRIVES {
                queue.pop_front();
                self.superseded.fetch_add(1, Ordering::Relaxed);
            }
            queue.push_back((arrived, payload));
            return wake;
        }
        let others = &mut waiting.others;
        if others.len() >= MAX_WAITING_DRIVES && !others.contains_key(key) {
            self.superseded.fetch_add(1, Ordering::Relaxed);
            return wake;
        }
        if others.insert(key.to_owned(), (arrived, payload)).is_some() {
            self.superseded.fetch_add(1, Ordering::Relaxed);
        }
        wake
    }

    /// The drives waiting: the holders' first (each key's in arrival order, the keys by their
    /// first arrival), then the others' by arrival.
    fn take(&self) -> Vec<(String, WaitingDrive)> {
        let Ok(mut waiting) = self.waiting.lock() else {
            return Vec::new();
        };
        let mut queues: Vec<_> = waiting.holders.drain().collect();
        queues.sort_by_key(|(_, queue)| queue.front().map(|(arrived, _)| *arrived));
        let mut taken: Vec<_> = queues
            .into_iter()
            .flat_map(|(key, queue)| queue.into_iter().map(move |drive| (key.clone(), drive)))
            .collect();
        let mut others: Vec<_> = waiting.others.drain().collect();
        others.sort_by_key(|(_, (arrived, _))| *arrived);
        taken.extend(others);
        taken
    }

    /// Whether the peer of drive key `key` holds control now.
    fn set_holder(&self, key: String, holds: bool) {
        if let Ok(mut holders) = self.holders.lock() {
            if holds {
                holders.insert(key);
            } else {
                holders.remove(&key);
            }
        }
    }
}

/// Queries dropped unanswered because their lane was full.
#[derive(Debug, Default)]
struct Dropped {
    queries: std::sync::atomic::AtomicU64,
    estops: std::sync::atomic::AtomicU64,
}

/// What the e-stop lane counted.
#[derive(Debug, Default)]
struct EstopCounters {
    accepted: std::sync::atomic::AtomicU64,
    copies: std::sync::atomic::AtomicU64,
    rejected: std::sync::atomic::AtomicU64,
    disabled: std::sync::atomic::AtomicU64,
}

impl EstopCounters {
    /// `counters` with the e-stops added: to the command counts, and apart.
    fn merged(&self, counters: Counters) -> Counters {
        let (accepted, rejected, disabled) = (
            self.accepted.load(Ordering::Relaxed),
            self.rejected.load(Ordering::Relaxed),
            self.disabled.load(Ordering::Relaxed),
        );
        Counters {
            commands_accepted: counters.commands_accepted + accepted,
            commands_rejected: counters.commands_rejected + rejected,
            commands_ignored_disabled: counters.commands_ignored_disabled + disabled,
            estops_accepted: accepted,
            estops_copies: self.copies.load(Ordering::Relaxed),
            estops_rejected: rejected,
            estops_ignored_disabled: disabled,
            ..counters
        }
    }
}

/// The e-stop lane: every remote e-stop, answered in arrival order, latched through the
/// bridge's own stop port as the stop of `remote:PEER` (a copy of one that latched is answered
/// as that stop: [`EstopCopies`]). Per query: the permission check and at most one stop
/// request; what is kept of e-stops is bounded.
fn serve_estops(
    robot_name: &RobotName,
    config: &ZenohConfig,
    estops: &std::sync::mpsc::Receiver<Estop>,
    counters: &EstopCounters,
    halt: &(dyn Fn() -> bool + Sync),
) -> anyhow::Result<()> {
    let node = services::node(&robot_name.node(Program::BridgeEstops))
        .map_err(|e| anyhow::anyhow!("creating the bridge's iceoryx2 node: {e}"))?;
    let mut port = ControlPort::open(&node, robot_name, Way::Stop, REMOTE_PREFIX)
        .map_err(|e| anyhow::anyhow!("opening the bridge's stop port: {e}"))?;
    let mut copies = EstopCopies::default();
    while !halt() {
        let Ok(item) = estops.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let (key, payload) = match &item {
            Estop::Query(query) => (
                query.key_expr().as_str(),
                query.payload().map(|payload| payload.to_bytes()),
            ),
            Estop::Put { key, payload } => (
                key.as_str(),
                payload.as_deref().map(std::borrow::Cow::Borrowed),
            ),
        };
        let answer = if !config.remote_commands.enabled {
            counters.disabled.fetch_add(1, Ordering::Relaxed);
            RemoteAnswer::rejected(DISABLED)
        } else {
            let now = services::monotonic();
            match estop(config, &mut port, &mut copies, now, key, payload.as_deref()) {
                Ok((accepted, copy)) => {
                    counters.accepted.fetch_add(1, Ordering::Relaxed);
                    if copy {
                        counters.copies.fetch_add(1, Ordering::Relaxed);
                    }
                    RemoteAnswer::accepted(&accepted)
                }
                Err(reason) => {
                    counters.rejected.fetch_add(1, Ordering::Relaxed);
                    RemoteAnswer::refused(&reason)
                }
            }
        };
        if let Estop::Query(query) = &item {
            reply(query, serde_json::to_string(&answer).unwrap_or_default());
        }
    }
    Ok(())
}

/// A remote e-stop: a query (answered) or a put (not; counted alike).
enum Estop {
    /// Asked with a query.
    Query(Query),
    /// Put on its key; an oversized payload is not kept (it only loses the reason).
    Put {
        key: String,
        payload: Option<Vec<u8>>,
    },
}

/// One remote e-stop: never refused for its payload (a missing, oversized or malformed one
/// only loses its reason, and its name as an act); it needs the permission and the stop
/// service, nothing else. Returns the answer and whether it was a copy of one that latched.
fn estop(
    config: &ZenohConfig,
    port: &mut ControlPort,
    copies: &mut EstopCopies,
    now: Duration,
    key: &str,
    payload: Option<&[u8]>,
) -> Result<(Accepted, bool), CommandError> {
    rules::allowed(&config.remote_commands, Permission::Estop)?;
    let (_, peer) = remote::parse_command_key(key)?;
    let json = payload
        .filter(|payload| payload.len() <= MAX_COMMAND_BYTES)
        .and_then(|payload| serde_json::from_slice::<Value>(payload).ok());
    let field = |name: &str| json.as_ref().and_then(|json| json.get(name));
    let reason = field("reason")
        .and_then(Value::as_str)
        .map_or_else(|| "remote estop".into(), str::to_owned);
    let act = field("seq")
        .and_then(Value::as_u64)
        .zip(field("sent_ms").and_then(Value::as_u64));
    let client = peer_client_name(peer);
    if let Some(accepted) = copies.copy_of(now, &client, act) {
        return Ok((accepted, true));
    }
    let accepted = port.request_for_peer(&Request::Stop { reason }, &client)?;
    copies.handle_latched(now, &client, act, &accepted);
    Ok((accepted, false))
}

const DISABLED: &str =
    "remote commands are disabled on this gateway (zenoh.remote_commands.enabled)";

/// What a query asks for.
#[derive(Debug, Clone, Copy)]
enum Asked {
    State,
    Info,
    Command,
}

/// How often the remote peers' link quality is published (when there are any).
const LINKS_PERIOD: Duration = Duration::from_secs(1);

/// Queries waiting for the query thread; more are dropped unanswered (and counted).
const MAX_QUEUED_QUERIES: usize = 1024;

/// E-stops waiting for the e-stop thread; more are dropped unanswered (and counted): that
/// many e-stops waiting already stop the robot.
const MAX_QUEUED_ESTOPS: usize = 4096;

fn reply(query: &Query, payload: String) {
    if let Err(error) = query
        .reply(query.key_expr().clone(), payload)
        .encoding(Encoding::APPLICATION_JSON)
        .wait()
    {
        warn!("zenoh: replying to {} failed: {error}", query.key_expr());
    }
}

/// Remote commands other than e-stops, the driver of [`Rules`]: a peer that takes control gets
/// a control port of its own, named `remote:PEER`, so the arbiter treats it like a local client
/// (leases, freshness, limits, priority); releases go through the bridge's stop port, naming
/// the peer. The peer is named by the command's key, which zenoh's access control binds to the
/// peer's certificate. Nothing is kept or opened for a peer before its command passed the
/// permission check.
struct RemoteControl<'a> {
    node: &'a iceoryx2::node::Node<services::Ipc>,
    robot: &'a str,
    config: &'a ZenohConfig,
    rules: Rules,
    /// The bridge's stop-service port, for releases.
    safety: ControlPort,
    /// The control ports of the peers the rules keep, by client name.
    ports: HashMap<String, ControlPort>,
    /// The fast lane, told which peers hold control.
    drives: Arc<DriveSlots>,
}

impl<'a> RemoteControl<'a> {
    fn new(
        node: &'a iceoryx2::node::Node<services::Ipc>,
        robot: &'a str,
        config: &'a ZenohConfig,
        drives: Arc<DriveSlots>,
    ) -> anyhow::Result<Self> {
        Ok(Self {
            node,
            robot,
            config,
            rules: Rules::new(config.remote_commands.clone()),
            safety: ControlPort::open(node, robot, Way::Stop, REMOTE_PREFIX)
                .map_err(|e| anyhow::anyhow!("opening the bridge's stop port: {e}"))?,
            ports: HashMap::new(),
            drives,
        })
    }

    fn handle(
        &mut self,
        arrived: Duration,
        query: &Query,
        counters: &mut Counters,
    ) -> RemoteAnswer {
        if !self.config.remote_commands.enabled {
            counters.commands_ignored_disabled += 1;
            return RemoteAnswer::rejected(DISABLED);
        }
        let answer = match self.decide(arrived, query) {
            Ok(accepted) => RemoteAnswer::accepted(&accepted),
            Err(reason) => RemoteAnswer::refused(&reason),
        };
        if answer.accepted {
            counters.commands_accepted += 1;
        } else {
            counters.commands_rejected += 1;
        }
        answer
    }

    /// A drive put on the fast lane, arrived at `arrived`: no answer goes back, the counters
    /// say what became of it.
    fn handle_put(
        &mut self,
        arrived: Duration,
        key: &str,
        payload: &[u8],
        counters: &mut Counters,
    ) {
        match self.send(arrived, key, Some(payload)) {
            Ok(_) => counters.drives_put_accepted += 1,
            Err(error) => {
                counters.drives_put_rejected += 1;
                debug!("zenoh: drive put on {key} refused: {error}");
            }
        }
    }

    fn decide(&mut self, arrived: Duration, query: &Query) -> Result<Accepted, CommandError> {
        let payload = query.payload().map(|payload| payload.to_bytes());
        self.send(arrived, query.key_expr().as_str(), payload.as_deref())
    }

    /// A command through the rules, then to the arbiter.
    fn send(
        &mut self,
        now: Duration,
        key: &str,
        payload: Option<&[u8]>,
    ) -> Result<Accepted, CommandError> {
        let send = self.rules.handle_command(now, key, payload)?;
        if let Some(evicted) = &send.evicted {
            self.ports.remove(evicted);
        }
        let answer = match send.via {
            Via::Safety => self.safety.request_for_peer(&send.request, &send.peer),
            Via::Control { sent } => {
                let port = match self.ports.entry(send.peer.clone()) {
                    Entry::Occupied(port) => port.into_mut(),
                    Entry::Vacant(slot) => slot.insert(ControlPort::open(
                        self.node,
                        self.robot,
                        Way::Control,
                        &send.peer,
                    )?),
                };
                port.request_sent_at(&send.request, sent)
            }
        };
        self.rules.handle_answer(&send.peer, &send.request, &answer);
        if let Ok((_, peer)) = remote::parse_command_key(key) {
            let drive_key = remote::command_key(self.robot, RemoteKind::Drive, peer);
            self.drives
                .set_holder(drive_key, self.rules.holds(&send.peer));
        }
        Ok(answer?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fast_lane_keeps_the_newest_drive_per_key_and_wakes_once() {
        let slots = DriveSlots::default();
        let ms = Duration::from_millis;
        assert!(
            slots.put("scout/r/cmd/drive/a", ms(10), b"1".to_vec()),
            "first wakes"
        );
        assert!(!slots.put("scout/r/cmd/drive/a", ms(30), b"2".to_vec()));
        assert!(!slots.put("scout/r/cmd/drive/b", ms(20), b"x".to_vec()));
        assert_eq!(slots.superseded.load(Ordering::Relaxed), 1);
        let taken = slots.take();
        let keys: Vec<(&str, &[u8])> = taken
            .iter()
            .map(|(key, (_, payload))| (key.as_str(), payload.as_slice()))
            .collect();
        assert_eq!(
            keys,
            [
                ("scout/r/cmd/drive/b", &b"x"[..]),
                ("scout/r/cmd/drive/a", &b"2"[..])
            ],
            "the newest per key, oldest arrival first"
        );
        assert!(
            slots.put("scout/r/cmd/drive/a", ms(40), b"3".to_vec()),
            "empty again"
        );
        // A flood of keys: past MAX_WAITING_DRIVES, new keys are dropped and counted.
        for peer in 0..MAX_WAITING_DRIVES + 10 {
            slots.put(&format!("scout/r/cmd/drive/p{peer}"), ms(50), Vec::new());
        }
        assert_eq!(slots.take().len(), MAX_WAITING_DRIVES);
        assert_eq!(slots.superseded.load(Ordering::Relaxed), 1 + 11);
    }

    #[test]
    fn a_burst_from_the_peer_in_control_reaches_the_arbiter_whole_and_in_order() {
        let slots = DriveSlots::default();
        let ms = Duration::from_millis;
        let key = "scout/r/cmd/drive/op";
        slots.set_holder(key.into(), true);
        assert!(slots.put(key, ms(10), b"1".to_vec()), "first wakes");
        assert!(!slots.put("scout/r/cmd/drive/other", ms(11), b"x".to_vec()));
        assert!(!slots.put(key, ms(12), b"2".to_vec()));
        assert!(!slots.put(key, ms(13), b"3".to_vec()));
        let taken = slots.take();
        let taken: Vec<(&str, Duration, &[u8])> = taken
            .iter()
            .map(|(key, (at, payload))| (key.as_str(), *at, payload.as_slice()))
            .collect();
        assert_eq!(
            taken,
            [
                (key, ms(10), &b"1"[..]),
                (key, ms(12), &b"2"[..]),
                (key, ms(13), &b"3"[..]),
                ("scout/r/cmd/drive/other", ms(11), &b"x"[..]),
            ]
        );
        assert_eq!(slots.superseded.load(Ordering::Relaxed), 0);
        // A bridge that far behind keeps the newest MAX_QUEUED_DRIVES, counting the rest.
        for at in 0..MAX_QUEUED_DRIVES as u64 + 3 {
            slots.put(key, ms(100 + at), at.to_string().into_bytes());
        }
        let taken = slots.take();
        assert_eq!(taken.len(), MAX_QUEUED_DRIVES);
        assert_eq!(taken[0].1.0, ms(103), "the oldest went");
        assert_eq!(slots.superseded.load(Ordering::Relaxed), 3);
    }

    #[test]
    fn the_driving_peers_drives_find_a_place_and_go_first_whatever_floods_the_lane() {
        let slots = DriveSlots::default();
        let ms = Duration::from_millis;
        slots.set_holder("scout/r/cmd/drive/op".into(), true);
        for peer in 0..MAX_WAITING_DRIVES + 100 {
            slots.put(&format!("scout/r/cmd/drive/p{peer}"), ms(10), Vec::new());
        }
        slots.put("scout/r/cmd/drive/op", ms(20), b"drive".to_vec());
        let taken = slots.take();
        assert_eq!(taken.len(), MAX_WAITING_DRIVES + 1);
        assert_eq!(taken[0].0, "scout/r/cmd/drive/op", "the driver first");
        // Once it lets go, it is one of the others again.
        slots.set_holder("scout/r/cmd/drive/op".into(), false);
        for peer in 0..MAX_WAITING_DRIVES {
            slots.put(&format!("scout/r/cmd/drive/p{peer}"), ms(30), Vec::new());
        }
        slots.put("scout/r/cmd/drive/op", ms(40), b"drive".to_vec());
        assert!(
            slots
                .take()
                .iter()
                .all(|(key, _)| key != "scout/r/cmd/drive/op")
        );
    }

    #[test]
    fn the_example_zenoh_configs_parse() {
        for file in [
            "zenoh-tls-gateway.json5",
            "zenoh-tls-operator.json5",
            "zenoh-wireguard-gateway.json5",
            "zenoh-wireguard-operator.json5",
        ] {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../config")
                .join(file);
            if let Err(error) = zenoh::Config::from_file(&path) {
                panic!("{}: {error}", path.display());
            }
        }
    }

    #[test]
    fn permissions_are_checked_when_the_config_is_read() {
        let config: ZenohConfig = serde_json::from_str(
            r#"{"remote_commands":{"enabled":true,"allowed":["estop","clear_fault"]}}"#,
        )
        .expect("valid");
        assert_eq!(
            config.remote_commands.allowed,
            [Permission::Estop, Permission::ClearFault]
        );
        let error =
            serde_json::from_str::<ZenohConfig>(r#"{"remote_commands":{"allowed":["fly"]}}"#)
                .expect_err("unknown permission");
        assert!(
            error.to_string().contains("unknown variant `fly`"),
            "{error}"
        );
        assert!(
            ZenohConfig {
                state_rate_hz: 0.0,
                ..Default::default()
            }
            .validate()
            .is_err()
        );
    }
}
