//! Generic terms (docs/spec/effects.md, "Generic terms"): effects
//! outside the catalogue, each a factor `g(x)` on one quantity of the model
//! driven by one covariate `x`, or an offset on what a site measures.
//!
//! This module is the vocabulary and the arithmetic: where a term acts
//! ([`ActsOn`]), what drives it ([`Driver`]), its shape ([`Form`]) and
//! [`Form::g`]. Which term applies to which contact, pulse or reading is
//! the engine's business (`engine::terms`); how a term is written in a
//! configuration is `config::GenericTerm`'s.

use serde::{Deserialize, Serialize};

/// The largest factor a generic term may put on a quantity, anywhere the
/// recording drives it: a factor of 10^12 is beyond any effect a rail shows
/// (discover searches up to e^20 = 4.9e8 at the data's extremes), and
/// everything the model computes from it stays finite.
pub const FACTOR_MAX: f64 = 1e12;

/// The largest measurement offset (`offset` of a `measurement` term): no
/// reading lies beyond +-10 (docs/spec/recording-format.md "Limits").
pub const OFFSET_MAX: f64 = 10.0;

/// The quantity a generic term multiplies (or, for `Measurement`, offsets).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActsOn {
    /// The mass that lands (pulse landing); m0 of eq. (1) is a constant.
    PulseMass,
    /// The transfer fraction `t` of eq. (6), before its clamp at 0.5 (step 3).
    Transfer,
    /// The whole consumption `c` of eq. (1), before `c <= m` (step 4).
    Consumption,
    /// muD of eq. (4) (step 2 and tribometer readings).
    FrictionDry,
    /// muC of eq. (4), likewise.
    FrictionBoundary,
    /// What a site measures: the model's value plus an offset (output).
    Measurement,
}

impl ActsOn {
    pub(crate) const ALL: [ActsOn; 6] = [
        ActsOn::PulseMass,
        ActsOn::Transfer,
        ActsOn::Consumption,
        ActsOn::FrictionDry,
        ActsOn::FrictionBoundary,
        ActsOn::Measurement,
    ];

    /// The name in a configuration (`acts_on = "..."`).
    pub fn name(self) -> &'static str {
        match self {
            ActsOn::PulseMass => "pulse_mass",
            ActsOn::Transfer => "transfer",
            ActsOn::Consumption => "consumption",
            ActsOn::FrictionDry => "friction_dry",
            ActsOn::FrictionBoundary => "friction_boundary",
            ActsOn::Measurement => "measurement",
        }
    }

    pub(crate) fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|a| a.name() == name)
    }

    /// The scope keys a term on this quantity may carry.
    pub(crate) fn scope_keys(self) -> &'static [&'static str] {
        match self {
            ActsOn::PulseMass => &["applicator", "rail"],
            ActsOn::Measurement => &["site", "rail", "quantity"],
            _ => &["rail"],
        }
    }

    /// What it is, for people.
    pub fn describe(self) -> &'static str {
        match self {
            ActsOn::PulseMass => "the applied pulse mass",
            ActsOn::Transfer => "the wheel-rail transfer",
            ActsOn::Consumption => "the product consumption",
            ActsOn::FrictionDry => "the dry friction level muD",
            ActsOn::FrictionBoundary => "the lubricated friction level muC",
            ActsOn::Measurement => "the measured value",
        }
    }

    /// Index into per-quantity tables (`ALL` order).
    #[inline]
    pub fn index(self) -> usize {
        self as usize
    }
}

/// The covariate `x` that drives a term.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Driver {
    #[serde(rename = "time")]
    Time,
    #[serde(rename = "air_temperature_c")]
    AirTemperatureC,
    #[serde(rename = "relative_humidity")]
    RelativeHumidity,
    #[serde(rename = "precipitation_mm_h")]
    PrecipitationMmH,
    #[serde(rename = "speed_mps")]
    SpeedMps,
    #[serde(rename = "wheel_load_kN")]
    WheelLoadKn,
    #[serde(rename = "creepage")]
    Creepage,
}

impl Driver {
    pub const ALL: [Driver; 7] = [
        Driver::Time,
        Driver::AirTemperatureC,
        Driver::RelativeHumidity,
        Driver::PrecipitationMmH,
        Driver::SpeedMps,
        Driver::WheelLoadKn,
        Driver::Creepage,
    ];

