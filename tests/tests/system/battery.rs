//! The battery end to end on the simulated chassis: a v1 pack estimated from its voltage, low
//! then critical in the state and the status, a critical battery refusing autonomy a new take
//! but never a teleop; a v2 smart battery believed, a charger seen charging, then full.

use std::time::{Duration, Instant};

use scout_clients::Class;
use scout_clients::control::ControlError;
use scout_system_tests::{Gateway, Sim, TempDir, connect, robot_name, scout, wait_for_state};

const LIMIT: Duration = Duration::from_secs(20);

/// Writes `text` as `file` in `dir`; its path.
fn write(dir: &TempDir, file: &str, text: &str) -> String {
    let path = dir.path().join(file);
    std::fs::write(&path, text).expect("a file of the test");
    path.to_string_lossy().into_owned()
}

#[test]
fn a_v1_pack_runs_low_then_critical_and_autonomy_is_refused_never_teleop() {
    let name = robot_name("battery-v1");
    let dir = TempDir::new(&name);
    // 24.5 V at rest: 15 % by the SCOUT's curve, below the 20 % low threshold.
    let params = write(&dir, "sim.toml", "battery_voltage = 24.5\n");
    let mut sim = Sim::start(&["--serial", "--params", &params]);
    let port = sim.port().to_owned();
    let gateway = Gateway::start(&["--serial", &port, "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("state");
    let low = wait_for_state(&states, LIMIT, |s| s["battery"]["level"] == "low");
    let battery = &low["battery"];
    assert_eq!(battery["source"], "voltage", "{battery}");
    assert_eq!(battery["status"], "discharging", "{battery}");
    let percent = battery["percent"].as_f64().expect("a charge");
    assert!((12.0..=17.0).contains(&percent), "{battery}");
    assert!(
        battery["current"].is_null(),
        "a v1 chassis measures no pack current"
    );
    let (code, status, stderr) = scout(&["status", "--name", &name]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(status.contains("LOW:"), "{status}");

    // Autonomy drives; the pack runs down to 24.2 V at rest, 7 % (a pack that low sags below
    // the chassis' 22 V cut-off as the motors accelerate: the simulator does that too).
    let mut autonomy = robot
        .controller("planner", Some(Class::Autonomy))
        .expect("a controller");
    autonomy.resume().expect("resume");
    autonomy.take_control().expect("autonomy takes control");
    autonomy.drive(0.2, 0.0).expect("drive");
    sim.send("battery 24.2");
    // Driving on all the while: a running autonomy is not cut off by the default policy.
    let deadline = Instant::now() + LIMIT;
    let critical = loop {
        autonomy
            .drive(0.2, 0.0)
            .expect("a running autonomy drives on");
        let state = wait_for_state(&states, LIMIT, |_| true);
        if state["battery"]["level"] == "critical" {
            break state;
        }
        assert!(Instant::now() < deadline, "never critical: {state}");
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(
        critical["battery"]["percent"].as_f64() <= Some(10.0),
        "critical by the estimate: {critical}"
    );
    // The default (refuse-autonomy): a running autonomy drives on; a new take is refused.
    autonomy
        .drive(0.2, 0.0)
        .expect("a running autonomy drives on");
    autonomy.relinquish().expect("relinquish");
    match autonomy.take_control() {
        Err(ControlError::Rejected(rejected)) => {
            assert!(rejected.reason.contains("battery critical"), "{rejected:?}")
        }
        other => panic!("autonomy took control on a critical battery: {other:?}"),
    }
    let (_, status, _) = scout(&["status", "--name", &name, "--json"]);
    let status: serde_json::Value = serde_json::from_str(&status).expect("status JSON");
    assert_eq!(status["battery"]["level"], "critical", "{status}");
    // A teleop drives it home.
    let mut teleop = robot
        .controller("operator", Some(Class::Teleop))
        .expect("a controller");
    teleop.take_control().expect("teleop on a critical battery");
    teleop.drive(0.2, 0.0).expect("teleop drives");
    teleop.relinquish().expect("relinquish");
    assert!(
        gateway.log().contains("battery critical"),
        "the log says it: {}",
        gateway.log()
    );
}

#[test]
fn a_v2_smart_battery_is_believed_and_a_charger_charges_it_full() {
    let name = robot_name("battery-v2");
    let dir = TempDir::new(&name);
    // A small pack with a smart battery: a 10 A charger fills it in seconds.
    let params = write(
        &dir,
        "sim.toml",
        "bms = true\nbattery_voltage = 25.2\nbattery_capacity_ah = 0.05\n",
    );
    let mut sim = Sim::start(&[
        "--slcan",
        "--protocol",
        "v2",
        "--model",
        "scout2",
        "--params",
        &params,
    ]);
    let port = sim.port().to_owned();
    let _gateway = Gateway::start(&["--slcan", &port, "--name", &name]);
    let robot = connect(&name);
    let states = robot.subscribe().expect("state");
    let reported = wait_for_state(&states, LIMIT, |s| s["battery"]["source"] == "bms");
    let battery = &reported["battery"];
    assert_eq!(
        battery["percent"].as_f64(),
        reported["bms"]["charge_percent"].as_f64(),
        "{reported}"
    );
    assert_eq!(battery["health_percent"], 96.0, "{battery}");
    assert_eq!(battery["temperature"], 25.0, "{battery}");
    sim.send("charger 10");
    let charging = wait_for_state(&states, LIMIT, |s| s["battery"]["status"] == "charging");
    assert!(
        charging["battery"]["current"].as_f64() > Some(9.0),
        "{charging}"
    );
    let full = wait_for_state(&states, LIMIT, |s| s["battery"]["status"] == "full");
    assert_eq!(full["battery"]["percent"], 100.0, "{full}");
    assert_eq!(full["battery"]["level"], "ok", "{full}");
}
