#!/usr/bin/env python3
"""Check a tortwin rerun recording (.rrd) against expected values.

    check_rrd.py FILE.rrd EXPECTED.json

Requires the Python package `rerun-sdk[datafusion]==0.36.3` (the version of
the crate's rerun dependency).

1. `rerun rrd verify FILE.rrd` (through `python -m rerun`, the CLI the pip
   package ships) must pass.
2. The file must hold exactly one recording, with an rrd footer (proof that
   the writer closed it), and the timelines `wheel_pass` and `time`.
3. The curve: the track's points (`/curve/mu/tracks/<rail>/<band>`, static
   positions) lie where docs/spec/interfaces.md "The section on a plan"
   puts them, computed here independently: on the arc of radius R + o about
   (0, -R), at arc length d along the centre line (or at (d, o) on tangent
   track), within 1 mm; at the snapshot their class ids are the documented
   mu classes of the expected mu, and the annotation context at `/curve/mu`
   gives every class the documented colour (the stops of "Colour scales",
   interpolated here).
4. The mu profile (`/profiles/mu/<rail>/<band>/mu`) at the snapshot is one
   line through grid points (x = d, y = -mu * length) that stays within
   5e-4 of mu at every grid point.
5. Pulses and site measurements (`/applicator/**`, `/sites/**`) are on the
   `time` timeline only (on `wheel_pass` a train's measurements would stack).
6. With "blueprint": the layout the viewer opens (see `blueprint_checks`).
7. With "line_wheels" (a line): at the snapshot, per rail, the mu that the
   watched axle and the next saw and what rail_mu reads
   (`/line/mu/<rail>/{axle,next_axle,rail_mu}`, y = -mu * length) and the
   axle's tread bands (`/line/tread/<rail>/{F,C,G}`, decades of mg from
   1e-4 to 1e2 over 0.8 * length) are each one line through grid points
   within 5e-4 of mu (5e-3 decades) at every grid point; with "blueprint",
   a 2D view per rail shows each with its profile's frame. Without "rail",
   the section's checks 3-4 are skipped (a line is not on an arc).

EXPECTED.json:

    {
      "rail": "high", "band": "top",       # plain names (no escaping needed)
      "wheel_pass": 16,                    # the snapshot, on the wheel_pass timeline
      "mu": [0.31, 0.30, ...],             # the expected values, one per grid point
      "mu_rounded": 1e-4,                  # optional: mu was rounded to this (a
                                           #   class may then differ at an edge)
      "d_m": [0.0, 1.0, ...],              # the grid
      "section": {"length_m": 100.0, "curve_radius_m": 300.0,   # null on tangent track
                  "rails": ["high", "low"]},
      "check_history": true,               # optional: a block of the track's
                                           #   history was logged at the snapshot
                                           #   and its newest row is mu's classes
      "history_logged_at": [16, 24],       # optional: exactly the wheel_pass values
                                           #   at which the track's history was logged
      "blueprint": true,                   # optional: require a blueprint store
                                           #   laid out as `blueprint_checks` says
      "line_wheels": {                     # optional, a line: the watched axles
        "wheel_pass": 96, "length_m": 4300.0, "d_m": [...],
        "rails": {"right": {"axle": [mu, ...], "next_axle": [...], "rail_mu": [...],
                            "F": [mg, ...], "C": [...], "G": [...]}}
      },
      "series": {                          # optional: per Scalars entity, every
        "/applicator/A1/high": [[t, [v]], ...]   # (time in ns, values) it holds on
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


def logged_at(table, column: str, timeline: str) -> list[int]:
    """The times at which `column` has a non-null cell, ascending, without repeats."""
    if column not in table.column_names:
        raise CheckFailed(f"no column {column}; columns: {table.column_names}")
    times = table.column(timeline).to_pylist()
    cells = table.column(column).to_pylist()
    return sorted({t for t, cell in zip(times, cells) if cell is not None})


def last_cell_at(table, column: str, timeline: str, time: int) -> object:
    """The last non-null cell of `column` logged exactly at `time` (latest-at wins)."""
    if column not in table.column_names:
        raise CheckFailed(f"no column {column}; columns: {table.column_names}")
    times = table.column(timeline).to_pylist()
    cells = table.column(column).to_pylist()
    found = [cell for t, cell in zip(times, cells) if t == time and cell is not None]
    if not found:
        logged = logged_at(table, column, timeline)
        raise CheckFailed(
            f"{column}: nothing logged at {timeline} = {time}; logged at {logged[:20]}"
        )
    return found[-1]


def static_cell(store, entity: str, column: str) -> object:
    table = store.reader(index=None, contents=entity).to_arrow_table()
    if column not in table.column_names or table.num_rows != 1:
        raise CheckFailed(f"{entity}: no static {column} ({table.column_names})")
    return table.column(column)[0].as_py()


def to_f32(value: float) -> float:
    return struct.unpack("f", struct.pack("f", value))[0]


# The documented mu scale (docs/spec/interfaces.md, "Colour scales"),
# written again here from the text: classes 0.01 wide from 0 to 0.80, each
# coloured by the piecewise-linear scale at its middle.
MU_CLASSES = 80
MU_STOPS = [
    (0.00, (25, 30, 100)),
    (0.15, (49, 84, 170)),
    (0.30, (150, 200, 235)),
    (0.30, (0, 140, 70)),
    (0.40, (170, 220, 120)),
    (0.40, (255, 230, 110)),
    (0.50, (250, 150, 60)),
    (0.60, (225, 70, 40)),
    (0.70, (170, 15, 40)),
    (0.80, (100, 0, 30)),
]


def mu_class(mu: float) -> int:
    k = math.floor(mu / 0.01)
    return 1 if k < 0 else min(k + 1, MU_CLASSES)


def mu_colour(mu: float) -> tuple[int, int, int]:
    if mu <= MU_STOPS[0][0]:
        return MU_STOPS[0][1]
    below = max(i for i, (at, _) in enumerate(MU_STOPS) if at <= mu)
    if below + 1 >= len(MU_STOPS):
        return MU_STOPS[-1][1]
    (a, ca), (b, cb) = MU_STOPS[below], MU_STOPS[below + 1]
    t = (mu - a) / (b - a)
    # Round half away from zero, as Rust's f64::round.
    return tuple(int(math.floor(x + (y - x) * t + 0.5)) for x, y in zip(ca, cb))


def class_colour(k: int) -> tuple[int, int, int]:
    return mu_colour((2 * k - 1) / 200)


def plan_offsets(section: dict) -> dict[str, float]:
    """Lateral offset of each rail: the drawn gauge max(L/40, 2 m), the
    rails evenly across it from the left (outside), `high` first and `low`
    last on a curve."""
    gauge = max(section["length_m"] / 40.0, 2.0)
    rails = list(section["rails"])
    if section.get("curve_radius_m") is not None:
        rank = {"high": 0, "low": 2}
        rails.sort(key=lambda r: rank.get(r, 1))
    span = max(len(rails) - 1, 0)
    return {
        rail: (span / 2 - place) * gauge / max(span, 1) for place, rail in enumerate(rails)
    }, gauge


def curve_checks(store, expected: dict) -> list[str]:
    rail, band = expected["rail"], expected["band"]
    section = expected["section"]
    d_m = [float(d) for d in expected["d_m"]]
    offsets, gauge = plan_offsets(section)
    offset = offsets[rail]
    if band != "top":
        offset -= math.copysign(1.0, offset) * gauge / 5
    radius = section.get("curve_radius_m")
    entity = f"/curve/mu/tracks/{rail}/{band}"
    positions = static_cell(store, entity, f"{entity}:Points2D:positions")
    if len(positions) != len(d_m):
        raise CheckFailed(f"{entity}: {len(positions)} points for {len(d_m)} grid points")
    worst = 0.0
    for (x, y), d in zip(positions, d_m):
        if radius is None:
            err = math.hypot(x - d, y - offset)
        else:
            r = math.hypot(x, y + radius)
            arc = math.atan2(x, y + radius) * radius
            err = max(abs(r - (radius + offset)), abs(arc - d))
        worst = max(worst, err)
    if worst > 1e-3:
        raise CheckFailed(f"{entity}: a point is {worst:.4f} m off the documented plan")
    done = [
        f"{entity}: {len(d_m)} points on the "
        + (f"arc of radius {radius} + {offset:.2f} m" if radius else f"line at {offset:.2f} m")
        + f", worst {worst * 1e3:.3f} mm"
    ]

    # The scale: every class's colour in the annotation context.
    context = static_cell(store, "/curve/mu", "/curve/mu:AnnotationContext:context")[0]
    colours = {}
    for entry in context:
        info = entry["class_description"]["info"]
        rgba = info["color"]
        colours[int(info["id"])] = ((rgba >> 24) & 255, (rgba >> 16) & 255, (rgba >> 8) & 255)
    for k in range(1, MU_CLASSES + 1):
        if colours.get(k) != class_colour(k):
            raise CheckFailed(f"/curve/mu: class {k} coloured {colours.get(k)}, documented {class_colour(k)}")
    done.append(f"/curve/mu: {MU_CLASSES} classes coloured as documented")

    # The snapshot's classes.
    mu = [float(v) for v in expected["mu"]]
    rounded = float(expected.get("mu_rounded", 0.0))
    table = store.reader(index="wheel_pass", contents=entity).to_arrow_table()
    ids = last_cell_at(table, f"{entity}:Points2D:class_ids", "wheel_pass", int(expected["wheel_pass"]))
    if len(ids) != len(mu):
        raise CheckFailed(f"{entity}: {len(ids)} class ids for {len(mu)} values")
    for i, (got, m) in enumerate(zip(ids, mu)):
        edge = abs(m * 100 - round(m * 100)) * 0.01 <= rounded
        if got != mu_class(m) and not (edge and abs(got - mu_class(m)) == 1):
            raise CheckFailed(
                f"{entity}[{i}]: class {got} (colour {colours.get(got)}), mu {m} is class {mu_class(m)}"
            )
    done.append(f"{entity} at wheel_pass {expected['wheel_pass']}: {len(mu)} points coloured by mu")

    # The profile line.
    entity = f"/profiles/mu/{rail}/{band}/mu"
    table = store.reader(index="wheel_pass", contents=entity).to_arrow_table()
    strips = last_cell_at(table, f"{entity}:LineStrips2D:strips", "wheel_pass", int(expected["wheel_pass"]))
    length = float(section["length_m"])
    kept = one_line_checks(
        entity, strips, d_m, mu, lambda m: -m * length, 5e-4 + rounded + 1e-6, length, y_slack=rounded
    )
    done.append(f"{entity}: a line through {kept} of {len(mu)} points within 5e-4 of mu")
    return done


def one_line_checks(
    entity: str, strips, d_m: list[float], values: list[float], y_of, tolerance: float, length: float,
    y_slack: float = 0.0,
) -> int:
    """`strips` is one line through grid points at y_of(value) (within
    (1e-6 + y_slack) * length) that stays within `tolerance` of the values
    between them. Returns its points."""
    if len(strips) != 1:
        raise CheckFailed(f"{entity}: {len(strips)} strips, expected one line")
    grid = {to_f32(d): i for i, d in enumerate(d_m)}
    kept = []
    for x, y in strips[0]:
        if x not in grid:
            raise CheckFailed(f"{entity}: point at x = {x} is not a grid point")
        i = grid[x]
        if abs(y - to_f32(y_of(values[i]))) > (1e-6 + y_slack) * length:
            raise CheckFailed(f"{entity}: point {i} at y = {y}, the value there is {values[i]}")
        kept.append(i)
    if not kept or kept[0] != 0 or kept[-1] != len(values) - 1:
        raise CheckFailed(f"{entity}: the line does not run from the first to the last grid point")
    for a, b in zip(kept, kept[1:]):
        for i in range(a, b + 1):
            t = (d_m[i] - d_m[a]) / (d_m[b] - d_m[a])
            between = values[a] + t * (values[b] - values[a])
            if abs(values[i] - between) > tolerance:
                raise CheckFailed(f"{entity}: the line is {abs(values[i] - between):.2e} off at grid point {i}")
    return len(kept)


def line_wheel_checks(store, expected: dict) -> list[str]:
    d_m = [float(d) for d in expected["d_m"]]
    length = float(expected["length_m"])
    wheel_pass = int(expected["wheel_pass"])

    def mu_y(mu: float) -> float:
        return -min(max(mu, -0.05), 0.85) * length

    def decades(mg: float) -> float:
        return math.log10(max(mg, 1e-4))

    def product_y(v: float) -> float:
        return -(min(max(v, -4.0), 2.0) + 4.0) / 6.0 * 0.8 * length

    done = []
    for rail, wheels in expected["rails"].items():
        for name in ("axle", "next_axle", "rail_mu", "F", "C", "G"):
            is_mu = name in ("axle", "next_axle", "rail_mu")
            entity = f"/line/{'mu' if is_mu else 'tread'}/{rail}/{name}"
            values = [float(v) for v in wheels[name]]
            if len(values) != len(d_m):
                raise CheckFailed(f"expected {rail}/{name}: {len(values)} values for {len(d_m)} points")
            if not is_mu:
                values = [decades(v) for v in values]
            table = store.reader(index="wheel_pass", contents=entity).to_arrow_table()
            strips = last_cell_at(table, f"{entity}:LineStrips2D:strips", "wheel_pass", wheel_pass)
            if is_mu:
                kept = one_line_checks(entity, strips, d_m, values, mu_y, 5e-4 + 1e-6, length)
            else:
                kept = one_line_checks(entity, strips, d_m, values, product_y, 5e-3 + 1e-6, length)
            done.append(f"{entity} at wheel_pass {wheel_pass}: a line through {kept} of {len(d_m)} points")
    return done


def history_checks(store, expected: dict) -> list[str]:
    rail, band = expected["rail"], expected["band"]
    root = f"/history/{rail}/{band}"
    schema_text = str(store.schema())
    blocks = [e for e in entities_in(schema_text) if e.startswith(root + "/block_")]
    if not blocks:
        raise CheckFailed(f"no history blocks under {root}")
    column = "SegmentationImage:buffer"
    times = set()
    found = None
    wheel_pass = int(expected["wheel_pass"])
    for block in blocks:
        table = store.reader(index="wheel_pass", contents=block).to_arrow_table()
        name = f"{block}:{column}"
        at = logged_at(table, name, "wheel_pass")
        times.update(at)
        if wheel_pass in at:
            found = (block, table)
    done = []
    if "history_logged_at" in expected:
        want = sorted(int(t) for t in expected["history_logged_at"])
        if sorted(times) != want:
            raise CheckFailed(f"{root}: logged at wheel_pass {sorted(times)}, expected {want}")
        done.append(f"{root}: logged at {sorted(times)}")
    if expected.get("check_history"):
        if found is None:
            raise CheckFailed(f"{root}: nothing logged at wheel_pass {wheel_pass}")
        block, table = found
        buffer = last_cell_at(table, f"{block}:{column}", "wheel_pass", wheel_pass)
        flat = bytes(buffer[0]) if isinstance(buffer[0], (list, bytes)) else bytes(buffer)
        mu = [float(v) for v in expected["mu"]]
        if len(flat) % len(mu):
            raise CheckFailed(f"{block}: {len(flat)} bytes are not rows of {len(mu)}")
        newest = list(flat[-len(mu):])
        rounded = float(expected.get("mu_rounded", 0.0))
        for i, (got, m) in enumerate(zip(newest, mu)):
            edge = abs(m * 100 - round(m * 100)) * 0.01 <= rounded
            if got != mu_class(m) and not (edge and abs(got - mu_class(m)) == 1):
                raise CheckFailed(f"{block}: newest row [{i}] = class {got}, mu {m} is {mu_class(m)}")
        done.append(f"{block} at wheel_pass {wheel_pass}: {len(flat) // len(mu)} rows, newest is mu's classes")
    return done


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

    schema_text = str(store.schema())
    for name in ("wheel_pass", "time"):
        if name not in schema_text:
            raise CheckFailed(f"timeline {name!r} missing; schema:\n{schema_text}")

    done = curve_checks(store, expected) if "rail" in expected else []
    if "line_wheels" in expected:
        done += line_wheel_checks(store, expected["line_wheels"])
    if expected.get("check_history") or "history_logged_at" in expected:
        done += history_checks(store, expected)
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
        got = sorted((t, [float(v) for v in cell]) for t, cell in zip(times, cells) if cell is not None)
        want = sorted((int(t), [float(v) for v in values]) for t, values in points)
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


def boundary_kinds(range_struct) -> list[tuple[str, str]]:
    """(start, end) boundary kinds of a struct<start: union, end: union> array."""
    kinds = []
    for side in ("start", "end"):
        union = range_struct.field(side)
        names = {code: union.type.field(i).name for i, code in enumerate(union.type.type_codes)}
        kinds.append([names[code] for code in union.type_codes.to_pylist()])
    return list(zip(*kinds))


def blueprint_cells(reader, store) -> tuple[dict[str, dict], dict[str, list]]:
    """A blueprint store as {entity path: {column: last non-null cell}}, and
    its record batches per entity path."""
    cells: dict[str, dict] = {}
    batches: dict[str, list] = {}
    for chunk in reader.stream(store=store):
        path = str(chunk.entity_path)
        batch = chunk.to_record_batch()
        batches.setdefault(path, []).append(batch)
        for name, column in batch.to_pydict().items():
            for cell in column:
                if cell is not None:
                    cells.setdefault(path, {})[name] = cell
    return cells, batches


def blueprint_checks(reader, blueprints, store, expected: dict) -> list[str]:
    """The default layout: what the viewer opens, reached from the viewport.

    - every view has a class the viewer knows;
    - 2D views of the curve by mu and by product, of the profiles, and of
      the track's mu history;
    - every TimeSeries view shows the whole run on `time` (visible range and
      x axis infinite at both ends);
    - the time panel is on `time` and follows the data (opens at the end),
      the blueprint and selection panels are collapsed or hidden.
    """
    import uuid

    if len(blueprints) != 1:
        raise CheckFailed(f"expected 1 blueprint store, found {blueprints}")
    # entity path -> {column: first cell}, and the raw record batches.
    cells, batches = blueprint_cells(reader, blueprints[0])

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

    done = []
    wanted = [
        (["+ /curve/mu/**"], "the curve coloured by mu"),
        (["+ /curve/product/**"], "the curve coloured by product"),
        (["+ /profiles/mu/**"], "the mu profiles"),
        (["+ /profiles/product/**"], "the product profiles"),
    ]
    if "rail" in expected:
        rail, band = expected["rail"], expected["band"]
        wanted.append(([f"+ /history/{rail}/{band}/**"], "the track's mu history"))
    for rail in expected.get("line_wheels", {}).get("rails", {}):
        wanted.append(([f"+ /line/mu/{rail}/**", "+ /profiles/mu/frame/**"], f"the watched axles' mu on {rail}"))
        wanted.append(([f"+ /line/tread/{rail}/**", "+ /profiles/product/frame/**"], f"the watched axle's tread on {rail}"))
    for queries_wanted, what in wanted:
        views = [
            name
            for class_, name, queries in infos.values()
            if class_ == "2D" and all(q in queries for q in queries_wanted)
        ]
        if not views:
            shown = sorted(q for _, _, qs in infos.values() for q in qs)
            raise CheckFailed(f"blueprint: no 2D view shows {what} ({queries_wanted}); view queries: {shown}")
        done.append(f"blueprint: {what} in {views[0]!r}")

    if expected.get("line_wheels"):
        # The watched axles' tab opens (a Tabs container's active tab).
        def views_under(path: str) -> list[str]:
            if path.startswith("/view/"):
                return [path]
            found = []
            for child in cells.get(path, {}).get("ContainerBlueprint:contents", []):
                found += views_under("/" + child.lstrip("/"))
            return found

        active = [
            "/" + str(cell[0]).lstrip("/")
            for path, columns in cells.items()
            for name, cell in columns.items()
            if name == "ContainerBlueprint:active_tab"
        ]
        opened = [
            tab for tab in active
            if any(q.startswith("+ /line/") for v in views_under(tab) for q in infos.get(v, ("", "", []))[2])
        ]
        if not opened:
            raise CheckFailed(f"blueprint: no tab of the watched axles is active (active tabs: {active})")
        done.append("blueprint: the watched axles' tab is the active one")

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
