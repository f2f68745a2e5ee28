//! `tortwin import` and `tortwin export`: a section's logs as CSV tables
//! in, the twin's results as Parquet and CSV tables out
//! (docs/spec/csv-tables.md).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use tortwin_engine::sink::{RunSummary, Sink};
use tortwin_files::usage::UsageError;
use tortwin_outputs::files::{make_folder, write_atomically};
use tortwin_outputs::provenance::Provenance;
use tortwin_outputs::tables::{Formats, TableOptions, TableSink};
use tortwin_recording::tables::export::{export_dir, ExportSummary};
use tortwin_recording::tables::format_time;
use tortwin_recording::tables::import::{import_dir, ImportSummary};

use super::replay::ReplayArgs;
use tortwin_study::progress::Progress;
use tortwin_study::{Error, Result};

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct ImportArgs {
    /// The folder of tables: section.toml and passages.csv, and any of
    /// pulses.csv, weather.csv, measurements.csv (docs/spec/csv-tables.md).
    pub tables: PathBuf,
    /// The recording to write (MCAP); its folder is made if missing.
    #[cfg_attr(feature = "cli", arg(long))]
    pub out: PathBuf,
    /// Do not print the summary.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

/// Which table files `export` writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum TableFormat {
    /// Parquet (typed columns, UTC timestamps; pandas, DuckDB, Spark).
    Parquet,
    /// CSV (RFC 3339 times; spreadsheets).
    Csv,
    /// Both.
    #[default]
    Both,
}

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct ExportArgs {
    /// The recording to replay (MCAP).
    pub recording: PathBuf,
    /// The folder to write the tables into (made if missing).
    #[cfg_attr(feature = "cli", arg(long))]
    pub out: PathBuf,
    /// Model configuration overlaid on the built-in defaults (TOML; only
    /// the keys it changes, e.g. a `tortwin discover` model.toml).
    #[cfg_attr(feature = "cli", arg(long))]
    pub config: Option<super::ConfigSource>,
    /// The files to write.
    #[cfg_attr(feature = "cli", arg(long, value_enum, default_value_t = TableFormat::Both))]
    pub format: TableFormat,
    /// Leave out the field table (one row per grid point per train and
    /// rail: by far the largest).
    #[cfg_attr(feature = "cli", arg(long))]
    pub no_field: bool,
    /// Lower end of the target band of mu, for the trains table's
    /// share_in_band and share_below_band.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.30))]
    pub band_lower: f64,
    /// Upper end of the target band of mu.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.40))]
    pub band_upper: f64,
    /// Also write the recording's own inputs as the tables `tortwin import`
    /// reads, into OUT/inputs/.
    #[cfg_attr(feature = "cli", arg(long))]
    pub inputs: bool,
    /// Do not print the summary.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

impl ExportArgs {
    /// Both formats, every table, the default band; set what a caller needs.
    pub fn new(recording: impl Into<PathBuf>, out: impl Into<PathBuf>) -> Self {
        Self {
            recording: recording.into(),
            out: out.into(),
            config: None,
            format: TableFormat::Both,
            no_field: false,
            band_lower: 0.30,
            band_upper: 0.40,
            inputs: false,
            quiet: true,
        }
    }
}

/// Builds the recording `args.out` from the tables in `args.tables`.
pub fn import(args: &ImportArgs, progress: &dyn Progress) -> Result<ImportSummary> {
    let _inputs = tortwin_outputs::files::InputScope::enter();
    if !args.tables.is_dir() {
        return Err(UsageError(format!(
            "{}: not a folder of tables (section.toml, passages.csv, ...)",
            args.tables.display()
        ))
        .into());
    }
    if let Some(folder) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        make_folder(folder)?;
    }
    progress.stage(&format!("reading the tables in {}", args.tables.display()));
    Ok(import_dir(&args.tables, &args.out)?)
}

/// What `export` wrote.
#[derive(Debug, Clone)]
pub struct Exported {
    pub run: RunSummary,
    /// The files written, in `args.out`.
    pub files: Vec<String>,
    /// The input tables, with `--inputs`.
    pub inputs: Option<ExportSummary>,
}

