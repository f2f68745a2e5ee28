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
   one snapshot must equal the expected values at the precision it is stored
   in: F64 exactly, F32 as the expected values rounded to f32 (any other
   buffer type fails).
4. Every track's mu profile has a static colour of its own; pulses and site
   measurements (`/applicator/**`, `/sites/**`) are on the `time` timeline
   only (on `wheel_pass` a train's measurements would stack).
5. With "blueprint": the layout the viewer opens (see `blueprint_checks`).

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
      "history_logged_at": [16, 24],       # optional: exactly the wheel_pass values
                                           #   at which mu_history was logged
      "blueprint": true,                   # optional: require a blueprint store
                                           #   laid out as `blueprint_checks` says
      "series": {                          # optional: per Scalars entity, every
        "/applicator/A1/high": [[t, v], ...]   # (time in ns, value) it holds on
      }                                    #   `time`, exactly, none missing or extra
    }

Exit status 0 when every check passes, 1 when one fails, 2 when the file or
the tools cannot be used. Each failure is printed on stderr.
"""

from __future__ import annotations

import json
import math
import os
import struct
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


def logged_at(table, column: str, timeline: str) -> list[int]:
    """The times at which `column` has a non-null cell, ascending, without repeats."""
    if column not in table.column_names:
        raise CheckFailed(f"no column {column}; columns: {table.column_names}")
    times = table.column(timeline).to_pylist()
    cells = table.column(column).to_pylist()
    return sorted({t for t, cell in zip(times, cells) if cell is not None})


def last_index_at(table, column: str, timeline: str, time: int) -> int:
    """The row of the last non-null cell of `column` logged exactly at `time`."""
    if column not in table.column_names:
        raise CheckFailed(f"no column {column}; columns: {table.column_names}")
    times = table.column(timeline).to_pylist()
    cells = table.column(column).to_pylist()
    found = [i for i, (t, cell) in enumerate(zip(times, cells)) if t == time and cell is not None]
    if not found:
        logged = logged_at(table, column, timeline)
        raise CheckFailed(
            f"{column}: nothing logged at {timeline} = {time}; logged at {logged[:20]}"
        )
    return found[-1]


def last_cell_at(table, column: str, timeline: str, time: int) -> object:
    """The last non-null cell of `column` logged exactly at `time` (latest-at wins)."""
    return table.column(column)[last_index_at(table, column, timeline, time)].as_py()


def buffer_type(table, column: str, index: int) -> str:
    """The TensorBuffer variant ("F32", "F64", ...) of a one-tensor cell."""
    tensor = table.column(column)[index].values
    union = tensor.field("buffer")
    code = union.type_codes[0].as_py()
    return union.type[list(union.type.type_codes).index(code)].name


def to_f32(value: float) -> float:
    return struct.unpack("f", struct.pack("f", value))[0]


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
    column = f"{entity}:BarChart:values"
    index = last_index_at(table, column, timeline, time)
    shape, values = tensor_values(
        table.column(column)[index].as_py(), f"{entity} values at {timeline} {time}"
    )
    if shape != [len(values)]:
        raise CheckFailed(f"{entity}: values shape {shape} is not a vector")
    stored = buffer_type(table, column, index)
    if stored == "F32":
        want = [to_f32(v) for v in mu]
    elif stored == "F64":
        want = mu
    else:
        raise CheckFailed(f"{entity}: values stored as {stored}, expected F32 or F64")
    compare(f"{entity} at {timeline} {time}", values, want, tolerance)
    done = [f"{entity} at {timeline} {time}: {len(mu)} values match ({stored})"]

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
        if "history_logged_at" in expected:
            want_times = sorted(int(t) for t in expected["history_logged_at"])
            got = logged_at(table, f"{history}:Tensor:data", timeline)
            if got != want_times:
                raise CheckFailed(
                    f"{history}: logged at {timeline} {got}, expected {want_times}"
                )
            done.append(f"{history} logged at {timeline} {got}")
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

    done += colour_checks(store, schema_text)
    done += time_only_checks(store, schema_text)
    done += series_checks(store, expected.get("series", {}))

    if expected.get("blueprint"):
        done += blueprint_checks(reader, blueprints, store, expected)
    return done


def series_checks(store, series: dict) -> list[str]:
    """Each Scalars series holds exactly the expected (time, value) points."""
    import pyarrow as pa

    done = []
    for entity, points in series.items():
        table = store.reader(index="time", contents=entity).to_arrow_table()
        column = f"{entity}:Scalars:scalars"
        if column not in table.column_names:
            raise CheckFailed(f"{entity}: no scalars; columns: {table.column_names}")
        times = table.column("time").cast(pa.int64()).to_pylist()
        cells = table.column(column).to_pylist()
        got = sorted((t, cell[0]) for t, cell in zip(times, cells) if cell is not None)
        want = sorted((int(t), float(v)) for t, v in points)
        if got != want:
            diff = next(
                (f"#{i}: got {g}, expected {w}" for i, (g, w) in enumerate(zip(got, want)) if g != w),
                "",
            )
            raise CheckFailed(
                f"{entity}: {len(got)} points, expected {len(want)}; first difference {diff}"
            )
        done.append(f"{entity}: {len(got)} (time, value) points match")
    return done


def entities_in(schema_text: str) -> list[str]:
    return sorted(
        {
            line.split("Entity path:", 1)[1].strip()
            for line in schema_text.splitlines()
            if "Entity path:" in line
        }
    )


def colour_checks(store, schema_text: str) -> list[str]:
    """Every track's mu profile has its own fixed (static) colour."""
    profiles = [
        e for e in entities_in(schema_text) if e.startswith("/field/") and e.endswith("/mu")
    ]
    colours = {}
    for entity in profiles:
        static = store.reader(index=None, contents=entity).to_arrow_table()
        column = f"{entity}:BarChart:color"
        if column not in static.column_names or static.num_rows != 1:
            raise CheckFailed(f"{entity}: no static colour ({static.column_names})")
        colours[entity] = static.column(column)[0].as_py()[0]
    if len(set(colours.values())) != len(colours):
        raise CheckFailed(f"tracks share a colour: {colours}")
    return [f"{len(colours)} tracks, {len(colours)} distinct colours"]


