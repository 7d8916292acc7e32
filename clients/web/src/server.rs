//! The driver around the sans-IO parts: a listening socket, a thread per page (its WebSocket,
//! its stops) and one per driving page (its control requests, newest drive only), and the
//! gateway's state and status turned into JSON for every page.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, mpsc};
use std::time::{Duration, Instant};

use scout_clients::client::{ClientError, Robot};
use scout_clients::control::{ControlError, Controller, Stopper};
use scout_interface::control::{Class, ReleaseTarget, Request};
use scout_interface::json::{state_json, status_json};
use scout_interface::services::{monotonic, monotonic_ns};
use serde_json::{Value, json};
use tracing::{debug, info, warn};
use tungstenite::protocol::{Role as WsRole, WebSocket};
use tungstenite::{Error as WsError, Message as WsMessage};

use crate::access::{self, Role, Users};
use crate::http::{self, Head, HeadError, MAX_HEAD_BYTES};
use crate::page::INDEX_HTML;
use crate::session::{Action, MAX_MESSAGE_BYTES, Session};
use crate::tls::Tls;

/// Pages (WebSockets) served at once; more are answered 503.
pub const MAX_PAGES: usize = 16;

/// Connections open at once (pages, and browsers' requests and idle pre-connections); more
/// are closed at once.
pub const MAX_CONNECTIONS: usize = 64;

/// How long a browser may take to send its request head once it began.
const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// How long a connection may stay open before it sends anything. Browsers open connections
/// ahead of need and keep them unused for up to 10 s (Chromium): one closed sooner, or
/// answered, would be the answer to the request the browser sends on it later.
const IDLE_TIMEOUT: Duration = Duration::from_secs(20);

/// How often a page's thread looks for its messages and for news to send it.
const PAGE_TICK: Duration = Duration::from_millis(10);

/// The least time between two states sent to a page (the gateway publishes at 50 Hz).
const STATE_EVERY: Duration = Duration::from_millis(50);

/// The least time between two statuses sent to a page.
const STATUS_EVERY: Duration = Duration::from_millis(100);

/// A gateway silent this long is shown as silent.
const SILENT_AFTER: Duration = Duration::from_millis(500);

/// A write to a page that takes longer closes it (its driving stops with it).
const WRITE_TIMEOUT: Duration = Duration::from_secs(2);

/// What `scout web` serves.
#[derive(Debug, Clone)]
pub struct WebOptions {
    /// The robot (gateway) name.
    pub robot: String,
    /// Where to listen.
    pub listen: SocketAddr,
    /// Who may connect.
    pub users: Users,
    /// TLS (needed beyond loopback).
    pub tls: Option<Tls>,
}

/// Why serving failed.
#[derive(Debug, thiserror::Error)]
pub enum WebError {
    /// The address cannot be listened on.
    #[error("cannot listen on {listen}: {source}")]
    Listen {
        /// The address.
        listen: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
    /// Not a loopback address, without TLS.
    #[error(
        "listening on {0} without TLS would send the page's tokens and commands in clear over \
         the network: give --tls-self-signed DIR (a certificate made there on first start) or \
         --tls-cert FILE --tls-key FILE, or listen on 127.0.0.1 and tunnel (ssh -L \
         8090:127.0.0.1:8090 ROBOT)"
    )]
    NeedsTls(SocketAddr),
    /// The gateway could not be read.
    #[error(transparent)]
    Gateway(#[from] ClientError),
}

/// What every page is sent: the newest state and status as JSON, or why there is none.
#[derive(Debug, Default)]
struct Feed {
    /// Bumped on every change.
    generation: u64,
    state: Option<Arc<str>>,
    status: Option<Arc<str>>,
    /// Why no state comes (the gateway is silent).
    silent: Option<String>,
}

/// The server.
#[derive(Debug)]
pub struct Server {
    listener: TcpListener,
    robot: Robot,
    options: WebOptions,
}

impl Server {
    /// Binds the address (loopback only) and connects to the gateway: fails at once when it
    /// cannot listen there, or no gateway runs.
    pub fn bind(options: WebOptions) -> Result<Server, WebError> {
        if !options.listen.ip().is_loopback() && options.tls.is_none() {
            return Err(WebError::NeedsTls(options.listen));
        }
        let listener = TcpListener::bind(options.listen).map_err(|source| WebError::Listen {
            listen: options.listen,
            source,
        })?;
        let robot = Robot::connect(&options.robot)?;
        Ok(Server {
            listener,
            robot,
            options,
        })
    }

