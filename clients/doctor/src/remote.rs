//! The zenoh checks, when asked (`--zenoh ENDPOINT`): a zenoh client session to that endpoint
//! (with TLS when `--zenoh-config` says so), the robot's state arriving through it, and the link
//! measured as a remote peer would meet it: queries answered, their round trip, and what the
//! gateway allows remote peers.

use std::time::{Duration, Instant};

use scout_clients::remote::{RemoteError, RemoteStates, SessionSettings, info_key};
use scout_interface::link::{Endpoint, PACED_DRIVES, Protection};
use zenoh::Wait;

use crate::check::{Check, Verdict};

/// Queries the link check sends, one every [`PROBE_SPACING`].
const PROBES: usize = 20;

/// Between two probes.
const PROBE_SPACING: Duration = Duration::from_millis(50);

/// How long a probe's answer is awaited.
const PROBE_TIMEOUT: Duration = Duration::from_secs(2);

/// A round trip past this makes remote driving over TCP unreliable: drives live 300 ms.
const SLOW_ROUND_TRIP: Duration = Duration::from_millis(250);

/// Connects to `endpoint` as a zenoh client (with `config_file`'s TLS settings if given), waits
/// up to `window` for robot `robot`'s state, then measures the link.
pub fn inspect(
    robot: &str,
    endpoint: &str,
    config_file: Option<&str>,
    window: Duration,
) -> Vec<Check> {
    let settings = SessionSettings {
        config_file: config_file.map(str::to_owned),
        listen: Vec::new(),
        connect: vec![endpoint.to_owned()],
    };
    let states = match RemoteStates::connect(&settings, robot) {
        Ok(states) => states,
        Err(error) => return vec![cannot_connect(endpoint, config_file, &error)],
    };
    let state = match states.next_timeout(window.max(Duration::from_secs(1))) {
        Ok(Some(_)) => Check::pass(
            "zenoh",
            format!("robot {robot}'s state arrives through zenoh at {endpoint}"),
        ),
        Ok(None) => Check::fail(
            "zenoh",
            format!(
                "connected to {endpoint}, but no state of robot {robot} arrived in {window:.1?}"
            ),
            if config_file.is_some() {
                "the access control may not list your certificate's common name (it then \
                 denies everything); or no gateway named so publishes there: `scout echo \
                 --remote --name '*'` lists the robots you may read"
            } else {
                "does the gateway run with zenoh (not --no-zenoh) and this --name? `scout echo \
                 --remote --name '*'` lists the robots that publish there"
            },
        ),
        Err(error) => Check::fail(
            "zenoh",
            format!("reading robot {robot}'s state at {endpoint}: {error}"),
            "see the error; `scout echo --remote` shows what arrives",
        ),
    };
    let reached = state.verdict == Verdict::Pass;
    let mut checks = vec![state];
    if reached {
        checks.push(link_kind(&settings, endpoint));
        checks.push(measure_link(&settings, robot, endpoint));
    }
    checks
}

/// Which kind of link `endpoint` is from this host, what protects it, and what the guide
/// recommends for it.
fn link_kind(settings: &SessionSettings, endpoint: &str) -> Check {
    let links = match settings.links("client", &[]) {
        Ok(links) => links,
        Err(error) => return Check::fail("zenoh.security", error.to_string(), "see the error"),
    };
    match links.iter().find(|link| link.endpoint == endpoint) {
        Some(link) => security(endpoint, &link.protection),
        None => Check::fail(
            "zenoh.security",
            format!("{endpoint} is not among the session's links"),
            "report this: the endpoint given is what the session connects to",
        ),
    }
}

