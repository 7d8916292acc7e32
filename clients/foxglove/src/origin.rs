//! Which web pages may open the live view's WebSocket, by the `Origin` header a browser puts
//! on every handshake (a page cannot change it). Without a check, any page open in a browser on
//! the robot or the operator's laptop could connect to `ws://127.0.0.1:8765`, read the robot and,
//! with `--estop` or `--allow-release`, call the services.
//!
//! Let in by default: a client that sends no `Origin` (not a browser: Foxglove's and
//! Lichtblick's desktop apps' own connections, the ws-protocol libraries, Python), a page of
//! this machine (`http(s)://localhost`, `127.x.x.x` or `[::1]`, any port: served by a local
//! process, which could connect itself anyway) and `file://`. Refused: any other origin,
//! including `null` (what a sandboxed frame of any page sends), unless `--allow-origin` names
//! it exactly (`*`: any). A DNS-rebinding page's origin is its own name, never a loopback one.

/// The origins let in beside the defaults.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct OriginPolicy {
    allowed: Vec<String>,
    any: bool,
}

impl OriginPolicy {
    /// The defaults plus each of `allowed` (compared without case and a trailing `/`; `*`
    /// lets in every origin).
    pub fn new(allowed: &[String]) -> Self {
        Self {
            any: allowed.iter().any(|origin| origin == "*"),
            allowed: allowed.iter().map(|origin| normalize(origin)).collect(),
        }
    }

    /// Whether a handshake with `origin` (`None`: no such header) is let in; if not, why, in
    /// words that say what to do.
    pub fn check(&self, origin: Option<&str>) -> Result<(), ForeignOrigin> {
        let Some(origin) = origin else {
            return Ok(());
        };
        let origin = normalize(origin);
        if self.any || is_local(&origin) || self.allowed.contains(&origin) {
            return Ok(());
        }
        Err(ForeignOrigin(origin))
    }
}

/// A handshake from a web page this policy does not let in (its origin, normalized).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "a WebSocket from the web page at {0} is refused: only this machine's pages and apps may \
     connect unless `scout foxglove --allow-origin {0}` lets it in"
)]
pub struct ForeignOrigin(pub String);

fn normalize(origin: &str) -> String {
    origin.trim().trim_end_matches('/').to_ascii_lowercase()
}

/// An origin served by this machine: `file://`, or http(s) on a loopback host.
fn is_local(origin: &str) -> bool {
    if origin == "file:" || origin == "file://" {
        return true;
    }
    let Some(rest) = origin
        .strip_prefix("http://")
        .or_else(|| origin.strip_prefix("https://"))
    else {
        return false;
    };
    let host = if let Some(bracketed) = rest.strip_prefix('[') {
        match bracketed.split_once(']') {
            Some((host, port)) if port.is_empty() || port.starts_with(':') => host,
            _ => return false,
        }
    } else {
        rest.split(':').next().unwrap_or_default()
    };
    if rest.contains(['/', '@', '?', '#']) {
        return false;
    }
    host == "localhost"
        || host == "::1"
        || host
            .parse::<std::net::Ipv4Addr>()
            .is_ok_and(|ip| ip.is_loopback())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_origin_and_this_machines_pages_are_let_in() {
        let policy = OriginPolicy::default();
        for origin in [
            None,
            Some("http://localhost:8080"),
            Some("http://127.0.0.1:8765"),
            Some("https://127.8.9.10"),
            Some("http://[::1]:3000"),
            Some("HTTP://LocalHost:1/"),
            Some("file://"),
        ] {
            assert_eq!(policy.check(origin), Ok(()), "{origin:?}");
        }
    }

    #[test]
    fn other_pages_are_refused_saying_how_to_let_them_in() {
        let policy = OriginPolicy::default();
        for origin in [
            "http://evil.example",
            "null",
            "https://app.foxglove.dev",
            "http://localhost.evil.example",
            "http://127.0.0.1.evil.example",
            "http://[::1].evil.example",
            "http://localhost@evil.example",
            "http://192.168.1.5:8765",
            "chrome-extension://abc",
            "",
        ] {
            let refused = policy.check(Some(origin)).expect_err(origin).to_string();
            assert!(refused.contains("--allow-origin"), "{refused}");
        }
    }

    #[test]
    fn allowed_origins_are_matched_exactly_and_star_lets_all_in() {
        let policy = OriginPolicy::new(&["https://app.foxglove.dev/".into(), "null".into()]);
        assert_eq!(policy.check(Some("https://APP.foxglove.dev")), Ok(()));
        assert_eq!(policy.check(Some("null")), Ok(()));
        assert!(policy.check(Some("https://app.foxglove.dev.evil")).is_err());
        let any = OriginPolicy::new(&["*".into()]);
        assert_eq!(any.check(Some("http://evil.example")), Ok(()));
    }
}
