"""The fleet summary: the sections ranked by what needs attention (failed
days, applicators whose delivery looks wrong, sensors that look biased,
constants far from the laboratory's, friction out of the band), written as
summary.md, summary.json and summary.png beside the dataset."""

from __future__ import annotations

import json
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc

import tortwin

from .dataset import _dataset
from .files import _join, _write_bytes
from .jobs import FleetRun
from .manifest import Manifest

# A constant calibrated this far from the laboratory's (relative) puts its
# section in the summary's list.
FAR_FROM_LABORATORY = 0.10
# A site whose mean residual (measured - simulated) is this far from zero
# and from the median of the section's other sites looks biased (three times
# the noise of a good friction sensor, sigma 0.01).
BIAS = 0.03


def write_summary(manifest: Manifest, fleet: FleetRun) -> dict[str, Any]:
    """Ranks the sections by what needs attention and writes summary.md,
    summary.json and summary.png beside the dataset."""
    # The days table (a row per section and day) and the RMSE table (a few
    # rows per day): the summary of a network-year reads no train.
    days_table = _dataset(manifest.output, "days")
    rmse = _dataset(manifest.output, "rmse")
    findings = _dataset(manifest.output, "findings")
    constants = _dataset(manifest.output, "constants")
    # Mean residual per section, site, rail and quantity over the manifest's days.
    wanted = pa.array(sorted(f"{x.id}/{d.date}" for x in manifest.sections for d in x.days))
    if rmse is not None and rmse.num_rows:
        keys = pc.binary_join_element_wise(rmse["section"], pc.cast(rmse["date"], pa.string()), "/")
        r = rmse.filter(pc.is_in(keys, wanted)).to_pandas()
        r["sum_residual"] = r["mean_residual"] * r["n"]
        g = r.groupby(["section", "site", "rail", "quantity"])[["n", "sum_residual"]].sum()
        g["mean"] = g["sum_residual"] / g["n"].clip(lower=1)
        site_means = g.groupby(level="section")
    else:
        import pandas as pd

        site_means = pd.DataFrame(
            columns=["n", "mean"],
            index=pd.MultiIndex.from_tuples([], names=["section", "site", "rail", "quantity"]),
        ).groupby(level="section")
    sections = []
    for section in manifest.sections:
        sid = section.id
        s: dict[str, Any] = {"section": sid, "days": len(section.days), "reasons": []}
        day_results = [d for d in fleet.days if d.section == sid]
        s["days_done"] = sum(d.status in ("done", "skipped") for d in day_results)
        failed = [d for d in day_results if d.status == "failed"]
        s["failed"] = [{"date": d.date, "error": d.error} for d in failed]
        for d in failed:
            s["reasons"].append(f"day {d.date} failed: {d.error}")
        dates = {d.date for d in section.days}
        if days_table is not None:
            d = days_table.filter(pc.equal(days_table["section"], sid))
            d = d.filter(pc.is_in(pc.cast(d["date"], pa.string()), pa.array(sorted(dates))))
            passes = pc.sum(d["wheel_passes"]).as_py() or 0
            if passes:
                s["in_band_share"] = pc.sum(d["in_band_passes"]).as_py() / passes
                s["below_band_share"] = pc.sum(d["below_band_passes"]).as_py() / passes
                s["above_band_share"] = 1.0 - s["in_band_share"] - s["below_band_share"]
                s["carry_on_m"] = pc.mean(d["carry_on_m_mean"]).as_py()
                s["product_g"] = pc.sum(d["product_g"]).as_py()
                if s["in_band_share"] < 0.5:
                    side = "above (dry)" if s["above_band_share"] > s["below_band_share"] else "below (slippery)"
                    s["reasons"].append(
                        f"friction out of band: {100 * (1 - s['in_band_share']):.0f} % of the contacts, mostly {side}"
                    )
        s["applicators"] = []
        s["sensors"] = []
        s["model_findings"] = []
        s["constants_far"] = []
        if findings is not None:
            f = findings.filter(pc.equal(findings["section"], sid)).to_pylist()
            for e in f:
                if e["acts_on"] == "pulse_mass":
                    s["applicators"].append({"applicator": e["applicator"], "finding": e["description"]})
                    s["reasons"].append(f"applicator {e['applicator'] or '(all)'}: {e['description']}")
                elif e["acts_on"] == "measurement":
                    s["sensors"].append({"site": e["site"], "rail": e["rail"], "quantity": e["quantity"],
                                         "finding": e["description"]})
                    s["reasons"].append(f"sensor {e['site']} {e['rail'] or ''} {e['quantity'] or ''}: {e['description']}")
                else:
                    # Physics the section's model lacks: for its configuration.
                    s["model_findings"].append(e["description"])
        if sid in site_means.groups:
            # A biased sensor stands out from the section's other sites; a
            # model error (a clogged nozzle, say) moves them together.
            g = site_means.get_group(sid)
            for (_, site, rail, quantity), row in g.iterrows():
                same = g.xs(quantity, level="quantity")
                others = same[same.index.get_level_values("site") != site]["mean"]
                if row["n"] < 30 or len(others) == 0:
                    continue
                offset = row["mean"] - float(others.median())
                if abs(row["mean"]) >= BIAS and abs(offset) >= BIAS:
                    s["sensors"].append({"site": site, "rail": rail, "quantity": quantity,
                                         "mean_residual": row["mean"], "offset_from_others": offset})
                    s["reasons"].append(
                        f"sensor {site} {rail} {quantity}: reads {offset:+.3f} off the section's "
                        f"other sites (measured - simulated {row['mean']:+.3f} on average)"
                    )
        # Constants calibrated far from the laboratory's: listed after what
        # is broken (applicators, sensors).
        if constants is not None:
            c = constants.filter(pc.equal(constants["section"], sid)).to_pylist()
            # discover's calibration (with the effects found) before calibrate's.
            c.sort(key=lambda r: r["study"] != "discover")
            seen = set()
            for r in c:
                if r["key"] in seen:
                    continue
                seen.add(r["key"])
                change = r["value"] / r["start"] - 1.0 if r["start"] else 0.0
                if abs(change) >= FAR_FROM_LABORATORY:
                    s["constants_far"].append({"key": r["key"], "value": r["value"], "start": r["start"],
                                               "change": change, "determined": r["determined"]})
            if s["constants_far"]:
                s["reasons"].append(
                    "constants far from the laboratory's: "
                    + ", ".join(f"{x['key'].removeprefix('product.')} {x['value']:.4g} ({100 * x['change']:+.0f} %)"
                                for x in s["constants_far"])
                )
        # Attention: failures first, then applicators, sensors, friction.
        s["attention"] = (
            100 * len(s["failed"])
            + 10 * len(s["applicators"])
            + 5 * len({x["site"] for x in s["sensors"]})
            + 2 * bool(s["constants_far"])
            + (1 - s.get("in_band_share", 1.0))
        )
        sections.append(s)
    sections.sort(key=lambda s: (-s["attention"], s["section"]))
    summary = {
        "output": manifest.output,
        "sections": sections,
        "days": {st: fleet.count(st) for st in ("done", "skipped", "failed", "not run")},
        "studies": [
            {"what": what, "section": r.section, "status": r.status, "error": r.error}
            for what, r in fleet.studies
        ],
        "seconds": fleet.seconds,
        "tortwin": tortwin.__version__,
    }
    _write_bytes(_join(manifest.output, "summary.json"), json.dumps(summary, indent=1).encode())
    _write_bytes(_join(manifest.output, "summary.md"), _markdown(summary).encode())
    png = _plot(sections)
    if png is not None:
        _write_bytes(_join(manifest.output, "summary.png"), png)
    return summary


