"""tortwin in Python: the twin of a track section for top-of-rail friction.

The same engine as the ``tortwin`` command line (one Rust library, called
through the extension module ``tortwin._native``)::

    import tortwin

    run = tortwin.replay("recordings/demo_day.mcap")
    run.measurements.to_pandas()     # measured, simulated, residual per measurement
    run.field                        # mu, adhesion, masses per train, rail, band and d_m
    run.summary["rmse"]              # the run's summary (as the command prints it)
    nxt = tortwin.replay("day2.mcap", state_in=run.state)   # carry the state on

    found = tortwin.discover("hidden.mcap")
    found.effects                    # the effects the model was missing

Configurations are a TOML file's path or a dict with the same keys (only
the keys that change the built-in defaults; ``[[effects.generic]]`` is a
list of dicts under ``{"effects": {"generic": [...]}}``). Units are those
of docs/spec/interfaces.md: metres, seconds, kg for the model's masses
(mg and g in the tables, as their column names say), mu and adhesion
dimensionless, times in UTC.

Errors raise :class:`InputError` (bad input: the recording, state,
configuration or arguments; the message names the file and where in it, as
the command line's exit status 2) or :class:`TortwinError` (anything else).
Long runs release the GIL and stop on Ctrl-C (KeyboardInterrupt), leaving
no output file under its final name.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field as dataclass_field
from pathlib import Path
from typing import Any, Union

import pyarrow as pa
import pyarrow.ipc
import tomli_w

from . import _native
from ._native import InputError, TortwinError

__all__ = [
    "ConfigText",
    "Discovery",
    "InputError",
    "Replay",
    "State",
    "TortwinError",
    "calibrate",
    "discover",
    "live",
    "replay",
    "strategy",
    "synth",
]

__version__: str = _native.version()

PathLike = Union[str, "os.PathLike[str]"]
Config = Union[PathLike, Mapping[str, Any], "ConfigText", None]


@dataclass(frozen=True)
class ConfigText:
    """A configuration's TOML text held in memory (read from a URI, say);
    ``name`` stands for it in error messages."""

    text: str
    name: str


def _config(config: Config) -> tuple[str, str, str] | None:
    """A configuration as the extension takes it: ("file", path, path) or
    ("toml", text, name)."""
    if config is None:
        return None
    if isinstance(config, ConfigText):
        return ("toml", config.text, config.name)
    if isinstance(config, Mapping):
        try:
            text = tomli_w.dumps(config)
        except (TypeError, ValueError) as e:
            raise InputError(f"configuration dict: {e}") from None
        return ("toml", text, "dict")
    if isinstance(config, (str, os.PathLike)):
        return ("file", os.fspath(config), os.fspath(config))
    raise TypeError(
        f"config must be a path to a TOML file or a dict, not {type(config).__name__}"
    )


def _table(ipc: bytes) -> pa.Table:
    return pa.ipc.open_stream(ipc).read_all()


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _options(options: Mapping[str, Any]) -> list[str]:
    """Keyword arguments as the command's flags: ``pulse_g=2.5`` is
    ``--pulse-g 2.5``, ``rail_mu_at_end=False`` is ``--rail-mu-at-end
    false``, a list repeats the flag; ``None`` leaves the default."""
    argv: list[str] = []
    for name, value in options.items():
        if value is None:
            continue
        if isinstance(value, (list, tuple)):
            for v in value:
                argv += [_flag(name), str(v)]
        elif isinstance(value, bool):
            argv += [_flag(name), "true" if value else "false"]
        else:
            argv += [_flag(name), os.fspath(value) if isinstance(value, os.PathLike) else str(value)]
    return argv


@dataclass(frozen=True)
class State:
    """The state of a section at the end of a replay (product on every grid
    point of every rail and band, wheel product carried on, the clock): pass
    it as ``state_in`` to replay the next recording of the same section.

    ``json`` is the text ``tortwin replay --state-out`` writes; :meth:`save`
    writes such a file and :meth:`load` reads one."""

    json: str

    def save(self, path: PathLike) -> None:
        """Writes the state as a file the command line reads with ``--state-in``."""
        Path(path).write_text(self.json)

    @classmethod
    def load(cls, path: PathLike) -> "State":
        """Reads a state written by :meth:`save` or ``--state-out``."""
        return cls(Path(path).read_text())


@dataclass(frozen=True)
class Replay:
    """What a replay gives.

    measurements
        One row per measurement of the recording: ``time_utc`` (timestamp,
        UTC), ``index_in_file`` (the message's index), ``site``, ``rail``,
        ``quantity`` (``mu``, ``adhesion`` or ``rail_mu``), ``train_id`` and
        ``axle_index`` (null for tribometer readings), ``measured``,
        ``simulated`` (dimensionless; bit-equal to ``/twin/measurement`` of
        the MCAP output) and ``residual`` (measured - simulated).
    field
        One row per train, rail/band and grid point after the train:
        ``train_id``, ``time_utc`` (the train's last axle leaves),
        ``rail``, ``band``, ``wheel_pass``, ``d_m`` (m along the section),
        ``mu`` and ``adhesion`` (what the train's last wheel saw),
        ``rail_mass_mg`` (product on the rail at the point, mg) and
        ``wheel_mass_mg`` (on the last wheel, mg). ``None`` with
        ``field=False``.
    trains
        One row per train and rail/band: times, direction, speed (m/s),
        axles, mu min/mean/max, the share of the section in and below the
        target band 0.30-0.40, product on the rail (g) and carried out (mg).
    summary
        The run's summary, as ``tortwin replay`` prints it: counts
        (``trains``, ``wheels``, ``contacts``, ``pulses``, ``measurements``,
        ``weather_messages``, ``unknown_topic_messages``), ``rmse`` by
        quantity (``{"mu": {"n": 5136, "rmse": 0.0099}, ...}``, measured vs
        simulated) and ``mass_balance`` in kg (``applied_kg``,
        ``on_rail_end_kg``, ``carried_out_kg``, ``consumed_kg``,
        ``capped_kg``, ...).
    state
        The section's state at the end, for the next recording.
    per_train
        With ``per_train=True``, one row per train and rail counted over
        every contact of the train's wheels: ``wheel_passes``,
        ``in_band_share`` and ``below_band_share`` (share of the contacts,
        every wheel at every grid point, with mu inside / below the target
        band 0.30-0.40), ``carry_on_m`` (m downstream of the applicators
        where at least half of the wheels saw mu in the band), ``pulses`` and
        ``product_g`` (the pulses from the train's entry to the next
        train's, g). The figures of ``tortwin strategy``, per train.
    """

    measurements: pa.Table
    field: pa.Table | None
    trains: pa.Table
    summary: dict[str, Any]
    state: State
    per_train: pa.Table | None = None


def replay(
    recording: PathLike,
    config: Config = None,
    state_in: State | PathLike | None = None,
    *,
    out_mcap: PathLike | None = None,
    out_rrd: PathLike | None = None,
    state_out: PathLike | None = None,
    every_wheel: bool = False,
    line_axle: int = 0,
    field: bool = True,
    per_train: bool = False,
) -> Replay:
    """Replays a recording (MCAP, docs/spec/recording-format.md) through the
    engine, as ``tortwin replay`` does.

    recording
        The recording's path.
    config
        The model: a TOML file's path or a dict of the keys that change the
        built-in defaults (e.g. ``{"product": {"k_m_mg": 150.0}}``, a
        discover ``model.toml``).
    state_in
        Start from a :class:`State` (``Replay.state`` of the previous day) or
        a state file written by ``--state-out``; default: a clean section.
    out_mcap, out_rrd
        Also write the MCAP output (Foxglove) and the rerun recording, as
        the command line's ``--out-mcap`` and ``--out-rrd``.
    state_out
        Also write the final state to this file.
    every_wheel
        Snapshot the field after every wheel pass in the .rrd (default:
        after every train).
    line_axle
        On a line, the axle whose view the .rrd opens on, with the next one
        (``--line-axle``).
    field
        Keep the field table (the largest: grid points x trains x rails);
        ``False`` leaves ``Replay.field`` as ``None``.
    per_train
        Count every train's contacts (``Replay.per_train``).
    """
    argv = ["replay", os.fspath(recording), "--quiet"]
    state_json = None
    if isinstance(state_in, State):
        state_json = state_in.json
    elif state_in is not None:
        argv += ["--state-in", os.fspath(state_in)]
    for flag, value in (
        ("--out-mcap", out_mcap),
        ("--out-rrd", out_rrd),
        ("--state-out", state_out),
    ):
        if value is not None:
            argv += [flag, os.fspath(value)]
    if every_wheel:
        argv.append("--every-wheel")
    argv += ["--line-axle", str(line_axle)]
    summary, state, measurements, field_ipc, trains, per_train_ipc = _native.replay(
        argv, _config(config), state_json, field, per_train
    )
    summary = json.loads(summary)
    summary["rmse"] = {q: {"n": n, "rmse": rmse} for q, n, rmse in summary["rmse"]}
    return Replay(
        measurements=_table(measurements),
        field=_table(field_ipc) if field_ipc is not None else None,
        trains=_table(trains),
        summary=summary,
        state=State(state),
        per_train=_table(per_train_ipc) if per_train_ipc is not None else None,
    )


def live(
    input: PathLike,
    out_dir: PathLike,
    config: Config = None,
    *,
    state_in: PathLike | None = None,
    state_out: PathLike | None = None,
    poll_ms: int | None = None,
    max_delay_s: float | None = None,
    abandon_s: float | None = None,
    idle_exit_s: float | None = None,
    connect: str | bool = False,
    foxglove: str | bool = False,
) -> Iterator[dict[str, Any]]:
    """Follows a recording while a logger writes it, or a folder in which
    its files appear, as ``tortwin live`` does (the same outputs in
    ``out_dir``, the same checkpoint: a follow stopped and started again
    continues), and yields what comes out as it comes, as dicts:

    ``{"kind": "train", ...}``
        A train's rail band once its field is out: ``train_id``,
        ``log_time_ns`` (the train's end), ``rail``, ``band``,
        ``wheel_pass``, ``mu_min`` and ``mu_mean``, ``below_band_m`` and
        ``above_band_m`` (``live --json``'s line).
    ``{"kind": "alert", "log_time_ns", "alert": {...}}``
        An alert raised or cleared (the ``/twin/alert`` message, with its
        evidence).
    ``{"kind": "recording", "recording", "trains", "measurements"}``
        A recording finished (its state is checkpointed).

    The iterator ends with the input: a file at its end, a folder after
    ``idle_exit_s`` without a new file (default: never). Leaving the loop
    (``break``, Ctrl-C, the generator collected) stops the follow as a
    kill would: what was checkpointed stays. ``connect`` (True or a URL)
    streams to a rerun viewer, ``foxglove`` (True or ``"HOST:PORT"``)
    serves the Foxglove app, as ``--connect`` and ``--foxglove`` do. A
    :class:`State` to start from is passed as a file (:meth:`State.save`).
    """
    argv = ["live", os.fspath(input), "--out-dir", os.fspath(out_dir), "--quiet"]
    argv += _options(
        dict(
            state_in=state_in,
            state_out=state_out,
            poll_ms=poll_ms,
            max_delay_s=max_delay_s,
            abandon_s=abandon_s,
            idle_exit_s=idle_exit_s,
        )
    )
    for flag, value in (("--connect", connect), ("--foxglove", foxglove)):
        if value is True:
            argv.append(flag)
        elif value:
            argv += [flag, str(value)]
    follower = _native.live(argv, _config(config))
    try:
        while (line := follower.next()) is not None:
            yield json.loads(line)
    finally:
        follower.close()


def synth(
    out: PathLike,
    *,
    preset: str | None = None,
    days: int = 1,
    seed: int = 1,
    hidden: Iterable[str] = (),
    truth_config: Config = None,
    key: PathLike | None = None,
    **options: Any,
) -> dict[str, Any]:
    """Writes a synthetic recording, as ``tortwin synth`` does, and returns
    its key (what was hidden, counts, the RMSE of the baseline model against
    the truth) with the key file's path under ``"key_path"``.

    out
        The recording to write (MCAP).
    preset
        ``"curve"`` (rails high/low, radius 400 m, the default) or
        ``"tangent"``; or give ``layout``, a line's TOML file
        (``docs/examples/line-10km.toml``), instead.
    days
        Days of traffic.
    seed
        Seed of every random draw: the same arguments give the same bytes.
    hidden
        Effects in the truth model the default model lacks, as the command's
        ``--hidden`` (``"rail_ageing:tau_s=7200"``,
        ``"generic:acts_on=pulse_mass,driver=time,form=step,..."``).
    truth_config
        The truth model: a TOML file's path or a dict.
    key
        Where to write the key (default: ``out`` with ``.key.json``).
    options
        Any other flag of ``tortwin synth --help`` by its name with
        underscores: ``length_m`` (m), ``pulse_g`` (g), ``trains_per_day``,
        ``noise_sigma``, ``outlier_share``, ...
    """
    argv = ["synth", "--out", os.fspath(out), "--quiet"]
    argv += _options({"preset": preset, "days": days, "seed": seed, "key": key})
    argv += _options({"hidden": list(hidden)})
    argv += _options(options)
    report, key_path = _native.synth(argv, _config(truth_config))
    result = json.loads(report)
    result["key_path"] = key_path
    return result


@dataclass(frozen=True)
class Discovery:
    """What ``discover`` found.

    report
        report.json's content: ``effects_found`` (each with ``name``,
        parameters and a sentence), ``rmse_before``/``rmse_after``, the
        ``verdict``, every step's candidates with their BIC, covariates.
    residuals
        One row per measurement: ``time_utc``, ``index_in_file``, ``site``,
        ``rail``, ``quantity``, ``train_id``, ``axle_index``, ``measured``,
        ``residual_before`` (with the starting model), ``residual_after``
        (with the model found) and ``outlier`` (left out of the fits as a
        gross error).
    model_toml
        The model found, as TOML (pass it to :func:`replay` through a file,
        or ``report_dir / "model.toml"``).
    report_dir
        The report's folder (report.md with plots, residuals.rrd), or
        ``None`` when none was asked for.
    """

    report: dict[str, Any]
    residuals: pa.Table
    model_toml: str
    report_dir: Path | None = None
    effects: list[str] = dataclass_field(default_factory=list)

    @property
    def verdict(self) -> str:
        """One paragraph: what was found, or that nothing is missing."""
        return self.report["verdict"]

    @property
    def constants(self) -> list[dict[str, Any]]:
        """The site's constants as the final model has them
        (report.json ``site_constants``): every ``[product]`` constant with
        ``key``, ``default``, ``value``, ``ci95`` (determined constants),
        ``determined``, ``status`` and a ``description``."""
        return self.report["site_constants"]

    @property
    def moved(self) -> dict[str, float]:
        """The constants calibrated away from their reference values, by key
        (``product.mu_d``: value)."""
        start = {c["key"]: c.get("start", c["default"]) for c in self.constants}
        return {c["key"]: c["value"] for c in self.constants if c["value"] != start[c["key"]]}


def discover(
    recording: PathLike,
    config: Config = None,
    *,
    report: PathLike | None = None,
    threads: int | None = None,
    calibrate: bool = True,
    **options: Any,
) -> Discovery:
    """Finds the effects the model misses in a recording with friction
    measurements, as ``tortwin discover`` does (the site's constants
    calibrated first, then residuals, covariates,
    candidate named effects and generic terms fitted by re-running the
    engine, forward selection by BIC and cross-validation).

    recording
        The recording (MCAP).
    config
        The starting model (a path or a dict); its effects are refitted.
    report
        Write the report folder here (report.md, report.json, model.toml,
        residuals.rrd); default: a temporary folder, removed afterwards.
    threads
        Worker threads for the fits (default: one per core).
    calibrate
        Calibrate the site's constants first (step 0, as the command does);
        ``False`` searches effects against ``config``'s constants as they
        are (``--no-calibrate``).
    options
        ``bic_threshold``, ``min_excess_share``, ``unexplained_ratio`` (see
        ``tortwin discover --help``).
    """
    flags = _options({"threads": threads}) + _options(options)
    if not calibrate:
        flags.append("--no-calibrate")
    return _study(_native.discover, "discover", recording, config, report, flags)


def calibrate(
    recording: PathLike,
    config: Config = None,
    *,
    report: PathLike | None = None,
    threads: int | None = None,
) -> Discovery:
    """Calibrates the site's constants on a recording with friction
    measurements, as ``tortwin calibrate`` does: which ``[product]``
    constants the recording determines, their values with 95 % intervals,
    which only in combination (``.constants``, ``.moved``); no effect is
    searched (``.effects`` is empty). ``residuals`` holds every
    measurement's residual before and after the calibration.

    recording
        The recording (MCAP).
    config
        The starting model (a path or a dict): its constants are where the
        calibration starts and what the intervals are compared with.
    report
        Write the report folder here (report.md, report.json, model.toml,
        residuals.rrd); default: a temporary folder, removed afterwards.
    threads
        Worker threads (default: one per core).
    """
    flags = _options({"threads": threads})
    return _study(_native.calibrate, "calibrate", recording, config, report, flags)


def _study(native, command, recording, config, report, flags) -> Discovery:
    """Runs ``tortwin COMMAND`` (discover or calibrate) through ``native``
    with its report in ``report`` (a temporary folder when None)."""
    with tempfile.TemporaryDirectory(prefix=f"tortwin-{command}-") as tmp:
        folder = Path(report) if report is not None else Path(tmp)
        argv = [command, os.fspath(recording), "--report", os.fspath(folder), "--quiet"]
        text, residuals = native(argv + flags, _config(config))
        model_toml = (folder / "model.toml").read_text()
    found = json.loads(text)
    return Discovery(
        report=found,
        residuals=_table(residuals),
        model_toml=model_toml,
        report_dir=Path(report) if report is not None else None,
        effects=[e["name"] for e in found["effects_found"]],
    )


def strategy(
    recording: PathLike | None = None,
    *,
    out: PathLike,
    config: Config = None,
    space: PathLike | None = None,
    method: str | None = None,
    synth: bool = False,
    threads: int | None = None,
    **options: Any,
) -> dict[str, Any]:
    """Evaluates application strategies (pulse mass, interval, applicator
    positions, rails) over a section's traffic, as ``tortwin strategy``
    does, and returns strategy.json's content (every strategy evaluated with
    its share of the section in the target band, carry-on distance in m,
    product per day in g; the Pareto front; the recommendation).

    recording
        The traffic (its own pulses are replaced by each strategy's);
        required unless ``synth=True``.
    out
        The result folder: strategy.json, report.md, recommended.rrd.
    config
        The model (a path or a dict), found effects included.
    space
        The search space and target (TOML file, ``tortwin strategy --help``).
    method
        ``"grid"``, ``"optimiser"`` or ``"auto"``.
    synth
        Generate the traffic instead (``synth_days``, ``synth_seed``, ...
        as options).
    """
    argv = ["strategy", "--out", os.fspath(out), "--quiet"]
    if recording is not None:
        argv.append(os.fspath(recording))
    if synth:
        argv.append("--synth")
    argv += _options({"space": space, "method": method, "threads": threads})
    argv += _options(options)
    path = _native.strategy(argv, _config(config))
    return json.loads(Path(path).read_text())
