//! The bridge's node on DDS, as ROS 2's default middlewares (Fast DDS, Cyclone DDS) speak it, on
//! RustDDS: a participant with the topics, services and QoS ROS users expect, made a ROS node by
//! its `ros_discovery_info` ([`crate::ros_discovery`]; its GIDs 24 bytes long for Humble, 16 from
//! Iron on, a setting read at start), so `ros2 node list` shows it. One thread waits on the
//! cmd_vel readers and the service requests and hands what arrives to the bridge's queues
//! ([`Senders`]); the writer's GUID, sequence number and source timestamp play the part of
//! rmw_zenoh's attachment. Names, types, QoS and the services' request identity are as
//! `ros2-client` 0.12 wrote them, which Fast DDS and Cyclone DDS graphs were tested against.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration as StdDuration;

use rustdds::mio1::{Events, Interest, Poll, Token};
use rustdds::no_key::{DataWriterCdr, SimpleDataReaderCdr};
use rustdds::{
    DomainParticipant, DomainParticipantBuilder, Duration, GUID, QosPolicies, QosPolicyBuilder,
    RTPSEntity, SampleIdentity, SequenceNumber, Timestamp, TopicKind, WriteOptionsBuilder, policy,
};
use serde::Serialize;
use tracing::{info, warn};

use crate::bridge::{BridgeError, Call, CmdVel, Counters, Publishers, Senders, ServiceKind};
use crate::cdr::{CdrError, ENCAPSULATION};
use crate::config::Ros2Config;
use crate::dds_wire::{
    AckermannDriveStamped, TriggerCall, TriggerReply, TriggerResponse, Twist, TwistStamped, Whole,
};
use crate::msgs::{AckermannDrive, Command, MessageType, PlanarTwist};
use crate::publish::Topic;
use crate::rmw::Distro;
use crate::ros_discovery::{self, NodeEntities};
use crate::stream::Origin;

fn dds_error(what: &str) -> impl Fn(rustdds::dds::CreateError) -> BridgeError + '_ {
    move |error| BridgeError::Dds(format!("{what}: {error:?}"))
}

/// A message already in CDR (the bytes after the encapsulation header), written as it is: a
/// tuple of bytes is serialized without length or padding, so the payload on the wire is
/// exactly the bytes [`crate::msgs`] made (and the system tests compare against rosbags).
#[derive(Debug, Clone)]
pub struct EncodedCdr(Vec<u8>);

impl Serialize for EncodedCdr {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut tuple = serializer.serialize_tuple(self.0.len())?;
        for byte in &self.0 {
            tuple.serialize_element(byte)?;
        }
        tuple.end()
    }
}

/// A DDS type name: `nav_msgs/msg/Odometry` is `nav_msgs::msg::dds_::Odometry_`.
fn type_name(message: &MessageType) -> String {
    dds_type(message.name, "")
}

/// `package/kind/Name` with `suffix` as DDS names it: `package::kind::dds_::Name{suffix}_`.
fn dds_type(name: &str, suffix: &str) -> String {
    let mut parts = name.split('/');
    let (package, kind, name) = (
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or_default(),
    );
    format!("{package}::{kind}::dds_::{name}{suffix}_")
}

/// The QoS of ROS 2's profiles as DDS policies: `reliability`, volatile, keep last `depth`,
/// and no deadline, lifespan or liveliness lease.
fn qos(reliability: policy::Reliability, depth: i32) -> QosPolicies {
    QosPolicyBuilder::new()
        .durability(policy::Durability::Volatile)
        .reliability(reliability)
        .history(policy::History::KeepLast { depth })
        .liveliness(policy::Liveliness::Automatic {
            lease_duration: Duration::INFINITE,
        })
        .deadline(policy::Deadline(Duration::INFINITE))
        .lifespan(policy::Lifespan {
            duration: Duration::INFINITE,
        })
        .build()
}

