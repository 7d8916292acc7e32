//! The driver around the sans-IO parts, on a tokio runtime of its own. Each connection is a task:
//! its TLS and its request head within deadlines, admitted through the [`Gate`] (connections
//! that have not authenticated give way, oldest first, to new ones). Each page's WebSocket is
//! split in two that never wait on each other: a reader whose stops go out at once (on the
//! page's stop thread) and a writer that sends the answers, then the newest state and status or
//! nothing, to a page that reads slowly. Around them: a thread reading the gateway, and one per
//! driving page for its control requests (newest drive only).

use std::collections::{HashMap, VecDeque};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex, mpsc as std_mpsc};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use scout_clients::client::{ClientError, Robot};
use scout_clients::control::{ControlError, Controller, Stopper};
use scout_clients::failure::{Failure, FailureKind};
use scout_interface::control::{Class, ReleaseTarget, Request};
use scout_interface::json::{state_json, status_json};
use scout_interface::services::{monotonic, monotonic_ns};
use serde_json::{Value, json};
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::{mpsc, oneshot, watch};
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;
use tokio_tungstenite::tungstenite::protocol::{CloseFrame, Role as WsRole, WebSocketConfig};
use tokio_tungstenite::tungstenite::{Error as WsError, Message as WsMessage};
use tracing::{debug, info, warn};

use crate::access::{self, Role, Users};
use crate::gate::{Admit, ConnId, Gate};
use crate::http::{self, Head, HeadError, MAX_HEAD_BYTES};
use crate::page::INDEX_HTML;
use crate::session::{Action, MAX_MESSAGE_BYTES, Session};
use crate::tls::Tls;

/// Pages (WebSockets) served at once; more are told so and closed.
pub const MAX_PAGES: usize = 16;

/// How long a TLS handshake may take.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(5);

/// How long a browser may take to send its request head once it began.
const HEAD_TIMEOUT: Duration = Duration::from_secs(5);

/// How long a connection may stay open before it sends anything. Browsers open connections
/// ahead of need and keep them unused for up to 10 s (Chromium): one closed sooner, or
/// answered, would be the answer to the request the browser sends on it later. Such a
/// connection gives way to a new one when too many wait ([`Gate`]).
const IDLE_TIMEOUT: Duration = Duration::from_secs(20);

/// The least time between two states sent to a page (the gateway publishes at 50 Hz).
const STATE_EVERY: Duration = Duration::from_millis(50);

/// The least time between two statuses sent to a page.
const STATUS_EVERY: Duration = Duration::from_millis(100);

/// A gateway silent this long is shown as silent.
const SILENT_AFTER: Duration = Duration::from_millis(500);

/// A page none of whose writes went through for this long is closed: a phone that receives
/// nothing for so long is gone. Its stops were read and served all the while.
const WRITE_STALL: Duration = Duration::from_secs(20);

/// The close codes a page is told why with (the browser shows a WebSocket's close code and
/// reason to the page's script, never an HTTP refusal's).
pub mod close {
    /// No token, or a wrong one.
    pub const WRONG_TOKEN: u16 = 4401;
    /// [`super::MAX_PAGES`] pages are open.
    pub const TOO_MANY_PAGES: u16 = 4503;
}

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
    /// The runtime could not be started.
    #[error("starting the server's runtime: {0}")]
    Runtime(std::io::Error),
}

/// What every page is sent: the newest state and status as JSON, or why there is none.
#[derive(Debug, Default, Clone)]
struct Feed {
    state: Option<Arc<str>>,
    status: Option<Arc<str>>,
    /// Why no state comes (the gateway is silent).
    silent: Option<String>,
}

/// The server.
#[derive(Debug)]
pub struct Server {
    listener: std::net::TcpListener,
    robot: Robot,
    options: WebOptions,
}

/// What every connection's task shares.
#[derive(Debug)]
struct Shared {
    options: WebOptions,
    feed: watch::Receiver<Feed>,
    gate: Mutex<Gate>,
    /// How to close each connection that has not authenticated (to make room).
    evictions: Mutex<HashMap<ConnId, oneshot::Sender<()>>>,
    pages: AtomicUsize,
}

