//! Where things are logged and how they look: entity paths from verbatim
//! names, a track's entities, labels, and the colours that make a rail
//! read alike in every view.

use crate::rerun_sdk::components::Color;
use crate::rerun_sdk::{EntityPath, EntityPathPart};
use tortwin_engine::sink::TrackInfo;
use tortwin_recording::Quantity;

/// A track's (rail/band's) entities, its label and its colour.
pub(super) struct TrackEntities {
    /// "high rail (top band)".
    pub(super) label: String,
    pub(super) color: Color,
    /// "blue", for the views' titles.
    pub(super) color_name: &'static str,
    /// The track's grid points on the plan, coloured by mu class.
    pub(super) curve_mu: EntityPath,
    /// The same points coloured by the rail product's class.
    pub(super) curve_product: EntityPath,
    /// Profile lines along d: mu, adhesion, rail product, wheel product.
    pub(super) mu: EntityPath,
    pub(super) adhesion: EntityPath,
    pub(super) rail_mass: EntityPath,
    pub(super) wheel_mass: EntityPath,
    /// `history/<rail>/<band>`: one image per block of trains below it.
    pub(super) history: EntityPath,
}

impl TrackEntities {
    /// The entities of `track`, one of the section's `tracks`.
    pub(super) fn new(track: &TrackInfo, tracks: &[TrackInfo]) -> Self {
        let (rail, band) = (track.rail_name.as_str(), track.band.as_str());
        TrackEntities {
            label: track_label(track),
            color: track_color(track, tracks).0,
            color_name: track_color(track, tracks).1,
            curve_mu: entity(&["curve", "mu", "tracks", rail, band]),
            curve_product: entity(&["curve", "product", "tracks", rail, band]),
            mu: entity(&["profiles", "mu", rail, band, "mu"]),
            adhesion: entity(&["profiles", "mu", rail, band, "adhesion"]),
            rail_mass: entity(&["profiles", "product", rail, band, "rail"]),
            wheel_mass: entity(&["profiles", "product", rail, band, "wheel"]),
            history: entity(&["history", rail, band]),
        }
    }

    /// The profile lines' entities, in the order of
    /// [`super::batch::PendingRows::strips`].
    pub(super) fn profiles(&self) -> [&EntityPath; 4] {
        [&self.mu, &self.adhesion, &self.rail_mass, &self.wheel_mass]
    }
}

/// A rail's entities of a line's watched axles ([`LineWheels`]): the mu
/// the chosen axle and the next saw and what `rail_mu` reads, in the mu
/// profile's coordinates; the chosen axle's tread bands in the product's.
///
/// [`LineWheels`]: tortwin_engine::sink::LineWheels
pub(super) struct LineWheelEntities {
    pub(super) mu: [EntityPath; 2],
    pub(super) rail_mu: EntityPath,
    /// F, C, G.
    pub(super) bands: [EntityPath; 3],
}

/// The tread bands' names and colours (the same on every rail: a view
/// shows one rail).
pub(super) const TREAD_BANDS: [(&str, (u8, u8, u8), &str); 3] = [
    ("F", (60, 170, 90), "green"),
    ("C", (66, 135, 245), "blue"),
    ("G", (235, 87, 70), "red"),
];

impl LineWheelEntities {
    pub(super) fn new(rail: &str) -> Self {
        LineWheelEntities {
            mu: [
                entity(&["line", "mu", rail, "axle"]),
                entity(&["line", "mu", rail, "next_axle"]),
            ],
            rail_mu: entity(&["line", "mu", rail, "rail_mu"]),
            bands: TREAD_BANDS.map(|(band, _, _)| entity(&["line", "tread", rail, band])),
        }
    }

    /// Each entity's static style: the rail's colour for the chosen axle, a
    /// paler one for the next, grey for `rail_mu`; the bands' colours.
    pub(super) fn styles(&self, rail: usize) -> Vec<(EntityPath, crate::rerun_sdk::LineStrips2D)> {
        use crate::rerun_sdk::components::Radius;
        let color = rail_color(rail);
        let style = |color: Color, width: f32| {
            crate::rerun_sdk::LineStrips2D::update_fields()
                .with_colors([color])
                .with_radii([Radius::new_ui_points(width)])
        };
        let mut styles = vec![
            (self.mu[0].clone(), style(color, 1.5)),
            (self.mu[1].clone(), style(lighten(color, 0.5), 1.5)),
            (
                self.rail_mu.clone(),
                style(Color::from_rgb(110, 110, 110), 1.0),
            ),
        ];
        for (path, (_, (r, g, b), _)) in self.bands.iter().zip(TREAD_BANDS) {
            styles.push((path.clone(), style(Color::from_rgb(r, g, b), 1.5)));
        }
        styles
    }
}

/// An entity path from verbatim names (rail names may hold any character).
pub(super) fn entity(parts: &[&str]) -> EntityPath {
    EntityPath::new(parts.iter().map(|p| EntityPathPart::new(*p)).collect())
}

/// "high rail (top band)", "high rail (gauge corner band)".
pub(super) fn track_label(track: &TrackInfo) -> String {
    format!(
        "{} rail ({} band)",
        track.rail_name,
        track.band.replace('_', " ")
    )
}

/// The order of a site's plots.
pub(super) const QUANTITIES: [Quantity; 3] = [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu];

pub(super) fn quantity_label(quantity: Quantity) -> &'static str {
    match quantity {
        Quantity::Mu => "wheel-rail mu per axle",
        Quantity::Adhesion => "adhesion T/N per axle",
        Quantity::RailMu => "rail mu (tribometer)",
    }
}

const RAIL_COLORS: [((u8, u8, u8), &str); 4] = [
    ((66, 135, 245), "blue"),
    ((235, 87, 70), "red"),
    ((160, 100, 220), "purple"),
    ((240, 200, 60), "yellow"),
];
/// A second shade per rail, for its bands other than `top`.
const BAND_COLORS: [((u8, u8, u8), &str); 4] = [
    ((60, 200, 200), "cyan"),
    ((245, 160, 50), "orange"),
    ((220, 120, 200), "pink"),
    ((150, 200, 70), "green"),
];

pub(super) fn rail_color(rail: usize) -> Color {
    let ((r, g, b), _) = RAIL_COLORS[rail % RAIL_COLORS.len()];
    Color::from_rgb(r, g, b)
}

/// The rail's colour for its `top` band (a line's `C`, or its only one), a
/// second shade for another band: the same rail reads alike in every plot. With its name.
pub(super) fn track_color(track: &TrackInfo, tracks: &[TrackInfo]) -> (Color, &'static str) {
    let single_band = tracks.iter().filter(|t| t.rail == track.rail).count() == 1;
    // A section's `top` band, a line's crown `C`.
    let first = track.band == "top" || track.band == "C";
    let ((r, g, b), name) = if first || single_band {
        RAIL_COLORS[track.rail % RAIL_COLORS.len()]
    } else {
        BAND_COLORS[track.rail % BAND_COLORS.len()]
    };
    (Color::from_rgb(r, g, b), name)
}

/// `color` blended towards white by `amount` (0 to 1).
pub(super) fn lighten(color: Color, amount: f32) -> Color {
    let [r, g, b, _] = color.to_array();
    let blend = |c: u8| (f32::from(c) + (255.0 - f32::from(c)) * amount).round() as u8;
    Color::from_rgb(blend(r), blend(g), blend(b))
}
