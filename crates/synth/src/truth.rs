//! The truth run: each planned day pushed through the one engine twice,
//! with the truth configuration and with the defaults; the truth plus noise
//! becomes the measured value, the defaults' residual the key's RMSE. The
//! day's messages are written as they were planned, the tribometer readings
//! kept for the end of the file if asked.

use std::path::Path;
use tortwin_study::progress::Progress;

use rand::Rng;
use rand_distr::{Distribution, Normal};

use super::params::SynthParams;
use super::planner::Planner;
use super::report::{
    quantity_slot, ByQuantity, Counts, NoiseKey, RainKey, RmseKey, SynthReport, QUANTITIES,
};
use super::traffic::TrainKind;
use super::writing::{self, SynthFile};
use super::{round_dp, stream, utc, Stream, GENERATOR, HOUR_NS};
use tortwin_engine::sink::{MeasurementOutput, Sink};
use tortwin_engine::{Engine, EngineOptions};
use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_recording::wire::{MeasurementMsg, PulseMsg};
use tortwin_recording::{Direction, Event, EventKind, Quantity};
use tortwin_study::{Error, Result};

/// Writes the synthetic recording `params` describes to `out` (under a
/// temporary name, renamed when complete), with measurements from the
/// engine run with `truth`, and returns its key.
pub fn generate(
    params: &SynthParams,
    truth: &ModelConfig,
    out: &Path,
    progress: &dyn Progress,
) -> Result<SynthReport> {
    params.validate()?;
    let section = params.section();
    let origin_ns = params.start_ns as i64;
    tortwin_engine::terms::check_terms_against(
        &truth.effects.generic,
        &section,
        "truth configuration",
    )?;
    let line = match &params.line {
        Some(layout) => {
            let line = layout
                .line(&section)
                .map_err(|e| UsageError(layout.error(e)))?;
            tortwin_engine::line::check_config(truth, "the truth (--truth-config, --hidden)")?;
            Some(line)
        }
        None => None,
    };
    let bends = match (&params.line, &line) {
        (Some(layout), Some(line)) => layout.bends(line),
        _ => Vec::new(),
    };
    let mut truth_engine = Engine::on_line(
        section.clone(),
        line.clone(),
        truth.clone(),
        EngineOptions::default(),
        origin_ns,
    );
    let mut baseline_engine = Engine::on_line(
        section.clone(),
        line.clone(),
        ModelConfig::default(),
        EngineOptions::default(),
        origin_ns,
    );
    let grid = truth_engine.grid().clone();

    let mut planner = Planner::new(params, section.clone(), bends);
    let mut file = SynthFile::create(out, params)?;
    let mut counts = Counts::default();
    let mut stats = Residuals::default();
    // `validate` refused a negative or non-finite sigma: a failure here is ours.
    let noise = Normal::new(0.0, params.noise_sigma)
        .map_err(|e| Error::Inconsistent(format!("noise sigma {}: {e}", params.noise_sigma)))?;
    let mut noise_rng = stream(params.seed, Stream::Noise);
    let mut outlier_rng = stream(params.seed, Stream::Outliers);
    let mut outliers = Vec::new();
    // Tribometer readings kept for the end of the file: (log_time, message,
    // an outlier).
    let mut at_end: Vec<(u64, MeasurementMsg, bool)> = Vec::new();

    file.write(params.start_ns, &writing::section_msg(&section, params))?;
    if let Some(layout) = &params.line {
        file.write(params.start_ns, &layout.line_msg())?;
    }
    let days = planner.days();
    let n_days = days.len() as u64;
    progress.stage_of("simulating the traffic, day by day", n_days);
    for (done, day) in days.into_iter().enumerate() {
        progress.done(done as u64);
        tortwin_study::progress::check(progress)?;
        let mut plan = planner.plan_day(day);
        counts.dropped_trains += plan.dropped_trains;
        plan.items
            .sort_by_key(|p| (p.log_time_ns, p.event.topic(), p.at_end, p.seq));
        let events: Vec<Event> = plan
            .items
            .iter()
            .enumerate()
            .map(|(i, p)| Event {
                log_time_ns: p.log_time_ns,
                index_in_file: i as u64,
                kind: p.event.clone(),
            })
            .collect();
        let truth_values = simulate(&mut truth_engine, &events)?;
        let baseline_values = simulate(&mut baseline_engine, &events)?;

        for (i, item) in plan.items.iter().enumerate() {
            match &item.event {
                EventKind::Passage(passage) => {
                    let train = plan
                        .trains
                        .iter()
                        .find(|t| t.passage.train_seq == passage.train_seq)
                        .ok_or_else(|| {
                            Error::Inconsistent(format!(
                                "train {} was not planned",
                                passage.train_id
                            ))
                        })?;
                    counts.trains += 1;
                    counts.axles += passage.axles.len() as u64;
                    match train.kind {
                        TrainKind::Freight => counts.freight += 1,
                        TrainKind::Passenger => counts.passenger += 1,
                    }
                    counts.down += u64::from(passage.direction == Direction::Down);
                    counts.measured_trains += u64::from(train.measured);
                    file.write(
                        item.log_time_ns,
                        &writing::passage_msg(train, &section.rails, line.as_ref())?,
                    )?;
                }
                EventKind::Pulse(pulse) => {
                    let mass_g = item.pulse_mass_g.ok_or_else(|| {
                        Error::Inconsistent("a pulse was planned without its mass in g".into())
                    })?;
                    counts.pulses += 1;
                    file.write(
                        item.log_time_ns,
                        &PulseMsg {
                            applicator_id: section.applicators[pulse.applicator].id.clone(),
                            rail: section.rails[pulse.rail].clone(),
                            mass_g,
                        },
                    )?;
                }
                EventKind::Weather(w) => {
                    counts.weather += 1;
                    file.write(item.log_time_ns, &writing::weather_msg(w))?;
                }
                EventKind::Measurement(m) => {
                    let (mut truth, baseline) = (truth_values[i], baseline_values[i]);
                    if truth.is_nan() || baseline.is_nan() {
                        return Err(Error::NotSimulated {
                            file: out.to_path_buf(),
                            log_time_ns: item.log_time_ns,
                            index_in_file: None,
                        });
                    }
                    let noise = if params.noise_sigma > 0.0 {
                        noise.sample(&mut noise_rng)
                    } else {
                        0.0
                    };
                    let site_id = &section.sites[m.site].id;
                    for l in &params.local_friction {
                        let from_ns = params.start_ns as f64 + l.start_h * 3600e9;
                        let to_ns = from_ns + l.hours * 3600e9;
                        let t = item.log_time_ns as f64;
                        if &l.site == site_id && t >= from_ns && t < to_ns {
                            truth += l.delta;
                        }
                    }
                    // A draw for every measurement, so that the share does
                    // not move which ones are hit.
                    let u: f64 = outlier_rng.random();
                    let gross = if u < params.outlier_share {
                        let size = outlier_rng.random_range(0.1..0.3);
                        if outlier_rng.random::<bool>() {
                            size
                        } else {
                            -size
                        }
                    } else {
                        0.0
                    };
                    let measured = round_dp(truth + noise + gross, 1e5);
                    stats.add(m.quantity(), truth, baseline, measured);
                    counts.measurements += 1;
                    *counts.by_quantity.get_mut(m.quantity()) += 1;
                    let message =
                        writing::measurement_msg(&section, m, measured).ok_or_else(|| {
                            Error::NotFinite {
                                file: out.to_path_buf(),
                                quantity: m.quantity().as_str(),
                                log_time_ns: item.log_time_ns,
                                value: measured,
                            }
                        })?;
                    if item.at_end {
                        at_end.push((item.log_time_ns, message, gross != 0.0));
                    } else {
                        if gross != 0.0 {
                            outliers.push(file.messages());
                        }
                        file.write(item.log_time_ns, &message)?;
                    }
                }
            }
        }
    }
    progress.done(n_days);
    for (log_time_ns, message, gross) in &at_end {
        if *gross {
            outliers.push(file.messages());
        }
        file.write(*log_time_ns, message)?;
    }
    counts.messages = file.messages();
    let size_bytes = file.finish()?;

    let summary = truth_engine.summary(0);
    counts.wheels = summary.wheels;
    counts.contacts = summary.contacts;

    let mut by_quantity = ByQuantity::<RmseKey>::default();
    for q in QUANTITIES {
        let s = quantity_slot(q);
        *by_quantity.get_mut(q) = RmseKey {
            n: stats.n[s],
            rmse: rmse(stats.baseline_truth[s], stats.n[s]),
        };
    }
    let n_all: u64 = stats.n.iter().sum();
    let sum = |v: &[f64; 3]| v.iter().sum::<f64>();
    let rmse_baseline_vs_truth = rmse(sum(&stats.baseline_truth), n_all);
    let site_grid_indices = section
        .sites
        .iter()
        .map(|s| (s.id.clone(), grid.snap(s.position_m)))
        .collect();
    Ok(SynthReport {
        generator: GENERATOR,
        version: env!("CARGO_PKG_VERSION"),
        recording: out
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
        size_bytes,
        seed: params.seed,
        days: params.days,
        start_utc: utc(params.start_ns),
        start_ns: params.start_ns,
        end_ns: params.end_ns(),
        effects: serde_json::to_value(&truth.effects).map_err(|source| Error::Json {
            what: "the effects",
            source,
        })?,
        truth_config_toml: truth.to_toml(),
        noise: NoiseKey {
            distribution: "gaussian",
            sigma: params.noise_sigma,
            applied_to: "every /measurement/friction value: measured = truth + N(0, sigma^2), \
                         rounded to 1e-5",
        },
        truth: "tortwin engine with the truth configuration (`effects`, `truth_config_toml`)",
        baseline: "tortwin engine with the default configuration (no effects)",
        rmse_baseline_vs_truth,
        rmse_baseline_vs_truth_by_quantity: by_quantity,
        rmse_baseline_vs_truth_over_sigma: match (rmse_baseline_vs_truth, params.noise_sigma) {
            (Some(r), s) if s > 0.0 => Some(r / s),
            _ => None,
        },
        rmse_measured_vs_truth: rmse(sum(&stats.measured_truth), n_all),
        rmse_measured_vs_baseline: rmse(sum(&stats.measured_baseline), n_all),
        counts,
        outliers_index_in_file: outliers,
        local_friction: params.local_friction.clone(),
        rain_events_h_from_start: planner
            .climate
            .rain
            .iter()
            .map(|r| RainKey {
                start_h: round_dp(
                    r.start_ns.saturating_sub(params.start_ns) as f64 / HOUR_NS as f64,
                    1e3,
                ),
                end_h: round_dp(
                    r.end_ns.saturating_sub(params.start_ns) as f64 / HOUR_NS as f64,
                    1e3,
                ),
                mm_h: round_dp(r.mm_h, 100.0),
            })
            .collect(),
        grid_points: grid.d_m.len(),
        applicator_grid_index: grid.snap(params.applicator_position_m),
        site_grid_indices,
        params: params.clone(),
    })
}

