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
//!    [`diagnose::rank`] ranks them by the share of the residual variance
//!    they explain (eta²). [`diagnose::noise_estimate`] estimates the
//!    measurement noise from axle-to-axle differences, independently of
//!    the fit.
//! 3. **Candidates.** Every effect of ../shared/spec/effects.md not yet in
//!    the model is fitted by re-running the engine ([`fit`]), the candidates
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
//!    jointly, and the search repeats until no candidate passes.
//! 5. **What is left.** If the final RMSE is still well above the noise
//!    estimate ([`Options::unexplained_ratio`]), the remaining residual is
//!    reported with the covariate it follows most closely: no effect is
//!    forced onto it.
//!
//! Effects already in the starting configuration stay on and are refitted
//! first (step 0).

pub mod data;
pub mod diagnose;
pub mod fit;
pub mod report;

use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

use anyhow::Result;
use rayon::prelude::*;
use serde::Serialize;

use crate::config::ModelConfig;
use data::Dataset;
use diagnose::CovariateScore;
use fit::{Blocking, Candidate, CrossValidation, Evaluator, Space, Start};

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
    /// At most this many effects are added.
    pub max_steps: usize,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            bic_threshold: -10.0,
            min_excess_share: 0.25,
            unexplained_ratio: 1.1,
            max_steps: Candidate::ALL.len(),
        }
    }
}

/// Progress of a run, for a display: called from several threads.
pub trait Progress: Sync {
    /// A new stage ("step 1: fitting 6 candidates").
    fn stage(&self, _message: &str) {}
    /// `runs` engine runs done so far.
    fn runs(&self, _runs: usize) {}
}

/// No display.
pub struct Silent;
impl Progress for Silent {}

/// An effect switched on, with its parameters by name.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EffectParams {
    pub name: String,
    pub params: BTreeMap<String, f64>,
}

/// One candidate at one step.
#[derive(Debug, Clone, Serialize)]
pub struct CandidateResult {
    pub name: String,
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
    /// Best BIC drop first.
    pub candidates: Vec<CandidateResult>,
    pub accepted: Option<String>,
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
}

/// Everything a run of the workflow found (report.json is this, in order).
#[derive(Debug, Clone, Serialize)]
pub struct Discovery {
    /// Effects the workflow added (not those of the starting model).
    pub effects_found: Vec<EffectParams>,
    pub rmse_before: f64,
    pub rmse_after: f64,
    /// sigma of the measurements, from axle-to-axle residual differences.
    pub noise_estimate: Option<f64>,
    /// One paragraph: what was found, or that nothing is missing.
    pub verdict: String,
    pub recording: String,
    pub measurements: usize,
    pub days: usize,
    /// The starting model's effects (from --config), and the final model's.
    pub start_effects: Vec<EffectParams>,
    pub model_effects: Vec<EffectParams>,
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
    pub elapsed_s: f64,
    #[serde(skip)]
    pub start: ModelConfig,
    #[serde(skip)]
    pub model: ModelConfig,
    #[serde(skip)]
    pub residual_before: Vec<f64>,
    #[serde(skip)]
    pub residual_after: Vec<f64>,
}

/// The effects on in `cfg`, with their parameters.
pub fn effects_of(cfg: &ModelConfig) -> Vec<EffectParams> {
    Candidate::ALL
        .iter()
        .filter_map(|c| {
            c.get(&cfg.effects).map(|p| EffectParams {
                name: c.name().to_string(),
                params: c.named(&p),
            })
        })
        .collect()
}

fn rmse(sse: f64, n: usize) -> f64 {
    (sse / n.max(1) as f64).sqrt()
}

