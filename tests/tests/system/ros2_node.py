#!/usr/bin/env python3
"""A stand-in for a ROS 2 node on rmw_zenoh, for the system tests: zenoh (the version ROS 2
Jazzy's rmw_zenoh carries) for the wire, rosbags for the messages (CDR and type hashes).

It connects as a peer to a router, as rmw_zenoh nodes do, and takes one JSON command per line
on standard input, answering each with one JSON line on standard output:

  {"cmd": "graph", "domain": 0}
      the liveliness tokens, each parsed by rmw_zenoh's rules, with every problem found
  {"cmd": "echo", "topic": "/odom", "type": "nav_msgs/msg/Odometry", "count": 5}
      that many samples on the exact data key, decoded, with their attachments
  {"cmd": "publish", "topic": "/cmd_vel", "linear": 0.5, "angular": 0.0, "rate": 20,
   "humble": false}
      starts publishing a Twist at that rate (with the attachment), until "quiet"; on Humble's
      key (no type hash) with "humble"; with "steering" (rad) instead of "angular", an
      ackermann_msgs/msg/AckermannDriveStamped of speed "linear"
  {"cmd": "quiet"}
      stops publishing
  {"cmd": "call", "service": "/scout/estop"}
      calls a std_srvs/srv/Trigger service, answers its response
  {"cmd": "get", "key": "0/**"}
      a plain zenoh query (no payload, no attachment), answers the replies' payloads
  {"cmd": "raw", "topic": "/cmd_vel", "type": "geometry_msgs/msg/Twist", "payload": "00..",
   "attachment": true}
      publishes one sample of arbitrary bytes (hex), with or without an attachment
"""

import json
import os
import struct
import sys
import threading
import time

import xxhash
import zenoh
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

STORE = get_typestore(Stores.ROS2_JAZZY)
DOMAIN = int(os.environ.get("ROS_DOMAIN_ID", "0"))


def register_trigger():
    """std_srvs/srv/Trigger as REP 2016 hashes a service: a struct of its request, response and
    event messages. rosbags knows messages only; `char` in .msg files is IDL uint8."""
    consts, fields = STORE.fielddefs["service_msgs/msg/ServiceEventInfo"]
    STORE.fielddefs["service_msgs/msg/ServiceEventInfo"] = (
        consts,
        [
            (name, (desc[0], ((desc[1][0][0], ("uint8", 0)), desc[1][1])))
            if name == "client_gid"
            else (name, desc)
            for name, desc in fields
        ],
    )
    types = {}
    for definition, name in [
        ("uint8 structure_needs_at_least_one_member\n", "Trigger_Request"),
        ("bool success\nstring message\n", "Trigger_Response"),
        (
            "service_msgs/ServiceEventInfo info\n"
            "std_srvs/srv/Trigger_Request[<=1] request\n"
            "std_srvs/srv/Trigger_Response[<=1] response\n",
            "Trigger_Event",
        ),
        (
            "std_srvs/srv/Trigger_Request request_message\n"
            "std_srvs/srv/Trigger_Response response_message\n"
            "std_srvs/srv/Trigger_Event event_message\n",
            "Trigger",
        ),
    ]:
        types.update(get_types_from_msg(definition, f"std_srvs/srv/{name}"))

    def fix(item):
        if isinstance(item, str):
            return item.replace("std_srvs/srv/msg/", "std_srvs/srv/")
        if isinstance(item, (tuple, list)):
            return type(item)(fix(i) for i in item)
        return item

    STORE.register({fix(k): fix(v) for k, v in types.items()})


register_trigger()


def register_ackermann():
    """ackermann_msgs (ros-drivers/ackermann_msgs), which rosbags does not carry: its fields."""
    types = {}
    types.update(get_types_from_msg(
        "float32 steering_angle\nfloat32 steering_angle_velocity\nfloat32 speed\n"
        "float32 acceleration\nfloat32 jerk\n", "ackermann_msgs/msg/AckermannDrive"))
    types.update(get_types_from_msg(
        "std_msgs/Header header\nackermann_msgs/AckermannDrive drive\n",
        "ackermann_msgs/msg/AckermannDriveStamped"))
    STORE.register(types)


