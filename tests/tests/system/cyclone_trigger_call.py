#!/usr/bin/env python3
"""A std_srvs/Trigger call as rmw_cyclonedds makes it, from a plain Cyclone DDS participant
(no ROS: `cyclonedds` from PyPI), for the system tests of `scout ros2` over DDS. Run only inside
a private network namespace.

    cyclone_trigger_call.py SERVICE

rmw_cyclonedds puts a header (the client's 64-bit id and the call's sequence number) before the
request and expects it back before the reply (`cdds_request_header_t` in its serdata.hpp):
this writes such a request on `rq/SERVICERequest`, reads `rr/SERVICEReply` until the reply with
its header comes, and prints one JSON object: the reply, or an error.
"""

import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import int64, uint8, uint64
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Request(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Request_"):
    guid: uint64
    seq: int64
    structure_needs_at_least_one_member: uint8


@dataclass
class Reply(IdlStruct, typename="std_srvs::srv::dds_::Trigger_Response_"):
    guid: uint64
    seq: int64
    success: bool
    message: str


CLIENT = 0x5C07_C1C1_0000_0001
SEQ = 42


def main() -> None:
    service = sys.argv[1].strip("/")
    participant = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    # ROS 2's service QoS: reliable, volatile, keep last 10.
    qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))
    writer = DataWriter(participant, Topic(participant, f"rq/{service}Request", Request), qos=qos)
    reader = DataReader(participant, Topic(participant, f"rr/{service}Reply", Reply), qos=qos)
    deadline = time.monotonic() + 20
    while not (writer.get_matched_subscriptions() and reader.get_matched_publications()):
        if time.monotonic() > deadline:
            print(json.dumps({"error": "the service's reader and writer never matched"}))
            return
        time.sleep(0.05)
    time.sleep(0.5)
    writer.write(Request(guid=CLIENT, seq=SEQ, structure_needs_at_least_one_member=0))
    others = 0
    while time.monotonic() < deadline:
        for reply in reader.take(N=10):
            if reply.guid == CLIENT and reply.seq == SEQ:
                print(json.dumps({"success": reply.success, "message": reply.message,
                                  "others": others}), flush=True)
                return
            others += 1
        time.sleep(0.01)
    print(json.dumps({"error": f"no reply with this call's header within 20 s ({others} others)"}))


if __name__ == "__main__":
    main()
