//! Application strategies: which pulse mass, pulse interval, applicator
//! position(s) and rails keep friction in the target band, for how much
//! product (the paper's stated purpose for its model).
//!
//! A strategy is evaluated by replaying the section's traffic through the
//! one [`Engine`]: the recording's passages and weather as they are, its
//! own pulses replaced by the pulses the strategy's applicators would have
//! fired ([`pulse_events`]: an axle counter per applicator). A sink
//! (`metrics.rs`) keeps, per rail, travel direction and grid point,
//! how many wheel passes saw mu inside, below and above the band; the
//! figures an engineer decides on follow from those counts
//! ([`Figures`]). [`search`] evaluates a whole space of strategies
//! (every one for a small space, an optimiser for a large one), finds the
//! Pareto front between product and coverage and recommends one;
//! `report.rs` writes the result.

mod metrics;
pub mod paper;
pub mod report;
pub mod search;

use std::path::Path;
use std::sync::Arc;

use serde::Serialize;

use tortwin_engine::sink::{Fanout, Sink};
use tortwin_engine::{Engine, EngineError, EngineOptions, Grid};
use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_recording::error::InputError;
use tortwin_recording::{Applicator, Direction, Event, EventKind, Pulse, Recording, Section};

pub use metrics::{
    Band, CarryOn, Figures, PerTrain, Profile, RailFigures, Target, TrainRail, WorstPoint,
};

use tortwin_study::{Error, Result};

const DAY_S: f64 = 86_400.0;

/// How long before the counted axle reaches the applicator its pulse lands
/// (the wheel sensor sits ahead of the applicator), at most: never before
/// the previous axle has passed (then halfway between the two).
pub const PULSE_LEAD_S: f64 = 0.05;

/// The traffic of a section over a period: everything of a recording but
/// its measurements (which a different application would not have seen).
#[derive(Debug, Clone)]
pub struct Traffic {
    /// Where it came from (a recording's path, or a description).
    pub source: String,
    pub section: Section,
    pub origin_ns: i64,
    /// Passages, weather and today's pulses, in replay order.
    pub events: Vec<Event>,
    pub trains: u64,
    pub axles: u64,
    /// From the section's log_time to the recording's last message.
    pub span_s: f64,
}

impl Traffic {
    /// Reads a recording (every input error names where it is).
    pub fn read(path: &Path) -> Result<Self, InputError> {
        let r = Recording::read_section(path, "strategy needs")?;
        // The span counts the measurements too, which `new` then drops.
        let span_s = (r.last_log_time_ns() - r.section_log_time_ns) as f64 * 1e-9;
        Ok(Self::new(
            path.display().to_string(),
            r.section,
            r.origin_ns,
            r.events,
            span_s,
        ))
    }

    /// Traffic from events already in replay order (measurements are dropped).
    pub(crate) fn new(
        source: String,
        section: Section,
        origin_ns: i64,
        mut events: Vec<Event>,
        span_s: f64,
    ) -> Self {
        events.retain(|e| !matches!(e.kind, EventKind::Measurement(_)));
        let (mut trains, mut axles) = (0, 0);
        for e in &events {
            if let EventKind::Passage(p) = &e.kind {
                trains += 1;
                axles += p.axles.len() as u64;
            }
        }
        Self {
            source,
            section,
            origin_ns,
            events,
            trains,
            axles,
            span_s,
        }
    }

    /// The engine's `source` as an error of replaying this traffic.
    fn replay_error(&self, source: EngineError) -> Error {
        Error::Replay {
            what: format!("the traffic of {}", self.source),
            source,
        }
    }

    /// Whole days the period stands for: the span rounded, at least one. A
    /// recording of one service day (05:00 to midnight) is one day.
    pub fn days(&self) -> f64 {
        (self.span_s / DAY_S).round().max(1.0)
    }

    /// Rail indices by name, for error messages and configuration.
    pub(crate) fn rail_index(&self, name: &str) -> Option<usize> {
        self.section.rails.iter().position(|r| r == name)
    }

    /// Today's application as a strategy-like description: pulses per
    /// applicator and rail, mean mass, axles per pulse.
    pub(crate) fn today(&self) -> Vec<TodayApplicator> {
        let s = &self.section;
        let mut out: Vec<TodayApplicator> = s
            .applicators
            .iter()
            .map(|a| TodayApplicator {
                id: a.id.clone(),
                position_m: a.position_m,
                rails: a.rails.iter().map(|&r| s.rails[r].clone()).collect(),
                nominal_pulse_g: a.nominal_pulse_kg * 1e3,
                pulses: 0,
                mean_pulse_g: 0.0,
                axles_per_pulse: f64::NAN,
            })
            .collect();
        let mut mass = vec![0.0; out.len()];
        for e in &self.events {
            if let EventKind::Pulse(p) = &e.kind {
                out[p.applicator].pulses += 1;
                mass[p.applicator] += p.mass_kg;
            }
        }
        for (a, t) in out.iter_mut().enumerate() {
            if t.pulses > 0 {
                t.mean_pulse_g = mass[a] * 1e3 / t.pulses as f64;
                // A pulse message is per rail.
                let per_rail = t.pulses as f64 / t.rails.len().max(1) as f64;
                t.axles_per_pulse = self.axles as f64 / per_rail;
            }
        }
        out
    }
}

