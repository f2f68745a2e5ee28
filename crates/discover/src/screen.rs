//! Which generic terms are worth fitting, and which measurements are gross
//! errors.
//!
//! The space of generic terms is too large to fit every member by
//! re-running the engine, so discover screens it first, through the same
//! engine:
//!
//! - **Sensitivity.** For every acts_on × driver (and applicator, for
//!   pulses) one engine run with a small factor `exp(ε (x − x_ref))` (for
//!   time, a small step at the residual's change point) gives each
//!   measurement's response `J`. The residual `r` regressed on `J` over a
//!   scope's rows (every row, one rail's, ...) says how much of the
//!   residual that term could remove, `(r·J)² / (J·J)`, and with which
//!   parameter (Gauss–Newton's first step). Rails are independent in the
//!   model, so a rail's scope is the same run's rows of that rail.
//! - **Change points.** A time step shows as a shift of the residual's mean
//!   at one moment: the split of the residual (in time order) with the
//!   largest between-segment variance gives `t0`; a step in another driver
//!   is found the same way along that driver's values.
//! - **Offsets.** A measurement term is an exact shift of its scope's
//!   residuals: its SSE reduction is `n mean²`, no run needed.
//!
//! The best directions are then fitted for real, in every form, by
//! `fit.rs`; the acceptance rules of the workflow decide.

use std::collections::BTreeMap;

use rayon::prelude::*;
use serde::Serialize;

use super::data::Dataset;
use super::fit::{Candidate, Evaluator, Start};
use super::space::{Drivers, GenericSlot, Reach, Scope};
use tortwin_model::config::ModelConfig;
use tortwin_model::generic::{ActsOn, Driver, FormKind};
use tortwin_model::product::ProductKey;
use tortwin_recording::Quantity;
use tortwin_study::Result;

/// A time step is fitted when its screening reduction is at least this
/// share of the best direction's.
const TIME_SHARE: f64 = 0.3;
/// Drivers whose every acts_on is fitted per step.
const TOP_DIRECTIONS: usize = 2;
/// The second driver is fitted when its screening reduction is at least
/// this share of the first's.
const SECOND_DRIVER: f64 = 0.5;
/// Measurement offsets fitted per step.
const TOP_OFFSETS: usize = 2;
/// The screening factor reaches this `|ln g|` at the driver's extreme.
const EPS_REACH: f64 = 0.05;
/// A time step's screening factor.
const EPS_STEP: f64 = 1.05;
/// The relative perturbation of a site constant for its response.
const EPS_CONSTANT: f64 = 0.01;
/// A pulse step's: pulses land on a rail near its cap (m0 of eq. (1) no
/// longer follows them), where a larger pulse is squeezed out at once and
/// a slightly smaller one too; only a clearly smaller one shows, as a
/// clogged nozzle does.
const EPS_PULSE_STEP: f64 = 0.7;
/// A change point keeps at least this share of the rows on each side.
const MIN_SIDE: f64 = 0.04;
/// The same for the step form of a direction already found in another
/// form (at least 5 rows each side in any case).
const MIN_SIDE_FORM: f64 = 0.002;
/// A time change point is tried when the split explains more than this
/// times `ln n σ²`.
const CHANGE_POINT_CHI2: f64 = 4.0;
/// A measurement is a gross outlier when it differs from its neighbours
/// by more than this many robust standard deviations.
const OUTLIER_Z: f64 = 7.0;

/// The measurements treated as gross errors.
#[derive(Debug, Clone, Serialize)]
pub struct Outliers {
    pub count: usize,
    /// Per site, rail and quantity: how many.
    pub by_place: BTreeMap<String, usize>,
    /// `index_in_file` of each.
    pub index_in_file: Vec<u64>,
    /// The robust spread the screen compared with.
    pub robust_sigma: f64,
    /// |deviation from the neighbours| above this was an outlier.
    pub threshold: f64,
    #[serde(skip)]
    pub active: Vec<bool>,
}