    /// The address pages connect to.
    pub fn address(&self) -> SocketAddr {
        self.listener.local_addr().unwrap_or(self.options.listen)
    }

    /// Serves until `stop` is set. A gateway that goes silent is shown silent to every page and
    /// connected to again (a restarted gateway has services of its own).
    pub fn run(self, stop: &AtomicBool) -> Result<(), WebError> {
        let feed = Arc::new((Mutex::new(Feed::default()), Condvar::new()));
        let open = Arc::new(Open::default());
        let listener = self.listener;
        listener
            .set_nonblocking(true)
            .map_err(|source| WebError::Listen {
                listen: self.options.listen,
                source,
            })?;
        let options = Arc::new(self.options);
        let mut source = Some(Source::of(self.robot)?);
        let mut last_state = Instant::now();
        let mut last_attempt = Instant::now();
        while !stop.load(Ordering::Relaxed) {
            loop {
                match listener.accept() {
                    Ok((stream, peer)) => accept(stream, peer, &options, &feed, &open),
                    Err(error) if error.kind() == std::io::ErrorKind::WouldBlock => break,
                    Err(error) => {
                        warn!("accepting a connection failed: {error}");
                        break;
                    }
                }
            }
            if last_state.elapsed() > RECONNECT_AFTER && last_attempt.elapsed() > RECONNECT_AFTER {
                last_attempt = Instant::now();
                match Robot::connect(&options.robot).and_then(Source::of) {
                    Ok(fresh) => source = Some(fresh),
                    Err(error) => debug!("connecting to gateway {} again: {error}", options.robot),
                }
            }
            let changed = match source.as_ref().map(Source::read) {
                Some(Ok(changed)) => changed,
                Some(Err(error)) => {
                    warn!(
                        "reading gateway {}: {error}; connecting again",
                        options.robot
                    );
                    source = None;
                    None
                }
                None => {
                    std::thread::sleep(Duration::from_millis(20));
                    None
                }
            };
            if changed.as_ref().is_some_and(|feed| feed.state.is_some()) {
                last_state = Instant::now();
            }
            let silent = (last_state.elapsed() > SILENT_AFTER).then(|| {
                format!(
                    "no state from gateway {} for {:.1} s: is scout-gateway running?",
                    options.robot,
                    last_state.elapsed().as_secs_f64()
                )
            });
            let (lock, wake) = &*feed;
            let mut current = lock.lock().unwrap_or_else(|poison| poison.into_inner());
            let silent_changed = current.silent.is_some() != silent.is_some();
            if let Some(changed) = changed {
                current.state = changed.state.or(current.state.take());
                current.status = changed.status.or(current.status.take());
            } else if !silent_changed {
                continue;
            }
            if silent_changed && let Some(silent) = &silent {
                warn!("{silent}");
            }
            current.silent = silent;
            current.generation += 1;
            wake.notify_all();
        }
        Ok(())
    }
}

/// A silent gateway is connected to again this often.
const RECONNECT_AFTER: Duration = Duration::from_secs(2);

/// The gateway's state and status.
#[derive(Debug)]
struct Source {
    state: scout_clients::client::StateSubscriber,
    status: scout_clients::control::StatusReader,
    _robot: Robot,
}

impl Source {
    fn of(robot: Robot) -> Result<Source, ClientError> {
        Ok(Source {
            state: robot.subscribe()?,
            status: robot.status()?,
            _robot: robot,
        })
    }

    /// Waits a little for the next state; the newest state and status as JSON, if any came.
    fn read(&self) -> Result<Option<Feed>, ClientError> {
        let mut changed = None;
        if let Some(first) = self.state.next_timeout(Duration::from_millis(20))? {
            let latest = self.state.try_latest()?.unwrap_or(first);
            changed.get_or_insert_with(Feed::default).state = Some(
                json!({"type": "state", "state": state_json(&latest, monotonic_ns())})
                    .to_string()
                    .into(),
            );
        }
        if let Some(latest) = self.status.latest(Duration::ZERO)? {
            changed.get_or_insert_with(Feed::default).status = Some(
                json!({"type": "status", "status": status_json(&latest, monotonic_ns())})
                    .to_string()
                    .into(),
            );
        }
        Ok(changed)
    }
}

