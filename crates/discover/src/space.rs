//! The space of generic terms discover searches (effects.md, "Generic
//! terms"): every acts_on × driver × form × scope the recording can show.
//!
//! A [`GenericSlot`] is one term with its parameter left free: acts_on,
//! driver, form, scope, and for a step its threshold (`x0`, or `t0` for a
//! time step), fixed when the slot is made. Its one fitted parameter (beta,
//! n, gamma, f or offset) is searched on a bounded range that follows from
//! the driver's observed range, so that every slot can move g over the same
//! span whatever the driver's units.
//!
//! [`Space::enumerate`] lists the directions the screening
//! (`screen.rs`) tries; adding a driver is one line in
//! `model::generic::Driver` and one in [`Drivers`].

use serde::Serialize;

use super::data::Dataset;
use tortwin_model::config::{Effects, GenericTerm, TermEffect};
use tortwin_model::generic::{ActsOn, Driver, Form, FormKind};
use tortwin_recording::{EventKind, Quantity};

/// How far a fitted exp or power factor may reach over the typical range
/// of its driver: `|ln g|` up to this much at the 5th or 95th percentile of
/// the values it sees (or between them). A driver whose values all sit far
/// from its `x_ref` (creepage on tangent track is about a tenth of 0.01)
/// needs room for a level, not only for a slope: a power of creepage with
/// n = 1.3 is g = 0.01 at the 5th percentile there.
const REACH: f64 = 5.0;
/// The same for a linear factor: g may reach 1 ± this at the typical
/// extremes (it is clamped at 0 below).
const LINEAR_REACH: f64 = 3.0;
/// And at the extremes of everything the recording shows, `|ln g|` stays
/// below this: a driver that is nearly always at one value (precipitation
/// is mostly 0) has almost no typical span, and a factor fitted to it must
/// still be a number at the rare extreme (the engine refuses one that is
/// not).
const FULL_REACH: f64 = 20.0;

/// The values a driver takes, for the range of a fitted parameter: its
/// 5th to 95th percentile, and everything the recording shows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Reach {
    pub(super) typical: (f64, f64),
    pub(super) full: (f64, f64),
}

impl Reach {
    /// For a step, whose factor `f` does not depend on the driver's values.
    pub(super) const STEP: Reach = Reach {
        typical: (0.0, 1.0),
        full: (0.0, 1.0),
    };
}
/// The largest measurement offset searched.
const OFFSET_MAX: f64 = 0.3;
/// A step's factor is searched in [0, STEP_F_MAX].
const STEP_F_MAX: f64 = 3.0;

/// One generic term with its parameter left free.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize)]
pub(super) struct GenericSlot {
    pub(super) acts_on: ActsOn,
    /// `None` for `measurement`.
    pub(super) driver: Option<Driver>,
    pub(super) form: Option<FormKind>,
    pub(super) applicator: Option<String>,
    pub(super) rail: Option<String>,
    pub(super) site: Option<String>,
    pub(super) quantity: Option<Quantity>,
    /// A step's threshold (unix seconds for time), as bits.
    x0_bits: Option<u64>,
    lo_bits: u64,
    hi_bits: u64,
}

/// Where a slot acts, by name.
#[derive(Debug, Clone, Default, PartialEq, Eq, Hash, Serialize)]
pub(super) struct Scope {
    pub(super) applicator: Option<String>,
    pub(super) rail: Option<String>,
    pub(super) site: Option<String>,
    pub(super) quantity: Option<Quantity>,
}

impl Scope {
    /// Scope keys named (more keys: a narrower statement).
    pub(super) fn keys(&self) -> usize {
        usize::from(self.applicator.is_some())
            + usize::from(self.rail.is_some())
            + usize::from(self.site.is_some())
            + usize::from(self.quantity.is_some())
    }
}

