//! What an engineer decides a strategy on, counted over every wheel contact
//! of the replayed period.
//!
//! The engine gives the sink every wheel's step-2 mass at every grid point
//! ([`WheelContacts`]); mu of the contact is eq. (4) of it. Eq. (4) is
//! strictly decreasing in the mass, so "mu inside the band" is "mass inside
//! the band's two edge masses", found once: the count per contact is two
//! comparisons, not an `exp`. The sink keeps, per rail, travel direction
//! and point, how many wheel passes saw mu inside and below the band.

use serde::{Deserialize, Serialize};

use super::Traffic;
use tortwin_engine::sink::{PulseEvent, RunSummary, Sink, TrainEvent, WheelContacts};
use tortwin_engine::Grid;
use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_model::product::{self, ProductParams};
use tortwin_recording::{Direction, Section};

/// The target friction band.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Band {
    pub lower_mu: f64,
    pub upper_mu: f64,
}

impl Default for Band {
    /// An intermediate friction level, what TOR products aim for.
    fn default() -> Self {
        Self {
            lower_mu: 0.30,
            upper_mu: 0.40,
        }
    }
}

/// The band and what the figures and the recommendation ask of a strategy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Target {
    pub band: Band,
    /// Rails whose coverage counts (names); empty: every rail.
    pub rails: Vec<String>,
    /// Carry-on reaches the farthest point downstream of an applicator
    /// where at least this share of the wheel passes saw mu inside the band.
    pub carry_on_pass_share: f64,
    /// A point is at braking risk when at least this share of the wheel
    /// passes saw mu below the band there.
    pub braking_risk_pass_share: f64,
    /// A strategy is admissible when at most this share of the contacts on
    /// the target rails sees mu below the band.
    pub max_below_share: f64,
    /// The recommendation: the least product among the admissible
    /// strategies whose coverage is within this (absolute share) of the
    /// best admissible coverage.
    pub coverage_tolerance: f64,
}

impl Default for Target {
    fn default() -> Self {
        Self {
            band: Band::default(),
            rails: Vec::new(),
            carry_on_pass_share: 0.5,
            braking_risk_pass_share: 0.1,
            max_below_share: 0.05,
            coverage_tolerance: 0.01,
        }
    }
}

impl Target {
    /// Checks the values (a usage error naming the key otherwise).
    pub fn check(&self, section: &Section) -> Result<(), UsageError> {
        let b = &self.band;
        if !(b.lower_mu.is_finite() && b.upper_mu.is_finite() && 0.0 < b.lower_mu) {
            return Err(UsageError(format!(
                "target.band: lower_mu {} and upper_mu {} must be finite and positive",
                b.lower_mu, b.upper_mu
            )));
        }
        if b.lower_mu >= b.upper_mu {
            return Err(UsageError(format!(
                "target.band: lower_mu {} must be below upper_mu {}",
                b.lower_mu, b.upper_mu
            )));
        }
        for (key, v) in [
            ("carry_on_pass_share", self.carry_on_pass_share),
            ("braking_risk_pass_share", self.braking_risk_pass_share),
            ("max_below_share", self.max_below_share),
            ("coverage_tolerance", self.coverage_tolerance),
        ] {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err(UsageError(format!("target.{key} = {v}: must be in [0, 1]")));
            }
        }
        if self.carry_on_pass_share == 0.0 || self.braking_risk_pass_share == 0.0 {
            return Err(UsageError(
                "target.carry_on_pass_share and target.braking_risk_pass_share must be above 0"
                    .into(),
            ));
        }
        for r in &self.rails {
            if !section.rails.contains(r) {
                return Err(UsageError(format!(
                    "target.rails: unknown rail {r:?}; the section's rails are {:?}",
                    section.rails
                )));
            }
        }
        Ok(())
    }

    /// The target rails' indices.
    pub(crate) fn rail_indices(&self, section: &Section) -> Vec<usize> {
        (0..section.rails.len())
            .filter(|&r| self.rails.is_empty() || self.rails.contains(&section.rails[r]))
            .collect()
    }
}

/// The band as step-2 masses: mu < lower ⇔ m > `below_above_kg`;
/// mu > upper ⇔ m < `above_below_kg` (eq. 4 is strictly decreasing).
#[derive(Debug, Clone, Copy)]
struct MassBand {
    below_above_kg: f64,
    above_below_kg: f64,
}

impl MassBand {
    fn new(p: &ProductParams, band: Band) -> Self {
        Self {
            below_above_kg: mass_at_or_above(p, band.lower_mu),
            above_below_kg: mass_at_or_below(p, band.upper_mu),
        }
    }
}

