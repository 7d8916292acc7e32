"""A safety monitor: latches a stop owned by `battery-monitor` when the battery runs low (or the
state stops coming). It never releases: an operator does (`scout release`).

    python battery_monitor.py --name scout --below 23.0
"""

from __future__ import annotations

import argparse
import sys

import scout


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--name", default="scout", help="the robot (gateway) name")
    parser.add_argument("--below", type=float, default=23.0, help="the lowest voltage, V")
    parser.add_argument("--silence", type=float, default=1.0, help="the longest gap, s")
    args = parser.parse_args()
    try:
        robot = scout.Robot.connect(args.name)
    except scout.ScoutError as error:
        print(f"battery-monitor: {error}", file=sys.stderr)
        return 3
    # Made ahead of time: a stop then costs one datagram each way.
    stopper = robot.stopper("battery-monitor")
    try:
        while True:
            try:
                state = robot.next(timeout=args.silence)
            except TimeoutError:
                stopper.stop(f"no state for {args.silence} s")
                print("battery-monitor: the state stopped coming; stop latched", file=sys.stderr)
                return 1
            if state.system is not None and state.system.battery_voltage < args.below:
                voltage = state.system.battery_voltage
                stopper.stop(f"battery {voltage:.1f} V < {args.below:.1f} V")
                print(f"battery-monitor: battery {voltage:.1f} V; stop latched", file=sys.stderr)
                return 1
    except KeyboardInterrupt:
        return 0


if __name__ == "__main__":
    sys.exit(main())
