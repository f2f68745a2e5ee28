"""The Python package against the command line: the same engine, the same
numbers, the same errors (issue 13). Run by .ci/run after `pip install
./python`."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pytest
from mcap.reader import make_reader

import tortwin

# The package supports Python 3.10, where tomllib is tomli.
if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib
from conftest import RECORDINGS, REFERENCE, REPO, rewrite, run_cli, twin_measurements

REFERENCE_CASES = [
    ("curve_2day.mcap", None),
    ("tangent_day.mcap", None),
    ("generic_day.mcap", "generic_day.config.toml"),
]


def bits(column: pa.ChunkedArray) -> list[int]:
    """Doubles as their bit patterns (equal means bit for bit, NaN included)."""
    return column.combine_chunks().view(pa.int64()).to_pylist()


@pytest.mark.parametrize("name,config", REFERENCE_CASES)
def test_replay_equals_the_command_line_bit_for_bit(tmp_path, tortwin_bin, name, config):
    recording = REFERENCE / name
    args = ["replay", recording, "--out-mcap", tmp_path / "cli.mcap", "-q"]
    if config:
        args += ["--config", REFERENCE / config]
    cli = run_cli(tortwin_bin, *args)
    assert cli.returncode == 0, cli.stderr
    expected = twin_measurements(tmp_path / "cli.mcap")

    configs = [None]
    if config:
        # The configuration as a path and as the dict a notebook would write.
        with open(REFERENCE / config, "rb") as f:
            configs = [REFERENCE / config, tomllib.load(f)]
    for cfg in configs:
        run = tortwin.replay(recording, config=cfg)
        table = run.measurements
        assert table.num_rows == len(expected) > 1000
        indices = table["index_in_file"].to_pylist()
        simulated = table["simulated"].to_pylist()
        measured = table["measured"].to_pylist()
        for i, s, m in zip(indices, simulated, measured):
            e = expected[i]
            # JSON in the MCAP keeps every digit: float(repr) is the same double.
            assert s.hex() == float(e["simulated"]).hex(), (name, i, s, e["simulated"])
            assert m == e["measured"]
        residual = pc.subtract(table["measured"], table["simulated"])
        assert bits(residual) == bits(table["residual"])
        assert run.summary["measurements"] == len(expected)


def test_outputs_through_python_equal_the_command_lines(tmp_path, tortwin_bin):
    recording = RECORDINGS / "demo_day.mcap"
    cli = run_cli(
        tortwin_bin, "replay", recording, "--out-mcap", tmp_path / "cli.mcap",
        "--state-out", tmp_path / "cli.state.json", "-q",
    )
    assert cli.returncode == 0, cli.stderr
    run = tortwin.replay(
        recording, out_mcap=tmp_path / "py.mcap", state_out=tmp_path / "py.state.json"
    )
    assert twin_measurements(tmp_path / "py.mcap") == twin_measurements(tmp_path / "cli.mcap")
    assert (tmp_path / "py.state.json").read_text() == (tmp_path / "cli.state.json").read_text()
    assert run.state.json == (tmp_path / "cli.state.json").read_text()
    # The field: one row per train, rail and grid point.
    section = run.summary
    assert run.field.num_rows == section["trains"] * 2 * (run.field.num_rows // (section["trains"] * 2))
    assert set(run.field.column_names) >= {"train_id", "rail", "band", "d_m", "mu", "adhesion",
                                           "rail_mass_mg", "wheel_mass_mg"}
    assert run.trains.num_rows == section["trains"] * 2
    df = run.measurements.to_pandas()
    assert list(df.columns[:5]) == ["time_utc", "index_in_file", "site", "rail", "quantity"]
    assert str(df["time_utc"].dt.tz) == "UTC"


def split(recording: Path, cut_ns: int, first: Path, second: Path) -> None:
    """The recording cut in two at `cut_ns`: the /section message opens both."""
    rewrite(recording, first, lambda topic, t, i, d: d if topic == "/section" or t < cut_ns else None)
    rewrite(recording, second, lambda topic, t, i, d: d if topic == "/section" or t >= cut_ns else None)


def test_a_state_round_trip_equals_one_replay(tmp_path):
    recording = REFERENCE / "curve_2day.mcap"
    whole = tortwin.replay(recording)
    trains = whole.trains.to_pandas().drop_duplicates("train_id")
    starts = trains["time_utc"].astype("int64").to_numpy()
    ends = trains["end_utc"].astype("int64").to_numpy()
    gaps = starts[1:] - ends[:-1]
    k = int(gaps.argmax())
    cut = int(ends[k] + gaps[k] // 2)
    split(recording, cut, tmp_path / "a.mcap", tmp_path / "b.mcap")

    first = tortwin.replay(tmp_path / "a.mcap")
    second = tortwin.replay(tmp_path / "b.mcap", state_in=first.state)
    # The state through a file, as the command line passes it.
    first.state.save(tmp_path / "a.state.json")
    from_file = tortwin.replay(tmp_path / "b.mcap", state_in=tmp_path / "a.state.json")

    assert first.measurements.num_rows > 0 and second.measurements.num_rows > 0
    columns = ["time_utc", "site", "rail", "quantity", "train_id", "axle_index", "measured", "simulated"]
    joined = pa.concat_tables([first.measurements.select(columns), second.measurements.select(columns)])
    assert joined.equals(whole.measurements.select(columns))
    assert bits(joined["simulated"]) == bits(whole.measurements["simulated"])
    assert pa.concat_tables([first.field, second.field]).equals(whole.field)
    assert second.state.json == whole.state.json
    assert from_file.state.json == whole.state.json
    assert from_file.measurements.equals(second.measurements)


def test_a_bad_recording_raises_with_the_command_lines_message(tmp_path, tortwin_bin):
    bad = tmp_path / "bad.mcap"

    def break_the_fifth_passage(topic, t, index, data):
        if topic == "/train/passage":
            break_the_fifth_passage.seen += 1
            if break_the_fifth_passage.seen == 5:
                return data.replace(b'"speed_mps":', b'"speed_mps":"fast","x":', 1)
        return data

    break_the_fifth_passage.seen = 0
    rewrite(RECORDINGS / "demo_day.mcap", bad, break_the_fifth_passage)
    cli = run_cli(tortwin_bin, "replay", bad, "-q")
    assert cli.returncode == 2
    message = cli.stderr.strip().removeprefix("error: ")
    with pytest.raises(tortwin.InputError) as caught:
        tortwin.replay(bad)
    assert str(caught.value) == message
    assert "/train/passage" in message and "log_time" in message, message

    with pytest.raises(tortwin.InputError, match="no_such_key"):
        tortwin.replay(RECORDINGS / "demo_day.mcap", config={"product": {"no_such_key": 1.0}})
    with pytest.raises(tortwin.InputError, match=r"effects\.generic\[0\]\.acts_on"):
        tortwin.replay(
            RECORDINGS / "demo_day.mcap",
            config={"effects": {"generic": [{"acts_on": "nothing", "driver": "time", "form": "exp"}]}},
        )
    missing = tmp_path / "missing.mcap"
    cli = run_cli(tortwin_bin, "replay", missing, "-q")
    with pytest.raises(tortwin.InputError) as caught:
        tortwin.replay(missing)
    assert str(caught.value) == cli.stderr.strip().removeprefix("error: ")
    # Nothing half-written under the output's name.
    with pytest.raises(tortwin.InputError):
        tortwin.replay(bad, out_mcap=tmp_path / "out.mcap")
    assert not (tmp_path / "out.mcap").exists()


def test_discover_names_the_same_effects_as_the_command_line(tmp_path, tortwin_bin):
    recording = RECORDINGS / "tangent_day_ageing.mcap"
    cli = run_cli(tortwin_bin, "discover", recording, "--report", tmp_path / "cli", "-q")
    assert cli.returncode == 0, cli.stderr
    expected = json.loads((tmp_path / "cli" / "report.json").read_text())
    found = tortwin.discover(recording, report=tmp_path / "py")
    assert found.effects == [e["name"] for e in expected["effects_found"]] == ["rail_ageing"]
    assert found.report["effects_found"] == expected["effects_found"]
    assert found.report["rmse_after"] == expected["rmse_after"]
    assert found.verdict == expected["verdict"]
    assert found.model_toml == (tmp_path / "cli" / "model.toml").read_text()
    # The residual table reproduces the report's RMSE over every row.
    after = found.residuals["residual_after"].to_numpy()
    assert abs((after**2).mean() ** 0.5 - expected["rmse_after_all_rows"]) < 1e-12
    # The model found replays through Python from its TOML as a dict.
    model = tomllib.loads(found.model_toml)
    rerun = tortwin.replay(recording, config=model)
    assert rerun.summary["rmse"]["mu"]["rmse"] < 0.0105


def test_calibrate_gives_the_command_lines_site_constants(tmp_path, tortwin_bin):
    """A tangent whose rail gives a dry friction of 0.52, not the
    laboratory's 0.58: calibrate through Python says what the command line
    says, and the interval holds the truth."""
    recording = tmp_path / "site.mcap"
    tortwin.synth(recording, preset="tangent", days=2, seed=36, trains_per_day=24,
                  truth_config={"product": {"mu_d": 0.52}})
    cli = run_cli(tortwin_bin, "calibrate", recording, "--report", tmp_path / "cli", "-q")
    assert cli.returncode == 0, cli.stderr
    expected = json.loads((tmp_path / "cli" / "report.json").read_text())
    found = tortwin.calibrate(recording, report=tmp_path / "py")
    assert found.effects == [] == expected["effects_found"]
    assert found.constants == expected["site_constants"]
    assert found.model_toml == (tmp_path / "cli" / "model.toml").read_text()
    mu_d = next(c for c in found.constants if c["key"] == "product.mu_d")
    assert mu_d["determined"] and mu_d["ci95"][0] <= 0.52 <= mu_d["ci95"][1], mu_d
    assert abs(found.moved["product.mu_d"] - 0.52) < 0.01, found.moved
    assert tomllib.loads(found.model_toml)["product"]["mu_d"] == mu_d["value"]
    # Every measurement's residual before and after.
    after = found.residuals["residual_after"].to_numpy()
    assert abs((after**2).mean() ** 0.5 - expected["rmse_after_all_rows"]) < 1e-12


def test_synth_writes_what_the_command_line_writes(tmp_path, tortwin_bin):
    args = dict(days=1, seed=7, trains_per_day=6, length_m=300.0)
    key = tortwin.synth(tmp_path / "py.mcap", hidden=["rail_ageing:tau_s=7200"], **args)
    cli = run_cli(
        tortwin_bin, "synth", "--out", tmp_path / "cli.mcap", "--days", "1", "--seed", "7",
        "--trains-per-day", "6", "--length-m", "300", "--hidden", "rail_ageing:tau_s=7200", "-q",
    )
    assert cli.returncode == 0, cli.stderr
    assert (tmp_path / "py.mcap").read_bytes() == (tmp_path / "cli.mcap").read_bytes()
    assert Path(key["key_path"]) == tmp_path / "py.key.json"
    with pytest.raises(tortwin.InputError, match="--no-such-flag"):
        tortwin.synth(tmp_path / "x.mcap", no_such_flag=1)


def test_ctrl_c_stops_a_long_job(tmp_path):
    """SIGINT during discover: KeyboardInterrupt within seconds, no report."""
    script = (
        "import sys, tortwin\n"
        "print('started', flush=True)\n"
        f"tortwin.discover({str(RECORDINGS / 'curve_day_all_effects.mcap')!r}, report={str(tmp_path / 'r')!r})\n"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", script], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    assert child.stdout.readline().strip() == "started"
    time.sleep(2.0)
    assert child.poll() is None, "discover ended before the signal"
    sent = time.monotonic()
    child.send_signal(signal.SIGINT)
    _, stderr = child.communicate(timeout=60)
    waited = time.monotonic() - sent
    assert child.returncode != 0
    assert "KeyboardInterrupt" in stderr, stderr
    assert waited < 10, waited
    assert not (tmp_path / "r" / "report.json").exists()


def test_a_replay_lets_other_python_threads_run():
    """The GIL is released while the engine runs: a counting thread goes on."""
    import threading

    counts = [0]
    stop = threading.Event()

    def count():
        while not stop.is_set():
            counts[0] += 1

    thread = threading.Thread(target=count)
    thread.start()
    time.sleep(0.05)
    before = counts[0]
    start = time.monotonic()
    tortwin.replay(REFERENCE / "curve_2day.mcap", field=False)
    during = counts[0] - before
    elapsed = time.monotonic() - start
    stop.set()
    thread.join()
    # A Python loop counts millions a second; with the GIL held for the
    # whole replay it would count only until the call started.
    assert elapsed > 0.05 and during > 20_000 * elapsed, (during, elapsed)


def test_a_line_rrd_opens_on_the_axle_asked_for(tmp_path, tortwin_bin):
    """``line_axle`` reaches the .rrd as ``--line-axle`` does: the watched
    axles' views name axle 4 and 5, and the axle's tread is logged per
    rail, as in the command line's .rrd. (Run where rerun-sdk is installed:
    .ci/run's first Python, not the bare 3.10 one.)"""
    RrdReader = pytest.importorskip("rerun.experimental").RrdReader

    recording = REFERENCE / "line_field.mcap"
    cli = run_cli(
        tortwin_bin, "replay", recording, "--out-rrd", tmp_path / "cli.rrd", "--line-axle", "4", "-q"
    )
    assert cli.returncode == 0, cli.stderr
    tortwin.replay(recording, out_rrd=tmp_path / "py.rrd", line_axle=4, field=False)

    def seen(path):
        reader = RrdReader(path)
        names = set()
        for chunk in reader.stream(store=reader.blueprints()[0]):
            for name, column in chunk.to_record_batch().to_pydict().items():
                if name == "ViewBlueprint:display_name":
                    names.update(v[0] for v in column if v)
        schema = str(reader.store().stream().collect().schema())
        entities = {e for e in ("/line/tread/left/F", "/line/tread/right/G", "/line/mu/right/next_axle") if e in schema}
        return sorted(n for n in names if n.endswith("along d [m]") and "axle" in n), entities

    py, cli = seen(tmp_path / "py.rrd"), seen(tmp_path / "cli.rrd")
    assert py == cli
    assert len(py[0]) == 4 and all("axle 4" in n for n in py[0]), py[0]
    assert len(py[1]) == 3, py[1]


