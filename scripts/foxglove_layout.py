#!/usr/bin/env python3
"""Write a Foxglove layout for a tortwin MCAP output.

    python3 scripts/foxglove_layout.py OUT.mcap LAYOUT.json

The layout is built with Foxglove's own `foxglove.layouts` (the
`foxglove-sdk` Python package), from what the output holds:

- a 3D panel on `/foxglove/track` (the section's rails coloured by mu, the
  sites and applicators labelled), seen from above, following the `section`
  frame;
- a plot per measurement site: for each rail and quantity measured there,
  the measured and the simulated value from `/twin/measurement` (message
  path filters on site, rail and quantity);
- the Log panel on `/foxglove/log` (trains, pulses per applicator,
  warnings where a train leaves mu below the target band).

docs/foxglove/tortwin-layout.json is this script's output for the bundled
demo day (`tortwin replay recordings/demo_day.mcap --out-mcap out/demo.mcap`);
tests/cli_foxglove.rs checks that it is current and that every topic it
names is in that output.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

QUANTITY_LABELS = {"mu": "mu", "adhesion": "adhesion T/N", "rail_mu": "rail mu (tribometer)"}


def section_and_measured(mcap_path: Path) -> tuple[dict, dict]:
    """/twin/section, and per site the (rail, quantity) pairs measured there."""
    from mcap.reader import make_reader

    section = None
    measured: dict[str, set] = {}
    with mcap_path.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(
            topics=["/twin/section", "/twin/measurement"]
        ):
            doc = json.loads(message.data)
            if channel.topic == "/twin/section":
                section = doc
            else:
                measured.setdefault(doc["site_id"], set()).add((doc["rail"], doc["quantity"]))
    if section is None:
        raise SystemExit(f"{mcap_path}: no /twin/section message: not a tortwin output")
    return section, measured


def layout(section: dict, measured: dict):
    import foxglove.layouts as fl

    length = float(section["length_m"])
    # The plan's middle and extent (docs/spec/interfaces.md, "The section
    # on a plan": on a curve of radius R it bends to the right).
    radius = section.get("curve_radius_m")
    points = []
    for k in range(101):
        d = length * k / 100
        points.append(
            (d, 0.0) if radius is None else (radius * math.sin(d / radius), radius * math.cos(d / radius) - radius)
        )
    xs, ys = [p[0] for p in points], [p[1] for p in points]
    middle = ((min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2, 0.0)
    extent = max(max(xs) - min(xs), max(ys) - min(ys), 1.0)
    track = fl.ThreeDeePanel(
        title="Track: mu along the section (blue < 0.30 too much product, green band, yellow-red dry)",
        config=fl.ThreeDeeConfig(
            follow_tf="section",
            topics={"/foxglove/track": fl.BaseRendererSceneUpdateTopicSettings(visible=True)},
            camera_state=fl.ThreeDeeCameraState(
                distance=round(1.5 * extent, 1),
                perspective=False,
                phi=0.0,
                target=tuple(round(c, 1) for c in middle),
                theta_offset=0.0,
            ),
        ),
    )
    plots = []
    for site in section["sites"]:
        site_id = site["id"]
        series = []
        for rail, quantity in sorted(measured.get(site_id, ())):
            path = (
                f'/twin/measurement{{site_id=="{site_id}"}}{{rail=="{rail}"}}'
                f'{{quantity=="{quantity}"}}'
            )
            label = f"{rail} rail {QUANTITY_LABELS.get(quantity, quantity)}"
            series.append(fl.PlotSeries(value=f"{path}.measured", label=f"{label}, measured", enabled=True))
            series.append(fl.PlotSeries(value=f"{path}.simulated", label=f"{label}, twin", enabled=True))
        if not series:
            continue
        plots.append(
            fl.TabItem(
                title=f"site {site_id} ({site['position_m']:.0f} m)",
                content=fl.PlotPanel(
                    title=f"Site {site_id}: measured and simulated",
                    config=fl.PlotConfig(paths=series, show_legend=True, x_axis_val="timestamp"),
                ),
            )
        )
    log = fl.LogPanel(
        title="Trains, pulses, warnings",
        config=fl.LogConfig(topic_to_render="/foxglove/log", min_log_level=1),
    )
    right = [fl.SplitItem(proportion=1, content=log)]
    if plots:
        right.insert(0, fl.SplitItem(proportion=1.5, content=fl.TabContainer(tabs=plots, selected_tab_index=0)))
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[
                fl.SplitItem(proportion=1.2, content=track),
                fl.SplitItem(proportion=1, content=fl.SplitContainer(direction="column", items=right)),
            ],
        )
    )


def main(argv: list[str]) -> int:
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    section, measured = section_and_measured(Path(argv[1]))
    text = json.dumps(json.loads(layout(section, measured).to_json()), indent=2, sort_keys=True)
    Path(argv[2]).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
