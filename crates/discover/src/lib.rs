//! The discrepancy workflow behind `tortwin discover`: what does the model
//! miss in a recording?
//!
//! 1. **Residuals.** The recording is read once ([`data::Dataset`]) and
//!    replayed through the one engine with the starting model; residual =
//!    measured − simulated for every measurement (mu, adhesion, rail_mu).
//! 2. **Diagnosis.** Each measurement carries covariates computed from the
//!    events (distance downstream of the applicator, time since the site
//!    was last touched, rain in that time, air temperature, train speed,
//!    leading/trailing axle, rail, wheel load, time of day, day, ...);
//!    `diagnose::rank` ranks them by the share of the residual variance
//!    they explain (eta²). `diagnose::noise_estimate` estimates the
//!    measurement noise from axle-to-axle differences, independently of
//!    the fit.
//! 3. **Candidates.** Every effect of docs/spec/effects.md not yet in
//!    the model is fitted by re-running the engine (`fit.rs`), the candidates
//!    in parallel (rayon), and judged by two criteria: the Bayesian
//!    information criterion must drop by more than
//!    [`Options::bic_threshold`] (`ΔBIC = n ln(SSE1/SSE0) + Δk ln n`); it
//!    must remove at least [`Options::min_excess_share`] of what the current
//!    model leaves above the noise; and cross-validation blocked by day, then
//!    by measurement site, must predict the held-out blocks better than the
//!    current model does (summed held-out SSE). The site blocks keep a
//!    cause that belongs to one place (a sensor's offset) from being taken
//!    for an effect of the track: an effect fitted on the other sites would
//!    not predict it.
//! 4. **Forward selection.** Of the candidates passing both, the one with
//!    the largest BIC drop is added, every effect in the model is refitted
//!    jointly, and the search repeats until no candidate passes. A step's
//!    threshold is placed by the fit, between the events it acts on (the
//!    applicator's pulses for a pulse mass, the trains otherwise); the close
//!    contenders of a step (up to three within 80 % of the best BIC drop)
//!    are fitted again with the model's effects free before they are
//!    compared. The site's constants are one candidate of every step until
//!    they are taken (`calibrate.rs`), calibrated with the effects already
//!    taken free and, when they contend, reduced to the fewest that explain
//!    as well; an effect must beat them by the BIC threshold (a constant is
//!    the plainer story), and a generic term everywhere on a quantity one
//!    constant scales (transfer: kt; muD, muC) must beat that constant
//!    fitted alone by as much. An effect taken before them that they make
//!    unnecessary is taken out again; when they are taken, the step's best
//!    effects are fitted jointly with them, and every named effect is
//!    fitted afresh at the next step.
//! 5. **What is left.** If the final RMSE is still well above the noise
//!    estimate ([`Options::unexplained_ratio`]), the remaining residual is
//!    reported with the covariate it follows most closely: no effect is
//!    forced onto it.
//!
//! Effects already in the starting configuration stay on and are refitted
//! first (step 0).

pub mod calibrate;
pub mod data;
mod describe;
mod diagnose;
mod fit;
pub mod report;
mod residuals_rrd;
mod screen;
mod search;
mod space;

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;
use tortwin_outputs::provenance::Provenance;

use serde::Serialize;

use data::Dataset;
use fit::{Candidate, Evaluator, Space, Start};
use search::Search;
use space::Drivers;
use tortwin_model::config::{ModelConfig, TermEffect};
use tortwin_model::effects::Named;
use tortwin_model::generic::ActsOn;
use tortwin_model::product::ProductKey;
use tortwin_study::Result;

