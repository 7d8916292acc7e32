//! What watching the robot costs: two `scout record` and one `scout foxglove` with a Foxglove
//! WebSocket client subscribed to every channel, attached to the gateway at once. The recorders'
//! CPU and bytes per minute, the live server's CPU, and the gateway's 0x130 intervals meanwhile.

use std::io::{BufRead, BufReader};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::Context;
use serde_json::{Value, json};
use tungstenite::client::IntoClientRequest;
use tungstenite::{Message, WebSocket};

use crate::procs::{command, usage};

/// The protocol's first name, which the live view serves as Lichtblick asks for it.
const SUBPROTOCOL: &str = "foxglove.websocket.v1";

/// A child process killed when dropped.
#[derive(Debug)]
pub struct Watcher {
    child: Child,
}

impl Watcher {
    pub fn pid(&self) -> i32 {
        self.child.id() as i32
    }
}

impl Drop for Watcher {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `scout-foxglove record --name ROBOT --output FILE`.
pub fn recorder(robot: &str, file: &Path) -> anyhow::Result<Watcher> {
    let child = command("scout-foxglove")?
        .args(["record", "--name", robot, "--output"])
        .arg(file)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .context("starting scout-foxglove record")?;
    Ok(Watcher { child })
}

/// `scout-foxglove serve --name ROBOT` on a free port, and its `ws://` URL.
pub fn live_view(robot: &str) -> anyhow::Result<(Watcher, String)> {
    let mut child = command("scout-foxglove")?
        .args(["serve", "--name", robot, "--listen", "127.0.0.1:0"])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .context("starting scout-foxglove serve")?;
    let stdout = child.stdout.take().context("its stdout")?;
    let watcher = Watcher { child };
    let mut line = String::new();
    BufReader::new(stdout).read_line(&mut line)?;
    let url = line
        .split_whitespace()
        .find(|word| word.starts_with("ws://"))
        .map(|url| url.trim_end_matches(':').to_owned())
        .with_context(|| format!("no URL in {line:?}"))?;
    Ok((watcher, url))
}

/// A Foxglove WebSocket client subscribed to every channel, counting messages on a thread.
#[derive(Debug)]
pub struct Client {
    messages: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<anyhow::Result<()>>>,
}

impl Client {
    pub fn connect(url: &str) -> anyhow::Result<Client> {
        let mut request = url.into_client_request()?;
        request
            .headers_mut()
            .insert("Sec-WebSocket-Protocol", SUBPROTOCOL.parse()?);
        let (mut socket, _) =
            tungstenite::connect(request).context("connecting to the live view")?;
        if let tungstenite::stream::MaybeTlsStream::Plain(stream) = socket.get_ref() {
            stream.set_read_timeout(Some(Duration::from_millis(100)))?;
        }
        let messages = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        let (counted, stopping) = (Arc::clone(&messages), Arc::clone(&stop));
        let thread = std::thread::spawn(move || read(&mut socket, &counted, &stopping));
        Ok(Client {
            messages,
            stop,
            thread: Some(thread),
        })
    }

    /// Messages received so far.
    pub fn messages(&self) -> u64 {
        self.messages.load(Ordering::Relaxed)
    }

    /// Stops reading; an error the reader met.
    pub fn finish(mut self) -> anyhow::Result<()> {
        self.stop.store(true, Ordering::Relaxed);
        self.thread
            .take()
            .map_or(Ok(()), |thread| thread.join().expect("the reader"))
    }
}

impl Drop for Client {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Subscribes to each channel as it is advertised and counts binary messages.
fn read(
    socket: &mut WebSocket<tungstenite::stream::MaybeTlsStream<TcpStream>>,
    messages: &AtomicU64,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let mut next_subscription = 1;
    while !stop.load(Ordering::Relaxed) {
        match socket.read() {
            Ok(Message::Text(text)) => {
                let message: Value = serde_json::from_str(&text)?;
                if message["op"] == "advertise" {
                    let subscriptions: Vec<Value> = message["channels"]
                        .as_array()
                        .map(Vec::as_slice)
                        .unwrap_or_default()
                        .iter()
                        .map(|channel| {
                            next_subscription += 1;
                            json!({ "id": next_subscription, "channelId": channel["id"] })
                        })
                        .collect();
                    let subscribe = json!({ "op": "subscribe", "subscriptions": subscriptions });
                    socket.send(Message::text(subscribe.to_string()))?;
                }
            }
            Ok(Message::Binary(_)) => {
                messages.fetch_add(1, Ordering::Relaxed);
            }
            Ok(_) => {}
            Err(tungstenite::Error::Io(error))
                if matches!(
                    error.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(error) => return Err(error.into()),
        }
    }
    Ok(())
}

/// CPU seconds of `pid` now.
pub fn cpu(pid: i32) -> anyhow::Result<f64> {
    Ok(usage(pid)?.0)
}

/// A window's CPU share of `pid`, % of a core, from `before` at `since`.
pub fn percent(pid: i32, before: f64, since: Instant) -> anyhow::Result<f64> {
    Ok((cpu(pid)? - before) / since.elapsed().as_secs_f64() * 100.0)
}
