//! tortwin: a digital twin of a railway track section for top-of-rail (TOR)
//! friction management.
//!
//! Data flows one way (see ARCHITECTURE.md):
//!
//! ```text
//! recording (MCAP in) -> typed events -> engine (section state + model) -> sinks
//! ```
//!
//! - [`model`]: the pure physics: product transport (Trummer et al. 2021,
//!   eq. 1–6) and contact mechanics (Hertz, Kalker, Polach).
//! - [`config`]: the model configuration (the paper's Table 2 and the
//!   contact parameters), overlaid from TOML.
//! - [`recording`]: turns an MCAP recording into typed, validated events.
//! - [`engine`]: owns time and state; steps the product wheel pass by wheel pass.
//! - [`sink`]: listeners that publish what the engine produces.
//! - [`output`]: files written under a temporary name, renamed when complete.
//! - [`discover`]: the discrepancy workflow: residuals, covariates, candidate
//!   effects fitted by re-running the engine, forward selection.
//! - [`plot`]: line plots (SVG) and CSV tables for figures and reports.
//! - [`synth`]: synthetic recordings whose measurements come from the engine
//!   run with a truth model (hidden effects), plus noise.

pub mod app;
pub mod config;
pub mod discover;
pub mod engine;
pub mod error;
pub mod model;
pub mod output;
pub mod paper;
pub mod plot;
pub mod recording;
pub mod sink;
pub mod strategy;
pub mod synth;
