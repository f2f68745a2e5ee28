//! `tortwin paper`: the paper's Figures 7 and 13–17 (Trummer et al. 2021,
//! sections 2.5 and 4) recomputed by this crate's model and engine, each as
//! a CSV table and an SVG picture, so that a reader can put them next to the
//! paper's and see the twin reproduce it.
//!
//! Figure 7 is the twin disc of eq. (1) and (4) ([`tortwin_strategy::paper::twin_disc`]);
//! Figures 13–17 are wayside scenarios run through the replay engine
//! ([`tortwin_strategy::paper::WaysideScenario`]), with the parameter varied in a copy
//! of the configuration.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use tortwin_model::config::ModelConfig;
use tortwin_plot::{write_csv, write_csv_columns, Colour, LinePlot, Panel, ReferenceLine, Series};
use tortwin_strategy::paper::{twin_disc, PassField, WaysideScenario};
use tortwin_study::{Error, Result};

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct PaperArgs {
    /// Directory for figNN.csv and figNN.svg (created if missing).
    #[cfg_attr(feature = "cli", arg(long, default_value = "out/paper"))]
    pub out: PathBuf,
    /// Model configuration overlaid on the built-in defaults (TOML).
    #[cfg_attr(feature = "cli", arg(long))]
    pub config: Option<super::ConfigSource>,
}

/// One figure written by [`paper`].
#[derive(Debug, Clone, PartialEq)]
pub struct FigureFiles {
    /// "fig07", "fig13", ...
    pub name: &'static str,
    pub what: String,
    pub csv: PathBuf,
    pub svg: PathBuf,
}

/// The numbers of Figure 13 that the paper (and model.md's "Check with the
/// paper") states, as this run gives them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fig13Numbers {
    /// (grid point's d in m, mu there) nearest to 0, 81 and 150 m.
    pub mu_at: [(f64, f64); 3],
    /// The first grid point where the rail keeps less than 1 mg.
    pub rail_below_1mg_from_m: Option<f64>,
    /// (grid point's d in m, wheel mass in mg) nearest to 500 m.
    pub wheel_mass_at_500_mg: (f64, f64),
}

#[derive(Debug, Clone, PartialEq)]
pub struct PaperReport {
    pub out_dir: PathBuf,
    pub figures: Vec<FigureFiles>,
    pub fig13: Fig13Numbers,
}

const D_LABEL: &str = "distance from applicator d [m]";
const MU_LABEL: &str = "coefficient of friction mu [-]";
/// The y range of every mu plot, so that the figures compare at a glance.
const MU_RANGE: (f64, f64) = (0.1, 0.65);

