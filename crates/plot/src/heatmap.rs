//! Heatmaps: one value per pair of categories (coverage over pulse mass ×
//! pulse interval in a strategy report), each cell coloured and labelled
//! with its value, and a colour bar that says what the colours mean.

use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::axis::{checked_range, data_range, snap_to_zero};
use crate::colour::{text_colour_on, viridis, Colour};
use crate::error::{DrawError, PlotError};
use crate::layout::{
    text_height_px, text_width_px, PixelBox, AXIS_DESC_PX, FONT, LABEL_PX, TICK_PX, TITLE_AREA_PX,
    TITLE_PX, X_DESC_AREA_PX,
};

/// A grid of values over two categorical axes, e.g. coverage over pulse
/// mass × pulse interval: one coloured cell per pair with its value printed
/// in it, and a colour bar at the right that says what the colours mean.
///
/// The colours are viridis: dark purple for low, yellow for high, with
/// lightness rising steadily in between, so that the order survives
/// greyscale printing and the common colour-vision deficiencies. The
/// printed values keep the figure exact where colours are only ordinal.
///
/// ```no_run
/// use tortwin_plot::Heatmap;
/// let masses = vec!["0.5 g".to_string(), "1.0 g".to_string()];
/// let intervals = vec!["1 train".to_string(), "2 trains".to_string(), "4 trains".to_string()];
/// let coverage = vec![vec![0.41, 0.35, 0.22], vec![0.78, 0.66, f64::NAN]];
/// Heatmap::new("coverage", "pulse interval", "pulse mass", intervals, masses, coverage)
///     .value_label("share of contacts in band [%]")
///     .range(0.0, 1.0)
///     .cell_text(|v| format!("{:.0}", 100.0 * v))
///     .highlight(1, 0)
///     .write_svg("coverage.svg".as_ref())?;
/// # Ok::<(), tortwin_plot::PlotError>(())
/// ```
#[derive(Debug, Clone)]
pub struct Heatmap {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub x_categories: Vec<String>,
    pub y_categories: Vec<String>,
    /// `values[row][col]`, as [`Heatmap::new`] takes them.
    pub values: Vec<Vec<f64>>,
    /// Name and unit of the colour scale, written beside the colour bar.
    pub value_label: String,
    /// `None`: from the smallest to the largest finite value. Given: values
    /// outside get the colour of the nearer end.
    pub range: Option<(f64, f64)>,
    /// Prints a value in its cell, and the colour bar's tick values, so that
    /// the bar reads in the same unit as the cells (a share of 0.25 printed
    /// as "25" under a label in [%]).
    pub cell_text: fn(f64) -> String,
    /// `(row, col)` of the cell outlined in black.
    pub highlight: Option<(usize, usize)>,
    /// What a grey (NaN) cell means, beside its swatch under the colour bar.
    pub missing_label: String,
    pub width_px: u32,
    pub height_px: u32,
}

/// The fill of a cell whose value is NaN (not evaluated): lighter than any
/// viridis colour and without hue, so it does not read as a value.
pub(crate) const NOT_EVALUATED: Colour = Colour(221, 221, 221);

// Heatmap layout, in pixels.
/// Longest category label before it is cut short with "…".
const MAX_CATEGORY_LABEL_PX: i32 = 150;
/// Width of the colour bar and of the gap between the cells and it.
const COLOUR_BAR_PX: i32 = 20;
const COLOUR_BAR_GAP_PX: i32 = 22;
/// Smallest font size (as plotters takes it) for the text in a cell.
const MIN_CELL_TEXT_PX: u32 = 9;

