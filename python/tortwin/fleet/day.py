"""One day of one section (a Ray task's body): the day replayed from the
previous day's end state, its tables (and MCAP / .rrd) written to the
dataset, then its end state and the marker that makes a re-run skip it;
skipped when done with the same inputs, not run after a failed day.

The test hook ``TORTWIN_FLEET_CRASH_ONCE`` (see the package's docstring)
is here: the worker replaying that day kills itself the first time."""

from __future__ import annotations

import json
import os
import signal
import tempfile
import time
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc

import tortwin

from .dataset import FORMAT, _rmse_table
from .files import _exists, _is_uri, _join, _put_file, _read_bytes, _sha256, _write_bytes, _write_parquet
from .jobs import DayJob, DayResult, _config_arg


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

    with tempfile.TemporaryDirectory(prefix="tortwin-fleet-") as tmp_name:
        tmp = Path(tmp_name)
        local = _local_copy(job.recording, data, tmp)
        # replay's out_mcap / out_rrd (Any: mypy checks a ** argument
        # against every keyword, the bool ones too).
        outputs: dict[str, Any] = {}
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
        assert t is not None  # replayed with per_train=True
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
