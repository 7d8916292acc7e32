//! `scout ros2`: the driver that makes a gateway's chassis a ROS 2 node over rmw_zenoh. An
//! ordinary local client of the gateway (state and status subscribers, controllers), and a
//! zenoh client of the ROS 2 router: it declares the node and its endpoints as liveliness
//! tokens, publishes what [`Messages`] makes, feeds cmd_vel through [`CmdVelStream`] into the
//! arbiter, and serves the e-stop and release services.
//!
//! Three threads, each blocked on its own input, so that no one waits for another: the state
//! (woken by the gateway's state event), the cmd_vel messages (a bounded queue the zenoh
//! callbacks fill) and the services (another queue, with a stop port of its own).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, TrySendError, sync_channel};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use scout_interface::remote::SessionSettings;
use scout_interface::services::{monotonic, monotonic_ns};
use serde::Serialize;
use tracing::{info, warn};
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Publisher;
use zenoh::qos::CongestionControl;
use zenoh::query::{Query, Queryable};

use crate::config::{ROS2_ROUTER, Ros2Config};
use crate::msgs::{self, MessageType};
use crate::publish::{Clocks, Messages, Topic};
use crate::rmw::{self, EntityKind, Node};
use crate::stream::{Action, CmdVelStream, Ignored, Origin, Outcome};
use scout_clients::client::{ClientError, Robot};
use scout_clients::control::ControlError;
use scout_interface::control::ReleaseTarget;

/// Why the bridge stopped.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// The gateway could not be reached.
    #[error(transparent)]
    Client(#[from] ClientError),
    /// The gateway stopped answering (it exited or hangs).
    #[error(transparent)]
    Control(#[from] ControlError),
    /// The ROS 2 router could not be reached, or zenoh failed.
    #[error("{0}")]
    Zenoh(String),
    /// A thread of the bridge could not start.
    #[error("starting a thread: {0}")]
    Thread(#[from] std::io::Error),
    /// The zenoh configuration file puts the session in another mode than client.
    #[error(
        "{file} sets zenoh mode \"{mode}\": the bridge must be a client of the ROS 2 router \
         (rmw_zenohd does not forward between peers); set mode: \"client\" or leave it out"
    )]
    NotClient {
        /// The file.
        file: String,
        /// The mode it asks for.
        mode: String,
    },
    /// Another bridge serves this robot on this ROS domain: two would share a client name
    /// and drive the chassis from both graphs.
    #[error(
        "another `scout ros2` bridge serves robot '{robot}' on ROS domain {domain} on this host: stop it first, or give this one another --domain"
    )]
    AlreadyRunning {
        /// The robot.
        robot: String,
        /// The ROS domain.
        domain: u32,
    },
}

/// The abstract socket address that one bridge per robot and ROS domain holds.
fn bridge_claim(robot: &str, domain: u32) -> String {
    format!("{}/ros2/{domain}", scout_interface::services::prefix(robot))
}

fn zenoh_error(what: &str) -> impl Fn(zenoh::Error) -> BridgeError + '_ {
    move |error| BridgeError::Zenoh(format!("{what}: {error}"))
}

/// What the bridge counted, shown in its diagnostics and logged when it stops.
#[derive(Debug, Default, Serialize)]
pub struct Counters {
    pub published: AtomicU64,
    pub cmd_vel_received: AtomicU64,
    pub cmd_vel_accepted: AtomicU64,
    pub cmd_vel_rejected: AtomicU64,
    /// Not CDR of the topic's type.
    pub cmd_vel_malformed: AtomicU64,
    /// No rmw_zenoh attachment: not from a ROS publisher (ROS subscribers drop these too).
    pub cmd_vel_without_attachment: AtomicU64,
    /// Ignored: the stream went on across a loss of control.
    pub cmd_vel_mid_stream: AtomicU64,
    /// Dropped: the command thread was [`QUEUE`] messages behind.
    pub cmd_vel_dropped: AtomicU64,
    pub service_calls: AtomicU64,
    /// Answered `busy` without being served: the service's queue was [`QUEUE`] calls behind.
    pub service_calls_dropped: AtomicU64,
    /// Refused with the reason: a wildcard query, or no Trigger request with the rmw_zenoh
    /// attachment.
    pub service_calls_malformed: AtomicU64,
}

impl Counters {
    fn add(counter: &AtomicU64) -> u64 {
        counter.fetch_add(1, Ordering::Relaxed) + 1
    }