/// The verdict on a link of `endpoint`'s protocol with `protection`.
fn security(endpoint: &str, protection: &Protection) -> Check {
    const NAME: &str = "zenoh.security";
    let parsed = Endpoint::parse(endpoint).ok();
    let udp = parsed.as_ref().is_some_and(|e| e.protocol == "udp");
    let paced = parsed.as_ref().is_some_and(|e| e.quic_underneath);
    let detail = |kind: &str| format!("{endpoint}: {kind} ({protection})");
    match protection {
        Protection::Local => Check::pass(NAME, detail("a link on this host")),
        Protection::Tunnel { .. } if paced => Check::warn(
            NAME,
            detail("inside an authenticated tunnel, but QUIC under udp/"),
            PACED_DRIVES,
        ),
        Protection::Tunnel { .. } if udp => Check::pass(
            NAME,
            detail(
                "plain UDP inside an authenticated tunnel, the link docs/remote.md recommends \
                 for driving over Wi-Fi or 4G",
            ),
        ),
        Protection::Tunnel { .. } => Check::warn(
            NAME,
            detail("inside an authenticated tunnel, but not over UDP"),
            "over TCP a lost packet holds back every drive after it: for driving over a lossy \
             link use udp/ inside the tunnel (docs/remote.md)",
        ),
        Protection::MutualTls => Check::pass(
            NAME,
            detail(
                "TLS or QUIC with certificates: authenticated; through loss, QUIC's drives \
                 arrive in bursts and TCP's wait behind a lost packet (docs/remote.md: which \
                 link)",
            ),
        ),
        Protection::ServerTls => Check::warn(
            NAME,
            detail("encrypted, but the gateway cannot tell who you are"),
            "give the operator a certificate and the gateway enable_mtls \
             (config/zenoh-tls-gateway.json5): without it the gateway takes e-stops only",
        ),
        Protection::Plain { .. } => Check::warn(
            NAME,
            detail("a plain link: nobody is authenticated"),
            "anyone who reaches it can command as any peer name; the gateway takes only \
             e-stops over it unless its network is declared trusted. Drive over UDP inside \
             WireGuard, or QUIC with certificates (docs/remote.md: drive over Wi-Fi or 4G \
             securely)",
        ),
    }
}

/// Why no session opened, and what to do: a TLS failure names the certificates.
fn cannot_connect(endpoint: &str, config_file: Option<&str>, error: &RemoteError) -> Check {
    let text = error.to_string();
    let lower = text.to_lowercase();
    let tls = ["certificate", "issuer", "tls", "handshake", "alert"]
        .iter()
        .any(|word| lower.contains(word));
    match error {
        RemoteError::Config(_) => Check::fail(
            "zenoh",
            format!("{endpoint}: {error}"),
            "give an endpoint as tcp/HOST:PORT, tls/..., quic/... or udp/... (the gateway \
             listens on tcp/127.0.0.1:7448 unless --zenoh-listen says otherwise) and a valid \
             --zenoh-config",
        ),
        _ if tls => Check::fail(
            "zenoh",
            format!("TLS with {endpoint} failed: {text}"),
            "the gateway's certificate and yours must be signed by the CA your configuration's \
             root_ca_certificate names (a wrong CA fails here), and not expired",
        ),
        _ if config_file.is_none()
            && (endpoint.starts_with("tls/") || endpoint.starts_with("quic/")) =>
        {
            Check::fail(
                "zenoh",
                format!("cannot reach {endpoint}: {text}"),
                "tls/ and quic/ need certificates: give --zenoh-config with your TLS settings \
                 (config/zenoh-tls-operator.json5)",
            )
        }
        // zenoh does not always say why a TLS or QUIC handshake failed.
        _ if endpoint.starts_with("tls/") || endpoint.starts_with("quic/") => Check::fail(
            "zenoh",
            format!("cannot reach {endpoint}: {text}"),
            "is the gateway listening there (check firewalls)? If it is, the TLS handshake \
             failed: both certificates must be signed by the CA the other side trusts (a \
             certificate from another CA fails here), and not expired",
        ),
        _ => Check::fail(
            "zenoh",
            format!("cannot reach {endpoint}: {text}"),
            "is the gateway (or the zenoh router) listening there? `scout-gateway \
             --zenoh-listen tcp/0.0.0.0:7448` listens beyond this machine (to drive over it, \
             see docs/remote.md: which links remote peers may drive over); check firewalls",
        ),
    }
}

