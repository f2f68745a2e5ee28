//! Line plots and heatmaps as SVG and small CSV tables: the pictures and
//! numbers that reports (the paper's figures, a discrepancy report, a
//! strategy report) leave behind for people.
//!
//! Why SVG only: the SVG backend of `plotters` needs no system fonts (the
//! viewer lays out the text; `plotters` only estimates its size to place
//! it), so the figures build the same on every machine and diff as text.
//!
//! A [`LinePlot`] is one or more [`Panel`]s stacked vertically that share
//! the x axis (the paper's Figure 13: masses on one panel, mu on the
//! other). A panel holds [`Series`] (solid or dashed, in a colour), thin
//! horizontal [`ReferenceLine`]s (mu_C and mu_D in Figure 7) and a legend.
//! Units belong in the axis labels: "distance from applicator d [m]".
//!
//! A [`Heatmap`] shows one value per pair of categories (coverage over
//! pulse mass × pulse interval in a strategy report), each cell coloured
//! and labelled with its value.
//!
//! ```no_run
//! use tortwin_plot::{Colour, LinePlot, Panel, ReferenceLine, Series};
//! let d = vec![0.0, 100.0, 200.0];
//! let plot = LinePlot::new(
//!     "friction along the rail",
//!     "distance from applicator d [m]",
//!     Panel::new("coefficient of friction mu [-]")
//!         .series(Series::new("after pass 100", d.clone(), vec![0.28, 0.33, 0.45]).colour(Colour::BLUE))
//!         .series(Series::new("before", d, vec![0.30, 0.36, 0.47]).dashed())
//!         .reference_line(ReferenceLine::new(0.58, "muD"))
//!         .y_range(0.0, 0.6),
//! );
//! plot.write_svg("friction.svg".as_ref())?;
//! # Ok::<(), anyhow::Error>(())
//! ```

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

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
    pub const PURPLE: Colour = Colour(148, 103, 189);
    pub const BROWN: Colour = Colour(140, 86, 75);

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

    fn rgb(self) -> RGBColor {
        RGBColor(self.0, self.1, self.2)
    }
}

/// How a series' line is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Stroke {
    #[default]
    Solid,
    Dashed,
    /// A dot of radius `width_px` at every point, unjoined: a scatter plot.
    Dots,
}

/// One line: `y[k]` over `x[k]`. Points where either is not finite are left
/// out (the line joins its neighbours).
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    /// The legend's text; an empty name keeps the series out of the legend.
    pub name: String,
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    /// `None`: the panel's palette colour for the series' position.
    pub colour: Option<Colour>,
    pub stroke: Stroke,
    pub width_px: u32,
}

impl Series {
    pub fn new(name: impl Into<String>, x: Vec<f64>, y: Vec<f64>) -> Self {
        Self {
            name: name.into(),
            x,
            y,
            colour: None,
            stroke: Stroke::Solid,
            width_px: 2,
        }
    }

    pub fn colour(mut self, colour: Colour) -> Self {
        self.colour = Some(colour);
        self
    }

    pub fn dashed(mut self) -> Self {
        self.stroke = Stroke::Dashed;
        self
    }

    /// Dots instead of a line (see [`Stroke::Dots`]).
    pub fn dots(mut self) -> Self {
        self.stroke = Stroke::Dots;
        self
    }

    pub fn width_px(mut self, width_px: u32) -> Self {
        self.width_px = width_px;
        self
    }
}

/// A thin grey horizontal line across the panel (a limiting value such as
/// mu_D, or a threshold), labelled just above it at the end of the panel
/// that the series leave free (the right one when both are).
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceLine {
    pub y: f64,
    pub label: String,
}

impl ReferenceLine {
    pub fn new(y: f64, label: impl Into<String>) -> Self {
        Self {
            y,
            label: label.into(),
        }
    }
}

/// Where a panel's legend goes, inside the plotting area.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Legend {
    /// The place of [`Legend::AUTO_ORDER`] that covers the least of the
    /// series, the reference lines and their labels.
    #[default]
    Auto,
    UpperLeft,
    UpperMiddle,
    UpperRight,
    MiddleLeft,
    MiddleRight,
    LowerLeft,
    LowerMiddle,
    LowerRight,
    /// No legend (a single series, or the title says it all).
    Hidden,
}

