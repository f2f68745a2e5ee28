//! The candidate effects of docs/spec/effects.md: what the 2021 model
//! leaves out. Each is a pure function of the step it acts at; the engine
//! consults the ones the configuration switches on ([`crate::config::Effects`]).
//!
//! | effect | step of "one contact" | function |
//! |---|---|---|
//! | `rail_ageing` | 1, pulse, reading | `ageing_factor` (in [`TimeEffects`]) |
//! | `rain_washoff` | 1, pulse, reading | `washoff_factor` (in [`TimeEffects`]) |
//! | `temperature_consumption` | 4 | [`temperature_factor`] |
//! | `speed_transfer` | 3 | [`speed_transfer_factor`] |
//! | `wheel_edge_reservoir` | 6 | [`wheel_edge_reservoir`] |
//! | `bogie_bands` | — | a layout: the engine keeps two tracks for the rail named `high` |
//!
//! `EFFECTS` (a row by [`Named::spec`]) describes each effect once as data
//! (name, parameters with units, valid ranges, the range and transform a
//! fitter searches, the step it acts at): configuration validation,
//! discover and the reports read it.

/// `rail_ageing`: rail product dries out and is lost between touches,
/// `m_r *= exp(-dt / tau)` with `dt` the time since the point was last touched.
#[inline]
pub(crate) fn ageing_factor(dt_s: f64, tau_s: f64) -> f64 {
    (-dt_s / tau_s).exp()
}

/// `rain_washoff`: `m_r *= exp(-k R)` with `R` the precipitation (mm) since
/// the point was last touched.
#[inline]
pub(crate) fn washoff_factor(rain_mm: f64, k_per_mm: f64) -> f64 {
    (-k_per_mm * rain_mm).exp()
}

/// `temperature_consumption`: the whole consumption `c` of eq. (1), k0
/// included, is multiplied by `exp(beta (T - 20 °C))` before `c <= m`.
#[inline]
pub fn temperature_factor(air_temperature_c: f64, beta_per_k: f64) -> f64 {
    (beta_per_k * (air_temperature_c - 20.0)).exp()
}

/// `speed_transfer`: the transfer fraction of eq. (6) is multiplied by
/// `(v / 20 m/s)^(-n)` before its clamp at 0.5.
#[inline]
pub fn speed_transfer_factor(speed_mps: f64, n: f64) -> f64 {
    (speed_mps / 20.0).powf(-n)
}

/// `wheel_edge_reservoir`, step 6: first `alpha m_w` moves from the wheel's
/// contact band to its edge reservoir `m_e`, then `r m_e` (the updated
/// `m_e`) moves back. Returns the new `(m_w, m_e)`; their sum is unchanged.
#[inline]
pub fn wheel_edge_reservoir(wheel_kg: f64, edge_kg: f64, alpha: f64, r: f64) -> (f64, f64) {
    let parked = alpha * wheel_kg;
    let (wheel_kg, edge_kg) = (wheel_kg - parked, edge_kg + parked);
    let back = r * edge_kg;
    (wheel_kg + back, edge_kg - back)
}

/// The time effects that are switched on (step 1, a pulse landing, a
/// tribometer reading).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct TimeEffects {
    pub ageing_tau_s: Option<f64>,
    pub rain_k_per_mm: Option<f64>,
}

impl TimeEffects {
    #[inline]
    pub fn any(&self) -> bool {
        self.ageing_tau_s.is_some() || self.rain_k_per_mm.is_some()
    }

    /// The rail mass after the time effects since the last touch, `dt_s`
    /// ago with `rain_mm` of rain since: ageing first, then rain, as two
    /// multiplications (effects.md).
    #[inline]
    pub fn apply(&self, mass_kg: f64, dt_s: f64, rain_mm: f64) -> f64 {
        let mut m = mass_kg;
        if let Some(tau) = self.ageing_tau_s {
            m *= ageing_factor(dt_s, tau);
        }
        if let Some(k) = self.rain_k_per_mm {
            // exp(0) = 1: most touches see no rain since the last one.
            if rain_mm != 0.0 {
                m *= washoff_factor(rain_mm, k);
            }
        }
        m
    }

