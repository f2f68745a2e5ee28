//! Every row of tests/reference/contact_golden.csv, the values of an
//! independent implementation of docs/spec/contact.md, must be matched
//! to 1e-6 relative (contact.md, first paragraph).
//!
//! The file has one header row and one row per case; `kind` says which
//! function the row checks and which columns it fills:
//!
//! - `hertz`: Q_N, R_wx_m, R_wy_m (`inf` = flat), R_ry_m, E_Pa, nu ->
//!   a_m, b_m, p0_Pa, pm_Pa.
//! - `kalker`: nu, a_m, b_m -> c11, c22, c23.
//! - `polach`: Q_N, a_m, b_m, G_Pa, c11, c22, c23, sx, sy, psi_per_m, V_mps,
//!   mu0, A, B_s_per_m, kA, kS -> mu_slip, eps, eps_M, Fx_N, Fy_N (total
//!   lateral force including spin), T_over_Q.

// A test asserts by panicking (clippy.toml allows it inside #[test] functions;
// this file's helpers are test code too).
#![allow(clippy::panic, clippy::expect_used, clippy::unwrap_used)]

use std::collections::HashMap;
use std::path::PathBuf;

use tortwin_model::contact::{
    hertz, kalker, polach, KalkerCoefficients, PolachInput, PolachParams, Steel,
};

/// Relative tolerance of contact.md.
const REL_TOL: f64 = 1e-6;
/// Where the reference value is exactly 0 a relative error is undefined; the
/// result must then be zero to this absolute amount (in the column's unit).
const ABS_FLOOR_AT_ZERO: f64 = 1e-12;

/// One row of the golden file: the case name, its kind and its non-empty
/// columns by header name.
struct Row {
    case: String,
    kind: String,
    values: HashMap<String, f64>,
}

impl Row {
    fn get(&self, column: &str) -> f64 {
        match self.values.get(column) {
            Some(v) => *v,
            None => panic!("{}: column {column} is empty or missing", self.case),
        }
    }
}

fn golden_rows() -> Vec<Row> {
    let path =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/reference/contact_golden.csv");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let mut lines = text.lines().filter(|l| !l.trim().is_empty());
    let header: Vec<&str> = lines
        .next()
        .expect("empty golden file")
        .split(',')
        .collect();
    assert_eq!(
        header[..2],
        ["case", "kind"],
        "unexpected header: {header:?}"
    );
    lines
        .map(|line| {
            let fields: Vec<&str> = line.split(',').collect();
            assert_eq!(fields.len(), header.len(), "ragged row: {line}");
            let values = header[2..]
                .iter()
                .zip(&fields[2..])
                .filter(|(_, f)| !f.trim().is_empty())
                .map(|(name, f)| {
                    // Rust's float parser reads `inf` as f64::INFINITY.
                    let v: f64 = f
                        .trim()
                        .parse()
                        .unwrap_or_else(|e| panic!("{}: {name} = {f:?}: {e}", fields[0]));
                    (name.to_string(), v)
                })
                .collect();
            Row {
                case: fields[0].to_string(),
                kind: fields[1].to_string(),
                values,
            }
        })
        .collect()
}

/// Compares one output against the reference column, returns the relative
/// error (0 where both are exactly 0) and records a message on failure.
fn check(row: &Row, column: &str, got: f64, failures: &mut Vec<String>) -> f64 {
    let want = row.get(column);
    let (error, ok) = if want == 0.0 {
        (got.abs(), got.abs() <= ABS_FLOOR_AT_ZERO)
    } else {
        let rel = ((got - want) / want).abs();
        (rel, rel <= REL_TOL)
    };
    if !ok {
        failures.push(format!(
            "{} {column}: got {got:e}, want {want:e} (error {error:e})",
            row.case
        ));
    }
    if want == 0.0 {
        0.0
    } else {
        error
    }
}