def time_only_checks(store, schema_text: str) -> list[str]:
    """Pulses and measurements have rows on `time` and none on `wheel_pass`."""
    series = [
        e for e in entities_in(schema_text) if e.startswith(("/sites/", "/applicator/"))
    ]
    for entity in series:
        on_wheel_pass = store.reader(index="wheel_pass", contents=entity).to_arrow_table()
        if on_wheel_pass.num_rows != 0:
            raise CheckFailed(
                f"{entity}: {on_wheel_pass.num_rows} rows on wheel_pass, expected `time` only"
            )
        if store.reader(index="time", contents=entity).to_arrow_table().num_rows == 0:
            raise CheckFailed(f"{entity}: nothing on the `time` timeline")
    if not series:
        return []
    return [f"{len(series)} pulse/measurement series on `time` only"]


# View classes the 0.36 viewer knows; any other shows "Unknown view class".
KNOWN_VIEW_CLASSES = {
    "2D", "3D", "BarChart", "Dataframe", "Graph", "Map", "StateTimeline",
    "Tensor", "TextDocument", "TextLog", "TimeSeries",
}
PANEL_HIDDEN, PANEL_COLLAPSED = 1, 2
PLAY_FOLLOWING = 3
VIEW_FIT_FILL = 2


def boundary_kinds(range_struct) -> list[tuple[str, str]]:
    """(start, end) boundary kinds of a struct<start: union, end: union> array."""
    kinds = []
    for side in ("start", "end"):
        union = range_struct.field(side)
        names = {code: union.type.field(i).name for i, code in enumerate(union.type.type_codes)}
        kinds.append([names[code] for code in union.type_codes.to_pylist()])
    return list(zip(*kinds))


