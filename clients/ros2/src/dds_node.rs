//! The bridge's node on DDS, as ROS 2's default middlewares (Fast DDS, Cyclone DDS) speak it:
//! a RustDDS participant made a ROS node by `ros2-client` (it publishes `ros_discovery_info`,
//! so `ros2 node list` shows it), with the same topics, services and QoS ROS users expect. One
//! thread waits on the cmd_vel readers and the service servers and hands what arrives to the
//! bridge's queues ([`Senders`]); the writer's GUID, sequence number and source timestamp play
//! the part of rmw_zenoh's attachment.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

// The backend's own paths: the crate root names them only while DDS is ros2-client's one backend
// (the system tests' rmw_zenoh peer turns on its zenoh backend in the same build).
use ros2_client::dds::{
    Context, ContextOptions, Node, Publisher, Server, ServiceMapping, Subscription,
};
use ros2_client::{
    MessageTypeName, Name, NodeName, NodeOptions, QosProfile, ServiceTypeName,
    qos::{Durability, History, WhenFull},
};
use rustdds::mio1::{Events, Interest, Poll, Token};
use serde::{Deserialize, Serialize};
use tracing::warn;

use crate::bridge::{BridgeError, Call, CmdVel, Counters, Publishers, Senders, ServiceKind};
use crate::cdr::{CdrError, ENCAPSULATION};
use crate::config::Ros2Config;
use crate::msgs::{MessageType, PlanarTwist};
use crate::publish::Topic;
use crate::stream::Origin;

fn dds_error(what: &str) -> impl Fn(ros2_client::CreateError) -> BridgeError + '_ {
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

/// `builtin_interfaces/Time`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

/// `std_msgs/Header`.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Header {
    stamp: Time,
    frame_id: String,
}

/// `geometry_msgs/Vector3`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

/// `geometry_msgs/Twist`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize)]
pub struct Twist {
    linear: Vector3,
    angular: Vector3,
}

/// `geometry_msgs/TwistStamped`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TwistStamped {
    header: Header,
    twist: Twist,
}

impl From<&Twist> for PlanarTwist {
    fn from(twist: &Twist) -> Self {
        PlanarTwist {
            linear: twist.linear.x,
            angular: twist.angular.z,
        }
    }
}

/// A message that must fill its sample: `T`, then less than 8 bytes of alignment padding, as
/// [`crate::cdr::Reader::finish`] allows on the zenoh path. RustDDS' reader would decode the
/// first bytes of a longer sample (a writer of another type on the topic) as a `T`; this refuses
/// it, saying how many bytes followed.
#[derive(Debug, Clone)]
pub struct Whole<T>(T);

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Whole<T> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for Visitor<T> {
            type Value = Whole<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a message and nothing after it but padding")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Whole<T>, A::Error> {
                let message = seq
                    .next_element::<T>()?
                    .ok_or_else(|| serde::de::Error::custom("an empty sample"))?;
                // What follows, a byte at a time until the sample ends (the read that fails).
                let mut trailing = 0;
                while trailing < 8 && matches!(seq.next_element::<u8>(), Ok(Some(_))) {
                    trailing += 1;
                }
                if trailing < 8 {
                    Ok(Whole(message))
                } else {
                    Err(serde::de::Error::custom(CdrError::Trailing(trailing)))
                }
            }
        }
        // A CDR tuple is its elements back to back: the message, then the bytes after it.
        deserializer.deserialize_tuple(usize::MAX, Visitor(std::marker::PhantomData))
    }
}

/// Written as the message itself (a Trigger request type must be writable to be served).
impl<T: Serialize> Serialize for Whole<T> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        self.0.serialize(serializer)
    }
}

/// A `std_srvs/Trigger` request: no fields but CDR's placeholder byte.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TriggerRequest {
    structure_needs_at_least_one_member: u8,
}

/// A `std_srvs/Trigger` response.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TriggerResponse {
    success: bool,
    message: String,
}