/// Pushes one day's events (already in replay order) through `engine` and
/// returns each measurement's simulated value by its position in `events`
/// (NaN for the other events). The day ends in the quiet night, so rolling
/// its last train now is what a replay of the whole file does later.
fn simulate(engine: &mut Engine, events: &[Event]) -> Result<Vec<f64>> {
    struct Collect<'a>(&'a mut [f64]);
    impl Sink for Collect<'_> {
        fn measurement(&mut self, m: &MeasurementOutput) -> tortwin_engine::sink::SinkResult {
            let slot = self.0.get_mut(m.index_in_file as usize).ok_or_else(|| {
                Error::Inconsistent(format!(
                    "measurement index {} out of range",
                    m.index_in_file
                ))
            })?;
            *slot = m.simulated;
            Ok(())
        }
    }
    let mut values = vec![f64::NAN; events.len()];
    let mut sink = Collect(&mut values);
    for event in events {
        engine.push(event.clone(), &mut sink)?;
    }
    engine.finish(&mut sink, 0)?;
    Ok(values)
}

/// Sums of squared differences per quantity.
#[derive(Debug, Default)]
struct Residuals {
    n: [u64; 3],
    baseline_truth: [f64; 3],
    measured_truth: [f64; 3],
    measured_baseline: [f64; 3],
}

impl Residuals {
    fn add(&mut self, q: Quantity, truth: f64, baseline: f64, measured: f64) {
        let s = quantity_slot(q);
        self.n[s] += 1;
        self.baseline_truth[s] += (baseline - truth).powi(2);
        self.measured_truth[s] += (measured - truth).powi(2);
        self.measured_baseline[s] += (measured - baseline).powi(2);
    }
}

fn rmse(sum_sq: f64, n: u64) -> Option<f64> {
    (n > 0).then(|| (sum_sq / n as f64).sqrt())
}
