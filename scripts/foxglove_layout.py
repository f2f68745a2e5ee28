#!/usr/bin/env python3
"""Write the Foxglove layouts for a tortwin MCAP output.

    python3 scripts/foxglove_layout.py OUT.mcap LAYOUT.json [STUDIO_LAYOUT.json]

One description of the panels, from what the output holds, written in two
formats: LAYOUT.json in Foxglove's own `foxglove.layouts` format (the
`foxglove-sdk` Python package; the current Foxglove app imports it), and
STUDIO_LAYOUT.json in the export format of Foxglove Studio 1.48 and of
Lichtblick (`configById` and a tree of splits; those apps do not read the
other one). The panels:

- a 3D panel on `/foxglove/track` (the section's rails coloured by mu, the
  sites and applicators labelled), seen from above, following the `section`
  frame;
- a plot per measurement site: for each rail and quantity measured there,
  the measured and the simulated value from `/twin/measurement` (message
  path filters on site, rail and quantity);
- the Log panel on `/foxglove/log` (trains, pulses per applicator,
  warnings where a train leaves mu below the target band).

docs/foxglove/tortwin-layout.json and tortwin-layout-studio.json are this
script's output for the bundled demo day (`tortwin replay
recordings/demo_day.mcap --out-mcap out/demo.mcap`); tests/cli_foxglove.rs
checks that they are current and that every topic they name is in that
output.

The 3D view frames the plan as drawn in the output's first `/foxglove/track`
message, its labels included (each about 0.6 of its font size wide per
character and centred on its position): seen from above, orthographic, the
view shows about `distance` metres top to bottom, and a panel about 0.7 as
wide as tall (the layouts' 55 % of a 16:10 window beside the sidebar) shows
0.7 of that across; the distance leaves a tenth more around both. A line
(docs/spec/line.md) is framed the same way.

Studio 1.48 centres its 3D view on `cameraState.targetOffset` and ignores
`target`: the Studio layout puts the plan's middle there (and `target` at
the origin, so that no app adds the two); its far plane is put beyond the
plan. Its plot palette has 7 colours, so every series there sets
its own.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

QUANTITY_LABELS = {"mu": "mu", "adhesion": "adhesion T/N", "rail_mu": "rail mu (tribometer)"}


def section_and_measured(mcap_path: Path) -> tuple[dict, dict]:
    """/twin/section with the plan's box as drawn (`"plan_box"`: x and y
    ranges of the first /foxglove/track's lines and labels), and per site
    the (rail, quantity) pairs measured there."""
    from mcap.reader import make_reader

    section = None
    box = None
    measured: dict[str, set] = {}
    with mcap_path.open("rb") as f:
        for _, channel, message in make_reader(f).iter_messages(
            topics=["/twin/section", "/twin/measurement", "/foxglove/track"]
        ):
            doc = json.loads(message.data)
            if channel.topic == "/twin/section":
                section = doc
            elif channel.topic == "/foxglove/track":
                if box is None:
                    box = plan_box(doc)
            else:
                measured.setdefault(doc["site_id"], set()).add((doc["rail"], doc["quantity"]))
    if section is None:
        raise SystemExit(f"{mcap_path}: no /twin/section message: not a tortwin output")
    section["plan_box"] = box
    return section, measured


# A character of a 3D label is about this share of its font size wide.
CHARACTER_WIDTH = 0.6
# The 3D panel's width over its height in the layouts (55 % of a 16:10
# window beside the app's sidebar).
PANEL_ASPECT = 0.7


def plan_box(scene: dict) -> tuple[tuple[float, float], tuple[float, float]] | None:
    """The x and y ranges of a SceneUpdate's lines and labels (a label
    centred on its position, CHARACTER_WIDTH of its font size wide per
    character, a font size tall)."""
    xs: list[float] = []
    ys: list[float] = []
    for entity in scene.get("entities", []):
        for line in entity.get("lines", []):
            for p in line.get("points", []):
                xs.append(p["x"])
                ys.append(p["y"])
        for text in entity.get("texts", []):
            p = text["pose"]["position"]
            half_w = CHARACTER_WIDTH * text["font_size"] * len(text["text"]) / 2
            half_h = text["font_size"] / 2
            xs += [p["x"] - half_w, p["x"] + half_w]
            ys += [p["y"] - half_h, p["y"] + half_h]
    if not xs:
        return None
    return (min(xs), max(xs)), (min(ys), max(ys))


TRACK_TITLE = "Track: mu along the section (blue < 0.30 too much product, green band, yellow-red dry)"
LOG_TITLE = "Trains, pulses, warnings"
# A colour per series (measured, then twin, per rail and quantity): distinct
# on a light and a dark background, and as many as a site can have series
# (two rails, three quantities, measured and twin: twelve), so that no two
# series of one plot share a colour. Matplotlib's tab10 without its grey
# (the apps' grid), then three saturated ones far from those nine and from
# the greys of axes and text (tests/js/studio/open.js tells series apart by
# colour).
SERIES_COLOURS = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b",
    "#e377c2", "#17becf", "#bcbd22", "#6b6ecf", "#e7ba52", "#ff1493",
]


def describe(section: dict, measured: dict) -> dict:
    """The panels, in neither app's format: the 3D view's centre and size,
    a plot per measurement site (title, series), the log."""
    box = section.get("plan_box")
    if box is None:
        # No train drew the plan: the centre line (docs/spec/interfaces.md,
        # "The section on a plan": on a curve of radius R it bends to the
        # right).
        length = float(section["length_m"])
        radius = section.get("curve_radius_m")
        points = []
        for k in range(101):
            d = length * k / 100
            points.append(
                (d, 0.0) if radius is None else (radius * math.sin(d / radius), radius * math.cos(d / radius) - radius)
            )
        box = (min(p[0] for p in points), max(p[0] for p in points)), (
            min(p[1] for p in points),
            max(p[1] for p in points),
        )
    (x0, x1), (y0, y1) = box
    middle = ((x0 + x1) / 2, (y0 + y1) / 2, 0.0)
    distance = 1.1 * max(y1 - y0, (x1 - x0) / PANEL_ASPECT, 1.0)
    sites = []
    for site in section["sites"]:
        site_id = site["id"]
        series = []
        for rail, quantity in sorted(measured.get(site_id, ())):
            path = (
                f'/twin/measurement{{site_id=="{site_id}"}}{{rail=="{rail}"}}'
                f'{{quantity=="{quantity}"}}'
            )
            label = f"{rail} rail {QUANTITY_LABELS.get(quantity, quantity)}"
            series.append((f"{path}.measured", f"{label}, measured"))
            series.append((f"{path}.simulated", f"{label}, twin"))
        if series:
            sites.append(
                {
                    "id": site_id,
                    "tab": f"site {site_id} ({site['position_m']:.0f} m)",
                    "title": f"Site {site_id}: measured and simulated",
                    "series": series,
                }
            )
    return {
        "middle": tuple(round(c, 1) for c in middle),
        "distance": round(distance, 1),
        "far": round(max(5000.0, 4 * distance), 1),
        "sites": sites,
        "log_topic": "/foxglove/log",
        "track_topic": "/foxglove/track",
    }


def layout(section: dict, measured: dict):
    """The layout in the `foxglove.layouts` format (the current app)."""
    import foxglove.layouts as fl

    d = describe(section, measured)
    track = fl.ThreeDeePanel(
        title=TRACK_TITLE,
        config=fl.ThreeDeeConfig(
            follow_tf="section",
            topics={d["track_topic"]: fl.BaseRendererSceneUpdateTopicSettings(visible=True)},
            camera_state=fl.ThreeDeeCameraState(
                distance=d["distance"],
                perspective=False,
                phi=0.0,
                target=d["middle"],
                theta_offset=0.0,
            ),
        ),
    )
    plots = [
        fl.TabItem(
            title=site["tab"],
            content=fl.PlotPanel(
                title=site["title"],
                config=fl.PlotConfig(
                    paths=[fl.PlotSeries(value=v, label=l, enabled=True) for v, l in site["series"]],
                    show_legend=True,
                    x_axis_val="timestamp",
                ),
            ),
        )
        for site in d["sites"]
    ]
    log = fl.LogPanel(
        title=LOG_TITLE,
        config=fl.LogConfig(topic_to_render=d["log_topic"], min_log_level=1),
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


def studio_layout(section: dict, measured: dict) -> dict:
    """The layout in the export format of Foxglove Studio 1.48 and
    Lichtblick: panel configurations by id (`TYPE!name`), and a tree of
    splits whose leaves are those ids."""
    d = describe(section, measured)
    middle = list(d["middle"])
    config_by_id: dict[str, dict] = {
        "3D!track": {
            "foxglovePanelTitle": TRACK_TITLE,
            "cameraState": {
                "distance": d["distance"],
                "perspective": False,
                "phi": 0.0,
                "thetaOffset": 0.0,
                "target": [0.0, 0.0, 0.0],
                "targetOffset": middle,
                "targetOrientation": [0.0, 0.0, 0.0, 1.0],
                "fovy": 45,
                "near": 0.5,
                "far": d["far"],
            },
            "followTf": "section",
            "followMode": "follow-pose",
            "scene": {},
            "transforms": {},
            "layers": {},
            "topics": {d["track_topic"]: {"visible": True}},
        },
        "RosOut!log": {
            "foxglovePanelTitle": LOG_TITLE,
            "topicToRender": d["log_topic"],
            "minLogLevel": 1,
            "searchTerms": [],
        },
    }
    tabs = []
    for site in d["sites"]:
        plot_id = f"Plot!site{site['id']}"
        config_by_id[plot_id] = {
            "foxglovePanelTitle": site["title"],
            "paths": [
                {
                    "value": v,
                    "label": l,
                    "enabled": True,
                    "timestampMethod": "receiveTime",
                    "color": SERIES_COLOURS[k % len(SERIES_COLOURS)],
                }
                for k, (v, l) in enumerate(site["series"])
            ],
            "showLegend": True,
            "legendDisplay": "floating",
            "showXAxisLabels": True,
            "showYAxisLabels": True,
            "isSynced": True,
            "xAxisVal": "timestamp",
        }
        tabs.append({"title": site["tab"], "layout": plot_id})
    right: object = "RosOut!log"
    if tabs:
        config_by_id["Tab!sites"] = {"activeTabIdx": 0, "tabs": tabs}
        right = {"direction": "column", "first": "Tab!sites", "second": "RosOut!log", "splitPercentage": 60}
    return {
        "configById": config_by_id,
        "globalVariables": {},
        "userNodes": {},
        "linkedGlobalVariables": [],
        "playbackConfig": {"speed": 1},
        "layout": {"direction": "row", "first": "3D!track", "second": right, "splitPercentage": 55},
    }


def main(argv: list[str]) -> int:
    if len(argv) not in (3, 4):
        print(__doc__, file=sys.stderr)
        return 2
    section, measured = section_and_measured(Path(argv[1]))
    text = json.dumps(json.loads(layout(section, measured).to_json()), indent=2, sort_keys=True)
    Path(argv[2]).write_text(text + "\n")
    if len(argv) == 4:
        studio = json.dumps(studio_layout(section, measured), indent=2, sort_keys=True)
        Path(argv[3]).write_text(studio + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
