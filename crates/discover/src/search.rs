//! The forward selection, step by step ([`Search::step`]): the
//! candidates of a step fitted and refined, the site's constants beside
//! them as one candidate, the best that passes taken, and what taking it
//! sets in motion (the joint refit, the backward checks). The order of the
//! stages and why each is there is the module doc of the crate.

use std::collections::{BTreeMap, HashMap};

use rayon::prelude::*;

use super::calibrate::{self, Calibration};
use super::data::Dataset;
use super::diagnose;
use super::fit::{self, Blocking, Candidate, Evaluator, Space, Start};
use super::screen::{self, Screening};
use super::space::{self, Drivers};
use super::{effects_of, fmt_param, residual_of, rmse, screened, SITE_CONSTANTS};
use super::{CandidateResult, ConstantBeside, FitStopped, Options, Step};
use tortwin_model::config::ModelConfig;
use tortwin_model::effects::Named;
use tortwin_model::generic::{ActsOn, Driver, FormKind};
use tortwin_model::product::{ProductKey, ProductParams};
use tortwin_recording::EventKind;
use tortwin_study::{Progress, Result};

/// The forward selection's state: the model so far and what each step
/// leaves for the next (warm starts, the screening's responses, the named
/// effects that failed), shared by its steps ([`Search::step`]).
pub(crate) struct Search<'a> {
    pub(crate) data: &'a Dataset,
    pub(crate) start: &'a ModelConfig,
    pub(crate) options: &'a Options,
    pub(crate) progress: &'a dyn Progress,
    pub(crate) ev: &'a Evaluator<'a>,
    pub(crate) drivers: &'a Drivers,
    /// Measurements the fits count.
    pub(crate) n: usize,
    pub(crate) current: ModelConfig,
    pub(crate) sse: f64,
    pub(crate) simulated_current: Vec<f64>,
    pub(crate) noise_now: Option<f64>,
    /// The effects in the model, the starting model's first.
    pub(crate) accepted: Vec<Candidate>,
    /// How many of `accepted` the starting model had (never taken out).
    pub(crate) starting: usize,
    pub(crate) rmse_by_step: Vec<(String, f64)>,
    pub(crate) calibration_start: Option<Calibration>,
    /// The starting model with its own effects refitted (step 0).
    pub(crate) start_refit_model: Option<ModelConfig>,
    /// The site's constants were taken by a step, these fitted.
    pub(crate) constants_in: bool,
    pub(crate) constant_keys: Vec<ProductKey>,
    pub(crate) warm: HashMap<Candidate, Vec<f64>>,
    pub(crate) responses: screen::ResponseCache,
    /// Named effects that did not pass the BIC at a step are not tried again.
    pub(crate) hopeless: Vec<Candidate>,
    pub(crate) steps: Vec<Step>,
}

impl<'a> Search<'a> {
    /// The constants once more, with the effects found fitted jointly: what
    /// the recording determines may differ now that the effects are in. An
    /// effect the calibrated constants make unnecessary (it made up for
    /// constants held where an earlier step had put them) is taken out, and
    /// the constants calibrated again. `None` without calibration.
    pub(crate) fn calibrate_with_effects(&mut self) -> Result<Option<Calibration>> {
        let (ev, start, options, progress) = (self.ev, self.start, self.options, self.progress);
        if !options.calibrate {
            return Ok(None);
        }
        progress.stage("calibrating the site's constants with the effects found");
        let noise_now = self.noise_now;
        let free: Vec<Candidate> = self
            .accepted
            .iter()
            .filter(|c| c.get(&self.current.effects).is_some())
            .cloned()
            .collect();
        match &self.calibration_start {
            // Nothing was added: step 0's calibration is the final one.
            Some(c0) if free.is_empty() && (c0.model == self.current || self.current == *start) => {
                self.current = c0.model.clone();
                Ok(Some(c0.clone()))
            }
            _ => {
                let mut c =
                    calibrate::calibrate(ev, &self.current, &start.product, &free, noise_now)?;
                self.current = c.model.clone();
                let dropped = drop_unneeded(
                    ev,
                    &mut self.accepted,
                    self.starting,
                    &mut self.current,
                    &start.product,
                    noise_now,
                    options,
                )?;
                if !dropped.is_empty() {
                    for d in &dropped {
                        progress.stage(&format!(
                            "{} is not needed with the site's constants",
                            d.label()
                        ));
                    }
                    let free: Vec<Candidate> =
                        free.into_iter().filter(|f| !dropped.contains(f)).collect();
                    c = calibrate::calibrate(ev, &self.current, &start.product, &free, noise_now)?;
                    self.current = c.model.clone();
                    self.rmse_by_step.push((
                        format!(
                            "- {} (not needed with the site's constants)",
                            dropped
                                .iter()
                                .map(Candidate::label)
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                        rmse(ev.evaluate(&self.current)?.sse, self.n),
                    ));
                }
                Ok(Some(c))
            }
        }
    }

    /// The candidates of step `step`: the named effects not in the model
    /// (warm where an earlier step fitted them; one whose earlier optimum no
    /// longer lowers the SSE left out), those the residual's signature
    /// brings back, and the generic terms the screening proposes; with the
    /// screening's record.
    fn candidates(&mut self, step: usize) -> Result<(Starts, Screening)> {
        let (data, ev, drivers, options, progress) = (
            self.data,
            self.ev,
            self.drivers,
            self.options,
            self.progress,
        );
        let (current, simulated_current, accepted) =
            (&self.current, &self.simulated_current, &self.accepted);
        let (noise_now, sse) = (self.noise_now, self.sse);
        let constants_beside = self.calibration_start.is_some() && !self.constants_in;
        let (hopeless, warm, responses) = (&mut self.hopeless, &mut self.warm, &mut self.responses);
        let has_high_rail = data.section.rails.iter().any(|r| r == "high");
        let ln_n = (self.n as f64).ln();
        // What the residual follows now: a covariate that is a catalogue
        // effect's signature (effects.md, "What each effect leaves in the
        // residuals") or a driver brings that effect and every term on
        // that driver back into this step, whatever they did before (a
        // strong term accepted first can hide a weaker effect until then).
        let mut forced: Vec<Driver> = Vec::new();
        if step > 1 {
            let residual_now = residual_of(data, simulated_current);
            let ranked = diagnose::rank(data, &screened(&residual_now, &ev.active));
            let top = ranked.first().map_or(0.0, |c| c.eta2_adjusted);
            for cov in ranked
                .iter()
                .take(2)
                .filter(|c| c.eta2_adjusted >= SIGNATURE_ETA2 && c.eta2_adjusted >= 0.5 * top)
            {
                let (named, driver) = signature_of(&cov.name);
                for n in named {
                    let c = Candidate::Named(n);
                    if hopeless.contains(&c) {
                        hopeless.retain(|h| *h != c);
                        warm.remove(&c);
                    }
                }
                forced.extend(driver);
            }
        }
        let mut candidates: Vec<(Candidate, Start)> = Candidate::all()
            .into_iter()
            .filter(|c| !accepted.contains(c))
            // Without a rail named `high` the effect does nothing.
            .filter(|c| *c != Candidate::Named(Named::BogieBands) || has_high_rail)
            .filter(|c| !hopeless.contains(c))
            .map(|c| {
                let start = warm
                    .get(&c)
                    .map_or(Start::Fresh, |u| Start::Warm(u.clone()));
                (c, start)
            })
            .collect();
        // The candidates of this step are built on the current model: a
        // time step continues from its state before the step.
        ev.pin_base(current)?;
        progress.stage(&format!("step {step}: screening the generic terms"));
        let screening_stage = ev.cost.enter(fit::Stage::Screening);
        let (generic, screening) = screen::propose(
            ev,
            drivers,
            current,
            simulated_current,
            noise_now,
            // ΔBIC < threshold needs n ln(SSE1/SSE0) < threshold − k ln n,
            // about a reduction of (|threshold| + k ln n) σ² for k = 1.
            noise_now.map_or(0.0, |s| (options.bic_threshold.abs() + ln_n) * s * s),
            &forced,
            constants_beside,
            responses,
        )?;
        drop(screening_stage);
        // A term on a direction already in the model (whatever its form
        // or range) would only stack on it.
        let in_model = |c: &Candidate| {
            let Candidate::Generic(g) = c else {
                return false;
            };
            accepted
                .iter()
                .any(|a| matches!(a, Candidate::Generic(h) if h.same_direction(g)))
        };
        let generic: Vec<(Candidate, Start)> = generic
            .into_iter()
            .filter(|(c, _)| !accepted.contains(c) && !hopeless.contains(c) && !in_model(c))
            .collect();
        // After a step: a named effect whose earlier optimum no longer
        // lowers the SSE at all was standing in for what was just added
        // (unless a generic term of its own family is a candidate: then it
        // is the better name for what that term finds).
        let families: Vec<Candidate> = generic
            .iter()
            .filter_map(|(c, _)| named_family(c))
            .collect();
        let stale: Vec<bool> = candidates
            .par_iter()
            .map(|(c, start)| match start {
                Start::Warm(u) if !c.is_generic() && !families.contains(c) => {
                    let space = Space {
                        base: current.clone(),
                        slots: vec![c.clone()],
                    };
                    Ok(ev.evaluate(&space.config(u))?.sse >= sse)
                }
                _ => Ok(false),
            })
            .collect::<Result<_>>()?;
        let mut stale = stale.into_iter();
        candidates.retain(|_| !stale.next().unwrap_or(false));
        candidates.extend(generic);
        Ok((candidates, screening))
    }

    /// Step `step` of the forward selection: its candidates
    /// ([`Search::candidates`]) fitted and refined, the site's constants
    /// beside them as one candidate, the best that passes taken (or none,
    /// and the search ends: `false`).
    pub(crate) fn step(&mut self, step: usize) -> Result<bool> {
        let (candidates, screening) = self.candidates(step)?;
        if candidates.is_empty() {
            return Ok(false);
        }
        let (mut results, more) = self.fit_candidates(step, &candidates)?;
        self.place_thresholds(step, &mut results)?;
        self.free_the_effects(step, &mut results)?;
        self.free_the_constants(step, &mut results)?;
        self.constant_beside_twins(step, &mut results, screening.beside_constant.clone())?;
        // A named effect that describes the data (nearly) as well as the
        // best generic term is the better statement: it goes first.
        prefer(&mut results, self.n, self.options);

        let constants = self.constants_candidate(step, &results)?;
        let constants_keys_now = constants.as_ref().map(|c| c.2.clone());
        let constants_pass = constants
            .as_ref()
            .filter(|(c, _, _)| c.passes_bic && c.passes_share)
            .map(|(c, _, _)| c.delta_bic);
        let starts: Vec<&(Candidate, Start)> = candidates.iter().chain(&more).collect();
        let (mut chosen, mut take_constants) =
            self.walk(step, &mut results, &starts, constants_pass)?;
        let mut pair_first = None;
        if let (false, Some(k), Some(constants)) = (take_constants, chosen, constants.as_ref()) {
            pair_first = self.pair_with_constants(step, &results, k, constants)?;
            if pair_first.is_some() {
                take_constants = true;
                chosen = None;
            }
        }
        let mut calibrated_beside = Vec::new();
        if let (false, false, Some(k), None, true) = (
            take_constants,
            self.constants_in,
            chosen,
            constants.as_ref(),
            self.calibration_start.is_some(),
        ) {
            let (k, scored) = self.calibrated_beside(step, &mut results, k)?;
            chosen = Some(k);
            calibrated_beside = scored;
        }

        let now = self.ev.evaluate(&self.current)?;
        let (sse, n) = (self.sse, self.n);
        let mut record = Step {
            step,
            model_effects: effects_of(&self.current),
            sse,
            rmse: rmse(sse, n),
            cv_sse: sse,
            sse_by_day: now.sse_by_day.clone(),
            sse_by_site: now.sse_by_site.clone(),
            screening,
            candidates: results.iter().map(|r| r.0.clone()).collect(),
            accepted: None,
            calibrated_beside,
            removed: None,
            rmse_after: rmse(sse, n),
            effects_after: effects_of(&self.current),
        };
        if let Some((c, _, _)) = &constants {
            let at = record
                .candidates
                .iter()
                .position(|r| r.delta_bic > c.delta_bic)
                .unwrap_or(record.candidates.len());
            record.candidates.insert(at, c.clone());
        }
        if chosen.is_none() && constants_pass.is_some() {
            take_constants = true;
        }
        if let (true, Some(constants)) = (take_constants, constants) {
            self.take_constants(step, record, constants, pair_first, &results)?;
            return Ok(true);
        }
        let Some(k) = chosen else {
            self.steps.push(record);
            return Ok(false);
        };
        let (result, space, u) = &results[k];
        let Some(c) = space.slots.first().cloned() else {
            return Ok(false);
        };
        self.current = space.config(u);
        self.sse = result.sse;
        self.accepted.push(c.clone());
        // The label says so when a site constant was fitted beside it.
        record.accepted = Some(result.label.clone());
        self.refit_with(step, &c)?;
        self.backward(step, &mut record)?;
        self.rmse_by_step
            .push((format!("+ {}", c.label()), rmse(self.sse, n)));
        if let Some(keys) = constants_keys_now.filter(|k| !k.is_empty() && !self.constants_in) {
            self.constants_for_earlier(step, &mut record, keys)?;
        }
        self.close(record)?;
        Ok(true)
    }

    /// How a candidate is judged against the current model.
    fn judge(&self) -> Judge<'a> {
        Judge {
            sse: self.sse,
            n: self.n,
            noise: self.noise_now,
            options: self.options,
        }
    }

    /// `r` judged again for `space` at `u`, refitted to `eval_sse`.
    fn update(&self, r: &mut CandidateResult, space: &Space, u: &[f64], eval_sse: f64) {
        let Some(c) = space.slots.first() else {
            unreachable!("a fitted space has its slot")
        };
        // Judged as a new result would be; what the fit recorded (its runs,
        // a constant beside it, cross-validation) stays.
        let judged = self.judge().result(&r.name, c.label(), eval_sse, r.k);
        r.label = judged.label;
        r.params = c.named(&space.params(u).pop().unwrap_or_default());
        r.sse = judged.sse;
        r.rmse = judged.rmse;
        r.delta_bic = judged.delta_bic;
        r.passes_bic = judged.passes_bic;
        r.excess_share = judged.excess_share;
        r.passes_share = judged.passes_share;
    }

