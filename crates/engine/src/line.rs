//! A line (line.md) laid on the engine's grid: per point its segment, per
//! rail, bogie position and point the bands that meet ([`crate::rows`]),
//! and the rail bands a pulse lands on. A line's tracks are, per rail, its
//! crown (`C`) and its gauge corner (`G`), in that order: rail `r`'s
//! crown is track `2r`, its gauge corner `2r + 1`.

use tortwin_model::config::ModelConfig;
use tortwin_model::error::ConfigError;
use tortwin_recording::line::Line;
use tortwin_recording::BogiePosition;

use crate::rows::{self, RailBand, WheelBand};
use crate::Grid;

/// The band name of a rail's crown track on a line.
pub(crate) const CROWN: &str = "C";
/// The band name of a rail's gauge-corner track on a line.
pub(crate) const GAUGE_CORNER: &str = "G";

/// Rail bands per rail on a line: its tracks are `2r` and `2r + 1`.
pub(crate) const RAIL_BANDS: usize = 2;

#[derive(Debug, Clone)]
pub(crate) struct LineLayout {
    pub(crate) line: Line,
    /// Per grid point: its segment.
    segment_of: Vec<u32>,
    /// Per rail and bogie position (`rail * 2 + trailing`), per point: the
    /// row, `wheel band * RAIL_BANDS + rail band`.
    rows: Vec<Vec<u8>>,
}

fn wheel_band_index(b: WheelBand) -> usize {
    match b {
        WheelBand::F => 0,
        WheelBand::C => 1,
        WheelBand::G => 2,
    }
}

fn rail_band_index(b: RailBand) -> usize {
    match b {
        RailBand::C => 0,
        RailBand::G => 1,
    }
}

impl LineLayout {
    pub(crate) fn new(line: Line, grid: &Grid, rails: usize) -> Self {
        // The last segment also holds d = L; a grid point is never past it.
        let last = line.segments.len() - 1;
        let segment_of = grid
            .d_m
            .iter()
            .map(|&d| line.segment_at(d).unwrap_or(last) as u32)
            .collect();
        let rows = (0..rails)
            .flat_map(|rail| {
                [BogiePosition::Leading, BogiePosition::Trailing].map(|bogie| (rail, bogie))
            })
            .map(|(rail, bogie)| {
                grid.d_m
                    .iter()
                    .map(|&d| {
                        let row = rows::row(&line, rail, bogie, d);
                        (wheel_band_index(row.wheel) * RAIL_BANDS + rail_band_index(row.rail)) as u8
                    })
                    .collect()
            })
            .collect();
        Self {
            line,
            segment_of,
            rows,
        }
    }

    pub(crate) fn segments(&self) -> usize {
        self.line.segments.len()
    }

    #[inline(always)]
    pub(crate) fn segment_of(&self, i: usize) -> usize {
        self.segment_of[i] as usize
    }

    /// The rows of `rail`'s wheels at `bogie` along the line, per point
    /// `wheel band * RAIL_BANDS + rail band`: the wheel band's index (F,
    /// C, G) and the rail band's (C, G).
    pub(crate) fn rows_of(&self, rail: usize, trailing: bool) -> &[u8] {
        &self.rows[rail * 2 + usize::from(trailing)]
    }

    /// Per point: its segment.
    pub(crate) fn segments_of(&self) -> &[u32] {
        &self.segment_of
    }

    /// Per rail: the tracks a pulse at grid point `point` lands on.
    pub(crate) fn pulse_tracks(&self, grid: &Grid, point: usize, rails: usize) -> Vec<Vec<usize>> {
        (0..rails)
            .map(|rail| {
                rows::pulse_bands(&self.line, rail, grid.d_m[point])
                    .iter()
                    .map(|&b| rail * RAIL_BANDS + rail_band_index(b))
                    .collect()
            })
            .collect()
    }
}

/// line.md: a line with an effect or a generic term of effects.md switched
/// on is a configuration error.
pub fn check_config(cfg: &ModelConfig, source_name: &str) -> Result<(), ConfigError> {
    let names = cfg.effects.names();
    let key = match (names.first(), cfg.effects.generic.is_empty()) {
        (Some(name), _) => format!("effects.{name}"),
        (None, false) => "effects.generic".to_string(),
        (None, true) => return Ok(()),
    };
    Err(ConfigError {
        source_name: source_name.to_string(),
        key,
        message: "the recording is a line (it has a /line topic), and a line takes no effects \
                  or generic terms yet (docs/spec/line.md): switch them off to replay it"
            .into(),
    })
}