/// Screens `residual` for gross errors: each axle measurement is compared
/// with the median of its nearest neighbours (the same train, site, rail,
/// quantity and bogie position, up to two axles on each side): those see
/// almost the same rail, so whatever the model gets wrong cancels and a
/// deviation of many sigma is the sensor's, not the track's. Measurements
/// without such neighbours (tribometer readings) are kept.
pub(super) fn outliers(data: &Dataset, residual: &[f64]) -> Outliers {
    let mut groups = super::diagnose::neighbours(data);
    // Two passes: a neighbourhood with two outliers of one sign moves its
    // median, so the second pass leaves the first pass's outliers out of
    // every neighbourhood.
    let mut flagged = vec![false; data.rows.len()];
    let mut deviation: Vec<(usize, f64)> = Vec::new();
    let mut threshold = f64::INFINITY;
    let mut robust_sigma = 0.0;
    for _pass in 0..2 {
        deviation.clear();
        for list in groups.values_mut() {
            let clean: Vec<(usize, usize)> =
                list.iter().copied().filter(|&(_, k)| !flagged[k]).collect();
            for &(axle, k) in list.iter() {
                // The two nearest clean axles on each side.
                let at = clean.partition_point(|&(a, _)| a < axle);
                let mut others: Vec<f64> = clean[at.saturating_sub(2)..at]
                    .iter()
                    .chain(clean[at..].iter().filter(|&&(a, _)| a != axle).take(2))
                    .map(|&(_, i)| residual[i])
                    .collect();
                if others.len() < 2 {
                    continue;
                }
                others.sort_unstable_by(f64::total_cmp);
                deviation.push((k, residual[k] - median(&others)));
            }
        }
        let mut abs: Vec<f64> = deviation.iter().map(|(_, d)| d.abs()).collect();
        abs.sort_unstable_by(f64::total_cmp);
        robust_sigma = 1.4826 * median(&abs);
        threshold = OUTLIER_Z * robust_sigma;
        if robust_sigma > 0.0 {
            for &(k, d) in &deviation {
                flagged[k] = d.abs() > threshold;
            }
        }
    }
    let mut active = vec![true; data.rows.len()];
    let mut by_place = BTreeMap::new();
    let mut index_in_file = Vec::new();
    if robust_sigma > 0.0 {
        for &(k, d) in &deviation {
            if d.abs() > threshold && flagged[k] {
                active[k] = false;
                let row = &data.rows[k];
                *by_place
                    .entry(format!(
                        "{} {} {}",
                        data.site_name(row.site),
                        data.rail_name(row.rail),
                        row.quantity.as_str()
                    ))
                    .or_insert(0) += 1;
                index_in_file.push(row.index_in_file);
            }
        }
    }
    index_in_file.sort_unstable();
    Outliers {
        count: index_in_file.len(),
        by_place,
        index_in_file,
        robust_sigma,
        threshold,
        active,
    }
}

fn median(sorted: &[f64]) -> f64 {
    match sorted.len() {
        0 => 0.0,
        n if n % 2 == 1 => sorted[n / 2],
        n => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
    }
}

/// The best single split of `residual` along `x` over the rows in `mask`
/// (active rows with a finite x): the threshold between the two sides and
/// the SSE it explains, `n1 n2 / n (m1 − m2)²`.
pub(super) fn best_split(
    x: &[f64],
    residual: &[f64],
    mask: &[bool],
    min_share: f64,
) -> Option<(f64, f64)> {
    let mut pts: Vec<(f64, f64)> = x
        .iter()
        .zip(residual)
        .zip(mask)
        .filter(|((x, r), &m)| m && x.is_finite() && r.is_finite())
        .map(|((&x, &r), _)| (x, r))
        .collect();
    let n = pts.len();
    if n < 20 {
        return None;
    }
    pts.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = pts.iter().map(|p| p.1).sum();
    let min_side = ((n as f64 * min_share).ceil() as usize).max(5);
    let mut left = 0.0;
    let mut best: Option<(f64, f64)> = None;
    for k in 1..n {
        left += pts[k - 1].1;
        if pts[k].0 <= pts[k - 1].0 || k < min_side || n - k < min_side {
            continue;
        }
        let (n1, n2) = (k as f64, (n - k) as f64);
        let m1 = left / n1;
        let m2 = (total - left) / n2;
        let gain = n1 * n2 / n as f64 * (m1 - m2).powi(2);
        if best.is_none_or(|b| gain > b.1) {
            best = Some((0.5 * (pts[k - 1].0 + pts[k].0), gain));
        }
    }
    best
}

/// One screened direction: a term on `acts_on` driven by `driver` (at a
/// pulse of `applicator`), with its response per measurement.
#[derive(Clone)]
struct Response {
    acts_on: ActsOn,
    driver: Driver,
    applicator: Option<String>,
    /// A step's threshold (unix s for time).
    x0: Option<f64>,
    /// The screening parameter and the slot's neutral value.
    eps: f64,
    neutral: f64,
    j: Vec<f64>,
}

/// The responses to the non-time directions, kept from the first step.
#[derive(Default)]
pub(super) struct ResponseCache {
    kept: Vec<Response>,
}

/// A direction to screen: acts_on, driver, applicator (pulses), a step's
/// threshold.
type DirectionKey = (ActsOn, Driver, Option<String>, Option<f64>);

/// A candidate to fit and where its fit starts.
type Proposed = (Candidate, Start);

