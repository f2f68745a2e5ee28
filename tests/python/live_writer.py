"""A logger for the tests of `tortwin live`: writes a finished recording
again, message by message in time order, at a pace (SPEED times real time
by log_time), into one growing MCAP file or into a folder of hourly files,
with the Python mcap package's writer (an implementation independent of
tortwin's). Chunks are small, so they complete a few messages at a time, and
every write to the file is cut in two with a pause between the halves, so
the follower meets half-written records.

    python3 live_writer.py INPUT OUTPUT --speed 1000 [--hourly]

With --hourly, OUTPUT is a folder: a new file starts at the first passage of
each UTC hour (`part-NNNN.mcap`), opening with the /section message (and a
/line) logged at that passage's time, as `tortwin split` cuts days.
"""

import argparse
import os
import time

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

HOUR_NS = 3600 * 10**9


class HalvedWrites:
    """A file whose every write lands in two halves, flushed apart."""

    def __init__(self, path):
        self.f = open(path, "wb")

    def write(self, data):
        data = bytes(data)
        half = len(data) // 2
        for part in (data[:half], data[half:]):
            if part:
                self.f.write(part)
                self.f.flush()
                time.sleep(0.001)
        return len(data)

    def tell(self):
        return self.f.tell()

    def close(self):
        self.f.close()


class Output:
    """One MCAP file being written, with the input's schemas and channels."""

    def __init__(self, path, channels):
        self.stream = HalvedWrites(path)
        self.writer = Writer(
            self.stream, chunk_size=4096, compression=CompressionType.ZSTD
        )
        self.writer.start(profile="", library="tortwin tests live_writer.py")
        self.ids = {}
        schemas = {}
        for cid, (topic, encoding, schema) in sorted(channels.items()):
            sid = 0
            if schema is not None:
                key = (schema.name, schema.encoding, schema.data)
                if key not in schemas:
                    schemas[key] = self.writer.register_schema(
                        schema.name, schema.encoding, schema.data
                    )
                sid = schemas[key]
            self.ids[cid] = self.writer.register_channel(topic, encoding, sid)

    def add(self, channel_id, message, log_time=None, readable=None):
        t = message.log_time if log_time is None else log_time
        before = self.stream.tell()
        self.writer.add_message(
            self.ids[channel_id],
            log_time=t,
            data=message.data,
            publish_time=t,
            sequence=message.sequence,
        )
        # A chunk written whole holds every message so far.
        if readable is not None and self.stream.tell() != before:
            readable.append((time.time_ns(), t))

    def finish(self):
        self.writer.finish()
        self.stream.close()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("--speed", type=float, default=1000.0)
    ap.add_argument("--hourly", action="store_true")
    ap.add_argument(
        "--log-readable",
        help="write here a line 'WALL_NS LOG_TIME_NS' each time the file has grown: "
        "every message up to that log_time is readable from that wall-clock time on",
    )
    args = ap.parse_args()
    readable = []

    with open(args.input, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {
            cid: (c.topic, c.message_encoding, summary.schemas.get(c.schema_id))
            for cid, c in summary.channels.items()
        }
        messages = [
            (m.log_time, m.channel_id, m)
            for _, _, m in reader.iter_messages(log_time_order=True)
        ]
    topic = {cid: c[0] for cid, c in channels.items()}
    opening = [
        (cid, m) for _, cid, m in messages if topic[cid] in ("/section", "/line")
    ]
    t0 = messages[0][0]
    wall0 = time.monotonic()
    out = None
    hour = None
    part = 0
    if args.hourly:
        os.makedirs(args.output, exist_ok=True)
    for log_time, cid, m in messages:
        due = wall0 + (log_time - t0) / 1e9 / args.speed
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        if not args.hourly:
            if out is None:
                out = Output(args.output, channels)
            out.add(cid, m, readable=readable)
            continue
        if topic[cid] in ("/section", "/line"):
            if out is None:
                out = Output(os.path.join(args.output, "part-0000.mcap"), channels)
            out.add(cid, m)
            continue
        passage = topic[cid] == "/train/passage"
        if passage and hour is not None and log_time // HOUR_NS != hour:
            out.finish()
            part += 1
            out = Output(os.path.join(args.output, "part-%04d.mcap" % part), channels)
            for ocid, om in opening:
                out.add(ocid, om, log_time=log_time)
        if passage:
            hour = log_time // HOUR_NS
        out.add(cid, m, readable=readable)
    out.finish()
    if args.log_readable:
        with open(args.log_readable, "w") as f:
            for wall, t in readable:
                f.write(f"{wall} {t}\n")


if __name__ == "__main__":
    main()
