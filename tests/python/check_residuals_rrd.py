#!/usr/bin/env python3
"""Check discover's residuals.rrd against its report.json.

    check_residuals_rrd.py REPORT_DIR

Requires `rerun-sdk[datafusion]==0.36.3` (as check_rrd.py, whose readers it
uses).

- `rerun rrd verify` passes; one recording with an rrd footer;
- `/finding` (markdown) holds the verdict and every effect found's sentence
  (or says nothing was added);
- every `/residuals/<site>/<rail>/<quantity>` row holds [before, after];
  over all of them the RMSE of "after" is report.json's
  `rmse_after_all_rows` (to 1e-9, relative);
- the residual against the strongest covariate (`/versus/<site>/<rail>/`)
  has points before and after, and a mean line of each;
- the layout: a text view of `/finding`, a 2D view per `/versus/<site>/<rail>`,
  a time series per residual series over the whole recording, the time
  panel on `time` and paused (the viewer opens at the start of the data).

Exit status 0 when all is well, 1 on a failure, 2 when the tools or files
cannot be used.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from check_rrd import CheckFailed, blueprint_cells, entities_in, verify_with_cli  # noqa: E402

PLAY_PAUSED = 1


def check(report_dir: Path) -> list[str]:
    from rerun.experimental import RrdReader

    report = json.loads((report_dir / "report.json").read_text())
    rrd = report_dir / "residuals.rrd"
    verify_with_cli(rrd)
    reader = RrdReader(rrd)
    if len(reader.recordings()) != 1:
        raise CheckFailed(f"{rrd}: expected one recording")
    store = reader.store().stream().collect()
    schema_text = str(store.schema())
    done = []

    finding = store.reader(index=None, contents="/finding").to_arrow_table()
    text = finding.column("/finding:TextDocument:text")[0].as_py()[0]
    if report["verdict"][:60] not in text:
        raise CheckFailed("/finding does not hold the verdict")
    effects = report["effects_found"]
    for effect in effects:
        if effect.get("description") and effect["description"] not in text:
            raise CheckFailed(f"/finding lacks the sentence of {effect['name']}: {effect['description']}")
    if not effects and "Nothing added" not in text:
        raise CheckFailed("/finding does not say that nothing was added")
    done.append(f"/finding: the verdict and {len(effects)} effects' sentences")

    series = [e for e in entities_in(schema_text) if e.startswith("/residuals/")]
    if not series:
        raise CheckFailed("no /residuals/ series")
    squares, count = 0.0, 0
    for entity in series:
        table = store.reader(index="time", contents=entity).to_arrow_table()
        for cell in table.column(f"{entity}:Scalars:scalars").to_pylist():
            if cell is None:
                continue
            # [before, after], or with the site's constants calibrated
            # [before, constants calibrated, after].
            want_len = 3 if report.get("calibration_start") else 2
            if len(cell) != want_len:
                raise CheckFailed(f"{entity}: a row of {len(cell)} values, expected {want_len}")
            squares += cell[-1] ** 2
            count += 1
    rmse = math.sqrt(squares / count)
    want = report["rmse_after_all_rows"]
    if abs(rmse - want) > 1e-9 * max(abs(want), 1e-12):
        raise CheckFailed(f"RMSE after over the residual series {rmse}, report.json {want}")
    done.append(f"{len(series)} residual series, {count} rows, RMSE after {rmse:.5f} as report.json")

    plots = sorted(
        {"/".join(e.split("/")[:4]) for e in entities_in(schema_text) if e.startswith("/versus/")}
    )
    for root in plots:
        for leaf in ("before", "after", "mean_before", "mean_after"):
            if f"{root}/{leaf}" not in schema_text:
                raise CheckFailed(f"{root}: no {leaf}")
    if report["covariates_before"] and not plots:
        raise CheckFailed("no residual against the strongest covariate")
    done.append(f"{len(plots)} residual-against-covariate plots")

    blueprints = reader.blueprints()
    if len(blueprints) != 1:
        raise CheckFailed(f"expected one blueprint store, found {blueprints}")
    cells, _ = blueprint_cells(reader, blueprints[0])
    views = {
        path: (c["ViewBlueprint:class_identifier"][0], cells.get(f"{path}/ViewContents", {}).get("ViewContents:query", []))
        for path, c in cells.items()
        if "ViewBlueprint:class_identifier" in c
    }
    shown = {(cls, q) for cls, queries in views.values() for q in queries}
    if ("TextDocument", "+ /finding") not in shown:
        raise CheckFailed(f"no text view of /finding: {sorted(shown)}")
    for root in plots:
        if ("2D", f"+ {root}/**") not in shown:
            raise CheckFailed(f"no 2D view of {root}")
    for entity in series:
        if ("TimeSeries", f"+ {entity}") not in shown:
            raise CheckFailed(f"no time series view of {entity}")
    panel = cells.get("/time_panel", {})
    if panel.get("TimePanelBlueprint:timeline") != ["time"] or panel.get(
        "TimePanelBlueprint:play_state"
    ) != [PLAY_PAUSED]:
        raise CheckFailed(f"time panel {panel}: expected `time`, paused")
    done.append(f"layout: the finding, {len(plots)} covariate plots, {len(series)} series; paused on time")
    return done


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        done = check(Path(argv[1]))
    except CheckFailed as err:
        print(f"check_residuals_rrd.py: FAILED: {err}", file=sys.stderr)
        return 1
    except (OSError, KeyError, ValueError) as err:
        print(f"check_residuals_rrd.py: {err}", file=sys.stderr)
        return 2
    for line in done:
        print(f"ok: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
