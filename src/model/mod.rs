//! The pure physics: no I/O, no allocation in the hot paths.
//!
//! - [`product`]: product consumption, friction and transfer (Trummer et al.,
//!   Lubricants 2021, 9, 100, eq. 1–6; ../shared/spec/model.md).
//! - [`effects`]: the candidate extensions of ../shared/spec/effects.md.
//! - [`contact`]: Hertz contact, Kalker coefficients and Polach's creep force
//!   model (../shared/spec/contact.md).

pub mod contact;
pub mod effects;
pub mod generic;
pub mod product;
