//! The remote-drive benchmark over a bad network (netem on loopback, in the VM): today's path
//! (drives queried) beside the fast lane (drives put), over TCP, QUIC and UDP, and UDP inside a
//! real WireGuard tunnel (netem on its underlay), at 100 ms delay with 10 % loss and at a bad 4G
//! link. It prints figures and asserts nothing about them; run it
//! with the command in BENCHMARKS.md.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use scout_clients::remote::{RemoteController, RemoteError, SessionSettings};
use scout_system_tests::{
    Gateway, Pki, connect_within, free_port, release_all, robot_name, zenoh_query,
};
use zenoh::Wait;

use crate::LIMIT;
use crate::netem::{Loopback, Netem};
use crate::wireguard::Tunnel;

/// How long each configuration drives.
const DRIVING: Duration = Duration::from_secs(10);

/// E-stops timed per configuration.
const ESTOPS: usize = 10;

/// The drives' speed, m/s.
const SPEED: f64 = 0.3;

/// A drive's life: the same on both paths, so that only the transport differs.
const LIFE: Duration = Duration::from_millis(300);

/// A network profile: a name, the netem rule, and whether control is taken through it.
struct Profile {
    name: &'static str,
    rule: &'static [&'static str],
    /// Control taken (and so the peer's clock offset learned) through the link, as by a
    /// teleop that connects over it; otherwise before the loss, so that the ages are the
    /// true one-way delays.
    taken_through: bool,
}

/// The network profiles.
const PROFILES: [Profile; 3] = [
    Profile {
        name: "100 ms, 10 % loss",
        rule: &["delay", "100ms", "loss", "10%"],
        taken_through: false,
    },
    Profile {
        name: "4G: 300 ± 50 ms, 20 % loss",
        rule: &["delay", "300ms", "50ms", "loss", "20%"],
        taken_through: false,
    },
    // netem's jitter reorders packets, which zenoh drops; an LTE link delivers in order (its
    // RLC layer reorders), which netem's `rate` keeps. Control is taken over the link.
    Profile {
        name: "4G in order, taken over it: 300 ± 50 ms, 20 % loss",
        rule: &["delay", "300ms", "50ms", "loss", "20%", "rate", "20mbit"],
        taken_through: true,
    },
];

/// How drives travel.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Path {
    /// Each drive a query, answered (before the fast lane).
    Queried,
    /// Drives put on the fast lane (`RemoteController`).
    Put,
    /// Drives put alone on a session of their own, none queried (control taken once, on
    /// another session): what a connection that carries only datagrams does.
    PutOnly,
}

/// The links and paths compared.
const RUNS: [(&str, Path); 8] = [
    ("tcp", Path::Queried),
    ("tcp", Path::Put),
    ("quic", Path::Queried),
    ("quic", Path::Put),
    ("quic", Path::PutOnly),
    ("udp", Path::Put),
    // `udp/...?rel=1;mixed_rel=1`: QUIC without encryption underneath, drives as datagrams.
    ("udp-rel", Path::Put),
    // Plain UDP inside a WireGuard tunnel, the gateway bound to it.
    ("wireguard", Path::Put),
];

/// What one configuration measured.
#[derive(Debug, Default)]
struct Figures {
    sent: u64,
    accepted: u64,
    age_p50_ms: Option<u64>,
    age_p99_ms: Option<u64>,
    /// Drives the bridge read, and of those refused for holding no control.
    received: u64,
    no_control: u64,
    /// Fast-lane drives replaced by a newer one of the same peer before the bridge read them.
    superseded: u64,
    lapses: u64,
    estops_ms: Vec<u64>,
    /// Of each, until the gateway published the stop (the status's stamp): the rest is this
    /// test seeing it.
    estops_published_ms: Vec<u64>,
    /// The chassis's states while driving, and those whose command was the drive's speed.
    states: u64,
    at_drive: u64,
}

