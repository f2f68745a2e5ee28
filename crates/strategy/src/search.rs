//! The search over a space of strategies.
//!
//! A space is a lattice: pulse masses × pulse intervals × applicator
//! layouts (one or two applicators at candidate positions) × rail sets.
//! A small space is evaluated whole, in parallel (rayon). A large one is
//! searched: a coarse sub-lattice first, then argmin's Nelder–Mead over the
//! lattice's index coordinates (rounded to the nearest lattice point) from
//! the best coarse points, first for the best admissible coverage, then for
//! the least product that keeps it within the tolerance, and a final
//! neighbour-by-neighbour polish on the lattice until no neighbour is
//! better. Every evaluation is cached by its lattice point.
//!
//! The recommendation is one rule applied to whatever was evaluated: among
//! the admissible strategies (at most `max_below_share` of the contacts
//! below the band), the least product whose coverage is within
//! `coverage_tolerance` of the best admissible coverage. The Pareto front
//! is the set of admissible strategies no other beats on both product and
//! coverage.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::metrics::{Figures, Target};
use super::{evaluate, Plan, Strategy, Traffic};
use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_study::error::optimiser;
use tortwin_study::{Error, Result};

/// The most values one dimension of a space may have (a list's length, a
/// range's `steps`, the candidate positions): a thousand is finer than any
/// applicator is set; a billion steps once asked for 8 GB.
pub const MAX_VALUES: usize = 1000;

/// The most strategies the grid method evaluates, one replay each (and
/// the most `[search] max_grid` may say): a larger space is searched by the
/// optimiser.
pub const MAX_GRID: usize = 100_000;

/// Values of one dimension: a list, or `steps` log-spaced values from
/// `min` to `max` (both included).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Values {
    List(Vec<f64>),
    Range { min: f64, max: f64, steps: usize },
}

impl Values {
    fn expand(&self, key: &str) -> Result<Vec<f64>, UsageError> {
        let count = match self {
            Values::List(v) => v.len(),
            Values::Range { steps, .. } => *steps,
        };
        if count > MAX_VALUES {
            return Err(UsageError(format!(
                "space.{key}: {count} values; a dimension has at most {MAX_VALUES}"
            )));
        }
        let v = match self {
            Values::List(v) => v.clone(),
            Values::Range { min, max, steps } => {
                if !(min.is_finite() && max.is_finite() && *min > 0.0 && min <= max) || *steps == 0
                {
                    return Err(UsageError(format!(
                        "space.{key}: a range needs 0 < min <= max and steps >= 1"
                    )));
                }
                if *steps == 1 {
                    vec![*min]
                } else {
                    let ratio = (max / min).ln() / (*steps - 1) as f64;
                    (0..*steps)
                        .map(|k| min * (ratio * k as f64).exp())
                        .collect()
                }
            }
        };
        if v.is_empty() || v.iter().any(|x| !x.is_finite()) {
            return Err(UsageError(format!(
                "space.{key}: needs at least one finite value"
            )));
        }
        Ok(v)
    }
}

/// A space of strategies as configured (`[space]` of the strategy file).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpaceConfig {
    /// Pulse masses in g.
    pub pulse_g: Values,
    /// Pulse intervals in axles (rounded, duplicates dropped).
    pub every_axles: Values,
    /// Candidate applicator positions in m.
    pub positions_m: Vec<f64>,
    /// How many applicators: 1, 2 or both.
    pub applicators: Vec<usize>,
    /// Rail sets to try (rail names).
    pub rails: Vec<Vec<String>>,
}

impl SpaceConfig {
    /// Around today's practice: 0.05 to 0.8 g, every 1 to 8 axles (coverage
    /// changes steeply between 2 and 4), the recorded applicators' positions and a third and two thirds into the
    /// section (whole metres), one or two applicators, all rails.
    pub fn around_today(traffic: &Traffic) -> Self {
        let s = &traffic.section;
        let mut positions: Vec<f64> = s.applicators.iter().map(|a| a.position_m).collect();
        positions.extend([s.length_m / 3.0, 2.0 * s.length_m / 3.0].map(f64::round));
        positions.sort_by(f64::total_cmp);
        positions.dedup();
        Self {
            pulse_g: Values::List(vec![0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.6, 0.8]),
            every_axles: Values::List(vec![1.0, 2.0, 3.0, 4.0, 6.0, 8.0]),
            positions_m: positions,
            applicators: vec![1, 2],
            rails: vec![s.rails.clone()],
        }
    }
}

