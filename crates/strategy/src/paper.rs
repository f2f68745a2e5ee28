//! The scenarios of the paper's sections 2 and 4 (Trummer et al. 2021),
//! computed by the same model and engine as a replay.
//!
//! - Figure 7: the twin disc of section 2.5: eq. (1) and (4) alone.
//! - Figures 13–17: a single applicator at d = 0 and a wheel that passes
//!   100 times (100 kN, cx = 1 %, cy = 0, diameter 0.92 m), product applied
//!   before passes; these are application strategies (`tortwin strategy`'s
//!   machinery: traffic of one-axle "trains", pulses by an axle counter)
//!   through [`Engine`], so the paper's figures check the replay engine and
//!   the strategy machinery.

use crate::{Plan, Strategy, Traffic};
use tortwin_engine::sink::{FieldSnapshot, Sink, SnapshotKind};
use tortwin_engine::{Engine, EngineOptions};
use tortwin_model::config::ModelConfig;
use tortwin_model::product;
use tortwin_recording::{
    Applicator, Axle, BogiePosition, Creepage, Direction, Event, EventKind, Passage, Section,
};
use tortwin_study::Result;

/// Figure 7: mu before each revolution's consumption in a twin disc, mass
/// starting at `m0_kg`, which is also the curve's m0 of eq. (1) (model.md:
/// each curve's applied mass is its m0), fp = fc = 1, no cap, no transfer.
pub fn twin_disc(cfg: &ModelConfig, m0_kg: f64, revolutions: usize) -> Vec<f64> {
    let p = &product::ProductParams {
        m0_kg,
        ..cfg.product
    };
    let mut m = m0_kg;
    (0..revolutions)
        .map(|_| {
            let mu = product::friction(p, m);
            m -= product::consumption(p, m, 1.0, 1.0);
            mu
        })
        .collect()
}

/// A wayside application scenario of the paper's section 4.
#[derive(Debug, Clone, PartialEq)]
pub struct WaysideScenario {
    pub length_m: f64,
    pub passes: usize,
    /// Mass applied before a pass that gets product.
    pub dose_kg: f64,
    /// Product before passes 1, 1 + every, 1 + 2 every, ...
    pub every: usize,
    pub wheel_load_n: f64,
    pub cx: f64,
    pub cy: f64,
    pub wheel_diameter_m: f64,
    pub rail_head_radius_m: f64,
    pub speed_mps: f64,
}

impl Default for WaysideScenario {
    /// Section 4.1: 0.1 g before each of 100 passes, 100 kN, 1 % creepage.
    fn default() -> Self {
        Self {
            length_m: 600.0,
            passes: 100,
            dose_kg: 0.1e-3,
            every: 1,
            wheel_load_n: 100e3,
            cx: 0.01,
            cy: 0.0,
            wheel_diameter_m: 0.92,
            rail_head_radius_m: 0.30,
            speed_mps: 20.0,
        }
    }
}

/// The field after one pass of a [`WaysideScenario`].
#[derive(Debug, Clone, PartialEq)]
pub struct PassField {
    pub pass: usize,
    pub d_m: Vec<f64>,
    /// Seen by the wheel of this pass at step 2.
    pub mu: Vec<f64>,
    /// After this pass.
    pub rail_mass_kg: Vec<f64>,
    /// This pass's wheel after each contact.
    pub wheel_mass_kg: Vec<f64>,
}

/// Seconds between passes: the wheel is long gone before the next pulse.
const PASS_INTERVAL_NS: u64 = 100_000_000_000;
/// The scenario's time origin (any instant will do).
const ORIGIN_NS: u64 = 1_600_000_000_000_000_000;

impl WaysideScenario {
    pub(crate) fn section(&self) -> Section {
        Section {
            section_id: "paper-section-4".into(),
            length_m: self.length_m,
            rails: vec!["rail".into()],
            curve_radius_m: None,
            rail_head_radius_m: self.rail_head_radius_m,
            nominal_wheel_diameter_m: self.wheel_diameter_m,
            applicators: vec![Applicator {
                id: "A".into(),
                position_m: 0.0,
                rails: vec![0],
                nominal_pulse_kg: self.dose_kg,
            }],
            sites: Vec::new(),
        }
    }

    /// The traffic: pass k (1-based) is a one-axle train at k × 100 s.
    pub fn traffic(&self) -> Traffic {
        let events = (1..=self.passes)
            .map(|k| Event {
                log_time_ns: ORIGIN_NS + k as u64 * PASS_INTERVAL_NS,
                index_in_file: k as u64,
                kind: EventKind::Passage(Passage {
                    train_id: format!("pass-{k}"),
                    train_seq: k - 1,
                    direction: Direction::Up,
                    speed_mps: self.speed_mps,
                    axles: vec![Axle {
                        offset_m: 0.0,
                        bogie_position: BogiePosition::Leading,
                        wheel_diameter_m: self.wheel_diameter_m,
                        wheel_load_n: vec![self.wheel_load_n],
                        creepage: vec![Creepage {
                            cx: self.cx,
                            cy: self.cy,
                            spin_per_m: 0.0,
                        }],
                        segments: Vec::new(),
                    }],
                }),
            })
            .collect();
        let span_s = self.passes as f64 * PASS_INTERVAL_NS as f64 * 1e-9;
        Traffic::new(
            "paper section 4 scenario".into(),
            self.section(),
            ORIGIN_NS as i64,
            events,
            span_s,
        )
    }

    /// The application: `dose` before passes 1, 1 + every, 1 + 2 every, ...
    /// (an axle counter at the applicator, d = 0).
    pub fn strategy(&self) -> Strategy {
        Strategy {
            pulse_kg: self.dose_kg,
            every_axles: self.every.max(1) as u32,
            positions_m: vec![0.0],
            rails: vec![0],
        }
    }

    /// Runs the scenario and returns the field after each pass in `passes`:
    /// the strategy machinery ([`crate::drive`]) over the engine.
    pub fn run(&self, cfg: &ModelConfig, passes: &[usize]) -> Result<Vec<PassField>> {
        let traffic = self.traffic();
        let strategy = self.strategy();
        let mut engine = Engine::new(
            strategy.section(&traffic.section),
            cfg.clone(),
            EngineOptions::default(),
            ORIGIN_NS as i64,
        );
        let mut sink = PassCapture {
            passes,
            pass: 0,
            fields: Vec::new(),
        };
        crate::drive(&mut engine, &traffic, &Plan::Strategy(strategy), &mut sink)?;
        engine.finish(&mut sink, 0)?;
        Ok(sink.fields)
    }
}

/// Keeps the train snapshots of the asked-for passes.
struct PassCapture<'a> {
    passes: &'a [usize],
    pass: usize,
    fields: Vec<PassField>,
}

impl Sink for PassCapture<'_> {
    fn field(&mut self, f: &FieldSnapshot<'_>) -> tortwin_engine::sink::SinkResult {
        if f.kind == SnapshotKind::Train {
            self.pass += 1;
            if self.passes.contains(&self.pass) {
                self.fields.push(PassField {
                    pass: self.pass,
                    d_m: f.d_m.to_vec(),
                    mu: f.mu.to_vec(),
                    rail_mass_kg: f.rail_mass_kg.to_vec(),
                    wheel_mass_kg: f.wheel_mass_kg.to_vec(),
                });
            }
        }
        Ok(())
    }
}