/// The QoS a ROS publisher of `topic` offers: reliable and volatile, which reliable and
/// best-effort (sensor data) subscribers both accept; `/tf` keeps 100 as tf2's broadcaster does.
/// A write that cannot be queued at once fails (counted as `publish_failed`) instead of holding
/// the state thread: the next state, 20 ms later, is worth more than a late one.
fn publisher_qos(topic: Topic) -> QosPolicies {
    let depth = match topic {
        Topic::Tf => 100,
        Topic::Odom | Topic::BatteryState | Topic::JointStates | Topic::Diagnostics => 10,
    };
    qos(
        policy::Reliability::Reliable {
            max_blocking_time: Duration::ZERO,
        },
        depth,
    )
}

/// cmd_vel is read best effort: it matches reliable and best-effort publishers alike, and a
/// lost command is better than a late one.
fn cmd_vel_qos() -> QosPolicies {
    qos(policy::Reliability::BestEffort, 10)
}

/// Services: ROS 2's default service QoS (reliable, volatile, keep last 10; a reply waits up to
/// 100 ms for room).
fn service_qos() -> QosPolicies {
    qos(
        policy::Reliability::Reliable {
            max_blocking_time: Duration::from_millis(100),
        },
        10,
    )
}

/// `ros_discovery_info`'s QoS, as rmw_dds_common's: late joiners get the last sample.
fn discovery_qos() -> QosPolicies {
    QosPolicyBuilder::new()
        .durability(policy::Durability::TransientLocal)
        .deadline(policy::Deadline(Duration::INFINITE))
        .ownership(policy::Ownership::Shared)
        .reliable(Duration::ZERO)
        .history(policy::History::KeepLast { depth: 1 })
        .lifespan(policy::Lifespan {
            duration: Duration::INFINITE,
        })
        .build()
}

/// Consecutive failed writes on one topic after which its writer is made anew.
///
/// RustDDS (0.15.1) holds a reliable writer's send window at 8192 samples and counts a newly
/// matched reliable reader as having acknowledged nothing, so once a writer has sent more than
/// 8192 samples (164 s at 50 Hz) every write fails until the new reader's first ACKNACK: a
/// sample or none for a healthy reader, but for a reader that never acknowledges (a stopped
/// process, its ACKNACKs lost on the way) the topic stays dead for every subscriber, until its
/// participant's lease ends or for good. A new writer starts its count at zero. 25 writes are
/// half a second of /odom.
pub const RECREATE_AFTER: u32 = 25;

/// A run of failed writes on one topic.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FailureStreak {
    failed: u32,
}

impl FailureStreak {
    /// Records a write; `true` when the writer should be made anew (the streak starts over).
    pub fn record(&mut self, succeeded: bool) -> bool {
        if succeeded {
            self.failed = 0;
            return false;
        }
        self.failed += 1;
        if self.failed >= RECREATE_AFTER {
            self.failed = 0;
            return true;
        }
        false
    }
}

/// The node as the graph knows it: its entry in `ros_discovery_info`, written at start, when a
/// writer is made anew, and empty when the node goes.
struct Graph {
    writer: DataWriterCdr<EncodedCdr>,
    participant: ros_discovery::Guid,
    node: NodeEntities,
    distro: Distro,
}

impl Graph {
    fn announce(&self, nodes: &[NodeEntities]) {
        let sample = ros_discovery::encode(self.participant, nodes, self.distro);
        let body = sample[ENCAPSULATION.len()..].to_vec();
        if let Err(error) = self.writer.write(EncodedCdr(body), Some(Timestamp::now())) {
            warn!("ros2: writing ros_discovery_info: {}", describe(&error));
        }
    }
}

impl Drop for Graph {
    fn drop(&mut self) {
        self.announce(&[]);
    }
}

/// One topic's writer.
struct Writer {
    topic: Topic,
    dds_topic: rustdds::Topic,
    writer: DataWriterCdr<EncodedCdr>,
    streak: FailureStreak,
}

/// The node's publishers on DDS, which make a writer anew when one is stuck, and its entry in
/// the graph.
pub struct DdsPublishers {
    publisher: rustdds::Publisher,
    writers: Vec<Writer>,
    graph: Graph,
    /// Keeps the participant while writers may still be made.
    _participant: DomainParticipant,
}