def blueprint_checks(reader, blueprints, store, expected: dict) -> list[str]:
    """The default layout: what the viewer opens, reached from the viewport.

    - every view has a class the viewer knows;
    - the track's mu profile has a BarChart view of its own, named after its
      rail and band, and no BarChart view mixes entities (one track per view);
    - with check_history: the track's mu_history has a Tensor view stretched
      to fill it, whose name states the colour range the entity carries;
    - every TimeSeries view shows the whole run on `time` (visible range and
      x axis infinite at both ends);
    - the time panel is on `time` and follows the data (opens at the end),
      the blueprint and selection panels are collapsed or hidden.
    """
    import uuid

    if len(blueprints) != 1:
        raise CheckFailed(f"expected 1 blueprint store, found {blueprints}")
    # entity path -> {column: first cell}, and the raw record batches.
    cells: dict[str, dict] = {}
    batches: dict[str, list] = {}
    for chunk in reader.stream(store=blueprints[0]):
        path = str(chunk.entity_path)
        batch = chunk.to_record_batch()
        batches.setdefault(path, []).append(batch)
        for name, column in batch.to_pydict().items():
            for cell in column:
                if cell is not None:
                    cells.setdefault(path, {})[name] = cell

    def component(path: str, name: str):
        value = cells.get(path, {}).get(name)
        if value is None:
            raise CheckFailed(f"blueprint: no {name} at {path}")
        return value

    # Walk the layout from the viewport's root container.
    root = uuid.UUID(bytes=bytes(component("/viewport", "ViewportBlueprint:root_container")[0]))
    views = []
    pending = [f"/container/{root}"]
    while pending:
        path = pending.pop()
        if path.startswith("/view/"):
            views.append(path)
            continue
        for child in component(path, "ContainerBlueprint:contents"):
            pending.append("/" + child.lstrip("/"))
    if not views:
        raise CheckFailed("blueprint: the layout has no views")

    def view_info(path: str) -> tuple[str, str, list[str]]:
        class_ = component(path, "ViewBlueprint:class_identifier")[0]
        name = component(path, "ViewBlueprint:display_name")[0]
        queries = component(f"{path}/ViewContents", "ViewContents:query")
        return class_, name, queries

    infos = {path: view_info(path) for path in views}
    for path, (class_, name, _) in infos.items():
        if class_ not in KNOWN_VIEW_CLASSES:
            raise CheckFailed(f"blueprint: view {name!r} has unknown class {class_!r}")

    rail, band = expected["rail"], expected["band"]
    track = f"{rail} rail ({band.replace('_', ' ')} band)"
    entity = f"/field/{rail}/{band}/mu"
    done = []

    profile = [
        (name, queries)
        for class_, name, queries in infos.values()
        if class_ == "BarChart" and f"+ {entity}" in queries
    ]
    if not profile:
        shown = sorted(q for _, _, qs in infos.values() for q in qs)
        raise CheckFailed(f"no blueprint view shows {entity}; view queries: {shown}")
    for name, queries in profile:
        if not name.startswith(f"{track}: mu"):
            raise CheckFailed(f"blueprint: the view of {entity} is named {name!r}, not {track!r}")
    for class_, name, queries in infos.values():
        if class_ == "BarChart" and (len(queries) != 1 or "*" in queries[0]):
            raise CheckFailed(f"blueprint: bar chart {name!r} shows {queries}, not one track")
    done.append(f"blueprint: {entity} in its own bar chart {profile[0][0]!r}")

    if expected.get("check_history"):
        history = f"/field/{rail}/{band}/mu_history"
        heatmaps = [
            path
            for path, (class_, _, queries) in infos.items()
            if class_ == "Tensor" and f"+ {history}" in queries
        ]
        if not heatmaps:
            raise CheckFailed(f"blueprint: no Tensor view of {history}")
        static = store.reader(index=None, contents=history).to_arrow_table()
        column = f"{history}:Tensor:value_range"
        if column not in static.column_names or static.num_rows != 1:
            raise CheckFailed(f"{history}: no static value range ({static.column_names})")
        low, high = static.column(column)[0].as_py()[0]
        mu = [float(v) for v in expected["mu"]]
        if not low <= min(mu) <= max(mu) <= high:
            raise CheckFailed(f"{history}: colour range [{low}, {high}] misses mu {min(mu)}..{max(mu)}")
        for path in heatmaps:
            name = infos[path][1]
            if f"{low:.2f} → {high:.2f}" not in name:
                raise CheckFailed(f"blueprint: heatmap {name!r} does not state [{low:.2f}, {high:.2f}]")
            fit = component(f"{path}/TensorViewFit", "TensorViewFit:scaling")
            if fit != [VIEW_FIT_FILL]:
                raise CheckFailed(f"blueprint: heatmap {name!r} fit {fit}, expected Fill")
        done.append(f"blueprint: {history} stretched, colour {low:.2f} → {high:.2f} in its name")

    series_views = [path for path, (class_, _, _) in infos.items() if class_ == "TimeSeries"]
    for path in series_views:
        name = infos[path][1]
        axis = batches.get(f"{path}/TimeAxis", [])
        ranges = batches.get(f"{path}/VisibleTimeRanges", [])
        if not axis or not ranges:
            raise CheckFailed(f"blueprint: time series {name!r} has no TimeAxis/VisibleTimeRanges")
        view_range = axis[-1].column("TimeAxis:view_range").values
        if boundary_kinds(view_range) != [("Infinite", "Infinite")]:
            raise CheckFailed(f"blueprint: {name!r} x axis is {boundary_kinds(view_range)}")
        visible = ranges[-1].column("VisibleTimeRanges:ranges").values
        timelines = visible.field("timeline").to_pylist()
        kinds = dict(zip(timelines, boundary_kinds(visible.field("range"))))
        if kinds.get("time") != ("Infinite", "Infinite"):
            raise CheckFailed(f"blueprint: {name!r} visible range on time is {kinds.get('time')}")
    done.append(f"blueprint: {len(series_views)} time series over the whole run")

    timeline = component("/time_panel", "TimePanelBlueprint:timeline")
    play = component("/time_panel", "TimePanelBlueprint:play_state")
    if timeline != ["time"] or play != [PLAY_FOLLOWING]:
        raise CheckFailed(f"blueprint: time panel on {timeline}, play state {play}")
    for panel in ("/blueprint_panel", "/selection_panel"):
        state = component(panel, "PanelBlueprint:state")
        if state[0] not in (PANEL_HIDDEN, PANEL_COLLAPSED):
            raise CheckFailed(f"blueprint: {panel} state {state}, expected collapsed")
    done.append("blueprint: opens following `time`, side panels collapsed")
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
