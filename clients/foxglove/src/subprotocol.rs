//! The Foxglove WebSocket protocol under both its names. Foxglove renamed `foxglove.websocket.v1`
//! to `foxglove.sdk.v1` (the same protocol) and its SDK's server accepts only the new name, so
//! Lichtblick releases from before late 2025 and clients of the `ws-protocol` libraries, which ask
//! for the old one, would be refused. The live view's address is this front: it lets the handshake of a client
//! that asks for `foxglove.websocket.v1` through as `foxglove.sdk.v1`, answers with the name the
//! client asked for, and then copies bytes both ways untouched. The SDK's server listens on a
//! loopback port of its own behind it, reachable from the front alone ([`crate::backend`]). A handshake from a web page of another origin than the
//! policy lets in ([`crate::origin`]) is answered 403 here and never reaches the server.

use std::io::{self, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use tracing::{debug, warn};

use crate::backend::Backend;
use crate::origin::OriginPolicy;

/// The protocol's first name, which Lichtblick and the ws-protocol libraries ask for.
pub const LEGACY: &str = "foxglove.websocket.v1";
/// Its current name, the only one the SDK's server accepts.
pub const CURRENT: &str = "foxglove.sdk.v1";
/// The longest handshake head accepted, bytes.
const MAX_HEAD: usize = 16 * 1024;
/// How long a client may take to send its whole handshake.
const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(10);
/// How long a write to a client may wait for it to read: a client that stops reading is
/// dropped rather than holding its threads.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);
/// The most clients served at once (each costs two threads); more are refused.
pub const MAX_CLIENTS: usize = 16;

/// The protocol header's name, compared without case.
const HEADER: &str = "sec-websocket-protocol";

/// The value of a head's line if it is header `header` (compared without case).
fn header_value<'a>(line: &'a str, header: &str) -> Option<&'a str> {
    let (name, value) = line.split_once(':')?;
    name.trim().eq_ignore_ascii_case(header).then_some(value)
}

fn is_protocol_header(line: &str) -> Option<&str> {
    header_value(line, HEADER)
}

/// The `Origin` a handshake's head carries (the first, if several), trimmed.
pub fn origin_of(head: &str) -> Option<&str> {
    head.split("\r\n")
        .skip(1)
        .find_map(|line| header_value(line, "origin"))
        .map(str::trim)
}

/// The answer to a handshake refused for `why`.
fn forbidden(why: &str) -> String {
    format!(
        "HTTP/1.1 403 Forbidden\r\nContent-Type: text/plain; charset=utf-8\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{why}",
        why.len()
    )
}

/// The request head to send on, and whether the client asked for the old name only.
pub fn rewrite_request(head: &str) -> (String, bool) {
    let offered: Vec<String> = head
        .split("\r\n")
        .filter_map(is_protocol_header)
        .flat_map(|value| value.split(','))
        .map(|token| token.trim().to_owned())
        .collect();
    let speaks_current = offered
        .iter()
        .any(|token| token.starts_with("foxglove.sdk."));
    if speaks_current || !offered.iter().any(|token| token == LEGACY) {
        return (head.to_owned(), false);
    }
    let mut replaced = false;
    let lines: Vec<String> = head
        .split("\r\n")
        .filter_map(|line| match is_protocol_header(line) {
            Some(_) if replaced => None,
            Some(_) => {
                replaced = true;
                Some(format!("Sec-WebSocket-Protocol: {CURRENT}"))
            }
            None => Some(line.to_owned()),
        })
        .collect();
    (lines.join("\r\n"), true)
}

/// The response head to send back to a client that asked for the old name.
pub fn rewrite_response(head: &str) -> String {
    head.split("\r\n")
        .map(|line| match is_protocol_header(line) {
            Some(value) if value.trim() == CURRENT => format!("Sec-WebSocket-Protocol: {LEGACY}"),
            Some(_) | None => line.to_owned(),
        })
        .collect::<Vec<_>>()
        .join("\r\n")
}