impl ResponseCache {
    fn has(&self, d: &DirectionKey) -> bool {
        self.kept
            .iter()
            .any(|r| r.acts_on == d.0 && r.driver == d.1 && r.applicator == d.2)
    }

    fn get(&self, d: &DirectionKey) -> Option<Response> {
        self.kept
            .iter()
            .find(|r| r.acts_on == d.0 && r.driver == d.1 && r.applicator == d.2)
            .cloned()
    }

    fn keep(&mut self, r: &Response) {
        if !self.has(&(r.acts_on, r.driver, r.applicator.clone(), None)) {
            self.kept.push(r.clone());
        }
    }
}

/// A direction with a scope and what it could remove.
#[derive(Debug, Clone, Serialize)]
pub struct Screened {
    pub label: String,
    pub reduction: f64,
    #[serde(skip)]
    acts_on: ActsOn,
    #[serde(skip)]
    driver: Driver,
    #[serde(skip)]
    scope: Scope,
    #[serde(skip)]
    x0: Option<f64>,
    /// Gauss–Newton estimate of the exp (or step) parameter.
    #[serde(skip)]
    estimate: f64,
    /// Scored with the site constant that scales its quantity free beside
    /// it (`None` when it scored better alone).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub beside: Option<&'static str>,
    /// What it and that constant remove together, to first order.
    #[serde(skip)]
    with_constant: f64,
}

/// What the screening found in one step, for the report.
#[derive(Debug, Clone, Serialize)]
pub struct Screening {
    pub engine_runs: usize,
    /// The strongest directions, best first.
    pub top: Vec<Screened>,
    /// The strongest offsets (site, rail, quantity scopes).
    pub offsets: Vec<Screened>,
    /// Time change points tried (RFC 3339).
    pub change_points_utc: Vec<String>,
    /// The directions proposed because they scored with their site
    /// constant beside them, with what the two remove together to first
    /// order: fitted with it at the step when that could compete.
    #[serde(skip)]
    pub(super) beside_constant: Vec<(GenericSlot, f64)>,
}

/// The generic candidates worth fitting at this step, with where each fit
/// starts, and what the screening saw: the residual's change points in
/// time and along the drivers, the directions they and the drivers give,
/// each direction's response (one replay, or the first step's), every
/// scope of it scored, and the candidates: steps, smooth factors on the
/// strongest drivers, offsets.
#[allow(clippy::too_many_arguments)]
pub(super) fn propose(
    ev: &Evaluator<'_>,
    drivers: &Drivers,
    current: &ModelConfig,
    simulated: &[f64],
    noise: Option<f64>,
    min_reduction: f64,
    forced: &[Driver],
    with_constants: bool,
    cache: &mut ResponseCache,
) -> Result<(Vec<Proposed>, Screening)> {
    let data = ev.data;
    let residual: Vec<f64> = data
        .rows
        .iter()
        .zip(simulated)
        .map(|(r, s)| r.measured - s)
        .collect();
    let active = &ev.active;
    let runs_before = ev.runs();

    // Splits of the residual, over every row and per rail.
    let mut masks: Vec<Vec<bool>> = vec![active.clone()];
    for rail in 0..data.section.rails.len() {
        masks.push(
            data.rows
                .iter()
                .zip(active)
                .map(|(r, &a)| a && r.rail == rail)
                .collect(),
        );
    }
    // A split of pure noise explains about 2 ln n σ²; a step worth a term
    // explains far more.
    let sigma2 = noise.map_or(0.0, |s| s * s);
    let n_active = active.iter().filter(|a| **a).count().max(2) as f64;
    let split_worth = CHANGE_POINT_CHI2 * n_active.ln() * sigma2;
    let change_points = change_points(drivers.values(Driver::Time), &residual, &masks, split_worth);
    let driver_steps = driver_steps(drivers, &residual, &masks, split_worth);

    let applicators: Vec<String> = data
        .section
        .applicators
        .iter()
        .map(|a| a.id.clone())
        .collect();
    let directions = directions(drivers, &change_points, &driver_steps, &applicators);
    let responses = responses(ev, drivers, current, simulated, directions, cache)?;
    let twins = constant_responses(ev, current, simulated, with_constants)?;
    let screened = score(
        data,
        active,
        &residual,
        &responses,
        &twins,
        applicators.len() == 1,
    );
    // What cannot remove enough to pass the BIC even to first order is not
    // fitted (the first-order reduction of a strong effect is smaller than
    // its fitted one, hence the half).
    let worth = |reduction: f64| reduction >= 0.5 * min_reduction;
    let mut candidates = step_candidates(drivers, &screened, &worth);
    let (smooth, beside_constant) = driver_candidates(drivers, &screened, forced, &worth);
    candidates.extend(smooth);
    let offsets = offsets(data, active, &residual);
    for o in offsets.iter().filter(|o| worth(o.reduction)) {
        let c = Candidate::Generic(GenericSlot::offset(o.scope.clone()));
        let u = c.unit(0, o.estimate);
        candidates.push((c, Start::Warm(vec![u])));
    }

    let screening = Screening {
        engine_runs: ev.runs() - runs_before,
        top: screened.into_iter().take(8).collect(),
        offsets,
        change_points_utc: change_points
            .iter()
            .map(|&t| tortwin_model::config::format_utc(t))
            .collect(),
        beside_constant,
    };
    Ok((candidates, screening))
}