/// Runs the workflow on `data` from the model `start`.
pub fn discover(
    data: &Dataset,
    start: &ModelConfig,
    options: &Options,
    progress: &dyn Progress,
) -> Result<Discovery> {
    let t0 = Instant::now();
    let n = data.rows.len();
    let ev = Evaluator::new(data, |runs| progress.runs(runs));

    progress.stage("replaying with the starting model");
    let (residual_before, eval_before) = ev.residuals(start)?;
    let rmse_before = rmse(eval_before.sse, n);
    let noise_estimate = diagnose::noise_estimate(data, &residual_before);
    let covariates_before = diagnose::rank(data, &residual_before);

    let mut current = start.clone();
    let mut sse = eval_before.sse;
    let mut accepted: Vec<Candidate> = Candidate::ALL
        .into_iter()
        .filter(|c| c.get(&start.effects).is_some())
        .collect();
    let mut rmse_by_step = vec![("starting model".to_string(), rmse_before)];

    // Step 0: the starting model's own effects, refitted.
    let mut start_refit = None;
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
        rmse_by_step.push(("starting effects refitted".to_string(), rmse(sse, n)));
    }

    let has_high_rail = data.section.rails.iter().any(|r| r == "high");
    let mut warm: HashMap<Candidate, Vec<f64>> = HashMap::new();
    let mut steps = Vec::new();
    let ln_n = (n as f64).ln();
    for step in 1..=options.max_steps {
        let candidates: Vec<Candidate> = Candidate::ALL
            .into_iter()
            .filter(|c| !accepted.contains(c))
            // Without a rail named `high` the effect does nothing.
            .filter(|c| *c != Candidate::BogieBands || has_high_rail)
            .collect();
        if candidates.is_empty() {
            break;
        }
        progress.stage(&format!(
            "step {step}: fitting {} candidate effects",
            candidates.len()
        ));
        let fits: Vec<(Candidate, Space, fit::Fit)> = candidates
            .par_iter()
            .map(|&c| {
                let space = Space {
                    base: current.clone(),
                    slots: vec![c],
                };
                let start = warm
                    .get(&c)
                    .map_or(Start::Fresh, |u| Start::Warm(u.clone()));
                fit::fit(&ev, &space, start, None).map(|f| (c, space, f))
            })
            .collect::<Result<_>>()?;
        let mut results: Vec<(CandidateResult, Space, Vec<f64>)> = fits
            .into_iter()
            .map(|(c, space, f)| {
                warm.insert(c, f.u.clone());
                let k = c.dims();
                let delta_bic = n as f64 * (f.eval.sse / sse).ln() + k as f64 * ln_n;
                let excess = noise_estimate
                    .map(|s| sse - n as f64 * s * s)
                    .filter(|e| *e > 0.0);
                let excess_share = excess.map(|e| (sse - f.eval.sse) / e);
                let params = space.params(&f.u).pop().unwrap_or_default();
                (
                    CandidateResult {
                        name: c.name().to_string(),
                        params: c.named(&params),
                        sse: f.eval.sse,
                        rmse: rmse(f.eval.sse, n),
                        k,
                        delta_bic,
                        passes_bic: delta_bic < options.bic_threshold,
                        excess_share,
                        passes_share: excess_share.is_none_or(|x| x >= options.min_excess_share),
                        cv: None,
                        passes_cv: None,
                        cv_site: None,
                        passes_cv_site: None,
                        engine_runs: f.runs,
                    },
                    space,
                    f.u,
                )
            })
            .collect();
        results.sort_by(|a, b| a.0.delta_bic.total_cmp(&b.0.delta_bic));

        // The current model's held-out SSE: every day predicted as it is.
        let cv_current = sse;
        let mut chosen = None;
        for (k, (result, space, u)) in results.iter_mut().enumerate() {
            if !(result.passes_bic && result.passes_share) {
                continue;
            }
            progress.stage(&format!(
                "step {step}: cross-validating {} by day",
                result.name
            ));
            let cv = fit::cross_validate(&ev, space, u, Blocking::Day)?;
            let passes = cv.held_out_sse < cv_current;
            result.engine_runs += cv.runs;
            result.cv = Some(cv);
            result.passes_cv = Some(passes);
            if !passes {
                continue;
            }
            if ev.sites.len() >= 2 {
                progress.stage(&format!(
                    "step {step}: cross-validating {} by site",
                    result.name
                ));
                let cv = fit::cross_validate(&ev, space, u, Blocking::Site)?;
                let passes = cv.held_out_sse < cv_current;
                result.engine_runs += cv.runs;
                result.cv_site = Some(cv);
                result.passes_cv_site = Some(passes);
                if !passes {
                    continue;
                }
            }
            chosen = Some(k);
            break;
        }
        let now = ev.evaluate(&current)?;
        let mut record = Step {
            step,
            model_effects: effects_of(&current),
            sse,
            rmse: rmse(sse, n),
            cv_sse: cv_current,
            sse_by_day: now.sse_by_day.clone(),
            sse_by_site: now.sse_by_site.clone(),
            candidates: results.iter().map(|r| r.0.clone()).collect(),
            accepted: None,
            rmse_after: rmse(sse, n),
            effects_after: effects_of(&current),
        };
        let Some(k) = chosen else {
            steps.push(record);
            break;
        };
        let (result, space, u) = &results[k];
        let Some(&c) = space.slots.first() else {
            break;
        };
        current = space.config(u);
        sse = result.sse;
        accepted.push(c);
        record.accepted = Some(c.name().to_string());

        // Refit every effect of the model together: the one just added was
        // fitted with the others held at values that had to make up for it.
        let joint = Space {
            base: current.clone(),
            slots: accepted.clone(),
        };
        if joint.dims() > c.dims() {
            progress.stage(&format!("step {step}: refitting every effect jointly"));
            let fit = fit::fit(&ev, &joint, Start::Warm(joint.units_of(&current)), None)?;
            if fit.eval.sse < sse {
                current = joint.config(&fit.u);
                sse = fit.eval.sse;
            }
        }
        record.rmse_after = rmse(sse, n);
        record.effects_after = effects_of(&current);
        rmse_by_step.push((format!("+ {}", c.name()), rmse(sse, n)));
        steps.push(record);
    }

    progress.stage("replaying with the final model");
    let (residual_after, eval_after) = ev.residuals(&current)?;
    let rmse_after = rmse(eval_after.sse, n);
    let covariates_after = diagnose::rank(data, &residual_after);
    let unexplained = match (noise_estimate, covariates_after.first()) {
        (Some(noise), Some(top)) if rmse_after > options.unexplained_ratio * noise => {
            Some(Unexplained {
                rmse: rmse_after,
                noise_estimate: noise,
                ratio: rmse_after / noise,
                covariate: top.name.clone(),
                description: top.description.clone(),
                eta2: top.eta2,
            })
        }
        _ => None,
    };
    let start_effects = effects_of(start);
    let model_effects = effects_of(&current);
    let effects_found: Vec<EffectParams> = model_effects
        .iter()
        .filter(|e| !start_effects.iter().any(|s| s.name == e.name))
        .cloned()
        .collect();
    let verdict = verdict(
        &effects_found,
        rmse_before,
        rmse_after,
        noise_estimate,
        unexplained.as_ref(),
    );
    Ok(Discovery {
        effects_found,
        rmse_before,
        rmse_after,
        noise_estimate,
        verdict,
        recording: data.path.display().to_string(),
        measurements: n,
        days: data.days.len(),
        start_effects,
        model_effects,
        start_refit,
        steps,
        rmse_by_step,
        covariates_before,
        covariates_after,
        unexplained,
        options: *options,
        engine_runs: ev.runs(),
        elapsed_s: t0.elapsed().as_secs_f64(),
        start: start.clone(),
        model: current,
        residual_before,
        residual_after,
    })
}

