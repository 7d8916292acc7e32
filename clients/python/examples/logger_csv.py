"""Logs every chassis state to a CSV file (or standard output) until Ctrl-C.

    python logger_csv.py --name scout --output run.csv
"""

from __future__ import annotations

import argparse
import csv
import sys
from typing import IO

import scout

COLUMNS = [
    "seq", "published_ns", "link", "battery_voltage", "faults",
    "linear", "angular", "command_linear", "command_angular", "x", "y", "yaw",
]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--name", default="scout", help="the robot (gateway) name")
    parser.add_argument("--output", help="the CSV file (default: standard output)")
    parser.add_argument("--count", type=int, help="stop after this many states")
    args = parser.parse_args()
    try:
        robot = scout.Robot.connect(args.name)
    except scout.ScoutError as error:
        print(f"logger: {error}", file=sys.stderr)
        return 3
    out: IO[str] = open(args.output, "w", newline="") if args.output else sys.stdout
    writer = csv.writer(out)
    writer.writerow(COLUMNS)
    written = 0
    try:
        for state in robot.states(timeout=3.0):
            system, motion = state.system, state.motion
            writer.writerow([
                state.seq, state.published_ns, state.link.state,
                "" if system is None else system.battery_voltage,
                "" if system is None else "|".join(system.faults),
                "" if motion is None else motion.linear,
                "" if motion is None else motion.angular,
                state.command.linear, state.command.angular,
                state.odometry.x, state.odometry.y, state.odometry.yaw,
            ])
            written += 1
            if args.count is not None and written >= args.count:
                break
    except KeyboardInterrupt:
        pass
    except TimeoutError as error:
        print(f"logger: {error}", file=sys.stderr)
        return 3
    finally:
        out.flush()
        if out is not sys.stdout:
            out.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
