//! `scout ros2`: the driver that makes a gateway's chassis a ROS 2 node, whatever the middleware.
//! An ordinary local client of the gateway (state and status subscribers, controllers): it
//! publishes what [`Messages`] makes, feeds cmd_vel through [`CmdVelStream`] into the arbiter,
//! and serves the e-stop and release services. The middleware ([`crate::zenoh_node`] or
//! [`crate::dds_node`]) only carries bytes: it publishes through [`Publishers`] and fills the
//! [`Inboxes`]' queues, so both obey the same rules by construction.
//!
//! Three threads, each blocked on its own input, so that no one waits for another: the state
//! (woken by the gateway's state event), the cmd_vel messages (a bounded queue the middleware
//! fills) and the services (two more queues, the e-stop's served first, with a stop port of
//! their own).

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use scout_interface::services::{monotonic, monotonic_ns};
use serde::Serialize;
use tracing::{info, warn};

use crate::cdr::CdrError;
use crate::config::{Middleware, Ros2Config};
use crate::msgs::{Command, NoTwist};
use crate::publish::{Clocks, Messages, Topic};
use crate::stream::{Action, CmdVelStream, Ignored, Origin, Outcome};
use scout_clients::client::{ClientError, Robot};
use scout_clients::control::ControlError;
use scout_clients::failure::{Failure, FailureKind};
use scout_interface::control::ReleaseTarget;
use scout_interface::robot::RobotName;
use scout_protocol::model::Model;

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
    /// The DDS participant or one of its endpoints could not be made.
    #[error("DDS: {0}")]
    Dds(String),
    /// The middleware stopped delivering (its receive thread failed).
    #[error("the middleware stopped delivering messages and calls: {0}")]
    Middleware(String),
    /// A thread of the bridge could not start.
    #[error("starting a thread")]
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

/// A setting that cannot work is a usage error.
impl FailureKind for BridgeError {
    fn kind(&self) -> Failure {
        match self {
            Self::Client(error) => error.kind(),
            Self::Control(error) => error.kind(),
            Self::NotClient { .. } | Self::AlreadyRunning { .. } => Failure::Usage,
            Self::Zenoh(_) | Self::Dds(_) | Self::Middleware(_) | Self::Thread(_) => {
                Failure::Failed
            }
        }
    }
}

/// What the bridge counted, shown in its diagnostics and logged when it stops.
#[derive(Debug, Default, Serialize)]
pub struct Counters {
    pub published: AtomicU64,
    /// Messages the middleware failed to send.
    pub publish_failed: AtomicU64,
    pub cmd_vel_received: AtomicU64,
    pub cmd_vel_accepted: AtomicU64,
    pub cmd_vel_rejected: AtomicU64,
    /// Not CDR of the topic's type.
    pub cmd_vel_malformed: AtomicU64,
    /// Without the publisher's identity (over zenoh: no rmw_zenoh attachment, not from a ROS
    /// publisher; ROS subscribers drop these too).
    pub cmd_vel_without_attachment: AtomicU64,
    /// Ignored: the stream went on across a loss of control.
    pub cmd_vel_mid_stream: AtomicU64,
    /// Dropped: the command thread was [`QUEUE`] messages behind.
    pub cmd_vel_dropped: AtomicU64,
    pub service_calls: AtomicU64,
    /// Answered `busy` without being served: the service's queue was [`QUEUE`] calls behind.
    pub service_calls_dropped: AtomicU64,
    /// Refused with the reason: a wildcard query, no rmw_zenoh attachment, or no Trigger
    /// request.
    pub service_calls_malformed: AtomicU64,
}

impl Counters {
    pub fn add(counter: &AtomicU64) -> u64 {
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
pub const QUEUE: usize = 64;

/// One cmd_vel message as the middleware delivered it.
#[derive(Debug, Clone, PartialEq)]
pub struct CmdVel {
    /// Which of [`Ros2Config::cmd_vel`].
    pub topic: usize,
    /// Its publisher, sequence number and source time; `None` when the middleware could not
    /// tell (over zenoh: no rmw_zenoh attachment).
    pub origin: Option<Origin>,
    /// What it asks, or why the payload is no message of the topic's type.
    pub command: Result<Command, CdrError>,
}

/// The two services.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServiceKind {
    Estop,
    Release,
}

impl ServiceKind {
    pub fn name(self, config: &Ros2Config) -> &str {
        match self {
            ServiceKind::Estop => &config.topics.estop,
            ServiceKind::Release => &config.topics.release,
        }
    }

