#!/usr/bin/env python3
"""scout-bench's rclpy subscriber (run inside the bench's network namespace): records when each
/odom arrived in its callback, CLOCK_BOOTTIME ns, one line each, for SECONDS after the first
(saying `receiving` on standard output when the first came).

    ros2_odom_subscriber.py OUT SECONDS
"""

import sys
import time

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from nav_msgs.msg import Odometry


def main():
    out, seconds = sys.argv[1], float(sys.argv[2])
    rclpy.init()
    node = Node("bench_odom")
    seen = []
    node.create_subscription(Odometry, "/odom", lambda _m: seen.append(time.clock_gettime_ns(time.CLOCK_BOOTTIME)), QoSProfile(depth=10))
    deadline = time.monotonic() + 30
    while not seen and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    # The bench measures the bridge's cost from here.
    print("receiving" if seen else "nothing", flush=True)
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        rclpy.spin_once(node, timeout_sec=0.1)
    with open(out, "w") as file:
        file.writelines(f"{t}\n" for t in seen)
    node.destroy_node()
    rclpy.shutdown()
    if not seen:
        sys.exit("no /odom within 30 s")


if __name__ == "__main__":
    main()
