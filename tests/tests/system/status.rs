//! `scout status` across real processes: in every state of the arbiter (clean, stopped by a
//! client, a stop whose cause persists, after an unclean restart, released, driving), the text
//! view says what `scout status --json` says: latched or not, every stop with its owner, cause,
//! reason and whether its cause persists, what to do, and who drives.

use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use scout_clients::interface::json::status_json;
use scout_clients::monotonic_ns;
use scout_system_tests::{
    Driver, Gateway, TempDir, connect, release_all, robot_name, scout, wait_for_status,
};
use serde_json::Value;

const LIMIT: Duration = Duration::from_secs(10);

/// `scout status` and `scout status --json` for robot `name`, one after the other.
fn both(name: &str) -> (String, Value) {
    let (code, text, stderr) = scout(&["status", "--name", name]);
    assert_eq!(code, Some(0), "scout status: {stderr}");
    let (code, json, stderr) = scout(&["status", "--name", name, "--json"]);
    assert_eq!(code, Some(0), "scout status --json: {stderr}");
    let json = serde_json::from_str(&json).expect("one JSON object");
    (text, json)
}

/// The lines of `text` labelled `label`.
fn labelled<'a>(text: &'a str, label: &str) -> Vec<&'a str> {
    let prefix = format!("{label:<9} ");
    text.lines()
        .filter(|line| line.starts_with(&prefix))
        .collect()
}

/// Asserts that the text view says what the JSON says.
fn agree(text: &str, json: &Value) {
    let context = format!("text:\n{text}\njson: {json}");
    assert_eq!(
        labelled(text, "robot"),
        [format!(
            "robot     {}",
            json["robot"].as_str().expect("robot")
        )],
        "{context}"
    );
    let latched = json["latched"].as_bool().expect("latched");
    let stops = json["stops"].as_array().expect("stops");
    let total = json["stop_total"].as_u64().expect("stop_total");
    let expected = if latched {
        format!("latched   YES: {total} stop(s)")
    } else {
        "latched   no".to_owned()
    };
    assert_eq!(labelled(text, "latched"), [expected], "{context}");
    let lines = labelled(text, "stop");
    let unlisted = usize::from(total > stops.len() as u64);
    assert_eq!(lines.len(), stops.len() + unlisted, "{context}");
    for (line, stop) in lines.iter().zip(stops) {
        for key in ["owner", "cause", "reason"] {
            let value = stop[key].as_str().expect("a text field");
            assert!(line.contains(value), "{key} {value} missing: {context}");
        }
        assert_eq!(
            line.contains("(cause persists: cannot be released yet)"),
            stop["persists"] == true,
            "{line}: {context}"
        );
    }
    let todo = labelled(text, "what to do");
    assert_eq!(todo.len(), usize::from(latched), "{context}");
    if let Some(todo) = todo.first() {
        let persists = stops.iter().any(|stop| stop["persists"] == true);
        assert_eq!(todo.contains("first:"), persists, "{context}");
        assert!(todo.contains("`scout release`"), "{context}");
    }
    let driving = labelled(text, "driving");
    match &json["selected"] {
        Value::Null => assert_eq!(driving, ["driving   nobody"], "{context}"),
        selected => {
            let client = selected["client"].as_str().expect("client");
            let class = selected["class"].as_str().expect("class");
            assert_eq!(
                driving,
                [format!("driving   {client} ({class})")],
                "{context}"
            );
        }
    }
    let autonomy = if json["autonomy_armed"] == true {
        "autonomy  armed"
    } else {
        "autonomy  disarmed: `scout resume` arms it"
    };
    assert_eq!(labelled(text, "autonomy"), [autonomy], "{context}");
    let clients = labelled(text, "client");
    for source in json["sources"].as_array().expect("sources") {
        let client = source["client"].as_str().expect("client");
        assert!(
            clients
                .iter()
                .any(|line| line.starts_with(&format!("client    {client}  "))),
            "client {client} missing: {context}"
        );
    }
}

