//! The result of a strategy study: `strategy.json` (every figure, for
//! scripts), `report.md` with its plots (coverage over pulse mass ×
//! interval, mu(d) of the recommendation against today's, the Pareto front)
//! and `recommended.rrd` (the recommended strategy's friction field, for the
//! rerun viewer).
//!
//! The plots and the recording come first, `strategy.json` and `report.md`
//! last, each file written whole under a temporary name and renamed: a
//! failed run never leaves a report that looks complete.

use std::fmt::Write as _;
use std::path::Path;
use tortwin_outputs::provenance::Provenance;

use serde::Serialize;

use super::metrics::{Figures, RailFigures, Target};
use super::search::{Evaluated, Space};
use super::{evaluate, Plan, Strategy, Study, TodayApplicator, Traffic};
use tortwin_engine::sink::Sink;
use tortwin_model::config::ModelConfig;
use tortwin_outputs::files::write_atomically;
use tortwin_outputs::rerun_out::{RerunOptions, RerunSink};
use tortwin_plot::{Colour, Heatmap, LinePlot, Panel, ReferenceLine, Series};
use tortwin_recording::Section;
use tortwin_study::{Error, Result};

/// A strategy as people and scripts read it.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct StrategyView {
    pub(crate) description: String,
    pub(crate) pulse_g: f64,
    pub(crate) every_axles: u32,
    pub(crate) positions_m: Vec<f64>,
    pub(crate) rails: Vec<String>,
}

impl StrategyView {
    pub(crate) fn new(s: &Strategy, section: &Section) -> Self {
        Self {
            description: s.describe(section),
            pulse_g: s.pulse_kg * 1e3,
            every_axles: s.every_axles,
            positions_m: s.positions_m.clone(),
            rails: s.rails.iter().map(|&r| section.rails[r].clone()).collect(),
        }
    }
}

#[derive(Debug, Serialize)]
struct Result_<'a> {
    tortwin_version: &'static str,
    provenance: &'a Provenance,
    traffic: TrafficView<'a>,
    target: &'a Target,
    space: SpaceView,
    search: SearchView,
    today: TodayView<'a>,
    recommended: Option<Choice>,
    best_coverage: Option<Choice>,
    pareto_front: Vec<Choice>,
    heatmap: Option<HeatmapView>,
    evaluated: Vec<Choice>,
    model: ModelConfig,
}

#[derive(Debug, Serialize)]
struct TrafficView<'a> {
    source: &'a str,
    section_id: &'a str,
    length_m: f64,
    rails: &'a [String],
    trains: u64,
    axles: u64,
    days: f64,
    span_h: f64,
}

#[derive(Debug, Serialize)]
struct SpaceView {
    size: usize,
    pulse_g: Vec<f64>,
    every_axles: Vec<u32>,
    positions_m: Vec<f64>,
    layouts_m: Vec<Vec<f64>>,
    rails: Vec<Vec<String>>,
}

#[derive(Debug, Serialize)]
struct SearchView {
    method: super::search::Method,
    evaluations: usize,
    seconds: f64,
    strategies_per_second: f64,
}

#[derive(Debug, Serialize)]
struct TodayView<'a> {
    applicators: Vec<TodayApplicator>,
    figures: &'a Figures,
}

#[derive(Debug, Clone, Serialize)]
struct Choice {
    strategy: StrategyView,
    figures: Figures,
    #[serde(skip_serializing_if = "Vec::is_empty")]
    reasons: Vec<String>,
    /// On the Pareto front: the other strategies with exactly the same
    /// product and coverage, shown as this one point.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    twins: Vec<StrategyView>,
}

#[derive(Debug, Serialize)]
struct HeatmapView {
    positions_m: Vec<f64>,
    rails: Vec<String>,
    pulse_g: Vec<f64>,
    every_axles: Vec<u32>,
    /// `[every][pulse]`
    coverage: Vec<Vec<f64>>,
    admissible: Vec<Vec<bool>>,
}

fn choice(e: &Evaluated, section: &Section) -> Choice {
    Choice {
        strategy: StrategyView::new(&e.strategy, section),
        figures: e.figures.clone(),
        reasons: Vec::new(),
        twins: Vec::new(),
    }
}