/// Computes and writes every figure into `args.out`.
pub fn paper(args: &PaperArgs) -> Result<PaperReport> {
    let cfg = super::load_config(args.config.as_ref())?;
    let out = &args.out;
    std::fs::create_dir_all(out).map_err(|source| Error::Io {
        what: "cannot create",
        path: out.clone(),
        source,
    })?;
    let mut figures = Vec::new();

    // Figure 7: twin disc, three applied masses.
    {
        let revolutions = 3000;
        let m0_g = [0.1, 0.3, 0.5];
        let n: Vec<f64> = (1..=revolutions).map(|k| k as f64).collect();
        let mu: Vec<Vec<f64>> = m0_g
            .iter()
            .map(|g| twin_disc(&cfg, g * 1e-3, revolutions))
            .collect();
        let rows = (0..revolutions).map(|k| [n[k], mu[0][k], mu[1][k], mu[2][k]]);
        let f = figure_files(
            out,
            "fig07",
            "twin disc: mu vs revolutions N for m0 = 0.1, 0.3, 0.5 g",
        );
        write_csv(
            &f.csv,
            &["N", "mu_m0_0.1g", "mu_m0_0.3g", "mu_m0_0.5g"],
            rows,
        )?;
        let mut panel = mu_panel(&cfg);
        for (k, (g, mu)) in m0_g.iter().zip(mu).enumerate() {
            panel = panel.series(
                Series::new(format!("m0 = {g} g"), n.clone(), mu).colour(Colour::palette(k)),
            );
        }
        LinePlot::new(
            "Figure 7: twin disc, eq. (1) and (4)",
            "number of disc revolutions N [-]",
            panel,
        )
        .x_range(0.0, revolutions as f64)
        .write_svg(&f.svg)?;
        figures.push(f);
    }

    // Figure 13: the reference scenario after 100 passes.
    let reference = after_pass_100(&cfg)?;
    let fig13 = {
        let r = &reference;
        let mg = |kg: &[f64]| kg.iter().map(|m| m * 1e6).collect::<Vec<f64>>();
        let (rail_mg, wheel_mg) = (mg(&r.rail_mass_kg), mg(&r.wheel_mass_kg));
        let f = figure_files(
            out,
            "fig13",
            "0.1 g before each of 100 passes: masses and mu after pass 100",
        );
        write_csv_columns(
            &f.csv,
            &[
                ("d_m", &r.d_m),
                ("mu", &r.mu),
                ("rail_mass_mg", &rail_mg),
                ("wheel_mass_mg", &wheel_mg),
            ],
        )?;
        let masses = Panel::new("product mass [mg]")
            .series(Series::new("rail m_r", r.d_m.clone(), rail_mg).colour(Colour::BLUE))
            .series(Series::new("wheel m_w", r.d_m.clone(), wheel_mg.clone()).colour(Colour::RED))
            .y_range(0.0, 110.0);
        let mu = mu_panel(&cfg).series(
            Series::new("mu seen by wheel 100", r.d_m.clone(), r.mu.clone()).colour(Colour::BLACK),
        );
        LinePlot::stacked(
            "Figure 13: after 100 passes, 0.1 g before each pass",
            D_LABEL,
            vec![masses, mu],
        )
        .x_range(0.0, 600.0)
        .write_svg(&f.svg)?;
        figures.push(f);

        let nearest = |d: f64| nearest_index(&r.d_m, d);
        let i500 = nearest(500.0);
        Fig13Numbers {
            mu_at: [0.0, 81.0, 150.0].map(|d| {
                let i = nearest(d);
                (r.d_m[i], r.mu[i])
            }),
            rail_below_1mg_from_m: r
                .rail_mass_kg
                .iter()
                .position(|&m| m < 1e-6)
                .map(|i| r.d_m[i]),
            wheel_mass_at_500_mg: (r.d_m[i500], wheel_mg[i500]),
        }
    };

    // Figures 14–16: one parameter of eq. (6) or (1) varied, mu after pass 100.
    let cm_g = cfg.product.cm_kg * 1e3;
    let variations: [(&'static str, &str, &str, Vec<Variation>); 3] = [
        (
            "fig14",
            "mu after pass 100, transfer parameter cm x 0.2, 1, 5",
            "Figure 14: variation of cm, transfer function eq. (6)",
            [1.0, 0.2, 5.0]
                .iter()
                .map(|&x| {
                    Variation::new("cm", x, format!("{} g", fmt_g(x * cm_g)), |c, x| {
                        c.product.cm_kg *= x
                    })
                })
                .collect(),
        ),
        (
            "fig15",
            "mu after pass 100, transfer parameter cN x 0.5, 1, 2",
            "Figure 15: variation of cN, transfer function eq. (6)",
            [1.0, 0.5, 2.0]
                .iter()
                .map(|&x| {
                    Variation::new("cN", x, format!("{}", x * cfg.product.cn), |c, x| {
                        c.product.cn *= x
                    })
                })
                .collect(),
        ),
        (
            "fig16",
            "mu after pass 100, consumption parameters km1 x 0.5, 2 and km2 x 0.5, 2",
            "Figure 16: variation of km1 and km2, consumption eq. (1)",
            {
                let km1_mg = cfg.product.km1_kg * 1e6;
                let km2 = cfg.product.km2;
                let mut v = vec![Variation::new("km1", 1.0, String::new(), |_, _| {})];
                for x in [0.5, 2.0] {
                    v.push(Variation::new(
                        "km1",
                        x,
                        format!("{:.3} mg", x * km1_mg),
                        |c, x| c.product.km1_kg *= x,
                    ));
                }
                for x in [0.5, 2.0] {
                    v.push(
                        Variation::new("km2", x, format!("{}", x * km2), |c, x| c.product.km2 *= x)
                            .dashed(),
                    );
                }
                v
            },
        ),
    ];
    for (name, what, title, variations) in variations {
        let fields = variations
            .iter()
            .map(|v| {
                let mut c = cfg.clone();
                (v.apply)(&mut c, v.factor);
                after_pass_100(&c)
            })
            .collect::<Result<Vec<_>>>()?;
        let f = figure_files(out, name, what);
        let headers: Vec<String> = variations.iter().map(Variation::column).collect();
        let mut columns: Vec<(&str, &[f64])> = vec![("d_m", &reference.d_m)];
        columns.extend(
            headers
                .iter()
                .map(String::as_str)
                .zip(fields.iter().map(|f| f.mu.as_slice())),
        );
        write_csv_columns(&f.csv, &columns)?;
        let mut panel = mu_panel(&cfg);
        let mut palette = 0;
        for (v, field) in variations.iter().zip(&fields) {
            let colour = if v.factor == 1.0 {
                Colour::BLACK
            } else {
                palette += 1;
                Colour::palette(palette - 1)
            };
            let mut s = Series::new(v.legend(), field.d_m.clone(), field.mu.clone()).colour(colour);
            if v.dashed {
                s = s.dashed();
            }
            panel = panel.series(s);
        }
        LinePlot::new(title, D_LABEL, panel)
            .x_range(0.0, 600.0)
            .write_svg(&f.svg)?;
        figures.push(f);
    }

    // Figure 17: the same mean mass, applied as 0.02 g before every pass or
    // 0.20 g before every 10th pass.
    {
        let small = WaysideScenario {
            dose_kg: 0.02e-3,
            every: 1,
            passes: 100,
            ..WaysideScenario::default()
        };
        let large = WaysideScenario {
            dose_kg: 0.20e-3,
            every: 10,
            passes: 101,
            ..WaysideScenario::default()
        };
        let small_fields = small.run(&cfg, &[100])?;
        let small_100 = pass(&small_fields, 100)?;
        let large_fields = large.run(&cfg, &[100, 101])?;
        let (large_100, large_101) = (pass(&large_fields, 100)?, pass(&large_fields, 101)?);
        let f = figure_files(
            out,
            "fig17",
            "0.02 g every pass (pass 100) vs 0.20 g every 10th pass (passes 100, 101)",
        );
        write_csv_columns(
            &f.csv,
            &[
                ("d_m", &small_100.d_m),
                ("mu_0.02g_every_pass_pass100", &small_100.mu),
                ("mu_0.20g_every_10th_pass100", &large_100.mu),
                ("mu_0.20g_every_10th_pass101", &large_101.mu),
            ],
        )?;
        let d = &small_100.d_m;
        let panel = mu_panel(&cfg)
            .series(
                Series::new(
                    "0.02 g every pass, pass 100",
                    d.clone(),
                    small_100.mu.clone(),
                )
                .colour(Colour::BLUE),
            )
            .series(
                Series::new(
                    "0.20 g every 10th pass, pass 100 (before reapplication)",
                    d.clone(),
                    large_100.mu.clone(),
                )
                .colour(Colour::RED)
                .dashed(),
            )
            .series(
                Series::new(
                    "0.20 g every 10th pass, pass 101 (after reapplication)",
                    d.clone(),
                    large_101.mu.clone(),
                )
                .colour(Colour::RED),
            );
        LinePlot::new(
            "Figure 17: application pattern, same mean mass",
            D_LABEL,
            panel,
        )
        .x_range(0.0, 600.0)
        .write_svg(&f.svg)?;
        figures.push(f);
    }

    Ok(PaperReport {
        out_dir: out.clone(),
        figures,
        fig13,
    })
}

/// The short table printed after a run.
pub fn render(report: &PaperReport) -> String {
    let mut s = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(
        s,
        "paper figures (Trummer et al. 2021) in {}",
        report.out_dir.display()
    );
    for f in &report.figures {
        let file = |p: &Path| {
            p.file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
        };
        let _ = writeln!(
            s,
            "  {}  {:<10} {:<10} {}",
            f.name,
            file(&f.csv),
            file(&f.svg),
            f.what
        );
    }
    let n = &report.fig13;
    let _ = writeln!(
        s,
        "figure 13 after pass 100{:18}this run   paper (see spec/model.md)",
        ""
    );
    let mut row = |what: String, got: String, paper: &str| {
        let _ = writeln!(s, "  {what:<40}{got:<11}{paper}");
    };
    for ((d, mu), paper) in n.mu_at.iter().zip(["0.276", "0.31", "0.41"]) {
        row(format!("mu at d = {d:.1} m"), format!("{mu:.3}"), paper);
    }
    let below = n
        .rail_below_1mg_from_m
        .map_or_else(|| "never".into(), |d| format!("{d:.1} m"));
    row(
        "rail mass below 1 mg from".into(),
        below,
        "about 240 m (none beyond 250 m)",
    );
    let (d, m) = n.wheel_mass_at_500_mg;
    row(
        format!("wheel mass at d = {d:.1} m"),
        format!("{m:.1} mg"),
        "about 27 mg",
    );
    s
}

/// A copy of the configuration with one parameter scaled.
struct Variation {
    parameter: &'static str,
    factor: f64,
    /// The scaled value, for the legend.
    value: String,
    apply: fn(&mut ModelConfig, f64),
    dashed: bool,
}

impl Variation {
    fn new(
        parameter: &'static str,
        factor: f64,
        value: String,
        apply: fn(&mut ModelConfig, f64),
    ) -> Self {
        Self {
            parameter,
            factor,
            value,
            apply,
            dashed: false,
        }
    }

    fn dashed(mut self) -> Self {
        self.dashed = true;
        self
    }

    fn column(&self) -> String {
        if self.factor == 1.0 {
            "mu_reference".into()
        } else {
            format!("mu_{}_x{}", self.parameter, self.factor)
        }
    }

    fn legend(&self) -> String {
        if self.factor == 1.0 {
            "reference (Table 2)".into()
        } else {
            format!("{} x {} = {}", self.factor, self.parameter, self.value)
        }
    }
}

fn mu_panel(cfg: &ModelConfig) -> Panel {
    Panel::new(MU_LABEL)
        .reference_line(ReferenceLine::new(
            cfg.product.mu_d,
            format!("muD = {}", cfg.product.mu_d),
        ))
        .reference_line(ReferenceLine::new(
            cfg.product.mu_c,
            format!("muC = {}", cfg.product.mu_c),
        ))
        .y_range(MU_RANGE.0, MU_RANGE.1)
}

fn figure_files(out: &Path, name: &'static str, what: &str) -> FigureFiles {
    FigureFiles {
        name,
        what: what.into(),
        csv: out.join(format!("{name}.csv")),
        svg: out.join(format!("{name}.svg")),
    }
}

/// Section 4.1's scenario with `cfg`: the field after pass 100.
fn after_pass_100(cfg: &ModelConfig) -> Result<PassField> {
    let fields = WaysideScenario::default().run(cfg, &[100])?;
    pass(&fields, 100).cloned()
}

fn pass(fields: &[PassField], k: usize) -> Result<&PassField> {
    fields
        .iter()
        .find(|f| f.pass == k)
        .ok_or_else(|| Error::Inconsistent(format!("the scenario gave no field after pass {k}")))
}

fn nearest_index(d_m: &[f64], d: f64) -> usize {
    (0..d_m.len())
        .min_by(|&a, &b| (d_m[a] - d).abs().total_cmp(&(d_m[b] - d).abs()))
        .unwrap_or(0)
}

/// A mass in g with the digits it needs (0.007, 0.035, 0.175).
fn fmt_g(g: f64) -> String {
    format!("{:.4}", g)
        .trim_end_matches('0')
        .trim_end_matches('.')
        .to_string()
}