register_ackermann()


def dds_name(type_name):
    package, kind, name = type_name.split("/")
    return f"{package}::{kind}::dds_::{name}_"


def type_of_dds(name):
    package, kind, _, rest = name.split("::")
    return f"{package}/{kind}/{rest[:-1]}"


def data_key(topic, type_name, humble=False):
    """The key rmw_zenoh publishes on; Humble's has no type hash."""
    type_hash = "TypeHashNotSupported" if humble else STORE.hash_rihs01(type_name)
    return f"{DOMAIN}/{topic.lstrip('/')}/{dds_name(type_name)}/{type_hash}"


class Attachments:
    """rmw_zenoh's attachment: i64 sequence number, i64 source time (ns), GID (varint 16 +
    16 bytes)."""

    def __init__(self):
        self.sequence = 0
        self.gid = os.urandom(16)

    def next(self):
        self.sequence += 1
        return struct.pack("<qq", self.sequence, time.time_ns()) + bytes([16]) + self.gid


def parse_attachment(attachment):
    if attachment is None:
        return None
    raw = attachment.to_bytes()
    if len(raw) != 33 or raw[16] != 16:
        return {"invalid": raw.hex()}
    sequence, stamp = struct.unpack("<qq", raw[:16])
    return {"sequence": sequence, "stamp_ns": stamp, "gid": raw[17:].hex()}


QOS_FIELDS = 6


def parse_qos(text, problems, token):
    """rmw_zenoh's keyexpr QoS: reliability:durability:history,depth:deadline s,ns:lifespan
    s,ns:liveliness kind,s,ns; empty fields mean the defaults."""
    parts = text.split(":")
    if len(parts) != QOS_FIELDS:
        problems.append(f"{token}: QoS {text!r} has {len(parts)} fields, not {QOS_FIELDS}")
        return None
    reliability, durability, history, deadline, lifespan, liveliness = parts
    for name, value, allowed in [
        ("reliability", reliability, {"", "1", "2"}),
        ("durability", durability, {"", "1", "2"}),
    ]:
        if value not in allowed:
            problems.append(f"{token}: {name} {value!r}")
    kind, _, depth = history.partition(",")
    if kind not in {"", "1", "2"} or (depth and not depth.isdigit()):
        problems.append(f"{token}: history {history!r}")
    for name, value, commas in [("deadline", deadline, 1), ("lifespan", lifespan, 1), ("liveliness", liveliness, 2)]:
        if value.count(",") != commas or not all(p == "" or p.isdigit() for p in value.split(",")):
            problems.append(f"{token}: {name} {value!r}")
    return {"reliability": reliability, "durability": durability, "history": history}


def parse_token(token, problems):
    """A liveliness token by rmw_zenoh's rules (rmw_zenoh_cpp/src/detail/liveliness_utils.cpp,
    Entity::make and keyexpr_to_qos)."""
    parts = token.split("/")
    if parts[0] != "@ros2_lv":
        problems.append(f"{token}: not under @ros2_lv")
        return None
    if len(parts) not in (9, 13):
        problems.append(f"{token}: {len(parts)} parts, not 9 (node) or 13 (endpoint)")
        return None
    if any(not part for part in parts):
        problems.append(f"{token}: an empty part (rmw_zenoh drops such tokens)")
    domain, zid, node_id, entity_id, kind, enclave, namespace, node = parts[1:9]
    entity = {
        "domain": int(domain) if domain.isdigit() else problems.append(f"{token}: domain") or -1,
        "zid": zid,
        "node_id": node_id,
        "entity_id": entity_id,
        "kind": kind,
        "enclave": enclave.replace("%", "/"),
        "namespace": namespace.replace("%", "/"),
        "node": node,
        # rmw_zenoh's GID of the entity: XXH3-128 of its token, low 64 bits first.
        "gid": xxhash.xxh3_128_intdigest(token.encode()).to_bytes(16, "little").hex(),
    }
    try:
        int(zid, 16)
    except ValueError:
        problems.append(f"{token}: zenoh id {zid!r} is not hex")
    for name, value in [("node id", node_id), ("entity id", entity_id)]:
        if not value.isdigit():
            problems.append(f"{token}: {name} {value!r} is not a number")
    if kind not in {"NN", "MP", "MS", "SS", "SC"}:
        problems.append(f"{token}: kind {kind!r}")
    if "%" in node or not node:
        problems.append(f"{token}: node name {node!r}")
    if (kind == "NN") != (len(parts) == 9):
        problems.append(f"{token}: kind {kind} with {len(parts)} parts")
    if len(parts) == 13:
        topic, type_dds, type_hash, qos = parts[9:13]
        entity["topic"] = topic.replace("%", "/")
        if not entity["topic"].startswith("/"):
            problems.append(f"{token}: topic {topic!r} is not absolute (mangled `/` first)")
        entity["type"] = type_of_dds(type_dds)
        try:
            expected = STORE.hash_rihs01(entity["type"])
        except KeyError:
            expected = None
            problems.append(f"{token}: type {entity['type']} unknown to rosbags")
        if expected and type_hash != expected:
            problems.append(f"{token}: hash {type_hash} but rosbags says {expected}")
        entity["hash"] = type_hash
        entity["qos"] = parse_qos(qos, problems, token)
    return entity