/// rmw_cyclonedds' request header, which it writes before every request and expects before
/// its reply (`cdds_request_header_t`: the client's id and the call's sequence number, two
/// 64-bit integers); kept as the bytes it came in, little-endian as on every platform ROS 2
/// runs on, and written back the same.
pub const CYCLONE_HEADER: usize = 16;

/// A Trigger call as either DDS service mapping carries it: Fast DDS' (and RustDDS' Enhanced
/// mapping) puts the request alone in the sample, the call's identity in its inline QoS;
/// rmw_cyclonedds puts its 16-byte header before the request. Told apart by length: the request
/// is one byte, padding less than 8; with the header 17 bytes and the same padding. Anything
/// else is refused as [`Whole`] refuses it.
#[derive(Debug, Clone)]
pub struct TriggerCall {
    cyclone_header: Option<[u8; CYCLONE_HEADER]>,
}

impl<'de> Deserialize<'de> for TriggerCall {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = TriggerCall;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a Trigger request, after rmw_cyclonedds' header or not")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<TriggerCall, A::Error> {
                // The sample a byte at a time, up to what the longest form holds.
                let mut bytes = Vec::with_capacity(32);
                while bytes.len() < CYCLONE_HEADER + 8 + 1 {
                    match seq.next_element::<u8>() {
                        Ok(Some(byte)) => bytes.push(byte),
                        Ok(None) | Err(_) => break,
                    }
                }
                match bytes.len() {
                    0 => Err(serde::de::Error::custom("an empty sample")),
                    1..=8 => Ok(TriggerCall {
                        cyclone_header: None,
                    }),
                    17..=24 => {
                        let mut header = [0; CYCLONE_HEADER];
                        header.copy_from_slice(&bytes[..CYCLONE_HEADER]);
                        Ok(TriggerCall {
                            cyclone_header: Some(header),
                        })
                    }
                    _ => Err(serde::de::Error::custom(CdrError::Trailing(
                        bytes.len() - 1,
                    ))),
                }
            }
        }
        deserializer.deserialize_tuple(usize::MAX, Visitor)
    }
}

/// Written as the Enhanced mapping's request (a request type must be writable to be served).
impl Serialize for TriggerCall {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut tuple = serializer.serialize_tuple(2)?;
        if let Some(header) = &self.cyclone_header {
            tuple.serialize_element(header)?;
        }
        tuple.serialize_element(&0u8)?;
        tuple.end()
    }
}

/// A Trigger reply in the form its call came in: after rmw_cyclonedds' header when the call
/// had one.
#[derive(Debug, Clone, Deserialize)]
pub struct TriggerReply {
    #[serde(skip)]
    cyclone_header: Option<[u8; CYCLONE_HEADER]>,
    response: TriggerResponse,
}

impl Serialize for TriggerReply {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let mut tuple = serializer.serialize_tuple(2)?;
        if let Some(header) = &self.cyclone_header {
            tuple.serialize_element(header)?;
        }
        tuple.serialize_element(&self.response)?;
        tuple.end()
    }
}

impl ros2_client::Message for TriggerCall {}
impl ros2_client::Message for TriggerReply {}
impl ros2_client::Message for TriggerResponse {}

/// Decodes a payload (with its encapsulation header) as a DDS reader of `T` does, with RustDDS'
/// CDR deserializer, refusing the encodings the reader refuses.
fn decode<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> Result<T, CdrError> {
    use rustdds::no_key::DeserializerAdapter;
    let (header, body) = match bytes {
        [a, b, _, _, body @ ..] => ([*a, *b], body),
        _ => return Err(CdrError::Truncated(bytes.len())),
    };
    let encoding = rustdds::RepresentationIdentifier::from_bytes(&header)
        .map_err(|_| CdrError::Truncated(bytes.len()))?;
    if !<rustdds::CDRDeserializerAdapter<T> as DeserializerAdapter<T>>::supported_encodings()
        .contains(&encoding)
    {
        return Err(CdrError::Encapsulation(header));
    }
    rustdds::CDRDeserializerAdapter::<T>::from_bytes(body, encoding)
        .map_err(|error| CdrError::Malformed(error.to_string()))
}

