"""Recordings: a section's consecutive days merged into one recording, the
input of its studies, and a recording of several days cut into one file per
service day. Both are ``tortwin merge`` and ``tortwin split`` (the Rust
library's, streaming: the messages go from file to file as written, never
all in memory)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterable

from tortwin import _native


def merge_recordings(paths: Iterable[str | os.PathLike], out: str | os.PathLike) -> None:
    """One recording of several consecutive days of one section: the first
    day's /section message, then every other message of every day (each
    later day's /section must be the first one's)."""
    _native.merge(["merge", *(os.fspath(p) for p in paths), "--out", os.fspath(out), "--quiet"])


def split_by_day(recording: str | os.PathLike, folder: str | os.PathLike) -> dict[str, Path]:
    """Cuts a recording of several days into one recording per service day,
    ``folder/YYYY-MM-DD.mcap``: a day holds the messages from its first
    train's passage (UTC date) to the next day's first train, so that no
    train is in the section at a cut; each file opens with the /section
    message (logged at the day's first passage). Returns the files by date."""
    days = _native.split(["split", os.fspath(recording), "--out", os.fspath(folder), "--quiet"])
    return {date: Path(path) for date, path in days}
