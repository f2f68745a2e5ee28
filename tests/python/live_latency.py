"""How soon `tortwin live --json` puts out a train's field after the message
that ends the train's occupation becomes readable (issue 31: within
100 ms). Runs the logger (live_writer.py, --log-readable) and the follower
side by side, stamps each line the follower prints as it arrives, and for
each train line takes the first moment the file held a message later than
the train's end (its snapshot's log_time).

    python3 live_latency.py TORTWIN REC.mcap WORK_DIR --speed 1000
"""

import argparse
import json
import os
import subprocess
import sys
import time


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tortwin")
    ap.add_argument("recording")
    ap.add_argument("work")
    ap.add_argument("--speed", default="1000")
    args = ap.parse_args()
    here = os.path.dirname(os.path.abspath(__file__))
    growing = os.path.join(args.work, "logger.mcap")
    log = os.path.join(args.work, "readable.txt")
    writer = subprocess.Popen(
        [sys.executable, os.path.join(here, "live_writer.py"), args.recording, growing,
         "--speed", args.speed, "--log-readable", log]
    )
    while not os.path.exists(growing):
        time.sleep(0.01)
    follower = subprocess.Popen(
        [args.tortwin, "live", growing, "--out-dir", os.path.join(args.work, "live"),
         "--json", "-q"],
        stdout=subprocess.PIPE, text=True,
    )
    arrivals = []
    for line in follower.stdout:
        arrivals.append((time.time_ns(), json.loads(line)))
    if follower.wait() != 0 or writer.wait() != 0:
        sys.exit("the follower or the logger failed")
    readable = [tuple(map(int, l.split())) for l in open(log)]
    latencies = {}
    for wall, line in arrivals:
        end = line["log_time_ns"]
        became = next((w for w, t in readable if t > end), None)
        if became is None:
            continue  # the last train: ended by the end of the file
        key = line["train_id"]
        latencies[key] = max(latencies.get(key, 0), (wall - became) / 1e6)
    values = sorted(latencies.values())
    if not values:
        sys.exit("no train lines")
    p = lambda q: values[min(len(values) - 1, int(q * len(values)))]
    print(f"{len(values)} trains: latency median {p(0.5):.1f} ms, 95 % {p(0.95):.1f} ms, "
          f"max {values[-1]:.1f} ms (from the message after the train's end becoming "
          f"readable to its last rail's line on stdout)")


if __name__ == "__main__":
    main()
