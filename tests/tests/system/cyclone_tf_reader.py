#!/usr/bin/env python3
"""A plain Cyclone DDS reader of ROS 2's /tf (no ROS: `cyclonedds` from PyPI), for the system
tests of `scout ros2` over DDS. Run only inside a private network namespace.

    cyclone_tf_reader.py COUNT

reads COUNT tf2_msgs/TFMessage samples from DDS topic `rt/tf` in domain $ROS_DOMAIN_ID and
prints one JSON object: the transforms of the last sample, or an error.
"""

import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Qos, Policy
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, sequence, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
    x: float64
    y: float64
    z: float64


@dataclass
class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
    x: float64
    y: float64
    z: float64
    w: float64


@dataclass
class Transform(IdlStruct, typename="geometry_msgs::msg::dds_::Transform_"):
    translation: Vector3
    rotation: Quaternion


@dataclass
class TransformStamped(IdlStruct, typename="geometry_msgs::msg::dds_::TransformStamped_"):
    header: Header
    child_frame_id: str
    transform: Transform


@dataclass
class TFMessage(IdlStruct, typename="tf2_msgs::msg::dds_::TFMessage_"):
    transforms: sequence[TransformStamped]


def main():
    count = int(sys.argv[1])
    participant = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    topic = Topic(participant, "rt/tf", TFMessage)
    # As tf2's listener asks: reliable, volatile, keep last 100.
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(100))
    reader = DataReader(participant, topic, qos=qos)
    got = []
    deadline = time.monotonic() + 20
    while len(got) < count and time.monotonic() < deadline:
        got.extend(reader.take(N=count - len(got)))
        time.sleep(0.01)
    if len(got) < count:
        print(json.dumps({"error": f"{len(got)} of {count} samples within 20 s"}), flush=True)
        return
    last = got[-1]
    print(
        json.dumps(
            {
                "samples": len(got),
                "transforms": [
                    {
                        "parent": t.header.frame_id,
                        "child": t.child_frame_id,
                        "x": t.transform.translation.x,
                        "w": t.transform.rotation.w,
                        "stamp": t.header.stamp.sec + t.header.stamp.nanosec * 1e-9,
                    }
                    for t in last.transforms
                ],
            }
        ),
        flush=True,
    )


if __name__ == "__main__":
    main()
