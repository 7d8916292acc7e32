"""Drives a robot from another machine through zenoh, with nothing but `eclipse-zenoh`.

The JSON command protocol of docs/remote.md, as any language would speak it: take control (a
query, answered), then a drive every 20 ms put on the fast lane (best effort, express, dropped
rather than queued: a lost drive is replaced by the next), one in ten as a query whose answer
says whether control still holds. The puts go on a session of their own (a connection that
carries nothing else: over QUIC, queries retransmitted after a loss would hold them back). When an answer says control ended (a stop, a gap, a release,
a takeover) it exits 4 and never takes control back by itself. At the end (or Ctrl-C) it puts a
zero drive and gives control back.

The gateway needs `--remote-commands estop,teleop` and a `--zenoh-listen` on a link that
authenticates peers. Through the WireGuard recipe of docs/remote.md (plain UDP in the tunnel,
user and password in the operator's zenoh configuration):

    python remote_drive.py --connect udp/10.8.0.1:7448 --config alice.json5 --name scout \
        --peer alice --linear 0.3

Exit codes: 0 done, 3 no answer from the gateway, 4 refused (the reason is printed).
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time

import zenoh

PERIOD = 0.02  # s between drives
LIFE_MS = 300  # a drive's life: after a partition the robot stops from there
ANSWERED_EVERY = 10  # one drive in this many is a query, to learn whether control holds
TIMEOUT = 5.0  # s to wait for an answer


def now_ms() -> int:
    """This host's clock for `sent_ms` (any epoch: the gateway learns the offset)."""
    return time.monotonic_ns() // 1_000_000


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="the gateway's zenoh endpoint")
    parser.add_argument(
        "--config", help="a zenoh configuration file (the user and password, TLS certificates)"
    )
    parser.add_argument("--name", default="scout", help="the robot (gateway) name")
    parser.add_argument("--peer", default="operator", help="this peer's name in the keys")
    parser.add_argument("--linear", type=float, default=0.0, help="m/s")
    parser.add_argument("--angular", type=float, default=0.0, help="rad/s")
    parser.add_argument("--duration", type=float, default=None, help="s (default: until Ctrl-C)")
    args = parser.parse_args()

    config = zenoh.Config.from_file(args.config) if args.config else zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([args.connect]))
    config.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(config) as session, zenoh.open(config) as drives:

        def key(kind: str) -> str:
            return f"scout/{args.name}/cmd/{kind}/{args.peer}"

        def ask(kind: str, command: dict) -> dict | None:
            """A command as a query: the gateway's answer, or None without one."""
            for reply in session.get(key(kind), payload=json.dumps(command), timeout=TIMEOUT):
                if reply.ok is not None:
                    return json.loads(reply.ok.payload.to_string())
                return {"accepted": False, "reason": reply.err.payload.to_string()}
            return None

        answer = ask("take-control", {"class": "teleop", "sent_ms": now_ms()})
        if answer is None:
            print(f"no answer from robot {args.name} at {args.connect}", file=sys.stderr)
            return 3
        if not answer["accepted"]:
            print(f"take-control refused: {answer.get('reason')}", file=sys.stderr)
            return 4
        print(f"control taken as remote:{args.peer}")

        def put_drive(drive: str) -> None:
            # Put with the key in full, not through a declared publisher: a publisher's key is
            # declared once and then sent as a number, and over a lossy link that declaration
            # can be lost or overtaken, after which the gateway drops the puts. (Python's
            # session.put has no reliability option: over `udp/` everything is best effort.)
            drives.put(
                key("drive"),
                drive,
                encoding=zenoh.Encoding.APPLICATION_JSON,
                congestion_control=zenoh.CongestionControl.DROP,
                priority=zenoh.Priority.REAL_TIME,
                express=True,
            )

        ended = threading.Event()
        reason: list[str] = []

        def on_answer(reply: zenoh.Reply) -> None:
            if reply.ok is None:
                return
            answer = json.loads(reply.ok.payload.to_string())
            if answer.get("lost_control"):
                reason.append(answer.get("reason", "control ended"))
                ended.set()

        seq = 0
        start = time.monotonic()
        next_send = start
        try:
            while not ended.is_set() and (
                args.duration is None or time.monotonic() - start < args.duration
            ):
                seq += 1
                drive = json.dumps(
                    {
                        "seq": seq,
                        "sent_ms": now_ms(),
                        "linear": args.linear,
                        "angular": args.angular,
                        "ttl_ms": LIFE_MS,
                    }
                )
                if seq % ANSWERED_EVERY == 1:
                    session.get(key("drive"), payload=drive, handler=on_answer, timeout=TIMEOUT)
                else:
                    put_drive(drive)
                next_send += PERIOD
                time.sleep(max(0.0, next_send - time.monotonic()))
        except KeyboardInterrupt:
            pass
        if ended.is_set():
            print(f"control ended: {reason[0]}", file=sys.stderr)
            return 4
        seq += 1
        stop = {"seq": seq, "sent_ms": now_ms(), "linear": 0.0, "angular": 0.0}
        put_drive(json.dumps(stop))
        answer = ask("relinquish", {})
        if answer is None or not answer["accepted"]:
            print(f"giving up control: {answer}", file=sys.stderr)
            return 3 if answer is None else 4
        print("control given back")
        return 0


if __name__ == "__main__":
    sys.exit(main())
