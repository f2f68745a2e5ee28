"""A Foxglove WebSocket client (the `websockets` package speaking the
protocol, subprotocol foxglove.sdk.v1, independent of tortwin and of the
foxglove SDK) that records what a server sends.

    python3 foxglove_client.py ws://HOST:PORT --out RECEIVED.json --ready FILE
        [--until-section] [--timeout S]

Connects (retrying until the server listens), subscribes to every channel
the server advertises (also those advertised later), writes FILE once all
of tortwin's eight topics are subscribed, and records each message:
topic, log_time and bytes. It stops when the server closes the connection,
or with --until-section at the first `/twin/section` message (a viewer
connecting late must get it at once). RECEIVED.json holds the channels
as advertised and the messages in the order they came.
"""

import argparse
import asyncio
import base64
import json
import struct
import sys
import time

import websockets

TOPICS = {
    "/twin/section",
    "/twin/train",
    "/twin/pulse",
    "/twin/measurement",
    "/twin/field",
    "/foxglove/track",
    "/foxglove/log",
    "/twin/alert",
}


async def connect(url, timeout):
    t0 = time.monotonic()
    while True:
        try:
            return await websockets.connect(
                url, subprotocols=["foxglove.sdk.v1"], max_size=None
            )
        except OSError:
            if time.monotonic() - t0 > timeout:
                raise
            await asyncio.sleep(0.05)


async def run(args):
    ws = await connect(args.url, args.timeout)
    channels = {}  # channel id -> advertised channel
    subscriptions = {}  # subscription id -> channel id
    received = []
    ready = False
    try:
        async with asyncio.timeout(args.timeout):
            async for frame in ws:
                if isinstance(frame, str):
                    msg = json.loads(frame)
                    if msg["op"] == "advertise":
                        subscribe = []
                        for ch in msg["channels"]:
                            channels[ch["id"]] = ch
                            sid = len(subscriptions) + 1
                            subscriptions[sid] = ch["id"]
                            subscribe.append({"id": sid, "channelId": ch["id"]})
                        await ws.send(
                            json.dumps({"op": "subscribe", "subscriptions": subscribe})
                        )
                        topics = {channels[c]["topic"] for c in subscriptions.values()}
                        if not ready and TOPICS <= topics:
                            ready = True
                            if args.ready:
                                open(args.ready, "w").close()
                    continue
                if frame[0] != 1:  # only MessageData is asked for
                    continue
                sid, log_time = struct.unpack_from("<IQ", frame, 1)
                topic = channels[subscriptions[sid]]["topic"]
                received.append(
                    {
                        "topic": topic,
                        "log_time": log_time,
                        "data": base64.b64encode(frame[13:]).decode(),
                    }
                )
                if args.until_section and topic == "/twin/section":
                    break
    except websockets.ConnectionClosed:
        pass
    finally:
        await ws.close()
    with open(args.out, "w") as f:
        json.dump({"channels": list(channels.values()), "messages": received}, f)
    print(f"{len(received)} messages on {len(channels)} channels")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("url")
    ap.add_argument("--out", required=True)
    ap.add_argument("--ready")
    ap.add_argument("--until-section", action="store_true")
    ap.add_argument("--timeout", type=float, default=300)
    args = ap.parse_args()
    try:
        asyncio.run(run(args))
    except TimeoutError:
        sys.exit(f"no end within {args.timeout} s")


if __name__ == "__main__":
    main()
