//! Colours: the palette of line plots, the heatmaps' colour map, and the
//! text colour that reads on a given fill.

use plotters::style::colors::colormaps::ViridisRGB;
use plotters::style::RGBColor;

/// A colour of a line. [`Colour::palette`] gives distinct colours in turn.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Colour(pub u8, pub u8, pub u8);

impl Colour {
    pub const BLACK: Colour = Colour(0, 0, 0);
    pub const GREY: Colour = Colour(120, 120, 120);
    /// The blue, orange, green, red and purple of matplotlib's "tab10",
    /// which stay distinguishable for most colour-blind readers.
    pub const BLUE: Colour = Colour(31, 119, 180);
    pub const ORANGE: Colour = Colour(255, 127, 14);
    pub const GREEN: Colour = Colour(44, 160, 44);
    pub const RED: Colour = Colour(214, 39, 40);
    pub(crate) const PURPLE: Colour = Colour(148, 103, 189);
    pub(crate) const BROWN: Colour = Colour(140, 86, 75);

    /// The `i`-th colour of a repeating palette (blue, orange, green, red, ...).
    pub fn palette(i: usize) -> Colour {
        const PALETTE: [Colour; 6] = [
            Colour::BLUE,
            Colour::ORANGE,
            Colour::GREEN,
            Colour::RED,
            Colour::PURPLE,
            Colour::BROWN,
        ];
        PALETTE[i % PALETTE.len()]
    }

    pub(crate) fn rgb(self) -> RGBColor {
        RGBColor(self.0, self.1, self.2)
    }
}

/// viridis at `t` in 0..=1 (clamped; NaN gives the low end): plotters'
/// `ViridisRGB`, matplotlib's map through eight stops.
pub(crate) fn viridis(t: f64) -> Colour {
    // plotters cannot place NaN on its map (it indexes with it).
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let RGBColor(r, g, b) = ViridisRGB::get_color(t);
    Colour(r, g, b)
}

/// Black or white, whichever contrasts more with `background` (WCAG's
/// contrast ratio of relative luminances).
pub(crate) fn text_colour_on(background: Colour) -> Colour {
    let linear = |c: u8| {
        let c = f64::from(c) / 255.0;
        if c <= 0.04045 {
            c / 12.92
        } else {
            ((c + 0.055) / 1.055).powf(2.4)
        }
    };
    let l = 0.2126 * linear(background.0)
        + 0.7152 * linear(background.1)
        + 0.0722 * linear(background.2);
    if (l + 0.05) / 0.05 >= 1.05 / (l + 0.05) {
        Colour::BLACK
    } else {
        Colour(255, 255, 255)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn viridis_ends_and_text_contrast() {
        assert_eq!(viridis(0.0), Colour(68, 1, 84));
        assert_eq!(viridis(1.0), Colour(254, 232, 37));
        // Halfway between plotters' stops 4 and 5 (of 8).
        assert_eq!(viridis(0.5), Colour(35, 145, 140));
        assert_eq!(viridis(f64::NAN), viridis(0.0));
        assert_eq!(viridis(-3.0), viridis(0.0));
        assert_eq!(viridis(f64::INFINITY), viridis(1.0));
        // Perceptually ordered: lightness (here luminance) rises throughout.
        let lum =
            |c: Colour| 0.2126 * f64::from(c.0) + 0.7152 * f64::from(c.1) + 0.0722 * f64::from(c.2);
        for k in 0..20 {
            let (a, b) = (f64::from(k) / 20.0, f64::from(k + 1) / 20.0);
            assert!(lum(viridis(a)) < lum(viridis(b)), "not ordered at {a}");
        }
        assert_eq!(text_colour_on(viridis(0.0)), Colour(255, 255, 255));
        assert_eq!(text_colour_on(viridis(1.0)), Colour::BLACK);
        assert_eq!(text_colour_on(crate::heatmap::NOT_EVALUATED), Colour::BLACK);
    }
}
