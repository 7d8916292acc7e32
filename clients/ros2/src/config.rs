//! The ROS 2 bridge's settings: one serde struct, read from a TOML file (`scout ros2 --config`),
//! with the command line's overrides on top. Every field has a default; unknown keys are errors.

use std::time::Duration;

use scout_interface::control::{Class, MAX_CLIENT_NAME};
use serde::{Deserialize, Serialize};

use crate::cdr::CdrError;
use crate::msgs::{self, Command, MessageType};
use crate::publish::Topic;
use crate::rmw::Distro;
use crate::stream::Pauses;

/// The highest ROS domain id (DDS' port mapping: 7400 + 250 * domain must fit in 16 bits).
pub const MAX_DOMAIN: u32 = 232;

/// The endpoint of a ROS 2 router (`rmw_zenohd`) on this host.
pub const ROS2_ROUTER: &str = "tcp/127.0.0.1:7447";

/// The ROS 2 middleware the bridge speaks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Middleware {
    /// DDS, as Fast DDS and Cyclone DDS speak it (ROS 2's default middlewares).
    Dds,
    /// rmw_zenoh, through the ROS 2 router (rmw_zenohd).
    Zenoh,
}

/// The RMW implementation that selects rmw_zenoh.
pub const RMW_ZENOH: &str = "rmw_zenoh_cpp";

impl Ros2Config {
    /// The distro the bridge speaks to: the setting, else Jazzy's (Iron and later).
    pub fn distro(&self) -> Distro {
        self.distro.unwrap_or_default()
    }
}

impl Middleware {
    /// The middleware every ROS node on this machine would use: `$RMW_IMPLEMENTATION`
    /// (`rmw_zenoh_cpp` is zenoh; unset or any other, a DDS implementation, is DDS), with why.
    pub fn from_rmw_implementation(rmw: Option<&str>) -> (Self, String) {
        match rmw {
            Some(RMW_ZENOH) => (
                Middleware::Zenoh,
                format!("RMW_IMPLEMENTATION is {RMW_ZENOH}"),
            ),
            Some(other) if !other.is_empty() => (
                Middleware::Dds,
                format!("RMW_IMPLEMENTATION is {other}, a DDS implementation"),
            ),
            Some(_) | None => (
                Middleware::Dds,
                "RMW_IMPLEMENTATION is not set: ROS 2's default middleware is DDS".into(),
            ),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Middleware::Dds => "dds",
            Middleware::Zenoh => "zenoh",
        }
    }
}

/// `scout ros2`'s settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Ros2Config {
    /// The ROS node name.
    pub node: String,
    /// The node's namespace (`/robot1`), empty for none: relative topic names resolve in it.
    pub namespace: String,
    /// The ROS domain; `--domain`, then `$ROS_DOMAIN_ID`, override it.
    pub domain: u32,
    /// `dds` or `zenoh`; unset: as `$RMW_IMPLEMENTATION` says (`--middleware` overrides).
    pub middleware: Option<Middleware>,
    /// Zenoh endpoints to connect to, in client mode: the ROS 2 router.
    pub connect: Vec<String>,
    /// A zenoh configuration file (JSON5) instead of the client-mode defaults.
    pub zenoh_config: Option<String>,
    /// `jazzy` (Iron and later: type hashes over zenoh, 16-byte GIDs over DDS) or `humble`
    /// (no type hashes, 24-byte GIDs); unset: as `$ROS_DISTRO` says (`--humble` overrides).
    pub distro: Option<Distro>,
    /// Publish the odom -> base transform on `/tf` (off when robot_localization publishes it).
    pub publish_tf: bool,
    /// Frame ids.
    pub frames: Frames,
    /// Topic names.
    pub topics: Topics,
    /// The wheels' joint names, motor 1 to 4 (front right, front left, rear left, rear right).
    pub wheel_joints: [String; 4],
    /// The steering joints' names, published as a JointState of their own (positions only) on
    /// a chassis that steers: a Hunter's front left and right (the first two), a Ranger's four
    /// in 0x271's order (which wheel each is, no source says: name them as yours are).
    pub steering_joints: [String; 4],
    /// Motor shaft turns per wheel turn (default: the gateway's model's).
    pub gear_ratio: Option<f64>,
    /// The topics that drive, each as a class of the arbiter.
    pub cmd_vel: Vec<CmdVelTopic>,
    /// How long a cmd_vel stream that let its control lapse by its own silence must pause
    /// before its next message takes control again, ms (a teleop key pressed again).
    pub new_stream_after_ms: u64,
    /// How long a stream that went on across a stop, a takeover, a release or a refusal (or
    /// that may have been going when the bridge started) must pause before it may take
    /// control, ms: a controller's stall must not restart the robot.
    pub blocked_pause_ms: u64,
    /// The e-stop and release services (std_srvs/Trigger).
    pub services: bool,
    /// The release service (any ROS node may call it: ROS has no identities; it releases
    /// only the stops the e-stop service latched). Off: only `scout release` releases them.
    pub release_service: bool,
}

