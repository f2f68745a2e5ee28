//! What discover's findings mean for the people who maintain the track:
//! one sentence per generic term, and where a residual no term explains
//! lives.

use serde::Serialize;

use super::data::Dataset;
use super::space::Drivers;
use tortwin_model::config::{format_utc, GenericTerm, TermEffect};
use tortwin_model::generic::{ActsOn, Driver, Form};

/// One sentence an engineer can act on.
pub(super) fn term(t: &GenericTerm, data: &Dataset, drivers: &Drivers) -> String {
    let on_rail = t
        .rail
        .as_ref()
        .map_or_else(String::new, |r| format!(" on the {r} rail"));
    match t.effect {
        TermEffect::Offset { offset } => {
            let site = t
                .site
                .as_deref()
                .map_or("every".to_string(), |s| s.to_string());
            let rail = t
                .rail
                .as_deref()
                .map_or(String::new(), |r| format!(" {r}-rail"));
            let quantity = t.quantity.map_or("friction", |q| q.as_str());
            let side = if offset > 0.0 { "above" } else { "below" };
            format!(
                "The {site}{rail} {quantity} sensor reads about {:.3} {side} the model: check its \
                 calibration (a data-quality finding, not physics; the twin's simulated values \
                 include the offset).",
                offset.abs()
            )
        }
        TermEffect::Factor { driver, form } => {
            let who = match (t.acts_on, &t.applicator) {
                (ActsOn::PulseMass, Some(a)) => format!("applicator {a}"),
                (ActsOn::PulseMass, None) if data.section.applicators.len() == 1 => data
                    .section
                    .applicators
                    .first()
                    .map_or("the applicators".into(), |a| format!("applicator {}", a.id)),
                (ActsOn::PulseMass, None) => "every applicator".into(),
                _ => String::new(),
            };
            if let (Driver::Time, Form::Step { x0, f }) = (driver, form) {
                let since = format_utc(x0);
                return match t.acts_on {
                    ActsOn::PulseMass if f < 1.0 => format!(
                        "{} delivers about {:.0} % of the logged mass{on_rail} since {since}: \
                         inspect the nozzle and the tank.",
                        capitalised(&who),
                        100.0 * f
                    ),
                    ActsOn::PulseMass => format!(
                        "{} delivers about {:.0} % of the logged mass{on_rail} since {since}: \
                         check the pump's calibration and the controller's log.",
                        capitalised(&who),
                        100.0 * f
                    ),
                    a => format!(
                        "{}{on_rail} is about {:.0} % of the model's since {since}: something \
                         changed on the track then (maintenance, grinding, another product?).",
                        capitalised(a.describe()),
                        100.0 * f
                    ),
                };
            }
            let (lo, hi) = drivers.range(driver);
            let x_ref = driver.x_ref().unwrap_or(0.0);
            let (g_lo, g_hi) = (form.g(lo, x_ref), form.g(hi, x_ref));
            let subject = match t.acts_on {
                ActsOn::PulseMass => format!("the mass {who} delivers{on_rail}"),
                a => format!("{}{on_rail}", a.describe()),
            };
            let advice = match t.acts_on {
                ActsOn::PulseMass => " check how the dosing behaves in that weather.",
                ActsOn::Transfer | ActsOn::Consumption => {
                    " the product behaves differently than the 2021 model assumes."
                }
                _ => " the rail surface's friction depends on it.",
            };
            format!(
                "{} follows {}: about {:.0} % of the model's at {} and {:.0} % at {} (g = {} form \
                 over the observed range);{advice}",
                capitalised(&subject),
                driver.describe(),
                100.0 * g_lo,
                short(lo),
                100.0 * g_hi,
                short(hi),
                form.kind().name(),
            )
        }
    }
}

fn capitalised(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(first) => first.to_uppercase().chain(c).collect(),
        None => String::new(),
    }
}

fn short(v: f64) -> String {
    if v.abs() >= 100.0 || v == 0.0 {
        format!("{v:.0}")
    } else if v.abs() >= 1.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.3}")
    }
}

/// Where a residual no term explains lives.
#[derive(Debug, Clone, Serialize)]
pub struct Location {
    pub site: String,
    pub rail: String,
    /// Distance downstream of the nearest applicator on that rail (either
    /// direction of travel), m.
    pub distance_from_applicator_m: Option<f64>,
    /// The time window of the strongest run of same-signed residuals there.
    pub from_utc: String,
    pub to_utc: String,
    pub measurements: usize,
    pub mean_residual: f64,
    /// Share of the whole excess over the noise that this window carries.
    pub share_of_excess: f64,
}

/// The site and rail with the largest excess over the noise, and within it
/// the contiguous time window whose residuals add up furthest from zero
/// (a maximum-sum run, either sign).
pub(super) fn locate(data: &Dataset, residual: &[f64], noise: f64) -> Option<Location> {
    let sites = data.section.sites.len();
    let rails = data.section.rails.len();
    let mut excess = vec![0.0; sites * rails];
    let mut total_excess = 0.0;
    for (row, &r) in data.rows.iter().zip(residual) {
        if r.is_finite() {
            let e = r * r - noise * noise;
            excess[row.site * rails + row.rail] += e;
            total_excess += e;
        }
    }
    let best = (0..excess.len()).max_by(|&a, &b| excess[a].total_cmp(&excess[b]))?;
    let (site, rail) = (best / rails, best % rails);
    let mut rows: Vec<(u64, f64)> = data
        .rows
        .iter()
        .zip(residual)
        .filter(|(row, r)| row.site == site && row.rail == rail && r.is_finite())
        .map(|(row, &r)| (row.log_time_ns, r))
        .collect();
    rows.sort_by_key(|x| x.0);
    // Kadane's maximum-sum run, on r and on −r, each term less a drift of
    // two noise sigmas so that noise around the run does not extend it
    // (CUSUM's reference value: shifts above 2 σ are found whole).
    let drift = 2.0 * noise;
    let mut found: Option<(f64, usize, usize)> = None;
    for sign in [1.0, -1.0] {
        let (mut sum, mut from) = (0.0, 0);
        for (k, &(_, r)) in rows.iter().enumerate() {
            if sum <= 0.0 {
                sum = 0.0;
                from = k;
            }
            sum += sign * r - drift;
            if found.is_none_or(|f| sum > f.0) {
                found = Some((sum, from, k));
            }
        }
    }
    let (_, from, to) = found?;
    let n = to + 1 - from;
    let sum = rows[from..=to].iter().map(|x| x.1).sum::<f64>();
    let mean = sum / n as f64;
    let position = data.section.sites.get(site).map(|s| s.position_m);
    let distance = position.and_then(|x| {
        data.section
            .applicators
            .iter()
            .filter(|a| a.rails.contains(&rail))
            .map(|a| (x - a.position_m).abs())
            .min_by(f64::total_cmp)
    });
    Some(Location {
        site: data.site_name(site).to_string(),
        rail: data.rail_name(rail).to_string(),
        distance_from_applicator_m: distance,
        from_utc: format_utc(rows[from].0 as f64 * 1e-9),
        to_utc: format_utc(rows[to].0 as f64 * 1e-9),
        measurements: n,
        mean_residual: mean,
        share_of_excess: if total_excess > 0.0 {
            (sum * sum / n as f64 / total_excess).min(1.0)
        } else {
            0.0
        },
    })
}