impl GenericSlot {
    /// A slot on `acts_on` driven by `driver` in `form` (a step at `x0`),
    /// its parameter searched on the range that `reach` (the driver's
    /// typical and full range, [`Drivers::reach`]) allows.
    pub(super) fn factor(
        acts_on: ActsOn,
        driver: Driver,
        form: FormKind,
        scope: Scope,
        x0: Option<f64>,
        reach: Reach,
    ) -> Self {
        let x_ref = driver.x_ref().unwrap_or(0.0);
        let linear_span = |(lo, hi): (f64, f64)| {
            (lo - x_ref)
                .abs()
                .max((hi - x_ref).abs())
                .max(hi - lo)
                .max(1e-9)
        };
        let log_span = |(lo, hi): (f64, f64)| {
            let (lo, hi) = (lo.max(1e-12), hi.max(1e-12));
            (lo / x_ref)
                .ln()
                .abs()
                .max((hi / x_ref).ln().abs())
                .max((hi / lo).ln())
                .max(1e-9)
        };
        let (lo, hi) = match form {
            FormKind::Exp => {
                let b =
                    (REACH / linear_span(reach.typical)).min(FULL_REACH / linear_span(reach.full));
                (-b, b)
            }
            FormKind::Linear => {
                let b = LINEAR_REACH / linear_span(reach.typical);
                (-b, b)
            }
            FormKind::Power => {
                let b = (REACH / log_span(reach.typical)).min(FULL_REACH / log_span(reach.full));
                (-b, b)
            }
            FormKind::Step => (0.0, STEP_F_MAX),
        };
        Self {
            acts_on,
            driver: Some(driver),
            form: Some(form),
            applicator: scope.applicator,
            rail: scope.rail,
            site: scope.site,
            quantity: scope.quantity,
            x0_bits: x0.map(f64::to_bits),
            lo_bits: lo.to_bits(),
            hi_bits: hi.to_bits(),
        }
    }

    /// An offset on what a site measures.
    pub(super) fn offset(scope: Scope) -> Self {
        Self {
            acts_on: ActsOn::Measurement,
            driver: None,
            form: None,
            applicator: None,
            rail: scope.rail,
            site: scope.site,
            quantity: scope.quantity,
            x0_bits: None,
            lo_bits: (-OFFSET_MAX).to_bits(),
            hi_bits: OFFSET_MAX.to_bits(),
        }
    }

    pub(super) fn scope(&self) -> Scope {
        Scope {
            applicator: self.applicator.clone(),
            rail: self.rail.clone(),
            site: self.site.clone(),
            quantity: self.quantity,
        }
    }

    pub(super) fn x0(&self) -> Option<f64> {
        self.x0_bits.map(f64::from_bits)
    }

    /// The fitted parameter's range.
    pub(super) fn bounds(&self) -> (f64, f64) {
        (f64::from_bits(self.lo_bits), f64::from_bits(self.hi_bits))
    }

