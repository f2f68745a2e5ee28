//! Fitting the candidate effects of docs/spec/effects.md by re-running
//! the engine.
//!
//! Every parameter is fitted in a bounded, transformed coordinate `u` in
//! [0, 1] (the [`Candidate::param`] map: log for a time constant, log-like
//! for rates that matter most near 0, linear for exponents), so the
//! optimiser sees comparable scales and never leaves the range the
//! configuration accepts. The objective is the sum of squared residuals
//! (measured − simulated) over the measurements of the days in the fit.
//!
//! - One parameter: a coarse grid over [0, 1] evaluated in parallel, then
//!   a Gauss–Newton line search on the residual vector in the grid cell
//!   pair around the best point ([`line_search`]); warm-started from an
//!   earlier optimum, the line search on a narrow bracket around it
//!   (widened to the full search if the optimum sits on the bracket's
//!   edge).
//! - Several: a coarse grid, then Levenberg–Marquardt on the residual
//!   vector from the best grid point ([`levenberg_marquardt`]: the
//!   Jacobian by differences once, then Broyden's updates), in the box.
//!
//! Both use the residuals, not only their sum of squares: the residuals'
//! linear model says where the minimum is and how much is left to gain, so
//! a fit stops after a few replays where a search on the SSE alone
//! (argmin's Brent and Nelder–Mead before 2026-11-28) took two to three
//! times as many. The parameters of the effects are not differentiated in
//! the engine (their tangents would be a slot each in every contact);
//! their derivatives come from the replays the search makes anyway.
//!
//! Every evaluation is one replay through the engine and costs ~0.1–0.3 s on
//! a 3-day recording, so results are cached by the exact parameters, and
//! each evaluation keeps the SSE per day: the cross-validation's folds
//! reuse them.
//!
//! Blocked cross-validation ([`cross_validate`], by day or by site): for
//! each block, the parameters are refitted on the other blocks,
//! warm-started from the full-data optimum, and the held-out block's SSE is
//! taken at the refitted parameters.

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use rayon::prelude::*;
use serde::Serialize;

use super::calibrate::{Calibration, CalibrationKey};
use super::data::Dataset;
use super::space::GenericSlot;
use tortwin_engine::Readout;
use tortwin_model::config::{Effects, ModelConfig};
use tortwin_model::effects::Named;
use tortwin_model::role::Role;
use tortwin_model::tangent::EffectParam;
use tortwin_study::progress::Progress;
use tortwin_study::{Error, Result};

/// The effects discover knows: the named ones of effects.md (their table,
/// `tortwin_model::effects::EFFECTS`, gives parameters, ranges and
/// transforms), and any generic term of its space ([`GenericSlot`]).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(super) enum Candidate {
    Named(Named),
    Generic(GenericSlot),
}

impl Candidate {
    /// Every named effect, in the order of effects.md.
    pub(super) fn all() -> Vec<Candidate> {
        Named::ALL.into_iter().map(Candidate::Named).collect()
    }

    /// The effect's name in effects.md (`generic` for a generic term).
    pub(super) fn name(&self) -> &'static str {
        match self {
            Candidate::Named(n) => n.name(),
            Candidate::Generic(_) => "generic",
        }
    }

    /// The name, or a generic term's label.
    pub(super) fn label(&self) -> String {
        match self {
            Candidate::Generic(g) => g.label(),
            c => c.name().to_string(),
        }
    }

    pub(super) fn is_generic(&self) -> bool {
        matches!(self, Candidate::Generic(_))
    }

    pub(super) fn param_names(&self) -> Vec<&'static str> {
        match self {
            Candidate::Named(n) => n.spec().params.iter().map(|p| p.name).collect(),
            Candidate::Generic(g) => vec![g.param_name()],
        }
    }

    pub(super) fn dims(&self) -> usize {
        match self {
            Candidate::Named(n) => n.spec().params.len(),
            Candidate::Generic(_) => 1,
        }
    }

    /// Parameter `i` at the search coordinate `u` in [0, 1].
    pub(super) fn param(&self, i: usize, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        match self {
            Candidate::Named(n) => n.spec().params.get(i).map_or(f64::NAN, |p| p.at(u)),
            Candidate::Generic(g) => {
                let (lo, hi) = g.bounds();
                lo + (hi - lo) * u
            }
        }
    }

    /// `d param(i, u) / du`.
    pub(super) fn dparam_du(&self, i: usize, u: f64) -> f64 {
        match self {
            Candidate::Named(n) => n.spec().params.get(i).map_or(f64::NAN, |p| p.dp_du(u)),
            Candidate::Generic(g) => {
                let (lo, hi) = g.bounds();
                hi - lo
            }
        }
    }

    /// The effect parameter a tangent can follow for parameter `i` in
    /// `effects` (where the effect is on): one that acts on the mass and is
    /// smooth (`tortwin_model::tangent::EffectParam`). `None` for a
    /// read-out term (its parameter is read, not replayed) and for the
    /// bands.
    pub(super) fn tangent_param(&self, i: usize, effects: &Effects) -> Option<EffectParam> {
        match self {
            Candidate::Named(Named::BogieBands) => None,
            Candidate::Named(n) => Some(EffectParam::Named {
                effect: *n,
                param: i,
            }),
            Candidate::Generic(g) if g.acts_on.role() == Role::State => effects
                .generic
                .iter()
                .position(|t| g.is(t))
                .map(|term| EffectParam::Generic { term }),
            Candidate::Generic(_) => None,
        }
    }

    /// The inverse of [`Candidate::param`] (clamped into [0, 1]).
    pub(super) fn unit(&self, i: usize, p: f64) -> f64 {
        match self {
            Candidate::Named(n) => n.spec().params.get(i).map_or(0.0, |param| param.unit_of(p)),
            Candidate::Generic(g) => {
                let (lo, hi) = g.bounds();
                let u = (p - lo) / (hi - lo);
                if u.is_finite() {
                    u.clamp(0.0, 1.0)
                } else {
                    0.0
                }
            }
        }
    }

    /// Switches the effect on in `effects` with `params`.
    pub(super) fn set(&self, effects: &mut Effects, params: &[f64]) {
        match self {
            Candidate::Named(n) => effects.set(*n, params),
            Candidate::Generic(g) => g.set(effects, params.first().copied().unwrap_or(f64::NAN)),
        }
    }

    /// Whether the effect is a step whose threshold the data chose (one
    /// more parameter for the BIC).
    pub(super) fn is_step(&self) -> bool {
        matches!(self, Candidate::Generic(g) if g.form == Some(tortwin_model::generic::FormKind::Step))
    }

    /// Switches the effect off in `effects`.
    pub(super) fn unset(&self, effects: &mut Effects) {
        match self {
            Candidate::Named(n) => effects.unset(*n),
            Candidate::Generic(g) => effects.generic.retain(|t| !g.is(t)),
        }
    }

    /// The effect's parameters in `effects`, `None` when it is off.
    pub(super) fn get(&self, effects: &Effects) -> Option<Vec<f64>> {
        match self {
            Candidate::Named(n) => effects.get(*n).map(<[f64]>::to_vec),
            Candidate::Generic(g) => g.get(effects).map(|p| vec![p]),
        }
    }

    /// Parameters as name -> value, for the report.
    pub(super) fn named(&self, params: &[f64]) -> std::collections::BTreeMap<String, f64> {
        self.param_names()
            .iter()
            .zip(params)
            .map(|(n, v)| (n.to_string(), *v))
            .collect()
    }
}

/// A set of effects whose parameters are searched together, on top of a
/// base configuration: one candidate, or every accepted effect at a joint
/// refit. The search vector is the concatenation of their coordinates.
#[derive(Debug, Clone)]
pub(super) struct Space {
    pub(super) base: ModelConfig,
    pub(super) slots: Vec<Candidate>,
}

impl Space {
    pub(super) fn dims(&self) -> usize {
        self.slots.iter().map(|c| c.dims()).sum()
    }

    /// Per slot, its parameters at `u` (clamped into the box).
    pub(super) fn params(&self, u: &[f64]) -> Vec<Vec<f64>> {
        let mut k = 0;
        self.slots
            .iter()
            .map(|c| {
                let p = (0..c.dims())
                    .map(|i| c.param(i, u.get(k + i).copied().unwrap_or(0.0)))
                    .collect();
                k += c.dims();
                p
            })
            .collect()
    }

    pub(super) fn config(&self, u: &[f64]) -> ModelConfig {
        let mut cfg = self.base.clone();
        for (c, p) in self.slots.iter().zip(self.params(u)) {
            c.set(&mut cfg.effects, &p);
        }
        cfg
    }

    /// The search coordinates of the slots' parameters in `cfg` (0.5 for an
    /// effect that is off).
    pub(super) fn units_of(&self, cfg: &ModelConfig) -> Vec<f64> {
        self.slots
            .iter()
            .flat_map(|c| {
                let p = c.get(&cfg.effects);
                (0..c.dims()).map(move |i| {
                    p.as_ref()
                        .and_then(|p| p.get(i))
                        .map_or(0.5, |&v| c.unit(i, v))
                })
            })
            .collect()
    }
}

/// How the measurements are split into blocks for cross-validation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Blocking {
    /// By calendar day (UTC): an effect must predict days it was not fitted on.
    Day,
    /// By measurement site: an effect must predict a site it was not fitted
    /// on. A cause that belongs to one site (a sensor's offset) fails this.
    Site,
}

/// One evaluation: SSE in total, per day (indexed like [`Dataset::days`])
/// and per measured site (like [`Evaluator::sites`]).
#[derive(Debug, Clone)]
pub(super) struct Evaluation {
    pub(super) sse: f64,
    pub(super) sse_by_day: Vec<f64>,
    pub(super) sse_by_site: Vec<f64>,
}

impl Evaluation {
    /// SSE over every day but `excluded` (an index into the days).
    pub(super) fn sse_without(&self, excluded: Option<(Blocking, usize)>) -> f64 {
        match excluded {
            None => self.sse,
            Some((blocking, j)) => self.sse - self.by(blocking)[j],
        }
    }

