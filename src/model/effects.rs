//! The candidate effects of ../shared/spec/effects.md: what the 2021 model
//! leaves out. Each is a pure function of the step it acts at; the engine
//! consults the ones the configuration switches on ([`crate::config::Effects`]).
//!
//! | effect | step of "one contact" | function |
//! |---|---|---|
//! | `rail_ageing` | 1, pulse, reading | [`ageing_factor`] |
//! | `rain_washoff` | 1, pulse, reading | [`washoff_factor`] |
//! | `temperature_consumption` | 4 | [`temperature_factor`] |
//! | `speed_transfer` | 3 | [`speed_transfer_factor`] |
//! | `wheel_edge_reservoir` | 6 | [`wheel_edge_reservoir`] |
//! | `bogie_bands` | — | a layout: the engine keeps two tracks for the rail named `high` |

/// `rail_ageing`: rail product dries out and is lost between touches,
/// `m_r *= exp(-dt / tau)` with `dt` the time since the point was last touched.
#[inline]
pub fn ageing_factor(dt_s: f64, tau_s: f64) -> f64 {
    (-dt_s / tau_s).exp()
}

/// `rain_washoff`: `m_r *= exp(-k R)` with `R` the precipitation (mm) since
/// the point was last touched.
#[inline]
pub fn washoff_factor(rain_mm: f64, k_per_mm: f64) -> f64 {
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
    fn reservoir_by_hand() {
        // m_w = 10, m_e = 4, alpha = 0.2, r = 0.25: park 2 (m_w 8, m_e 6),
        // then 1.5 comes back (m_w 9.5, m_e 4.5).
        assert_eq!(wheel_edge_reservoir(10.0, 4.0, 0.2, 0.25), (9.5, 4.5));
        assert_eq!(wheel_edge_reservoir(10.0, 4.0, 0.0, 0.0), (10.0, 4.0));
        // Everything parked, nothing back.
        assert_eq!(wheel_edge_reservoir(10.0, 0.0, 1.0, 0.0), (0.0, 10.0));
    }
}
