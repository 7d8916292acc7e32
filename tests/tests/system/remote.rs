//! Zenoh for remote peers, over 127.0.0.1 only with multicast scouting off: state to a remote
//! process, liveliness, queryables, remote commands (off by default, then enabled and
//! authenticated with TLS and access control), and a two-robot fleet through a router.

use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use scout_clients::interface::json::state_json;
use scout_clients::monotonic_ns;
use scout_system_tests::{
    Background, Gateway, NetNs, Pki, Sim, connect, free_port, robot_name, scout, skip, tcp,
    wait_for_state, wait_for_status, zenoh_query, zenoh_session,
};
use serde_json::Value;
use zenoh::Wait;
use zenoh::sample::SampleKind;

const LIMIT: Duration = Duration::from_secs(10);
const QUERY: Duration = Duration::from_secs(3);
/// How long a query that must reach nothing waits (loopback answers take milliseconds).
const DENIED: Duration = Duration::from_secs(1);

/// Queries until the gateway's queryable answers (it starts after the session opens).
fn query_until_answered(session: &zenoh::Session, key: &str) -> Value {
    let deadline = Instant::now() + LIMIT;
    loop {
        if let Some(answer) = zenoh_query(session, key, None, Duration::from_millis(500)).pop() {
            return answer;
        }
        assert!(Instant::now() < deadline, "no answer on {key}");
    }
}

/// A gateway on the simulator listening for zenoh on `endpoint` (with `args`: `--remote-commands`
/// and the like), read here through iceoryx2, and a zenoh session that reached it.
struct Remote {
    name: String,
    _gateway: Gateway,
    robot: scout_clients::client::Robot,
    status: scout_clients::control::StatusReader,
    session: zenoh::Session,
}

impl Remote {
    fn start(prefix: &str, endpoint: &str, args: &[&str]) -> Remote {
        let name = robot_name(prefix);
        let gateway = Gateway::start(
            &[
                &["--sim", "--name", &name, "--zenoh-listen", endpoint],
                args,
            ]
            .concat(),
        );
        let robot = connect(&name);
        let status = robot.status().expect("status");
        let session = zenoh_session("client", &[], &[endpoint.to_owned()]);
        query_until_answered(&session, &format!("scout/{name}/info"));
        Remote {
            name,
            _gateway: gateway,
            robot,
            status,
            session,
        }
    }
}

#[test]
fn a_remote_process_reads_the_state_of_a_gateway_driving_the_simulator() {
    let name = robot_name("remote-state");
    let port = free_port();
    let sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&[
        "--serial",
        &device,
        "--name",
        &name,
        "--zenoh-listen",
        &tcp(port),
    ]);
    connect(&name);
    let (code, stdout, stderr) = scout(&[
        "echo",
        "--remote",
        &tcp(port),
        "--name",
        &name,
        "--json",
        "--count",
        "5",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    let states: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).expect("JSON"))
        .collect();
    assert_eq!(states.len(), 5);
    for state in &states {
        assert_eq!(state["robot"], name.as_str());
        assert_eq!(state["link"]["transport"], "serial");
    }
    assert!(
        states
            .iter()
            .any(|s| s["link"]["state"] == "ok" && s["system"]["state"] == "normal")
    );
    // The queryables: the latest state on get, and the gateway's information.
    let session = zenoh_session("client", &[], &[tcp(port)]);
    let state = query_until_answered(&session, &format!("scout/{name}/state"));
    assert_eq!(state["robot"], name.as_str());
    let info = query_until_answered(&session, &format!("scout/{name}/info"));
    assert_eq!(info["transport"], "serial");
    assert_eq!(info["device"], device.as_str());
    assert_eq!(info["remote_commands"]["enabled"], false);
    assert_eq!(info["max_linear"], 1.5);
}

#[test]
fn liveliness_appears_and_disappears_with_the_gateway() {
    let name = robot_name("alive");
    let router_port = free_port();
    let router = zenoh_session("router", &[tcp(router_port)], &[]);
    let tokens = router
        .liveliness()
        .declare_subscriber(format!("scout/{name}/alive"))
        .history(true)
        .wait()
        .expect("liveliness subscriber");
    let mut gateway = Gateway::start(&[
        "--sim",
        "--name",
        &name,
        "--zenoh-listen",
        &tcp(free_port()),
        "--zenoh-connect",
        &tcp(router_port),
    ]);
    let appeared = tokens
        .recv_timeout(LIMIT)
        .expect("receive")
        .expect("the token appears");
    assert_eq!(appeared.kind(), SampleKind::Put);
    gateway.signal(Signal::SIGTERM);
    assert_eq!(gateway.wait_exit(LIMIT), Some(0));
    let gone = tokens
        .recv_timeout(LIMIT)
        .expect("receive")
        .expect("the token disappears");
    assert_eq!(gone.kind(), SampleKind::Delete);
}