fn verdict(
    found: &[EffectParams],
    rmse_before: f64,
    rmse_after: f64,
    noise: Option<f64>,
    unexplained: Option<&Unexplained>,
) -> String {
    let noise_text = noise.map_or_else(
        || "the noise could not be estimated (no pairs of axles)".to_string(),
        |s| format!("the noise estimate is {s:.5}"),
    );
    let mut text = if found.is_empty() {
        match unexplained {
            None => format!(
                "The model explains the data to the noise level: no candidate effect passes \
                 (RMSE {rmse_before:.5}; {noise_text}). Nothing was added."
            ),
            Some(_) => format!(
                "No candidate effect passes, but the model does not explain the data to the noise \
                 level (RMSE {rmse_before:.5}; {noise_text}). Nothing was added."
            ),
        }
    } else {
        let names: Vec<String> = found
            .iter()
            .map(|e| {
                let params: Vec<String> = e
                    .params
                    .iter()
                    .map(|(k, v)| format!("{k} = {}", fmt_param(*v)))
                    .collect();
                if params.is_empty() {
                    e.name.clone()
                } else {
                    format!("{} ({})", e.name, params.join(", "))
                }
            })
            .collect();
        format!(
            "Found {}: RMSE {rmse_before:.5} -> {rmse_after:.5}; {noise_text}.",
            names.join(", ")
        )
    };
    if let (Some(_), false) = (unexplained, found.is_empty()) {
        text.push_str(
            " The effects found explain part of the residual; what is left may have a cause \
             they only stand in for.",
        );
    }
    if let Some(u) = unexplained {
        text.push_str(&format!(
            " An unexplained residual remains (RMSE {:.5} = {:.2} x the noise estimate); it follows \
             {} most closely (eta² = {:.3}). No known effect explains it.",
            u.rmse, u.ratio, u.covariate, u.eta2
        ));
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
