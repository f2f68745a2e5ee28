"""Checks what `tortwin live` wrote against what `tortwin replay` writes,
with the Python mcap package (independent of tortwin's reader).

    python3 check_live.py LIVE_DIR REPLAY.mcap [REPLAY.mcap ...] [--whole WHOLE.mcap]

The live folder's MCAP files (in name order: recording, then day) and the
replay outputs (in the order given) are each read as one stream of messages
in file order, every `/twin/section` after the first left out (a live
output opens every day with it; replays of consecutive recordings each open
with it). The two streams must be equal message for message: topic,
log_time and bytes. Every train is in the live output once. With --whole,
the live output's trains, fields and measurements must also be those of the
replay of the whole recording (`index_in_file` aside: the live recordings
are other files).
"""

import argparse
import glob
import json
import os
import sys

from mcap.reader import make_reader


def messages(path):
    with open(path, "rb") as f:
        return [
            (c.topic, m.log_time, bytes(m.data))
            for _, c, m in make_reader(f).iter_messages(log_time_order=False)
        ]


def stream(paths):
    out = []
    for p in paths:
        ms = messages(p)
        if out:
            ms = [m for m in ms if m[0] != "/twin/section"]
        out += ms
    return out


def fail(text):
    print(text)
    sys.exit(1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("live")
    ap.add_argument("replays", nargs="+")
    ap.add_argument("--whole")
    args = ap.parse_args()

    files = sorted(glob.glob(os.path.join(args.live, "*.mcap")))
    if not files:
        fail(f"no MCAP files in {args.live}")
    live = stream(files)
    replay = stream(args.replays)
    for i, (a, b) in enumerate(zip(replay, live)):
        if a != b:
            fail(
                f"message {i}: the replay has {a[0]} at {a[1]} ns "
                f"({a[2][:120]!r}), the live output {b[0]} at {b[1]} ns ({b[2][:120]!r})"
            )
    if len(live) != len(replay):
        fail(f"the live output has {len(live)} messages, the replay {len(replay)}")

    trains = [json.loads(m[2])["train_id"] for m in live if m[0] == "/twin/train"]
    twice = {t for t in trains if trains.count(t) > 1}
    if twice:
        fail(f"trains in the live output more than once: {sorted(twice)[:5]}")
    if not trains:
        fail("no trains in the live output")

    if args.whole:
        keep = ("/twin/train", "/twin/field", "/twin/measurement", "/twin/alert")

        def norm(m):
            d = json.loads(m[2])
            d.pop("index_in_file", None)
            return (m[0], m[1], d)

        w = [norm(m) for m in messages(args.whole) if m[0] in keep]
        lv = [norm(m) for m in live if m[0] in keep]
        for i, (a, b) in enumerate(zip(w, lv)):
            if a != b:
                fail(f"{a[0]} {i} at {a[1]} ns differs from the whole recording's replay")
        if len(w) != len(lv):
            fail(f"{len(lv)} trains, fields, measurements and alerts live, {len(w)} in the whole replay")

    alerts = sum(1 for m in live if m[0] == "/twin/alert")
    if not alerts:
        fail("no alerts in the live output")
    print(
        f"{len(files)} live files, {len(live)} messages equal to the replay's, "
        f"{len(trains)} trains once each, {alerts} alerts"
        + (", same as the whole recording" if args.whole else "")
    )


if __name__ == "__main__":
    main()