/// An applicator of the recording and what it did.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct TodayApplicator {
    pub(crate) id: String,
    pub(crate) position_m: f64,
    pub(crate) rails: Vec<String>,
    pub(crate) nominal_pulse_g: f64,
    /// Pulse messages (one per rail).
    pub(crate) pulses: u64,
    pub(crate) mean_pulse_g: f64,
    /// Axles of the traffic per pulse on one rail.
    pub(crate) axles_per_pulse: f64,
}

/// One application strategy: every applicator fires a pulse of `pulse_kg`
/// on each of `rails` for every `every_axles`-th axle that reaches it.
#[derive(Debug, Clone, PartialEq)]
pub struct Strategy {
    pub pulse_kg: f64,
    pub every_axles: u32,
    /// One or two applicators, ascending.
    pub positions_m: Vec<f64>,
    /// Rail indices, ascending.
    pub rails: Vec<usize>,
}

impl Strategy {
    /// Checks the strategy fits the section (a usage error otherwise).
    pub(crate) fn check(&self, section: &Section) -> Result<(), UsageError> {
        let bad = |what: String| Err(UsageError(format!("strategy {self:?}: {what}")));
        if !(self.pulse_kg.is_finite() && self.pulse_kg > 0.0) {
            return bad("the pulse mass must be a positive number".into());
        }
        if self.every_axles == 0 {
            return bad("the pulse interval must be at least one axle".into());
        }
        if self.positions_m.is_empty() {
            return bad("needs at least one applicator".into());
        }
        for &p in &self.positions_m {
            if !(p.is_finite() && (0.0..=section.length_m).contains(&p)) {
                return bad(format!(
                    "applicator position {p} m is outside the section [0, {}] m",
                    section.length_m
                ));
            }
        }
        if self.rails.is_empty() || self.rails.iter().any(|&r| r >= section.rails.len()) {
            return bad("needs one or more of the section's rails".into());
        }
        Ok(())
    }

    /// The section with this strategy's applicators (`S1`, `S2`) in place of
    /// the recorded ones, their nominal pulse the strategy's pulse.
    pub fn section(&self, recorded: &Section) -> Section {
        Section {
            applicators: self
                .positions_m
                .iter()
                .enumerate()
                .map(|(k, &position_m)| Applicator {
                    id: format!("S{}", k + 1),
                    position_m,
                    rails: self.rails.clone(),
                    nominal_pulse_kg: self.pulse_kg,
                })
                .collect(),
            ..recorded.clone()
        }
    }

    /// E.g. `0.200 g every 4 axles at 10 m and 300 m on high, low`.
    pub fn describe(&self, section: &Section) -> String {
        let at = self
            .positions_m
            .iter()
            .map(|p| format!("{p} m"))
            .collect::<Vec<_>>()
            .join(" and ");
        let rails = self
            .rails
            .iter()
            .map(|&r| section.rails[r].as_str())
            .collect::<Vec<_>>()
            .join(", ");
        let every = match self.every_axles {
            1 => "every axle".to_string(),
            k => format!("every {k} axles"),
        };
        format!("{:.3} g {every} at {at} on {rails}", self.pulse_kg * 1e3)
    }
}

/// What to replay: the recording as it was, or with a strategy's pulses.
#[derive(Debug, Clone, PartialEq)]
pub enum Plan {
    Today,
    Strategy(Strategy),
}

