//! Site constants (docs/spec/interfaces.md, "Site constants (calibration)"):
//! which of the `[product]` constants a recording determines, their values
//! with honest 95 % intervals, and which it determines only in combination.
//!
//! A real section's rail steel, product batch and traffic make its
//! constants differ from the twin-disc laboratory's (Table 2). A constant
//! that differs for the whole recording is a property of the site, not an
//! effect and not a change in time; it is calibrated before any effect is
//! looked for, and again with the effects found.
//!
//! **Coordinates.** A constant moves in `θ = ln(p / p_ref)`, `p_ref` its
//! value in the starting model (the laboratory's unless `--config` sets
//! it): a relative change, one scale for every constant, within a factor
//! 2.5 of the reference. An effect's parameter fitted with the constants
//! (discover's final calibration) moves in its search coordinate `u` in
//! [0, 1] (`fit.rs`).
//!
//! **Sensitivities.** `J = ∂ simulated / ∂ θ`: the ten constants that move
//! the product masses from one replay with tangents (exact derivatives,
//! `tortwin_model::tangent`), `muD`, `muC` and `km` by differences read
//! from that replay's read-outs, an effect's parameters by forward
//! differences (one replay each). `JᵀJ / σ²` is the Fisher information,
//! `σ` the noise estimated from axle-to-axle differences.
//!
//! **1. Everything free.** Levenberg–Marquardt over every constant at once,
//! each step restricted to the directions the recording determines (the
//! eigenvectors of `JᵀJ` whose standard error is at most [`SD_NULL`]): the
//! least change that fits.
//!
//! **2. Determined alone.** A constant is determined when its standard
//! error with every other constant (and effect parameter) free is at most
//! [`SD_DETERMINED`] — the profile likelihood's question, linearised — at
//! the fit *and* at the reference values (a valley the fit followed may be
//! flat where it started: a constant is pinned down only if it is at
//! both), and no more than [`NULL_SHARE`] of it lies in an undetermined
//! direction. Its 95 % interval is that standard error, the larger of the
//! model-based and the train-clustered (sandwich) one: the measurements of
//! one train share its errors. Where constants end held at their reference
//! values (4. below), what their own intervals allow them to push into a
//! determined constant widens its interval ([`lean_of_held`]).
//!
//! **3. Combinations.** What else the recording determines is carried by
//! representatives: constants taken in the order of their information
//! while each keeps a standard error of at most [`SD_DETERMINED`] with the
//! others held ([`select`]); a representative carries the combination of
//! itself and the constants it cannot be told from (`A = (J_FᵀJ_F)⁻¹
//! J_FᵀJ_U`: a held constant's deviation `θ_u` shows as `A θ_u` on the
//! representatives), which the report names. The determined constants and
//! the representatives are fitted together, the others held.
//!
//! **4. Held where the data allow.** A determined constant whose interval
//! holds its reference value is held there. A determined constant that
//! moved is tested once more: fitted again at its reference value with the
//! rest free, if the fit is as good (a likelihood-ratio test at 95 %) it
//! is not determined after all (unless it moved by [`LR_SURE`] standard
//! errors or more, where the linearised test's margin is ten-fold). A representative whose combination's
//! interval holds its reference value is held there, one at a time, the
//! others following linearly ([`pin_sequentially`]).
//!
//! **Fits.** Levenberg–Marquardt on exact Jacobians ([`Problem::fit_exact`]):
//! every trial is one replay with tangents, which gives the next step's
//! Jacobian too; a step stays inside the bounds by an active set
//! ([`Problem::bounded_step`]); a refit with fewer knobs free starts where
//! the last Jacobian expects it to end ([`Problem::projected`]).
//!
//! The campaign (scripts/calibration-campaign.py) measures the intervals'
//! coverage on synthetic sites.

use std::sync::Arc;
use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;
use serde::Serialize;

use super::fit::{Candidate, Evaluator, Stage};
use super::fmt_param;
use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_model::product::{ProductKey, ProductParams};
use tortwin_model::role::Role;
use tortwin_model::tangent::{self, EffectParam};
use tortwin_study::Result;

/// A constant is determined when the standard error of `ln p` is at most
/// this: its 95 % interval spans about ±20 %.
pub const SD_DETERMINED: f64 = 0.1;
/// The forward difference in `θ` (0.1 % of a constant) or in `u`.
const STEP: f64 = 1e-3;
/// The 97.5 % point of the standard normal distribution.
const Z95: f64 = 1.959_963_984_540_054;
/// Constants stay within a factor 2.5 of their reference values: a site
/// is not another product, and a constant pushed further stands in for
/// something else.
const THETA_MAX: f64 = 0.916_290_731_874_155;
/// Levenberg–Marquardt's iterations, and its stop: the SSE falls by less
/// than `LM_FLAT` noise variances (a log-likelihood change of 0.25), or no
/// parameter moves by more than `MOVE_TOL` of its standard error.
const LM_MAX_ITERS: usize = 20;
const LM_FLAT: f64 = 0.5;
const MOVE_TOL: f64 = 0.05;
/// The 95 % point of the chi-square distribution with one degree of freedom.
const CHI2_1_95: f64 = 3.841_458_820_694_124;
/// The damping's factor after a step that does not improve (each trial of
/// an exact fit is a replay: few, decisive ones).
const REJECTED: f64 = 10.0;
/// The most a step lightens the damping (Nielsen's rule takes a third):
/// where the linearised model predicts the step's gain well, the weakly
/// determined directions are freed within a few steps rather than a
/// dozen (the damping is added to the eigenvalues relative to the
/// largest, which may exceed the smallest by ten orders of magnitude).
const LIGHTEN: f64 = 0.1;
/// The most a step lightens the damping once a step climbed (Nielsen's
/// third): the curvature is then larger than the linearised model's.
const CLIMBED_LIGHTEN: f64 = 1.0 / 3.0;
/// Where along a step that climbed the cubic's minimum is taken at least
/// and at most (a fraction of the step).
const SEARCH_RANGE: (f64, f64) = (0.02, 0.9);
/// The standard error of ln p along which [`Problem::projected`] moves a
/// refit's start: the directions the recording determines (the others'
/// linear extrapolation is no guide).
const PROJECT_SD: f64 = 0.1;
/// A determined constant that moved by at least this many standard errors
/// (those of the fit with everything free, the larger at the fit and at
/// the reference values) is not tested by a refit at its reference
/// value: linearised, that refit's SSE rises by this squared (36 noise
/// variances, ten times the test's 3.84), more than a curved valley
/// makes up.
const LR_SURE: f64 = 6.0;
/// Rounds of holding representatives (each refits).
const PIN_ROUNDS: usize = 3;

/// One constant of `[product]` as the calibration found it (report.json
/// `site_constants`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SiteConstant {
    /// `product.mu_d`, ...
    pub key: String,
    /// The laboratory's value (the built-in default: Table 2, model.md).
    pub default: f64,
    /// The value the calibration started from, when `--config` set another.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub start: Option<f64>,
    /// The calibrated value (written into model.toml).
    pub value: f64,
    /// The 95 % interval of a determined constant.
    pub ci95: Option<[f64; 2]>,
    /// Whether the recording pins it down alone.
    pub determined: bool,
    /// The standard error of `ln value` (fitted constants).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sd_ln: Option<f64>,
    /// `fitted` (moved to the value the data want), `held` (fitted, but its
    /// interval holds its reference value, so it is kept there), `carries`
    /// (fitted for a combination it is the representative of) or `kept`
    /// (not fitted: kept at its reference value).
    pub status: String,
    /// The combination the recording determines, for a constant it cannot
    /// tell apart from others.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub combination: Option<Combination>,
    /// One sentence for a railway engineer.
    pub description: String,
}

/// A product of constants the recording determines, although it cannot
/// tell its factors apart: `p_1 × (p_2 / p_2,ref)^a × ...`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Combination {
    /// E.g. `km_kg × (kt / 0.5)^0.81`.
    pub expression: String,
    /// The constants and their exponents.
    pub factors: Vec<(String, f64)>,
    pub value: f64,
    pub ci95: [f64; 2],
}

/// What [`calibrate`] found.
#[derive(Debug, Clone, Serialize)]
pub struct Calibration {
    /// Every constant examined, in the order of [`ProductKey::ALL`].
    pub constants: Vec<SiteConstant>,
    /// RMSE over the measurements used, before and after.
    pub rmse_before: f64,
    pub rmse_after: f64,
    /// The noise the information is scaled by.
    pub noise: f64,
    /// The keys moved away from their reference value.
    pub moved: Vec<String>,
    /// One paragraph.
    pub summary: String,
    pub engine_runs: usize,
    pub elapsed_s: f64,
    /// The calibrated configuration (effects as given, their fitted
    /// parameters included).
    #[serde(skip)]
    pub model: ModelConfig,
    /// The keys fitted (a [`refit`] moves these again).
    #[serde(skip)]
    pub fitted: Vec<ProductKey>,
}

/// A parameter the calibration moves.
#[derive(Debug, Clone, PartialEq)]
enum Knob {
    /// `θ = ln(p / p_ref)`.
    Constant(ProductKey),
    /// Parameter `i` of an effect, `θ = u`.
    Effect(Candidate, usize),
}

/// The starting model breaks a range the configuration checks (it was
/// checked when read: only a clamped constant can get here).
fn out_of_range() -> tortwin_study::Error {
    UsageError("the starting model's constants are out of range for a calibration".into()).into()
}

/// The least squares problem over the active measurements.
struct Problem<'e, 'a> {
    ev: &'e Evaluator<'a>,
    /// The configuration the knobs are applied to.
    base: ModelConfig,
    /// The constants' reference values (`θ = 0`).
    reference: ProductParams,
    knobs: Vec<Knob>,
    /// The active rows (indices into the dataset's rows).
    rows: Vec<usize>,
    measured: DVector<f64>,
    /// The noise variance the fits' stop is measured in (set once known).
    noise2: f64,
    /// The simulated values of the last configurations replayed, by their
    /// `θ` (a Jacobian is asked for again where a fit stopped on one).
    replayed: std::sync::Mutex<std::collections::VecDeque<(Vec<u64>, DVector<f64>)>>,
    /// How many of them are kept: a bounded amount of memory.
    keep: usize,
    /// The state constants' columns at the last `θ` replayed with tangents.
    sensed: std::sync::Mutex<std::collections::VecDeque<(Vec<u64>, StateColumns)>>,
}

/// The columns of the state constants among the knobs: (knob, column).
type StateColumns = Arc<Vec<(usize, DVector<f64>)>>;

/// How many replays with tangents [`Problem`] keeps.
const SENSED_KEPT: usize = 4;

/// The memory [`Problem`] keeps replays in, at most (in f64 values).
const REPLAYS_KEPT_VALUES: usize = 8 << 20;

impl<'e, 'a> Problem<'e, 'a> {
    fn new(
        ev: &'e Evaluator<'a>,
        base: &ModelConfig,
        reference: &ProductParams,
        effects: &[Candidate],
    ) -> Self {
        let mut knobs: Vec<Knob> = ProductKey::ALL
            .into_iter()
            .filter(|k| k.get(reference) > 0.0)
            .map(Knob::Constant)
            .collect();
        for c in effects {
            if c.get(&base.effects).is_some() {
                knobs.extend((0..c.dims()).map(|i| Knob::Effect(c.clone(), i)));
            }
        }
        let rows: Vec<usize> = (0..ev.data.rows.len()).filter(|&i| ev.active[i]).collect();
        let measured =
            DVector::from_iterator(rows.len(), rows.iter().map(|&i| ev.data.rows[i].measured));
        // A Jacobian's replays and a few more.
        let keep = (REPLAYS_KEPT_VALUES / rows.len().max(1)).clamp(1, 4 * (knobs.len() + 2));
        Self {
            ev,
            base: base.clone(),
            reference: *reference,
            knobs,
            rows,
            measured,
            noise2: 0.0,
            replayed: Default::default(),
            keep,
            sensed: Default::default(),
        }
    }