/// The lattice of a space.
#[derive(Debug, Clone, PartialEq)]
pub struct Space {
    pub pulse_kg: Vec<f64>,
    pub every_axles: Vec<u32>,
    pub positions_m: Vec<f64>,
    /// Position indices of each layout, ascending.
    pub layouts: Vec<Vec<usize>>,
    pub rails: Vec<Vec<usize>>,
}

/// A lattice point: indices into the space's dimensions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
pub struct Key {
    pub pulse: usize,
    pub every: usize,
    pub layout: usize,
    pub rails: usize,
}

impl Space {
    pub fn new(c: &SpaceConfig, traffic: &Traffic) -> Result<Self, UsageError> {
        let section = &traffic.section;
        let mut pulse_g = c.pulse_g.expand("pulse_g")?;
        if pulse_g.iter().any(|&g| g <= 0.0) {
            return Err(UsageError("space.pulse_g: masses must be positive".into()));
        }
        pulse_g.sort_by(f64::total_cmp);
        pulse_g.dedup();
        let mut every: Vec<u32> = Vec::new();
        for k in c.every_axles.expand("every_axles")? {
            if !(1.0..=1e6).contains(&k) {
                return Err(UsageError(format!(
                    "space.every_axles: {k} is not an interval from 1 to 1e6 axles"
                )));
            }
            every.push(k.round() as u32);
        }
        every.sort_unstable();
        every.dedup();
        let mut positions = c.positions_m.clone();
        if positions.len() > MAX_VALUES {
            return Err(UsageError(format!(
                "space.positions_m: {} positions; at most {MAX_VALUES}",
                positions.len()
            )));
        }
        if c.rails.len() > MAX_VALUES {
            return Err(UsageError(format!(
                "space.rails: {} rail sets; at most {MAX_VALUES}",
                c.rails.len()
            )));
        }
        if positions.is_empty() {
            return Err(UsageError(
                "space.positions_m: needs at least one position".into(),
            ));
        }
        for &p in &positions {
            if !(p.is_finite() && (0.0..=section.length_m).contains(&p)) {
                return Err(UsageError(format!(
                    "space.positions_m: {p} m is outside the section [0, {}] m",
                    section.length_m
                )));
            }
        }
        positions.sort_by(f64::total_cmp);
        positions.dedup();
        let mut layouts = Vec::new();
        if c.applicators.is_empty() || c.applicators.iter().any(|&n| n != 1 && n != 2) {
            return Err(UsageError(
                "space.applicators: give 1, 2 or both (one or two applicators)".into(),
            ));
        }
        if c.applicators.contains(&1) {
            layouts.extend((0..positions.len()).map(|i| vec![i]));
        }
        if c.applicators.contains(&2) {
            if positions.len() < 2 {
                return Err(UsageError(
                    "space.applicators: two applicators need at least two positions_m".into(),
                ));
            }
            for i in 0..positions.len() {
                for j in i + 1..positions.len() {
                    layouts.push(vec![i, j]);
                }
            }
        }
        let mut rails = Vec::new();
        for set in &c.rails {
            let mut idx = Vec::new();
            for name in set {
                match traffic.rail_index(name) {
                    Some(r) => idx.push(r),
                    None => {
                        return Err(UsageError(format!(
                            "space.rails: unknown rail {name:?}; the section's rails are {:?}",
                            section.rails
                        )))
                    }
                }
            }
            idx.sort_unstable();
            idx.dedup();
            if idx.is_empty() {
                return Err(UsageError("space.rails: a rail set is empty".into()));
            }
            if !rails.contains(&idx) {
                rails.push(idx);
            }
        }
        if rails.is_empty() {
            return Err(UsageError(
                "space.rails: needs at least one rail set".into(),
            ));
        }
        Ok(Self {
            pulse_kg: pulse_g.iter().map(|g| g * 1e-3).collect(),
            every_axles: every,
            positions_m: positions,
            layouts,
            rails,
        })
    }

    /// Strategies in the space.
    pub fn size(&self) -> usize {
        [self.every_axles.len(), self.layouts.len(), self.rails.len()]
            .into_iter()
            .fold(self.pulse_kg.len(), usize::saturating_mul)
    }

