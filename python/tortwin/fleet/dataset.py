"""The Parquet dataset (its layout in the package's docstring): the tables a
day and a study write, the markers that make a re-run skip a section's
study done with the same inputs, and a table of the dataset read back (for
the summary)."""

from __future__ import annotations

import json
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.fs as pafs

from .files import _exists, _fs, _join, _read_bytes, _write_bytes, _write_parquet
from .jobs import SectionJob

# The version of what a day or study writes: part of the key a re-run
# compares, so that a new layout or column is written again.
FORMAT = 2


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


def _skip_section(job: SectionJob, what: str, key: str) -> bool:
    done_at = _join(job.output, "_done", job.section, f"{what}.json")
    try:
        return _exists(done_at) and json.loads(_read_bytes(done_at))["key"] == key
    except (OSError, ValueError, KeyError):
        return False


def _mark_section(job: SectionJob, what: str, key: str) -> None:
    _write_bytes(_join(job.output, "_done", job.section, f"{what}.json"), json.dumps({"key": key}).encode())


def _dataset(output: str, name: str) -> pa.Table | None:
    fs, path = _fs(output)
    root = f"{path.rstrip('/')}/{name}"
    if fs.get_file_info(root).type != pafs.FileType.Directory:
        return None
    return ds.dataset(root, filesystem=fs, format="parquet", partitioning="hive").to_table()
