//! The generic terms of a configuration, compiled for one section: scope
//! names resolved to indices, a time step's threshold turned into time_s
//! from the engine's origin. The engine asks this table for the product of
//! the terms on one quantity at one contact, pulse or reading; with no term
//! on a quantity the answer is exactly 1 (effects.md: a term whose g is 1
//! changes nothing, bit for bit).

use tortwin_model::config::terms::{err, TermError};
use tortwin_model::config::{GenericTerm, TermEffect};
use tortwin_model::error::ConfigError;
use tortwin_model::generic::{ActsOn, Driver, Form};
use tortwin_recording::{Quantity, Section, Weather};

/// When a term is asked for its factor: the time, the weather in effect
/// and, at a contact, the wheel's drivers.
#[derive(Debug, Clone, Copy)]
pub(crate) struct When<'a> {
    pub(crate) time_s: f64,
    pub(crate) weather: &'a Weather,
    pub(crate) wheel: Option<&'a WheelDrivers>,
}

/// A name in a scope that the section does not have: matches nothing (the
/// commands refuse such a configuration before the engine sees it).
const UNKNOWN: usize = usize::MAX;

#[derive(Debug, Clone, Copy)]
struct Compiled {
    /// Its index among the `[[effects.generic]]` tables.
    index: usize,
    driver: Driver,
    form: Form,
    x_ref: f64,
    offset: f64,
    applicator: Option<usize>,
    rail: Option<usize>,
    site: Option<usize>,
    quantity: Option<Quantity>,
}

impl Compiled {
    /// The term's driver value where it acts (`rail`, `applicator`) among
    /// the terms `which` selects, `at` a time with its weather and, at a
    /// contact, the wheel's drivers; `None` where it does not act (a wheel
    /// term without a wheel: g = 1).
    #[inline]
    fn driver_value(
        &self,
        which: Which,
        applicator: Option<usize>,
        rail: usize,
        at: When<'_>,
    ) -> Option<f64> {
        if self.rail.is_some_and(|r| r != rail)
            || self.applicator.is_some_and(|a| Some(a) != applicator)
        {
            return None;
        }
        let When {
            time_s,
            weather,
            wheel,
        } = at;
        Some(match (self.driver, which) {
            (d, Which::Wheel) if !d.is_wheel() => return None,
            (d, Which::Event) if d.is_wheel() => return None,
            (Driver::Time, _) => time_s,
            (Driver::AirTemperatureC, _) => weather.air_temperature_c,
            (Driver::RelativeHumidity, _) => weather.relative_humidity,
            (Driver::PrecipitationMmH, _) => weather.precipitation_mm_h,
            (Driver::SpeedMps, _) => wheel?.speed_mps,
            (Driver::WheelLoadKn, _) => wheel?.wheel_load_kn,
            (Driver::Creepage, _) => wheel?.creepage,
        })
    }
}

/// A generic term whose factor is not a finite number at a driver value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UndefinedFactor {
    /// Index among the `[[effects.generic]]` tables.
    pub term: usize,
    pub driver: Driver,
    pub x: f64,
    pub g: f64,
}

/// What a wheel brings to a contact: the wheel drivers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct WheelDrivers {
    pub(crate) speed_mps: f64,
    pub(crate) wheel_load_kn: f64,
    /// `sqrt(cx² + cy²)`.
    pub(crate) creepage: f64,
}

/// Which terms a product takes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Which {
    /// Every term.
    All,
    /// Terms driven by the wheel (constant along its path).
    Wheel,
    /// Terms driven by time or weather (they change from point to point).
    Event,
}

/// The compiled terms, per quantity they act on.
#[derive(Debug, Clone, Default)]
pub(crate) struct GenericSet {
    by_acts_on: [Vec<Compiled>; 6],
}

