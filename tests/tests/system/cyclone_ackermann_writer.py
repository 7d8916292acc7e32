#!/usr/bin/env python3
"""A plain Cyclone DDS writer of ackermann_msgs/AckermannDriveStamped (no ROS: `cyclonedds` from
PyPI, whose ROS wheels carry no ackermann_msgs), for the system tests of `scout ros2` over DDS.
Run only inside a private network namespace.

    cyclone_ackermann_writer.py TOPIC SPEED STEERING_ANGLE SECONDS

publishes on DDS topic `rt/TOPIC` in domain $ROS_DOMAIN_ID, as rmw does (the ROS type's DDS
name, reliable), once the bridge's reader matched, at 20 Hz for SECONDS, and prints one JSON
object: how many it wrote, or an error.
"""

import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float32
from cyclonedds.pub import DataWriter
from cyclonedds.topic import Topic
from cyclonedds.util import duration

# The ROS types both scripts declare (this folder is on the path of a script run from it).
from cyclone_tf_reader import Header, Time


@dataclass
class AckermannDrive(IdlStruct, typename="ackermann_msgs::msg::dds_::AckermannDrive_"):
    steering_angle: float32
    steering_angle_velocity: float32
    speed: float32
    acceleration: float32
    jerk: float32


@dataclass
class AckermannDriveStamped(
    IdlStruct, typename="ackermann_msgs::msg::dds_::AckermannDriveStamped_"
):
    header: Header
    drive: AckermannDrive


def main():
    topic_name, speed, angle, seconds = sys.argv[1], *map(float, sys.argv[2:5])
    participant = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
    topic = Topic(participant, f"rt/{topic_name.lstrip('/')}", AckermannDriveStamped)
    writer = DataWriter(participant, topic, qos=qos)
    deadline = time.monotonic() + 20
    while not writer.get_matched_subscriptions():
        if time.monotonic() > deadline:
            print(json.dumps({"error": "the bridge's reader never matched"}))
            return
        time.sleep(0.05)
    sent = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        now = time.time()
        writer.write(AckermannDriveStamped(
            header=Header(stamp=Time(sec=int(now), nanosec=int(now % 1 * 1e9)), frame_id="base_link"),
            drive=AckermannDrive(steering_angle=angle, steering_angle_velocity=0.0, speed=speed,
                                 acceleration=0.0, jerk=0.0)))
        sent += 1
        time.sleep(0.05)
    print(json.dumps({"sent": sent}))


if __name__ == "__main__":
    main()