    fn is_constant(&self, j: usize) -> bool {
        matches!(self.knobs[j], Knob::Constant(_))
    }

    /// The effect knobs whose columns a replay with tangents gives (the
    /// first [`tangent::EFFECT_SLOTS`] that act on the mass smoothly), with
    /// the parameter each slot follows.
    fn followed(&self) -> Vec<(usize, EffectParam)> {
        self.knobs
            .iter()
            .enumerate()
            .filter_map(|(j, knob)| match knob {
                Knob::Effect(c, i) => c.tangent_param(*i, &self.base.effects).map(|p| (j, p)),
                Knob::Constant(_) => None,
            })
            .take(tangent::EFFECT_SLOTS)
            .collect()
    }

    /// Whether knob `j`'s column is exact: a constant's (tangents or
    /// read-outs), a followed effect parameter's, or a read-out term's
    /// (its column, like a read-out constant's, from the read-outs the
    /// replay with tangents kept: no replay of its own).
    fn is_exact(&self, j: usize) -> bool {
        self.is_constant(j)
            || self.followed().iter().any(|&(k, _)| k == j)
            || matches!(&self.knobs[j], Knob::Effect(Candidate::Generic(g), _) if g.acts_on.role() == Role::ReadOut)
    }

    /// The knobs' coordinates in `cfg`.
    fn theta_of(&self, cfg: &ModelConfig) -> Vec<f64> {
        self.knobs
            .iter()
            .map(|k| match k {
                Knob::Constant(key) => (key.get(&cfg.product) / key.get(&self.reference))
                    .ln()
                    .clamp(-THETA_MAX, THETA_MAX),
                Knob::Effect(c, i) => c
                    .get(&cfg.effects)
                    .and_then(|p| p.get(*i).copied())
                    .map_or(0.5, |v| c.unit(*i, v)),
            })
            .collect()
    }

    /// A constant within [`THETA_MAX`] of its reference and within its
    /// physical range (`ProductKey::physical_range`: a model.toml written
    /// from the fit reads back); an effect's coordinate in [0, 1].
    fn bounds(&self, j: usize) -> (f64, f64) {
        match self.knobs[j] {
            Knob::Constant(key) => {
                let (lo, hi, _) = key.physical_range();
                let r = key.get(&self.reference);
                if r == 0.0 {
                    // 0 scaled stays 0.
                    return (-THETA_MAX, THETA_MAX);
                }
                // r e^θ within [lo, hi]: for r > 0, θ within [ln(lo / r),
                // ln(hi / r)]; for r < 0 the ends swap.
                let (a, b) = if r > 0.0 {
                    (lo / r, hi / r)
                } else {
                    (hi / r, lo / r)
                };
                let ln = |x: f64| if x > 0.0 { x.ln() } else { f64::NEG_INFINITY };
                (ln(a).max(-THETA_MAX), ln(b).min(THETA_MAX))
            }
            Knob::Effect(..) => (0.0, 1.0),
        }
    }

    /// The configuration at `theta`.
    fn config(&self, theta: &[f64]) -> ModelConfig {
        let mut cfg = self.base.clone();
        for (k, &t) in self.knobs.iter().zip(theta) {
            match k {
                Knob::Constant(key) => {
                    key.set(&mut cfg.product, key.get(&self.reference) * t.exp())
                }
                Knob::Effect(c, i) => {
                    if let Some(mut p) = c.get(&cfg.effects) {
                        if let Some(slot) = p.get_mut(*i) {
                            *slot = c.param(*i, t);
                        }
                        c.set(&mut cfg.effects, &p);
                    }
                }
            }
        }
        cfg
    }

    /// The simulated values of the active rows at `theta`; `None` for a
    /// configuration out of its ranges (muD below muC, say).
    fn simulated(&self, theta: &[f64]) -> Result<Option<DVector<f64>>> {
        let cfg = self.config(theta);
        if cfg.validate("calibration").is_err() {
            return Ok(None);
        }
        let key: Vec<u64> = theta.iter().map(|t| t.to_bits()).collect();
        let lock = || self.replayed.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, sim)) = lock().iter().find(|(k, _)| *k == key) {
            return Ok(Some(sim.clone()));
        }
        let all = self.ev.simulate(&cfg)?;
        let sim = self.active(&all);
        self.remember(key, &sim);
        Ok(Some(sim))
    }

    /// The active rows of a column over every row.
    fn active(&self, all: &[f64]) -> DVector<f64> {
        DVector::from_iterator(self.rows.len(), self.rows.iter().map(|&i| all[i]))
    }

    /// Keeps the simulated values at the `θ` with bits `key`.
    fn remember(&self, key: Vec<u64>, sim: &DVector<f64>) {
        let mut kept = self.replayed.lock().unwrap_or_else(|e| e.into_inner());
        if kept.len() >= self.keep {
            kept.pop_front();
        }
        kept.push_back((key, sim.clone()));
    }

    /// The derivatives of the simulated values in every state constant
    /// among the knobs at `theta` (knob, column), from one replay with
    /// tangents (kept: a Jacobian asked for again at the same `θ` costs
    /// nothing), which also gives the values there; `None` for a
    /// configuration out of its ranges.
    fn state_columns(&self, theta: &[f64]) -> Result<Option<StateColumns>> {
        let key: Vec<u64> = theta.iter().map(|t| t.to_bits()).collect();
        let lock = || self.sensed.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, columns)) = lock().iter().find(|(k, _)| *k == key) {
            return Ok(Some(columns.clone()));
        }
        let cfg = self.config(theta);
        if cfg.validate("calibration").is_err() {
            return Ok(None);
        }
        let state: Vec<(usize, ProductKey)> = self
            .knobs
            .iter()
            .enumerate()
            .filter_map(|(j, knob)| match knob {
                Knob::Constant(key) if key.role() == Role::State => Some((j, *key)),
                _ => None,
            })
            .collect();
        let keys: Vec<ProductKey> = state.iter().map(|&(_, key)| key).collect();
        let followed = self.followed();
        let params: Vec<EffectParam> = followed.iter().map(|&(_, p)| p).collect();
        let (all, columns) = self.ev.sensitivities(&cfg, &keys, &params)?;
        self.remember(key.clone(), &self.active(&all));
        // An effect's coordinate is u: the tangent's ∂/∂q times dq/du.
        let scale = |j: usize| match &self.knobs[j] {
            Knob::Effect(c, i) => c.dparam_du(*i, theta[j]),
            Knob::Constant(_) => 1.0,
        };
        let columns: StateColumns = Arc::new(
            state
                .iter()
                .map(|&(j, _)| j)
                .chain(followed.iter().map(|&(j, _)| j))
                .zip(columns)
                .map(|(j, column)| (j, self.active(&column) * scale(j)))
                .collect(),
        );
        let mut kept = lock();
        if kept.len() >= SENSED_KEPT {
            kept.pop_front();
        }
        kept.push_back((key, columns.clone()));
        Ok(Some(columns))
    }

    /// The simulated values' derivatives in the knobs `cols`: the state
    /// constants' and the followed effect parameters' ([`Problem::followed`])
    /// from one replay with tangents (exact), the others by forward
    /// differences (inwards at a bound; a read-out constant's from the
    /// read-outs that replay kept, any other effect parameter's one replay
    /// each, in parallel).
    fn jacobian(&self, theta: &[f64], at: &DVector<f64>, cols: &[usize]) -> Result<DMatrix<f64>> {
        let followed = self.followed();
        let wants_state = cols.iter().any(|&j| {
            matches!(self.knobs[j], Knob::Constant(key) if key.role() == Role::State)
                || followed.iter().any(|&(k, _)| k == j)
        });
        let state = match wants_state {
            true => self.state_columns(theta)?,
            false => None,
        };
        let exact: Vec<Option<DVector<f64>>> = cols
            .iter()
            .map(|&j| {
                state
                    .as_ref()
                    .and_then(|s| s.iter().find(|(k, _)| *k == j).map(|(_, c)| c.clone()))
            })
            .collect();
        let columns: Vec<DVector<f64>> = cols
            .par_iter()
            .zip(exact)
            .map(|(&j, exact)| {
                if let Some(column) = exact {
                    return Ok(column);
                }
                let (_, hi) = self.bounds(j);
                let h = if theta[j] + STEP <= hi { STEP } else { -STEP };
                let mut t = theta.to_vec();
                t[j] += h;
                Ok(match self.simulated(&t)? {
                    Some(s) => (s - at) / h,
                    None => DVector::zeros(at.len()),
                })
            })
            .collect::<Result<_>>()?;
        Ok(DMatrix::from_columns(&columns))
    }

    /// Levenberg–Marquardt over the knobs `free` from `theta`; returns the
    /// optimum and its simulated values. With `truncate` (a floor on the
    /// eigenvalues of `JᵀJ`), the steps move only along the directions the
    /// recording determines (a least-change solution: directions below
    /// the floor are left where they are), so that confounded constants can
    /// all be free at once.
    fn fit(
        &self,
        theta: &[f64],
        free: &[usize],
        truncate: Option<f64>,
    ) -> Result<(Vec<f64>, DVector<f64>)> {
        self.fit_from(theta, free, truncate, None)
    }

    /// [`Problem::fit`], the first Jacobian given (over `free`): computed at
    /// `theta` (`true`), or carried from nearby (`false`: computed again
    /// before the fit may stop on it). A fit whose knobs all have exact
    /// columns (constants, followed effect parameters) takes exact
    /// Jacobians ([`Problem::fit_exact`]); with any other effect parameter
    /// (a step's threshold, a third one) it carries one by Broyden's
    /// updates.
    fn fit_from(
        &self,
        theta: &[f64],
        free: &[usize],
        truncate: Option<f64>,
        mut first_j: Option<(DMatrix<f64>, bool)>,
    ) -> Result<(Vec<f64>, DVector<f64>)> {
        if !free.is_empty() && free.iter().all(|&f| self.is_exact(f)) {
            return self.fit_exact(theta, free, truncate, None);
        }
        let flat_sse = LM_FLAT * self.noise2;
        let mut theta = theta.to_vec();
        let mut sim = self.simulated(&theta)?.ok_or_else(out_of_range)?;
        if free.is_empty() {
            return Ok((theta, sim));
        }
        let mut sse = (&self.measured - &sim).norm_squared();
        let mut lambda = 1e-3;
        // The Jacobian is computed once (one replay per knob) and then
        // carried along by Broyden's rank-one updates from each step taken
        // (one replay per trial): computed again only when a step from the
        // carried one fails to improve (Madsen, Nielsen and Tingleff,
        // "Methods for non-linear least squares problems", 2004, §3.4).
        let (mut j, mut fresh) = match first_j.take() {
            Some(given) => given,
            None => (self.jacobian(&theta, &sim, free)?, true),
        };
        for _ in 0..LM_MAX_ITERS {
            let r = &self.measured - &sim;
            let a = j.transpose() * &j;
            let g = j.transpose() * &r;
            let sigma2 = sse / (self.rows.len().saturating_sub(free.len()).max(1)) as f64;
            let eigen = truncate.map(|_| a.clone().symmetric_eigen());
            // From a computed Jacobian, the most any step can gain is the
            // Gauss–Newton step's (the linearised SSE's fall, `gᵀ A⁺ g`):
            // when that is flat, the fit has converged without a trial.
            if fresh && predicted_gain(&a, &g, eigen.as_ref(), truncate) <= flat_sse {
                break;
            }
            // The step for a damping.
            let step_for = |lambda| damped_step(&a, &g, eigen.as_ref(), truncate, lambda, 0.0);
            // Two dampings tried at once (both cores): the current one and
            // four times it; the lighter one that improves is taken.
            let mut improved = None;
            for _ in 0..5 {
                let tries: Vec<(f64, Option<Trial>)> = [lambda, 4.0 * lambda]
                    .par_iter()
                    .map(|&l| {
                        let Some(step) = step_for(l) else {
                            return Ok((l, None));
                        };
                        let mut trial = theta.clone();
                        for (k, &f) in free.iter().enumerate() {
                            let (lo, hi) = self.bounds(f);
                            trial[f] = (theta[f] + step[k]).clamp(lo, hi);
                        }
                        Ok((
                            l,
                            self.simulated(&trial)?.map(|s| {
                                let e = (&self.measured - &s).norm_squared();
                                (trial, s, step, e)
                            }),
                        ))
                    })
                    .collect::<Result<_>>()?;
                if let Some((l, Some((trial, s, step, _)))) = tries
                    .into_iter()
                    .find(|(_, t)| t.as_ref().is_some_and(|t| t.3 < sse))
                {
                    improved = Some((trial, s, step));
                    lambda = (l / 3.0).max(1e-9);
                    break;
                }
                // A carried Jacobian that misleads is computed again rather
                // than damped further.
                if !fresh {
                    break;
                }
                lambda *= 16.0;
            }
            let Some((trial, s, step)) = improved else {
                if fresh {
                    break;
                }
                j = self.jacobian(&theta, &sim, free)?;
                fresh = true;
                continue;
            };
            let new_sse = (&self.measured - &s).norm_squared();
            // Whether this step came from a computed Jacobian (the update
            // below carries it).
            let from_computed = fresh;
            // Broyden: the Jacobian made to map the step actually taken
            // (after the bounds) onto the change it made.
            let taken =
                DVector::from_iterator(free.len(), free.iter().map(|&f| trial[f] - theta[f]));
            let norm2 = taken.norm_squared();
            if norm2 > 0.0 {
                let miss = (&s - &sim) - &j * &taken;
                j += miss * taken.transpose() / norm2;
                fresh = false;
            }
            // How far each parameter moved, in its standard errors.
            let inv = match (&eigen, truncate) {
                (Some(e), Some(floor)) => Some(pseudo_inverse(e, floor)),
                _ => a.clone().try_inverse(),
            };
            let moved = inv.map_or(f64::INFINITY, |inv| {
                (0..free.len())
                    .filter(|&k| inv[(k, k)] > 0.0)
                    .map(|k| step[k].abs() / (sigma2 * inv[(k, k)]).sqrt())
                    .fold(0.0, f64::max)
            });
            let flat = sse - new_sse <= flat_sse;
            // A flat step from a computed Jacobian: converged where that
            // Jacobian was computed (the step gains less than the flat
            // threshold; staying lets the caller reuse the replays).
            if flat && from_computed {
                break;
            }
            theta = trial;
            sim = s;
            sse = new_sse;
            if flat || moved < MOVE_TOL {
                // Converged as the carried Jacobian sees it: once more from
                // a computed one before stopping.
                if from_computed {
                    break;
                }
                j = self.jacobian(&theta, &sim, free)?;
                fresh = true;
            }
        }
        Ok((theta, sim))
    }
}