    /// `r` replaced by its refit, `space` at `u` with SSE `eval_sse`,
    /// judged again.
    fn refitted(&self, r: &mut Ranked, space: Space, u: Vec<f64>, eval_sse: f64) {
        self.update(&mut r.0, &space, &u, eval_sse);
        r.1 = space;
        r.2 = u;
    }

    /// The candidates fitted, then the best directions (acts_on × driver
    /// × scope), whichever form found them, in every other form: a factor
    /// clamped at 0 shows first as a step, a power first as an exp. Each
    /// judged, sorted by its BIC drop; with the other forms' starts.
    fn fit_candidates(
        &mut self,
        step: usize,
        candidates: &[(Candidate, Start)],
    ) -> Result<(Vec<Ranked>, Starts)> {
        let (data, ev, drivers, options, progress) = (
            self.data,
            self.ev,
            self.drivers,
            self.options,
            self.progress,
        );
        let (sse, n) = (self.sse, self.n);
        let ln_n = (n as f64).ln();
        progress.stage_of(
            &format!("step {step}: fitting {} candidates", candidates.len()),
            candidates.len() as u64,
        );
        let bic_of = BicOf { sse, n };
        let mut fits = fit_each(
            ev,
            &self.current,
            candidates,
            progress,
            &bic_of,
            0.0,
            FORMS_FOR,
        )?;
        let residual_now: Vec<f64> = data
            .rows
            .iter()
            .zip(&self.simulated_current)
            .map(|(r, s)| r.measured - s)
            .collect();
        let mut improving: Vec<&(Candidate, Space, fit::Fit)> = fits
            .iter()
            .filter(|(c, _, f)| {
                f.eval.sse < sse
                    && matches!(c, Candidate::Generic(g)
                        if g.driver.is_some_and(|d| d != Driver::Time))
            })
            .collect();
        improving.sort_by(|a, b| a.2.eval.sse.total_cmp(&b.2.eval.sse));
        let mut directions: Vec<space::GenericSlot> = Vec::new();
        let mut more: Vec<(Candidate, Start)> = Vec::new();
        for (c, space, f) in improving {
            let Candidate::Generic(g) = c else { continue };
            if directions.iter().any(|d| d.same_direction(g)) {
                continue;
            }
            if directions.len() == FORMS_FOR {
                break;
            }
            directions.push(g.clone());
            let p = space.params(&f.u).pop().and_then(|p| p.first().copied());
            let beta = p.filter(|_| g.form == Some(FormKind::Exp));
            more.extend(
                screen::other_forms(data, drivers, &ev.active, &residual_now, g, beta)
                    .into_iter()
                    .filter(|(o, _)| !fits.iter().any(|(c, _, _)| c == o)),
            );
        }
        if !more.is_empty() {
            progress.stage_of(
                &format!("step {step}: fitting {} more forms", more.len()),
                more.len() as u64,
            );
            let so_far = fits
                .iter()
                .map(|(c, _, f)| bic_of.of(f.eval.sse, c.dims() + usize::from(c.is_step())))
                .fold(0.0, f64::min);
            fits.extend(fit_each(
                ev,
                &self.current,
                &more,
                progress,
                &bic_of,
                so_far,
                0,
            )?);
        }
        let judge = self.judge();
        let warm = &mut self.warm;
        let mut results: Vec<Ranked> = fits
            .into_iter()
            .map(|(c, space, f)| {
                if !c.is_generic() {
                    warm.insert(c.clone(), f.u.clone());
                }
                let k = c.dims() + usize::from(c.is_step());
                let params = space.params(&f.u).pop().unwrap_or_default();
                let mut r = judge.result(c.name(), c.label(), f.eval.sse, k);
                r.params = c.named(&params);
                r.engine_runs = f.runs;
                r.fit_stopped = f.stopped.map(|optimistic| FitStopped {
                    optimistic_delta_bic: bic_of.of(optimistic, k),
                });
                (r, space, f.u)
            })
            .collect();
        // A named effect that could not pass the BIC while the residual was
        // larger will not pass on a smaller one (one whose fit stopped
        // early: not even optimistically).
        for (r, space, _) in &results {
            if let Some(c) = space.slots.first().filter(|c| !c.is_generic()) {
                let bic = match &r.fit_stopped {
                    Some(stopped) => stopped.optimistic_delta_bic,
                    None => n as f64 * (r.sse / sse).ln() + c.dims() as f64 * ln_n,
                };
                if bic >= options.bic_threshold {
                    self.hopeless.push(c.clone());
                }
            }
        }
        by_bic(&mut results);
        Ok((results, more))
    }

    /// The change point of the residual lags a cause with memory (less
    /// product on the rail shows only as it runs out), and a split of the
    /// residual along a driver is only a first guess: the best step in
    /// time and the best step along another driver have their threshold
    /// placed by the fit itself ([`refine_step`]).
    /// Steps in time on other quantities that come close to the best one
    /// (within 20 % of its BIC drop: a nozzle that clogs and a transfer
    /// that drops at about the same time) have theirs placed too, so
    /// that the comparison between them is not decided by a first guess.
    fn place_thresholds(&self, step: usize, results: &mut [Ranked]) -> Result<()> {
        let best_bic = results.first().map_or(0.0, |r| r.0.delta_bic);
        let mut to_place: Vec<usize> = Vec::new();
        if let Some(k) = results.iter().position(|r| {
            is_step_slot(&r.1) && is_time_step(&r.1) && r.0.delta_bic < 0.5 * best_bic
        }) {
            to_place.push(k);
            let best_time = results[k].0.delta_bic;
            let mut quantities = vec![acts_on_of(&results[k].1)];
            for (i, r) in results.iter().enumerate().skip(k + 1) {
                if to_place.len() >= MAX_TIME_STEPS_PLACED || r.0.delta_bic >= 0.8 * best_time {
                    break;
                }
                let q = acts_on_of(&r.1);
                if is_step_slot(&r.1) && is_time_step(&r.1) && !quantities.contains(&q) {
                    quantities.push(q);
                    to_place.push(i);
                }
            }
        }
        if let Some(k) = results.iter().position(|r| {
            is_step_slot(&r.1) && !is_time_step(&r.1) && r.0.delta_bic < 0.5 * best_bic
        }) {
            to_place.push(k);
        }
        for k in to_place {
            self.progress.stage(&format!(
                "step {step}: placing the threshold of {}",
                results[k].0.label
            ));
            let refined = refine_step(
                self.ev,
                self.data,
                self.drivers,
                &results[k].1,
                &results[k].2,
            )?;
            if let Some((space, u, eval)) = refined {
                self.refitted(&mut results[k], space, u, eval.sse);
            }
        }
        by_bic(results);
        Ok(())
    }

    /// The close contenders with the model's effects free: each was
    /// fitted with them held where they had to make up for what is still
    /// missing, and the one that is missing frees them most (a clogged
    /// nozzle behind rail ageing: with ageing's time constant held where
    /// the nozzle had put it, a drop of the transfer matched the data
    /// better than the nozzle itself).
    fn free_the_effects(&self, step: usize, results: &mut [Ranked]) -> Result<()> {
        let ev = self.ev;
        if !self.accepted.is_empty() {
            let passing: Vec<usize> = results
                .iter()
                .enumerate()
                .filter(|(_, r)| contends(r, ev))
                .map(|(k, _)| k)
                .collect();
            if let Some(&first) = passing.first() {
                let best = results[first].0.delta_bic;
                let close: Vec<usize> = passing
                    .into_iter()
                    .filter(|&k| results[k].0.delta_bic <= CONTENDER_SHARE * best)
                    .take(MAX_CONTENDERS)
                    .collect();
                if close.len() > 1 {
                    for k in close {
                        self.progress.stage(&format!(
                            "step {step}: {} with the model's effects free",
                            results[k].0.label
                        ));
                        let (space, u) = (&results[k].1, &results[k].2);
                        if let Some((space, u, eval_sse)) = with_effects_free(
                            ev,
                            self.data,
                            self.drivers,
                            &self.accepted,
                            space,
                            u,
                        )? {
                            if eval_sse < results[k].0.sse {
                                self.refitted(&mut results[k], space, u, eval_sse);
                            }
                        }
                    }
                }
            }
        }
        by_bic(results);
        Ok(())
    }

    /// With the site's constants in the model, the best generic term on a
    /// quantity a named effect scales and that named effect are both
    /// fitted with the constants free: held where they made up for what
    /// was missing, the constants favour the term (a temperature-driven
    /// consumption at a site whose km_kg is 23 % high: with the constants
    /// of step 1 held, temperature_consumption's beta went to 0.009 for
    /// 0.04, and a step of the consumption on air temperature was
    /// reported).
    fn free_the_constants(&self, step: usize, results: &mut [Ranked]) -> Result<()> {
        let ev = self.ev;
        if !self.constants_in || self.constant_keys.is_empty() {
            return Ok(());
        }
        let best = results.iter().position(|r| contends(r, ev));
        let rivals = best.map(|k| {
            let window = self.options.bic_threshold.abs();
            rivals_beside_constants(results, k, true, ev, window)
        });
        if let Some(at) = rivals.filter(|at| at.len() > 1) {
            self.progress.stage(&format!(
                "step {step}: {} with the site's constants free",
                labels_of(results, &at)
            ));
            let _stage = ev.cost.enter(fit::Stage::Refits);
            let pairs = beside_constants_at(
                ev,
                results,
                &at,
                &self.constant_keys,
                &self.start.product,
                self.noise_now,
            )?;
            for (i, space, u, pair_sse) in pairs {
                if pair_sse < results[i].0.sse {
                    self.refitted(&mut results[i], space, u, pair_sse);
                }
            }
            by_bic(results);
        }
        Ok(())
    }

    /// The best generic direction everywhere on a quantity one constant
    /// scales (muD, muC, kt), in each of its forms with that constant free
    /// beside it: a factor is 1 at its driver's reference point, so with
    /// the constant held at the laboratory's value it can only bend the
    /// quantity about that point, and where the site's level differs as
    /// well a step on the driver (free on one side) fits better than the
    /// term's true form. The constant moved with the term is part of the
    /// candidate and counted in its BIC; it is calibrated and reported with
    /// the effects found. (muD 13 % high with a dry friction falling
    /// linearly with humidity: both averaged to the laboratory's level,
    /// step 0 kept muD, and a step on humidity was reported with a second
    /// term on precipitation.) The directions the screening ranked with
    /// their constant beside them (`screened_beside`) are fitted so as
    /// well. Either only where it could compete with the step's best: a
    /// passing direction within [`CONTENDER_SHARE`] of its BIC drop, a
    /// screened one whose first-order reduction with the constant comes as
    /// close to the best's SSE reduction.
    fn constant_beside_twins(
        &self,
        step: usize,
        results: &mut [Ranked],
        screened_beside: Vec<(space::GenericSlot, f64)>,
    ) -> Result<()> {
        if self.calibration_start.is_none() || self.constants_in {
            return Ok(());
        }
        let (ev, sse, n) = (self.ev, self.sse, self.n);
        let ln_n = (n as f64).ln();
        let best = results
            .iter()
            .find(|(r, _, _)| r.passes_bic && r.passes_share)
            .map(|(r, _, _)| (r.delta_bic, sse - r.sse));
        let (best_bic, best_reduction) = best.unwrap_or((0.0, 0.0));
        let passing = twin_direction(results, ev)
            .filter(|(_, bic)| *bic <= CONTENDER_SHARE * best_bic)
            .map(|(g, _)| g);
        let screened = screened_beside
            .into_iter()
            .filter(|(_, with_constant)| *with_constant >= CONTENDER_SHARE * best_reduction)
            .map(|(g, _)| g);
        let mut twins: Vec<space::GenericSlot> = Vec::new();
        for g in passing.into_iter().chain(screened) {
            if twins.len() < TWIN_DIRECTIONS && !twins.iter().any(|t| t.same_direction(&g)) {
                twins.push(g);
            }
        }
        for g in twins {
            let Some(key) = twin_constant(g.acts_on) else {
                continue;
            };
            let at: Vec<usize> = results
                .iter()
                .enumerate()
                .filter(|(_, r)| {
                    matches!(r.1.slots.first(), Some(Candidate::Generic(h)) if h.same_direction(&g))
                        && r.1.base.product == self.current.product
                })
                .map(|(i, _)| i)
                .collect();
            if at.is_empty() {
                continue;
            }
            self.progress.stage(&format!(
                "step {step}: {} with {} beside it",
                labels_of(results, &at),
                key.name()
            ));
            let _stage = ev.cost.enter(fit::Stage::Refits);
            let pairs = beside_constants_at(
                ev,
                results,
                &at,
                &[key],
                &self.start.product,
                self.noise_now,
            )?;
            for (i, space, u, pair_sse) in pairs {
                let Some(c) = space.slots.first().cloned() else {
                    continue;
                };
                let k = results[i].0.k + 1;
                let bic = n as f64 * (pair_sse / sse).ln() + k as f64 * ln_n;
                if bic < results[i].0.delta_bic {
                    let alone = results[i].0.delta_bic;
                    results[i].0.k = k;
                    let value = key.get(&space.base.product);
                    self.refitted(&mut results[i], space, u, pair_sse);
                    results[i].0.label = format!(
                        "{} with {} {} beside it",
                        c.label(),
                        key.name(),
                        fmt_param(value)
                    );
                    results[i].0.beside = Some(ConstantBeside {
                        constant: key.name().to_string(),
                        value,
                        delta_bic_alone: alone,
                    });
                }
            }
        }
        by_bic(results);
        Ok(())
    }