    pub fn keys(&self) -> Vec<Key> {
        let mut keys = Vec::with_capacity(self.size());
        for rails in 0..self.rails.len() {
            for layout in 0..self.layouts.len() {
                for every in 0..self.every_axles.len() {
                    for pulse in 0..self.pulse_kg.len() {
                        keys.push(Key {
                            pulse,
                            every,
                            layout,
                            rails,
                        });
                    }
                }
            }
        }
        keys
    }

    pub fn strategy(&self, k: Key) -> Strategy {
        Strategy {
            pulse_kg: self.pulse_kg[k.pulse],
            every_axles: self.every_axles[k.every],
            positions_m: self.layouts[k.layout]
                .iter()
                .map(|&i| self.positions_m[i])
                .collect(),
            rails: self.rails[k.rails].clone(),
        }
    }

    /// The layout with these position indices, if the space has it.
    fn layout_of(&self, positions: &[usize]) -> Option<usize> {
        self.layouts.iter().position(|l| l == positions)
    }

    /// The lattice neighbours of `k`: one step in pulse, interval or one
    /// applicator's position; any other rail set; one applicator more or
    /// fewer.
    fn neighbours(&self, k: Key) -> Vec<Key> {
        let mut out = Vec::new();
        let step = |i: usize, n: usize| {
            [i.checked_sub(1), (i + 1 < n).then_some(i + 1)]
                .into_iter()
                .flatten()
        };
        out.extend(step(k.pulse, self.pulse_kg.len()).map(|pulse| Key { pulse, ..k }));
        out.extend(step(k.every, self.every_axles.len()).map(|every| Key { every, ..k }));
        out.extend(
            (0..self.rails.len())
                .filter(|&r| r != k.rails)
                .map(|rails| Key { rails, ..k }),
        );
        let layout = &self.layouts[k.layout];
        let mut moved = Vec::new();
        for a in 0..layout.len() {
            for p in step(layout[a], self.positions_m.len()) {
                let mut l = layout.clone();
                l[a] = p;
                moved.push(l);
            }
        }
        if layout.len() == 2 {
            moved.push(vec![layout[0]]);
            moved.push(vec![layout[1]]);
        } else {
            for p in step(layout[0], self.positions_m.len()) {
                let mut l = vec![layout[0], p];
                l.sort_unstable();
                moved.push(l);
            }
        }
        for mut l in moved {
            l.sort_unstable();
            if l.windows(2).any(|w| w[0] == w[1]) {
                continue;
            }
            if let Some(layout) = self.layout_of(&l) {
                out.push(Key { layout, ..k });
            }
        }
        out
    }
}

/// How to search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Every strategy when the space has at most `max_grid` of them, the
    /// optimiser otherwise.
    Auto,
    Grid,
    Optimiser,
}

/// One evaluated strategy.
#[derive(Debug, Clone, Serialize)]
pub struct Evaluated {
    pub key: Key,
    #[serde(skip)]
    pub strategy: Strategy,
    pub figures: Figures,
}

/// Evaluations by lattice point, shared by parallel workers.
pub struct Searcher<'a> {
    traffic: &'a Traffic,
    cfg: &'a ModelConfig,
    target: &'a Target,
    space: &'a Space,
    cache: Mutex<HashMap<Key, Arc<Evaluated>>>,
    error: Mutex<Option<Error>>,
    on_evaluation: &'a (dyn Fn(usize) -> Result<()> + Sync),
}

/// Penalty weight of a broken constraint in the optimiser's objectives.
const PENALTY: f64 = 10.0;
/// Cost of a point outside the lattice (two applicators at one position).
const INFEASIBLE: f64 = 1e3;
const NM_MAX_ITERS: u64 = 40;

impl<'a> Searcher<'a> {
    pub fn new(
        traffic: &'a Traffic,
        cfg: &'a ModelConfig,
        target: &'a Target,
        space: &'a Space,
        on_evaluation: &'a (dyn Fn(usize) -> Result<()> + Sync),
    ) -> Self {
        Self {
            traffic,
            cfg,
            target,
            space,
            cache: Mutex::new(HashMap::new()),
            error: Mutex::new(None),
            on_evaluation,
        }
    }

    /// Evaluations so far.
    pub fn evaluations(&self) -> usize {
        self.lock_cache().len()
    }

