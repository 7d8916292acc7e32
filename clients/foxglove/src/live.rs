//! `scout foxglove`: the transcript live on a Foxglove WebSocket server (subprotocol
//! `foxglove.websocket.v1`, or `foxglove.sdk.v1` as it is called now: [`crate::subprotocol`]), the same channels as a recording; the stops holding the robot as
//! the server's status messages (Foxglove's Problems list), with their owners and causes. Read
//! only unless asked: `--estop` offers a stop service (the stop of a named owner, through the
//! gateway's stop path like every other stop), `--allow-release` a release of that owner's
//! stops only.

use std::collections::BTreeSet;
use std::net::SocketAddr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use foxglove::websocket::service::{Request, Service, ServiceSchema};
use foxglove::websocket::{Capability, Status};
use foxglove::{Context, Schema, WebSocketServer, WebSocketServerHandle};
use serde_json::{Value, json};
use tracing::{info, warn};

use scout_clients::ReleaseTarget;
use scout_clients::control::ControlError;
use scout_clients::control::Stopper;
use scout_clients::failure::{Failure, FailureKind};

use crate::backend::Backend;
use crate::channels::{ChannelError, Channels};
use crate::origin::OriginPolicy;
use crate::source::{Source, SourceError, Update};
use crate::subprotocol::Front;
use crate::transcript::Entry;

/// The stop service's name.
pub const ESTOP_SERVICE: &str = "/scout/estop";
/// The release service's name.
pub const RELEASE_SERVICE: &str = "/scout/release";

/// What to serve.
#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// The robot.
    pub robot: String,
    /// Where to listen (port 0: any free port).
    pub listen: SocketAddr,
    /// Offer `/scout/estop`.
    pub estop: bool,
    /// Offer `/scout/release` (the owner's own stops only).
    pub allow_release: bool,
    /// The owner of the stops the service latches.
    pub owner: String,
    /// Which web pages may connect.
    pub origins: OriginPolicy,
}

