//! Gateways through zenoh: a remote reader of state and status (`scout echo --remote`, `scout
//! status --remote`) and a remote controller (`scout drive --remote`, `scout teleop
//! --remote`). The keys, the command JSON and the session settings are the contract's
//! ([`scout_interface::remote`]).

use std::time::Duration;

use scout_interface::control::DriveMode;
use zenoh::Wait;

pub use scout_interface::remote::*;

/// Reads the JSON a gateway publishes through zenoh: its state (`scout echo --remote`) or its
/// arbiter's status (`scout status --remote`), and answers its information query.
pub struct RemoteStates {
    session: zenoh::Session,
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
        Self::subscribe(settings, state_key(robot))
    }

    /// Connects as [`RemoteStates::connect`] does, subscribing to the arbiter's status of
    /// `robot` instead (published on change, and each second).
    pub fn connect_status(settings: &SessionSettings, robot: &str) -> Result<Self, RemoteError> {
        Self::subscribe(settings, status_key(robot))
    }

    fn subscribe(settings: &SessionSettings, key: String) -> Result<Self, RemoteError> {
        let session = settings.open("client")?;
        let subscriber = session
            .declare_subscriber(key)
            .wait()
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
        Ok(Self {
            session,
            subscriber,
        })
    }

    /// The information `robot`'s gateway gives on [`info_key`] (its settings, counters and
    /// remote peers' `links`), waiting at most `timeout`; `None` when nothing answered.
    pub fn info(
        &self,
        robot: &str,
        timeout: Duration,
    ) -> Result<Option<serde_json::Value>, RemoteError> {
        let replies = self
            .session
            .get(info_key(robot))
            .timeout(timeout)
            .wait()
            .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
        let Some(reply) = replies.recv_timeout(timeout).ok().flatten() else {
            return Ok(None);
        };
        let sample = reply.result().map_err(|error| {
            let text = error.payload().try_to_string().unwrap_or_default();
            RemoteError::Zenoh(format!("the information query failed: {text}"))
        })?;
        json_of(sample.payload(), "the information").map(Some)
    }

    /// The next state (or status) JSON, waiting at most `timeout`.
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
        json_of(sample.payload(), "a sample").map(Some)
    }
}

/// The JSON in `payload` (`what` names it in the error).
fn json_of(payload: &zenoh::bytes::ZBytes, what: &str) -> Result<serde_json::Value, RemoteError> {
    let text = payload
        .try_to_string()
        .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
    serde_json::from_str(&text).map_err(|e| RemoteError::Zenoh(format!("{what} is not JSON: {e}")))
}

/// Remote commands sent as a query: how long to wait for the gateway's answer.
pub const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);

/// One drive in this many goes as a query, so that its answer tells whether control still
/// holds; the others are put on the fast lane, unanswered.
const ANSWERED_EVERY: u64 = 10;

/// Answers to drives awaited at once; an older one is given up.
const MAX_PENDING_ANSWERS: usize = 8;

/// Best-effort copies an e-stop is put as, beside its query.
const ESTOP_COPIES: usize = 3;

/// An e-stop query not answered this soon is asked again...
const ESTOP_QUERY_AFTER: Duration = Duration::from_millis(150);

/// ... up to this many queries in all.
const ESTOP_QUERIES: usize = 3;

/// Drives a robot through zenoh as remote peer `peer`, as a remote operator's program would:
/// take control (a query, answered), drive (samples put on the fast lane: best effort,
/// express, dropped rather than queued), stop (put and queried: whichever arrives first
/// latches), release and relinquish (queries). The peer's name is part of each key; with
/// mutual TLS the gateway's access control binds it to the peer's certificate.
///
/// Two sessions, so two connections: the drive lane carries the puts alone (drives and
/// e-stop copies), the other every query and its answer. Over QUIC the queries' stream
/// traffic (retransmitted after a loss) otherwise shares one congestion controller with the
/// drives' datagrams and holds them back: in the VM through 100 ms and 10 % loss, 43 % of the
/// drives were accepted on one connection, 65 % on their own (BENCHMARKS.md). Over UDP it costs
/// a session; an e-stop's copies never wait behind a stream's retransmission back-off.
///
/// Control is never taken back by this type: when the gateway says it ended (a stop, a gap,
/// a release, a takeover), [`RemoteController::drive`] returns [`RemoteError::Refused`] with
/// `lost_control`, and only [`RemoteController::take_control`], called again, resumes.
pub struct RemoteController {
    /// Queries and their answers.
    session: zenoh::Session,
    /// The drive lane: puts alone.
    drives: zenoh::Session,
    robot: String,
    peer: String,
    seq: u64,
    pending: Vec<zenoh::handlers::FifoChannelHandler<zenoh::query::Reply>>,
    /// How long a query waits for its answer.
    answer_timeout: Duration,
}

