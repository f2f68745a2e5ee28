//! The model of docs/spec (model.md, contact.md, effects.md): the pure physics (no I/O, no allocation in
//! the hot paths) and its configuration.
//!
//! - [`product`]: product consumption, friction and transfer (Trummer et al.,
//!   Lubricants 2021, 9, 100, eq. 1–6; docs/spec/model.md).
//! - [`effects`]: the candidate extensions of docs/spec/effects.md.
//! - [`contact`]: Hertz contact, Kalker coefficients and Polach's creep force
//!   model (docs/spec/contact.md).
//! - [`generic`]: generic terms g(x) on one model quantity.
//! - [`config`]: the model configuration (the paper's Table 2, the contact
//!   parameters, the effects switched on), overlaid from TOML.
//! - [`error`]: configuration and usage errors.
//! - [`role`]: which parameters move the product masses and which only
//!   read them (what a fit can evaluate without a replay).
//! - [`tangent`]: the masses' derivatives with respect to the constants
//!   that move them, stepped beside the masses (one replay for all).

pub mod config;
pub mod contact;
pub mod effects;
pub mod error;
pub mod exp;
pub mod generic;
pub mod product;
mod quantity;
pub mod role;
pub mod tangent;

pub use quantity::Quantity;