/// Reads up to the end of an HTTP head (`\r\n\r\n`) within `limit` in all: the head, and what
/// came after it.
fn read_head(stream: &mut TcpStream, limit: Duration) -> io::Result<(String, Vec<u8>)> {
    let deadline = Instant::now() + limit;
    let mut bytes = Vec::new();
    let mut chunk = [0_u8; 2048];
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(io::Error::new(
                io::ErrorKind::TimedOut,
                "the handshake took longer than 10 s",
            ));
        }
        stream.set_read_timeout(Some(left))?;
        if let Some(end) = bytes.windows(4).position(|w| w == b"\r\n\r\n") {
            let rest = bytes.split_off(end + 4);
            let head = String::from_utf8(bytes)
                .map_err(|_| io::Error::new(io::ErrorKind::InvalidData, "a head not in UTF-8"))?;
            return Ok((head, rest));
        }
        if bytes.len() > MAX_HEAD {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "a head over 16 KiB",
            ));
        }
        let n = stream.read(&mut chunk)?;
        if n == 0 {
            return Err(io::ErrorKind::UnexpectedEof.into());
        }
        bytes.extend_from_slice(&chunk[..n]);
    }
}

/// Copies `from` to `to` until either ends, then closes both directions.
fn pipe(mut from: TcpStream, mut to: TcpStream) {
    let _ = io::copy(&mut from, &mut to);
    let _ = to.shutdown(Shutdown::Both);
    let _ = from.shutdown(Shutdown::Both);
}

fn serve(mut client: TcpStream, backend: &Arc<Backend>, origins: &OriginPolicy) -> io::Result<()> {
    let (head, early) = read_head(&mut client, HANDSHAKE_TIMEOUT)?;
    if let Err(why) = origins.check(origin_of(&head)) {
        let _ = client.write_all(forbidden(&why.to_string()).as_bytes());
        let _ = client.shutdown(Shutdown::Both);
        return Err(io::Error::new(io::ErrorKind::PermissionDenied, why));
    }
    let (head, legacy) = rewrite_request(&head);
    // The permit lets this connection's port through the server's guard until it ends.
    let (mut server, _permit) = backend.connect(HANDSHAKE_TIMEOUT)?;
    server.set_nodelay(true)?;
    client.set_nodelay(true)?;
    server.write_all(head.as_bytes())?;
    server.write_all(&early)?;
    if legacy {
        let (response, rest) = read_head(&mut server, HANDSHAKE_TIMEOUT)?;
        server.set_read_timeout(None)?;
        client.write_all(rewrite_response(&response).as_bytes())?;
        client.write_all(&rest)?;
    }
    client.set_read_timeout(None)?;
    client.set_write_timeout(Some(WRITE_TIMEOUT))?;
    let (client_in, server_in) = (client.try_clone()?, server.try_clone()?);
    std::thread::Builder::new()
        .name("foxglove-up".into())
        .spawn(move || pipe(client_in, server_in))?;
    pipe(server, client);
    Ok(())
}

/// The front, accepting on its own thread until dropped.
#[derive(Debug)]
pub struct Front {
    address: SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
}

impl Front {
    /// Listens on `listen` and hands every connection whose origin `origins` lets in to the
    /// server at `backend`.
    pub fn start(
        listen: SocketAddr,
        backend: Arc<Backend>,
        origins: OriginPolicy,
    ) -> io::Result<Self> {
        let origins = Arc::new(origins);
        let listener = TcpListener::bind(listen)?;
        let address = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let stop = Arc::new(AtomicBool::new(false));
        let accepting = Arc::clone(&stop);
        let clients = Arc::new(AtomicUsize::new(0));
        let thread = std::thread::Builder::new()
            .name("foxglove-front".into())
            .spawn(move || {
                while !accepting.load(Ordering::Relaxed) {
                    match listener.accept() {
                        Ok((client, peer)) => {
                            if clients.fetch_add(1, Ordering::Relaxed) >= MAX_CLIENTS {
                                clients.fetch_sub(1, Ordering::Relaxed);
                                warn!(
                                    "Foxglove client {peer} refused: {MAX_CLIENTS} clients are \
                                     served already"
                                );
                                continue;
                            }
                            debug!("Foxglove client {peer} connected");
                            let _ = client.set_nonblocking(false);
                            let served = Arc::clone(&clients);
                            let origins = Arc::clone(&origins);
                            let backend = Arc::clone(&backend);
                            let spawned = std::thread::Builder::new()
                                .name("foxglove-down".into())
                                .spawn(move || {
                                    if let Err(error) = serve(client, &backend, &origins) {
                                        warn!("Foxglove client {peer}: {error}");
                                    }
                                    served.fetch_sub(1, Ordering::Relaxed);
                                });
                            if let Err(error) = spawned {
                                clients.fetch_sub(1, Ordering::Relaxed);
                                warn!("Foxglove client {peer} refused: no thread ({error})");
                            }
                        }
                        Err(error) if error.kind() == io::ErrorKind::WouldBlock => {
                            std::thread::sleep(Duration::from_millis(20));
                        }
                        Err(error) => {
                            warn!("accepting Foxglove clients: {error}");
                            std::thread::sleep(Duration::from_millis(100));
                        }
                    }
                }
            })?;
        Ok(Self {
            address,
            stop,
            thread: Some(thread),
        })
    }

