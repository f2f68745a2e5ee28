"""The command ``tortwin-fleet MANIFEST`` (the console script, and ``python
-m tortwin.fleet``): its arguments, a local Ray started or a cluster
joined, the run, a report on stdout and the exit status."""

from __future__ import annotations

import argparse
import os
import sys

from .files import _join
from .manifest import ManifestError, load_manifest
from .tasks import run


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