impl Legend {
    /// The places [`Legend::Auto`] tries, in order of preference.
    pub const AUTO_ORDER: [Legend; 8] = [
        Legend::UpperRight,
        Legend::LowerRight,
        Legend::UpperLeft,
        Legend::LowerLeft,
        Legend::MiddleRight,
        Legend::MiddleLeft,
        Legend::UpperMiddle,
        Legend::LowerMiddle,
    ];
}

/// One plotting area with its own y axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Panel {
    pub y_label: String,
    pub series: Vec<Series>,
    pub reference_lines: Vec<ReferenceLine>,
    /// `None`: the data's range (with the reference lines), padded by 5 %.
    /// Given: points outside are drawn on the border.
    pub y_range: Option<(f64, f64)>,
    pub legend: Legend,
}

impl Panel {
    pub fn new(y_label: impl Into<String>) -> Self {
        Self {
            y_label: y_label.into(),
            series: Vec::new(),
            reference_lines: Vec::new(),
            y_range: None,
            legend: Legend::default(),
        }
    }

    pub fn series(mut self, series: Series) -> Self {
        self.series.push(series);
        self
    }

    pub fn reference_line(mut self, line: ReferenceLine) -> Self {
        self.reference_lines.push(line);
        self
    }

    pub fn y_range(mut self, min: f64, max: f64) -> Self {
        self.y_range = Some((min, max));
        self
    }

    pub fn legend(mut self, legend: Legend) -> Self {
        self.legend = legend;
        self
    }

    fn data_y_range(&self) -> Option<(f64, f64)> {
        let ys = self
            .series
            .iter()
            .flat_map(|s| finite_points(s).map(|(_, y)| y));
        let ys = ys.chain(
            self.reference_lines
                .iter()
                .map(|r| r.y)
                .filter(|y| y.is_finite()),
        );
        min_max(ys).map(|(lo, hi)| pad(lo, hi))
    }
}

/// A figure: a title, panels stacked top to bottom sharing one x axis, and
/// the x axis label under the bottom panel.
#[derive(Debug, Clone, PartialEq)]
pub struct LinePlot {
    pub title: String,
    pub x_label: String,
    pub panels: Vec<Panel>,
    /// `None`: from the smallest to the largest x of all series.
    pub x_range: Option<(f64, f64)>,
    /// Width of the picture and height of one panel, in pixels.
    pub width_px: u32,
    pub panel_height_px: u32,
}

const FONT: &str = "sans-serif";
// Text sizes as plotters takes them (the SVG gets size / 1.24).
const TITLE_PX: u32 = 24;
const TICK_PX: u32 = 17;
const AXIS_DESC_PX: u32 = 19;
const LEGEND_PX: u32 = 17;
const LABEL_PX: u32 = 16;
/// Heights of the title above the panels and of the x axis label below.
const TITLE_AREA_PX: u32 = 44;
const X_DESC_AREA_PX: u32 = 26;

impl LinePlot {
    /// A figure with one panel.
    pub fn new(title: impl Into<String>, x_label: impl Into<String>, panel: Panel) -> Self {
        Self::stacked(title, x_label, vec![panel])
    }