/// The pulses `strategy` fires on the passages of `events` (replay order):
/// per applicator an axle counter counts every axle that reaches it (either
/// direction); axles number 1, 1 + k, 1 + 2k, ... trigger one pulse per
/// rail, which lands [`PULSE_LEAD_S`] before that axle reaches the
/// applicator (halfway after the previous axle if that passed later), so
/// the counted axle is the first to roll over it. `section` is the
/// strategy's section, `grid` its grid; `out` is cleared first.
pub fn pulse_events(
    section: &Section,
    grid: &Grid,
    origin_ns: i64,
    events: &[Event],
    strategy: &Strategy,
    out: &mut Vec<Event>,
) {
    out.clear();
    let every = u64::from(strategy.every_axles.max(1));
    for (a, applicator) in section.applicators.iter().enumerate() {
        let first = out.len();
        let d_app = grid.d_m[grid.snap(applicator.position_m)];
        let mut counted: u64 = 0;
        let mut previous_s = f64::NEG_INFINITY;
        for e in events {
            let EventKind::Passage(p) = &e.kind else {
                continue;
            };
            let t_passage_s = (e.log_time_ns as i64).wrapping_sub(origin_ns) as f64 * 1e-9;
            let d_entry = match p.direction {
                Direction::Up => 0.0,
                Direction::Down => section.length_m,
            };
            for axle in &p.axles {
                // The engine's time of a wheel at a grid point (model.md).
                let arrival_s =
                    t_passage_s + ((d_app - d_entry).abs() + axle.offset_m) / p.speed_mps;
                if counted.is_multiple_of(every) {
                    let lead_s = PULSE_LEAD_S.min((arrival_s - previous_s) / 2.0);
                    // In ns from the origin first: an f64 of ns since the
                    // epoch resolves only 256 ns.
                    let from_origin_ns = ((arrival_s - lead_s) * 1e9).floor() as i64;
                    let log_time_ns = origin_ns.saturating_add(from_origin_ns).max(0) as u64;
                    for &rail in &strategy.rails {
                        out.push(Event {
                            log_time_ns,
                            index_in_file: u64::MAX,
                            kind: EventKind::Pulse(Pulse {
                                applicator: a,
                                rail,
                                mass_kg: strategy.pulse_kg,
                            }),
                        });
                    }
                }
                counted += 1;
                previous_s = arrival_s;
            }
        }
        // Down trains reach the applicator in another order than their
        // passages: keep each applicator's pulses in time order.
        out[first..].sort_by_key(|e| e.log_time_ns);
    }
    out.sort_by_key(|e| e.log_time_ns);
}

/// Replays `plan` over `traffic` through the engine with the statistics
/// sink (and `extra`, e.g. a rerun recording) and returns the figures.
pub fn evaluate(
    traffic: &Traffic,
    cfg: &ModelConfig,
    target: &Target,
    plan: &Plan,
    detail: bool,
    extra: Option<&mut dyn Sink>,
) -> Result<Figures> {
    let section = match plan {
        Plan::Today => traffic.section.clone(),
        Plan::Strategy(s) => {
            s.check(&traffic.section)?;
            s.section(&traffic.section)
        }
    };
    let opts = EngineOptions {
        every_wheel_contacts: true,
        ..EngineOptions::default()
    };
    let mut engine = Engine::new(section.clone(), cfg.clone(), opts, traffic.origin_ns);
    let mut stats = metrics::Stats::new(&section, engine.grid(), cfg, target, detail)?;
    let mut fanout: Fanout<&mut dyn Sink> = Fanout::default();
    fanout.sinks.push(&mut stats);
    if let Some(extra) = extra {
        fanout.sinks.push(extra);
    }
    drive(&mut engine, traffic, plan, &mut fanout)?;
    engine
        .finish(&mut fanout, 0)
        .map_err(|source| traffic.replay_error(source))?;
    drop(fanout);
    Ok(stats.figures(traffic))
}

/// Pushes `traffic` into `engine` with the plan's pulses: the recorded
/// ones for [`Plan::Today`], else the strategy's ([`pulse_events`]) in
/// their place, merged in replay order. The engine must have been made for
/// the plan's section ([`Strategy::section`]); `finish` is the caller's.
pub fn drive(
    engine: &mut Engine,
    traffic: &Traffic,
    plan: &Plan,
    sink: &mut dyn Sink,
) -> Result<()> {
    let context = |source| traffic.replay_error(source);
    let strategy = match plan {
        Plan::Today => {
            for e in &traffic.events {
                engine.push(e.clone(), sink).map_err(context)?;
            }
            return Ok(());
        }
        Plan::Strategy(s) => s,
    };
    let mut pulses = Vec::new();
    pulse_events(
        engine.section(),
        engine.grid(),
        traffic.origin_ns,
        &traffic.events,
        strategy,
        &mut pulses,
    );
    let mut pulses = pulses.into_iter().peekable();
    for e in &traffic.events {
        if matches!(e.kind, EventKind::Pulse(_)) {
            continue;
        }
        // Replay order: log_time, then topic (a pulse after a passage of
        // the same instant, before the weather).
        let before = |p: &Event| {
            p.log_time_ns < e.log_time_ns
                || (p.log_time_ns == e.log_time_ns && matches!(e.kind, EventKind::Weather(_)))
        };
        while let Some(p) = pulses.next_if(before) {
            engine.push(p, sink).map_err(context)?;
        }
        engine.push(e.clone(), sink).map_err(context)?;
    }
    for p in pulses {
        engine.push(p, sink).map_err(context)?;
    }
    Ok(())
}

