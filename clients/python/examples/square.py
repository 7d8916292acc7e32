"""Drives a square (four sides and four quarter turns) as autonomy, then gives up control.

Arms autonomy first (a deliberate act); any stop, teleop takeover or release ends the drive
with the reason and the robot stays where it is: nothing here takes control back.

    python square.py --name scout --side 1.0
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import scout

PERIOD = 0.05  # s between commands (the gateway stops a silent client)


def drive_for(controller: scout.Controller, linear: float, angular: float, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        controller.drive(linear, angular)
        time.sleep(PERIOD)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--name", default="scout", help="the robot (gateway) name")
    parser.add_argument("--side", type=float, default=1.0, help="side length, m")
    parser.add_argument("--speed", type=float, default=0.3, help="linear speed, m/s")
    parser.add_argument("--turn-rate", type=float, default=0.5, help="turning speed, rad/s")
    args = parser.parse_args()
    try:
        robot = scout.Robot.connect(args.name)
        with robot.controller("square", scout.Class.AUTONOMY) as controller:
            controller.resume()
            controller.take_control()
            for side in range(4):
                drive_for(controller, args.speed, 0.0, args.side / args.speed)
                drive_for(controller, 0.0, args.turn_rate, (math.pi / 2) / args.turn_rate)
                state = robot.latest()
                if state is not None:
                    print(f"side {side + 1}: x={state.odometry.x:+.2f} y={state.odometry.y:+.2f}")
    except scout.Rejected as refused:
        print(f"square: {refused} ({refused.cause})", file=sys.stderr)
        return 4
    except scout.ScoutError as error:
        print(f"square: {error}", file=sys.stderr)
        return 3
    return 0


if __name__ == "__main__":
    sys.exit(main())