impl Problem<'_, '_> {
    /// Where a fit over `free` that starts at `start` is expected to end,
    /// as the sensitivities `j` (over every knob) at a fit `from` see it:
    /// the knobs of `free` take over, linearly, what the others' change
    /// from `from` to `start` did to the simulated values. A refit with a
    /// constant held thus starts near its optimum (a few replays, not a
    /// dozen); `start` itself when that point is out of its ranges or
    /// the free knobs' sensitivities are singular.
    fn projected(&self, j: &DMatrix<f64>, from: &[f64], start: &[f64], free: &[usize]) -> Vec<f64> {
        if free.is_empty() {
            return start.to_vec();
        }
        let held: Vec<usize> = (0..self.knobs.len())
            .filter(|k| !free.contains(k))
            .collect();
        let moved = DVector::from_iterator(held.len(), held.iter().map(|&k| start[k] - from[k]));
        let (j_free, j_held) = (j.select_columns(free), j.select_columns(&held));
        let floor = self.noise2 / PROJECT_SD.powi(2);
        let eigen = (j_free.transpose() * &j_free).symmetric_eigen();
        let shift = pseudo_inverse(&eigen, floor) * (j_free.transpose() * (j_held * moved));
        let mut theta = start.to_vec();
        for (q, &k) in free.iter().enumerate() {
            let (lo, hi) = self.bounds(k);
            theta[k] = (from[k] - shift[q]).clamp(lo, hi);
        }
        match theta.iter().all(|t| t.is_finite())
            && self.config(&theta).validate("calibration").is_ok()
        {
            true => theta,
            false => start.to_vec(),
        }
    }

    /// The values and the Jacobian over `free` at `theta`: one replay with
    /// tangents for the state constants (the values come with it), the
    /// read-out constants' columns from its read-outs. `None` out of range.
    fn sensed(
        &self,
        theta: &[f64],
        free: &[usize],
    ) -> Result<Option<(DVector<f64>, DMatrix<f64>)>> {
        if self.state_columns(theta)?.is_none() {
            return Ok(None);
        }
        let Some(sim) = self.simulated(theta)? else {
            return Ok(None);
        };
        let j = self.jacobian(theta, &sim, free)?;
        Ok(Some((sim, j)))
    }

    /// Levenberg–Marquardt over constants alone, each trial evaluated with
    /// its exact Jacobian ([`Problem::sensed`]: one replay with tangents
    /// gives both): a step taken comes with the Jacobian of the next. A
    /// constant at its bound that the step would push out stays there (the
    /// step is solved without it). The damping follows the gain ratio
    /// (Nielsen's rule; Madsen, Nielsen and Tingleff 2004, §3.2). A step
    /// that climbs is followed by a trial at the minimum along it of the
    /// cubic through the SSE's values and exact slopes at both ends, and
    /// the damping raised to shorten the next steps as much: where the
    /// model misses something (large residuals) or a cap or threshold
    /// bends the SSE, its curvature exceeds the linearised model's, and
    /// damping by tenfold rises and falls zig-zagged over a dozen trials
    /// (seen in the joint refits of a nozzle case: 26 replays with
    /// tangents for one constant). Stops
    /// when the Gauss–Newton step's predicted gain or a step's actual gain
    /// is flat (`LM_FLAT` noise variances), when no constant moves by more
    /// than `MOVE_TOL` of its standard error, or when no damping improves.
    /// With a `target` SSE (a likelihood-ratio test's), also when the fit
    /// cannot reach it: twice the Gauss–Newton step's predicted gain (a
    /// curved valley gives less than the first prediction, not more) still
    /// leaves it above.
    fn fit_exact(
        &self,
        theta: &[f64],
        free: &[usize],
        truncate: Option<f64>,
        target: Option<f64>,
    ) -> Result<(Vec<f64>, DVector<f64>)> {
        let mut theta = theta.to_vec();
        let (mut sim, mut j) = self.sensed(&theta, free)?.ok_or_else(out_of_range)?;
        let mut sse = (&self.measured - &sim).norm_squared();
        let mut lambda = 1e-3;
        // A step has climbed where the linearised model promised a fall:
        // the damping is lightened less from then on.
        let mut climbed = false;
        for _ in 0..LM_MAX_ITERS {
            let r = &self.measured - &sim;
            let a = j.transpose() * &j;
            let g = j.transpose() * &r;
            // Flat in the residuals' variance: where the model misses
            // something (the residuals exceed the noise) the likelihood is
            // that much flatter.
            let flat_sse = LM_FLAT * self.noise2.max(sse / self.rows.len().max(1) as f64);
            let Some((on, gain)) = self.unblocked(&theta, free, &a, &g, truncate) else {
                break;
            };
            if gain <= flat_sse || target.is_some_and(|t| sse - 2.0 * gain > t) {
                break;
            }
            let mut taken = None;
            // A step that climbed, with its exact slope: the next trial is
            // the minimum along it of the cubic through both ends.
            let mut along: Option<DVector<f64>> = None;
            for _ in 0..4 {
                let from_search = along.is_some();
                let Some(step) = along
                    .take()
                    .or_else(|| self.bounded_step(&theta, free, &on, &a, &g, truncate, lambda))
                else {
                    lambda *= REJECTED;
                    continue;
                };
                let mut trial = theta.clone();
                for (k, &f) in free.iter().enumerate() {
                    let (lo, hi) = self.bounds(f);
                    trial[f] = (theta[f] + step[k]).clamp(lo, hi);
                }
                // What the linearised model promised for the step taken.
                let h =
                    DVector::from_iterator(free.len(), free.iter().map(|&f| trial[f] - theta[f]));
                let promised = 2.0 * h.dot(&g) - h.dot(&(&a * &h));
                let tried = self.sensed(&trial, free)?;
                let new_sse = tried
                    .as_ref()
                    .map_or(f64::INFINITY, |(s, _)| (&self.measured - s).norm_squared());
                if new_sse < sse && promised > 0.0 {
                    if !from_search {
                        let rho = (sse - new_sse) / promised;
                        let floor = if climbed { CLIMBED_LIGHTEN } else { LIGHTEN };
                        lambda *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(floor);
                    }
                    let sigma2 = (sse / self.rows.len() as f64).max(self.noise2);
                    let moved = standard_moves(&a, &h, sigma2, truncate);
                    taken = tried.map(|(s, jt)| (trial, s, jt, new_sse, moved));
                    break;
                }
                // The SSE's exact slopes along the step, at both ends
                // (`-2 Jᵀr`): where it climbed past a minimum, that
                // minimum is tried next and the damping made to shorten
                // the next steps as much.
                if let (false, Some((s_t, j_t))) = (from_search, &tried) {
                    let d0 = -2.0 * g.dot(&h);
                    let d1 = -2.0 * (j_t.transpose() * (&self.measured - s_t)).dot(&h);
                    if let Some(alpha) = cubic_minimum(sse, d0, new_sse, d1) {
                        along = Some(&h * alpha);
                        lambda = (1.0 + lambda) / alpha - 1.0;
                        climbed = true;
                        continue;
                    }
                }
                lambda *= REJECTED;
            }
            let Some((trial, s, jt, new_sse, moved)) = taken else {
                break;
            };
            let flat = sse - new_sse <= flat_sse;
            (theta, sim, j, sse) = (trial, s, jt, new_sse);
            if flat || moved < MOVE_TOL {
                break;
            }
        }
        Ok((theta, sim))
    }