    pub(super) fn by(&self, blocking: Blocking) -> &[f64] {
        match blocking {
            Blocking::Day => &self.sse_by_day,
            Blocking::Site => &self.sse_by_site,
        }
    }
}

/// Runs the engine for a configuration, with a cache and a run counter.
pub(super) struct Evaluator<'a> {
    pub(super) data: &'a Dataset,
    /// Row -> index into `data.days`.
    day_slot: Vec<usize>,
    /// The sites with measurements, ascending (indices into the section's).
    pub(super) sites: Vec<usize>,
    /// Row -> index into `sites`.
    site_slot: Vec<usize>,
    /// Rows that count in the SSE (false: treated as a gross outlier).
    pub(super) active: Vec<bool>,
    cache: Mutex<HashMap<Vec<u64>, Arc<Evaluation>>>,
    /// The residual vectors of the last evaluations, by the same key: a
    /// fit that goes on from points evaluated a while ago (a candidate's
    /// first look, [`first_look`], then its fit to the end) finds them
    /// here, at 8 bytes a row where the kept read-outs take about 40
    /// times that, and replays nothing again.
    residuals: Mutex<std::collections::VecDeque<KeptResidual>>,
    /// How many residual vectors are kept.
    keep_residuals: usize,
    /// The read-outs of the last replays, by their configuration's state
    /// part ([`ModelConfig::state_part`]): a configuration that differs
    /// from one of them only in read-out parameters is read, not replayed.
    readouts: Mutex<std::collections::VecDeque<Kept>>,
    /// The models candidates are built on ([`Evaluator::pin_base`]), with
    /// checkpoints: a configuration that adds a later time step to one of
    /// them continues from its state there.
    bases: Mutex<std::collections::VecDeque<(Kept, Arc<super::data::Checkpoints>)>>,
    /// How many replays' read-outs are kept (a bounded amount of memory).
    keep_readouts: usize,
    /// The last calibrations, by what they were asked
    /// ([`super::calibrate::calibrate`]).
    calibrations: Mutex<std::collections::VecDeque<(CalibrationKey, Calibration)>>,
    /// What the evaluations cost: replays and read-outs, with their time.
    pub(super) cost: CostMeter,
    /// Asked before every engine run whether to stop.
    progress: &'a dyn Progress,
}

/// The memory [`Evaluator`] keeps read-outs in, at most.
const READOUTS_KEPT_BYTES: usize = 256 << 20;
/// The memory it keeps residual vectors in, at most.
const RESIDUALS_KEPT_BYTES: usize = 64 << 20;
/// Checkpoints along a base's replay, and how many bases are kept.
const CHECKPOINTS: usize = 16;
const BASES_KEPT: usize = 4;
/// Calibrations kept by their arguments (a few configurations each).
const CALIBRATIONS_KEPT: usize = 8;

/// A residual vector kept by the [`Evaluator`], by its configuration's
/// cache key.
type KeptResidual = (Vec<u64>, Arc<Vec<f64>>);

/// A replay kept by the [`Evaluator`].
#[derive(Clone)]
struct Kept {
    state: ModelConfig,
    readouts: Arc<Vec<Readout>>,
}

/// Engine replays and read-outs, counted and timed: a read-out is a
/// fraction of a replay, and the report gives both as run-equivalents
/// (replays + read-out time over the mean replay's time).
#[derive(Debug, Default)]
pub(super) struct CostMeter {
    replays: AtomicUsize,
    replay_ns: std::sync::atomic::AtomicU64,
    readouts: AtomicUsize,
    readout_ns: std::sync::atomic::AtomicU64,
    resumed: AtomicUsize,
    resumed_ns: std::sync::atomic::AtomicU64,
    tangents: AtomicUsize,
    tangent_ns: std::sync::atomic::AtomicU64,
    /// The stage now running, and what each stage has cost so far.
    stages: Mutex<Stages>,
}

#[derive(Debug, Default)]
struct Stages {
    /// The stage now running and how many guards hold it. A stage entered
    /// while another runs is part of that one (a calibration inside a
    /// refit is the refit's): the work inside a stage runs on parallel
    /// threads, where "the innermost stage" would depend on their timing
    /// (one thread's evaluation after its calibration, beside a sibling's
    /// still in its own, was counted to either).
    entered: Option<(Stage, usize)>,
    spent: Vec<(Stage, Cost)>,
}

/// What discover and calibrate spend their evaluations on (report.json
/// `cost`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// The site's constants (step 0, after each effect, the final one).
    Calibration,
    /// Every candidate probed at one value on the current model.
    Screening,
    /// The candidates' fits.
    Fits,
    /// Held-out days and sites.
    CrossValidation,
    /// Refits of a chosen candidate: with the model's effects free, its
    /// threshold placed again, beside the constants, without each effect.
    Refits,
}

/// A stage's cost in report.json.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StageCost {
    pub stage: Stage,
    #[serde(flatten)]
    pub cost: Cost,
}

/// Leaves its stage when dropped (see [`CostMeter::enter`]).
pub(super) struct StageGuard<'m> {
    meter: &'m CostMeter,
}

impl Drop for StageGuard<'_> {
    fn drop(&mut self) {
        let mut lock = self.meter.lock();
        lock.entered = match lock.entered {
            Some((stage, holders)) if holders > 1 => Some((stage, holders - 1)),
            _ => None,
        };
    }
}

/// [`CostMeter`] at one moment; differences give a stage's cost.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Cost {
    /// Engine replays from the start.
    pub engine_runs: usize,
    /// Replays continued from a checkpoint.
    pub resumed_runs: usize,
    /// Evaluations read from a kept replay.
    pub readouts: usize,
    /// Replays with tangents: every measurement's derivatives in the state
    /// constants from one replay (`tortwin_model::tangent`).
    pub tangent_runs: usize,
    /// Replays, plus the read-outs', continued replays' and replays with
    /// tangents' time in replays (measured).
    pub run_equivalents: f64,
    #[serde(skip)]
    replay_ns: u64,
    #[serde(skip)]
    readout_ns: u64,
    #[serde(skip)]
    resumed_ns: u64,
    #[serde(skip)]
    tangent_ns: u64,
}

/// What one evaluation was, and its time.
#[derive(Debug, Clone, Copy)]
enum Spent {
    Replay(u64),
    Readout(u64),
    Resumed(u64),
    Tangents(u64),
}

impl CostMeter {
    fn lock(&self) -> std::sync::MutexGuard<'_, Stages> {
        self.stages.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// From now until the guard drops, evaluations count to `stage`,
    /// unless another stage runs: then they stay that stage's
    /// ([`Stages::entered`]).
    pub(super) fn enter(&self, stage: Stage) -> StageGuard<'_> {
        let mut lock = self.lock();
        lock.entered = Some(match lock.entered {
            Some((running, holders)) => (running, holders + 1),
            None => (stage, 1),
        });
        StageGuard { meter: self }
    }

    /// Adds one evaluation to the stage now running.
    fn add_to_stage(&self, spent: Spent) {
        let mut lock = self.lock();
        let stage = lock.entered.map_or(Stage::Fits, |(s, _)| s);
        let slot = match lock.spent.iter().position(|(s, _)| *s == stage) {
            Some(k) => k,
            None => {
                lock.spent.push((stage, Cost::default()));
                lock.spent.len() - 1
            }
        };
        let cost = &mut lock.spent[slot].1;
        let (count, total, ns) = match spent {
            Spent::Replay(ns) => (&mut cost.engine_runs, &mut cost.replay_ns, ns),
            Spent::Readout(ns) => (&mut cost.readouts, &mut cost.readout_ns, ns),
            Spent::Resumed(ns) => (&mut cost.resumed_runs, &mut cost.resumed_ns, ns),
            Spent::Tangents(ns) => (&mut cost.tangent_runs, &mut cost.tangent_ns, ns),
        };
        *count += 1;
        *total += ns;
    }

    fn add(&self, spent: Spent) {
        let (count, total, ns) = match spent {
            Spent::Replay(ns) => (&self.replays, &self.replay_ns, ns),
            Spent::Readout(ns) => (&self.readouts, &self.readout_ns, ns),
            Spent::Resumed(ns) => (&self.resumed, &self.resumed_ns, ns),
            Spent::Tangents(ns) => (&self.tangents, &self.tangent_ns, ns),
        };
        count.fetch_add(1, Ordering::Relaxed);
        total.fetch_add(ns, Ordering::Relaxed);
        self.add_to_stage(spent);
    }

    /// Each stage's cost so far, in run-equivalents of the mean replay of
    /// the whole run.
    pub(super) fn by_stage(&self) -> Vec<StageCost> {
        let per_replay = self.now().per_replay_ns();
        self.lock()
            .spent
            .iter()
            .map(|(stage, cost)| StageCost {
                stage: *stage,
                cost: cost.with_equivalents(per_replay),
            })
            .collect()
    }

    /// The totals so far.
    pub(super) fn now(&self) -> Cost {
        let c = Cost {
            engine_runs: self.replays.load(Ordering::Relaxed),
            resumed_runs: self.resumed.load(Ordering::Relaxed),
            readouts: self.readouts.load(Ordering::Relaxed),
            tangent_runs: self.tangents.load(Ordering::Relaxed),
            run_equivalents: 0.0,
            replay_ns: self.replay_ns.load(Ordering::Relaxed),
            readout_ns: self.readout_ns.load(Ordering::Relaxed),
            resumed_ns: self.resumed_ns.load(Ordering::Relaxed),
            tangent_ns: self.tangent_ns.load(Ordering::Relaxed),
        };
        c.with_equivalents(c.per_replay_ns())
    }
}

impl Cost {
    /// Replays plus the read-outs', continued replays' and replays with
    /// tangents' time in replays of `per_replay_ns`.
    fn with_equivalents(mut self, per_replay_ns: f64) -> Self {
        self.run_equivalents = self.engine_runs as f64
            + if per_replay_ns > 0.0 {
                (self.readout_ns + self.resumed_ns + self.tangent_ns) as f64 / per_replay_ns
            } else {
                0.0
            };
        self
    }

