"""Writes docs/examples/tortwin.ipynb (no outputs; CI executes it:
tests/python_pkg/test_notebook.py). Edit the cells here and run
`python3 scripts/make_notebook.py`."""

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

CELLS = [
    new_markdown_cell(
        """# tortwin in a notebook

The twin of a track section for top-of-rail friction management, from Python: the same
engine as the `tortwin` command line. Install the package once from the repository's root:

```sh
pip install ./python
```

This notebook replays the bundled demo day (a day of traffic on a 600 m curve with
friction measured at three sites), plots mu at the sites and along the section, runs
`discover` on a recording where the model lacks an effect, and shows the rerun recording."""
    ),
    new_code_cell(
        """import sys
from pathlib import Path

import matplotlib.pyplot as plt
import tortwin

# The repository's root (this notebook lives in docs/examples/).
ROOT = next(p for p in [Path.cwd(), *Path.cwd().parents] if (p / "recordings" / "demo_day.mcap").exists())
OUT = ROOT / "out" / "notebook"
OUT.mkdir(parents=True, exist_ok=True)
print("tortwin", tortwin.__version__)"""
    ),
    new_markdown_cell(
        """## Replay the demo day

`tortwin.replay` returns the measurements with their simulated values, the field after every
train (mu, adhesion and the product per grid point), per-train figures, the run's summary and
the section's state at the end (pass it as `state_in` to replay the next day)."""
    ),
    new_code_cell(
        """run = tortwin.replay(ROOT / "recordings" / "demo_day.mcap", out_rrd=OUT / "demo.rrd")
run.summary"""
    ),
    new_code_cell(
        """m = run.measurements.to_pandas()
rmse = m.groupby(["quantity", "site", "rail"])["residual"].agg(lambda r: (r**2).mean() ** 0.5)
rmse.rename("RMSE").to_frame()"""
    ),
    new_markdown_cell(
        """## mu at the sites, measured and simulated

The recording's measurements carry noise of sigma 0.01; the green band is the target
0.30 to 0.40."""
    ),
    new_code_cell(
        """mu = m[m.quantity == "mu"]
sites = sorted(mu.site.unique())
fig, axes = plt.subplots(len(sites), 1, figsize=(10, 2.4 * len(sites)), sharex=True)
for ax, site in zip(axes, sites):
    for rail, colour in zip(sorted(mu.rail.unique()), ["tab:blue", "tab:orange"]):
        s = mu[(mu.site == site) & (mu.rail == rail)]
        ax.plot(s.time_utc, s.measured, ".", ms=2, alpha=0.3, color=colour, label=f"{rail} rail, measured")
        ax.plot(s.time_utc, s.simulated, "-", lw=0.8, color=colour, label=f"{rail} rail, simulated")
    ax.axhspan(0.30, 0.40, color="green", alpha=0.08)
    ax.set_ylabel(f"mu at {site}")
axes[0].legend(ncol=2, fontsize=8, loc="lower right")
axes[-1].set_xlabel("time (UTC)")
fig.tight_layout()"""
    ),
    new_markdown_cell("""## mu(d) after the last train"""),
    new_code_cell(
        """f = run.field.to_pandas()
last = f[f.train_id == f.train_id.iloc[-1]]
fig, ax = plt.subplots(figsize=(10, 3.2))
for (rail, band), g in last.groupby(["rail", "band"]):
    ax.plot(g.d_m, g.mu, label=f"{rail} rail ({band})")
ax.axhspan(0.30, 0.40, color="green", alpha=0.1, label="target band")
ax.set_xlabel("d (m)")
ax.set_ylabel("mu")
ax.set_title(f"after train {last.train_id.iloc[0]}")
ax.legend()
fig.tight_layout()"""
    ),
    new_markdown_cell(
        """## Discover: an effect the model lacks

`tangent_day_ageing.mcap` was made with the product ageing on the rail (an effect the paper's
model does not have). `discover` finds it from the residuals, fits it and says how much of the
gap it closes; `residuals` has every measurement's residual before and after."""
    ),
    new_code_cell(
        """found = tortwin.discover(ROOT / "recordings" / "tangent_day_ageing.mcap", report=OUT / "ageing")
print(found.verdict)
found.effects"""
    ),
    new_code_cell(
        """r = found.residuals.to_pandas()
fig, ax = plt.subplots(figsize=(10, 3))
ax.plot(r.time_utc, r.residual_before, ".", ms=2, alpha=0.3, label="the paper's model")
ax.plot(r.time_utc, r.residual_after, ".", ms=2, alpha=0.3, label="with the effect found")
ax.set_ylabel("measured - simulated")
ax.legend(markerscale=5)
fig.tight_layout()

# The model found, replayed from its TOML as a dict (tomllib is Python
# 3.11's; on 3.10 the package brings tomli, the same parser).
if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib
model = tomllib.loads(found.model_toml)
tortwin.replay(ROOT / "recordings" / "tangent_day_ageing.mcap", config=model, field=False).summary["rmse"]"""
    ),
    new_markdown_cell(
        """## The rerun recording in the notebook

With rerun's notebook viewer (`pip install "rerun-sdk[notebook]==0.36.3"`) the .rrd written
above opens here; otherwise open it with `rerun out/notebook/demo.rrd`."""
    ),
    new_code_cell(
        """try:
    import rerun as rr
    from rerun.notebook import Viewer

    recording = rr.RecordingStream("tortwin")
    viewer = Viewer(recording=recording, width="auto", height=640)
    recording.log_file_from_path(OUT / "demo.rrd")
    viewer.display()
except ImportError as e:
    print(f"rerun's notebook viewer is not available ({e}); open the file with: rerun {OUT / 'demo.rrd'}")"""
    ),
]


def main() -> None:
    notebook = new_notebook(cells=CELLS)
    notebook.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    notebook.metadata["language_info"] = {"name": "python"}
    out = Path(__file__).resolve().parents[1] / "docs" / "examples" / "tortwin.ipynb"
    nbformat.write(notebook, out)
    print(out)


if __name__ == "__main__":
    main()