impl Server {
    /// Binds the address (loopback only) and connects to the gateway: fails at once when it
    /// cannot listen there, or no gateway runs.
    pub fn bind(options: WebOptions) -> Result<Server, WebError> {
        if !options.listen.ip().is_loopback() && options.tls.is_none() {
            return Err(WebError::NeedsTls(options.listen));
        }
        let listen = |source| WebError::Listen {
            listen: options.listen,
            source,
        };
        let listener = std::net::TcpListener::bind(options.listen).map_err(listen)?;
        listener.set_nonblocking(true).map_err(listen)?;
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
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("scout-web")
            .enable_all()
            .build()
            .map_err(WebError::Runtime)?;
        let (feed, pages_feed) = watch::channel(Feed::default());
        let robot_name = self.options.robot.clone();
        let source = Source::of(self.robot)?;
        let shared = Arc::new(Shared {
            options: self.options,
            feed: pages_feed,
            gate: Mutex::new(Gate::default()),
            evictions: Mutex::new(HashMap::new()),
            pages: AtomicUsize::new(0),
        });
        let listen = shared.options.listen;
        let listener = {
            let _entered = runtime.enter();
            tokio::net::TcpListener::from_std(self.listener)
                .map_err(|source| WebError::Listen { listen, source })?
        };
        std::thread::scope(|scope| {
            scope.spawn(|| read_gateway(&robot_name, source, &feed, stop));
            runtime.block_on(accept_loop(listener, shared, stop));
        });
        runtime.shutdown_timeout(Duration::from_secs(1));
        Ok(())
    }
}

/// A silent gateway is connected to again this often.
const RECONNECT_AFTER: Duration = Duration::from_secs(2);

/// Reads the gateway into `feed` until `stop`: its newest state and status, or why none comes.
fn read_gateway(robot: &str, source: Source, feed: &watch::Sender<Feed>, stop: &AtomicBool) {
    let mut source = Some(source);
    let mut last_state = Instant::now();
    let mut last_attempt = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        if last_state.elapsed() > RECONNECT_AFTER && last_attempt.elapsed() > RECONNECT_AFTER {
            last_attempt = Instant::now();
            match Robot::connect(robot).and_then(Source::of) {
                Ok(fresh) => source = Some(fresh),
                Err(error) => debug!("connecting to gateway {robot} again: {error}"),
            }
        }
        let changed = match source.as_ref().map(Source::read) {
            Some(Ok(changed)) => changed,
            Some(Err(error)) => {
                warn!("reading gateway {robot}: {error}; connecting again");
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
                "no state from gateway {robot} for {:.1} s: is scout-gateway running?",
                last_state.elapsed().as_secs_f64()
            )
        });
        feed.send_if_modified(|current| {
            let silent_changed = current.silent.is_some() != silent.is_some();
            if silent_changed && let Some(silent) = &silent {
                warn!("{silent}");
            }
            let Some(changed) = changed else {
                if silent_changed {
                    current.silent = silent;
                }
                return silent_changed;
            };
            current.state = changed.state.or(current.state.take());
            current.status = changed.status.or(current.status.take());
            current.silent = silent;
            true
        });
    }
}

/// Accepts connections until `stop`, each through the gate, each a task of its own.
async fn accept_loop(listener: tokio::net::TcpListener, shared: Arc<Shared>, stop: &AtomicBool) {
    let mut next_id: ConnId = 0;
    let mut tick = tokio::time::interval(Duration::from_millis(100));
    let started = Instant::now();
    loop {
        tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok((stream, peer)) => {
                    next_id += 1;
                    admit(stream, peer, next_id, &shared);
                }
                Err(error) => {
                    warn!("accepting a connection failed: {error}");
                    tokio::time::sleep(Duration::from_millis(10)).await;
                }
            },
            _ = tick.tick() => {
                if stop.load(Ordering::Relaxed) {
                    return;
                }
                let line = lock(&shared.gate).poll_log(started.elapsed());
                if let Some(line) = line {
                    info!("{line}");
                }
            }
        }
    }
}

