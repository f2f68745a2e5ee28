//! The typed events a recording is read into: SI units, rails,
//! applicators, sites and trains as indices. They exist only valid: the
//! reader ([`crate::reader`]) builds them from the wire messages
//! ([`crate::wire`]) and checks every rule of the format on the way.

use crate::topic::Topic;

/// The `/section` message: the track section the recording describes.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Section {
    pub section_id: String,
    pub length_m: f64,
    /// Rail names; every rail index in an event points into this list.
    pub rails: Vec<String>,
    /// `None` on tangent track.
    pub curve_radius_m: Option<f64>,
    pub rail_head_radius_m: f64,
    pub nominal_wheel_diameter_m: f64,
    pub applicators: Vec<Applicator>,
    pub sites: Vec<Site>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Applicator {
    pub id: String,
    pub position_m: f64,
    /// Indices into [`Section::rails`], in the order the recording lists them.
    pub rails: Vec<usize>,
    pub nominal_pulse_kg: f64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Site {
    pub id: String,
    pub position_m: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Direction {
    /// Towards increasing `d`; enters at `d = 0`.
    Up,
    /// Towards decreasing `d`; enters at `d = length_m`.
    Down,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum BogiePosition {
    Leading,
    Trailing,
}

/// A wheel's creepages on one rail, exactly as recorded.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Creepage {
    pub cx: f64,
    pub cy: f64,
    pub spin_per_m: f64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Axle {
    /// Distance behind the train front; non-decreasing along the train.
    pub offset_m: f64,
    pub bogie_position: BogiePosition,
    pub wheel_diameter_m: f64,
    /// Vertical wheel force Q per rail index, in N.
    pub wheel_load_n: Vec<f64>,
    /// Creepages per rail index.
    pub creepage: Vec<Creepage>,
    /// On a line (line.md): where the load or the creepage differs from
    /// the axle's own, by segment (sorted by segment index). Empty on a
    /// section.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub segments: Vec<AxleSegment>,
}

/// An axle's load or creepage in one segment of a line, in place of its
/// own there (`None`: the axle's own).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AxleSegment {
    /// An index into the line's segments.
    pub segment: usize,
    /// Per rail index, in N.
    pub wheel_load_n: Option<Vec<f64>>,
    pub creepage: Option<Vec<Creepage>>,
}

/// A `/train/passage` message.
#[derive(Debug, Clone, PartialEq)]
pub struct Passage {
    pub train_id: String,
    /// 0-based count of passages in this recording, in log_time order.
    pub train_seq: usize,
    pub direction: Direction,
    pub speed_mps: f64,
    /// Never empty.
    pub axles: Vec<Axle>,
}

/// An `/applicator/pulse` message: checked to be on a rail its applicator lists.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pulse {
    pub applicator: usize,
    pub rail: usize,
    pub mass_kg: f64,
}

pub use tortwin_model::Quantity;

/// Which wheel a `mu`/`adhesion` measurement saw.
#[derive(Debug, Clone, PartialEq)]
pub struct AxleRef {
    /// Shared by the train's measurements (see [`crate::decode`]'s trains).
    pub train_id: std::sync::Arc<str>,
    /// The passage's [`Passage::train_seq`].
    pub train_seq: usize,
    /// Checked to be in range of that train's axles.
    pub axle_index: usize,
}

/// A `/measurement/friction` message.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    pub site: usize,
    pub rail: usize,
    pub of: Measured,
    pub value: f64,
}

/// What a measurement measured: a contact of one axle (`mu`, `adhesion`),
/// or the rail alone (`rail_mu`, a hand tribometer, no train).
#[derive(Debug, Clone, PartialEq)]
pub enum Measured {
    Mu(AxleRef),
    Adhesion(AxleRef),
    RailMu,
}

impl Measurement {
    pub fn quantity(&self) -> Quantity {
        match self.of {
            Measured::Mu(_) => Quantity::Mu,
            Measured::Adhesion(_) => Quantity::Adhesion,
            Measured::RailMu => Quantity::RailMu,
        }
    }

    /// The axle a `mu`/`adhesion` measurement saw (`None` for `rail_mu`).
    pub fn axle(&self) -> Option<&AxleRef> {
        match &self.of {
            Measured::Mu(axle) | Measured::Adhesion(axle) => Some(axle),
            Measured::RailMu => None,
        }
    }
}

/// An `/environment/weather` message, in effect until the next one.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Weather {
    pub air_temperature_c: f64,
    pub relative_humidity: f64,
    pub precipitation_mm_h: f64,
}

impl Default for Weather {
    /// The values in effect before the first weather message.
    fn default() -> Self {
        Self {
            air_temperature_c: 20.0,
            relative_humidity: 0.5,
            precipitation_mm_h: 0.0,
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub enum EventKind {
    Passage(Passage),
    Pulse(Pulse),
    Measurement(Measurement),
    Weather(Weather),
}

impl EventKind {
    /// The topic the event comes from.
    pub fn topic(&self) -> Topic {
        match self {
            EventKind::Passage(_) => Topic::Passage,
            EventKind::Pulse(_) => Topic::Pulse,
            EventKind::Measurement(_) => Topic::Measurement,
            EventKind::Weather(_) => Topic::Weather,
        }
    }
}

/// One message of the recording after `/section`, in replay order.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    pub log_time_ns: u64,
    /// 0-based index of the message in the file (every message counted).
    pub index_in_file: u64,
    pub kind: EventKind,
}
