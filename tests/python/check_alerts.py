"""Reads the alerts of a tortwin MCAP output with the Python mcap package
(not tortwin's reader), for tests/alerts.rs: prints one JSON object with
every alert (kind, state, subject, the log_time, and how many trains had
left the section between ONSET_NS and it: negative when before the onset)
and the number of residual-chart samples the output's measurements make
(one per train, site, rail and quantity; one per tribometer reading).

    python3 check_alerts.py OUTPUT.mcap ONSET_NS
"""

import json
import sys

from mcap.reader import make_reader


def main():
    path, onset = sys.argv[1], int(sys.argv[2])
    trains, alerts, samples = [], [], set()
    with open(path, "rb") as f:
        reader = make_reader(f)
        topics = ["/twin/train", "/twin/alert", "/twin/measurement"]
        for _s, channel, m in reader.iter_messages(topics=topics):
            d = json.loads(m.data)
            if channel.topic == "/twin/train":
                trains.append(d["end_time_ns"])
            elif channel.topic == "/twin/measurement":
                train = d.get("train_id", "reading %d" % d["index_in_file"])
                samples.add((d["site_id"], d["rail"], d["quantity"], train))
            else:
                alerts.append((m.log_time, d))
    out = []
    for t, d in alerts:
        if t >= onset:
            after = sum(1 for e in trains if onset <= e <= t)
        else:
            after = -sum(1 for e in trains if t < e < onset)
        out.append(
            {
                "kind": d["kind"],
                "state": d["state"],
                "subject": " ".join(
                    d[k] for k in ("applicator_id", "site_id", "rail", "quantity") if k in d
                ),
                "log_time": t,
                "trains_after_onset": after,
                "evidence": d["evidence"],
            }
        )
    print(json.dumps({"alerts": out, "chart_samples": len(samples), "trains": len(trains)}))


if __name__ == "__main__":
    main()