#[test]
fn remote_commands_are_ignored_by_default_and_counted() {
    let Remote {
        name,
        robot,
        session,
        _gateway,
        ..
    } = Remote::start("remote-off", &tcp(free_port()), &[]);
    let answers = zenoh_query(
        &session,
        &format!("scout/{name}/cmd/estop/laptop"),
        Some("{}"),
        QUERY,
    );
    assert_eq!(answers.len(), 1);
    assert_eq!(answers[0]["accepted"], false);
    assert!(
        answers[0]["reason"]
            .as_str()
            .is_some_and(|r| r.contains("disabled")),
        "{answers:?}"
    );
    session
        .put(format!("scout/{name}/cmd/drive/x"), "{}")
        .wait()
        .expect("put");
    let status = robot.status().expect("status");
    assert_eq!(wait_for_status(&status, LIMIT, |_| true)["latched"], false);
    let deadline = Instant::now() + LIMIT;
    loop {
        let info = query_until_answered(&session, &format!("scout/{name}/info"));
        let counters = &info["counters"];
        if counters["commands_ignored_disabled"] == 1 && counters["puts_ignored"] == 1 {
            break;
        }
        assert!(Instant::now() < deadline, "{info}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Peer `peer`'s command `kind` with `payload` to robot `name`, queried: its one answer.
fn remote_command(
    session: &zenoh::Session,
    name: &str,
    kind: &str,
    peer: &str,
    payload: &str,
) -> Value {
    let mut answers = zenoh_query(
        session,
        &format!("scout/{name}/cmd/{kind}/{peer}"),
        Some(payload),
        QUERY,
    );
    assert_eq!(answers.len(), 1, "{kind} {payload}: {answers:?}");
    answers.remove(0)
}

#[test]
fn enabled_remote_commands_go_through_the_arbiter_and_bad_input_is_rejected() {
    let Remote {
        name,
        robot,
        status,
        session,
        _gateway,
    } = Remote::start(
        "remote-on",
        &tcp(free_port()),
        &["--remote-commands", "estop,teleop,release"],
    );
    // The peer's name is the last chunk of the key: zenoh's access control binds it to the
    // peer's certificate (see the TLS test); the payload names nobody.
    let command = |kind: &str, peer: &str, payload: &str| {
        remote_command(&session, &name, kind, peer, payload)
    };
    let drive = |seq: u64, sent_ms: u64| {
        format!(r#"{{"seq":{seq},"sent_ms":{sent_ms},"linear":0.3,"angular":0.0,"ttl_ms":300}}"#)
    };
    let no_control = command("drive", "laptop", &drive(1, 1000));
    assert!(
        no_control["reason"]
            .as_str()
            .is_some_and(|r| r.contains("take-control")),
        "{no_control}"
    );
    assert_eq!(
        command(
            "take-control",
            "laptop",
            r#"{"class":"teleop","sent_ms":1000}"#
        )["accepted"],
        true
    );
    // The peer's clock: 1000 ms at the take-control (a stamp ahead of it is refused).
    let took = std::time::Instant::now();
    let peer_now = || 1000 + took.elapsed().as_millis() as u64;
    assert_eq!(
        command("drive", "laptop", &drive(2, 1000))["accepted"],
        true
    );
    let driving = wait_for_status(&status, LIMIT, |s| {
        s["selected"]["client"] == "remote:laptop"
    });
    assert_eq!(driving["selected"]["class"], "teleop");
    // Duplicated and reordered commands are refused; so is one the network held up past its
    // life (sent 1000 ms "earlier" than the fastest delivery seen from this peer).
    let duplicate = command("drive", "laptop", &drive(2, 1020));
    assert!(
        duplicate["reason"]
            .as_str()
            .is_some_and(|r| r.contains("out of order")),
        "{duplicate}"
    );
    let held_up = command("drive", "laptop", &drive(3, 1040 - 1000));
    assert!(
        held_up["reason"]
            .as_str()
            .is_some_and(|r| r.contains("held up")),
        "{held_up}"
    );
    let refusals = [
        ("take-control", r#"{"class":"autonomy"}"#, "not allowed"),
        ("resume", "{}", "not allowed"),
        (
            "drive",
            r#"{"seq":9,"sent_ms":1,"linear":"NaN","angular":0.0}"#,
            "invalid JSON",
        ),
        ("drive", "{not json", "invalid JSON"),
        (
            "drive",
            r#"{"seq":10,"sent_ms":1}"#,
            "needs `linear` and `angular`",
        ),
        ("drive", r#"{"linear":1,"angular":0}"#, "needs `seq`"),
        (
            "drive",
            r#"{"linear":1,"angular":0,"extra":1}"#,
            "invalid JSON",
        ),
        ("fly", "{}", "unknown command"),
    ];
    for (kind, payload, reason) in refusals {
        let answer = command(kind, "laptop", payload);
        assert_eq!(answer["accepted"], false, "{kind} {payload}");
        assert!(
            answer["reason"]
                .as_str()
                .is_some_and(|r| r.contains(reason)),
            "{kind} {payload}: {answer}"
        );
    }
    let nameless = zenoh_query(
        &session,
        &format!("scout/{name}/cmd/estop"),
        Some("{}"),
        QUERY,
    );
    assert!(
        nameless[0]["reason"]
            .as_str()
            .is_some_and(|r| r.contains("name yourself")),
        "{nameless:?}"
    );
    // A local officer's stop: a remote peer allowed `release` releases only its own stops.
    robot
        .stopper("safety-officer")
        .expect("stopper")
        .stop("person ahead")
        .expect("stop");
    let not_owner = command("release", "laptop", "{}");
    assert_eq!(not_owner["accepted"], false, "{not_owner}");
    assert!(
        not_owner["reason"]
            .as_str()
            .is_some_and(|r| r.contains("safety-officer")),
        "{not_owner}"
    );
    // An e-stop is never refused for its payload: an oversized one only loses its reason.
    let huge = format!(r#"{{"reason":"{}"}}"#, "x".repeat(5000));
    assert_eq!(command("estop", "laptop", &huge)["accepted"], true);
    let latched = wait_for_status(&status, LIMIT, |s| s["stop_total"] == 2);
    assert_eq!(latched["stops"][1]["owner"], "remote:laptop");
    assert_eq!(command("release", "laptop", "{}")["accepted"], true);
    let left = wait_for_status(&status, LIMIT, |s| s["stop_total"] == 1);
    assert_eq!(
        left["stops"][0]["owner"], "safety-officer",
        "the officer's stop holds"
    );
    // The lease ended with the stop: the old stream is refused until it takes control again.
    let revoked = command("drive", "laptop", &drive(20, peer_now()));
    assert!(
        revoked["reason"]
            .as_str()
            .is_some_and(|r| r.contains("control revoked (stop by safety-officer")),
        "{revoked}"
    );
    let again = command("drive", "laptop", &drive(21, 2020));
    assert!(
        again["reason"]
            .as_str()
            .is_some_and(|r| r.contains("take-control")),
        "{again}"
    );
}

/// A take-control the network held up across a release arrives after it: refused as outdated,
/// so healing restarts nothing; one sent after the release takes control.
#[test]
fn a_take_control_held_up_across_a_release_is_refused_as_outdated() {
    let Remote {
        name,
        status,
        session,
        _gateway,
        ..
    } = Remote::start(
        "remote-outdated",
        &tcp(free_port()),
        &["--remote-commands", "estop,teleop,release"],
    );
    let started = Instant::now();
    let clock_ms = || 1_000 + started.elapsed().as_millis() as u64;
    let command =
        |kind: &str, payload: &str| remote_command(&session, &name, kind, "laptop", payload);
    let take = |sent_ms: u64| {
        command(
            "take-control",
            &format!(r#"{{"class":"teleop","sent_ms":{sent_ms}}}"#),
        )
    };
    // The first take-control: the bridge learns how fast this peer's commands arrive.
    let first = take(clock_ms());
    assert_eq!(first["accepted"], true, "{first}");
    // The peer's e-stop ends its control. A take-control it sends while the stop holds (stamped
    // then) is held up in the network and arrives after the release. A loaded host may hold
    // the release up past the command's life (500 ms): that is refused too ("held up"), and
    // tried again.
    let mut answers = Vec::new();
    for _ in 0..3 {
        assert_eq!(command("estop", r#"{"reason":"check"}"#)["accepted"], true);
        let stamped = clock_ms();
        // Longer than the arbiter's tolerance for a remote send time's estimate (100 ms).
        std::thread::sleep(Duration::from_millis(200));
        let released = command("release", "{}");
        assert_eq!(released["accepted"], true, "{released}");
        let late = take(stamped);
        assert_eq!(late["accepted"], false, "{late}");
        let outdated = late["reason"]
            .as_str()
            .is_some_and(|r| r.contains("before the stops were released"));
        answers.push(late);
        if outdated {
            break;
        }
    }
    let last = answers.last().expect("an answer");
    assert!(
        last["reason"]
            .as_str()
            .is_some_and(|r| r.contains("before the stops were released")),
        "{answers:#?}"
    );
    let counted = wait_for_status(&status, LIMIT, |s| s["rejections"]["outdated"] == 1);
    assert!(counted["selected"].is_null(), "{counted}");
    // Sent after the release: a new decision, which takes control.
    let again = take(clock_ms());
    assert_eq!(again["accepted"], true, "{again}");
}

/// The counters of the gateway's information queryable once `wanted` holds (polled).
fn counters_when(session: &zenoh::Session, name: &str, wanted: impl Fn(&Value) -> bool) -> Value {
    let deadline = Instant::now() + LIMIT;
    loop {
        let info = query_until_answered(session, &format!("scout/{name}/info"));
        if wanted(&info["counters"]) {
            return info["counters"].clone();
        }
        assert!(Instant::now() < deadline, "{info}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn drives_put_on_the_fast_lane_drive_and_stop_when_they_stop() {
    drives_put_on_the_fast_lane(&tcp(free_port()));
}

/// The same over a plain UDP link (no TLS: on a network you trust only).
#[test]
fn drives_put_over_udp_drive_and_stop_when_they_stop() {
    drives_put_on_the_fast_lane(&format!("udp/127.0.0.1:{}", free_port()));
}

fn drives_put_on_the_fast_lane(endpoint: &str) {
    let scheme = endpoint.split('/').next().unwrap_or("link");
    let Remote {
        name,
        robot,
        status,
        session,
        _gateway,
    } = Remote::start(
        &format!("remote-put-{scheme}"),
        endpoint,
        &["--remote-commands", "estop,teleop"],
    );
    let state = robot.subscribe().expect("subscribe");
    let key = format!("scout/{name}/cmd/drive/laptop");
    let started = Instant::now();
    let sent_ms = || 1_000 + started.elapsed().as_millis() as u64;
    let put = |seq: u64| {
        let drive = format!(
            r#"{{"seq":{seq},"sent_ms":{},"linear":0.4,"angular":0.0,"ttl_ms":300}}"#,
            sent_ms()
        );
        session.put(&key, drive).wait().expect("put");
    };
    // Without control a put drives nothing: refused and counted (a put has no answer).
    put(1);
    counters_when(&session, &name, |c| c["drives_put_rejected"] == 1);
    let taken = zenoh_query(
        &session,
        &format!("scout/{name}/cmd/take-control/laptop"),
        Some(&format!(r#"{{"class":"teleop","sent_ms":{}}}"#, sent_ms())),
        QUERY,
    );
    assert_eq!(taken[0]["accepted"], true, "{taken:?}");
    // Puts at 50 Hz drive the chassis.
    let mut seq = 1;
    let deadline = Instant::now() + LIMIT;
    loop {
        seq += 1;
        put(seq);
        let driving = state
            .next_timeout(Duration::from_millis(20))
            .expect("state")
            .map(|s| state_json(&s, monotonic_ns()))
            .is_some_and(|s| s["motion"]["linear"].as_f64() > Some(0.3));
        if driving {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "the puts never drove the chassis"
        );
    }
    let driving = wait_for_status(&status, LIMIT, |s| {
        s["selected"]["client"] == "remote:laptop"
    });
    assert_eq!(driving["selected"]["class"], "teleop");
    // A replayed put (an old seq) is refused, not applied. (A put the host held up past its
    // life may be refused too: counts are compared, not equated.)
    let rejected = |c: &Value| c["drives_put_rejected"].as_u64().unwrap_or(0);
    let before = rejected(&counters_when(&session, &name, |c| {
        c["drives_put_accepted"].as_u64() >= Some(1)
    }));
    put(1);
    counters_when(&session, &name, |c| rejected(c) > before);
    // The puts stop (a lost link): the command is zero once its life ends, and control
    // ends; a later put is refused until the peer takes control again.
    wait_for_state(&state, LIMIT, |s| s["command"]["linear"] == 0.0);
    wait_for_status(&status, LIMIT, |s| s["selected"].is_null());
    let before = rejected(&counters_when(&session, &name, |_| true));
    put(seq + 1);
    counters_when(&session, &name, |c| rejected(c) > before);
    // What changes who drives is a query: a put of another kind is ignored and counted.
    session
        .put(format!("scout/{name}/cmd/resume/laptop"), "{}")
        .wait()
        .expect("put");
    counters_when(&session, &name, |c| c["puts_ignored"] == 1);
    assert_eq!(wait_for_status(&status, LIMIT, |_| true)["latched"], false);
    // But an e-stop goes on both lanes: put and queried, it latches once, as the peer's. Named
    // (`seq` and `sent_ms`), whichever copy arrives second is answered as the stop the first
    // latched: a release decided on that answer releases it.
    let newest = |status: &serde_json::Value| status["newest_stop"].as_u64().unwrap_or(0);
    let before = newest(&wait_for_status(&status, LIMIT, |_| true));
    let estop_key = format!("scout/{name}/cmd/estop/laptop");
    let estop = r#"{"reason":"both lanes","seq":900,"sent_ms":5}"#;
    session.put(&estop_key, estop).wait().expect("put");
    let answered = zenoh_query(&session, &estop_key, Some(estop), QUERY);
    assert_eq!(answered[0]["accepted"], true, "{answered:?}");
    let counted = counters_when(&session, &name, |c| c["estops_accepted"] == 2);
    assert_eq!(counted["estops_copies"], 1, "{counted}");
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    let stops = latched["stops"].as_array().expect("stops");
    assert_eq!(stops.len(), 1, "{latched}");
    assert_eq!(stops[0]["owner"], "remote:laptop");
    assert_eq!(stops[0]["reason"], "both lanes");
    assert_eq!(newest(&latched), before + 1, "latched once: {latched}");
    assert_eq!(answered[0]["stop"], before + 1, "{answered:?}");
    // Another e-stop of the same peer (another number) latches again, a new id.
    let again = r#"{"reason":"both lanes","seq":901,"sent_ms":6}"#;
    let answered = zenoh_query(&session, &estop_key, Some(again), QUERY);
    assert_eq!(answered[0]["stop"], before + 2, "{answered:?}");
}

/// `scout drive --remote` drives on the fast lane (over plain UDP) and its
/// link quality shows; `scout estop --remote` latches the peer's stop, which ends the drive's
/// control (it exits, refused, and never takes control back); `scout release --remote`
/// releases that stop, and nothing moves.
#[test]
fn scout_drives_stops_and_releases_a_remote_robot() {
    let name = robot_name("remote-scout");
    let endpoint = format!("udp/127.0.0.1:{}", free_port());
    let _gateway = Gateway::start_remote(&name, &endpoint, &[]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let state = robot.subscribe().expect("subscribe");
    let session = zenoh_session("client", &[], std::slice::from_ref(&endpoint));
    query_until_answered(&session, &format!("scout/{name}/info"));
    let remote = ["--name", &name, "--remote", &endpoint, "--client", "laptop"];
    let mut drive = Background::scout(&[&["drive", "--linear", "0.4"], &remote[..]].concat());
    let driving = wait_for_status(&status, LIMIT, |s| {
        s["selected"]["client"] == "remote:laptop"
    });
    assert_eq!(driving["selected"]["class"], "teleop");
    wait_for_state(&state, LIMIT, |s| {
        s["motion"]["linear"].as_f64() > Some(0.3)
    });
    let links = counters_when(&session, &name, |_| true);
    let info = query_until_answered(&session, &format!("scout/{name}/info"));
    let link = &info["links"][0];
    assert_eq!(link["peer"], "remote:laptop", "{info} {links}");
    assert!(link["accepted"].as_u64() > Some(10), "{link}");
    assert!(link["age_p99_ms"].is_u64(), "{link}");
    // The published link quality says the same.
    let published = session
        .declare_subscriber(format!("scout/{name}/links"))
        .wait()
        .expect("subscribe to the links");
    let sample = published
        .recv_timeout(LIMIT)
        .expect("links")
        .expect("links");
    let text = sample.payload().try_to_string().expect("text").into_owned();
    let published: Value = serde_json::from_str(&text).expect("links JSON");
    assert_eq!(published[0]["peer"], "remote:laptop", "{published}");
    // `scout status --remote`: the status through zenoh, with each peer's link quality.
    let (code, stdout, stderr) =
        scout(&["status", "--json", "--name", &name, "--remote", &endpoint]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    let remote_status: Value = serde_json::from_str(&stdout).expect("status JSON");
    assert_eq!(
        remote_status["selected"]["client"], "remote:laptop",
        "{remote_status}"
    );
    assert_eq!(
        remote_status["links"][0]["peer"], "remote:laptop",
        "{remote_status}"
    );
    assert!(
        remote_status["links"][0]["accepted"].as_u64() > Some(10),
        "{remote_status}"
    );
    let (code, stdout, stderr) = scout(&["status", "--name", &name, "--remote", &endpoint]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    assert!(
        stdout.contains("link      remote:laptop  accepted "),
        "{stdout}"
    );

    let (code, stdout, stderr) = scout(&[&["estop", "--reason", "wall"], &remote[..]].concat());
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    // The answer names the stop, as the status lists it. Its copies (puts, on the drive lane)
    // and its queries may arrive apart: each later one refreshes the same stop with a new id,
    // so the status lists the answer's id or a newer one, in one entry.
    let id: u64 = (stdout.strip_prefix("stop #"))
        .and_then(|rest| rest.split_once(' '))
        .and_then(|(id, rest)| rest.starts_with("latched").then_some(id))
        .and_then(|id| id.parse().ok())
        .unwrap_or_else(|| panic!("no stop id in {stdout:?}"));
    let latched = wait_for_status(&status, LIMIT, |s| s["stops"][0]["id"].as_u64() >= Some(id));
    assert_eq!(latched["latched"], true, "{latched}");
    assert_eq!(latched["stops"][0]["owner"], "remote:laptop", "{latched}");
    assert_eq!(
        latched["stops"].as_array().map(Vec::len),
        Some(1),
        "{latched}"
    );
    // The drive learns from an answer that its control ended, and exits refused (4).
    assert_eq!(drive.wait_exit(LIMIT), Some(4));
    wait_for_state(&state, LIMIT, |s| s["command"]["linear"] == 0.0);

    // A careless client of the same peer goes on putting drives through the release: they
    // are refused, since control ended with the stop.
    let streaming = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let careless = {
        let (session, key, streaming) = (
            session.clone(),
            format!("scout/{name}/cmd/drive/laptop"),
            std::sync::Arc::clone(&streaming),
        );
        std::thread::spawn(move || {
            let mut seq = 1_000_000;
            while streaming.load(std::sync::atomic::Ordering::Relaxed) {
                seq += 1;
                let drive = format!(
                    r#"{{"seq":{seq},"sent_ms":{},"linear":0.4,"angular":0.0,"ttl_ms":300}}"#,
                    monotonic_ns() / 1_000_000
                );
                session.put(&key, drive).wait().expect("put");
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };
    let (code, stdout, stderr) = scout(&[&["release"], &remote[..]].concat());
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    let (code, _, stderr) = scout(&[&["release", "--owner", "x"], &remote[..]].concat());
    assert_eq!(code, Some(2), "{stderr}");
    // Released, nothing moves: control ended with the stop.
    let still = Instant::now();
    while still.elapsed() < Duration::from_secs(1) {
        if let Some(sample) = state
            .next_timeout(Duration::from_millis(100))
            .expect("state")
        {
            assert_eq!(sample.command.linear, 0.0, "a release restarted motion");
        }
    }
    streaming.store(false, std::sync::atomic::Ordering::Relaxed);
    careless.join().expect("the careless client");
    let refused = counters_when(&session, &name, |_| true);
    assert!(
        refused["drives_put_rejected"].as_u64() > Some(10),
        "{refused}"
    );
}

/// The Python example of docs/remote.md (plain `eclipse-zenoh`, the JSON protocol) drives the
/// robot on the fast lane and gives control back. Needs `python3` (or `$SCOUT_PYTHON`) with
/// `eclipse-zenoh`; `.ci/run` installs it (and requires this test to run).
#[test]
fn the_python_zenoh_example_drives_on_the_fast_lane() {
    const TEST: &str = "the_python_zenoh_example_drives_on_the_fast_lane";
    let python = crate::ros2::python();
    let has_zenoh = std::process::Command::new(&python)
        .args(["-c", "import zenoh"])
        .output()
        .is_ok_and(|output| output.status.success());
    if !has_zenoh {
        assert!(
            std::env::var_os("SCOUT_REQUIRE_ROS2_STANDIN").is_none(),
            "{TEST}: {python} lacks eclipse-zenoh"
        );
        scout_system_tests::skip(
            TEST,
            &format!("{python} lacks eclipse-zenoh (pip install eclipse-zenoh)"),
        );
        return;
    }
    let name = robot_name("remote-python");
    let endpoint = format!("udp/127.0.0.1:{}", free_port());
    // The secure recipe's configurations (users and access control), on loopback.
    let configs = scout_system_tests::ShippedUsers::new(&name, &endpoint);
    let _gateway = Gateway::start(&[
        "--sim",
        "--name",
        &name,
        "--zenoh-config",
        &configs.gateway,
        "--zenoh-listen",
        &endpoint,
        "--remote-commands",
        "estop,teleop",
    ]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let state = robot.subscribe().expect("subscribe");
    let alice = configs.operator(Some(("alice", "alice-secret")));
    let session = scout_system_tests::open_within(
        &scout_clients::remote::SessionSettings {
            config_file: Some(alice.clone()),
            connect: vec![endpoint.clone()],
            ..Default::default()
        },
        LIMIT,
    );
    query_until_answered(&session, &format!("scout/{name}/info"));
    let example =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/remote_drive.py");
    let mut command = std::process::Command::new(&python);
    command
        .arg(example)
        .args(["--connect", &endpoint, "--config", &alice])
        .args(["--name", &name, "--peer", "alice"])
        .args(["--linear", "0.4", "--duration", "4"]);
    let mut driver = Background::spawn(command);
    let driving = wait_for_status(&status, LIMIT, |s| {
        s["selected"]["client"] == "remote:alice"
    });
    assert_eq!(driving["selected"]["class"], "teleop");
    wait_for_state(&state, LIMIT, |s| {
        s["motion"]["linear"].as_f64() > Some(0.3)
    });
    assert_eq!(driver.wait_exit(LIMIT), Some(0));
    // Control given back: the output ramps to zero.
    wait_for_state(&state, LIMIT, |s| s["command"]["linear"] == 0.0);
    let links = counters_when(&session, &name, |_| true);
    let info = query_until_answered(&session, &format!("scout/{name}/info"));
    assert!(
        info["links"][0]["accepted"].as_u64() > Some(50),
        "{info} {links}"
    );
    assert!(links["drives_put_accepted"].as_u64() > Some(50), "{links}");
}

#[test]
fn a_two_robot_fleet_through_a_router() {
    let router_port = free_port();
    let _router = Background::scout(&["router", "--listen", &tcp(router_port)]);
    let names = [robot_name("fleet-a"), robot_name("fleet-b")];
    let _gateways: Vec<Gateway> = names
        .iter()
        .map(|name| {
            Gateway::start(&[
                "--sim",
                "--name",
                name,
                "--zenoh-listen",
                &tcp(free_port()),
                "--zenoh-connect",
                &tcp(router_port),
            ])
        })
        .collect();
    for name in &names {
        connect(name);
    }
    let (code, stdout, stderr) = scout(&[
        "echo",
        "--remote",
        &tcp(router_port),
        "--name",
        "*",
        "--json",
        "--count",
        "60",
    ]);
    assert_eq!(code, Some(0), "{stderr}");
    for name in &names {
        assert!(
            stdout
                .lines()
                .any(|l| l.contains(&format!("\"robot\":\"{name}\""))),
            "{name} missing"
        );
    }
}

/// The access control of the documented set-up: only the operator's certificate may use the
/// robot's keys; everyone else is denied everything.
const OPERATOR_ONLY: &str = r#"access_control: {
    enabled: true,
    default_permission: "deny",
    rules: [
      {
        id: "declarations",
        messages: ["declare_subscriber", "declare_queryable", "liveliness_token",
                   "liveliness_query", "declare_liveliness_subscriber"],
        flows: ["ingress", "egress"],
        permission: "allow",
        key_exprs: ["scout/**"],
      },
      {
        id: "read",
        messages: ["put", "delete", "query", "reply"],
        flows: ["ingress", "egress"],
        permission: "allow",
        key_exprs: ["scout/*/state", "scout/*/status", "scout/*/info", "scout/*/alive"],
      },
      {
        id: "command-as-operator",
        messages: ["put", "query", "reply"],
        flows: ["ingress", "egress"],
        permission: "allow",
        key_exprs: ["scout/*/cmd/*/operator"],
      },
    ],
    subjects: [{ id: "operator", cert_common_names: ["operator"] }],
    policies: [{ rules: ["declarations", "read", "command-as-operator"], subjects: ["operator"] }],
  },"#;

#[test]
fn tls_with_mutual_authentication_and_access_control() {
    mutual_tls_and_access_control("tls");
}

/// QUIC takes the TLS settings: the same certificates, the same access control.
#[test]
fn quic_with_mutual_authentication_and_access_control() {
    mutual_tls_and_access_control("quic");
}

fn mutual_tls_and_access_control(scheme: &str) {
    let name = robot_name(scheme);
    let pki = Pki::new(scheme);
    let endpoint = format!("{scheme}/127.0.0.1:{}", free_port());
    let listen = format!(r#"listen: {{ endpoints: ["{endpoint}"] }}"#);
    let connect_to = format!(r#"connect: {{ endpoints: ["{endpoint}"] }}"#);
    let gateway_config = pki.config("gateway", "peer", &listen, OPERATOR_ONLY);
    let mut gateway = Gateway::start(&[
        "--sim",
        "--name",
        &name,
        "--zenoh-config",
        &gateway_config,
        "--remote-commands",
        "estop,teleop,release",
    ]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    // The gateway listens a moment after its services are up.
    let open = |who: &str| {
        let settings = scout_clients::remote::SessionSettings {
            config_file: Some(pki.config(who, "client", &connect_to, "")),
            ..Default::default()
        };
        scout_system_tests::open_within(&settings, LIMIT)
    };
    // The operator reads and commands.
    let operator = open("operator");
    let state = query_until_answered(&operator, &format!("scout/{name}/state"));
    assert_eq!(state["robot"], name.as_str());
    let estop = format!("scout/{name}/cmd/estop/operator");
    let answers = zenoh_query(&operator, &estop, Some(r#"{"reason":"tls test"}"#), QUERY);
    assert_eq!(answers.len(), 1, "{answers:?}");
    assert_eq!(answers[0]["accepted"], true);
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], "remote:operator");
    // The certificate binds the name: the operator cannot command as another peer.
    let impostor = format!("scout/{name}/cmd/release/laptop");
    assert!(zenoh_query(&operator, &impostor, Some("{}"), QUERY).is_empty());
    let release = format!("scout/{name}/cmd/release/operator");
    assert_eq!(
        zenoh_query(&operator, &release, Some("{}"), QUERY)[0]["accepted"],
        true
    );
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    // The intruder's certificate is valid, but the access control gives it nothing: its
    // command never reaches the gateway, and nothing latches.
    let intruder = open("intruder");
    let answers = zenoh_query(&intruder, &estop, Some("{}"), QUERY);
    assert!(answers.is_empty(), "the intruder was answered: {answers:?}");
    assert!(zenoh_query(&intruder, &format!("scout/{name}/state"), None, QUERY).is_empty());
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(wait_for_status(&status, LIMIT, |_| true)["latched"], false);
    // A certificate named `operator` but signed by another CA: the gateway does not trust it
    // (nor does that peer trust the gateway's), so it reaches nothing.
    let rogue = Pki::new(&format!("{scheme}-rogue"));
    let rogue_settings = scout_clients::remote::SessionSettings {
        config_file: Some(rogue.config("operator", "client", &connect_to, "")),
        ..Default::default()
    };
    if let Ok(session) = rogue_settings.open("client") {
        let answers = zenoh_query(&session, &estop, Some("{}"), QUERY);
        assert!(answers.is_empty(), "a wrong CA was answered: {answers:?}");
    }
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(wait_for_status(&status, LIMIT, |_| true)["latched"], false);
    // `scout doctor --zenoh` names each case: the operator passes, a wrong CA fails the TLS,
    // an unlisted name is reached but reads nothing.
    let doctor_with = |config: String| {
        scout_system_tests::doctor(&[
            "--name",
            &name,
            "--zenoh",
            &endpoint,
            "--zenoh-config",
            &config,
        ])
        .1
    };
    let checks = doctor_with(pki.config("operator", "client", &connect_to, ""));
    assert_eq!(
        scout_system_tests::doctor_check(&checks, "zenoh.link")["verdict"],
        "pass",
        "{checks:#?}"
    );
    let checks = doctor_with(rogue.config("operator", "client", &connect_to, ""));
    let zenoh = scout_system_tests::doctor_check(&checks, "zenoh");
    assert_eq!(zenoh["verdict"], "fail", "{checks:#?}");
    assert!(
        zenoh["fix"].as_str().is_some_and(|fix| fix.contains("CA")),
        "{zenoh}"
    );
    let checks = doctor_with(pki.config("intruder", "client", &connect_to, ""));
    let zenoh = scout_system_tests::doctor_check(&checks, "zenoh");
    assert!(
        zenoh["fix"]
            .as_str()
            .is_some_and(|fix| fix.contains("access control")),
        "{zenoh}"
    );
    // A peer without a certificate cannot even connect: the gateway only speaks mutual TLS.
    let plain = scout_clients::remote::SessionSettings {
        config_file: Some(String::new()),
        connect: vec![endpoint.replacen(scheme, "tcp", 1)],
        ..Default::default()
    };
    if let Ok(session) = plain.open("client") {
        assert!(zenoh_query(&session, &estop, Some("{}"), QUERY).is_empty());
    }
    assert!(gateway.is_running(), "{}", gateway.log());
}

/// A remote e-stop's answer: accepted, or panics with what came back.
fn remote_estop(session: &zenoh::Session, robot: &str, peer: &str) {
    let answers = zenoh_query(
        session,
        &format!("scout/{robot}/cmd/estop/{peer}"),
        Some(r#"{"reason":"remote test"}"#),
        QUERY,
    );
    assert!(
        answers.len() == 1 && answers[0]["accepted"] == true,
        "e-stop from {peer}: {answers:?}"
    );
}

#[test]
fn a_remote_estop_is_answered_and_latched_under_a_flood_from_rotating_peer_names() {
    let port = free_port();
    let Remote {
        name,
        status,
        session,
        _gateway,
        ..
    } = Remote::start("remote-flood", &tcp(port), &["--remote-commands", "estop"]);
    // Two sessions flood releases (not allowed here) over 1000 peer names, never waiting.
    let flooding = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(true));
    let floods: Vec<_> = (0..2)
        .map(|flooder| {
            let (flooding, name) = (std::sync::Arc::clone(&flooding), name.clone());
            let session = zenoh_session("client", &[], &[tcp(port)]);
            std::thread::spawn(move || {
                let mut sent = 0u64;
                while flooding.load(std::sync::atomic::Ordering::Relaxed) {
                    let peer = format!("x{}", (sent * 2 + flooder) % 1000);
                    let _ = session
                        .get(format!("scout/{name}/cmd/release/{peer}"))
                        .payload("{}")
                        .timeout(Duration::from_secs(1))
                        .wait();
                    sent += 1;
                }
                sent
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(500));
    let mut newest = 0;
    for _ in 0..6 {
        remote_estop(&session, &name, "guard");
        let latched = wait_for_status(&status, LIMIT, |s| {
            s["newest_stop"].as_u64() > Some(newest)
                && s["stops"]
                    .as_array()
                    .is_some_and(|stops| stops.iter().any(|stop| stop["owner"] == "remote:guard"))
        });
        newest = latched["newest_stop"].as_u64().unwrap_or(0);
        std::thread::sleep(Duration::from_millis(100));
    }
    flooding.store(false, std::sync::atomic::Ordering::Relaxed);
    let sent: u64 = floods.into_iter().map(|f| f.join().expect("flooder")).sum();
    let info = query_until_answered(&session, &format!("scout/{name}/info"));
    let counters = &info["counters"];
    assert!(counters["estops_accepted"].as_u64() >= Some(6), "{info}");
    // The refusals were cheap and counted (or dropped and counted, past the lane's length).
    let refused = counters["commands_rejected"].as_u64().unwrap_or(0)
        + counters["queries_dropped"].as_u64().unwrap_or(0);
    assert!(refused > 0, "{info}");
    println!("flood: {sent} releases sent, {refused} refused or dropped; {counters}");
}

#[test]
fn any_peer_name_zenoh_carries_can_stop_and_release_its_own() {
    let Remote {
        name,
        status,
        session,
        _gateway,
        ..
    } = Remote::start(
        "remote-names",
        &tcp(free_port()),
        &["--remote-commands", "estop,release"],
    );
    let long = "a".repeat(26);
    let mapped = scout_clients::interface::remote::peer_client_name(&long);
    for (peer, owner) in [
        (long.as_str(), mapped.as_str()),
        ("opérateur", "remote:op%C3%A9rateur"),
    ] {
        remote_estop(&session, &name, peer);
        let latched = wait_for_status(&status, LIMIT, |s| {
            s["stops"]
                .as_array()
                .is_some_and(|stops| stops.iter().any(|stop| stop["owner"] == owner))
        });
        assert_eq!(latched["latched"], true);
        let released = zenoh_query(
            &session,
            &format!("scout/{name}/cmd/release/{peer}"),
            Some("{}"),
            QUERY,
        );
        assert_eq!(
            released.first().map(|a| a["accepted"] == true),
            Some(true),
            "{released:?}"
        );
        wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    }
}

/// Runs `scout-gateway` on the simulator as `name` with `args` inside `namespace`; returns its
/// exit code if it exits within the limit (else `None`, once it logged that its zenoh is up:
/// it is then killed), and its log.
fn gateway_in(namespace: &NetNs, name: &str, args: &[&str]) -> (Option<i32>, String) {
    let run_dir = scout_system_tests::TempDir::new(name);
    let mut child = namespace
        .binary("scout-gateway")
        .env("RUST_LOG", "info")
        .env("SCOUT_RUN_DIR", run_dir.path())
        .args(["--sim", "--name", name])
        .args(args)
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("spawn scout-gateway in the namespace");
    let lines = scout_system_tests::line_reader(child.stderr.take().expect("stderr"));
    let deadline = Instant::now() + LIMIT;
    let mut log = String::new();
    while let Ok(line) = lines.recv_timeout(deadline.saturating_duration_since(Instant::now())) {
        log.push_str(&line);
        log.push('\n');
        if line.contains("zenoh: publishing") {
            let _ = child.kill();
            let _ = child.wait();
            return (None, log);
        }
    }
    // Its stderr closed (it is exiting) or the limit passed.
    while Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            return (status.code(), log);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = child.kill();
    let _ = child.wait();
    panic!("scout-gateway neither started its zenoh nor exited in {LIMIT:?}:\n{log}");
}

/// Remote peers drive only over links that authenticate them: a gateway asked to take teleop
/// over plain UDP on every interface, or over a zenoh configuration that listens on zenoh's
/// default (TCP, every interface), refuses to start (exit 2), saying why and what to do; with
/// e-stops alone, or the network declared trusted (a warning naming the link), it starts. In a
/// network namespace of its own: nothing listens beyond the test.
#[test]
fn drive_permissions_over_links_that_authenticate_nobody_are_refused_unless_declared_trusted() {
    const TEST: &str =
        "drive_permissions_over_links_that_authenticate_nobody_are_refused_unless_declared_trusted";
    let namespace = match NetNs::create() {
        Ok(namespace) => namespace,
        Err(why) => {
            assert!(!nix::unistd::geteuid().is_root(), "{TEST}: {why}");
            skip(TEST, &why);
            return;
        }
    };
    let name = robot_name("untrusted_link");
    let every = format!("udp/0.0.0.0:{}", free_port());
    let listen = ["--zenoh-listen", every.as_str()];
    let (code, log) = gateway_in(
        &namespace,
        &name,
        &[&listen[..], &["--remote-commands", "estop,teleop,release"]].concat(),
    );
    assert_eq!(code, Some(2), "{log}");
    for words in [
        "refusing to take remote commands (teleop, release)",
        &format!("{every} (plain, no authentication, reachable on every interface)"),
        "WireGuard",
        "--remote-commands estop",
        "--zenoh-trusted-network",
    ] {
        assert!(log.contains(words), "{words:?} not in:\n{log}");
    }
    // A zenoh configuration that names no listener: zenoh's own default, every interface.
    let dir = scout_system_tests::TempDir::new(&format!("{name}-zenoh"));
    let file = dir.path().join("zenoh.json5");
    std::fs::write(
        &file,
        r#"{ mode: "peer", scouting: { multicast: { enabled: false } } }"#,
    )
    .expect("write zenoh config");
    let file = file.display().to_string();
    let (code, log) = gateway_in(
        &namespace,
        &name,
        &["--zenoh-config", &file, "--remote-commands", "autonomy"],
    );
    assert_eq!(code, Some(2), "{log}");
    assert!(log.contains("tcp/[::]:0 (plain"), "{log}");
    // E-stops alone: it starts, and says nothing of the link.
    let (code, log) = gateway_in(
        &namespace,
        &name,
        &[&listen[..], &["--remote-commands", "estop"]].concat(),
    );
    assert_eq!(code, None, "{log}");
    assert!(!log.contains("declared trusted"), "{log}");
    // Declared trusted: it starts, with a warning naming the link.
    let (code, log) = gateway_in(
        &namespace,
        &name,
        &[
            &listen[..],
            &[
                "--remote-commands",
                "estop,teleop",
                "--zenoh-trusted-network",
            ],
        ]
        .concat(),
    );
    assert_eq!(code, None, "{log}");
    assert!(
        log.contains(&format!("over {every} (plain")) && log.contains("declared trusted"),
        "{log}"
    );
}

/// The shipped configurations for remote drive inside a tunnel (config/zenoh-wireguard-*.json5,
/// its endpoints moved to loopback): zenoh's user/password authentication and access control
/// bind each peer name to its user. Bob cannot take control, drive, release or relinquish as
/// alice (his queries under her name reach nothing, and her control holds); an unlisted user,
/// a wrong password and no credentials reach nothing.
#[test]
fn user_names_bind_each_peer_name_to_its_password() {
    let name = robot_name("usrpwd");
    let endpoint = format!("udp/127.0.0.1:{}", free_port());
    let configs = scout_system_tests::ShippedUsers::new(&name, &endpoint);
    let mut gateway = Gateway::start(&[
        "--sim",
        "--name",
        &name,
        "--zenoh-config",
        &configs.gateway,
        "--zenoh-listen",
        &endpoint,
        "--remote-commands",
        "estop,teleop,release",
    ]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let settings = |user: Option<(&str, &str)>| scout_clients::remote::SessionSettings {
        config_file: Some(configs.operator(user)),
        connect: vec![endpoint.clone()],
        ..Default::default()
    };
    let open = |user: Option<(&str, &str)>| settings(user).open("client");
    // The gateway listens a moment after its services are up.
    let alice = scout_system_tests::open_within(&settings(Some(("alice", "alice-secret"))), LIMIT);
    let state = query_until_answered(&alice, &format!("scout/{name}/state"));
    assert_eq!(state["robot"], name.as_str());
    let take = r#"{"class":"teleop","sent_ms":1000}"#;
    assert_eq!(
        remote_command(&alice, &name, "take-control", "alice", take)["accepted"],
        true
    );
    let took = Instant::now();
    let drive = |seq: u64| {
        let sent_ms = 1000 + took.elapsed().as_millis() as u64;
        format!(r#"{{"seq":{seq},"sent_ms":{sent_ms},"linear":0.0,"angular":0.0,"ttl_ms":300}}"#)
    };
    assert_eq!(
        remote_command(&alice, &name, "drive", "alice", &drive(1))["accepted"],
        true
    );
    // Bob reads, and commands as bob; as alice, nothing of his reaches the gateway.
    let bob = open(Some(("bob", "bob-secret"))).expect("bob's session");
    assert_eq!(
        query_until_answered(&bob, &format!("scout/{name}/state"))["robot"],
        name.as_str()
    );
    for (kind, payload) in [
        ("relinquish", "{}".to_owned()),
        ("release", "{}".to_owned()),
        ("take-control", take.to_owned()),
        ("drive", drive(50)),
    ] {
        let key = format!("scout/{name}/cmd/{kind}/alice");
        let answers = zenoh_query(&bob, &key, Some(&payload), DENIED);
        assert!(answers.is_empty(), "bob as alice, {kind}: {answers:?}");
    }
    // Alice's control held through all of it.
    assert_eq!(
        remote_command(&alice, &name, "drive", "alice", &drive(2))["accepted"],
        true
    );
    assert_eq!(
        wait_for_status(&status, LIMIT, |s| s["selected"]["client"]
            == "remote:alice")["selected"]["class"],
        "teleop"
    );
    // Bob's own stop is his; alice cannot release it as bob either.
    assert_eq!(
        remote_command(&bob, &name, "estop", "bob", r#"{"reason":"bob"}"#)["accepted"],
        true
    );
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["stops"][0]["owner"], "remote:bob");
    let key = format!("scout/{name}/cmd/release/bob");
    assert!(zenoh_query(&alice, &key, Some("{}"), DENIED).is_empty());
    assert_eq!(
        remote_command(&bob, &name, "release", "bob", "{}")["accepted"],
        true
    );
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    // An unlisted user, a wrong password, no credentials: no session, or one that reaches
    // nothing (not even the state), and nothing latches.
    for user in [
        Some(("carol", "carol-secret")),
        Some(("alice", "bob-secret")),
        None,
    ] {
        let Ok(session) = open(user) else { continue };
        let estop = format!("scout/{name}/cmd/estop/alice");
        let answers = zenoh_query(&session, &estop, Some("{}"), DENIED);
        assert!(answers.is_empty(), "{user:?} was answered: {answers:?}");
        let state = zenoh_query(&session, &format!("scout/{name}/state"), None, DENIED);
        assert!(state.is_empty(), "{user:?} read the state");
    }
    assert_eq!(wait_for_status(&status, LIMIT, |_| true)["latched"], false);
    assert!(gateway.is_running(), "{}", gateway.log());
}