impl GenericSet {
    pub(crate) fn compile(terms: &[GenericTerm], section: &Section, origin_ns: i64) -> Self {
        let mut set = Self::default();
        fn index<'a>(
            name: &Option<String>,
            mut names: impl Iterator<Item = &'a String>,
        ) -> Option<usize> {
            name.as_ref()
                .map(|n| names.position(|x| x == n).unwrap_or(UNKNOWN))
        }
        for (term_index, term) in terms.iter().enumerate() {
            let (driver, form, offset) = match term.effect {
                TermEffect::Factor { driver, form } => (driver, form, 0.0),
                TermEffect::Offset { offset } => {
                    (Driver::Time, Form::Step { x0: 0.0, f: 1.0 }, offset)
                }
            };
            // A time step's threshold in the engine's time_s, through the
            // same integer difference as every event's time (model.md).
            let form = match (driver, form) {
                (Driver::Time, Form::Step { x0, f }) => {
                    let t0_ns = (x0 * 1e9).round() as i64;
                    Form::Step {
                        x0: t0_ns.wrapping_sub(origin_ns) as f64 * 1e-9,
                        f,
                    }
                }
                (_, form) => form,
            };
            set.by_acts_on[term.acts_on.index()].push(Compiled {
                index: term_index,
                driver,
                form,
                x_ref: driver.x_ref().unwrap_or(0.0),
                offset,
                applicator: index(&term.applicator, section.applicators.iter().map(|a| &a.id)),
                rail: index(&term.rail, section.rails.iter()),
                site: index(&term.site, section.sites.iter().map(|s| &s.id)),
                quantity: term.quantity,
            });
        }
        set
    }

    /// The first factor that is not a finite number (or is beyond
    /// [`tortwin_model::generic::FACTOR_MAX`]) where `value` gives its
    /// driver a value (`None` for drivers the event does not carry), e.g. a
    /// `power` of a temperature below 0 °C or of a creepage of 0 with a
    /// negative exponent: effects.md's formula has no value there, and a NaN
    /// or infinite factor would quietly empty or flood the rail.
    pub(crate) fn undefined(
        &self,
        value: impl Fn(Driver) -> Option<f64>,
    ) -> Option<UndefinedFactor> {
        self.by_acts_on.iter().flatten().find_map(|t| {
            let x = value(t.driver)?;
            let g = t.form.g(x, t.x_ref);
            (!(g.is_finite() && g <= tortwin_model::generic::FACTOR_MAX)).then_some(
                UndefinedFactor {
                    term: t.index,
                    driver: t.driver,
                    x,
                    g,
                },
            )
        })
    }

    /// Whether any term acts on `acts_on`.
    pub(crate) fn any(&self, acts_on: ActsOn) -> bool {
        !self.by_acts_on[acts_on.index()].is_empty()
    }

    /// Whether a term on `acts_on` for `rail` changes along a wheel's path
    /// (driven by time or weather).
    pub(crate) fn varies(&self, acts_on: ActsOn, rail: usize) -> bool {
        self.by_acts_on[acts_on.index()]
            .iter()
            .any(|t| t.rail.is_none_or(|r| r == rail) && !t.driver.is_wheel())
    }

    /// The terms on `acts_on` that `which` selects and that apply to `rail`
    /// (and `applicator`, for pulses), each with its driver's value `at` a
    /// time with its weather and, at a contact, the wheel's drivers. A
    /// wheel term has no value without a wheel: it does not act.
    #[inline]
    fn acting<'s>(
        &'s self,
        acts_on: ActsOn,
        which: Which,
        applicator: Option<usize>,
        rail: usize,
        at: When<'s>,
    ) -> impl Iterator<Item = (&'s Compiled, f64)> + 's {
        self.by_acts_on[acts_on.index()]
            .iter()
            .filter_map(move |t| Some((t, t.driver_value(which, applicator, rail, at)?)))
    }

    /// The product of the [`GenericSet::acting`] terms' factors (1 when
    /// none acts).
    #[inline]
    pub(crate) fn factor(
        &self,
        acts_on: ActsOn,
        which: Which,
        applicator: Option<usize>,
        rail: usize,
        at: When<'_>,
    ) -> f64 {
        self.acting(acts_on, which, applicator, rail, at)
            .fold(1.0, |g, (t, x)| g * t.form.g(x, t.x_ref))
    }

    /// [`GenericSet::factor`] and its derivative in the smooth parameter of
    /// `[[effects.generic]]` table `term` (`Form::dg_dq`; 0 when that term
    /// is not among the factors), by the product rule: exact where a
    /// factor is 0.
    pub(crate) fn factor_and_derivative(
        &self,
        acts_on: ActsOn,
        which: Which,
        applicator: Option<usize>,
        rail: usize,
        at: When<'_>,
        term: usize,
    ) -> (f64, f64) {
        self.acting(acts_on, which, applicator, rail, at)
            .fold((1.0, 0.0), |(g, dg), (t, x)| {
                let gt = t.form.g(x, t.x_ref);
                let own = if t.index == term {
                    t.form.dg_dq(x, t.x_ref)
                } else {
                    0.0
                };
                (g * gt, dg * gt + g * own)
            })
    }

    /// muD and muC of eq. (4) with the friction terms for `rail` at this
    /// contact or reading.
    #[inline]
    pub(crate) fn friction_levels(
        &self,
        mu_d: f64,
        mu_c: f64,
        rail: usize,
        time_s: f64,
        weather: &Weather,
        wheel: Option<&WheelDrivers>,
    ) -> (f64, f64) {
        let dry = ActsOn::FrictionDry;
        let boundary = ActsOn::FrictionBoundary;
        let at = When {
            time_s,
            weather,
            wheel,
        };
        let gd = self.factor(dry, Which::All, None, rail, at);
        let gc = self.factor(boundary, Which::All, None, rail, at);
        (mu_d * gd, mu_c * gc)
    }

    /// Whether any friction term exists (the field and the site contacts
    /// then carry their own muD, muC).
    pub(crate) fn any_friction(&self) -> bool {
        self.any(ActsOn::FrictionDry) || self.any(ActsOn::FrictionBoundary)
    }

    /// The simulated value of a measurement with the `measurement` terms'
    /// offsets added, in the order of the terms.
    #[inline]
    pub(crate) fn measured(&self, value: f64, site: usize, rail: usize, quantity: Quantity) -> f64 {
        let mut v = value;
        for t in &self.by_acts_on[ActsOn::Measurement.index()] {
            if t.site.is_none_or(|s| s == site)
                && t.rail.is_none_or(|r| r == rail)
                && t.quantity.is_none_or(|q| q == quantity)
            {
                v += t.offset;
            }
        }
        v
    }
}