/// Checks every row of `kind` with `outputs`, which returns (column, value)
/// pairs for a row; asserts the number of rows and prints the worst error.
fn check_kind(
    kind: &str,
    expected_rows: usize,
    outputs: impl Fn(&Row) -> Vec<(&'static str, f64)>,
) {
    let rows: Vec<Row> = golden_rows()
        .into_iter()
        .filter(|r| r.kind == kind)
        .collect();
    assert_eq!(rows.len(), expected_rows, "number of {kind} rows");
    let mut failures = Vec::new();
    let mut worst = (0.0_f64, String::new());
    for row in &rows {
        for (column, got) in outputs(row) {
            let rel = check(row, column, got, &mut failures);
            if rel >= worst.0 {
                worst = (rel, format!("{} {column}", row.case));
            }
        }
    }
    println!(
        "{kind}: {} rows, worst relative error {:e} at {}",
        rows.len(),
        worst.0,
        worst.1
    );
    assert!(
        failures.is_empty(),
        "{} mismatches:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

#[test]
fn golden_file_has_only_known_kinds() {
    let rows = golden_rows();
    assert_eq!(rows.len(), 99);
    for row in &rows {
        assert!(
            matches!(row.kind.as_str(), "hertz" | "kalker" | "polach"),
            "{}: unknown kind {}",
            row.case,
            row.kind
        );
    }
}

#[test]
fn hertz_rows() {
    check_kind("hertz", 32, |row| {
        let steel = Steel {
            e_pa: row.get("E_Pa"),
            nu: row.get("nu"),
        };
        let h = hertz(
            row.get("Q_N"),
            row.get("R_wx_m"),
            row.get("R_wy_m"),
            row.get("R_ry_m"),
            &steel,
        );
        vec![
            ("a_m", h.a_m),
            ("b_m", h.b_m),
            ("p0_Pa", h.p0_pa),
            ("pm_Pa", h.pm_pa),
        ]
    });
}

#[test]
fn kalker_rows() {
    check_kind("kalker", 40, |row| {
        let k = kalker(row.get("nu"), row.get("a_m"), row.get("b_m"));
        vec![("c11", k.c11), ("c22", k.c22), ("c23", k.c23)]
    });
}

#[test]
fn polach_rows() {
    check_kind("polach", 27, |row| {
        let input = PolachInput {
            q_n: row.get("Q_N"),
            a_m: row.get("a_m"),
            b_m: row.get("b_m"),
            g_pa: row.get("G_Pa"),
            kalker: KalkerCoefficients {
                c11: row.get("c11"),
                c22: row.get("c22"),
                c23: row.get("c23"),
            },
            sx: row.get("sx"),
            sy: row.get("sy"),
            psi_per_m: row.get("psi_per_m"),
            speed_mps: row.get("V_mps"),
            mu0: row.get("mu0"),
        };
        let params = PolachParams {
            p_a: row.get("A"),
            p_b_s_per_m: row.get("B_s_per_m"),
            k_a: row.get("kA"),
            k_s: row.get("kS"),
        };
        let f = polach(&input, &params);
        vec![
            ("mu_slip", f.mu_slip),
            ("eps", f.eps),
            ("eps_M", f.eps_m),
            ("Fx_N", f.fx_n),
            ("Fy_N", f.fy_n),
            ("T_over_Q", f.t_over_q),
        ]
    });
}

/// The polach rows give G directly; it is the spec's steel's
/// `G = E / (2 (1 + nu))` with E = 210 GPa and the row's nu.
#[test]
fn polach_rows_use_the_spec_steel() {
    for row in golden_rows().iter().filter(|r| r.kind == "polach") {
        let steel = Steel {
            nu: row.get("nu"),
            ..Steel::DEFAULT
        };
        let want = row.get("G_Pa");
        assert!(
            ((steel.g_pa() - want) / want).abs() <= 1e-15,
            "{}",
            row.case
        );
    }
}