    fn values(&self) -> Vec<(String, String)> {
        serde_json::to_value(self)
            .ok()
            .and_then(|json| json.as_object().cloned())
            .unwrap_or_default()
            .into_iter()
            .map(|(key, value)| (key, value.to_string()))
            .collect()
    }
}

/// Messages waiting for the command or service thread; more are dropped and counted.
const QUEUE: usize = 64;

/// A publisher with its sequence number and GID, for the attachment.
struct RosPublisher {
    publisher: Publisher<'static>,
    topic: String,
    gid: [u8; 16],
    seq: i64,
}

impl RosPublisher {
    fn put(&mut self, payload: Vec<u8>, counters: &Counters) {
        self.seq += 1;
        let attachment = rmw::attachment(self.seq, unix_now().as_nanos() as i64, &self.gid);
        match self
            .publisher
            .put(payload)
            .attachment(attachment.to_vec())
            .wait()
        {
            Ok(()) => {
                Counters::add(&counters.published);
            }
            Err(error) => warn!("ros2: publishing on {} failed: {error}", self.topic),
        }
    }
}

fn unix_now() -> Duration {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
}

/// The node and its endpoints' liveliness tokens; entity ids count from 1 (the node's own
/// token uses the node id).
struct Declared {
    node: Node,
    next_entity: u32,
    tokens: Vec<LivelinessToken>,
}

impl Declared {
    fn declare(
        &mut self,
        session: &zenoh::Session,
        kind: EntityKind,
        name: &str,
        message: &MessageType,
        config: &Ros2Config,
    ) -> Result<[u8; 16], BridgeError> {
        self.next_entity += 1;
        let entity = self.next_entity;
        let key = self
            .node
            .entity_token(entity, kind, name, message, config.distro);
        let gid = rmw::gid(&key);
        self.tokens.push(
            session
                .liveliness()
                .declare_token(key)
                .wait()
                .map_err(zenoh_error("declaring a liveliness token"))?,
        );
        Ok(gid)
    }
}

/// The zenoh session's settings: client mode towards the ROS 2 router. `$ZENOH_CONFIG` is never
/// read: a file meant for other zenoh programs would silently change the bridge's mode.
pub fn session_settings(config: &Ros2Config) -> SessionSettings {
    let connect = if config.connect.is_empty() && config.zenoh_config.is_none() {
        vec![ROS2_ROUTER.to_owned()]
    } else {
        config.connect.clone()
    };
    SessionSettings {
        config_file: Some(config.zenoh_config.clone().unwrap_or_default()),
        listen: Vec::new(),
        connect,
    }
}

/// The zenoh configuration of the bridge's session: always a client of the ROS 2 router, since
/// rmw_zenohd does not forward between peers (its `peers_failover_brokering` is off). A file
/// without a mode is made a client; a file asking for another mode is refused.
pub fn session_config(config: &Ros2Config) -> Result<zenoh::Config, BridgeError> {
    let settings = session_settings(config);
    let mut zenoh_config = settings
        .config("client")
        .map_err(|error| BridgeError::Zenoh(error.to_string()))?;
    let mode = zenoh_config
        .get_json("mode")
        .map_err(|error| BridgeError::Zenoh(format!("reading the zenoh mode: {error}")))?;
    match mode.trim_matches('"') {
        "client" => {}
        "null" | "" => zenoh_config
            .insert_json5("mode", "\"client\"")
            .map_err(|error| BridgeError::Zenoh(format!("setting client mode: {error}")))?,
        other => {
            return Err(BridgeError::NotClient {
                file: config.zenoh_config.clone().unwrap_or_default(),
                mode: other.to_owned(),
            });
        }
    }
    Ok(zenoh_config)
}