/// Decodes a cmd_vel payload as the bridge's DDS reader does: the fuzz target's entry to it.
pub fn decode_cmd_vel(bytes: &[u8], stamped: bool) -> Result<PlanarTwist, CdrError> {
    if stamped {
        decode::<Whole<TwistStamped>>(bytes).map(|Whole(message)| PlanarTwist::from(&message.twist))
    } else {
        decode::<Whole<Twist>>(bytes).map(|Whole(message)| PlanarTwist::from(&message))
    }
}

/// Decodes a Trigger request as the bridge's DDS service does (either service mapping): the
/// fuzz target's entry to it. `Ok(true)` for rmw_cyclonedds' form.
pub fn decode_trigger_request(bytes: &[u8]) -> Result<bool, CdrError> {
    decode::<TriggerCall>(bytes).map(|call| call.cyclone_header.is_some())
}

/// `package/msg/Name` as ros2-client names a type.
fn type_name(message: &MessageType) -> MessageTypeName {
    let (package, rest) = message.name.split_once('/').unwrap_or(("", message.name));
    let name = rest.rsplit('/').next().unwrap_or(rest);
    MessageTypeName::new(package, name)
}

/// The QoS a ROS publisher of `topic` offers: reliable and volatile, which reliable and
/// best-effort (sensor data) subscribers both accept; `/tf` keeps 100 as tf2's broadcaster does.
/// A write that cannot be queued at once fails (counted as `publish_failed`) instead of holding
/// the state thread up to 100 ms: the next state, 20 ms later, is worth more than a late one.
fn publisher_qos(topic: Topic) -> QosProfile {
    let depth = match topic {
        Topic::Tf => 100,
        Topic::Odom | Topic::BatteryState | Topic::JointStates | Topic::Diagnostics => 10,
    };
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::Fail)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth })
}