    /// The replay the run-equivalents are counted in: the mean time (ms)
    /// of the replays so far (`None` before the first).
    pub fn replay_ms(&self) -> Option<f64> {
        (self.engine_runs > 0).then(|| self.per_replay_ns() * 1e-6)
    }

    /// The mean replay's time so far.
    fn per_replay_ns(&self) -> f64 {
        self.replay_ns as f64 / self.engine_runs.max(1) as f64
    }
}

impl<'a> Evaluator<'a> {
    /// `active`: the rows that count (every row when empty).
    pub(super) fn new(data: &'a Dataset, active: Vec<bool>, progress: &'a dyn Progress) -> Self {
        let active = if active.len() == data.rows.len() {
            active
        } else {
            vec![true; data.rows.len()]
        };
        let day_slot = data
            .rows
            .iter()
            .map(|r| data.days.partition_point(|&d| d < r.day))
            .collect();
        let mut sites: Vec<usize> = data.rows.iter().map(|r| r.site).collect();
        sites.sort_unstable();
        sites.dedup();
        let site_slot = data
            .rows
            .iter()
            .map(|r| sites.partition_point(|&s| s < r.site))
            .collect();
        Self {
            data,
            day_slot,
            sites,
            site_slot,
            active,
            cache: Mutex::new(HashMap::new()),
            residuals: Default::default(),
            keep_residuals: (RESIDUALS_KEPT_BYTES
                / (data.rows.len().max(1) * std::mem::size_of::<f64>()))
            .max(2),
            readouts: Default::default(),
            bases: Default::default(),
            keep_readouts: (READOUTS_KEPT_BYTES
                / (data.rows.len().max(1) * std::mem::size_of::<Readout>()))
            .clamp(2, 64),
            calibrations: Default::default(),
            cost: CostMeter::default(),
            progress,
        }
    }

    /// The blocks of `blocking`, as labels.
    pub(super) fn blocks(&self, blocking: Blocking) -> Vec<String> {
        match blocking {
            Blocking::Day => self.data.days.iter().map(|d| format!("day {d}")).collect(),
            Blocking::Site => self
                .sites
                .iter()
                .map(|&s| self.data.site_name(s).to_string())
                .collect(),
        }
    }

    /// Engine runs so far (cache misses).
    pub(super) fn runs(&self) -> usize {
        self.cost.replays.load(Ordering::Relaxed)
    }

    /// The rows that count.
    pub(super) fn n_active(&self) -> usize {
        self.active.iter().filter(|a| **a).count()
    }

    /// Whether row `k` counts outside the block `excluded`.
    fn counts(&self, k: usize, excluded: Option<(Blocking, usize)>) -> bool {
        self.active[k]
            && match excluded {
                None => true,
                Some((Blocking::Day, j)) => self.day_slot[k] != j,
                Some((Blocking::Site, j)) => self.site_slot[k] != j,
            }
    }

    /// The rows that count outside the block `excluded`.
    pub(super) fn n_counted(&self, excluded: Option<(Blocking, usize)>) -> usize {
        (0..self.active.len())
            .filter(|&k| self.counts(k, excluded))
            .count()
    }

    /// The simulated value of every row with `cfg`: read from a kept
    /// replay of its state part when there is one, else one engine run
    /// (counted) whose read-outs are kept.
    pub(super) fn simulate(&self, cfg: &ModelConfig) -> Result<Vec<f64>> {
        let state = cfg.state_part();
        let bases: Vec<(Kept, Arc<super::data::Checkpoints>)> = lock_ignoring_poison(&self.bases)
            .iter()
            .rev()
            .cloned()
            .collect();
        let kept = bases
            .iter()
            .map(|(k, _)| k)
            .chain(self.kept().iter().rev())
            .find(|k| k.state == state)
            .map(|k| k.readouts.clone());
        if let Some(readouts) = kept {
            let start = std::time::Instant::now();
            let simulated = self.data.read_out(cfg, &readouts);
            self.cost
                .add(Spent::Readout(start.elapsed().as_nanos() as u64));
            return Ok(simulated);
        }
        tortwin_study::progress::check(self.progress)?;
        let start = std::time::Instant::now();
        for (base, checkpoints) in &bases {
            if let Some(readouts) = self.data.resume(&state, checkpoints, &base.readouts) {
                let readouts = readouts?;
                let simulated = self.data.read_out(cfg, &readouts);
                self.cost
                    .add(Spent::Resumed(start.elapsed().as_nanos() as u64));
                self.keep(state, readouts);
                return Ok(simulated);
            }
        }
        let (simulated, readouts) = self.data.simulate_with_readouts(cfg)?;
        self.cost
            .add(Spent::Replay(start.elapsed().as_nanos() as u64));
        self.keep(state, readouts);
        Ok(simulated)
    }

    /// Every row's simulated value with `cfg` and its derivatives in `ln p`
    /// of the state constants `keys` (one column per key), then in the
    /// effect parameters `effects` (one column each), from one replay with
    /// tangents ([`Dataset::simulate_with_tangents`]), counted at its
    /// measured time; its read-outs are kept.
    pub(super) fn sensitivities(
        &self,
        cfg: &ModelConfig,
        keys: &[tortwin_model::product::ProductKey],
        effects: &[tortwin_model::tangent::EffectParam],
    ) -> Result<(Vec<f64>, Vec<Vec<f64>>)> {
        tortwin_study::progress::check(self.progress)?;
        let start = std::time::Instant::now();
        let s = self.data.simulate_with_tangents(cfg, keys, effects)?;
        self.cost
            .add(Spent::Tangents(start.elapsed().as_nanos() as u64));
        self.keep(cfg.state_part(), s.readouts);
        Ok((s.simulated, s.columns))
    }

    /// Keeps `cfg`'s replay with checkpoints: the candidates built on it
    /// (a time step added to it) continue from its state before their
    /// step instead of replaying from the start. One replay, counted,
    /// unless it is kept already.
    pub(super) fn pin_base(&self, cfg: &ModelConfig) -> Result<()> {
        let state = cfg.state_part();
        {
            let mut bases = lock_ignoring_poison(&self.bases);
            if let Some(k) = bases.iter().position(|(b, _)| b.state == state) {
                if let Some(b) = bases.remove(k) {
                    bases.push_back(b);
                }
                return Ok(());
            }
        }
        tortwin_study::progress::check(self.progress)?;
        let start = std::time::Instant::now();
        let (_, readouts, checkpoints) = self.data.simulate_with_checkpoints(cfg, CHECKPOINTS)?;
        self.cost
            .add(Spent::Replay(start.elapsed().as_nanos() as u64));
        let mut bases = lock_ignoring_poison(&self.bases);
        if bases.len() >= BASES_KEPT {
            bases.pop_front();
        }
        bases.push_back((
            Kept {
                state,
                readouts: Arc::new(readouts),
            },
            Arc::new(checkpoints),
        ));
        Ok(())
    }

    /// The calibration asked for with `key` earlier, if it is kept.
    pub(super) fn calibrated(&self, key: &CalibrationKey) -> Option<Calibration> {
        lock_ignoring_poison(&self.calibrations)
            .iter()
            .find(|(k, _)| k == key)
            .map(|(_, c)| c.clone())
    }

    /// Keeps a calibration for [`Evaluator::calibrated`] (the oldest of
    /// [`CALIBRATIONS_KEPT`] goes first).
    pub(super) fn keep_calibration(&self, key: CalibrationKey, calibration: &Calibration) {
        let mut kept = lock_ignoring_poison(&self.calibrations);
        if kept.len() >= CALIBRATIONS_KEPT {
            kept.pop_front();
        }
        kept.push_back((key, calibration.clone()));
    }

