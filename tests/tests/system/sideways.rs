//! Sideways motion across processes: `scout drive --lateral` moves a SCOUT MINI OMNI (the
//! gateway's simulated one, protocol v2) to its left, the gateway's odometry following, and a
//! chassis that does not move sideways refuses it whole, saying why.

use std::time::Duration;

use scout_protocol::model::Model;
use scout_system_tests::{Gateway, connect, robot_name, scout, wait_for_state};

const LIMIT: Duration = Duration::from_secs(10);

/// A gateway for a SCOUT MINI OMNI on protocol v2 on `port` (`--sim`, `--slcan PATH`), its
/// state subscribed, and its first state with the link up.
fn omni(
    name: &str,
    port: &[&str],
) -> (
    Gateway,
    scout_clients::client::StateSubscriber,
    serde_json::Value,
) {
    let args = [
        "--protocol",
        "v2",
        "--model",
        "scout-mini-omni",
        "--name",
        name,
    ];
    let gateway = Gateway::start(&[port, &args[..]].concat());
    let state = connect(name).subscribe().expect("state");
    let ready = wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "ok");
    (gateway, state, ready)
}

#[test]
fn scout_drive_moves_the_omni_sideways_and_the_odometry_follows() {
    let name = robot_name("omni");
    let (_gateway, state, ready) = omni(&name, &["--sim"]);
    assert_eq!(ready["chassis"]["max_lateral"], 2.0, "{}", ready["chassis"]);
    let (code, stdout, stderr) = scout(&[
        "drive",
        "--name",
        &name,
        "--lateral",
        "0.4",
        "--duration",
        "1.5",
    ]);
    assert_eq!(code, Some(0), "{stdout}{stderr}");
    // Left of where it started, not ahead: 0.4 m/s for 1.5 s, less the ramps.
    let moved = wait_for_state(&state, LIMIT, |s| {
        s["odometry"]["y"].as_f64().is_some_and(|y| y > 0.3)
    });
    let odometry = &moved["odometry"];
    assert!(
        odometry["x"].as_f64().is_some_and(|x| x.abs() < 0.05),
        "{odometry}"
    );
    // `scout drive` commands zero before it leaves.
    wait_for_state(&state, LIMIT, |s| s["command"]["lateral"] == 0.0);
}

#[test]
fn a_chassis_that_does_not_move_sideways_refuses_it_whole_and_says_why() {
    let name = robot_name("no-sideways");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    let robot = connect(&name);
    let state = robot.subscribe().expect("state");
    wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "ok");
    let (code, stdout, stderr) = scout(&[
        "drive",
        "--name",
        &name,
        "--linear",
        "0.3",
        "--lateral",
        "0.2",
        "--duration",
        "0.5",
    ]);
    assert_eq!(code, Some(4), "{stdout}{stderr}");
    let said = format!("{stdout}{stderr}");
    assert!(said.contains("a scout does not move sideways"), "{said}");
    let now = wait_for_state(&state, LIMIT, |_| true);
    assert_eq!(now["command"]["linear"], 0.0, "refused whole: {now}");
    assert_eq!(now["odometry"]["x"], 0.0, "{now}");
}

/// `tests/system/v2_chassis.py`, an emulated v2 chassis on an slcan pseudo-terminal written from
/// the vendor's field layout: the path of its port, and each motion command it decoded.
pub(crate) struct EmulatedChassis {
    child: std::process::Child,
    lines: std::sync::mpsc::Receiver<String>,
    /// What it printed other than motion commands (a Ranger's mode requests), in order.
    events: std::cell::RefCell<Vec<serde_json::Value>>,
    pub(crate) port: String,
}

impl EmulatedChassis {
    /// The emulator with `args` (`--motion-modes`: a Ranger).
    pub(crate) fn start(args: &[&str]) -> Self {
        let script =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/v2_chassis.py");
        let mut child = std::process::Command::new("python3")
            .arg(script)
            .args(args)
            .stdout(std::process::Stdio::piped())
            .spawn()
            .expect("python3 runs the emulated chassis");
        let lines = scout_system_tests::line_reader(child.stdout.take().expect("stdout"));
        let port = lines.recv_timeout(LIMIT).expect("the emulator's port");
        Self {
            child,
            lines,
            events: std::cell::RefCell::default(),
            port,
        }
    }

    /// What it printed other than motion commands so far (read by [`Self::commands_until`]).
    pub(crate) fn events(&self) -> Vec<serde_json::Value> {
        self.events.borrow().clone()
    }

