#!/usr/bin/env python3
"""Check tortwin's Foxglove topics against Foxglove's own schemas.

    check_foxglove.py OUT.mcap [--layout LAYOUT.json]

The schemas are read from the `@foxglove/schemas` npm package that .ci/run
installs into tests/js (`npm ci --prefix tests/js`), through `node`: they
are Foxglove's, not the copies tortwin writes into its files.

- every channel whose schema is named `foxglove.X` has `message_encoding`
  "json", and its schema is the npm package's `X` (equal as JSON);
- every message on such a channel validates against the npm package's
  schema `X` (jsonschema);
- `/foxglove/track` holds SceneUpdates whose line primitives have one colour
  per point, and `/foxglove/log` Logs;
- with --layout (either format: `foxglove.layouts`, or Foxglove Studio
  1.48's and Lichtblick's export with `configById`, whose tree and Tab
  panels must place exactly the panels it configures): every topic the
  layout names (3D topics, the Log panel's topic, the topic of every plot
  path) is a channel of the file, and every
  `{site_id=="..."}` / `{rail=="..."}` filter names a site / rail of
  `/twin/section`.

Exit status 0 when all is well, 1 on a failure, 2 on a usage error, 3 when a
tool is missing (python packages `mcap`, `jsonschema`; `node` and the npm
package).
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
NODE_MODULES = ROOT / "tests" / "js" / "node_modules"


def npm_schemas(names: list[str]) -> dict[str, dict]:
    script = (
        "const s = require(process.argv[1]);"
        "const out = {};"
        "for (const n of process.argv.slice(2)) out[n] = s[n];"
        "process.stdout.write(JSON.stringify(out));"
    )
    module = NODE_MODULES / "@foxglove" / "schemas" / "jsonschema"
    try:
        result = subprocess.run(
            ["node", "-e", script, str(module), *names],
            capture_output=True,
            text=True,
            check=False,
        )
    except FileNotFoundError:
        print("check_foxglove.py: no `node` on PATH", file=sys.stderr)
        sys.exit(3)
    if result.returncode != 0:
        print(
            f"check_foxglove.py: cannot load @foxglove/schemas from {NODE_MODULES} "
            f"(run `npm ci --prefix tests/js`): {result.stderr.strip()}",
            file=sys.stderr,
        )
        sys.exit(3)
    return json.loads(result.stdout)


def panel_topics(kind: str, config: dict, topics: set[str], paths: list[str]) -> None:
    """Adds the topics and plot paths one panel names; `kind` in either
    format's name (the 3D panel is `ThreeDee` or `3D`, the Log panel `Log`
    or `RosOut`)."""
    if kind in ("ThreeDee", "3D"):
        topics.update(config.get("topics", {}))
    elif kind in ("Log", "RosOut"):
        topics.add(config["topicToRender"])
    elif kind == "Plot":
        for series in config.get("paths", []):
            paths.append(series["value"])
            topics.add(re.match(r"^(/[^{.]*)", series["value"]).group(1))


def studio_layout_topics(layout: dict) -> tuple[set[str], list[str]]:
    """Topics and plot paths of a layout in the export format of Foxglove
    Studio 1.48 and Lichtblick (`configById` and a tree of splits); raises
    ValueError where the tree or a Tab panel names a panel without a
    configuration, or a configuration is not placed anywhere."""
    configs = layout["configById"]
    placed: list[str] = []

    def leaves(node):
        if isinstance(node, str):
            placed.append(node)
        elif isinstance(node, dict):
            for key in ("first", "second"):
                if key not in node:
                    raise ValueError(f"a split without {key!r}: {node}")
                leaves(node[key])
        else:
            raise ValueError(f"not a panel id nor a split: {node!r}")

    leaves(layout["layout"])
    for panel_id, config in configs.items():
        if panel_id.split("!")[0] == "Tab":
            for tab in config.get("tabs", []):
                leaves(tab["layout"])
    for panel_id in placed:
        if panel_id not in configs:
            raise ValueError(f"panel {panel_id} is placed but has no configuration")
    for panel_id in configs:
        if panel_id not in placed:
            raise ValueError(f"panel {panel_id} has a configuration but is placed nowhere")
    topics: set[str] = set()
    paths: list[str] = []
    for panel_id, config in configs.items():
        panel_topics(panel_id.split("!")[0], config, topics, paths)
    return topics, paths


def layout_topics(layout: dict) -> tuple[set[str], list[str]]:
    """Topics a layout names, and its plot paths (either format)."""
    if "configById" in layout:
        return studio_layout_topics(layout)
    topics: set[str] = set()
    paths: list[str] = []

    def walk(node):
        if isinstance(node, dict):
            if node.get("type") == "panel":
                panel_topics(node.get("panelType"), node.get("config", {}), topics, paths)
            for value in node.values():
                walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    walk(layout)
    return topics, paths


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("path")
    parser.add_argument("--layout")
    args = parser.parse_args(argv[1:])
    try:
        import jsonschema
        from mcap.reader import make_reader
    except ImportError as err:
        print(f"check_foxglove.py: missing Python package ({err})", file=sys.stderr)
        return 3

    failures: list[str] = []
    messages: dict[str, list] = {}
    schemas: dict[str, tuple[str, dict]] = {}
    section = None
    channels: set[str] = set()
    with open(args.path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            channels.add(channel.topic)
            if channel.topic == "/twin/section":
                section = json.loads(message.data)
            if schema is None or not schema.name.startswith("foxglove."):
                continue
            if channel.message_encoding != "json":
                failures.append(f"{channel.topic}: encoding {channel.message_encoding}")
            schemas[channel.topic] = (schema.name, json.loads(schema.data))
            messages.setdefault(channel.topic, []).append(json.loads(message.data))
        summary = reader.get_summary()
        if summary is not None:
            channels.update(c.topic for c in summary.channels.values())

    names = sorted({name.split(".", 1)[1] for name, _ in schemas.values()})
    official = npm_schemas(names)
    counts = {}
    for topic, (name, embedded) in sorted(schemas.items()):
        short = name.split(".", 1)[1]
        schema = official.get(short)
        if schema is None:
            failures.append(f"{topic}: {name} is not a schema of @foxglove/schemas")
            continue
        if embedded != schema:
            failures.append(f"{topic}: the file's {name} schema differs from @foxglove/schemas'")
        validator = jsonschema.Draft202012Validator(schema)
        bad = 0
        for index, document in enumerate(messages[topic]):
            for error in validator.iter_errors(document):
                bad += 1
                if bad <= 3:
                    where = "/".join(str(p) for p in error.path) or "(root)"
                    failures.append(f"{topic} message {index}: at {where}: {error.message}")
        counts[topic] = (name, len(messages[topic]))

    for update in messages.get("/foxglove/track", []):
        for entity in update["entities"]:
            for line in entity["lines"]:
                if len(line["colors"]) != len(line["points"]):
                    failures.append(
                        f"/foxglove/track {entity['id']}: {len(line['colors'])} colours "
                        f"for {len(line['points'])} points"
                    )
    for topic, name in [("/foxglove/track", "foxglove.SceneUpdate"), ("/foxglove/log", "foxglove.Log")]:
        if counts.get(topic, (None, 0))[0] != name or counts[topic][1] == 0:
            failures.append(f"{topic}: expected {name} messages, found {counts.get(topic)}")

    if args.layout:
        layout = json.loads(Path(args.layout).read_text())
        try:
            topics, paths = layout_topics(layout)
        except (ValueError, KeyError) as err:
            failures.append(f"layout {args.layout}: {err}")
            topics, paths = set(), []
        for topic in sorted(topics - channels):
            failures.append(f"layout names topic {topic}, which the file does not have")
        sites = {s["id"] for s in (section or {}).get("sites", [])}
        rails = set((section or {}).get("rails", []))
        for path in paths:
            for key, value in re.findall(r'\{(\w+)=="([^"]*)"\}', path):
                known = {"site_id": sites, "rail": rails}.get(key)
                if known is not None and value not in known:
                    failures.append(f"layout path {path}: no {key} {value!r} in /twin/section")
        print(f"layout: {len(topics)} topics, {len(paths)} plot paths, all in the file")

    for topic, (name, count) in sorted(counts.items()):
        print(f"{topic}\t{name}\t{count} messages valid")
    for failure in failures:
        print(f"check_foxglove.py: FAILED: {failure}", file=sys.stderr)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
