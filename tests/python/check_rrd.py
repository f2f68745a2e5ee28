#!/usr/bin/env python3
"""Check a tortwin rerun recording (.rrd) against expected values.

    check_rrd.py FILE.rrd EXPECTED.json

Requires the Python package `rerun-sdk[datafusion]==0.36.3` (the version of
the crate's rerun dependency).

1. `rerun rrd verify FILE.rrd` (through `python -m rerun`, the CLI the pip
   package ships) must pass.
2. The file must hold exactly one recording, with an rrd footer (proof that
   the writer closed it), and the timelines `wheel_pass` and `time`.
3. The `mu` profile of one track, `/field/<rail>/<band>/mu` (a BarChart), at
   one snapshot must equal the expected values.

EXPECTED.json:

    {
      "rail": "high", "band": "top",       # plain names (no escaping needed)
      "wheel_pass": 16,                    # the snapshot, on the wheel_pass timeline
      "mu": [0.31, 0.30, ...],             # the expected values, one per grid point
      "tolerance": 0.0,                    # optional, absolute; default exact
      "d_m": [0.0, 1.0, ...],              # optional: the expected abscissa
      "check_history": true,               # optional: the newest row of
                                           #   mu_history at that snapshot is mu (f16)
      "history_rows": 2,                   # optional: rows mu_history holds then
      "blueprint": true                    # optional: require a blueprint store
                                           #   with a view of that mu profile
    }

Exit status 0 when every check passes, 1 when one fails, 2 when the file or
the tools cannot be used. Each failure is printed on stderr.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

PIP_HINT = 'pip install "rerun-sdk[datafusion]==0.36.3"'


class CheckFailed(Exception):
    pass


def verify_with_cli(rrd: Path) -> None:
    # `CI` keeps the CLI's first-run analytics banner and pipeline off.
    env = dict(os.environ, CI="1")
    result = subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "verify", str(rrd)],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if result.returncode != 0:
        raise CheckFailed(
            f"`rerun rrd verify {rrd}` failed (status {result.returncode}):\n"
            f"{result.stdout}{result.stderr}"
        )


def tensor_values(cell: object, what: str) -> tuple[list[int], list[float]]:
    """A TensorData cell as read from arrow: [{"shape": [...], "buffer": [...]}]."""
    if not isinstance(cell, list) or len(cell) != 1 or not isinstance(cell[0], dict):
        raise CheckFailed(f"{what}: expected one tensor, got {cell!r:.200}")
    tensor = cell[0]
    return [int(n) for n in tensor["shape"]], [float(v) for v in tensor["buffer"]]


def last_cell_at(table, column: str, timeline: str, time: int) -> object:
    """The last non-null cell of `column` logged exactly at `time` (latest-at wins)."""
    if column not in table.column_names:
        raise CheckFailed(f"no column {column}; columns: {table.column_names}")
    times = table.column(timeline).to_pylist()
    cells = table.column(column).to_pylist()
    found = [cell for t, cell in zip(times, cells) if t == time and cell is not None]
    if not found:
        logged = sorted({t for t, cell in zip(times, cells) if cell is not None})
        raise CheckFailed(
            f"{column}: nothing logged at {timeline} = {time}; logged at {logged[:20]}"
        )
    return found[-1]


def compare(what: str, actual: list[float], expected: list[float], tolerance: float) -> None:
    if len(actual) != len(expected):
        raise CheckFailed(f"{what}: {len(actual)} values, expected {len(expected)}")
    for i, (a, e) in enumerate(zip(actual, expected)):
        if not (math.isfinite(a) and abs(a - e) <= tolerance):
            raise CheckFailed(
                f"{what}[{i}] = {a!r}, expected {e!r} (tolerance {tolerance})"
            )


def check(rrd: Path, expected: dict) -> list[str]:
    from rerun.experimental import RrdReader

    verify_with_cli(rrd)

    reader = RrdReader(rrd)
    recordings = reader.recordings()
    if len(recordings) != 1:
        raise CheckFailed(f"expected 1 recording in {rrd}, found {recordings}")
    blueprints = reader.blueprints()
    if expected.get("blueprint") and not blueprints:
        raise CheckFailed(f"no blueprint store in {rrd}")
    try:
        # Needs the footer's manifest: fails on a file whose writer never closed.
        lazy = reader.store()
    except Exception as err:  # noqa: BLE001 - any failure here means "no footer"
        raise CheckFailed(f"{rrd} has no readable rrd footer: {err}") from err
    store = lazy.stream().collect()

    timeline = "wheel_pass"
    schema_text = str(store.schema())
    for name in (timeline, "time"):
        if name not in schema_text:
            raise CheckFailed(f"timeline {name!r} missing; schema:\n{schema_text}")

    rail, band = expected["rail"], expected["band"]
    entity = f"/field/{rail}/{band}/mu"
    time = int(expected["wheel_pass"])
    tolerance = float(expected.get("tolerance", 0.0))
    mu = [float(v) for v in expected["mu"]]

    table = store.reader(index=timeline, contents=entity).to_arrow_table()
    shape, values = tensor_values(
        last_cell_at(table, f"{entity}:BarChart:values", timeline, time),
        f"{entity} values at {timeline} {time}",
    )
    if shape != [len(values)]:
        raise CheckFailed(f"{entity}: values shape {shape} is not a vector")
    compare(f"{entity} at {timeline} {time}", values, mu, tolerance)
    done = [f"{entity} at {timeline} {time}: {len(mu)} values match"]

    if "d_m" in expected:
        # Logged once, statically: read it from the static-only view.
        static = store.reader(index=None, contents=entity).to_arrow_table()
        column = f"{entity}:BarChart:abscissa"
        if column not in static.column_names or static.num_rows != 1:
            raise CheckFailed(f"{entity}: no static abscissa ({static.column_names})")
        _, abscissa = tensor_values(static.column(column)[0].as_py(), f"{entity} abscissa")
        compare(f"{entity} abscissa", abscissa, [float(d) for d in expected["d_m"]], 1e-9)
        done.append(f"{entity} abscissa is d_m")

    if expected.get("check_history"):
        history = f"/field/{rail}/{band}/mu_history"
        table = store.reader(index=timeline, contents=history).to_arrow_table()
        shape, flat = tensor_values(
            last_cell_at(table, f"{history}:Tensor:data", timeline, time),
            f"{history} at {timeline} {time}",
        )
        if len(shape) != 2 or shape[1] != len(mu) or shape[0] * shape[1] != len(flat):
            raise CheckFailed(f"{history}: shape {shape}, expected [rows, {len(mu)}]")
        if "history_rows" in expected and shape[0] != int(expected["history_rows"]):
            raise CheckFailed(
                f"{history}: {shape[0]} rows, expected {expected['history_rows']}"
            )
        newest = flat[-len(mu):]
        # The heatmap is f16 (11 significant bits): compare at that precision.
        compare(
            f"{history} newest row",
            newest,
            mu,
            max(tolerance, 2.0**-11 * max(1.0, max(abs(v) for v in mu))),
        )
        done.append(f"{history} at {timeline} {time}: {shape[0]} rows, newest is mu")

    if expected.get("blueprint"):
        # The default layout must show this profile in some view.
        queries = []
        for chunk in reader.stream(store=blueprints[0]):
            for name, column in chunk.to_record_batch().to_pydict().items():
                if name.endswith("ViewContents:query"):
                    queries += [q for cell in column if cell for q in cell]
        if f"+ {entity}" not in queries:
            raise CheckFailed(f"no blueprint view shows {entity}; view queries: {queries}")
        done.append(f"blueprint has a view of {entity}")
    return done


def main(argv: list[str]) -> int:
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    rrd, expected_path = Path(argv[1]), Path(argv[2])
    try:
        import rerun  # noqa: F401
        import datafusion  # noqa: F401
    except ImportError as err:
        print(f"check_rrd.py: {err}; install the checker's packages: {PIP_HINT}", file=sys.stderr)
        return 2
    if not rrd.is_file():
        print(f"check_rrd.py: {rrd}: no such file", file=sys.stderr)
        return 2
    try:
        expected = json.loads(expected_path.read_text())
    except (OSError, ValueError) as err:
        print(f"check_rrd.py: {expected_path}: {err}", file=sys.stderr)
        return 2
    try:
        done = check(rrd, expected)
    except CheckFailed as err:
        print(f"check_rrd.py: FAILED: {err}", file=sys.stderr)
        return 1
    except KeyError as err:
        print(f"check_rrd.py: {expected_path}: missing key {err}", file=sys.stderr)
        return 2
    for line in done:
        print(f"ok: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