    /// The damped step over `free` (the knobs `on` may move) that keeps
    /// within the bounds: a knob the step would take past its bound is
    /// put on it and the others' step solved again given that move (an
    /// active set), so that the step is the damped model's best within the
    /// box rather than a clipped one, which may climb. With `truncate` the
    /// damping `λ` is added to the eigenvalues relative to the largest
    /// (the poorly determined directions shrink first), else Marquardt's.
    #[allow(clippy::too_many_arguments)]
    fn bounded_step(
        &self,
        theta: &[f64],
        free: &[usize],
        on: &[usize],
        a: &DMatrix<f64>,
        g: &DVector<f64>,
        truncate: Option<f64>,
        lambda: f64,
    ) -> Option<DVector<f64>> {
        let mut step = DVector::zeros(free.len());
        let mut on = on.to_vec();
        let mut fixed: Vec<usize> = Vec::new();
        loop {
            if on.is_empty() {
                return Some(step);
            }
            // What the knobs put on their bounds do to the gradient.
            let g_on = g.select_rows(&on)
                - a.select_rows(&on).select_columns(&fixed) * step.select_rows(&fixed);
            let a_on = a.select_rows(&on).select_columns(&on);
            let eigen = truncate.map(|_| a_on.clone().symmetric_eigen());
            let solved = match &eigen {
                Some(e) => {
                    let largest = e.eigenvalues.iter().copied().fold(0.0, f64::max);
                    damped_step(&a_on, &g_on, Some(e), truncate, 0.0, lambda * largest)
                }
                None => damped_step(&a_on, &g_on, None, None, lambda, 0.0),
            }?;
            let mut crossing = Vec::new();
            for (q, &k) in on.iter().enumerate() {
                let (lo, hi) = self.bounds(free[k]);
                let to = theta[free[k]] + solved[q];
                if to > hi || to < lo {
                    step[k] = to.clamp(lo, hi) - theta[free[k]];
                    crossing.push(k);
                } else {
                    step[k] = solved[q];
                }
            }
            if crossing.is_empty() {
                return Some(step);
            }
            on.retain(|k| !crossing.contains(k));
            fixed.extend(crossing);
        }
    }

    /// The knobs of `free` (indices into it) a step may move at `theta`:
    /// those at a bound that the Gauss–Newton step pushes outwards are
    /// left out, until none is; and that step's predicted gain. `None` when
    /// every knob is blocked.
    fn unblocked(
        &self,
        theta: &[f64],
        free: &[usize],
        a: &DMatrix<f64>,
        g: &DVector<f64>,
        truncate: Option<f64>,
    ) -> Option<(Vec<usize>, f64)> {
        let mut on: Vec<usize> = (0..free.len()).collect();
        loop {
            let a_on = a.select_rows(&on).select_columns(&on);
            let g_on = g.select_rows(&on);
            let eigen = truncate.map(|_| a_on.clone().symmetric_eigen());
            let step = damped_step(&a_on, &g_on, eigen.as_ref(), truncate, 0.0, 0.0)?;
            let blocked: Vec<usize> = on
                .iter()
                .zip(step.iter())
                .filter(|(&k, &d)| {
                    let (lo, hi) = self.bounds(free[k]);
                    (theta[free[k]] >= hi && d > 0.0) || (theta[free[k]] <= lo && d < 0.0)
                })
                .map(|(&k, _)| k)
                .collect();
            if blocked.is_empty() {
                let gain = predicted_gain(&a_on, &g_on, eigen.as_ref(), truncate);
                return Some((on, gain));
            }
            on.retain(|k| !blocked.contains(k));
            if on.is_empty() {
                return None;
            }
        }
    }
}

/// The minimum in (0, 1) of the cubic with values `f0`, `f1` and slopes
/// `d0 < 0`, `d1` at 0 and 1 (Nocedal and Wright, "Numerical
/// optimization", 2006, eq. 3.59), within [`SEARCH_RANGE`]; `None` where
/// the slopes say no minimum lies between.
fn cubic_minimum(f0: f64, d0: f64, f1: f64, d1: f64) -> Option<f64> {
    if !(d0 < 0.0 && (f1 >= f0 || d1 > 0.0)) {
        return None;
    }
    let e1 = d0 + d1 - 3.0 * (f1 - f0);
    let disc = e1 * e1 - d0 * d1;
    let alpha = if disc >= 0.0 {
        let e2 = disc.sqrt();
        1.0 - (d1 + e2 - e1) / (d1 - d0 + 2.0 * e2)
    } else {
        // No real stationary point: the quadratic through f0, d0, f1.
        -d0 / (2.0 * (f1 - f0 - d0))
    };
    alpha
        .is_finite()
        .then(|| alpha.clamp(SEARCH_RANGE.0, SEARCH_RANGE.1))
}

/// The largest move of a step `h` in standard errors (`A = JᵀJ`, `sigma2`
/// the residual variance): the diagonal of `sigma2 A⁻¹` (with `truncate`,
/// the pseudo-inverse over the directions above that floor), infinite
/// where `A` is singular.
fn standard_moves(a: &DMatrix<f64>, h: &DVector<f64>, sigma2: f64, truncate: Option<f64>) -> f64 {
    let inverse = match truncate {
        Some(floor) => Some(pseudo_inverse(&a.clone().symmetric_eigen(), floor)),
        None => a.clone().try_inverse(),
    };
    let Some(inv) = inverse else {
        return f64::INFINITY;
    };
    (0..h.len())
        .filter(|&k| inv[(k, k)] > 0.0)
        .map(|k| h[k].abs() / (sigma2 * inv[(k, k)]).sqrt())
        .fold(0.0, f64::max)
}

/// The Levenberg–Marquardt step for the damping `lambda` (`A = JᵀJ`, `g =
/// Jᵀr`): with `truncate` (a floor on the eigenvalues of `A`) along the
/// directions above the floor only, each eigenvalue `l` damped to `l (1 +
/// λ) + shift`; else Marquardt's scaled damping.
fn damped_step(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    eigen: Option<&nalgebra::SymmetricEigen<f64, nalgebra::Dyn>>,
    truncate: Option<f64>,
    lambda: f64,
    shift: f64,
) -> Option<DVector<f64>> {
    match (eigen, truncate) {
        (Some(e), Some(floor)) => {
            let mut step = DVector::zeros(g.len());
            for (k, &l) in e.eigenvalues.iter().enumerate() {
                if l >= floor {
                    let v = e.eigenvectors.column(k);
                    step += v * (v.dot(g) / (l * (1.0 + lambda) + shift));
                }
            }
            Some(step)
        }
        _ => {
            let mut m = a.clone();
            for d in 0..m.nrows() {
                m[(d, d)] += lambda * a[(d, d)].max(1e-30);
            }
            m.cholesky().map(|c| c.solve(g))
        }
    }
}

/// The fall of the linearised SSE at the Gauss–Newton step (`gᵀ A⁻¹ g`,
/// `A = JᵀJ`, `g = Jᵀr`): with `truncate`, over the directions whose
/// eigenvalue is at least the floor only (the steps [`Problem::fit_from`]
/// takes); without, infinite when `A` is singular (no prediction).
fn predicted_gain(
    a: &DMatrix<f64>,
    g: &DVector<f64>,
    eigen: Option<&nalgebra::SymmetricEigen<f64, nalgebra::Dyn>>,
    truncate: Option<f64>,
) -> f64 {
    match (eigen, truncate) {
        (Some(e), Some(floor)) => e
            .eigenvalues
            .iter()
            .enumerate()
            .filter(|(_, &l)| l >= floor && l.is_finite())
            .map(|(k, &l)| e.eigenvectors.column(k).dot(g).powi(2) / l)
            .sum(),
        _ => a
            .clone()
            .cholesky()
            .map_or(f64::INFINITY, |c| g.dot(&c.solve(g))),
    }
}

/// The pseudo-inverse of a symmetric matrix from its eigen decomposition,
/// eigenvalues below `floor` left out.
fn pseudo_inverse(e: &nalgebra::SymmetricEigen<f64, nalgebra::Dyn>, floor: f64) -> DMatrix<f64> {
    let p = e.eigenvalues.len();
    let mut inv = DMatrix::<f64>::zeros(p, p);
    for (k, &l) in e.eigenvalues.iter().enumerate() {
        if l >= floor && l.is_finite() {
            let v = e.eigenvectors.column(k);
            inv += v * v.transpose() / l;
        }
    }
    inv
}

/// The larger, per parameter, of the model-based and the train-clustered
/// (sandwich) variances of a least squares fit with Jacobian `j` (n × p),
/// `inv` the (pseudo-)inverse of `jᵀj` and residuals `r`.
fn robust_variances(
    j: &DMatrix<f64>,
    inv: &DMatrix<f64>,
    r: &DVector<f64>,
    clusters: &[usize],
    dof_p: usize,
) -> Vec<f64> {
    let (n, p) = (j.nrows(), j.ncols());
    let dof = n.saturating_sub(dof_p).max(1) as f64;
    let sigma2 = r.norm_squared() / dof;
    let groups = clusters.iter().copied().max().map_or(0, |m| m + 1);
    let mut scores = DMatrix::<f64>::zeros(groups, p);
    for i in 0..n {
        for k in 0..p {
            scores[(clusters[i], k)] += j[(i, k)] * r[i];
        }
    }
    let used = (0..groups)
        .filter(|&g| (0..p).any(|k| scores[(g, k)] != 0.0))
        .count()
        .max(2) as f64;
    let meat = scores.transpose() * &scores * (used / (used - 1.0) * (n as f64 - 1.0) / dof);
    let sandwich = inv * meat * inv;
    (0..p)
        .map(|k| (sigma2 * inv[(k, k)]).max(sandwich[(k, k)]))
        .collect()
}

/// What the recording determines with every parameter free (the profile
/// likelihood's view, linearised at the fit): a constant is pinned down
/// alone when its standard error, every other constant and effect
/// parameter free, is at most [`SD_DETERMINED`].
struct Identifiability {
    /// Per knob: the standard error with everything free, `None` where the
    /// knob has a part in a direction the recording does not determine at
    /// all.
    marginal_sd: Vec<Option<f64>>,
}

/// A direction whose standard error exceeds this (in `ln p`, a factor e)
/// is not determined at all; it is left out of the pseudo-inverse.
const SD_NULL: f64 = 1.0;
/// A knob with more than this share of its unit vector in such directions
/// has no standard error of its own.
const NULL_SHARE: f64 = 0.01;

/// With `r` (residuals at a fit), the variances are the robust ones;
/// without, the model-based ones with the noise `sigma` (at a point that is
/// not a fit, whose residuals say nothing of the noise).
fn identifiability(
    j: &DMatrix<f64>,
    r: Option<&DVector<f64>>,
    clusters: &[usize],
    sigma: f64,
) -> Identifiability {
    let p = j.ncols();
    let eigen = (j.transpose() * j).symmetric_eigen();
    let floor = (sigma / SD_NULL).powi(2);
    let inv = pseudo_inverse(&eigen, floor);
    let mut kept = vec![0.0; p];
    let mut rank = 0;
    for (k, &lambda) in eigen.eigenvalues.iter().enumerate() {
        if lambda >= floor && lambda.is_finite() {
            let v = eigen.eigenvectors.column(k);
            for (a, kept_a) in kept.iter_mut().enumerate() {
                *kept_a += v[a] * v[a];
            }
            rank += 1;
        }
    }
    let var: Vec<f64> = match r {
        Some(r) => robust_variances(j, &inv, r, clusters, rank),
        None => (0..p).map(|k| sigma * sigma * inv[(k, k)]).collect(),
    };
    Identifiability {
        marginal_sd: (0..p)
            .map(|k| (1.0 - kept[k] <= NULL_SHARE).then(|| var[k].sqrt()))
            .collect(),
    }
}

