"""Reads a `scout record --ros2` bag with two independent readers and prints a JSON report.

Usage: ros2_bag_check.py BAG_DIR

rosbags opens the bag through its metadata.yaml and reads every message, which is then
deserialized by rosbags' own ROS 2 Humble and Jazzy type stores (not by the definitions the bag
carries); mcap-ros2-support decodes every message of the MCAP file with the definitions the file
itself carries (its `ros2msg` schemas). So the bytes match the real types, and the definitions
match the bytes. The report, per topic: the type, the counts each decoded and the metadata's,
and what the test checks (the largest odometry x, the largest commanded speed, the battery's
voltage and percentage, the wheels' names, the diagnostics' names).
"""

import json
import math
import sys
from pathlib import Path

from mcap_ros2.reader import read_ros2_messages
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore
from ruamel.yaml import YAML  # rosbags' own YAML reader

bag = Path(sys.argv[1])
metadata = YAML(typ="safe").load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
report = {"metadata_version": metadata["version"], "storage": metadata["storage_identifier"], "topics": {}}
for entry in metadata["topics_with_message_count"]:
    meta = entry["topic_metadata"]
    report["topics"][meta["name"]] = {"type": meta["type"], "metadata_count": entry["message_count"],
                                      "rosbags_count": 0, "mcap_ros2_count": 0}


def finite_or_none(value):
    return value if math.isfinite(value) else None


humble, jazzy = get_typestore(Stores.ROS2_HUMBLE), get_typestore(Stores.ROS2_JAZZY)
with AnyReader([bag]) as reader:
    for connection, _, raw in reader.messages():
        humble.deserialize_cdr(raw, connection.msgtype)
        message = jazzy.deserialize_cdr(raw, connection.msgtype)
        topic = report["topics"][connection.topic]
        topic["rosbags_count"] += 1
        if connection.msgtype == "nav_msgs/msg/Odometry":
            topic["max_x"] = max(topic.get("max_x", -1e9), message.pose.pose.position.x)
            topic["frame_id"] = message.header.frame_id
            topic["child_frame_id"] = message.child_frame_id
            topic["yaw_variance"] = message.pose.covariance[35]
        elif connection.msgtype == "geometry_msgs/msg/Twist":
            topic["max_linear"] = max(topic.get("max_linear", -1e9), message.linear.x)
        elif connection.msgtype == "sensor_msgs/msg/BatteryState":
            topic["voltage"] = message.voltage
            topic["percentage"] = finite_or_none(message.percentage)
            topic["present"] = message.present
        elif connection.msgtype == "sensor_msgs/msg/JointState":
            topic["names"] = list(message.name)
        elif connection.msgtype == "diagnostic_msgs/msg/DiagnosticArray":
            topic["names"] = sorted({status.name for status in message.status})
        elif connection.msgtype == "tf2_msgs/msg/TFMessage":
            topic["frames"] = [message.transforms[0].header.frame_id, message.transforms[0].child_frame_id]

files = sorted(bag.glob("*.mcap"))
report["files"] = [file.name for file in files]
for file in files:
    for message in read_ros2_messages(str(file)):
        report["topics"][message.channel.topic]["mcap_ros2_count"] += 1
print(json.dumps(report))