    /// The arguments of [`TimeEffects::apply`]'s exponentials: ageing's
    /// `-dt / tau` and washoff's `-k R` (0 where the effect is off or there
    /// was no rain), for a caller that takes many exponentials at once.
    #[inline(always)]
    pub fn exp_args(&self, dt_s: f64, rain_mm: f64) -> [f64; 2] {
        [
            self.ageing_tau_s.map_or(0.0, |tau| -dt_s / tau),
            self.rain_k_per_mm
                .filter(|_| rain_mm != 0.0)
                .map_or(0.0, |k| -k * rain_mm),
        ]
    }

    /// [`TimeEffects::apply`] with its exponentials given: `exps` is `exp`
    /// of [`TimeEffects::exp_args`]. The same multiplications, the same
    /// bits.
    #[inline(always)]
    pub fn apply_given(&self, mass_kg: f64, rain_mm: f64, exps: [f64; 2]) -> f64 {
        let mut m = mass_kg;
        if self.ageing_tau_s.is_some() {
            m *= exps[0];
        }
        if self.rain_k_per_mm.is_some() && rain_mm != 0.0 {
            m *= exps[1];
        }
        m
    }
}

// ------------------------------------------------------------- the table

#[cfg(test)]
use crate::config::Effects;

/// The named effects of effects.md, in its order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Named {
    RailAgeing,
    RainWashoff,
    TemperatureConsumption,
    SpeedTransfer,
    WheelEdgeReservoir,
    BogieBands,
}

/// How a fitter maps its search coordinate `u` in [0, 1] onto a parameter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Transform {
    /// Evenly in the logarithm from `lo` to `hi` (both > 0).
    Log,
    /// `lo + (hi − lo) (base^u − 1)/(base − 1)`: fine steps near `lo` (0),
    /// where a small value already matters.
    LogLike { base: f64 },
    /// Evenly from `lo` to `hi`.
    Linear,
}

/// One parameter of a named effect.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Param {
    /// Its key in `[effects.NAME]`.
    pub name: &'static str,
    pub unit: &'static str,
    /// The values a configuration may give: `[valid.0, valid.1]`, or
    /// `(valid.0, ∞)` finite when `valid_open_low` (e.g. a time constant).
    pub valid: (f64, f64),
    pub valid_open_low: bool,
    /// The range a fitter searches, and how.
    pub search: (f64, f64),
    pub transform: Transform,
}

impl Param {
    /// True when a configuration may give `x`.
    pub(crate) fn is_valid(&self, x: f64) -> bool {
        let (lo, hi) = self.valid;
        if hi.is_infinite() {
            x.is_finite() && if self.valid_open_low { x > lo } else { x >= lo }
        } else {
            lo <= x && x <= hi
        }
    }

    /// The rule [`Param::is_valid`] checks, in words.
    pub(crate) fn rule(&self) -> String {
        let (lo, hi) = self.valid;
        match (hi.is_infinite(), self.valid_open_low) {
            (true, true) => format!("finite and > {lo}"),
            (true, false) => format!("finite and >= {lo}"),
            (false, _) => format!("in [{lo}, {hi}]"),
        }
    }

    /// The parameter at the search coordinate `u` (clamped into [0, 1]).
    pub fn at(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        let (lo, hi) = self.search;
        match self.transform {
            Transform::Log => (lo.ln() + u * (hi.ln() - lo.ln())).exp(),
            Transform::LogLike { base } => lo + (hi - lo) * ((base.powf(u) - 1.0) / (base - 1.0)),
            Transform::Linear => lo + (hi - lo) * u,
        }
    }

    /// The inverse of [`Param::at`], clamped into [0, 1] (0 when undefined).
    /// `d at(u) / du`, the search transform's slope (inside the box; at
    /// its ends the slope of the side within it).
    pub fn dp_du(&self, u: f64) -> f64 {
        let u = u.clamp(0.0, 1.0);
        let (lo, hi) = self.search;
        match self.transform {
            Transform::Log => self.at(u) * (hi.ln() - lo.ln()),
            Transform::LogLike { base } => (hi - lo) * base.ln() * base.powf(u) / (base - 1.0),
            Transform::Linear => hi - lo,
        }
    }

    pub fn unit_of(&self, p: f64) -> f64 {
        let (lo, hi) = self.search;
        let u = match self.transform {
            Transform::Log => (p.max(lo).ln() - lo.ln()) / (hi.ln() - lo.ln()),
            Transform::LogLike { base } => {
                let y = (p - lo).max(0.0) / (hi - lo);
                (1.0 + y * (base - 1.0)).ln() / base.ln()
            }
            Transform::Linear => (p - lo) / (hi - lo),
        };
        if u.is_finite() {
            u.clamp(0.0, 1.0)
        } else {
            0.0
        }
    }
}

