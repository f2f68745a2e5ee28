"""What the tasks are given and what they give back: a day's job, a
section's study job, their result (a day's carries its end state to the
next day's task), the configuration a job passes to tortwin, and what a
whole run did."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import tortwin

from .manifest import Day


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


@dataclass(frozen=True)
class SectionJob:
    section: str
    days: tuple[Day, ...]
    output: str
    config_text: str | None
    config_name: str | None
    strategy_space: str | None
    threads: int


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