    /// A figure with `panels` stacked top to bottom, sharing x.
    pub fn stacked(
        title: impl Into<String>,
        x_label: impl Into<String>,
        panels: Vec<Panel>,
    ) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            panels,
            x_range: None,
            width_px: 900,
            panel_height_px: 420,
        }
    }

    pub fn x_range(mut self, min: f64, max: f64) -> Self {
        self.x_range = Some((min, max));
        self
    }

    /// The figure as SVG text.
    pub fn render_svg(&self) -> Result<String> {
        if self.panels.is_empty() {
            bail!("plot \"{}\" has no panels", self.title);
        }
        for s in self.panels.iter().flat_map(|p| &p.series) {
            if s.x.len() != s.y.len() {
                bail!(
                    "series \"{}\" of plot \"{}\": {} x values but {} y values",
                    s.name,
                    self.title,
                    s.x.len(),
                    s.y.len()
                );
            }
        }
        let x_range = match self.x_range {
            Some(r) => checked_range(r, "x", &self.title)?,
            None => {
                let xs = self
                    .panels
                    .iter()
                    .flat_map(|p| &p.series)
                    .flat_map(|s| finite_points(s).map(|(x, _)| x));
                min_max(xs).map_or(
                    (0.0, 1.0),
                    |(lo, hi)| if lo < hi { (lo, hi) } else { pad(lo, hi) },
                )
            }
        };

        let n = self.panels.len() as u32;
        let height_px = TITLE_AREA_PX + n * self.panel_height_px + X_DESC_AREA_PX;
        let mut svg = String::new();
        {
            let root =
                SVGBackend::with_string(&mut svg, (self.width_px, height_px)).into_drawing_area();
            root.fill(&WHITE)?;
            let (title_area, mut rest) = root.split_vertically(TITLE_AREA_PX);
            let title_style = TextStyle::from((FONT, TITLE_PX).into_font())
                .pos(Pos::new(HPos::Center, VPos::Center));
            title_area.draw(&Text::new(
                self.title.clone(),
                (self.width_px as i32 / 2, TITLE_AREA_PX as i32 / 2 + 4),
                title_style,
            ))?;
            for (k, panel) in self.panels.iter().enumerate() {
                let area = if k + 1 == self.panels.len() {
                    rest.clone()
                } else {
                    let (top, below) = rest.split_vertically(self.panel_height_px);
                    rest = below;
                    top
                };
                // Only the bottom panel has the x axis label; the others
                // share it.
                let x_label = if k + 1 == self.panels.len() {
                    Some(self.x_label.as_str())
                } else {
                    None
                };
                draw_panel(&area, panel, x_range, x_label, &self.title)?;
            }
            root.present()?;
        }
        Ok(svg)
    }

    /// Writes the figure as an SVG file.
    pub fn write_svg(&self, path: &Path) -> Result<()> {
        let svg = self.render_svg()?;
        tortwin_outputs::files::write_atomically(path, svg.as_bytes())
    }
}