/// Writes the study's result into `dir` (created if missing).
pub fn write(
    dir: &Path,
    traffic: &Traffic,
    cfg: &ModelConfig,
    target: &Target,
    space: &Space,
    study: &Study,
    provenance: &Provenance,
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Io {
        what: "creating",
        path: dir.to_path_buf(),
        source,
    })?;
    let section = &traffic.section;

    // Today's and the recommendation's profiles; the recommendation's field
    // goes to the rerun recording in the same run.
    let today = evaluate(traffic, cfg, target, &Plan::Today, true, None)?;
    let rec_path = dir.join("recommended.rrd");
    let recommended = match &study.recommended {
        Some(r) => {
            let mut rerun = RerunSink::create(
                &rec_path,
                RerunOptions {
                    recording_name: Some(format!("recommended: {}", r.strategy.describe(section))),
                    provenance: Some(provenance.clone()),
                    ..RerunOptions::default()
                },
            )?;
            let figures = evaluate(
                traffic,
                cfg,
                target,
                &Plan::Strategy(r.strategy.clone()),
                true,
                Some(&mut rerun as &mut dyn Sink),
            )?;
            Some(figures)
        }
        None => None,
    };

    if let Some(h) = &study.heatmap {
        heatmap_plot(space, study, h, section).write_svg(&dir.join("coverage_heatmap.svg"))?;
    }
    profile_plot(target, &today, recommended.as_ref(), section)
        .write_svg(&dir.join("mu_profile.svg"))?;
    pareto_plot(study).write_svg(&dir.join("pareto.svg"))?;

    let reasons = recommendation_reasons(traffic, target, study);
    let result = Result_ {
        tortwin_version: env!("CARGO_PKG_VERSION"),
        provenance,
        traffic: TrafficView {
            source: &traffic.source,
            section_id: &section.section_id,
            length_m: section.length_m,
            rails: &section.rails,
            trains: traffic.trains,
            axles: traffic.axles,
            days: traffic.days(),
            span_h: traffic.span_s / 3600.0,
        },
        target,
        space: SpaceView {
            size: space.size(),
            pulse_g: space.pulse_kg.iter().map(|m| m * 1e3).collect(),
            every_axles: space.every_axles.clone(),
            positions_m: space.positions_m.clone(),
            layouts_m: space
                .layouts
                .iter()
                .map(|l| l.iter().map(|&i| space.positions_m[i]).collect())
                .collect(),
            rails: space
                .rails
                .iter()
                .map(|set| set.iter().map(|&r| section.rails[r].clone()).collect())
                .collect(),
        },
        search: SearchView {
            method: study.method,
            evaluations: study.search_evaluations,
            seconds: study.search_seconds,
            strategies_per_second: study.search_evaluations as f64 / study.search_seconds.max(1e-9),
        },
        today: TodayView {
            applicators: traffic.today(),
            figures: &study.today,
        },
        recommended: study.recommended.as_ref().map(|r| Choice {
            reasons: reasons.clone(),
            ..choice(r, section)
        }),
        best_coverage: study.best_coverage.as_ref().map(|e| choice(e, section)),
        pareto_front: study
            .pareto
            .iter()
            .map(|p| Choice {
                twins: p
                    .twins
                    .iter()
                    .map(|t| StrategyView::new(&t.strategy, section))
                    .collect(),
                ..choice(&p.chosen, section)
            })
            .collect(),
        heatmap: study.heatmap.as_ref().map(|h| HeatmapView {
            positions_m: space.layouts[h.layout]
                .iter()
                .map(|&i| space.positions_m[i])
                .collect(),
            rails: space.rails[h.rails]
                .iter()
                .map(|&r| section.rails[r].clone())
                .collect(),
            pulse_g: h
                .pulse_index
                .iter()
                .map(|&i| space.pulse_kg[i] * 1e3)
                .collect(),
            every_axles: h
                .every_index
                .iter()
                .map(|&i| space.every_axles[i])
                .collect(),
            coverage: h.coverage.clone(),
            admissible: h.admissible.clone(),
        }),
        evaluated: study.evaluated.iter().map(|e| choice(e, section)).collect(),
        model: cfg.clone(),
    };
    let mut json = serde_json::to_string_pretty(&result).map_err(|source| Error::Json {
        what: "the result",
        source,
    })?;
    json.push('\n');
    let md = markdown(
        traffic,
        target,
        study,
        &reasons,
        &today,
        recommended.as_ref(),
    );
    write_atomically(&dir.join("strategy.json"), json.as_bytes())?;
    write_atomically(&dir.join("report.md"), md.as_bytes())?;
    if study.recommended.is_none() && rec_path.exists() {
        // A recording of an earlier run must not pass for this one's.
        std::fs::remove_file(&rec_path).map_err(|source| Error::Io {
            what: "removing",
            path: rec_path.clone(),
            source,
        })?;
    }
    Ok(())
}