/// A new connection through the gate (closing an older one that has not authenticated, if
/// room is needed), then served on a task of its own.
fn admit(stream: TcpStream, peer: SocketAddr, id: ConnId, shared: &Arc<Shared>) {
    let (evict, evicted) = oneshot::channel();
    let admitted = lock(&shared.gate).handle_connect(id, peer.ip());
    if let Admit::AcceptEvicting(old) = admitted
        && let Some(close) = lock(&shared.evictions).remove(&old)
    {
        let _ = close.send(());
    }
    lock(&shared.evictions).insert(id, evict);
    let shared = Arc::clone(shared);
    tokio::spawn(async move {
        let outcome = tokio::select! {
            outcome = serve(stream, peer, id, &shared) => outcome,
            // Only a send evicts: the sender dropped (the connection authenticated) does not.
            Ok(()) = evicted => {
                debug!("{peer}: closed before it authenticated, to make room for a newer connection");
                Ok(())
            }
        };
        if let Err(error) = outcome {
            debug!("{peer}: {error}");
        }
        lock(&shared.gate).handle_closed(id);
        lock(&shared.evictions).remove(&id);
    });
}

/// Locks `mutex`, whatever a panicking holder left.
fn lock<T>(mutex: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(|poison| poison.into_inner())
}

/// Sets the connection up (its TLS, where there is) and answers it.
async fn serve(
    stream: TcpStream,
    peer: SocketAddr,
    id: ConnId,
    shared: &Arc<Shared>,
) -> std::io::Result<()> {
    stream.set_nodelay(true)?;
    match &shared.options.tls {
        None => respond(stream, peer, id, shared).await,
        Some(tls) => {
            let acceptor = tokio_rustls::TlsAcceptor::from(Arc::clone(&tls.config));
            let stream = tokio::time::timeout(HANDSHAKE_TIMEOUT, acceptor.accept(stream))
                .await
                .map_err(|_| std::io::Error::other("the TLS handshake took too long"))??;
            respond(stream, peer, id, shared).await
        }
    }
}

/// Reads the request head and answers it: the page, its WebSocket, or a refusal.
async fn respond<S>(
    mut stream: S,
    peer: SocketAddr,
    id: ConnId,
    shared: &Arc<Shared>,
) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let Some(head) = read_head(&mut stream).await? else {
        return Ok(());
    };
    let head = match head {
        Ok(head) => head,
        Err(error) => {
            let status = if error == HeadError::TooLong {
                431
            } else {
                400
            };
            return send(&mut stream, &http::refusal(status, &error.to_string())).await;
        }
    };
    if head.method != "GET" {
        return send(&mut stream, &http::refusal(405, "only GET is served")).await;
    }
    match head.path.as_str() {
        "/" | "/index.html" => {
            let page = http::response(200, "OK", "text/html; charset=utf-8", INDEX_HTML.as_bytes());
            send(&mut stream, &page).await
        }
        "/ws" if head.is_websocket() => websocket(stream, &head, peer, id, shared).await,
        _ => {
            send(
                &mut stream,
                &http::refusal(404, "not here: the page is at /"),
            )
            .await
        }
    }
}

/// The request head: `None` for a connection closed, or idle past [`IDLE_TIMEOUT`], before it
/// said anything (closed without a word); past [`HEAD_TIMEOUT`] once it began, an error.
async fn read_head<S: AsyncRead + Unpin>(
    stream: &mut S,
) -> std::io::Result<Option<Result<Head, HeadError>>> {
    let mut buffer = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    let mut deadline = tokio::time::Instant::now() + IDLE_TIMEOUT;
    loop {
        let read = match tokio::time::timeout_at(deadline, stream.read(&mut chunk)).await {
            Err(_) if buffer.is_empty() => return Ok(None),
            Err(_) => {
                return Ok(Some(Err(HeadError::Malformed(
                    "the request head took too long".into(),
                ))));
            }
            Ok(Ok(0)) => return Ok(None),
            Ok(Ok(read)) => read,
            Ok(Err(error)) => return Err(error),
        };
        if buffer.is_empty() {
            deadline = tokio::time::Instant::now() + HEAD_TIMEOUT;
        }
        let room = MAX_HEAD_BYTES + 1 - buffer.len().min(MAX_HEAD_BYTES);
        buffer.extend_from_slice(&chunk[..read.min(room)]);
        match Head::parse(&buffer) {
            Ok((head, _)) => return Ok(Some(Ok(head))),
            Err(HeadError::Partial) => {}
            Err(error) => return Ok(Some(Err(error))),
        }
    }
}

