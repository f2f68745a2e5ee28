//! Trains: consists of real vehicle types, their wheel loads and the
//! creepages of each wheel. The planner ([`super::planner`]) decides when a
//! train runs; this file decides what it is.

use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{round_dp, uniform};
use tortwin_recording::{BogiePosition, Creepage, Passage};

/// The curve radius the creepage ranges below are calibrated for, m.
const REFERENCE_RADIUS_M: f64 = 400.0;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum TrainKind {
    Freight,
    Passenger,
}

impl TrainKind {
    pub(super) fn as_str(self) -> &'static str {
        match self {
            TrainKind::Freight => "freight",
            TrainKind::Passenger => "passenger",
        }
    }
}

/// One vehicle of a consist: two two-axle bogies.
#[derive(Debug, Clone, Copy)]
pub(super) struct Vehicle {
    /// Length over buffers (or couplers).
    pub(super) length_m: f64,
    pub(super) bogie_centres_m: f64,
    /// Axle spacing within a bogie.
    pub(super) wheelbase_m: f64,
    /// Mean static wheel load, kN.
    pub(super) wheel_load_kn: f64,
}

/// Bo'Bo' locomotive (e.g. a TRAXX-like 4-axle electric, ~21 t axle load).
const LOCOMOTIVE: (f64, f64, f64) = (19.0, 10.3, 2.5);
/// Four-axle freight wagons on Y25 bogies: (length, bogie centres, wheelbase).
const WAGONS: [(f64, f64, f64); 5] = [
    (19.74, 14.86, 1.8), // flat wagon for containers
    (15.74, 10.5, 1.8),  // open high-sided wagon
    (16.24, 11.0, 1.8),  // tank wagon
    (23.24, 17.5, 2.0),  // sliding-wall van
    (12.54, 7.8, 1.8),   // hopper
];
/// EMU car: 26.4 m, bogies at 19 m, 2.5 m wheelbase.
const EMU_CAR: (f64, f64, f64) = (26.4, 19.0, 2.5);

pub(super) fn freight_consist(rng: &mut ChaCha8Rng) -> Vec<Vehicle> {
    let locomotives = if rng.random_bool(0.3) { 2 } else { 1 };
    let wagons = rng.random_range(20..=40);
    // A block train of one wagon type, or a mixed one.
    let block = rng
        .random_bool(0.6)
        .then(|| rng.random_range(0..WAGONS.len()));
    let mut consist = Vec::with_capacity(locomotives + wagons);
    for _ in 0..locomotives {
        let (length_m, bogie_centres_m, wheelbase_m) = LOCOMOTIVE;
        consist.push(Vehicle {
            length_m,
            bogie_centres_m,
            wheelbase_m,
            wheel_load_kn: uniform(rng, 100.0, 110.0),
        });
    }
    for _ in 0..wagons {
        let kind = block.unwrap_or_else(|| rng.random_range(0..WAGONS.len()));
        let (length_m, bogie_centres_m, wheelbase_m) = WAGONS[kind];
        consist.push(Vehicle {
            length_m,
            bogie_centres_m,
            wheelbase_m,
            wheel_load_kn: uniform(rng, 90.0, 125.0),
        });
    }
    consist
}

pub(super) fn passenger_consist(rng: &mut ChaCha8Rng) -> Vec<Vehicle> {
    let units = if rng.random_bool(0.35) { 2 } else { 1 };
    let cars_per_unit = rng.random_range(4..=6);
    let (length_m, bogie_centres_m, wheelbase_m) = EMU_CAR;
    (0..units * cars_per_unit)
        .map(|_| Vehicle {
            length_m,
            bogie_centres_m,
            wheelbase_m,
            wheel_load_kn: uniform(rng, 65.0, 85.0),
        })
        .collect()
}

/// A planned train: the typed passage plus what goes on the wire.
#[derive(Debug, Clone)]
pub(super) struct TrainPlan {
    pub(super) kind: TrainKind,
    pub(super) passage: Passage,
    /// Wheel loads as written, kN: `[axle * rails + rail]`.
    pub(super) load_kn: Vec<f64>,
    /// On a line, per axle, the loads as written in each of its
    /// `segments` entries (in their order), kN per rail.
    pub(super) segment_load_kn: Vec<Vec<Vec<f64>>>,
    pub(super) log_time_ns: u64,
    pub(super) measured: bool,
    pub(super) adhesion: bool,
}

/// Creepages of one wheel on one rail (model input, not a simulation).
/// In a curve a bogie's leading axle runs with a large angle of attack: large
/// lateral creepage and spin, of opposite spin sign on the two rails, and a
/// longitudinal creepage from the rolling radius difference; the trailing
/// axle runs nearly radial. On tangent track every creepage is small.
pub(super) fn creepages(
    rng: &mut ChaCha8Rng,
    curve_radius_m: Option<f64>,
    position: BogiePosition,
) -> [Creepage; 2] {
    let c = |cx: f64, cy: f64, spin: f64| Creepage {
        cx: round_dp(cx, 1e6),
        cy: round_dp(cy, 1e6),
        spin_per_m: round_dp(spin, 1e4),
    };
    match curve_radius_m {
        Some(radius_m) => {
            let k = (REFERENCE_RADIUS_M / radius_m).min(3.0);
            let (cx, cy, spin_outer, spin_inner) = match position {
                BogiePosition::Leading => (
                    uniform(rng, 0.002, 0.006),
                    k * uniform(rng, 0.003, 0.008),
                    k * uniform(rng, 0.10, 0.30),
                    -k * uniform(rng, 0.08, 0.25),
                ),
                BogiePosition::Trailing => (
                    uniform(rng, 0.0005, 0.002),
                    uniform(rng, -0.001, 0.002),
                    k * uniform(rng, 0.02, 0.10),
                    -k * uniform(rng, 0.02, 0.08),
                ),
            };
            let cx_inner = -cx * uniform(rng, 0.8, 1.2);
            let cy_inner = cy * uniform(rng, 0.85, 1.0);
            [c(cx, cy, spin_outer), c(cx_inner, cy_inner, spin_inner)]
        }
        None => {
            let mut one = |spin_lo: f64, spin_hi: f64| {
                c(
                    uniform(rng, -0.002, 0.002),
                    uniform(rng, -0.001, 0.001),
                    uniform(rng, spin_lo, spin_hi),
                )
            };
            [one(0.01, 0.05), one(-0.06, -0.008)]
        }
    }
}
