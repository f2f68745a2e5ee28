"""A network of sections over many days, on Ray: ``tortwin-fleet``.

A fleet manifest (TOML) lists sections, each with its recordings by day
(local paths or URIs pyarrow's filesystems read: ``s3://``, ``gs://``,
``hdfs://``, ``file://``), its model configuration and what to run::

    output = "out/fleet"              # the dataset and the reports (a folder or a URI)

    [defaults]                        # every section's, unless it says otherwise
    run = ["replay"]                  # replay; "calibrate", "discover" and "strategy" over all its days
    out_mcap = false                  # also an MCAP / .rrd per section and day
    out_rrd = false

    [[section]]
    id = "S01"
    config = "configs/S01.toml"       # optional: the model (relative to the manifest)
    run = ["replay", "discover"]
    days = { 2024-04-08 = "S01/2024-04-08.mcap", 2024-04-09 = "S01/2024-04-09.mcap" }

Each section's days are replayed in date order, the state carried from one
day to the next; sections run in parallel as Ray tasks, one task per
section and day, chained by the state. A day already done with the same
recording (sha256), configuration, starting state and tortwin version is
skipped; a task whose worker dies is retried by Ray (``max_retries``); a day
that fails (bad input) stops its section's chain and is reported with its
error; the other sections go on.

The output (``output``, written through pyarrow's filesystems)::

    trains/section=S/date=D/part-0.parquet    per train and rail: contacts in/below the band,
                                              carry-on (m), pulses, product (g)
    rmse/section=S/date=D/part-0.parquet      per site, rail and quantity: n, RMSE, mean residual
    days/section=S/date=D/part-0.parquet      per day: counts, mass balance (g), seconds, input hash
    discover/section=S/part-0.parquet         discover over the section's days: verdict, RMSE
    findings/section=S/part-0.parquet         the effects discover found, one row each
    constants/section=S/study=T/part-0.parquet  the site's constants (calibrate, or discover's
                                              calibration): value, 95 % interval, determined
    strategy/section=S/part-0.parquet         today's application and the recommended one
    mcap/S/D.mcap, rrd/S/D.rrd                with out_mcap / out_rrd
    summary.md, summary.json, summary.png     sections ranked by what needs attention
    _done/S/D.json, _state/S/D.state.json     what makes a re-run skip a day, and its end state

A test hook: the environment variable ``TORTWIN_FLEET_CRASH_ONCE`` =
``SECTION/DATE:MARKER_PATH`` makes the worker replaying that day kill itself
(SIGKILL) the first time (while MARKER_PATH does not exist): a worker lost
mid-task, for the retry tests.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import signal
import sys
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

# The standard library reads TOML from Python 3.11; on 3.10 (which the
# package supports) tomli is the same parser under another name.
if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.fs as pafs
import pyarrow.parquet as pq

import tortwin

RUNS = ("replay", "calibrate", "discover", "strategy")
# A constant calibrated this far from the laboratory's (relative) puts its
# section in the summary's list.
FAR_FROM_LABORATORY = 0.10
# The version of what a day or study writes: part of the key a re-run
# compares, so that a new layout or column is written again.
FORMAT = 2
# A site whose mean residual (measured - simulated) is this far from zero
# and from the median of the section's other sites looks biased (three times
# the noise of a good friction sensor, sigma 0.01).
BIAS = 0.03


# --------------------------------------------------------------------------
# The manifest


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


def _is_uri(s: str) -> bool:
    return "://" in s


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


# --------------------------------------------------------------------------
# Files through pyarrow's filesystems


def _fs(location: str) -> tuple[pafs.FileSystem, str]:
    if _is_uri(location):
        return pafs.FileSystem.from_uri(location)
    return pafs.LocalFileSystem(), os.path.abspath(location)


def _join(root: str, *parts: str) -> str:
    return "/".join([root.rstrip("/"), *parts])


def _read_bytes(location: str) -> bytes:
    fs, path = _fs(location)
    with fs.open_input_stream(path) as f:
        return f.readall()


def _exists(location: str) -> bool:
    fs, path = _fs(location)
    return fs.get_file_info(path).type == pafs.FileType.File


def _write_bytes(location: str, data: bytes) -> None:
    """Writes a file whole: under a temporary name, then moved into place."""
    fs, path = _fs(location)
    fs.create_dir(path.rsplit("/", 1)[0], recursive=True)
    partial = f"{path}.partial-{uuid.uuid4().hex}"
    with fs.open_output_stream(partial) as f:
        f.write(data)
    fs.move(partial, path)


def _put_file(local: Path, location: str) -> None:
    _write_bytes(location, local.read_bytes())


def _write_parquet(location: str, table: pa.Table) -> None:
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, compression="zstd")
    _write_bytes(location, sink.getvalue().to_pybytes())


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


# --------------------------------------------------------------------------
# One day of one section (a Ray task)


@dataclass(frozen=True)
class DayJob:
    section: str
    date: str
    recording: str
    output: str
    config_text: str | None
    config_name: str | None
    out_mcap: bool
    out_rrd: bool


@dataclass
class DayResult:
    section: str
    date: str
    status: str  # "done", "skipped", "failed", "not run"
    error: str | None = None
    state: str | None = field(default=None, repr=False)
    seconds: float = 0.0
    attempt_pid: int | None = None


def _config_arg(job) -> tortwin.Config:
    if job.config_text is None:
        return None
    return tortwin.ConfigText(job.config_text, job.config_name)


def _crash_hook(section: str, date: str) -> None:
    spec = os.environ.get("TORTWIN_FLEET_CRASH_ONCE")
    if not spec:
        return
    which, _, marker = spec.partition(":")
    if which == f"{section}/{date}" and marker and not os.path.exists(marker):
        Path(marker).write_text(str(os.getpid()))
        os.kill(os.getpid(), signal.SIGKILL)


def _local_copy(recording: str, data: bytes, tmp: Path) -> Path:
    if not _is_uri(recording):
        return Path(recording)
    local = tmp / "recording.mcap"
    local.write_bytes(data)
    return local


def _rmse_table(measurements: pa.Table) -> pa.Table:
    if measurements.num_rows == 0:
        return pa.table(
            {
                "site": pa.array([], pa.string()),
                "rail": pa.array([], pa.string()),
                "quantity": pa.array([], pa.string()),
                "n": pa.array([], pa.int64()),
                "rmse": pa.array([], pa.float64()),
                "mean_residual": pa.array([], pa.float64()),
            }
        )
    squared = pc.multiply(measurements["residual"], measurements["residual"])
    t = measurements.select(["site", "rail", "quantity", "residual"]).append_column("sq", squared)
    g = t.group_by(["site", "rail", "quantity"]).aggregate(
        [("residual", "count"), ("sq", "mean"), ("residual", "mean")]
    )
    g = g.sort_by([("site", "ascending"), ("rail", "ascending"), ("quantity", "ascending")])
    return pa.table(
        {
            "site": g["site"],
            "rail": g["rail"],
            "quantity": g["quantity"],
            "n": g["residual_count"],
            "rmse": pc.sqrt(g["sq_mean"]),
            "mean_residual": g["residual_mean"],
        }
    )


def replay_day(job: DayJob, previous: DayResult | None) -> DayResult:
    """Replays one day from the previous day's state (a Ray task's body)."""
    t0 = time.monotonic()
    result = DayResult(job.section, job.date, "done", attempt_pid=os.getpid())
    if previous is not None and previous.status in ("failed", "not run"):
        result.status = "not run"
        result.error = f"day {previous.date} did not finish"
        return result
    state_in = previous.state if previous is not None else None
    done_at = _join(job.output, "_done", job.section, f"{job.date}.json")
    state_at = _join(job.output, "_state", job.section, f"{job.date}.state.json")
    try:
        data = _read_bytes(job.recording)
    except OSError as e:
        result.status, result.error = "failed", f"{job.recording}: cannot read: {e}"
        return result
    key = {
        "recording": job.recording,
        "input_sha256": _sha256(data),
        "config_sha256": _sha256(job.config_text.encode()) if job.config_text else None,
        "state_in_sha256": _sha256(state_in.encode()) if state_in else None,
        "out_mcap": job.out_mcap,
        "out_rrd": job.out_rrd,
        "tortwin": tortwin.__version__,
        "fleet_format": FORMAT,
    }
    try:
        if _exists(done_at) and json.loads(_read_bytes(done_at))["key"] == key:
            result.status = "skipped"
            result.state = _read_bytes(state_at).decode()
            result.seconds = time.monotonic() - t0
            return result
    except (OSError, ValueError, KeyError):
        pass  # an unreadable marker: the day is done again
    _crash_hook(job.section, job.date)

    with tempfile.TemporaryDirectory(prefix="tortwin-fleet-") as tmp:
        tmp = Path(tmp)
        local = _local_copy(job.recording, data, tmp)
        outputs = {}
        if job.out_mcap:
            outputs["out_mcap"] = tmp / "day.mcap"
        if job.out_rrd:
            outputs["out_rrd"] = tmp / "day.rrd"
        try:
            run = tortwin.replay(
                local,
                config=_config_arg(job),
                state_in=tortwin.State(state_in) if state_in else None,
                field=False,
                per_train=True,
                **outputs,
            )
        except tortwin.TortwinError as e:
            # A URI's local copy is named by the URI in the message.
            result.status, result.error = "failed", str(e).replace(str(local), job.recording)
            return result
        part = f"section={job.section}/date={job.date}/part-0.parquet"
        _write_parquet(_join(job.output, "trains", part), run.per_train)
        _write_parquet(_join(job.output, "rmse", part), _rmse_table(run.measurements))
        s = run.summary
        balance = s["mass_balance"]
        t = run.per_train
        weight = pc.cast(t["wheel_passes"], pa.float64())
        weighted = lambda col: pc.sum(pc.multiply(t[col], weight)).as_py() or 0.0
        day_row = {
            # The day's contacts in and below the band (wheel passes x grid
            # points x shares), for the summary without reading every train.
            "wheel_passes": pc.sum(t["wheel_passes"]).as_py() or 0,
            "in_band_passes": weighted("in_band_share"),
            "below_band_passes": weighted("below_band_share"),
            "carry_on_m_mean": pc.mean(t["carry_on_m"]).as_py() if t.num_rows else 0.0,
            "product_g": pc.sum(t["product_g"]).as_py() or 0.0,
            "trains": s["trains"],
            "wheels": s["wheels"],
            "contacts": s["contacts"],
            "pulses": s["pulses"],
            "measurements": s["measurements"],
            "applied_g": balance["applied_kg"] * 1e3,
            "on_rail_end_g": balance["on_rail_end_kg"] * 1e3,
            "carried_out_g": balance["carried_out_kg"] * 1e3,
            "consumed_g": balance["consumed_kg"] * 1e3,
            "seconds": time.monotonic() - t0,
            "input_sha256": key["input_sha256"],
            "recording": job.recording,
        }
        _write_parquet(_join(job.output, "days", part), pa.Table.from_pylist([day_row]))
        if job.out_mcap:
            _put_file(outputs["out_mcap"], _join(job.output, "mcap", job.section, f"{job.date}.mcap"))
        if job.out_rrd:
            _put_file(outputs["out_rrd"], _join(job.output, "rrd", job.section, f"{job.date}.rrd"))
    # The state, then the marker that says the day is done.
    _write_bytes(state_at, run.state.json.encode())
    marker = {"key": key, "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
    _write_bytes(done_at, json.dumps(marker, indent=1).encode())
    result.state = run.state.json
    result.seconds = time.monotonic() - t0
    return result


# --------------------------------------------------------------------------
# Discover and strategy over a section's days (Ray tasks)


def merge_recordings(paths: Iterable[Path], out: Path) -> None:
    """One recording of several consecutive days of one section: the first
    day's /section message, then every other message of every day in order
    (with the `mcap` package's reader and writer)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(out, "wb") as f_out:
        writer = Writer(f_out)
        writer.start(profile="", library=f"tortwin-fleet {tortwin.__version__}")
        schemas: dict[tuple, int] = {}
        channels: dict[tuple, int] = {}
        section_written = False
        for path in paths:
            with open(path, "rb") as f_in:
                for schema, channel, message in make_reader(f_in).iter_messages(log_time_order=True):
                    if channel.topic == "/section":
                        if section_written:
                            continue
                        section_written = True
                    skey = (schema.name, schema.encoding, schema.data) if schema else None
                    if skey is not None and skey not in schemas:
                        schemas[skey] = writer.register_schema(*skey)
                    ckey = (channel.topic, channel.message_encoding, skey)
                    if ckey not in channels:
                        channels[ckey] = writer.register_channel(
                            channel.topic, channel.message_encoding, schemas.get(skey, 0)
                        )
                    writer.add_message(
                        channels[ckey],
                        log_time=message.log_time,
                        publish_time=message.publish_time,
                        data=message.data,
                    )
        writer.finish()


def split_by_day(recording: str | os.PathLike, folder: str | os.PathLike) -> dict[str, Path]:
    """Cuts a recording of several days into one recording per service day,
    ``folder/YYYY-MM-DD.mcap``: a day holds the messages from its first
    train's passage (UTC date) to the next day's first train, so that no
    train is in the section at a cut; each file opens with the /section
    message (logged at the day's first message). Returns the files by date."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    with open(recording, "rb") as f:
        messages = [(s, c, m) for s, c, m in make_reader(f).iter_messages(log_time_order=True)]
    section = [x for x in messages if x[1].topic == "/section"]
    if not section:
        raise ValueError(f"{recording}: no /section message")
    first_of_day: dict[str, int] = {}
    for _, channel, message in messages:
        if channel.topic == "/train/passage":
            date = time.strftime("%Y-%m-%d", time.gmtime(message.log_time // 1_000_000_000))
            first_of_day.setdefault(date, message.log_time)
    if not first_of_day:
        raise ValueError(f"{recording}: no /train/passage message")
    starts = sorted(first_of_day.items(), key=lambda kv: kv[1])
    out: dict[str, Path] = {}
    for k, (date, start) in enumerate(starts):
        end = starts[k + 1][1] if k + 1 < len(starts) else None
        lo = None if k == 0 else start
        day = [
            x for x in messages
            if x[1].topic != "/section"
            and (lo is None or x[2].log_time >= lo)
            and (end is None or x[2].log_time < end)
        ]
        path = folder / f"{date}.mcap"
        with open(path, "wb") as f_out:
            writer = Writer(f_out)
            writer.start(profile="", library=f"tortwin-fleet {tortwin.__version__}")
            schemas: dict[int, int] = {}
            channels: dict[int, int] = {}
            opening = section[0][2].log_time if k == 0 else min(start, day[0][2].log_time)
            for schema, channel, message in [section[0], *day]:
                if schema is not None and schema.id not in schemas:
                    schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                if channel.id not in channels:
                    channels[channel.id] = writer.register_channel(
                        channel.topic, channel.message_encoding, schemas.get(channel.schema_id, 0)
                    )
                t = opening if channel.topic == "/section" else message.log_time
                writer.add_message(channels[channel.id], log_time=t, publish_time=t, data=message.data)
            writer.finish()
        out[date] = path
    return out


@dataclass(frozen=True)
class SectionJob:
    section: str
    days: tuple[Day, ...]
    output: str
    config_text: str | None
    config_name: str | None
    strategy_space: str | None
    threads: int


def _section_inputs(job: SectionJob, tmp: Path) -> tuple[Path, str]:
    """The days merged into one local recording, and a hash of the inputs."""
    h = hashlib.sha256()
    local = []
    for k, day in enumerate(job.days):
        data = _read_bytes(day.recording)
        h.update(data)
        p = tmp / f"day{k}.mcap"
        p.write_bytes(data)
        local.append(p)
    h.update((job.config_text or "").encode())
    h.update(f"{tortwin.__version__} {FORMAT}".encode())
    merged = tmp / f"{job.section}.mcap"
    merge_recordings(local, merged)
    return merged, h.hexdigest()


def _skip_section(job: SectionJob, what: str, key: str) -> bool:
    done_at = _join(job.output, "_done", job.section, f"{what}.json")
    try:
        return _exists(done_at) and json.loads(_read_bytes(done_at))["key"] == key
    except (OSError, ValueError, KeyError):
        return False


def _mark_section(job: SectionJob, what: str, key: str) -> None:
    _write_bytes(_join(job.output, "_done", job.section, f"{what}.json"), json.dumps({"key": key}).encode())


def _section_study(job: SectionJob, days: tuple[DayResult, ...], what: str, extra_key: str, study) -> DayResult:
    """The frame of a study over a section's days (a Ray task's body): not
    run after a failed day; skipped when done with the same inputs; else the
    days merged into one recording for `study(merged, tmp)`, which runs it
    and writes its tables (a TortwinError is the study's failure)."""
    result = DayResult(job.section, f"{job.days[0].date}..{job.days[-1].date}", "done")
    if any(d.status in ("failed", "not run") for d in days):
        result.status, result.error = "not run", "a day did not finish"
        return result
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="tortwin-fleet-") as tmp:
        tmp = Path(tmp)
        merged, key = _section_inputs(job, tmp)
        key += f":{what}:{extra_key}"
        if _skip_section(job, what, key):
            result.status = "skipped"
            return result
        try:
            study(merged, tmp)
        except tortwin.TortwinError as e:
            result.status, result.error = "failed", str(e)
            return result
    _mark_section(job, what, key)
    result.seconds = time.monotonic() - t0
    return result