    /// The services this configuration serves.
    pub fn served(config: &Ros2Config) -> &'static [ServiceKind] {
        match (config.services, config.release_service) {
            (false, _) => &[],
            (true, false) => &[ServiceKind::Estop],
            (true, true) => &[ServiceKind::Estop, ServiceKind::Release],
        }
    }

    /// The answer to a call that the queue had no room for.
    pub fn busy(self) -> &'static str {
        match self {
            ServiceKind::Estop => "busy: the e-stop calls already waiting latch the stop",
            ServiceKind::Release => "busy: too many calls waiting, call again",
        }
    }
}

/// Sends a call's Trigger response: whether it worked, and what happened.
pub type Reply = Box<dyn FnOnce(bool, &str) + Send>;

/// A service call waiting to be served: the middleware's way to send its Trigger response.
pub struct Call {
    pub reply: Reply,
}

/// Where the middleware puts what arrives; each queue is bounded, and what does not fit is
/// counted (`cmd_vel_dropped`) or answered busy (`service_calls_dropped`).
#[derive(Clone)]
pub struct Senders {
    twists: SyncSender<CmdVel>,
    estops: crossbeam_channel::Sender<Call>,
    releases: crossbeam_channel::Sender<Call>,
    pub counters: Arc<Counters>,
    /// Why the middleware can no longer deliver, once it cannot: the bridge stops on it.
    failure: Arc<std::sync::Mutex<Option<String>>>,
}

impl Senders {
    /// Queues a cmd_vel message (never blocks: a full queue drops it, counted).
    pub fn twist(&self, message: CmdVel) {
        if let Err(TrySendError::Full(_)) = self.twists.try_send(message) {
            Counters::add(&self.counters.cmd_vel_dropped);
        }
    }

    /// The middleware can no longer deliver what arrives (its receive thread failed): the
    /// bridge stops with this reason rather than run on deaf to cmd_vel and the e-stop service.
    pub fn fail(&self, why: String) {
        if let Ok(mut failure) = self.failure.lock() {
            failure.get_or_insert(why);
        }
    }

    /// Queues a service call (never blocks: a full queue answers it busy, counted).
    pub fn call(&self, kind: ServiceKind, call: Call) {
        let queue = match kind {
            ServiceKind::Estop => &self.estops,
            ServiceKind::Release => &self.releases,
        };
        if let Err(crossbeam_channel::TrySendError::Full(call)) = queue.try_send(call) {
            Counters::add(&self.counters.service_calls_dropped);
            (call.reply)(false, kind.busy());
        }
    }
}

impl std::fmt::Debug for Call {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Call").finish_non_exhaustive()
    }
}

impl std::fmt::Debug for Senders {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Senders").finish_non_exhaustive()
    }
}

impl std::fmt::Debug for Inboxes {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Inboxes").finish_non_exhaustive()
    }
}

/// The bridge's side of the queues.
pub struct Inboxes {
    twists: Receiver<CmdVel>,
    estops: crossbeam_channel::Receiver<Call>,
    releases: crossbeam_channel::Receiver<Call>,
}

/// The queues between a middleware and the bridge.
pub fn queues(counters: Arc<Counters>) -> (Senders, Inboxes) {
    let (twists, twist_inbox) = sync_channel(QUEUE);
    let (estops, estop_inbox) = crossbeam_channel::bounded(QUEUE);
    let (releases, release_inbox) = crossbeam_channel::bounded(QUEUE);
    (
        Senders {
            twists,
            estops,
            releases,
            counters,
            failure: Arc::default(),
        },
        Inboxes {
            twists: twist_inbox,
            estops: estop_inbox,
            releases: release_inbox,
        },
    )
}

/// The node's publishers, whatever the middleware: the CDR payload of a message (with its
/// encapsulation header) goes out on its topic.
pub trait Publishers {
    /// Publishes `payload` on `topic` (a topic not published is ignored).
    fn publish(&mut self, topic: Topic, payload: Vec<u8>) -> Result<(), BridgeError>;
}