    /// The name in a configuration (`driver = "..."`).
    pub fn name(self) -> &'static str {
        match self {
            Driver::Time => "time",
            Driver::AirTemperatureC => "air_temperature_c",
            Driver::RelativeHumidity => "relative_humidity",
            Driver::PrecipitationMmH => "precipitation_mm_h",
            Driver::SpeedMps => "speed_mps",
            Driver::WheelLoadKn => "wheel_load_kN",
            Driver::Creepage => "creepage",
        }
    }

    pub(crate) fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|d| d.name() == name)
    }

    /// `x_ref` of the forms (effects.md); `None` for time, which takes only
    /// a step.
    #[inline]
    pub fn x_ref(self) -> Option<f64> {
        match self {
            Driver::Time => None,
            Driver::AirTemperatureC => Some(20.0),
            Driver::RelativeHumidity => Some(0.5),
            Driver::PrecipitationMmH => Some(0.0),
            Driver::SpeedMps => Some(20.0),
            Driver::WheelLoadKn => Some(100.0),
            Driver::Creepage => Some(0.01),
        }
    }

    /// A property of the wheel (no value at a pulse or a tribometer reading).
    #[inline]
    pub fn is_wheel(self) -> bool {
        matches!(
            self,
            Driver::SpeedMps | Driver::WheelLoadKn | Driver::Creepage
        )
    }

    /// Whether `form` is allowed with this driver (effects.md: `time` takes
    /// only `step`; `power` not for `precipitation_mm_h` or `time`).
    pub fn allows(self, form: FormKind) -> bool {
        match (self, form) {
            (Driver::Time, FormKind::Step) => true,
            (Driver::Time, _) => false,
            (Driver::PrecipitationMmH, FormKind::Power) => false,
            _ => true,
        }
    }

    /// What it is and its unit, for people.
    pub fn describe(self) -> &'static str {
        match self {
            Driver::Time => "time (UTC)",
            Driver::AirTemperatureC => "air temperature (°C)",
            Driver::RelativeHumidity => "relative humidity (0-1)",
            Driver::PrecipitationMmH => "precipitation (mm/h)",
            Driver::SpeedMps => "train speed (m/s)",
            Driver::WheelLoadKn => "wheel load (kN)",
            Driver::Creepage => "creepage",
        }
    }
}

/// The forms of effects.md without their parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FormKind {
    Exp,
    Power,
    Linear,
    Step,
}

impl FormKind {
    pub(crate) const ALL: [FormKind; 4] = [
        FormKind::Exp,
        FormKind::Power,
        FormKind::Linear,
        FormKind::Step,
    ];

    pub fn name(self) -> &'static str {
        match self {
            FormKind::Exp => "exp",
            FormKind::Power => "power",
            FormKind::Linear => "linear",
            FormKind::Step => "step",
        }
    }

    pub(crate) fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|f| f.name() == name)
    }
}

/// A form with its parameters. A step on `time` keeps its threshold as
/// time_s from the engine's origin once compiled; in a configuration it
/// is `t0_utc` (see `config::GenericTerm`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Form {
    /// `exp(beta (x - x_ref))`
    Exp { beta: f64 },
    /// `(x / x_ref)^n`
    Power { n: f64 },
    /// `max(0, 1 + gamma (x - x_ref))`
    Linear { gamma: f64 },
    /// 1 where `x < x0`, `f` where `x >= x0`.
    Step { x0: f64, f: f64 },
}

impl Form {
    #[inline]
    pub fn kind(self) -> FormKind {
        match self {
            Form::Exp { .. } => FormKind::Exp,
            Form::Power { .. } => FormKind::Power,
            Form::Linear { .. } => FormKind::Linear,
            Form::Step { .. } => FormKind::Step,
        }
    }

    /// Whether `g(x)` is exactly 1 for every finite `x`: `beta`, `n` or
    /// `gamma` 0, a step to `f` = 1. Such a term multiplies its quantity by
    /// 1.0 and changes no bit of a replay.
    pub fn is_neutral(self) -> bool {
        match self {
            Form::Exp { beta: q } | Form::Power { n: q } | Form::Linear { gamma: q } => q == 0.0,
            Form::Step { f, .. } => f == 1.0,
        }
    }

    /// `g(x)` (effects.md, "Its shape"). `x_ref` is the driver's; a step
    /// ignores it.
    #[inline]
    pub fn g(self, x: f64, x_ref: f64) -> f64 {
        match self {
            Form::Exp { beta } => (beta * (x - x_ref)).exp(),
            Form::Power { n } => (x / x_ref).powf(n),
            Form::Linear { gamma } => (1.0 + gamma * (x - x_ref)).max(0.0),
            Form::Step { x0, f } => {
                if x >= x0 {
                    f
                } else {
                    1.0
                }
            }
        }
    }