def discover_section(job: SectionJob, *days: DayResult) -> DayResult:
    """discover over all the section's days, once they replayed (a Ray task)."""

    def study(merged: Path, tmp: Path) -> None:
        found = tortwin.discover(merged, config=_config_arg(job), threads=job.threads)
        _write_discovery(job, found.report)
        _write_constants(job, "discover", found.report)

    return _section_study(job, days, "discover", "", study)


def calibrate_section(job: SectionJob, *days: DayResult) -> DayResult:
    """The site's constants over all the section's days (a Ray task)."""

    def study(merged: Path, tmp: Path) -> None:
        found = tortwin.calibrate(merged, config=_config_arg(job), threads=job.threads)
        _write_constants(job, "calibrate", found.report)

    return _section_study(job, days, "calibrate", "", study)


CONSTANTS_SCHEMA = pa.schema(
    [
        ("key", pa.string()),
        ("default", pa.float64()),
        ("start", pa.float64()),
        ("value", pa.float64()),
        ("ci95_low", pa.float64()),
        ("ci95_high", pa.float64()),
        ("determined", pa.bool_()),
        ("status", pa.string()),
        ("description", pa.string()),
        ("first_date", pa.string()),
        ("last_date", pa.string()),
    ]
)


def _write_constants(job: SectionJob, study: str, report: dict[str, Any]) -> None:
    """report.json's site_constants as a table, one row per constant."""
    rows = []
    for c in report.get("site_constants", []):
        ci = c.get("ci95") or [None, None]
        rows.append(
            {
                "key": c["key"],
                "default": c["default"],
                "start": c.get("start", c["default"]),
                "value": c["value"],
                "ci95_low": ci[0],
                "ci95_high": ci[1],
                "determined": c["determined"],
                "status": c.get("status"),
                "description": c["description"],
                "first_date": job.days[0].date,
                "last_date": job.days[-1].date,
            }
        )
    _write_parquet(
        _join(job.output, "constants", f"section={job.section}/study={study}/part-0.parquet"),
        pa.Table.from_pylist(rows, schema=CONSTANTS_SCHEMA),
    )