    /// The site's constants, as one candidate with as many parameters as
    /// the calibration fitted, until they are taken (`None` once they are,
    /// without calibration, or when the recording moves none).
    /// At the first step the calibration of step 0; after an effect is
    /// accepted the calibration runs again on the model with it (the
    /// effects held): what the recording determines of the constants
    /// changes once a strong effect no longer hides them (a clogged nozzle
    /// hid a consumption 19 % below the laboratory's, which generic terms
    /// on creepage then took).
    fn constants_candidate(&self, step: usize, results: &[Ranked]) -> Result<Option<Constants>> {
        let (ev, start, options, progress) = (self.ev, self.start, self.options, self.progress);
        let (current, n, noise_now) = (&self.current, self.n, self.noise_now);
        let judge = self.judge();
        let constants = match &self.calibration_start {
            Some(cal0) if !self.constants_in => {
                let on_start =
                    *current == *start || Some(current) == self.start_refit_model.as_ref();
                let cal = if on_start {
                    cal0.clone()
                } else {
                    progress.stage(&format!("step {step}: calibrating the site's constants"));
                    // The effects taken are free beside the constants, as
                    // every candidate of a step is refitted with them: held
                    // where they made up for a constant (rail ageing's time
                    // constant 70 % long beside a muC 29 % low), they would
                    // keep the constant from being found.
                    let own: Vec<Candidate> = self
                        .accepted
                        .iter()
                        .filter(|c| c.dims() > 0)
                        .cloned()
                        .collect();
                    calibrate::calibrate(ev, current, &start.product, &own, noise_now)?
                };
                if cal.fitted.is_empty() {
                    None
                } else {
                    let (mut model, mut keys) = (cal.model, cal.fitted);
                    let mut sse_constants = ev.evaluate(&model)?.sse;
                    // The calibration moves every constant whose interval
                    // leaves its reference value; as a candidate the
                    // constants count one parameter each. When they contend
                    // with the step's best, the fewest that explain as well
                    // stand for them (kt 26 % high came with km1_kg and
                    // m0_kg moved by 2-4 %, and lost to a transfer term on
                    // creepage by the two parameters' price).
                    let best = results
                        .iter()
                        .filter(|(r, _, _)| r.passes_bic && r.passes_share)
                        .map(|(r, _, _)| r.delta_bic)
                        .fold(f64::INFINITY, f64::min);
                    let price = (keys.len() as f64 - 1.0) * (n as f64).ln();
                    let contends = judge
                        .result(SITE_CONSTANTS, String::new(), sse_constants, keys.len())
                        .delta_bic
                        < best + price - options.bic_threshold;
                    if keys.len() > 1 && contends {
                        progress.stage(&format!("step {step}: the fewest site constants"));
                        (model, keys, sse_constants) = fewest_constants(
                            ev,
                            &model,
                            &start.product,
                            keys,
                            sse_constants,
                            noise_now,
                        )?;
                    }
                    let names: Vec<&str> = keys.iter().map(|key| key.name()).collect();
                    let mut r = judge.result(
                        SITE_CONSTANTS,
                        format!("the site's constants ({})", names.join(", ")),
                        sse_constants,
                        keys.len(),
                    );
                    r.params = keys
                        .iter()
                        .map(|key| (key.name().to_string(), key.get(&model.product)))
                        .collect();
                    Some((r, model, keys))
                }
            }
            _ => None,
        };
        // A generic term everywhere on a quantity one constant scales (the
        // transfer: kt; muD, muC) is that constant unless it describes the
        // data better by the BIC threshold: over a narrow range of its
        // driver such a term is a constant factor (a transfer term on
        // creepage, 87 % of the model's, was kt 13 % low). The best such
        // term of the step is set against its constant fitted alone, which
        // stands for the site's constants when it is as good.
        let mut constants = constants;
        if self.calibration_start.is_some() && !self.constants_in {
            let first_twin = results
                .iter()
                .filter(|(r, _, _)| r.passes_bic && r.passes_share)
                .find_map(|(r, space, _)| match space.slots.first() {
                    Some(Candidate::Generic(g))
                        if g.applicator.is_none() && g.rail.is_none() && g.site.is_none() =>
                    {
                        twin_constant(g.acts_on).map(|key| (r.delta_bic, key))
                    }
                    _ => None,
                });
            let covered = constants
                .as_ref()
                .is_some_and(|(_, _, keys)| first_twin.is_some_and(|(_, key)| keys.contains(&key)));
            if let (Some((delta_bic, key)), false) = (first_twin, covered) {
                progress.stage(&format!("step {step}: {} alone", key.name()));
                let model = calibrate::refit(ev, current, &start.product, &[key], noise_now)?;
                let twin_sse = ev.evaluate(&model)?.sse;
                let mut r = judge.result(
                    SITE_CONSTANTS,
                    format!("the site's constants ({})", key.name()),
                    twin_sse,
                    1,
                );
                r.params = [(key.name().to_string(), key.get(&model.product))].into();
                let better_than_calibrated = constants
                    .as_ref()
                    .is_none_or(|(c, _, _)| r.delta_bic < c.delta_bic);
                if r.delta_bic <= delta_bic - options.bic_threshold && better_than_calibrated {
                    constants = Some((r, model, vec![key]));
                }
            }
        }
        Ok(constants)
    }

    /// Down the ranking to the first candidate that passes the BIC, its
    /// share and the cross-validation: its index, or the site's constants
    /// taken instead (`true`) when they explain the data as well as what
    /// is left (`constants_pass`: their BIC drop when they pass).
    /// Candidates whose fits stopped early lie beyond what the walk
    /// reaches unless everything better is turned down: before it would
    /// decide at a candidate one of them could precede or rival (within
    /// the window in which rivals of another kind are weighed beside the
    /// site's constants), or turn everything down while one could still
    /// pass, they are fitted to the end (from their `starts`) and the walk
    /// begins again.
    fn walk(
        &self,
        step: usize,
        results: &mut [Ranked],
        starts: &[&(Candidate, Start)],
        constants_pass: Option<f64>,
    ) -> Result<(Option<usize>, bool)> {
        let (ev, options, progress, n) = (self.ev, self.options, self.progress, self.n);
        // The current model's held-out SSE: every block predicted as it is.
        let cv_current = self.sse;
        let mut chosen = None;
        let mut take_constants = false;
        let mut walks = 0;
        loop {
            walks += 1;
            let stopped_floor = results
                .iter()
                .filter_map(|r| r.0.fit_stopped.as_ref())
                .map(|s| s.optimistic_delta_bic)
                .fold(f64::INFINITY, f64::min);
            let mut reached_stopped = false;
            for (k, (result, space, u)) in results.iter_mut().enumerate() {
                if !(result.passes_bic && result.passes_share) {
                    continue;
                }
                if result.delta_bic + result.rivals_window(options) >= stopped_floor {
                    reached_stopped = true;
                    break;
                }
                // A change in time before the first measurement it could
                // affect is a site constant, not a change: never an effect.
                if space
                    .slots
                    .first()
                    .is_some_and(|c| constant_in_disguise(c, ev))
                {
                    continue;
                }
                // The site's constants explain the data as well as what is
                // left: they are taken at this step. A constant that
                // differs for the whole recording is the plainer story, so
                // an effect must beat them by the BIC threshold (a
                // consumption term on creepage that is 122 % of the model's
                // at 0 and 117 % at 0.002 is kc 19 % low: 2.6 BIC units
                // apart).
                if constants_pass.is_some_and(|d| d <= result.delta_bic - options.bic_threshold) {
                    take_constants = true;
                    break;
                }
                if !cross_validated(
                    ev,
                    result,
                    space,
                    u,
                    &self.current,
                    cv_current,
                    progress,
                    step,
                )? {
                    continue;
                }
                chosen = Some(k);
                break;
            }
            let none_taken = chosen.is_none() && !take_constants;
            if walks > 1
                || !(reached_stopped || none_taken && stopped_floor < options.bic_threshold)
            {
                return Ok((chosen, take_constants));
            }
            progress.stage(&format!(
                "step {step}: the candidates left early, to the end"
            ));
            for r in results.iter_mut().filter(|r| r.0.fit_stopped.is_some()) {
                let Some(c) = r.1.slots.first() else { continue };
                let start = starts
                    .iter()
                    .find(|(d, _)| d == c)
                    .map_or_else(|| Start::Warm(r.2.clone()), |(_, s)| s.clone());
                let f = fit::fit(ev, &r.1, start, None)?;
                if f.eval.sse < r.0.sse {
                    self.update(&mut r.0, &r.1, &f.u, f.eval.sse);
                    r.2 = f.u;
                }
                r.0.engine_runs += f.runs;
                r.0.fit_stopped = None;
            }
            by_bic(results);
            prefer(results, n, options);
            (chosen, take_constants) = (None, false);
        }
    }

    /// An effect chosen (`k`) over the site's constants may stand in for
    /// both them and another effect that the laboratory's constants kept
    /// from fitting: a named effect on the same quantity (consumption
    /// growing with the temperature at a site whose kc is 32 % high: with
    /// kc held, temperature_consumption's beta went to 0.094 to make up for
    /// kc and lost to a power of humidity by 11700 BIC units; with kc and
    /// km1_kg free it describes the data better than the humidity term does
    /// with them), or a contender of another kind the BIC cannot tell from
    /// it (a transfer step 2.6 units ahead of the clogged nozzle at a site
    /// whose kt is 27 % high). They are fitted beside the constants; when
    /// another is the better there and the pair beats the choice alone by
    /// the BIC threshold, the constants and that effect are taken together:
    /// that effect with its model and SSE.
    fn pair_with_constants(
        &self,
        step: usize,
        results: &[Ranked],
        k: usize,
        (constants_alone, _, keys): &Constants,
    ) -> Result<Option<(Candidate, ModelConfig, f64)>> {
        let (ev, options, noise_now) = (self.ev, self.options, self.noise_now);
        let (sse, n) = (self.sse, self.n);
        let window = results[k].0.rivals_window(options);
        let at = rivals_beside_constants(results, k, true, ev, window);
        if at.len() <= 1 {
            return Ok(None);
        }
        self.progress.stage(&format!(
            "step {step}: {} beside the site's constants",
            labels_of(results, &at)
        ));
        let _stage = ev.cost.enter(fit::Stage::Refits);
        let tried: Vec<_> = at.iter().map(|&i| &results[i]).collect();
        let best =
            best_beside_constants(ev, &tried, keys, &self.start.product, noise_now, options)?;
        let choice = results[k].1.slots.first();
        if let Some((c, own, u, pair_sse)) = best.filter(|b| Some(&b.0) != choice) {
            let k_pair = keys.len() + c.dims();
            let pair_bic = n as f64 * (pair_sse / sse).ln() + k_pair as f64 * (n as f64).ln();
            if pair_bic <= results[k].0.delta_bic + options.bic_threshold
                && passes_beside_constants(
                    ev,
                    &c,
                    &own,
                    &u,
                    pair_sse,
                    constants_alone.sse,
                    noise_now,
                    options,
                )?
            {
                return Ok(Some((c, own.config(&u), pair_sse)));
            }
        }
        Ok(None)
    }