    fn lock_cache(&self) -> std::sync::MutexGuard<'_, HashMap<Key, Arc<Evaluated>>> {
        self.cache.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Evaluates `k` (once).
    pub(crate) fn eval(&self, k: Key) -> Result<Arc<Evaluated>> {
        if let Some(e) = self.lock_cache().get(&k) {
            return Ok(e.clone());
        }
        let strategy = self.space.strategy(k);
        let figures = evaluate(
            self.traffic,
            self.cfg,
            self.target,
            &Plan::Strategy(strategy.clone()),
            false,
            None,
        )?;
        let e = Arc::new(Evaluated {
            key: k,
            strategy,
            figures,
        });
        let n = {
            let mut cache = self.lock_cache();
            cache.entry(k).or_insert_with(|| e.clone());
            cache.len()
        };
        (self.on_evaluation)(n)?;
        Ok(e)
    }

    /// Evaluates every key, in parallel.
    pub(crate) fn eval_all(&self, keys: &[Key]) -> Result<Vec<Arc<Evaluated>>> {
        keys.par_iter().map(|&k| self.eval(k)).collect()
    }

    /// Everything evaluated, by key.
    pub fn all(&self) -> Vec<Arc<Evaluated>> {
        let mut v: Vec<_> = self.lock_cache().values().cloned().collect();
        v.sort_by_key(|e| e.key);
        v
    }

    /// Runs the search and returns the recommendation's key.
    pub fn run(&self, method: Method, max_grid: usize) -> Result<Method> {
        if max_grid > MAX_GRID {
            return Err(UsageError(format!(
                "search.max_grid = {max_grid}; at most {MAX_GRID} (a replay each)"
            ))
            .into());
        }
        let size = self.space.size();
        let grid = match method {
            Method::Auto => size <= max_grid,
            Method::Grid if size > MAX_GRID => {
                return Err(UsageError(format!(
                    "--method grid: the space holds {size} strategies, a replay each; the grid \
                     evaluates at most {MAX_GRID} (the optimiser searches larger spaces)"
                ))
                .into())
            }
            Method::Grid => true,
            Method::Optimiser => false,
        };
        if grid {
            self.eval_all(&self.space.keys())?;
            Ok(Method::Grid)
        } else {
            self.optimise()?;
            Ok(Method::Optimiser)
        }
    }

    /// The optimiser (see the module documentation).
    fn optimise(&self) -> Result<()> {
        let space = self.space;
        // Coarse sub-lattice: ends and middle of each ordered dimension,
        // every layout size and rail set.
        let levels = |n: usize| {
            let mut v = vec![0, (n - 1) / 2, n - 1];
            v.dedup();
            v
        };
        let mut seeds = Vec::new();
        for rails in 0..space.rails.len() {
            for layout in 0..space.layouts.len() {
                let l = &space.layouts[layout];
                let on_coarse = l
                    .iter()
                    .all(|&p| levels(space.positions_m.len()).contains(&p));
                if !on_coarse {
                    continue;
                }
                for &pulse in &levels(space.pulse_kg.len()) {
                    for &every in &levels(space.every_axles.len()) {
                        seeds.push(Key {
                            pulse,
                            every,
                            layout,
                            rails,
                        });
                    }
                }
            }
        }
        self.eval_all(&seeds)?;

        // Stage 1: best admissible coverage, Nelder–Mead from the two best
        // coarse points of each (applicator count, rail set).
        let starts = self.starts(&seeds, |e| self.coverage_cost(&e.figures));
        starts
            .par_iter()
            .try_for_each(|&k| self.nelder_mead(k, Objective::Coverage))?;
        // (The coarse lattice is never empty: there is always a best.)
        if let Some(best) = self.best_coverage_key() {
            self.polish(best, Objective::Coverage)?;
        }

        // Stage 2: the least product within the tolerance of that coverage.
        let objective = self.product_objective();
        let all: Vec<Key> = self.all().iter().map(|e| e.key).collect();
        let starts = self.starts(&all, |e| self.cost(objective, &e.figures));
        starts
            .par_iter()
            .try_for_each(|&k| self.nelder_mead(k, objective))?;
        let rec = recommend(&self.all(), self.target).map(|r| r.key);
        if let Some(rec) = rec {
            self.polish(rec, self.product_objective())?;
        }
        Ok(())
    }