def _markdown(summary: dict[str, Any]) -> str:
    d = summary["days"]
    lines = [
        "# Fleet summary",
        "",
        f"Days: {d['done']} replayed, {d['skipped']} already done, {d['failed']} failed, "
        f"{d['not run']} not run (after a failed day). tortwin {summary['tortwin']}, "
        f"{summary['seconds']:.1f} s.",
        "",
        "Sections by what needs attention (failed days, applicators whose delivery looks wrong, "
        "sensors that look biased, site constants calibrated more than "
        f"{100 * FAR_FROM_LABORATORY:.0f} % from the laboratory's, friction out of the band 0.30-0.40):",
        "",
        "| rank | section | days | in band | below | above | carry-on (m) | product (g) | needs attention | the model misses (discover) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    pct = lambda x: "" if x is None else f"{100 * x:.0f} %"
    for k, s in enumerate(summary["sections"], 1):
        lines.append(
            f"| {k} | {s['section']} | {s['days_done']}/{s['days']} | {pct(s.get('in_band_share'))} | "
            f"{pct(s.get('below_band_share'))} | {pct(s.get('above_band_share'))} | "
            f"{s.get('carry_on_m', 0):.0f} | {s.get('product_g', 0):.1f} | "
            f"{'; '.join(s['reasons']) or '—'} | {'; '.join(s['model_findings']) or '—'} |"
        )
    failed = [x for x in summary["studies"] if x["status"] == "failed"]
    if failed:
        lines += ["", "Studies that failed:", ""]
        lines += [f"- {x['what']} of {x['section']}: {x['error']}" for x in failed]
    lines += ["", "![share of contacts in the band per section](summary.png)", ""]
    return "\n".join(lines)


def _plot(sections: list[dict[str, Any]]) -> bytes | None:
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    import io

    names = [s["section"] for s in sections]
    below = [s.get("below_band_share", 0.0) for s in sections]
    inside = [s.get("in_band_share", 0.0) for s in sections]
    above = [s.get("above_band_share", 0.0) for s in sections]
    fig, ax = plt.subplots(figsize=(max(6, 0.35 * len(names) + 2), 3.6))
    x = range(len(names))
    ax.bar(x, below, color="#3b6fb6", label="below the band")
    ax.bar(x, inside, bottom=below, color="#4caf50", label="in the band")
    ax.bar(x, above, bottom=[b + i for b, i in zip(below, inside)], color="#d9822b", label="above")
    for i, s in enumerate(sections):
        if s["reasons"]:
            ax.text(i, 1.02, "!", ha="center", color="#b00020", fontweight="bold")
    ax.set_xticks(list(x), names, rotation=90 if len(names) > 12 else 0)
    ax.set_ylim(0, 1.1)
    ax.set_ylabel("share of contacts")
    ax.set_title("sections ranked by attention (! = a reason in summary.md)")
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return buf.getvalue()