/// Writes `bytes` and flushes them (through TLS, where there is).
async fn send<S: AsyncWrite + Unpin>(stream: &mut S, bytes: &[u8]) -> std::io::Result<()> {
    stream.write_all(bytes).await?;
    stream.flush().await
}

/// A page's WebSocket: refused before the upgrade for another origin (which must learn
/// nothing); otherwise upgraded, and a wrong token or a full house told by the close code (a
/// page's script sees it, where it would see nothing of an HTTP refusal), a wrong token after a
/// delay that grows with its address's guesses.
async fn websocket<S>(
    mut stream: S,
    head: &Head,
    peer: SocketAddr,
    id: ConnId,
    shared: &Arc<Shared>,
) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let scheme = if shared.options.tls.is_some() {
        "https"
    } else {
        "http"
    };
    let admitted = access::admit(head, &shared.options.users, scheme);
    if let Err(refusal) = &admitted
        && refusal.status != 401
    {
        info!(
            "{peer}: WebSocket refused ({}): {}",
            refusal.status, refusal.reason
        );
        return send(&mut stream, &http::refusal(refusal.status, &refusal.reason)).await;
    }
    let key = head.header("sec-websocket-key").unwrap_or("");
    send(&mut stream, &http::switching_protocols(key)).await?;
    let mut config = WebSocketConfig::default();
    config.max_message_size = Some(MAX_MESSAGE_BYTES * 4);
    config.max_frame_size = Some(MAX_MESSAGE_BYTES * 4);
    let mut socket = WebSocketStream::from_raw_socket(stream, WsRole::Server, Some(config)).await;
    let user = match admitted {
        Ok(user) => user.clone(),
        Err(refusal) => {
            let delay = lock(&shared.gate).handle_wrong_token(monotonic(), peer.ip());
            tokio::time::sleep(delay).await;
            debug!("{peer}: WebSocket refused: {}", refusal.reason);
            return close_with(&mut socket, close::WRONG_TOKEN, &refusal.reason).await;
        }
    };
    // A right token: this connection no longer counts against anyone, nor gives way.
    lock(&shared.gate).handle_authenticated(id);
    lock(&shared.evictions).remove(&id);
    if shared.pages.fetch_add(1, Ordering::SeqCst) >= MAX_PAGES {
        shared.pages.fetch_sub(1, Ordering::SeqCst);
        warn!(
            "{peer}: page of web:{} refused: {MAX_PAGES} pages are open",
            user.name
        );
        let reason = format!("{MAX_PAGES} pages are open already: close one");
        return close_with(&mut socket, close::TOO_MANY_PAGES, &reason).await;
    }
    info!(
        "{peer}: page of web:{} ({}) connected",
        user.name, user.role
    );
    let outcome = page(
        socket,
        peer,
        shared,
        Session::new(user.clone(), monotonic()),
    )
    .await;
    shared.pages.fetch_sub(1, Ordering::SeqCst);
    info!("{peer}: page of web:{} closed", user.name);
    outcome
}

/// Closes a WebSocket with `code` and `reason` (cut to what a close frame holds).
async fn close_with<S>(
    socket: &mut WebSocketStream<S>,
    code: u16,
    reason: &str,
) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    let mut cut = reason.len().min(120);
    while !reason.is_char_boundary(cut) {
        cut -= 1;
    }
    let frame = CloseFrame {
        code: CloseCode::from(code),
        reason: reason[..cut].to_owned().into(),
    };
    match socket.close(Some(frame)).await {
        Ok(()) | Err(WsError::ConnectionClosed | WsError::AlreadyClosed) => Ok(()),
        Err(error) => Err(std::io::Error::other(error.to_string())),
    }
}

/// What waits for a page's control thread: in order, a waiting drive replaced by a newer one.
#[derive(Debug, Default)]
struct Pending {
    actions: VecDeque<Action>,
    closed: bool,
    superseded: u64,
}

type Slot = Arc<(Mutex<Pending>, Condvar)>;

/// What a page's stop thread does.
#[derive(Debug)]
enum StopJob {
    Stop(String),
    Release(u64),
}