def _write_discovery(job: SectionJob, report: dict[str, Any]) -> None:
    part = f"section={job.section}/part-0.parquet"
    _write_parquet(
        _join(job.output, "discover", part),
        pa.Table.from_pylist(
            [
                {
                    "first_date": job.days[0].date,
                    "last_date": job.days[-1].date,
                    "verdict": report["verdict"],
                    "effects": len(report["effects_found"]),
                    "rmse_before": report["rmse_before"],
                    "rmse_after": report["rmse_after"],
                    "noise_estimate": report["noise_estimate"],
                    "measurements": report["measurements"],
                }
            ]
        ),
    )
    rows = []
    for e in report["effects_found"]:
        scope = e.get("scope") or {}
        rows.append(
            {
                "name": e["name"],
                "acts_on": e.get("acts_on"),
                "driver": e.get("driver"),
                "form": e.get("form"),
                "kind": e.get("kind"),
                "applicator": scope.get("applicator"),
                "site": scope.get("site"),
                "rail": scope.get("rail"),
                "quantity": scope.get("quantity"),
                "params": json.dumps(e["params"], sort_keys=True),
                "description": e.get("description") or tortwin_effect_text(e),
            }
        )
    schema = pa.schema(
        [(n, pa.string()) for n in ("name", "acts_on", "driver", "form", "kind", "applicator",
                                    "site", "rail", "quantity", "params", "description")]
    )
    _write_parquet(_join(job.output, "findings", part), pa.Table.from_pylist(rows, schema=schema))