/// Frame ids.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Frames {
    pub odom: String,
    pub base: String,
}

/// Topic names: relative ones resolve in the namespace.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Topics {
    pub odom: String,
    pub tf: String,
    pub battery_state: String,
    pub joint_states: String,
    pub diagnostics: String,
    /// std_srvs/Trigger: latch a stop owned by this bridge.
    pub estop: String,
    /// std_srvs/Trigger: release the stops this bridge latched.
    pub release: String,
}

/// A topic that drives.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CmdVelTopic {
    pub topic: String,
    /// `autonomy` (armed by `scout resume`) or `teleop` (overrides autonomy).
    #[serde(default = "autonomy")]
    pub class: Class,
    /// geometry_msgs/TwistStamped instead of Twist (Nav2 on Jazzy and later can send it).
    #[serde(default)]
    pub stamped: bool,
    /// ackermann_msgs/AckermannDriveStamped instead of Twist: a chassis that steers its front
    /// wheels (the Hunter); its speed and steering angle are made a twist with its wheelbase.
    #[serde(default)]
    pub ackermann: bool,
}

impl CmdVelTopic {
    /// The message type it carries.
    pub fn message(&self) -> MessageType {
        match (self.ackermann, self.stamped) {
            (true, _) => msgs::ACKERMANN_DRIVE_STAMPED,
            (false, true) => msgs::TWIST_STAMPED,
            (false, false) => msgs::TWIST,
        }
    }

    /// Its payload decoded ([`CmdVelTopic::message`]).
    pub fn decode(&self, bytes: &[u8]) -> Result<Command, CdrError> {
        match self.ackermann {
            true => msgs::decode_ackermann(bytes).map(Command::Ackermann),
            false => msgs::decode_twist(bytes, self.stamped).map(Command::Twist),
        }
    }
}

fn autonomy() -> Class {
    Class::Autonomy
}

impl Default for Frames {
    fn default() -> Self {
        Self {
            odom: "odom".into(),
            base: "base_link".into(),
        }
    }
}

impl Default for Topics {
    fn default() -> Self {
        Self {
            odom: "odom".into(),
            tf: "/tf".into(),
            battery_state: "battery_state".into(),
            joint_states: "joint_states".into(),
            diagnostics: "/diagnostics".into(),
            estop: "~/estop".into(),
            release: "~/release".into(),
        }
    }
}

impl Default for Ros2Config {
    fn default() -> Self {
        Self {
            node: "scout".into(),
            namespace: String::new(),
            domain: 0,
            middleware: None,
            connect: Vec::new(),
            zenoh_config: None,
            distro: None,
            publish_tf: true,
            frames: Frames::default(),
            topics: Topics::default(),
            wheel_joints: [
                "front_right_wheel".into(),
                "front_left_wheel".into(),
                "rear_left_wheel".into(),
                "rear_right_wheel".into(),
            ],
            steering_joints: [
                "front_left_steering".into(),
                "front_right_steering".into(),
                "rear_left_steering".into(),
                "rear_right_steering".into(),
            ],
            gear_ratio: None,
            cmd_vel: vec![CmdVelTopic {
                topic: "cmd_vel".into(),
                class: Class::Autonomy,
                stamped: false,
                ackermann: false,
            }],
            new_stream_after_ms: 500,
            blocked_pause_ms: 2000,
            services: true,
            release_service: true,
        }
    }
}

