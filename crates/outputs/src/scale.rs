//! The fixed colour scales of the outputs (docs/spec/interfaces.md,
//! "Colour scales"): the same colour means the same mu, or the same mass of
//! product, in every file tortwin writes, whatever the run.
//!
//! # mu
//! mu is cut into classes 0.01 wide: class `k` (1 to [`MU_CLASSES`]) holds
//! `(k - 1) / 100 <= mu < k / 100`; mu below 0 falls in class 1, mu of 0.80
//! and above in the last class. A class's colour is the scale at its middle,
//! interpolated linearly in sRGB between stops anchored on the paper's target
//! band 0.30 <= mu < 0.40:
//! - below the band (too much product, braking risk): blues, darkest at 0;
//! - inside the band: greens, from a strong green at 0.30 to a pale one at 0.40;
//! - above the band (too little product, dry): yellow at 0.40 through orange
//!   to dark red at 0.80.
//!
//! The band edges are class edges, and the colour jumps there, so where
//! the band starts and ends reads off the picture. The scale does not move
//! with a run's own band ([`TARGET_BAND`] is the paper's): comparing two
//! files by colour stays possible.
//!
//! # Product mass
//! The product on the rail, in mg per grid point, is cut into classes a
//! quarter of a decade wide from 1e-4 mg to 1e2 mg ([`MASS_CLASSES`]), plus
//! class 1 for less than 1e-4 mg (grey: no product to speak of); the classes
//! are coloured by viridis (plotters' `ViridisRGB`), dark for little
//! product, yellow for much.

use plotters::style::colors::colormaps::ViridisRGB;
use plotters::style::RGBColor;

/// The paper's target band of mu, lower edge inclusive: the scale's anchors.
pub const TARGET_BAND: [f64; 2] = [0.30, 0.40];

/// Classes of the mu scale (0.01 wide from 0 to 0.80).
pub const MU_CLASSES: u16 = 80;
/// Width of a mu class.
pub const MU_CLASS_WIDTH: f64 = 0.01;

/// The mu scale's stops: (mu, colour), sorted; a stop repeated at the same
/// mu makes a jump there (the band edges).
const MU_STOPS: [(f64, [u8; 3]); 10] = [
    (0.00, [25, 30, 100]),
    (0.15, [49, 84, 170]),
    (0.30, [150, 200, 235]),
    (0.30, [0, 140, 70]),
    (0.40, [170, 220, 120]),
    (0.40, [255, 230, 110]),
    (0.50, [250, 150, 60]),
    (0.60, [225, 70, 40]),
    (0.70, [170, 15, 40]),
    (0.80, [100, 0, 30]),
];

/// The class of a point no wheel of the train touched on a band (a NaN mu:
/// on a line, a rail band the rows there do not use).
pub const NO_CONTACT_CLASS: u16 = 0;

/// The colour of [`NO_CONTACT_CLASS`]: a neutral grey, off the mu scale.
const NO_CONTACT_COLOR: [u8; 3] = [150, 150, 150];

/// The class of `mu` (1 to [`MU_CLASSES`]); NaN (no contact) is
/// [`NO_CONTACT_CLASS`].
pub fn mu_class(mu: f64) -> u16 {
    let k = (mu / MU_CLASS_WIDTH).floor();
    if mu.is_nan() {
        NO_CONTACT_CLASS
    } else if k < 0.0 {
        1
    } else if k >= f64::from(MU_CLASSES) {
        MU_CLASSES
    } else {
        k as u16 + 1
    }
}

/// The mu range `[low, high)` of `class` (1 to [`MU_CLASSES`]).
pub fn mu_class_range(class: u16) -> [f64; 2] {
    let k = f64::from(class.clamp(1, MU_CLASSES) - 1);
    [k / 100.0, (k + 1.0) / 100.0]
}

/// The colour of `class` (1 to [`MU_CLASSES`]): the scale at the class's
/// middle, `(2 class - 1) / 200`; grey for [`NO_CONTACT_CLASS`].
pub fn mu_class_color(class: u16) -> [u8; 3] {
    if class == NO_CONTACT_CLASS {
        return NO_CONTACT_COLOR;
    }
    let class = class.min(MU_CLASSES);
    mu_scale(f64::from(2 * class - 1) / 200.0)
}

/// "mu 0.30-0.31 (in band)".
pub fn mu_class_label(class: u16) -> String {
    if class == NO_CONTACT_CLASS {
        return "no contact: no wheel of the train on this band here".to_owned();
    }
    let [low, high] = mu_class_range(class);
    let [band_low, band_high] = TARGET_BAND;
    let mid = (low + high) / 2.0;
    let place = if mid < band_low {
        "below band: too much product"
    } else if mid < band_high {
        "in band"
    } else {
        "above band: dry"
    };
    if class == MU_CLASSES {
        format!("mu {low:.2} and above ({place})")
    } else {
        format!("mu {low:.2}-{high:.2} ({place})")
    }
}

