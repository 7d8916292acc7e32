//! HTTP request heads without I/O: what a browser asks for (the page, or the WebSocket), parsed
//! with limits, and the few answers the server gives.

use std::collections::BTreeMap;

/// The longest request head read, bytes: a browser's is well under 2 KiB.
pub const MAX_HEAD_BYTES: usize = 8192;

/// The most headers a request may carry.
const MAX_HEADERS: usize = 48;

/// A request head.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Head {
    /// `GET`, ...
    pub method: String,
    /// The path, without the query.
    pub path: String,
    /// The query's `key=value` pairs (percent-decoded).
    pub query: BTreeMap<String, String>,
    /// The headers, names lower-cased (a repeated header keeps its first value).
    pub headers: BTreeMap<String, String>,
}

/// Why a head is refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum HeadError {
    /// Not all there yet.
    #[error("the request head is incomplete")]
    Partial,
    /// Longer than [`MAX_HEAD_BYTES`].
    #[error("the request head is longer than {MAX_HEAD_BYTES} bytes")]
    TooLong,
    /// Not HTTP/1.x, or a header not text.
    #[error("not an HTTP/1.1 request head: {0}")]
    Malformed(String),
}

impl Head {
    /// Parses the head at the start of `bytes` (which may hold more); returns it and its length.
    pub fn parse(bytes: &[u8]) -> Result<(Head, usize), HeadError> {
        let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
        let mut request = httparse::Request::new(&mut headers);
        let length = match request.parse(bytes) {
            Ok(httparse::Status::Complete(length)) => length,
            Ok(httparse::Status::Partial) if bytes.len() >= MAX_HEAD_BYTES => {
                return Err(HeadError::TooLong);
            }
            Ok(httparse::Status::Partial) => return Err(HeadError::Partial),
            Err(error) => return Err(HeadError::Malformed(error.to_string())),
        };
        if length > MAX_HEAD_BYTES {
            return Err(HeadError::TooLong);
        }
        let target = request.path.unwrap_or("/");
        let (path, query) = target.split_once('?').unwrap_or((target, ""));
        let mut fields = BTreeMap::new();
        for header in request.headers.iter() {
            let value = std::str::from_utf8(header.value)
                .map_err(|_| HeadError::Malformed(format!("header {} is not text", header.name)))?;
            fields
                .entry(header.name.to_ascii_lowercase())
                .or_insert_with(|| value.trim().to_owned());
        }
        Ok((
            Head {
                method: request.method.unwrap_or("").to_owned(),
                path: path.to_owned(),
                query: parse_query(query),
                headers: fields,
            },
            length,
        ))
    }

    /// A header's value (`name` lower case).
    pub fn header(&self, name: &str) -> Option<&str> {
        self.headers.get(name).map(String::as_str)
    }

    /// Whether it asks for a WebSocket (`Upgrade: websocket`, with a key).
    pub fn is_websocket(&self) -> bool {
        self.header("upgrade")
            .is_some_and(|value| value.eq_ignore_ascii_case("websocket"))
            && self.header("sec-websocket-key").is_some()
    }
}

/// The `key=value` pairs of a query string, percent-decoded (`+` is a space).
fn parse_query(query: &str) -> BTreeMap<String, String> {
    query
        .split('&')
        .filter(|pair| !pair.is_empty())
        .map(|pair| {
            let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
            (percent_decode(key), percent_decode(value))
        })
        .collect()
}

