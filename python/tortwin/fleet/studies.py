"""calibrate, discover and strategy over all of a section's days, once they
replayed (Ray tasks' bodies): the days merged into one recording, the study
skipped when done with the same inputs, its tables written to the
dataset."""

from __future__ import annotations

import hashlib
import tempfile
import time
from pathlib import Path

import tortwin

from .dataset import FORMAT, _mark_section, _skip_section, _write_constants, _write_discovery, _write_strategy
from .files import _read_bytes, _sha256
from .jobs import DayResult, SectionJob, _config_arg
from .recordings import merge_recordings


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
    with tempfile.TemporaryDirectory(prefix="tortwin-fleet-") as tmp_name:
        tmp = Path(tmp_name)
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
