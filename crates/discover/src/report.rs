//! What `discover` leaves in its report directory:
//!
//! | file | what |
//! |---|---|
//! | `report.json` | [`super::Discovery`]: `effects_found`, `rmse_before`, `rmse_after`, `noise_estimate` (docs/spec/interfaces.md), then the steps, criteria and covariate rankings |
//! | `model.toml` | the final configuration, whole; loads back with `--config` |
//! | `report.md` | the narrative, with the plots below |
//! | `rmse_by_step.svg/.csv` | RMSE of the model after each step, and the noise estimate |
//! | `residual_vs_<covariate>.svg/.csv` | the residual against the covariate it followed most closely at the start, before and after |
//! | `mu_vs_distance.svg/.csv` | measured and simulated mu against the distance from the applicator, before and after, per rail |
//! | `residuals.rrd` | the finding, the residual against its strongest covariate per site and rail, and the residuals over time, before and after, in a layout that opens on them (rerun; see `residuals_rrd.rs`) |
//!
//! Every file is written under a temporary name and renamed when complete.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::data::{Dataset, Values};
use super::diagnose::{self, CovariateScore};
use super::fit::CrossValidation;
use super::{fmt_param, Discovery, EffectParams};
use tortwin_outputs::files::write_atomically;
use tortwin_plot::{Colour, LinePlot, Panel, ReferenceLine, Series};
use tortwin_recording::Quantity;
use tortwin_study::{Error, Result};

/// Scatter plots show at most this many points per panel.
const MAX_DOTS: usize = 2500;

/// Writes every file of the report into `dir` (created if needed); returns
/// the paths written.
pub fn write(dir: &Path, data: &Dataset, d: &Discovery) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        what: "cannot create the report directory",
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    let mut put = |name: &str, bytes: &[u8]| -> Result<()> {
        let path = dir.join(name);
        write_atomically(&path, bytes)?;
        written.push(path);
        Ok(())
    };

    let mut json = serde_json::to_string_pretty(d).map_err(|source| Error::Json {
        what: "report.json",
        source,
    })?;
    json.push('\n');
    put("report.json", json.as_bytes())?;
    put("model.toml", model_toml(d).as_bytes())?;

    let rmse_plot = rmse_by_step_plot(d);
    put("rmse_by_step.svg", rmse_plot.render_svg()?.as_bytes())?;
    put(
        "rmse_by_step.csv",
        tortwin_plot::csv_text(
            &["step", "rmse"],
            d.rmse_by_step
                .iter()
                .enumerate()
                .map(|(k, (_, r))| [k as f64, *r]),
        )?
        .as_bytes(),
    )?;

    let strongest = d.covariates_before.first();
    let mut residual_file = None;
    if let Some(top) = strongest {
        if let Some((svg, csv)) = residual_plot(data, d, top)? {
            let name = format!("residual_vs_{}", top.name);
            put(&format!("{name}.svg"), svg.as_bytes())?;
            put(&format!("{name}.csv"), csv.as_bytes())?;
            residual_file = Some(name);
        }
    }
    let mut distance_file = false;
    if let Some((svg, csv)) = mu_vs_distance_plot(data, d)? {
        put("mu_vs_distance.svg", svg.as_bytes())?;
        put("mu_vs_distance.csv", csv.as_bytes())?;
        distance_file = true;
    }
    let md = markdown(data, d, residual_file.as_deref(), distance_file);
    put("report.md", md.as_bytes())?;
    let rrd = dir.join("residuals.rrd");
    super::residuals_rrd::write_rrd(&rrd, data, d, &md)?;
    written.push(rrd);
    Ok(written)
}