/// `sup { m >= 0 : mu(m) >= x }`: +inf when every mass gives mu >= x, −1
/// when none does.
fn mass_at_or_above(p: &ProductParams, x: f64) -> f64 {
    if x <= p.mu_c {
        f64::INFINITY
    } else if x > p.mu_d {
        -1.0
    } else {
        -p.km_kg * ((x - p.mu_c) / (p.mu_d - p.mu_c)).ln()
    }
}

/// `inf { m >= 0 : mu(m) <= x }`: 0 when mu(0) = mu_D <= x, +inf when no
/// mass gives mu <= x.
fn mass_at_or_below(p: &ProductParams, x: f64) -> f64 {
    if x >= p.mu_d {
        0.0
    } else if x <= p.mu_c {
        f64::INFINITY
    } else {
        -p.km_kg * ((x - p.mu_c) / (p.mu_d - p.mu_c)).ln()
    }
}

/// Counts of one rail in one travel direction.
#[derive(Debug, Clone)]
struct Counts {
    wheels: u64,
    in_band: Vec<u32>,
    below: Vec<u32>,
}

/// The statistics sink of one evaluation.
pub(super) struct Stats {
    mass_band: MassBand,
    params: ProductParams,
    /// [rail][direction: Up, Down]
    counts: Vec<[Counts; 2]>,
    /// Per rail: sum of mu over the wheel passes, per point (detail only).
    mu_sum: Option<Vec<Vec<f64>>>,
    /// Per rail: the pulses' product in whole micrograms ([`pulse_ug`]).
    applied_ug: Vec<u64>,
    pulses: Vec<u64>,
    d_m: Vec<f64>,
    spacing_m: f64,
    /// Per applicator: grid point and rails.
    applicators: Vec<(String, usize, Vec<usize>)>,
    target: Target,
    target_rails: Vec<usize>,
    rail_names: Vec<String>,
}

impl Stats {
    pub(super) fn new(
        section: &Section,
        grid: &Grid,
        cfg: &ModelConfig,
        target: &Target,
        detail: bool,
    ) -> Result<Self, UsageError> {
        target.check(section)?;
        let points = grid.d_m.len();
        let rails = section.rails.len();
        let zero = || Counts {
            wheels: 0,
            in_band: vec![0; points],
            below: vec![0; points],
        };
        Ok(Self {
            mass_band: MassBand::new(&cfg.product, target.band),
            params: cfg.product,
            counts: (0..rails).map(|_| [zero(), zero()]).collect(),
            mu_sum: detail.then(|| vec![vec![0.0; points]; rails]),
            applied_ug: vec![0; rails],
            pulses: vec![0; rails],
            d_m: grid.d_m.clone(),
            spacing_m: grid.spacing_m,
            applicators: section
                .applicators
                .iter()
                .map(|a| (a.id.clone(), grid.snap(a.position_m), a.rails.clone()))
                .collect(),
            target: target.clone(),
            target_rails: target.rail_indices(section),
            rail_names: section.rails.clone(),
        })
    }

    /// The figures of the run.
    pub(super) fn figures(&self, traffic: &Traffic) -> Figures {
        let days = traffic.days();
        let rails: Vec<RailFigures> = (0..self.counts.len())
            .map(|r| self.rail_figures(r, days, traffic.axles))
            .collect();
        let t = &self.target_rails;
        let mean = |f: fn(&RailFigures) -> f64| {
            t.iter().map(|&r| f(&rails[r])).sum::<f64>() / t.len().max(1) as f64
        };
        let coverage = mean(|r| r.coverage);
        let below_share = mean(|r| r.below_share);
        let product_ug: u64 = rails.iter().map(|r| r.product_ug).sum();
        let (product_g, product_g_per_day, product_g_per_1000_axles) =
            per_day_and_axles(product_ug, days, traffic.axles);
        Figures {
            coverage,
            below_share,
            admissible: below_share <= self.target.max_below_share,
            pulses: rails.iter().map(|r| r.pulses).sum(),
            product_ug,
            product_g,
            product_g_per_day,
            product_g_per_1000_axles,
            rails,
        }
    }