    /// The parameter's name in a `[[effects.generic]]` table.
    pub(super) fn param_name(&self) -> &'static str {
        match self.form {
            None => "offset",
            Some(FormKind::Exp) => "beta",
            Some(FormKind::Power) => "n",
            Some(FormKind::Linear) => "gamma",
            Some(FormKind::Step) => "f",
        }
    }

    /// The parameter value at which the term changes nothing.
    pub(super) fn neutral(&self) -> f64 {
        match self.form {
            Some(FormKind::Step) => 1.0,
            _ => 0.0,
        }
    }

    /// The term with parameter `p`.
    pub(super) fn term(&self, p: f64) -> GenericTerm {
        let effect = match (self.driver, self.form) {
            (Some(driver), Some(kind)) => TermEffect::Factor {
                driver,
                form: match kind {
                    FormKind::Exp => Form::Exp { beta: p },
                    FormKind::Power => Form::Power { n: p },
                    FormKind::Linear => Form::Linear { gamma: p },
                    FormKind::Step => Form::Step {
                        x0: self.x0().unwrap_or(0.0),
                        f: p,
                    },
                },
            },
            _ => TermEffect::Offset { offset: p },
        };
        GenericTerm {
            acts_on: self.acts_on,
            applicator: self.applicator.clone(),
            rail: self.rail.clone(),
            site: self.site.clone(),
            quantity: self.quantity,
            effect,
        }
    }

    /// Whether `other` acts on the same quantity, driven by the same
    /// covariate, in the same scope (whatever its form).
    pub(super) fn same_direction(&self, other: &GenericSlot) -> bool {
        self.acts_on == other.acts_on
            && self.driver == other.driver
            && self.scope() == other.scope()
    }

    /// Whether `term` is this slot (whatever its parameter).
    pub(super) fn is(&self, term: &GenericTerm) -> bool {
        let shape = match term.effect {
            TermEffect::Offset { .. } => (None, None, None),
            TermEffect::Factor { driver, form } => (
                Some(driver),
                Some(form.kind()),
                match form {
                    Form::Step { x0, .. } => Some(x0.to_bits()),
                    _ => None,
                },
            ),
        };
        term.acts_on == self.acts_on
            && term.applicator == self.applicator
            && term.rail == self.rail
            && term.site == self.site
            && term.quantity == self.quantity
            && shape == (self.driver, self.form, self.x0_bits)
    }

    /// The parameter of this slot's term in `effects`, if it is on.
    pub(super) fn get(&self, effects: &Effects) -> Option<f64> {
        effects
            .generic
            .iter()
            .find(|t| self.is(t))
            .map(|t| match t.effect {
                TermEffect::Offset { offset } => offset,
                TermEffect::Factor { form, .. } => match form {
                    Form::Exp { beta } => beta,
                    Form::Power { n } => n,
                    Form::Linear { gamma } => gamma,
                    Form::Step { f, .. } => f,
                },
            })
    }

    /// Switches the term on in `effects` with parameter `p` (replacing
    /// its earlier value).
    pub(super) fn set(&self, effects: &mut Effects, p: f64) {
        let term = self.term(p);
        match effects.generic.iter_mut().find(|t| self.is(t)) {
            Some(t) => *t = term,
            None => effects.generic.push(term),
        }
    }

    /// A short label: `consumption × creepage (power; rail low)`.
    pub(super) fn label(&self) -> String {
        let scope = self.scope();
        let mut parts = Vec::new();
        if let Some(a) = &scope.applicator {
            parts.push(format!("applicator {a}"));
        }
        if let Some(r) = &scope.rail {
            parts.push(format!("rail {r}"));
        }
        if let Some(s) = &scope.site {
            parts.push(format!("site {s}"));
        }
        if let Some(q) = scope.quantity {
            parts.push(format!("quantity {}", q.as_str()));
        }
        let scope = if parts.is_empty() {
            "everywhere".to_string()
        } else {
            parts.join(", ")
        };
        match (self.driver, self.form) {
            (Some(d), Some(f)) => {
                let at = match (d, self.x0()) {
                    (Driver::Time, Some(x0)) => {
                        format!(" at {}", tortwin_model::config::format_utc(x0))
                    }
                    (_, Some(x0)) => format!(" at {x0:.4}"),
                    _ => String::new(),
                };
                format!(
                    "generic {} × {} ({}{at}; {scope})",
                    self.acts_on.name(),
                    d.name(),
                    f.name()
                )
            }
            _ => format!("generic measurement offset ({scope})"),
        }
    }
}

/// Every driver's value at each measurement (NaN where it has none), and its
/// range over everything the recording shows (contacts and weather).
pub(super) struct Drivers {
    /// [driver][row]
    pub(super) at_row: Vec<Vec<f64>>,
    /// [driver]: (min, max) over the recording.
    pub(super) range: Vec<(f64, f64)>,
    /// [driver]: the 5th and 95th percentiles of the values a term sees
    /// (every weather message, every wheel on every rail, every event
    /// time): where a fitted factor must be able to reach.
    pub(super) typical: Vec<(f64, f64)>,
    /// [driver]: every distinct value a term sees, ascending: where a
    /// step's threshold can make a difference.
    pub(super) distinct: Vec<Vec<f64>>,
}