/// Why a configuration cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum Ros2ConfigError {
    #[error("reading {path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Parse {
        path: String,
        source: Box<toml::de::Error>,
    },
    #[error("{what} `{name}` is not a valid ROS name: {why}")]
    BadName {
        what: &'static str,
        name: String,
        why: &'static str,
    },
    #[error("ROS domain {0} is out of range: ROS 2 domains are 0 to {MAX_DOMAIN}")]
    BadDomain(u32),
    #[error(
        "{setting} is a zenoh setting, but the middleware is {middleware} ({why}): give \
         --middleware zenoh (or RMW_IMPLEMENTATION=rmw_zenoh_cpp), or leave {setting} out"
    )]
    OtherMiddlewares {
        setting: &'static str,
        middleware: &'static str,
        why: String,
    },
    #[error("topic {0} is used twice: give each publisher and cmd_vel topic a name of its own")]
    Duplicate(String),
    #[error(
        "joint {0} is named twice: give each of wheel_joints and steering_joints a name of its own"
    )]
    DuplicateJoint(String),
    #[error("gear_ratio must be a positive number, found {0}")]
    BadGearRatio(f64),
    #[error(
        "cmd_vel topic {0} is both `stamped` and `ackermann`: an AckermannDriveStamped is stamped \
         already; give `ackermann = true` alone"
    )]
    StampedAckermann(String),
    #[error(
        "new_stream_after_ms must be 500..=10000 (at least a command's longest life) and \
         blocked_pause_ms new_stream_after_ms..=60000, found {0} and {1}"
    )]
    BadPauses(u64, u64),
    #[error(
        "the arbiter client name `{0}` is longer than {MAX_CLIENT_NAME} bytes: shorten the \
         namespace, node or topic name"
    )]
    LongClientName(String),
}