    fn rail_figures(&self, r: usize, days: f64, axles: u64) -> RailFigures {
        let [up, down] = &self.counts[r];
        let wheels = up.wheels + down.wheels;
        let points = self.d_m.len();
        let contacts = (wheels * points as u64).max(1) as f64;
        let w = wheels.max(1) as f64;
        let in_share: Vec<f64> = (0..points)
            .map(|i| f64::from(up.in_band[i] + down.in_band[i]) / w)
            .collect();
        let below_point: Vec<f64> = (0..points)
            .map(|i| f64::from(up.below[i] + down.below[i]) / w)
            .collect();
        // Whole counts: a share is one division of two integers.
        let in_total: u64 = (0..points)
            .map(|i| u64::from(up.in_band[i]) + u64::from(down.in_band[i]))
            .sum();
        let below_total: u64 = (0..points)
            .map(|i| u64::from(up.below[i]) + u64::from(down.below[i]))
            .sum();

        // Carry-on: from each applicator on this rail, downstream in each
        // direction that had traffic.
        let mut carry_on = Vec::new();
        for (id, point, app_rails) in &self.applicators {
            if !app_rails.contains(&r) {
                continue;
            }
            for (dir, c) in [(Direction::Up, up), (Direction::Down, down)] {
                if c.wheels == 0 {
                    continue;
                }
                carry_on.push(CarryOn {
                    applicator: id.clone(),
                    direction: match dir {
                        Direction::Up => "up",
                        Direction::Down => "down",
                    },
                    distance_m: self.carry_on_m(c, *point, dir, r),
                });
            }
        }
        let risk_points = below_point
            .iter()
            .filter(|&&s| s >= self.target.braking_risk_pass_share)
            .count();
        let (worst_i, worst) =
            below_point
                .iter()
                .copied()
                .enumerate()
                .fold(
                    (0, 0.0),
                    |best, (i, s)| if s > best.1 { (i, s) } else { best },
                );
        let (product_g, product_g_per_day, product_g_per_1000_axles) =
            per_day_and_axles(self.applied_ug[r], days, axles);
        RailFigures {
            rail: self.rail_names[r].clone(),
            wheel_passes: wheels,
            coverage: in_total as f64 / contacts,
            below_share: below_total as f64 / contacts,
            carry_on_m: carry_on.iter().map(|c| c.distance_m).fold(0.0, f64::max),
            carry_on,
            braking_risk_length_m: risk_points as f64 * self.spacing_m,
            worst_below: (worst > 0.0).then(|| WorstPoint {
                d_m: self.d_m[worst_i],
                pass_share: worst,
            }),
            pulses: self.pulses[r],
            product_ug: self.applied_ug[r],
            product_g,
            product_g_per_day,
            product_g_per_1000_axles,
            profile: self.mu_sum.as_ref().map(|sum| Profile {
                d_m: self.d_m.clone(),
                mean_mu: sum[r].iter().map(|s| s / w).collect(),
                in_band_share: in_share.clone(),
                below_band_share: below_point.clone(),
            }),
        }
    }

    /// From the applicator's point downstream (in the direction of travel)
    /// to the next applicator on this rail or the end of the section: the
    /// distance to the farthest point where at least `carry_on_pass_share`
    /// of the passes saw mu inside the band (0 if there is none). Right at
    /// an applicator many passes see fresh product (mu below the band) or
    /// a rail just picked clean; the reach is what counts.
    fn carry_on_m(&self, c: &Counts, start: usize, dir: Direction, rail: usize) -> f64 {
        let w = c.wheels as f64;
        let downstream = |i: usize| match dir {
            Direction::Up => i > start,
            Direction::Down => i < start,
        };
        let end = self
            .applicators
            .iter()
            .filter(|(_, p, rails)| rails.contains(&rail) && downstream(*p))
            .map(|(_, p, _)| *p)
            .min_by_key(|&p| p.abs_diff(start));
        let range = match (dir, end) {
            (Direction::Up, Some(e)) => start..e,
            (Direction::Up, None) => start..self.d_m.len(),
            (Direction::Down, Some(e)) => e + 1..start + 1,
            (Direction::Down, None) => 0..start + 1,
        };
        range
            .filter(|&i| f64::from(c.in_band[i]) / w >= self.target.carry_on_pass_share)
            .map(|i| (self.d_m[i] - self.d_m[start]).abs())
            .fold(0.0, f64::max)
    }
}

impl Stats {
    /// Back to no wheel pass and no pulse (a new train of [`PerTrain`]).
    fn reset(&mut self) {
        for pair in &mut self.counts {
            for c in pair {
                c.wheels = 0;
                c.in_band.fill(0);
                c.below.fill(0);
            }
        }
        if let Some(sum) = &mut self.mu_sum {
            sum.iter_mut().for_each(|s| s.fill(0.0));
        }
        self.applied_ug.fill(0);
        self.pulses.fill(0);
    }
}