/// Draws one panel into `area`: axes, reference lines with their labels,
/// the series, and the legend where it hides the least.
fn draw_panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    panel: &Panel,
    (x0, x1): (f64, f64),
    x_label: Option<&str>,
    title: &str,
) -> Result<()> {
    let (y0, y1) = match panel.y_range {
        Some(r) => checked_range(r, "y", title)?,
        None => panel.data_y_range().unwrap_or((0.0, 1.0)),
    };
    let extra_px = if x_label.is_some() { X_DESC_AREA_PX } else { 0 };
    let mut chart = ChartBuilder::on(area)
        .margin_top(10)
        .margin_bottom(4)
        .margin_left(12)
        .margin_right(30)
        .x_label_area_size(30 + extra_px)
        .y_label_area_size(85)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    // A tick computed as a sum of steps lands a rounding error off 0.
    let x_ticks = |v: &f64| tick_label(snap_to_zero(*v, x1 - x0));
    let y_ticks = |v: &f64| tick_label(snap_to_zero(*v, y1 - y0));
    chart
        .configure_mesh()
        .x_desc(x_label.unwrap_or(""))
        .y_desc(&panel.y_label)
        .x_label_formatter(&x_ticks)
        .y_label_formatter(&y_ticks)
        .label_style((FONT, TICK_PX))
        .axis_desc_style((FONT, AXIS_DESC_PX))
        .bold_line_style(BLACK.mix(0.12))
        .light_line_style(BLACK.mix(0.04))
        .draw()?;

    // Everything the labels should not cover, in pixels of the plotting
    // area: the series and the reference lines, sampled every few pixels.
    let plotting_area = chart.plotting_area().clone();
    let (px, py) = plotting_area.get_pixel_range();
    let to_px = |x: f64, y: f64| {
        let (bx, by) = plotting_area.map_coordinate(&(x.clamp(x0, x1), y.clamp(y0, y1)));
        (bx - px.start, by - py.start)
    };
    let plot_w = px.end - px.start;
    let mut series_px = Vec::new();
    for s in &panel.series {
        let points: Vec<(i32, i32)> = finite_points(s).map(|(x, y)| to_px(x, y)).collect();
        match s.stroke {
            Stroke::Dots => series_px.extend(points),
            Stroke::Solid | Stroke::Dashed => densify(&points, &mut series_px),
        }
    }
    let mut lines_px = Vec::new();
    for line in &panel.reference_lines {
        densify(&[to_px(x0, line.y), to_px(x1, line.y)], &mut lines_px);
    }

    let plot = chart.plotting_area().strip_coord_spec();
    let grey = Colour::GREY.rgb();
    let mut label_boxes = Vec::new();
    for line in &panel.reference_lines {
        let y = line.y.clamp(y0, y1);
        chart.draw_series(LineSeries::new(
            [(x0, y), (x1, y)],
            ShapeStyle::from(grey).stroke_width(1),
        ))?;
        // Just above the line (below it when the line is at the top), at
        // whichever end the series leave free.
        let (_, y_px) = to_px(x0, y);
        let w = text_width_px(&line.label, LABEL_PX) + 6;
        let h = text_height_px(LABEL_PX) + 4;
        let (top, bottom) = if y_px - h >= 0 {
            (y_px - h, y_px - 1)
        } else {
            (y_px + 1, y_px + h)
        };
        let right = PixelBox {
            x0: plot_w - w,
            y0: top,
            x1: plot_w,
            y1: bottom,
        };
        let left = PixelBox {
            x0: 0,
            y0: top,
            x1: w,
            y1: bottom,
        };
        let at = if left.count(&series_px) < right.count(&series_px) {
            left
        } else {
            right
        };
        let style = TextStyle::from((FONT, LABEL_PX).into_font())
            .color(&grey)
            .pos(Pos::new(HPos::Left, VPos::Bottom));
        plot.draw(&Text::new(
            line.label.clone(),
            (at.x0 + 3, at.y1 - 2),
            style,
        ))?;
        label_boxes.push(at);
    }

    for (i, s) in panel.series.iter().enumerate() {
        let style = series_style(s, i);
        let points: Vec<(f64, f64)> = finite_points(s)
            .map(|(x, y)| (x.clamp(x0, x1), y.clamp(y0, y1)))
            .collect();
        match s.stroke {
            Stroke::Solid => chart.draw_series(LineSeries::new(points, style))?,
            Stroke::Dashed => {
                let (dash, gap) = dash_px(s.width_px);
                chart.draw_series(DashedLineSeries::new(points, dash, gap, style))?
            }
            Stroke::Dots => chart.draw_series(
                points
                    .into_iter()
                    .map(|p| Circle::new(p, s.width_px, style.filled())),
            )?,
        };
    }

    let entries: Vec<(usize, &Series)> = panel
        .series
        .iter()
        .enumerate()
        .filter(|(_, s)| !s.name.is_empty())
        .collect();
    if entries.is_empty() || panel.legend == Legend::Hidden {
        return Ok(());
    }
    let plot_h = py.end - py.start;
    let row_h = text_height_px(LEGEND_PX) + 6;
    let sample_w = 32;
    let text_w = entries
        .iter()
        .map(|(_, s)| text_width_px(&s.name, LEGEND_PX))
        .max()
        .unwrap_or(0);
    let (w, h) = (
        10 + sample_w + 8 + text_w + 10,
        8 + row_h * entries.len() as i32 + 4,
    );
    let inset = 10;
    let place = |legend: Legend| {
        let x = match legend {
            Legend::UpperLeft | Legend::MiddleLeft | Legend::LowerLeft => inset,
            Legend::UpperMiddle | Legend::LowerMiddle => (plot_w - w) / 2,
            _ => plot_w - w - inset,
        };
        let y = match legend {
            Legend::UpperLeft | Legend::UpperMiddle | Legend::UpperRight => inset,
            Legend::MiddleLeft | Legend::MiddleRight => (plot_h - h) / 2,
            _ => plot_h - h - inset,
        };
        PixelBox {
            x0: x,
            y0: y,
            x1: x + w,
            y1: y + h,
        }
    };
    let at = match panel.legend {
        Legend::Auto => {
            // The candidate that covers the fewest series samples; a
            // reference line through it counts a little, a reference
            // label a lot. Ties go to the earlier (more usual) place.
            let cost = |b: &PixelBox| {
                let labels = label_boxes.iter().filter(|l| l.overlaps(b)).count();
                b.count(&series_px) as f64
                    + 0.1 * b.count(&lines_px) as f64
                    + 1000.0 * labels as f64
            };
            Legend::AUTO_ORDER
                .iter()
                .map(|&l| place(l))
                .min_by(|a, b| cost(a).total_cmp(&cost(b)))
                .unwrap_or_else(|| place(Legend::UpperRight))
        }
        fixed => place(fixed),
    };
    plot.draw(&Rectangle::new(
        [(at.x0, at.y0), (at.x1, at.y1)],
        WHITE.mix(0.9).filled(),
    ))?;
    plot.draw(&Rectangle::new(
        [(at.x0, at.y0), (at.x1, at.y1)],
        BLACK.mix(0.3),
    ))?;
    let text_style =
        TextStyle::from((FONT, LEGEND_PX).into_font()).pos(Pos::new(HPos::Left, VPos::Center));
    for (row, (i, s)) in entries.iter().enumerate() {
        let y = at.y0 + 8 + row_h * row as i32 + row_h / 2;
        let (xa, xb) = (at.x0 + 10, at.x0 + 10 + sample_w);
        let style = series_style(s, *i);
        match s.stroke {
            Stroke::Solid => plot.draw(&PathElement::new(vec![(xa, y), (xb, y)], style))?,
            Stroke::Dashed => {
                let (dash, gap) = dash_px(s.width_px);
                plot.draw(&DashedPathElement::new(
                    vec![(xa, y), (xb, y)],
                    dash,
                    gap,
                    style,
                ))?
            }
            Stroke::Dots => plot.draw(&Circle::new(
                ((xa + xb) / 2, y),
                s.width_px.max(3),
                style.filled(),
            ))?,
        }
        plot.draw(&Text::new(s.name.clone(), (xb + 8, y), text_style.clone()))?;
    }
    Ok(())
}