impl Heatmap {
    /// `values[row][col]`: row = y category (drawn bottom to top: row 0 at
    /// the bottom), col = x category. NaN = not evaluated (drawn as a light
    /// grey cell with no label).
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
        x_categories: Vec<String>,
        y_categories: Vec<String>,
        values: Vec<Vec<f64>>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            x_categories,
            y_categories,
            values,
            value_label: String::new(),
            range: None,
            cell_text: |v| format!("{v:.2}"),
            highlight: None,
            missing_label: NOT_EVALUATED_TEXT.to_string(),
            width_px: 900,
            height_px: 600,
        }
    }

    /// Name and unit of the colour scale, e.g. "share of contacts in band [%]".
    pub fn value_label(mut self, label: impl Into<String>) -> Self {
        self.value_label = label.into();
        self
    }

    /// Colour range (default: min..max of the finite values). A fixed range
    /// lets several heatmaps be compared by colour.
    pub fn range(mut self, min: f64, max: f64) -> Self {
        self.range = Some((min, max));
        self
    }

    /// How a cell's value is printed inside it (default:
    /// `format!("{:.2}", v)`), e.g. `|v| format!("{:.0}", 100.0 * v)`. The
    /// colour bar's ticks are printed the same way.
    pub fn cell_text(mut self, f: fn(f64) -> String) -> Self {
        self.cell_text = f;
        self
    }

    /// What the grey (NaN) cells mean (default "not evaluated").
    pub fn missing_label(mut self, label: impl Into<String>) -> Self {
        self.missing_label = label.into();
        self
    }

    /// Outline one cell (row, col) with a thick black border, e.g. the
    /// recommended strategy.
    pub fn highlight(mut self, row: usize, col: usize) -> Self {
        self.highlight = Some((row, col));
        self
    }

    /// The figure as SVG text. An error says what is wrong with the grid
    /// (its shape, the range, the highlighted cell, or a picture too small
    /// for it).
    pub(crate) fn render_svg(&self) -> Result<String, PlotError> {
        let (lo, hi) = self.colour_range()?;
        let grid = self.layout(lo, hi)?;
        let mut svg = String::new();
        self.draw(&mut svg, (lo, hi), &grid)
            .map_err(|source| PlotError::Draw {
                title: self.title.clone(),
                source,
            })?;
        Ok(svg)
    }

    /// Draws the checked grid, laid out by [`Heatmap::layout`], with colours
    /// over `lo..hi`.
    fn draw(
        &self,
        svg: &mut String,
        (lo, hi): (f64, f64),
        grid: &HeatmapGrid,
    ) -> Result<(), DrawError> {
        let (w, h) = (self.width_px as i32, self.height_px as i32);
        let n_rows = self.y_categories.len();
        let n_cols = self.x_categories.len();
        let colour_of = |v: f64| viridis((v - lo) / (hi - lo));

        let root =
            SVGBackend::with_string(svg, (self.width_px, self.height_px)).into_drawing_area();
        root.fill(&WHITE)?;
        let centred = Pos::new(HPos::Center, VPos::Center);
        root.draw(&Text::new(
            self.title.clone(),
            (w / 2, TITLE_AREA_PX as i32 / 2 + 4),
            TextStyle::from((FONT, TITLE_PX).into_font()).pos(centred),
        ))?;

        // The cells, then their values in a size that fits the longest.
        let texts: Vec<Vec<Option<String>>> = self
            .values
            .iter()
            .map(|row| {
                row.iter()
                    .map(|&v| (!v.is_nan()).then(|| (self.cell_text)(v)))
                    .collect()
            })
            .collect();
        let longest = texts
            .iter()
            .flatten()
            .flatten()
            .max_by_key(|t| t.chars().count())
            .map_or("", String::as_str);
        let cell_text_px = (MIN_CELL_TEXT_PX..=LABEL_PX)
            .rev()
            .find(|&size| {
                text_width_px(longest, size) <= grid.cell_w - 6
                    && text_height_px(size) <= grid.cell_h - 4
            })
            .unwrap_or(MIN_CELL_TEXT_PX);
        for (row, (values, texts)) in self.values.iter().zip(&texts).enumerate() {
            for (col, (&v, text)) in values.iter().zip(texts).enumerate() {
                let b = grid.cell(row, col);
                let fill = if v.is_nan() {
                    NOT_EVALUATED
                } else {
                    colour_of(v)
                };
                root.draw(&Rectangle::new(
                    [(b.x0, b.y0), (b.x1, b.y1)],
                    fill.rgb().filled(),
                ))?;
                if let Some(text) = text {
                    let text_colour = text_colour_on(fill).rgb();
                    let style = TextStyle::from((FONT, cell_text_px).into_font())
                        .color(&text_colour)
                        .pos(centred);
                    root.draw(&Text::new(
                        text.clone(),
                        ((b.x0 + b.x1) / 2, (b.y0 + b.y1) / 2),
                        style,
                    ))?;
                }
            }
        }
        if let Some((row, col)) = self.highlight {
            // Black outside, a white line inside: the frame stands out
            // on the dark cells as well as on the light ones.
            let b = grid.cell(row, col);
            for (inset, thickness, colour) in [(0, 3, BLACK), (3, 1, WHITE)] {
                let (x0, y0, x1, y1) = (b.x0 + inset, b.y0 + inset, b.x1 - inset, b.y1 - inset);
                for [a, z] in [
                    [(x0, y0), (x1, y0 + thickness)],
                    [(x0, y1 - thickness), (x1, y1)],
                    [(x0, y0), (x0 + thickness, y1)],
                    [(x1 - thickness, y0), (x1, y1)],
                ] {
                    root.draw(&Rectangle::new([a, z], colour.filled()))?;
                }
            }
        }

        // Category labels: y at the left of their row; x under their
        // column, turned to read upwards when they would not fit across.
        let tick_font = (FONT, TICK_PX).into_font();
        let grid_bottom = grid.y0 + grid.cell_h * n_rows as i32;
        let grid_right = grid.x0 + grid.cell_w * n_cols as i32;
        for (row, label) in self.y_categories.iter().enumerate() {
            let b = grid.cell(row, 0);
            root.draw(&Text::new(
                fit_text(label, TICK_PX, MAX_CATEGORY_LABEL_PX),
                (grid.x0 - 8, (b.y0 + b.y1) / 2),
                TextStyle::from(tick_font.clone()).pos(Pos::new(HPos::Right, VPos::Center)),
            ))?;
        }
        for (col, label) in self.x_categories.iter().enumerate() {
            let b = grid.cell(0, col);
            let x = (b.x0 + b.x1) / 2;
            let (font, pos) = if grid.x_labels_across {
                (tick_font.clone(), Pos::new(HPos::Center, VPos::Top))
            } else {
                (
                    tick_font.transform(FontTransform::Rotate270),
                    Pos::new(HPos::Right, VPos::Center),
                )
            };
            root.draw(&Text::new(
                fit_text(label, TICK_PX, MAX_CATEGORY_LABEL_PX),
                (x, grid_bottom + 6),
                TextStyle::from(font).pos(pos),
            ))?;
        }
        let desc_font = (FONT, AXIS_DESC_PX).into_font();
        root.draw(&Text::new(
            self.x_label.clone(),
            (
                (grid.x0 + grid_right) / 2,
                h - X_DESC_AREA_PX as i32 / 2 - 4,
            ),
            TextStyle::from(desc_font.clone()).pos(centred),
        ))?;
        root.draw(&Text::new(
            self.y_label.clone(),
            (
                12 + text_height_px(AXIS_DESC_PX) / 2,
                (grid.y0 + grid_bottom) / 2,
            ),
            TextStyle::from(desc_font.transform(FontTransform::Rotate270)).pos(centred),
        ))?;

        // The colour bar: 2 px slices from lo at the bottom to hi at the
        // top, ticks at round values, and the grey of "not evaluated"
        // under it when a cell has that.
        let bar_x0 = grid_right + COLOUR_BAR_GAP_PX;
        let bar_x1 = bar_x0 + COLOUR_BAR_PX;
        let bar_top = grid.y0;
        let bar_bottom = if grid.any_not_evaluated {
            grid_bottom - grid.swatch_h - 12
        } else {
            grid_bottom
        };
        let bar_h = bar_bottom - bar_top;
        let mut y = bar_bottom;
        while y > bar_top {
            let top = (y - 2).max(bar_top);
            let t = f64::from(bar_bottom - (y + top) / 2) / f64::from(bar_h);
            root.draw(&Rectangle::new(
                [(bar_x0, top), (bar_x1, y)],
                viridis(t).rgb().filled(),
            ))?;
            y = top;
        }
        root.draw(&Rectangle::new(
            [(bar_x0, bar_top), (bar_x1, bar_bottom)],
            BLACK.mix(0.5),
        ))?;
        let tick_style = TextStyle::from(tick_font.clone()).pos(Pos::new(HPos::Left, VPos::Center));
        for (v, label) in &grid.ticks {
            let y = bar_bottom - ((v - lo) / (hi - lo) * f64::from(bar_h)).round() as i32;
            root.draw(&PathElement::new(
                vec![(bar_x1, y), (bar_x1 + 5, y)],
                ShapeStyle::from(BLACK).stroke_width(1),
            ))?;
            root.draw(&Text::new(
                label.clone(),
                (bar_x1 + 9, y),
                tick_style.clone(),
            ))?;
        }
        if grid.any_not_evaluated {
            root.draw(&Rectangle::new(
                [(bar_x0, grid_bottom - grid.swatch_h), (bar_x1, grid_bottom)],
                NOT_EVALUATED.rgb().filled(),
            ))?;
            root.draw(&Text::new(
                self.missing_label.as_str(),
                (bar_x1 + 9, grid_bottom - grid.swatch_h / 2),
                TextStyle::from((FONT, LABEL_PX).into_font())
                    .pos(Pos::new(HPos::Left, VPos::Center)),
            ))?;
        }
        root.draw(&Text::new(
            self.value_label.clone(),
            (
                bar_x1 + 9 + grid.bar_labels_w + 10 + text_height_px(AXIS_DESC_PX) / 2,
                (bar_top + bar_bottom) / 2,
            ),
            TextStyle::from(desc_font.transform(FontTransform::Rotate270)).pos(centred),
        ))?;
        root.present()
    }

    /// Writes the figure as an SVG file (whole or not at all, see
    /// [`tortwin_files`]).
    pub fn write_svg(&self, path: &Path) -> Result<(), PlotError> {
        let svg = self.render_svg().map_err(|e| e.for_file(path))?;
        tortwin_files::write_atomically(path, svg.as_bytes())?;
        Ok(())
    }

    /// Checks the grid's shape and the highlighted cell, and gives the
    /// colour range.
    fn colour_range(&self) -> Result<(f64, f64), PlotError> {
        let title = || self.title.clone();
        let (n_rows, n_cols) = (self.y_categories.len(), self.x_categories.len());
        if n_rows == 0 || n_cols == 0 {
            return Err(PlotError::NoCategories {
                title: title(),
                x: n_cols,
                y: n_rows,
            });
        }
        if self.values.len() != n_rows {
            return Err(PlotError::RowCount {
                title: title(),
                rows: self.values.len(),
                y: n_rows,
            });
        }
        for (row, (values, name)) in self.values.iter().zip(&self.y_categories).enumerate() {
            if values.len() != n_cols {
                return Err(PlotError::RowLength {
                    title: title(),
                    row,
                    name: name.clone(),
                    values: values.len(),
                    x: n_cols,
                });
            }
        }
        if let Some((row, col)) = self.highlight {
            if row >= n_rows || col >= n_cols {
                return Err(PlotError::HighlightOutside {
                    title: title(),
                    row,
                    col,
                    rows: n_rows,
                    cols: n_cols,
                });
            }
        }
        match self.range {
            Some(r) => checked_range(r, "colour", &self.title),
            None => Ok(data_range(
                self.values
                    .iter()
                    .flatten()
                    .copied()
                    .filter(|v| v.is_finite()),
            )),
        }
    }

    /// Where everything goes: the margins take what the labels need, the
    /// cells share the rest equally.
    fn layout(&self, lo: f64, hi: f64) -> Result<HeatmapGrid, PlotError> {
        let (w, h) = (self.width_px as i32, self.height_px as i32);
        let (n_rows, n_cols) = (
            self.y_categories.len() as i32,
            self.x_categories.len() as i32,
        );
        let any_not_evaluated = self.values.iter().flatten().any(|v| v.is_nan());
        let ticks = colour_bar_ticks(lo, hi, self.cell_text);

        let label_w = |l: &String| text_width_px(l, TICK_PX).min(MAX_CATEGORY_LABEL_PX);
        let y_labels_w = self.y_categories.iter().map(label_w).max().unwrap_or(0);
        let x0 = 12 + text_height_px(AXIS_DESC_PX) + 10 + y_labels_w + 8;
        let ticks_w = ticks
            .iter()
            .map(|(_, l)| text_width_px(l, TICK_PX))
            .max()
            .unwrap_or(0);
        let not_evaluated_w = if any_not_evaluated {
            text_width_px(&self.missing_label, LABEL_PX)
        } else {
            0
        };
        let bar_labels_w = ticks_w.max(not_evaluated_w);
        let right_w = COLOUR_BAR_GAP_PX
            + COLOUR_BAR_PX
            + 9
            + bar_labels_w
            + 10
            + text_height_px(AXIS_DESC_PX)
            + 12;
        let cell_w = (w - x0 - right_w) / n_cols;

        let x_labels_w = self.x_categories.iter().map(label_w).max().unwrap_or(0);
        let x_labels_across = x_labels_w <= cell_w - 6;
        let x_labels_h = if x_labels_across {
            text_height_px(TICK_PX)
        } else {
            x_labels_w
        } + 12;
        let y0 = TITLE_AREA_PX as i32 + 6;
        let cell_h = (h - y0 - x_labels_h - X_DESC_AREA_PX as i32 - 8) / n_rows;
        // Room for a line of the smallest cell text; under that the cells
        // are unreadable and the picture should be made larger.
        let min_cell_h = text_height_px(MIN_CELL_TEXT_PX) + 2;
        if cell_w < 2 * min_cell_h || cell_h < min_cell_h {
            return Err(PlotError::TooSmall {
                title: self.title.clone(),
                width_px: self.width_px,
                height_px: self.height_px,
                cols: self.x_categories.len(),
                rows: self.y_categories.len(),
                cell_w_px: cell_w,
                cell_h_px: cell_h,
            });
        }
        Ok(HeatmapGrid {
            x0,
            y0,
            cell_w,
            cell_h,
            n_rows,
            x_labels_across,
            any_not_evaluated,
            swatch_h: text_height_px(LABEL_PX) + 2,
            ticks,
            bar_labels_w,
        })
    }
}