impl Ros2Config {
    /// The file's settings, or the defaults without one.
    pub fn load(path: Option<&std::path::Path>) -> Result<Self, Ros2ConfigError> {
        let Some(path) = path else {
            return Ok(Self::default());
        };
        let shown = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| Ros2ConfigError::Read {
            path: shown.clone(),
            source,
        })?;
        toml::from_str(&text).map_err(|source| Ros2ConfigError::Parse {
            path: shown,
            source: Box::new(source),
        })
    }

    /// The pauses a cmd_vel stream must make before it may take control.
    pub fn pauses(&self) -> Pauses {
        Pauses {
            new_stream: Duration::from_millis(self.new_stream_after_ms),
            blocked: Duration::from_millis(self.blocked_pause_ms),
        }
    }

    /// `topic` as a fully qualified name: absolute as given, `~/x` under the node, else under
    /// the namespace.
    pub fn resolve(&self, topic: &str) -> String {
        if topic.starts_with('/') {
            topic.to_owned()
        } else if let Some(private) = topic.strip_prefix("~/") {
            format!("{}/{}/{private}", self.namespace, self.node)
        } else {
            format!("{}/{topic}", self.namespace)
        }
    }

    /// The arbiter client a cmd_vel topic drives as: `ros2:<domain>:<topic>`.
    pub fn cmd_vel_client(&self, topic: &CmdVelTopic) -> String {
        format!("ros2:{}:{}", self.domain, self.resolve(&topic.topic))
    }

    /// The arbiter client of the services, the owner of the stops they latch:
    /// `ros2:<domain>:<namespace>/<node>`, so that two bridges never share stops.
    pub fn service_client(&self) -> String {
        format!("ros2:{}:{}/{}", self.domain, self.namespace, self.node)
    }

    /// The topics the bridge publishes, resolved, with `/tf` only when it is on.
    pub fn published(&self) -> Vec<String> {
        Topic::ALL
            .iter()
            .filter_map(|topic| topic.name(self))
            .map(|name| self.resolve(name))
            .collect()
    }

    /// Checks names and values, so that a mistake is reported at start and not as a silent
    /// topic.
    pub fn validate(&self) -> Result<(), Ros2ConfigError> {
        // DDS maps a domain to UDP ports 7400 + 250 * domain: ROS allows 0 to 232.
        if self.domain > MAX_DOMAIN {
            return Err(Ros2ConfigError::BadDomain(self.domain));
        }
        check_name("node name", &self.node, false)?;
        if !self.namespace.is_empty() {
            check_name("namespace", &self.namespace, true)?;
            if !self.namespace.starts_with('/') {
                return Err(Ros2ConfigError::BadName {
                    what: "namespace",
                    name: self.namespace.clone(),
                    why: "it must start with `/`",
                });
            }
        }
        if let Some(both) = self.cmd_vel.iter().find(|c| c.stamped && c.ackermann) {
            return Err(Ros2ConfigError::StampedAckermann(both.topic.clone()));
        }
        let mut seen = std::collections::BTreeSet::new();
        let drives = self.cmd_vel.iter().map(|c| c.topic.as_str());
        let services = [self.topics.estop.as_str(), self.topics.release.as_str()];
        let services = services
            .into_iter()
            .take(if self.release_service { 2 } else { 1 });
        for topic in self
            .published()
            .iter()
            .map(String::as_str)
            .chain(drives)
            .chain(services.filter(|_| self.services))
        {
            let resolved = self.resolve(topic);
            check_name("topic", &resolved, true)?;
            if !seen.insert(resolved.clone()) {
                return Err(Ros2ConfigError::Duplicate(resolved));
            }
        }
        let mut joints = std::collections::BTreeSet::new();
        for joint in self.wheel_joints.iter().chain(&self.steering_joints) {
            if joint.is_empty() {
                return Err(Ros2ConfigError::BadName {
                    what: "joint",
                    name: joint.clone(),
                    why: "it is empty",
                });
            }
            if !joints.insert(joint.as_str()) {
                return Err(Ros2ConfigError::DuplicateJoint(joint.clone()));
            }
        }
        if let Some(gear_ratio) = self.gear_ratio
            && !(gear_ratio.is_finite() && gear_ratio > 0.0)
        {
            return Err(Ros2ConfigError::BadGearRatio(gear_ratio));
        }
        let (new, blocked) = (self.new_stream_after_ms, self.blocked_pause_ms);
        if !(500..=10_000).contains(&new) || !(new..=60_000).contains(&blocked) {
            return Err(Ros2ConfigError::BadPauses(new, blocked));
        }
        let clients = self.cmd_vel.iter().map(|topic| self.cmd_vel_client(topic));
        for name in clients.chain([self.service_client()]) {
            if name.len() > MAX_CLIENT_NAME {
                return Err(Ros2ConfigError::LongClientName(name));
            }
        }
        Ok(())
    }
}

/// ROS names: alphanumerics and `_`, tokens not starting with a digit, `/` between tokens
/// where `path` allows it.
fn check_name(what: &'static str, name: &str, path: bool) -> Result<(), Ros2ConfigError> {
    let bad = |why| {
        Err(Ros2ConfigError::BadName {
            what,
            name: name.to_owned(),
            why,
        })
    };
    let body = if path {
        name.strip_prefix('/').unwrap_or(name)
    } else {
        name
    };
    if body.is_empty() {
        return bad("it is empty");
    }
    if !path && body.contains('/') {
        return bad("it may not contain `/`");
    }
    for token in body.split('/') {
        if token.is_empty() {
            return bad("it has an empty part (`//` or a trailing `/`)");
        }
        if token.starts_with(|c: char| c.is_ascii_digit()) {
            return bad("a part starts with a digit");
        }
        if !token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return bad("only letters, digits and `_` are allowed");
        }
    }
    Ok(())
}