/// The fit of the knobs `fitted` alone (the others held): per fitted knob
/// its standard error, and how much of each held knob's deviation it
/// absorbs (`A = (J_FᵀJ_F)⁻¹ J_FᵀJ_U`, rows over `fitted`, columns over
/// every knob).
struct Conditional {
    sd: Vec<f64>,
    absorbs: DMatrix<f64>,
}

fn conditional(
    j: &DMatrix<f64>,
    r: &DVector<f64>,
    clusters: &[usize],
    fitted: &[usize],
) -> Option<Conditional> {
    let jf = j.select_columns(fitted);
    let inv = (jf.transpose() * &jf).try_inverse()?;
    let var = robust_variances(&jf, &inv, r, clusters, fitted.len());
    let a = &inv * (jf.transpose() * j);
    Some(Conditional {
        sd: var.iter().map(|v| v.sqrt()).collect(),
        absorbs: a,
    })
}

/// The knobs to fit: every effect knob, and the constants in the order of
/// their information while each constant of the set keeps a standard
/// error of at most [`SD_DETERMINED`] with the set fitted together, the
/// others held (`s`: the Jacobian over the noise).
fn select(problem: &Problem<'_, '_>, s: &DMatrix<f64>, exclude: &[usize]) -> Vec<usize> {
    let info = s.transpose() * s;
    let mut fitted: Vec<usize> = (0..problem.knobs.len())
        .filter(|&j| !problem.is_constant(j))
        .collect();
    let sds = |set: &[usize]| -> Option<Vec<f64>> {
        let m = DMatrix::from_fn(set.len(), set.len(), |a, b| info[(set[a], set[b])]);
        let inv = m.cholesky()?.inverse();
        Some((0..set.len()).map(|k| inv[(k, k)].sqrt()).collect())
    };
    let mut order: Vec<usize> = (0..problem.knobs.len())
        .filter(|&j| problem.is_constant(j) && info[(j, j)] > 0.0 && !exclude.contains(&j))
        .collect();
    // Most information first; within 2 % the order of ProductKey::ALL.
    let bucket = |j: usize| -> i64 { -((info[(j, j)].ln() / 1.02f64.ln()).round() as i64) };
    order.sort_by_key(|&j| (bucket(j), j));
    for j in order {
        if info[(j, j)].sqrt().recip() > SD_DETERMINED {
            continue;
        }
        let mut trial = fitted.clone();
        trial.push(j);
        let Some(sd) = sds(&trial) else {
            continue;
        };
        let before = sds(&fitted);
        let ok = trial.iter().enumerate().all(|(k, &t)| {
            if problem.is_constant(t) {
                sd[k] <= SD_DETERMINED
            } else {
                // An effect's parameter may not lose more than half its
                // precision to the constant.
                before
                    .as_ref()
                    .and_then(|b| b.get(k))
                    .is_none_or(|&b0| sd[k] <= 2.0 * b0.max(1e-3))
            }
        });
        if ok {
            fitted.push(j);
        }
    }
    fitted.sort_unstable();
    fitted
}

/// Which representatives of `free` (at `theta`, Jacobian `j` over every
/// knob) to hold at their reference values: the one whose estimate is
/// fewest standard errors from it, if within 1.96 (its interval holds the
/// reference value), then again with the others moved and their
/// covariance conditioned as the linearised fit says, until none is.
/// The covariance is the model-based one with its variances raised to the
/// robust ones the report gives (the correlations kept), so that what is
/// held is what the reported interval says.
fn pin_sequentially(
    j: &DMatrix<f64>,
    r: &DVector<f64>,
    clusters: &[usize],
    theta: &[f64],
    free: &[usize],
    reps: &[usize],
) -> Option<Vec<(usize, f64, f64)>> {
    let jf = j.select_columns(free);
    let inv = (jf.transpose() * &jf).try_inverse()?;
    let var = robust_variances(&jf, &inv, r, clusters, free.len());
    let scale = DVector::from_fn(free.len(), |a, _| {
        if inv[(a, a)] > 0.0 {
            (var[a] / inv[(a, a)]).sqrt()
        } else {
            0.0
        }
    });
    let mut cov = DMatrix::from_fn(free.len(), free.len(), |a, b| {
        inv[(a, b)] * scale[a] * scale[b]
    });
    let mut est: Vec<f64> = free.iter().map(|&k| theta[k]).collect();
    let mut alive: Vec<bool> = vec![true; free.len()];
    let mut pinned = Vec::new();
    loop {
        let weakest = (0..free.len())
            .filter(|&a| alive[a] && reps.contains(&free[a]) && cov[(a, a)] > 0.0)
            .map(|a| (a, est[a].abs() / cov[(a, a)].sqrt()))
            .filter(|&(_, z)| z <= Z95)
            .min_by(|x, y| x.1.total_cmp(&y.1));
        let Some((a, _)) = weakest else {
            break;
        };
        // Its estimate and standard error as the interval that holds the
        // reference value says (the report gives it).
        pinned.push((free[a], est[a], cov[(a, a)].sqrt()));
        let (ca, ea) = (cov.column(a).clone_owned(), est[a]);
        for b in 0..free.len() {
            est[b] -= ca[b] / ca[a] * ea;
        }
        cov -= &ca * ca.transpose() / ca[a];
        alive[a] = false;
    }
    Some(pinned)
}

/// Row -> cluster: the measured train, or the row itself (a tribometer
/// reading).
fn clusters(problem: &Problem<'_, '_>) -> Vec<usize> {
    let trains = problem.ev.data.passages.len();
    problem
        .rows
        .iter()
        .enumerate()
        .map(|(k, &i)| problem.ev.data.rows[i].train_seq.unwrap_or(trains + k))
        .collect()
}

/// Calibrates the constants of `base` on the recording of `ev`. The
/// constants the recording determines, and one for each combination it
/// determines, are fitted together with the parameters of `effects`
/// (effects switched on in `base`); every other constant is held at its
/// value in `reference`. `noise`: the measurements' standard deviation
/// (the RMSE of `base` when unknown).
///
/// A calibration is a function of these arguments and the evaluator's
/// rows: one asked for again with the same arguments (the final
/// calibration of a discover whose last step's calibration started from
/// the model it ends with) is the earlier one, with no engine runs of its
/// own.
pub(super) fn calibrate(
    ev: &Evaluator<'_>,
    base: &ModelConfig,
    reference: &ProductParams,
    effects: &[Candidate],
    noise: Option<f64>,
) -> Result<Calibration> {
    let t0 = Instant::now();
    let key = CalibrationKey {
        base: base.clone(),
        reference: *reference,
        effects: effects.to_vec(),
        noise: noise.map(f64::to_bits),
    };
    if let Some(earlier) = ev.calibrated(&key) {
        return Ok(Calibration {
            engine_runs: 0,
            elapsed_s: t0.elapsed().as_secs_f64(),
            ..earlier
        });
    }
    let calibration = calibrate_anew(ev, base, reference, effects, noise)?;
    ev.keep_calibration(key, &calibration);
    Ok(calibration)
}

/// What a [`calibrate`] call is a function of (besides the evaluator).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct CalibrationKey {
    base: ModelConfig,
    reference: ProductParams,
    effects: Vec<Candidate>,
    /// The noise's bits.
    noise: Option<u64>,
}