def test_a_line_replays_per_band_as_the_command_line(tmp_path, tortwin_bin):
    """line_field.mcap (docs/spec/line.md's field line): the measurements
    bit for bit as the command line's, and the field table per rail band
    (C, G) equal to its /twin/field messages (which round), null exactly
    where no wheel of the train used the band, as the MCAP's nulls."""
    recording = REFERENCE / "line_field.mcap"
    cli = run_cli(tortwin_bin, "replay", recording, "--out-mcap", tmp_path / "cli.mcap", "-q")
    assert cli.returncode == 0, cli.stderr
    expected = twin_measurements(tmp_path / "cli.mcap")
    run = tortwin.replay(recording)
    table = run.measurements
    assert table.num_rows == len(expected) == 32
    for i, s in zip(table["index_in_file"].to_pylist(), table["simulated"].to_pylist()):
        assert s.hex() == float(expected[i]["simulated"]).hex()

    fields = {}
    with open(tmp_path / "cli.mcap", "rb") as f:
        for _, _, message in make_reader(f).iter_messages(topics=["/twin/field"]):
            m = json.loads(message.data)
            fields[(m["train_id"], m["rail"], m["band"])] = m
    field = run.field
    assert sorted(set(field["band"].to_pylist())) == ["C", "G"]
    assert field.num_rows == len(fields) * 1384
    nulls = 0
    for (train, rail, band), m in fields.items():
        rows = field.filter(
            pc.and_(
                pc.and_(pc.equal(field["train_id"], train), pc.equal(field["rail"], rail)),
                pc.equal(field["band"], band),
            )
        )
        for column in ("mu", "adhesion", "wheel_mass_mg"):
            got = rows[column].to_pylist()
            want = m[column]
            assert [g is None for g in got] == [w is None for w in want], (train, rail, band)
            for g, w in zip(got, want):
                # The MCAP's /twin/field rounds: mu and adhesion to 1e-4,
                # masses to three significant digits (0 below 1e-4 mg).
                if w is None:
                    continue
                if column == "wheel_mass_mg":
                    assert abs(g - w) <= 5e-3 * abs(g) + 1e-4, (train, rail, band, column)
                else:
                    assert abs(g - w) <= 5.000001e-5, (train, rail, band, column)
        nulls += rows["mu"].null_count
    # The low rail's gauge corner is never used, the high rail's only in
    # the curves' rows.
    assert nulls > 0
    assert field.schema.field("mu").nullable