/// Counts of what is open.
#[derive(Debug, Default)]
struct Open {
    connections: AtomicUsize,
    pages: AtomicUsize,
}

/// Takes a new connection: a thread of its own, or closed when [`MAX_CONNECTIONS`] are open.
fn accept(
    stream: TcpStream,
    peer: SocketAddr,
    options: &Arc<WebOptions>,
    feed: &Arc<(Mutex<Feed>, Condvar)>,
    open: &Arc<Open>,
) {
    if open.connections.fetch_add(1, Ordering::SeqCst) >= MAX_CONNECTIONS {
        open.connections.fetch_sub(1, Ordering::SeqCst);
        warn!("{peer}: closed at once: {MAX_CONNECTIONS} connections are open already");
        return;
    }
    let (options, feed, open) = (options.clone(), feed.clone(), open.clone());
    let spawned = std::thread::Builder::new()
        .name("scout-web page".into())
        .spawn(move || {
            if let Err(error) = serve(stream, peer, &options, &feed, &open) {
                debug!("{peer}: {error}");
            }
            open.connections.fetch_sub(1, Ordering::SeqCst);
        });
    if let Err(error) = spawned {
        warn!("{peer}: no thread for it: {error}");
    }
}

/// Sets the connection up (its TLS, where there is) and answers it.
fn serve(
    stream: TcpStream,
    peer: SocketAddr,
    options: &WebOptions,
    feed: &(Mutex<Feed>, Condvar),
    open: &Open,
) -> std::io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    stream.set_write_timeout(Some(WRITE_TIMEOUT))?;
    // Timeouts are set on the socket through this handle, whatever is layered on it.
    let socket = stream.try_clone()?;
    match &options.tls {
        None => respond(stream, &socket, peer, options, feed, open),
        Some(tls) => {
            let connection =
                rustls::ServerConnection::new(tls.config.clone()).map_err(std::io::Error::other)?;
            respond(
                rustls::StreamOwned::new(connection, stream),
                &socket,
                peer,
                options,
                feed,
                open,
            )
        }
    }
}

/// Reads the request head and answers it: the page, its WebSocket, or a refusal.
fn respond<S: Read + Write>(
    mut stream: S,
    socket: &TcpStream,
    peer: SocketAddr,
    options: &WebOptions,
    feed: &(Mutex<Feed>, Condvar),
    open: &Open,
) -> std::io::Result<()> {
    let mut deadline = Instant::now() + IDLE_TIMEOUT;
    let mut buffer = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    let head = loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() && buffer.is_empty() {
            // Never used: closed without a word (see IDLE_TIMEOUT).
            return Ok(());
        }
        if left.is_zero() {
            return send(
                &mut stream,
                &http::refusal(400, "the request head took too long"),
            );
        }
        socket.set_read_timeout(Some(left))?;
        let read = match stream.read(&mut chunk) {
            Ok(0) => return Ok(()),
            Ok(read) => {
                if buffer.is_empty() {
                    deadline = Instant::now() + HEAD_TIMEOUT;
                }
                read
            }
            Err(error) if is_timeout(&error) => continue,
            Err(error) => return Err(error),
        };
        buffer.extend_from_slice(
            &chunk[..read.min(MAX_HEAD_BYTES + 1 - buffer.len().min(MAX_HEAD_BYTES))],
        );
        match Head::parse(&buffer) {
            Ok((head, _)) => break head,
            Err(HeadError::Partial) => continue,
            Err(error @ HeadError::TooLong) => {
                return send(&mut stream, &http::refusal(431, &error.to_string()));
            }
            Err(error) => return send(&mut stream, &http::refusal(400, &error.to_string())),
        }
    };
    if head.method != "GET" {
        return send(&mut stream, &http::refusal(405, "only GET is served"));
    }
    match head.path.as_str() {
        "/" | "/index.html" => send(
            &mut stream,
            &http::response(200, "OK", "text/html; charset=utf-8", INDEX_HTML.as_bytes()),
        ),
        "/ws" if head.is_websocket() => {
            let scheme = if options.tls.is_some() {
                "https"
            } else {
                "http"
            };
            let user = match access::admit(&head, &options.users, scheme) {
                Ok(user) => user.clone(),
                Err(refusal) => {
                    info!(
                        "{peer}: WebSocket refused ({}): {}",
                        refusal.status, refusal.reason
                    );
                    return send(&mut stream, &http::refusal(refusal.status, &refusal.reason));
                }
            };
            if open.pages.fetch_add(1, Ordering::SeqCst) >= MAX_PAGES {
                open.pages.fetch_sub(1, Ordering::SeqCst);
                warn!(
                    "{peer}: page of web:{} refused: {MAX_PAGES} pages are open",
                    user.name
                );
                return send(
                    &mut stream,
                    &http::refusal(
                        503,
                        &format!("{MAX_PAGES} pages are open already: close one"),
                    ),
                );
            }
            let key = head.header("sec-websocket-key").unwrap_or("");
            let outcome = send(&mut stream, &http::switching_protocols(key))
                .and_then(|()| socket.set_read_timeout(Some(PAGE_TICK)))
                .and_then(|()| {
                    info!(
                        "{peer}: page of web:{} ({}) connected",
                        user.name, user.role
                    );
                    page(
                        stream,
                        peer,
                        options,
                        feed,
                        Session::new(user.clone(), monotonic()),
                    )
                });
            open.pages.fetch_sub(1, Ordering::SeqCst);
            info!("{peer}: page of web:{} closed", user.name);
            outcome
        }
        _ => send(
            &mut stream,
            &http::refusal(404, "not here: the page is at /"),
        ),
    }
}