impl std::fmt::Debug for RemoteController {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RemoteController")
            .field("robot", &self.robot)
            .field("peer", &self.peer)
            .field("seq", &self.seq)
            .finish_non_exhaustive()
    }
}

impl RemoteController {
    /// Connects as a zenoh client (to the gateway of `robot`, or a router) as peer `peer`.
    pub fn connect(
        settings: &SessionSettings,
        robot: &str,
        peer: &str,
    ) -> Result<Self, RemoteError> {
        let session = settings.open("client")?;
        let drives = settings.open("client")?;
        Ok(Self {
            session,
            drives,
            robot: robot.to_owned(),
            peer: peer.to_owned(),
            seq: 0,
            pending: Vec::new(),
            answer_timeout: ANSWER_TIMEOUT,
        })
    }

    /// Waits at most `timeout` for each answer from now on (default [`ANSWER_TIMEOUT`]): a
    /// program that asks again on its own, on a link that loses queries, waits less.
    pub fn set_answer_timeout(&mut self, timeout: Duration) {
        self.answer_timeout = timeout;
    }

    /// Takes control as `class` (a query; the gateway's answer returned).
    pub fn take_control(&mut self, class: crate::Class) -> Result<RemoteAnswer, RemoteError> {
        let command = RemoteCommand {
            class: Some(class.name().to_owned()),
            sent_ms: Some(now_ms()),
            ..RemoteCommand::default()
        };
        self.pending.clear();
        self.ask(RemoteKind::TakeControl, &command)
    }

    /// Drives at `linear` m/s and `angular` rad/s for at most `ttl` (send again at 20-50 Hz):
    /// put on the fast lane, one in [`ANSWERED_EVERY`] as a query. Returns the newest answer
    /// that arrived meanwhile (if any), or [`RemoteError::Refused`] once one says control
    /// ended.
    pub fn drive(
        &mut self,
        linear: f64,
        angular: f64,
        ttl: Duration,
    ) -> Result<Option<RemoteAnswer>, RemoteError> {
        self.drive_body(linear, 0.0, angular, ttl)
    }

    /// Drives at a body velocity (`linear` m/s forward, `lateral` m/s leftward, `angular`
    /// rad/s) as [`RemoteController::drive`] does; a chassis that does not move sideways
    /// refuses a `lateral` other than zero (a queried drive's answer says so).
    pub fn drive_body(
        &mut self,
        linear: f64,
        lateral: f64,
        angular: f64,
        ttl: Duration,
    ) -> Result<Option<RemoteAnswer>, RemoteError> {
        self.drive_command(linear, lateral, angular, ttl, None)
    }

    /// [`RemoteController::drive_body`] in motion mode `mode`, on a chassis that has them (a
    /// Ranger; [`DriveMode::Park`] with zero velocity parks it).
    pub fn drive_in_mode(
        &mut self,
        mode: DriveMode,
        linear: f64,
        lateral: f64,
        angular: f64,
        ttl: Duration,
    ) -> Result<Option<RemoteAnswer>, RemoteError> {
        self.drive_command(linear, lateral, angular, ttl, Some(mode))
    }