/// A configuration that cannot be used is a usage error.
impl scout_interface::failure::FailureKind for Ros2ConfigError {
    fn kind(&self) -> scout_interface::failure::Failure {
        scout_interface::failure::Failure::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_resolve_in_the_namespace_and_under_the_node() {
        let config = Ros2Config {
            namespace: "/robot1".into(),
            ..Default::default()
        };
        assert_eq!(config.resolve("odom"), "/robot1/odom");
        assert_eq!(config.resolve("/tf"), "/tf");
        assert_eq!(config.resolve("~/estop"), "/robot1/scout/estop");
        assert_eq!(Ros2Config::default().resolve("cmd_vel"), "/cmd_vel");
        config.validate().expect("valid");
    }

    #[test]
    fn a_file_sets_what_it_names_and_keeps_the_rest() {
        let config: Ros2Config = toml::from_str(
            r#"
            namespace = "/r2"
            publish_tf = false
            distro = "humble"
            [frames]
            base = "base_footprint"
            [[cmd_vel]]
            topic = "cmd_vel_nav"
            stamped = true
            [[cmd_vel]]
            topic = "cmd_vel_teleop"
            class = "teleop"
            "#,
        )
        .expect("valid TOML");
        assert_eq!(config.frames.odom, "odom");
        assert_eq!(config.frames.base, "base_footprint");
        assert_eq!(config.distro, Some(Distro::Humble));
        assert_eq!(config.cmd_vel[0].class, Class::Autonomy);
        assert!(config.cmd_vel[0].stamped);
        assert_eq!(config.cmd_vel[1].class, Class::Teleop);
        assert!(!config.published().contains(&"/tf".to_owned()));
        config.validate().expect("valid");
    }

    #[test]
    fn an_ackermann_topic_carries_its_type_and_is_not_also_stamped() {
        let mut config: Ros2Config = toml::from_str(
            r#"
            [[cmd_vel]]
            topic = "ackermann_cmd"
            ackermann = true
            "#,
        )
        .expect("valid TOML");
        config.validate().expect("valid");
        assert_eq!(config.cmd_vel[0].message(), msgs::ACKERMANN_DRIVE_STAMPED);
        let mut twice = config.clone();
        twice.steering_joints[0] = twice.wheel_joints[1].clone();
        assert_eq!(
            twice.validate().map_err(|e| e.to_string()),
            Err(
                "joint front_left_wheel is named twice: give each of wheel_joints and \
                 steering_joints a name of its own"
                    .into()
            )
        );
        config.cmd_vel[0].stamped = true;
        assert_eq!(
            config.validate().map_err(|e| e.to_string()),
            Err(
                "cmd_vel topic ackermann_cmd is both `stamped` and `ackermann`: an \
                 AckermannDriveStamped is stamped already; give `ackermann = true` alone"
                    .into()
            )
        );
    }

    #[test]
    fn the_example_file_is_valid_and_states_the_defaults() {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/scout-ros2.toml");
        let example = Ros2Config::load(Some(&path)).expect("the example loads");
        example.validate().expect("the example is valid");
        // What it marks as not the default: the namespace and the cmd_vel topics after the first.
        let defaults = Ros2Config {
            namespace: String::new(),
            cmd_vel: example.cmd_vel[..1].to_vec(),
            connect: Vec::new(),
            ..example.clone()
        };
        assert_eq!(defaults, Ros2Config::default());
        assert_eq!(example.connect, [ROS2_ROUTER]);
    }

    #[test]
    fn mistakes_are_reported_at_start() {
        let error = toml::from_str::<Ros2Config>("frame = 1").expect_err("unknown key");
        assert!(
            error.to_string().contains("unknown field `frame`"),
            "{error}"
        );
        let error = toml::from_str::<Ros2Config>("[[cmd_vel]]\ntopic = \"x\"\nclass = \"boss\"")
            .expect_err("unknown class");
        assert!(
            error.to_string().contains("unknown variant `boss`"),
            "{error}"
        );
        for (config, wanted) in [
            (
                Ros2Config {
                    node: "scout-1".into(),
                    ..Default::default()
                },
                "only letters",
            ),
            (
                Ros2Config {
                    namespace: "robot".into(),
                    ..Default::default()
                },
                "must start with `/`",
            ),
            (
                Ros2Config {
                    cmd_vel: vec![CmdVelTopic {
                        topic: "/odom".into(),
                        class: Class::Teleop,
                        stamped: false,
                        ackermann: false,
                    }],
                    ..Default::default()
                },
                "used twice",
            ),
            (
                Ros2Config {
                    topics: Topics {
                        odom: "base//odom".into(),
                        ..Default::default()
                    },
                    ..Default::default()
                },
                "empty part",
            ),
            (
                Ros2Config {
                    gear_ratio: Some(0.0),
                    ..Default::default()
                },
                "gear_ratio",
            ),
        ] {
            let error = config.validate().expect_err(wanted).to_string();
            assert!(error.contains(wanted), "{error}");
        }
    }
}