/// Writes `bytes` and flushes them (through TLS, where there is).
fn send(stream: &mut impl Write, bytes: &[u8]) -> std::io::Result<()> {
    stream.write_all(bytes)?;
    stream.flush()
}

fn is_timeout(error: &std::io::Error) -> bool {
    matches!(
        error.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}

/// What waits for a page's control thread: in order, a waiting drive replaced by a newer one.
#[derive(Debug, Default)]
struct Pending {
    actions: VecDeque<Action>,
    closed: bool,
    superseded: u64,
}

type Slot = Arc<(Mutex<Pending>, Condvar)>;

/// One page's WebSocket: its messages through its session, stops at once on this thread,
/// control requests to its control thread; the feed sent to it as it changes.
fn page<S: Read + Write>(
    stream: S,
    peer: SocketAddr,
    options: &WebOptions,
    feed: &(Mutex<Feed>, Condvar),
    mut session: Session,
) -> std::io::Result<()> {
    let mut config = tungstenite::protocol::WebSocketConfig::default();
    config.max_message_size = Some(MAX_MESSAGE_BYTES * 4);
    config.max_frame_size = Some(MAX_MESSAGE_BYTES * 4);
    let mut socket = WebSocket::from_raw_socket(stream, WsRole::Server, Some(config));
    let user = session.user().clone();
    let client = user.client_name();
    let mut stopper = match Stopper::new(&options.robot, &client) {
        Ok(stopper) => Some(stopper),
        Err(error) => {
            warn!("{peer}: no stop client for {client}: {error}");
            None
        }
    };
    let (answers, answered) = mpsc::channel::<Value>();
    let slot: Slot = Arc::default();
    let control = (user.role >= Role::Drive).then(|| {
        let (robot, client, slot, answers) = (
            options.robot.clone(),
            client.clone(),
            slot.clone(),
            answers.clone(),
        );
        std::thread::Builder::new()
            .name("scout-web control".into())
            .spawn(move || control_thread(&robot, &client, &slot, &answers))
    });
    let hello = json!({"type": "hello", "user": user.name, "client": client, "role": user.role.name(), "robot": options.robot});
    let mut seen = 0;
    let mut last_state_sent = Instant::now() - STATE_EVERY;
    let mut pending_state: Option<Arc<str>> = None;
    let mut last_status_sent = Instant::now() - STATUS_EVERY;
    let mut pending_status: Option<Arc<str>> = None;
    let outcome = (|| -> Result<(), WsError> {
        socket.send(WsMessage::text(hello.to_string()))?;
        loop {
            match socket.read() {
                Ok(WsMessage::Text(text)) => {
                    let now = monotonic();
                    let answer = match session.handle_message(now, text.as_str()) {
                        Ok(Action::Stop { reason }) => {
                            Some(stop(&mut stopper, &client, peer, &reason))
                        }
                        Ok(Action::Release { through }) => {
                            Some(release(&mut stopper, &client, peer, through))
                        }
                        Ok(action) => {
                            hand_over(&slot, action);
                            None
                        }
                        Err(refused) => {
                            // The first of each kind at info, the rest counted (a lossy link
                            // refuses late drives 20 times a second) and summed up at close.
                            let kind = refused.kind();
                            match session.refused().find(|(k, _)| *k == kind) {
                                Some((_, 1)) => {
                                    info!("{peer}: web:{}: refused: {refused}", user.name);
                                }
                                _ => debug!("{peer}: web:{}: refused: {refused}", user.name),
                            }
                            Some(
                                json!({"type": "answer", "op": "message", "ok": false, "error": refused.to_string()}),
                            )
                        }
                    };
                    if let Some(answer) = answer {
                        socket.send(WsMessage::text(answer.to_string()))?;
                    }
                }
                Ok(WsMessage::Close(_)) => return Ok(()),
                Ok(_) => {}
                Err(WsError::Io(error)) if is_timeout(&error) => {}
                Err(error) => return Err(error),
            }
            while let Ok(answer) = answered.try_recv() {
                socket.send(WsMessage::text(answer.to_string()))?;
            }
            let (lock, _) = feed;
            let news = {
                let current = lock.lock().unwrap_or_else(|poison| poison.into_inner());
                (current.generation != seen).then(|| {
                    seen = current.generation;
                    (
                        current.state.clone(),
                        current.status.clone(),
                        current.silent.clone(),
                    )
                })
            };
            if let Some((state, status, silent)) = news {
                if let Some(silent) = silent {
                    socket.send(WsMessage::text(
                        json!({"type": "silent", "reason": silent}).to_string(),
                    ))?;
                } else if state.is_some() {
                    pending_state = state;
                }
                if status.is_some() {
                    pending_status = status;
                }
            }
            if last_status_sent.elapsed() >= STATUS_EVERY
                && let Some(status) = pending_status.take()
            {
                last_status_sent = Instant::now();
                socket.send(WsMessage::text(status.to_string()))?;
            }
            if last_state_sent.elapsed() >= STATE_EVERY
                && let Some(state) = pending_state.take()
            {
                last_state_sent = Instant::now();
                socket.send(WsMessage::text(state.to_string()))?;
            }
        }
    })();
    let refused: Vec<String> = session
        .refused()
        .map(|(kind, count)| format!("{kind} {count}"))
        .collect();
    if !refused.is_empty() {
        info!(
            "{peer}: web:{}: messages refused on this page: {}",
            user.name,
            refused.join(", ")
        );
    }
    if let Some(action) = session.handle_close() {
        info!("{peer}: web:{}: page gone, giving up control", user.name);
        hand_over(&slot, action);
    }
    {
        let (lock, wake) = &*slot;
        lock.lock()
            .unwrap_or_else(|poison| poison.into_inner())
            .closed = true;
        wake.notify_all();
    }
    if let Some(Ok(control)) = control {
        let _ = control.join();
    }
    match outcome {
        Ok(()) | Err(WsError::ConnectionClosed | WsError::AlreadyClosed) => Ok(()),
        Err(WsError::Io(error)) => Err(error),
        Err(error) => Err(std::io::Error::other(error.to_string())),
    }
}

/// Queues `action` for the control thread; a waiting drive is replaced by a newer one.
fn hand_over(slot: &Slot, action: Action) {
    let (lock, wake) = &**slot;
    let mut pending = lock.lock().unwrap_or_else(|poison| poison.into_inner());
    if matches!(action, Action::Drive { .. })
        && matches!(pending.actions.back(), Some(Action::Drive { .. }))
    {
        pending.actions.pop_back();
        pending.superseded += 1;
    }
    pending.actions.push_back(action);
    wake.notify_all();
}

fn answer_of(op: &str, result: &Result<scout_interface::control::Accepted, ControlError>) -> Value {
    match result {
        Ok(accepted) => {
            json!({"type": "answer", "op": op, "ok": true, "stop": accepted.stop, "lease": accepted.lease})
        }
        Err(error) => json!({"type": "answer", "op": op, "ok": false, "error": error.to_string(),
                             "lost": error.lost_control()}),
    }
}

/// The E-STOP: a stop owned by the page's user, latched now on this thread.
fn stop(stopper: &mut Option<Stopper>, client: &str, peer: SocketAddr, reason: &str) -> Value {
    let result = match stopper {
        Some(stopper) => stopper.stop(reason),
        None => Err(ControlError::Client(ClientError::BadClientName(
            client.to_owned(),
        ))),
    };
    match &result {
        Ok(accepted) => info!(
            "{peer}: {client}: E-STOP latched stop #{}: {reason}",
            accepted.stop.unwrap_or(0)
        ),
        Err(error) => warn!("{peer}: {client}: E-STOP NOT latched: {error}"),
    }
    answer_of("estop", &result)
}

/// Releases the user's own stops up to `through`.
fn release(stopper: &mut Option<Stopper>, client: &str, peer: SocketAddr, through: u64) -> Value {
    let result = match stopper {
        Some(stopper) => stopper.release(ReleaseTarget::Own, through),
        None => Err(ControlError::Client(ClientError::BadClientName(
            client.to_owned(),
        ))),
    };
    info!(
        "{peer}: {client}: release of its own stops through #{through}: {}",
        match &result {
            Ok(_) => "done".to_owned(),
            Err(error) => error.to_string(),
        }
    );
    answer_of("release", &result)
}

/// A driving page's control requests, in order, as `web:USER` with the teleop class. The
/// control client is made at the first take, and made again at the next take after a take
/// failed (a gateway restarted since has new services).
fn control_thread(robot: &str, client: &str, slot: &Slot, answers: &mpsc::Sender<Value>) {
    let connect = || -> Result<(Robot, Controller), ClientError> {
        let robot = Robot::connect(robot)?;
        let controller = robot.controller(client, Some(Class::Teleop))?;
        Ok((robot, controller))
    };
    let mut control: Option<(Robot, Controller)> = None;
    let mut drives_refused = 0u64;
    loop {
        let action = {
            let (lock, wake) = &**slot;
            let mut pending = lock.lock().unwrap_or_else(|poison| poison.into_inner());
            loop {
                if let Some(action) = pending.actions.pop_front() {
                    break Some(action);
                }
                if pending.closed {
                    break None;
                }
                pending = wake
                    .wait(pending)
                    .unwrap_or_else(|poison| poison.into_inner());
            }
        };
        let Some(action) = action else {
            if drives_refused > 0 {
                info!("{client}: {drives_refused} drives of this page refused by the gateway");
            }
            return;
        };
        match action {
            Action::TakeControl => {
                let result = match &mut control {
                    Some((_, controller)) => controller.take_control(),
                    None => connect().map_err(ControlError::Client).and_then(
                        |(robot, mut controller)| {
                            let result = controller.take_control();
                            control = Some((robot, controller));
                            result
                        },
                    ),
                };
                match &result {
                    Ok(_) => info!("{client}: took control"),
                    Err(error) => {
                        info!("{client}: take control refused: {error}");
                        if !matches!(error, ControlError::Rejected(_)) {
                            // Not the arbiter's answer: the gateway is gone or new.
                            control = None;
                        }
                    }
                }
                let _ = answers.send(answer_of("take", &result));
            }
            Action::Relinquish => {
                if let Some((_, controller)) = &mut control
                    && controller.lease().is_some()
                {
                    let result = controller.relinquish();
                    info!("{client}: gave up control");
                    let _ = answers.send(answer_of("relinquish", &result));
                }
            }
            Action::Drive {
                linear,
                angular,
                sent,
                ttl,
            } => {
                let Some((_, controller)) = &mut control else {
                    continue;
                };
                let Some(lease) = controller.lease() else {
                    continue;
                };
                let request = Request::Drive {
                    lease,
                    linear,
                    angular,
                    ttl: Some(ttl),
                };
                let result = controller.request_sent_at(&request, sent);
                if let Err(error) = &result {
                    drives_refused += 1;
                    debug!("{client}: drive refused ({drives_refused} so far): {error}");
                    if error.lost_control() {
                        info!("{client}: lost control: {error}");
                        let _ = answers.send(answer_of("drive", &result));
                    }
                }
            }
            Action::Stop { .. } | Action::Release { .. } => {
                warn!(
                    "{client}: a stop or release reached the control thread: ignored (the page's thread serves them)"
                );
            }
        }
    }
}