    fn drive_command(
        &mut self,
        linear: f64,
        lateral: f64,
        angular: f64,
        ttl: Duration,
        mode: Option<DriveMode>,
    ) -> Result<Option<RemoteAnswer>, RemoteError> {
        self.seq += 1;
        let command = RemoteCommand {
            seq: Some(self.seq),
            sent_ms: Some(now_ms()),
            linear: Some(linear),
            lateral: (lateral != 0.0).then_some(lateral),
            angular: Some(angular),
            ttl_ms: Some(u32::try_from(ttl.as_millis()).unwrap_or(u32::MAX)),
            mode: mode.map(|mode| mode.name().to_owned()),
            ..RemoteCommand::default()
        };
        let payload = to_json(&command);
        if self.seq % ANSWERED_EVERY == 1 {
            if self.pending.len() >= MAX_PENDING_ANSWERS {
                self.pending.remove(0);
            }
            let replies = self
                .session
                .get(command_key(&self.robot, RemoteKind::Drive, &self.peer))
                .payload(payload)
                .timeout(self.answer_timeout)
                .wait()
                .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
            self.pending.push(replies);
        } else {
            self.put(RemoteKind::Drive, payload)?;
        }
        let mut newest = None;
        let mut error = None;
        self.pending.retain(|replies| match replies.try_recv() {
            Ok(Some(reply)) => {
                let answer = answer_of(&reply);
                if answer.lost_control {
                    error = Some(RemoteError::Refused {
                        command: RemoteKind::Drive,
                        answer: answer.clone(),
                    });
                }
                newest = Some(answer);
                false
            }
            Ok(None) => true,
            Err(_) => false,
        });
        match error {
            Some(error) => {
                self.pending.clear();
                Err(error)
            }
            None => Ok(newest),
        }
    }

    /// Latches a stop owned by this peer: put as best-effort copies and queried, so that it
    /// latches from whichever arrives first, once (the copies carry the same `seq` and
    /// `sent_ms`, and the gateway answers a later one as the stop the first latched). Returns
    /// the query's answer.
    pub fn stop(&mut self, reason: &str) -> Result<RemoteAnswer, RemoteError> {
        self.seq += 1;
        let command = RemoteCommand {
            seq: Some(self.seq),
            sent_ms: Some(now_ms()),
            reason: Some(reason.to_owned()),
            ..RemoteCommand::default()
        };
        let payload = to_json(&command);
        for _ in 0..ESTOP_COPIES {
            // A copy that cannot be sent leaves the query to carry the stop.
            let _ = self.put(RemoteKind::Estop, payload.clone());
        }
        self.ask(RemoteKind::Estop, &command)
    }

    /// Releases this peer's own stops latched up to stop `through` (the status's
    /// `newest_stop`; `None`: all of them). Nothing moves until control is taken again.
    pub fn release(&mut self, through: Option<u64>) -> Result<RemoteAnswer, RemoteError> {
        let command = RemoteCommand {
            through,
            ..RemoteCommand::default()
        };
        self.ask(RemoteKind::Release, &command)
    }

    /// Gives up control: the output ramps to zero.
    pub fn relinquish(&mut self) -> Result<RemoteAnswer, RemoteError> {
        self.pending.clear();
        self.ask(RemoteKind::Relinquish, &RemoteCommand::default())
    }

    /// Puts `payload` on the fast lane: best effort, express, dropped rather than queued.
    ///
    /// Each put names its key in full. A declared publisher would make zenoh send the key once
    /// as a declaration and then a number for it, in every put and in every query on that key
    /// too; over a lossy link the declaration can be lost (plain UDP) or overtaken (QUIC's
    /// streams), and the gateway's zenoh then drops those messages ("unknown scope"): the
    /// netem bench lost an e-stop, query and copies, that way.
    fn put(&self, kind: RemoteKind, payload: String) -> Result<(), RemoteError> {
        self.drives
            .put(command_key(&self.robot, kind, &self.peer), payload)
            .encoding(zenoh::bytes::Encoding::APPLICATION_JSON)
            .congestion_control(zenoh::qos::CongestionControl::Drop)
            .reliability(zenoh::qos::Reliability::BestEffort)
            .priority(zenoh::qos::Priority::RealTime)
            .express(true)
            .wait()
            .map_err(|e| RemoteError::Zenoh(e.to_string()))
    }