/// Time change points: the best split in time of the residual over each
/// of `masks` that explains more than `split_worth`, at most one.
fn change_points(
    times: &[f64],
    residual: &[f64],
    masks: &[Vec<bool>],
    split_worth: f64,
) -> Vec<f64> {
    let mut change_points: Vec<f64> = Vec::new();
    for mask in masks {
        if let Some((x0, gain)) = best_split(times, residual, mask, MIN_SIDE) {
            let x0 = x0.round();
            if gain > split_worth && !change_points.iter().any(|&c| (c - x0).abs() < 60.0) {
                change_points.push(x0);
            }
        }
    }
    change_points.truncate(1);
    change_points
}

/// Steps along the other drivers: a factor that jumps at a load, a
/// speed or a humidity shows as a split of the residual along that
/// driver, and the smooth forms' first-order screening (centred on
/// x_ref) can miss it when it lifts nearly every contact. The strongest
/// splits, each at a threshold people can read.
fn driver_steps(
    drivers: &Drivers,
    residual: &[f64],
    masks: &[Vec<bool>],
    split_worth: f64,
) -> Vec<(Driver, f64, f64)> {
    let mut driver_steps: Vec<(Driver, f64, f64)> = Vec::new();
    for driver in Driver::ALL {
        if driver == Driver::Time || !drivers.varies(driver) {
            continue;
        }
        let best = masks
            .iter()
            .filter_map(|mask| best_split(drivers.values(driver), residual, mask, MIN_SIDE))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((x0, gain)) = best {
            if gain > split_worth {
                driver_steps.push((driver, round_sig(x0, 3), gain));
            }
        }
    }
    driver_steps.sort_by(|a, b| b.2.total_cmp(&a.2));
    let strongest = driver_steps.first().map_or(0.0, |s| s.2);
    driver_steps.retain(|s| s.2 >= SECOND_DRIVER * strongest);
    driver_steps.truncate(TOP_DIRECTIONS);
    driver_steps
}

/// The directions to screen: (acts_on, driver, applicator, x0), every
/// quantity on every driver that varies (pulses on the applicators for the
/// drivers of the weather), steps at the change points and driver steps.
fn directions(
    drivers: &Drivers,
    change_points: &[f64],
    driver_steps: &[(Driver, f64, f64)],
    applicators: &[String],
) -> Vec<DirectionKey> {
    let physics = [
        ActsOn::Transfer,
        ActsOn::Consumption,
        ActsOn::FrictionDry,
        ActsOn::FrictionBoundary,
    ];
    let mut directions: Vec<(ActsOn, Driver, Option<String>, Option<f64>)> = Vec::new();
    for driver in Driver::ALL {
        if driver == Driver::Time {
            for &x0 in change_points {
                for acts_on in physics {
                    directions.push((acts_on, driver, None, Some(x0)));
                }
                for a in applicators {
                    directions.push((ActsOn::PulseMass, driver, Some(a.clone()), Some(x0)));
                }
            }
            continue;
        }
        if !drivers.varies(driver) {
            continue;
        }
        for acts_on in physics {
            directions.push((acts_on, driver, None, None));
        }
        if !driver.is_wheel() {
            for a in applicators {
                directions.push((ActsOn::PulseMass, driver, Some(a.clone()), None));
            }
        }
        for &(_, x0, _) in driver_steps.iter().filter(|s| s.0 == driver) {
            for acts_on in physics {
                directions.push((acts_on, driver, None, Some(x0)));
            }
            if !driver.is_wheel() {
                for a in applicators {
                    directions.push((ActsOn::PulseMass, driver, Some(a.clone()), Some(x0)));
                }
            }
        }
    }
    directions
}