fn calibrate_anew(
    ev: &Evaluator<'_>,
    base: &ModelConfig,
    reference: &ProductParams,
    effects: &[Candidate],
    noise: Option<f64>,
) -> Result<Calibration> {
    let _stage = ev.cost.enter(Stage::Calibration);
    let t0 = Instant::now();
    let runs0 = ev.runs();
    let mut problem = Problem::new(ev, base, reference, effects);
    let all: Vec<usize> = (0..problem.knobs.len()).collect();
    let theta0 = problem.theta_of(base);
    let sim0 = problem.simulated(&theta0)?.ok_or_else(out_of_range)?;
    let n = problem.rows.len().max(1) as f64;
    let rmse_before = ((&problem.measured - &sim0).norm_squared() / n).sqrt();
    let sigma = noise.filter(|s| *s > 0.0).unwrap_or(rmse_before).max(1e-6);
    problem.noise2 = sigma * sigma;
    let problem = problem;
    let clusters = clusters(&problem);

    // 1. Every knob free, moving only along the directions the recording
    //    determines: the fit with nothing held.
    let floor = (sigma / SD_NULL).powi(2);
    let j0 = problem.jacobian(&theta0, &sim0, &all)?;
    let (theta_all, sim_all) =
        problem.fit_from(&theta0, &all, Some(floor), Some((j0.clone(), true)))?;
    let j_all = problem.jacobian(&theta_all, &sim_all, &all)?;
    let r_all = &problem.measured - &sim_all;

    // 2. What it pins down alone: a determined constant keeps that fit's
    //    estimate (its reference value where the interval holds it).
    // The sensitivities change along the way: what is pinned down at the
    // fit may not be at the reference values, where a valley the fit
    // followed was still flat. A constant is determined only if it is
    // at both.
    let id = identifiability(&j_all, Some(&r_all), &clusters, sigma);
    let id0 = identifiability(&j0, None, &clusters, sigma);
    let mut fits: Vec<Option<Fit>> = vec![None; problem.knobs.len()];
    let mut determined = Vec::new();
    for k in 0..problem.knobs.len() {
        let both = id.marginal_sd[k]
            .zip(id0.marginal_sd[k])
            .map(|(a, b)| a.max(b));
        if let (true, Some(sd)) = (problem.is_constant(k), both) {
            if sd <= SD_DETERMINED {
                fits[k] = Some(Fit {
                    theta: theta_all[k],
                    value_theta: 0.0,
                    sd,
                    lean: 0.0,
                    determined: true,
                    partners: Vec::new(),
                    pinned: theta_all[k].abs() <= Z95 * sd,
                    flat: false,
                });
                determined.push(k);
            }
        }
    }

    // 3. The rest of what it determines, through representatives: one
    //    constant per combination, the others held at their reference
    //    values; the effects' parameters fitted with them.
    //    The determined constants are fitted with them (their intervals
    //    stay those of the fit with nothing held: the profile view).
    let reps = select(&problem, &(&j_all / sigma), &determined);
    let mut start = vec![0.0; problem.knobs.len()];
    let mut free = reps.clone();
    for k in 0..problem.knobs.len() {
        match &fits[k] {
            Some(f) if !f.pinned => {
                start[k] = f.theta;
                free.push(k);
            }
            _ if !problem.is_constant(k) => start[k] = theta_all[k],
            _ => {}
        }
    }
    free.sort_unstable();
    free.dedup();
    let start = problem.projected(&j_all, &theta_all, &start, &free);
    let (mut theta, mut sim) = problem.fit_from(
        &start,
        &free,
        None,
        Some((j_all.select_columns(&free), false)),
    )?;
    //    The start is a linear view from the fit with nothing held; where
    //    the model misses much (two hidden effects: a combination's
    //    exponent of -250) it is no guide, and the fit from it may end
    //    worse than the starting constants (tests/discover_generic.rs,
    //    tangent seed 5: RMSE 0.0385 -> 0.0843). Then it is fitted again
    //    from the starting constants, the others held at their reference
    //    values, and the better kept: at step 0 a calibration never ends
    //    worse than it started.
    let sse0 = (&problem.measured - &sim0).norm_squared();
    if (&problem.measured - &sim).norm_squared() > sse0 {
        let mut t = theta0.clone();
        for (k, t) in t.iter_mut().enumerate() {
            if problem.is_constant(k) && !free.contains(&k) {
                *t = 0.0;
            }
        }
        let (t2, s2) = problem.fit_from(&t, &free, None, None)?;
        if (&problem.measured - &s2).norm_squared() < (&problem.measured - &sim).norm_squared() {
            (theta, sim) = (t2, s2);
        }
    }

    //    A determined constant that moved must still be needed: fitted
    //    again with it at its reference value and the rest free, the fit
    //    may be as good to the noise (a likelihood-ratio test at 95 %, the
    //    profile likelihood's view): the linearised view misjudges a curved
    //    valley, and such a constant is not determined after all.
    let sigma2 = sigma * sigma;
    let mut sse = (&problem.measured - &sim).norm_squared();
    let mut moved: Vec<(usize, f64)> = determined
        .iter()
        .filter_map(|&k| {
            fits[k]
                .as_ref()
                .filter(|f| !f.pinned && f.theta.abs() < LR_SURE * f.sd)
                .map(|f| (k, f.theta.abs() / f.sd))
        })
        .collect();
    moved.sort_by(|a, b| a.1.total_cmp(&b.1));
    // The sensitivities at the fit (its last replay with tangents gave
    // them): each refit below starts where they expect it to end.
    let mut j = problem.jacobian(&theta, &sim, &all)?;
    for (k, _) in moved {
        let rest: Vec<usize> = free.iter().copied().filter(|&f| f != k).collect();
        let mut t = theta.clone();
        t[k] = 0.0;
        let target = sse + CHI2_1_95 * sigma2;
        let (t2, s2) = if rest.iter().all(|&f| problem.is_constant(f)) {
            problem.fit_exact(&t, &rest, None, Some(target))?
        } else {
            problem.fit_from(&t, &rest, None, Some((j_all.select_columns(&rest), false)))?
        };
        let sse2 = (&problem.measured - &s2).norm_squared();
        if sse2 <= target {
            if let Some(f) = fits[k].as_mut() {
                f.determined = false;
                f.flat = true;
                f.pinned = true;
            }
            determined.retain(|&d| d != k);
            free = rest;
            (theta, sim, sse) = (t2, s2, sse2.min(sse));
            j = problem.jacobian(&theta, &sim, &all)?;
        }
    }

    // 4. A representative whose combination's interval holds its reference
    //    value is held there, one at a time (the weakest first) while the
    //    others' estimates and intervals follow linearly, so that several
    //    that lean on each other are not all let go; then fitted once more.
    //    The linear view of the others' moves is only a view: after the
    //    refit, what now holds its reference value is held too (a few
    //    rounds at most, each holds one more).
    let mut held_at: Vec<(usize, f64, f64)> = Vec::new();
    for _ in 0..PIN_ROUNDS {
        let r = &problem.measured - &sim;
        let pinned = pin_sequentially(&j, &r, &clusters, &theta, &free, &reps).unwrap_or_default();
        if pinned.is_empty() {
            break;
        }
        let mut t = theta.clone();
        for &(k, _, _) in &pinned {
            t[k] = 0.0;
        }
        free.retain(|k| !pinned.iter().any(|p| p.0 == *k));
        held_at.extend(pinned);
        let t = problem.projected(&j, &theta, &t, &free);
        (theta, sim) = problem.fit_from(&t, &free, None, Some((j.select_columns(&free), false)))?;
        j = problem.jacobian(&theta, &sim, &all)?;
    }
    // A representative the fit took where the recording no longer sees it
    // (m_max above every mass: its column vanishes) has no interval: it is
    // held at its reference value, the weakest first, and the rest fitted
    // again, until the fit's information is regular. What the report calls
    // held is what model.toml holds.
    let mut cond = conditional(&j, &(&problem.measured - &sim), &clusters, &free);
    while cond.is_none() {
        let Some(&blind) = free
            .iter()
            .filter(|&&k| problem.is_constant(k) && reps.contains(&k))
            .min_by(|&&a, &&b| {
                j.column(a)
                    .norm_squared()
                    .total_cmp(&j.column(b).norm_squared())
            })
        else {
            break;
        };
        held_at.push((blind, theta[blind], f64::NAN));
        free.retain(|&k| k != blind);
        let mut t = theta.clone();
        t[blind] = 0.0;
        let t = problem.projected(&j, &theta, &t, &free);
        (theta, sim) = problem.fit_from(&t, &free, None, Some((j.select_columns(&free), false)))?;
        j = problem.jacobian(&theta, &sim, &all)?;
        cond = conditional(&j, &(&problem.measured - &sim), &clusters, &free);
    }
    for &k in &reps {
        let slot = free.iter().position(|&f| f == k);
        let fit = match (slot, &cond) {
            (Some(slot), Some(c)) => Fit {
                theta: theta[k],
                value_theta: theta[k],
                sd: c.sd[slot],
                lean: 0.0,
                determined: false,
                partners: partners_of(&problem, &c.absorbs, slot, &free),
                pinned: false,
                flat: false,
            },
            // Held at its reference value: the estimate and standard error
            // with which its interval held it.
            _ => Fit {
                theta: held_at.iter().find(|p| p.0 == k).map_or(0.0, |p| p.1),
                value_theta: 0.0,
                sd: held_at.iter().find(|p| p.0 == k).map_or(f64::NAN, |p| p.2),
                lean: 0.0,
                determined: false,
                partners: Vec::new(),
                pinned: true,
                flat: false,
            },
        };
        fits[k] = Some(fit);
    }
    for &k in &determined {
        if let Some(f) = fits[k].as_mut() {
            f.value_theta = theta[k];
        }
    }
    if let Some(c) = &cond {
        lean_of_held(&mut fits, c, &free);
    }
    let fitted = free;
    let model = problem.config(&theta);
    Ok(report(
        &problem,
        &fits,
        &cond,
        &fitted,
        &theta,
        &sim,
        &j,
        model,
        rmse_before,
        sigma,
        ev.runs() - runs0,
        t0,
    ))
}

/// What the constants held at their reference values can push into the
/// determined constants fitted beside them. A held constant `u` (a
/// determined one whose interval holds its reference value, a
/// representative held there, one the likelihood-ratio test let go) is
/// not known to be at its reference value: the recording puts it at its
/// estimate `θ_u` within its standard error `s_u`, and the fitted knobs
/// absorb a deviation of it as `A θ_u` (`A` from [`conditional`]). So a
/// determined constant `k` has a spread of at least
/// `√(s_k|held² + Σ_u (A_ku s_u)²)` (its conditional one and what the held
/// ones add), kept where that exceeds its spread with everything free, and
/// its interval reaches from the value the model carries to where the held
/// constants' estimates would move it (`-Σ_u A_ku θ_u`, [`Fit::lean`]).
/// The seed 20261146 campaign showed why: `km_kg` -33 % held at the
/// laboratory's value (its interval held both) moved `mu_d` by -1.7 %,
/// five of its standard errors.
///
/// A held constant's spread counts at most [`THETA_MAX`]: no constant is
/// let further from its reference value than that, so a held one the
/// recording leaves open cannot push more. The seed 20261208 campaign (site
/// 4) held `m_max_kg` with a standard error of 2.4 million in `ln p` (its
/// sensitivity gone at the final fit); through an absorption of 0.003 it
/// widened `mu_d`, determined to a fraction of a percent, to 95 % 0–inf,
/// written as `null` in report.json.
fn lean_of_held(fits: &mut [Option<Fit>], cond: &Conditional, fitted: &[usize]) {
    let held: Vec<(usize, f64, f64)> = fits
        .iter()
        .enumerate()
        .filter(|(u, _)| !fitted.contains(u))
        .filter_map(|(u, f)| f.as_ref().map(|f| (u, f.theta, f.sd.min(THETA_MAX))))
        .filter(|&(_, theta, sd)| theta.is_finite() && sd.is_finite())
        .collect();
    for (slot, &k) in fitted.iter().enumerate() {
        let Some(fit) = fits[k].as_mut().filter(|f| f.determined && !f.pinned) else {
            continue;
        };
        let (mut lean, mut var) = (0.0, cond.sd[slot].powi(2));
        for &(u, theta, sd) in &held {
            let a = cond.absorbs[(slot, u)];
            lean -= a * theta;
            var += (a * sd).powi(2);
        }
        fit.lean = lean;
        fit.sd = fit.sd.max(var.sqrt());
    }
}

/// A damped step tried: the constants, the simulated measurements, the
/// step taken and the sum of squared residuals.
type Trial = (Vec<f64>, DVector<f64>, DVector<f64>, f64);

/// What the calibration says of one constant it fitted.
#[derive(Debug, Clone)]
struct Fit {
    /// The estimate (`θ`): with everything free for a determined constant,
    /// the combination's for a representative.
    theta: f64,
    /// Where the final fit put it (`θ`; 0 when held).
    value_theta: f64,
    /// Its standard error (of `ln p`).
    sd: f64,
    /// For a determined constant fitted beside constants held at their
    /// reference values: where those constants' own estimates would move
    /// it (`θ`), the side its interval widens to ([`lean_of_held`]).
    lean: f64,
    determined: bool,
    /// For a representative: the held constants whose deviation it carries,
    /// with the exponent.
    partners: Vec<(usize, f64)>,
    /// Its interval holds its reference value: held there.
    pinned: bool,
    /// Determined in the linearised view, but the fit with it at its
    /// reference value and the rest free is as good: not determined.
    flat: bool,
}

/// Fits the constants `keys` again (and nothing else) on `base`: after an
/// effect was added, the constants it was standing in for move back.
pub(super) fn refit(
    ev: &Evaluator<'_>,
    base: &ModelConfig,
    reference: &ProductParams,
    keys: &[ProductKey],
    noise: Option<f64>,
) -> Result<ModelConfig> {
    let _stage = ev.cost.enter(Stage::Calibration);
    let mut problem = Problem::new(ev, base, reference, &[]);
    let free: Vec<usize> = (0..problem.knobs.len())
        .filter(|&k| matches!(&problem.knobs[k], Knob::Constant(key) if keys.contains(key)))
        .collect();
    if free.is_empty() {
        return Ok(base.clone());
    }
    problem.noise2 = noise.map_or(0.0, |s| s * s);
    let (theta, _) = problem.fit(&problem.theta_of(base), &free, None)?;
    Ok(problem.config(&theta))
}

/// Fits the constants `keys` and the parameters of `effect` together on
/// `base` (Levenberg–Marquardt from where they are): an effect taken
/// beside the constants, each moved to where it no longer makes up for
/// the other.
pub(super) fn refit_with(
    ev: &Evaluator<'_>,
    base: &ModelConfig,
    reference: &ProductParams,
    keys: &[ProductKey],
    effect: &Candidate,
    noise: Option<f64>,
) -> Result<ModelConfig> {
    let _stage = ev.cost.enter(Stage::Refits);
    let mut problem = Problem::new(ev, base, reference, std::slice::from_ref(effect));
    let free: Vec<usize> = (0..problem.knobs.len())
        .filter(|&k| match &problem.knobs[k] {
            Knob::Constant(key) => keys.contains(key),
            Knob::Effect(..) => true,
        })
        .collect();
    problem.noise2 = noise.map_or(0.0, |s| s * s);
    let (theta, _) = problem.fit(&problem.theta_of(base), &free, None)?;
    Ok(problem.config(&theta))
}