/// The earliest time_s at which any of `terms` can be other than 1 (or
/// add an offset): a time step's `t0` (never, for a step of 1), and for
/// every other term the beginning of time.
pub fn acts_from_s(terms: &[GenericTerm], origin_ns: i64) -> f64 {
    terms
        .iter()
        .map(|term| match term.effect {
            TermEffect::Factor {
                driver: Driver::Time,
                form: Form::Step { x0, f },
            } => {
                if f == 1.0 {
                    f64::INFINITY
                } else {
                    // As `GenericSet::compile` places it.
                    let t0_ns = (x0 * 1e9).round() as i64;
                    t0_ns.wrapping_sub(origin_ns) as f64 * 1e-9
                }
            }
            _ => f64::NEG_INFINITY,
        })
        .fold(f64::INFINITY, f64::min)
}

/// Checks the generic terms of `terms` against `section`; the error names
/// the term (its index among the `[[effects.generic]]` tables) and the key.
pub fn check_terms_against(
    terms: &[GenericTerm],
    section: &Section,
    source_name: &str,
) -> Result<(), ConfigError> {
    for (k, term) in terms.iter().enumerate() {
        check_section(term, section).map_err(|(key, message)| ConfigError {
            source_name: source_name.into(),
            key: format!("effects.generic[{k}].{key}"),
            message: format!("({} term) {message}", term.acts_on.name()),
        })?;
    }
    Ok(())
}

/// Every name in the scope exists in `section` (an unknown applicator,
/// rail or site is a configuration error naming the term and key).
fn check_section(term: &GenericTerm, section: &Section) -> Result<(), TermError> {
    if let Some(a) = &term.applicator {
        if !section.applicators.iter().any(|x| &x.id == a) {
            let ids: Vec<&str> = section.applicators.iter().map(|x| x.id.as_str()).collect();
            return Err(err(
                "applicator",
                format!(
                    "unknown applicator `{a}`: section {} has {}",
                    section.section_id,
                    ids.join(", ")
                ),
            ));
        }
    }
    if let Some(r) = &term.rail {
        if !section.rails.iter().any(|x| x == r) {
            return Err(err(
                "rail",
                format!(
                    "unknown rail `{r}`: section {} has {}",
                    section.section_id,
                    section.rails.join(", ")
                ),
            ));
        }
    }
    if let Some(s) = &term.site {
        if !section.sites.iter().any(|x| &x.id == s) {
            let ids: Vec<&str> = section.sites.iter().map(|x| x.id.as_str()).collect();
            return Err(err(
                "site",
                format!(
                    "unknown site `{s}`: section {} has {}",
                    section.section_id,
                    ids.join(", ")
                ),
            ));
        }
    }
    Ok(())
}
