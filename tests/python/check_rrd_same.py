"""Compares the data of two rerun recordings (.rrd) with rerun-sdk's own
reader, for tests/live_viewers.rs: what a rerun gRPC server received from
`tortwin live --connect` (saved by `rerun --save`) against the .rrd of
`tortwin replay --out-rrd`. Every entity and component, static and on the
`time` and `wheel_pass` timelines, must hold the same cells at the same
times; how the data was cut into chunks, the recording's id and name and
the blueprints may differ.

    python3 check_rrd_same.py RECEIVED.rrd REPLAY.rrd
"""

import json
import sys
import warnings

warnings.filterwarnings("ignore")  # a streamed file has no footer: read whole

import pyarrow as pa  # noqa: E402
import pyarrow.compute as pc  # noqa: E402
from rerun.experimental import RrdReader  # noqa: E402

# The recording's own properties: its id, name and start differ.
PROPERTIES = "/__properties"


def columns(store, index):
    """{column: table of (time, cell) with the non-null cells, by time}."""
    table = store.reader(index=index, contents="/**").to_arrow_table()
    out = {}
    for name in table.column_names:
        if name.startswith(PROPERTIES) or name in ("time", "wheel_pass") or ":" not in name:
            continue
        column = table.column(name)
        keep = pc.is_valid(column)
        if index:
            part = pa.table({"t": table.column(index), "v": column}).filter(keep)
            part = part.sort_by("t")
        else:
            part = pa.table({"v": column}).filter(keep)
        out[name] = part
    return out


def as_cells(part):
    """The cells as sorted (time, JSON) pairs, once each: the slow, exact
    comparison when the tables differ in order or in repeats."""
    times = part.column("t").to_pylist() if "t" in part.column_names else [-1] * part.num_rows
    values = part.column("v").to_pylist()
    return sorted({(t, json.dumps(v, sort_keys=True, default=str)) for t, v in zip(times, values)})


def main():
    received, replay = sys.argv[1], sys.argv[2]
    stores = [RrdReader(p).stream().collect() for p in (received, replay)]
    failures = []
    compared = 0
    for index in (None, "time", "wheel_pass"):
        a, b = (columns(s, index) for s in stores)
        for name in sorted(set(a) | set(b)):
            if name not in a:
                failures.append(f"{index}: {name} only in the replay")
            elif name not in b:
                failures.append(f"{index}: {name} only in what was received")
            elif a[name].equals(b[name]):
                compared += a[name].num_rows
            else:
                x, y = as_cells(a[name]), as_cells(b[name])
                if x != y:
                    first = next((p, q) for p, q in zip(x + [None], y + [None]) if p != q)
                    failures.append(
                        f"{index}: {name}: {len(x)} cells received, {len(y)} in the "
                        f"replay; first difference {str(first)[:300]}"
                    )
                else:
                    compared += len(x)
    for f in failures[:20]:
        print("FAIL", f)
    if failures:
        sys.exit(1)
    print(f"{compared} cells equal")


if __name__ == "__main__":
    main()