    /// `∂g/∂q` at `x`, `q` the form's smooth parameter: `beta`, `n`,
    /// `gamma`, or a step's `f` (its threshold `x0` moves g by a jump: it
    /// has no derivative, and a fit takes differences for it). Where the
    /// linear form is clamped at 0 the derivative of that branch: 0.
    #[inline]
    pub fn dg_dq(self, x: f64, x_ref: f64) -> f64 {
        match self {
            Form::Exp { beta } => (x - x_ref) * (beta * (x - x_ref)).exp(),
            Form::Power { n } => (x / x_ref).ln() * (x / x_ref).powf(n),
            Form::Linear { gamma } => {
                if 1.0 + gamma * (x - x_ref) > 0.0 {
                    x - x_ref
                } else {
                    0.0
                }
            }
            Form::Step { x0, .. } => {
                if x >= x0 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn forms_by_hand() {
        // exp: beta 0.8 at RH 0.75 (x_ref 0.5): e^0.2.
        let g = Form::Exp { beta: 0.8 }.g(0.75, 0.5);
        assert!((g - 0.2f64.exp()).abs() < 1e-15);
        // power: creepage 0.02 at n 0.3: 2^0.3 = 1.2311444133449163.
        let g = Form::Power { n: 0.3 }.g(0.02, 0.01);
        assert!((g - 1.231_144_413_344_916_3).abs() < 1e-15);
        // linear: speed 30 m/s at gamma -0.02: 1 - 0.2 = 0.8; clamped at 0.
        assert!((Form::Linear { gamma: -0.02 }.g(30.0, 20.0) - 0.8).abs() < 1e-15);
        assert_eq!(Form::Linear { gamma: -0.02 }.g(80.0, 20.0), 0.0);
        // step: 1 below x0, f at and above.
        let s = Form::Step { x0: 0.8, f: 1.5 };
        assert_eq!(
            (s.g(0.79, 0.5), s.g(0.8, 0.5), s.g(0.9, 0.5)),
            (1.0, 1.5, 1.5)
        );
    }

    #[test]
    fn the_parameter_derivative_is_the_central_difference() {
        let forms = [
            (Form::Exp { beta: 0.8 }, 0.75, 0.5),
            (Form::Power { n: -0.3 }, 0.02, 0.01),
            (Form::Linear { gamma: -0.02 }, 30.0, 20.0),
            (Form::Step { x0: 0.8, f: 0.4 }, 0.9, 0.5),
            (Form::Step { x0: 0.8, f: 0.4 }, 0.7, 0.5),
        ];
        let h = 1e-6;
        for (form, x, x_ref) in forms {
            let moved = |d: f64| match form {
                Form::Exp { beta } => Form::Exp { beta: beta + d },
                Form::Power { n } => Form::Power { n: n + d },
                Form::Linear { gamma } => Form::Linear { gamma: gamma + d },
                Form::Step { x0, f } => Form::Step { x0, f: f + d },
            };
            let fd = (moved(h).g(x, x_ref) - moved(-h).g(x, x_ref)) / (2.0 * h);
            let d = form.dg_dq(x, x_ref);
            assert!(
                (fd - d).abs() <= 1e-8 * d.abs().max(1.0),
                "{form:?}: {d} vs {fd}"
            );
        }
        // Clamped at 0: the branch's derivative.
        assert_eq!(Form::Linear { gamma: -0.02 }.dg_dq(80.0, 20.0), 0.0);
    }

    #[test]
    fn neutral_parameters_give_exactly_one() {
        for x in [-5.0, 0.0, 0.3, 17.0, 250.0] {
            assert_eq!(Form::Exp { beta: 0.0 }.g(x, 20.0), 1.0);
            assert_eq!(Form::Linear { gamma: 0.0 }.g(x, 20.0), 1.0);
            assert_eq!(Form::Step { x0: 1.0, f: 1.0 }.g(x, 20.0), 1.0);
            if x > 0.0 {
                assert_eq!(Form::Power { n: 0.0 }.g(x, 20.0), 1.0);
            }
        }
    }

    #[test]
    fn names_round_trip() {
        for a in ActsOn::ALL {
            assert_eq!(ActsOn::from_name(a.name()), Some(a));
        }
        for d in Driver::ALL {
            assert_eq!(Driver::from_name(d.name()), Some(d));
        }
        for f in FormKind::ALL {
            assert_eq!(FormKind::from_name(f.name()), Some(f));
        }
        assert!(!Driver::Time.allows(FormKind::Exp));
        assert!(Driver::Time.allows(FormKind::Step));
        assert!(!Driver::PrecipitationMmH.allows(FormKind::Power));
        assert!(Driver::WheelLoadKn.allows(FormKind::Power));
    }
}