/// Each direction's response per measurement: one replay with a small
/// factor (a small step at a threshold) against `simulated`. The responses
/// to the drivers change little as the model grows: the first step's
/// (kept in `cache`) serve the later ones; steps depend on x0 and are run
/// anew.
fn responses(
    ev: &Evaluator<'_>,
    drivers: &Drivers,
    current: &ModelConfig,
    simulated: &[f64],
    directions: Vec<DirectionKey>,
    cache: &mut ResponseCache,
) -> Result<Vec<Response>> {
    let (reuse, to_run): (Vec<_>, Vec<_>) = directions
        .into_iter()
        .partition(|d| d.3.is_none() && cache.has(d));
    let mut responses: Vec<Response> = to_run
        .into_par_iter()
        .map(|(acts_on, driver, applicator, x0)| {
            let scope = Scope {
                applicator: applicator.clone(),
                ..Scope::default()
            };
            let (slot, eps) = match x0 {
                Some(x0) => (
                    GenericSlot::factor(
                        acts_on,
                        driver,
                        FormKind::Step,
                        scope,
                        Some(x0),
                        Reach::STEP,
                    ),
                    if acts_on == ActsOn::PulseMass {
                        EPS_PULSE_STEP
                    } else {
                        EPS_STEP
                    },
                ),
                None => {
                    let (lo, hi) = drivers.range(driver);
                    let x_ref = driver.x_ref().unwrap_or(0.0);
                    let span = (lo - x_ref).abs().max((hi - x_ref).abs()).max(1e-12);
                    (
                        GenericSlot::factor(
                            acts_on,
                            driver,
                            FormKind::Exp,
                            scope,
                            None,
                            drivers.reach(driver),
                        ),
                        EPS_REACH / span,
                    )
                }
            };
            let mut cfg = current.clone();
            slot.set(&mut cfg.effects, eps);
            let perturbed = ev.simulate(&cfg)?;
            Ok(Response {
                acts_on,
                driver,
                applicator,
                x0,
                eps,
                neutral: slot.neutral(),
                j: perturbed
                    .iter()
                    .zip(simulated)
                    .map(|(p, s)| p - s)
                    .collect(),
            })
        })
        .collect::<Result<_>>()?;
    for r in &responses {
        if r.x0.is_none() {
            cache.keep(r);
        }
    }
    responses.extend(reuse.iter().filter_map(|d| cache.get(d)));
    Ok(responses)
}

/// The responses to the site constants that scale a quantity (muD, muC,
/// kt), while the constants are still to be found: a factor is 1 at its
/// driver's reference point, so alone it cannot say that the site's
/// level differs too, and a term whose driver explains the residual
/// with a level beside it (muD 16 % high, falling linearly with the
/// humidity) would rank below one that merely correlates.
fn constant_responses(
    ev: &Evaluator<'_>,
    current: &ModelConfig,
    simulated: &[f64],
    with_constants: bool,
) -> Result<Vec<(ProductKey, Vec<f64>)>> {
    if !with_constants {
        return Ok(Vec::new());
    }
    [
        ActsOn::FrictionDry,
        ActsOn::FrictionBoundary,
        ActsOn::Transfer,
    ]
    .into_par_iter()
    .filter_map(super::search::twin_constant)
    .map(|key| {
        let mut cfg = current.clone();
        key.set(
            &mut cfg.product,
            key.get(&current.product) * (1.0 + EPS_CONSTANT),
        );
        let perturbed = ev.simulate(&cfg)?;
        Ok((
            key,
            perturbed
                .iter()
                .zip(simulated)
                .map(|(p, s)| p - s)
                .collect(),
        ))
    })
    .collect()
}

/// Every scope of every direction, scored: what it could remove from the
/// residual to first order (alone, or with its site constant beside it),
/// best first.
fn score(
    data: &Dataset,
    active: &[bool],
    residual: &[f64],
    responses: &[Response],
    twins: &[(ProductKey, Vec<f64>)],
    single_applicator: bool,
) -> Vec<Screened> {
    let mut screened: Vec<Screened> = Vec::new();
    for resp in responses {
        let mut scopes: Vec<Scope> = Vec::new();
        let rails: Vec<Option<String>> = std::iter::once(None)
            .chain(data.section.rails.iter().cloned().map(Some))
            .collect();
        for rail in rails {
            let applicator = match (&resp.applicator, resp.driver) {
                // With one applicator, "its pulses" and "every pulse" are
                // the same term: a change at a moment is a device's (name
                // the applicator), a dependence on the weather the
                // product's (no applicator).
                (Some(a), Driver::Time) => Some(a.clone()),
                (Some(_), _) if single_applicator => None,
                (a, _) => a.clone(),
            };
            scopes.push(Scope {
                applicator,
                rail,
                ..Scope::default()
            });
        }
        for scope in scopes {
            let rail = scope
                .rail
                .as_ref()
                .and_then(|r| data.section.rails.iter().position(|x| x == r));
            let (mut rj, mut jj) = (0.0, 0.0);
            for (k, row) in data.rows.iter().enumerate() {
                if !active[k] || rail.is_some_and(|r| r != row.rail) {
                    continue;
                }
                rj += residual[k] * resp.j[k];
                jj += resp.j[k] * resp.j[k];
            }
            if jj <= 0.0 || !jj.is_finite() {
                continue;
            }
            let mut label = label_of(resp.acts_on, resp.driver, &scope, resp.x0);
            let (mut reduction, mut coefficient, mut beside) = (rj * rj / jj, rj / jj, None);
            let mut with_constant = 0.0;
            let twin = super::search::twin_constant(resp.acts_on)
                .and_then(|key| twins.iter().find(|t| t.0 == key))
                .filter(|_| resp.x0.is_none() && scope.keys() == 0);
            if let Some((key, jc)) = twin {
                if let Some((extra, both, a)) = beyond_constant(residual, &resp.j, jc, active) {
                    if extra > reduction {
                        (reduction, coefficient, beside) = (extra, a, Some(key.name()));
                        with_constant = both;
                        label = format!("{label} with {} beside it", key.name());
                    }
                }
            }
            screened.push(Screened {
                label,
                reduction,
                acts_on: resp.acts_on,
                driver: resp.driver,
                scope,
                x0: resp.x0,
                estimate: resp.neutral + (resp.eps - resp.neutral) * coefficient,
                beside,
                with_constant,
            });
        }
    }
    screened.sort_by(|a, b| b.reduction.total_cmp(&a.reduction));
    screened
}