/// cmd_vel is read best effort: it matches reliable and best-effort publishers alike, and a
/// lost command is better than a late one.
fn cmd_vel_qos() -> QosProfile {
    QosProfile::subscription_default()
        .reliability_best_effort()
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

/// Services: ROS 2's default service QoS (reliable, volatile, keep last 10).
fn service_qos() -> QosProfile {
    QosProfile::publisher_default()
        .reliability_reliable(WhenFull::DEFAULT)
        .durability(Durability::Volatile)
        .history(History::KeepLast { depth: 10 })
}

fn ros_name(name: &str) -> Result<Name, BridgeError> {
    Name::parse(name).map_err(|error| BridgeError::Dds(format!("the name {name}: {error:?}")))
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

/// One topic's writer.
struct Writer {
    topic: Topic,
    dds_topic: ros2_client::dds::rustdds::Topic,
    publisher: Publisher<EncodedCdr>,
    streak: FailureStreak,
}

/// The node's publishers on DDS, and the node, which makes a writer anew when one is stuck.
pub struct DdsPublishers {
    node: Node,
    writers: Vec<Writer>,
}

/// What a failed write says, without its payload.
fn describe(error: &ros2_client::WriteError<EncodedCdr>) -> String {
    match error {
        ros2_client::WriteError::WouldBlock { .. } => {
            "the reliable send window is full (a subscriber has not acknowledged)".into()
        }
        other => other.to_string(),
    }
}

impl Publishers for DdsPublishers {
    fn publish(&mut self, topic: Topic, payload: Vec<u8>) -> Result<(), String> {
        let Some(writer) = self.writers.iter_mut().find(|w| w.topic == topic) else {
            return Ok(());
        };
        let body = payload
            .strip_prefix(&ENCAPSULATION[..])
            .ok_or("a payload without the CDR little-endian header")?;
        let result = writer.publisher.publish(EncodedCdr(body.to_vec()));
        if writer.streak.record(result.is_ok()) {
            match self
                .node
                .create_publisher::<EncodedCdr>(&writer.dds_topic, None)
            {
                Ok(publisher) => {
                    warn!(
                        "ros2: {RECREATE_AFTER} writes of {topic:?} failed in a row: its writer \
                         is made anew (a subscriber that never acknowledges held it)"
                    );
                    writer.publisher = publisher;
                }
                Err(error) => warn!("ros2: making a new writer of {topic:?}: {error:?}"),
            }
        }
        result.map_err(|error| describe(&error))
    }
}

/// What keeps the node in the graph: its receive thread (stopped and joined on drop), the node
/// and the participant.
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

/// A cmd_vel reader of either type.
enum CmdVelReader {
    Twist(Subscription<Whole<Twist>>),
    Stamped(Subscription<Whole<TwistStamped>>),
}

type TriggerServer = Server<TriggerCall, TriggerReply>;

/// Makes the participant and the node with its publishers, cmd_vel readers and services.
pub fn start(
    config: &Ros2Config,
    senders: Senders,
) -> Result<(DdsPublishers, DdsNode), BridgeError> {
    let domain = u16::try_from(config.domain)
        .map_err(|_| BridgeError::Dds(format!("ROS domain {} is out of range", config.domain)))?;
    let context = Context::with_options(ContextOptions::new().domain_id(domain))
        .map_err(dds_error("making the DDS participant"))?;
    let namespace = if config.namespace.is_empty() {
        "/"
    } else {
        config.namespace.as_str()
    };
    let node_name = NodeName::new(namespace, &config.node)
        .map_err(|error| BridgeError::Dds(format!("the node name: {error:?}")))?;
    let mut node = context
        .new_node(
            node_name,
            NodeOptions::new()
                .enable_rosout(false)
                .start_parameter_services(false),
        )
        .map_err(|error| BridgeError::Dds(format!("making the node: {error:?}")))?;
    let mut publishers = Vec::new();
    for topic in Topic::ALL {
        let Some(name) = topic.name(config) else {
            continue;
        };
        let qos = publisher_qos(topic);
        let dds_topic = node
            .create_topic(
                &ros_name(&config.resolve(name))?,
                type_name(&topic.message()),
                &qos,
            )
            .map_err(dds_error("making a topic"))?;
        let publisher = node
            .create_publisher::<EncodedCdr>(&dds_topic, None)
            .map_err(dds_error("making a publisher"))?;
        publishers.push(Writer {
            topic,
            dds_topic,
            publisher,
            streak: FailureStreak::default(),
        });
    }
    let mut readers = Vec::new();
    for cmd_vel in &config.cmd_vel {
        let name = ros_name(&config.resolve(&cmd_vel.topic))?;
        let message = if cmd_vel.stamped {
            crate::msgs::TWIST_STAMPED
        } else {
            crate::msgs::TWIST
        };
        let dds_topic = node
            .create_topic(&name, type_name(&message), &cmd_vel_qos())
            .map_err(dds_error("making the cmd_vel topic"))?;
        readers.push(if cmd_vel.stamped {
            CmdVelReader::Stamped(
                node.create_subscription(&dds_topic, None)
                    .map_err(dds_error("subscribing to cmd_vel"))?,
            )
        } else {
            CmdVelReader::Twist(
                node.create_subscription(&dds_topic, None)
                    .map_err(dds_error("subscribing to cmd_vel"))?,
            )
        });
    }
    let mut servers = Vec::new();
    for &kind in ServiceKind::served(config) {
        let server: TriggerServer = node
            .create_server(
                ServiceMapping::Enhanced,
                &ros_name(&config.resolve(kind.name(config)))?,
                &ServiceTypeName::new("std_srvs", "Trigger"),
                service_qos(),
                service_qos(),
            )
            .map_err(dds_error("making a service"))?;
        servers.push((kind, server));
    }
    let poll = register(&mut readers, &mut servers).map_err(BridgeError::Thread)?;
    let servers: Vec<_> = servers
        .into_iter()
        .map(|(kind, server)| (kind, Arc::new(server)))
        .collect();
    let halt = Arc::new(AtomicBool::new(false));
    let receiver = {
        let halt = Arc::clone(&halt);
        std::thread::Builder::new()
            .name("ros2-dds".into())
            .spawn(move || {
                // The participant lives on this thread (the node on the state thread's
                // publishers), as long as the bridge runs.
                let _context = context;
                if let Err(error) = receive(poll, &readers, &servers, &senders, &halt) {
                    senders.fail(format!("waiting for DDS input: {error}"));
                }
            })?
    };
    Ok((
        DdsPublishers {
            node,
            writers: publishers,
        },
        DdsNode {
            halt,
            receiver: Some(receiver),
        },
    ))
}

/// A poll that wakes when a cmd_vel reader or a server has input: reader `i` is token `i`, the
/// servers follow.
fn register(
    readers: &mut [CmdVelReader],
    servers: &mut [(ServiceKind, TriggerServer)],
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
        }
    }
    for (index, (_, server)) in servers.iter_mut().enumerate() {
        poll.registry()
            .register(server, Token(readers.len() + index), Interest::READABLE)?;
    }
    Ok(poll)
}