def tortwin_effect_text(effect: dict[str, Any]) -> str:
    """`name (p = v, ...)`, four significant digits, as report.md writes it."""
    params = ", ".join(
        f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in effect["params"].items()
    )
    return f"{effect['name']} ({params})"


def strategy_section(job: SectionJob, *days: DayResult) -> DayResult:
    """strategy over all the section's days' traffic (a Ray task)."""
    try:
        space_text = _read_bytes(job.strategy_space).decode() if job.strategy_space else ""
    except OSError as e:
        return DayResult(job.section, "", "failed", error=f"{job.strategy_space}: cannot read: {e}")

    def study(merged: Path, tmp: Path) -> None:
        space = None
        if job.strategy_space:
            space = tmp / "space.toml"
            space.write_text(space_text)
        result = tortwin.strategy(
            merged, out=tmp / "strategy", config=_config_arg(job), space=space, threads=job.threads
        )
        _write_strategy(job, result)

    return _section_study(job, days, "strategy", _sha256(space_text.encode()), study)


def _write_strategy(job: SectionJob, result: dict[str, Any]) -> None:
    today = result["today"]["figures"]
    rec = result.get("recommended") or {}
    rec_strategy = rec.get("strategy") or {}
    rec_figures = rec.get("figures") or {}
    row = {
        "first_date": job.days[0].date,
        "last_date": job.days[-1].date,
        "today_coverage": today["coverage"],
        "today_below_share": today["below_share"],
        "today_product_g_per_day": today["product_g_per_day"],
        "recommended": rec_strategy.get("description"),
        "recommended_pulse_g": rec_strategy.get("pulse_g"),
        "recommended_every_axles": rec_strategy.get("every_axles"),
        "recommended_coverage": rec_figures.get("coverage"),
        "recommended_below_share": rec_figures.get("below_share"),
        "recommended_product_g_per_day": rec_figures.get("product_g_per_day"),
    }
    _write_parquet(
        _join(job.output, "strategy", f"section={job.section}/part-0.parquet"),
        pa.Table.from_pylist([row]),
    )