/// The text beside the colour of [`NOT_EVALUATED`] under the colour bar.
const NOT_EVALUATED_TEXT: &str = "not evaluated";

/// Where a [`Heatmap`] draws, in pixels of the picture, y downwards.
#[derive(Debug, Clone)]
struct HeatmapGrid {
    /// Upper left corner of the top left cell.
    x0: i32,
    y0: i32,
    cell_w: i32,
    cell_h: i32,
    n_rows: i32,
    /// Whether every x category label fits across its column.
    x_labels_across: bool,
    any_not_evaluated: bool,
    /// Height of the "not evaluated" swatch under the colour bar.
    swatch_h: i32,
    ticks: Vec<(f64, String)>,
    /// Width of the widest text right of the colour bar.
    bar_labels_w: i32,
}

impl HeatmapGrid {
    /// The filled part of cell `(row, col)`, row 0 at the bottom. One pixel
    /// at its right and bottom stays white, a gap between neighbours.
    fn cell(&self, row: usize, col: usize) -> PixelBox {
        let x0 = self.x0 + col as i32 * self.cell_w;
        let y0 = self.y0 + (self.n_rows - 1 - row as i32) * self.cell_h;
        PixelBox {
            x0,
            y0,
            x1: x0 + self.cell_w - 1,
            y1: y0 + self.cell_h - 1,
        }
    }
}