/// A rectangle in pixels of a plotting area, y downwards.
#[derive(Debug, Clone, Copy)]
struct PixelBox {
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
}

impl PixelBox {
    fn contains(&self, (x, y): (i32, i32)) -> bool {
        (self.x0..=self.x1).contains(&x) && (self.y0..=self.y1).contains(&y)
    }

    fn count(&self, points: &[(i32, i32)]) -> usize {
        points.iter().filter(|&&p| self.contains(p)).count()
    }

    fn overlaps(&self, o: &PixelBox) -> bool {
        self.x0 <= o.x1 && o.x0 <= self.x1 && self.y0 <= o.y1 && o.y0 <= self.y1
    }
}

/// The polyline's points with extra points at most 3 px apart, so that a
/// long straight segment through a box is seen.
fn densify(points: &[(i32, i32)], out: &mut Vec<(i32, i32)>) {
    out.extend(points.first());
    for pair in points.windows(2) {
        let ((xa, ya), (xb, yb)) = (pair[0], pair[1]);
        let len = f64::from(xb - xa).hypot(f64::from(yb - ya));
        let steps = (len / 3.0).ceil().max(1.0) as i32;
        for k in 1..=steps {
            let t = f64::from(k) / f64::from(steps);
            out.push((
                xa + (f64::from(xb - xa) * t).round() as i32,
                ya + (f64::from(yb - ya) * t).round() as i32,
            ));
        }
    }
}

fn series_style(s: &Series, i: usize) -> ShapeStyle {
    ShapeStyle::from(s.colour.unwrap_or_else(|| Colour::palette(i)).rgb()).stroke_width(s.width_px)
}

/// Dash and gap lengths that stay visible as the line gets wider.
fn dash_px(width_px: u32) -> (i32, i32) {
    let w = width_px.min(20) as i32;
    (6 + 2 * w, 3 + 2 * w)
}

