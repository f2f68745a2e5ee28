//! The key written beside a synthetic recording: what was hidden, how
//! visible it is (RMSE of the default model against the truth), what the
//! file holds, and every parameter.

use std::collections::BTreeMap;

use serde::Serialize;

use super::params::{LocalFriction, SynthParams};
use tortwin_recording::Quantity;

/// What a synthetic recording holds and how visible its hidden effects are:
/// the key written beside the recording.
#[derive(Debug, Clone, Serialize)]
pub struct SynthReport {
    pub generator: &'static str,
    pub version: &'static str,
    /// The recording's file name.
    pub recording: String,
    pub size_bytes: u64,
    pub seed: u64,
    pub days: u32,
    pub start_utc: String,
    pub start_ns: u64,
    pub end_ns: u64,
    /// The hidden effects and their parameters (effects.md names).
    pub effects: serde_json::Value,
    /// The whole truth configuration (defaults included), as TOML.
    pub truth_config_toml: String,
    pub noise: NoiseKey,
    pub truth: &'static str,
    pub baseline: &'static str,
    /// RMSE of the default model against the truth over every measurement
    /// (no noise); `null` without measurements.
    pub rmse_baseline_vs_truth: Option<f64>,
    pub rmse_baseline_vs_truth_by_quantity: ByQuantity<RmseKey>,
    pub rmse_baseline_vs_truth_over_sigma: Option<f64>,
    pub rmse_measured_vs_truth: Option<f64>,
    pub rmse_measured_vs_baseline: Option<f64>,
    pub counts: Counts,
    /// 0-based position among all messages of the file of every measurement
    /// given a gross error (`--outlier-share`).
    pub outliers_index_in_file: Vec<u64>,
    /// Local friction changes outside the model (`--local-friction`).
    pub local_friction: Vec<LocalFriction>,
    pub rain_events_h_from_start: Vec<RainKey>,
    pub grid_points: usize,
    pub applicator_grid_index: usize,
    pub site_grid_indices: BTreeMap<String, usize>,
    pub params: SynthParams,
}

#[derive(Debug, Clone, Serialize)]
pub struct NoiseKey {
    pub distribution: &'static str,
    pub sigma: f64,
    pub applied_to: &'static str,
}

#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct RmseKey {
    pub n: u64,
    pub rmse: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct RainKey {
    pub start_h: f64,
    pub end_h: f64,
    pub mm_h: f64,
}

/// Message and object counts of a synthetic recording.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Counts {
    pub messages: u64,
    pub measurements: u64,
    pub by_quantity: ByQuantity<u64>,
    pub trains: u64,
    pub freight: u64,
    pub passenger: u64,
    pub down: u64,
    pub measured_trains: u64,
    /// Trains drawn for a day that did not fit in its service hours.
    pub dropped_trains: u64,
    pub axles: u64,
    pub pulses: u64,
    pub weather: u64,
    pub wheels: u64,
    pub contacts: u64,
}

/// One value per measured quantity, in the format's order.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct ByQuantity<T> {
    pub mu: T,
    pub adhesion: T,
    pub rail_mu: T,
}

impl<T> ByQuantity<T> {
    pub(crate) fn get(&self, q: Quantity) -> &T {
        match q {
            Quantity::Mu => &self.mu,
            Quantity::Adhesion => &self.adhesion,
            Quantity::RailMu => &self.rail_mu,
        }
    }

    pub(crate) fn get_mut(&mut self, q: Quantity) -> &mut T {
        match q {
            Quantity::Mu => &mut self.mu,
            Quantity::Adhesion => &mut self.adhesion,
            Quantity::RailMu => &mut self.rail_mu,
        }
    }

    /// The quantities in the format's order, with their values.
    pub fn iter(&self) -> impl Iterator<Item = (Quantity, &T)> {
        QUANTITIES.into_iter().map(move |q| (q, self.get(q)))
    }
}

pub(super) const QUANTITIES: [Quantity; 3] = [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu];

pub(super) fn quantity_slot(q: Quantity) -> usize {
    match q {
        Quantity::Mu => 0,
        Quantity::Adhesion => 1,
        Quantity::RailMu => 2,
    }
}
