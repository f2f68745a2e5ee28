"""The fleet manifest (TOML, its keys in the package's docstring) and its
checks: the sections, each with its days in date order, its model and what
to run; an error names the file and the key."""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

# The standard library reads TOML from Python 3.11; on 3.10 (which the
# package supports) tomli is the same parser under another name.
if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

from .files import _is_uri

RUNS = ("replay", "calibrate", "discover", "strategy")


@dataclass(frozen=True)
class Day:
    date: str
    recording: str


@dataclass(frozen=True)
class Section:
    id: str
    days: tuple[Day, ...]
    config: str | None = None
    run: tuple[str, ...] = ("replay",)
    out_mcap: bool = False
    out_rrd: bool = False
    strategy_space: str | None = None


@dataclass(frozen=True)
class Manifest:
    path: str
    output: str
    sections: tuple[Section, ...]


class ManifestError(ValueError):
    """A manifest that cannot be used; the message names the file and key."""


def _resolve(base: Path, s: str) -> str:
    """A manifest's path relative to its folder; URIs as they are."""
    if _is_uri(s) or os.path.isabs(s):
        return s
    return str((base / s).resolve())


def load_manifest(path: str | os.PathLike) -> Manifest:
    """Reads and checks a fleet manifest (errors name the file and the key)."""
    path = Path(path)
    where = str(path)
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except OSError as e:
        raise ManifestError(f"{where}: cannot read: {e}") from None
    except tomllib.TOMLDecodeError as e:
        raise ManifestError(f"{where}: {e}") from None
    base = path.resolve().parent
    known = {"output", "defaults", "section"}
    for key in doc:
        if key not in known:
            raise ManifestError(f"{where}: unknown key {key!r} (known: {sorted(known)})")
    output = doc.get("output")
    if not isinstance(output, str) or not output:
        raise ManifestError(f"{where}: output: a folder or URI is required")
    defaults = doc.get("defaults", {})
    section_keys = {"id", "days", "config", "run", "out_mcap", "out_rrd", "strategy_space"}
    for key in defaults:
        if key not in section_keys - {"id", "days"}:
            raise ManifestError(f"{where}: defaults.{key}: unknown key")
    sections = []
    seen = set()
    raw_sections = doc.get("section", [])
    if not isinstance(raw_sections, list) or not raw_sections:
        raise ManifestError(f"{where}: section: at least one [[section]] is required")
    for k, raw in enumerate(raw_sections):
        at = f"{where}: section[{k}]"
        merged = {**defaults, **raw}
        for key in merged:
            if key not in section_keys:
                raise ManifestError(f"{at}.{key}: unknown key (known: {sorted(section_keys)})")
        sid = merged.get("id")
        if not isinstance(sid, str) or not sid or "/" in sid or "=" in sid:
            raise ManifestError(f"{at}.id: a name without '/' or '=' is required")
        if sid in seen:
            raise ManifestError(f"{at}.id: {sid!r} appears twice")
        seen.add(sid)
        days_raw = merged.get("days")
        if not isinstance(days_raw, dict) or not days_raw:
            raise ManifestError(f"{at}.days: a table date = recording is required")
        days = []
        for date, recording in days_raw.items():
            date = str(date)
            try:
                time.strptime(date, "%Y-%m-%d")
            except ValueError:
                raise ManifestError(f"{at}.days: {date!r} is not a date YYYY-MM-DD") from None
            if not isinstance(recording, str):
                raise ManifestError(f"{at}.days.{date}: a path or URI is required")
            days.append(Day(date, _resolve(base, recording)))
        days.sort(key=lambda d: d.date)
        run = merged.get("run", ["replay"])
        if not isinstance(run, list) or any(r not in RUNS for r in run):
            raise ManifestError(f"{at}.run: a list of {list(RUNS)}")
        if "replay" not in run:
            run = ["replay", *run]
        for flag in ("out_mcap", "out_rrd"):
            if not isinstance(merged.get(flag, False), bool):
                raise ManifestError(f"{at}.{flag}: true or false")
        config = merged.get("config")
        space = merged.get("strategy_space")
        sections.append(
            Section(
                id=sid,
                days=tuple(days),
                config=_resolve(base, config) if config else None,
                run=tuple(run),
                out_mcap=merged.get("out_mcap", False),
                out_rrd=merged.get("out_rrd", False),
                strategy_space=_resolve(base, space) if space else None,
            )
        )
    return Manifest(path=str(path), output=_resolve(base, output), sections=tuple(sections))