    /// Where the recording moves no constant yet (a strong effect hides
    /// them), close contenders of another kind than the choice `k` are
    /// told apart with the site's constants calibrated beside each: held
    /// at the laboratory's values, the constants favour whichever effect
    /// makes up for them (a transfer step came 2.6 BIC units ahead of a
    /// clogged nozzle at a site whose kt is 27 % and km_kg 25 % high;
    /// calibrated with each, the nozzle is about 250 units ahead). The
    /// best calibrated (BIC, the constants each moved counted) is chosen
    /// instead when it passes the cross-validation as the choice did.
    /// Returns the choice and each contender's calibrated BIC.
    fn calibrated_beside(
        &self,
        step: usize,
        results: &mut [Ranked],
        k: usize,
    ) -> Result<(usize, Vec<(String, f64)>)> {
        let (ev, options) = (self.ev, self.options);
        let window = results[k].0.rivals_window(options);
        let at = rivals_beside_constants(results, k, false, ev, window);
        if at.len() <= 1 {
            return Ok((k, Vec::new()));
        }
        self.progress.stage(&format!(
            "step {step}: the site's constants calibrated beside {}",
            labels_of(results, &at)
        ));
        let scored = calibrated_bic(
            ev,
            results,
            &at,
            &self.start.product,
            self.sse,
            self.noise_now,
        )?;
        let best = scored
            .iter()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|b| b.0);
        let calibrated_beside = scored
            .iter()
            .map(|&(i, bic)| (results[i].0.label.clone(), bic))
            .collect();
        let mut chosen = k;
        if let Some(i) = best.filter(|&i| i != k) {
            let (result, space, u) = &mut results[i];
            if cross_validated(
                ev,
                result,
                space,
                u,
                &self.current,
                self.sse,
                self.progress,
                step,
            )? {
                chosen = i;
            }
        }
        Ok((chosen, calibrated_beside))
    }

    /// The site's constants taken at this step (with the effect
    /// `pair_first` when it was found the better beside them); then what
    /// the constants could not imitate, and the effects that stood in for
    /// them taken out again.
    fn take_constants(
        &mut self,
        step: usize,
        mut record: Step,
        (c, model, keys): Constants,
        pair_first: Option<(Candidate, ModelConfig, f64)>,
        results: &[Ranked],
    ) -> Result<()> {
        let (ev, start, options, progress) = (self.ev, self.start, self.options, self.progress);
        let n = self.n;
        progress.stage(&format!("step {step}: {} taken", c.label));
        self.current = model;
        self.sse = c.sse;
        self.constants_in = true;
        self.constant_keys = keys;
        // A named effect that could not pass beside the laboratory's
        // constants may beside the site's (rain wash-off, found nothing
        // while muC was 19 % off, is the cause of what they leave): each
        // is fitted again from its grid at the next step.
        self.hopeless.retain(Candidate::is_generic);
        self.warm.retain(|c, _| c.is_generic());
        record.accepted = Some(c.label.clone());
        self.rmse_by_step
            .push(("site constants calibrated".to_string(), rmse(self.sse, n)));
        // What the constants could not imitate: the step's best effects
        // fitted again beside them, the constants refitted with each.
        // Constants that soak up part of a strong effect (rail ageing
        // beside a km_kg 31 % high and a k0_kg 33 % low) leave its rest
        // too small to be found afterwards; one that still explains enough
        // of what they leave (BIC, share, cross-validation) is taken with
        // them.
        progress.stage(&format!(
            "step {step}: the best effects beside the site's constants"
        ));
        let pair = match pair_first {
            Some(pair) => Some(pair),
            None => effect_beside_constants(
                ev,
                results,
                &self.constant_keys,
                &start.product,
                self.sse,
                self.noise_now,
                options,
            )?,
        };
        if let Some((effect, model, pair_sse)) = pair {
            progress.stage(&format!(
                "step {step}: {} taken with the site's constants",
                effect.label()
            ));
            self.current = model;
            self.sse = pair_sse;
            record.accepted = Some(format!("{}; {}", c.label, effect.label()));
            // The constants were refitted once beside the effect as it was
            // fitted without them: calibrated again with it free, they find
            // their values (and which of them the recording determines)
            // with it.
            progress.stage(&format!(
                "step {step}: calibrating the site's constants with {}",
                effect.label()
            ));
            let cal = calibrate::calibrate(
                ev,
                &self.current,
                &start.product,
                std::slice::from_ref(&effect),
                self.noise_now,
            )?;
            let cal_sse = ev.evaluate(&cal.model)?.sse;
            if cal_sse < self.sse && !cal.fitted.is_empty() {
                self.current = cal.model;
                self.sse = cal_sse;
                self.constant_keys = cal.fitted;
            }
            self.rmse_by_step
                .push((format!("+ {}", effect.label()), rmse(self.sse, n)));
            self.accepted.push(effect);
        }
        // Backward: an effect taken before the constants that stood in for
        // them (a dry-friction step on wheel load for a site whose muD is
        // 7 % below the laboratory's) is taken out again, the constants
        // refitted without it.
        let mut removed = Vec::new();
        loop {
            let without = without_each(
                ev,
                &self.accepted,
                self.starting,
                &self.current,
                &self.constant_keys,
                &start.product,
                self.noise_now,
            )?;
            let Some((i, w, cfg)) = least_needed(
                &self.accepted,
                without,
                self.sse,
                n,
                self.noise_now,
                options,
            ) else {
                break;
            };
            removed.push(self.take_out(i, cfg, w, |c| {
                format!("step {step}: {c} is no longer needed with the site's constants")
            }));
        }
        if let Some(twin) = self.swap_time_twins(step)? {
            removed.push(format!("a step in time, for {twin}"));
        }
        if !removed.is_empty() {
            record.removed = Some(removed.join("; "));
        }
        self.close(record)
    }

    /// With `c` just added: every effect of the model refitted together
    /// (`c` was fitted with the others held at values that had to make up
    /// for it), the constants taken earlier refitted, and each generic
    /// term's other forms tried once more.
    fn refit_with(&mut self, step: usize, c: &Candidate) -> Result<()> {
        let (ev, start, progress) = (self.ev, self.start, self.progress);
        let joint = Space {
            base: self.current.clone(),
            slots: self.accepted.clone(),
        };
        if joint.dims() > c.dims() {
            progress.stage(&format!("step {step}: refitting every effect jointly"));
            let fit = fit::fit(ev, &joint, Start::Warm(joint.units_of(&self.current)), None)?;
            if fit.eval.sse < self.sse {
                self.current = joint.config(&fit.u);
                self.sse = fit.eval.sse;
            }
        }
        // The constants taken earlier made up for the effect as well as
        // they could: with it in the model they move back.
        if !self.constant_keys.is_empty() {
            progress.stage(&format!("step {step}: refitting the site's constants"));
            let refitted = calibrate::refit(
                ev,
                &self.current,
                &start.product,
                &self.constant_keys,
                self.noise_now,
            )?;
            let eval = ev.evaluate(&refitted)?;
            if eval.sse < self.sse {
                self.current = refitted;
                self.sse = eval.sse;
            }
        }
        // The generic terms' forms once more: a term was fitted in its form
        // with the others held where they had to make up for it; now that
        // they are refitted, another form may describe the data better (an
        // exp that was a power all along). The best is swapped in.
        if joint.dims() > c.dims() {
            let drivers = self.drivers;
            let (accepted, current) = (&self.accepted, &self.current);
            let swaps: Vec<(usize, Candidate, Space, fit::Fit)> = accepted
                .iter()
                .enumerate()
                .filter_map(|(i, a)| match a {
                    Candidate::Generic(g) => {
                        g.driver.filter(|&d| d != Driver::Time).map(|d| (i, g, d))
                    }
                    _ => None,
                })
                .flat_map(|(i, g, d)| {
                    [FormKind::Exp, FormKind::Linear, FormKind::Power]
                        .into_iter()
                        .filter(move |&form| Some(form) != g.form && drivers.allows(d, form))
                        .map(move |form| {
                            let alt = space::GenericSlot::factor(
                                g.acts_on,
                                d,
                                form,
                                g.scope(),
                                None,
                                drivers.reach(d),
                            );
                            (i, Candidate::Generic(alt))
                        })
                })
                .collect::<Vec<_>>()
                .into_par_iter()
                .map(|(i, alt)| {
                    let mut base = current.clone();
                    accepted[i].unset(&mut base.effects);
                    let space = Space {
                        base,
                        slots: vec![alt.clone()],
                    };
                    let fit = fit::fit(ev, &space, Start::Fresh, None)?;
                    Ok((i, alt, space, fit))
                })
                .collect::<Result<_>>()?;
            if let Some((i, alt, space, fit)) = swaps
                .into_iter()
                .filter(|s| s.3.eval.sse < self.sse)
                .min_by(|a, b| a.3.eval.sse.total_cmp(&b.3.eval.sse))
            {
                progress.stage(&format!("step {step}: {} describes it better", alt.label()));
                self.current = space.config(&fit.u);
                self.sse = fit.eval.sse;
                self.accepted[i] = alt;
            }
        }
        Ok(())
    }

    /// Backward: an effect added earlier that the model no longer needs
    /// (it stood in for what came later) is taken out again; two changes
    /// in time that are one another's twin are swapped.
    fn backward(&mut self, step: usize, record: &mut Step) -> Result<()> {
        let (ev, start, options, progress) = (self.ev, self.start, self.options, self.progress);
        if self.accepted.len() > 1 {
            let without = without_each(
                ev,
                &self.accepted,
                self.starting,
                &self.current,
                &[],
                &start.product,
                self.noise_now,
            )?;
            if let Some((i, _, _)) = least_needed(
                &self.accepted,
                without,
                self.sse,
                self.n,
                self.noise_now,
                options,
            ) {
                let c = self.accepted.remove(i);
                progress.stage(&format!("step {step}: {} is no longer needed", c.label()));
                c.unset(&mut self.current.effects);
                let joint = Space {
                    base: self.current.clone(),
                    slots: self.accepted.clone(),
                };
                let fit = fit::fit(ev, &joint, Start::Warm(joint.units_of(&self.current)), None)?;
                self.current = joint.config(&fit.u);
                self.sse = fit.eval.sse;
                record.removed = Some(c.label());
                self.hopeless.push(c);
            }
        }
        self.swap_time_twins(step)?;
        Ok(())
    }

    /// An effect taken earlier that the site's constants (`keys`, as this
    /// step calibrated them) explain as well (BIC with the constants'
    /// parameters counted) is replaced by them: a dry-friction term on
    /// wheel load taken for a muD 7 % below the laboratory's while rail
    /// ageing, not yet in, hid the constants. The effect just added was
    /// preferred to the constants already.
    fn constants_for_earlier(
        &mut self,
        step: usize,
        record: &mut Step,
        keys: Vec<ProductKey>,
    ) -> Result<()> {
        let (ev, start) = (self.ev, self.start);
        let (sse, n) = (self.sse, self.n);
        let ln_n = (n as f64).ln();
        let last = self.accepted.len().saturating_sub(1);
        let swaps = without_each(
            ev,
            &self.accepted[..last],
            self.starting,
            &self.current,
            &keys,
            &start.product,
            self.noise_now,
        )?;
        let best = swaps
            .into_iter()
            .map(|(i, w, cfg)| {
                let c = &self.accepted[i];
                let k = c.dims() + usize::from(c.is_step());
                let bic = n as f64 * (w / sse).ln() + (keys.len() as f64 - k as f64) * ln_n;
                (i, bic, w, cfg)
            })
            .filter(|(_, bic, _, _)| *bic <= 0.0)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, _, w, cfg)) = best {
            let c = self.take_out(i, cfg, w, |c| {
                format!("step {step}: the site's constants explain {c} as well")
            });
            self.constants_in = true;
            self.constant_keys = keys;
            record.removed = Some(match record.removed.take() {
                Some(r) => format!("{r}; {c}"),
                None => c.clone(),
            });
            self.rmse_by_step.push((
                format!("site constants calibrated for {c}"),
                rmse(self.sse, n),
            ));
        }
        Ok(())
    }

    /// Two changes in time that are one another's twin swapped where the
    /// other describes the data better ([`swap_time_twins`]): what was
    /// taken out, if anything.
    fn swap_time_twins(&mut self, step: usize) -> Result<Option<String>> {
        swap_time_twins(
            self.ev,
            self.data,
            &mut self.accepted,
            &mut self.current,
            &mut self.sse,
            (&self.start.product, &self.constant_keys, self.noise_now),
            (self.options, self.progress, step),
        )
    }

    /// The effect `i` taken out of the model, which becomes `model` with
    /// SSE `sse`, and not tried again; `say` what happened. Its label.
    fn take_out(
        &mut self,
        i: usize,
        model: ModelConfig,
        sse: f64,
        say: impl FnOnce(&str) -> String,
    ) -> String {
        let c = self.accepted.remove(i);
        let label = c.label();
        self.progress.stage(&say(&label));
        self.current = model;
        self.sse = sse;
        self.hopeless.push(c);
        label
    }

    /// The step closed: the model it leaves simulated for the next step's
    /// residual and noise, and its record kept.
    fn close(&mut self, mut record: Step) -> Result<()> {
        self.simulated_current = self.ev.simulate(&self.current)?;
        self.noise_now = noise_again(self.ev, &self.simulated_current, self.noise_now);
        record.rmse_after = rmse(self.sse, self.n);
        record.effects_after = effects_of(&self.current);
        self.steps.push(record);
        Ok(())
    }
}

/// A candidate as a step judged it: its result, its space and its fitted
/// parameters (units of the space).
type Ranked = (CandidateResult, Space, Vec<f64>);

/// Candidates with where their fits start.
type Starts = Vec<(Candidate, Start)>;

/// The site's constants as a step's candidate: its result, the model with
/// them calibrated and the constants that moved.
type Constants = (CandidateResult, ModelConfig, Vec<ProductKey>);

/// A step's results sorted by their BIC drop, the best first.
fn by_bic(results: &mut [Ranked]) {
    results.sort_by(|a, b| a.0.delta_bic.total_cmp(&b.0.delta_bic));
}

/// The order in which a step's sorted results are walked: a named effect
/// that describes the data (nearly) as well as the best generic term is
/// the better statement; a direct driver before one that stands in for
/// it; a narrow offset before a wide one.
fn prefer(results: &mut [Ranked], n: usize, options: &Options) {
    prefer_named(results, n, options);
    prefer_direct_drivers(results);
    prefer_narrow_offsets(results, n);
}

/// How a candidate is judged against the current model: its BIC drop
/// and its share of the excess over the noise.
struct Judge<'o> {
    /// The current model's SSE, over `n` measurements.
    sse: f64,
    n: usize,
    noise: Option<f64>,
    options: &'o Options,
}

impl Judge<'_> {
    /// The result of a candidate with `k` parameters fitted to `new_sse`
    /// (no parameters named, no cross-validation yet).
    fn result(&self, name: &str, label: String, new_sse: f64, k: usize) -> CandidateResult {
        let n = self.n;
        let delta_bic = n as f64 * (new_sse / self.sse).ln() + k as f64 * (n as f64).ln();
        let (excess_share, passes_share) =
            judge_share(self.sse, new_sse, n, self.noise, self.options);
        CandidateResult {
            name: name.to_string(),
            label,
            params: BTreeMap::new(),
            sse: new_sse,
            rmse: rmse(new_sse, n),
            k,
            delta_bic,
            passes_bic: delta_bic < self.options.bic_threshold,
            excess_share,
            passes_share,
            cv: None,
            passes_cv: None,
            cv_site: None,
            passes_cv_site: None,
            engine_runs: 0,
            beside: None,
            fit_stopped: None,
        }
    }
}

/// The noise estimated again on the residual of `simulated` (an effect
/// that varies from axle to axle inflated the earlier estimate): the
/// smallest kept.
fn noise_again(ev: &Evaluator<'_>, simulated: &[f64], noise: Option<f64>) -> Option<f64> {
    let residual: Vec<f64> = ev
        .data
        .rows
        .iter()
        .zip(simulated)
        .zip(&ev.active)
        .map(|((r, s), &a)| if a { r.measured - s } else { f64::NAN })
        .collect();
    match diagnose::noise_estimate(ev.data, &residual) {
        Some(again) => Some(noise.map_or(again, |s| s.min(again))),
        None => noise,
    }
}

/// A covariate the residual follows is read as a signature when its
/// adjusted eta² is at least this.
const SIGNATURE_ETA2: f64 = 0.02;

/// The catalogue effects whose signature a covariate is (effects.md, "What
/// each effect leaves in the residuals"), and the generic driver it is.
fn signature_of(covariate: &str) -> (Vec<Named>, Option<Driver>) {
    match covariate {
        "time_since_last_touch_s" => (vec![Named::RailAgeing], None),
        "rain_since_last_touch_mm" => (vec![Named::RainWashoff], Some(Driver::PrecipitationMmH)),
        "air_temperature_c" => (
            vec![Named::TemperatureConsumption],
            Some(Driver::AirTemperatureC),
        ),
        // A generic driver without a catalogue effect: a surface that
        // behaves differently when humid (effects.md, "Generic terms").
        "relative_humidity" => (Vec::new(), Some(Driver::RelativeHumidity)),
        "train_speed_mps" => (vec![Named::SpeedTransfer], Some(Driver::SpeedMps)),
        "bogie_position" => (vec![Named::BogieBands], None),
        "distance_from_applicator_m" => (vec![Named::WheelEdgeReservoir], None),
        "wheel_load_kn" => (Vec::new(), Some(Driver::WheelLoadKn)),
        _ => (Vec::new(), None),
    }
}

/// A step in time whose `t0` lies at or before the first measurement it
/// could affect acts on every measurement of its scope alike: a constant in
/// disguise (interfaces.md, "Site constants"), which the calibration
/// handles; never reported as a change in time.
fn constant_in_disguise(c: &Candidate, ev: &Evaluator<'_>) -> bool {
    let Candidate::Generic(g) = c else {
        return false;
    };
    let (Some(Driver::Time), Some(FormKind::Step), Some(t0)) = (g.driver, g.form, g.x0()) else {
        return false;
    };
    t0 <= first_affected_s(g, ev)
}