/// Every acts_on at each change point, in time or along a driver (the
/// best scope of each): which one moved is what the fits tell apart; the
/// screening's first-order response cannot (a clogged nozzle and a drop
/// of transfer look alike until the product runs out).
fn step_candidates(
    drivers: &Drivers,
    screened: &[Screened],
    worth: &dyn Fn(f64) -> bool,
) -> Vec<Proposed> {
    let mut candidates: Vec<Proposed> = Vec::new();
    let mut timed: Vec<&Screened> = Vec::new();
    // Steps compete with the smooth directions: tried when one could remove
    // a good part of what the best direction could.
    let best_reduction = screened.first().map_or(0.0, |s| s.reduction);
    for s in screened
        .iter()
        .filter(|s| s.x0.is_some() && worth(s.reduction))
        .filter(|s| s.reduction >= TIME_SHARE * best_reduction)
    {
        if !timed.iter().any(|t| {
            t.acts_on == s.acts_on
                && t.driver == s.driver
                && t.scope.applicator == s.scope.applicator
        }) {
            timed.push(s);
            let slot = GenericSlot::factor(
                s.acts_on,
                s.driver,
                FormKind::Step,
                s.scope.clone(),
                s.x0,
                drivers.reach(s.driver),
            );
            let c = Candidate::Generic(slot);
            let u = c.unit(0, s.estimate);
            candidates.push((c, Start::Warm(vec![u])));
        }
    }
    candidates
}

/// The strongest drivers: every acts_on with each (its best scope), in
/// the exp form. Which quantity a driver acts on is what the fits tell
/// apart (to first order a pulse, a transfer and a consumption term look
/// alike); the other forms follow for the best of them
/// ([`other_forms`]).
fn driver_candidates(
    drivers: &Drivers,
    screened: &[Screened],
    forced: &[Driver],
    worth: &dyn Fn(f64) -> bool,
) -> (Vec<Proposed>, Vec<(GenericSlot, f64)>) {
    let mut top_drivers: Vec<Driver> = Vec::new();
    let mut first = None;
    for s in screened
        .iter()
        .filter(|s| s.x0.is_none() && worth(s.reduction))
    {
        // A second driver only if it could remove about as much: two
        // correlated weather covariates are one finding.
        let best = *first.get_or_insert(s.reduction);
        if !top_drivers.contains(&s.driver) && s.reduction >= SECOND_DRIVER * best {
            top_drivers.push(s.driver);
        }
    }
    top_drivers.truncate(TOP_DIRECTIONS);
    // The drivers the residual's diagnosis names: every acts_on with them,
    // whatever the first-order screening says.
    for &d in forced {
        if !top_drivers.contains(&d) && drivers.varies(d) {
            top_drivers.push(d);
        }
    }
    let mut candidates: Vec<Proposed> = Vec::new();
    let mut taken: Vec<&Screened> = Vec::new();
    let mut beside_constant: Vec<(GenericSlot, f64)> = Vec::new();
    for s in screened.iter().filter(|s| {
        s.x0.is_none()
            && top_drivers.contains(&s.driver)
            && (worth(s.reduction) || forced.contains(&s.driver))
    }) {
        if taken
            .iter()
            .any(|t| t.acts_on == s.acts_on && t.driver == s.driver)
        {
            continue;
        }
        taken.push(s);
        let slot = GenericSlot::factor(
            s.acts_on,
            s.driver,
            FormKind::Exp,
            s.scope.clone(),
            None,
            drivers.reach(s.driver),
        );
        if s.beside.is_some() {
            beside_constant.push((slot.clone(), s.with_constant));
        }
        let c = Candidate::Generic(slot);
        let u = c.unit(0, s.estimate);
        candidates.push((c, Start::Warm(vec![u])));
    }
    (candidates, beside_constant)
}