#[test]
fn status_text_agrees_with_json_in_every_state() {
    let name = robot_name("status-view");
    let run_dir = TempDir::new(&name);
    let gateway = Gateway::start_in(run_dir.path(), &["--sim", "--name", &name]);
    let robot = connect(&name);
    let status = robot.status().expect("status");
    wait_for_status(&status, LIMIT, |_| true);

    // A clean start: nothing holds, nobody drives.
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["latched"], false, "{json}");
    assert_eq!(json["selected"], Value::Null, "{json}");

    // An operator's stop.
    let reason = "person ahead (status view)";
    let (code, _, stderr) = scout(&["estop", "--name", &name, "--reason", reason]);
    assert_eq!(code, Some(0), "{stderr}");
    wait_for_status(&status, LIMIT, |s| s["latched"] == true);
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["stop_total"], 1, "{json}");
    let stop = &json["stops"][0];
    assert_eq!(
        (&stop["owner"], &stop["cause"], &stop["reason"]),
        (&"operator".into(), &"client".into(), &reason.into()),
        "{json}"
    );
    assert!(
        labelled(&text, "what to do")[0].starts_with("what to do `scout release`"),
        "{text}"
    );

    // A heartbeat source goes silent: a second stop, whose cause persists.
    let mut handheld = robot.controller("handheld", None).expect("controller");
    handheld
        .heartbeat(Duration::from_millis(200))
        .expect("register a heartbeat");
    wait_for_status(&status, LIMIT, |s| {
        s["stops"][1]["cause"] == "heartbeat" && s["stops"][1]["persists"] == true
    });
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["stop_total"], 2, "{json}");
    assert_eq!(json["stops"][1]["owner"], "handheld", "{json}");
    assert_eq!(
        labelled(&text, "what to do"),
        ["what to do first: heartbeat source still silent (handheld); then `scout release`"],
        "{text}"
    );
    // The source gives up its heartbeat: the stop stays, its cause is gone.
    handheld
        .heartbeat(Duration::ZERO)
        .expect("deregister the heartbeat");
    wait_for_status(&status, LIMIT, |s| {
        s["stops"][1]["cause"] == "heartbeat" && s["stops"][1]["persists"] == false
    });
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["stop_total"], 2, "{json}");
    assert!(!text.contains("cause persists"), "{text}");

    // Released: nothing holds, nobody drives.
    release_all(&name);
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["latched"], false, "{json}");
    assert_eq!(json["stop_total"], 0, "{json}");

    // Driving: `scout drive` in the background.
    let mut driver = Driver::start(&name, &["--linear", "0.3", "--client", "status-driver"]);
    wait_for_status(&status, LIMIT, |s| {
        s["selected"]["client"] == "status-driver"
    });
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["selected"]["client"], "status-driver", "{json}");
    assert_eq!(
        labelled(&text, "driving"),
        ["driving   status-driver (teleop)"],
        "{text}"
    );
    driver.signal(Signal::SIGINT);
    assert_eq!(driver.wait_exit(LIMIT), Some(0));
    drop(gateway);
}

#[test]
fn status_text_agrees_with_json_after_an_unclean_restart() {
    let name = robot_name("status-restart");
    let run_dir = TempDir::new(&name);
    let args = ["--sim", "--name", &name];
    let mut gateway = Gateway::start_in(run_dir.path(), &args);
    let status = connect(&name).status().expect("status");
    wait_for_status(&status, LIMIT, |_| true);
    gateway.signal(Signal::SIGKILL);
    gateway.wait_exit(LIMIT);
    let _restarted = Gateway::start_in(run_dir.path(), &args);
    // The killed gateway's services linger until the new one replaces them: read again until
    // the new gateway's status (stopped by its start) comes.
    let deadline = Instant::now() + LIMIT;
    let status = loop {
        if let Ok(status) = connect(&name).status()
            && let Ok(Some(latest)) = status.latest(Duration::from_millis(200))
            && status_json(&latest, monotonic_ns())["stops"][0]["cause"] == "gateway_start"
        {
            break status;
        }
        assert!(
            Instant::now() < deadline,
            "no gateway_start stop after the restart"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["latched"], true, "{json}");
    assert_eq!(json["stops"][0]["owner"], "gateway", "{json}");
    assert_eq!(json["stops"][0]["persists"], false, "{json}");
    assert!(
        labelled(&text, "what to do")[0].contains("check the robot"),
        "{text}"
    );
    release_all(&name);
    wait_for_status(&status, LIMIT, |s| s["latched"] == false);
    let (text, json) = both(&name);
    agree(&text, &json);
    assert_eq!(json["latched"], false, "{json}");
}
