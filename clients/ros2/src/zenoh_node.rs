//! The bridge's node on rmw_zenoh: a zenoh client of the ROS 2 router (rmw_zenohd) that declares
//! the node and its endpoints as liveliness tokens, publishes with rmw_zenoh's attachment, and
//! hands cmd_vel samples and service queries to the bridge's queues ([`Senders`]).

use std::sync::Arc;

use scout_interface::remote::SessionSettings;
use tracing::warn;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::qos::CongestionControl;
use zenoh::query::{Query, Queryable};

use crate::bridge::{
    BridgeError, Call, CmdVel, Counters, Publishers, Senders, ServiceKind, unix_now,
};
use crate::config::{ROS2_ROUTER, Ros2Config};
use crate::msgs::{self, MessageType};
use crate::publish::Topic;
use crate::rmw::{self, EntityKind, Node};
use crate::stream::Origin;

fn zenoh_error(what: &str) -> impl Fn(zenoh::Error) -> BridgeError + '_ {
    move |error| BridgeError::Zenoh(format!("{what}: {error}"))
}

/// A publisher with its sequence number and GID, for the attachment.
struct RosPublisher {
    publisher: Publisher<'static>,
    gid: [u8; 16],
    seq: i64,
}

/// The node's publishers on rmw_zenoh.
pub struct ZenohPublishers {
    publishers: Vec<(Topic, RosPublisher)>,
}

impl Publishers for ZenohPublishers {
    fn publish(&mut self, topic: Topic, payload: Vec<u8>) -> Result<(), BridgeError> {
        let Some((_, publisher)) = self.publishers.iter_mut().find(|(t, _)| *t == topic) else {
            return Ok(());
        };
        publisher.seq += 1;
        let attachment =
            rmw::attachment(publisher.seq, unix_now().as_nanos() as i64, &publisher.gid);
        publisher
            .publisher
            .put(payload)
            .attachment(attachment.to_vec())
            .wait()
            .map_err(|error| BridgeError::Zenoh(error.to_string()))
    }
}

/// What keeps the node in the graph: the session, its tokens, subscribers and queryables.
pub struct ZenohNode {
    _subscribers: Vec<Subscriber<()>>,
    _queryables: Vec<Queryable<()>>,
    _tokens: Vec<LivelinessToken>,
    _session: zenoh::Session,
}

impl std::fmt::Debug for ZenohPublishers {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohPublishers").finish_non_exhaustive()
    }
}

impl std::fmt::Debug for ZenohNode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohNode").finish_non_exhaustive()
    }
}

/// The node and its endpoints' liveliness tokens; entity ids count from 1 (the node's own
/// token uses the node id).
struct Declared {
    node: Node,
    next_entity: u32,
    tokens: Vec<LivelinessToken>,
}

impl Declared {
    /// Declares an entity's token and returns its GID.
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
            .entity_token(entity, kind, name, message, config.distro());
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

/// Opens the session, declares the node, its publishers, cmd_vel subscriptions and services.
pub fn start(
    config: &Ros2Config,
    senders: Senders,
) -> Result<(ZenohPublishers, ZenohNode), BridgeError> {
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
    let mut publishers = Vec::new();
    for topic in Topic::ALL {
        let Some(name) = topic.name(config) else {
            continue;
        };
        let name = config.resolve(name);
        let message = topic.message();
        let gid = declared.declare(&session, EntityKind::Publisher, &name, &message, config)?;
        let publisher = session
            .declare_publisher(rmw::data_key(
                config.domain,
                &name,
                &message,
                config.distro(),
            ))
            .congestion_control(CongestionControl::Drop)
            .wait()
            .map_err(zenoh_error("declaring a publisher"))?;
        publishers.push((
            topic,
            RosPublisher {
                publisher,
                gid,
                seq: 0,
            },
        ));
    }
    let mut subscribers = Vec::new();
    for (index, cmd_vel) in config.cmd_vel.iter().enumerate() {
        let name = config.resolve(&cmd_vel.topic);
        let message = cmd_vel.message();
        declared.declare(&session, EntityKind::Subscription, &name, &message, config)?;
        let senders = senders.clone();
        let topic = cmd_vel.clone();
        subscribers.push(
            session
                .declare_subscriber(rmw::subscription_key(config.domain, &name, &message))
                .callback(move |sample| {
                    let origin = sample
                        .attachment()
                        .and_then(|a| rmw::parse_attachment(&a.to_bytes()))
                        .map(|(sequence, sent_ns, gid)| Origin {
                            gid,
                            sequence,
                            sent_ns,
                        });
                    senders.twist(CmdVel {
                        topic: index,
                        origin,
                        command: topic.decode(&sample.payload().to_bytes()),
                    });
                })
                .wait()
                .map_err(zenoh_error("subscribing to cmd_vel"))?,
        );
    }
    let mut queryables = Vec::new();
    for &kind in ServiceKind::served(config) {
        let name = config.resolve(kind.name(config));
        declared.declare(&session, EntityKind::Service, &name, &msgs::TRIGGER, config)?;
        let key = rmw::data_key(config.domain, &name, &msgs::TRIGGER, config.distro());
        let senders = senders.clone();
        queryables.push(
            session
                .declare_queryable(key.clone())
                .complete(true)
                .callback(move |query| serve_query(query, &key, kind, &senders))
                .wait()
                .map_err(zenoh_error("declaring a service"))?,
        );
    }
    Ok((
        ZenohPublishers { publishers },
        ZenohNode {
            _subscribers: subscribers,
            _queryables: queryables,
            _tokens: declared.tokens,
            _session: session,
        },
    ))
}

/// A query on a service's key: a call queued for the bridge, or refused at once with why.
fn serve_query(query: Query, key: &str, kind: ServiceKind, senders: &Senders) {
    let counters: &Arc<Counters> = &senders.counters;
    // A wildcard query (`**`, a diagnostic tool's) is no call.
    if query.key_expr().as_str() != key {
        Counters::add(&counters.service_calls_malformed);
        refuse(&query, "not a service call: query the service's exact key");
        return;
    }
    // Checked here, so that only real calls wait in the queue. An rmw_zenoh client ignores
    // error replies (its caller would wait for its timeout): a call with the attachment is
    // refused with a Trigger response saying why.
    if let Err(why) = trigger_request(&query) {
        Counters::add(&counters.service_calls_malformed);
        match why {
            NoCall::NotRmwZenoh(why) => refuse(&query, why),
            NoCall::NotTrigger(why) => answer(&query, kind, false, &why),
        }
        return;
    }
    senders.call(
        kind,
        Call {
            reply: Box::new(move |success, message| answer(&query, kind, success, message)),
        },
    );
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