/// The SVG backend writes a font size of `size / 1.24`; a sans-serif glyph
/// is on average a little over half as wide as the font size. Generous, so
/// that a box drawn around text holds it in any common sans-serif font.
fn text_width_px(text: &str, size: u32) -> i32 {
    (text.chars().count() as f64 * 0.6 * f64::from(size) / 1.24).ceil() as i32
}

fn text_height_px(size: u32) -> i32 {
    (f64::from(size) / 1.24 * 1.2).ceil() as i32
}

/// A tick value without float noise: 500 not 500.0, 0.3 not
/// 0.30000000000000004, and very small or large values in e notation.
fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e7).contains(&a) {
        return format!("{v:.2e}");
    }
    let text = format!("{v:.6}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// 0 for a value within a billionth of the axis span of it.
fn snap_to_zero(v: f64, span: f64) -> f64 {
    if v.abs() <= 1e-9 * span.abs() {
        0.0
    } else {
        v
    }
}

fn finite_points(s: &Series) -> impl Iterator<Item = (f64, f64)> + '_ {
    s.x.iter()
        .zip(&s.y)
        .map(|(&x, &y)| (x, y))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
}

fn min_max(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// 5 % of the span on each side; a flat line gets a span of its own.
fn pad(lo: f64, hi: f64) -> (f64, f64) {
    let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
    (lo - 0.05 * span, hi + 0.05 * span)
}

fn checked_range((lo, hi): (f64, f64), axis: &str, title: &str) -> Result<(f64, f64)> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        bail!("plot \"{title}\": the {axis} range {lo}..{hi} is empty or not finite");
    }
    Ok((lo, hi))
}

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
/// use crate::Heatmap;
/// let masses = vec!["0.5 g".to_string(), "1.0 g".to_string()];
/// let intervals = vec!["1 train".to_string(), "2 trains".to_string(), "4 trains".to_string()];
/// let coverage = vec![vec![0.41, 0.35, 0.22], vec![0.78, 0.66, f64::NAN]];
/// Heatmap::new("coverage", "pulse interval", "pulse mass", intervals, masses, coverage)
///     .value_label("share of contacts in band [%]")
///     .range(0.0, 1.0)
///     .cell_text(|v| format!("{:.0}", 100.0 * v))
///     .highlight(1, 0)
///     .write_svg("coverage.svg".as_ref())?;
/// # Ok::<(), anyhow::Error>(())
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
const NOT_EVALUATED: Colour = Colour(221, 221, 221);

