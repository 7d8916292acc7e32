//! Zenoh for remote peers, over 127.0.0.1 only with multicast scouting off: state to a remote
//! process, liveliness, queryables, remote commands (off by default, then enabled and
//! authenticated with TLS and access control), and a two-robot fleet through a router.

use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use scout_system_tests::{
    Gateway, Sim, connect, free_port, robot_name, scout, wait_for_status, zenoh_query,
    zenoh_session,
};
use serde_json::Value;
use zenoh::Wait;
use zenoh::sample::SampleKind;

const LIMIT: Duration = Duration::from_secs(10);
const QUERY: Duration = Duration::from_secs(3);

fn tcp(port: u16) -> String {
    format!("tcp/127.0.0.1:{port}")
}

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
    let name = robot_name("remote-off");
    let port = free_port();
    let _gateway = Gateway::start(&["--sim", "--name", &name, "--zenoh-listen", &tcp(port)]);
    let robot = connect(&name);
    let session = zenoh_session("client", &[], &[tcp(port)]);
    query_until_answered(&session, &format!("scout/{name}/info"));
    let answers = zenoh_query(
        &session,
        &format!("scout/{name}/cmd/estop"),
        Some(r#"{"client":"laptop"}"#),
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
        .put(format!("scout/{name}/cmd/drive"), r#"{"client":"x"}"#)
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

#[test]
fn enabled_remote_commands_go_through_the_arbiter_and_bad_input_is_rejected() {
    let name = robot_name("remote-on");
    let port = free_port();
    let _gateway = Gateway::start(&[
        "--sim",
        "--name",
        &name,
        "--zenoh-listen",
        &tcp(port),
        "--remote-commands",
        "estop,teleop,release",
    ]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    let session = zenoh_session("client", &[], &[tcp(port)]);
    query_until_answered(&session, &format!("scout/{name}/info"));
    let command = |kind: &str, payload: &str| {
        let mut answers = zenoh_query(
            &session,
            &format!("scout/{name}/cmd/{kind}"),
            Some(payload),
            QUERY,
        );
        assert_eq!(answers.len(), 1, "{kind} {payload}: {answers:?}");
        answers.remove(0)
    };
    let drive = r#"{"client":"laptop","class":"teleop","linear":0.3,"angular":0.0,"ttl_ms":300}"#;
    assert_eq!(command("drive", drive)["accepted"], true);
    let driving = wait_for_status(&status, LIMIT, |s| {
        s["selected"]["client"] == "remote:laptop"
    });
    assert_eq!(driving["selected"]["class"], "teleop");
    let refusals = [
        (
            "drive",
            r#"{"client":"laptop","class":"autonomy","linear":0.3,"angular":0.0}"#,
            "not allowed",
        ),
        ("resume", r#"{"client":"laptop"}"#, "not allowed"),
        (
            "drive",
            r#"{"client":"laptop","class":"teleop","linear":"NaN","angular":0.0}"#,
            "invalid JSON",
        ),
        ("drive", "{not json", "invalid JSON"),
        (
            "drive",
            r#"{"client":"laptop","class":"teleop"}"#,
            "needs `linear` and `angular`",
        ),
        (
            "drive",
            r#"{"client":"laptop","class":"teleop","linear":1,"angular":0,"extra":1}"#,
            "invalid JSON",
        ),
        ("fly", r#"{"client":"laptop"}"#, "unknown command"),
        ("estop", r#"{"client":""}"#, "`client`"),
    ];
    for (kind, payload, reason) in refusals {
        let answer = command(kind, payload);
        assert_eq!(answer["accepted"], false, "{kind} {payload}");
        assert!(
            answer["reason"]
                .as_str()
                .is_some_and(|r| r.contains(reason)),
            "{kind} {payload}: {answer}"
        );
    }
    let huge = format!(r#"{{"client":"laptop","reason":"{}"}}"#, "x".repeat(5000));
    assert!(
        command("estop", &huge)["reason"]
            .as_str()
            .is_some_and(|r| r.contains("exceeds"))
    );
    assert_eq!(
        command("estop", r#"{"client":"laptop","reason":"remote stop"}"#)["accepted"],
        true
    );
    let latched = wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    assert_eq!(latched["latched_by"]["client"], "remote:laptop");
    assert_eq!(
        command("release", r#"{"client":"laptop"}"#)["accepted"],
        true
    );
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
}

#[test]
fn a_two_robot_fleet_through_a_router() {
    let router_port = free_port();
    let _router = zenoh_session("router", &[tcp(router_port)], &[]);
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
