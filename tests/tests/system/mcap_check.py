"""Reads an MCAP file from `scout record` with the `mcap` package and prints a JSON report.

Usage: mcap_check.py FILE [--truncated]

A whole file is read through its summary and index (make_reader); a cut one (--truncated) as a
stream, record by record, up to the cut. The report: whether it has a summary, its statistics,
how many chunks and their compression, and per topic: the schema's name and encoding, the
message encoding, the count, the first and last log times, whether log times never go back, and
the first and last messages' JSON (JSON channels) or their sizes.
"""

import json
import sys

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import StreamReader


def report_messages(schemas, channels, messages):
    topics = {}
    for channel_id, log_time, data in messages:
        channel = channels[channel_id]
        schema = schemas.get(channel.schema_id)
        topic = topics.setdefault(
            channel.topic,
            {
                "schema": schema.name if schema else None,
                "schema_encoding": schema.encoding if schema else None,
                "encoding": channel.message_encoding,
                "count": 0,
                "first_ns": log_time,
                "last_ns": log_time,
                "in_order": True,
                "first": None,
                "last": None,
            },
        )
        topic["count"] += 1
        if log_time < topic["last_ns"]:
            topic["in_order"] = False
        topic["last_ns"] = log_time
        body = json.loads(data) if channel.message_encoding == "json" else len(data)
        if topic["first"] is None:
            topic["first"] = body
        topic["last"] = body
    return topics


def whole(path):
    with open(path, "rb") as stream:
        reader = make_reader(stream)
        try:
            summary = reader.get_summary()
        except McapError as cut:
            # A file cut before its footer (SIGKILL, power loss): its end is not a footer.
            return {"summary": False, "error": f"{type(cut).__name__}: {cut}"}
        if summary is None:
            return {"summary": False}
        schemas = summary.schemas
        channels = summary.channels
        messages = [
            (message.channel_id, message.log_time, message.data)
            for _, _, message in reader.iter_messages(log_time_order=False)
        ]
        statistics = summary.statistics
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        return {
            "summary": True,
            "message_count": statistics.message_count if statistics else None,
            "channel_message_counts": {
                channels[cid].topic: n
                for cid, n in (statistics.channel_message_counts.items() if statistics else [])
            },
            "chunks": len(summary.chunk_indexes),
            "compression": sorted({c.compression for c in summary.chunk_indexes}),
            "metadata": metadata,
            "topics": report_messages(schemas, channels, messages),
        }


def truncated(path):
    schemas, channels, messages = {}, {}, []
    chunks, error = 0, None
    try:
        for record in StreamReader(path, skip_magic=False).records:
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                messages.append((record.channel_id, record.log_time, record.data))
            elif isinstance(record, Chunk):
                chunks += 1
    except (McapError, EOFError, ValueError) as cut:
        error = f"{type(cut).__name__}: {cut}"
    return {
        "summary": False,
        "stopped_at": error,
        "topics": report_messages(schemas, channels, messages),
    }


def main():
    path = sys.argv[1]
    report = truncated(path) if "--truncated" in sys.argv[2:] else whole(path)
    print(json.dumps(report))


if __name__ == "__main__":
    main()