/// Offsets: every site scope, and each quantity everywhere, scored by the
/// exact reduction `n mean²`; the strongest, each with the instrument
/// inside it that carries most of it.
fn offsets(data: &Dataset, active: &[bool], residual: &[f64]) -> Vec<Screened> {
    let mut offsets: Vec<(Scope, Vec<bool>, f64, f64)> = Vec::new();
    let quantities = [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu];
    let mut scopes: Vec<Scope> = Vec::new();
    for q in quantities {
        scopes.push(Scope {
            quantity: Some(q),
            ..Scope::default()
        });
    }
    for site in &data.section.sites {
        for rail in std::iter::once(None).chain(data.section.rails.iter().cloned().map(Some)) {
            for q in std::iter::once(None).chain(quantities.into_iter().map(Some)) {
                scopes.push(Scope {
                    site: Some(site.id.clone()),
                    rail: rail.clone(),
                    quantity: q,
                    ..Scope::default()
                });
            }
        }
    }
    for scope in scopes {
        let mask: Vec<bool> = data
            .rows
            .iter()
            .zip(active)
            .map(|(row, &a)| {
                a && scope
                    .site
                    .as_deref()
                    .is_none_or(|s| s == data.site_name(row.site))
                    && scope
                        .rail
                        .as_deref()
                        .is_none_or(|r| r == data.rail_name(row.rail))
                    && scope.quantity.is_none_or(|q| q == row.quantity)
            })
            .collect();
        let (mut n, mut sum) = (0usize, 0.0);
        for (k, &m) in mask.iter().enumerate() {
            if m {
                n += 1;
                sum += residual[k];
            }
        }
        if n < 10 {
            continue;
        }
        let mean = sum / n as f64;
        // The same rows under another name: keep the narrower statement
        // (a sensor is at a site, on a rail, measuring one quantity).
        if let Some(same) = offsets.iter_mut().find(|o| o.1 == mask) {
            if scope.keys() > same.0.keys() {
                same.0 = scope;
            }
            continue;
        }
        offsets.push((scope, mask, n as f64 * mean * mean, mean));
    }
    offsets.sort_by(|a, b| b.2.total_cmp(&a.2));
    // The strongest offsets, each with the instrument inside it that
    // carries most of it (site, rail and quantity named): the selection
    // prefers that one unless the broader scope is decisively better.
    let mut chosen: Vec<usize> = Vec::new();
    for k in 0..offsets.len().min(TOP_OFFSETS) {
        chosen.push(k);
        let broad = &offsets[k].0;
        let instrument = offsets
            .iter()
            .enumerate()
            .filter(|(_, o)| {
                o.0.keys() == 3
                    && broad.keys() < 3
                    && broad
                        .site
                        .as_ref()
                        .is_none_or(|s| o.0.site.as_ref() == Some(s))
                    && broad
                        .rail
                        .as_ref()
                        .is_none_or(|r| o.0.rail.as_ref() == Some(r))
                    && broad.quantity.is_none_or(|q| o.0.quantity == Some(q))
            })
            .max_by(|a, b| a.1 .2.total_cmp(&b.1 .2))
            .map(|(i, _)| i);
        if let Some(i) = instrument {
            if !chosen.contains(&i) {
                chosen.push(i);
            }
        }
    }
    chosen
        .into_iter()
        .map(|k| offsets[k].clone())
        .map(|(scope, _, reduction, mean)| Screened {
            label: GenericSlot::offset(scope.clone()).label(),
            reduction,
            acts_on: ActsOn::Measurement,
            driver: Driver::Time,
            scope,
            x0: None,
            estimate: mean,
            beside: None,
            with_constant: 0.0,
        })
        .collect()
}

