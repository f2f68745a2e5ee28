"""The driver, ``run``: the manifest on Ray, a task per section and day, a
section's days chained by the state (each day's task takes the previous
day's result), a task per study of a section after its days; the results
gathered, the summary written."""

from __future__ import annotations

import os
import time
from typing import TYPE_CHECKING, Any, cast

from .day import replay_day
from .files import _read_bytes
from .jobs import DayJob, DayResult, FleetRun, SectionJob
from .manifest import Day, Manifest, ManifestError, Section, load_manifest
from .studies import calibrate_section, discover_section, strategy_section
from .summary import write_summary

if TYPE_CHECKING:
    from ray import ObjectRef


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
            # The previous day's ObjectRef[DayResult] for the argument
            # DayResult | None (Ray's typing has ObjectRef invariant).
            previous = day_task.remote(job, cast("ObjectRef[DayResult | None] | None", previous))
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