/// The wall clock, for ROS stamps and source times.
pub fn unix_now() -> Duration {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .unwrap_or_default()
}

/// Runs the bridge for robot `robot` on `middleware` until `stop` is set or something fails.
pub fn run(
    robot: &RobotName,
    config: &Ros2Config,
    middleware: Middleware,
    stop: &AtomicBool,
) -> Result<(), BridgeError> {
    let _claim =
        scout_interface::stop_socket::claim(&robot.ros2_claim(config.domain)).map_err(|errno| {
            match errno {
                nix::errno::Errno::EADDRINUSE => BridgeError::AlreadyRunning {
                    robot: robot.to_string(),
                    domain: config.domain,
                },
                other => BridgeError::Thread(other.into()),
            }
        })?;
    let gateway = Robot::connect(robot)?;
    let counters = Arc::new(Counters::default());
    let (senders, inboxes) = queues(Arc::clone(&counters));
    let failure = Arc::clone(&senders.failure);
    let middleware_failed = || failure.lock().map_or(true, |failure| failure.is_some());
    // The middleware's node lives as long as the bridge runs: dropping it leaves the graph.
    let (mut publishers, node): (Box<dyn Publishers>, Box<dyn std::any::Any>) = match middleware {
        Middleware::Zenoh => {
            let (publishers, node) = crate::zenoh_node::start(config, senders)?;
            (Box::new(publishers), Box::new(node))
        }
        Middleware::Dds => {
            let (publishers, node) = crate::dds_node::start(config, senders)?;
            (Box::new(publishers), Box::new(node))
        }
    };
    info!(
        "scout ros2: node {}/{} in domain {} over {}; publishing {:?}; driving from {}",
        config.namespace,
        config.node,
        config.domain,
        middleware.name(),
        config.published(),
        config
            .cmd_vel
            .iter()
            .map(|c| format!("{} as {}", config.resolve(&c.topic), c.class))
            .collect::<Vec<_>>()
            .join(", "),
    );
    let failed = AtomicBool::new(false);
    let halt =
        || stop.load(Ordering::Relaxed) || failed.load(Ordering::Relaxed) || middleware_failed();
    let give_up = |result: Result<(), BridgeError>| {
        if result.is_err() {
            failed.store(true, Ordering::Relaxed);
        }
        result
    };
    let Inboxes {
        twists,
        estops,
        releases,
    } = inboxes;
    let result = std::thread::scope(|scope| {
        let (gateway, counters, halt, give_up) = (&gateway, &*counters, &halt, &give_up);
        let commands = std::thread::Builder::new()
            .name("ros2-cmd-vel".into())
            .spawn_scoped(scope, move || {
                give_up(drive(gateway, config, &twists, counters, halt))
            })?;
        let services = std::thread::Builder::new()
            .name("ros2-services".into())
            .spawn_scoped(scope, move || {
                give_up(serve(gateway, config, [&estops, &releases], counters, halt))
            })?;
        let published = give_up(publish(gateway, config, &mut *publishers, counters, halt));
        let driven = commands.join().unwrap_or_else(|_| {
            Err(BridgeError::Thread(std::io::Error::other(
                "the cmd_vel thread panicked",
            )))
        });
        let served = services.join().unwrap_or_else(|_| {
            Err(BridgeError::Thread(std::io::Error::other(
                "the service thread panicked",
            )))
        });
        published.and(driven).and(served)
    });
    let result = match failure.lock().ok().and_then(|failure| failure.clone()) {
        Some(why) => result.and(Err(BridgeError::Middleware(why))),
        None => result,
    };
    info!(
        "scout ros2: stopping; counters {}",
        serde_json::to_string(&*counters).unwrap_or_default()
    );
    drop(publishers);
    drop(node);
    result
}

/// The state thread: each new state becomes the messages [`Messages`] makes of it.
fn publish(
    gateway: &Robot,
    config: &Ros2Config,
    publishers: &mut dyn Publishers,
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
            let topic = outgoing.topic;
            match publishers.publish(topic, outgoing.payload) {
                Ok(()) => {
                    Counters::add(&counters.published);
                }
                Err(error) => {
                    let count = Counters::add(&counters.publish_failed);
                    if count.is_power_of_two() {
                        warn!("ros2: publishing {topic:?} failed ({count} so far): {error}");
                    }
                }
            }
        }
    }
    Ok(())
}

