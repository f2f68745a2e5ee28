//! `tortwin paper`: every figure is written, the pictures carry their axis
//! labels, the CSVs of Figures 7, 13 and 17 are the reference
//! implementation's (tests/reference/paper_fig7.csv, paper_fig13.csv and
//! paper_fig17.csv), and Figures 14–17 show what the paper's section 4
//! says about them.
//!
//! The thresholds of the section 4 checks are set from what the model gives
//! with Table 2 (printed in the comments) with room to spare, but tight
//! enough that a change of the physics behind the statement fails them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use tortwin_jobs::paper::{paper, PaperArgs, PaperReport};

const FIGURES: [&str; 6] = ["fig07", "fig13", "fig14", "fig15", "fig16", "fig17"];

/// Runs the command into a fresh temporary directory (it takes
/// milliseconds, so every test has its own).
fn run() -> (tempfile::TempDir, PaperReport) {
    let dir = tempfile::tempdir().unwrap();
    let report = paper(&PaperArgs {
        out: dir.path().join("figures"),
        config: None,
    })
    .unwrap();
    (dir, report)
}

/// A CSV written by the command, by column name.
fn columns(path: &Path) -> BTreeMap<String, Vec<f64>> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .split(',')
        .map(str::to_string)
        .collect();
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); header.len()];
    for line in lines.filter(|l| !l.trim().is_empty()) {
        let values: Vec<f64> = line.split(',').map(|v| v.parse().unwrap()).collect();
        assert_eq!(values.len(), header.len(), "{}: {line}", path.display());
        for (col, v) in cols.iter_mut().zip(values) {
            col.push(v);
        }
    }
    header.into_iter().zip(cols).collect()
}

/// Runs the command and reads one of its CSV files.
fn figure(name: &str) -> BTreeMap<String, Vec<f64>> {
    let (_dir, report) = run();
    columns(&report.out_dir.join(format!("{name}.csv")))
}

fn col<'a>(fig: &'a BTreeMap<String, Vec<f64>>, name: &str) -> &'a [f64] {
    fig.get(name).unwrap_or_else(|| {
        panic!(
            "no column {name}; columns: {:?}",
            fig.keys().collect::<Vec<_>>()
        )
    })
}

/// The first d where `mu` reaches `level`.
fn first_reaching(d: &[f64], mu: &[f64], level: f64) -> f64 {
    d.iter()
        .zip(mu)
        .find(|(_, &m)| m >= level)
        .map(|(&d, _)| d)
        .expect("mu never reaches the level")
}

#[test]
fn every_figure_is_written_with_labelled_axes() {
    let (_dir, report) = run();
    let out_dir = &report.out_dir;
    let names: Vec<&str> = report.figures.iter().map(|f| f.name).collect();
    assert_eq!(names, FIGURES);
    for name in FIGURES {
        let csv = out_dir.join(format!("{name}.csv"));
        let svg_path = out_dir.join(format!("{name}.svg"));
        let fig = columns(&csv);
        assert!(fig.len() >= 2, "{name}.csv has {} columns", fig.len());
        let rows = fig.values().next().unwrap().len();
        assert!(rows >= 200, "{name}.csv has {rows} rows");

        let svg = std::fs::read_to_string(&svg_path).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
            "{name}.svg is not an SVG"
        );
        assert!(svg.len() > 10_000, "{name}.svg is only {} bytes", svg.len());
        assert!(
            svg.matches("<polyline").count() >= 3,
            "{name}.svg draws almost no lines"
        );
        let x_label = if name == "fig07" {
            "number of disc revolutions N [-]"
        } else {
            "distance from applicator d [m]"
        };
        for label in [
            x_label,
            "coefficient of friction mu [-]",
            "muD = 0.58",
            "muC = 0.15",
        ] {
            assert!(svg.contains(label), "{name}.svg lacks \"{label}\"");
        }
    }
    let fig13 = std::fs::read_to_string(out_dir.join("fig13.svg")).unwrap();
    assert!(fig13.contains("product mass [mg]"));
    assert_eq!(
        columns(&out_dir.join("fig07.csv"))
            .values()
            .next()
            .unwrap()
            .len(),
        3000
    );
}