# --------------------------------------------------------------------------
# The driver


@dataclass
class FleetRun:
    """What a run did: every day's and every study's result."""

    output: str
    days: list[DayResult]
    studies: list[tuple[str, DayResult]]
    summary: dict[str, Any]
    seconds: float

    def count(self, status: str) -> int:
        return sum(1 for d in self.days if d.status == status)


def _config_of(section: Section) -> tuple[str | None, str | None]:
    if section.config is None:
        return None, None
    try:
        return _read_bytes(section.config).decode(), section.config
    except OSError as e:
        raise ManifestError(f"section {section.id}: config {section.config}: cannot read: {e}") from None


def run(
    manifest: Manifest | str | os.PathLike,
    *,
    max_retries: int = 3,
    runtime_env: dict[str, Any] | None = None,
    summary: bool = True,
) -> FleetRun:
    """Runs the manifest on the Ray cluster this process is connected to
    (``ray.init`` first; without it, a local Ray is started with every core)."""
    import ray

    if not isinstance(manifest, Manifest):
        manifest = load_manifest(manifest)
    if not ray.is_initialized():
        ray.init()
    t0 = time.monotonic()
    options: dict[str, Any] = {"max_retries": max_retries, "num_cpus": 1}
    if runtime_env:
        options["runtime_env"] = runtime_env
    day_task = ray.remote(replay_day).options(**options)
    # discover and strategy run their fits on 2 threads each.
    study_options = {**options, "num_cpus": max(1, min(2, int(ray.cluster_resources().get("CPU", 1))))}
    discover_task = ray.remote(discover_section).options(**study_options)
    calibrate_task = ray.remote(calibrate_section).options(**study_options)
    strategy_task = ray.remote(strategy_section).options(**study_options)

    day_refs: list[tuple[Section, Day, Any]] = []
    study_refs: list[tuple[str, Section, Any]] = []
    for section in manifest.sections:
        config_text, config_name = _config_of(section)
        previous = None
        refs = []
        for day in section.days:
            job = DayJob(
                section=section.id,
                date=day.date,
                recording=day.recording,
                output=manifest.output,
                config_text=config_text,
                config_name=config_name,
                out_mcap=section.out_mcap,
                out_rrd=section.out_rrd,
            )
            previous = day_task.remote(job, previous)
            refs.append(previous)
            day_refs.append((section, day, previous))
        sjob = SectionJob(
            section=section.id,
            days=section.days,
            output=manifest.output,
            config_text=config_text,
            config_name=config_name,
            strategy_space=section.strategy_space,
            threads=study_options["num_cpus"],
        )
        if "calibrate" in section.run:
            study_refs.append(("calibrate", section, calibrate_task.remote(sjob, *refs)))
        if "discover" in section.run:
            study_refs.append(("discover", section, discover_task.remote(sjob, *refs)))
        if "strategy" in section.run:
            study_refs.append(("strategy", section, strategy_task.remote(sjob, *refs)))

    days = []
    failed_sections: dict[str, str] = {}
    for section, day, ref in day_refs:
        try:
            result = ray.get(ref)
        except Exception as e:  # a task that failed after its retries
            result = DayResult(section.id, day.date, "failed", error=f"{type(e).__name__}: {e}")
        if section.id in failed_sections and result.status == "failed":
            result = DayResult(section.id, day.date, "not run", error=failed_sections[section.id])
        if result.status == "failed":
            failed_sections[section.id] = f"day {day.date} did not finish"
        result.state = None  # the states stay in the output, not in the report
        days.append(result)
    studies = []
    for what, section, ref in study_refs:
        try:
            result = ray.get(ref)
        except Exception as e:
            result = DayResult(section.id, "", "failed", error=f"{type(e).__name__}: {e}")
        studies.append((what, result))
    fleet = FleetRun(manifest.output, days, studies, {}, time.monotonic() - t0)
    if summary:
        fleet.summary = write_summary(manifest, fleet)
    return fleet


