//! What rmw_zenoh (ROS 2's zenoh middleware) puts on the wire besides the CDR payload: the data
//! key of a topic, the 33-byte attachment every sample carries, and the liveliness tokens that
//! make a node and its publishers and subscriptions appear in the ROS graph.
//!
//! Checked against ros2/rmw_zenoh's `rmw_zenoh_cpp/src/detail/`: `liveliness_utils.cpp`
//! (`TopicInfo`'s key, `Entity`'s token fields and `mangle_name`, `qos_to_keyexpr` against
//! `qos.cpp`'s defaults: reliable, volatile, keep last 42), `attachment_helpers.cpp` (zenoh-ext
//! serialization of `i64, i64, std::array<u8, 16>`, the array with its length).

use crate::msgs::MessageType;

/// Reliable, volatile, keep last 10, default deadline, lifespan and liveliness: rmw_zenoh's
/// `qos_to_keyexpr` of ROS 2's default QoS.
pub const DEFAULT_QOS: &str = "::,10:,:,:,,";

/// Whether the peers speak Jazzy or later (type hashes) or Humble (none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Distro {
    /// `RIHS01_<sha256>` in keys and tokens.
    #[default]
    Jazzy,
    /// `TypeHashNotSupported`.
    Humble,
}

impl Distro {
    /// The distro every ROS node on this machine speaks: `$ROS_DISTRO` (`humble`, and the
    /// older `galactic` and `foxy`, have Humble's wire; anything else, or unset, Jazzy's), with
    /// why.
    pub fn from_ros_distro(ros_distro: Option<&str>) -> (Self, String) {
        match ros_distro {
            Some(name @ ("humble" | "galactic" | "foxy")) => {
                (Distro::Humble, format!("ROS_DISTRO is {name}"))
            }
            Some(name) if !name.is_empty() => (
                Distro::Jazzy,
                format!("ROS_DISTRO is {name}: Iron and later share Jazzy's wire"),
            ),
            Some(_) | None => (
                Distro::Jazzy,
                "ROS_DISTRO is not set: Jazzy's wire (Iron and later)".into(),
            ),
        }
    }

    /// The name in settings and logs.
    pub fn name(self) -> &'static str {
        match self {
            Distro::Jazzy => "jazzy",
            Distro::Humble => "humble",
        }
    }

    pub fn hash(self, message: &MessageType) -> &'static str {
        match self {
            Distro::Jazzy => message.hash,
            Distro::Humble => "TypeHashNotSupported",
        }
    }
}

/// A topic name without its leading slash, as in data keys.
fn bare(topic: &str) -> &str {
    topic.trim_start_matches('/')
}

/// `/` replaced by `%`, and an empty name as `%`, as in liveliness tokens.
pub fn mangle(name: &str) -> String {
    if name.is_empty() {
        "%".into()
    } else {
        name.replace('/', "%")
    }
}

/// `<domain>/<topic>/<type>/<hash>`.
pub fn data_key(domain: u32, topic: &str, message: &MessageType, distro: Distro) -> String {
    format!(
        "{domain}/{}/{}/{}",
        bare(topic),
        message.dds_name,
        distro.hash(message)
    )
}

/// The node an entity belongs to.
#[derive(Debug, Clone)]
pub struct Node {
    pub domain: u32,
    /// The zenoh session id, as zenoh prints it.
    pub zid: String,
    pub id: u32,
    /// `/name` or empty.
    pub namespace: String,
    pub name: String,
    pub enclave: String,
}

/// What an entity is, as its token says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    Node,
    Publisher,
    Subscription,
    /// A service server.
    Service,
}

impl EntityKind {
    fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
            EntityKind::Service => "SS",
        }
    }
}

impl Node {
    fn prefix(&self, entity: u32, kind: EntityKind) -> String {
        format!(
            "@ros2_lv/{}/{}/{}/{entity}/{}/{}/{}/{}",
            self.domain,
            self.zid,
            self.id,
            kind.code(),
            mangle(&self.enclave),
            mangle(&self.namespace),
            mangle(&self.name),
        )
    }

    /// The node's own token (its entity id is the node id).
    pub fn token(&self) -> String {
        self.prefix(self.id, EntityKind::Node)
    }

    /// A publisher's or subscription's token.
    pub fn entity_token(
        &self,
        entity: u32,
        kind: EntityKind,
        topic: &str,
        message: &MessageType,
        distro: Distro,
    ) -> String {
        format!(
            "{}/{}/{}/{}/{DEFAULT_QOS}",
            self.prefix(entity, kind),
            mangle(topic),
            message.dds_name,
            distro.hash(message)
        )
    }
}