/// Runs the bridge for robot `robot` until `stop` is set or something fails.
pub fn run(robot: &str, config: &Ros2Config, stop: &AtomicBool) -> Result<(), BridgeError> {
    let _claim = scout_interface::stop_socket::claim(&bridge_claim(robot, config.domain)).map_err(
        |errno| match errno {
            nix::errno::Errno::EADDRINUSE => BridgeError::AlreadyRunning {
                robot: robot.to_owned(),
                domain: config.domain,
            },
            other => BridgeError::Thread(other.into()),
        },
    )?;
    let gateway = Robot::connect(robot)?;
    let settings = session_settings(config);
    let session = zenoh::open(session_config(config)?)
        .wait()
        .map_err(|error| {
            BridgeError::Zenoh(format!(
                "{error}: no ROS 2 router at {:?}? Start one (`ros2 run rmw_zenoh_cpp rmw_zenohd`) \
             or give --connect ENDPOINT",
                settings.connect
            ))
        })?;
    let mut declared = Declared {
        node: Node {
            domain: config.domain,
            zid: session.zid().to_string(),
            id: 0,
            namespace: config.namespace.clone(),
            name: config.node.clone(),
            enclave: String::new(),
        },
        next_entity: 0,
        tokens: Vec::new(),
    };
    declared.tokens.push(
        session
            .liveliness()
            .declare_token(declared.node.token())
            .wait()
            .map_err(zenoh_error("declaring the node"))?,
    );
    let counters = Arc::new(Counters::default());
    let mut publishers = Vec::new();
    for topic in Topic::ALL {
        let Some(name) = topic.name(config) else {
            continue;
        };
        let name = config.resolve(name);
        let message = topic.message();
        let gid = declared.declare(&session, EntityKind::Publisher, &name, &message, config)?;
        let publisher = session
            .declare_publisher(rmw::data_key(config.domain, &name, &message, config.distro))
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(zenoh_error("declaring a publisher"))?;
        publishers.push((
            topic,
            RosPublisher {
                publisher,
                gid,
                topic: name,
                seq: 0,
            },
        ));
    }
    let (twists, twist_inbox) = sync_channel::<(usize, zenoh::sample::Sample)>(QUEUE);
    let mut subscribers = Vec::new();
    for (index, cmd_vel) in config.cmd_vel.iter().enumerate() {
        let name = config.resolve(&cmd_vel.topic);
        let message = if cmd_vel.stamped {
            msgs::TWIST_STAMPED
        } else {
            msgs::TWIST
        };
        declared.declare(&session, EntityKind::Subscription, &name, &message, config)?;
        let (sender, counters) = (twists.clone(), Arc::clone(&counters));
        subscribers.push(
            session
                .declare_subscriber(rmw::subscription_key(config.domain, &name, &message))
                .callback(move |sample| {
                    if let Err(TrySendError::Full(_)) = sender.try_send((index, sample)) {
                        Counters::add(&counters.cmd_vel_dropped);
                    }
                })
                .wait()
                .map_err(zenoh_error("subscribing to cmd_vel"))?,
        );
    }
    drop(twists);
    // A queue per service, the e-stop's served first: a flood of release calls never holds an
    // e-stop up. The senders live as long as the bridge, so the queues never disconnect.
    let (estops, estop_inbox) = crossbeam_channel::bounded::<Query>(QUEUE);
    let (releases, release_inbox) = crossbeam_channel::bounded::<Query>(QUEUE);
    let mut queryables: Vec<Queryable<()>> = Vec::new();
    let services = match (config.services, config.release_service) {
        (false, _) => &[][..],
        (true, false) => &[ServiceKind::Estop][..],
        (true, true) => &[ServiceKind::Estop, ServiceKind::Release][..],
    };
    for &kind in services {
        let name = config.resolve(kind.name(config));
        declared.declare(&session, EntityKind::Service, &name, &msgs::TRIGGER, config)?;
        let key = rmw::data_key(config.domain, &name, &msgs::TRIGGER, config.distro);
        let sender = match kind {
            ServiceKind::Estop => estops.clone(),
            ServiceKind::Release => releases.clone(),
        };
        let counters = Arc::clone(&counters);
        queryables.push(
            session
                .declare_queryable(key.clone())
                .complete(true)
                .callback(move |query| {
                    // A wildcard query (`**`, a diagnostic tool's) is no call.
                    if query.key_expr().as_str() != key {
                        Counters::add(&counters.service_calls_malformed);
                        refuse(&query, "not a service call: query the service's exact key");
                        return;
                    }
                    // Checked here, so that only real calls wait in the queue. An rmw_zenoh
                    // client ignores error replies (its caller would wait for its timeout): a
                    // call with the attachment is refused with a Trigger response saying why.
                    if let Err(why) = trigger_request(&query) {
                        Counters::add(&counters.service_calls_malformed);
                        match why {
                            NoCall::NotRmwZenoh(why) => refuse(&query, why),
                            NoCall::NotTrigger(why) => answer(&query, kind, false, &why),
                        }
                        return;
                    }
                    if let Err(crossbeam_channel::TrySendError::Full(query)) =
                        sender.try_send(query)
                    {
                        Counters::add(&counters.service_calls_dropped);
                        let message = match kind {
                            ServiceKind::Estop => {
                                "busy: the e-stop calls already waiting latch the stop"
                            }
                            ServiceKind::Release => "busy: too many calls waiting, call again",
                        };
                        answer(&query, kind, false, message);
                    }
                })
                .wait()
                .map_err(zenoh_error("declaring a service"))?,
        );
    }
    info!(
        "scout ros2: node {}/{} in domain {} ({:?}), connected to {:?}; publishing {:?}; \
         driving from {}",
        config.namespace,
        config.node,
        config.domain,
        config.distro,
        settings.connect,
        publishers
            .iter()
            .map(|(_, p)| p.topic.as_str())
            .collect::<Vec<_>>(),
        config
            .cmd_vel
            .iter()
            .map(|c| format!("{} as {}", config.resolve(&c.topic), c.class))
            .collect::<Vec<_>>()
            .join(", "),
    );
    let failed = AtomicBool::new(false);
    let halt = || stop.load(Ordering::Relaxed) || failed.load(Ordering::Relaxed);
    let give_up = |result: Result<(), BridgeError>| {
        if result.is_err() {
            failed.store(true, Ordering::Relaxed);
        }
        result
    };
    let result = std::thread::scope(|scope| {
        let (gateway, counters, halt, give_up) = (&gateway, &*counters, &halt, &give_up);
        let commands = std::thread::Builder::new()
            .name("ros2-cmd-vel".into())
            .spawn_scoped(scope, move || {
                give_up(drive(gateway, config, &twist_inbox, counters, halt))
            })?;
        let services = std::thread::Builder::new()
            .name("ros2-services".into())
            .spawn_scoped(scope, move || {
                give_up(serve(
                    gateway,
                    config,
                    [&estop_inbox, &release_inbox],
                    counters,
                    halt,
                ))
            })?;
        let published = give_up(publish(gateway, config, &mut publishers, counters, halt));
        let driven = commands
            .join()
            .unwrap_or_else(|_| Err(BridgeError::Zenoh("the cmd_vel thread panicked".into())));
        let served = services
            .join()
            .unwrap_or_else(|_| Err(BridgeError::Zenoh("the service thread panicked".into())));
        published.and(driven).and(served)
    });
    info!(
        "scout ros2: stopping; counters {}",
        serde_json::to_string(&*counters).unwrap_or_default()
    );
    drop(subscribers);
    drop(queryables);
    drop(declared);
    result
}

