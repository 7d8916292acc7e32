//! The odometry's calibration against the simulated chassis: a chassis whose firmware reports
//! 0.95 of the distance it travels and 1.26 times its turn (scout-sim's deliberate error, as
//! scout_ros#5 saw), driven around a 1 m square by a client steering on the gateway's own
//! odometry, as a planner would. With the gateway's `[odometry]` factors, what the odometry
//! says and where the chassis really is (the simulator's pose) agree within 2 % of the path.

use std::time::{Duration, Instant};

use scout_clients::Class;
use scout_clients::StatePayload;
use scout_clients::client::{Robot, StateSubscriber};
use scout_clients::control::Controller;
use scout_system_tests::{Gateway, Sim, TempDir, connect, robot_name};

/// The deliberate error and the factors that undo it.
const REPORTED_DISTANCE: f64 = 0.95;
const REPORTED_YAW: f64 = 1.26;
const SIDE: f64 = 1.0;
const LINEAR: f64 = 0.3;
const ANGULAR: f64 = 0.4;
/// No leg of the square takes longer than this.
const LEG_LIMIT: Duration = Duration::from_secs(20);

/// The newest state: one that came since the last read, else the last one read.
struct Newest {
    states: StateSubscriber,
    last: Option<StatePayload>,
}

impl Newest {
    fn state(&mut self) -> StatePayload {
        let deadline = Instant::now() + Duration::from_secs(2);
        loop {
            if let Some(state) = self.states.try_latest().expect("reading the state") {
                self.last = Some(state);
            }
            if let Some(state) = self.last {
                return state;
            }
            assert!(Instant::now() < deadline, "no state from the gateway");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// The gateway's odometry: x, y, yaw, distance.
    fn odometry(&mut self) -> (f64, f64, f64, f64) {
        let odometry = self.state().odometry;
        (odometry.x, odometry.y, odometry.yaw, odometry.distance)
    }
}

/// Drives (linear, angular) at 50 Hz until `done` says so from the odometry, then commands
/// zero until the chassis stands still.
fn leg(
    teleop: &mut Controller,
    states: &mut Newest,
    speeds: (f64, f64),
    done: impl Fn((f64, f64, f64, f64)) -> bool,
) {
    let deadline = Instant::now() + LEG_LIMIT;
    while !done(states.odometry()) {
        assert!(
            Instant::now() < deadline,
            "a leg of the square took too long"
        );
        teleop.drive(speeds.0, speeds.1).expect("a drive");
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut still = 0;
    while still < 10 {
        assert!(Instant::now() < deadline, "the chassis did not stop");
        teleop.drive(0.0, 0.0).expect("a stop command");
        let state = states.state();
        let moving = state.motion.linear().abs() > 0.001 || state.motion.angular().abs() > 0.001;
        still = if moving { 0 } else { still + 1 };
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn wrap(angle: f64) -> f64 {
    let turned = (angle + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU);
    turned - std::f64::consts::PI
}

/// Drives the square on `chassis` (scout-sim's arguments, `--params` added) through a
/// gateway (its `transport` arguments, `--config` added) and returns the odometry's error
/// against the simulator's pose: position and yaw, each over the path (4 m, 2 pi).
/// The simulator's parameters with the deliberate error, in `dir`; their path.
fn erring_params(dir: &TempDir) -> String {
    let params = dir.path().join("sim.toml");
    std::fs::write(
        &params,
        format!(
            "reported_distance_scale = {REPORTED_DISTANCE}\nreported_yaw_scale = {REPORTED_YAW}\n"
        ),
    )
    .expect("the simulator's parameters");
    params.to_string_lossy().into_owned()
}

/// The factors that undo the deliberate error, as the gateway's configuration.
pub(crate) fn exact_factors() -> String {
    format!(
        "[odometry]\ndistance_scale = {}\nyaw_scale = {}\n",
        1.0 / REPORTED_DISTANCE,
        1.0 / REPORTED_YAW
    )
}

/// Drives the square on the erring chassis with the gateway configured by `gateway_config`;
/// the position and yaw errors over the path.
pub(crate) fn square(
    prefix: &str,
    chassis: &[&str],
    transport: &[&str],
    gateway_config: &str,
) -> (f64, f64) {
    let name = robot_name(prefix);
    let dir = TempDir::new(&name);
    let params = erring_params(&dir);
    let config = dir.path().join("gateway.toml");
    std::fs::write(&config, gateway_config).expect("the gateway's configuration");
    let mut sim = Sim::start(&[chassis, &["--params", &params]].concat());
    let port = sim.port().to_owned();
    let config = config.to_string_lossy().into_owned();
    let _gateway =
        Gateway::start(&[transport, &[&port, "--name", &name, "--config", &config]].concat());
    let robot: Robot = connect(&name);
    let mut states = Newest {
        states: robot.subscribe().expect("state"),
        last: None,
    };
    let mut teleop = robot
        .controller("square", Some(Class::Teleop))
        .expect("a controller");
    let deadline = Instant::now() + Duration::from_secs(10);
    states.state();
    while teleop.take_control().is_err() {
        assert!(Instant::now() < deadline, "no control of {name}");
        std::thread::sleep(Duration::from_millis(50));
    }
    for corner in 1..=4 {
        let start = states.odometry().3;
        leg(
            &mut teleop,
            &mut states,
            (LINEAR, 0.0),
            |(_, _, _, distance)| {
                // Less the distance the ramp down adds (1 m/s² from 0.3 m/s).
                distance - start >= SIDE - 0.045
            },
        );
        let heading = f64::from(corner) * std::f64::consts::FRAC_PI_2;
        leg(
            &mut teleop,
            &mut states,
            (0.0, ANGULAR),
            |(_, _, yaw, _)| {
                // Less what the ramp down adds (1.5 rad/s² from 0.4 rad/s).
                wrap(heading - yaw) <= 0.053
            },
        );
    }
    let (x, y, yaw, _) = states.odometry();
    let truth = sim.stats()["pose"].clone();
    let (true_x, true_y, true_yaw) = (
        truth["x"].as_f64().expect("x"),
        truth["y"].as_f64().expect("y"),
        truth["yaw"].as_f64().expect("yaw"),
    );
    eprintln!(
        "{prefix}: odometry ({x:.3}, {y:.3}, {yaw:.3}), truth ({true_x:.3}, {true_y:.3}, {true_yaw:.3})"
    );
    (
        ((x - true_x).hypot(y - true_y)) / (4.0 * SIDE),
        wrap(yaw - true_yaw).abs() / std::f64::consts::TAU,
    )
}

/// The bound the issue sets: 2 % of the path.
const WITHIN: f64 = 0.02;

/// The square's position and yaw errors are within [`WITHIN`] of the path.
pub(crate) fn assert_within(position: f64, yaw: f64) {
    assert!(
        position < WITHIN && yaw < WITHIN,
        "position error {:.2} %, yaw error {:.2} % of the path",
        position * 100.0,
        yaw * 100.0
    );
}

#[test]
fn a_calibrated_v1_chassis_drives_a_square_its_odometry_follows() {
    let (position, yaw) = square(
        "odometry-v1",
        &["--serial"],
        &["--serial"],
        &exact_factors(),
    );
    assert_within(position, yaw);
}

#[test]
fn a_calibrated_v2_chassis_drives_a_square_its_odometers_follow() {
    let (position, yaw) = square(
        "odometry-v2",
        &["--slcan", "--protocol", "v2", "--model", "scout2"],
        &["--slcan"],
        &exact_factors(),
    );
    assert_within(position, yaw);
}

/// `scout calibrate` on the erring chassis, the operator's measurements being the simulator's
/// truth: it writes factors that undo the error within 2 %, and a square driven with them ends
/// within 2 % of the path.
#[test]
fn scout_calibrate_measures_the_error_and_its_factors_drive_a_square() {
    let name = robot_name("calibrate");
    let dir = TempDir::new(&name);
    let params = erring_params(&dir);
    let written = calibrate(
        &name,
        &dir,
        &["--serial", "--params", &params],
        "--serial",
        &[],
    );
    let factors: toml::Table = toml::from_str(&written).expect("TOML");
    let scale = |key: &str| factors["odometry"][key].as_float().expect("a factor");
    let (distance_scale, yaw_scale) = (scale("distance_scale"), scale("yaw_scale"));
    eprintln!(
        "scout calibrate wrote distance_scale {distance_scale} (exact {:.4}), yaw_scale \
         {yaw_scale} (exact {:.4})",
        1.0 / REPORTED_DISTANCE,
        1.0 / REPORTED_YAW
    );
    assert!(
        (distance_scale * REPORTED_DISTANCE - 1.0).abs() < WITHIN,
        "{written}"
    );
    assert!((yaw_scale * REPORTED_YAW - 1.0).abs() < WITHIN, "{written}");
    let (position, yaw) = square("calibrated", &["--serial"], &["--serial"], &written);
    assert_within(position, yaw);
}

/// `scout calibrate` on a simulated Hunter SE, which cannot turn in place: it turns on a
/// circle. Its simulator reports 0.95 of its speed (a steered chassis reports its wheels'
/// angle, not a yaw rate, so the gateway's yaw rate is 0.95 of the truth too): both factors it
/// writes undo that within 2 %.
#[test]
fn scout_calibrate_turns_a_hunter_on_a_circle() {
    let name = robot_name("calibrate-hunter");
    let dir = TempDir::new(&name);
    let params = dir.path().join("sim.toml");
    let erring = format!("reported_distance_scale = {REPORTED_DISTANCE}\n");
    std::fs::write(&params, erring).expect("the simulator's parameters");
    let params = params.to_string_lossy().into_owned();
    let chassis = [
        "--slcan",
        "--protocol",
        "v2",
        "--model",
        "hunter-se",
        "--params",
        &params,
    ];
    let written = calibrate(&name, &dir, &chassis, "--slcan", &["--speed", "0.6"]);
    let factors: toml::Table = toml::from_str(&written).expect("TOML");
    for key in ["distance_scale", "yaw_scale"] {
        let factor = factors["odometry"][key].as_float().expect("a factor");
        eprintln!(
            "scout calibrate on a Hunter SE wrote {key} {factor} (exact {:.4})",
            1.0 / REPORTED_DISTANCE
        );
        assert!(
            (factor * REPORTED_DISTANCE - 1.0).abs() < WITHIN,
            "{written}"
        );
    }
}

/// Runs `scout calibrate --distance 1 --turns 1 EXTRA` against a gateway (on the simulator's
/// port by `transport`) on a simulated chassis (`chassis` args, `--model` among them or not),
/// answering its questions with the simulator's truth; returns the configuration it wrote
/// (with its comments kept).
fn calibrate(
    name: &str,
    dir: &TempDir,
    chassis: &[&str],
    transport: &str,
    extra: &[&str],
) -> String {
    use std::io::{BufRead, Write};
    use std::process::Stdio;

    let config = dir.path().join("gateway.toml");
    std::fs::write(
        &config,
        "# this robot\n[odometry]\ndistance_scale = 1.0\nyaw_scale = 1.0\n",
    )
    .expect("the gateway's configuration");
    let config_path = config.to_string_lossy().into_owned();
    let mut sim = Sim::start(chassis);
    let port = sim.port().to_owned();
    let model = chassis.iter().position(|arg| *arg == "--model");
    let model = model.map_or(&[][..], |at| &chassis[at..at + 2]);
    let gateway = [transport, &port, "--name", name, "--config", &config_path];
    let _gateway = Gateway::start(&[&gateway[..], model].concat());
    let _robot = connect(name);
    let mut child = scout_system_tests::command("scout")
        .args(["calibrate", "--name", name, "--config", &config_path])
        .args(["--distance", "1", "--turns", "1"])
        .args(extra)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("scout calibrate");
    let mut answers = child.stdin.take().expect("stdin");
    let (lines, said) = std::sync::mpsc::channel::<String>();
    let stdout = child.stdout.take().expect("stdout");
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout)
            .lines()
            .map_while(Result::ok)
        {
            if lines.send(line).is_err() {
                break;
            }
        }
    });
    let pose = |sim: &mut Sim| {
        let pose = sim.stats()["pose"].clone();
        let value = |key: &str| pose[key].as_f64().expect("a pose");
        (value("x"), value("y"), value("yaw"))
    };
    let deadline = Instant::now() + Duration::from_secs(90);
    let mut start = (0.0, 0.0, 0.0);
    // The real turn, unwrapped from the simulator's pose while it turns.
    let mut turning: Option<(f64, f64)> = None;
    let mut transcript = Vec::new();
    loop {
        assert!(
            Instant::now() < deadline,
            "scout calibrate: {transcript:#?}"
        );
        if let Some((turned, last)) = turning.as_mut() {
            let (_, _, yaw) = pose(&mut sim);
            *turned += wrap(yaw - *last);
            *last = yaw;
        }
        let line = match said.recv_timeout(Duration::from_millis(50)) {
            Ok(line) => line,
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => continue,
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => break,
        };
        transcript.push(line.clone());
        let answer = if line.starts_with("press Enter to drive straight") {
            start = pose(&mut sim);
            String::new()
        } else if line.starts_with("distance?") {
            let (x, y, _) = pose(&mut sim);
            format!("{:.4}", (x - start.0).hypot(y - start.1))
        } else if line.starts_with("press Enter to turn") {
            let (_, _, yaw) = pose(&mut sim);
            turning = Some((0.0, yaw));
            String::new()
        } else if line.starts_with("turn?") {
            let (turned, _) = turning.take().expect("a turn measured");
            format!("{:.2}", turned.to_degrees())
        } else {
            continue;
        };
        writeln!(answers, "{answer}").expect("answering scout calibrate");
    }
    let status = child.wait().expect("scout calibrate exits");
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().expect("stderr"), &mut stderr)
        .expect("stderr");
    assert!(status.success(), "{status}: {transcript:#?} {stderr}");
    let written = std::fs::read_to_string(&config).expect("the configuration");
    assert!(
        written.starts_with("# this robot\n"),
        "comments kept: {written}"
    );
    written
}
