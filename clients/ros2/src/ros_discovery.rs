//! `ros_discovery_info`: how a ROS 2 node over DDS tells the graph which DDS readers and writers
//! are its own (rmw_dds_common's `ParticipantEntitiesInfo`), with the GID length of the
//! distro: 24 bytes for Humble, 16 from Iron on (Jazzy, Kilted). `ros2 node list` and `ros2 node
//! info` read it; topics and services flow without it. Sans-IO: GUIDs in, CDR out.

use crate::cdr::Writer;
use crate::rmw::Distro;

/// The DDS topic.
pub const TOPIC: &str = "ros_discovery_info";

/// The DDS type.
pub const TYPE: &str = "rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_";

/// A DDS entity's GUID: its participant's 12-byte prefix, then its 4-byte entity id.
pub type Guid = [u8; 16];

/// How many bytes a GID has on `distro`'s wire (rmw_dds_common/msg/Gid: `char[24]` up to
/// Humble, `char[16]` from Iron on).
pub const fn gid_length(distro: Distro) -> usize {
    match distro {
        Distro::Humble => 24,
        Distro::Jazzy => 16,
    }
}

/// One node's entry: its names and its endpoints.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeEntities {
    /// `/` or `/robot1`.
    pub namespace: String,
    /// `scout`.
    pub name: String,
    /// Its readers' GUIDs.
    pub readers: Vec<Guid>,
    /// Its writers' GUIDs.
    pub writers: Vec<Guid>,
}

impl NodeEntities {
    /// Replaces writer `old` by `new` (a writer made anew), keeping its place.
    pub fn replace_writer(&mut self, old: Guid, new: Guid) {
        match self.writers.iter_mut().find(|writer| **writer == old) {
            Some(writer) => *writer = new,
            None => self.writers.push(new),
        }
    }
}

fn gid(writer: &mut Writer, guid: Guid, distro: Distro) {
    for byte in guid {
        writer.u8(byte);
    }
    for _ in guid.len()..gid_length(distro) {
        writer.u8(0);
    }
}

/// The message of participant `participant` with `nodes` (none: the participant is leaving),
/// as CDR with its encapsulation header.
pub fn encode(participant: Guid, nodes: &[NodeEntities], distro: Distro) -> Vec<u8> {
    let mut writer = Writer::new();
    gid(&mut writer, participant, distro);
    writer.sequence(nodes.len());
    for node in nodes {
        writer.string(&node.namespace).string(&node.name);
        writer.sequence(node.readers.len());
        for reader in &node.readers {
            gid(&mut writer, *reader, distro);
        }
        writer.sequence(node.writers.len());
        for written in &node.writers {
            gid(&mut writer, *written, distro);
        }
    }
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(text: &str) -> Vec<u8> {
        (0..text.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&text[i..i + 2], 16).expect("hex"))
            .collect()
    }

    fn guid(entity: [u8; 4]) -> Guid {
        let mut guid = [0; 16];
        guid[..12].copy_from_slice(&[1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
        guid[12..].copy_from_slice(&entity);
        guid
    }

    fn example() -> (Guid, Vec<NodeEntities>) {
        let node = NodeEntities {
            namespace: "/robot1".into(),
            name: "scout".into(),
            readers: vec![guid([0, 0, 0x12, 0x04])],
            writers: vec![guid([0, 0, 0x13, 0x03]), guid([0, 0, 0x14, 0x02])],
        };
        (guid([0, 0, 1, 0xC1]), vec![node])
    }

    /// Golden bytes from rosbags 0.11 (`serialize_cdr` of the same message with its Humble and
    /// its Jazzy type store).
    #[test]
    fn both_layouts_match_rosbags_byte_for_byte() {
        let (participant, nodes) = example();
        assert_eq!(
            encode(participant, &nodes, Distro::Humble),
            hex(
                "000100000102030405060708090a0b0c000001c1000000000000000001000000080000002f726f626f74\
                 31000600000073636f7574000000010000000102030405060708090a0b0c00001204000000000000\
                 0000020000000102030405060708090a0b0c0000130300000000000000000102030405060708090a\
                 0b0c000014020000000000000000"
            )
        );
        assert_eq!(
            encode(participant, &nodes, Distro::Jazzy),
            hex(
                "000100000102030405060708090a0b0c000001c101000000080000002f726f626f7431000600000073\
                 636f7574000000010000000102030405060708090a0b0c00001204020000000102030405060708090a\
                 0b0c000013030102030405060708090a0b0c00001402"
            )
        );
        assert_eq!(
            encode(participant, &[], Distro::Humble),
            hex("000100000102030405060708090a0b0c000001c1000000000000000000000000")
        );
        assert_eq!(
            encode(participant, &[], Distro::Jazzy),
            hex("000100000102030405060708090a0b0c000001c100000000")
        );
    }

    #[test]
    fn a_writer_made_anew_takes_the_old_ones_place() {
        let (_, mut nodes) = example();
        let node = &mut nodes[0];
        node.replace_writer(guid([0, 0, 0x13, 0x03]), guid([0, 0, 0x20, 0x03]));
        assert_eq!(
            node.writers,
            [guid([0, 0, 0x20, 0x03]), guid([0, 0, 0x14, 0x02])]
        );
    }
}
