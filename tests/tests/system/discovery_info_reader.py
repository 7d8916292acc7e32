#!/usr/bin/env python3
"""What a ROS 2 graph of a given distro reads of the nodes on DDS: a plain Cyclone DDS reader
(no ROS: `cyclonedds` from PyPI) of `ros_discovery_info` with that distro's GID length (24
bytes for Humble, 16 from Iron on), and of the DDS publications (their GUIDs), for the system
tests of `scout ros2`. Run only inside a private network namespace.

    discovery_info_reader.py GID_LENGTH NODE

waits for the entry of node NODE and prints one JSON object: the participant's GID, the node's
reader and writer GIDs (hex), and each DDS publication's topic and GUID (hex); or an error.
"""

import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication
from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, sequence, uint8
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


def types(length):
    @dataclass
    class Gid(IdlStruct, typename="rmw_dds_common::msg::dds_::Gid_"):
        data: array[uint8, length]

    @dataclass
    class NodeEntitiesInfo(IdlStruct, typename="rmw_dds_common::msg::dds_::NodeEntitiesInfo_"):
        node_namespace: str
        node_name: str
        reader_gid_seq: sequence[Gid]
        writer_gid_seq: sequence[Gid]

    @dataclass
    class ParticipantEntitiesInfo(
        IdlStruct, typename="rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_"
    ):
        gid: Gid
        node_entities_info_seq: sequence[NodeEntitiesInfo]

    return ParticipantEntitiesInfo


def hexed(gid):
    return bytes(gid.data).hex()


def main():
    length, node = int(sys.argv[1]), sys.argv[2]
    participant = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    # rmw_dds_common's QoS: reliable, transient local, keep last 1.
    qos = Qos(
        Policy.Reliability.Reliable(duration(seconds=1)),
        Policy.Durability.TransientLocal,
        Policy.History.KeepLast(1),
    )
    info = DataReader(participant, Topic(participant, "ros_discovery_info", types(length)), qos=qos)
    publications = BuiltinDataReader(participant, BuiltinTopicDcpsPublication)
    deadline = time.monotonic() + 20
    entry, gid, topics = None, None, {}
    while time.monotonic() < deadline and (entry is None or not topics.get("rt/odom")):
        try:
            samples = info.take(N=10)
        except Exception as error:  # a sample of another layout does not deserialize
            print(json.dumps({"error": f"reading ros_discovery_info: {error}"}), flush=True)
            return
        for sample in samples:
            for found in sample.node_entities_info_seq:
                if found.node_name == node:
                    entry, gid = found, sample.gid
        for publication in publications.take(N=100):
            topics.setdefault(publication.topic_name, []).append(publication.key.bytes.hex())
        time.sleep(0.05)
    if entry is None:
        print(json.dumps({"error": f"no entry of node {node} within 20 s"}), flush=True)
        return
    print(
        json.dumps(
            {
                "participant": hexed(gid),
                "namespace": entry.node_namespace,
                "readers": [hexed(r) for r in entry.reader_gid_seq],
                "writers": [hexed(w) for w in entry.writer_gid_seq],
                "publications": topics,
            }
        ),
        flush=True,
    )


if __name__ == "__main__":
    main()