/// `path` made absolute, so that a command the report suggests works from
/// the report's folder (as given when that fails).
fn absolute(path: &Path) -> PathBuf {
    std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The final configuration, whole, with a header saying where it comes from.
pub(crate) fn model_toml(d: &Discovery) -> String {
    let mut text = String::new();
    let _ = writeln!(
        text,
        "# tortwin discover: the model configuration with the effects found switched on and fitted."
    );
    let _ = writeln!(text, "# recording: {}", d.recording);
    let _ = writeln!(
        text,
        "# RMSE {:.5} -> {:.5} (noise estimate {})",
        d.rmse_before,
        d.rmse_after,
        d.noise_estimate
            .map_or_else(|| "unknown".to_string(), |s| format!("{s:.5}"))
    );
    let _ = writeln!(
        text,
        "# use it from this folder with: tortwin replay {} --config model.toml\n",
        absolute(Path::new(&d.recording)).display()
    );
    text.push_str(&d.model.to_toml());
    text
}

fn rmse_by_step_plot(d: &Discovery) -> LinePlot {
    let x: Vec<f64> = (0..d.rmse_by_step.len()).map(|k| k as f64).collect();
    let y: Vec<f64> = d.rmse_by_step.iter().map(|(_, r)| *r).collect();
    let mut panel = Panel::new("RMSE measured vs simulated [-]")
        .series(
            Series::new("RMSE", x.clone(), y.clone())
                .colour(Colour::BLUE)
                .width_px(2),
        )
        .series(
            Series::new("", x, y)
                .colour(Colour::BLUE)
                .dots()
                .width_px(5),
        );
    if let Some(s) = d.noise_estimate {
        panel = panel.reference_line(ReferenceLine::new(s, "noise estimate"));
    }
    let low = d
        .noise_estimate
        .unwrap_or(f64::INFINITY)
        .min(d.rmse_after)
        .min(d.rmse_before);
    let high = d.rmse_before.max(d.rmse_after);
    let panel = panel.y_range(0.0f64.max(low * 0.8), high * 1.1 + 1e-9);
    let steps = d.rmse_by_step.len().max(2) as f64;
    LinePlot::new(
        "RMSE after each step of the forward selection",
        "step (0 = starting model; then each effect added)",
        panel,
    )
    .x_range(-0.25, steps - 0.75)
}

/// Every `stride`-th index so that at most [`MAX_DOTS`] remain.
fn thin(indices: &[usize]) -> Vec<usize> {
    let stride = indices.len().div_ceil(MAX_DOTS).max(1);
    indices.iter().step_by(stride).copied().collect()
}

/// The residual against the covariate `top`: scatter and bin means, one
/// panel before and one after. `None` when the covariate is unknown.
fn residual_plot(
    data: &Dataset,
    d: &Discovery,
    top: &CovariateScore,
) -> Result<Option<(String, String)>> {
    let Some(cov) = data.covariate(&top.name) else {
        return Ok(None);
    };
    let bins = diagnose::bins(cov);
    let (x, x_label): (Vec<f64>, String) = match &cov.values {
        Values::Continuous(v) => (v.clone(), cov.description.to_string()),
        Values::Categorical { labels, codes } => (
            codes.iter().map(|&c| f64::from(c)).collect(),
            format!(
                "{} ({})",
                cov.description,
                labels
                    .iter()
                    .enumerate()
                    .map(|(k, l)| format!("{k} = {l}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        ),
    };
    // Bin means (x = the bin's mean covariate, or the category code).
    let nbins = bins.labels.len();
    let mean_of = |residual: &[f64]| -> (Vec<f64>, Vec<f64>) {
        let mut sx = vec![0.0; nbins];
        let mut sr = vec![0.0; nbins];
        let mut n = vec![0usize; nbins];
        for ((&b, &xi), &r) in bins.index.iter().zip(&x).zip(residual) {
            if xi.is_finite() {
                sx[b] += xi;
                sr[b] += r;
                n[b] += 1;
            }
        }
        let mut pts: Vec<(f64, f64)> = (0..nbins)
            .filter(|&b| n[b] > 0)
            .map(|b| (sx[b] / n[b] as f64, sr[b] / n[b] as f64))
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        pts.into_iter().unzip()
    };
    let finite: Vec<usize> = (0..x.len()).filter(|&i| x[i].is_finite()).collect();
    if finite.is_empty() {
        return Ok(None);
    }
    let shown = thin(&finite);
    let all = d
        .residual_before
        .iter()
        .chain(&d.residual_after)
        .fold(0.0f64, |m, r| m.max(r.abs()));
    let y_max = all.max(1e-6) * 1.05;
    let panel = |label: &str, residual: &[f64], colour: Colour| {
        let (mx, my) = mean_of(residual);
        Panel::new(format!("residual {label} [-]"))
            .series(
                Series::new(
                    format!("each measurement, {label}"),
                    shown.iter().map(|&i| x[i]).collect(),
                    shown.iter().map(|&i| residual[i]).collect(),
                )
                .colour(Colour(190, 190, 190))
                .dots()
                .width_px(1),
            )
            .series(
                Series::new(format!("mean per bin, {label}"), mx.clone(), my.clone())
                    .colour(colour)
                    .width_px(3),
            )
            .series(Series::new("", mx, my).colour(colour).dots().width_px(5))
            .reference_line(ReferenceLine::new(0.0, "0"))
            .y_range(-y_max, y_max)
    };
    let plot = LinePlot::stacked(
        format!(
            "Residual (measured - simulated) against {} (eta² {:.3} before, {:.3} after)",
            cov.name,
            top.eta2,
            diagnose::score(cov, &d.residual_after).eta2
        ),
        x_label,
        vec![
            panel("before", &d.residual_before, Colour::ORANGE),
            panel("after", &d.residual_after, Colour::BLUE),
        ],
    );
    let svg = plot.render_svg()?;
    let csv = tortwin_plot::csv_text(
        &[cov.name, "residual_before", "residual_after"],
        (0..x.len()).map(|i| [x[i], d.residual_before[i], d.residual_after[i]]),
    )?;
    Ok(Some((svg, csv)))
}

/// Mean measured and simulated mu per distance from the applicator, before
/// and after, one panel per rail.
fn mu_vs_distance_plot(data: &Dataset, d: &Discovery) -> Result<Option<(String, String)>> {
    let Some(cov) = data.covariate("distance_from_applicator_m") else {
        return Ok(None);
    };
    let Values::Continuous(dist) = &cov.values else {
        return Ok(None);
    };
    let bins = diagnose::bins(cov);
    let nbins = bins.labels.len();
    let mut panels = Vec::new();
    let mut rows_csv = Vec::new();
    for (rail, rail_name) in data.section.rails.iter().enumerate() {
        let idx: Vec<usize> = (0..data.rows.len())
            .filter(|&i| {
                data.rows[i].rail == rail
                    && data.rows[i].quantity == Quantity::Mu
                    && dist[i].is_finite()
            })
            .collect();
        if idx.is_empty() {
            continue;
        }
        // Per bin: sums of x, measured, simulated before and after.
        let mut acc = vec![[0.0f64; 5]; nbins];
        for &i in &idx {
            let m = data.rows[i].measured;
            let a = &mut acc[bins.index[i]];
            a[0] += dist[i];
            a[1] += m;
            a[2] += m - d.residual_before[i];
            a[3] += m - d.residual_after[i];
            a[4] += 1.0;
        }
        let mut means: Vec<[f64; 4]> = acc
            .iter()
            .filter(|a| a[4] > 0.0)
            .map(|a| [a[0] / a[4], a[1] / a[4], a[2] / a[4], a[3] / a[4]])
            .collect();
        means.sort_by(|a, b| a[0].total_cmp(&b[0]));
        for m in &means {
            rows_csv.push([rail as f64, m[0], m[1], m[2], m[3]]);
        }
        let col = |k: usize| means.iter().map(|m| m[k]).collect::<Vec<f64>>();
        let shown = thin(&idx);
        panels.push(
            Panel::new(format!("mu on rail {rail_name} [-]"))
                .series(
                    Series::new(
                        "measured",
                        shown.iter().map(|&i| dist[i]).collect(),
                        shown.iter().map(|&i| data.rows[i].measured).collect(),
                    )
                    .colour(Colour(190, 190, 190))
                    .dots()
                    .width_px(1),
                )
                .series(
                    Series::new("simulated before, mean", col(0), col(2))
                        .colour(Colour::ORANGE)
                        .dashed()
                        .width_px(3),
                )
                .series(
                    Series::new("simulated after, mean", col(0), col(3))
                        .colour(Colour::BLUE)
                        .width_px(3),
                )
                // Last, on top: the measured means the lines should meet.
                .series(
                    Series::new("measured, mean", col(0), col(1))
                        .colour(Colour::BLACK)
                        .dots()
                        .width_px(6),
                ),
        );
    }
    if panels.is_empty() {
        return Ok(None);
    }
    let plot = LinePlot::stacked(
        "Measured and simulated mu against the distance from the applicator",
        "distance downstream of the applicator the wheel passed [m]",
        panels,
    );
    let svg = plot.render_svg()?;
    let csv = tortwin_plot::csv_text(
        &[
            "rail",
            "distance_m",
            "measured_mean",
            "simulated_before_mean",
            "simulated_after_mean",
        ],
        rows_csv,
    )?;
    Ok(Some((svg, csv)))
}

/// The site's constants: each against the laboratory's, with its interval
/// and what determined it (interfaces.md, "Site constants").
fn site_constants_md(md: &mut String, d: &Discovery, c: &super::Calibration) {
    let _ = writeln!(md, "## Site constants\n");
    let _ = writeln!(md, "{}\n", c.summary);
    let _ = writeln!(
        md,
        "A constant that differs for the whole recording is the site's (its rail, its product \
         batch, its traffic), not an effect: it is calibrated before any effect is looked for, \
         and again with the effects found. A constant is **determined** when the recording \
         pins it down alone (standard error of ln p at most {:.0} %, every other constant and \
         effect free); its 95 % interval is then honest whatever the others are. One the \
         recording cannot tell from others stands for the **combination** it determines. A \
         constant whose interval holds its reference value stays there.\n",
        100.0 * super::calibrate::SD_DETERMINED
    );
    let _ = writeln!(
        md,
        "| constant | laboratory | value | 95 % interval | determined | what the recording says |\n|---|---|---|---|---|---|"
    );
    for k in &d.site_constants {
        let ci = k.ci95.map_or_else(
            || "–".to_string(),
            |[lo, hi]| format!("{} – {}", fmt_param(lo), fmt_param(hi)),
        );
        let value = if k.value == k.start.unwrap_or(k.default) {
            fmt_param(k.value)
        } else {
            format!("**{}**", fmt_param(k.value))
        };
        let _ = writeln!(
            md,
            "| `{}` | {} | {value} | {ci} | {} | {} |",
            k.key,
            fmt_param(k.default),
            if k.determined { "yes" } else { "no" },
            k.description
        );
    }
    let _ = writeln!(
        md,
        "\nRMSE with the starting constants {:.5}, with the calibrated ones {:.5} (step 0, \
         before any effect); {} engine runs.\n",
        d.rmse_before,
        d.calibration_start
            .as_ref()
            .map_or(c.rmse_after, |s| s.rmse_after),
        c.engine_runs
    );
}

/// What the evaluations cost, by stage, in one line.
pub(crate) fn cost_text(d: &Discovery) -> String {
    let stages: Vec<String> = d
        .cost
        .iter()
        .map(|s| {
            format!(
                "{} {:.1}",
                serde_json::to_value(s.stage)
                    .ok()
                    .and_then(|v| v.as_str().map(|t| t.replace('_', "-")))
                    .unwrap_or_default(),
                s.cost.run_equivalents
            )
        })
        .collect();
    // Every replay but the first (which finds the outliers) is timed.
    let unit = match (d.replay_ms, d.engine_runs.saturating_sub(1)) {
        (Some(ms), 1) => format!(" of {ms:.0} ms (the one replay timed)"),
        (Some(ms), n) => format!(" of {ms:.0} ms (the mean of {n} replays timed)"),
        (None, _) => String::new(),
    };
    format!(
        "{:.1} run-equivalents{unit}: {} replays, {} with tangents, {} read-outs; {}",
        d.run_equivalents,
        d.engine_runs,
        d.tangent_runs(),
        d.cost.iter().map(|s| s.cost.readouts).sum::<usize>(),
        stages.join(", ")
    )
}

fn effect_text(e: &EffectParams) -> String {
    format!("`{}`", e.text())
}

fn effects_text(list: &[EffectParams]) -> String {
    if list.is_empty() {
        "none".to_string()
    } else {
        list.iter().map(effect_text).collect::<Vec<_>>().join(", ")
    }
}

fn markdown(data: &Dataset, d: &Discovery, residual_file: Option<&str>, distance: bool) -> String {
    let mut md = String::new();
    let noise = d
        .noise_estimate
        .map_or_else(|| "unknown".to_string(), |s| format!("{s:.5}"));
    let _ = writeln!(md, "# What the model misses: `{}`\n", d.recording);
    let _ = writeln!(md, "{}\n", d.verdict);
    let _ = writeln!(md, "| | |\n|---|---|");
    let _ = writeln!(
        md,
        "| measurements | {} over {} days |",
        d.measurements, d.days
    );
    let _ = writeln!(
        md,
        "| starting model | {} |",
        effects_text(&d.start_effects)
    );
    let _ = writeln!(md, "| effects found | {} |", effects_text(&d.effects_found));
    let _ = writeln!(
        md,
        "| final model | {} (`model.toml`) |",
        effects_text(&d.model_effects)
    );
    let _ = writeln!(md, "| RMSE before | {:.5} |", d.rmse_before);
    let _ = writeln!(md, "| RMSE after | {:.5} |", d.rmse_after);
    let _ = writeln!(md, "| noise estimate | {noise} |");
    let places: Vec<String> = d
        .outliers
        .by_place
        .iter()
        .map(|(place, n)| format!("{place}: {n}"))
        .collect();
    let _ = writeln!(
        md,
        "| gross outliers left out | {} of {} (more than {:.4} from their neighbours){} |",
        d.outliers.count,
        d.measurements,
        d.outliers.threshold,
        if places.is_empty() {
            String::new()
        } else {
            format!("; {}", places.join(", "))
        }
    );
    let _ = writeln!(
        md,
        "| engine runs | {} in {:.1} s ({}) |\n",
        d.engine_runs,
        d.elapsed_s,
        cost_text(d)
    );
    let _ = writeln!(
        md,
        "Replay with the model found (from this folder): `tortwin replay {} --config \
         model.toml`.\n",
        absolute(&data.path).display()
    );

    if let Some(c) = &d.calibration {
        site_constants_md(&mut md, d, c);
    }
    let _ = writeln!(md, "## RMSE per step\n");
    let _ = writeln!(md, "![RMSE per step](rmse_by_step.svg)\n");
    let _ = writeln!(md, "| step | model | RMSE |\n|---|---|---|");
    for (k, (label, r)) in d.rmse_by_step.iter().enumerate() {
        let _ = writeln!(md, "| {k} | {label} | {r:.5} |");
    }

    let _ = writeln!(md, "\n## Where the residuals come from\n");
    if let Some(top) = d.covariates_before.first() {
        let after = d.covariates_after.iter().find(|c| c.name == top.name);
        let _ = writeln!(
            md,
            "At the start the residual followed **{}** most closely ({}: eta² = {:.3}); \
             after the selection eta² = {:.3}.\n",
            top.name,
            top.description,
            top.eta2,
            after.map_or(f64::NAN, |a| a.eta2)
        );
    }
    if let Some(name) = residual_file {
        let _ = writeln!(
            md,
            "![residual against the strongest covariate]({name}.svg)\n"
        );
    }
    if distance {
        let _ = writeln!(
            md,
            "![measured and simulated mu against distance](mu_vs_distance.svg)\n"
        );
    }
    let _ = writeln!(
        md,
        "Share of the residual variance each covariate explains (eta² over its categories, \
         or its deciles; adjusted for the number of bins), strongest first:\n"
    );
    let _ = writeln!(
        md,
        "| covariate | eta² before | eta² after | bins |\n|---|---|---|---|"
    );
    for c in &d.covariates_before {
        let after = d
            .covariates_after
            .iter()
            .find(|a| a.name == c.name)
            .map_or(f64::NAN, |a| a.eta2);
        let _ = writeln!(
            md,
            "| {} ({}) | {:.4} | {:.4} | {} |",
            c.name, c.description, c.eta2, after, c.bins
        );
    }

    let _ = writeln!(md, "\n## Candidates, step by step\n");
    let _ = writeln!(
        md,
        "Each effect of effects.md not yet in the model is fitted by re-running the engine on \
         the recording (bounded search: a coarse grid, then Gauss–Newton steps on the residuals). It is added only if \
         the BIC drops by more than {} (ΔBIC = n ln(SSE1/SSE0) + Δk ln n), it removes at \
         least {:.0} % of what the current model leaves above the noise (SSE0 − n σ̂²), **and** \
         cross-validation blocked by day, then by measurement site, predicts the held-out \
         blocks better than the current model (each block's SSE with the parameters refitted \
         on the other blocks, summed; the current model's is its SSE). \
         Of those, the largest BIC drop is added; then every effect in the model is refitted \
         jointly and the search repeats.\n",
        d.options.bic_threshold,
        100.0 * d.options.min_excess_share
    );
    if let Some(refit) = &d.start_refit {
        let _ = writeln!(
            md,
            "Step 0 refitted the starting model's effects: {}.\n",
            effects_text(refit)
        );
    }
    for s in &d.steps {
        let _ = writeln!(
            md,
            "### Step {}: on top of {} (RMSE {:.5}; SSE {:.4}, the held-out SSE to beat)\n",
            s.step,
            effects_text(&s.model_effects),
            s.rmse,
            s.cv_sse
        );
        let _ = writeln!(
            md,
            "| candidate | fitted | RMSE | ΔBIC | share of the excess | held-out SSE by day / by site | verdict | runs |\n|---|---|---|---|---|---|---|---|"
        );
        for c in &s.candidates {
            let params = if c.params.is_empty() {
                "-".to_string()
            } else {
                c.params
                    .iter()
                    .map(|(k, v)| format!("{k} = {}", fmt_param(*v)))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let held = |cv: &Option<CrossValidation>| match cv {
                None => "-".to_string(),
                Some(cv) => match &cv.evidence_in {
                    Some(b) => format!("{:.4} (seen on {b} alone)", cv.held_out_sse),
                    None => format!("{:.4}", cv.held_out_sse),
                },
            };
            let cv = format!("{} / {}", held(&c.cv), held(&c.cv_site));
            let verdict = match (c.passes_bic, c.passes_cv, c.passes_cv_site) {
                (false, _, _) => "BIC not low enough",
                (true, _, _) if !c.passes_share => {
                    "explains too little of the excess over the noise"
                }
                (true, None, _) => "passes BIC; not cross-validated (a better one was added)",
                (true, Some(false), _) => "fails cross-validation by day",
                (true, Some(true), Some(false)) => "fails cross-validation by site",
                _ if s.accepted.as_deref() == Some(c.name.as_str()) => "**added**",
                _ => "passes",
            };
            let share = c
                .excess_share
                .map_or_else(|| "-".to_string(), |x| format!("{:.0} %", 100.0 * x));
            let _ = writeln!(
                md,
                "| `{}` | {} | {:.5} | {:.1} | {} | {} | {} | {} |",
                c.name, params, c.rmse, c.delta_bic, share, cv, verdict, c.engine_runs
            );
        }
        if !s.calibrated_beside.is_empty() {
            let _ = writeln!(
                md,
                "\nThe closest contenders of different kinds, with the site's constants \
                 calibrated beside each (ΔBIC, the constants moved counted): {}.",
                s.calibrated_beside
                    .iter()
                    .map(|(label, bic)| format!("`{label}` {bic:.1}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
        match &s.accepted {
            Some(name) => {
                let _ = writeln!(
                    md,
                    "\nAdded `{name}`; after the joint refit: {} (RMSE {:.5}).\n",
                    effects_text(&s.effects_after),
                    s.rmse_after
                );
            }
            None => {
                let _ = writeln!(md, "\nNo candidate passes: the selection stops.\n");
            }
        }
    }

    let _ = writeln!(md, "## What is left\n");
    match &d.unexplained {
        None => {
            let _ = writeln!(
                md,
                "The final RMSE {:.5} is within {} × the noise estimate ({noise}): what is left \
                 is measurement noise.",
                d.rmse_after, d.options.unexplained_ratio
            );
        }
        Some(u) => {
            let _ = writeln!(
                md,
                "The final RMSE {:.5} is {:.2} × the noise estimate ({noise}). No known effect \
                 explains the rest. It follows **{}** ({}) most closely: eta² = {:.3}. Look at \
                 `residuals.rrd` and the covariate table above for its shape.",
                u.rmse, u.ratio, u.covariate, u.description, u.eta2
            );
        }
    }
    let _ = writeln!(
        md,
        "\nThe noise estimate comes from the differences between the residuals of consecutive \
         axles of one train with the same bogie position at the same site and rail \
         (sqrt(mean(diff²)/2)): it does not depend on the fit. `residuals.rrd` holds the \
         residuals before and after per site, rail and quantity on the `time` timeline \
         (`rerun residuals.rrd`)."
    );
    md
}