/// The cmd_vel thread: each message through its topic's [`CmdVelStream`] to the arbiter.
fn drive(
    gateway: &Robot,
    config: &Ros2Config,
    inbox: &Receiver<CmdVel>,
    counters: &Counters,
    halt: &dyn Fn() -> bool,
) -> Result<(), BridgeError> {
    // The chassis' model, for its wheelbase (an Ackermann drive's steering angle made a yaw
    // rate): the newest state's, read when one arrives, where a topic carries Ackermann drives.
    let states = match config.cmd_vel.iter().any(|topic| topic.ackermann) {
        true => Some(gateway.subscribe()?),
        false => None,
    };
    let mut model = None;
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
        let Ok(message) = inbox.recv_timeout(Duration::from_millis(100)) else {
            continue;
        };
        let Some((controller, stream, name)) = drivers.get_mut(message.topic) else {
            continue;
        };
        Counters::add(&counters.cmd_vel_received);
        let Some(origin) = message.origin else {
            let count = Counters::add(&counters.cmd_vel_without_attachment);
            if count.is_power_of_two() {
                warn!(
                    "ros2: {name}: a message without its publisher's identity ({count} so far): \
                     dropped, as ROS subscribers drop it; publish through rmw_zenoh"
                );
            }
            continue;
        };
        let twist = match message.command {
            Ok(Command::Twist(twist)) => twist,
            Ok(Command::Ackermann(drive)) => {
                match states.as_ref().map(|states| states.try_latest()) {
                    Some(Ok(Some(state))) => model = state.chassis.model().or(model),
                    Some(Err(error)) => warn!("ros2: {name}: reading the gateway's state: {error}"),
                    Some(Ok(None)) | None => {}
                }
                match drive.twist_for(model) {
                    Ok(twist) => twist,
                    Err(refused) => {
                        let (counter, why) = match refused {
                            NoTwist::NotAWheelAngle => (
                                &counters.cmd_vel_malformed,
                                format!(
                                    "a steering angle of {} rad is not one a wheel takes \
                                     (radians, within a quarter turn)",
                                    drive.steering_angle
                                ),
                            ),
                            NoTwist::NotSteered => (
                                &counters.cmd_vel_rejected,
                                format!(
                                    "an AckermannDriveStamped steers a chassis by its front \
                                     wheels (a hunter2 or a hunter-se); this {} does not: \
                                     publish a Twist on a cmd_vel topic",
                                    model.map_or("chassis of unknown model", Model::name)
                                ),
                            ),
                        };
                        let count = Counters::add(counter);
                        if count.is_power_of_two() {
                            warn!("ros2: {name}: {why} ({count} so far)");
                        }
                        continue;
                    }
                }
            }
            Err(error) => {
                let count = Counters::add(&counters.cmd_vel_malformed);
                if count.is_power_of_two() {
                    warn!("ros2: {name}: not a valid message ({count} so far): {error}");
                }
                continue;
            }
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
                // linear.y too: a chassis that does not move sideways refuses it, saying so.
                Action::Drive => {
                    controller.drive_body(twist.linear, twist.lateral, twist.angular, None)
                }
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

/// The service thread: an e-stop latches a stop owned by [`Ros2Config::service_client`]; a
/// release releases that client's own stops (others' need an operator) and restarts nothing.
/// E-stop calls are served before release calls.
fn serve(
    gateway: &Robot,
    config: &Ros2Config,
    [estops, releases]: [&crossbeam_channel::Receiver<Call>; 2],
    counters: &Counters,
    halt: &dyn Fn() -> bool,
) -> Result<(), BridgeError> {
    let mut controller = gateway.controller(&config.service_client(), None)?;
    while !halt() {
        let (kind, call) = match estops.try_recv() {
            Ok(call) => (ServiceKind::Estop, call),
            Err(_) => crossbeam_channel::select! {
                recv(estops) -> call => match call {
                    Ok(call) => (ServiceKind::Estop, call),
                    Err(_) => continue,
                },
                recv(releases) -> call => match call {
                    Ok(call) => (ServiceKind::Release, call),
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
        (call.reply)(result.is_ok(), &message);
        if let Err(error @ ControlError::NoAnswer { .. }) = result {
            return Err(error.into());
        }
    }
    Ok(())
}
