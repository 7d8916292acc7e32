#!/usr/bin/env python3
"""scout-bench's Python subscriber (the `scout` package): records, for each state `next()`
returns, when it was seen (with its `motion` read) and when the gateway published it (CLOCK_BOOTTIME ns, one line
each), for SECONDS after the first (saying `receiving` on standard output when it came), then
its CPU (every thread, user + system) over that window and its resident memory, as a JSON line.

    python_state_subscriber.py ROBOT OUT SECONDS
"""

import json
import resource
import sys
import time

import scout


def main() -> None:
    name, out, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
    robot = scout.Robot.connect(name)
    robot.next(timeout=5.0)
    robot.latest()  # from the newest on
    print("receiving", flush=True)
    rows = []
    usage = resource.getrusage(resource.RUSAGE_SELF)
    started = time.monotonic()
    end = started + seconds
    while time.monotonic() < end:
        state = robot.next(timeout=1.0)
        # Seen once a field is in hand, as a controller would use it (sections are made when
        # first read).
        motion = state.motion
        seen = time.clock_gettime_ns(time.CLOCK_BOOTTIME)
        assert motion is not None
        rows.append((seen, state.published_ns))
    elapsed = time.monotonic() - started
    after = resource.getrusage(resource.RUSAGE_SELF)
    cpu = (after.ru_utime - usage.ru_utime) + (after.ru_stime - usage.ru_stime)
    with open("/proc/self/status") as status:
        rss_kb = next(int(line.split()[1]) for line in status if line.startswith("VmRSS:"))
    print(json.dumps({"cpu_percent": cpu / elapsed * 100.0, "rss_mb": rss_kb / 1024.0}), flush=True)
    with open(out, "w") as file:
        file.writelines(f"{seen} {published}\n" for seen, published in rows)


if __name__ == "__main__":
    main()
