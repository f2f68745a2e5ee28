"""Checks what a Foxglove WebSocket client received from `tortwin live
--foxglove` against the MCAP files the same follower wrote, with the Python
mcap package.

    python3 check_foxglove_ws.py RECEIVED.json LIVE_DIR

RECEIVED.json is tests/python/foxglove_client.py's. Every channel of the
MCAP output must have been advertised with the same topic, message
encoding, schema name, schema encoding and schema; the messages received
must be those of the live folder's MCAP files read in name order (each
file in its own order), message for message: topic, log_time and bytes.
"""

import base64
import glob
import json
import os
import sys

from mcap.reader import make_reader


def fail(text):
    print(text)
    sys.exit(1)


def main():
    received_path, live_dir = sys.argv[1:3]
    with open(received_path) as f:
        received = json.load(f)
    paths = sorted(
        p
        for p in glob.glob(os.path.join(live_dir, "*.mcap"))
        if not os.path.basename(p).startswith(".")
    )
    if not paths:
        fail(f"no MCAP files in {live_dir}")
    advertised = {c["topic"]: c for c in received["channels"]}
    want = []
    for path in paths:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            for channel in summary.channels.values():
                schema = summary.schemas[channel.schema_id]
                got = advertised.get(channel.topic)
                if got is None:
                    fail(f"{channel.topic} was not advertised")
                expected = {
                    "encoding": channel.message_encoding,
                    "schemaName": schema.name,
                    "schemaEncoding": schema.encoding,
                    "schema": schema.data.decode(),
                }
                for key, value in expected.items():
                    if got.get(key) != value:
                        fail(f"{channel.topic}: advertised {key} differs from the MCAP's")
            for _, channel, message in reader.iter_messages(log_time_order=False):
                want.append((channel.topic, message.log_time, bytes(message.data)))
    got = [
        (m["topic"], m["log_time"], base64.b64decode(m["data"]))
        for m in received["messages"]
    ]
    for i, (g, w) in enumerate(zip(got, want)):
        if g != w:
            fail(
                f"message {i}: received {g[0]} at {g[1]} ns, the MCAP output has "
                f"{w[0]} at {w[1]} ns" + (" (other bytes)" if g[:2] == w[:2] else "")
            )
    if len(got) != len(want):
        fail(f"received {len(got)} messages, the MCAP output holds {len(want)}")
    topics = sorted({t for t, _, _ in got})
    print(
        f"{len(got)} messages on {len(topics)} topics equal to the {len(paths)} MCAP "
        f"files' ({', '.join(topics)})"
    )


if __name__ == "__main__":
    main()