/// One page: its reader and its writer, side by side until the page goes, then its control
/// given up.
async fn page<S>(
    socket: WebSocketStream<S>,
    peer: SocketAddr,
    shared: &Arc<Shared>,
    mut session: Session,
) -> std::io::Result<()>
where
    S: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let options = &shared.options;
    let user = session.user().clone();
    let client = user.client_name();
    let (answers, answered) = mpsc::unbounded_channel::<Value>();
    // The stops on a thread of the page's own: a datagram and its answer, never behind a write.
    let (stops, stop_jobs) = std_mpsc::channel::<StopJob>();
    let stop_thread = {
        let (robot, client, answers) = (options.robot.clone(), client.clone(), answers.clone());
        std::thread::Builder::new()
            .name("scout-web stops".into())
            .spawn(move || stop_thread(&robot, &client, peer, &stop_jobs, &answers))?
    };
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
    let (sink, mut stream) = socket.split();
    let mut writer = tokio::spawn(write_page(
        sink,
        shared.feed.clone(),
        answered,
        hello.to_string(),
    ));
    let outcome: Result<(), WsError> = async {
        loop {
            let message = tokio::select! {
                message = stream.next() => message,
                // The writer gave up (the page stalled, or went): so does the page.
                written = &mut writer => {
                    return match written {
                        Ok(outcome) => outcome,
                        Err(error) => Err(WsError::Io(std::io::Error::other(error.to_string()))),
                    };
                }
            };
            let text = match message {
                Some(Ok(WsMessage::Text(text))) => text,
                Some(Ok(WsMessage::Close(_))) | None => return Ok(()),
                Some(Ok(_)) => continue,
                Some(Err(error)) => return Err(error),
            };
            match session.handle_message(monotonic(), text.as_str()) {
                Ok(Action::Stop { reason }) => {
                    let _ = stops.send(StopJob::Stop(reason));
                }
                Ok(Action::Release { through }) => {
                    let _ = stops.send(StopJob::Release(through));
                }
                Ok(action) => hand_over(&slot, action),
                Err(refused) => {
                    // The first of each kind at info, the rest counted (a lossy link refuses
                    // late drives 20 times a second) and summed up at close.
                    let kind = refused.kind();
                    match session.refused().find(|(k, _)| *k == kind) {
                        Some((_, 1)) => info!("{peer}: web:{}: refused: {refused}", user.name),
                        _ => debug!("{peer}: web:{}: refused: {refused}", user.name),
                    }
                    let _ = answers.send(
                        json!({"type": "answer", "op": "message", "ok": false, "error": refused.to_string()}),
                    );
                }
            }
        }
    }
    .await;
    writer.abort();
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
    drop(stops);
    // The threads end by themselves (their queue closed); waited for off the runtime.
    tokio::task::spawn_blocking(move || {
        let _ = stop_thread.join();
        if let Some(Ok(control)) = control {
            let _ = control.join();
        }
    });
    match outcome {
        Ok(()) | Err(WsError::ConnectionClosed | WsError::AlreadyClosed) => Ok(()),
        Err(WsError::Io(error)) => Err(error),
        Err(error) => Err(std::io::Error::other(error.to_string())),
    }
}