/// What a failed write says, without its payload.
fn describe<D>(error: &rustdds::dds::WriteError<D>) -> String {
    match error {
        rustdds::dds::WriteError::WouldBlock { .. } => {
            "the reliable send window is full (a subscriber has not acknowledged)".into()
        }
        rustdds::dds::WriteError::Serialization { reason, .. } => {
            format!("serializing: {reason}")
        }
        rustdds::dds::WriteError::Poisoned { reason, .. } => format!("RustDDS: {reason}"),
        rustdds::dds::WriteError::Io(error) => format!("I/O: {error}"),
        rustdds::dds::WriteError::Internal { reason } => format!("RustDDS: {reason}"),
    }
}

impl Publishers for DdsPublishers {
    fn publish(&mut self, topic: Topic, payload: Vec<u8>) -> Result<(), BridgeError> {
        let Some(writer) = self.writers.iter_mut().find(|w| w.topic == topic) else {
            return Ok(());
        };
        let body = payload.strip_prefix(&ENCAPSULATION[..]).ok_or_else(|| {
            BridgeError::Dds("a payload without the CDR little-endian header".into())
        })?;
        let result = writer
            .writer
            .write(EncodedCdr(body.to_vec()), Some(Timestamp::now()));
        if writer.streak.record(result.is_ok()) {
            match self
                .publisher
                .create_datawriter_no_key(&writer.dds_topic, None)
            {
                Ok(made) => {
                    warn!(
                        "ros2: {RECREATE_AFTER} writes of {topic:?} failed in a row: its writer \
                         is made anew (a subscriber that never acknowledges held it)"
                    );
                    let old = std::mem::replace(&mut writer.writer, made);
                    self.graph
                        .node
                        .replace_writer(old.guid().to_bytes(), writer.writer.guid().to_bytes());
                    drop(old);
                    self.graph.announce(std::slice::from_ref(&self.graph.node));
                }
                Err(error) => warn!("ros2: making a new writer of {topic:?}: {error:?}"),
            }
        }
        result.map_err(|error| BridgeError::Dds(describe(&error)))
    }
}

/// What keeps the node's readers served: its receive thread (stopped and joined on drop).
pub struct DdsNode {
    halt: Arc<AtomicBool>,
    receiver: Option<JoinHandle<()>>,
}

impl Drop for DdsNode {
    fn drop(&mut self) {
        self.halt.store(true, Ordering::Relaxed);
        if let Some(receiver) = self.receiver.take() {
            receiver.join().ok();
        }
    }
}

impl std::fmt::Debug for DdsPublishers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DdsPublishers").finish_non_exhaustive()
    }
}

impl std::fmt::Debug for DdsNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DdsNode").finish_non_exhaustive()
    }
}

/// A cmd_vel reader of its topic's type.
enum CmdVelReader {
    Twist(SimpleDataReaderCdr<Whole<Twist>>),
    Stamped(SimpleDataReaderCdr<Whole<TwistStamped>>),
    Ackermann(SimpleDataReaderCdr<Whole<AckermannDriveStamped>>),
}

impl CmdVelReader {
    fn guid(&self) -> GUID {
        match self {
            Self::Twist(reader) => reader.guid(),
            Self::Stamped(reader) => reader.guid(),
            Self::Ackermann(reader) => reader.guid(),
        }
    }
}

/// A Trigger service: its request reader and its reply writer (the Enhanced mapping's endpoints;
/// rmw_cyclonedds' calls come on the same, see [`TriggerCall`]).
struct TriggerService {
    kind: ServiceKind,
    requests: SimpleDataReaderCdr<TriggerCall>,
    replies: Arc<DataWriterCdr<TriggerReply>>,
}

/// The DDS name of the absolute ROS name `name` with `prefix` and `suffix`: `rt/odom`,
/// `rq/scout/estopRequest`.
fn dds_name(prefix: &str, name: &str, suffix: &str) -> String {
    format!("{prefix}{name}{suffix}")
}