/// The state thread: each new state becomes the messages [`Messages`] makes of it.
fn publish(
    gateway: &Robot,
    config: &Ros2Config,
    publishers: &mut [(Topic, RosPublisher)],
    counters: &Counters,
    halt: &dyn Fn() -> bool,
) -> Result<(), BridgeError> {
    let states = gateway.subscribe()?;
    let status = gateway.status()?;
    let mut messages = Messages::new(config.clone());
    let mut last_status = None;
    let mut last_state_ns = monotonic_ns();
    while !halt() {
        let clocks = || Clocks {
            monotonic_ns: monotonic_ns(),
            unix: unix_now(),
        };
        let bridge = || counters.values();
        let outgoing = match states.next_timeout(Duration::from_millis(100)) {
            Ok(Some(state)) => {
                // The newest of a burst: each message is made from the frames it holds.
                let state = states.try_latest()?.unwrap_or(state);
                last_state_ns = monotonic_ns();
                last_status = status.latest(Duration::ZERO)?.or(last_status);
                messages.handle_state(&state, last_status.as_ref(), clocks(), &bridge)
            }
            // No state (the gateway stopped or hangs), or a signal interrupted the wait
            // (Ctrl-C sets `halt` on its own thread).
            Ok(None) | Err(ClientError::Wait(_)) => {
                messages.handle_silence(gateway.name(), last_state_ns, clocks(), &bridge)
            }
            Err(error) => return Err(error.into()),
        };
        for outgoing in outgoing {
            if let Some((_, publisher)) = publishers.iter_mut().find(|(t, _)| *t == outgoing.topic)
            {
                publisher.put(outgoing.payload, counters);
            }
        }
    }
    Ok(())
}

