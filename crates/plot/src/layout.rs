//! Where things go on the picture: the fonts and text sizes every figure
//! shares, an estimate of how much room a text takes (the SVG backend does
//! not measure text: the viewer lays it out), and boxes in pixels for
//! placing legends, labels and cells where they cover nothing.

pub(crate) const FONT: &str = "sans-serif";
// Text sizes as plotters takes them (the SVG gets size / 1.24).
pub(crate) const TITLE_PX: u32 = 24;
pub(crate) const TICK_PX: u32 = 17;
pub(crate) const AXIS_DESC_PX: u32 = 19;
pub(crate) const LEGEND_PX: u32 = 17;
pub(crate) const LABEL_PX: u32 = 16;
/// Heights of the title above the panels and of the x axis label below.
pub(crate) const TITLE_AREA_PX: u32 = 44;
pub(crate) const X_DESC_AREA_PX: u32 = 26;

/// A rectangle in pixels of a plotting area, y downwards.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PixelBox {
    pub(crate) x0: i32,
    pub(crate) y0: i32,
    pub(crate) x1: i32,
    pub(crate) y1: i32,
}

impl PixelBox {
    pub(crate) fn contains(&self, (x, y): (i32, i32)) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    pub(crate) fn count(&self, points: &[(i32, i32)]) -> usize {
        points.iter().filter(|&&p| self.contains(p)).count()
    }

    pub(crate) fn overlaps(&self, o: &PixelBox) -> bool {
        self.x0 <= o.x1 && o.x0 <= self.x1 && self.y0 <= o.y1 && o.y0 <= self.y1
    }
}

/// The SVG backend writes a font size of `size / 1.24`; a sans-serif glyph
/// is on average a little over half as wide as the font size. Generous, so
/// that a box drawn around text holds it in any common sans-serif font.
pub(crate) fn text_width_px(text: &str, size: u32) -> i32 {
    (text.chars().count() as f64 * 0.6 * f64::from(size) / 1.24).ceil() as i32
}

pub(crate) fn text_height_px(size: u32) -> i32 {
    (f64::from(size) / 1.24 * 1.2).ceil() as i32
}