/// Three to six ticks at round values (steps of 1, 2, 2.5 or 5 times a
/// power of ten) within `lo..=hi`, printed by `text`; a tick that prints
/// like the one below it is left out. The two ends when no round values fit.
fn colour_bar_ticks(lo: f64, hi: f64, text: fn(f64) -> String) -> Vec<(f64, String)> {
    let span = hi - lo;
    let raw = span / 4.0;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * magnitude)
        .find(|&s| s >= raw)
        .unwrap_or(10.0 * magnitude);
    let first = (lo / step - 1e-9).ceil();
    let last = (hi / step + 1e-9).floor();
    let mut ticks: Vec<(f64, String)> = Vec::new();
    if step.is_finite() && step > 0.0 && last - first <= 10.0 {
        let mut k = first;
        while k <= last {
            let v = snap_to_zero(k * step, span).clamp(lo, hi);
            let label = text(v);
            if ticks.last().is_none_or(|(_, l)| *l != label) {
                ticks.push((v, label));
            }
            k += 1.0;
        }
    }
    if ticks.len() < 2 {
        ticks = vec![(lo, text(lo)), (hi, text(hi))];
        ticks.dedup_by(|a, b| a.1 == b.1);
    }
    ticks
}

/// `text` cut short with "…" to at most `max_px` wide at font `size`.
fn fit_text(text: &str, size: u32, max_px: i32) -> String {
    if text_width_px(text, size) <= max_px {
        return text.to_string();
    }
    let mut chars: Vec<char> = text.chars().collect();
    while !chars.is_empty()
        && text_width_px(&format!("{}…", String::from_iter(&chars)), size) > max_px
    {
        chars.pop();
    }
    format!("{}…", String::from_iter(&chars))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `<rect>` of the SVG: x, y, width, height and fill.
    #[derive(Debug, Clone, PartialEq)]
    struct SvgRect {
        x: i32,
        y: i32,
        w: i32,
        h: i32,
        fill: String,
    }

    impl SvgRect {
        fn contains(&self, (x, y): (i32, i32)) -> bool {
            (self.x..=self.x + self.w).contains(&x) && (self.y..=self.y + self.h).contains(&y)
        }
    }

    /// A `<text>` of the SVG: its anchor point, fill and content.
    #[derive(Debug, Clone)]
    struct SvgText {
        x: i32,
        y: i32,
        fill: String,
        font_size_px: f64,
        text: String,
    }

    fn attr<'a>(tag: &'a str, name: &str) -> &'a str {
        let key = format!(" {name}=\"");
        let start = tag
            .find(&key)
            .unwrap_or_else(|| panic!("no {name} in {tag}"))
            + key.len();
        let len = tag[start..].find('"').unwrap();
        &tag[start..start + len]
    }

    fn svg_rects(svg: &str) -> Vec<SvgRect> {
        svg.split("<rect")
            .skip(1)
            .map(|rest| {
                let tag = &rest[..rest.find("/>").unwrap()];
                SvgRect {
                    x: attr(tag, "x").parse().unwrap(),
                    y: attr(tag, "y").parse().unwrap(),
                    w: attr(tag, "width").parse().unwrap(),
                    h: attr(tag, "height").parse().unwrap(),
                    fill: attr(tag, "fill").to_string(),
                }
            })
            .collect()
    }

    fn svg_texts(svg: &str) -> Vec<SvgText> {
        svg.split("<text")
            .skip(1)
            .map(|rest| {
                let (tag, body) = rest.split_once('>').unwrap();
                SvgText {
                    x: attr(tag, "x").parse().unwrap(),
                    y: attr(tag, "y").parse().unwrap(),
                    fill: attr(tag, "fill").to_string(),
                    font_size_px: attr(tag, "font-size").parse().unwrap(),
                    text: body[..body.find("</text>").unwrap()].trim().to_string(),
                }
            })
            .collect()
    }

    fn hex(c: Colour) -> String {
        format!("#{:02X}{:02X}{:02X}", c.0, c.1, c.2)
    }

    fn strings(s: &[&str]) -> Vec<String> {
        s.iter().map(|s| s.to_string()).collect()
    }

    /// 3 pulse masses x 4 intervals, each value different so that each cell
    /// has its own colour and text. The range is fixed at 0..1.2 so that
    /// the expected colours follow from the values alone.
    fn coverage_heatmap() -> Heatmap {
        Heatmap::new(
            "coverage by pulse",
            "pulse interval [trains]",
            "pulse mass [g]",
            strings(&["every 1", "every 2", "every 4", "every 8"]),
            strings(&["0.5 g", "1.0 g", "2.0 g"]),
            vec![
                vec![0.00, 0.11, 0.22, 0.33],
                vec![0.44, 0.55, 0.66, 0.77],
                vec![0.88, 0.99, 1.10, 1.20],
            ],
        )
        .value_label("share of contacts in band [%]")
        .range(0.0, 1.2)
        .cell_text(|v| format!("{:.1}%", 100.0 * v))
    }

    /// The rectangles filled with the colour of one of `values` (in
    /// `0..1.2`), with the value they were matched to. Colour bar slices
    /// are 2 px high and so are left out by asking for cell-sized ones.
    fn data_cells(svg: &str, values: &[f64]) -> Vec<(SvgRect, f64)> {
        svg_rects(svg)
            .into_iter()
            .filter(|r| r.w > 20 && r.h > 20)
            .filter_map(|r| {
                let v = values
                    .iter()
                    .find(|&&v| !v.is_nan() && hex(viridis(v / 1.2)) == r.fill)?;
                Some((r, *v))
            })
            .collect()
    }

    #[test]
    fn heatmap_draws_every_cell_with_its_colour_and_text() {
        let heatmap = coverage_heatmap();
        let svg = heatmap.render_svg().unwrap();
        for text in [
            "coverage by pulse",
            "pulse interval [trains]",
            "pulse mass [g]",
            "share of contacts in band [%]",
        ]
        .iter()
        .chain(&[
            "every 1", "every 2", "every 4", "every 8", "0.5 g", "1.0 g", "2.0 g",
        ]) {
            assert!(svg.contains(text), "{text} missing");
        }
        let values: Vec<f64> = heatmap.values.iter().flatten().copied().collect();
        let cells = data_cells(&svg, &values);
        assert_eq!(cells.len(), 12, "{cells:?}");
        // All the same size, one per value, on a 4 x 3 grid.
        assert!(cells
            .iter()
            .all(|(r, _)| (r.w, r.h) == (cells[0].0.w, cells[0].0.h)));
        let mut matched: Vec<f64> = cells.iter().map(|(_, v)| *v).collect();
        matched.sort_by(f64::total_cmp);
        assert_eq!(matched, values);
        let mut xs: Vec<i32> = cells.iter().map(|(r, _)| r.x).collect();
        let mut ys: Vec<i32> = cells.iter().map(|(r, _)| r.y).collect();
        xs.sort();
        xs.dedup();
        ys.sort();
        ys.dedup();
        assert_eq!((xs.len(), ys.len()), (4, 3));

        // Row 0 at the bottom, column 0 at the left.
        let at = |v: f64| cells.iter().find(|(_, c)| *c == v).unwrap().0.clone();
        assert!(at(0.00).y > at(0.44).y && at(0.44).y > at(0.88).y);
        assert!(at(0.00).x < at(0.11).x && at(0.11).x < at(0.33).x);
        assert_eq!(at(0.00).x, at(0.88).x);

        // Each cell holds exactly its own text, white on dark, black on light;
        // no other text lies on a cell.
        let texts = svg_texts(&svg);
        for (rect, v) in &cells {
            let inside: Vec<&SvgText> =
                texts.iter().filter(|t| rect.contains((t.x, t.y))).collect();
            assert_eq!(inside.len(), 1, "cell {v}: {inside:?}");
            assert_eq!(inside[0].text, format!("{:.1}%", 100.0 * v));
            assert_eq!(inside[0].fill, hex(text_colour_on(viridis(v / 1.2))));
        }
        assert_eq!(at(0.00).fill, "#440154");
        assert_eq!(at(1.20).fill, "#FEE825");
        // The colour bar's ticks speak the cells' unit.
        for tick in ["0.0%", "50.0%", "100.0%"] {
            assert!(
                texts
                    .iter()
                    .any(|t| t.text == tick && !cells.iter().any(|(r, _)| r.contains((t.x, t.y)))),
                "tick {tick} missing"
            );
        }
        // No highlight asked for: nothing is filled black.
        assert!(svg_rects(&svg).iter().all(|r| r.fill != "#000000"));
    }

    #[test]
    fn heatmap_leaves_not_evaluated_cells_grey_and_blank() {
        let mut heatmap = coverage_heatmap();
        heatmap.values[1][2] = f64::NAN;
        let svg = heatmap.render_svg().unwrap();
        let values: Vec<f64> = heatmap.values.iter().flatten().copied().collect();
        let cells = data_cells(&svg, &values);
        assert_eq!(cells.len(), 11);
        let grey: Vec<SvgRect> = svg_rects(&svg)
            .into_iter()
            .filter(|r| r.fill == hex(NOT_EVALUATED) && r.w > 20 && r.h > 20)
            .collect();
        assert_eq!(grey.len(), 1, "{grey:?}");
        let texts = svg_texts(&svg);
        assert!(!texts.iter().any(|t| grey[0].contains((t.x, t.y))));
        assert!(!svg.contains("NaN"));
        // In the cell between 0.55 (left) and 0.77 (right), below 0.99.
        let at = |v: f64| cells.iter().find(|(_, c)| *c == v).unwrap().0.clone();
        assert!(at(0.55).x < grey[0].x && grey[0].x < at(0.77).x);
        assert!(grey[0].y > at(0.99).y);
        assert!(svg.contains(NOT_EVALUATED_TEXT));
    }

    #[test]
    fn heatmap_outlines_the_highlighted_cell() {
        let heatmap = coverage_heatmap().highlight(2, 3);
        let svg = heatmap.render_svg().unwrap();
        let values: Vec<f64> = heatmap.values.iter().flatten().copied().collect();
        let cell = data_cells(&svg, &values)
            .into_iter()
            .find(|(_, v)| *v == 1.20)
            .unwrap()
            .0;
        let black: Vec<SvgRect> = svg_rects(&svg)
            .into_iter()
            .filter(|r| r.fill == "#000000")
            .collect();
        assert_eq!(black.len(), 4, "{black:?}");
        // The four sides span the cell exactly.
        let x0 = black.iter().map(|r| r.x).min().unwrap();
        let y0 = black.iter().map(|r| r.y).min().unwrap();
        let x1 = black.iter().map(|r| r.x + r.w).max().unwrap();
        let y1 = black.iter().map(|r| r.y + r.h).max().unwrap();
        assert_eq!(
            (x0, y0, x1, y1),
            (cell.x, cell.y, cell.x + cell.w, cell.y + cell.h)
        );
        assert!(black.iter().all(|r| r.w.min(r.h) == 3));
    }

    #[test]
    fn heatmap_refuses_what_it_cannot_draw() {
        let err = |h: Heatmap| h.render_svg().unwrap_err().to_string();
        let mut short = coverage_heatmap();
        short.values.pop();
        assert!(err(short).contains("2 rows of values for 3 y categories"));
        let mut ragged = coverage_heatmap();
        ragged.values[1].push(0.5);
        assert!(err(ragged).contains("row 1 (1.0 g) has 5 values for 4 x categories"));
        assert!(err(coverage_heatmap().highlight(3, 0)).contains("highlighted cell (row 3, col 0)"));
        assert!(err(coverage_heatmap().highlight(0, 4)).contains("highlighted cell (row 0, col 4)"));
        assert!(err(coverage_heatmap().range(1.0, 1.0)).contains("range"));
        assert!(err(coverage_heatmap().range(0.0, f64::NAN)).contains("range"));
        let empty = Heatmap::new("e", "x", "y", vec![], strings(&["a"]), vec![vec![]]);
        assert!(err(empty).contains("at least one category"));
        let mut tiny = coverage_heatmap();
        tiny.height_px = 120;
        assert!(err(tiny).contains("too small"));
    }

    #[test]
    fn heatmap_of_equal_or_missing_values_still_renders() {
        let flat = Heatmap::new(
            "flat",
            "x",
            "y",
            strings(&["a", "b"]),
            strings(&["c"]),
            vec![vec![0.3, 0.3]],
        );
        let svg = flat.render_svg().unwrap();
        // Widened around 0.3, which lands mid-scale.
        let cells: Vec<SvgRect> = svg_rects(&svg)
            .into_iter()
            .filter(|r| r.w > 20 && r.h > 20 && r.fill != "#FFFFFF")
            .collect();
        assert_eq!(cells.len(), 2, "{cells:?}");
        let texts = svg_texts(&svg);
        for cell in &cells {
            assert_eq!(cell.fill, hex(viridis(0.5)));
            let inside: Vec<&str> = texts
                .iter()
                .filter(|t| cell.contains((t.x, t.y)))
                .map(|t| t.text.as_str())
                .collect();
            assert_eq!(inside, ["0.30"]);
        }
        let none = Heatmap::new(
            "none",
            "x",
            "y",
            strings(&["a"]),
            strings(&["b"]),
            vec![vec![f64::NAN]],
        );
        assert!(none.render_svg().is_ok());
    }

    #[test]
    fn heatmap_16_by_16_stays_readable() {
        let labels: Vec<String> = (0..16)
            .map(|k| format!("{:.2} g", 0.25 * f64::from(k)))
            .collect();
        let values: Vec<Vec<f64>> = (0..16)
            .map(|r| (0..16).map(|c| f64::from(r * 16 + c) / 255.0).collect())
            .collect();
        let heatmap = Heatmap::new(
            "sixteen by sixteen",
            "pulse interval [trains]",
            "pulse mass [g]",
            labels.clone(),
            labels.clone(),
            values,
        )
        .value_label("coverage [-]");
        let svg = heatmap.render_svg().unwrap();
        let cells: Vec<SvgRect> = svg_rects(&svg)
            .into_iter()
            .filter(|r| r.w > 20 && r.h > 20 && r.fill != "#FFFFFF")
            .collect();
        assert_eq!(cells.len(), 256);
        let texts = svg_texts(&svg);
        for cell in &cells {
            assert!(cell.w >= 30 && cell.h >= 20, "{cell:?}");
            let inside: Vec<&SvgText> =
                texts.iter().filter(|t| cell.contains((t.x, t.y))).collect();
            assert_eq!(inside.len(), 1, "{cell:?}: {inside:?}");
            // At least 9 px in the SVG, and across the cell with room.
            let t = inside[0];
            assert!(t.font_size_px >= 9.0, "{t:?}");
            let width = (t.text.chars().count() as f64 * 0.6 * t.font_size_px).ceil() as i32;
            assert!(width < cell.w - 4, "{t:?} in {cell:?}");
        }
        for label in &labels {
            // Once on each axis, not cut short.
            assert_eq!(
                texts.iter().filter(|t| t.text == *label).count(),
                2,
                "{label}"
            );
        }
    }
}