    /// The best key by `cost` for each (applicator count, rail set), and
    /// the second best.
    fn starts(&self, keys: &[Key], cost: impl Fn(&Evaluated) -> f64) -> Vec<Key> {
        let mut groups: HashMap<(usize, usize), Vec<(f64, Key)>> = HashMap::new();
        for &k in keys {
            if let Some(e) = self.lock_cache().get(&k).cloned() {
                let group = (self.space.layouts[k.layout].len(), k.rails);
                groups.entry(group).or_default().push((cost(&e), k));
            }
        }
        let mut starts = Vec::new();
        let mut groups: Vec<_> = groups.into_iter().collect();
        groups.sort_by_key(|(g, _)| *g);
        for (_, mut v) in groups {
            v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            starts.extend(v.iter().take(2).map(|(_, k)| *k));
        }
        starts
    }

    fn best_coverage_key(&self) -> Option<Key> {
        self.all()
            .iter()
            .min_by(|a, b| {
                self.coverage_cost(&a.figures)
                    .total_cmp(&self.coverage_cost(&b.figures))
                    .then(a.key.cmp(&b.key))
            })
            .map(|e| e.key)
    }

    /// Stage 1's cost: the coverage, constraint as a penalty.
    fn coverage_cost(&self, f: &Figures) -> f64 {
        -f.coverage + PENALTY * (f.below_share - self.target.max_below_share).max(0.0)
    }

    /// Stage 2's cost: product relative to `scale`, with the coverage
    /// `floor` and the constraint as penalties.
    fn product_cost(&self, f: &Figures, floor: f64, scale: f64) -> f64 {
        f.product_g_per_day / scale
            + PENALTY * (floor - f.coverage).max(0.0)
            + PENALTY * (f.below_share - self.target.max_below_share).max(0.0)
    }

    /// Stage 2's objective: the coverage floor is the best admissible
    /// coverage so far less the tolerance, the scale that strategy's product.
    fn product_objective(&self) -> Objective {
        let best = best_coverage(&self.all()).map(|e| {
            (
                e.figures.coverage - self.target.coverage_tolerance,
                e.figures.product_g_per_day.max(1e-9),
            )
        });
        let (floor, scale) = best.unwrap_or((0.0, 1.0));
        Objective::Product { floor, scale }
    }

    fn cost(&self, objective: Objective, f: &Figures) -> f64 {
        match objective {
            Objective::Coverage => self.coverage_cost(f),
            Objective::Product { floor, scale } => self.product_cost(f, floor, scale),
        }
    }

    /// Nelder–Mead over (pulse, interval, position(s)) index coordinates
    /// with the rail set and applicator count of `start` fixed.
    fn nelder_mead(&self, start: Key, objective: Objective) -> Result<()> {
        let space = self.space;
        let layout = &space.layouts[start.layout];
        let mut x0 = vec![start.pulse as f64, start.every as f64];
        x0.extend(layout.iter().map(|&p| p as f64));
        let upper: Vec<f64> = [space.pulse_kg.len(), space.every_axles.len()]
            .into_iter()
            .chain(layout.iter().map(|_| space.positions_m.len()))
            .map(|n| (n - 1) as f64)
            .collect();
        if upper.iter().all(|&u| u == 0.0) {
            return Ok(());
        }
        let mut simplex = vec![x0.clone()];
        for (d, &u) in upper.iter().enumerate() {
            let step = (u / 4.0).max(1.0);
            let mut x = x0.clone();
            x[d] = if x[d] + step <= u {
                x[d] + step
            } else {
                x[d] - step
            };
            simplex.push(x);
        }
        let problem = LatticeCost {
            searcher: self,
            start,
            upper,
            objective,
        };
        let solver = NelderMead::new(simplex)
            .with_sd_tolerance(1e-6)
            .map_err(optimiser)?;
        Executor::new(problem, solver)
            .configure(|state| state.max_iters(NM_MAX_ITERS))
            .run()
            .map_err(optimiser)?;
        self.take_error()
    }

    /// Moves to the best lattice neighbour while one is better.
    fn polish(&self, mut k: Key, objective: Objective) -> Result<()> {
        loop {
            let here = self.cost(objective, &self.eval(k)?.figures);
            let next = self
                .eval_all(&self.space.neighbours(k))?
                .into_iter()
                .map(|e| (self.cost(objective, &e.figures), e.key))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            match next {
                Some((c, n)) if c < here => k = n,
                _ => return Ok(()),
            }
        }
    }