fn pct(v: f64) -> String {
    format!("{:.1} %", 100.0 * v)
}

/// Why the recommendation is the one, in sentences.
pub(crate) fn recommendation_reasons(
    traffic: &Traffic,
    target: &Target,
    study: &Study,
) -> Vec<String> {
    let section = &traffic.section;
    let Some(r) = &study.recommended else {
        return vec![format!(
            "No strategy of the space keeps the share of contacts below mu {} within {}: \
             less product per pulse, longer intervals or another position are needed.",
            target.band.lower_mu,
            pct(target.max_below_share)
        )];
    };
    let f = &r.figures;
    let mut out = Vec::new();
    let admissible = study
        .evaluated
        .iter()
        .filter(|e| e.figures.admissible)
        .count();
    out.push(format!(
        "{} of the contacts on the target rails see mu in {}–{}, {} below it \
         (limit {}); {} of the {} strategies evaluated keep within that limit.",
        pct(f.coverage),
        target.band.lower_mu,
        target.band.upper_mu,
        pct(f.below_share),
        pct(target.max_below_share),
        admissible,
        study.evaluated.len()
    ));
    if let Some(b) = &study.best_coverage {
        if b.key == r.key {
            out.push("It is also the best coverage found.".to_string());
        } else {
            let saving = 1.0 - f.product_g_per_day / b.figures.product_g_per_day;
            out.push(format!(
                "The best coverage found, {} ({}), needs {:.1} g/day; this one is within {:.1} \
                 points of it for {:.0} % less product.",
                pct(b.figures.coverage),
                b.strategy.describe(section),
                b.figures.product_g_per_day,
                100.0 * target.coverage_tolerance,
                100.0 * saving
            ));
        }
    }
    let t = &study.today;
    out.push(format!(
        "Today's application: {} in band, {} below, {:.1} g/day; the recommendation \
         changes coverage by {:+.1} points and product by {:+.1} g/day ({:+.0} %).",
        pct(t.coverage),
        pct(t.below_share),
        t.product_g_per_day,
        100.0 * (f.coverage - t.coverage),
        f.product_g_per_day - t.product_g_per_day,
        if t.product_g_per_day > 0.0 {
            100.0 * (f.product_g_per_day / t.product_g_per_day - 1.0)
        } else {
            f64::NAN
        }
    ));
    for rail in &f.rails {
        out.push(format!(
            "Rail {}: carry-on {:.0} m, {} in band, braking risk over {:.0} m, {:.1} g/day, \
             {:.2} g per 1000 axles.",
            rail.rail,
            rail.carry_on_m,
            pct(rail.coverage),
            rail.braking_risk_length_m,
            rail.product_g_per_day,
            rail.product_g_per_1000_axles
        ));
    }
    out
}