/// The cmd_vel thread: each message through its topic's [`CmdVelStream`] to the arbiter.
fn drive(
    gateway: &Robot,
    config: &Ros2Config,
    inbox: &Receiver<(usize, zenoh::sample::Sample)>,
    counters: &Counters,
    halt: &dyn Fn() -> bool,
) -> Result<(), BridgeError> {
    let mut drivers = Vec::new();
    let topics = &config.cmd_vel;
    for topic in topics {
        let name = config.resolve(&topic.topic);
        let client = config.cmd_vel_client(topic);
        drivers.push((
            gateway.controller(&client, Some(topic.class))?,
            CmdVelStream::new(monotonic(), config.pauses()),
            name,
        ));
    }
    while !halt() {
        let Ok((index, sample)) = inbox.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let Some((controller, stream, name)) = drivers.get_mut(index) else {
            continue;
        };
        Counters::add(&counters.cmd_vel_received);
        let Some((sequence, sent_ns, gid)) = sample
            .attachment()
            .and_then(|a| rmw::parse_attachment(&a.to_bytes()))
        else {
            let count = Counters::add(&counters.cmd_vel_without_attachment);
            if count.is_power_of_two() {
                warn!(
                    "ros2: {name}: a message without the rmw_zenoh attachment ({count} so far): \
                     dropped, as ROS subscribers drop it; publish through rmw_zenoh"
                );
            }
            continue;
        };
        let twist = match msgs::decode_twist(&sample.payload().to_bytes(), topics[index].stamped) {
            Ok(twist) => twist,
            Err(error) => {
                let count = Counters::add(&counters.cmd_vel_malformed);
                if count.is_power_of_two() {
                    warn!("ros2: {name}: not a valid message ({count} so far): {error}");
                }
                continue;
            }
        };
        let origin = Origin {
            gid,
            sequence,
            sent_ns,
        };
        let mut action = stream.handle_twist(monotonic(), origin, twist);
        loop {
            let answer = match action {
                Action::Ignore(why) => {
                    let counter = match why {
                        Ignored::MidStream => Some(&counters.cmd_vel_mid_stream),
                        Ignored::NotFinite => Some(&counters.cmd_vel_malformed),
                        Ignored::Zero => None,
                    };
                    if let Some(count) = counter.map(Counters::add)
                        && count.is_power_of_two()
                    {
                        warn!("ros2: {name}: ignored ({count} so far): {}", why.reason());
                    }
                    break;
                }
                Action::Take => controller.take_control(),
                Action::Drive => controller.drive(twist.linear, twist.angular),
            };
            match &answer {
                // A message is accepted when its speed is: taking control on the way is not a
                // second acceptance.
                Ok(_) if action == Action::Take => {}
                Ok(_) => {
                    Counters::add(&counters.cmd_vel_accepted);
                }
                Err(error) => {
                    let count = Counters::add(&counters.cmd_vel_rejected);
                    if count.is_power_of_two() || action == Action::Take {
                        info!("ros2: {name}: {error} ({count} refused so far)");
                    }
                }
            }
            let outcome = match answer {
                Ok(_) => Outcome::Accepted,
                Err(error @ ControlError::NoAnswer { .. }) => return Err(error.into()),
                Err(error) if error.lost_control() => Outcome::LostControl,
                Err(_) => Outcome::Refused,
            };
            match stream.handle_answer(outcome) {
                Some(next) => action = next,
                None => break,
            }
        }
    }
    Ok(())
}

/// The two services.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ServiceKind {
    Estop,
    Release,
}

impl ServiceKind {
    fn name(self, config: &Ros2Config) -> &str {
        match self {
            ServiceKind::Estop => &config.topics.estop,
            ServiceKind::Release => &config.topics.release,
        }
    }
}

/// The service thread: an e-stop latches a stop owned by [`Ros2Config::service_client`]; a
/// release releases that client's own stops (others' need an operator) and restarts nothing.
/// E-stop calls are served before release calls.
fn serve(
    gateway: &Robot,
    config: &Ros2Config,
    [estops, releases]: [&crossbeam_channel::Receiver<Query>; 2],
    counters: &Counters,
    halt: &dyn Fn() -> bool,
) -> Result<(), BridgeError> {
    let mut controller = gateway.controller(&config.service_client(), None)?;
    while !halt() {
        let (kind, query) = match estops.try_recv() {
            Ok(query) => (ServiceKind::Estop, query),
            Err(_) => crossbeam_channel::select! {
                recv(estops) -> query => match query {
                    Ok(query) => (ServiceKind::Estop, query),
                    Err(_) => continue,
                },
                recv(releases) -> query => match query {
                    Ok(query) => (ServiceKind::Release, query),
                    Err(_) => continue,
                },
                default(Duration::from_millis(100)) => continue,
            },
        };
        Counters::add(&counters.service_calls);
        let result = match kind {
            ServiceKind::Estop => controller.stop("ROS 2 e-stop service"),
            // This node's own stops only, which only its e-stop service latches: every one of
            // them, whenever latched (a ROS caller names no stop).
            ServiceKind::Release => controller.release(ReleaseTarget::Own, u64::MAX),
        };
        let message = match (&result, kind) {
            (Ok(_), ServiceKind::Estop) => {
                "stopped: the release service or an operator (`scout release`) releases it".into()
            }
            (Ok(_), ServiceKind::Release) => {
                "released: nothing moves until a client takes control".into()
            }
            (Err(error), _) => error.to_string(),
        };
        info!("ros2: {kind:?} service: {message}");
        answer(&query, kind, result.is_ok(), &message);
        if let Err(error @ ControlError::NoAnswer { .. }) = result {
            return Err(error.into());
        }
    }
    Ok(())
}