    fn kept(&self) -> std::sync::MutexGuard<'_, std::collections::VecDeque<Kept>> {
        lock_ignoring_poison(&self.readouts)
    }

    /// Keeps a replay's read-outs in the bounded store (the oldest go
    /// first).
    fn keep(&self, state: ModelConfig, readouts: Vec<Readout>) {
        let mut lock = self.kept();
        if lock.len() >= self.keep_readouts {
            lock.pop_front();
        }
        lock.push_back(Kept {
            state,
            readouts: Arc::new(readouts),
        });
    }

    /// Residuals (measured − simulated) of `cfg` by one engine run, and
    /// their SSE over the active rows (cached for [`Evaluator::evaluate`]).
    pub(super) fn residuals(&self, cfg: &ModelConfig) -> Result<(Vec<f64>, Arc<Evaluation>)> {
        let key = cache_key(cfg);
        let kept = lock_ignoring_poison(&self.residuals)
            .iter()
            .find(|(k, _)| *k == key)
            .map(|(_, r)| r.clone());
        if let (Some(residual), Some(eval)) = (kept, self.lock().get(&key).cloned()) {
            return Ok((residual.as_ref().clone(), eval));
        }
        let simulated = self.simulate(cfg)?;
        let residual: Vec<f64> = self
            .data
            .rows
            .iter()
            .zip(&simulated)
            .map(|(r, s)| r.measured - s)
            .collect();
        let mut sse_by_day = vec![0.0; self.data.days.len()];
        let mut sse_by_site = vec![0.0; self.sites.len()];
        for (((r, &d), &s), _) in residual
            .iter()
            .zip(&self.day_slot)
            .zip(&self.site_slot)
            .zip(&self.active)
            .filter(|(_, &a)| a)
        {
            sse_by_day[d] += r * r;
            sse_by_site[s] += r * r;
        }
        let eval = Arc::new(Evaluation {
            sse: sse_by_day.iter().sum(),
            sse_by_day,
            sse_by_site,
        });
        self.lock().insert(key.clone(), eval.clone());
        let mut kept = lock_ignoring_poison(&self.residuals);
        if kept.len() >= self.keep_residuals {
            kept.pop_front();
        }
        kept.push_back((key, Arc::new(residual.clone())));
        Ok((residual, eval))
    }

    /// SSE of `cfg` in total and per day; cached by the exact parameters.
    pub(super) fn evaluate(&self, cfg: &ModelConfig) -> Result<Arc<Evaluation>> {
        Ok(self.evaluate_counted(cfg)?.0)
    }

    /// [`Evaluator::evaluate`], and whether it ran the engine (a cache miss).
    pub(super) fn evaluate_counted(&self, cfg: &ModelConfig) -> Result<(Arc<Evaluation>, bool)> {
        if let Some(hit) = self.lock().get(&cache_key(cfg)) {
            return Ok((hit.clone(), false));
        }
        Ok((self.residuals(cfg)?.1, true))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<Vec<u64>, Arc<Evaluation>>> {
        // A panic while holding the lock leaves a consistent map.
        self.cache.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A lock whose data stays consistent when a holder panicked.
fn lock_ignoring_poison<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// The exact parameters a fit or a calibration varies, as bits: the
/// product constants and the effects'. Parameters that cannot matter are
/// keyed as 0: the reservoir's `r` when `alpha` = 0 (nothing is ever
/// parked).
fn cache_key(cfg: &ModelConfig) -> Vec<u64> {
    let mut key = Vec::with_capacity(32);
    key.extend(
        tortwin_model::product::ProductKey::ALL
            .iter()
            .map(|k| k.get(&cfg.product).to_bits()),
    );
    for c in Candidate::all() {
        match c.get(&cfg.effects) {
            None => key.push(0),
            Some(mut p) => {
                if c == Candidate::Named(Named::WheelEdgeReservoir) && p.first() == Some(&0.0) {
                    p[1] = 0.0;
                }
                key.push(1);
                key.extend(p.iter().map(|v| v.to_bits()));
            }
        }
    }
    // Generic terms: their whole text (Debug prints every f64 exactly).
    for term in &cfg.effects.generic {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        format!("{term:?}").hash(&mut h);
        key.push(h.finish());
    }
    key
}

/// The result of a fit.
#[derive(Debug, Clone)]
pub(super) struct Fit {
    /// The optimum's search coordinates.
    pub(super) u: Vec<f64>,
    pub(super) eval: Arc<Evaluation>,
    /// Engine runs the fit cost (cache misses).
    pub(super) runs: usize,
    /// A fit stopped after its first look ([`first_look`]): the least SSE
    /// it could still reach, optimistically; `None` for a fit run to its
    /// end.
    pub(super) stopped: Option<f64>,
}

/// How a fit starts.
#[derive(Debug, Clone)]
pub(super) enum Start {
    /// A coarse grid over the whole box first.
    Fresh,
    /// From these coordinates (an earlier optimum).
    Warm(Vec<f64>),
}

/// The objective of one fit: SSE of `space` at `u`, all blocks but
/// `excluded`. Errors of the engine are kept (the optimisers cannot carry
/// them) and the point costs +inf.
struct Objective<'e, 'a> {
    ev: &'e Evaluator<'a>,
    space: &'e Space,
    excluded: Option<(Blocking, usize)>,
    error: Mutex<Option<Error>>,
    /// Every point evaluated: (u clamped, eval).
    seen: Mutex<Vec<(Vec<f64>, Arc<Evaluation>)>>,
    /// Engine runs this objective caused (cache misses).
    runs: AtomicUsize,
    /// At most this many engine runs ([`look_further`]): an evaluation
    /// that would need one more is not made, and the fit ends where it is.
    budget: Option<usize>,
    /// The budget stopped an evaluation.
    exhausted: std::sync::atomic::AtomicBool,
    /// With a budget: the residuals of every point of a line search, for
    /// the promise of what is left ([`secant_promise`]).
    line_points: Mutex<Vec<(f64, f64, Vec<f64>)>>,
    /// With a budget: what the Gauss–Newton step of Levenberg–Marquardt's
    /// latest Jacobian promised from its latest point.
    lm_promise: Mutex<Option<f64>>,
}

impl<'e, 'a> Objective<'e, 'a> {
    fn new(
        ev: &'e Evaluator<'a>,
        space: &'e Space,
        excluded: Option<(Blocking, usize)>,
        budget: Option<usize>,
    ) -> Self {
        Objective {
            ev,
            space,
            excluded,
            error: Mutex::new(None),
            seen: Mutex::new(Vec::new()),
            runs: AtomicUsize::new(0),
            budget,
            exhausted: std::sync::atomic::AtomicBool::new(false),
            line_points: Mutex::new(Vec::new()),
            lm_promise: Mutex::new(None),
        }
    }

    /// Whether evaluating `cfg` would exceed the budget (it needs an
    /// engine run and the budget is spent); marks the objective exhausted.
    fn over_budget(&self, cfg: &ModelConfig) -> bool {
        let Some(budget) = self.budget else {
            return false;
        };
        if self.runs.load(Ordering::Relaxed) < budget
            || self.ev.lock().contains_key(&cache_key(cfg))
        {
            return false;
        }
        self.exhausted.store(true, Ordering::Relaxed);
        true
    }

    fn eval(&self, u: &[f64]) -> Option<Arc<Evaluation>> {
        let u: Vec<f64> = u.iter().map(|x| x.clamp(0.0, 1.0)).collect();
        let cfg = self.space.config(&u);
        if self.over_budget(&cfg) {
            return None;
        }
        match self.ev.evaluate_counted(&cfg) {
            Ok((e, ran)) => {
                if ran {
                    self.runs.fetch_add(1, Ordering::Relaxed);
                }
                self.seen
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .push((u, e.clone()));
                Some(e)
            }
            Err(err) => {
                let mut slot = self.error.lock().unwrap_or_else(|e| e.into_inner());
                slot.get_or_insert(err);
                None
            }
        }
    }

    /// The SSE at `u` (in the box) and the residuals of the rows it
    /// counts (active, not held out), recorded like [`Objective::eval`].
    /// The residuals come from a kept replay's read-outs where there is one
    /// ([`Evaluator::simulate`]).
    fn residual_at(&self, u: &[f64]) -> Option<(f64, Vec<f64>)> {
        let cfg = self.space.config(u);
        if self.over_budget(&cfg) {
            return None;
        }
        let cached = self.ev.lock().contains_key(&cache_key(&cfg));
        match self.ev.residuals(&cfg) {
            Ok((residual, e)) => {
                if !cached {
                    self.runs.fetch_add(1, Ordering::Relaxed);
                }
                self.seen
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .push((u.to_vec(), e.clone()));
                let counted: Vec<f64> = residual
                    .iter()
                    .enumerate()
                    .filter(|&(k, _)| self.counts(k))
                    .map(|(_, r)| *r)
                    .collect();
                let sse = e.sse_without(self.excluded);
                if self.budget.is_some() && u.len() == 1 {
                    self.line_points
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .push((u[0], sse, counted.clone()));
                }
                Some((sse, counted))
            }
            Err(err) => {
                let mut slot = self.error.lock().unwrap_or_else(|e| e.into_inner());
                slot.get_or_insert(err);
                None
            }
        }
    }

    /// Whether row `k` counts in this objective's SSE.
    fn counts(&self, k: usize) -> bool {
        self.ev.counts(k, self.excluded)
    }

    /// The SSE at `u` projected onto the box: outside it the objective is
    /// flat, so a simplex that leaves the box towards an optimum on its
    /// boundary (an effect switched off) stops there.
    fn cost_at(&self, u: &[f64]) -> f64 {
        match self.eval(u) {
            Some(e) => e.sse_without(self.excluded),
            None => f64::INFINITY,
        }
    }

    fn best(&self) -> Option<(Vec<f64>, Arc<Evaluation>)> {
        self.seen
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .min_by(|a, b| {
                a.1.sse_without(self.excluded)
                    .total_cmp(&b.1.sse_without(self.excluded))
            })
            .cloned()
    }

    fn take_error(&self) -> Result<()> {
        match self.error.lock().unwrap_or_else(|e| e.into_inner()).take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

/// Points of the coarse grid per dimension (1-D: both ends included,
/// a spacing of 0.25; the two points halfway beside its best follow, so
/// that the line search starts on a spacing of 0.125 as from a grid of
/// nine, for seven evaluations instead of nine, and five where the best
/// is on a bound or the objective is flat).
const GRID_1D: usize = 5;
/// Points per dimension of a fit of several parameters from nothing (the
/// centres of 3 × 3 cells for two: Levenberg–Marquardt goes on from the
/// best).
const GRID_ND: usize = 3;
/// A line search's smallest step in `u` (the optimum to about 1e-4 of the
/// range).
const LINE_TOL: f64 = 1e-4;
/// The line search's first secant step, as a share of its bracket.
const LINE_FIRST_STEP: f64 = 0.1;
/// Its steps at most, and steps in a row that may fail to lower the SSE.
const LINE_MAX_STEPS: usize = 20;
const LINE_MAX_MISSES: usize = 3;
/// Levenberg–Marquardt's damping: at the start, its bounds, the floor of
/// the scaling diagonal (a share of its largest entry), and failed steps
/// in a row before it stops.
const LM_LAMBDA0: f64 = 1e-3;
const LM_LAMBDA_MIN: f64 = 1e-9;
const LM_LAMBDA_MAX: f64 = 1e9;
const LM_DIAG_FLOOR: f64 = 1e-9;
const LM_MAX_MISSES: usize = 4;
/// A search stops once what is left to gain is below this share of the
/// SSE (the residuals' linear model says so, or the grid is that flat):
/// the rest would move the BIC by less than n × 1e-6 (0.015 for 15 000
/// measurements) and the parameters by a small fraction of their
/// statistical uncertainty.
const FLAT_REL: f64 = 1e-6;
/// The first differences' step of a fit of several parameters from the
/// best point of the coarse grid (a tenth of its spacing).
const FRESH_STEP: f64 = 0.1 / GRID_ND as f64;
/// An optimum found on a bound of `u` is checked this far inwards.
const BOUND_PROBE: f64 = 0.005;
/// How much more than its local model promises a fit stopped after its
/// first look ([`first_look`]) is taken to be able to gain still: the
/// secant and the parabola are first-order guides, and a candidate is
/// only left where even this much would not bring it near the best.
pub(super) const OPTIMISM: f64 = 8.0;

/// How far a warm start looks, and how long a fit of several parameters
/// may run.
#[derive(Debug, Clone, Copy)]
struct Limits {
    /// Half width of the line search's bracket around a warm start.
    warm_half_width: f64,
    /// The first differences' step of a warm-started fit of several
    /// parameters.
    warm_step: f64,
    /// Its Levenberg–Marquardt steps at most.
    max_steps: usize,
}

const FULL: Limits = Limits {
    warm_half_width: 0.15,
    warm_step: 0.03,
    max_steps: 30,
};
/// A cross-validation fold leaves out a third of the data or less: its
/// optimum is usually close to the full-data one, where it starts.
const FOLD: Limits = Limits {
    warm_half_width: 0.04,
    warm_step: 0.01,
    max_steps: 6,
};

/// Fits `space` on every block but `excluded`.
pub(super) fn fit(
    ev: &Evaluator<'_>,
    space: &Space,
    start: Start,
    excluded: Option<(Blocking, usize)>,
) -> Result<Fit> {
    fit_with(ev, space, start, excluded, FULL)
}

/// [`fit`] with fewer Levenberg–Marquardt steps: a cross-validation fold,
/// warm-started next to its optimum.
fn fit_limited(
    ev: &Evaluator<'_>,
    space: &Space,
    start: Start,
    excluded: Option<(Blocking, usize)>,
) -> Result<Fit> {
    fit_with(ev, space, start, excluded, FOLD)
}

fn fit_with(
    ev: &Evaluator<'_>,
    space: &Space,
    start: Start,
    excluded: Option<(Blocking, usize)>,
    limits: Limits,
) -> Result<Fit> {
    let obj = Objective::new(ev, space, excluded, None);
    run_fit(&obj, start, limits)?;
    finish(&obj)
}

/// The search of [`fit_with`] on `obj`, from `start`.
fn run_fit(obj: &Objective<'_, '_>, start: Start, limits: Limits) -> Result<()> {
    let dims = obj.space.dims();
    if dims == 0 {
        obj.cost_at(&[]);
    } else if dims == 1 {
        let bracket = match &start {
            // An earlier optimum on a bound says little about the new one.
            Start::Warm(u) if u.iter().all(|&x| x > BOUND_PROBE && x < 1.0 - BOUND_PROBE) => {
                let u0 = u.first().copied().unwrap_or(0.5);
                Some((
                    u0,
                    (u0 - limits.warm_half_width).max(0.0),
                    (u0 + limits.warm_half_width).min(1.0),
                ))
            }
            Start::Warm(_) | Start::Fresh => None,
        };
        let mut done = false;
        if let Some((u0, lo, hi)) = bracket {
            let edge = 3.0 * LINE_TOL + 1e-3;
            let inner_edge = |u: f64, lo: f64, hi: f64| {
                (u - lo < edge && lo > 0.0) || (hi - u < edge && hi < 1.0)
            };
            let u = line_search(obj, u0, lo, hi)?;
            done = !inner_edge(u, lo, hi);
            // On an inner edge of the bracket: the optimum has moved away.
            // Once more from there, in a bracket twice as wide (three or
            // four evaluations); the grid where it moved further still.
            if !done {
                let wide = 2.0 * limits.warm_half_width;
                let (lo, hi) = ((u - wide).max(0.0), (u + wide).min(1.0));
                let u = line_search(obj, u, lo, hi)?;
                done = !inner_edge(u, lo, hi);
            }
        }
        if !done {
            let g = coarse_grid(obj)?;
            if let Some(mids) = g.mids(obj)? {
                // The line search within half a spacing of the best of
                // the grid and the mids.
                let (mut u, mut at_u) = (g.grid[g.best], g.costs[g.best]);
                for &(m, c) in &mids {
                    if c < at_u {
                        (u, at_u) = (m, c);
                    }
                }
                let half = 0.5 / (GRID_1D - 1) as f64;
                line_search(obj, u, (u - half).max(0.0), (u + half).min(1.0))?;
            }
        }
    } else {
        let (u0, step) = match &start {
            Start::Warm(u) => (u.clone(), limits.warm_step),
            Start::Fresh => {
                let grid = grid_points(dims, GRID_ND);
                let costs: Vec<f64> = grid.par_iter().map(|u| obj.cost_at(u)).collect();
                obj.take_error()?;
                let best = (0..grid.len())
                    .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
                    .unwrap_or(0);
                (grid[best].clone(), FRESH_STEP)
            }
        };
        levenberg_marquardt(obj, &u0, step, limits.max_steps)?;
    }
    Ok(())
}

fn finish(obj: &Objective<'_, '_>) -> Result<Fit> {
    obj.take_error()?;
    let (u, eval) = obj.best().ok_or(Error::NoFitPoint)?;
    Ok(Fit {
        u,
        eval,
        runs: obj.runs.load(Ordering::Relaxed),
        stopped: None,
    })
}

/// [`fit`] from `start` for at most `budget` more engine runs (the
/// evaluations made before, by a look or an earlier call, come from the
/// cache): `Done` where the fit ends within them, else the best point so
/// far and the least SSE the rest could reach, optimistically
/// ([`OPTIMISM`] times the promise of the line search's latest secant,
/// [`secant_promise`], or for several parameters of the Gauss–Newton step
/// of Levenberg–Marquardt's latest Jacobian).
pub(super) fn look_further(
    ev: &Evaluator<'_>,
    space: &Space,
    start: &Start,
    budget: usize,
) -> Result<Look> {
    if space.dims() == 0 {
        return fit(ev, space, start.clone(), None).map(Look::Done);
    }
    let obj = Objective::new(ev, space, None, Some(budget));
    run_fit(&obj, start.clone(), FULL)?;
    let fit = finish(&obj)?;
    if !obj.exhausted.load(Ordering::Relaxed) {
        return Ok(Look::Done(fit));
    }
    let promised = if space.dims() == 1 {
        secant_promise(&obj.line_points.lock().unwrap_or_else(|e| e.into_inner()))
    } else {
        *obj.lm_promise.lock().unwrap_or_else(|e| e.into_inner())
    };
    let optimistic = promised.map_or(0.0, |promised| fit.eval.sse - OPTIMISM * promised);
    Ok(Look::Open(fit, optimistic.max(0.0)))
}

/// What the residuals' secant between the best of `points` (u, SSE,
/// residuals) and the one nearest to it promises still: the fall of the
/// SSE to the minimum of their linear model (`(J·r)² / (J·J)`); `None`
/// with fewer than two points or a secant that says nothing.
fn secant_promise(points: &[(f64, f64, Vec<f64>)]) -> Option<f64> {
    let best = points.iter().min_by(|a, b| a.1.total_cmp(&b.1))?;
    let other = points
        .iter()
        .filter(|p| (p.0 - best.0).abs() >= LINE_TOL)
        .min_by(|a, b| (a.0 - best.0).abs().total_cmp(&(b.0 - best.0).abs()))?;
    let du = other.0 - best.0;
    let (mut jj, mut g) = (0.0, 0.0);
    for (o, b) in other.2.iter().zip(&best.2) {
        let j = (o - b) / du;
        jj += j * j;
        g += j * b;
    }
    let promised = g * g / jj;
    (jj > 0.0 && promised.is_finite()).then_some(promised)
}

/// What a candidate's first evaluations say ([`first_look`]).
pub(super) enum Look {
    /// The fit ran to its end (nothing to gain from stopping it early).
    Done(Fit),
    /// The fit's best point so far, and the least SSE its continuation
    /// could reach, optimistically ([`OPTIMISM`] times what the residuals'
    /// or the SSE's local model still promises).
    Open(Fit, f64),
}

/// The evaluations [`fit`] begins with, without the rest: for a warm
/// start inside the box the line search's first two points (the start
/// and its first secant step), for a fresh one the grid and the two
/// points halfway beside its best; then the least SSE the rest of the
/// search could reach, optimistically. A candidate that cannot come near
/// the best of its step is then left there (discover's `fit_each`); one
/// that can is fitted by [`fit`] from the same start, which finds these
/// evaluations in the cache. A fit of no or of several parameters, and
/// one whose best grid point lies on a bound (one probe inwards decides
/// it), runs to its end here.
pub(super) fn first_look(ev: &Evaluator<'_>, space: &Space, start: &Start) -> Result<Look> {
    if space.dims() == 0 {
        return fit(ev, space, start.clone(), None).map(Look::Done);
    }
    let obj = Objective::new(ev, space, None, None);
    let limits = FULL;
    let optimistic = match start {
        _ if space.dims() > 1 => {
            let (u0, step) = match start {
                Start::Warm(u) => (u.clone(), limits.warm_step),
                Start::Fresh => {
                    let grid = grid_points(space.dims(), GRID_ND);
                    let costs: Vec<f64> = grid.par_iter().map(|u| obj.cost_at(u)).collect();
                    obj.take_error()?;
                    let best = (0..grid.len())
                        .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
                        .unwrap_or(0);
                    (grid[best].clone(), FRESH_STEP)
                }
            };
            match gauss_newton_promise(&obj, &u0, step)? {
                Some((sse, promised)) => sse - OPTIMISM * promised,
                None => return fit(ev, space, start.clone(), None).map(Look::Done),
            }
        }
        Start::Warm(u) if u.iter().all(|&x| x > BOUND_PROBE && x < 1.0 - BOUND_PROBE) => {
            let u0 = u.first().copied().unwrap_or(0.5);
            let (lo, hi) = (
                (u0 - limits.warm_half_width).max(0.0),
                (u0 + limits.warm_half_width).min(1.0),
            );
            let first = u0.clamp(lo, hi);
            let Some(u1) = first_secant_point(first, lo, hi).map(|u| u.clamp(lo, hi)) else {
                return fit(ev, space, start.clone(), None).map(Look::Done);
            };
            let (a, b) = (obj.residual_at(&[first]), obj.residual_at(&[u1]));
            obj.take_error()?;
            let (Some((sse_a, r_a)), Some((sse_b, r_b))) = (a, b) else {
                return fit(ev, space, start.clone(), None).map(Look::Done);
            };
            // The secant's promise from the better of the two points.
            let du = u1 - first;
            let best = if sse_b < sse_a { &r_b } else { &r_a };
            let (mut jj, mut g) = (0.0, 0.0);
            for ((x, y), r) in r_b.iter().zip(&r_a).zip(best) {
                let j = (x - y) / du;
                jj += j * j;
                g += j * r;
            }
            let promised = if jj > 0.0 { g * g / jj } else { 0.0 };
            if !promised.is_finite() {
                return fit(ev, space, start.clone(), None).map(Look::Done);
            }
            sse_a.min(sse_b) - OPTIMISM * promised
        }
        Start::Warm(_) | Start::Fresh => {
            let g = coarse_grid(&obj)?;
            let Some(mids) = g.mids(&obj)? else {
                return fit(ev, space, start.clone(), None).map(Look::Done);
            };
            let (grid, costs, best, probed) = (&g.grid, &g.costs, g.best, g.probed);
            // The parabola through the best of these (the grid, the mids)
            // and its neighbours half a spacing away, or at an end the
            // next two inwards; its least value within them.
            let mut points: Vec<(f64, f64)> =
                grid.iter().copied().zip(costs.iter().copied()).collect();
            points.extend(mids);
            points.sort_by(|a, b| a.0.total_cmp(&b.0));
            let Some(k) = (0..points.len()).min_by(|&a, &b| points[a].1.total_cmp(&points[b].1))
            else {
                return fit(ev, space, start.clone(), None).map(Look::Done);
            };
            let three = match k {
                0 => 0,
                k if k + 1 == points.len() => k - 2,
                k => k - 1,
            };
            if points.len() < 3 || points.iter().any(|p| !p.1.is_finite()) {
                return fit(ev, space, start.clone(), None).map(Look::Done);
            }
            let ((u0, f0), (u1, f1), (u2, f2)) =
                (points[three], points[three + 1], points[three + 2]);
            // Divided differences: the curvature, and the vertex.
            let (s01, s12) = ((f1 - f0) / (u1 - u0), (f2 - f1) / (u2 - u1));
            let curvature = 2.0 * (s12 - s01) / (u2 - u0);
            if !(curvature > 0.0 && curvature.is_finite()) {
                return fit(ev, space, start.clone(), None).map(Look::Done);
            }
            let vertex = (0.5 * (u0 + u1) - s01 / curvature).clamp(u0, u2);
            let at = |u: f64| f0 + s01 * (u - u0) + 0.5 * curvature * (u - u0) * (u - u1);
            let (_, f_best) = points[k];
            // At an end, the probe inwards gained already: at least that.
            let gained = (f_best - at(vertex)).max(0.0);
            let probe_gain = probed.map_or(0.0, |p| (costs[best] - p).max(0.0));
            f_best.min(probed.unwrap_or(f64::INFINITY)) - OPTIMISM * gained.max(probe_gain)
        }
    };
    obj.take_error()?;
    let (u, eval) = obj.best().ok_or(Error::NoFitPoint)?;
    let fit = Fit {
        u,
        eval,
        runs: obj.runs.load(Ordering::Relaxed),
        stopped: None,
    };
    Ok(Look::Open(fit, optimistic.max(0.0)))
}

/// A fit of one parameter's coarse grid ([`GRID_1D`] points, both ends
/// included: several effects are off, or nearly, at an end, and an
/// optimum there is found at once), evaluated in parallel.
struct CoarseGrid {
    grid: Vec<f64>,
    costs: Vec<f64>,
    best: usize,
    /// The SSE one step inwards from the best point where that is an end
    /// of a grid that is not flat.
    probed: Option<f64>,
    /// Nothing to refine: the grid is flat (an effect the recording
    /// cannot show, e.g. rain wash-off without rain), or its best point is
    /// an end and one step inwards is no better (a search would creep
    /// towards the bound for many evaluations).
    settled: bool,
}

fn coarse_grid(obj: &Objective<'_, '_>) -> Result<CoarseGrid> {
    let grid: Vec<f64> = (0..GRID_1D)
        .map(|i| i as f64 / (GRID_1D - 1) as f64)
        .collect();
    let costs: Vec<f64> = grid.par_iter().map(|&u| obj.cost_at(&[u])).collect();
    obj.take_error()?;
    let best = (0..GRID_1D)
        .min_by(|&a, &b| costs[a].total_cmp(&costs[b]))
        .unwrap_or(0);
    let worst = costs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let flat = worst - costs[best] <= FLAT_REL * costs[best].abs();
    let at_end = best == 0 || best + 1 == GRID_1D;
    let probed = if at_end && !flat {
        let u = if best == 0 {
            BOUND_PROBE
        } else {
            1.0 - BOUND_PROBE
        };
        let probe = obj.cost_at(&[u]);
        obj.take_error()?;
        Some(probe)
    } else {
        None
    };
    let settled = flat || probed.is_some_and(|p| p >= costs[best]);
    Ok(CoarseGrid {
        grid,
        costs,
        best,
        probed,
        settled,
    })
}

impl CoarseGrid {
    /// The points halfway to the best point's neighbours (one at an
    /// end), evaluated: (u, SSE); `None` where the grid is settled.
    fn mids(&self, obj: &Objective<'_, '_>) -> Result<Option<Vec<(f64, f64)>>> {
        if self.settled {
            return Ok(None);
        }
        let half = 0.5 / (GRID_1D - 1) as f64;
        let mids: Vec<f64> = [self.grid[self.best] - half, self.grid[self.best] + half]
            .into_iter()
            .filter(|u| (0.0..=1.0).contains(u))
            .collect();
        let costs: Vec<f64> = mids.par_iter().map(|&u| obj.cost_at(&[u])).collect();
        obj.take_error()?;
        Ok(Some(mids.into_iter().zip(costs).collect()))
    }
}

/// What [`levenberg_marquardt`] from `u0` begins with (the residuals
/// there and the forward differences of `step`, inwards at a bound),
/// and what the Gauss–Newton step of that Jacobian promises: the SSE at
/// `u0` and its predicted fall; `None` where the point or the Jacobian
/// says nothing.
fn gauss_newton_promise(
    obj: &Objective<'_, '_>,
    u0: &[f64],
    step: f64,
) -> Result<Option<(f64, f64)>> {
    use nalgebra::{DMatrix, DVector};
    let u: Vec<f64> = u0.iter().map(|x| x.clamp(0.0, 1.0)).collect();
    let Some((sse, r)) = obj.residual_at(&u) else {
        return obj.take_error().map(|()| None);
    };
    type Probe = (f64, Option<(f64, Vec<f64>)>);
    let probes: Vec<Probe> = (0..u.len())
        .into_par_iter()
        .map(|i| {
            let mut v = u.clone();
            let h = if u[i] + step <= 1.0 { step } else { -step };
            v[i] += h;
            (h, obj.residual_at(&v))
        })
        .collect();
    obj.take_error()?;
    let r = DVector::from_vec(r);
    let mut jac = DMatrix::<f64>::zeros(r.len(), u.len());
    for (i, (h, probe)) in probes.into_iter().enumerate() {
        let Some((_, ri)) = probe else {
            return Ok(None);
        };
        jac.set_column(i, &((DVector::from_vec(ri) - &r) / h));
    }
    let jtj = jac.transpose() * &jac;
    let g = jac.transpose() * &r;
    let promised = jtj
        .cholesky()
        .map(|c| g.dot(&c.solve(&g)))
        .filter(|p| p.is_finite() && *p >= 0.0);
    Ok(promised.map(|p| (sse, p)))
}

/// The line search's first secant step from `u` in `[lo, hi]`: a short
/// step into the bracket's wider side; `None` when the bracket is too
/// narrow for one.
fn first_secant_point(u: f64, lo: f64, hi: f64) -> Option<f64> {
    let h = (LINE_FIRST_STEP * (hi - lo)).max(2.0 * LINE_TOL);
    let u1 = if hi - u >= u - lo { u + h } else { u - h };
    ((u1.clamp(lo, hi) - u).abs() >= LINE_TOL).then_some(u1)
}

/// A point of [`line_search`]: where, its SSE and the residuals it counts.
struct LinePoint {
    u: f64,
    sse: f64,
    residual: Vec<f64>,
}

/// Minimises the SSE along one coordinate in `[lo, hi]`, from `u0`, by
/// Gauss–Newton steps on the residual vector: the residuals' derivative
/// is the secant through the best point and the latest other one (1-D
/// Broyden), the step `-(J·r) / (J·J)` goes to the minimum of the
/// residuals' linear model, clamped into the bracket. A step that does
/// not lower the SSE still gives the secant its curvature, and the next
/// step is shorter. It stops when the linear model promises less than
/// [`FLAT_REL`] of the SSE (the same flatness at which the grid and
/// Nelder–Mead stop), when a step would move `u` by less than
/// [`LINE_TOL`], or when the SSE does not change along the coordinate.
/// Where the model is smooth that takes three to five evaluations, where
/// a parabola through SSEs alone (Brent) took eight to twelve.
fn line_search(obj: &Objective<'_, '_>, u0: f64, lo: f64, hi: f64) -> Result<f64> {
    let point = |u: f64| -> Result<Option<LinePoint>> {
        let u = u.clamp(lo, hi);
        match obj.residual_at(&[u]) {
            Some((sse, residual)) => Ok(Some(LinePoint { u, sse, residual })),
            None => obj.take_error().map(|()| None),
        }
    };
    let Some(first) = point(u0)? else {
        return Ok(u0);
    };
    // The first secant: a short step into the bracket's wider side.
    let Some(u1) = first_secant_point(first.u, lo, hi) else {
        return Ok(first.u);
    };
    let Some(second) = point(u1)? else {
        return Ok(first.u);
    };
    let (mut best, mut other) = if second.sse < first.sse {
        (second, first)
    } else {
        (first, second)
    };
    let mut misses = 0;
    for _ in 0..LINE_MAX_STEPS {
        let du = other.u - best.u;
        let slope: Vec<f64> = other
            .residual
            .iter()
            .zip(&best.residual)
            .map(|(o, b)| (o - b) / du)
            .collect();
        let jj: f64 = slope.iter().map(|j| j * j).sum();
        let g: f64 = slope.iter().zip(&best.residual).map(|(j, r)| j * r).sum();
        if !(jj > 0.0 && jj.is_finite() && g.is_finite()) {
            break;
        }
        if g * g / jj <= FLAT_REL * best.sse.abs() {
            break;
        }
        let next = (best.u - g / jj).clamp(lo, hi);
        if (next - best.u).abs() < LINE_TOL {
            break;
        }
        let Some(p) = point(next)? else {
            break;
        };
        if p.sse < best.sse {
            other = std::mem::replace(&mut best, p);
            misses = 0;
        } else {
            other = p;
            misses += 1;
            if misses == LINE_MAX_MISSES {
                break;
            }
        }
    }
    Ok(best.u)
}

/// Minimises the SSE over several coordinates in the unit box from `u0`
/// by Levenberg–Marquardt on the residual vector: the Jacobian by forward
/// differences of `step` (one replay per coordinate, in parallel), then
/// kept current by Broyden's rank-one update from every point tried
/// (no more differences), a step solving `(JᵀJ + λ D) δ = −Jᵀr` with `D`
/// the diagonal of `JᵀJ` (floored, so that a coordinate the SSE does not
/// see stays put), projected onto the box. λ shrinks after a step that
/// lowers the SSE and grows after one that does not. It stops when the
/// linear model promises less than [`FLAT_REL`] of the SSE, when a step
/// moves no coordinate by [`LINE_TOL`], after [`LM_MAX_MISSES`] steps in a
/// row that fail, or after `max_steps`.
fn levenberg_marquardt(
    obj: &Objective<'_, '_>,
    u0: &[f64],
    step: f64,
    max_steps: usize,
) -> Result<()> {
    use nalgebra::{DMatrix, DVector};
    let d = u0.len();
    type Point = Option<(f64, DVector<f64>)>;
    let at = |u: &[f64]| -> Result<Point> {
        match obj.residual_at(u) {
            Some((sse, r)) => Ok(Some((sse, DVector::from_vec(r)))),
            None => obj.take_error().map(|()| None),
        }
    };
    let mut u: Vec<f64> = u0.iter().map(|x| x.clamp(0.0, 1.0)).collect();
    let Some((mut sse, mut r)) = at(&u)? else {
        return Ok(());
    };
    // Forward differences, inwards where the step would leave the box.
    let probes: Vec<(f64, Point)> = (0..d)
        .into_par_iter()
        .map(|i| {
            let mut v = u.clone();
            let h = if u[i] + step <= 1.0 { step } else { -step };
            v[i] += h;
            Ok((h, at(&v)?))
        })
        .collect::<Result<_>>()?;
    let mut jac = DMatrix::<f64>::zeros(r.len(), d);
    for (i, (h, probe)) in probes.iter().enumerate() {
        let Some((_, ri)) = probe else {
            return Ok(());
        };
        jac.set_column(i, &((ri - &r) / *h));
    }
    // (A difference point better than the start counts as the fit's result
    // through the objective's best point, whatever the steps do.)
    let mut lambda = LM_LAMBDA0;
    let mut misses = 0;
    for _ in 0..max_steps {
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * &r;
        if obj.budget.is_some() {
            let full = jtj
                .clone()
                .cholesky()
                .map(|c| g.dot(&c.solve(&g)))
                .filter(|p| p.is_finite() && *p >= 0.0);
            *obj.lm_promise.lock().unwrap_or_else(|e| e.into_inner()) = full;
        }
        let floor = LM_DIAG_FLOOR * jtj.diagonal().max().max(f64::MIN_POSITIVE);
        let delta = loop {
            let mut a = jtj.clone();
            for i in 0..d {
                a[(i, i)] += lambda * jtj[(i, i)].max(floor);
            }
            match a.cholesky() {
                Some(c) => break Some(-c.solve(&g)),
                None if lambda < LM_LAMBDA_MAX => lambda *= 10.0,
                None => break None,
            }
        };
        let Some(delta) = delta.filter(|x| x.iter().all(|v| v.is_finite())) else {
            break;
        };
        let next: Vec<f64> = u
            .iter()
            .zip(delta.iter())
            .map(|(x, dx)| (x + dx).clamp(0.0, 1.0))
            .collect();
        let moved = DVector::from_iterator(d, next.iter().zip(&u).map(|(a, b)| a - b));
        if moved.amax() < LINE_TOL {
            break;
        }
        // What the linear model promises for the step as projected.
        let promised = -(2.0 * g.dot(&moved) + (&jac * &moved).norm_squared());
        if promised.is_nan() || promised <= FLAT_REL * sse.abs() {
            break;
        }
        let Some((sse_next, r_next)) = at(&next)? else {
            break;
        };
        // Broyden: the secant along the step holds for the new Jacobian.
        let miss = &r_next - &r - &jac * &moved;
        jac += miss * moved.transpose() / moved.norm_squared();
        if sse_next < sse {
            u = next;
            sse = sse_next;
            r = r_next;
            lambda = (lambda / 3.0).max(LM_LAMBDA_MIN);
            misses = 0;
        } else {
            lambda *= 4.0;
            misses += 1;
            if misses == LM_MAX_MISSES {
                break;
            }
        }
    }
    Ok(())
}

/// The centres of a `per_dim`^dims grid over the unit box.
fn grid_points(dims: usize, per_dim: usize) -> Vec<Vec<f64>> {
    let mut points = vec![Vec::new()];
    for _ in 0..dims {
        points = points
            .into_iter()
            .flat_map(|p: Vec<f64>| {
                (0..per_dim).map(move |i| {
                    let mut q = p.clone();
                    q.push((i as f64 + 0.5) / per_dim as f64);
                    q
                })
            })
            .collect();
    }
    points
}

/// Blocked cross-validation of a candidate.
#[derive(Debug, Clone, Serialize)]
pub struct CrossValidation {
    pub blocking: Blocking,
    /// Σ over blocks of the held-out block's SSE with the parameters fitted
    /// on the other blocks.
    pub held_out_sse: f64,
    /// Per block: the parameters fitted without it (per slot; none where
    /// nothing is left to fit), and its SSE.
    pub folds: Vec<Fold>,
    pub runs: usize,
    /// The one block the effect's evidence lies in, when every other
    /// block's fold is supported and its own is not (the rain of one day,
    /// the one day of a recording): this blocking cannot test such an
    /// effect, for no other block predicts it.
    pub evidence_in: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Fold {
    pub held_out: String,
    pub params: Vec<Vec<f64>>,
    pub held_out_sse: f64,
    /// Whether the other blocks alone support the effect (its BIC on them,
    /// against the model without it, below 0). A fold they do not support
    /// predicts its block without the effect: `held_out_sse` is the
    /// model's without it.
    pub supported: bool,
}

/// For each block: refit on the other blocks, warm-started from the
/// full-data optimum `u_star` (a bracket around it for one parameter,
/// Levenberg–Marquardt from it for several, both stopping once the SSE is
/// flat), and take the held-out block's SSE at the refitted parameters.
/// The folds run in parallel; every run of one fold serves the others
/// through the cache.
///
/// A warm start keeps the full-data optimum where the other blocks say
/// nothing about the parameters (an effect of the rain on the one day it
/// rained, a term on precipitation that is 1 wherever it is 0): the held-out
/// block would be predicted by parameters fitted on it. So a fold counts
/// its refit only where the other blocks support it by themselves, BIC
/// below 0 against the model without the effects of `space` (its base with
/// every slot off); elsewhere it predicts its block with that model.
pub(super) fn cross_validate(
    ev: &Evaluator<'_>,
    space: &Space,
    u_star: &[f64],
    blocking: Blocking,
) -> Result<CrossValidation> {
    let _stage = ev.cost.enter(Stage::CrossValidation);
    let labels = ev.blocks(blocking);
    let mut without = space.base.clone();
    for c in &space.slots {
        c.unset(&mut without.effects);
    }
    let (without, ran) = ev.evaluate_counted(&without)?;
    // A step in time has its threshold's placement besides its size.
    let k = space.dims() + space.slots.iter().filter(|c| c.is_step()).count();
    let folds: Vec<(Fold, usize)> = (0..labels.len())
        .into_par_iter()
        .map(|b| {
            let excluded = Some((blocking, b));
            let n_in = ev.n_counted(excluded);
            // Nothing outside the block (a recording of one day): nothing
            // to fit, and nothing supports the effect.
            if n_in == 0 {
                let fold = Fold {
                    held_out: labels[b].clone(),
                    params: Vec::new(),
                    held_out_sse: without.by(blocking)[b],
                    supported: false,
                };
                return Ok((fold, 0));
            }
            let f = fit_limited(ev, space, Start::Warm(u_star.to_vec()), excluded)?;
            let supported = {
                let (fitted, base) = (f.eval.sse_without(excluded), without.sse_without(excluded));
                n_in as f64 * (fitted / base).ln() + k as f64 * (n_in as f64).ln() < 0.0
            };
            let held_out_sse = if supported {
                f.eval.by(blocking)[b]
            } else {
                without.by(blocking)[b]
            };
            Ok((
                Fold {
                    held_out: labels[b].clone(),
                    params: space.params(&f.u),
                    held_out_sse,
                    supported,
                },
                f.runs,
            ))
        })
        .collect::<Result<_>>()?;
    let unsupported: Vec<&Fold> = folds
        .iter()
        .map(|(f, _)| f)
        .filter(|f| !f.supported)
        .collect();
    // One block alone (a recording of one day) is such a block too.
    let evidence_in = match unsupported[..] {
        [one] => Some(one.held_out.clone()),
        _ => None,
    };
    Ok(CrossValidation {
        blocking,
        held_out_sse: folds.iter().map(|(f, _)| f.held_out_sse).sum(),
        runs: folds.iter().map(|(_, r)| r).sum::<usize>() + usize::from(ran),
        folds: folds.into_iter().map(|(f, _)| f).collect(),
        evidence_in,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Calibrations inside a refit on two threads whose guards leave in
    /// the other order than they entered, one thread evaluating after its
    /// calibration while the other's still runs: every evaluation is the
    /// refit's, and the refit's stage is left with its guard. (A guard
    /// that restored "the stage before me" counted the second thread's
    /// run to the refit and left the calibration set after both: what a
    /// stage cost depended on the threads' timing.)
    #[test]
    fn a_stage_inside_another_on_parallel_threads_is_the_outer_ones() {
        use std::sync::Barrier;
        let meter = CostMeter::default();
        let refit = meter.enter(Stage::Refits);
        let (entered, first_left) = (Barrier::new(2), Barrier::new(2));
        std::thread::scope(|scope| {
            scope.spawn(|| {
                let calibration = meter.enter(Stage::Calibration);
                entered.wait();
                meter.add(Spent::Replay(1));
                drop(calibration);
                first_left.wait();
            });
            scope.spawn(|| {
                entered.wait();
                let calibration = meter.enter(Stage::Calibration);
                first_left.wait();
                meter.add(Spent::Replay(1));
                drop(calibration);
            });
        });
        for _ in 0..3 {
            meter.add(Spent::Replay(1));
        }
        drop(refit);
        meter.add(Spent::Replay(1));
        let runs = |stage| {
            meter
                .by_stage()
                .iter()
                .find(|c| c.stage == stage)
                .map_or(0, |c| c.cost.engine_runs)
        };
        assert_eq!(runs(Stage::Calibration), 0);
        assert_eq!(runs(Stage::Refits), 5);
        assert_eq!(runs(Stage::Fits), 1);
        assert!(meter.lock().entered.is_none());
    }

    /// A bundled recording (recordings/NAME.mcap) and its truth
    /// (NAME.key.json's `truth_config_toml`).
    fn bundled(name: &str) -> (Dataset, ModelConfig) {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../recordings");
        let data = Dataset::read(&root.join(format!("{name}.mcap"))).expect("bundled recording");
        let key: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(root.join(format!("{name}.key.json"))).expect("key"),
        )
        .expect("key json");
        let truth = ModelConfig::from_overlay_str(
            key["truth_config_toml"].as_str().expect("truth"),
            "truth",
        )
        .expect("truth config");
        (data, truth)
    }

    /// The smallest SSE of `space` over `points` (each evaluated).
    fn scanned(ev: &Evaluator<'_>, space: &Space, points: &[Vec<f64>]) -> f64 {
        points
            .par_iter()
            .map(|u| ev.evaluate(&space.config(u)).expect("replay").sse)
            .reduce(|| f64::INFINITY, f64::min)
    }

    /// One parameter from a fresh start (grid, then the Gauss–Newton line
    /// search): the hidden rail ageing's time constant at an SSE no point
    /// of a 41-point scan beats, in a fraction of the scan's replays.
    #[test]
    fn the_line_search_finds_what_a_dense_scan_finds() {
        let (data, truth) = bundled("tangent_day_ageing");
        let mut base = truth.clone();
        Candidate::Named(Named::RailAgeing).unset(&mut base.effects);
        let space = Space {
            base,
            slots: vec![Candidate::Named(Named::RailAgeing)],
        };
        let silent = tortwin_study::progress::Silent;
        let ev = Evaluator::new(&data, Vec::new(), &silent);
        let f = fit(&ev, &space, Start::Fresh, None).expect("fit");
        let scan: Vec<Vec<f64>> = (0..=40).map(|i| vec![i as f64 / 40.0]).collect();
        let best = scanned(&ev, &space, &scan);
        assert!(f.eval.sse <= best * (1.0 + 1e-9), "{} > {best}", f.eval.sse);
        assert!(f.runs <= 16, "{} replays", f.runs);
        let tau = space.params(&f.u)[0][0];
        assert!((tau / 7200.0 - 1.0).abs() < 0.05, "tau {tau}");
    }

    /// Two parameters (the wheel edge reservoir's alpha and r) from a fresh
    /// start: Levenberg–Marquardt from the coarse grid's best point ends no
    /// worse than any point of a 9 × 9 scan, in under half its replays.
    #[test]
    fn levenberg_marquardt_finds_what_a_dense_scan_finds() {
        let (data, truth) = bundled("curve_day_all_effects");
        let reservoir = Candidate::Named(Named::WheelEdgeReservoir);
        let mut base = truth.clone();
        reservoir.unset(&mut base.effects);
        let space = Space {
            base,
            slots: vec![reservoir],
        };
        let silent = tortwin_study::progress::Silent;
        let ev = Evaluator::new(&data, Vec::new(), &silent);
        let f = fit(&ev, &space, Start::Fresh, None).expect("fit");
        let scan = grid_points(2, 9);
        let best = scanned(&ev, &space, &scan);
        assert!(f.eval.sse <= best * (1.0 + 1e-9), "{} > {best}", f.eval.sse);
        assert!(f.runs <= 40, "{} replays", f.runs);
    }

    /// Each named effect taken out of `truth` (a recording that holds them
    /// all): the candidate, its space, and its fit from nothing on an
    /// evaluator of its own (nothing cached).
    fn each_effect_out_of_its_truth(
        data: &Dataset,
        truth: &ModelConfig,
    ) -> Vec<(Candidate, Space, Fit)> {
        let silent = tortwin_study::progress::Silent;
        Candidate::all()
            .into_iter()
            .filter(|c| c.dims() > 0)
            .map(|c| {
                let mut base = truth.clone();
                c.unset(&mut base.effects);
                let space = Space {
                    base,
                    slots: vec![c.clone()],
                };
                let alone = Evaluator::new(data, Vec::new(), &silent);
                let whole = fit(&alone, &space, Start::Fresh, None).expect("fit");
                (c, space, whole)
            })
            .collect()
    }

    /// A first look (`first_look`) is the beginning of the fit, not a
    /// detour: for every effect of a recording that holds them all, taken
    /// out of its truth, the fit from the same start after the look costs
    /// only the rest of the fit's replays and ends where a fit from
    /// nothing ends; and where the look stops, the least SSE it expects
    /// is below the SSE the whole fit reaches (the optimism holds).
    #[test]
    fn a_first_look_begins_the_fit_and_its_hope_is_not_too_low() {
        let (data, truth) = bundled("curve_day_all_effects");
        let silent = tortwin_study::progress::Silent;
        let mut open = 0;
        for (c, space, whole) in each_effect_out_of_its_truth(&data, &truth) {
            let ev = Evaluator::new(&data, Vec::new(), &silent);
            let look = first_look(&ev, &space, &Start::Fresh).expect("look");
            let (seen, runs) = match &look {
                Look::Done(f) => (f.eval.sse, f.runs),
                Look::Open(f, optimistic) => {
                    open += 1;
                    assert!(
                        *optimistic <= whole.eval.sse,
                        "{c:?}: hoped for {optimistic}, the fit reaches {}",
                        whole.eval.sse
                    );
                    (f.eval.sse, f.runs)
                }
            };
            assert!(seen >= whole.eval.sse * (1.0 - 1e-12), "{c:?}");
            let rest = fit(&ev, &space, Start::Fresh, None).expect("fit");
            assert_eq!(rest.eval.sse, whole.eval.sse, "{c:?}");
            assert_eq!(runs + rest.runs, whole.runs, "{c:?}: replays");
        }
        assert!(open >= 3, "only {open} looks stopped short of their fits");
    }

    #[test]
    fn rounds_after_a_look_walk_the_fit_and_their_hope_is_not_too_low() {
        // Each named effect, taken out of the truth and fitted in rounds
        // of three replays after its look: the rounds
        // are the fit cut in pieces (the same end, the same replays in
        // all), each round's optimistic SSE is below what the fit reaches,
        // and no round replays more than its budget.
        let (data, truth) = bundled("curve_day_all_effects");
        let silent = tortwin_study::progress::Silent;
        let mut rounds = 0;
        for (c, space, whole) in each_effect_out_of_its_truth(&data, &truth) {
            let ev = Evaluator::new(&data, Vec::new(), &silent);
            let mut look = first_look(&ev, &space, &Start::Fresh).expect("look");
            let mut runs = 0;
            loop {
                match look {
                    Look::Done(f) => {
                        runs += f.runs;
                        assert_eq!(f.eval.sse, whole.eval.sse, "{c:?}");
                        break;
                    }
                    Look::Open(f, optimistic) => {
                        assert!(
                            optimistic <= whole.eval.sse,
                            "{c:?}: hoped for {optimistic}, the fit reaches {}",
                            whole.eval.sse
                        );
                        assert!(f.eval.sse >= whole.eval.sse * (1.0 - 1e-12), "{c:?}");
                        runs += f.runs;
                        look = look_further(&ev, &space, &Start::Fresh, 3).expect("round");
                        let (Look::Open(f, _) | Look::Done(f)) = &look;
                        assert!(f.runs <= 3 + 1, "{c:?}: {} replays in a round", f.runs);
                        rounds += 1;
                    }
                }
            }
            assert_eq!(runs, whole.runs, "{c:?}: replays");
        }
        assert!(rounds >= 3, "only {rounds} rounds");
    }

    #[test]
    fn transforms_round_trip_and_hit_the_bounds() {
        for c in Candidate::all() {
            for i in 0..c.dims() {
                for u in [0.0, 0.1, 0.37, 0.5, 0.9, 1.0] {
                    let p = c.param(i, u);
                    assert!((c.unit(i, p) - u).abs() < 1e-9, "{c:?} {u} {p}");
                }
                // The searched range of the parameter.
                let (lo, hi) = match &c {
                    Candidate::Named(n) => n.spec().params[i].search,
                    Candidate::Generic(g) => g.bounds(),
                };
                assert!((c.param(i, 0.0) - lo).abs() < 1e-9 * hi.abs().max(1.0));
                assert!((c.param(i, 1.0) - hi).abs() < 1e-9 * hi.abs().max(1.0));
            }
        }
    }

    #[test]
    fn every_candidate_sets_a_valid_config() {
        for c in Candidate::all() {
            let space = Space {
                base: ModelConfig::default(),
                slots: vec![c.clone()],
            };
            for u in [0.0, 0.5, 1.0] {
                let cfg = space.config(&vec![u; c.dims()]);
                cfg.validate("test").unwrap();
                assert_eq!(cfg.effects.names(), vec![c.name()]);
            }
        }
    }
}
