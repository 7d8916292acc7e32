//! `scout ros2` against a stand-in for a ROS 2 node (`ros2_node.py`: zenoh 1.6.2 as ROS 2
//! Jazzy's rmw_zenoh carries it, rosbags for CDR and type hashes), through a router as
//! rmw_zenohd would be: the graph, odometry, cmd_vel through the arbiter, the services.
//!
//! The stand-in needs `python3` (or `$SCOUT_PYTHON`) with `eclipse-zenoh==1.6.2` and `rosbags`
//! (`.ci/run` installs them). Without them the test skips, saying why, unless
//! `SCOUT_REQUIRE_ROS2_STANDIN` is set (as in CI): then it fails.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use scout_system_tests::{
    Background, Gateway, JsonPeer, Sim, chassis_stays_still, comes_to_rest, connect, free_port,
    moving, robot_name, scout, skip, tcp,
};
use serde_json::{Value, json};

const LIMIT: Duration = Duration::from_secs(10);
/// The bridge's default `blocked_pause_ms`, with a margin: the pause a stream must make
/// after a stop (or the bridge's start) before it may take control.
const BLOCKED_PAUSE: Duration = Duration::from_millis(2100);

/// The Python with the stand-in's packages (eclipse-zenoh among them): `$SCOUT_PYTHON`.
pub(crate) fn python() -> String {
    std::env::var("SCOUT_PYTHON").unwrap_or_else(|_| "python3".into())
}

/// Why the stand-in cannot run here, if it cannot.
fn standin_missing() -> Option<String> {
    let check =
        "import importlib.metadata as m, rosbags, xxhash, zenoh; print(m.version('eclipse-zenoh'))";
    match Command::new(python()).args(["-c", check]).output() {
        Ok(output) if output.status.success() => None,
        Ok(output) => Some(format!(
            "{} lacks eclipse-zenoh, rosbags or xxhash ({}): pip install eclipse-zenoh==1.6.2 \
             rosbags xxhash",
            python(),
            String::from_utf8_lossy(&output.stderr).trim()
        )),
        Err(error) => Some(format!("no {}: {error}", python())),
    }
}

/// The Python stand-in, one JSON command and answer per line.
struct RosNode(JsonPeer);

impl RosNode {
    fn start(router: &str, domain: u32) -> RosNode {
        let script =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/system/ros2_node.py");
        let mut command = Command::new(python());
        command
            .arg(script)
            .arg(router)
            .env("ROS_DOMAIN_ID", domain.to_string());
        RosNode(JsonPeer::start(
            command,
            "the ROS 2 stand-in",
            Duration::from_secs(30),
        ))
    }

    fn ask(&mut self, command: Value) -> Value {
        self.0.ask(command)
    }

    fn echo(&mut self, topic: &str, type_name: &str, count: usize) -> Vec<Value> {
        let answer =
            self.ask(json!({"cmd": "echo", "topic": topic, "type": type_name, "count": count}));
        let samples = answer["samples"].as_array().cloned().unwrap_or_default();
        assert_eq!(samples.len(), count, "{answer}");
        for sample in &samples {
            assert!(sample.get("error").is_none(), "{sample}");
            // rosbags writes the very bytes the bridge wrote, and every sample has the
            // attachment rmw_zenoh subscribers require.
            assert_eq!(sample["rosbags_same_bytes"], true, "{topic}: {sample}");
            assert!(
                sample["attachment"]["sequence"].as_i64() > Some(0),
                "{sample}"
            );
        }
        samples
    }

    /// The bridge's own counters, from its diagnostics.
    fn counters(&mut self) -> Value {
        let sample = self
            .echo("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", 1)
            .remove(0);
        sample["status"]
            .as_array()
            .and_then(|statuses| statuses.iter().find(|s| s["name"] == "scout: ros2 bridge"))
            .map(|status| status["values"].clone())
            .unwrap_or_else(|| panic!("no bridge counters in {sample}"))
    }

    fn call(&mut self, service: &str) -> Value {
        let answer = self.ask(json!({"cmd": "call", "service": service}));
        let replies = answer["replies"].as_array().cloned().unwrap_or_default();
        assert_eq!(replies.len(), 1, "{answer}");
        replies[0].clone()
    }
}

/// `scout ros2`, its log kept in a file shown when the test fails.
struct Bridge {
    process: Background,
    log: std::path::PathBuf,
}