    fn take_error(&self) -> Result<()> {
        match self.error.lock().unwrap_or_else(|e| e.into_inner()).take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Objective {
    Coverage,
    Product { floor: f64, scale: f64 },
}

/// The cost of a continuous point: rounded to the nearest lattice point.
struct LatticeCost<'s, 'a> {
    searcher: &'s Searcher<'a>,
    start: Key,
    upper: Vec<f64>,
    objective: Objective,
}

impl LatticeCost<'_, '_> {
    fn key(&self, x: &[f64]) -> Option<Key> {
        let idx: Vec<usize> = x
            .iter()
            .zip(&self.upper)
            .map(|(&v, &u)| v.clamp(0.0, u).round() as usize)
            .collect();
        let mut positions = idx[2..].to_vec();
        positions.sort_unstable();
        if positions.windows(2).any(|w| w[0] == w[1]) {
            return None;
        }
        Some(Key {
            pulse: idx[0],
            every: idx[1],
            layout: self.searcher.space.layout_of(&positions)?,
            rails: self.start.rails,
        })
    }
}

impl CostFunction for LatticeCost<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        let Some(k) = self.key(x) else {
            return Ok(INFEASIBLE);
        };
        // Outside the box: the clamped point's cost plus the distance, so
        // the simplex comes back.
        let outside: f64 = x
            .iter()
            .zip(&self.upper)
            .map(|(&v, &u)| (v - v.clamp(0.0, u)).abs())
            .sum();
        match self.searcher.eval(k) {
            Ok(e) => Ok(self.searcher.cost(self.objective, &e.figures) + outside),
            Err(err) => {
                let mut slot = self
                    .searcher
                    .error
                    .lock()
                    .unwrap_or_else(|e| e.into_inner());
                slot.get_or_insert(err);
                Ok(INFEASIBLE)
            }
        }
    }
}

/// The order the choices follow among strategies (docs/spec/interfaces.md,
/// "Strategy figures"): less product (whole micrograms, so equal doses are
/// equal), then higher coverage, then fewer pulses, then the lattice point
/// (pulse mass, interval, layout, rails: the space's order).
fn cheaper_then_better(a: &Evaluated, b: &Evaluated) -> std::cmp::Ordering {
    let (fa, fb) = (&a.figures, &b.figures);
    fa.product_ug
        .cmp(&fb.product_ug)
        .then(fb.coverage.total_cmp(&fa.coverage))
        .then(fa.pulses.cmp(&fb.pulses))
        .then(a.key.cmp(&b.key))
}

/// The recommendation among `evaluated` (see the module documentation):
/// among the admissible strategies whose coverage is within the tolerance
/// of the best admissible coverage, the first in [`cheaper_then_better`]'s
/// order. `None` when nothing is admissible.
pub fn recommend<'e>(evaluated: &'e [Arc<Evaluated>], target: &Target) -> Option<&'e Evaluated> {
    let best = evaluated
        .iter()
        .filter(|e| e.figures.admissible)
        .map(|e| e.figures.coverage)
        .fold(f64::NEG_INFINITY, f64::max);
    evaluated
        .iter()
        .filter(|e| e.figures.admissible && e.figures.coverage >= best - target.coverage_tolerance)
        .min_by(|a, b| cheaper_then_better(a, b))
        .map(|e| e.as_ref())
}

/// The strategy with the best admissible coverage (ties: less product,
/// then fewer pulses, then the lattice point).
pub(crate) fn best_coverage(evaluated: &[Arc<Evaluated>]) -> Option<&Evaluated> {
    evaluated
        .iter()
        .filter(|e| e.figures.admissible)
        .min_by(|a, b| {
            b.figures
                .coverage
                .total_cmp(&a.figures.coverage)
                .then(cheaper_then_better(a, b))
        })
        .map(|e| e.as_ref())
}

/// A point of the Pareto front: the strategy shown, and its twins (other
/// strategies with exactly the same product and coverage), in
/// [`cheaper_then_better`]'s order.
#[derive(Debug, Clone)]
pub struct FrontPoint {
    pub chosen: Arc<Evaluated>,
    pub twins: Vec<Arc<Evaluated>>,
}