#[test]
fn figures_7_and_13_csv_are_the_reference() {
    let (_dir, report) = run();
    let reference = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/reference");
    for (name, reference_csv, cols) in [
        (
            "fig07",
            "paper_fig7.csv",
            &["N", "mu_m0_0.1g", "mu_m0_0.3g", "mu_m0_0.5g"][..],
        ),
        (
            "fig13",
            "paper_fig13.csv",
            &["d_m", "mu", "rail_mass_mg", "wheel_mass_mg"][..],
        ),
    ] {
        let want = columns(&reference.join(reference_csv));
        let got = columns(&report.out_dir.join(format!("{name}.csv")));
        for &c in cols {
            let (g, w) = (col(&got, c), col(&want, c));
            assert_eq!(g.len(), w.len(), "{name} {c}: rows");
            for (i, (g, w)) in g.iter().zip(w).enumerate() {
                let scale = w.abs().max(1e-300);
                assert!(
                    (g - w).abs() <= 1e-9 * scale,
                    "{name} {c} row {i}: got {g:e}, reference {w:e}"
                );
            }
        }
    }
}

#[test]
fn figure_13_numbers_printed_are_the_papers() {
    let (_dir, report) = run();
    let n = report.fig13;
    let [(d0, mu0), (d81, mu81), (d150, mu150)] = n.mu_at;
    assert_eq!(d0, 0.0);
    assert!((d81 - 81.0).abs() < 1.5 && (d150 - 150.0).abs() < 1.5);
    assert!(
        (mu0 - 0.276).abs() < 0.0005 && (mu81 - 0.31).abs() < 0.01 && (mu150 - 0.41).abs() < 0.01
    );
    let below = n.rail_below_1mg_from_m.unwrap();
    assert!((220.0..260.0).contains(&below), "{below}");
    assert!(
        (n.wheel_mass_at_500_mg.1 - 27.0).abs() < 2.0,
        "{:?}",
        n.wheel_mass_at_500_mg
    );
    let text = tortwin_jobs::paper::render(&report);
    for f in FIGURES {
        assert!(
            text.contains(&format!("{f}.csv")) && text.contains(&format!("{f}.svg")),
            "{text}"
        );
    }
}

#[test]
fn figure_14_small_cm_changes_little_large_cm_raises_mu() {
    // Section 4.3: "the curve for 0.2 cm is almost identical to the
    // reference"; increasing cm reduces transfer and raises mu.
    // Model: max |0.2 cm - reference| = 0.008; 5 cm is above the reference
    // by at least 0.021 everywhere past the applicator.
    let f = figure("fig14");
    let (d, reference) = (col(&f, "d_m"), col(&f, "mu_reference"));
    let small = col(&f, "mu_cm_x0.2");
    let large = col(&f, "mu_cm_x5");
    let max_small = small
        .iter()
        .zip(reference)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(
        max_small < 0.015,
        "0.2 cm differs from the reference by {max_small}"
    );
    for i in 1..d.len() {
        assert!(
            large[i] - reference[i] > 0.015,
            "5 cm at {} m: {} vs {}",
            d[i],
            large[i],
            reference[i]
        );
    }
}

#[test]
fn figure_15_smaller_cn_moves_the_transition_towards_the_applicator() {
    // Section 4.3: reducing cN "shifts the location of the transition
    // between coefficient of friction 0.3 and 0.4 towards the application
    // site". Model: mu reaches 0.35 at 69 m (0.5 cN), 110 m (reference),
    // 150 m (2 cN).
    let f = figure("fig15");
    let d = col(&f, "d_m");
    let at = |name: &str| first_reaching(d, col(&f, name), 0.35);
    let (half, reference, double) = (at("mu_cN_x0.5"), at("mu_reference"), at("mu_cN_x2"));
    assert!(
        reference - half > 25.0,
        "0.5 cN: {half} m, reference {reference} m"
    );
    assert!(
        double - reference > 25.0,
        "2 cN: {double} m, reference {reference} m"
    );
    // All three start from the same friction at the applicator.
    for name in ["mu_cN_x0.5", "mu_cN_x2"] {
        assert!((col(&f, name)[0] - col(&f, "mu_reference")[0]).abs() < 1e-3);
    }
}

#[test]
fn figure_16_consumption_km1_everywhere_km2_far_away() {
    // Section 4.4: increasing km1 makes mu rise quickly; reducing it keeps
    // mu at an intermediate level. Model, d >= 100 m: 2 km1 is above the
    // reference by at least 0.043, 0.5 km1 below it by at least 0.020.
    // km2 "has a larger influence further away": below 0.005 within 50 m,
    // about 0.03 past 500 m; increasing km2 (less consumption) lowers mu.
    let f = figure("fig16");
    let (d, reference) = (col(&f, "d_m"), col(&f, "mu_reference"));
    let (km1_half, km1_double) = (col(&f, "mu_km1_x0.5"), col(&f, "mu_km1_x2"));
    let (km2_half, km2_double) = (col(&f, "mu_km2_x0.5"), col(&f, "mu_km2_x2"));
    for i in (0..d.len()).filter(|&i| d[i] >= 100.0) {
        assert!(km1_double[i] - reference[i] > 0.03, "2 km1 at {} m", d[i]);
        assert!(reference[i] - km1_half[i] > 0.01, "0.5 km1 at {} m", d[i]);
    }
    for i in 0..d.len() {
        let effect = (km2_double[i] - reference[i])
            .abs()
            .max((km2_half[i] - reference[i]).abs());
        if d[i] < 50.0 {
            assert!(
                effect < 0.005,
                "km2 near the applicator, {} m: {effect}",
                d[i]
            );
        }
        if d[i] > 500.0 {
            assert!(effect > 0.02, "km2 far away, {} m: {effect}", d[i]);
            assert!(
                km2_double[i] < reference[i] && reference[i] < km2_half[i],
                "km2 order at {} m",
                d[i]
            );
        }
    }
}

