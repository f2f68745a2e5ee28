//! Line plots: a [`LinePlot`] is one or more [`Panel`]s stacked vertically
//! that share the x axis (the paper's Figure 13: masses on one panel, mu on
//! the other). A panel holds [`Series`] (solid, dashed or dots, in a
//! colour), thin horizontal [`ReferenceLine`]s (mu_C and mu_D in Figure 7)
//! and a [`Legend`], placed by default where it covers the least of the
//! data.

use std::path::Path;

use plotters::element::DashedPathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use crate::axis::{checked_range, data_range, min_max, pad, snap_to_zero, tick_label};
use crate::colour::Colour;
use crate::error::{DrawError, PlotError};
use crate::layout::{
    text_height_px, text_width_px, PixelBox, AXIS_DESC_PX, FONT, LABEL_PX, LEGEND_PX, TICK_PX,
    TITLE_AREA_PX, TITLE_PX, X_DESC_AREA_PX,
};

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
    /// The place of `Legend::AUTO_ORDER` that covers the least of the
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
    pub(crate) const AUTO_ORDER: [Legend; 8] = [
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

    /// The figure as SVG text. An error says what cannot be drawn (no
    /// panels, a series with more x than y values, an empty range).
    pub fn render_svg(&self) -> Result<String, PlotError> {
        if self.panels.is_empty() {
            return Err(PlotError::NoPanels {
                title: self.title.clone(),
            });
        }
        for s in self.panels.iter().flat_map(|p| &p.series) {
            if s.x.len() != s.y.len() {
                return Err(PlotError::SeriesLengths {
                    title: self.title.clone(),
                    series: s.name.clone(),
                    x: s.x.len(),
                    y: s.y.len(),
                });
            }
        }
        let x_range = match self.x_range {
            Some(r) => checked_range(r, "x", &self.title)?,
            None => data_range(
                self.panels
                    .iter()
                    .flat_map(|p| &p.series)
                    .flat_map(|s| finite_points(s).map(|(x, _)| x)),
            ),
        };
        let y_ranges = self
            .panels
            .iter()
            .map(|panel| match panel.y_range {
                Some(r) => checked_range(r, "y", &self.title),
                None => Ok(panel.data_y_range().unwrap_or((0.0, 1.0))),
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mut svg = String::new();
        self.draw(&mut svg, x_range, &y_ranges)
            .map_err(|source| PlotError::Draw {
                title: self.title.clone(),
                source,
            })?;
        Ok(svg)
    }

    /// Writes the figure as an SVG file (whole or not at all, see
    /// [`tortwin_files`]).
    pub fn write_svg(&self, path: &Path) -> Result<(), PlotError> {
        let svg = self.render_svg().map_err(|e| e.for_file(path))?;
        tortwin_files::write_atomically(path, svg.as_bytes())?;
        Ok(())
    }

    /// Draws the checked figure: the title, then the panels top to bottom.
    fn draw(
        &self,
        svg: &mut String,
        x_range: (f64, f64),
        y_ranges: &[(f64, f64)],
    ) -> Result<(), DrawError> {
        let n = self.panels.len() as u32;
        let height_px = TITLE_AREA_PX + n * self.panel_height_px + X_DESC_AREA_PX;
        let root = SVGBackend::with_string(svg, (self.width_px, height_px)).into_drawing_area();
        root.fill(&WHITE)?;
        let (title_area, mut rest) = root.split_vertically(TITLE_AREA_PX);
        let title_style =
            TextStyle::from((FONT, TITLE_PX).into_font()).pos(Pos::new(HPos::Center, VPos::Center));
        title_area.draw(&Text::new(
            self.title.clone(),
            (self.width_px as i32 / 2, TITLE_AREA_PX as i32 / 2 + 4),
            title_style,
        ))?;
        for (k, (panel, &y_range)) in self.panels.iter().zip(y_ranges).enumerate() {
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
            draw_panel(&area, panel, x_range, y_range, x_label)?;
        }
        root.present()
    }
}

/// Draws one panel into `area`: axes, reference lines with their labels,
/// the series, and the legend where it hides the least.
fn draw_panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    panel: &Panel,
    (x0, x1): (f64, f64),
    (y0, y1): (f64, f64),
    x_label: Option<&str>,
) -> Result<(), DrawError> {
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

fn finite_points(s: &Series) -> impl Iterator<Item = (f64, f64)> + '_ {
    s.x.iter()
        .zip(&s.y)
        .map(|(&x, &y)| (x, y))
        .filter(|(x, y)| x.is_finite() && y.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

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
    fn mismatched_series_is_an_error() {
        let plot = LinePlot::new(
            "t",
            "x",
            Panel::new("y").series(Series::new("s", vec![0.0], vec![])),
        );
        assert!(plot.render_svg().is_err());
    }
}