/// `%XX` decoded (a bad escape is kept as it is), `+` a space; bytes that are not UTF-8 are
/// replaced.
fn percent_decode(text: &str) -> String {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut at = 0;
    while at < bytes.len() {
        let hex = |byte: u8| char::from(byte).to_digit(16);
        match bytes[at] {
            b'%' if at + 2 < bytes.len() => match (hex(bytes[at + 1]), hex(bytes[at + 2])) {
                (Some(high), Some(low)) => {
                    out.push((high * 16 + low) as u8);
                    at += 3;
                    continue;
                }
                _ => out.push(b'%'),
            },
            b'+' => out.push(b' '),
            byte => out.push(byte),
        }
        at += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// A complete response with a body, closing the connection.
pub fn response(status: u16, reason: &str, content_type: &str, body: &[u8]) -> Vec<u8> {
    let mut out = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nX-Content-Type-Options: nosniff\r\nX-Frame-Options: DENY\r\n\
         Content-Security-Policy: default-src 'self'; style-src 'self' 'unsafe-inline'; \
         script-src 'self' 'unsafe-inline'; connect-src 'self'\r\nConnection: close\r\n\r\n",
        body.len()
    )
    .into_bytes();
    out.extend_from_slice(body);
    out
}

/// A plain-text refusal: `status`, and the reason as the body.
pub fn refusal(status: u16, reason: &str) -> Vec<u8> {
    let phrase = match status {
        400 => "Bad Request",
        401 => "Unauthorized",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        429 => "Too Many Requests",
        431 => "Request Header Fields Too Large",
        503 => "Service Unavailable",
        _ => "Error",
    };
    response(
        status,
        phrase,
        "text/plain; charset=utf-8",
        format!("{reason}\n").as_bytes(),
    )
}

/// The answer that switches to the WebSocket protocol.
pub fn switching_protocols(key: &str) -> Vec<u8> {
    format!(
        "HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\
         Sec-WebSocket-Accept: {}\r\n\r\n",
        tungstenite::handshake::derive_accept_key(key.as_bytes())
    )
    .into_bytes()
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const UPGRADE: &[u8] = b"GET /ws?token=a%2Bb+c&x HTTP/1.1\r\nHost: 127.0.0.1:8090\r\n\
        Upgrade: websocket\r\nConnection: Upgrade\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\
        Origin: http://127.0.0.1:8090\r\nSec-WebSocket-Version: 13\r\n\r\nextra";

    #[test]
    fn a_websocket_upgrade_is_read_with_its_query_and_headers() {
        let (head, length) = Head::parse(UPGRADE).expect("complete");
        assert_eq!(length, UPGRADE.len() - "extra".len());
        assert_eq!(head.method, "GET");
        assert_eq!(head.path, "/ws");
        assert_eq!(head.query["token"], "a+b c");
        assert_eq!(head.query["x"], "");
        assert_eq!(head.header("origin"), Some("http://127.0.0.1:8090"));
        assert!(head.is_websocket());
        // RFC 6455's example key and answer.
        let answer = String::from_utf8(switching_protocols("dGhlIHNhbXBsZSBub25jZQ==")).unwrap();
        assert!(answer.contains("Sec-WebSocket-Accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo=\r\n"));
    }

    #[test]
    fn partial_long_and_broken_heads_are_told_apart() {
        assert_eq!(
            Head::parse(b"GET / HTTP/1.1\r\nHost: x\r\n"),
            Err(HeadError::Partial)
        );
        let long = [b"GET / HTTP/1.1\r\nX: ".as_slice(), &[b'a'; MAX_HEAD_BYTES]].concat();
        assert_eq!(Head::parse(&long), Err(HeadError::TooLong));
        assert!(matches!(
            Head::parse(b"\x00\x01 nonsense\r\n\r\n"),
            Err(HeadError::Malformed(_))
        ));
        let (plain, _) = Head::parse(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n").expect("complete");
        assert!(!plain.is_websocket());
    }

    #[test]
    fn percent_escapes_decode_and_bad_ones_stay() {
        assert_eq!(percent_decode("a%20b%zz%2"), "a b%zz%2");
        assert_eq!(percent_decode("%"), "%");
        assert_eq!(percent_decode("%e2%82%ac"), "€");
    }

    proptest! {
        #[test]
        fn any_bytes_parse_or_are_refused_without_panicking(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let _ = Head::parse(&bytes);
        }

        #[test]
        fn any_query_decodes(query in ".{0,80}") {
            let _ = parse_query(&query);
        }
    }
}