/// What a response `j` removes from `residual` (over the `active` rows)
/// beyond what the response `jc` of a constant removes alone, with both
/// fitted together (least squares), what the two remove together, and
/// `j`'s coefficient in that fit; `None` when the two cannot be told
/// apart.
fn beyond_constant(
    residual: &[f64],
    j: &[f64],
    jc: &[f64],
    active: &[bool],
) -> Option<(f64, f64, f64)> {
    let (mut jj, mut jcjc, mut jjc, mut rj, mut rjc) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in (0..residual.len()).filter(|&k| active[k]) {
        jj += j[k] * j[k];
        jcjc += jc[k] * jc[k];
        jjc += j[k] * jc[k];
        rj += residual[k] * j[k];
        rjc += residual[k] * jc[k];
    }
    let det = jj * jcjc - jjc * jjc;
    if det <= 1e-9 * jj * jcjc || !det.is_finite() {
        return None;
    }
    let a = (rj * jcjc - rjc * jjc) / det;
    let b = (rjc * jj - rj * jjc) / det;
    let both = a * rj + b * rjc;
    Some((both - rjc * rjc / jcjc, both, a))
}

fn label_of(acts_on: ActsOn, driver: Driver, scope: &Scope, x0: Option<f64>) -> String {
    let form = if x0.is_some() {
        FormKind::Step
    } else {
        FormKind::Exp
    };
    GenericSlot::factor(acts_on, driver, form, scope.clone(), x0, Reach::STEP).label()
}

/// `x` to `digits` significant digits (a threshold people can read).
fn round_sig(x: f64, digits: i32) -> f64 {
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = 10f64.powi(digits - 1 - x.abs().log10().floor() as i32);
    (x * scale).round() / scale
}

/// The other forms of a fitted term on the same direction: exp, linear and
/// power (from the exp's first-order slope where the fitted term is an exp,
/// `gamma ≈ beta`, `n ≈ beta x_ref`; searched afresh otherwise), and a step
/// where the residual splits along the driver (over the slot's rail).
pub(super) fn other_forms(
    data: &Dataset,
    drivers: &Drivers,
    active: &[bool],
    residual: &[f64],
    slot: &GenericSlot,
    beta: Option<f64>,
) -> Vec<Proposed> {
    let Some(driver) = slot.driver else {
        return Vec::new();
    };
    let reach = drivers.reach(driver);
    let x_ref = driver.x_ref().unwrap_or(0.0);
    let mut out = Vec::new();
    for form in [FormKind::Exp, FormKind::Linear, FormKind::Power] {
        if Some(form) == slot.form || !drivers.allows(driver, form) {
            continue;
        }
        let c = Candidate::Generic(GenericSlot::factor(
            slot.acts_on,
            driver,
            form,
            slot.scope(),
            None,
            reach,
        ));
        let start = match (beta, form) {
            (Some(b), FormKind::Power) => Start::Warm(vec![c.unit(0, b * x_ref)]),
            (Some(b), _) => Start::Warm(vec![c.unit(0, b)]),
            (None, _) => Start::Fresh,
        };
        out.push((c, start));
    }
    if slot.form == Some(FormKind::Step) {
        return out;
    }
    let rail = slot
        .rail
        .as_ref()
        .and_then(|r| data.section.rails.iter().position(|x| x == r));
    let mask: Vec<bool> = data
        .rows
        .iter()
        .zip(active)
        .map(|(row, &a)| a && rail.is_none_or(|r| r == row.rail))
        .collect();
    // The direction is known to matter here: a step may sit where few rows
    // are (heavy rain is rare), the fit and the acceptance rules decide.
    if let Some((x0, _)) = best_split(drivers.values(driver), residual, &mask, MIN_SIDE_FORM) {
        let c = Candidate::Generic(GenericSlot::factor(
            slot.acts_on,
            driver,
            FormKind::Step,
            slot.scope(),
            Some(round_sig(x0, 3)),
            reach,
        ));
        // From g = 1: the bracket around it reaches f = 0.55 to 1.45, and
        // widens to the whole range if the optimum is beyond.
        let u = c.unit(0, 1.0);
        out.push((c, Start::Warm(vec![u])));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn best_split_finds_a_step() {
        let x: Vec<f64> = (0..200).map(f64::from).collect();
        let r: Vec<f64> = x
            .iter()
            .map(|&v| if v >= 120.0 { 0.05 } else { 0.0 } + 0.001 * (v * 7.0).sin())
            .collect();
        let (x0, gain) = best_split(&x, &r, &[true; 200], MIN_SIDE).unwrap();
        assert!((x0 - 119.5).abs() < 1e-9, "{x0}");
        // n1 n2 / n (Δm)² = 120 · 80 / 200 · 0.05² = 0.12 (plus a sliver).
        assert!((gain - 0.12).abs() < 0.01, "{gain}");
        assert!(best_split(&x[..10], &r[..10], &[true; 10], MIN_SIDE).is_none());
    }

    #[test]
    fn round_sig_reads_well() {
        assert_eq!(round_sig(0.81234, 3), 0.812);
        assert_eq!(round_sig(1_713_619_812.4, 3), 1_710_000_000.0);
        assert_eq!(round_sig(-12.345, 2), -12.0);
    }
}