    /// An emulated chassis with a gateway for `model` on protocol v2 on it (its link up) and
    /// `scout drive` with `drive` (`--linear 0.1 ...`) running against it.
    pub(crate) fn driven(
        model: &str,
        drive: &[&str],
    ) -> (Self, Gateway, scout_system_tests::Background) {
        let model_named = Model::from_name(model);
        let modes = model_named.and_then(Model::four_wheel).is_some();
        let brake = model_named.is_some_and(Model::parking_brake);
        let chassis = Self::start(match (modes, brake) {
            (true, _) => &["--motion-modes"],
            (false, true) => &["--brake"],
            (false, false) => &[],
        });
        let name = robot_name(&format!("{model}-wire"));
        let args = [
            "--slcan",
            &chassis.port,
            "--protocol",
            "v2",
            "--model",
            model,
        ];
        let gateway = Gateway::start(&[&args[..], &["--name", &name]].concat());
        let state = connect(&name).subscribe().expect("state");
        wait_for_state(&state, LIMIT, |s| s["link"]["state"] == "ok");
        let drive = scout_system_tests::Background::scout(
            &[
                &["drive", "--name", &name][..],
                drive,
                &["--duration", "1.5"],
            ]
            .concat(),
        );
        (chassis, gateway, drive)
    }

    /// Waits for zero on every field (what a client ending sends).
    pub(crate) fn ends_at_zero(&self) {
        let seen = self.commands_until(|c| *c == [0, 0, 0, 0]);
        assert_eq!(seen.last(), Some(&[0, 0, 0, 0]), "{seen:?}");
    }

    /// Reads what it prints until it has printed `wanted` (other than a motion command), or
    /// `within` passes; returns whether it did.
    pub(crate) fn wait_event(&self, wanted: &serde_json::Value, within: Duration) -> bool {
        let deadline = std::time::Instant::now() + within;
        while !self.events.borrow().contains(wanted) {
            let Ok(line) = self
                .lines
                .recv_timeout(deadline.saturating_duration_since(std::time::Instant::now()))
            else {
                return false;
            };
            let json: serde_json::Value = serde_json::from_str(&line).expect("a JSON line");
            if json.get("linear_mm_s").is_none() {
                self.events.borrow_mut().push(json);
            }
        }
        true
    }

    /// The motion commands it decoded, as (linear, angular, lateral, steering), until `done`
    /// says so of the newest or `LIMIT` passes.
    pub(crate) fn commands_until(&self, done: impl Fn(&[i64; 4]) -> bool) -> Vec<[i64; 4]> {
        let deadline = std::time::Instant::now() + LIMIT;
        let mut seen = Vec::new();
        while let Ok(line) = self
            .lines
            .recv_timeout(deadline.saturating_duration_since(std::time::Instant::now()))
        {
            let json: serde_json::Value = serde_json::from_str(&line).expect("a JSON line");
            if json.get("linear_mm_s").is_none() {
                self.events.borrow_mut().push(json);
                continue;
            }
            let field = |name: &str| json[name].as_i64().expect("a field");
            let command = [
                field("linear_mm_s"),
                field("angular_mrad_s"),
                field("lateral_mm_s"),
                field("steering_mrad"),
            ];
            seen.push(command);
            if done(&command) {
                break;
            }
        }
        seen
    }
}

impl Drop for EmulatedChassis {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The bytes of 0x111 against the vendor's layout (`MotionCommandFrame`: linear, angular,
/// lateral, steering, each a big-endian int16 in thousandths), read by a chassis emulated
/// apart from this project's codec and simulator: the OMNI's sideways speed is bytes 4-5.
#[test]
fn the_omnis_sideways_speed_is_where_the_vendor_puts_it_in_0x111() {
    let (chassis, _gateway, drive) =
        EmulatedChassis::driven("scout-mini-omni", &["--linear", "0.1", "--lateral", "-0.3"]);
    // The ramps (1 m/s², 20 ms) reach 0.1 forward and 0.3 to the right.
    let seen = chassis.commands_until(|c| c[0] == 100 && c[2] == -300);
    assert_eq!(
        seen.last().map(|c| (c[0], c[2])),
        Some((100, -300)),
        "{seen:?}"
    );
    assert!(
        seen.iter().all(|c| c[1] == 0 && c[3] == 0),
        "no yaw, no steering: {seen:?}"
    );
    // Then zero on every field when `scout drive` ends.
    chassis.ends_at_zero();
    drop(drive);
}