/// The thresholds of the selection.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Options {
    /// A candidate must lower the BIC by more than this (a negative number).
    pub bic_threshold: f64,
    /// A candidate must explain at least this share of what the current
    /// model leaves above the noise (`(SSE0 − SSE1) / (SSE0 − n σ̂²)`): an
    /// effect that removes only a sliver of a large residual is not its
    /// cause, however significant the sliver.
    pub min_excess_share: f64,
    /// After selection, a RMSE above this times the noise estimate is
    /// reported as an unexplained residual.
    pub unexplained_ratio: f64,
    /// At most this many effects are added (0: calibrate only).
    pub max_steps: usize,
    /// Calibrate the site's constants first, and with the effects found
    /// (docs/spec/interfaces.md, "Site constants").
    pub calibrate: bool,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            bic_threshold: -10.0,
            min_excess_share: 0.25,
            unexplained_ratio: 1.1,
            max_steps: Named::ALL.len(),
            calibrate: true,
        }
    }
}

pub use calibrate::{Calibration, Combination, SiteConstant};
pub use tortwin_study::progress::{Progress, Silent};
// What a `Discovery` holds, from the files that compute it.
pub use describe::Location;
pub use diagnose::{BinMean, CovariateScore};
pub use fit::{Blocking, Cost, CrossValidation, Fold, Stage, StageCost};
pub use screen::{Outliers, Screened, Screening};

/// An effect switched on, with its parameters by name (interfaces.md,
/// report.json): a named effect, or a generic term with its acts_on,
/// driver, form, scope and a sentence for an engineer.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EffectParams {
    pub name: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub acts_on: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub driver: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub form: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scope: Option<BTreeMap<String, String>>,
    pub params: BTreeMap<String, serde_json::Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// `physics` or `data quality` (a term on `measurement`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub kind: Option<String>,
}

impl EffectParams {
    /// Whether two entries are the same effect (whatever their parameters).
    pub(crate) fn same_effect(&self, other: &EffectParams) -> bool {
        self.name == other.name
            && self.acts_on == other.acts_on
            && self.driver == other.driver
            && self.form == other.form
            && self.scope == other.scope
            && (self.name != "generic"
                || self.params.get("t0_utc") == other.params.get("t0_utc")
                    && self.params.get("x0") == other.params.get("x0"))
    }

    /// `name (p = v, ...)` for people.
    /// Whether `c` (a candidate of a step) is this effect.
    fn is_candidate(&self, c: &CandidateResult) -> bool {
        match (&self.acts_on, &self.driver, &self.form) {
            (Some(a), Some(d), Some(f)) => {
                c.name == "generic" && c.label.starts_with(&format!("generic {a} × {d} ({f}"))
            }
            _ => c.name == self.name && c.name != "generic",
        }
    }

    pub fn text(&self) -> String {
        let params: Vec<String> = self
            .params
            .iter()
            .map(|(k, v)| match v.as_f64() {
                Some(x) => format!("{k} = {}", fmt_param(x)),
                None => format!("{k} = {}", v.as_str().unwrap_or("?")),
            })
            .collect();
        let head = match (&self.acts_on, &self.driver, &self.form) {
            (Some(a), Some(d), Some(f)) => format!("generic {a} × {d} ({f}{})", self.scope_text()),
            (Some(a), _, _) => format!(
                "generic {a} offset ({})",
                self.scope_text().trim_start_matches("; ")
            ),
            _ => self.name.clone(),
        };
        if params.is_empty() {
            head
        } else {
            format!("{head} ({})", params.join(", "))
        }
    }