# --------------------------------------------------------------------------
# The fleet summary


def _dataset(output: str, name: str) -> pa.Table | None:
    fs, path = _fs(output)
    root = f"{path.rstrip('/')}/{name}"
    if fs.get_file_info(root).type != pafs.FileType.Directory:
        return None
    return ds.dataset(root, filesystem=fs, format="parquet", partitioning="hive").to_table()


def write_summary(manifest: Manifest, fleet: FleetRun) -> dict[str, Any]:
    """Ranks the sections by what needs attention and writes summary.md,
    summary.json and summary.png beside the dataset."""
    # The days table (a row per section and day) and the RMSE table (a few
    # rows per day): the summary of a network-year reads no train.
    days_table = _dataset(manifest.output, "days")
    rmse = _dataset(manifest.output, "rmse")
    findings = _dataset(manifest.output, "findings")
    constants = _dataset(manifest.output, "constants")
    # Mean residual per section, site, rail and quantity over the manifest's days.
    wanted = pa.array(sorted(f"{x.id}/{d.date}" for x in manifest.sections for d in x.days))
    if rmse is not None and rmse.num_rows:
        keys = pc.binary_join_element_wise(rmse["section"], pc.cast(rmse["date"], pa.string()), "/")
        r = rmse.filter(pc.is_in(keys, wanted)).to_pandas()
        r["sum_residual"] = r["mean_residual"] * r["n"]
        g = r.groupby(["section", "site", "rail", "quantity"])[["n", "sum_residual"]].sum()
        g["mean"] = g["sum_residual"] / g["n"].clip(lower=1)
        site_means = g.groupby(level="section")
    else:
        import pandas as pd

        site_means = pd.DataFrame(
            columns=["n", "mean"],
            index=pd.MultiIndex.from_tuples([], names=["section", "site", "rail", "quantity"]),
        ).groupby(level="section")
    sections = []
    for section in manifest.sections:
        sid = section.id
        s: dict[str, Any] = {"section": sid, "days": len(section.days), "reasons": []}
        day_results = [d for d in fleet.days if d.section == sid]
        s["days_done"] = sum(d.status in ("done", "skipped") for d in day_results)
        failed = [d for d in day_results if d.status == "failed"]
        s["failed"] = [{"date": d.date, "error": d.error} for d in failed]
        for d in failed:
            s["reasons"].append(f"day {d.date} failed: {d.error}")
        dates = {d.date for d in section.days}
        if days_table is not None:
            d = days_table.filter(pc.equal(days_table["section"], sid))
            d = d.filter(pc.is_in(pc.cast(d["date"], pa.string()), pa.array(sorted(dates))))
            passes = pc.sum(d["wheel_passes"]).as_py() or 0
            if passes:
                s["in_band_share"] = pc.sum(d["in_band_passes"]).as_py() / passes
                s["below_band_share"] = pc.sum(d["below_band_passes"]).as_py() / passes
                s["above_band_share"] = 1.0 - s["in_band_share"] - s["below_band_share"]
                s["carry_on_m"] = pc.mean(d["carry_on_m_mean"]).as_py()
                s["product_g"] = pc.sum(d["product_g"]).as_py()
                if s["in_band_share"] < 0.5:
                    side = "above (dry)" if s["above_band_share"] > s["below_band_share"] else "below (slippery)"
                    s["reasons"].append(
                        f"friction out of band: {100 * (1 - s['in_band_share']):.0f} % of the contacts, mostly {side}"
                    )
        s["applicators"] = []
        s["sensors"] = []
        s["model_findings"] = []
        s["constants_far"] = []
        if findings is not None:
            f = findings.filter(pc.equal(findings["section"], sid)).to_pylist()
            for e in f:
                if e["acts_on"] == "pulse_mass":
                    s["applicators"].append({"applicator": e["applicator"], "finding": e["description"]})
                    s["reasons"].append(f"applicator {e['applicator'] or '(all)'}: {e['description']}")
                elif e["acts_on"] == "measurement":
                    s["sensors"].append({"site": e["site"], "rail": e["rail"], "quantity": e["quantity"],
                                         "finding": e["description"]})
                    s["reasons"].append(f"sensor {e['site']} {e['rail'] or ''} {e['quantity'] or ''}: {e['description']}")
                else:
                    # Physics the section's model lacks: for its configuration.
                    s["model_findings"].append(e["description"])
        if sid in site_means.groups:
            # A biased sensor stands out from the section's other sites; a
            # model error (a clogged nozzle, say) moves them together.
            g = site_means.get_group(sid)
            for (_, site, rail, quantity), row in g.iterrows():
                same = g.xs(quantity, level="quantity")
                others = same[same.index.get_level_values("site") != site]["mean"]
                if row["n"] < 30 or len(others) == 0:
                    continue
                offset = row["mean"] - float(others.median())
                if abs(row["mean"]) >= BIAS and abs(offset) >= BIAS:
                    s["sensors"].append({"site": site, "rail": rail, "quantity": quantity,
                                         "mean_residual": row["mean"], "offset_from_others": offset})
                    s["reasons"].append(
                        f"sensor {site} {rail} {quantity}: reads {offset:+.3f} off the section's "
                        f"other sites (measured - simulated {row['mean']:+.3f} on average)"
                    )
        # Constants calibrated far from the laboratory's: listed after what
        # is broken (applicators, sensors).
        if constants is not None:
            c = constants.filter(pc.equal(constants["section"], sid)).to_pylist()
            # discover's calibration (with the effects found) before calibrate's.
            c.sort(key=lambda r: r["study"] != "discover")
            seen = set()
            for r in c:
                if r["key"] in seen:
                    continue
                seen.add(r["key"])
                change = r["value"] / r["start"] - 1.0 if r["start"] else 0.0
                if abs(change) >= FAR_FROM_LABORATORY:
                    s["constants_far"].append({"key": r["key"], "value": r["value"], "start": r["start"],
                                               "change": change, "determined": r["determined"]})
            if s["constants_far"]:
                s["reasons"].append(
                    "constants far from the laboratory's: "
                    + ", ".join(f"{x['key'].removeprefix('product.')} {x['value']:.4g} ({100 * x['change']:+.0f} %)"
                                for x in s["constants_far"])
                )
        # Attention: failures first, then applicators, sensors, friction.
        s["attention"] = (
            100 * len(s["failed"])
            + 10 * len(s["applicators"])
            + 5 * len({x["site"] for x in s["sensors"]})
            + 2 * bool(s["constants_far"])
            + (1 - s.get("in_band_share", 1.0))
        )
        sections.append(s)
    sections.sort(key=lambda s: (-s["attention"], s["section"]))
    summary = {
        "output": manifest.output,
        "sections": sections,
        "days": {st: fleet.count(st) for st in ("done", "skipped", "failed", "not run")},
        "studies": [
            {"what": what, "section": r.section, "status": r.status, "error": r.error}
            for what, r in fleet.studies
        ],
        "seconds": fleet.seconds,
        "tortwin": tortwin.__version__,
    }
    _write_bytes(_join(manifest.output, "summary.json"), json.dumps(summary, indent=1).encode())
    _write_bytes(_join(manifest.output, "summary.md"), _markdown(summary).encode())
    png = _plot(sections)
    if png is not None:
        _write_bytes(_join(manifest.output, "summary.png"), png)
    return summary