/// The strategy's figures of one train on one rail: its wheel passes'
/// contacts (every wheel at every grid point of the rail) in and below the
/// target band, how far downstream of the applicators mu stayed in the band
/// for at least `carry_on_pass_share` of its wheels, and the product of the
/// pulses from its entry to the next train's.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrainRail {
    pub train_id: String,
    /// The train's front enters the section.
    pub log_time_ns: u64,
    pub rail: String,
    pub wheel_passes: u64,
    /// Share of the contacts with mu inside the band.
    pub in_band_share: f64,
    /// Share of the contacts with mu below the band (braking risk).
    pub below_band_share: f64,
    pub carry_on_m: f64,
    pub pulses: u64,
    pub product_g: f64,
}

/// A sink giving [`TrainRail`] rows: the strategy statistics of every train
/// (the fleet's per-train metrics). Needs the engine's
/// `every_wheel_contacts`.
pub struct PerTrain {
    stats: Stats,
    /// The train being counted: id, entry time.
    current: Option<(String, u64)>,
    rows: Vec<TrainRail>,
}

impl PerTrain {
    pub fn new(section: &Section, cfg: &ModelConfig, target: &Target) -> Result<Self, UsageError> {
        let grid = Grid::new(section.length_m, section.nominal_wheel_diameter_m);
        Ok(Self {
            stats: Stats::new(section, &grid, cfg, target, false)?,
            current: None,
            rows: Vec::new(),
        })
    }

    /// The rows so far, a train's once the next train entered (all of them
    /// after [`Sink::finish`]).
    pub fn rows(&self) -> &[TrainRail] {
        &self.rows
    }

    fn close(&mut self) {
        if let Some((train_id, log_time_ns)) = self.current.take() {
            for r in 0..self.stats.counts.len() {
                let f = self.stats.rail_figures(r, 1.0, 0);
                self.rows.push(TrainRail {
                    train_id: train_id.clone(),
                    log_time_ns,
                    rail: f.rail,
                    wheel_passes: f.wheel_passes,
                    in_band_share: f.coverage,
                    below_band_share: f.below_share,
                    carry_on_m: f.carry_on_m,
                    pulses: f.pulses,
                    product_g: f.product_g,
                });
            }
        }
        self.stats.reset();
    }
}

impl Sink for PerTrain {
    fn train(&mut self, t: &TrainEvent<'_>) -> tortwin_engine::sink::SinkResult {
        self.close();
        self.current = Some((t.train_id.to_string(), t.log_time_ns));
        Ok(())
    }

    fn pulse(&mut self, p: &PulseEvent<'_>) -> tortwin_engine::sink::SinkResult {
        self.stats.pulse(p)
    }

    fn wheel_contacts(&mut self, w: &WheelContacts<'_>) -> tortwin_engine::sink::SinkResult {
        self.stats.wheel_contacts(w)
    }

    fn finish(&mut self, _summary: &RunSummary) -> tortwin_engine::sink::SinkResult {
        self.close();
        Ok(())
    }
}

impl Sink for Stats {
    fn pulse(&mut self, p: &PulseEvent<'_>) -> tortwin_engine::sink::SinkResult {
        self.applied_ug[p.rail] += pulse_ug(p.mass_kg);
        self.pulses[p.rail] += 1;
        Ok(())
    }

    fn wheel_contacts(&mut self, w: &WheelContacts<'_>) -> tortwin_engine::sink::SinkResult {
        let dir = usize::from(w.direction == Direction::Down);
        let c = &mut self.counts[w.rail][dir];
        c.wheels += 1;
        if let Some(mu) = w.mu.as_deref() {
            // Generic friction terms: mu is given, compared with the band.
            let band = self.target.band;
            for ((&mu, inside), below) in
                mu.iter().zip(c.in_band.iter_mut()).zip(c.below.iter_mut())
            {
                let is_below = mu < band.lower_mu;
                *below += u32::from(is_below);
                *inside += u32::from(!is_below && mu <= band.upper_mu);
            }
            if let Some(sum) = &mut self.mu_sum {
                for (s, &mu) in sum[w.rail].iter_mut().zip(mu) {
                    *s += mu;
                }
            }
            return Ok(());
        }
        let band = self.mass_band;
        for ((&m, inside), below) in w
            .seen_mass_kg
            .iter()
            .zip(c.in_band.iter_mut())
            .zip(c.below.iter_mut())
        {
            let is_below = m > band.below_above_kg;
            *below += u32::from(is_below);
            *inside += u32::from(!is_below && m >= band.above_below_kg);
        }
        if let Some(sum) = &mut self.mu_sum {
            for (s, &m) in sum[w.rail].iter_mut().zip(w.seen_mass_kg.iter()) {
                *s += product::friction(&self.params, m);
            }
        }
        Ok(())
    }
}