/// The continuous scale at `mu` (clamped to the stops).
fn mu_scale(mu: f64) -> [u8; 3] {
    let first = MU_STOPS[0];
    if mu.is_nan() || mu <= first.0 {
        return first.1;
    }
    // The last stop at or below mu, and the one after it: a stop repeated
    // at the same mu is a jump, the later one holds from there on.
    let below = MU_STOPS.iter().rposition(|&(at, _)| at <= mu).unwrap_or(0);
    let Some(&(to_mu, to)) = MU_STOPS.get(below + 1) else {
        return MU_STOPS[MU_STOPS.len() - 1].1;
    };
    let (from_mu, from) = MU_STOPS[below];
    let t = (mu - from_mu) / (to_mu - from_mu);
    let mix = |a: u8, b: u8| (f64::from(a) + (f64::from(b) - f64::from(a)) * t).round() as u8;
    [
        mix(from[0], to[0]),
        mix(from[1], to[1]),
        mix(from[2], to[2]),
    ]
}

/// Classes of the mass scale: below 1e-4 mg, then a quarter decade each up
/// to 1e2 mg and beyond.
pub const MASS_CLASSES: u16 = 25;
/// Lower edge of class 2, in mg.
const MASS_LOWEST_MG: f64 = 1e-4;
const MASS_CLASSES_PER_DECADE: f64 = 4.0;
/// Grey for "no product to speak of".
const MASS_NONE_COLOR: [u8; 3] = [170, 170, 170];

/// The class of a product mass in mg (1 to [`MASS_CLASSES`]); NaN falls in class 1.
pub fn mass_class(mass_mg: f64) -> u16 {
    if mass_mg.is_nan() || mass_mg < MASS_LOWEST_MG {
        return 1;
    }
    let k = ((mass_mg / MASS_LOWEST_MG).log10() * MASS_CLASSES_PER_DECADE).floor();
    if k >= f64::from(MASS_CLASSES - 2) {
        MASS_CLASSES
    } else {
        k as u16 + 2
    }
}

/// The mass range `[low, high)` in mg of `class`; class 1 is `[0, 1e-4)`.
pub fn mass_class_range(class: u16) -> [f64; 2] {
    let class = class.clamp(1, MASS_CLASSES);
    if class == 1 {
        return [0.0, MASS_LOWEST_MG];
    }
    let edge = |k: u16| MASS_LOWEST_MG * 10f64.powf(f64::from(k) / MASS_CLASSES_PER_DECADE);
    let high = if class == MASS_CLASSES {
        f64::INFINITY
    } else {
        edge(class - 1)
    };
    [edge(class - 2), high]
}

/// The colour of a mass class: grey for class 1, viridis over the others.
pub fn mass_class_color(class: u16) -> [u8; 3] {
    let class = class.clamp(1, MASS_CLASSES);
    if class == 1 {
        return MASS_NONE_COLOR;
    }
    let t = f64::from(class - 2) / f64::from(MASS_CLASSES - 2);
    let RGBColor(r, g, b) = ViridisRGB::get_color(t);
    [r, g, b]
}

/// "product 0.18-0.32 mg".
pub fn mass_class_label(class: u16) -> String {
    let [low, high] = mass_class_range(class);
    if class <= 1 {
        format!("product below {MASS_LOWEST_MG:.0e} mg")
    } else if high.is_infinite() {
        format!("product {} mg and more", short(low))
    } else {
        format!("product {}-{} mg", short(low), short(high))
    }
}

/// Two significant digits, plain for 0.001 to 999, else in e-notation.
fn short(x: f64) -> String {
    if (1e-3..1e3).contains(&x) {
        let digits = (1 - x.log10().floor() as i32).max(0) as usize;
        format!("{x:.digits$}")
    } else {
        format!("{x:.1e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mu_classes_cut_at_hundredths_and_jump_at_the_band() {
        assert_eq!(mu_class(-0.2), 1);
        assert_eq!(mu_class(0.0), 1);
        assert_eq!(mu_class(0.005), 1);
        assert_eq!(mu_class(0.30), 31);
        assert_eq!(mu_class(0.3999), 40);
        assert_eq!(mu_class(0.40), 41);
        assert_eq!(mu_class(0.95), MU_CLASSES);
        assert_eq!(mu_class(f64::NAN), NO_CONTACT_CLASS);
        assert_eq!(mu_class_range(31), [0.30, 0.31]);
        // Below, in and above the band differ in hue: blue, green, yellow-red.
        let [r, g, b] = mu_class_color(30);
        assert!(b > r && b > g, "{r} {g} {b}");
        let [r, g, b] = mu_class_color(31);
        assert!(g > r && g > b, "{r} {g} {b}");
        let [r, _, b] = mu_class_color(45);
        assert!(r > b, "{r} {b}");
        assert!(mu_class_label(35).contains("in band"));
        assert!(mu_class_label(20).contains("too much product"));
        assert!(mu_class_label(MU_CLASSES).contains("dry"));
    }

    #[test]
    fn mass_classes_are_quarter_decades() {
        assert_eq!(mass_class(0.0), 1);
        assert_eq!(mass_class(0.99e-4), 1);
        assert_eq!(mass_class(1e-4), 2);
        assert_eq!(mass_class(1.5e-4), 2);
        assert_eq!(mass_class(1e-3), 6);
        assert_eq!(mass_class(1e3), MASS_CLASSES);
        let [low, high] = mass_class_range(6);
        assert!((low - 1e-3).abs() < 1e-15 && (high - 10f64.powf(-2.75)).abs() < 1e-15);
        assert_eq!(mass_class_color(1), MASS_NONE_COLOR);
        assert_eq!(mass_class_label(1), "product below 1e-4 mg");
    }
}