def _markdown(summary: dict[str, Any]) -> str:
    d = summary["days"]
    lines = [
        "# Fleet summary",
        "",
        f"Days: {d['done']} replayed, {d['skipped']} already done, {d['failed']} failed, "
        f"{d['not run']} not run (after a failed day). tortwin {summary['tortwin']}, "
        f"{summary['seconds']:.1f} s.",
        "",
        "Sections by what needs attention (failed days, applicators whose delivery looks wrong, "
        "sensors that look biased, site constants calibrated more than "
        f"{100 * FAR_FROM_LABORATORY:.0f} % from the laboratory's, friction out of the band 0.30-0.40):",
        "",
        "| rank | section | days | in band | below | above | carry-on (m) | product (g) | needs attention | the model misses (discover) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    pct = lambda x: "" if x is None else f"{100 * x:.0f} %"
    for k, s in enumerate(summary["sections"], 1):
        lines.append(
            f"| {k} | {s['section']} | {s['days_done']}/{s['days']} | {pct(s.get('in_band_share'))} | "
            f"{pct(s.get('below_band_share'))} | {pct(s.get('above_band_share'))} | "
            f"{s.get('carry_on_m', 0):.0f} | {s.get('product_g', 0):.1f} | "
            f"{'; '.join(s['reasons']) or '—'} | {'; '.join(s['model_findings']) or '—'} |"
        )
    failed = [x for x in summary["studies"] if x["status"] == "failed"]
    if failed:
        lines += ["", "Studies that failed:", ""]
        lines += [f"- {x['what']} of {x['section']}: {x['error']}" for x in failed]
    lines += ["", "![share of contacts in the band per section](summary.png)", ""]
    return "\n".join(lines)


def _plot(sections: list[dict[str, Any]]) -> bytes | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    import io

    names = [s["section"] for s in sections]
    below = [s.get("below_band_share", 0.0) for s in sections]
    inside = [s.get("in_band_share", 0.0) for s in sections]
    above = [s.get("above_band_share", 0.0) for s in sections]
    fig, ax = plt.subplots(figsize=(max(6, 0.35 * len(names) + 2), 3.6))
    x = range(len(names))
    ax.bar(x, below, color="#3b6fb6", label="below the band")
    ax.bar(x, inside, bottom=below, color="#4caf50", label="in the band")
    ax.bar(x, above, bottom=[b + i for b, i in zip(below, inside)], color="#d9822b", label="above")
    for i, s in enumerate(sections):
        if s["reasons"]:
            ax.text(i, 1.02, "!", ha="center", color="#b00020", fontweight="bold")
    ax.set_xticks(list(x), names, rotation=90 if len(names) > 12 else 0)
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("share of contacts")
    ax.set_title("sections ranked by attention (! = a reason in summary.md)")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()


# --------------------------------------------------------------------------
# The command


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="tortwin-fleet",
        description="Replay, discover and strategy over a fleet of sections and days, on Ray.",
        epilog="Exit status: 0 when every day and study finished, 1 when some failed (the summary "
        "names them), 2 on a bad manifest.",
    )
    parser.add_argument("manifest", help="the fleet manifest (TOML)")
    parser.add_argument(
        "--address",
        default=None,
        help="a Ray cluster to connect to (e.g. 'auto' on a cluster's head node, or "
        "ray://HOST:10001); default: the RAY_ADDRESS environment variable, or a local Ray",
    )
    parser.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local Ray (default: all)")
    parser.add_argument("--max-retries", type=int, default=3, help="retries of a task whose worker died")
    args = parser.parse_args(argv)
    try:
        manifest = load_manifest(args.manifest)
    except ManifestError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    import ray

    if args.address or os.environ.get("RAY_ADDRESS"):
        ray.init(address=args.address, log_to_driver=False)
    else:
        ray.init(num_cpus=args.num_cpus, log_to_driver=False)
    try:
        fleet = run(manifest, max_retries=args.max_retries)
    except ManifestError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    d = fleet.summary["days"]
    print(
        f"fleet {args.manifest}: {len(manifest.sections)} sections, {d['done']} days replayed, "
        f"{d['skipped']} already done, {d['failed']} failed, {d['not run']} not run; "
        f"{fleet.seconds:.1f} s"
    )
    for r in fleet.days:
        if r.status == "failed":
            print(f"  {r.section} {r.date}: {r.error}")
    for what, r in fleet.studies:
        print(f"  {what} {r.section}: {r.status}{': ' + r.error if r.error else ''}")
    top = [s for s in fleet.summary["sections"] if s["reasons"]][:5]
    for s in top:
        print(f"  attention {s['section']}: {'; '.join(s['reasons'])}")
    print(f"summary: {_join(manifest.output, 'summary.md')}")
    failed = d["failed"] + sum(1 for _, r in fleet.studies if r.status == "failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