#[test]
#[ignore = "a benchmark: prints figures (BENCHMARKS.md says how to run it in the VM)"]
fn netem_bench_remote_drive() {
    const TEST: &str = "netem_bench_remote_drive";
    let Some(loopback) = Loopback::or_skip(TEST) else {
        return;
    };
    let pki = Pki::new("netem-bench");
    // `SCOUT_NETEM_RUNS=udp-put,quic-put` runs only those.
    let only: Option<Vec<String>> = std::env::var("SCOUT_NETEM_RUNS")
        .ok()
        .map(|runs| runs.split(',').map(str::to_owned).collect());
    // `SCOUT_NETEM_PROFILES=0,2` runs only the first and the third network.
    let profiles: Option<Vec<usize>> = std::env::var("SCOUT_NETEM_PROFILES").ok().map(|p| {
        (p.split(','))
            .map(|p| {
                p.trim()
                    .parse()
                    .expect("SCOUT_NETEM_PROFILES: indexes, e.g. 0,2")
            })
            .collect()
    });
    let mut rows = Vec::new();
    for (p, profile) in PROFILES.iter().enumerate() {
        if profiles
            .as_ref()
            .is_some_and(|profiles| !profiles.contains(&p))
        {
            continue;
        }
        for (r, (link, path)) in RUNS.into_iter().enumerate() {
            let label = format!("{link}-{path:?}").to_lowercase();
            if only.as_ref().is_some_and(|only| !only.contains(&label)) {
                continue;
            }
            let name = robot_name(&format!("bench-{p}-{r}"));
            // Over the tunnel, netem goes on its underlay (loopback stays without delay).
            let tunnel = match link {
                "wireguard" => match Tunnel::or_skip(TEST) {
                    Some(tunnel) => Some(tunnel),
                    None => continue,
                },
                _ => None,
            };
            let network: &dyn Netem = match &tunnel {
                Some(tunnel) => tunnel,
                None => &loopback,
            };
            let figures = run(network, tunnel.as_ref(), &pki, &name, link, path, profile);
            eprintln!("{link} {path:?} {}: {figures:?}", profile.name);
            rows.push((profile.name, link, path, figures));
        }
    }
    println!(
        "| network | link | drives | read / superseded | accepted | no control | age p50 / p99 (ms) | control lapsed | output at the drive | e-stop latched p50 / max (ms) | of it published p50 / max |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (profile, link, path, figures) in rows {
        let mut estops = figures.estops_ms.clone();
        estops.sort_unstable();
        let mut published = figures.estops_published_ms.clone();
        published.sort_unstable();
        let show = |ms: Option<u64>| ms.map_or("-".to_owned(), |ms| ms.to_string());
        println!(
            "| {profile} | {link}, {} | {} | {} / {} | {:.0} % | {} | {} / {} | {} | {:.0} % | {} / {} ({} of {ESTOPS}) | {} / {} |",
            match path {
                Path::Queried => "queried",
                Path::Put => "put (fast lane)",
                Path::PutOnly => "put alone, none queried",
            },
            figures.sent,
            figures.received,
            figures.superseded,
            100.0 * figures.accepted as f64 / figures.sent.max(1) as f64,
            figures.no_control,
            show(figures.age_p50_ms),
            show(figures.age_p99_ms),
            figures.lapses,
            100.0 * figures.at_drive as f64 / figures.states.max(1) as f64,
            show(estops.get(estops.len() / 2).copied()),
            show(estops.last().copied()),
            estops.len(),
            show(published.get(published.len() / 2).copied()),
            show(published.last().copied()),
        );
    }
}