/// A pulse's mass in whole micrograms, the unit products are counted in:
/// sums of them are exact, so two strategies that deliver the same product
/// (0.05 g every axle and 0.1 g every second axle) compare equal, where
/// sums of the masses in kilograms would differ in their last bits.
pub(crate) fn pulse_ug(mass_kg: f64) -> u64 {
    (mass_kg * 1e9).round() as u64
}

/// Grams, grams per day and grams per 1000 axles of `ug` micrograms: one
/// rounding each, so equal counts give equal figures.
fn per_day_and_axles(ug: u64, days: f64, axles: u64) -> (f64, f64, f64) {
    let g = ug as f64 / 1e6;
    let per_1000_axles = if axles == 0 {
        0.0
    } else {
        ug as f64 / 1e3 / axles as f64
    };
    (g, ug as f64 / 1e6 / days, per_1000_axles)
}

/// The figures of one strategy over the replayed period.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Figures {
    /// Share of the contacts on the target rails (every wheel pass at every
    /// grid point) that saw mu inside the band: the share of the section
    /// inside the band over the period, weighted by traffic.
    pub coverage: f64,
    /// Share of those contacts below the band (braking risk).
    pub below_share: f64,
    /// `below_share` within the target's limit.
    pub admissible: bool,
    /// Every rail's pulses.
    pub pulses: u64,
    /// Every rail's product in whole micrograms (each pulse's mass rounded
    /// to the microgram, then summed): what the front and the
    /// recommendation compare.
    pub product_ug: u64,
    /// `product_ug` in grams, per day and per 1000 axles.
    pub product_g: f64,
    pub product_g_per_day: f64,
    pub product_g_per_1000_axles: f64,
    pub rails: Vec<RailFigures>,
}

/// The figures of one rail.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RailFigures {
    pub rail: String,
    pub wheel_passes: u64,
    pub coverage: f64,
    pub below_share: f64,
    /// The longest of `carry_on`.
    pub carry_on_m: f64,
    pub carry_on: Vec<CarryOn>,
    /// Track length where at least `braking_risk_pass_share` of the wheel
    /// passes saw mu below the band.
    pub braking_risk_length_m: f64,
    /// The point with the largest share of passes below the band (none if
    /// no contact was below).
    pub worst_below: Option<WorstPoint>,
    pub pulses: u64,
    pub product_ug: u64,
    pub product_g: f64,
    pub product_g_per_day: f64,
    pub product_g_per_1000_axles: f64,
    /// Per point (only for the strategies the report draws).
    #[serde(skip)]
    pub profile: Option<Profile>,
}

/// How far one applicator keeps mu in the band for one travel direction.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CarryOn {
    pub applicator: String,
    pub direction: &'static str,
    pub distance_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WorstPoint {
    pub d_m: f64,
    pub pass_share: f64,
}

/// Per grid point over the period.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    pub d_m: Vec<f64>,
    pub mean_mu: Vec<f64>,
    pub in_band_share: Vec<f64>,
    pub below_band_share: Vec<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> ProductParams {
        ModelConfig::default().product
    }

    #[test]
    fn band_edges_are_eq4_inverted() {
        let p = params();
        let m_lo = mass_at_or_above(&p, 0.30);
        let m_hi = mass_at_or_below(&p, 0.40);
        assert!((product::friction(&p, m_lo) - 0.30).abs() < 1e-14);
        assert!((product::friction(&p, m_hi) - 0.40).abs() < 1e-14);
        assert!(m_hi < m_lo);
        // Just inside and outside each edge.
        assert!(product::friction(&p, m_lo * (1.0 + 1e-9)) < 0.30);
        assert!(product::friction(&p, m_lo * (1.0 - 1e-9)) > 0.30);
        assert!(product::friction(&p, m_hi * (1.0 - 1e-9)) > 0.40);
    }

    #[test]
    fn band_edges_outside_the_friction_range() {
        let p = params();
        // Lower edge at or below muC: nothing is ever below.
        assert_eq!(mass_at_or_above(&p, p.mu_c), f64::INFINITY);
        // Lower edge above muD: everything is below.
        assert!(mass_at_or_above(&p, p.mu_d + 0.01) < 0.0);
        // Upper edge at muD: nothing is above (m >= 0).
        assert_eq!(mass_at_or_below(&p, p.mu_d), 0.0);
        assert_eq!(mass_at_or_below(&p, p.mu_c), f64::INFINITY);
    }
}
