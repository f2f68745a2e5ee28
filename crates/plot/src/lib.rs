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
//! Units belong in the axis labels: "distance from applicator d \[m\]".
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
//! # Ok::<(), tortwin_plot::PlotError>(())
//! ```
//!
//! The files: `line.rs` the line plots, `heatmap.rs` the heatmaps, `csv.rs`
//! the tables; what both kinds of figure share is in `colour.rs` (the
//! palette, the colour map, text on a fill), `axis.rs` (ranges and tick
//! labels) and `layout.rs` (fonts, text sizes, boxes in pixels).
//! `error.rs`: [`PlotError`], what cannot be drawn or written, naming the
//! plot by its title and a file by its path. Files are written whole or
//! not at all ([`tortwin_files`]).

mod axis;
mod colour;
mod csv;
mod error;
mod heatmap;
mod layout;
mod line;

pub use colour::Colour;
pub use csv::{csv_text, write_csv, write_csv_columns};
pub use error::{DrawError, PlotError};
pub use heatmap::Heatmap;
pub use line::{Legend, LinePlot, Panel, ReferenceLine, Series, Stroke};