/// One configuration: a gateway of its own (robot `name`, in the tunnel's robot namespace when
/// there is one), a teleop driving at 50 Hz through `rule` for [`DRIVING`] (taking control
/// again whenever it lapsed), then [`ESTOPS`] e-stops timed to the latch, each released locally.
fn run(
    network: &dyn Netem,
    tunnel: Option<&Tunnel>,
    pki: &Pki,
    name: &str,
    link: &str,
    path: Path,
    profile: &Profile,
) -> Figures {
    network.change(&["delay", "0ms"]);
    let port = free_port();
    let (listen, endpoint) = match (link, tunnel) {
        (_, Some(tunnel)) => (tunnel.listen(port), tunnel.connect(port)),
        ("quic", None) => {
            let endpoint = format!("quic/127.0.0.1:{port}?mixed_rel=1");
            (endpoint.clone(), endpoint)
        }
        ("udp-rel", None) => {
            let endpoint = format!("udp/127.0.0.1:{port}?rel=1;mixed_rel=1");
            (endpoint.clone(), endpoint)
        }
        (_, None) => {
            let endpoint = format!("{link}/127.0.0.1:{port}");
            (endpoint.clone(), endpoint)
        }
    };
    let tls = link == "quic";
    let mut args = vec![
        "--sim",
        "--name",
        &name,
        "--remote-commands",
        "estop,teleop",
    ];
    let gateway_config;
    if tls {
        let listen = format!(r#"listen: {{ endpoints: ["{listen}"] }}"#);
        gateway_config = pki.config("gateway", "peer", &listen, "");
        args.extend(["--zenoh-config", &gateway_config]);
    } else {
        args.extend(["--zenoh-listen", &listen]);
    }
    let through = tunnel.map(|tunnel| tunnel.robot().through());
    let gateway = Gateway::start_through(through.as_ref().map_or(&[][..], |t| &t[..]), &args, &[]);
    let robot = connect_within(name, LIMIT);
    let status = robot.status().expect("status");
    let state = robot.subscribe().expect("state");
    let settings = SessionSettings {
        config_file: tls.then(|| {
            let connect = format!(r#"connect: {{ endpoints: ["{endpoint}"] }}"#);
            pki.config("operator", "client", &connect, "")
        }),
        connect: if tls {
            Vec::new()
        } else {
            vec![endpoint.clone()]
        },
        ..Default::default()
    };
    // Every session opens before the loss; the gateway listens a moment after it starts.
    let deadline = Instant::now() + LIMIT;
    let session = loop {
        if let Ok(session) = settings.open("client")
            && !zenoh_query(&session, &format!("scout/{name}/info"), None, LIMIT).is_empty()
        {
            break session;
        }
        assert!(Instant::now() < deadline, "the gateway never answered");
        std::thread::sleep(Duration::from_millis(200));
    };
    // The emulated CPU may overrun a tick as the gateway starts (a stop): released first, on
    // purpose, as an operator would after checking the robot.
    release_all(name);
    let mut controller = RemoteController::connect(&settings, name, "operator").expect("connect");
    // A take-control or its answer lost through the loss is asked again after a second, as
    // an operator would, not after the default 5 s (half the drive would wait on it).
    controller.set_answer_timeout(Duration::from_secs(1));
    if profile.taken_through {
        network.change(profile.rule);
    }
    let deadline = Instant::now() + LIMIT;
    while let Err(error) = controller.take_control(scout_clients::Class::Teleop) {
        assert!(Instant::now() < deadline, "no take-control: {error}");
    }
    let figures = Arc::new(Mutex::new(Figures::default()));
    let running = Arc::new(AtomicBool::new(true));
    let sent = Arc::new(AtomicU64::new(0));
    let teleop = {
        let (session, name, running, sent, figures) = (
            session.clone(),
            name.to_owned(),
            Arc::clone(&running),
            Arc::clone(&sent),
            Arc::clone(&figures),
        );
        let settings = settings.clone();
        std::thread::spawn(move || match path {
            Path::Put => drive_put(controller, &running, &sent, &figures),
            Path::Queried => drive_queried(&session, &name, &running, &sent, &figures),
            Path::PutOnly => {
                let drives = settings.open("client").expect("the drives' session");
                drive_put_only(&drives, &name, &running, &sent);
                drop(controller);
            }
        })
    };
    network.change(profile.rule);
    // Meanwhile, how much of the time the chassis is commanded the drive's speed.
    let (mut states, mut at_drive) = (0, 0);
    let driving = Instant::now();
    while driving.elapsed() < DRIVING {
        if let Ok(Some(sample)) = state.next_timeout(Duration::from_millis(100)) {
            states += 1;
            at_drive += u64::from((sample.command.linear - SPEED).abs() < 0.01);
        }
    }
    running.store(false, Ordering::Relaxed);
    teleop.join().expect("teleop");
    let mut figures = std::mem::take(&mut *figures.lock().expect("figures"));
    figures.sent = sent.load(Ordering::Relaxed);
    (figures.states, figures.at_drive) = (states, at_drive);

    // E-stops through the same loss: put and queried on the fast lane, queried on the old.
    let estop_key = format!("scout/{name}/cmd/estop/operator");

    for act in 0..ESTOPS {
        // The statuses so far are not this stop's.
        while status.try_next().expect("status").is_some() {}
        let asked = Instant::now();
        let asked_ns = scout_clients::monotonic_ns();
        // Named as `RemoteController::stop` names it: its copies latch it once.
        let estop = format!(
            r#"{{"reason":"bench","seq":{act},"sent_ms":{}}}"#,
            asked_ns / 1_000_000
        );
        if matches!(path, Path::Put | Path::PutOnly) {
            // As `RemoteController::stop` does: copies put in full (no declared publisher).
            for _ in 0..3 {
                let _ = (session.put(&estop_key, &estop))
                    .congestion_control(zenoh::qos::CongestionControl::Drop)
                    .reliability(zenoh::qos::Reliability::BestEffort)
                    .express(true)
                    .wait();
            }
        }
        let answer = session
            .get(&estop_key)
            .payload(&estop)
            .timeout(LIMIT)
            .wait()
            .expect("e-stop query");
        let deadline = asked + LIMIT;
        // Every status waiting is read at each look (one per look would put the test's
        // reading behind the gateway's publishing).
        let latched = 'seen: loop {
            while let Some(seen) = status.try_next().expect("status") {
                if seen.stopped() {
                    let published = seen.published_ns.saturating_sub(asked_ns) / 1_000_000;
                    figures.estops_published_ms.push(published);
                    break 'seen Some(asked.elapsed());
                }
            }
            if Instant::now() > deadline {
                break None;
            }
            std::thread::sleep(Duration::from_millis(1));
        };
        if latched.is_none() {
            let info = zenoh_query(&session, &format!("scout/{name}/info"), None, LIMIT);
            eprintln!(
                "{name}: an e-stop did not latch within {LIMIT:?}: its answer {:?}; counters {}; \
                 the gateway's log:\n{}",
                answer
                    .try_recv()
                    .map(|reply| reply.map(|reply| reply.result().is_ok())),
                info.first()
                    .map(|info| info["counters"].to_string())
                    .unwrap_or_default(),
                gateway.log()
            );
        }
        if let Some(latched) = latched {
            figures.estops_ms.push(latched.as_millis() as u64);
            release_all(name);
            while status
                .latest(Duration::from_millis(100))
                .expect("status")
                .is_some_and(|status| status.stopped())
            {}
        }
    }
    // The link quality, read once the network is good again.
    network.change(&["delay", "0ms"]);
    let info = zenoh_query(&session, &format!("scout/{name}/info"), None, LIMIT);
    if let Some(link) = info.first().map(|info| &info["links"][0]) {
        eprintln!("{name}: {link}");
        figures.accepted = link["accepted"].as_u64().unwrap_or(0);
        figures.age_p50_ms = link["age_p50_ms"].as_u64();
        figures.age_p99_ms = link["age_p99_ms"].as_u64();
        figures.received = link["received"].as_u64().unwrap_or(0);
        figures.no_control = link["no_control"].as_u64().unwrap_or(0);
    }
    if let Some(info) = info.first() {
        figures.superseded = info["counters"]["drives_superseded"].as_u64().unwrap_or(0);
    }
    // `SCOUT_NETEM_LOGS=1` prints each gateway's log (with `SCOUT_TEST_GATEWAY_LOG` for more).
    if std::env::var_os("SCOUT_NETEM_LOGS").is_some() {
        eprintln!("{name}: the gateway's log:\n{}", gateway.log());
    }
    figures
}

/// The fast lane: a drive put every 20 ms; control taken again when an answer says it lapsed.
fn drive_put(
    mut controller: RemoteController,
    running: &AtomicBool,
    sent: &AtomicU64,
    figures: &Mutex<Figures>,
) {
    let mut next = Instant::now();
    while running.load(Ordering::Relaxed) {
        sent.fetch_add(1, Ordering::Relaxed);
        if let Err(RemoteError::Refused { answer, .. }) = controller.drive(SPEED, 0.0, LIFE)
            && answer.lost_control
        {
            figures.lock().expect("figures").lapses += 1;
            let _ = controller.take_control(scout_clients::Class::Teleop);
        }
        next += Duration::from_millis(20);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
}

/// Drive `seq` as the bench's teleop sends it, stamped now.
fn drive(seq: u64) -> String {
    format!(
        r#"{{"seq":{seq},"sent_ms":{},"linear":{SPEED},"angular":0.0,"ttl_ms":{}}}"#,
        scout_clients::monotonic_ns() / 1_000_000,
        LIFE.as_millis()
    )
}

/// Drives put alone on `session`, as `RemoteController` puts them, none queried.
fn drive_put_only(session: &zenoh::Session, name: &str, running: &AtomicBool, sent: &AtomicU64) {
    let key = format!("scout/{name}/cmd/drive/operator");
    let mut seq = 0u64;
    let mut next = Instant::now();
    while running.load(Ordering::Relaxed) {
        seq += 1;
        let payload = drive(seq);
        let _ = (session.put(&key, payload))
            .congestion_control(zenoh::qos::CongestionControl::Drop)
            .reliability(zenoh::qos::Reliability::BestEffort)
            .priority(zenoh::qos::Priority::RealTime)
            .express(true)
            .wait();
        sent.fetch_add(1, Ordering::Relaxed);
        next += Duration::from_millis(20);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
}

/// Today's path: each drive a query, its answer read when it comes; control taken again when
/// an answer says it lapsed.
fn drive_queried(
    session: &zenoh::Session,
    name: &str,
    running: &AtomicBool,
    sent: &AtomicU64,
    figures: &Mutex<Figures>,
) {
    let key = |kind: &str| format!("scout/{name}/cmd/{kind}/operator");
    let mut pending = Vec::new();
    let mut seq = 0u64;
    let mut next = Instant::now();
    while running.load(Ordering::Relaxed) {
        seq += 1;
        let payload = drive(seq);
        let replies = (session.get(key("drive")).payload(payload))
            .timeout(LIMIT)
            .wait()
            .expect("send a drive query");
        pending.push(replies);
        sent.fetch_add(1, Ordering::Relaxed);
        let mut lapsed = false;
        pending.retain(|replies| match replies.try_recv() {
            Ok(Some(reply)) => {
                let answer: serde_json::Value = reply
                    .result()
                    .ok()
                    .and_then(|sample| {
                        sample
                            .payload()
                            .try_to_string()
                            .ok()
                            .map(|t| t.into_owned())
                    })
                    .and_then(|text| serde_json::from_str(&text).ok())
                    .unwrap_or_default();
                lapsed |= answer["lost_control"] == true;
                false
            }
            Ok(None) => true,
            Err(_) => false,
        });
        if lapsed {
            figures.lock().expect("figures").lapses += 1;
            pending.clear();
            // As an operator would: take control, and wait for the answer.
            let _ = session
                .get(key("take-control"))
                .payload(format!(
                    r#"{{"class":"teleop","sent_ms":{}}}"#,
                    scout_clients::monotonic_ns() / 1_000_000
                ))
                .timeout(LIMIT)
                .wait()
                .map(|replies| replies.recv_timeout(LIMIT));
        }
        next += Duration::from_millis(20);
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
}