fn heatmap_plot(
    space: &Space,
    study: &Study,
    h: &super::HeatmapData,
    section: &Section,
) -> Heatmap {
    let pulses: Vec<String> = h
        .pulse_index
        .iter()
        .map(|&i| format!("{:.3}", space.pulse_kg[i] * 1e3))
        .collect();
    let every: Vec<String> = h
        .every_index
        .iter()
        .map(|&i| space.every_axles[i].to_string())
        .collect();
    let at = space.layouts[h.layout]
        .iter()
        .map(|&i| format!("{} m", space.positions_m[i]))
        .collect::<Vec<_>>()
        .join(" + ");
    let rails = space.rails[h.rails]
        .iter()
        .map(|&r| section.rails[r].as_str())
        .collect::<Vec<_>>()
        .join(", ");
    let values: Vec<Vec<f64>> = h
        .coverage
        .iter()
        .zip(&h.admissible)
        .map(|(row, ok)| {
            row.iter()
                .zip(ok)
                .map(|(&c, &ok)| if ok { c } else { f64::NAN })
                .collect()
        })
        .collect();
    let mut plot = Heatmap::new(
        format!("coverage over pulse mass × interval (applicators at {at}; rails {rails})"),
        "pulse mass [g]",
        "pulse every k axles",
        pulses,
        every,
        values,
    )
    .value_label("contacts with mu in band [%]")
    .missing_label("below-band limit exceeded")
    .range(0.0, 1.0)
    .cell_text(|v| format!("{:.0}", 100.0 * v));
    if let Some(r) = &study.recommended {
        let row = h.every_index.iter().position(|&i| i == r.key.every);
        let col = h.pulse_index.iter().position(|&i| i == r.key.pulse);
        if let (Some(row), Some(col), true) =
            (row, col, r.key.layout == h.layout && r.key.rails == h.rails)
        {
            plot = plot.highlight(row, col);
        }
    }
    plot
}

fn profile_plot(
    target: &Target,
    today: &Figures,
    recommended: Option<&Figures>,
    section: &Section,
) -> LinePlot {
    let panels = (0..section.rails.len())
        .map(|r| {
            let mut panel = Panel::new(format!("mean mu, rail {} [-]", section.rails[r]));
            if let Some(p) = &today.rails[r].profile {
                panel = panel.series(
                    Series::new("today", p.d_m.clone(), p.mean_mu.clone())
                        .colour(Colour::GREY)
                        .dashed(),
                );
            }
            if let Some(p) = recommended.and_then(|f| f.rails[r].profile.as_ref()) {
                panel = panel.series(
                    Series::new("recommended", p.d_m.clone(), p.mean_mu.clone())
                        .colour(Colour::BLUE),
                );
            }
            panel
                .reference_line(ReferenceLine::new(target.band.lower_mu, "band lower edge"))
                .reference_line(ReferenceLine::new(target.band.upper_mu, "band upper edge"))
        })
        .collect();
    LinePlot::stacked(
        "mu seen by the wheels, mean over the period: recommended vs today",
        "distance along the section d [m]",
        panels,
    )
    .x_range(0.0, section.length_m)
}

fn pareto_plot(study: &Study) -> LinePlot {
    let xy = |v: &mut dyn Iterator<Item = &Figures>| -> (Vec<f64>, Vec<f64>) {
        v.map(|f| (f.product_g_per_day, 100.0 * f.coverage)).unzip()
    };
    let (ex, ey) = xy(&mut study
        .evaluated
        .iter()
        .filter(|e| e.figures.admissible)
        .map(|e| &e.figures));
    let (nx, ny) = xy(&mut study
        .evaluated
        .iter()
        .filter(|e| !e.figures.admissible)
        .map(|e| &e.figures));
    let (px, py) = xy(&mut study.pareto.iter().map(|p| &p.chosen.figures));
    let mut panel = Panel::new("contacts with mu in band [%]")
        .series(Series::new("evaluated", ex, ey).colour(Colour::GREY).dots())
        .series(
            Series::new("below-band limit exceeded", nx, ny)
                .colour(Colour::ORANGE)
                .dots(),
        )
        .series(Series::new("Pareto front", px, py).colour(Colour::BLUE));
    let (tx, ty) = xy(&mut std::iter::once(&study.today));
    panel = panel.series(Series::new("today", tx, ty).colour(Colour::RED).dots());
    if let Some(r) = &study.recommended {
        let (rx, ry) = xy(&mut std::iter::once(&r.figures));
        panel = panel.series(
            Series::new("recommended", rx, ry)
                .colour(Colour::GREEN)
                .dots(),
        );
    }
    LinePlot::new(
        "product used against coverage",
        "product used [g/day]",
        panel,
    )
}