/// The times (unix seconds, ascending) at which a change in time on a
/// slot's quantity can show: the pulses in its scope for a pulse mass (a
/// step between two pulses changes the later ones), the train passages for
/// every other quantity.
fn acting_times_s(g: &space::GenericSlot, data: &Dataset) -> Vec<f64> {
    if g.acts_on == ActsOn::PulseMass {
        let mut t: Vec<f64> = data
            .events
            .iter()
            .filter_map(|e| match &e.kind {
                EventKind::Pulse(p) => Some((e.log_time_ns, p)),
                _ => None,
            })
            .filter(|(_, p)| {
                g.applicator.as_deref().is_none_or(|a| {
                    data.section
                        .applicators
                        .get(p.applicator)
                        .is_some_and(|x| x.id == a)
                }) && g
                    .rail
                    .as_deref()
                    .is_none_or(|r| r == data.rail_name(p.rail))
            })
            .map(|(t, _)| t as f64 * 1e-9)
            .collect();
        t.sort_unstable_by(f64::total_cmp);
        t
    } else {
        data.passages
            .iter()
            .map(|p| p.log_time_ns as f64 * 1e-9)
            .collect()
    }
}

/// The first time a change in time on a slot can act on what is measured:
/// its first pulse for a pulse mass (a step at or before it changes every
/// pulse alike), otherwise the first measurement in its scope (a step at or
/// before it changes every measurement alike). A step there is a site
/// constant, not a change.
fn first_affected_s(g: &space::GenericSlot, ev: &Evaluator<'_>) -> f64 {
    let data = ev.data;
    if g.acts_on == ActsOn::PulseMass {
        return acting_times_s(g, data)
            .first()
            .copied()
            .unwrap_or(f64::INFINITY);
    }
    data.rows
        .iter()
        .zip(&ev.active)
        .filter(|&(row, &a)| {
            a && g
                .rail
                .as_deref()
                .is_none_or(|r| r == data.rail_name(row.rail))
                && g.site
                    .as_deref()
                    .is_none_or(|s| s == data.site_name(row.site))
                && g.quantity.is_none_or(|q| q == row.quantity)
        })
        .map(|(row, _)| row.log_time_ns as f64 * 1e-9)
        .fold(f64::INFINITY, f64::min)
}

/// Steps in time whose threshold is placed by the fit at one step, at most.
const MAX_TIME_STEPS_PLACED: usize = 3;

/// Candidates whose BIC drop is at least this share of the best one's are
/// close contenders, fitted again with the model's effects free.
const CONTENDER_SHARE: f64 = 0.8;

/// The most close contenders fitted with the model's effects free.
const MAX_CONTENDERS: usize = 3;

/// The most thresholds a step's placement tries in one pass.
const COARSE_THRESHOLDS: usize = 48;

/// Pulses closer together than this are one burst (one train's): a step
/// in pulse mass is placed between bursts.
const BURST_GAP_S: f64 = 60.0;

/// The thresholds a placement tries again with the factor refitted at the
/// best one: those that came closest.
const REFIT_THRESHOLDS: usize = 12;

/// The quantity a space's (generic) slot acts on.
fn acts_on_of(space: &Space) -> Option<ActsOn> {
    match space.slots.first() {
        Some(Candidate::Generic(g)) => Some(g.acts_on),
        _ => None,
    }
}

fn is_time_step(space: &Space) -> bool {
    matches!(space.slots.first(), Some(Candidate::Generic(g)) if g.driver == Some(Driver::Time))
}

fn is_step_slot(space: &Space) -> bool {
    space.slots.first().is_some_and(Candidate::is_step)
}

/// A candidate fitted together with the effects already in the model (a
/// step in time has its threshold placed again with them where they go),
/// as a space of its own slot over a base that holds them at their new
/// values. `None` when the candidate has no slot.
fn with_effects_free(
    ev: &Evaluator<'_>,
    data: &Dataset,
    drivers: &Drivers,
    accepted: &[Candidate],
    space: &Space,
    u: &[f64],
) -> Result<Option<(Space, Vec<f64>, f64)>> {
    let _stage = ev.cost.enter(fit::Stage::Refits);
    let Some(c) = space.slots.first().cloned() else {
        return Ok(None);
    };
    // The joint fit from `cfg`, split back into the candidate's own space.
    let joint_fit = |c: &Candidate, cfg: ModelConfig| -> Result<(Space, Vec<f64>, f64)> {
        let joint = Space {
            slots: accepted.iter().cloned().chain([c.clone()]).collect(),
            base: cfg,
        };
        let fit = fit::fit(ev, &joint, Start::Warm(joint.units_of(&joint.base)), None)?;
        let fitted = joint.config(&fit.u);
        let mut base = fitted.clone();
        c.unset(&mut base.effects);
        let own = Space {
            base,
            slots: vec![c.clone()],
        };
        let u = own.units_of(&fitted);
        Ok((own, u, fit.eval.sse))
    };
    let (own, u1, sse1) = joint_fit(&c, space.config(u))?;
    if !(is_step_slot(&own) && is_time_step(&own)) {
        return Ok(Some((own, u1, sse1)));
    }
    match refine_step(ev, data, drivers, &own, &u1)? {
        Some((placed, u2, eval)) if eval.sse < sse1 => {
            let Some(c2) = placed.slots.first().cloned() else {
                return Ok(Some((own, u1, sse1)));
            };
            let (own2, u3, sse3) = joint_fit(&c2, placed.config(&u2))?;
            Ok(Some(if sse3 < eval.sse {
                (own2, u3, sse3)
            } else {
                (placed, u2, eval.sse)
            }))
        }
        _ => Ok(Some((own, u1, sse1))),
    }
}

/// Named effects fitted beside the site's constants when they are taken,
/// and the best generic directions (offsets aside: they are the sensors').
const GENERIC_BESIDE_CONSTANTS: usize = 3;
/// The generic directions of a step fitted with the site constant that
/// scales their quantity beside them: the best that passes, and those the
/// screening ranked so.
const TWIN_DIRECTIONS: usize = 2;

/// The site constant that scales the quantity a generic term everywhere
/// acts on, where one does: `kt` the transfer fraction (eq. 6), `mu_d` and
/// `mu_c` the friction levels (eq. 4). Consumption and the landing mass
/// have none (k0 and km1 together scale the first; m0 is no scale).
pub(crate) fn twin_constant(acts_on: ActsOn) -> Option<ProductKey> {
    match acts_on {
        ActsOn::Transfer => Some(ProductKey::Kt),
        ActsOn::FrictionDry => Some(ProductKey::MuD),
        ActsOn::FrictionBoundary => Some(ProductKey::MuC),
        ActsOn::Consumption | ActsOn::PulseMass | ActsOn::Measurement => None,
    }
}

/// The best passing generic direction of a step that acts everywhere on a
/// quantity one site constant scales ([`twin_constant`]), by a factor on a
/// driver other than time, with its BIC drop.
fn twin_direction(results: &[Ranked], ev: &Evaluator<'_>) -> Option<(space::GenericSlot, f64)> {
    results
        .iter()
        .filter(|(r, _, _)| r.passes_bic && r.passes_share)
        .find_map(|(r, space, _)| match space.slots.first() {
            Some(c @ Candidate::Generic(g))
                if g.applicator.is_none()
                    && g.rail.is_none()
                    && g.site.is_none()
                    && g.driver.is_some_and(|d| d != Driver::Time)
                    && !constant_in_disguise(c, ev) =>
            {
                twin_constant(g.acts_on).map(|_| (g.clone(), r.delta_bic))
            }
            _ => None,
        })
}

/// The fewest of the site's constants `keys` that describe the data as
/// well (BIC): each is held at its reference value in turn with the others
/// refitted, and the one whose freedom is worth least is dropped while
/// that lowers the BIC. The model, the keys and its SSE.
fn fewest_constants(
    ev: &Evaluator<'_>,
    model: &ModelConfig,
    reference: &ProductParams,
    mut keys: Vec<ProductKey>,
    mut sse: f64,
    noise: Option<f64>,
) -> Result<(ModelConfig, Vec<ProductKey>, f64)> {
    // Its refits run side by side: the evaluations between them are the
    // calibration's too.
    let _stage = ev.cost.enter(fit::Stage::Calibration);
    let n = ev.active.iter().filter(|&&a| a).count() as f64;
    let mut model = model.clone();
    while keys.len() > 1 {
        let tries: Vec<(usize, ModelConfig, f64)> = (0..keys.len())
            .into_par_iter()
            .map(|i| {
                let mut base = model.clone();
                keys[i].set(&mut base.product, keys[i].get(reference));
                let others: Vec<_> = keys
                    .iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .map(|(_, k)| *k)
                    .collect();
                let cfg = calibrate::refit(ev, &base, reference, &others, noise)?;
                let s = ev.evaluate(&cfg)?.sse;
                Ok((i, cfg, s))
            })
            .collect::<Result<_>>()?;
        let Some((i, cfg, s)) = tries.into_iter().min_by(|a, b| a.2.total_cmp(&b.2)) else {
            break;
        };
        if n * (s / sse).ln() - n.ln() >= 0.0 {
            break;
        }
        keys.remove(i);
        model = cfg;
        sse = s;
    }
    Ok((model, keys, sse))
}

/// The best of a step's passing effects (every named one, the best
/// [`GENERIC_BESIDE_CONSTANTS`] generic directions) fitted beside the
/// site's constants `keys` ([`best_beside_constants`]), if it explains
/// enough of what the constants alone leave (`sse_constants`:
/// [`passes_beside_constants`]). The effect, the model with both and its
/// SSE.
fn effect_beside_constants(
    ev: &Evaluator<'_>,
    results: &[Ranked],
    keys: &[ProductKey],
    reference: &ProductParams,
    sse_constants: f64,
    noise: Option<f64>,
    options: &Options,
) -> Result<Option<(Candidate, ModelConfig, f64)>> {
    let _stage = ev.cost.enter(fit::Stage::Refits);
    let mut directions: Vec<&space::GenericSlot> = Vec::new();
    let tried: Vec<&Ranked> = results
        .iter()
        .filter(|r| r.0.passes_bic && r.0.passes_share)
        .filter(|r| match r.1.slots.first() {
            Some(Candidate::Named(_)) => true,
            Some(c @ Candidate::Generic(g)) => {
                if g.acts_on == ActsOn::Measurement
                    || constant_in_disguise(c, ev)
                    || directions.len() >= GENERIC_BESIDE_CONSTANTS
                    || directions.iter().any(|d| d.same_direction(g))
                {
                    return false;
                }
                directions.push(g);
                true
            }
            None => false,
        })
        .collect();
    let Some((c, own, u, pair_sse)) =
        best_beside_constants(ev, &tried, keys, reference, noise, options)?
    else {
        return Ok(None);
    };
    if !passes_beside_constants(ev, &c, &own, &u, pair_sse, sse_constants, noise, options)? {
        return Ok(None);
    }
    Ok(Some((c, own.config(&u), pair_sse)))
}

/// An effect fitted beside the site's constants: the effect, its space over
/// a base that holds the constants, its coordinates and the SSE.
type Beside = (Candidate, Space, Vec<f64>, f64);

/// The best of `tried` by SSE, each fitted beside the site's constants
/// `keys` ([`each_beside_constants`]).
fn best_beside_constants(
    ev: &Evaluator<'_>,
    tried: &[&Ranked],
    keys: &[ProductKey],
    reference: &ProductParams,
    noise: Option<f64>,
    options: &Options,
) -> Result<Option<Beside>> {
    let mut pairs = each_beside_constants(ev, tried, keys, reference, noise)?;
    pairs.sort_by(|a, b| a.3.total_cmp(&b.3));
    // A named effect that describes the data as well as the best generic
    // term beside the constants is the better statement there too, by
    // [`prefer_named`]'s criterion (the generic consumption term on air
    // temperature is temperature_consumption's form, 0.02 BIC units apart).
    let n = ev.n_active() as f64;
    let params = |c: &Candidate| (c.dims() + usize::from(c.is_step())) as f64;
    let named = match pairs.first() {
        Some(best) if best.0.is_generic() => pairs.iter().position(|p| {
            !p.0.is_generic()
                && n * (p.3 / best.3).ln() + (params(&p.0) - params(&best.0)) * n.ln()
                    < options.bic_threshold.abs()
        }),
        _ => None,
    };
    Ok(match named {
        Some(i) => Some(pairs.swap_remove(i)),
        None => pairs.into_iter().next(),
    })
}

/// A result fitted beside the site's constants: its index in the step's
/// results, its space over a base that holds the constants, its
/// coordinates and the SSE.
type BesideAt = (usize, Space, Vec<f64>, f64);

/// The results at `at` fitted beside the site's constants `keys`
/// ([`each_beside_constants`]), each with its index in `results`.
fn beside_constants_at(
    ev: &Evaluator<'_>,
    results: &[Ranked],
    at: &[usize],
    keys: &[ProductKey],
    reference: &ProductParams,
    noise: Option<f64>,
) -> Result<Vec<BesideAt>> {
    let tried: Vec<_> = at.iter().map(|&i| &results[i]).collect();
    let pairs = each_beside_constants(ev, &tried, keys, reference, noise)?;
    Ok(pairs
        .into_iter()
        .filter_map(|(c, space, u, sse)| {
            at.iter()
                .copied()
                .find(|&i| results[i].1.slots.first() == Some(&c))
                .map(|i| (i, space, u, sse))
        })
        .collect())
}