/// What a study found.
#[derive(Debug, Clone)]
pub struct Study {
    /// The method that ran (`grid` or `optimiser`).
    pub method: search::Method,
    pub space_size: usize,
    /// Strategies evaluated by the search (the heatmap's extra ones not counted).
    pub search_evaluations: usize,
    pub search_seconds: f64,
    pub today: Figures,
    /// Every strategy evaluated (search and heatmap), by lattice point.
    pub evaluated: Vec<Arc<search::Evaluated>>,
    pub recommended: Option<Arc<search::Evaluated>>,
    pub best_coverage: Option<Arc<search::Evaluated>>,
    /// The Pareto front, by ascending product, each point with its twins.
    pub pareto: Vec<search::FrontPoint>,
    /// Coverage over pulse mass × interval at the recommended (or best)
    /// layout and rail set: `coverage[every][pulse]`.
    pub heatmap: Option<HeatmapData>,
}

/// The dose × interval grid of the report's heatmap.
#[derive(Debug, Clone)]
pub struct HeatmapData {
    pub layout: usize,
    pub rails: usize,
    pub pulse_index: Vec<usize>,
    pub every_index: Vec<usize>,
    /// `[every][pulse]`
    pub coverage: Vec<Vec<f64>>,
    pub admissible: Vec<Vec<bool>>,
}

/// Most categories per heatmap axis (larger dimensions are thinned evenly).
const HEATMAP_MAX: usize = 12;

/// Evaluates today's application, searches the space, and evaluates the
/// report's dose × interval grid.
pub fn study(
    traffic: &Traffic,
    cfg: &ModelConfig,
    target: &Target,
    space: &search::Space,
    method: search::Method,
    max_grid: usize,
    on_evaluation: &(dyn Fn(usize) -> Result<()> + Sync),
) -> Result<Study> {
    target.check(&traffic.section)?;
    let today = evaluate(traffic, cfg, target, &Plan::Today, false, None)?;
    let t0 = std::time::Instant::now();
    let searcher = search::Searcher::new(traffic, cfg, target, space, on_evaluation);
    let method = searcher.run(method, max_grid)?;
    let search_seconds = t0.elapsed().as_secs_f64();
    let search_evaluations = searcher.evaluations();
    let found = searcher.all();
    // The heatmap is drawn at the search's choice's layout and rails.
    let at = search::recommend(&found, target)
        .or_else(|| search::best_coverage(&found))
        .or(found.first().map(|e| e.as_ref()))
        .map(|e| e.key);

    let heatmap = match at {
        Some(at) => {
            let thin = |n: usize| -> Vec<usize> {
                if n <= HEATMAP_MAX {
                    (0..n).collect()
                } else {
                    let mut v: Vec<usize> = (0..HEATMAP_MAX)
                        .map(|k| (k * (n - 1) + (HEATMAP_MAX - 1) / 2) / (HEATMAP_MAX - 1))
                        .collect();
                    v.dedup();
                    v
                }
            };
            let pulse_index = thin(space.pulse_kg.len());
            let every_index = thin(space.every_axles.len());
            let keys: Vec<search::Key> = every_index
                .iter()
                .flat_map(|&every| {
                    pulse_index
                        .iter()
                        .map(move |&pulse| search::Key { pulse, every, ..at })
                })
                .collect();
            let cells = searcher.eval_all(&keys)?;
            let row = |f: &dyn Fn(&search::Evaluated) -> bool| -> Vec<Vec<bool>> {
                cells
                    .chunks(pulse_index.len())
                    .map(|r| r.iter().map(|e| f(e)).collect())
                    .collect()
            };
            Some(HeatmapData {
                layout: at.layout,
                rails: at.rails,
                coverage: cells
                    .chunks(pulse_index.len())
                    .map(|r| r.iter().map(|e| e.figures.coverage).collect())
                    .collect(),
                admissible: row(&|e| e.figures.admissible),
                pulse_index,
                every_index,
            })
        }
        None => None,
    };
    // The choices are made among every strategy evaluated, the heatmap's
    // cells included (the optimiser may not have met them): strategy.json's
    // `evaluated` is the set they follow from.
    let evaluated = searcher.all();
    let find =
        |k: Option<search::Key>| k.and_then(|k| evaluated.iter().find(|e| e.key == k).cloned());
    let recommended = search::recommend(&evaluated, target).map(|e| e.key);
    let best = search::best_coverage(&evaluated).map(|e| e.key);
    let pareto = search::pareto_front(&evaluated);
    Ok(Study {
        method,
        space_size: space.size(),
        search_evaluations,
        search_seconds,
        today,
        recommended: find(recommended),
        best_coverage: find(best),
        pareto,
        evaluated: evaluated.clone(),
        heatmap,
    })
}