def decode(sample, type_name):
    """The message, its attachment, and whether rosbags writes the very same bytes for it."""
    payload = sample.payload.to_bytes()
    message = STORE.deserialize_cdr(payload, type_name)
    same = bytes(STORE.serialize_cdr(message, type_name)) == bytes(payload)
    return message, parse_attachment(sample.attachment), same


def summary(message, type_name):
    if type_name == "nav_msgs/msg/Odometry":
        p, t = message.pose.pose, message.twist.twist
        return {
            "stamp": message.header.stamp.sec + message.header.stamp.nanosec * 1e-9,
            "frame_id": message.header.frame_id,
            "child_frame_id": message.child_frame_id,
            "x": p.position.x, "y": p.position.y,
            "qz": p.orientation.z, "qw": p.orientation.w,
            "linear": t.linear.x, "angular": t.angular.z,
        }
    if type_name == "tf2_msgs/msg/TFMessage":
        return {"transforms": [{"parent": t.header.frame_id, "child": t.child_frame_id,
                                "x": t.transform.translation.x} for t in message.transforms]}
    if type_name == "sensor_msgs/msg/BatteryState":
        return {"voltage": message.voltage, "present": message.present,
                "health": message.power_supply_health, "frame_id": message.header.frame_id,
                "percentage": message.percentage, "status": message.power_supply_status}
    if type_name == "sensor_msgs/msg/JointState":
        return {"name": list(message.name), "position": list(message.position),
                "velocity": list(message.velocity), "effort": list(message.effort)}
    if type_name == "diagnostic_msgs/msg/DiagnosticArray":
        return {"status": [{"level": int(s.level), "name": s.name, "message": s.message,
                            "values": {kv.key: kv.value for kv in s.values}} for s in message.status]}
    return {}