/// Makes the participant and the node with its publishers, cmd_vel readers and services.
pub fn start(
    config: &Ros2Config,
    senders: Senders,
) -> Result<(DdsPublishers, DdsNode), BridgeError> {
    let domain = u16::try_from(config.domain)
        .map_err(|_| BridgeError::Dds(format!("ROS domain {} is out of range", config.domain)))?;
    let distro = config.distro();
    info!(
        "ros2: DDS domain {domain}, ros_discovery_info with {}-byte GIDs ({})",
        ros_discovery::gid_length(distro),
        match distro {
            Distro::Humble => "Humble",
            Distro::Jazzy => "Iron and later: Jazzy, Kilted",
        }
    );
    let participant = DomainParticipantBuilder::new(domain)
        .build()
        .map_err(dds_error("making the DDS participant"))?;
    let publisher = participant
        .create_publisher(&qos(
            policy::Reliability::Reliable {
                max_blocking_time: Duration::from_millis(100),
            },
            1,
        ))
        .map_err(dds_error("making the DDS publisher"))?;
    let subscriber = participant
        .create_subscriber(&qos(policy::Reliability::BestEffort, 1))
        .map_err(dds_error("making the DDS subscriber"))?;
    let discovery_writer = discovery_writer(&participant, &publisher)?;
    let writers = make_writers(config, &participant, &publisher)?;
    let mut readers = make_cmd_vel_readers(config, &participant, &subscriber)?;
    let mut services = make_services(config, &participant, &publisher, &subscriber)?;
    let graph = Graph {
        node: node_entities(config, &readers, &writers, &services, &discovery_writer),
        writer: discovery_writer,
        participant: participant.guid().to_bytes(),
        distro,
    };
    graph.announce(std::slice::from_ref(&graph.node));

    let poll = register(&mut readers, &mut services).map_err(BridgeError::Thread)?;
    let halt = Arc::new(AtomicBool::new(false));
    let receiver = {
        let halt = Arc::clone(&halt);
        let participant = participant.clone();
        std::thread::Builder::new()
            .name("ros2-dds".into())
            .spawn(move || {
                if let Err(error) = receive(poll, &readers, &services, &senders, &halt) {
                    senders.fail(format!("waiting for DDS input: {error}"));
                }
                // The readers and the services' endpoints go before the participant (this may
                // be its last handle): dropped after it, each would log an ERROR that it
                // cannot be removed from a participant already gone.
                drop(services);
                drop(readers);
                drop(participant);
            })?
    };
    Ok((
        DdsPublishers {
            publisher,
            writers,
            graph,
            _participant: participant,
        },
        DdsNode {
            halt,
            receiver: Some(receiver),
        },
    ))
}

/// The writer of the node's entry in `ros_discovery_info`.
fn discovery_writer(
    participant: &DomainParticipant,
    publisher: &rustdds::Publisher,
) -> Result<DataWriterCdr<EncodedCdr>, BridgeError> {
    let topic = participant
        .create_topic(
            ros_discovery::TOPIC.into(),
            ros_discovery::TYPE.into(),
            &discovery_qos(),
            TopicKind::NoKey,
        )
        .map_err(dds_error("making ros_discovery_info"))?;
    publisher
        .create_datawriter_no_key(&topic, None)
        .map_err(dds_error("writing ros_discovery_info"))
}

/// A writer for each topic the settings publish.
fn make_writers(
    config: &Ros2Config,
    participant: &DomainParticipant,
    publisher: &rustdds::Publisher,
) -> Result<Vec<Writer>, BridgeError> {
    let mut writers = Vec::new();
    for topic in Topic::ALL {
        let Some(name) = topic.name(config) else {
            continue;
        };
        let dds_topic = participant
            .create_topic(
                dds_name("rt", &config.resolve(name), ""),
                type_name(&topic.message()),
                &publisher_qos(topic),
                TopicKind::NoKey,
            )
            .map_err(dds_error("making a topic"))?;
        let writer = publisher
            .create_datawriter_no_key(&dds_topic, None)
            .map_err(dds_error("making a publisher"))?;
        writers.push(Writer {
            topic,
            dds_topic,
            writer,
            streak: FailureStreak::default(),
        });
    }
    Ok(writers)
}