/// The attachment of one sample: sequence number (from 1), source time (ns since the Unix
/// epoch), and the publisher's 16-byte GID with its length as a varint: zenoh-ext's
/// serialization of `(i64, i64, [u8; 16])`, 33 bytes.
pub fn attachment(sequence: i64, source_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut bytes = [0u8; 33];
    bytes[..8].copy_from_slice(&sequence.to_le_bytes());
    bytes[8..16].copy_from_slice(&source_ns.to_le_bytes());
    bytes[16] = 16;
    bytes[17..].copy_from_slice(gid);
    bytes
}

/// The sequence number, source time and GID of an attachment, if it is one.
pub fn parse_attachment(bytes: &[u8]) -> Option<(i64, i64, [u8; 16])> {
    if bytes.len() != 33 || bytes[16] != 16 {
        return None;
    }
    Some((
        i64::from_le_bytes(bytes[..8].try_into().ok()?),
        i64::from_le_bytes(bytes[8..16].try_into().ok()?),
        bytes[17..].try_into().ok()?,
    ))
}

/// rmw_zenoh's GID of an entity: the XXH3-128 (seed 0) of its liveliness token, the low 64 bits
/// then the high 64, each in little-endian byte order (`liveliness_utils.cpp`, `Entity::gid`).
/// Receivers recompute it from the token, so `message_info.publisher_gid` and
/// `ros2 topic info -v` agree only when the attachment carries this value.
pub fn gid(token: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(token.as_bytes()).to_le_bytes()
}

/// The data key a subscription listens on: any type hash (`*`), so that publishers of every
/// distro reach it (Humble's `TypeHashNotSupported` and Jazzy's `RIHS01_...` are different keys).
pub fn subscription_key(domain: u32, topic: &str, message: &MessageType) -> String {
    format!("{domain}/{}/{}/*", bare(topic), message.dds_name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::{ODOMETRY, TWIST};

    #[test]
    fn the_issue_s_example_key() {
        assert_eq!(
            data_key(0, "/odom", &ODOMETRY, Distro::Jazzy),
            "0/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
        );
        assert_eq!(
            data_key(3, "/robot1/cmd_vel", &TWIST, Distro::Humble),
            "3/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported"
        );
    }

    #[test]
    fn tokens_mangle_slashes_and_empty_names() {
        let node = Node {
            domain: 0,
            zid: "1a2b".into(),
            id: 0,
            namespace: String::new(),
            name: "scout".into(),
            enclave: String::new(),
        };
        assert_eq!(node.token(), "@ros2_lv/0/1a2b/0/0/NN/%/%/scout");
        assert_eq!(
            node.entity_token(1, EntityKind::Publisher, "/odom", &ODOMETRY, Distro::Jazzy),
            format!(
                "@ros2_lv/0/1a2b/0/1/MP/%/%/scout/%odom/nav_msgs::msg::dds_::Odometry_/{}/::,10:,:,:,,",
                ODOMETRY.hash
            )
        );
    }

    #[test]
    fn gids_are_xxh3_128_of_the_token_low_half_first() {
        // XXH3-128 of the empty input is 0x99aa06d3014798d8_6001c324468d497f (xxHash's tests).
        assert_eq!(
            gid(""),
            [
                0x7f, 0x49, 0x8d, 0x46, 0x24, 0xc3, 0x01, 0x60, 0xd8, 0x98, 0x47, 0x01, 0xd3, 0x06,
                0xaa, 0x99
            ]
        );
        assert_ne!(gid("@ros2_lv/0/1a2b/0/1/MP"), gid("@ros2_lv/0/1a2b/0/2/MP"));
    }

    #[test]
    fn subscriptions_accept_every_distro_s_hash() {
        assert_eq!(
            subscription_key(3, "/robot1/cmd_vel", &TWIST),
            "3/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/*"
        );
    }

    #[test]
    fn the_attachment_is_33_bytes_and_reads_back() {
        let gid = gid("@ros2_lv/0/1a2b/0/1/MP");
        let bytes = attachment(7, 1_700_000_000_000_000_000, &gid);
        assert_eq!(bytes.len(), 33);
        assert_eq!(
            parse_attachment(&bytes),
            Some((7, 1_700_000_000_000_000_000, gid))
        );
        assert_ne!(gid, super::gid("@ros2_lv/0/1a2b/0/2/MP"));
        assert_eq!(parse_attachment(&bytes[..32]), None);
    }
}