class Node:
    def __init__(self, router):
        config = zenoh.Config()
        config.insert_json5("mode", '"peer"')
        config.insert_json5("connect/endpoints", json.dumps([router]))
        config.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(config)
        self.publishing = None

    def graph(self, command):
        tokens = []
        for reply in self.session.liveliness().get(f"@ros2_lv/{command.get('domain', DOMAIN)}/**", timeout=3.0):
            if reply.ok is not None:
                tokens.append(str(reply.ok.key_expr))
        problems = []
        parsed = [parse_token(token, problems) for token in sorted(tokens)]
        return {"tokens": sorted(tokens), "entities": [p for p in parsed if p], "problems": problems}

    def echo(self, command):
        type_name = command["type"]
        key = data_key(command["topic"], type_name)
        received = []
        done = threading.Event()

        def on_sample(sample):
            if done.is_set():
                return
            try:
                message, attachment, same = decode(sample, type_name)
                received.append({"attachment": attachment, "rosbags_same_bytes": same,
                                 **summary(message, type_name)})
            except Exception as error:  # noqa: BLE001 - reported to the test
                received.append({"error": f"{type(error).__name__}: {error}"})
            if len(received) >= command.get("count", 1):
                done.set()

        subscriber = self.session.declare_subscriber(key, on_sample)
        done.wait(command.get("timeout", 10.0))
        subscriber.undeclare()
        return {"key": key, "samples": received[: command.get("count", 1)]}

    def publish(self, command):
        self.quiet({})
        if "steering" in command:
            type_name = "ackermann_msgs/msg/AckermannDriveStamped"
            Stamped = STORE.types[type_name]
            Drive = STORE.types["ackermann_msgs/msg/AckermannDrive"]
            Header = STORE.types["std_msgs/msg/Header"]
            Time = STORE.types["builtin_interfaces/msg/Time"]
            message = Stamped(
                header=Header(stamp=Time(sec=0, nanosec=0), frame_id="base_link"),
                drive=Drive(steering_angle=command["steering"], steering_angle_velocity=0.0,
                            speed=command["linear"], acceleration=0.0, jerk=0.0))
        else:
            type_name = "geometry_msgs/msg/Twist"
            Twist = STORE.types[type_name]
            Vector3 = STORE.types["geometry_msgs/msg/Vector3"]
            message = Twist(linear=Vector3(x=command["linear"], y=0.0, z=0.0),
                            angular=Vector3(x=0.0, y=0.0, z=command["angular"]))
        payload = STORE.serialize_cdr(message, type_name)
        publisher = self.session.declare_publisher(
            data_key(command.get("topic", "/cmd_vel"), type_name, command.get("humble", False)))
        attachments = Attachments()
        stop = threading.Event()
        period = 1.0 / command.get("rate", 20)

        def loop():
            while not stop.is_set():
                publisher.put(bytes(payload), attachment=attachments.next())
                stop.wait(period)
            publisher.undeclare()

        thread = threading.Thread(target=loop, daemon=True)
        thread.start()
        self.publishing = (stop, thread, attachments)
        return {"publishing": True}

    def quiet(self, _command):
        sent = 0
        if self.publishing:
            stop, thread, attachments = self.publishing
            stop.set()
            thread.join()
            sent = attachments.sequence
            self.publishing = None
        return {"sent": sent}

    def raw(self, command):
        key = data_key(command["topic"], command["type"])
        attachment = Attachments().next() if command.get("attachment", True) else None
        self.session.put(key, bytes.fromhex(command["payload"]), attachment=attachment)
        return {"key": key}

    def get(self, command):
        replies = []
        for reply in self.session.get(command["key"], timeout=3.0):
            if reply.ok is not None:
                replies.append({"ok": reply.ok.payload.to_bytes().hex()})
            else:
                replies.append({"err": reply.err.payload.to_string()})
        return {"replies": replies}

    def call(self, command):
        type_name = "std_srvs/srv/Trigger"
        key = data_key(command["service"], type_name)
        request = bytes([0, 1, 0, 0, 0])  # CDR of Trigger_Request: its placeholder uint8
        replies = []
        for reply in self.session.get(key, payload=request, attachment=Attachments().next(), timeout=5.0):
            if reply.ok is not None:
                message = STORE.deserialize_cdr(reply.ok.payload.to_bytes(), "std_srvs/srv/Trigger_Response")
                replies.append({"success": bool(message.success), "message": message.message,
                                "attachment": parse_attachment(reply.ok.attachment)})
            else:
                replies.append({"error": reply.err.payload.to_string()})
        return {"key": key, "replies": replies}


def main():
    node = Node(sys.argv[1])
    print(json.dumps({"ready": True, "zenoh": zenoh.__version__ if hasattr(zenoh, "__version__") else "?"}), flush=True)
    for line in sys.stdin:
        if not line.strip():
            continue
        command = json.loads(line)
        try:
            answer = getattr(node, command["cmd"])(command)
        except Exception as error:  # noqa: BLE001 - reported to the test
            answer = {"error": f"{type(error).__name__}: {error}"}
        print(json.dumps(answer), flush=True)
    node.quiet({})


if __name__ == "__main__":
    main()