def test_synth_of_a_line_writes_what_the_command_line_writes(tmp_path, tortwin_bin):
    layout = REPO / "docs" / "examples" / "line-10km.toml"
    key = tortwin.synth(tmp_path / "py.mcap", layout=layout, trains_per_day=4, seed=2)
    cli = run_cli(
        tortwin_bin, "synth", "--out", tmp_path / "cli.mcap", "--layout", layout,
        "--trains-per-day", "4", "--seed", "2", "-q",
    )
    assert cli.returncode == 0, cli.stderr
    assert (tmp_path / "py.mcap").read_bytes() == (tmp_path / "cli.mcap").read_bytes()
    assert key["params"]["line"]["line_id"] == "demo-10km"


CLOGGED = (
    "generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,"
    "t0_utc=2024-04-09T00:00:00Z,f=0.3"
)


def test_live_yields_the_lines_the_command_line_prints(tmp_path, tortwin_bin):
    """tortwin.live over a finished 3-day recording with a clogged nozzle:
    every train's rail band and the alert, as `live --json` prints them,
    then the recording; the outputs are the command line's."""
    rec = tmp_path / "rec.mcap"
    tortwin.synth(rec, days=3, seed=3, hidden=[CLOGGED])
    cli = run_cli(tortwin_bin, "live", rec, "--out-dir", tmp_path / "cli", "--json", "-q")
    assert cli.returncode == 0, cli.stderr
    printed = [json.loads(line) for line in cli.stdout.splitlines() if line.startswith("{")]
    got = list(tortwin.live(rec, tmp_path / "py"))
    assert got[-1] == {
        "kind": "recording",
        "recording": str(rec),
        "trains": 120,
        "measurements": got[-1]["measurements"],
    }
    assert got[:-1] == printed
    kinds = [item["kind"] for item in printed]
    assert kinds.count("train") == 240 and kinds.count("alert") == 1
    alert = next(item for item in printed if item["kind"] == "alert")
    assert alert["alert"]["kind"] == "applicator_fade"
    for name in ("rec.2024-04-08.mcap", "rec.2024-04-09.mcap", "rec.2024-04-10.mcap"):
        py, cl = tmp_path / "py" / name, tmp_path / "cli" / name
        with open(py, "rb") as a, open(cl, "rb") as b:
            ours = [(c.topic, m.log_time, m.data) for _, c, m in make_reader(a).iter_messages()]
            theirs = [(c.topic, m.log_time, m.data) for _, c, m in make_reader(b).iter_messages()]
        assert ours == theirs, name


def test_leaving_a_live_loop_stops_the_follow(tmp_path):
    """A folder is followed for ever; breaking out of the loop after its
    first file stops the follower within a poll, its checkpoint kept."""
    folder = tmp_path / "in"
    folder.mkdir()
    tortwin.synth(folder / "a.mcap", days=1, seed=5, trains_per_day=6, length_m=300.0)
    follow = tortwin.live(folder, tmp_path / "out")
    for item in follow:
        if item["kind"] == "recording":
            break
    import threading

    closing = threading.Thread(target=follow.close, daemon=True)
    closing.start()
    closing.join(timeout=10)
    assert not closing.is_alive(), "the follower did not stop"
    checkpoint = json.loads((tmp_path / "out" / "live-checkpoint.json").read_text())
    assert checkpoint["done"] == ["a.mcap"]
    assert (tmp_path / "out" / "a.2024-04-08.mcap").exists()