/// Why the live view failed.
#[derive(Debug, thiserror::Error)]
pub enum LiveError {
    /// The gateway could not be read.
    #[error(transparent)]
    Source(#[from] SourceError),
    /// A channel could not be made.
    #[error(transparent)]
    Channel(#[from] ChannelError),
    /// The stop client could not be made (a bad owner name).
    #[error("the stop service's owner")]
    Owner(#[source] scout_clients::client::ClientError),
    /// The server could not start.
    #[error("starting the Foxglove WebSocket server: {0}")]
    Serve(foxglove::FoxgloveError),
    /// The address cannot be listened on.
    #[error("listening on {listen} (is the port in use?)")]
    Listen {
        /// The address.
        listen: SocketAddr,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// Reading the gateway failed.
    #[error("reading the gateway")]
    Read(#[source] scout_clients::client::ClientError),
}

/// An address that cannot be listened on is a usage error.
impl FailureKind for LiveError {
    fn kind(&self) -> Failure {
        match self {
            Self::Listen { .. } => Failure::Usage,
            Self::Source(error) => error.kind(),
            Self::Owner(error) | Self::Read(error) => error.kind(),
            Self::Channel(_) | Self::Serve(_) => Failure::Failed,
        }
    }
}

fn trigger_schema(name: &str, properties: Value) -> Schema {
    let schema = json!({ "title": name, "type": "object", "properties": properties });
    Schema::new(name, "jsonschema", schema.to_string().into_bytes())
}

fn service_schema(name: &str, request: Value) -> ServiceSchema {
    ServiceSchema::new(name)
        .with_request("json", trigger_schema(&format!("{name}Request"), request))
        .with_response(
            "json",
            trigger_schema(
                &format!("{name}Response"),
                json!({
                    "success": { "type": "boolean" },
                    "message": { "type": "string" },
                    "stop": { "type": "integer" },
                }),
            ),
        )
}

/// The answer a service call gets: `success` and a message, as `std_srvs/Trigger` answers.
fn answer(result: Result<scout_clients::Accepted, ControlError>, done: &str) -> Vec<u8> {
    match result {
        Ok(accepted) => json!({
            "success": true,
            "message": done,
            "stop": accepted.stop,
        }),
        Err(error) => json!({ "success": false, "message": error.to_string() }),
    }
    .to_string()
    .into_bytes()
}

/// The reason a stop request gives, if it is a JSON object with a string `reason`.
pub fn reason_of(payload: &[u8]) -> Option<String> {
    let value: Value = serde_json::from_slice(payload).ok()?;
    Some(value.get("reason")?.as_str()?.to_owned())
}

/// The stop id a release request names: `{"through": N}`, the newest stop its sender saw.
pub fn through_of(payload: &[u8]) -> Option<u64> {
    let value: Value = serde_json::from_slice(payload).ok()?;
    value.get("through")?.as_u64()
}

/// The release a caller asks for, through the newest stop it saw (`through`): a stop latched
/// after it survives. A `through` past the newest stop this view has shown names stops no
/// caller of this view can have seen, and is refused.
fn release_through(payload: &[u8], newest_seen: u64) -> Result<u64, ReleaseRefused> {
    match through_of(payload) {
        Some(through) if through <= newest_seen => Ok(through),
        Some(through) => Err(ReleaseRefused::NeverShown {
            through,
            newest_seen,
        }),
        None => Err(ReleaseRefused::NoThrough { newest_seen }),
    }
}

/// Why a release through this view was refused before it reached the gateway.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
enum ReleaseRefused {
    /// It names a stop newer than the view has shown.
    #[error(
        "stop #{through} was never shown here (the newest in the Problems list is \
         #{newest_seen}): name the newest stop you saw"
    )]
    NeverShown { through: u64, newest_seen: u64 },
    /// It names no stop.
    #[error(
        "say which stops you saw: {{\"through\": N}}, N the newest stop number in the \
         Problems list (now #{newest_seen}); stops latched after it are kept"
    )]
    NoThrough { newest_seen: u64 },
}

fn services(
    options: &LiveOptions,
    newest_stop: &Arc<AtomicU64>,
) -> Result<Vec<Service>, LiveError> {
    let mut services = Vec::new();
    if !(options.estop || options.allow_release) {
        return Ok(services);
    }
    // The owner's name is checked now; each call makes a stopper of its own (a socket and a
    // bind), so that no call waits on another: a stop is never queued behind a release or a
    // slow answer.
    Stopper::with_fallback(&options.robot, &options.owner).map_err(LiveError::Owner)?;
    let stopper = {
        let (robot, owner) = (options.robot.clone(), options.owner.clone());
        move || Stopper::with_fallback(&robot, &owner).map_err(ControlError::Client)
    };
    if options.estop {
        let stopper = stopper.clone();
        let owner = options.owner.clone();
        services.push(
            Service::builder(
                ESTOP_SERVICE,
                service_schema("scout.Estop", json!({ "reason": { "type": "string" } })),
            )
            .blocking_handler_fn(move |request: Request| {
                // A stop is never refused: a request that is not the JSON it should be still
                // stops, with the default reason.
                let reason =
                    reason_of(request.payload()).unwrap_or_else(|| "Foxglove e-stop".into());
                let reason = format!("Foxglove client {}: {reason}", request.client_id());
                warn!(
                    "stop from Foxglove client {} as {owner}: {reason}",
                    request.client_id()
                );
                let result = stopper().and_then(|mut stopper| stopper.stop(&reason));
                Ok::<_, String>(answer(result, "stop latched"))
            }),
        );
    }
    if options.allow_release {
        let newest_stop = Arc::clone(newest_stop);
        let owner = options.owner.clone();
        let request_schema = json!({ "through": { "type": "integer" } });
        services.push(
            Service::builder(
                RELEASE_SERVICE,
                service_schema("scout.Release", request_schema),
            )
            .blocking_handler_fn(move |request: Request| {
                let through =
                    release_through(request.payload(), newest_stop.load(Ordering::Relaxed));
                let result = match through {
                    Ok(through) => {
                        info!(
                            "release of {owner}'s stops through #{through} from Foxglove \
                                 client {}",
                            request.client_id()
                        );
                        stopper().and_then(|mut s| s.release(ReleaseTarget::Own, through))
                    }
                    Err(why) => {
                        return Ok::<_, String>(
                            json!({ "success": false, "message": why.to_string() })
                                .to_string()
                                .into_bytes(),
                        );
                    }
                };
                Ok(answer(
                    result,
                    "released: nothing moves until a client takes control again",
                ))
            }),
        );
    }
    Ok(services)
}

/// The problems in a status JSON as server status messages, keyed by their ids: the stops,
/// and a low or critical battery.
fn problem_statuses(status: &Value) -> Vec<(String, Status)> {
    let battery = &status["battery"];
    let charge = battery["percent"]
        .as_f64()
        .map_or_else(|| "charge unknown".to_owned(), |p| format!("{p:.0} %"));
    let key = "scout-battery".to_owned();
    let battery = match battery["level"].as_str() {
        Some("low") => Some(Status::warning(format!(
            "battery low: {charge}, charge soon"
        ))),
        Some("critical") => Some(Status::error(format!(
            "battery critical: {charge}, charge now"
        ))),
        _ => None,
    }
    .map(|status| (key.clone(), status.with_id(key)));
    let Some(stops) = status["stops"].as_array() else {
        return battery.into_iter().collect();
    };
    stops
        .iter()
        .map(|stop| {
            let id = stop["id"].as_u64().unwrap_or(0);
            let persists = if stop["persists"].as_bool() == Some(true) {
                " (its cause persists)"
            } else {
                ""
            };
            let message = format!(
                "STOP #{id} by {} ({}): {}{persists}",
                stop["owner"].as_str().unwrap_or("?"),
                stop["cause"].as_str().unwrap_or("unknown"),
                stop["reason"].as_str().unwrap_or(""),
            );
            let key = format!("scout-stop-{id}");
            (key.clone(), Status::error(message).with_id(key))
        })
        .chain(battery)
        .collect()
}

/// The running server.
#[derive(Debug)]
pub struct Live {
    /// Where clients connect, in front of the server.
    front: Front,
    server: WebSocketServerHandle,
    /// The channels' context: the channels close when it goes.
    _context: Arc<Context>,
    source: Source,
    channels: Channels,
    newest_stop: Arc<AtomicU64>,
    shown: BTreeSet<String>,
}

impl Live {
    /// Connects to the gateway and starts the server.
    pub fn start(options: &LiveOptions) -> Result<Self, LiveError> {
        let source = Source::start(&options.robot)?;
        let context = Context::new();
        let channels = Channels::new(&context, &options.robot)?;
        let newest_stop = Arc::new(AtomicU64::new(0));
        let services = services(options, &newest_stop)?;
        let capabilities = if services.is_empty() {
            Vec::new()
        } else {
            vec![Capability::Services]
        };
        let server = WebSocketServer::new()
            .context(&context)
            .name(format!("scout {}", options.robot))
            .bind("127.0.0.1", 0)
            .capabilities(capabilities)
            .services(services)
            .start_blocking()
            .map_err(LiveError::Serve)?;
        let backend = SocketAddr::from(([127, 0, 0, 1], server.port()));
        let backend = match Backend::guard(backend) {
            Ok(guarded) => guarded,
            Err(error) => {
                warn!(
                    "the Foxglove server behind the front at {backend} stays reachable by any \
                     local process, past the front's origin check and client limit: {error}"
                );
                Backend::unguarded(backend)
            }
        };
        let front = Front::start(options.listen, Arc::new(backend), options.origins.clone())
            .map_err(|source| LiveError::Listen {
                listen: options.listen,
                source,
            })?;
        Ok(Self {
            front,
            server,
            _context: context,
            source,
            channels,
            newest_stop,
            shown: BTreeSet::new(),
        })
    }