#[allow(clippy::too_many_arguments)]
fn report(
    problem: &Problem<'_, '_>,
    fits: &[Option<Fit>],
    cond: &Option<Conditional>,
    fitted: &[usize],
    theta: &[f64],
    sim: &DVector<f64>,
    j: &DMatrix<f64>,
    model: ModelConfig,
    rmse_before: f64,
    sigma: f64,
    engine_runs: usize,
    t0: Instant,
) -> Calibration {
    let n = problem.rows.len().max(1) as f64;
    let rmse_after = ((&problem.measured - sim).norm_squared() / n).sqrt();
    let laboratory = ModelConfig::default().product;
    let mut constants = Vec::new();
    let mut moved = Vec::new();
    let mut fitted_keys = Vec::new();
    for key in ProductKey::ALL {
        let reference = key.get(&problem.reference);
        let default = key.get(&laboratory);
        let value = key.get(&model.product);
        let name = format!("product.{}", key.name());
        let start = (reference != default).then_some(reference);
        let base = SiteConstant {
            key: name.clone(),
            default,
            start,
            value,
            ci95: None,
            determined: false,
            sd_ln: None,
            status: "kept".into(),
            combination: None,
            description: String::new(),
        };
        let Some(k) = problem.knobs.iter().position(|x| *x == Knob::Constant(key)) else {
            constants.push(SiteConstant {
                description: format!(
                    "not examined: its value {} is not positive; kept",
                    fmt_param(reference)
                ),
                ..base
            });
            continue;
        };
        let constant = match &fits[k] {
            Some(fit) => {
                if !fit.pinned && theta[k] != 0.0 {
                    fitted_keys.push(key);
                }
                describe_fitted(problem, key, fit, reference, base)
            }
            None => describe_held(problem, key, k, j, sigma, fitted, cond.as_ref(), base),
        };
        if constant.value != reference {
            moved.push(name);
        }
        constants.push(constant);
    }
    let summary = summary(&constants, rmse_before, rmse_after, sigma);
    Calibration {
        constants,
        rmse_before,
        rmse_after,
        noise: sigma,
        moved,
        summary,
        engine_runs,
        elapsed_s: t0.elapsed().as_secs_f64(),
        model,
        fitted: fitted_keys,
    }
}

/// The 95 % interval of `value` with standard error `sd` of its logarithm.
fn interval(value: f64, sd: f64) -> [f64; 2] {
    [value * (-Z95 * sd).exp(), value * (Z95 * sd).exp()]
}

fn percent(ratio: f64) -> String {
    let change = (ratio - 1.0) * 100.0;
    // A change under 1 % keeps a decimal: "-0 %" would say nothing moved.
    if change.abs() < 0.95 {
        format!("{change:+.1} %")
    } else {
        format!("{change:+.0} %")
    }
}

fn describe_fitted(
    problem: &Problem<'_, '_>,
    key: ProductKey,
    fit: &Fit,
    reference: f64,
    base: SiteConstant,
) -> SiteConstant {
    let estimate = reference * fit.theta.exp();
    // A determined constant's interval is centred on the value the model
    // carries (the fit with the representatives; its spread is the one
    // with every other constant free, or what the held constants add
    // where that is more: [`lean_of_held`]); one held at its reference
    // value shows the interval that holds it.
    let centre = if fit.determined && !fit.pinned {
        reference * fit.value_theta.exp()
    } else {
        estimate
    };
    let ci = interval(centre, fit.sd);
    // Widened on the side the held constants lean to.
    let ci = [
        ci[0] * fit.lean.min(0.0).exp(),
        ci[1] * fit.lean.max(0.0).exp(),
    ];
    let ci_text = format!("{}–{}", fmt_param(ci[0]), fmt_param(ci[1]));
    let reference_text = if base.start.is_some() {
        format!("the starting model's {}", fmt_param(reference))
    } else {
        format!("the laboratory's {}", fmt_param(reference))
    };
    // A representative held where its conditional covariance could not be
    // formed (a singular fit): nothing honest to say of its interval.
    let keeping = if base.start.is_some() {
        "kept at the starting model's value"
    } else {
        "kept at the laboratory's value"
    };
    let kept = |description: String| SiteConstant {
        ci95: None,
        determined: false,
        sd_ln: None,
        status: "kept".into(),
        description,
        ..base.clone()
    };
    if !fit.sd.is_finite() {
        return kept(format!(
                "not determined alone: with the constants it would be fitted with, the recording gives no interval for it; {keeping}"
            ));
    }
    if fit.flat {
        return kept(format!(
                "not determined: the linearised fit put it at {} (±{:.0} %), but with it at its reference value and the others refitted the recording is fitted as well (likelihood-ratio test at 95 %); {keeping}",
                fmt_param(estimate),
                Z95 * fit.sd * 100.0
            ));
    }
    if fit.determined {
        let description = if fit.pinned {
            format!("determined by this recording, and its 95 % interval {ci_text} holds {reference_text}: kept there")
        } else {
            format!(
                "determined by this recording: {} (95 % {ci_text}), {} against {reference_text}",
                fmt_param(base.value),
                percent(base.value / reference)
            )
        };
        return SiteConstant {
            ci95: Some(ci),
            determined: true,
            sd_ln: Some(fit.sd),
            status: if fit.pinned { "held" } else { "fitted" }.into(),
            description,
            ..base
        };
    }
    // A representative: it carries a combination with the constants it
    // cannot be told from.
    let mut factors = vec![(key.name().to_string(), 1.0)];
    let mut expression = key.name().to_string();
    let mut with = Vec::new();
    for &(other, a) in &fit.partners {
        let Knob::Constant(o) = problem.knobs[other] else {
            continue;
        };
        factors.push((o.name().to_string(), a));
        with.push(o.name());
        expression.push_str(&format!(
            " × ({} / {})^{:.2}",
            o.name(),
            fmt_param(o.get(&problem.reference)),
            a
        ));
    }
    let with = with.join(", ");
    // An interval wider than the range a constant may move at all
    // (THETA_MAX either way) fixes nothing.
    let open = Z95 * fit.sd > THETA_MAX;
    let description = RepresentativeText {
        with: &with,
        expression: &expression,
        estimate,
        name: key.name(),
        ci_text: &ci_text,
        reference_text: &reference_text,
        keeping,
    }
    .describe(fit.pinned, open);
    SiteConstant {
        ci95: None,
        determined: false,
        sd_ln: Some(fit.sd),
        status: if fit.pinned { "held" } else { "carries" }.into(),
        combination: (!fit.partners.is_empty()).then_some(Combination {
            expression,
            factors,
            value: estimate,
            ci95: ci,
        }),
        description,
        ..base
    }
}

/// What a representative's description is made of ([`describe_fitted`]).
struct RepresentativeText<'a> {
    /// The held constants it cannot be told from, by name ("" if none).
    with: &'a str,
    /// Its combination with them, as a product of powers.
    expression: &'a str,
    /// The fitted value of the representative (of the combination).
    estimate: f64,
    name: &'a str,
    ci_text: &'a str,
    /// The reference value, saying whose it is.
    reference_text: &'a str,
    /// Where a constant the recording leaves open is kept.
    keeping: &'a str,
}

impl RepresentativeText<'_> {
    /// The description of a representative `held` at its reference value
    /// or carrying the fit, whose interval is `open` (wider than the range
    /// a constant may move at all): an open interval fixes nothing, alone
    /// or as a combination.
    fn describe(&self, held: bool, open: bool) -> String {
        let Self {
            with,
            expression,
            estimate,
            name,
            ci_text,
            reference_text,
            keeping,
        } = *self;
        let acts = format!("not determined alone: it acts on these measurements as {with} do");
        let left_open = format!(
            "open (95 % {ci_text}, wider than the factor 2.5 a constant may move): {keeping}"
        );
        match (with.is_empty(), held) {
            (true, true) if open => format!(
                "not determined alone; with the others held the recording leaves it {left_open}"
            ),
            (true, true) => format!(
                "not determined alone; with the others held the recording fixes it within 95 % {ci_text}, which holds {reference_text}: kept there"
            ),
            (true, false) => format!(
                "not determined alone; with the others held the recording puts it at {} (95 % {ci_text})",
                fmt_param(estimate)
            ),
            (false, true) if open => {
                format!("{acts}; the recording leaves the combination {expression} {left_open}")
            }
            (false, true) => format!(
                "{acts}; the recording fixes the combination {expression} within 95 % {ci_text}, which holds {reference_text}: kept there"
            ),
            (false, false) => format!(
                "{acts}; the recording fixes the combination {expression} = {} (95 % {ci_text}), carried by {name} with {with} at their reference values",
                fmt_param(estimate),
            ),
        }
    }
}

/// The held constants whose deviation the representative at `slot` of
/// `fitted` absorbs most, with the exponent: those within a third of the
/// strongest, at most three.
fn partners_of(
    problem: &Problem<'_, '_>,
    absorbs: &DMatrix<f64>,
    slot: usize,
    fitted: &[usize],
) -> Vec<(usize, f64)> {
    let row: Vec<(usize, f64)> = (0..problem.knobs.len())
        .filter(|&k| problem.is_constant(k) && !fitted.contains(&k))
        .map(|k| (k, absorbs[(slot, k)]))
        .filter(|(_, a)| a.abs() > 0.05)
        .collect();
    let strongest = row.iter().map(|(_, a)| a.abs()).fold(0.0, f64::max);
    let mut partners: Vec<(usize, f64)> = row
        .into_iter()
        .filter(|(_, a)| a.abs() >= strongest / 3.0)
        .collect();
    partners.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    partners.truncate(3);
    partners
}

#[allow(clippy::too_many_arguments)]
fn describe_held(
    problem: &Problem<'_, '_>,
    key: ProductKey,
    k: usize,
    j: &DMatrix<f64>,
    sigma: f64,
    fitted: &[usize],
    cond: Option<&Conditional>,
    base: SiteConstant,
) -> SiteConstant {
    let alone = sigma / j.column(k).norm().max(1e-300);
    let keeping = if base.start.is_some() {
        "kept at the starting model's value"
    } else {
        "kept at the laboratory's value"
    };
    let description = if alone > SD_DETERMINED {
        format!(
            "not determined by this recording: {keeping} (alone, the recording would fix it to ±{:.0} % only)",
            (Z95 * alone * 100.0).min(999.0)
        )
    } else {
        // The representative that takes its part.
        let carrier = cond.and_then(|c| {
            (0..fitted.len())
                .filter(|&s| problem.is_constant(fitted[s]))
                .max_by(|&a, &b| c.absorbs[(a, k)].abs().total_cmp(&c.absorbs[(b, k)].abs()))
                .filter(|&s| c.absorbs[(s, k)].abs() > 0.05)
                .map(|s| (fitted[s], c.absorbs[(s, k)]))
        });
        match carrier {
            Some((f, a)) => {
                let name = match &problem.knobs[f] {
                    Knob::Constant(c) => c.name().to_string(),
                    Knob::Effect(c, _) => c.label(),
                };
                format!(
                    "not determined alone: on these measurements a change of {} looks like {a:.2} times that change of {name}, which carries it; {keeping}",
                    key.name()
                )
            }
            None => format!(
                "not determined alone: its effect on these measurements is that of other constants together; {keeping}"
            ),
        }
    };
    SiteConstant {
        description,
        ..base
    }
}

