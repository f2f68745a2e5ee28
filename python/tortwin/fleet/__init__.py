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

The package, a module for each job:

    manifest      the manifest and its checks
    files         files through pyarrow's filesystems (local paths or URIs)
    jobs          what a task is given and what it gives back
    recordings    recordings merged (a section's days) and cut by day (MCAP)
    dataset       the Parquet dataset's tables and the markers of the studies
    day           one day of one section (a Ray task's body)
    studies       calibrate, discover and strategy over a section's days (Ray tasks' bodies)
    tasks         the driver: the Ray tasks, a section's days chained by the state
    summary       the fleet summary (summary.md, summary.json, summary.png)
    cli           the command ``tortwin-fleet`` (also ``python -m tortwin.fleet``)
"""

from __future__ import annotations

from .cli import main
from .dataset import CONSTANTS_SCHEMA, FORMAT, tortwin_effect_text
from .day import replay_day
from .jobs import DayJob, DayResult, FleetRun, SectionJob
from .manifest import RUNS, Day, Manifest, ManifestError, Section, load_manifest
from .recordings import merge_recordings, split_by_day
from .studies import calibrate_section, discover_section, strategy_section
from .summary import BIAS, FAR_FROM_LABORATORY, write_summary
from .tasks import run

__all__ = [
    "BIAS",
    "CONSTANTS_SCHEMA",
    "Day",
    "DayJob",
    "DayResult",
    "FAR_FROM_LABORATORY",
    "FORMAT",
    "FleetRun",
    "Manifest",
    "ManifestError",
    "RUNS",
    "Section",
    "SectionJob",
    "calibrate_section",
    "discover_section",
    "load_manifest",
    "main",
    "merge_recordings",
    "replay_day",
    "run",
    "split_by_day",
    "strategy_section",
    "tortwin_effect_text",
    "write_summary",
]