/// Replays `args.recording` into the tables of `args.out`.
pub fn export(args: &ExportArgs, progress: &dyn Progress) -> Result<Exported> {
    let band = (args.band_lower, args.band_upper);
    if !(band.0.is_finite() && band.1.is_finite() && 0.0 <= band.0 && band.0 < band.1) {
        return Err(UsageError(format!(
            "--band-lower {} --band-upper {}: need 0 <= lower < upper",
            band.0, band.1
        ))
        .into());
    }
    if args.out.is_file() {
        return Err(UsageError(format!(
            "--out {}: is a file; it must be a folder (made if missing)",
            args.out.display()
        ))
        .into());
    }
    // The inputs are known before the first table is made: none of the
    // tables may be one of them (tortwin_files::output_target).
    let _inputs = tortwin_outputs::files::InputScope::enter();
    tortwin_outputs::files::check_input(&args.recording).map_err(|e| {
        tortwin_recording::error::InputError::file(
            &args.recording,
            format!("cannot open the recording: {e}"),
        )
    })?;
    super::load_config(args.config.as_ref())?;
    make_folder(&args.out)?;
    let options = TableOptions {
        formats: Formats {
            parquet: args.format != TableFormat::Csv,
            csv: args.format != TableFormat::Parquet,
            memory: false,
        },
        band,
        field: !args.no_field,
    };
    let mut files = TableSink::file_names(&options);
    let mut sink = TableSink::create(&args.out, options)?;
    let replay = ReplayArgs {
        config: args.config.clone(),
        ..ReplayArgs::new(&args.recording)
    };
    let run =
        super::replay::replay(&replay, None, &mut [&mut sink as &mut dyn Sink], progress)?.summary;

    let mut inputs = vec![args.recording.as_path()];
    inputs.extend(args.config.as_ref().and_then(super::ConfigSource::path));
    let config = super::load_config(args.config.as_ref())?;
    let provenance = Provenance::of_run(&inputs, &config)?;
    let json = serde_json::to_string_pretty(&provenance).map_err(|source| Error::Json {
        what: "the provenance",
        source,
    })?;
    write_atomically(&args.out.join("provenance.json"), json.as_bytes())?;
    files.push("provenance.json".into());

    let inputs = if args.inputs {
        let dir = args.out.join("inputs");
        progress.stage(&format!(
            "writing the inputs as tables in {}",
            dir.display()
        ));
        Some(export_dir(&args.recording, &dir)?)
    } else {
        None
    };
    Ok(Exported { run, files, inputs })
}

/// The few lines `import` prints.
pub fn render_import(args: &ImportArgs, s: &ImportSummary) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "imported {} into {}",
        args.tables.display(),
        args.out.display()
    );
    let _ = writeln!(
        out,
        "  trains {}, axles {}, pulses {}, weather messages {}, measurements {}",
        s.trains, s.axles, s.pulses, s.weather, s.measurements
    );
    let _ = writeln!(
        out,
        "  from {} to {}",
        format_time(s.first_ns),
        format_time(s.last_ns)
    );
    let _ = writeln!(
        out,
        "replay it with: tortwin replay {} --out-rrd out/imported.rrd",
        args.out.display()
    );
    out
}

/// The few lines `export` prints.
pub fn render_export(args: &ExportArgs, e: &Exported) -> String {
    let mut out = super::summary::render(&args.recording, &e.run);
    let _ = writeln!(out, "tables in {}:", args.out.display());
    for name in &e.files {
        let _ = writeln!(out, "  {name}");
    }
    if let Some(s) = &e.inputs {
        let _ = writeln!(
            out,
            "  inputs/ (trains {}, axles {}, pulses {}, weather {}, measurements {}): \
             `tortwin import {} --out REC.mcap` makes the recording again",
            s.trains,
            s.axles,
            s.pulses,
            s.weather,
            s.measurements,
            Path::new(&args.out).join("inputs").display()
        );
    }
    if args.format != TableFormat::Csv {
        let _ = writeln!(
            out,
            "read them with: python3 -c \"import pandas; print(pandas.read_parquet('{}'))\"",
            args.out.join("measurements.parquet").display()
        );
    }
    out
}