/// A named effect as data: what the configuration (parsing, validation,
/// writing), synth, discover and the reports read. The physics is the
/// function of the row's step, above; [`crate::config::Effects`] holds the
/// parameters of the effects that are on, in the order of `params`.
#[derive(Debug, Clone, Copy)]
pub struct EffectSpec {
    pub effect: Named,
    /// `[effects.NAME]`.
    pub name: &'static str,
    /// Where it acts (effects.md).
    pub step: &'static str,
    pub params: &'static [Param],
}

/// `tau_s` of `rail_ageing`: the search range 60 s to 1e6 s.
const TAU_SEARCH_S: (f64, f64) = (60.0, 1e6);

/// Every named effect, in the order of effects.md.
pub(crate) static EFFECTS: [EffectSpec; 6] = [
    EffectSpec {
        effect: Named::RailAgeing,
        name: "rail_ageing",
        step: "1, pulse, reading: m_r *= exp(-dt / tau_s)",
        params: &[Param {
            name: "tau_s",
            unit: "s",
            valid: (0.0, f64::INFINITY),
            valid_open_low: true,
            search: TAU_SEARCH_S,
            transform: Transform::Log,
        }],
    },
    EffectSpec {
        effect: Named::RainWashoff,
        name: "rain_washoff",
        step: "1, pulse, reading: m_r *= exp(-k R)",
        params: &[Param {
            name: "k_per_mm",
            unit: "1/mm",
            valid: (0.0, f64::INFINITY),
            valid_open_low: false,
            search: (0.0, 20.0),
            transform: Transform::LogLike { base: 21.0 },
        }],
    },
    EffectSpec {
        effect: Named::TemperatureConsumption,
        name: "temperature_consumption",
        step: "4: c *= exp(beta (T - 20 °C))",
        params: &[Param {
            name: "beta_per_k",
            unit: "1/K",
            valid: (-1.0, 1.0),
            valid_open_low: false,
            search: (-0.3, 0.3),
            transform: Transform::Linear,
        }],
    },
    EffectSpec {
        effect: Named::SpeedTransfer,
        name: "speed_transfer",
        step: "3: transfer *= (v / 20 m/s)^(-n)",
        params: &[Param {
            name: "n",
            unit: "1",
            valid: (-10.0, 10.0),
            valid_open_low: false,
            search: (-10.0, 10.0),
            transform: Transform::Linear,
        }],
    },
    EffectSpec {
        effect: Named::WheelEdgeReservoir,
        name: "wheel_edge_reservoir",
        step: "6: alpha m_w parked at the band's edge, r m_e back",
        params: &[
            Param {
                name: "alpha",
                unit: "1",
                valid: (0.0, 1.0),
                valid_open_low: false,
                search: (0.0, 1.0),
                transform: Transform::LogLike { base: 1000.0 },
            },
            Param {
                name: "r",
                unit: "1",
                valid: (0.0, 1.0),
                valid_open_low: false,
                search: (0.0, 1.0),
                transform: Transform::LogLike { base: 1000.0 },
            },
        ],
    },
    EffectSpec {
        effect: Named::BogieBands,
        name: "bogie_bands",
        step: "layout: two tracks on the rail named `high`",
        params: &[],
    },
];

impl Named {
    /// Every named effect, in the order of effects.md (and of `EFFECTS`).
    pub const ALL: [Named; 6] = [
        Named::RailAgeing,
        Named::RainWashoff,
        Named::TemperatureConsumption,
        Named::SpeedTransfer,
        Named::WheelEdgeReservoir,
        Named::BogieBands,
    ];

    /// The effect called `name` in `[effects.NAME]`.
    pub fn from_name(name: &str) -> Option<Named> {
        Named::ALL.into_iter().find(|e| e.name() == name)
    }