impl Bridge {
    fn start(args: &[&str]) -> Bridge {
        static STARTED: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = STARTED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let log = std::env::temp_dir().join(format!("scout-ros2-{}-{n}.log", std::process::id()));
        let file = std::fs::File::create(&log).expect("create the bridge's log");
        let mut command = scout_system_tests::command("scout");
        command
            .args(args)
            // The middleware as every ROS node on the machine chooses it.
            .env("RMW_IMPLEMENTATION", "rmw_zenoh_cpp")
            .env("RUST_LOG", "info")
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(file);
        Bridge {
            process: Background::spawn(command),
            log,
        }
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        if std::thread::panicking() {
            let log = std::fs::read_to_string(&self.log).unwrap_or_default();
            eprintln!("scout ros2's log:\n{log}");
        }
        let _ = std::fs::remove_file(&self.log);
    }
}

fn counter(counters: &Value, name: &str) -> u64 {
    counters[name]
        .as_str()
        .and_then(|text| text.parse().ok())
        .unwrap_or_else(|| panic!("no counter {name} in {counters}"))
}

fn ok(args: &[&str]) {
    let (code, _, stderr) = scout(args);
    assert_eq!(code, Some(0), "scout {args:?}: {stderr}");
}

/// A router as rmw_zenohd runs: gossip on, and no forwarding between peers (rmw_zenoh's nodes
/// are peers; the bridge must be a client to be reached). Its endpoint, the process, and its
/// settings file (removed by the caller).
fn rmw_zenohd(name: &str) -> (String, Background, std::path::PathBuf) {
    let router = tcp(free_port());
    let settings = std::env::temp_dir().join(format!("{name}-rmw_zenohd.json5"));
    std::fs::write(
        &settings,
        "{ mode: \"router\", scouting: { multicast: { enabled: false }, gossip: { enabled: true } },\n  \
         routing: { router: { peers_failover_brokering: false } } }\n",
    )
    .expect("write the router's settings");
    let process = Background::scout(&[
        "router",
        "--listen",
        &router,
        "--zenoh-config",
        &settings.display().to_string(),
    ]);
    (router, process, settings)
}

