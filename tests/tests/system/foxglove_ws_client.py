"""A Foxglove WebSocket client (protocol foxglove.websocket.v1) for the tests, with `websockets`.

Usage: foxglove_ws_client.py URL SECONDS [--call SERVICE JSON]...

Connects, reads serverInfo and the advertisements, subscribes to every channel, and counts and
decodes (JSON channels) what arrives for SECONDS; then calls each service given (the request as
JSON) and waits for its answer, and reads a little longer for the status messages that follow.
Prints one JSON report.
"""

import json
import struct
import sys
import time

from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.websocket.v1"
MESSAGE_DATA = 0x01
SERVICE_CALL_REQUEST = 0x02
SERVICE_CALL_RESPONSE = 0x03


def main():
    url, seconds = sys.argv[1], float(sys.argv[2])
    calls = []
    args = sys.argv[3:]
    while args:
        if args[0] != "--call" or len(args) < 3:
            sys.exit(f"bad arguments: {args}")
        calls.append((args[1], args[2]))
        args = args[3:]

    report = {
        "subprotocol": None,
        "server_info": None,
        "channels": {},
        "services": {},
        "messages": {},
        "first": {},
        "last": {},
        "statuses": [],
        "removed_statuses": [],
        "responses": {},
        "failures": {},
    }
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=10) as ws:
        report["subprotocol"] = ws.subprotocol
        subscriptions = {}

        def handle(frame):
            if isinstance(frame, str):
                message = json.loads(frame)
                op = message.get("op")
                if op == "serverInfo":
                    report["server_info"] = message
                elif op == "advertise":
                    new = []
                    for channel in message["channels"]:
                        report["channels"][channel["topic"]] = channel
                        sub_id = len(subscriptions) + 1
                        subscriptions[sub_id] = channel
                        new.append({"id": sub_id, "channelId": channel["id"]})
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                elif op == "advertiseServices":
                    for service in message["services"]:
                        report["services"][service["name"]] = service
                elif op == "status":
                    report["statuses"].append(message)
                elif op == "removeStatus":
                    report["removed_statuses"].extend(message.get("statusIds", []))
                elif op == "serviceCallFailure":
                    report["failures"][str(message["callId"])] = message["message"]
                return
            opcode = frame[0]
            if opcode == MESSAGE_DATA:
                sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
                channel = subscriptions[sub_id]
                topic = channel["topic"]
                payload = frame[13:]
                report["messages"][topic] = report["messages"].get(topic, 0) + 1
                body = json.loads(payload) if channel["encoding"] == "json" else len(payload)
                report["first"].setdefault(topic, {"log_time": log_time, "body": body})
                report["last"][topic] = {"log_time": log_time, "body": body}
            elif opcode == SERVICE_CALL_RESPONSE:
                service_id, call_id, length = struct.unpack_from("<III", frame, 1)
                encoding = frame[13 : 13 + length].decode()
                payload = frame[13 + length :]
                report["responses"][str(call_id)] = {
                    "service_id": service_id,
                    "encoding": encoding,
                    "body": json.loads(payload) if encoding == "json" else payload.hex(),
                }

        def read_for(duration):
            deadline = time.monotonic() + duration
            while (left := deadline - time.monotonic()) > 0:
                try:
                    handle(ws.recv(timeout=left))
                except TimeoutError:
                    break

        read_for(seconds)
        for call_id, (name, request) in enumerate(calls, start=1):
            service = report["services"].get(name)
            if service is None:
                report["failures"][str(call_id)] = f"no service {name} advertised"
                continue
            encoding = b"json"
            ws.send(
                struct.pack("<BIII", SERVICE_CALL_REQUEST, service["id"], call_id, len(encoding))
                + encoding
                + request.encode()
            )
            deadline = time.monotonic() + 5
            while (
                str(call_id) not in report["responses"]
                and str(call_id) not in report["failures"]
                and time.monotonic() < deadline
            ):
                read_for(0.1)
        if calls:
            read_for(1.5)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