    /// Its row of `EFFECTS`, the table of the effects.
    pub fn spec(self) -> &'static EffectSpec {
        &EFFECTS[self as usize]
    }

    pub fn name(self) -> &'static str {
        self.spec().name
    }

    /// Whether the effect with `params` changes nothing: its factor is 1.0
    /// at every step (wash-off `k_per_mm`, `beta_per_k`, the speed's `n`
    /// 0) or nothing is ever parked (the reservoir's `alpha` 0). Ageing
    /// (neutral only at an infinite `tau_s`) and the bands never are.
    pub fn is_neutral(self, params: &[f64]) -> bool {
        match self {
            Named::RainWashoff
            | Named::TemperatureConsumption
            | Named::SpeedTransfer
            | Named::WheelEdgeReservoir => params.first() == Some(&0.0),
            Named::RailAgeing | Named::BogieBands => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ageing_by_hand() {
        // Two hours at tau = 2 h: a factor 1/e.
        assert_eq!(ageing_factor(7200.0, 7200.0), (-1.0f64).exp());
        assert_eq!(ageing_factor(0.0, 7200.0), 1.0);
        let effects = TimeEffects {
            ageing_tau_s: Some(3600.0),
            rain_k_per_mm: None,
        };
        let m = effects.apply(1e-4, 1800.0, 5.0);
        assert!((m - 1e-4 * (-0.5f64).exp()).abs() < 1e-20);
    }

    #[test]
    fn washoff_by_hand() {
        assert_eq!(washoff_factor(2.0, 0.5), (-1.0f64).exp());
        assert_eq!(washoff_factor(0.0, 3.0), 1.0);
        assert_eq!(washoff_factor(4.0, 0.0), 1.0);
    }

    #[test]
    fn ageing_then_rain_as_two_multiplications() {
        let effects = TimeEffects {
            ageing_tau_s: Some(1000.0),
            rain_k_per_mm: Some(0.2),
        };
        let m = effects.apply(2e-4, 500.0, 1.5);
        assert_eq!(m, 2e-4 * (-0.5f64).exp() * (-0.3f64).exp());
        assert!(!TimeEffects::default().any());
        assert_eq!(TimeEffects::default().apply(2e-4, 1e6, 100.0), 2e-4);
    }

    #[test]
    fn temperature_by_hand() {
        assert_eq!(temperature_factor(20.0, 0.05), 1.0);
        assert!((temperature_factor(30.0, 0.05) - 0.5f64.exp()).abs() < 1e-15);
        assert!((temperature_factor(0.0, 0.05) - (-1.0f64).exp()).abs() < 1e-15);
    }

    #[test]
    fn speed_transfer_by_hand() {
        assert_eq!(speed_transfer_factor(20.0, 3.0), 1.0);
        assert!((speed_transfer_factor(40.0, 1.0) - 0.5).abs() < 1e-15);
        assert!((speed_transfer_factor(10.0, 2.0) - 4.0).abs() < 1e-15);
    }

    #[test]
    fn the_table_is_in_order_and_its_maps_invert() {
        for (k, spec) in EFFECTS.iter().enumerate() {
            assert_eq!(spec.effect as usize, k, "{}", spec.name);
            assert_eq!(spec.effect.name(), spec.name);
            for param in spec.params {
                for u in [0.0, 0.25, 0.5, 1.0] {
                    let x = param.at(u);
                    assert!(param.is_valid(x), "{}.{} = {x}", spec.name, param.name);
                    assert!((param.unit_of(x) - u).abs() < 1e-9, "{}", param.name);
                }
            }
            assert_eq!(Named::ALL[k], spec.effect);
            assert_eq!(Named::from_name(spec.name), Some(spec.effect));
            let mut effects = Effects::default();
            assert_eq!(effects.get(spec.effect), None);
            let values: Vec<f64> = spec.params.iter().map(|p| p.at(0.5)).collect();
            effects.set(spec.effect, &values);
            assert_eq!(effects.get(spec.effect), Some(values.as_slice()));
            assert_eq!(effects.names(), vec![spec.name]);
            effects.unset(spec.effect);
            assert_eq!(effects, Effects::default());
        }
    }

    #[test]
    fn reservoir_by_hand() {
        // m_w = 10, m_e = 4, alpha = 0.2, r = 0.25: park 2 (m_w 8, m_e 6),
        // then 1.5 comes back (m_w 9.5, m_e 4.5).
        assert_eq!(wheel_edge_reservoir(10.0, 4.0, 0.2, 0.25), (9.5, 4.5));
        assert_eq!(wheel_edge_reservoir(10.0, 4.0, 0.0, 0.0), (10.0, 4.0));
        // Everything parked, nothing back.
        assert_eq!(wheel_edge_reservoir(10.0, 0.0, 1.0, 0.0), (0.0, 10.0));
    }
}