/// The gateway's clock (`now_ms` in its information) less this host's, ms, and how far off
/// that may be (half the round trip, and 1 ms for the gateway's whole ms), from the probe
/// answered fastest: as NTP does, taking the gateway's reading to fall halfway through the
/// round trip. `None` from a gateway that does
/// not give its clock. Remote commands need no common clock (the gateway learns each peer's
/// offset), so this is shown, not judged.
fn clock_offset(
    sent: &[(Instant, u64)],
    arrivals: &[(usize, Instant, serde_json::Value)],
) -> Option<(f64, f64)> {
    arrivals
        .iter()
        .filter_map(|(probe, arrived, info)| {
            let (sent_at, sent_ns) = sent[*probe];
            let round_trip = arrived.saturating_duration_since(sent_at);
            let gateway_ms = info["now_ms"].as_u64()? as f64;
            let halfway_ms = sent_ns as f64 / 1e6 + round_trip.as_secs_f64() * 1e3 / 2.0;
            Some((round_trip, gateway_ms - halfway_ms))
        })
        .min_by_key(|(round_trip, _)| *round_trip)
        .map(|(round_trip, offset)| (offset, round_trip.as_secs_f64() * 1e3 / 2.0 + 1.0))
}

/// [`PROBES`] information queries, one every [`PROBE_SPACING`] without waiting for the
/// answers: how many are answered, their round trip, and what the gateway allows remote peers.
fn measure_link(settings: &SessionSettings, robot: &str, endpoint: &str) -> Check {
    let session = match settings.open("client") {
        Ok(session) => session,
        Err(error) => return Check::fail("zenoh.link", error.to_string(), "see the error"),
    };
    // Each answer stamped as it arrives, with the probe it answers.
    let arrivals = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let mut sent = Vec::new();
    for probe in 0..PROBES {
        let arrivals = std::sync::Arc::clone(&arrivals);
        sent.push((Instant::now(), scout_clients::monotonic_ns()));
        let asked = session
            .get(info_key(robot))
            .timeout(PROBE_TIMEOUT)
            .callback(move |reply| {
                let info = reply.result().ok().and_then(|sample| {
                    let text = sample.payload().try_to_string().ok()?;
                    serde_json::from_str::<serde_json::Value>(&text).ok()
                });
                // The first answer to each probe (a router may pass on more than one).
                if let (Some(info), Ok(mut arrivals)) = (info, arrivals.lock())
                    && !arrivals.iter().any(|(answered, _, _)| *answered == probe)
                {
                    arrivals.push((probe, Instant::now(), info));
                }
            })
            .wait();
        if let Err(error) = asked {
            return Check::fail("zenoh.link", format!("querying: {error}"), "see the error");
        }
        std::thread::sleep(PROBE_SPACING);
    }
    let deadline = Instant::now() + PROBE_TIMEOUT;
    while Instant::now() < deadline && arrivals.lock().map_or(0, |a| a.len()) < PROBES {
        std::thread::sleep(Duration::from_millis(10));
    }
    let arrivals = arrivals.lock().map(|a| a.clone()).unwrap_or_default();
    let mut round_trips: Vec<Duration> = (arrivals.iter())
        .map(|(probe, arrived, _)| arrived.saturating_duration_since(sent[*probe].0))
        .collect();
    let offset = clock_offset(&sent, &arrivals);
    let info = arrivals.last().map(|(_, _, info)| info.clone());
    round_trips.sort_unstable();
    let Some(info) = info else {
        return Check::fail(
            "zenoh.link",
            format!("none of {PROBES} queries on scout/{robot}/info was answered"),
            "the state arrives, but queries do not: the access control may allow reading the \
             state and not scout/ROBOT/info, or the link drops every answer",
        );
    };
    let (median, slowest) = (
        round_trips[round_trips.len() / 2],
        round_trips[round_trips.len() - 1],
    );
    let commands = &info["remote_commands"];
    let allowed = match commands["enabled"].as_bool() {
        Some(true) => format!(
            "remote commands on ({})",
            commands["allowed"]
                .as_array()
                .map(|list| {
                    list.iter()
                        .filter_map(serde_json::Value::as_str)
                        .collect::<Vec<_>>()
                        .join(", ")
                })
                .unwrap_or_default()
        ),
        _ => "remote commands off (read-only)".to_owned(),
    };
    let offset = offset.map_or_else(String::new, |(offset, within)| {
        format!("; clock offset {offset:+.1} ms (within {within:.1} ms)")
    });
    let detail = format!(
        "{} of {PROBES} queries answered through {endpoint}, round trip {median:.0?} median, \
         {slowest:.0?} slowest{offset}; {allowed}",
        round_trips.len()
    );
    if round_trips.len() < PROBES || slowest > SLOW_ROUND_TRIP {
        let udp = endpoint.starts_with("udp/");
        return Check::warn(
            "zenoh.link",
            detail,
            if udp {
                "a lossy or slow link: drives put on the fast lane (scout drive --remote) get \
                 through a little loss; past a few percent, or a round trip near 300 ms (a \
                 drive's life), remote driving is not supported (docs/remote.md: which link)"
            } else {
                "a lossy or slow link: over TCP, TLS and QUIC a lost packet holds drives back \
                 (docs/remote.md: which link); use udp/ inside a network you trust or a VPN"
            },
        );
    }
    Check::pass("zenoh.link", detail)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_kind_of_link_gets_the_guides_verdict() {
        let tunnel = Protection::Tunnel {
            interface: "wg0".into(),
        };
        let plain = Protection::Plain {
            reach: "interface wlan0".into(),
        };
        let verdict = |endpoint: &str, protection: &Protection| {
            let check = security(endpoint, protection);
            (check.verdict, check.detail)
        };
        let (pass, detail) = verdict("udp/10.8.0.1:7448", &tunnel);
        assert_eq!(pass, Verdict::Pass);
        assert!(
            detail.contains("recommends") && detail.contains("wg0"),
            "{detail}"
        );
        assert_eq!(verdict("tcp/10.8.0.1:7448", &tunnel).0, Verdict::Warn);
        let (warn, detail) = verdict("udp/10.8.0.1:7448?rel=1;mixed_rel=1", &tunnel);
        assert_eq!(warn, Verdict::Warn);
        assert!(detail.contains("QUIC under udp/"), "{detail}");
        assert_eq!(verdict("udp/192.168.1.20:7448", &plain).0, Verdict::Warn);
        assert_eq!(
            verdict("quic/192.168.1.20:7448", &Protection::ServerTls).0,
            Verdict::Warn
        );
        assert_eq!(
            verdict("quic/192.168.1.20:7448", &Protection::MutualTls).0,
            Verdict::Pass
        );
        assert_eq!(
            verdict("tcp/127.0.0.1:7448", &Protection::Local).0,
            Verdict::Pass
        );
    }

    #[test]
    fn the_clock_offset_comes_from_the_fastest_answer() {
        let start = Instant::now();
        let ms = Duration::from_millis;
        // This host's clock reads 1000 ms at the start; the gateway's is 5000 ms ahead.
        let sent = [(start, 1_000_000_000), (start + ms(50), 1_050_000_000)];
        let info = |now_ms: u64| serde_json::json!({ "now_ms": now_ms });
        let arrivals = [
            // Probe 0: 40 ms there, 10 back (the gateway read 6040).
            (0, start + ms(50), info(6_040)),
            // Probe 1: 5 ms each way (6055), the fastest.
            (1, start + ms(60), info(6_055)),
        ];
        let (offset, within) = clock_offset(&sent, &arrivals).expect("an offset");
        assert!((offset - 5000.0).abs() < 1e-6, "{offset}");
        assert!((within - 6.0).abs() < 1e-6, "{within}");
        // A gateway that does not give its clock: no offset.
        let silent = [(0, start + ms(10), serde_json::json!({}))];
        assert_eq!(clock_offset(&sent, &silent), None);
    }
}