/// A reader for each cmd_vel stream of the settings, of its message type.
fn make_cmd_vel_readers(
    config: &Ros2Config,
    participant: &DomainParticipant,
    subscriber: &rustdds::Subscriber,
) -> Result<Vec<CmdVelReader>, BridgeError> {
    let mut readers = Vec::new();
    for cmd_vel in &config.cmd_vel {
        let message = cmd_vel.message();
        let dds_topic = participant
            .create_topic(
                dds_name("rt", &config.resolve(&cmd_vel.topic), ""),
                type_name(&message),
                &cmd_vel_qos(),
                TopicKind::NoKey,
            )
            .map_err(dds_error("making the cmd_vel topic"))?;
        readers.push(if cmd_vel.ackermann {
            CmdVelReader::Ackermann(
                subscriber
                    .create_simple_datareader_no_key(&dds_topic, None)
                    .map_err(dds_error("subscribing to cmd_vel"))?,
            )
        } else if cmd_vel.stamped {
            CmdVelReader::Stamped(
                subscriber
                    .create_simple_datareader_no_key(&dds_topic, None)
                    .map_err(dds_error("subscribing to cmd_vel"))?,
            )
        } else {
            CmdVelReader::Twist(
                subscriber
                    .create_simple_datareader_no_key(&dds_topic, None)
                    .map_err(dds_error("subscribing to cmd_vel"))?,
            )
        });
    }
    Ok(readers)
}

/// The request reader and reply writer of each Trigger service the settings serve.
fn make_services(
    config: &Ros2Config,
    participant: &DomainParticipant,
    publisher: &rustdds::Publisher,
    subscriber: &rustdds::Subscriber,
) -> Result<Vec<TriggerService>, BridgeError> {
    let mut services = Vec::new();
    for &kind in ServiceKind::served(config) {
        let name = config.resolve(kind.name(config));
        let topic = |prefix: &str, suffix: &str, kind: &str| {
            participant
                .create_topic(
                    dds_name(prefix, &name, suffix),
                    dds_type("std_srvs/srv/Trigger", kind),
                    &service_qos(),
                    TopicKind::NoKey,
                )
                .map_err(dds_error("making a service's topic"))
        };
        let (request_topic, reply_topic) = (
            topic("rq", "Request", "_Request")?,
            topic("rr", "Reply", "_Response")?,
        );
        let requests = subscriber
            .create_simple_datareader_no_key(&request_topic, Some(service_qos()))
            .map_err(dds_error("reading a service's requests"))?;
        let replies = publisher
            .create_datawriter_no_key(&reply_topic, Some(service_qos()))
            .map_err(dds_error("writing a service's replies"))?;
        services.push(TriggerService {
            kind,
            requests,
            replies: Arc::new(replies),
        });
    }
    Ok(services)
}

/// The node as `ros_discovery_info` lists it: its readers and writers, the discovery writer
/// last (as ros2-client and rmw list it).
fn node_entities(
    config: &Ros2Config,
    readers: &[CmdVelReader],
    writers: &[Writer],
    services: &[TriggerService],
    discovery_writer: &DataWriterCdr<EncodedCdr>,
) -> NodeEntities {
    let namespace = if config.namespace.is_empty() {
        "/".to_owned()
    } else {
        config.namespace.clone()
    };
    let mut node = NodeEntities {
        namespace,
        name: config.node.clone(),
        readers: readers.iter().map(|r| r.guid().to_bytes()).collect(),
        writers: writers.iter().map(|w| w.writer.guid().to_bytes()).collect(),
    };
    for service in services {
        node.readers.push(service.requests.guid().to_bytes());
        node.writers.push(service.replies.guid().to_bytes());
    }
    node.writers.push(discovery_writer.guid().to_bytes());
    node
}

/// A poll that wakes when a cmd_vel reader or a service has input: reader `i` is token `i`, the
/// services follow.
fn register(
    readers: &mut [CmdVelReader],
    services: &mut [TriggerService],
) -> std::io::Result<Poll> {
    let poll = Poll::new()?;
    for (index, reader) in readers.iter_mut().enumerate() {
        let token = Token(index);
        match reader {
            CmdVelReader::Twist(reader) => {
                poll.registry()
                    .register(reader, token, Interest::READABLE)?;
            }
            CmdVelReader::Stamped(reader) => {
                poll.registry()
                    .register(reader, token, Interest::READABLE)?;
            }
            CmdVelReader::Ackermann(reader) => {
                poll.registry()
                    .register(reader, token, Interest::READABLE)?;
            }
        }
    }
    for (index, service) in services.iter_mut().enumerate() {
        poll.registry().register(
            &mut service.requests,
            Token(readers.len() + index),
            Interest::READABLE,
        )?;
    }
    Ok(poll)
}

