//! A ROS 2 node on rmw_zenoh written by others than the bridge's authors (ros2-client's zenoh
//! backend), for the system tests: it finds the bridge in the graph, reads `/odom` and drives
//! through `cmd_vel`. One JSON line per result on stdout; exit 0 done, 1 failed, 2 usage.
//!
//! ```text
//! rmw-zenoh-peer --router tcp/127.0.0.1:P --domain D graph --node /scout
//! rmw-zenoh-peer --router tcp/127.0.0.1:P --domain D echo-odom --count 10
//! rmw-zenoh-peer --router tcp/127.0.0.1:P --domain D drive --linear 0.5 --seconds 3
//! ```

use std::process::ExitCode;
use std::time::{Duration, Instant};

use ros2_client::zenoh::{Context, ContextOptions, Node};
use ros2_client::{MessageTypeName, Name, NodeName, NodeOptions, QosProfile};
use serde::{Deserialize, Serialize};

/// How long a command waits for what it needs before it fails.
const LIMIT: Duration = Duration::from_secs(15);

#[derive(Debug, Deserialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

#[derive(Debug, Deserialize)]
struct Header {
    stamp: Time,
    frame_id: String,
}

#[derive(Debug, Serialize, Deserialize)]
struct Vector3 {
    x: f64,
    y: f64,
    z: f64,
}

#[derive(Debug, Deserialize)]
struct Quaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

#[derive(Debug, Deserialize)]
struct Pose {
    position: Vector3,
    orientation: Quaternion,
}

/// A 6x6 covariance: serde reads arrays of up to 32, and CDR lays the two parts back to back.
#[derive(Debug, Deserialize)]
struct Covariance([f64; 32], [f64; 4]);

#[derive(Debug, Deserialize)]
struct PoseWithCovariance {
    pose: Pose,
    covariance: Covariance,
}

#[derive(Debug, Serialize, Deserialize)]
struct Twist {
    linear: Vector3,
    angular: Vector3,
}

#[derive(Debug, Deserialize)]
struct TwistWithCovariance {
    twist: Twist,
    covariance: Covariance,
}

/// `nav_msgs/Odometry`.
#[derive(Debug, Deserialize)]
struct Odometry {
    header: Header,
    child_frame_id: String,
    pose: PoseWithCovariance,
    twist: TwistWithCovariance,
}

struct Args {
    router: String,
    domain: u16,
    command: String,
    node: String,
    count: usize,
    linear: f64,
    seconds: f64,
}

fn parse(mut args: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut parsed = Args {
        router: String::new(),
        domain: 0,
        command: String::new(),
        node: "/scout".into(),
        count: 10,
        linear: 0.0,
        seconds: 1.0,
    };
    while let Some(arg) = args.next() {
        let mut value = |name: &str| args.next().ok_or(format!("{name} needs a value"));
        match arg.as_str() {
            "--router" => parsed.router = value("--router")?,
            "--domain" => parsed.domain = number(&value("--domain")?)?,
            "--node" => parsed.node = value("--node")?,
            "--count" => parsed.count = number(&value("--count")?)?,
            "--linear" => parsed.linear = number(&value("--linear")?)?,
            "--seconds" => parsed.seconds = number(&value("--seconds")?)?,
            "graph" | "echo-odom" | "drive" => parsed.command = arg,
            other => return Err(format!("unknown argument {other}")),
        }
    }
    if parsed.router.is_empty() || parsed.command.is_empty() {
        return Err(
            "usage: rmw-zenoh-peer --router ENDPOINT --domain D graph|echo-odom|drive".into(),
        );
    }
    Ok(parsed)
}

fn number<T: std::str::FromStr>(text: &str) -> Result<T, String> {
    text.parse().map_err(|_| format!("{text} is not a number"))
}

/// rmw_zenoh's default session: a peer that finds others through the router (gossip), with no
/// multicast; it listens on loopback only.
fn context(args: &Args) -> Result<Context, String> {
    let mut config = zenoh::Config::default();
    for (key, value) in [
        ("mode", "\"peer\"".to_owned()),
        ("connect/endpoints", format!("[\"{}\"]", args.router)),
        ("listen/endpoints", "[\"tcp/127.0.0.1:0\"]".to_owned()),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "true".to_owned()),
    ] {
        config
            .insert_json5(key, &value)
            .map_err(|error| format!("zenoh setting {key}: {error}"))?;
    }
    Context::with_options(
        ContextOptions::new()
            .domain_id(args.domain)
            .zenoh_config(config),
    )
    .map_err(|error| format!("opening the zenoh session: {error:?}"))
}

fn node(context: &Context, name: &str) -> Result<Node, String> {
    let name = NodeName::new("/", name).map_err(|error| format!("{error:?}"))?;
    context
        .new_node(name, NodeOptions::new().enable_rosout(false))
        .map_err(|error| format!("making the node: {error:?}"))
}