    /// Sends `command` as a query and waits for the answer: accepted, or
    /// [`RemoteError::Refused`]. An e-stop not answered within [`ESTOP_QUERY_AFTER`] is asked
    /// again, the same bytes, up to [`ESTOP_QUERIES`] in all, and put again on the drive lane
    /// with each (over plain UDP a query or its answer can be lost; over QUIC a query can wait
    /// behind its stream's retransmission back-off, where a datagram does not; a repeated stop
    /// only refreshes the same stop): the first answer is the answer. Nothing else is
    /// repeated: a copy of a take-control that arrives after the first was answered could
    /// grant control after that control was used and given up, or after the take was refused,
    /// and the bridge would then attach it to drives still streaming.
    fn ask(
        &mut self,
        kind: RemoteKind,
        command: &RemoteCommand,
    ) -> Result<RemoteAnswer, RemoteError> {
        let queries = match kind {
            RemoteKind::Estop => ESTOP_QUERIES,
            RemoteKind::Drive
            | RemoteKind::TakeControl
            | RemoteKind::Relinquish
            | RemoteKind::Release
            | RemoteKind::Resume
            | RemoteKind::Lights
            | RemoteKind::ClearFault => 1,
        };
        let payload = to_json(command);
        let start = std::time::Instant::now();
        let mut asked = Vec::new();
        let reply = loop {
            if asked.len() < queries && start.elapsed() >= ESTOP_QUERY_AFTER * asked.len() as u32 {
                if !asked.is_empty() {
                    // A copy that cannot be sent leaves the query to carry the stop.
                    let _ = self.put(kind, payload.clone());
                }
                let replies = self
                    .session
                    .get(command_key(&self.robot, kind, &self.peer))
                    .payload(payload.clone())
                    .timeout(self.answer_timeout)
                    .wait()
                    .map_err(|e| RemoteError::Zenoh(e.to_string()))?;
                asked.push(Some(replies));
            }
            let mut reply = None;
            for slot in &mut asked {
                match slot.as_ref().map(|replies| replies.try_recv()) {
                    Some(Ok(Some(answer))) => reply = Some(answer),
                    Some(Ok(None)) | None => {}
                    // Finished unanswered: nothing (no gateway of that name) answers it.
                    Some(Err(_)) => *slot = None,
                }
            }
            if let Some(reply) = reply {
                break reply;
            }
            let finished = asked.len() == queries && asked.iter().all(Option::is_none);
            if finished || start.elapsed() > self.answer_timeout + Duration::from_secs(1) {
                return Err(RemoteError::NoAnswer {
                    command: kind,
                    // In whole ms, for people.
                    timeout: Duration::from_millis(start.elapsed().as_millis() as u64)
                        .min(self.answer_timeout),
                });
            }
            std::thread::sleep(Duration::from_millis(2));
        };
        let answer = answer_of(&reply);
        if answer.accepted {
            Ok(answer)
        } else {
            Err(RemoteError::Refused {
                command: kind,
                answer,
            })
        }
    }
}

/// This host's clock for `sent_ms`: the gateway learns its offset.
fn now_ms() -> u64 {
    crate::monotonic_ns() / 1_000_000
}

fn to_json(command: &RemoteCommand) -> String {
    // A command of plain fields always serializes.
    serde_json::to_string(command).unwrap_or_default()
}

/// The gateway's answer in a reply; an error reply or a payload that is no answer, as a
/// rejection saying so.
fn answer_of(reply: &zenoh::query::Reply) -> RemoteAnswer {
    let sample = match reply.result() {
        Ok(sample) => sample,
        Err(error) => {
            let text = error.payload().try_to_string().unwrap_or_default();
            return RemoteAnswer::rejected(format!("an error reply: {text}"));
        }
    };
    let text = sample.payload().try_to_string().unwrap_or_default();
    serde_json::from_str(&text)
        .unwrap_or_else(|error| RemoteAnswer::rejected(format!("not an answer ({error}): {text}")))
}