/// How often the receive thread looks whether the bridge stops.
const HALT_POLL: StdDuration = StdDuration::from_millis(100);

/// Waits on the readers and services, and queues what arrives.
fn receive(
    mut poll: Poll,
    readers: &[CmdVelReader],
    services: &[TriggerService],
    senders: &Senders,
    halt: &AtomicBool,
) -> std::io::Result<()> {
    let mut events = Events::with_capacity(16);
    while !halt.load(Ordering::Relaxed) {
        if let Err(error) = poll.poll(&mut events, Some(HALT_POLL)) {
            if error.kind() == std::io::ErrorKind::Interrupted {
                continue;
            }
            return Err(error);
        }
        // Edge-triggered: everything that arrived is taken, whichever woke the poll (the
        // e-stop service first).
        for service in services {
            take_calls(service, senders);
        }
        for (index, reader) in readers.iter().enumerate() {
            take_twists(index, reader, senders);
        }
    }
    Ok(())
}

/// A DDS timestamp as ROS time, ns (`None` for the invalid and infinite ones).
fn nanos(timestamp: Timestamp) -> Option<i64> {
    if timestamp == Timestamp::INVALID || timestamp == Timestamp::INFINITE {
        return None;
    }
    let ticks = timestamp.to_ticks();
    let seconds = (ticks >> 32) as i64;
    let fraction = (((ticks & 0xFFFF_FFFF) as i64) * 1_000_000_000) >> 32;
    Some(seconds * 1_000_000_000 + fraction)
}

/// Where a sample came from: its writer, its sequence number and its source time.
fn origin<D>(sample: &rustdds::no_key::DeserializedCacheChange<D>) -> Option<Origin> {
    Some(Origin {
        gid: sample.writer_guid().to_bytes(),
        sequence: i64::from(sample.sequence_number),
        sent_ns: nanos(sample.source_timestamp()?)?,
    })
}

fn take_twists(topic: usize, reader: &CmdVelReader, senders: &Senders) {
    match reader {
        CmdVelReader::Twist(reader) => reader.drain_read_notifications(),
        CmdVelReader::Stamped(reader) => reader.drain_read_notifications(),
        CmdVelReader::Ackermann(reader) => reader.drain_read_notifications(),
    }
    loop {
        let taken = match reader {
            CmdVelReader::Twist(reader) => reader.try_take_one().map(|sample| {
                sample.map(|sample| {
                    let origin = origin(&sample);
                    (
                        Command::Twist(PlanarTwist::from(&sample.into_value().0)),
                        origin,
                    )
                })
            }),
            CmdVelReader::Stamped(reader) => reader.try_take_one().map(|sample| {
                sample.map(|sample| {
                    let origin = origin(&sample);
                    let twist = PlanarTwist::from(&sample.into_value().0.twist);
                    (Command::Twist(twist), origin)
                })
            }),
            CmdVelReader::Ackermann(reader) => reader.try_take_one().map(|sample| {
                sample.map(|sample| {
                    let origin = origin(&sample);
                    let drive = AckermannDrive::from(&sample.into_value().0);
                    (Command::Ackermann(drive), origin)
                })
            }),
        };
        match taken {
            Ok(Some((command, origin))) => senders.twist(CmdVel {
                topic,
                origin,
                command: Ok(command),
            }),
            Ok(None) => break,
            // A sample that is no message of the type: counted as malformed by the bridge.
            Err(error) => senders.twist(CmdVel {
                topic,
                origin: None,
                command: Err(CdrError::Malformed(format!("{error:?}"))),
            }),
        }
    }
}

/// The identity a reply names: the request's related sample identity where its writer sent one
/// (Fast DDS), else the request's own writer and sequence number; Fast DDS' unknown sequence
/// number is the request's own (as `ros2-client` did).
fn request_identity<D>(request: &rustdds::no_key::DeserializedCacheChange<D>) -> SampleIdentity {
    let mut identity = request.related_sample_identity().unwrap_or(SampleIdentity {
        writer_guid: request.writer_guid(),
        sequence_number: request.sequence_number,
    });
    if identity.sequence_number == SequenceNumber::UNKNOWN {
        identity.sequence_number = request.sequence_number;
    }
    identity
}