fn summary(constants: &[SiteConstant], before: f64, after: f64, sigma: f64) -> String {
    let moved: Vec<String> = constants
        .iter()
        .filter(|c| c.value != c.start.unwrap_or(c.default))
        .map(|c| {
            let reference = c.start.unwrap_or(c.default);
            format!(
                "{} {} ({} against {})",
                c.key.trim_start_matches("product."),
                fmt_param(c.value),
                percent(c.value / reference),
                fmt_param(reference)
            )
        })
        .collect();
    let determined = constants.iter().filter(|c| c.determined).count();
    let head = if moved.is_empty() {
        "The site's constants are the laboratory's as far as this recording tells".to_string()
    } else {
        format!(
            "This site's constants differ from the laboratory's: {}",
            moved.join(", ")
        )
    };
    format!(
        "{head}. The recording determines {determined} of {} constants alone; RMSE {:.5} -> {:.5} (noise {:.5}).",
        constants.len(),
        before,
        after,
        sigma
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Jacobian of `n` rows from column functions of the row index.
    fn jacobian(n: usize, columns: &[&dyn Fn(usize) -> f64]) -> DMatrix<f64> {
        DMatrix::from_fn(n, columns.len(), |i, c| columns[c](i))
    }

    /// A held constant the recording leaves open (a standard error of
    /// millions in `ln p`) widens a determined constant beside it by at most
    /// what moving it to the edge of its range ([`THETA_MAX`]) would push,
    /// and a held one the recording pins down by what its spread pushes.
    #[test]
    fn a_held_constant_pushes_no_more_than_its_range_allows() {
        let fit = |sd: f64, determined: bool| Fit {
            theta: 0.01,
            value_theta: 0.0,
            sd,
            lean: 0.0,
            determined,
            partners: Vec::new(),
            pinned: false,
            flat: false,
        };
        // Knob 0 determined and fitted; 1 held, open; 2 held, pinned down.
        let mut fits = vec![
            Some(fit(0.004, true)),
            Some(fit(2.4e6, false)),
            Some(fit(0.05, false)),
        ];
        let cond = Conditional {
            sd: vec![0.0039],
            absorbs: DMatrix::from_row_slice(1, 3, &[1.0, 0.003, 0.2]),
        };
        lean_of_held(&mut fits, &cond, &[0]);
        let sd = fits[0].as_ref().map(|f| f.sd).unwrap();
        let most =
            (0.0039f64.powi(2) + (0.003 * THETA_MAX).powi(2) + (0.2 * 0.05f64).powi(2)).sqrt();
        assert!((sd - most).abs() < 1e-12, "{sd} against {most}");
        assert!(sd < 0.02, "{sd}");
    }

    #[test]
    fn an_open_interval_fixes_no_combination_either() {
        let text = RepresentativeText {
            with: "km2",
            expression: "m0_kg × (km2 / 1.2)^1.00",
            estimate: 2e-4,
            name: "m0_kg",
            ci_text: "1.1e-6–0.037",
            reference_text: "the laboratory's 0.0002",
            keeping: "kept at the laboratory's value",
        };
        let open = text.describe(true, true);
        assert!(
            open.contains("leaves the combination m0_kg × (km2 / 1.2)^1.00 open"),
            "{open}"
        );
        assert!(!open.contains("fixes"), "{open}");
        let narrow = text.describe(true, false);
        assert!(narrow.contains("fixes the combination"), "{narrow}");
        // Alone, the same.
        let alone = RepresentativeText { with: "", ..text };
        assert!(alone.describe(true, true).contains("leaves it open"));
        assert!(alone.describe(true, false).contains("fixes it within"));
        // Carrying the fit, the interval is given with the value.
        let carried = text.describe(false, true);
        assert!(
            carried.contains("(95 % 1.1e-6–0.037), carried by m0_kg"),
            "{carried}"
        );
    }

    #[test]
    fn a_duplicated_sensitivity_is_not_determined_alone() {
        // Columns: a (its own), b and b again (m0 and km2 in eq. 1).
        let n = 400;
        let a = |i: usize| ((i as f64) * 0.37).sin();
        let b = |i: usize| ((i as f64) * 0.11).cos();
        let j = jacobian(n, &[&a, &b, &b]);
        let r = DVector::from_fn(n, |i, _| 0.01 * ((i * 7919 % 13) as f64 - 6.0) / 6.0);
        let clusters: Vec<usize> = (0..n).collect();
        let id = identifiability(&j, None, &clusters, 0.01);
        let sd_a = id.marginal_sd[0].expect("a is determined");
        // sigma / |a| with |a|² ≈ n / 2.
        assert!(
            (sd_a - 0.01 / (n as f64 / 2.0).sqrt()).abs() < 0.2 * sd_a,
            "{sd_a}"
        );
        assert_eq!(id.marginal_sd[1], None);
        assert_eq!(id.marginal_sd[2], None);
        // With residuals, the sandwich variant agrees in order of magnitude.
        let id = identifiability(&j, Some(&r), &clusters, 0.01);
        assert!(id.marginal_sd[0].is_some());
    }

    #[test]
    fn the_clustered_variance_sees_errors_shared_by_a_train() {
        // 50 trains of 8 measurements; the residual of a train shared by
        // all its measurements: the sandwich is about 8 times the
        // model-based variance, and is the one taken.
        let n = 400;
        let j = jacobian(n, &[&|_| 1.0]);
        let r = DVector::from_fn(n, |i, _| if (i / 8) % 2 == 0 { 0.01 } else { -0.01 });
        let clusters: Vec<usize> = (0..n).map(|i| i / 8).collect();
        let inv = (j.transpose() * &j).try_inverse().unwrap();
        let clustered = robust_variances(&j, &inv, &r, &clusters, 1)[0];
        let singles: Vec<usize> = (0..n).collect();
        let independent = robust_variances(&j, &inv, &r, &singles, 1)[0];
        assert!(
            clustered > 6.0 * independent,
            "{clustered} vs {independent}"
        );
    }

    #[test]
    fn representatives_are_held_one_at_a_time() {
        // Two representatives that lean on each other: each alone within
        // its interval of 0, together not. Holding the weaker moves the
        // other away from 0, which is then kept.
        let n = 400;
        let a = |i: usize| ((i as f64) * 0.37).sin();
        let b = |i: usize| ((i as f64) * 0.37).sin() + 0.05 * ((i as f64) * 0.91).cos();
        let j = jacobian(n, &[&a, &b]);
        let sigma = 0.01;
        let inv = (j.transpose() * &j).try_inverse().unwrap() * (sigma * sigma);
        let (s0, s1) = (inv[(0, 0)].sqrt(), inv[(1, 1)].sqrt());
        // Estimates opposite and large together, small against their sds.
        let theta = [0.5 * s0, -0.6 * s1];
        // Residuals of size sigma everywhere, each measurement its own
        // cluster: the sandwich variance is then sigma² (JᵀJ)⁻¹ exactly.
        let r = DVector::from_fn(n, |i, _| if (i * 7919) % 13 < 6 { sigma } else { -sigma });
        let singles: Vec<usize> = (0..n).collect();
        let held = |theta: &[f64]| -> Vec<usize> {
            pin_sequentially(&j, &r, &singles, theta, &[0, 1], &[0, 1])
                .unwrap()
                .iter()
                .map(|p| p.0)
                .collect()
        };
        assert_eq!(
            held(&theta),
            vec![0],
            "the weaker is held, the other then stands"
        );
        // Nothing is held that is far from its reference.
        assert!(held(&[10.0 * s0, 10.0 * s1]).is_empty());
    }

    #[test]
    fn a_constant_held_at_its_reference_widens_the_interval_of_one_it_leans_on() {
        // The truth: knob 1 at 0.3, knob 0 at 0. Knob 1 is held at its
        // reference value (0) with the estimate 0.25 ± 0.2 its interval
        // allows; knob 0, fitted alone, takes up `A · 0.3` of it, many of
        // its own standard errors away from the truth.
        let n = 400;
        let a = |i: usize| ((i as f64) * 0.37).sin();
        let b = |i: usize| 0.5 * ((i as f64) * 0.37).sin() + 0.2 * ((i as f64) * 0.91).cos();
        let j = jacobian(n, &[&a, &b]);
        let sigma = 0.01;
        let r = DVector::from_fn(n, |i, _| if (i * 7919) % 13 < 6 { sigma } else { -sigma });
        let singles: Vec<usize> = (0..n).collect();
        let cond = conditional(&j, &r, &singles, &[0]).unwrap();
        let absorbed = cond.absorbs[(0, 1)];
        let value = absorbed * 0.3;
        let fit = |theta: f64, sd: f64, determined: bool, pinned: bool| Fit {
            theta,
            value_theta: theta,
            sd,
            lean: 0.0,
            determined,
            partners: Vec::new(),
            pinned,
            flat: false,
        };
        let sd0 = cond.sd[0];
        assert!(
            value.abs() > 10.0 * sd0,
            "the bias is {} standard errors",
            value / sd0
        );
        let mut fits = vec![
            Some(fit(value, sd0, true, false)),
            Some(fit(0.25, 0.2, false, true)),
        ];
        lean_of_held(&mut fits, &cond, &[0]);
        let f = fits[0].as_ref().unwrap();
        assert!((f.lean + absorbed * 0.25).abs() < 1e-12);
        let expected = (sd0 * sd0 + (absorbed * 0.2).powi(2)).sqrt();
        assert!((f.sd - expected).abs() < 1e-12 * expected);
        let (lo, hi) = (
            value + f.lean.min(0.0) - Z95 * f.sd,
            value + f.lean.max(0.0) + Z95 * f.sd,
        );
        assert!(lo <= 0.0 && 0.0 <= hi, "{lo}..{hi} holds the truth");
        assert!(
            lo <= value && value <= hi,
            "and the value the model carries"
        );
        // A constant kept without an interval of its own adds nothing.
        let mut alone = vec![Some(fit(value, sd0, true, false)), None];
        lean_of_held(&mut alone, &cond, &[0]);
        assert_eq!(alone[0].as_ref().unwrap().sd, sd0);
    }

    #[test]
    fn intervals_are_symmetric_in_the_logarithm() {
        let [lo, hi] = interval(0.5, 0.1);
        assert!(((0.5f64 / lo).ln() - (hi / 0.5).ln()).abs() < 1e-12);
        assert!(((hi / 0.5).ln() - Z95 * 0.1).abs() < 1e-12);
    }

    #[test]
    fn the_minimum_along_a_step_that_climbed_is_found() {
        // A quadratic (t - 0.3)² and a cubic with its minimum at 0.4: both
        // ends' values and slopes give it exactly.
        let alpha = cubic_minimum(0.09, -0.6, 0.49, 1.4).unwrap();
        assert!((alpha - 0.3).abs() < 1e-12, "{alpha}");
        let f = |t: f64| t * t * t - 0.3 * t * t - 0.24 * t;
        let d = |t: f64| 3.0 * t * t - 0.6 * t - 0.24;
        let alpha = cubic_minimum(f(0.0), d(0.0), f(1.0), d(1.0)).unwrap();
        assert!((alpha - 0.4).abs() < 1e-12, "{alpha}");
        // A sharp rise (a kink just past the start): the trial stays near
        // the start, at the least fraction of the step.
        let alpha = cubic_minimum(1.0, -1.0, 50.0, 100.0).unwrap();
        assert_eq!(alpha, SEARCH_RANGE.0);
        // Still falling at the far end and lower there: no minimum between.
        assert!(cubic_minimum(1.0, -1.0, 0.5, -0.2).is_none());
        // Climbing from the start: no descent to search.
        assert!(cubic_minimum(1.0, 0.5, 2.0, 1.0).is_none());
    }
}