fn topic_name(name: &str) -> Result<Name, String> {
    Name::parse(name).map_err(|error| format!("{name}: {error:?}"))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|byte| format!("{byte:02x}")).collect()
}

/// Waits until the graph shows the bridge's node, its `/odom` publisher and `cmd_vel`
/// subscription, and prints what it saw.
fn graph(args: &Args) -> Result<(), String> {
    let context = context(args)?;
    let deadline = Instant::now() + LIMIT;
    loop {
        let nodes = context.node_names();
        let odom = context.publisher_count("/odom");
        let cmd_vel = context.subscription_count("/cmd_vel");
        if nodes.contains(&args.node) && odom > 0 && cmd_vel > 0 {
            println!(
                "{}",
                serde_json::json!({"nodes": nodes, "odom_publishers": odom,
                                   "cmd_vel_subscriptions": cmd_vel})
            );
            return Ok(());
        }
        if Instant::now() > deadline {
            return Err(format!(
                "the graph never showed {} with /odom and /cmd_vel: nodes {nodes:?}, \
                 /odom publishers {odom}, /cmd_vel subscriptions {cmd_vel}",
                args.node
            ));
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Prints `--count` odometry messages with what rmw_zenoh's attachment says of each.
fn echo_odom(args: &Args) -> Result<(), String> {
    let context = context(args)?;
    let node = node(&context, "independent_odom_reader")?;
    let topic = node.create_topic(
        &topic_name("/odom")?,
        MessageTypeName::new("nav_msgs", "Odometry"),
        &QosProfile::subscription_default(),
    );
    let subscription = node
        .create_subscription::<Odometry>(&topic, None)
        .map_err(|error| format!("subscribing to /odom: {error:?}"))?;
    let deadline = Instant::now() + LIMIT;
    let mut printed = 0;
    while printed < args.count {
        match subscription.try_take() {
            Ok(Some((odometry, info))) => {
                printed += 1;
                let stamp = f64::from(odometry.header.stamp.sec)
                    + f64::from(odometry.header.stamp.nanosec) * 1e-9;
                let orientation = &odometry.pose.pose.orientation;
                println!(
                    "{}",
                    serde_json::json!({
                        "frame_id": odometry.header.frame_id,
                        "child_frame_id": odometry.child_frame_id,
                        "stamp": stamp,
                        "x": odometry.pose.pose.position.x,
                        "y": odometry.pose.pose.position.y,
                        "orientation_norm": (orientation.x.powi(2) + orientation.y.powi(2)
                            + orientation.z.powi(2) + orientation.w.powi(2)).sqrt(),
                        "linear": odometry.twist.twist.linear.x,
                        "angular": odometry.twist.twist.angular.z,
                        "pose_covariance_xx": odometry.pose.covariance.0[0],
                        "twist_covariance_last": odometry.twist.covariance.1[3],
                        "sequence": info.sequence_number(),
                        "gid": hex(&info.publisher_gid().to_bytes16()),
                    })
                );
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(5)),
            Err(error) => return Err(format!("reading /odom: {error:?}")),
        }
        if Instant::now() > deadline {
            return Err(format!(
                "{printed} of {} odometry messages in {LIMIT:?}",
                args.count
            ));
        }
    }
    Ok(())
}

/// Publishes `Twist(--linear, 0)` on `/cmd_vel` at 20 Hz for `--seconds`, then stops.
fn drive(args: &Args) -> Result<(), String> {
    let context = context(args)?;
    let node = node(&context, "independent_driver")?;
    let topic = node.create_topic(
        &topic_name("/cmd_vel")?,
        MessageTypeName::new("geometry_msgs", "Twist"),
        &QosProfile::publisher_default(),
    );
    let publisher = node
        .create_publisher::<Twist>(&topic, None)
        .map_err(|error| format!("publishing on /cmd_vel: {error:?}"))?;
    let end = Instant::now() + Duration::from_secs_f64(args.seconds);
    let mut published = 0u64;
    while Instant::now() < end {
        let twist = Twist {
            linear: Vector3 {
                x: args.linear,
                y: 0.0,
                z: 0.0,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.0,
            },
        };
        publisher
            .publish(twist)
            .map_err(|error| format!("publishing: {error:?}"))?;
        published += 1;
        std::thread::sleep(Duration::from_millis(50));
    }
    println!("{}", serde_json::json!({"published": published}));
    Ok(())
}

fn main() -> ExitCode {
    let args = match parse(std::env::args().skip(1)) {
        Ok(args) => args,
        Err(error) => {
            eprintln!("rmw-zenoh-peer: {error}");
            return ExitCode::from(2);
        }
    };
    let result = match args.command.as_str() {
        "graph" => graph(&args),
        "echo-odom" => echo_odom(&args),
        "drive" => drive(&args),
        other => Err(format!("no command {other}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(error) => {
            eprintln!("rmw-zenoh-peer: {error}");
            ExitCode::FAILURE
        }
    }
}