#[test]
fn figure_17_patterns_differ_only_near_the_applicator() {
    // Section 4.5: the two patterns "show different values of the
    // coefficient of friction only in a short section after the application
    // site. Further away ... very similar". Model: |pass 101 of 0.20 g every
    // 10th - pass 100 of 0.02 g every pass| is 0.188 at the applicator and
    // at most 0.025 beyond 300 m.
    let f = figure("fig17");
    let d = col(&f, "d_m");
    let small = col(&f, "mu_0.02g_every_pass_pass100");
    let before = col(&f, "mu_0.20g_every_10th_pass100");
    let after = col(&f, "mu_0.20g_every_10th_pass101");
    let max_diff = |keep: &dyn Fn(f64) -> bool| {
        (0..d.len())
            .filter(|&i| keep(d[i]))
            .map(|i| (after[i] - small[i]).abs())
            .fold(0.0, f64::max)
    };
    let near = max_diff(&|d| d < 20.0);
    let far = max_diff(&|d| d > 300.0);
    assert!(near > 0.1, "near the applicator: {near}");
    assert!(
        far < 0.03 && far < near / 5.0,
        "beyond 300 m: {far} (near: {near})"
    );
    // Reapplying 0.20 g lowers mu at the applicator (overapplication), and
    // before reapplication the rail there has dried to nearly muD.
    assert!(
        after[0] < 0.3 && before[0] > 0.5,
        "{} {}",
        after[0],
        before[0]
    );
}

/// Figure 17 as `tortwin paper` draws it equals the independent
/// implementation's (tests/reference/paper_fig17.csv, m0 a constant of the
/// product) to 1e-9 relative at every point, and says the paper's two
/// sentences (section 4.5): the patterns differ strongly just after the
/// applicator, and further away they are "very similar with a tendency
/// for a small reduction of the coefficient of friction when smaller
/// amounts were applied more frequently".
#[test]
fn figure_17_is_the_reference_and_the_papers_statements() {
    let f = figure("fig17");
    let want =
        columns(&PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/reference/paper_fig17.csv"));
    for (ours, theirs) in [
        ("d_m", "d_m"),
        ("mu_0.02g_every_pass_pass100", "mu_every_pass_p100"),
        ("mu_0.20g_every_10th_pass100", "mu_every10_p100"),
        ("mu_0.20g_every_10th_pass101", "mu_every10_p101"),
    ] {
        let (g, w) = (col(&f, ours), col(&want, theirs));
        assert_eq!(g.len(), w.len(), "fig17 {ours}: rows");
        for (i, (g, w)) in g.iter().zip(w).enumerate() {
            assert!(
                (g - w).abs() <= 1e-9 * w.abs().max(1e-300),
                "fig17 {ours} row {i}: got {g:e}, reference {w:e}"
            );
        }
    }
    let d = col(&f, "d_m");
    let every_pass = col(&f, "mu_0.02g_every_pass_pass100");
    let every_10th = col(&f, "mu_0.20g_every_10th_pass100");
    let after = col(&f, "mu_0.20g_every_10th_pass101");
    // At the applicator: 0.464 every pass against 0.558 and 0.276.
    for other in [every_10th[0], after[0]] {
        assert!(
            (every_pass[0] - other).abs() > 0.05,
            "at the applicator: every pass {} against {other}",
            every_pass[0]
        );
    }
    // Beyond 300 m: the every-pass curve lies below the every-10th curve
    // of pass 100, by less than 0.005 (0.0013 to 0.0034).
    let far: Vec<usize> = (0..d.len()).filter(|&i| d[i] > 300.0).collect();
    assert!(far.len() > 50);
    for i in far {
        let below = every_10th[i] - every_pass[i];
        assert!(
            below > 0.0 && below < 0.005,
            "at {} m: every pass {} against every 10th {}",
            d[i],
            every_pass[i],
            every_10th[i]
        );
    }
}