/// How often the receive thread looks whether the bridge stops.
const HALT_POLL: Duration = Duration::from_millis(100);

/// Waits on the readers and servers, and queues what arrives.
fn receive(
    mut poll: Poll,
    readers: &[CmdVelReader],
    servers: &[(ServiceKind, Arc<TriggerServer>)],
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
        for (kind, server) in servers {
            take_calls(*kind, server, senders);
        }
        for (index, reader) in readers.iter().enumerate() {
            take_twists(index, reader, senders);
        }
    }
    Ok(())
}

fn origin(info: &ros2_client::MessageInfo) -> Option<Origin> {
    Some(Origin {
        gid: info.publisher_gid().to_bytes16(),
        sequence: info.sequence_number(),
        sent_ns: info.source_timestamp()?.to_nanos(),
    })
}

fn take_twists(topic: usize, reader: &CmdVelReader, senders: &Senders) {
    loop {
        let taken = match reader {
            CmdVelReader::Twist(reader) => reader.take().map(|message| {
                message.map(|(Whole(twist), info)| (PlanarTwist::from(&twist), info))
            }),
            CmdVelReader::Stamped(reader) => reader.take().map(|message| {
                message.map(|(Whole(stamped), info)| (PlanarTwist::from(&stamped.twist), info))
            }),
        };
        match taken {
            Ok(Some((twist, info))) => senders.twist(CmdVel {
                topic,
                origin: origin(&info),
                twist: Ok(twist),
            }),
            Ok(None) => break,
            // A sample that is no message of the type: counted as malformed by the bridge.
            Err(error) => senders.twist(CmdVel {
                topic,
                origin: None,
                twist: Err(CdrError::Malformed(format!("{error:?}"))),
            }),
        }
    }
}

fn take_calls(kind: ServiceKind, server: &Arc<TriggerServer>, senders: &Senders) {
    loop {
        match server.receive_request() {
            Ok(Some((id, call))) => {
                let server = Arc::clone(server);
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
                            if let Err(error) = server.send_response(id, reply) {
                                warn!("ros2: replying to a {kind:?} call failed: {error:?}");
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
            let bits = |twist: PlanarTwist| (twist.linear.to_bits(), twist.angular.to_bits());
            proptest::prop_assert_eq!(
                decode_cmd_vel(&payload, false).ok().map(bits),
                crate::msgs::decode_twist(&payload, false).ok().map(bits)
            );
        }
    }

    #[test]
    fn type_names_split_as_ros2_client_wants() {
        let name = type_name(&crate::msgs::ODOMETRY);
        assert_eq!(name.dds_msg_type(), "nav_msgs::msg::dds_::Odometry_");
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