/// A page's writer: the answers first, as they come; then the newest state and status (at most
/// every [`STATE_EVERY`] and [`STATUS_EVERY`]), or nothing when the page reads slowly (what came
/// meanwhile replaces what waited). Gives up when no write went through for [`WRITE_STALL`].
async fn write_page<K>(
    mut sink: K,
    mut feed: watch::Receiver<Feed>,
    mut answers: mpsc::UnboundedReceiver<Value>,
    hello: String,
) -> Result<(), WsError>
where
    K: futures_util::Sink<WsMessage, Error = WsError> + Unpin,
{
    let write = async |sink: &mut K, text: String| -> Result<(), WsError> {
        match tokio::time::timeout(WRITE_STALL, sink.send(WsMessage::text(text))).await {
            Ok(sent) => sent,
            Err(_) => Err(WsError::Io(std::io::Error::other(format!(
                "nothing written to the page for {} s: closed",
                WRITE_STALL.as_secs()
            )))),
        }
    };
    write(&mut sink, hello).await?;
    let never = tokio::time::Instant::now() + Duration::from_secs(86_400 * 365);
    let mut state: Option<Arc<str>> = None;
    let mut status: Option<Arc<str>> = None;
    let mut silent: Option<String> = None;
    let mut silent_sent = false;
    let mut state_due = tokio::time::Instant::now();
    let mut status_due = tokio::time::Instant::now();
    feed.mark_changed();
    loop {
        let due = match (&state, &status) {
            (Some(_), Some(_)) => state_due.min(status_due),
            (Some(_), None) => state_due,
            (None, Some(_)) => status_due,
            (None, None) => never,
        };
        tokio::select! {
            biased;
            answer = answers.recv() => match answer {
                Some(answer) => write(&mut sink, answer.to_string()).await?,
                None => return Ok(()),
            },
            changed = feed.changed() => {
                if changed.is_err() {
                    return Ok(());
                }
                let current = feed.borrow_and_update().clone();
                if current.silent != silent {
                    silent_sent = false;
                }
                silent = current.silent;
                state = if silent.is_some() { None } else { current.state.or(state) };
                status = current.status.or(status);
                if let Some(reason) = &silent
                    && !silent_sent
                {
                    silent_sent = true;
                    write(&mut sink, json!({"type": "silent", "reason": reason}).to_string()).await?;
                }
            }
            () = tokio::time::sleep_until(due) => {
                let now = tokio::time::Instant::now();
                if now >= status_due && let Some(text) = status.take() {
                    status_due = now + STATUS_EVERY;
                    write(&mut sink, text.to_string()).await?;
                }
                if now >= state_due && let Some(text) = state.take() {
                    state_due = now + STATE_EVERY;
                    write(&mut sink, text.to_string()).await?;
                }
            }
        }
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

/// A page's stops and releases, as they come, each answered: stops owned by the page's user.
fn stop_thread(
    robot: &str,
    client: &str,
    peer: SocketAddr,
    jobs: &std_mpsc::Receiver<StopJob>,
    answers: &mpsc::UnboundedSender<Value>,
) {
    let mut stopper = match Stopper::new(robot, client) {
        Ok(stopper) => Some(stopper),
        Err(error) => {
            warn!("{peer}: no stop client for {client}: {error}");
            None
        }
    };
    let no_stopper = || ControlError::Client(ClientError::BadClientName(client.to_owned()));
    while let Ok(job) = jobs.recv() {
        let answer = match job {
            StopJob::Stop(reason) => {
                let result = stopper
                    .as_mut()
                    .map_or_else(|| Err(no_stopper()), |stopper| stopper.stop(&reason));
                match &result {
                    Ok(accepted) => info!(
                        "{peer}: {client}: E-STOP latched stop #{}: {reason}",
                        accepted.stop.unwrap_or(0)
                    ),
                    Err(error) => warn!("{peer}: {client}: E-STOP NOT latched: {error}"),
                }
                answer_of("estop", &result)
            }
            StopJob::Release(through) => {
                let result = stopper.as_mut().map_or_else(
                    || Err(no_stopper()),
                    |stopper| stopper.release(ReleaseTarget::Own, through),
                );
                info!(
                    "{peer}: {client}: release of its own stops through #{through}: {}",
                    match &result {
                        Ok(_) => "done".to_owned(),
                        Err(error) => error.to_string(),
                    }
                );
                answer_of("release", &result)
            }
        };
        let _ = answers.send(answer);
    }
}

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

/// A driving page's control requests, in order, as `web:USER` with the teleop class. The
/// control client is made at the first take, and made again at the next take after a take
/// failed (a gateway restarted since has new services).
fn control_thread(robot: &str, client: &str, slot: &Slot, answers: &mpsc::UnboundedSender<Value>) {
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
                lateral,
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
                // Sideways where the chassis moves sideways: the arbiter refuses it elsewhere.
                let request = Request::Drive {
                    lease,
                    linear,
                    lateral,
                    angular,
                    ttl: Some(ttl),
                    mode: None,
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
                    "{client}: a stop or release reached the control thread: ignored (the page's stop thread serves them)"
                );
            }
        }
    }
}

/// An address that cannot be listened on, or needs TLS, is a usage error.
impl FailureKind for WebError {
    fn kind(&self) -> Failure {
        match self {
            Self::Listen { .. } | Self::NeedsTls(_) => Failure::Usage,
            Self::Gateway(error) => error.kind(),
            Self::Runtime(_) => Failure::Failed,
        }
    }
}
