//! Read-outs: a measurement's simulated value from what one replay kept.
//!
//! The parameters of [`tortwin_model::role::Role::ReadOut`] (eq. (4)'s
//! `muD`, `muC`, `km`, the `friction_dry` and `friction_boundary` terms and
//! the `measurement` offsets) do not change the product masses. A sink that
//! asks for them ([`crate::sink::Sink::wants_readouts`]) gets, with each
//! measurement, the mass it read, its time and weather, the wheel's drivers
//! and (for adhesion) the wheel's Polach contact: a [`Readout`]. A
//! [`ReadoutModel`] of another configuration with the same state part
//! ([`ModelConfig::state_part`]) gives that measurement's value with the
//! engine's own functions in the engine's order, so it is the value a
//! replay of that configuration gives, bit for bit.

use std::sync::Arc;

use tortwin_model::config::ModelConfig;
use tortwin_model::contact::PolachContact;
use tortwin_model::product::{self, ProductParams};
use tortwin_model::tangent::Tangent;
use tortwin_model::Quantity;
use tortwin_recording::{Section, Weather};

use crate::terms::{GenericSet, WheelDrivers};

/// What a measurement's value was read from.
#[derive(Debug, Clone, Copy)]
pub struct Readout {
    /// The product mass read: `m` at step 2 of the measured contact, or the
    /// rail mass with the time effects up to the reading for `rail_mu`.
    pub mass_kg: f64,
    /// The contact's or reading's time_s.
    pub time_s: f64,
    /// The weather in effect then.
    pub weather: Weather,
    /// The wheel's drivers at a contact (`None` for `rail_mu`).
    pub(crate) wheel: Option<WheelDrivers>,
    /// The wheel's contact, for an adhesion measurement.
    pub(crate) contact: Option<PolachContact>,
    /// With [`crate::EngineOptions::tangents`]: the tangent of `mass_kg`,
    /// its derivatives with respect to `ln p` of the state constants
    /// ([`tortwin_model::tangent::STATE_KEYS`]).
    pub mass_tangent: Option<Tangent>,
}

/// The read-out parameters of one configuration, compiled for a section.
pub struct ReadoutModel {
    product: ProductParams,
    generic: Arc<GenericSet>,
}

impl ReadoutModel {
    /// `cfg`'s read-out parameters. Its generic terms must have been
    /// checked against `section` (as for [`crate::Engine::new`]).
    pub fn new(section: &Section, cfg: &ModelConfig, origin_ns: i64) -> Self {
        Self {
            product: cfg.product,
            generic: Arc::new(GenericSet::compile(
                &cfg.effects.generic,
                section,
                origin_ns,
            )),
        }
    }

    /// The simulated value of a measurement of `quantity` at `site` on
    /// `rail` read from `r`, as the engine computes it
    /// (`Engine::value_from`, `read_rail` and the offsets of
    /// `emit_measurement`).
    pub fn value(&self, r: &Readout, site: usize, rail: usize, quantity: Quantity) -> f64 {
        let mu = if self.generic.any_friction() {
            let levels = self.generic.friction_levels(
                self.product.mu_d,
                self.product.mu_c,
                rail,
                r.time_s,
                &r.weather,
                r.wheel.as_ref(),
            );
            crate::friction_at(&self.product, levels, r.mass_kg)
        } else {
            product::friction(&self.product, r.mass_kg)
        };
        let value = match (quantity, &r.contact) {
            (Quantity::Adhesion, Some(contact)) => contact.forces(mu).t_over_q,
            _ => mu,
        };
        self.generic.measured(value, site, rail, quantity)
    }

    /// The derivative of [`ReadoutModel::value`] with respect to the mass
    /// read, by central differences over a ten-thousandth of eq. (4)'s mass
    /// scale (`km / 10⁴`): eq. (4), Polach's law in `mu` and the offsets
    /// are smooth in the mass, so the difference is exact to about 1e-9
    /// relative.
    pub fn slope(&self, r: &Readout, site: usize, rail: usize, quantity: Quantity) -> f64 {
        let h = 1e-4 * self.product.km_kg;
        let at = |mass_kg: f64| self.value(&Readout { mass_kg, ..*r }, site, rail, quantity);
        (at(r.mass_kg + h) - at(r.mass_kg - h)) / (2.0 * h)
    }
}