    fn scope_text(&self) -> String {
        match &self.scope {
            Some(s) if !s.is_empty() => format!(
                "; {}",
                s.iter()
                    .map(|(k, v)| format!("{k} {v}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            _ => String::new(),
        }
    }
}

/// One candidate at one step.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateResult {
    pub name: String,
    /// The name, or a generic term's acts_on, driver, form and scope.
    pub label: String,
    /// Fitted on every day.
    pub params: BTreeMap<String, f64>,
    pub sse: f64,
    pub rmse: f64,
    /// Parameters fitted (Δk).
    pub k: usize,
    pub delta_bic: f64,
    pub passes_bic: bool,
    /// Share of the current model's excess over the noise this candidate
    /// removes (`None` without a noise estimate, or with no excess).
    pub excess_share: Option<f64>,
    pub passes_share: bool,
    /// Blocked-by-day cross-validation; computed for candidates that pass
    /// the BIC and the share, in order of their BIC drop, until one passes.
    pub cv: Option<CrossValidation>,
    pub passes_cv: Option<bool>,
    /// Blocked-by-site cross-validation, for a candidate that passes by
    /// day (with measurements at two sites or more).
    pub cv_site: Option<CrossValidation>,
    pub passes_cv_site: Option<bool>,
    pub engine_runs: usize,
    /// A generic term fitted with the site constant that scales its
    /// quantity beside it: that constant, and the term's BIC drop without
    /// it (what the constant bought is the difference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub beside: Option<ConstantBeside>,
    /// The fit was stopped after its first look: even optimistically it
    /// could not come near the step's best (`params`, `sse` and
    /// `delta_bic` are its best point so far).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_stopped: Option<FitStopped>,
}

/// A candidate's fit stopped early ([`CandidateResult::fit_stopped`]).
#[derive(Debug, Clone, Serialize)]
pub struct FitStopped {
    /// The BIC drop its fit could reach at best, optimistically.
    pub optimistic_delta_bic: f64,
}

/// The site constant a candidate was fitted with.
#[derive(Debug, Clone, Serialize)]
pub struct ConstantBeside {
    pub constant: String,
    pub value: f64,
    pub delta_bic_alone: f64,
}

impl CandidateResult {
    /// The BIC window in which contenders of another kind are weighed
    /// against this one with the site's constants beside them: the BIC
    /// threshold, or what a constant fitted beside it bought, if more
    /// (the rivals must have constants of their own to compete).
    fn rivals_window(&self, options: &Options) -> f64 {
        let bought = self
            .beside
            .as_ref()
            .map_or(0.0, |b| b.delta_bic_alone - self.delta_bic);
        options.bic_threshold.abs().max(bought)
    }
}

/// One round of the forward selection.
#[derive(Debug, Clone, Serialize)]
pub struct Step {
    pub step: usize,
    /// The model the candidates are tried on.
    pub model_effects: Vec<EffectParams>,
    pub sse: f64,
    pub rmse: f64,
    /// The current model's held-out SSE: each block predicted with the
    /// current parameters (fitted on every block, which favours the current
    /// model: a candidate must beat it all the same). The SSE itself.
    pub cv_sse: f64,
    /// The current model's SSE per day and per measured site.
    pub sse_by_day: Vec<f64>,
    pub sse_by_site: Vec<f64>,
    /// What the screening of the generic terms saw.
    pub screening: screen::Screening,
    /// Best BIC drop first.
    pub candidates: Vec<CandidateResult>,
    pub accepted: Option<String>,
    /// Close contenders of another kind told apart with the site's
    /// constants calibrated beside each (their BIC against the current
    /// model, the constants moved counted), where the recording moved no
    /// constant yet.
    pub calibrated_beside: Vec<(String, f64)>,
    /// An effect taken out again after the step: the model no longer needs it.
    pub removed: Option<String>,
    /// The model after the step (after the joint refit).
    pub rmse_after: f64,
    pub effects_after: Vec<EffectParams>,
}

/// A residual no known effect explains.
#[derive(Debug, Clone, Serialize)]
pub struct Unexplained {
    pub rmse: f64,
    pub noise_estimate: f64,
    pub ratio: f64,
    /// The covariate the remaining residual follows most closely.
    pub covariate: String,
    pub description: String,
    pub eta2: f64,
    /// The three covariates it follows most closely, with eta².
    pub follows: Vec<(String, f64)>,
    /// Where it lives: site, rail, time window, distance.
    pub location: Option<describe::Location>,
}

/// Everything a run of the workflow found (report.json is this, in order).
#[derive(Debug, Clone, Serialize)]
pub struct Discovery {
    /// Effects the workflow added (not those of the starting model).
    pub effects_found: Vec<EffectParams>,
    /// Every `[product]` constant examined, as the final model has it
    /// (interfaces.md, "Site constants"); empty without calibration.
    pub site_constants: Vec<SiteConstant>,
    /// RMSE over the measurements used (all but gross outliers), before
    /// and after: what a replay with model.toml gives when there are none.
    pub rmse_before: f64,
    pub rmse_after: f64,
    /// sigma of the measurements, from axle-to-axle residual differences.
    pub noise_estimate: Option<f64>,
    /// One paragraph: what was found, or that nothing is missing.
    pub verdict: String,
    pub recording: String,
    pub measurements: usize,
    /// Measurements the fits use (all but the gross outliers).
    pub measurements_used: usize,
    /// The measurements treated as gross errors, and where.
    pub outliers: screen::Outliers,
    /// RMSE of the final model over every measurement, outliers included
    /// (`rmse_after` leaves them out).
    pub rmse_after_all_rows: f64,
    pub days: usize,
    /// The starting model's effects (from --config), and the final model's.
    pub start_effects: Vec<EffectParams>,
    pub model_effects: Vec<EffectParams>,
    /// Step 0: the site's constants calibrated on the starting model
    /// (before any effect is looked for).
    pub calibration_start: Option<Calibration>,
    /// The final calibration, with the effects found fitted jointly.
    pub calibration: Option<Calibration>,
    /// Step 0: the starting model's effects refitted (if it has any).
    pub start_refit: Option<Vec<EffectParams>>,
    pub steps: Vec<Step>,
    /// (label, RMSE): the starting model, after step 0, after each added effect.
    pub rmse_by_step: Vec<(String, f64)>,
    pub covariates_before: Vec<CovariateScore>,
    pub covariates_after: Vec<CovariateScore>,
    pub unexplained: Option<Unexplained>,
    pub options: Options,
    pub engine_runs: usize,
    /// Replays plus read-outs, continued replays and replays with tangents
    /// in replays (measured).
    pub run_equivalents: f64,
    /// The replay `run_equivalents` are counted in: the mean time (ms) of
    /// this run's replays from the start but the first (`engine_runs - 1`
    /// of them), measured (the machine's speed and a replay's warm-up move
    /// it: a run of few replays rests on early ones).
    pub replay_ms: Option<f64>,
    /// What each stage cost.
    pub cost: Vec<fit::StageCost>,
    pub elapsed_s: f64,
    /// The recording and configuration read, the starting model, the
    /// version and the command line (set by the job that writes the report).
    pub provenance: Option<Provenance>,
    #[serde(skip)]
    pub start: ModelConfig,
    #[serde(skip)]
    pub model: ModelConfig,
    #[serde(skip)]
    pub residual_before: Vec<f64>,
    /// After step 0's calibration (the starting model's residual without it).
    #[serde(skip)]
    pub residual_calibrated: Vec<f64>,
    #[serde(skip)]
    pub residual_after: Vec<f64>,
}

impl Discovery {
    /// The replays with tangents (the calibration's Jacobians).
    pub fn tangent_runs(&self) -> usize {
        self.cost.iter().map(|s| s.cost.tangent_runs).sum()
    }
}

/// The effects on in `cfg`, with their parameters: the named ones in the
/// order of effects.md, then the generic terms in their order.
pub(crate) fn effects_of(cfg: &ModelConfig) -> Vec<EffectParams> {
    let mut list: Vec<EffectParams> = Candidate::all()
        .iter()
        .filter_map(|c| {
            c.get(&cfg.effects).map(|p| EffectParams {
                name: c.name().to_string(),
                acts_on: None,
                driver: None,
                form: None,
                scope: None,
                params: c
                    .named(&p)
                    .into_iter()
                    .map(|(k, v)| (k, serde_json::Value::from(v)))
                    .collect(),
                description: None,
                kind: None,
            })
        })
        .collect();
    for term in &cfg.effects.generic {
        let mut params: BTreeMap<String, serde_json::Value> = term
            .params()
            .into_iter()
            .map(|(k, v)| (k.to_string(), serde_json::Value::from(v)))
            .collect();
        if let Some(t0) = term.t0_utc() {
            params.insert("t0_utc".into(), serde_json::Value::from(t0));
        }
        let (driver, form) = match term.effect {
            TermEffect::Factor { driver, form } => (
                Some(driver.name().to_string()),
                Some(form.kind().name().to_string()),
            ),
            TermEffect::Offset { .. } => (None, None),
        };
        list.push(EffectParams {
            name: "generic".into(),
            acts_on: Some(term.acts_on.name().to_string()),
            driver,
            form,
            scope: Some(
                term.scope()
                    .into_iter()
                    .map(|(k, v)| (k.to_string(), v))
                    .collect(),
            ),
            params,
            description: None,
            kind: Some(
                if term.acts_on == ActsOn::Measurement {
                    "data quality"
                } else {
                    "physics"
                }
                .into(),
            ),
        });
    }
    list
}

/// The name of the site's constants as a candidate of a step.
pub const SITE_CONSTANTS: &str = "site_constants";

/// Measured minus `simulated`, row by row.
fn residual_of(data: &Dataset, simulated: &[f64]) -> Vec<f64> {
    data.rows
        .iter()
        .zip(simulated)
        .map(|(r, s)| r.measured - s)
        .collect()
}

fn rmse(sse: f64, n: usize) -> f64 {
    (sse / n.max(1) as f64).sqrt()
}

/// Residuals with the outliers' set to NaN (left out of the diagnosis).
fn screened(residual: &[f64], active: &[bool]) -> Vec<f64> {
    residual
        .iter()
        .zip(active)
        .map(|(&r, &a)| if a { r } else { f64::NAN })
        .collect()
}

/// Runs the workflow on `data` from the model `start`.
pub fn discover(
    data: &Dataset,
    start: &ModelConfig,
    options: &Options,
    progress: &dyn Progress,
) -> Result<Discovery> {
    let t0 = Instant::now();
    tortwin_engine::terms::check_terms_against(&start.effects.generic, &data.section, "--config")?;

    progress.stage("replaying with the starting model");
    // Gross outliers first: nothing after this sees them.
    let simulated_start = data.simulate(start)?;
    let raw_residual = residual_of(data, &simulated_start);
    let outliers = screen::outliers(data, &raw_residual);
    let ev = Evaluator::new(data, outliers.active.clone(), progress);
    let n = ev.n_active();
    let drivers = Drivers::of(data);

    let (residual_before, eval_before) = ev.residuals(start)?;
    let rmse_before = rmse(eval_before.sse, n);
    let clean_before = screened(&residual_before, &ev.active);
    let noise_estimate = diagnose::noise_estimate(data, &clean_before);
    let covariates_before = diagnose::rank(data, &clean_before);

    let mut current = start.clone();
    let mut sse = eval_before.sse;
    // The noise estimate of the selection: an effect that varies from axle
    // to axle (a load-driven one) inflates the first estimate, so it is
    // estimated again as the model grows, the smallest kept.
    let noise_now = noise_estimate;
    let accepted: Vec<Candidate> = Candidate::all()
        .into_iter()
        .filter(|c| c.get(&start.effects).is_some())
        .collect();
    // The effects of the starting model come first in `accepted`: they are
    // never taken out.
    let starting = accepted.len();
    let mut rmse_by_step = vec![("starting model".to_string(), rmse_before)];

    // Step 0: the site's constants. A constant that differs for the whole
    // recording is the site's, not an effect: calibrated before any effect
    // is looked for, and offered to the search as the first candidate of
    // every step until it is taken. Taken outright, the constants would
    // average away a strong effect they can mimic (a reservoir at the wheel
    // edge is matched to the noise by muC 2.5 times the laboratory's and kt
    // at 40 %): the data decide which explains them better (BIC).
    let mut calibration_start: Option<Calibration> = None;
    // The site's constants were taken by a step, these fitted.
    let constants_in = false;
    let constant_keys: Vec<ProductKey> = Vec::new();
    let mut residual_calibrated = residual_before.clone();
    if options.calibrate {
        progress.stage("step 0: calibrating the site's constants");
        // The starting model's own effects are fitted with the constants
        // (a poor starting value would otherwise pull them).
        let own: Vec<Candidate> = accepted.iter().filter(|c| c.dims() > 0).cloned().collect();
        let c = calibrate::calibrate(&ev, &current, &start.product, &own, noise_estimate)?;
        residual_calibrated = ev.residuals(&c.model)?.0;
        calibration_start = Some(c);
    }

    // Step 0: the starting model's own effects, refitted.
    let mut start_refit = None;
    let mut start_refit_model: Option<ModelConfig> = None;
    if accepted.iter().any(|c| c.dims() > 0) {
        progress.stage("step 0: refitting the starting model's effects");
        let space = Space {
            base: current.clone(),
            slots: accepted.clone(),
        };
        let fit = fit::fit(&ev, &space, Start::Warm(space.units_of(&current)), None)?;
        if fit.eval.sse < sse {
            current = space.config(&fit.u);
            sse = fit.eval.sse;
        }
        start_refit = Some(effects_of(&current));
        start_refit_model = Some(current.clone());
        rmse_by_step.push(("starting effects refitted".to_string(), rmse(sse, n)));
    }

    let simulated_current = if current == *start {
        simulated_start
    } else {
        ev.simulate(&current)?
    };
    let mut search = Search {
        data,
        start,
        options,
        progress,
        ev: &ev,
        drivers: &drivers,
        n,
        current,
        sse,
        simulated_current,
        noise_now,
        accepted,
        starting,
        rmse_by_step,
        calibration_start,
        start_refit_model,
        constants_in,
        constant_keys,
        warm: HashMap::new(),
        responses: screen::ResponseCache::default(),
        hopeless: Vec::new(),
        steps: Vec::new(),
    };
    for step in 1..=options.max_steps {
        if !search.step(step)? {
            break;
        }
    }
    let calibration = search.calibrate_with_effects()?;
    let Search {
        current,
        noise_now,
        rmse_by_step,
        calibration_start,
        steps,
        ..
    } = search;

    progress.stage("replaying with the final model");
    let (residual_after, eval_after) = ev.residuals(&current)?;
    let rmse_after = rmse(eval_after.sse, n);
    let clean_after = screened(&residual_after, &ev.active);
    let covariates_after = diagnose::rank(data, &clean_after);
    let noise_estimate = noise_now;
    let unexplained = match (noise_estimate, covariates_after.first()) {
        (Some(noise), Some(top)) if rmse_after > options.unexplained_ratio * noise => {
            Some(Unexplained {
                rmse: rmse_after,
                noise_estimate: noise,
                ratio: rmse_after / noise,
                covariate: top.name.clone(),
                description: top.description.clone(),
                eta2: top.eta2,
                follows: covariates_after
                    .iter()
                    .take(3)
                    .map(|c| (c.name.clone(), c.eta2))
                    .collect(),
                location: describe::locate(data, &clean_after, noise),
            })
        }
        _ => None,
    };
    let start_effects = effects_of(start);
    let mut model_effects = effects_of(&current);
    for (e, term) in model_effects
        .iter_mut()
        .filter(|e| e.name == "generic")
        .zip(&current.effects.generic)
    {
        e.description = Some(describe::term(term, data, &drivers));
    }
    let effects_found: Vec<EffectParams> = model_effects
        .iter()
        .filter(|e| !start_effects.iter().any(|s| s.same_effect(e)))
        .cloned()
        .collect();
    let mut verdict = verdict(
        &effects_found,
        rmse_before,
        rmse_after,
        noise_estimate,
        unexplained.as_ref(),
        calibration.as_ref(),
    );
    verdict.push_str(&ties(&steps));
    verdict.push_str(&constants_or_effect(&steps, &effects_found, options));
    let rmse_after_all_rows = {
        let all: f64 = residual_after.iter().map(|r| r * r).sum();
        rmse(all, residual_after.len())
    };
    Ok(Discovery {
        effects_found,
        site_constants: calibration
            .as_ref()
            .map(|c| c.constants.clone())
            .unwrap_or_default(),
        rmse_before,
        rmse_after,
        noise_estimate,
        verdict,
        recording: data.path.display().to_string(),
        measurements: data.rows.len(),
        measurements_used: n,
        outliers,
        rmse_after_all_rows,
        days: data.days.len(),
        start_effects,
        model_effects,
        calibration_start,
        calibration,
        start_refit,
        steps,
        rmse_by_step,
        covariates_before,
        covariates_after,
        unexplained,
        options: *options,
        engine_runs: ev.runs() + 1,
        run_equivalents: ev.cost.now().run_equivalents + 1.0,
        replay_ms: ev.cost.now().replay_ms(),
        cost: ev.cost.by_stage(),
        elapsed_s: t0.elapsed().as_secs_f64(),
        provenance: None,
        start: start.clone(),
        model: current,
        residual_before,
        residual_calibrated,
        residual_after,
    })
}

fn verdict(
    found: &[EffectParams],
    rmse_before: f64,
    rmse_after: f64,
    noise: Option<f64>,
    unexplained: Option<&Unexplained>,
    calibration: Option<&Calibration>,
) -> String {
    let noise_text = noise.map_or_else(
        || "the noise could not be estimated (no pairs of axles)".to_string(),
        |s| format!("the noise estimate is {s:.5}"),
    );
    // The site's constants first: what differs from the laboratory for the
    // whole recording is not an effect.
    let (mut text, model, rmse_text) = match calibration {
        Some(c) if !c.moved.is_empty() => (
            format!("{} ", c.summary),
            "With the site's constants calibrated, the model",
            format!("RMSE {rmse_before:.5} -> {rmse_after:.5}"),
        ),
        Some(c) => (
            format!("{} ", c.summary),
            "The model",
            format!("RMSE {rmse_after:.5}"),
        ),
        None => (String::new(), "The model", format!("RMSE {rmse_before:.5}")),
    };
    text.push_str(&if found.is_empty() {
        match unexplained {
            None => format!(
                "{model} explains the data to the noise level: no candidate effect passes \
                 ({rmse_text}; {noise_text}). No effect was added."
            ),
            Some(_) => format!(
                "No candidate effect passes, but the model does not explain the data to the noise \
                 level ({rmse_text}; {noise_text}). No effect was added."
            ),
        }
    } else {
        let names: Vec<String> = found.iter().map(EffectParams::text).collect();
        format!(
            "Found {}: RMSE {rmse_before:.5} -> {rmse_after:.5}; {noise_text}.",
            names.join(", ")
        )
    });
    if let (Some(_), false) = (unexplained, found.is_empty()) {
        text.push_str(
            " The effects found explain part of the residual; what is left may have a cause \
             they only stand in for.",
        );
    }
    for e in found.iter().filter(|e| e.description.is_some()) {
        text.push_str(&format!(" {}", e.description.as_deref().unwrap_or("")));
    }
    if let Some(u) = unexplained {
        text.push_str(&format!(
            " An unexplained residual remains (RMSE {:.5} = {:.2} x the noise estimate); it follows \
             {} most closely (eta² = {:.3}). No known effect explains it.",
            u.rmse, u.ratio, u.covariate, u.eta2
        ));
        if let Some(at) = &u.location {
            let distance = at
                .distance_from_applicator_m
                .map_or_else(String::new, |d| format!(", {d:.0} m from the applicator"));
            text.push_str(&format!(
                " It lives at site {} on the {} rail{distance}, from {} to {} ({} measurements, \
                 mean residual {:+.4}, {:.0} % of the excess over the noise): look there.",
                at.site,
                at.rail,
                at.from_utc,
                at.to_utc,
                at.measurements,
                at.mean_residual,
                100.0 * at.share_of_excess
            ));
        }
    }
    text
}

/// What the recording could not decide: for each accepted candidate, the
/// others of its step that fit exactly as well (the same SSE to 1e-9), in
/// words; empty when there are none.
fn ties(steps: &[Step]) -> String {
    let mut text = String::new();
    for step in steps {
        let Some(accepted) = &step.accepted else {
            continue;
        };
        let Some(chosen) = step.candidates.iter().find(|c| &c.label == accepted) else {
            continue;
        };
        let equal: Vec<&str> = step
            .candidates
            .iter()
            // A named effect and its generic equivalent tie by construction
            // (temperature_consumption is consumption × exp of temperature):
            // only generic terms of different drivers or quantities count.
            .filter(|c| chosen.name == "generic" && c.name == "generic")
            .filter(|c| c.label != chosen.label)
            .filter(|c| (c.sse - chosen.sse).abs() <= 1e-9 * chosen.sse)
            .map(|c| c.label.as_str())
            .collect();
        if !equal.is_empty() {
            text.push_str(&format!(
                concat!(
                    " The recording cannot tell {} from {}: they fit exactly as well, so these ",
                    "measurements cannot decide which one acts (where drivers tie, the more ",
                    "direct one is named: rain, temperature, the wheel, humidity, time)."
                ),
                accepted,
                equal.join(", ")
            ));
        }
    }
    text
}

/// Where the site's constants were preferred to an effect that describes
/// the measurements nearly as well (within the BIC threshold: a constant
/// is the plainer story), the effect in words: the recording cannot tell
/// them apart, another might (a wider range of the effect's driver).
/// Empty otherwise.
fn constants_or_effect(steps: &[Step], found: &[EffectParams], options: &Options) -> String {
    let mut text = String::new();
    for step in steps {
        let Some(constants) = step.candidates.iter().find(|c| c.name == SITE_CONSTANTS) else {
            continue;
        };
        let rival = step
            .candidates
            .iter()
            .filter(|c| c.name != SITE_CONSTANTS && c.passes_bic && c.passes_share)
            .filter(|c| !found.iter().any(|e| e.is_candidate(c)))
            .min_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
        let Some(rival) = rival else {
            continue;
        };
        let apart = rival.delta_bic - constants.delta_bic;
        let taken = step.accepted.as_deref() != Some(rival.label.as_str());
        if taken && apart.abs() <= options.bic_threshold.abs() {
            let params: Vec<String> = rival
                .params
                .iter()
                .map(|(k, v)| format!("{k} = {}", fmt_param(*v)))
                .collect();
            text.push_str(&format!(
                " The candidate {} ({}) describes these measurements nearly as well as the \
                 site's constants \
                 ({:.1} BIC units apart, within the threshold of {:.0}): this recording cannot \
                 tell that effect from the constants, and the constants, the plainer story, are \
                 taken; a recording over a wider range of its driver could tell them apart.",
                rival.label,
                params.join(", "),
                apart,
                options.bic_threshold.abs()
            ));
            break;
        }
    }
    text
}

/// A parameter value for people: 4 significant digits.
pub fn fmt_param(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if v.abs() >= 1e4 || v.abs() < 1e-3 {
        format!("{v:.3e}")
    } else {
        let digits = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.digits$}")
    }
}