/// Each of `tried` fitted beside the site's constants `keys` (the constants
/// refitted on the effect's model, then the effect on theirs, then both
/// together), in the order given; one without a slot is left out.
fn each_beside_constants(
    ev: &Evaluator<'_>,
    tried: &[&Ranked],
    keys: &[ProductKey],
    reference: &ProductParams,
    noise: Option<f64>,
) -> Result<Vec<Beside>> {
    let pairs: Vec<Beside> = tried
        .par_iter()
        .map(|(_, space, u)| {
            let Some(c) = space.slots.first().cloned() else {
                return Ok(None);
            };
            let with_constants = calibrate::refit(ev, &space.config(u), reference, keys, noise)?;
            let own = Space {
                base: with_constants,
                slots: vec![c.clone()],
            };
            let mut fit = fit::fit(ev, &own, Start::Warm(own.units_of(&own.base)), None)?;
            // A fit that stopped at a bound of its box was standing in for
            // the constants (rail ageing's time constant at its 60 s floor
            // beside a muD 23 % high): beside them it starts again from
            // the grid.
            if u.iter().any(|&x| x <= 1e-6 || x >= 1.0 - 1e-6) {
                let fresh = fit::fit(ev, &own, Start::Fresh, None)?;
                if fresh.eval.sse < fit.eval.sse {
                    fit = fresh;
                }
            }
            // Then the constants and the effect together: alone, each
            // stays where it made up for the other (kc 39 % low beside a
            // rail ageing that takes three times the product away).
            let joint = calibrate::refit_with(ev, &own.config(&fit.u), reference, keys, &c, noise)?;
            let joint_sse = ev.evaluate(&joint)?.sse;
            if joint_sse < fit.eval.sse {
                let own = Space {
                    base: joint,
                    slots: vec![c.clone()],
                };
                let u = own.units_of(&own.base);
                return Ok(Some((c, own, u, joint_sse)));
            }
            Ok(Some((c, own, fit.u, fit.eval.sse)))
        })
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .flatten()
        .collect();
    Ok(pairs)
}

/// Whether an effect fitted beside the site's constants (`pair_sse`)
/// explains enough of what the constants alone leave (`sse_constants`):
/// BIC, share of the excess and cross-validation by day and by site, as
/// any effect.
#[allow(clippy::too_many_arguments)]
fn passes_beside_constants(
    ev: &Evaluator<'_>,
    c: &Candidate,
    own: &Space,
    u: &[f64],
    pair_sse: f64,
    sse_constants: f64,
    noise: Option<f64>,
    options: &Options,
) -> Result<bool> {
    let n = ev.active.iter().filter(|&&a| a).count();
    let k = c.dims() + usize::from(c.is_step());
    let delta_bic = n as f64 * (pair_sse / sse_constants).ln() + k as f64 * (n as f64).ln();
    let (_, big) = judge_share(sse_constants, pair_sse, n, noise, options);
    if delta_bic >= options.bic_threshold || !big {
        return Ok(false);
    }
    // Held-out blocks predicted better than by the constants alone (an
    // effect seen on one day alone by the sites only, as at a step).
    let by_site = ev.sites.len() >= 2;
    for blocking in [Blocking::Day, Blocking::Site] {
        if blocking == Blocking::Site && !by_site {
            continue;
        }
        let cv = fit::cross_validate(ev, own, u, blocking)?;
        let untested = blocking == Blocking::Day && by_site && cv.evidence_in.is_some();
        if cv.held_out_sse >= sse_constants && !untested {
            return Ok(false);
        }
    }
    Ok(true)
}

/// Whether a step's result contends for the step: it passes the BIC and
/// the share, and is no change in time before the first measurement it
/// could affect (a site constant in disguise).
fn contends(r: &Ranked, ev: &Evaluator<'_>) -> bool {
    r.0.passes_bic
        && r.0.passes_share
        && !r
            .1
            .slots
            .first()
            .is_some_and(|c| constant_in_disguise(c, ev))
}

/// Where among `results` the named rival of result `k` is
/// ([`named_on_quantity`]), if it was fitted at this step.
fn rival_of(results: &[Ranked], k: usize) -> Option<usize> {
    let named = results[k].1.slots.first().and_then(named_on_quantity)?;
    results
        .iter()
        .position(|x| x.1.slots.first() == Some(&named))
}

/// Whether a step's result predicts held-out blocks better than the current
/// model (`cv_current`, its SSE): by day, then by site where the recording
/// has two sites or more; the cross-validations are kept in `result`.
#[allow(clippy::too_many_arguments)]
fn cross_validated(
    ev: &Evaluator<'_>,
    result: &mut CandidateResult,
    space: &Space,
    u: &[f64],
    current: &ModelConfig,
    cv_current: f64,
    progress: &dyn Progress,
    step: usize,
) -> Result<bool> {
    progress.stage(&format!(
        "step {step}: cross-validating {} by day",
        result.label
    ));
    let (space, u) = &validated_with_its_constant(space, u, current, ev.data);
    let cv = fit::cross_validate(ev, space, u, Blocking::Day)?;
    // A sensor's offset belongs to its site: other sites cannot predict
    // it, and need not.
    let site_bound = space.slots.first().is_some_and(|c| {
        matches!(c, Candidate::Generic(g) if g.acts_on == ActsOn::Measurement && g.site.is_some())
    });
    let by_site = ev.sites.len() >= 2 && !site_bound;
    // An effect seen on one day alone (the rain of that day) is not tested
    // by the days, for none predicts another: the sites test it.
    let passes = cv.held_out_sse < cv_current || (by_site && cv.evidence_in.is_some());
    result.engine_runs += cv.runs;
    result.cv = Some(cv);
    result.passes_cv = Some(passes);
    if !passes || !by_site {
        return Ok(passes);
    }
    progress.stage(&format!(
        "step {step}: cross-validating {} by site",
        result.label
    ));
    let cv = fit::cross_validate(ev, space, u, Blocking::Site)?;
    let passes = cv.held_out_sse < cv_current;
    result.engine_runs += cv.runs;
    result.cv_site = Some(cv);
    result.passes_cv_site = Some(passes);
    Ok(passes)
}

/// The space a candidate is cross-validated in. A generic term fitted with
/// the site constant that scales its quantity beside it (on a base that
/// differs from the step's model `current` in that constant alone) has the
/// constant refitted in every fold, as what it is to the engine: a factor
/// on that quantity from before the first passage on (a step in time that
/// is a constant in disguise), on the step's model. Fitted on every block
/// and held in the folds, the constant carried the held-out block into
/// them: a transfer term on humidity with kt 47 % low beside it was
/// "supported" by two sites where the friction had changed at the third,
/// and predicted it better only through kt.
fn validated_with_its_constant(
    space: &Space,
    u: &[f64],
    current: &ModelConfig,
    data: &Dataset,
) -> (Space, Vec<f64>) {
    let unchanged = || (space.clone(), u.to_vec());
    let Some(Candidate::Generic(g)) = space.slots.first() else {
        return unchanged();
    };
    let Some(key) = twin_constant(g.acts_on) else {
        return unchanged();
    };
    let mut product = current.product;
    key.set(&mut product, key.get(&space.base.product));
    if space.base.product == current.product || product != space.base.product {
        return unchanged();
    }
    let Some(first_ns) = data.passages.iter().map(|p| p.log_time_ns).min() else {
        return unchanged();
    };
    let ratio = key.get(&space.base.product) / key.get(&current.product);
    let constant = Candidate::Generic(space::GenericSlot::factor(
        g.acts_on,
        Driver::Time,
        FormKind::Step,
        space::Scope::default(),
        Some(first_ns as f64 * 1e-9 - 1.0),
        space::Reach::STEP,
    ));
    let mut base = space.base.clone();
    base.product = current.product;
    let mut u = u.to_vec();
    u.push(constant.unit(0, ratio));
    let slots = vec![space.slots[0].clone(), constant];
    (Space { base, slots }, u)
}

/// How well each of `results` at `at` describes the data with the site's
/// constants calibrated beside it ([`calibrate::calibrate`], the effect
/// free): its BIC against the current model's SSE `sse`, counting the
/// effect's parameters and the constants its calibration moved (none
/// where the calibration does not lower the SSE).
fn calibrated_bic(
    ev: &Evaluator<'_>,
    results: &[Ranked],
    at: &[usize],
    reference: &ProductParams,
    sse: f64,
    noise: Option<f64>,
) -> Result<Vec<(usize, f64)>> {
    let _stage = ev.cost.enter(fit::Stage::Refits);
    let n = ev.active.iter().filter(|&&a| a).count() as f64;
    at.par_iter()
        .filter_map(|&i| {
            let (result, space, u) = &results[i];
            let effect = space.slots.first()?.clone();
            // A constant fitted beside the effect counts (`k`).
            Some((i, result.sse, result.k, space.config(u), effect))
        })
        .map(|(i, fit_sse, own, cfg, effect)| {
            let cal = calibrate::calibrate(ev, &cfg, reference, &[effect], noise)?;
            let cal_sse = ev.evaluate(&cal.model)?.sse;
            let (fit_sse, k) = match cal_sse < fit_sse {
                true => (cal_sse, own + cal.fitted.len()),
                false => (fit_sse, own),
            };
            Ok((i, n * (fit_sse / sse).ln() + k as f64 * n.ln()))
        })
        .collect()
}

/// Result `k` (the step's best) and its rivals, fitted beside the site's
/// constants before one is taken: its named rival on the same quantity
/// ([`rival_of`], with `named_rival`) and the contenders of another kind
/// whose BIC drop is within the BIC threshold of its own (the BIC cannot
/// tell them apart while the constants are held where the laboratory put
/// them); at most [`MAX_CONTENDERS`] in all, the best first.
fn rivals_beside_constants(
    results: &[Ranked],
    k: usize,
    named_rival: bool,
    ev: &Evaluator<'_>,
    window: f64,
) -> Vec<usize> {
    let mut at = vec![k];
    if named_rival {
        at.extend(rival_of(results, k));
    }
    let Some(own) = results[k].1.slots.first() else {
        return at;
    };
    for (i, r) in results.iter().enumerate() {
        if at.len() >= MAX_CONTENDERS {
            break;
        }
        let close = (r.0.delta_bic - results[k].0.delta_bic).abs() <= window;
        let other_kind = r.1.slots.first().is_some_and(|c| {
            !same_kind(c, own)
                && !matches!(c, Candidate::Generic(g) if g.acts_on == ActsOn::Measurement)
        });
        let failed_cv = r.0.passes_cv == Some(false) || r.0.passes_cv_site == Some(false);
        if close && other_kind && !failed_cv && !at.contains(&i) && contends(r, ev) {
            at.push(i);
        }
    }
    at
}

/// Whether two candidates are of one kind: generic terms on the same
/// quantity (whatever drives them), a named effect and a term everywhere
/// on the quantity it scales ([`named_on_quantity`]: the named one is
/// preferred between them by its own rule, [`prefer_named`]), or the
/// same named effect.
fn same_kind(a: &Candidate, b: &Candidate) -> bool {
    match (a, b) {
        (Candidate::Generic(g), Candidate::Generic(h)) => g.acts_on == h.acts_on,
        (Candidate::Generic(_), _) => named_on_quantity(a).as_ref() == Some(b),
        (_, Candidate::Generic(_)) => named_on_quantity(b).as_ref() == Some(a),
        _ => a == b,
    }
}

