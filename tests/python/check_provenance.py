#!/usr/bin/env python3
"""Check the provenance tortwin writes into an output, independently of its
Rust code (hashlib, the mcap reader, rerun's RrdReader, json).

Usage:
    check_provenance.py OUTPUT INPUT [CONFIG]

OUTPUT is an .mcap, .rrd or .json (report.json, strategy.json,
provenance.json). Checks that it names INPUT as its first input with
INPUT's size and sha256 (and CONFIG's as the second when given), the tool
and version, a command line, and the effective model configuration as TOML
(in an MCAP also as the attachment `model.toml`, equal to the metadata's).
Prints a JSON summary; exits 0 when all holds, 1 otherwise, 3 when a
package is missing.
"""

import hashlib
import json
import os
import sys
import tomllib

try:
    from mcap.reader import make_reader
except ImportError as err:  # pragma: no cover
    print(f"check_provenance.py: missing Python package ({err})", file=sys.stderr)
    sys.exit(3)


def sha256(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 16), b""):
            h.update(block)
    return h.hexdigest()


def from_pairs(pairs):
    """The flat pairs of an MCAP metadata record or rerun properties, as the
    JSON object shape."""
    inputs = []
    k = 0
    while f"input.{k}.sha256" in pairs:
        inputs.append({"path": pairs[f"input.{k}.path"],
                       "absolute_path": pairs.get(f"input.{k}.absolute_path"),
                       "bytes": int(pairs[f"input.{k}.bytes"]),
                       "sha256": pairs[f"input.{k}.sha256"]})
        k += 1
    return {"tool": pairs.get("tool"), "command_line": pairs.get("command_line"),
            "model_toml": pairs.get("model_toml"), "inputs": inputs}


def read(output, failures):
    if output.endswith(".mcap"):
        with open(output, "rb") as f:
            reader = make_reader(f)
            meta = {m.name: m.metadata for m in reader.iter_metadata()}
            attachments = {a.name: a.data for a in reader.iter_attachments()}
        if "provenance" not in meta:
            failures.append(f"no provenance metadata record (records: {sorted(meta)})")
            return None
        p = from_pairs(meta["provenance"])
        toml_attached = attachments.get("model.toml")
        if toml_attached is None or toml_attached.decode() != p["model_toml"]:
            failures.append("the model.toml attachment differs from the metadata's model_toml")
        return p
    if output.endswith(".rrd"):
        from rerun.experimental import RrdReader
        store = RrdReader(output).store().stream().collect()
        table = store.reader(index=None, contents="/__properties/**").to_arrow_table()
        prefix = "property:provenance:"
        pairs = {}
        for name in table.column_names:
            if name.startswith(prefix):
                values = [v for v in table.column(name).to_pylist() if v]
                if values:
                    pairs[name[len(prefix):]] = values[-1][0]
        if not pairs:
            failures.append(f"no provenance property; columns {table.column_names}")
            return None
        return from_pairs(pairs)
    with open(output) as f:
        doc = json.load(f)
    p = doc.get("provenance", doc)
    if isinstance(p.get("command_line"), list):
        p = dict(p, command_line=" ".join(p["command_line"]))
    return p


def main():
    output, inputs = sys.argv[1], sys.argv[2:]
    failures = []
    p = read(output, failures)
    if p is not None:
        if not (p.get("tool") or "").startswith("tortwin "):
            failures.append(f"tool {p.get('tool')!r}")
        if not p.get("command_line"):
            failures.append("no command line")
        try:
            model = tomllib.loads(p.get("model_toml") or "")
            if "product" not in model:
                failures.append("model_toml has no [product] table")
        except tomllib.TOMLDecodeError as err:
            failures.append(f"model_toml is not TOML: {err}")
        got = p.get("inputs") or []
        if len(got) < len(inputs):
            failures.append(f"{len(got)} inputs named, expected {len(inputs)}")
        for want, have in zip(inputs, got):
            if os.path.realpath(have.get("absolute_path") or "") != os.path.realpath(want):
                failures.append(f"input {have.get('absolute_path')} ({have['path']}) vs {want}")
            if have["sha256"] != sha256(want) or have["bytes"] != os.path.getsize(want):
                failures.append(f"{want}: sha256/size {have['sha256']} {have['bytes']} differ")
    print(json.dumps({"output": output, "failures": failures}))
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