impl Drivers {
    pub(super) fn of(data: &Dataset) -> Self {
        let n = data.rows.len();
        let mut at_row = vec![vec![f64::NAN; n]; Driver::ALL.len()];
        let mut seen: Vec<Vec<f64>> = vec![Vec::new(); Driver::ALL.len()];
        let mut widen = |d: Driver, x: f64| {
            if x.is_finite() {
                seen[d as usize].push(x);
            }
        };
        let defaults = tortwin_recording::Weather::default();
        widen(Driver::AirTemperatureC, defaults.air_temperature_c);
        widen(Driver::RelativeHumidity, defaults.relative_humidity);
        widen(Driver::PrecipitationMmH, defaults.precipitation_mm_h);
        for event in &data.events {
            match &event.kind {
                EventKind::Weather(w) => {
                    widen(Driver::AirTemperatureC, w.air_temperature_c);
                    widen(Driver::RelativeHumidity, w.relative_humidity);
                    widen(Driver::PrecipitationMmH, w.precipitation_mm_h);
                }
                EventKind::Passage(p) => {
                    widen(Driver::SpeedMps, p.speed_mps);
                    for axle in &p.axles {
                        for q in &axle.wheel_load_n {
                            widen(Driver::WheelLoadKn, q / 1000.0);
                        }
                        for c in &axle.creepage {
                            widen(Driver::Creepage, (c.cx * c.cx + c.cy * c.cy).sqrt());
                        }
                    }
                }
                _ => {}
            }
            widen(Driver::Time, event.log_time_ns as f64 * 1e-9);
        }
        let mut range = Vec::with_capacity(seen.len());
        let mut typical = Vec::with_capacity(seen.len());
        for values in &mut seen {
            values.sort_unstable_by(f64::total_cmp);
            let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
            if values.is_empty() {
                range.push((f64::INFINITY, f64::NEG_INFINITY));
                typical.push((f64::INFINITY, f64::NEG_INFINITY));
            } else {
                range.push((at(0.0), at(1.0)));
                typical.push((at(0.05), at(0.95)));
            }
            values.dedup();
        }
        for (k, row) in data.rows.iter().enumerate() {
            at_row[Driver::Time as usize][k] = row.log_time_ns as f64 * 1e-9;
            let w = data.weather_at(row.log_time_ns);
            at_row[Driver::AirTemperatureC as usize][k] = w.air_temperature_c;
            at_row[Driver::RelativeHumidity as usize][k] = w.relative_humidity;
            at_row[Driver::PrecipitationMmH as usize][k] = w.precipitation_mm_h;
            if let (Some(seq), Some(axle)) = (row.train_seq, row.axle_index) {
                if let Some(p) = data.passages.get(seq) {
                    at_row[Driver::SpeedMps as usize][k] = p.speed_mps;
                    if let Some(q) = p.wheel_load_n.get(axle).and_then(|l| l.get(row.rail)) {
                        at_row[Driver::WheelLoadKn as usize][k] = q / 1000.0;
                    }
                    if let Some(c) = p.creepage.get(axle).and_then(|l| l.get(row.rail)) {
                        at_row[Driver::Creepage as usize][k] = *c;
                    }
                }
            }
        }
        Self {
            at_row,
            range,
            typical,
            distinct: seen,
        }
    }

    pub(super) fn values(&self, d: Driver) -> &[f64] {
        &self.at_row[d as usize]
    }

    pub(super) fn range(&self, d: Driver) -> (f64, f64) {
        self.range[d as usize]
    }

    /// Every distinct value a term driven by `d` sees, ascending.
    pub(super) fn distinct(&self, d: Driver) -> &[f64] {
        &self.distinct[d as usize]
    }

    /// The 5th and 95th percentiles of the values a term driven by `d` sees,
    /// and all of them.
    pub(super) fn reach(&self, d: Driver) -> Reach {
        Reach {
            typical: self.typical[d as usize],
            full: self.range[d as usize],
        }
    }

    /// Whether the recording shows the driver changing at all.
    pub(super) fn varies(&self, d: Driver) -> bool {
        let (lo, hi) = self.range(d);
        lo.is_finite() && hi > lo * (1.0 + 1e-9) + 1e-12
    }

    /// Whether `form` can describe `d` over its observed range (a power
    /// needs x > 0 throughout).
    pub(super) fn allows(&self, d: Driver, form: FormKind) -> bool {
        d.allows(form) && (form != FormKind::Power || self.range(d).0 > 0.0)
    }
}
