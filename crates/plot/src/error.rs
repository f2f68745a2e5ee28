//! Why a figure or a table could not be made or written. A figure's errors
//! name it by its title; a write's name the file.

use std::path::PathBuf;

use tortwin_files::FileError;

/// What plotters reports when drawing into SVG text fails.
pub type DrawError = plotters::drawing::DrawingAreaErrorKind<std::io::Error>;

/// A figure that cannot be drawn, a table that cannot be written, or a file
/// that cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("plot \"{title}\" has no panels")]
    NoPanels { title: String },
    #[error("series \"{series}\" of plot \"{title}\": {x} x values but {y} y values")]
    SeriesLengths {
        title: String,
        series: String,
        x: usize,
        y: usize,
    },
    /// A given range (`axis` is "x", "y" or "colour").
    #[error("plot \"{title}\": the {axis} range {lo}..{hi} is empty or not finite")]
    Range {
        title: String,
        axis: &'static str,
        lo: f64,
        hi: f64,
    },
    #[error(
        "heatmap \"{title}\" needs at least one category on each axis, \
         has {x} x and {y} y categories"
    )]
    NoCategories { title: String, x: usize, y: usize },
    #[error("heatmap \"{title}\": {rows} rows of values for {y} y categories")]
    RowCount {
        title: String,
        rows: usize,
        y: usize,
    },
    #[error("heatmap \"{title}\": row {row} ({name}) has {values} values for {x} x categories")]
    RowLength {
        title: String,
        row: usize,
        name: String,
        values: usize,
        x: usize,
    },
    #[error(
        "heatmap \"{title}\": the highlighted cell (row {row}, col {col}) \
         is outside the grid of {rows} rows and {cols} columns"
    )]
    HighlightOutside {
        title: String,
        row: usize,
        col: usize,
        rows: usize,
        cols: usize,
    },
    /// Cells too small for a line of the smallest text: make the picture
    /// larger.
    #[error(
        "heatmap \"{title}\": {width_px}x{height_px} px is too small for {cols} x {rows} \
         categories (cells of {cell_w_px}x{cell_h_px} px)"
    )]
    TooSmall {
        title: String,
        width_px: u32,
        height_px: u32,
        cols: usize,
        rows: usize,
        cell_w_px: i32,
        cell_h_px: i32,
    },
    /// plotters failed (it reports a layout it cannot make this way).
    #[error("plot \"{title}\": drawing failed")]
    Draw {
        title: String,
        #[source]
        source: DrawError,
    },
    #[error("CSV row {row} has {values} values for {columns} columns ({header})")]
    CsvRow {
        row: usize,
        values: usize,
        columns: usize,
        header: String,
    },
    #[error("CSV column {name} has {values} values, the first has {first}")]
    CsvColumn {
        name: String,
        values: usize,
        first: usize,
    },
    /// The figure or table for `path` could not be made (the source says
    /// why); nothing was written.
    #[error("cannot write {}", path.display())]
    Unwritten {
        path: PathBuf,
        #[source]
        source: Box<PlotError>,
    },
    /// Writing the file failed (the error names it).
    #[error(transparent)]
    File(#[from] FileError),
}

impl PlotError {
    /// Whether the user asked for the impossible: a file in an output
    /// folder that cannot be made (`tortwin_files::FileError::is_input`).
    pub fn is_input(&self) -> bool {
        match self {
            PlotError::File(e) => e.is_input(),
            PlotError::Unwritten { source, .. } => source.is_input(),
            _ => false,
        }
    }

    /// `self` as the reason `path` was not written.
    pub(crate) fn for_file(self, path: &std::path::Path) -> PlotError {
        PlotError::Unwritten {
            path: path.to_path_buf(),
            source: Box::new(self),
        }
    }
}
