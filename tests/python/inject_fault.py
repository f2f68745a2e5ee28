"""Hides a fault in a recording, for the tests of the alerts: reads INPUT
with the Python mcap package (not tortwin's reader), changes the messages
the fault touches from ONSET on, and writes OUTPUT with the package's
writer, every other message as it was.

    python3 inject_fault.py INPUT OUTPUT --fault stuck|drift|no-pulses
        --onset-ns NS [--site M2 --rail high] [--applicator A1]
        [--drift-per-day 0.05] [--hours 2]

- stuck: the site's readings on that rail (every quantity) repeat the
  last value read before the onset;
- drift: the site's readings on that rail gain drift-per-day x the days
  since the onset (a sensor's calibration walking off);
- no-pulses: the applicator's pulses (every rail) are gone (its pump
  stopped: the tank ran dry and the controller stopped firing);
- outage: every message from the onset for `hours` is gone (the logger
  was down).
"""

import argparse
import json

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

DAY_NS = 86400 * 10**9


def main():
    p = argparse.ArgumentParser()
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--fault", required=True, choices=["stuck", "drift", "no-pulses", "outage"])
    p.add_argument("--onset-ns", type=int, required=True)
    p.add_argument("--site", default="M2")
    p.add_argument("--rail", default="high")
    p.add_argument("--applicator", default="A1")
    p.add_argument("--drift-per-day", type=float, default=0.05)
    p.add_argument("--hours", type=float, default=2.0)
    a = p.parse_args()

    with open(a.input, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        messages = list(reader.iter_messages(log_time_order=False))
    touched = 0
    last = {}
    with open(a.output, "wb") as out:
        w = Writer(out, compression=CompressionType.ZSTD)
        w.start(profile="", library="tortwin tests inject_fault.py")
        schema_ids = {
            sid: w.register_schema(s.name, s.encoding, s.data)
            for sid, s in sorted(summary.schemas.items())
        }
        channel_ids = {
            cid: w.register_channel(c.topic, c.message_encoding, schema_ids.get(c.schema_id, 0))
            for cid, c in sorted(summary.channels.items())
        }
        for _schema, channel, m in messages:
            data = m.data
            if a.fault == "outage" and channel.topic != "/section":
                if a.onset_ns <= m.log_time < a.onset_ns + a.hours * 3600 * 10**9:
                    touched += 1
                    continue
            if channel.topic == "/applicator/pulse" and a.fault == "no-pulses":
                d = json.loads(data)
                if m.log_time >= a.onset_ns and d["applicator_id"] == a.applicator:
                    touched += 1
                    continue
            if channel.topic == "/measurement/friction" and a.fault in ("stuck", "drift"):
                d = json.loads(data)
                if d["site_id"] == a.site and d["rail"] == a.rail:
                    q = d["quantity"]
                    if m.log_time < a.onset_ns:
                        last[q] = d["value"]
                    elif a.fault == "stuck" and q in last:
                        d["value"] = last[q]
                        touched += 1
                    elif a.fault == "drift":
                        days = (m.log_time - a.onset_ns) / DAY_NS
                        d["value"] = d["value"] + a.drift_per_day * days
                        touched += 1
                    data = json.dumps(d).encode()
            w.add_message(
                channel_ids[channel.id],
                log_time=m.log_time,
                data=data,
                publish_time=m.publish_time,
                sequence=m.sequence,
            )
        w.finish()
    print(json.dumps({"fault": a.fault, "messages_changed": touched}))


if __name__ == "__main__":
    main()