/// The Pareto front of the admissible strategies: those that no other
/// admissible strategy dominates (at most their product and at least their
/// coverage, one of the two strictly), by ascending product. Strategies
/// with exactly the same product and coverage do not dominate each other:
/// they are one point, shown once with its twins named. Over-applying
/// strategies are not choices and are left out.
pub(crate) fn pareto_front(evaluated: &[Arc<Evaluated>]) -> Vec<FrontPoint> {
    let mut v: Vec<&Arc<Evaluated>> = evaluated.iter().filter(|e| e.figures.admissible).collect();
    v.sort_by(|a, b| cheaper_then_better(a, b));
    let mut front: Vec<FrontPoint> = Vec::new();
    // The best coverage among the strategies before (none dominated by a
    // later one: those have at least as much product).
    let mut best_before = f64::NEG_INFINITY;
    for e in v {
        let f = &e.figures;
        if let Some(last) = front.last_mut() {
            let l = &last.chosen.figures;
            if l.product_ug == f.product_ug && l.coverage == f.coverage {
                last.twins.push(e.clone());
                continue;
            }
        }
        if f.coverage > best_before {
            best_before = f.coverage;
            front.push(FrontPoint {
                chosen: e.clone(),
                twins: Vec::new(),
            });
        }
    }
    front
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A strategy with only what the choices read: product, coverage,
    /// pulses, admissibility.
    fn evaluated(
        i: usize,
        product_ug: u64,
        coverage: f64,
        pulses: u64,
        admissible: bool,
    ) -> Arc<Evaluated> {
        Arc::new(Evaluated {
            key: Key {
                pulse: i,
                every: 0,
                layout: 0,
                rails: 0,
            },
            strategy: super::Strategy {
                pulse_kg: 1e-4,
                every_axles: 1,
                positions_m: vec![0.0],
                rails: vec![0],
            },
            figures: Figures {
                coverage,
                below_share: 0.0,
                admissible,
                pulses,
                product_ug,
                product_g: product_ug as f64 / 1e6,
                product_g_per_day: product_ug as f64 / 1e6,
                product_g_per_1000_axles: 0.0,
                rails: Vec::new(),
            },
        })
    }

    fn dominates(a: &Figures, b: &Figures) -> bool {
        a.product_ug <= b.product_ug
            && a.coverage >= b.coverage
            && (a.product_ug < b.product_ug || a.coverage > b.coverage)
    }

    proptest! {
        /// Few products and coverages, so that exact ties are common: the
        /// front (points and twins) is the admissible set no admissible
        /// strategy dominates, each point's twins equal it, and the
        /// recommendation is the first of the documented order.
        #[test]
        fn the_front_is_the_non_dominated_set(
            rows in prop::collection::vec((0u64..6, 0u8..6, 1u64..4, any::<bool>()), 0..40),
            tolerance in 0.0f64..0.3,
        ) {
            let all: Vec<Arc<Evaluated>> = rows
                .iter()
                .enumerate()
                .map(|(i, &(p, c, n, a))| evaluated(i, p * 50_000, f64::from(c) / 8.0, n, a))
                .collect();
            let front = pareto_front(&all);
            let mut shown: Vec<Key> = front
                .iter()
                .flat_map(|p| std::iter::once(&p.chosen).chain(&p.twins).map(|e| e.key))
                .collect();
            shown.sort();
            let admissible: Vec<&Arc<Evaluated>> = all.iter().filter(|e| e.figures.admissible).collect();
            let mut expected: Vec<Key> = admissible
                .iter()
                .filter(|e| !admissible.iter().any(|o| dominates(&o.figures, &e.figures)))
                .map(|e| e.key)
                .collect();
            expected.sort();
            prop_assert_eq!(shown, expected);
            for p in &front {
                for t in &p.twins {
                    prop_assert_eq!(t.figures.product_ug, p.chosen.figures.product_ug);
                    prop_assert_eq!(t.figures.coverage, p.chosen.figures.coverage);
                    prop_assert!(cheaper_then_better(&p.chosen, t).is_lt());
                }
            }
            let target = Target { coverage_tolerance: tolerance, ..Target::default() };
            let best = admissible.iter().map(|e| e.figures.coverage).fold(f64::NEG_INFINITY, f64::max);
            let by_hand = admissible
                .iter()
                .filter(|e| e.figures.coverage >= best - tolerance)
                .min_by_key(|e| {
                    // The documented order, written again: product, then
                    // coverage (higher first), then pulses, then the key.
                    (e.figures.product_ug, std::cmp::Reverse((e.figures.coverage * 8.0) as u64), e.figures.pulses, e.key)
                })
                .map(|e| e.key);
            prop_assert_eq!(recommend(&all, &target).map(|e| e.key), by_hand);
        }
    }
}
