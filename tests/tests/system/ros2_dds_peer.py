#!/usr/bin/env python3
"""A real ROS 2 node (rclpy from PyPI, on Fast DDS) for the system tests of `scout ros2` over DDS.

Run only inside a private network namespace (the tests make one): DDS discovers peers by
multicast on every interface. It takes one JSON command per line on standard input and answers
each with one JSON line on standard output:

  {"cmd": "graph"}
      the nodes, topics with their types and services the ROS graph shows
  {"cmd": "echo", "topic": "/odom", "type": "nav_msgs/msg/Odometry", "count": 5,
   "qos": "default" | "sensor_data"}
      that many messages, deserialized by rclpy, summarised
  {"cmd": "publish", "topic": "/cmd_vel", "stamped": false, "linear": 0.5, "angular": 0.0,
   "rate": 20}
      starts publishing a Twist (or TwistStamped) at that rate, until "quiet"; with
      "wrong_type": true a TwistWithCovariance on the same topic (a misconfigured node)
  {"cmd": "quiet"}
      stops publishing
  {"cmd": "call", "service": "/scout/estop"}
      calls a std_srvs/srv/Trigger service, answers its response
"""

import json
import sys
import threading
import time

import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist, TwistStamped, TwistWithCovariance
from nav_msgs.msg import Odometry
from sensor_msgs.msg import BatteryState, JointState
from std_srvs.srv import Trigger

TYPES = {
    "nav_msgs/msg/Odometry": Odometry,
    "sensor_msgs/msg/BatteryState": BatteryState,
    "sensor_msgs/msg/JointState": JointState,
    "diagnostic_msgs/msg/DiagnosticArray": DiagnosticArray,
}


def stamp(header):
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def summary(message):
    if isinstance(message, Odometry):
        return {
            "frame_id": message.header.frame_id,
            "child_frame_id": message.child_frame_id,
            "stamp": stamp(message.header),
            "x": message.pose.pose.position.x,
            "linear": message.twist.twist.linear.x,
            "angular": message.twist.twist.angular.z,
        }
    if isinstance(message, BatteryState):
        return {"voltage": message.voltage, "percentage": message.percentage,
                "power_supply_status": message.power_supply_status,
                "design_capacity": message.design_capacity, "stamp": stamp(message.header)}
    if isinstance(message, JointState):
        return {
            "name": list(message.name),
            "position": list(message.position),
            "velocity": list(message.velocity),
        }
    if isinstance(message, DiagnosticArray):
        return {
            "status": [
                {
                    "name": status.name,
                    "level": int.from_bytes(status.level, "little")
                    if isinstance(status.level, bytes)
                    else int(status.level),
                    "message": status.message,
                    "values": {kv.key: kv.value for kv in status.values},
                }
                for status in message.status
            ]
        }
    return {"repr": repr(message)}


class Peer:
    def __init__(self):
        self.node = Node("dds_peer")
        self.executor = MultiThreadedExecutor()
        self.executor.add_node(self.node)
        self.spinner = threading.Thread(target=self.spin, daemon=True)
        self.spinner.start()
        self.publisher = None
        self.timer = None

    def spin(self):
        """Runs the executor for good. The main thread destroys subscriptions, publishers and
        clients while this one waits on them, and rclpy's executor then raises InvalidHandle
        ("destruction was requested") out of its wait. `executor.spin()` ended on it, and no
        callback ran again: every later echo got no sample and every call no response, which
        CI saw as /diagnostics and /scout/release flakes. That wait is simply made again."""
        while rclpy.ok():
            try:
                self.executor.spin_once(timeout_sec=0.1)
            except Exception as error:  # the pybind11 class is not importable by a stable name
                if type(error).__name__ != "InvalidHandle":
                    raise

    def graph(self, _command):
        node = self.node
        return {
            "nodes": [
                (namespace.rstrip("/") + "/" + name)
                for name, namespace in node.get_node_names_and_namespaces()
            ],
            "topics": {name: types for name, types in node.get_topic_names_and_types()},
            "services": {name: types for name, types in node.get_service_names_and_types()},
            "scout_publishers": {
                name: types
                for name, types in node.get_publisher_names_and_types_by_node("scout", "/")
            }
            if ("scout", "/") in node.get_node_names_and_namespaces()
            else {},
        }

    def echo(self, command):
        message_type = TYPES[command["type"]]
        count = command["count"]
        qos = qos_profile_sensor_data if command.get("qos") == "sensor_data" else QoSProfile(depth=10)
        got = []
        done = threading.Event()

        def on_message(message):
            if len(got) < count:
                got.append((time.monotonic(), summary(message)))
            if len(got) >= count:
                done.set()

        subscription = self.node.create_subscription(message_type, command["topic"], on_message, qos)
        done.wait(timeout=20)
        self.node.destroy_subscription(subscription)
        times = [t for t, _ in got]
        return {
            "samples": [s for _, s in got],
            "rate_hz": (len(times) - 1) / (times[-1] - times[0]) if len(times) > 2 else None,
        }

    def publish(self, command):
        self.quiet(None)
        stamped = command.get("stamped", False)
        wrong_type = command.get("wrong_type", False)
        message_type = TwistWithCovariance if wrong_type else TwistStamped if stamped else Twist
        self.publisher = self.node.create_publisher(message_type, command.get("topic", "/cmd_vel"), 10)
        linear, angular = command["linear"], command["angular"]

        def tick():
            message = message_type()
            twist = message.twist if stamped or wrong_type else message
            twist.linear.x = float(linear)
            twist.angular.z = float(angular)
            if stamped and not wrong_type:
                message.header.stamp = self.node.get_clock().now().to_msg()
                message.header.frame_id = "base_link"
            self.publisher.publish(message)

        self.timer = self.node.create_timer(1.0 / command.get("rate", 20), tick)
        return {"publishing": True}

    def quiet(self, _command):
        if self.timer is not None:
            self.node.destroy_timer(self.timer)
            self.timer = None
        if self.publisher is not None:
            self.node.destroy_publisher(self.publisher)
            self.publisher = None
        return {"quiet": True}

    def call(self, command):
        client = self.node.create_client(Trigger, command["service"])
        try:
            if not client.wait_for_service(timeout_sec=20):
                return {"error": "the service never appeared"}
            future = client.call_async(Trigger.Request())
            deadline = time.monotonic() + 20
            while not future.done() and time.monotonic() < deadline:
                time.sleep(0.01)
            if not future.done():
                return {"error": "no response within 20 s"}
            response = future.result()
            return {"success": response.success, "message": response.message}
        finally:
            self.node.destroy_client(client)


def main():
    rclpy.init()
    peer = Peer()
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        command = json.loads(line)
        try:
            answer = getattr(peer, command["cmd"])(command)
        except Exception as error:  # the test shows it
            answer = {"error": f"{type(error).__name__}: {error}"}
        print(json.dumps(answer), flush=True)
    peer.quiet(None)
    peer.executor.shutdown()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