fn take_calls(service: &TriggerService, senders: &Senders) {
    let kind = service.kind;
    service.requests.drain_read_notifications();
    loop {
        match service.requests.try_take_one() {
            Ok(Some(request)) => {
                let identity = request_identity(&request);
                let call = request.into_value();
                let replies = Arc::clone(&service.replies);
                senders.call(
                    kind,
                    Call {
                        reply: Box::new(move |success, message| {
                            let reply = TriggerReply {
                                cyclone_header: call.cyclone_header,
                                response: TriggerResponse {
                                    success,
                                    message: message.to_owned(),
                                },
                            };
                            let options = WriteOptionsBuilder::new()
                                .source_timestamp(Timestamp::now())
                                .related_sample_identity(identity)
                                .build();
                            if let Err(error) = replies.write_with_options(reply, options) {
                                warn!(
                                    "ros2: replying to a {kind:?} call failed: {}",
                                    describe(&error)
                                );
                            }
                        }),
                    },
                );
            }
            Ok(None) => break,
            Err(error) => {
                Counters::add(&senders.counters.service_calls_malformed);
                warn!("ros2: a {kind:?} call that is no Trigger request: {error:?}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dds_wire::{CYCLONE_HEADER, decode, decode_cmd_vel, decode_trigger_request};

    #[test]
    fn encoded_cdr_is_written_byte_for_byte() {
        use rustdds::no_key::SerializerAdapter;
        let response = crate::msgs::encode_trigger_response(true, "stopped");
        let body = response[ENCAPSULATION.len()..].to_vec();
        let written =
            rustdds::CDRSerializerAdapter::<EncodedCdr>::to_bytes(&EncodedCdr(body.clone()))
                .expect("serializes");
        assert_eq!(&written[..], &body[..]);
        assert_eq!(
            rustdds::CDRSerializerAdapter::<EncodedCdr>::output_encoding().to_bytes(),
            [ENCAPSULATION[0], ENCAPSULATION[1]]
        );
    }

    #[test]
    fn cmd_vel_decodes_as_the_reader_does() {
        let mut writer = crate::cdr::Writer::new();
        writer.f64s(&[0.5, 0.0, 0.0, 0.0, 0.0, -0.25]);
        let twist = writer.finish();
        assert_eq!(
            decode_cmd_vel(&twist, false),
            Ok(PlanarTwist {
                linear: 0.5,
                lateral: 0.0,
                angular: -0.25
            })
        );
        assert!(decode_cmd_vel(&twist[..20], false).is_err());
        assert!(decode_cmd_vel(&[], true).is_err());
        let mut xcdr2 = twist.clone();
        xcdr2[1] = 0x07;
        assert_eq!(
            decode_cmd_vel(&xcdr2, false),
            Err(CdrError::Encapsulation([0x00, 0x07]))
        );
        assert_eq!(decode_trigger_request(&[0, 1, 0, 0, 0]), Ok(false));
        assert!(decode_trigger_request(&[0, 1, 0, 0]).is_err());
    }

    #[test]
    fn a_cyclone_call_is_told_by_its_header_and_answered_after_it() {
        use rustdds::no_key::SerializerAdapter;
        // rmw_cyclonedds: the client's id and the call's number, then the request's byte.
        let mut header = [0u8; CYCLONE_HEADER];
        header[..8].copy_from_slice(&0x1122_3344_5566_7788u64.to_le_bytes());
        header[8..].copy_from_slice(&7i64.to_le_bytes());
        let mut payload = ENCAPSULATION.to_vec();
        payload.extend(header);
        payload.extend([0, 0, 0, 0]);
        assert_eq!(decode_trigger_request(&payload), Ok(true));
        let call = decode::<TriggerCall>(&payload).expect("a Cyclone call");
        let reply = TriggerReply {
            cyclone_header: call.cyclone_header,
            response: TriggerResponse {
                success: true,
                message: "stopped".into(),
            },
        };
        let written =
            rustdds::CDRSerializerAdapter::<TriggerReply>::to_bytes(&reply).expect("serializes");
        // The header back, then the response aligned from the header's start: the bool at 16,
        // the string's length at 20.
        let mut wanted = header.to_vec();
        wanted.extend([1, 0, 0, 0]);
        wanted.extend(8u32.to_le_bytes());
        wanted.extend(b"stopped\0");
        assert_eq!(&written[..], &wanted[..]);
        // The Enhanced mapping's reply is the response alone, as rosbags writes it.
        let plain = TriggerReply {
            cyclone_header: None,
            response: TriggerResponse {
                success: true,
                message: "stopped".into(),
            },
        };
        let written =
            rustdds::CDRSerializerAdapter::<TriggerReply>::to_bytes(&plain).expect("serializes");
        let rosbags = crate::msgs::encode_trigger_response(true, "stopped");
        assert_eq!(&written[..], &rosbags[ENCAPSULATION.len()..]);
        // Between the two forms' lengths: refused.
        let mut odd = ENCAPSULATION.to_vec();
        odd.extend([0; 12]);
        assert!(decode_trigger_request(&odd).is_err());
    }

    #[test]
    fn a_longer_sample_is_no_twist() {
        let mut writer = crate::cdr::Writer::new();
        writer.f64s(&[0.5, 0.0, 0.0, 0.0, 0.0, -0.25]);
        let twist = writer.finish();
        // Alignment padding passes, as on the zenoh path.
        let mut padded = twist.clone();
        padded.extend([0; 7]);
        assert!(decode_cmd_vel(&padded, false).is_ok());
        // A TwistWithCovariance (the twist, then 36 doubles) is refused, saying why.
        let mut with_covariance = twist.clone();
        with_covariance.extend([0; 36 * 8]);
        assert_eq!(
            decode_cmd_vel(&with_covariance, false),
            Err(CdrError::Malformed(CdrError::Trailing(8).to_string()))
        );
        assert!(decode_trigger_request(&[0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]).is_err());
    }

    proptest::proptest! {
        /// One rule for what a Twist is, whichever middleware carried it: RustDDS' reader with
        /// [`Whole`] and the zenoh path's decoder agree on every little-endian CDR payload.
        #[test]
        fn the_dds_reader_agrees_with_the_zenoh_decoder(
            body in proptest::collection::vec(proptest::prelude::any::<u8>(), 0..80),
        ) {
            let mut payload = ENCAPSULATION.to_vec();
            payload.extend(&body);
            let bits = |twist: PlanarTwist| {
                (twist.linear.to_bits(), twist.lateral.to_bits(), twist.angular.to_bits())
            };
            proptest::prop_assert_eq!(
                decode_cmd_vel(&payload, false).ok().map(bits),
                crate::msgs::decode_twist(&payload, false).ok().map(bits)
            );
        }
    }

    #[test]
    fn names_are_the_dds_names_ros_2_uses() {
        assert_eq!(
            type_name(&crate::msgs::ODOMETRY),
            "nav_msgs::msg::dds_::Odometry_"
        );
        assert_eq!(
            dds_type("std_srvs/srv/Trigger", "_Request"),
            "std_srvs::srv::dds_::Trigger_Request_"
        );
        assert_eq!(dds_name("rt", "/robot1/odom", ""), "rt/robot1/odom");
        assert_eq!(
            dds_name("rr", "/scout/estop", "Reply"),
            "rr/scout/estopReply"
        );
    }

    #[test]
    fn source_times_become_ros_nanoseconds() {
        // 1 700 000 000 s and a quarter (2^30 of 2^32) after the epoch.
        let stamp = Timestamp::from_ticks((1_700_000_000u64 << 32) | (1 << 30));
        assert_eq!(nanos(stamp), Some(1_700_000_000_250_000_000));
        assert_eq!(nanos(Timestamp::INVALID), None);
        assert_eq!(nanos(Timestamp::INFINITE), None);
    }

    #[test]
    fn a_writer_is_made_anew_only_after_a_run_of_failed_writes() {
        let mut streak = FailureStreak::default();
        // A healthy subscriber joining costs a failed write now and then: never a new writer.
        for i in 0..10_000 {
            assert!(!streak.record(i % 7 != 0));
        }
        let made_anew: Vec<u32> = (1..=60).filter(|_| streak.record(false)).collect();
        assert_eq!(
            made_anew.len(),
            2,
            "every {RECREATE_AFTER} failures in a row"
        );
        assert!(!streak.record(true));
    }
}
