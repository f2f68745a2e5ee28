"""Benchmark of tortwin-fleet: N sections x D days replayed with the state
carried, written to the Parquet dataset, sequentially in one process and as
Ray tasks on a local Ray, on this machine.

    python3 scripts/bench_fleet.py [--sections 40] [--days 7] [--cpus 2] [--work out/bench-fleet]

The recordings are made once with tortwin synth (the curve preset, 600 m,
40 trains a day, a different seed per section) and cut into days. The
sequential run calls the same function a Ray task runs (fleet.replay_day),
day after day, section after section; the Ray run is `fleet.run` on a fresh
output folder. Prints both wall times, the cost per section-day and the
speed-up, as the README's figures.
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

import tortwin
from tortwin import fleet


def make_recordings(work: Path, sections: int, days: int) -> dict[str, dict[str, Path]]:
    out = {}
    for k in range(sections):
        sid = f"N{k:03d}"
        whole = work / "recordings" / f"{sid}.mcap"
        folder = work / "recordings" / sid
        if not folder.exists():
            whole.parent.mkdir(parents=True, exist_ok=True)
            tortwin.synth(whole, days=days, seed=1000 + k)
            fleet.split_by_day(whole, folder)
            whole.unlink()
        out[sid] = {p.stem: p for p in sorted(folder.glob("*.mcap"))}
    return out


def write_manifest(path: Path, output: Path, recordings) -> Path:
    lines = [f'output = "{output}"']
    for sid, days in recordings.items():
        table = ", ".join(f'{d} = "{p}"' for d, p in days.items())
        lines += ["[[section]]", f'id = "{sid}"', f"days = {{ {table} }}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def sequential(manifest: fleet.Manifest) -> float:
    t0 = time.perf_counter()
    for section in manifest.sections:
        previous = None
        for day in section.days:
            job = fleet.DayJob(section.id, day.date, day.recording, manifest.output, None, None, False, False)
            previous = fleet.replay_day(job, previous)
            assert previous.status == "done", previous
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sections", type=int, default=40)
    parser.add_argument("--days", type=int, default=7)
    parser.add_argument("--cpus", type=int, default=2)
    parser.add_argument("--work", default="out/bench-fleet")
    args = parser.parse_args()
    work = Path(args.work).resolve()
    t0 = time.perf_counter()
    recordings = make_recordings(work, args.sections, args.days)
    print(f"recordings: {args.sections} sections x {args.days} days in {time.perf_counter() - t0:.1f} s")
    section_days = sum(len(d) for d in recordings.values())

    for name in ("seq", "ray"):
        shutil.rmtree(work / name, ignore_errors=True)
    seq_manifest = fleet.load_manifest(write_manifest(work / "seq.toml", work / "seq", recordings))
    seq_s = sequential(seq_manifest)

    import ray

    ray.init(num_cpus=args.cpus, log_to_driver=False, include_dashboard=False)
    # Ray's workers start with the first tasks: a warm-up of one section.
    warm = write_manifest(work / "warm.toml", work / "warm", dict(list(recordings.items())[:1]))
    fleet.run(warm, summary=False)
    t1 = time.perf_counter()
    result = fleet.run(write_manifest(work / "ray.toml", work / "ray", recordings), summary=False)
    ray_s = time.perf_counter() - t1
    assert result.count("done") == section_days, result.days
    contacts = sum(
        r["contacts"] for r in __import__("pyarrow.dataset", fromlist=["dataset"])
        .dataset(work / "seq" / "days", format="parquet", partitioning="hive").to_table().to_pylist()
    )
    per_day = seq_s / section_days
    print(f"section-days: {section_days}, contacts: {contacts / 1e6:.1f} M")
    print(f"sequential (one process): {seq_s:.1f} s, {per_day * 1e3:.0f} ms per section-day")
    print(f"Ray on {args.cpus} CPUs: {ray_s:.1f} s, speed-up {seq_s / ray_s:.2f}x")


if __name__ == "__main__":
    main()