/// The labels of `results` at `at`, joined.
fn labels_of(results: &[Ranked], at: &[usize]) -> String {
    at.iter()
        .map(|&i| results[i].0.label.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The named effect that is a factor on the quantity a generic term acts
/// on everywhere, whatever drives the term (effects.md:
/// `temperature_consumption` on the consumption, `speed_transfer` on the
/// transfer): the rival the term may stand in for.
fn named_on_quantity(c: &Candidate) -> Option<Candidate> {
    match c {
        Candidate::Generic(g) if g.scope().keys() == 0 => match g.acts_on {
            ActsOn::Consumption => Some(Candidate::Named(Named::TemperatureConsumption)),
            ActsOn::Transfer => Some(Candidate::Named(Named::SpeedTransfer)),
            _ => None,
        },
        _ => None,
    }
}

/// Takes out of `current` (and `accepted`) every effect found that the
/// model no longer needs ([`least_needed`]), the weakest first. The effects
/// of the starting model (the first `starting`) stay. Returns those taken
/// out.
fn drop_unneeded(
    ev: &Evaluator<'_>,
    accepted: &mut Vec<Candidate>,
    starting: usize,
    current: &mut ModelConfig,
    reference: &ProductParams,
    noise: Option<f64>,
    options: &Options,
) -> Result<Vec<Candidate>> {
    let _stage = ev.cost.enter(fit::Stage::Refits);
    let n = ev.active.iter().filter(|&&a| a).count();
    let mut sse = ev.evaluate(current)?.sse;
    let mut dropped = Vec::new();
    loop {
        let without = without_each(ev, accepted, starting, current, &[], reference, noise)?;
        let Some((i, w, cfg)) = least_needed(accepted, without, sse, n, noise, options) else {
            return Ok(dropped);
        };
        dropped.push(accepted.remove(i));
        (*current, sse) = (cfg, w);
    }
}

/// The model without each effect found (`accepted[starting..]`, those on in
/// `current`), the site's constants `keys` refitted on it (none: as it is):
/// the effect's index in `accepted`, the model's SSE and the model.
fn without_each(
    ev: &Evaluator<'_>,
    accepted: &[Candidate],
    starting: usize,
    current: &ModelConfig,
    keys: &[ProductKey],
    reference: &ProductParams,
    noise: Option<f64>,
) -> Result<Vec<(usize, f64, ModelConfig)>> {
    let _stage = ev.cost.enter(fit::Stage::Refits);
    (starting..accepted.len())
        .into_par_iter()
        .filter(|&i| accepted[i].get(&current.effects).is_some())
        .map(|i| {
            let mut cfg = current.clone();
            accepted[i].unset(&mut cfg.effects);
            let cfg = calibrate::refit(ev, &cfg, reference, keys, noise)?;
            Ok((i, ev.evaluate(&cfg)?.sse, cfg))
        })
        .collect()
}

/// A step in time taken on one quantity of the product may be its twin
/// on another at the same moment: an applicator's pulse mass, the
/// transfer or the consumption everywhere. Taken while the site's
/// constants were still off, the wrong twin can win (a nozzle at half on
/// the tangent, seed 20261147's site 20: the transfer step came 290 BIC
/// units ahead at step 1; with the constants found at step 2 the nozzle
/// is about 300 better). Each accepted step in time is fitted again as
/// each twin at its moment, beside the model as it is now; the best twin
/// replaces it where it lowers the BIC by the threshold, and the constants
/// taken so far are refitted with it. Returns the twin's label (and says
/// it to `progress`).
fn swap_time_twins(
    ev: &Evaluator<'_>,
    data: &Dataset,
    accepted: &mut [Candidate],
    current: &mut ModelConfig,
    sse: &mut f64,
    constants: (&ProductParams, &[ProductKey], Option<f64>),
    (options, progress, step): (&Options, &dyn Progress, usize),
) -> Result<Option<String>> {
    let _stage = ev.cost.enter(fit::Stage::Refits);
    let product = [ActsOn::Transfer, ActsOn::Consumption, ActsOn::PulseMass];
    let twins: Vec<(usize, Candidate, Start)> = accepted
        .iter()
        .enumerate()
        .filter_map(|(i, a)| match a {
            Candidate::Generic(g)
                if g.driver == Some(Driver::Time)
                    && g.form == Some(FormKind::Step)
                    && product.contains(&g.acts_on) =>
            {
                let p = a.get(&current.effects)?;
                Some((i, g, a.unit(0, *p.first()?)))
            }
            _ => None,
        })
        .flat_map(|(i, g, u)| {
            let scopes = [(ActsOn::Transfer, None), (ActsOn::Consumption, None)]
                .into_iter()
                .chain(
                    data.section
                        .applicators
                        .iter()
                        .map(|a| (ActsOn::PulseMass, Some(a.id.clone()))),
                );
            scopes
                .map(move |(acts_on, applicator)| {
                    space::GenericSlot::factor(
                        acts_on,
                        Driver::Time,
                        FormKind::Step,
                        space::Scope {
                            applicator,
                            ..space::Scope::default()
                        },
                        g.x0(),
                        space::Reach::STEP,
                    )
                })
                .filter(move |t| !t.same_direction(g))
                .map(move |t| (i, Candidate::Generic(t), Start::Warm(vec![u])))
        })
        .collect();
    if twins.is_empty() {
        return Ok(None);
    }
    let fits: Vec<(usize, Candidate, Space, fit::Fit)> = twins
        .into_par_iter()
        .map(|(i, twin, start)| {
            let mut base = current.clone();
            accepted[i].unset(&mut base.effects);
            let space = Space {
                base,
                slots: vec![twin.clone()],
            };
            let fit = fit::fit(ev, &space, start, None)?;
            Ok((i, twin, space, fit))
        })
        .collect::<Result<_>>()?;
    let n = ev.n_counted(None) as f64;
    let Some((i, twin, space, fit)) = fits
        .into_iter()
        .filter(|f| n * (f.3.eval.sse / *sse).ln() <= options.bic_threshold)
        .min_by(|a, b| a.3.eval.sse.total_cmp(&b.3.eval.sse))
    else {
        return Ok(None);
    };
    *current = space.config(&fit.u);
    *sse = fit.eval.sse;
    let label = twin.label();
    progress.stage(&format!("step {step}: {label} describes it better"));
    accepted[i] = twin;
    let (reference, keys, noise) = constants;
    if !keys.is_empty() {
        let refitted = calibrate::refit(ev, current, reference, keys, noise)?;
        let eval = ev.evaluate(&refitted)?;
        if eval.sse < *sse {
            *current = refitted;
            *sse = eval.sse;
        }
    }
    Ok(Some(label))
}

/// Of the models `without` one effect each ([`without_each`]), the one
/// whose effect the model (SSE `sse` over `n` measurements) needs least, if
/// it does not need it: taking it out raises the BIC by no more than the
/// threshold, or the effect removes too small a share of the excess over
/// the noise to matter.
fn least_needed(
    accepted: &[Candidate],
    without: Vec<(usize, f64, ModelConfig)>,
    sse: f64,
    n: usize,
    noise: Option<f64>,
    options: &Options,
) -> Option<(usize, f64, ModelConfig)> {
    let ln_n = (n as f64).ln();
    without
        .into_iter()
        .map(|(i, w, cfg)| {
            let c = &accepted[i];
            let k = c.dims() + usize::from(c.is_step());
            let keep_bic = n as f64 * (sse / w).ln() + k as f64 * ln_n;
            let (_, big) = judge_share(w, sse, n, noise, options);
            (keep_bic, big, (i, w, cfg))
        })
        .filter(|(keep_bic, big, _)| *keep_bic >= options.bic_threshold || !big)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, _, r)| r)
}

/// A fitted space: the space, its search coordinates and their evaluation.
type Fitted = (Space, Vec<f64>, std::sync::Arc<fit::Evaluation>);

/// Places a step's threshold: the fitted factor is tried at thresholds
/// around the first guess (between consecutive acting times for time, see
/// [`acting_times_s`]; between
/// consecutive observed values for another driver, coarse then fine), and
/// the threshold goes to the middle of the thresholds that give exactly the
/// best fit: a friction term acts only where it is measured, so every t0
/// between two measured trains gives the same values, and wherever in there
/// the change was, the middle is off by least. (A wider interval, of
/// thresholds within the noise of the best, moved the threshold across
/// trains and observed values it should not cross.) The factor is then
/// fitted again there.
fn refine_step(
    ev: &Evaluator<'_>,
    data: &Dataset,
    drivers: &Drivers,
    space: &Space,
    u: &[f64],
) -> Result<Option<Fitted>> {
    let _stage = ev.cost.enter(fit::Stage::Refits);
    let Some(Candidate::Generic(slot)) = space.slots.first() else {
        return Ok(None);
    };
    let (Some(x0), Some(driver)) = (slot.x0(), slot.driver) else {
        return Ok(None);
    };
    let f = space
        .params(u)
        .pop()
        .and_then(|p| p.first().copied())
        .unwrap_or(1.0);
    let with_x0 = |x: f64| -> Space {
        let moved = space::GenericSlot::factor(
            slot.acts_on,
            driver,
            FormKind::Step,
            slot.scope(),
            Some(x),
            space::Reach::STEP,
        );
        Space {
            base: space.base.clone(),
            slots: vec![Candidate::Generic(moved)],
        }
    };
    let sse_at = |x: f64| -> Result<f64> {
        let s = with_x0(x);
        Ok(ev.evaluate(&s.config(&[s.slots[0].unit(0, f)]))?.sse)
    };
    // The intervals between consecutive values a threshold can fall in:
    // trains for time, observed values for another driver.
    let values: Vec<f64> = if driver == Driver::Time {
        acting_times_s(slot, data)
    } else {
        drivers.distinct(driver).to_vec()
    };
    let mut gaps: Vec<(f64, f64)> = values.windows(2).map(|w| (w[0], w[1])).collect();
    // An applicator's pulses come in bursts, one per train (an axle
    // counter fires them a fraction of a second apart): a nozzle's change
    // is placed between bursts, not among a train's own pulses.
    if driver == Driver::Time
        && slot.acts_on == ActsOn::PulseMass
        && gaps.iter().any(|g| g.1 - g.0 >= BURST_GAP_S)
    {
        gaps.retain(|g| g.1 - g.0 >= BURST_GAP_S);
    }
    if gaps.is_empty() {
        return Ok(None);
    }
    let at = gaps.partition_point(|g| g.1 <= x0).min(gaps.len() - 1);
    // Time: the gaps from 8 h before to 2 h after (the widest 48 of them
    // first where pulses make more, then every gap next to the best). Another
    // driver: a coarse pass over a fifth of the values on each side, then
    // every gap next to the best coarse one.
    let mut fine_pass = true;
    let mut candidates: Vec<usize> = if driver == Driver::Time {
        // Never at or before the first time it can act: that is a constant.
        let first_s = first_affected_s(slot, ev);
        let mut window: Vec<usize> = (0..gaps.len())
            .filter(|&k| {
                let mid = 0.5 * (gaps[k].0 + gaps[k].1);
                mid >= x0 - 8.0 * 3600.0 && mid <= x0 + 2.0 * 3600.0 && mid > first_s
            })
            .collect();
        if window.len() > COARSE_THRESHOLDS {
            window.sort_by(|&a, &b| (gaps[b].1 - gaps[b].0).total_cmp(&(gaps[a].1 - gaps[a].0)));
            window.truncate(COARSE_THRESHOLDS);
        } else {
            fine_pass = false;
        }
        window
    } else {
        let reach = (gaps.len() / 5).max(8);
        let (lo, hi) = (at.saturating_sub(reach), (at + reach).min(gaps.len() - 1));
        let stride = ((hi - lo) / 24).max(1);
        (lo..=hi).step_by(stride).chain([at]).collect()
    };
    let mut tried: Vec<(usize, f64)> = Vec::new();
    for pass in 0..2 {
        candidates.sort_unstable();
        candidates.dedup();
        candidates.retain(|k| !tried.iter().any(|(t, _)| t == k));
        let sse: Vec<f64> = candidates
            .par_iter()
            .map(|&k| sse_at(0.5 * (gaps[k].0 + gaps[k].1)))
            .collect::<Result<_>>()?;
        tried.extend(candidates.iter().copied().zip(sse));
        tried.sort_unstable_by_key(|t| t.0);
        if pass == 1 || !fine_pass {
            break;
        }
        // Fine: every gap between the best coarse one's neighbours.
        let Some(b) = (0..tried.len()).min_by(|&a, &b| tried[a].1.total_cmp(&tried[b].1)) else {
            break;
        };
        let from = tried[b.saturating_sub(1)].0;
        let to = tried[(b + 1).min(tried.len() - 1)].0;
        candidates = (from..=to).collect();
        if candidates.len() > COARSE_THRESHOLDS {
            let stride = candidates.len() / COARSE_THRESHOLDS + 1;
            candidates = (from..=to).step_by(stride).chain([tried[b].0]).collect();
        }
    }
    let base_sse = ev.evaluate(&space.config(u))?.sse;
    let Some(best) = (0..tried.len()).min_by(|&a, &b| tried[a].1.total_cmp(&tried[b].1)) else {
        return Ok(None);
    };
    if tried[best].1 >= base_sse {
        return Ok(None);
    }
    // The factor fitted at the best threshold, and every threshold tried
    // again with it: the first guess's factor was a compromise that makes
    // the other thresholds look worse than they are.
    let at_best = with_x0(0.5 * (gaps[tried[best].0].0 + gaps[tried[best].0].1));
    let refit = fit::fit(
        ev,
        &at_best,
        Start::Warm(vec![at_best.slots[0].unit(0, f)]),
        None,
    )?;
    let f = at_best
        .params(&refit.u)
        .pop()
        .and_then(|p| p.first().copied())
        .unwrap_or(f);
    let sse_at = |x: f64| -> Result<f64> {
        let s = with_x0(x);
        Ok(ev.evaluate(&s.config(&[s.slots[0].unit(0, f)]))?.sse)
    };
    // Only the thresholds that came close: the factor moves the SSE of
    // thresholds near the best alike, and one far behind does not win
    // with it (the others keep their SSE, which can only be worse).
    let mut order: Vec<usize> = (0..tried.len()).collect();
    order.sort_by(|&a, &b| tried[a].1.total_cmp(&tried[b].1));
    // (Thresholds tied with the last one kept stay: a run of thresholds
    // that give the same values is never cut.)
    if let Some(&last) = order.get(REFIT_THRESHOLDS.saturating_sub(1)) {
        let cut = tried[last].1;
        let keep = order
            .iter()
            .take_while(|&&t| tried[t].1 - cut <= 1e-12 * cut.abs())
            .count()
            .max(REFIT_THRESHOLDS);
        order.truncate(keep);
    }
    let again: Vec<f64> = order
        .par_iter()
        .map(|&t| {
            let k = tried[t].0;
            sse_at(0.5 * (gaps[k].0 + gaps[k].1))
        })
        .collect::<Result<_>>()?;
    for t in tried.iter_mut() {
        t.1 = f64::INFINITY;
    }
    for (&t, sse) in order.iter().zip(again) {
        tried[t].1 = sse;
    }
    let Some(best) = (0..tried.len()).min_by(|&a, &b| tried[a].1.total_cmp(&tried[b].1)) else {
        return Ok(None);
    };
    let best_sse = tried[best].1;
    let near = |k: usize| tried[k].1 - best_sse <= 1e-12 * best_sse;
    let (mut first, mut last) = (best, best);
    while first > 0 && near(first - 1) {
        first -= 1;
    }
    while last + 1 < tried.len() && near(last + 1) {
        last += 1;
    }
    let (lo, hi) = (gaps[tried[first].0].0, gaps[tried[last].0].1);
    let mid = 0.5 * (lo + hi);
    let x = if driver == Driver::Time {
        mid.round()
    } else {
        // Inside the gap that holds the middle, never on an observed value:
        // every value the recording shows then falls on one side of it.
        let middle = (first..=last)
            .map(|k| gaps[tried[k].0])
            .min_by(|a, b| {
                let off = |g: &(f64, f64)| (0.5 * (g.0 + g.1) - mid).abs();
                off(a).total_cmp(&off(b))
            })
            .unwrap_or((lo, hi));
        readable_between(middle.0, middle.1)
    };
    let s = with_x0(x);
    let start = Start::Warm(vec![s.slots[0].unit(0, f)]);
    let fitted = fit::fit(ev, &s, start, None)?;
    Ok(Some((s, fitted.u, fitted.eval)))
}

/// The number with the fewest significant digits in the middle half of
/// (lo, hi), strictly inside it: a threshold people can read (85 rather
/// than 84.9873), where any value in between says the same.
fn readable_between(lo: f64, hi: f64) -> f64 {
    let mid = 0.5 * (lo + hi);
    let (a, b) = (mid - 0.25 * (hi - lo), mid + 0.25 * (hi - lo));
    for digits in 1..=15 {
        let scale = 10f64.powi(digits - 1 - mid.abs().max(1e-300).log10().floor() as i32);
        let x = (mid * scale).round() / scale;
        if x > lo && x < hi && x >= a && x <= b {
            return x;
        }
    }
    mid
}

/// The named effect a generic term is a form of (effects.md:
/// `temperature_consumption` is consumption × exp of air temperature,
/// `speed_transfer` transfer × power of speed), for an unscoped term.
fn named_family(c: &Candidate) -> Option<Candidate> {
    match c {
        Candidate::Generic(g) if g.scope().keys() == 0 => match (g.acts_on, g.driver) {
            (ActsOn::Consumption, Some(Driver::AirTemperatureC)) => {
                Some(Candidate::Named(Named::TemperatureConsumption))
            }
            (ActsOn::Transfer, Some(Driver::SpeedMps)) => {
                Some(Candidate::Named(Named::SpeedTransfer))
            }
            _ => None,
        },
        _ => None,
    }
}