    /// The address it listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }
}

impl Drop for Front {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const REQUEST: &str = "GET / HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nUpgrade: websocket\r\n\
                           Connection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\
                           Sec-WebSocket-Version: 13\r\n";

    #[test]
    fn a_client_asking_for_the_old_name_is_let_through_as_the_new_one_and_answered_in_its_own() {
        let head = format!("{REQUEST}sec-websocket-protocol: {LEGACY}\r\n\r\n");
        let (rewritten, legacy) = rewrite_request(&head);
        assert!(legacy);
        assert!(
            rewritten.contains(&format!("Sec-WebSocket-Protocol: {CURRENT}\r\n")),
            "{rewritten}"
        );
        assert!(!rewritten.contains(LEGACY));
        assert!(rewritten.ends_with("\r\n\r\n"));
        let response = format!(
            "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nsec-websocket-protocol: {CURRENT}\r\n\r\n"
        );
        let answered = rewrite_response(&response);
        assert!(
            answered.contains(&format!("Sec-WebSocket-Protocol: {LEGACY}\r\n")),
            "{answered}"
        );
        assert!(answered.ends_with("\r\n\r\n"));
    }

    #[test]
    fn a_client_that_knows_the_new_name_or_asks_for_neither_is_left_alone() {
        for protocols in [
            format!("{LEGACY}, {CURRENT}"),
            "foxglove.sdk.v1.1".to_owned(),
            "something.else".to_owned(),
        ] {
            let head = format!("{REQUEST}Sec-WebSocket-Protocol: {protocols}\r\n\r\n");
            assert_eq!(rewrite_request(&head), (head.clone(), false), "{protocols}");
        }
        let none = format!("{REQUEST}\r\n");
        assert_eq!(rewrite_request(&none), (none.clone(), false));
    }

    #[test]
    fn the_origin_is_read_from_the_head_and_a_refusal_is_a_whole_answer() {
        assert_eq!(origin_of(REQUEST), None);
        let with = REQUEST.replace("Host:", "ORIGIN:  http://evil.example \r\nHost:");
        assert_eq!(origin_of(&with), Some("http://evil.example"));
        // The request line is no header, whatever it says.
        assert_eq!(origin_of("GET /origin: x HTTP/1.1\r\n\r\n"), None);
        let answer = forbidden("not you");
        assert!(answer.starts_with("HTTP/1.1 403 Forbidden\r\n"), "{answer}");
        assert!(answer.ends_with("Content-Length: 7\r\nConnection: close\r\n\r\nnot you"));
    }

    #[test]
    fn the_old_name_in_two_headers_becomes_one() {
        let head = format!(
            "{REQUEST}Sec-WebSocket-Protocol: other\r\nSec-WebSocket-Protocol: {LEGACY}\r\n\r\n"
        );
        let (rewritten, legacy) = rewrite_request(&head);
        assert!(legacy);
        assert_eq!(
            rewritten.matches("Sec-WebSocket-Protocol").count(),
            1,
            "{rewritten}"
        );
    }
}
