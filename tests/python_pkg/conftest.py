"""Shared helpers of the Python package's tests: the repository, the
command-line binary built from the same workspace, and an MCAP rewriter
(the `mcap` package's own reader and writer) to cut and corrupt recordings."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Callable

import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

REPO = Path(__file__).resolve().parents[2]
REFERENCE = REPO / "tests" / "reference" / "recordings"
RECORDINGS = REPO / "recordings"


@pytest.fixture(scope="session")
def tortwin_bin() -> Path:
    """The `tortwin` binary of this workspace's release build (built if
    missing). The same command as .ci/run's test build, so that there it
    finds everything built: `cargo build --bin tortwin` alone resolves the
    features of arrow and parquet without the Python extension's and the
    tests', and compiled parquet and every tortwin crate again (about 5 of
    pytest's 8 minutes in the clean CI run of 2026-11-27)."""
    subprocess.run(
        ["cargo", "test", "--release", "--workspace", "--no-run", "--quiet"],
        cwd=REPO,
        check=True,
    )
    meta = subprocess.run(
        ["cargo", "metadata", "--format-version", "1", "--no-deps"],
        cwd=REPO,
        check=True,
        capture_output=True,
        text=True,
    )
    return Path(json.loads(meta.stdout)["target_directory"]) / "release" / "tortwin"


def run_cli(binary: Path, *args: str | os.PathLike) -> subprocess.CompletedProcess:
    return subprocess.run(
        [os.fspath(binary), *map(os.fspath, args)], capture_output=True, text=True
    )


def twin_measurements(path: Path) -> dict[int, dict]:
    """/twin/measurement of an MCAP output, by the input message's index."""
    out = {}
    with open(path, "rb") as f:
        for _, _, message in make_reader(f).iter_messages(topics=["/twin/measurement"]):
            m = json.loads(message.data)
            out[m["index_in_file"]] = m
    return out


def rewrite(
    src: Path,
    dst: Path,
    change: Callable[[str, int, int, bytes], bytes | None],
) -> None:
    """Copies a recording message by message; `change(topic, log_time,
    index, data)` returns the data to write, or None to leave it out."""
    with open(src, "rb") as f_in, open(dst, "wb") as f_out:
        writer = Writer(f_out)
        writer.start(profile="", library="tortwin tests")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for index, (schema, channel, message) in enumerate(
            make_reader(f_in).iter_messages(log_time_order=False)
        ):
            data = change(channel.topic, message.log_time, index, message.data)
            if data is None:
                continue
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(
                    schema.name, schema.encoding, schema.data
                )
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(
                    channel.topic,
                    channel.message_encoding,
                    schemas.get(channel.schema_id, 0),
                    dict(channel.metadata),
                )
            writer.add_message(
                channels[channel.id],
                log_time=message.log_time,
                publish_time=message.publish_time,
                data=data,
                sequence=message.sequence,
            )
        writer.finish()
