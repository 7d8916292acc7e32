//! A robot's name, checked once, and the names derived from it that are not services or keys:
//! its processes' iceoryx2 nodes, the running marker, the ROS 2 bridge's claim. (Services,
//! zenoh keys and the stop endpoint all start from [`crate::services::prefix`].)

use std::fmt;
use std::ops::Deref;
use std::str::FromStr;

/// The longest robot name: it names every service and key.
pub const MAX_ROBOT_NAME: usize = 32;

/// A robot name that cannot name services and keys.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "robot name `{0}` must be 1 to {MAX_ROBOT_NAME} letters, digits, `-` or `_` (it names iceoryx2 services and zenoh keys)"
)]
pub struct BadRobotName(pub String);

/// A robot (gateway) name: 1 to [`MAX_ROBOT_NAME`] ASCII letters, digits, `-` and `_`. Made
/// only by [`RobotName::new`] (or parsing), so a value of this type always names services,
/// keys, nodes and sockets; it reads as a `&str` wherever one is wanted.
#[derive(
    Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(try_from = "String", into = "String")]
pub struct RobotName(String);

impl RobotName {
    /// `name`, if it is a valid robot name.
    pub fn new(name: &str) -> Result<Self, BadRobotName> {
        let valid = !name.is_empty()
            && name.len() <= MAX_ROBOT_NAME
            && name
                .bytes()
                .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
        if valid {
            Ok(Self(name.to_owned()))
        } else {
            Err(BadRobotName(name.to_owned()))
        }
    }

    /// The iceoryx2 node name of `program` serving or using this robot (`scout-gateway-ROBOT`).
    pub fn node(&self, program: Program) -> String {
        format!("{}-{}", program.prefix(), self.0)
    }

    /// The robot whose `program` node this is, if it is one (the doctor reads what dead
    /// processes left).
    pub fn of_node(node: &str, program: Program) -> Option<Self> {
        let name = node.strip_prefix(program.prefix())?.strip_prefix('-')?;
        Self::new(name).ok()
    }

    /// The file name of the marker that exists while a gateway of this robot runs.
    pub fn running_marker(&self) -> String {
        format!("robot-{}.running", self.0)
    }

    /// The abstract socket address that one ROS 2 bridge per robot and ROS domain holds.
    pub fn ros2_claim(&self, domain: u32) -> String {
        format!("{}/ros2/{domain}", crate::services::prefix(&self.0))
    }
}

/// The programs whose iceoryx2 nodes carry the robot's name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Program {
    /// The gateway's driver.
    Gateway,
    /// The zenoh bridge's state and status publisher.
    Bridge,
    /// The zenoh bridge's remote commands.
    BridgeCommands,
    /// The zenoh bridge's remote e-stops.
    BridgeEstops,
    /// A client (`scout`, the libraries).
    Client,
}

impl Program {
    fn prefix(self) -> &'static str {
        match self {
            Self::Gateway => "scout-gateway",
            Self::Bridge => "scout-bridge",
            Self::BridgeCommands => "scout-bridge-commands",
            Self::BridgeEstops => "scout-bridge-estops",
            Self::Client => "scout-client",
        }
    }
}

impl Deref for RobotName {
    type Target = str;

    fn deref(&self) -> &str {
        &self.0
    }
}

impl fmt::Display for RobotName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl FromStr for RobotName {
    type Err = BadRobotName;

    fn from_str(name: &str) -> Result<Self, BadRobotName> {
        Self::new(name)
    }
}

impl TryFrom<String> for RobotName {
    type Error = BadRobotName;

    fn try_from(name: String) -> Result<Self, BadRobotName> {
        Self::new(&name)
    }
}

impl From<RobotName> for String {
    fn from(name: RobotName) -> Self {
        name.0
    }
}

impl PartialEq<&str> for RobotName {
    fn eq(&self, other: &&str) -> bool {
        self.0 == *other
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_checked() {
        assert!(RobotName::new("scout-1_b").is_ok());
        let longest = "a".repeat(MAX_ROBOT_NAME);
        assert!(RobotName::new(&longest).is_ok());
        for bad in [
            "",
            "a/b",
            "a b",
            "ä",
            "a.b",
            &"a".repeat(MAX_ROBOT_NAME + 1),
        ] {
            assert!(RobotName::new(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn node_names_read_back_for_their_program_only() {
        let robot = RobotName::new("alpha-2").expect("valid");
        for program in [
            Program::Gateway,
            Program::Bridge,
            Program::BridgeCommands,
            Program::BridgeEstops,
            Program::Client,
        ] {
            let node = robot.node(program);
            assert_eq!(RobotName::of_node(&node, program), Some(robot.clone()));
        }
        // `scout-bridge-estops-x` is the bridge's e-stop node of x, not the bridge node of
        // `estops-x`... which is a valid name: the programs' nodes are told apart by the caller.
        assert_eq!(RobotName::of_node("scout-gateway-", Program::Gateway), None);
        assert_eq!(RobotName::of_node("scout-client-a", Program::Gateway), None);
        assert_eq!(
            RobotName::of_node("scout-gatewayx-a", Program::Gateway),
            None
        );
    }

    #[test]
    fn derived_names() {
        let robot = RobotName::new("r1").expect("valid");
        assert_eq!(robot.running_marker(), "robot-r1.running");
        assert_eq!(robot.ros2_claim(7), "scout/r1/ros2/7");
        assert_eq!(&*robot, "r1");
    }
}