    /// The address clients connect to.
    pub fn address(&self) -> SocketAddr {
        self.front.address()
    }

    /// Serves until `stop` is set or reading the gateway fails.
    pub fn run(mut self, stop: &AtomicBool) -> Result<(), LiveError> {
        let outcome = loop {
            if stop.load(Ordering::Relaxed) {
                break Ok(());
            }
            match self.source.next(Duration::from_millis(100)) {
                Some(Update::Entries(entries)) => {
                    for timed in &entries {
                        self.channels.write(timed);
                        if let Entry::Status(status) = &timed.entry {
                            self.show_stops(status);
                        }
                    }
                }
                Some(Update::Silent(since)) => {
                    warn!("no state from the gateway for {since:.1?}: is it running?");
                    self.server.publish_status(
                        Status::warning("no state from the gateway: is it running?")
                            .with_id("scout-silent"),
                    );
                }
                Some(Update::Flowing) => self.server.remove_status(vec!["scout-silent".into()]),
                Some(Update::Missed(_)) | None => {}
                Some(Update::Failed(error)) => break Err(LiveError::Read(error)),
            }
        };
        // The handle it returns is only to wait for the connections to close.
        let _ = self.server.stop();
        outcome
    }

    fn show_stops(&mut self, status: &Value) {
        if let Some(newest) = status["newest_stop"].as_u64() {
            self.newest_stop.store(newest, Ordering::Relaxed);
        }
        let now = problem_statuses(status);
        let keys: BTreeSet<String> = now.iter().map(|(key, _)| key.clone()).collect();
        let gone: Vec<String> = self.shown.difference(&keys).cloned().collect();
        if !gone.is_empty() {
            self.server.remove_status(gone);
        }
        // Every status (at least once a second): a client that connected since sees the stops
        // holding the robot too (a status replaces the one with its id).
        for (_, status) in now {
            self.server.publish_status(status);
        }
        self.shown = keys;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_low_or_critical_battery_is_a_problem_beside_the_stops() {
        let keys = |status: &Value| -> Vec<String> {
            problem_statuses(status)
                .into_iter()
                .map(|(key, _)| key)
                .collect()
        };
        let stop = json!({ "id": 3, "owner": "safety", "cause": "client", "reason": "x" });
        assert_eq!(
            keys(&json!({ "stops": [stop], "battery": { "level": "ok", "percent": 60.0 } })),
            ["scout-stop-3"]
        );
        assert_eq!(
            keys(&json!({ "stops": [stop], "battery": { "level": "low", "percent": 18.0 } })),
            ["scout-stop-3", "scout-battery"]
        );
        let problems =
            problem_statuses(&json!({ "battery": { "level": "critical", "percent": 7.0 } }));
        let (_, status) = &problems[0];
        let text = format!("{status:?}");
        assert!(text.contains("battery critical: 7 %, charge now"), "{text}");
    }

    #[test]
    fn a_stop_request_that_is_not_json_still_has_a_reason_to_stop_with() {
        assert_eq!(
            reason_of(br#"{"reason":"obstacle"}"#).as_deref(),
            Some("obstacle")
        );
        assert_eq!(reason_of(b"not json"), None);
        assert_eq!(reason_of(br#"{"reason":3}"#), None);
        assert_eq!(reason_of(b""), None);
    }

    #[test]
    fn a_release_names_the_stops_its_sender_saw_and_never_more_than_the_view_saw() {
        assert_eq!(release_through(br#"{"through": 4}"#, 7), Ok(4));
        assert_eq!(release_through(br#"{"through": 7}"#, 7), Ok(7));
        for beyond in [
            &br#"{"through": 8}"#[..],
            br#"{"through": 18446744073709551615}"#,
        ] {
            let refused = release_through(beyond, 7)
                .expect_err("never shown")
                .to_string();
            assert!(
                refused.contains("never shown") && refused.contains("#7"),
                "{refused}"
            );
        }
        for payload in [&b"{}"[..], b"", b"not json", br#"{"through": -1}"#] {
            let refused = release_through(payload, 7)
                .expect_err("no through")
                .to_string();
            assert!(
                refused.contains("\"through\"") && refused.contains("#7"),
                "{refused}"
            );
        }
    }

    #[test]
    fn each_stop_is_one_status_with_its_owner_cause_and_reason() {
        let status = json!({ "stops": [
            { "id": 4, "owner": "lidar", "cause": "client", "reason": "obstacle", "persists": false },
            { "id": 5, "owner": "gateway", "cause": "chassis_estop", "reason": "pressed", "persists": true },
        ]});
        let statuses = problem_statuses(&status);
        assert_eq!(statuses.len(), 2);
        assert_eq!(statuses[0].0, "scout-stop-4");
        assert_eq!(statuses[0].1.message, "STOP #4 by lidar (client): obstacle");
        assert_eq!(
            statuses[1].1.message,
            "STOP #5 by gateway (chassis_estop): pressed (its cause persists)"
        );
        assert!(problem_statuses(&json!({})).is_empty());
    }
}