fn rail_rows(out: &mut String, label: &str, f: &Figures) {
    for r in &f.rails {
        let worst = r.worst_below.as_ref().map_or_else(
            || "-".to_string(),
            |w| format!("{:.0} % at {:.0} m", 100.0 * w.pass_share, w.d_m),
        );
        let RailFigures {
            rail,
            coverage,
            below_share,
            carry_on_m,
            braking_risk_length_m,
            product_g_per_day,
            product_g_per_1000_axles,
            ..
        } = r;
        let _ = writeln!(
            out,
            "| {label} | {rail} | {} | {carry_on_m:.0} | {} | {braking_risk_length_m:.0} | {worst} | {product_g_per_day:.1} | {product_g_per_1000_axles:.2} |",
            pct(*coverage),
            pct(*below_share),
        );
    }
}

fn markdown(
    traffic: &Traffic,
    target: &Target,
    study: &Study,
    reasons: &[String],
    today: &Figures,
    recommended: Option<&Figures>,
) -> String {
    let section = &traffic.section;
    let mut out = String::new();
    let _ = writeln!(out, "# Application strategies for {}\n", section.section_id);
    let _ = writeln!(
        out,
        "Traffic: {} ({} trains, {} axles, {} day(s)); each strategy's pulses replace the \
         recorded ones, everything else is replayed as recorded through the engine, from \
         clean rails. Target band mu {}–{}; a strategy is admissible when at most {} of the \
         contacts on the target rails see mu below the band.\n",
        traffic.source,
        traffic.trains,
        traffic.axles,
        traffic.days(),
        target.band.lower_mu,
        target.band.upper_mu,
        pct(target.max_below_share)
    );
    let _ = writeln!(
        out,
        "Search: {:?}, {} of the {} strategies of the space evaluated in {:.1} s.\n",
        study.method, study.search_evaluations, study.space_size, study.search_seconds
    );
    let _ = writeln!(out, "## Recommendation\n");
    if let Some(r) = &study.recommended {
        let _ = writeln!(out, "**{}**\n", r.strategy.describe(section));
    }
    for reason in reasons {
        let _ = writeln!(out, "- {reason}");
    }
    let _ = writeln!(out, "\n## Figures per rail\n");
    let _ = writeln!(
        out,
        "Coverage: share of the wheel contacts (every wheel pass at every grid point) with mu \
         in the band. Carry-on: from the applicator downstream (up to the next applicator) to \
         the farthest point where at least {} of the passes see mu in the band. \
         Braking risk: track length where at least {} of the passes see mu below the band.\n",
        pct(target.carry_on_pass_share),
        pct(target.braking_risk_pass_share)
    );
    let _ = writeln!(
        out,
        "| strategy | rail | in band | carry-on [m] | below band | braking risk [m] | worst point | g/day | g/1000 axles |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|---|---|---|---|");
    rail_rows(&mut out, "today", today);
    if let Some(f) = recommended {
        rail_rows(&mut out, "recommended", f);
    }
    if let Some(b) = &study.best_coverage {
        if study.recommended.as_ref().map(|r| r.key) != Some(b.key) {
            rail_rows(&mut out, "best coverage", &b.figures);
        }
    }
    let _ = writeln!(out, "\n![mu along the section](mu_profile.svg)\n");
    if study.heatmap.is_some() {
        let _ = writeln!(out, "![coverage heatmap](coverage_heatmap.svg)\n");
    }
    let _ = writeln!(out, "## Pareto front: product against coverage\n");
    let _ = writeln!(
        out,
        "| strategy | in band | below band | g/day | g/1000 axles |"
    );
    let _ = writeln!(out, "|---|---|---|---|---|");
    for p in &study.pareto {
        let f = &p.chosen.figures;
        let mut name = p.chosen.strategy.describe(section);
        if !p.twins.is_empty() {
            let twins: Vec<String> = p
                .twins
                .iter()
                .map(|t| t.strategy.describe(section))
                .collect();
            name = format!(
                "{name} (the same product and coverage: {})",
                twins.join("; ")
            );
        }
        let _ = writeln!(
            out,
            "| {} | {} | {} | {:.1} | {:.2} |",
            name,
            pct(f.coverage),
            pct(f.below_share),
            f.product_g_per_day,
            f.product_g_per_1000_axles
        );
    }
    let _ = writeln!(out, "\n![Pareto front](pareto.svg)\n");
    let _ = writeln!(
        out,
        "The recommended strategy's friction field is in `recommended.rrd` (`rerun recommended.rrd`); \
         every evaluated strategy's figures are in `strategy.json`."
    );
    out
}