/// Fits each candidate alone on top of `current`, in parallel, telling
/// `progress` how many are done.
///
/// Most candidates of a step cannot come near its best, and their fits
/// to the end were half of what a discover cost (2026-11-30: 3 040 of
/// 6 305 run-equivalents over tests/discover.rs and
/// tests/discover_generic.rs). So each first gets a look
/// ([`fit::first_look`]: a warm start's first two points, or a fresh
/// grid); a named effect or a generic term on the product (whose
/// evaluations are replays) goes on only where, with [`fit::OPTIMISM`]
/// times what its local model still promises, its BIC drop could reach
/// [`PRUNE_SHARE`] of the step's best so far (`at_least` or the best
/// point of any fit), in rounds of [`ROUND_RUNS`] replays
/// ([`fit::look_further`]) after which its hope and the best are weighed
/// again; one whose direction is among the `forms_for` best is fitted to
/// its end at once (those are fitted in their other forms next,
/// [`FORMS_FOR`]). The rest stop where they are, marked ([`fit::Fit::stopped`]): the rules
/// that weigh a candidate against the best (contenders with the model's
/// effects free and twins beside their constant within
/// [`CONTENDER_SHARE`], time steps placed within half) look within that
/// share, and the choice fits them to the end before it would decide
/// where one could precede or rival its candidate. Read-out terms and
/// time steps cost a fraction of a replay each and are fitted to the end
/// at once.
fn fit_each(
    ev: &Evaluator<'_>,
    current: &ModelConfig,
    candidates: &[(Candidate, Start)],
    progress: &dyn Progress,
    bic: &BicOf,
    at_least: f64,
    forms_for: usize,
) -> Result<Vec<(Candidate, Space, fit::Fit)>> {
    let finished = std::sync::atomic::AtomicU64::new(0);
    let space_of = |c: &Candidate| Space {
        base: current.clone(),
        slots: vec![c.clone()],
    };
    let looks: Vec<fit::Look> = candidates
        .par_iter()
        .map(|(c, start)| {
            let space = space_of(c);
            let look = if may_stop(c) {
                fit::first_look(ev, &space, start)
            } else {
                fit::fit(ev, &space, start.clone(), None).map(fit::Look::Done)
            };
            if matches!(look, Ok(fit::Look::Done(_))) {
                let n = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                progress.done(n);
            }
            look
        })
        .collect::<Result<_>>()?;
    let k_of = |c: &Candidate| c.dims() + usize::from(c.is_step());
    let seen = |look: &fit::Look| match look {
        fit::Look::Done(f) | fit::Look::Open(f, _) => f.eval.sse,
    };
    let best = candidates
        .iter()
        .zip(&looks)
        .map(|((c, _), look)| bic.of(seen(look), k_of(c)))
        .fold(at_least, f64::min);
    // The best directions of generic terms on a driver, by what their
    // looks reached: they are fitted in every other form next, so they
    // are fitted to the end here.
    let mut directions: Vec<(f64, &space::GenericSlot)> = candidates
        .iter()
        .zip(&looks)
        .filter_map(|((c, _), look)| match c {
            Candidate::Generic(g) if g.driver.is_some_and(|d| d != Driver::Time) => {
                Some((seen(look), g))
            }
            _ => None,
        })
        .filter(|(sse, _)| *sse < bic.sse)
        .collect();
    directions.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut top: Vec<&space::GenericSlot> = Vec::new();
    for (_, g) in directions {
        if top.len() < forms_for && !top.iter().any(|t| t.same_direction(g)) {
            top.push(g);
        }
    }
    let is_top = |c: &Candidate| matches!(c, Candidate::Generic(g) if top.iter().any(|t| t.same_direction(g)));
    let wanted = |c: &Candidate, optimistic: f64, best: f64| {
        best >= 0.0 || bic.of(optimistic, k_of(c)) <= PRUNE_SHARE * best || is_top(c)
    };
    let done = || {
        let n = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
        progress.done(n);
    };
    // Rounds: every open fit that could still come near the best goes on
    // for ROUND_RUNS more replays (a direction fitted in its other forms
    // next to its end), the best is taken again, and what can no longer
    // reach its share stops.
    let mut states = looks;
    let mut best = best;
    loop {
        best = candidates
            .iter()
            .zip(&states)
            .map(|((c, _), look)| bic.of(seen(look), k_of(c)))
            .fold(best, f64::min);
        let open: Vec<usize> = (0..states.len())
            .filter(|&i| match &states[i] {
                fit::Look::Open(f, optimistic) => {
                    f.stopped.is_none() && wanted(&candidates[i].0, *optimistic, best)
                }
                fit::Look::Done(_) => false,
            })
            .collect();
        for (i, state) in states.iter_mut().enumerate() {
            if let fit::Look::Open(f, optimistic) = state {
                if f.stopped.is_none() && !open.contains(&i) {
                    f.stopped = Some(*optimistic);
                    done();
                }
            }
        }
        if open.is_empty() {
            break;
        }
        let further: Vec<fit::Look> = open
            .par_iter()
            .map(|&i| {
                let (c, start) = &candidates[i];
                let space = space_of(c);
                if is_top(c) {
                    fit::fit(ev, &space, start.clone(), None).map(fit::Look::Done)
                } else {
                    fit::look_further(ev, &space, start, ROUND_RUNS)
                }
            })
            .collect::<Result<_>>()?;
        for (i, look) in open.into_iter().zip(further) {
            let before = match &states[i] {
                fit::Look::Done(f) | fit::Look::Open(f, _) => f.runs,
            };
            states[i] = match look {
                fit::Look::Done(mut f) => {
                    f.runs += before;
                    done();
                    fit::Look::Done(f)
                }
                fit::Look::Open(mut f, optimistic) => {
                    f.runs += before;
                    fit::Look::Open(f, optimistic)
                }
            };
        }
    }
    Ok(candidates
        .iter()
        .zip(states)
        .map(|((c, _), state)| {
            let fit = match state {
                fit::Look::Done(f) | fit::Look::Open(f, _) => f,
            };
            (c.clone(), space_of(c), fit)
        })
        .collect())
}

/// The replays an open fit goes on for in one round of [`fit_each`]
/// before its hope is weighed again (a line search's step is one).
const ROUND_RUNS: usize = 3;

/// Whether a candidate's fit may stop after its first look
/// ([`fit_each`]): a named effect, or a generic term on the product along
/// a driver other than time (their evaluations are replays from the
/// start).
fn may_stop(c: &Candidate) -> bool {
    match c {
        Candidate::Named(_) => true,
        Candidate::Generic(g) => {
            g.acts_on.role() == tortwin_model::role::Role::State
                && g.driver.is_some_and(|d| d != Driver::Time)
        }
    }
}

/// A stopped fit goes on only where its BIC drop, optimistically, could
/// reach this share of the step's best ([`fit_each`]): every rule that
/// weighs candidates against the best looks within it (placing time
/// steps at 0.5, contenders and twins at [`CONTENDER_SHARE`]).
const PRUNE_SHARE: f64 = 0.5;

/// The BIC drop of a candidate against the step's model.
struct BicOf {
    /// The step model's SSE and the measurements counted.
    sse: f64,
    n: usize,
}

impl BicOf {
    fn of(&self, sse: f64, k: usize) -> f64 {
        let n = self.n as f64;
        n * (sse / self.sse).ln() + k as f64 * n.ln()
    }
}

/// Moves the best passing named effect in front of the generic terms when
/// the best generic term is not decisively better (effects.md: an effect is
/// reported by its name where a named effect describes it; the named
/// effects are the model's own vocabulary).
fn prefer_named(results: &mut [Ranked], n: usize, options: &Options) {
    let passing = |r: &CandidateResult| r.passes_bic && r.passes_share;
    let Some(best) = results.iter().position(|r| passing(&r.0)) else {
        return;
    };
    if results[best].0.name != "generic" {
        return;
    }
    // A named effect acts everywhere: it describes the data only where the
    // best generic term does too (a term scoped to one rail, applicator or
    // site says something the named effect cannot).
    let unscoped = matches!(
        results[best].1.slots.first(),
        Some(Candidate::Generic(g)) if g.scope().keys() == 0
    );
    if !unscoped {
        return;
    }
    // "Describes it": the generic term is not decisively better, by the
    // same criterion that accepts an effect at all (the BIC of one against
    // the other). A named effect that leaves a residual the generic term
    // explains is a stand-in (temperature for humidity, say), however much
    // of the first residual both remove.
    let ln_n = (n as f64).ln();
    let generic = &results[best].0;
    if let Some(named) = results.iter().position(|r| {
        r.0.name != "generic"
            && passing(&r.0)
            && n as f64 * (r.0.sse / generic.sse).ln() + (r.0.k as f64 - generic.k as f64) * ln_n
                < options.bic_threshold.abs()
    }) {
        results[best..=named].rotate_right(1);
    }
}

/// A sensor's offset: the narrowest scope (site, rail, quantity: one
/// instrument) goes first when it describes the residual as well as the
/// best offset, to within [`NARROW_MARGIN`] of BIC: where the few
/// tribometer readings at a site cannot tell a sensor's offset from a
/// site's, the statement stays with the instrument that carries the
/// evidence. The BIC decides otherwise, both ways: readings that share the
/// offset make the broader scope better, readings that do not, worse.
fn prefer_narrow_offsets(results: &mut [Ranked], n: usize) {
    let passing = |r: &CandidateResult| r.passes_bic && r.passes_share;
    let Some(best) = results.iter().position(|r| passing(&r.0)) else {
        return;
    };
    let offset_scope = |space: &Space| match space.slots.first() {
        Some(Candidate::Generic(g)) if g.acts_on == ActsOn::Measurement => Some(g.scope()),
        _ => None,
    };
    let Some(broad) = offset_scope(&results[best].1) else {
        return;
    };
    let within = |narrow: &space::Scope| {
        broad
            .site
            .as_ref()
            .is_none_or(|s| narrow.site.as_ref() == Some(s))
            && broad
                .rail
                .as_ref()
                .is_none_or(|r| narrow.rail.as_ref() == Some(r))
            && broad.quantity.is_none_or(|q| narrow.quantity == Some(q))
            && narrow.keys() > broad.keys()
    };
    let best_sse = results[best].0.sse;
    let narrowest = results
        .iter()
        .enumerate()
        .filter(|(_, r)| passing(&r.0))
        .filter_map(|(k, r)| offset_scope(&r.1).map(|s| (k, s, r.0.sse)))
        .filter(|(_, s, sse)| within(s) && n as f64 * (sse / best_sse).ln() < NARROW_MARGIN)
        .max_by(|a, b| a.1.keys().cmp(&b.1.keys()).then(b.2.total_cmp(&a.2)));
    if let Some((k, _, _)) = narrowest {
        results[best..=k].rotate_right(1);
    }
}

/// How directly a driver can cause a change of the model's quantities, for
/// [`prefer_direct_drivers`]: rain wets the rail, temperature changes the
/// product, the wheel's own speed, load and creepage act at the contact;
/// relative humidity in a weather log rises with rain and falls with
/// temperature, so it often stands in for them; a step in time stands in
/// for anything.
fn directness(driver: Option<Driver>) -> u8 {
    match driver {
        Some(Driver::PrecipitationMmH) => 0,
        Some(Driver::AirTemperatureC) => 1,
        Some(Driver::SpeedMps | Driver::WheelLoadKn | Driver::Creepage) => 2,
        Some(Driver::RelativeHumidity) => 3,
        Some(Driver::Time) | None => 4,
    }
}

/// Two generic terms on the same quantity and scope whose drivers split the
/// measurements identically (rain at or above 0.8 mm/h exactly when
/// humidity is at or above 0.88) fit to the same residual: the recording
/// cannot tell them apart. The one with the more direct driver
/// ([`directness`]) goes first; the report lists the other beside it with
/// the same ΔBIC.
fn prefer_direct_drivers(results: &mut [Ranked]) {
    let passing = |r: &CandidateResult| r.passes_bic && r.passes_share;
    let Some(best) = results.iter().position(|r| passing(&r.0)) else {
        return;
    };
    let slot = |space: &Space| match space.slots.first() {
        Some(Candidate::Generic(g)) => Some(g.clone()),
        _ => None,
    };
    let Some(first) = slot(&results[best].1) else {
        return;
    };
    let best_sse = results[best].0.sse;
    let tied = |r: &CandidateResult| (r.sse - best_sse).abs() <= 1e-9 * best_sse;
    let better = results
        .iter()
        .enumerate()
        .skip(best + 1)
        .filter(|(_, r)| passing(&r.0) && tied(&r.0))
        .filter_map(|(k, r)| slot(&r.1).map(|g| (k, g)))
        .filter(|(_, g)| {
            g.acts_on == first.acts_on
                && g.scope() == first.scope()
                && directness(g.driver) < directness(first.driver)
        })
        .min_by_key(|(k, g)| (directness(g.driver), *k));
    if let Some((k, _)) = better {
        results[best..=k].rotate_right(1);
    }
}

/// The share of the current excess over the noise a candidate removes, and
/// whether that passes: at least [`Options::min_excess_share`] of it, and
/// a drop of the mean squared residual of at least [`MIN_EFFECT`] σ² (an
/// effect too small to matter to anyone is not added, however significant
/// with many measurements).
fn judge_share(
    sse0: f64,
    sse1: f64,
    n: usize,
    noise: Option<f64>,
    options: &Options,
) -> (Option<f64>, bool) {
    let Some(s) = noise else {
        return (None, true);
    };
    let excess = sse0 - n as f64 * s * s;
    let share = (excess > 0.0).then(|| (sse0 - sse1) / excess);
    let big_enough = (sse0 - sse1) / n as f64 >= MIN_EFFECT * s * s;
    (
        share,
        big_enough && share.is_none_or(|x| x >= options.min_excess_share),
    )
}

/// See [`judge_share`]: 2 % of σ², an effect of about 0.14 σ RMS.
const MIN_EFFECT: f64 = 0.02;

/// See [`prefer_narrow_offsets`]: a difference of BIC that is "not worth
/// more than a bare mention".
const NARROW_MARGIN: f64 = 2.0;

/// The exp terms whose other forms are fitted too, per step.
const FORMS_FOR: usize = 2;
