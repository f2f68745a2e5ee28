//! Which parameters move the product mass state and which only read it.
//!
//! A fit asks the model the same question many times with other
//! parameters. Most parameters change how product lands, moves and is
//! consumed (the mass state): a new value needs a new replay. Some only
//! change what is read from the state: eq. (4)'s `muD`, `muC` and `km`, the
//! `friction_dry` and `friction_boundary` terms (factors on `muD` and `muC`
//! at step 2 and at a reading) and the `measurement` offsets. With the
//! masses, times, weather and contacts of one replay kept, their values are
//! read again in O(measurements) without one.
//!
//! Every parameter says which it is here, in one place: a new constant, a
//! new named effect or a new kind of generic term must declare its role,
//! and the compiler asks for it. [`ModelConfig::state_part`] is the part of
//! a configuration a replay's masses depend on: two configurations with the
//! same state part have the same masses at every measurement.

use std::sync::OnceLock;

use crate::config::ModelConfig;
use crate::effects::Named;
use crate::generic::ActsOn;
use crate::product::{ProductKey, ProductParams};

/// What a parameter does to a replay.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// It changes the product masses (landing, transfer, consumption, the
    /// cap, time effects, the bands): another value needs another replay.
    State,
    /// It only changes what a measurement reads from the masses.
    ReadOut,
}

impl ProductKey {
    /// `muD`, `muC` and `km` enter eq. (4) alone; every other constant
    /// moves product.
    pub fn role(self) -> Role {
        match self {
            ProductKey::MuD | ProductKey::MuC | ProductKey::KmKg => Role::ReadOut,
            ProductKey::Kc
            | ProductKey::Kt
            | ProductKey::Cn
            | ProductKey::K0Kg
            | ProductKey::Km1Kg
            | ProductKey::M0Kg
            | ProductKey::Km2
            | ProductKey::Kp
            | ProductKey::CmKg
            | ProductKey::MMaxKg => Role::State,
        }
    }
}

impl ActsOn {
    /// The friction levels and the offsets are read; the rest moves
    /// product.
    pub fn role(self) -> Role {
        match self {
            ActsOn::FrictionDry | ActsOn::FrictionBoundary | ActsOn::Measurement => Role::ReadOut,
            ActsOn::PulseMass | ActsOn::Transfer | ActsOn::Consumption => Role::State,
        }
    }
}

impl Named {
    /// Every named effect acts on the masses (effects.md): ageing and rain
    /// at a touch, temperature on consumption, speed on transfer, the
    /// reservoir on the wheel, the bands on which surface a wheel meets.
    pub fn role(self) -> Role {
        match self {
            Named::RailAgeing
            | Named::RainWashoff
            | Named::TemperatureConsumption
            | Named::SpeedTransfer
            | Named::WheelEdgeReservoir
            | Named::BogieBands => Role::State,
        }
    }
}

/// The built-in product constants, read once.
fn default_product() -> &'static ProductParams {
    static DEFAULT: OnceLock<ProductParams> = OnceLock::new();
    DEFAULT.get_or_init(|| ModelConfig::default().product)
}

impl ModelConfig {
    /// The part of this configuration the product masses depend on: the
    /// read-out constants set to the built-in defaults, the read-out
    /// generic terms left out, and so the effects and state terms that
    /// change nothing ([`Named::is_neutral`],
    /// [`crate::generic::Form::is_neutral`]: a candidate at its neutral
    /// value shares its replay with the model without it).
    /// Replaying it gives the masses (and so the read-out inputs) of every
    /// configuration with the same state part.
    pub fn state_part(&self) -> ModelConfig {
        let mut cfg = self.clone();
        for key in ProductKey::ALL {
            if key.role() == Role::ReadOut {
                key.set(&mut cfg.product, key.get(default_product()));
            }
        }
        for effect in Named::ALL {
            if cfg
                .effects
                .get(effect)
                .is_some_and(|p| effect.is_neutral(p))
            {
                cfg.effects.unset(effect);
            }
        }
        cfg.effects
            .generic
            .retain(|t| t.acts_on.role() == Role::State && !t.is_neutral());
        cfg
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::terms::GenericTerm;

    #[test]
    fn the_state_part_forgets_exactly_the_read_outs() {
        let text = r#"
            [product]
            mu_d = 0.5
            mu_c = 0.2
            km_kg = 1e-4
            kc = 0.6
            [[effects.generic]]
            acts_on = "friction_dry"
            driver = "relative_humidity"
            form = "linear"
            gamma = -0.5
            [[effects.generic]]
            acts_on = "consumption"
            driver = "air_temperature_c"
            form = "exp"
            beta = 0.01
            [[effects.generic]]
            acts_on = "measurement"
            offset = 0.01
        "#;
        let cfg = ModelConfig::from_overlay_str(text, "test").unwrap();
        let state = cfg.state_part();
        let default = ModelConfig::default();
        assert_eq!(state.product.mu_d, default.product.mu_d);
        assert_eq!(state.product.mu_c, default.product.mu_c);
        assert_eq!(state.product.km_kg, default.product.km_kg);
        assert_eq!(state.product.kc, 0.6);
        let kinds: Vec<ActsOn> = state
            .effects
            .generic
            .iter()
            .map(|t: &GenericTerm| t.acts_on)
            .collect();
        assert_eq!(kinds, vec![ActsOn::Consumption]);
        // Read-out changes leave the state part as it is; a state change does not.
        let mut other = cfg.clone();
        other.product.mu_d = 0.45;
        other.effects.generic.remove(0);
        assert_eq!(other.state_part(), state);
        other.product.kt = 0.4;
        assert_ne!(other.state_part(), state);
        assert!(state.validate("state part").is_ok());
    }

    #[test]
    fn a_state_term_that_changes_nothing_is_not_part_of_the_state() {
        let with = |beta: f64, f: f64| {
            let text = format!(
                r#"
                [[effects.generic]]
                acts_on = "consumption"
                driver = "air_temperature_c"
                form = "exp"
                beta = {beta:?}
                [[effects.generic]]
                acts_on = "transfer"
                driver = "wheel_load_kN"
                form = "step"
                x0 = 100.0
                f = {f:?}
                "#
            );
            ModelConfig::from_overlay_str(&text, "test").unwrap()
        };
        let without = ModelConfig::default().state_part();
        assert_eq!(with(0.0, 1.0).state_part(), without);
        assert_eq!(with(-0.0, 1.0).state_part(), without);
        assert_eq!(with(0.0, 1.0 + 1e-15).state_part().effects.generic.len(), 1);
        assert_eq!(with(1e-300, 1.0).state_part().effects.generic.len(), 1);
    }
}