#[test]
fn a_ros_2_node_sees_the_graph_reads_odometry_and_drives_through_the_arbiter() {
    let test = "ros2_node_drives_through_the_arbiter";
    if let Some(why) = standin_missing() {
        assert!(
            std::env::var_os("SCOUT_REQUIRE_ROS2_STANDIN").is_none(),
            "{test}: {why}"
        );
        return skip(test, &why);
    }
    let name = robot_name("ros2");
    let domain = std::process::id() % 200 + 1;
    let mut sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    connect(&name);
    let (router, router_process, router_settings) = rmw_zenohd(&name);
    let mut node = RosNode::start(&router, domain);
    let started = Instant::now();
    let mut bridge = Bridge::start(&[
        "ros2",
        "--name",
        &name,
        "--connect",
        &router,
        "--domain",
        &domain.to_string(),
    ]);

    // The graph: the node, five publishers, cmd_vel, two services, each token as rmw_zenoh
    // parses it and with the hash rosbags computes for its type.
    let deadline = Instant::now() + LIMIT;
    let graph = loop {
        let graph = node.ask(json!({"cmd": "graph", "domain": domain}));
        if graph["entities"].as_array().map(Vec::len) == Some(9) {
            break graph;
        }
        assert!(Instant::now() < deadline, "incomplete graph: {graph}");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(graph["problems"], json!([]), "{graph}");
    let entities: Vec<(String, String, String)> = graph["entities"]
        .as_array()
        .expect("entities")
        .iter()
        .map(|e| {
            (
                e["kind"].as_str().unwrap_or("").to_owned(),
                e["topic"].as_str().unwrap_or("").to_owned(),
                e["type"].as_str().unwrap_or("").to_owned(),
            )
        })
        .collect();
    for wanted in [
        ("NN", "", ""),
        ("MP", "/odom", "nav_msgs/msg/Odometry"),
        ("MP", "/tf", "tf2_msgs/msg/TFMessage"),
        ("MP", "/battery_state", "sensor_msgs/msg/BatteryState"),
        ("MP", "/joint_states", "sensor_msgs/msg/JointState"),
        ("MP", "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
        ("MS", "/cmd_vel", "geometry_msgs/msg/Twist"),
        ("SS", "/scout/estop", "std_srvs/srv/Trigger"),
        ("SS", "/scout/release", "std_srvs/srv/Trigger"),
    ] {
        let wanted = (wanted.0.into(), wanted.1.into(), wanted.2.into());
        assert!(entities.contains(&wanted), "{wanted:?} not in {entities:?}");
    }

    // Odometry on the exact key: rising sequence numbers, wall-clock stamps, the frames; the
    // attachment's GID is the one rmw_zenoh computes from the publisher's token.
    let odometry = node.echo("/odom", "nav_msgs/msg/Odometry", 10);
    let odom_gid = graph["entities"]
        .as_array()
        .and_then(|entities| {
            entities
                .iter()
                .find(|e| e["kind"] == "MP" && e["topic"] == "/odom")
        })
        .map(|entity| entity["gid"].clone())
        .expect("the /odom publisher's token");
    assert_eq!(odometry[0]["attachment"]["gid"], odom_gid, "{graph}");
    let sequences: Vec<i64> = odometry
        .iter()
        .map(|s| s["attachment"]["sequence"].as_i64().expect("sequence"))
        .collect();
    assert!(sequences.windows(2).all(|w| w[1] > w[0]), "{sequences:?}");
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("clock")
        .as_secs_f64();
    for sample in &odometry {
        assert_eq!(sample["frame_id"], "odom");
        assert_eq!(sample["child_frame_id"], "base_link");
        let stamp = sample["stamp"].as_f64().expect("stamp");
        assert!((now - stamp).abs() < 10.0, "stamp {stamp} vs now {now}");
    }
    let battery = node.echo("/battery_state", "sensor_msgs/msg/BatteryState", 1);
    assert!(battery[0]["voltage"].as_f64() > Some(20.0), "{battery:?}");
    let percentage = battery[0]["percentage"].as_f64().expect("a percentage");
    assert!((0.7..=0.81).contains(&percentage), "{battery:?}");
    assert_eq!(battery[0]["status"], 2, "DISCHARGING: {battery:?}");
    let joints = node.echo("/joint_states", "sensor_msgs/msg/JointState", 1);
    assert_eq!(joints[0]["name"][0], "front_right_wheel");
    let tf = node.echo("/tf", "tf2_msgs/msg/TFMessage", 1);
    assert_eq!(tf[0]["transforms"][0]["child"], "base_link");

    // cmd_vel drives as autonomy once autonomy is armed; silence stops the robot. A stream is
    // new only after a pause since the bridge started (else it may have been going before).
    std::thread::sleep(BLOCKED_PAUSE.saturating_sub(started.elapsed()));
    ok(&["resume", "--name", &name]);
    node.ask(json!({"cmd": "publish", "linear": 0.5, "angular": 0.0}));
    moving(&mut sim, LIMIT);
    let moving_odometry = node.echo("/odom", "nav_msgs/msg/Odometry", 3);
    assert!(
        moving_odometry[2]["linear"].as_f64() > Some(0.2),
        "{moving_odometry:?}"
    );
    assert!(moving_odometry[2]["x"].as_f64() > moving_odometry[0]["x"].as_f64());
    node.ask(json!({"cmd": "quiet"}));
    comes_to_rest(&mut sim, LIMIT);

    // A new stream drives again; `scout estop` stops it; the stream goes on through the
    // release and the resume and never restarts the robot.
    node.ask(json!({"cmd": "publish", "linear": 0.5, "angular": 0.0}));
    moving(&mut sim, LIMIT);
    ok(&["estop", "--name", &name]);
    comes_to_rest(&mut sim, LIMIT);
    ok(&["release", "--name", &name]);
    ok(&["resume", "--name", &name]);
    chassis_stays_still(&mut sim, Duration::from_millis(1500));
    // Zeros mid-stream (a collision monitor's) do not re-arm it either: a new publisher
    // takes over without a pause, first zeros, then motion.
    node.ask(json!({"cmd": "publish", "linear": 0.0, "angular": 0.0}));
    std::thread::sleep(Duration::from_millis(200));
    node.ask(json!({"cmd": "publish", "linear": 0.5, "angular": 0.0}));
    chassis_stays_still(&mut sim, Duration::from_millis(1000));
    // Nor does a network freeze: the router stops for longer than the pause, then delivers
    // what it held (late, in a burst, with no message lost): no pause on the sender's clock.
    router_process.signal(Signal::SIGSTOP);
    std::thread::sleep(BLOCKED_PAUSE + Duration::from_millis(500));
    router_process.signal(Signal::SIGCONT);
    chassis_stays_still(&mut sim, Duration::from_millis(1500));
    assert!(counter(&node.counters(), "cmd_vel_mid_stream") > 0);
    // A pause, then publishing again: a deliberate act; from a Humble publisher (its key has
    // no type hash: the bridge subscribes to any).
    node.ask(json!({"cmd": "quiet"}));
    std::thread::sleep(BLOCKED_PAUSE);
    node.ask(json!({"cmd": "publish", "linear": 0.5, "angular": 0.0, "humble": true}));
    moving(&mut sim, LIMIT);

    // The e-stop service stops it, owned by the bridge; its release restarts nothing.
    let estop = node.call("/scout/estop");
    assert_eq!(estop["success"], true, "{estop}");
    assert!(
        estop["attachment"]["sequence"].as_i64() == Some(1),
        "{estop}"
    );
    comes_to_rest(&mut sim, LIMIT);
    let owner = format!("ros2:{domain}:/scout");
    let (_, status, _) = scout(&["status", "--name", &name, "--json"]);
    assert!(status.contains(&owner), "{status}");
    let release = node.call("/scout/release");
    assert_eq!(release["success"], true, "{release}");
    ok(&["resume", "--name", &name]);
    chassis_stays_still(&mut sim, Duration::from_millis(1000));
    node.ask(json!({"cmd": "quiet"}));

    // A plain wildcard query (a diagnostic tool's) calls no service, and says so.
    let answer = node.ask(json!({"cmd": "get", "key": format!("{domain}/**")}));
    assert!(
        answer["replies"]
            .as_array()
            .is_some_and(|replies| !replies.is_empty()
                && replies.iter().all(|r| r["err"]
                    .as_str()
                    .is_some_and(|e| e.contains("not a service call")))),
        "{answer}"
    );
    let (_, status, _) = scout(&["status", "--name", &name, "--json"]);
    let status: Value = serde_json::from_str(&status).expect("status JSON");
    assert_eq!(
        status["stops"],
        json!([]),
        "a wildcard query latched a stop: {status}"
    );

    // Bad input is counted, not obeyed: a payload that is no Twist, a sample without the
    // attachment rmw_zenoh publishers send.
    let before = node.counters();
    for (payload, attachment) in [("000100000102", true), ("00010000", false)] {
        node.ask(
            json!({"cmd": "raw", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist",
                        "payload": payload, "attachment": attachment}),
        );
    }
    let deadline = Instant::now() + LIMIT;
    loop {
        let after = node.counters();
        let grew = |name| counter(&after, name) > counter(&before, name);
        if grew("cmd_vel_malformed") && grew("cmd_vel_without_attachment") {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "not counted: {before} -> {after}"
        );
    }
    chassis_stays_still(&mut sim, Duration::from_millis(300));

    bridge.process.signal(Signal::SIGINT);
    assert_eq!(bridge.process.wait_exit(LIMIT), Some(0));
    let _ = std::fs::remove_file(&router_settings);
}

/// A Hunter driven by an `ackermann_msgs/AckermannDriveStamped` topic (`ackermann = true`): the
/// bridge subscribes with the type's hash as rosbags computes it, and the chassis goes at the
/// speed asked and turns at the yaw rate the steering angle makes with its wheelbase (the
/// inner wheel's angle on the wire is the gateway's, from that rate); `/joint_states` carries
/// its front wheels' steering joints.
#[test]
fn a_hunter_drives_from_an_ackermann_topic() {
    let test = "a_hunter_drives_from_an_ackermann_topic";
    if let Some(why) = standin_missing() {
        assert!(
            std::env::var_os("SCOUT_REQUIRE_ROS2_STANDIN").is_none(),
            "{test}: {why}"
        );
        return skip(test, &why);
    }
    let name = robot_name("ros2-ackermann");
    let domain = std::process::id() % 200 + 11;
    let mut sim = Sim::start(&["--slcan", "--protocol", "v2", "--model", "hunter2"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--slcan", &device, "--model", "hunter2", "--name", &name]);
    connect(&name);
    let (router, _router_process, router_settings) = rmw_zenohd(&name);
    let settings = std::env::temp_dir().join(format!("{name}-ros2.toml"));
    std::fs::write(
        &settings,
        "[[cmd_vel]]\ntopic = \"ackermann_cmd\"\nclass = \"teleop\"\nackermann = true\n",
    )
    .expect("write the bridge's settings");
    let mut node = RosNode::start(&router, domain);
    let started = Instant::now();
    let _bridge = Bridge::start(&[
        "ros2",
        "--name",
        &name,
        "--connect",
        &router,
        "--domain",
        &domain.to_string(),
        "--config",
        &settings.display().to_string(),
    ]);
    let deadline = Instant::now() + LIMIT;
    loop {
        let graph = node.ask(json!({"cmd": "graph", "domain": domain}));
        let subscribed = graph["entities"].as_array().is_some_and(|entities| {
            entities.iter().any(|e| {
                e["kind"] == "MS"
                    && e["topic"] == "/ackermann_cmd"
                    && e["type"] == "ackermann_msgs/msg/AckermannDriveStamped"
            })
        });
        if subscribed {
            assert_eq!(graph["problems"], json!([]), "{graph}");
            break;
        }
        assert!(
            Instant::now() < deadline,
            "no ackermann subscription: {graph}"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    std::thread::sleep(BLOCKED_PAUSE.saturating_sub(started.elapsed()));
    node.ask(json!({"cmd": "publish", "topic": "/ackermann_cmd", "linear": 0.5, "steering": 0.2}));
    moving(&mut sim, LIMIT);
    let wanted = 0.5 * 0.2_f64.tan() / 0.650;
    let deadline = Instant::now() + LIMIT;
    loop {
        let actual = sim.stats()["actual"].clone();
        let linear = actual["linear"].as_f64().unwrap_or_default();
        let angular = actual["angular"].as_f64().unwrap_or_default();
        if (linear - 0.5).abs() < 0.01 && (angular - wanted).abs() < 0.01 {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "not at 0.5 m/s turning at {wanted} rad/s: {actual}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // Its front wheels' steering joints, positions alone, the inner (left) one wider: rosbags
    // reads the JointState.
    let joints = node.echo("/joint_states", "sensor_msgs/msg/JointState", 4);
    let steering = joints
        .iter()
        .find(|joints| joints["name"][0] == "front_left_steering")
        .unwrap_or_else(|| panic!("no steering joints in {joints:?}"));
    assert_eq!(steering["name"][1], "front_right_steering", "{steering}");
    let (left, right) = (
        steering["position"][0].as_f64().unwrap_or_default(),
        steering["position"][1].as_f64().unwrap_or_default(),
    );
    assert!(left > right && right > 0.1, "{steering}");
    assert_eq!(steering["velocity"], json!([]), "{steering}");
    node.ask(json!({"cmd": "quiet"}));
    comes_to_rest(&mut sim, LIMIT);
    let _ = std::fs::remove_file(&settings);
    let _ = std::fs::remove_file(&router_settings);
}

#[test]
fn scout_ros2_says_what_is_missing() {
    let (code, _, stderr) = scout(&[
        "ros2",
        "--middleware",
        "zenoh",
        "--name",
        &robot_name("ros2-nobody"),
    ]);
    assert_eq!(code, Some(3), "{stderr}");
    assert!(stderr.contains("scout-gateway"), "{stderr}");
    let name = robot_name("ros2-norouter");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    let (code, _, stderr) = scout(&[
        "ros2",
        "--middleware",
        "zenoh",
        "--name",
        &name,
        "--connect",
        &tcp(free_port()),
    ]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("rmw_zenohd"), "{stderr}");
    // A zenoh setting with DDS is a usage error before anything starts (DDS never runs here).
    let (code, _, stderr) = scout(&[
        "ros2",
        "--middleware",
        "dds",
        "--name",
        &name,
        "--connect",
        &tcp(free_port()),
    ]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("--connect is a zenoh setting, but the middleware is dds"),
        "{stderr}"
    );
    let (code, _, stderr) = scout(&[
        "ros2",
        "--middleware",
        "zenoh",
        "--name",
        &name,
        "--node",
        "scout-1",
    ]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("not a valid ROS name"), "{stderr}");
}

#[test]
fn a_second_bridge_for_one_robot_and_domain_is_refused() {
    let name = robot_name("ros2-twice");
    let _gateway = Gateway::start(&["--sim", "--name", &name]);
    connect(&name);
    let router = tcp(free_port());
    let _router = Background::scout(&["router", "--listen", &router]);
    let deadline = Instant::now() + LIMIT;
    while scout_system_tests::try_zenoh_session("client", &[], std::slice::from_ref(&router))
        .is_err()
    {
        assert!(Instant::now() < deadline, "the router never listened");
        std::thread::sleep(Duration::from_millis(100));
    }
    let domain = (std::process::id() % 200 + 1).to_string();
    let bridge = [
        "ros2",
        "--middleware",
        "zenoh",
        "--name",
        &name,
        "--connect",
        &router,
        "--domain",
        &domain,
    ];
    let mut first = Background::scout(&bridge);
    // The first bridge holds its claim (an abstract socket) once it runs.
    let claim = format!("@scout/{name}/ros2/{domain}");
    let deadline = Instant::now() + LIMIT;
    while !std::fs::read_to_string("/proc/net/unix").is_ok_and(|table| table.contains(&claim)) {
        assert!(
            Instant::now() < deadline,
            "the first bridge never claimed {claim}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let (code, _, stderr) = scout(&bridge);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(
        stderr.contains("another `scout ros2` bridge serves robot"),
        "{stderr}"
    );
    // Another domain is another graph: that bridge runs.
    let other = (std::process::id() % 20 + 201).to_string();
    let mut second = Background::scout(&[
        "ros2",
        "--middleware",
        "zenoh",
        "--name",
        &name,
        "--connect",
        &router,
        "--domain",
        &other,
    ]);
    let other_claim = format!("@scout/{name}/ros2/{other}");
    let deadline = Instant::now() + LIMIT;
    while !std::fs::read_to_string("/proc/net/unix").is_ok_and(|table| table.contains(&other_claim))
    {
        assert!(
            Instant::now() < deadline,
            "the other domain's bridge never ran"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    for bridge in [&mut first, &mut second] {
        bridge.signal(Signal::SIGINT);
        assert_eq!(bridge.wait_exit(LIMIT), Some(0));
    }
}

/// The second rmw_zenoh peer (`tests/rmw-zenoh-peer`: ros2-client's zenoh backend, written by
/// others than the bridge's authors), built beside the workspace's binaries (a no-op when it is
/// up to date), or why it cannot be. It is a workspace of its own so that its zenoh features
/// and ros2-client's zenoh backend stay out of the gateway and the bridge under test.
fn rmw_zenoh_peer() -> Result<std::path::PathBuf, String> {
    static BUILT: std::sync::OnceLock<Result<std::path::PathBuf, String>> =
        std::sync::OnceLock::new();
    BUILT
        .get_or_init(|| {
            let bin_dir = scout_system_tests::bin("scout")
                .parent()
                .expect("the binaries' directory")
                .to_owned();
            let target_dir = bin_dir.parent().expect("the target directory");
            let manifest =
                std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("rmw-zenoh-peer/Cargo.toml");
            let mut build = scout_system_tests::cargo();
            // CI lints the workspace by compiling it through clippy's driver: not this
            // workspace, which is not under test.
            build
                .env_remove("RUSTC_WORKSPACE_WRAPPER")
                .env_remove("CLIPPY_ARGS")
                .args(["build", "--quiet", "--locked", "--manifest-path"])
                .arg(&manifest)
                .arg("--target-dir")
                .arg(target_dir);
            if bin_dir.ends_with("release") {
                build.arg("--release");
            }
            match build.output() {
                Ok(output) if output.status.success() => Ok(bin_dir.join("rmw-zenoh-peer")),
                Ok(output) => Err(format!(
                    "building {} failed (it needs crates.io once): {}",
                    manifest.display(),
                    String::from_utf8_lossy(&output.stderr).trim()
                )),
                Err(error) => Err(format!("no cargo to build {}: {error}", manifest.display())),
            }
        })
        .clone()
}

/// Runs the peer's `args` to the end and returns its JSON lines.
fn peer_lines(peer: &std::path::Path, router: &str, domain: u32, args: &[&str]) -> Vec<Value> {
    let child = Command::new(peer)
        .args(["--router", router, "--domain", &domain.to_string()])
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start rmw-zenoh-peer");
    let output = scout_system_tests::wait_output(child, Duration::from_secs(30));
    assert!(
        output.status.success(),
        "rmw-zenoh-peer {args:?}: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    String::from_utf8_lossy(&output.stdout)
        .lines()
        .map(|line| serde_json::from_str(line).expect("a JSON line"))
        .collect()
}

#[test]
fn an_independent_rmw_zenoh_node_reads_odometry_and_drives_through_the_arbiter() {
    let test = "independent_rmw_zenoh_node";
    let peer = match rmw_zenoh_peer() {
        Ok(peer) => peer,
        Err(why) => {
            assert!(
                std::env::var_os("SCOUT_REQUIRE_ROS2_STANDIN").is_none(),
                "{test}: {why}"
            );
            return skip(test, &why);
        }
    };
    let name = robot_name("ros2-peer");
    let domain = std::process::id() % 200 + 1;
    let mut sim = Sim::start(&["--serial"]);
    let device = sim.port().to_owned();
    let _gateway = Gateway::start(&["--serial", &device, "--name", &name]);
    connect(&name);
    let (router, _router_process, router_settings) = rmw_zenohd(&name);
    let started = Instant::now();
    let _bridge = Bridge::start(&[
        "ros2",
        "--name",
        &name,
        "--connect",
        &router,
        "--domain",
        &domain.to_string(),
    ]);

    // The peer's graph cache (built from the liveliness tokens) shows the node and its ends.
    let graph = peer_lines(&peer, &router, domain, &["graph", "--node", "/scout"]);
    assert!(
        graph[0]["nodes"].to_string().contains("/scout"),
        "{graph:?}"
    );

    // Odometry as the peer's own CDR decodes it: the frames, a unit quaternion, rising
    // sequence numbers from one publisher.
    let odometry = peer_lines(&peer, &router, domain, &["echo-odom", "--count", "10"]);
    assert_eq!(odometry.len(), 10);
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .expect("clock")
        .as_secs_f64();
    for sample in &odometry {
        assert_eq!(sample["frame_id"], "odom", "{sample}");
        assert_eq!(sample["child_frame_id"], "base_link", "{sample}");
        assert_eq!(sample["gid"], odometry[0]["gid"], "{sample}");
        let norm = sample["orientation_norm"].as_f64().expect("norm");
        assert!((norm - 1.0).abs() < 1e-9, "{sample}");
        let stamp = sample["stamp"].as_f64().expect("stamp");
        assert!((now - stamp).abs() < 10.0, "stamp {stamp} vs now {now}");
    }
    assert_ne!(odometry[0]["gid"], "00000000000000000000000000000000");
    let sequences: Vec<i64> = odometry
        .iter()
        .map(|s| s["sequence"].as_i64().expect("sequence"))
        .collect();
    assert!(sequences.windows(2).all(|w| w[1] > w[0]), "{sequences:?}");

    // Its cmd_vel drives as autonomy once armed; its silence stops the robot.
    std::thread::sleep(BLOCKED_PAUSE.saturating_sub(started.elapsed()));
    ok(&["resume", "--name", &name]);
    let drive = |seconds: &str| {
        let mut command = Command::new(&peer);
        command
            .args(["--router", &router, "--domain", &domain.to_string()])
            .args(["drive", "--linear", "0.5", "--seconds", seconds])
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::null());
        Background::spawn(command)
    };
    let mut first = drive("3");
    moving(&mut sim, LIMIT);
    let moving_odometry = peer_lines(&peer, &router, domain, &["echo-odom", "--count", "3"]);
    assert!(
        moving_odometry[2]["linear"].as_f64() > Some(0.2),
        "{moving_odometry:?}"
    );
    assert_eq!(first.wait_exit(LIMIT), Some(0));
    comes_to_rest(&mut sim, LIMIT);

    // A stream that goes on across a stop, its release and the resume never moves the robot.
    std::thread::sleep(BLOCKED_PAUSE);
    let _streaming = drive("60");
    moving(&mut sim, LIMIT);
    ok(&["estop", "--name", &name]);
    comes_to_rest(&mut sim, LIMIT);
    ok(&["release", "--name", &name]);
    ok(&["resume", "--name", &name]);
    chassis_stays_still(&mut sim, Duration::from_millis(1500));
    let _ = std::fs::remove_file(&router_settings);
}