/// viridis at 0, 1/8, ..., 1 (R's `viridis(9)`, the same map as
/// matplotlib's); linear interpolation between neighbours stays within a
/// unit or two of the full 256-entry table.
const VIRIDIS: [Colour; 9] = [
    Colour(0x44, 0x01, 0x54),
    Colour(0x47, 0x2D, 0x7B),
    Colour(0x3B, 0x52, 0x8B),
    Colour(0x2C, 0x72, 0x8E),
    Colour(0x21, 0x90, 0x8C),
    Colour(0x27, 0xAD, 0x81),
    Colour(0x5D, 0xC8, 0x63),
    Colour(0xAA, 0xDC, 0x32),
    Colour(0xFD, 0xE7, 0x25),
];

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

    /// Outline one cell (row, col) with a thick black border, e.g. the
    /// recommended strategy.
    /// What the grey (NaN) cells mean (default "not evaluated").
    pub fn missing_label(mut self, label: impl Into<String>) -> Self {
        self.missing_label = label.into();
        self
    }

    pub fn highlight(mut self, row: usize, col: usize) -> Self {
        self.highlight = Some((row, col));
        self
    }

    /// The figure as SVG text. An error says what is wrong with the grid
    /// (its shape, the range, the highlighted cell, or a picture too small
    /// for it).
    pub fn render_svg(&self) -> Result<String> {
        let (lo, hi) = self.colour_range()?;
        let grid = self.layout(lo, hi)?;
        let (w, h) = (self.width_px as i32, self.height_px as i32);
        let n_rows = self.y_categories.len();
        let n_cols = self.x_categories.len();
        let colour_of = |v: f64| viridis((v - lo) / (hi - lo));

        let mut svg = String::new();
        {
            let root = SVGBackend::with_string(&mut svg, (self.width_px, self.height_px))
                .into_drawing_area();
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
            let tick_style =
                TextStyle::from(tick_font.clone()).pos(Pos::new(HPos::Left, VPos::Center));
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
            root.present()?;
        }
        Ok(svg)
    }

    /// Writes the figure as an SVG file (whole or not at all, see
    /// [`tortwin_outputs::files`]).
    pub fn write_svg(&self, path: &Path) -> Result<()> {
        let svg = self
            .render_svg()
            .with_context(|| format!("cannot write {}", path.display()))?;
        tortwin_outputs::files::write_atomically(path, svg.as_bytes())
    }

    /// Checks the grid's shape and the highlighted cell, and gives the
    /// colour range.
    fn colour_range(&self) -> Result<(f64, f64)> {
        let title = &self.title;
        let (n_rows, n_cols) = (self.y_categories.len(), self.x_categories.len());
        if n_rows == 0 || n_cols == 0 {
            bail!(
                "heatmap \"{title}\" needs at least one category on each axis, \
                 has {n_cols} x and {n_rows} y categories"
            );
        }
        if self.values.len() != n_rows {
            bail!(
                "heatmap \"{title}\": {} rows of values for {n_rows} y categories",
                self.values.len()
            );
        }
        for (row, (values, name)) in self.values.iter().zip(&self.y_categories).enumerate() {
            if values.len() != n_cols {
                bail!(
                    "heatmap \"{title}\": row {row} ({name}) has {} values for {n_cols} x categories",
                    values.len()
                );
            }
        }
        if let Some((row, col)) = self.highlight {
            if row >= n_rows || col >= n_cols {
                bail!(
                    "heatmap \"{title}\": the highlighted cell (row {row}, col {col}) \
                     is outside the grid of {n_rows} rows and {n_cols} columns"
                );
            }
        }
        match self.range {
            Some(r) => checked_range(r, "colour", title),
            None => {
                let finite = self
                    .values
                    .iter()
                    .flatten()
                    .copied()
                    .filter(|v| v.is_finite());
                Ok(min_max(finite).map_or(
                    (0.0, 1.0),
                    |(lo, hi)| {
                        if lo < hi {
                            (lo, hi)
                        } else {
                            pad(lo, hi)
                        }
                    },
                ))
            }
        }
    }

    /// Where everything goes: the margins take what the labels need, the
    /// cells share the rest equally.
    fn layout(&self, lo: f64, hi: f64) -> Result<HeatmapGrid> {
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
            bail!(
                "heatmap \"{}\": {}x{} px is too small for {n_cols} x {n_rows} categories \
                 (cells of {cell_w}x{cell_h} px)",
                self.title,
                self.width_px,
                self.height_px
            );
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

/// viridis at `t` in 0..=1 (clamped; NaN gives the low end).
fn viridis(t: f64) -> Colour {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    let mix = |p: u8, q: u8| (f64::from(p) + f * (f64::from(q) - f64::from(p))).round() as u8;
    Colour(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// Black or white, whichever contrasts more with `background` (WCAG's
/// contrast ratio of relative luminances).
fn text_colour_on(background: Colour) -> Colour {
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

/// CSV text: the header, then one line per row, each value in Rust's
/// shortest round-trip form (`{}` of f64), so reading the file back gives
/// the same bits. Every row must have as many values as the header.
pub fn csv_text<R: AsRef<[f64]>>(
    header: &[&str],
    rows: impl IntoIterator<Item = R>,
) -> Result<String> {
    let mut out = header.join(",");
    out.push('\n');
    for (k, row) in rows.into_iter().enumerate() {
        let row = row.as_ref();
        if row.len() != header.len() {
            bail!(
                "CSV row {k} has {} values for {} columns ({})",
                row.len(),
                header.len(),
                header.join(",")
            );
        }
        for (j, v) in row.iter().enumerate() {
            if j > 0 {
                out.push(',');
            }
            // Writing to a String cannot fail.
            let _ = write!(out, "{v}");
        }
        out.push('\n');
    }
    Ok(out)
}

/// Writes [`csv_text`] to `path`.
pub fn write_csv<R: AsRef<[f64]>>(
    path: &Path,
    header: &[&str],
    rows: impl IntoIterator<Item = R>,
) -> Result<()> {
    let text =
        csv_text(header, rows).with_context(|| format!("cannot write {}", path.display()))?;
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Writes columns of equal length as a CSV file: `(name, values)` in order.
pub fn write_csv_columns(path: &Path, columns: &[(&str, &[f64])]) -> Result<()> {
    let len = columns.first().map_or(0, |(_, c)| c.len());
    if let Some((name, c)) = columns.iter().find(|(_, c)| c.len() != len) {
        bail!(
            "cannot write {}: column {name} has {} values, the first has {len}",
            path.display(),
            c.len()
        );
    }
    let header: Vec<&str> = columns.iter().map(|(name, _)| *name).collect();
    let rows = (0..len).map(|i| columns.iter().map(|(_, c)| c[i]).collect::<Vec<f64>>());
    write_csv(path, &header, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips_f64() {
        let values = [0.1 + 0.2, 1e-300, -2.5, 1.0 / 3.0];
        let text = csv_text(
            &["a", "b"],
            [[values[0], values[1]], [values[2], values[3]]],
        )
        .unwrap();
        let parsed: Vec<f64> = text
            .lines()
            .skip(1)
            .flat_map(|l| l.split(','))
            .map(|v| v.parse().unwrap())
            .collect();
        assert_eq!(parsed, values);
        assert!(text.starts_with("a,b\n"));
    }

    #[test]
    fn csv_refuses_ragged_rows() {
        assert!(csv_text(&["a", "b"], [vec![1.0]]).is_err());
    }

    #[test]
    fn svg_has_labels_and_legend() {
        let x = vec![0.0, 1.0, 2.0];
        let plot = LinePlot::stacked(
            "two panels",
            "distance d [m]",
            vec![
                Panel::new("mass [mg]").series(Series::new("rail", x.clone(), vec![3.0, 2.0, 1.0])),
                Panel::new("mu [-]")
                    .series(Series::new("dashed one", x.clone(), vec![0.2, f64::NAN, 0.4]).dashed())
                    .series(Series::new("dots", x, vec![0.25, 0.3, 0.35]).dots())
                    .reference_line(ReferenceLine::new(0.58, "muD")),
            ],
        );
        let svg = plot.render_svg().unwrap();
        for text in [
            "two panels",
            "distance d [m]",
            "mass [mg]",
            "mu [-]",
            "rail",
            "dashed one",
            "dots",
            "muD",
        ] {
            assert!(svg.contains(text), "{text} missing");
        }
        // Three dots in the panel and one in the legend.
        assert!(svg.matches("<circle").count() >= 4, "dots missing");
    }

    #[test]
    fn tick_labels_have_no_float_noise() {
        assert_eq!(tick_label(500.0), "500");
        assert_eq!(tick_label(0.1 + 0.2), "0.3");
        assert_eq!(tick_label(-2.5), "-2.5");
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(1.5e-6), "1.50e-6");
        assert_eq!(tick_label(snap_to_zero(-0.15 + 3.0 * 0.05, 0.3)), "0");
        assert_eq!(tick_label(snap_to_zero(1.5e-6, 3e-6)), "1.50e-6");
    }

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
    fn viridis_ends_and_text_contrast() {
        assert_eq!(viridis(0.0), Colour(68, 1, 84));
        assert_eq!(viridis(1.0), Colour(253, 231, 37));
        assert_eq!(viridis(0.5), Colour(0x21, 0x90, 0x8C));
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
        assert_eq!(text_colour_on(NOT_EVALUATED), Colour::BLACK);
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
        assert_eq!(at(1.20).fill, "#FDE725");
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

    #[test]
    fn mismatched_series_is_an_error() {
        let plot = LinePlot::new(
            "t",
            "x",
            Panel::new("y").series(Series::new("s", vec![0.0], vec![])),
        );
        assert!(plot.render_svg().is_err());
    }
}