/// Why a query is no call to serve.
enum NoCall {
    /// Without the rmw_zenoh attachment: not an rmw_zenoh client (an error reply).
    NotRmwZenoh(&'static str),
    /// An rmw_zenoh client's call whose payload is no Trigger request (a Trigger response with
    /// `success` false, which the client does see).
    NotTrigger(String),
}

/// Whether a query is a std_srvs/srv/Trigger request as an rmw_zenoh client sends it: CDR of
/// the request (its one placeholder byte) and the attachment.
fn trigger_request(query: &Query) -> Result<(), NoCall> {
    query
        .attachment()
        .and_then(|attachment| rmw::parse_attachment(&attachment.to_bytes()))
        .ok_or(NoCall::NotRmwZenoh(
            "no rmw_zenoh attachment: call the service through rmw_zenoh",
        ))?;
    let payload = query.payload().map(ZBytes::to_bytes).unwrap_or_default();
    msgs::decode_trigger_request(&payload).map_err(|error| {
        NoCall::NotTrigger(format!(
            "refused: {} bytes are no std_srvs/srv/Trigger request: {error}",
            payload.len()
        ))
    })
}

/// The Trigger response to a call.
fn answer(query: &Query, kind: ServiceKind, success: bool, message: &str) {
    let mut reply = query.reply(
        query.key_expr().clone(),
        msgs::encode_trigger_response(success, message),
    );
    if let Some(attachment) = query.attachment() {
        reply = reply.attachment(reply_attachment(attachment));
    }
    if let Err(error) = reply.wait() {
        warn!("ros2: replying to a {kind:?} call failed: {error}");
    }
}

/// An error reply, with the reason.
fn refuse(query: &Query, why: &str) {
    if let Err(error) = query.reply_err(why.to_owned()).wait() {
        warn!("ros2: refusing a call failed: {error}");
    }
}

/// A reply carries the request's sequence number and client GID with the reply's time.
fn reply_attachment(request: &ZBytes) -> Vec<u8> {
    match rmw::parse_attachment(&request.to_bytes()) {
        Some((seq, _, gid)) => rmw::attachment(seq, unix_now().as_nanos() as i64, &gid).to_vec(),
        None => request.to_bytes().to_vec(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_file(json5: &str) -> Result<zenoh::Config, BridgeError> {
        let path = std::env::temp_dir().join(format!(
            "scout-ros2-zenoh-{}-{}.json5",
            std::process::id(),
            json5.len()
        ));
        std::fs::write(&path, json5).expect("write a zenoh config");
        let config = Ros2Config {
            zenoh_config: Some(path.display().to_string()),
            ..Ros2Config::default()
        };
        let result = session_config(&config);
        std::fs::remove_file(&path).ok();
        result
    }

    fn mode(config: &zenoh::Config) -> String {
        config.get_json("mode").expect("a mode")
    }

    #[test]
    fn the_session_is_a_client_of_the_router_whatever_the_file() {
        let default = session_config(&Ros2Config::default()).expect("the default");
        assert_eq!(mode(&default), "\"client\"");
        let without_mode = with_file("{ connect: { endpoints: [\"tcp/127.0.0.1:7447\"] } }")
            .expect("a file without a mode");
        assert_eq!(mode(&without_mode), "\"client\"");
        with_file("{ mode: \"client\" }").expect("a client file");
        let peer = with_file("{ mode: \"peer\" }").expect_err("a peer file is refused");
        assert!(
            matches!(&peer, BridgeError::NotClient { mode, .. } if mode == "peer"),
            "{peer}"
        );
        assert!(
            peer.to_string().contains("does not forward between peers"),
            "{peer}"
        );
    }
}
