//! rerun output sink: the twin's results as an `.rrd` a railway engineer
//! opens in the rerun viewer (rerun 0.36).
//!
//! # Timelines
//! - `time` (timestamp): the event's log_time. The viewer opens on it.
//! - `wheel_pass` (sequence): wheels that have rolled over the section so far,
//!   the largest [`FieldSnapshot::wheel_pass`] seen. Scrubbing it steps
//!   through the run train by train (or wheel by wheel).
//!
//! Field snapshots and trains are logged on both. Pulses and measurements are
//! logged on `time` only: several of them fall between two snapshots, where
//! `wheel_pass` does not advance, so on that timeline a whole train's
//! measurements would stack at one abscissa. The SDK's automatic `log_time` /
//! `log_tick` timelines are switched off: they would record when the twin
//! ran, not when the trains did.
//!
//! # Memory and size
//! Memory grows with the section, not with the recording, and a month of
//! traffic (1200 trains on a 1.5 km curve) is a file of about 40 MB:
//! - what is logged at every snapshot, pulse or measurement (the profiles,
//!   hundreds of thousands of series values a month) is not logged row by
//!   row: the sink buffers it and sends it as columns
//!   ([`RecordingStream::send_columns`]), a chunk per entity of
//!   [`SERIES_CHUNK_ROWS`] values or, for the profiles, about
//!   [`BATCH_CHUNK_BYTES`], and the rest at [`Sink::finish`]. A row logged
//!   through the SDK's batcher costs several times its data while it waits
//!   (its own arrays and arrow types), and the batcher fell behind the
//!   engine: the backlog, and the process, grew with the length of the run;
//! - the heatmaps are logged every [`RerunOptions::history_every`] trains
//!   and after the last train, not at every train: each log is the whole
//!   `K * N` heatmap, and at every train they made most of the file;
//! - the profiles are stored as f32 (seven significant digits, far below
//!   what a bar chart shows; the exact values are in the MCAP output): as
//!   f64 they were the bulk of a long run's file once the heatmaps were not;
//! - what still goes through the batcher (trains, heatmaps, static data) is
//!   cut into chunks by size ([`BATCH_CHUNK_BYTES`], about the viewer's own
//!   chunk size, or [`SERIES_CHUNK_ROWS`] rows), not every 200 ms of wall
//!   clock, and the SDK's queues hold at most [`MAX_BYTES_IN_FLIGHT`]: few
//!   large chunks (the file's footer keeps an entry per chunk until the
//!   end) and a file that does not depend on how fast the machine ran.
//!
//! The sink's own collections are bounded by the section: a style flag per
//! series, the sites' quantities and rails, the applicators, up to
//! [`SERIES_CHUNK_ROWS`] values per series, about [`BATCH_CHUNK_BYTES`] of
//! profiles per quantity and track, and `K` rows of f16 per heatmap.
//!
//! # Entity layout
//! Rail and band names are taken verbatim (escaped by [`EntityPath`]).
//!
//! | entity                                  | archetype                 | logged        |
//! |-----------------------------------------|---------------------------|---------------|
//! | `section/description`                   | `TextDocument` (markdown) | static        |
//! | `section/map/rails`                     | `LineStrips2D`            | static        |
//! | `section/map/applicators`, `…/sites`    | `Points2D` with labels    | static        |
//! | `field/<rail>/<band>/mu`                | `BarChart` (f32)          | every snapshot (sent in columns) |
//! | `field/<rail>/<band>/adhesion`          | `BarChart` (T/N, f32)     | every snapshot (sent in columns) |
//! | `field/<rail>/<band>/rail_mass_mg`      | `BarChart` (f32)          | every snapshot (sent in columns) |
//! | `field/<rail>/<band>/wheel_mass_mg`     | `BarChart` (f32)          | every snapshot (sent in columns) |
//! | `field/<rail>/<band>/mu_history`        | `Tensor` (heatmap)        | every `E`-th train, last train |
//! | `sites/<site>/<rail>/<quantity>/measured`  | `Scalars` + `SeriesPoints` | measurement (`time`, sent in columns) |
//! | `sites/<site>/<rail>/<quantity>/simulated` | `Scalars` + `SeriesLines` + `SeriesPoints` | measurement (`time`, sent in columns) |
//! | `applicator/<id>/<rail>`                | `Scalars` in g + `SeriesPoints` | pulse (`time`, sent in columns) |
//! | `trains`                                | `TextLog`                 | train         |
//! | `run/summary`                           | `TextDocument` (markdown) | static, at finish |
//!
//! A profile is a `BarChart` whose abscissa is the grid `d_i` in m and whose
//! bar widths are the grid spacing `C`, so the plot's x axis is distance
//! along the section (the viewer draws bin `i` over `[d_i, d_i + C)`). The
//! abscissa, widths and colour are logged once, statically, and only the
//! values at each snapshot: rerun joins the two per component, and a long run
//! does not store the grid once per wheel. Every track (rail/band) has a
//! fixed colour: its rail's (blue for the first rail, red for the second),
//! and a second shade of it for a rail's band other than `top`.
//!
//! The heatmap `mu_history` of a track is its `mu` after each of the last
//! [`RerunOptions::history_rows`] trains: row 0 is the oldest, the last row
//! the newest, one column per grid point. rerun has no "append a row", so it
//! is rewritten whole, after every [`RerunOptions::history_every`]-th train
//! (`E`) and after the last train at [`Sink::finish`] (at that train's time
//! and wheel pass), and stored as f16 (three significant digits, plenty for
//! a colour; the profiles hold the finer values): a run stores about
//! `trains / E * K * N * 2` bytes per track before compression, e.g. 20 MB
//! for a month of 1200 trains, E = 32, K = 256, N = 527 and 2 tracks (at
//! E = 1, 0.6 GB).
//! Between two logs the viewer shows the latest one, at most `E - 1` trains
//! behind the profiles. It holds only the trains run so far, not `K` rows
//! padded with NaN: the 0.36 viewer paints NaN in the colormap's low end,
//! which would read as low mu (the blueprint stretches the image instead, so
//! a one-train heatmap is not a one-pixel strip). Its colour scale (a
//! `ValueRange` on the entity) is [`RerunOptions::mu_color_range`], or by
//! default the run's mu range rounded out to 0.05, logged at
//! [`Sink::finish`]; the heatmap views and the run summary state it.
//!
//! # Blueprint
//! The layout is written by hand into a blueprint store rather than through
//! [`rerun::blueprint::Blueprint`]: the 0.36 Rust builder has no way to set
//! view properties (a time series' visible range, a tensor view's fit and
//! colormap, a plot legend), which this layout needs. It logs the same
//! archetypes the builder does (`ContainerBlueprint`, `ViewBlueprint`,
//! `ViewContents`, `ViewportBlueprint`, the panels) plus those properties
//! under `view/<id>/<Archetype>`, where the viewer looks them up, and sends
//! the store with [`RecordingStream::send_blueprint`], so it lands in the
//! same `.rrd`, followed by the activation command.
//!
//! It is sent at [`Sink::finish`], when the run is known: which sites
//! measured which quantities on which rails (a plot for each, no empty
//! ones), the mu range of the heatmaps, the time span (the playback speed).
//! The layout:
//! - left, a grid with one column per track: a row per quantity along `d`
//!   (mu, adhesion, rail product, wheel product), each view titled with its
//!   rail and band ("high rail (top band): mu along d \[m\]") and no legend,
//!   and a last row with the track's mu history heatmap (stretched to fill
//!   the view, Viridis, the colour range in the title);
//! - right, a tab per site, in it a row per quantity measured there and a
//!   plot per rail over the whole run (measured as dots in the rail's
//!   colour, simulated as a pale line through small dots); below, tabs with
//!   the trains, pulses, section, section map and run summary;
//! - the time panel collapsed to its bar, on `time`, following the data, so
//!   the viewer opens at the end of the run; playback (should one rewind)
//!   covers the run in about a minute; the blueprint and selection side
//!   panels collapsed.
//!
//! What 0.36 cannot do: set the time cursor itself (following the data is
//! the only way to open at the end), bind a view to a timeline other than
//! the time panel's, draw a colour bar next to a tensor view or leave NaN
//! cells blank, or set a bar chart's axes.
//!
//! # Files
//! The recording is written to `.NAME.partial-<pid>` next to the target;
//! [`Sink::finish`] sends the buffered profiles and series and the last
//! heatmaps, flushes the stream, closes it (which writes the rrd footer) and
//! renames the file into place. A sink dropped without `finish` closes the
//! stream and deletes the temporary file.

use std::collections::{BTreeMap, BTreeSet, HashSet, VecDeque};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Duration;

use anyhow::{anyhow, bail, Context};
use rerun::blueprint::components::{
    AutoLayout, AutoViews, ColumnShare, ContainerKind, Corner2D, Fps, GridColumns, IncludedContent,
    PanelState, PlayState, PlaybackSpeed, QueryExpression, RootContainer, RowShare, TimelineName,
    ViewClass, ViewFit,
};
use rerun::components::{
    Color, Colormap, MagnificationFilter, MarkerShape, Name, Radius, TextLogLevel, ValueRange,
};
use rerun::datatypes::{TensorBuffer, TensorData, TimeRange, VisibleTimeRange};
use rerun::external::arrow::datatypes::{ArrowPrimitiveType, Float16Type};
use rerun::external::re_log_types::{BlueprintActivationCommand, LogMsg, RecordingId};
use rerun::external::re_sdk_types::blueprint::archetypes::{
    ContainerBlueprint, PanelBlueprint, PlotLegend, TensorScalarMapping, TensorViewFit, TimeAxis,
    TimePanelBlueprint, ViewBlueprint, ViewContents, ViewportBlueprint, VisibleTimeRanges,
};
use rerun::external::re_sdk_types::external::uuid::Uuid;
use rerun::log::ChunkBatcherConfig;
use rerun::{
    Archetype, AsComponents, EntityPath, EntityPathPart, RecordingStream, RecordingStreamBuilder,
    TimeCell, TimeColumn,
};

use crate::files::PartialFile;
use tortwin_engine::sink::{
    FieldSnapshot, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink, SnapshotKind,
    TrackInfo, TrainEvent,
};
use tortwin_recording::{Direction, Quantity};

/// Name of the sequence timeline: wheel passes so far.
pub const TIMELINE_WHEEL_PASS: &str = "wheel_pass";
/// Name of the timestamp timeline: the events' log_time.
pub const TIMELINE_TIME: &str = "time";

/// `half::f16`, named through arrow so the crate needs no `half` dependency.
type F16 = <Float16Type as ArrowPrimitiveType>::Native;

const MG_PER_KG: f64 = 1e6;
const G_PER_KG: f64 = 1e3;
/// Playback (should the user rewind and press play) covers the run in this.
const PLAYBACK_S: f64 = 60.0;
/// The default heatmap colour range is the run's mu rounded out to 1/this
/// (0.05).
const MU_COLOR_STEPS_PER_UNIT: f64 = 20.0;
/// Values a pulse or measurement series buffers before it is sent as one
/// chunk; also the batcher's row limit. The viewer's own chunks hold up to
/// 4096 rows (`ChunkStoreConfig::DEFAULT`).
pub const SERIES_CHUNK_ROWS: usize = 4096;
/// The batcher sends an entity's rows as a chunk once they reach this size
/// (the viewer's own chunk size, `ChunkStoreConfig::DEFAULT`), not every
/// 200 ms: fewer, larger chunks, and a file that does not depend on how fast
/// the machine ran.
pub const BATCH_CHUNK_BYTES: u64 = 384 * 1024;
/// The most the SDK's queues hold before `log` waits for the writer (rerun's
/// default is 100 MiB).
pub const MAX_BYTES_IN_FLIGHT: u64 = 8 * 1024 * 1024;

/// What the rerun recording holds beyond the fixed layout.
#[derive(Debug, Clone)]
pub struct RerunOptions {
    /// The viewer groups recordings (and remembers layouts) by application id.
    pub application_id: String,
    /// Shown in the viewer's recording list; `None` for the file name.
    pub recording_name: Option<String>,
    /// `K`: trains kept in each track's `mu_history` heatmap; 0 logs none.
    pub history_rows: usize,
    /// `E`: the heatmaps are logged after every `E`-th train, and after the
    /// last train at [`Sink::finish`]; 1 (or 0) logs them at every train.
    /// Each log stores the whole heatmap (`K` rows), so this divides their
    /// share of the file.
    pub history_every: usize,
    /// The heatmap colour scale for mu, fixed for the whole run so a colour
    /// means the same mu at every train. `None`: the run's mu range, rounded
    /// out to 0.05 (known, and logged, at [`Sink::finish`]).
    pub mu_color_range: Option<[f64; 2]>,
    /// Send the default layout (see the module docs).
    pub blueprint: bool,
}

impl Default for RerunOptions {
    fn default() -> Self {
        RerunOptions {
            application_id: "tortwin".to_owned(),
            recording_name: None,
            history_rows: 256,
            // K / 8: the heatmap is never more than an eighth of its rows
            // behind, and a month of trains stores it about 40 times.
            history_every: 32,
            mu_color_range: None,
            blueprint: true,
        }
    }
}

/// Writes the twin's results to a rerun `.rrd` (see the module docs).
pub struct RerunSink {
    /// `None` once [`Sink::finish`] has closed the stream.
    rec: Option<RecordingStream>,
    /// The output under its temporary name; renamed at finish, deleted if dropped before.
    file: PartialFile,
    options: RerunOptions,
    /// What the blueprint needs from [`Sink::begin`], `None` before it.
    layout: Option<Layout>,
    tracks: Vec<TrackState>,
    grid_len: usize,
    /// Snapshots a track buffers before its profiles are sent: a chunk of
    /// about [`BATCH_CHUNK_BYTES`] per quantity.
    profile_chunk_rows: usize,
    /// Largest wheel_pass of any track so far: the `wheel_pass` timeline.
    wheel_pass: u64,
    /// Series entities whose static style has been logged.
    styled: HashSet<EntityPath>,
    /// Per site index, per quantity (in [`QUANTITIES`] order): the
    /// quantity and the rails it was measured on.
    measured: BTreeMap<usize, BTreeMap<usize, (Quantity, BTreeSet<usize>)>>,
    /// Applicator entities that received a pulse.
    pulsed: BTreeSet<EntityPath>,
    /// Pulse and measurement values not sent yet, per entity.
    series: BTreeMap<EntityPath, Series>,
    /// Smallest and largest mu put into a heatmap.
    mu_seen: Option<[f64; 2]>,
    /// First and last log_time of anything logged on `time`.
    time_span_ns: Option<[u64; 2]>,
}

/// The section as the blueprint needs it, copied at [`Sink::begin`].
struct Layout {
    rails: Vec<String>,
    /// `(id, position_m)`, in section order.
    sites: Vec<(String, f64)>,
}

/// Picks one of a track's entities.
type TrackEntity = fn(&TrackState) -> &EntityPath;

struct TrackState {
    /// "high rail (top band)".
    label: String,
    color: Color,
    mu: EntityPath,
    adhesion: EntityPath,
    rail_mass: EntityPath,
    wheel_mass: EntityPath,
    mu_history: EntityPath,
    /// mu after each of the last K trains, oldest first.
    history: VecDeque<Vec<F16>>,
    /// Trains added to `history` since it was last logged.
    history_unlogged: usize,
    /// `(log_time_ns, wheel_pass)` of the last train snapshot: where the
    /// heatmap is logged at finish if that train's was not.
    last_train: Option<(u64, u64)>,
    /// Profiles not sent yet.
    pending: PendingProfiles,
}

/// A track's profiles not sent yet, a row per snapshot; the quantities
/// share the times.
#[derive(Default)]
struct PendingProfiles {
    times_ns: Vec<i64>,
    wheel_passes: Vec<i64>,
    /// mu, adhesion, rail product (mg), wheel product (mg), as f32.
    values: [Vec<Vec<f32>>; 4],
}

/// A scalar series on `time`, buffered until it is sent as columns.
#[derive(Default)]
struct Series {
    times_ns: Vec<i64>,
    values: Vec<f64>,
}

impl RerunSink {
    /// Opens `.NAME.partial-<pid>` next to `path` as the recording's file.
    pub fn create(path: &Path, options: RerunOptions) -> anyhow::Result<RerunSink> {
        let file = PartialFile::beside(path)?;
        let temp_path = file.temp_path().to_path_buf();
        let file_name = path.file_name().unwrap_or_default();

        let recording_name = options
            .recording_name
            .clone()
            .unwrap_or_else(|| file_name.to_string_lossy().into_owned());
        // `enabled(true)`: the user asked for this file, so the `RERUN=off`
        // environment switch must not silently drop it.
        let application_id = rerun::ApplicationId::try_new(options.application_id.as_str())
            .map_err(|err| anyhow!("rerun output {}: {err}", path.display()))?;
        let rec = RecordingStreamBuilder::new(application_id)
            .recording_name(recording_name)
            .enabled(true)
            .batcher_config(ChunkBatcherConfig {
                flush_tick: Duration::MAX,
                flush_num_bytes: BATCH_CHUNK_BYTES,
                flush_num_rows: SERIES_CHUNK_ROWS as u64,
                max_bytes_in_flight: MAX_BYTES_IN_FLIGHT,
                ..ChunkBatcherConfig::DEFAULT
            })
            .save(&temp_path)
            .with_context(|| format!("creating rerun output {}", temp_path.display()))?;
        rec.set_log_time_enabled(false);
        rec.set_log_tick_enabled(false);

        Ok(RerunSink {
            rec: Some(rec),
            file,
            options,
            layout: None,
            tracks: Vec::new(),
            grid_len: 0,
            profile_chunk_rows: 1,
            wheel_pass: 0,
            styled: HashSet::new(),
            measured: BTreeMap::new(),
            pulsed: BTreeSet::new(),
            series: BTreeMap::new(),
            mu_seen: None,
            time_span_ns: None,
        })
    }

    fn rec(&self) -> anyhow::Result<&RecordingStream> {
        self.rec.as_ref().ok_or_else(|| {
            anyhow!(
                "rerun output {}: already finished",
                self.file.final_path().display()
            )
        })
    }

    /// Sets the calling thread's time: `time` always, `wheel_pass` if given
    /// (else that timeline is cleared). The next logs land there. Returns
    /// the time as rerun takes it.
    fn set_time(&mut self, log_time_ns: u64, wheel_pass: Option<u64>) -> anyhow::Result<i64> {
        let time_ns = self.note_time(log_time_ns)?;
        let wheel_pass = wheel_pass
            .map(|w| i64::try_from(w).with_context(|| format!("wheel_pass {w} out of range")))
            .transpose()?;
        let rec = self.rec()?;
        match wheel_pass {
            Some(wheel_pass) => {
                rec.set_time(TIMELINE_WHEEL_PASS, TimeCell::from_sequence(wheel_pass));
            }
            None => rec.disable_timeline(TIMELINE_WHEEL_PASS),
        }
        rec.set_time(
            TIMELINE_TIME,
            TimeCell::from_timestamp_nanos_since_epoch(time_ns),
        );
        Ok(time_ns)
    }

    /// Checks a log_time and widens the run's time span by it.
    fn note_time(&mut self, log_time_ns: u64) -> anyhow::Result<i64> {
        let time_ns = i64::try_from(log_time_ns)
            .with_context(|| format!("log_time {log_time_ns} ns out of range"))?;
        self.time_span_ns = Some(match self.time_span_ns {
            Some([first, last]) => [first.min(log_time_ns), last.max(log_time_ns)],
            None => [log_time_ns, log_time_ns],
        });
        Ok(time_ns)
    }

    /// Adds a value to the series at `path` on `time`; sends the series once
    /// it holds [`SERIES_CHUNK_ROWS`] values.
    fn push_series(
        &mut self,
        path: EntityPath,
        log_time_ns: u64,
        value: f64,
    ) -> anyhow::Result<()> {
        let time_ns = self.note_time(log_time_ns)?;
        let series = self.series.entry(path.clone()).or_default();
        series.times_ns.push(time_ns);
        series.values.push(value);
        if series.values.len() >= SERIES_CHUNK_ROWS {
            let series = std::mem::take(series);
            send_series(self.rec()?, path, series)?;
        }
        Ok(())
    }

    /// Sends every buffered series.
    fn flush_series(&mut self) -> anyhow::Result<()> {
        let rec = self.rec.as_ref().ok_or_else(|| {
            anyhow!(
                "rerun output {}: already finished",
                self.file.final_path().display()
            )
        })?;
        for (path, series) in std::mem::take(&mut self.series) {
            if !series.values.is_empty() {
                send_series(rec, path, series)?;
            }
        }
        Ok(())
    }

    /// Logs a time series style once per entity, statically.
    fn style_once(
        &mut self,
        path: &EntityPath,
        styles: &[&dyn AsComponents],
    ) -> anyhow::Result<()> {
        if self.styled.contains(path) {
            return Ok(());
        }
        for style in styles {
            self.rec()?.log_static(path.clone(), *style)?;
        }
        self.styled.insert(path.clone());
        Ok(())
    }

    fn log_context(&self, info: &SectionInfo<'_>) -> anyhow::Result<()> {
        let rec = self.rec()?;
        let section = info.section;
        rec.log_static(
            "section/description",
            &rerun::TextDocument::from_markdown(describe(info)),
        )?;

        // A schematic plan of the section: d along x, the rails drawn apart
        // so the labels do not collide (the gap is not to scale).
        let rail_gap = (section.length_m / 25.0).max(1.0) as f32;
        let rail_y = |rail: usize| rail as f32 * rail_gap;
        let length = section.length_m as f32;
        rec.log_static(
            "section/map/rails",
            &rerun::LineStrips2D::new(
                (0..section.rails.len()).map(|r| vec![[0.0, rail_y(r)], [length, rail_y(r)]]),
            )
            .with_labels(section.rails.iter().map(|r| format!("{r} rail")))
            .with_colors((0..section.rails.len()).map(rail_color))
            .with_radii([Radius::new_ui_points(2.0)]),
        )?;
        let mut positions = Vec::new();
        let mut labels = Vec::new();
        for applicator in &section.applicators {
            for &rail in &applicator.rails {
                positions.push([applicator.position_m as f32, rail_y(rail)]);
                labels.push(format!(
                    "{} ({:.1} m)",
                    applicator.id, applicator.position_m
                ));
            }
        }
        rec.log_static(
            "section/map/applicators",
            &rerun::Points2D::new(positions)
                .with_labels(labels)
                .with_show_labels(true)
                .with_colors([Color::from_rgb(230, 160, 30)])
                .with_radii([Radius::new_ui_points(6.0)]),
        )?;
        let mut positions = Vec::new();
        let mut labels = Vec::new();
        for site in &section.sites {
            positions.push([site.position_m as f32, -0.5 * rail_gap]);
            labels.push(format!("site {} ({:.1} m)", site.id, site.position_m));
        }
        rec.log_static(
            "section/map/sites",
            &rerun::Points2D::new(positions)
                .with_labels(labels)
                .with_show_labels(true)
                .with_colors([Color::from_rgb(90, 200, 120)])
                .with_radii([Radius::new_ui_points(6.0)]),
        )?;

        // The parts of every profile that never change: d, the bar width C
        // and the track's colour.
        let spacing_m = match info.grid_d_m {
            [first, second, ..] => (second - first) as f32,
            _ => 1.0,
        };
        let abscissa = TensorData::from(info.grid_d_m);
        for track in &self.tracks {
            for path in [
                &track.mu,
                &track.adhesion,
                &track.rail_mass,
                &track.wheel_mass,
            ] {
                rec.log_static(
                    path.clone(),
                    &rerun::BarChart::update_fields()
                        .with_abscissa(abscissa.clone())
                        .with_widths(vec![spacing_m; info.grid_d_m.len()])
                        .with_color(track.color),
                )?;
            }
            if let Some([low, high]) = self.options.mu_color_range {
                rec.log_static(
                    track.mu_history.clone(),
                    &rerun::Tensor::update_fields().with_value_range(ValueRange::new(low, high)),
                )?;
            }
        }
        Ok(())
    }

    /// The heatmaps' colour range: the option, or the run's mu rounded out.
    fn mu_color_range(&self) -> [f64; 2] {
        if let Some(range) = self.options.mu_color_range {
            return range;
        }
        match self.mu_seen {
            Some([low, high]) => {
                let steps = MU_COLOR_STEPS_PER_UNIT;
                let low = (low * steps).floor() / steps;
                let high = (high * steps).ceil() / steps;
                [low, high.max(low + 1.0 / steps)]
            }
            None => [0.0, 0.6],
        }
    }

    /// Builds the default layout (see the module docs) as blueprint messages.
    fn blueprint(&self) -> anyhow::Result<Vec<LogMsg>> {
        let Some(layout) = &self.layout else {
            bail!("no section: the sink was never begun");
        };
        let application_id = rerun::ApplicationId::try_new(self.options.application_id.as_str())
            .map_err(|err| anyhow!("{err}"))?;
        let (rec, storage) = RecordingStreamBuilder::new(application_id)
            .recording_id(RecordingId::random())
            .blueprint()
            .memory()?;
        // The viewer identifies blueprint data by this timeline.
        rec.set_time_sequence("blueprint", 0);
        let bp = BlueprintWriter { rec: &rec };
        let everything = [TIMELINE_TIME, TIMELINE_WHEEL_PASS].map(|timeline| VisibleTimeRange {
            timeline: timeline.into(),
            range: TimeRange::EVERYTHING,
        });
        // A time series over the whole run, whatever the time cursor: the
        // default x range of 0.36 is a window of +-30 s (or +-1000 passes)
        // around the cursor once the data spans more.
        let whole_run = |bp: &BlueprintWriter<'_>, view: &BlueprintItem| -> anyhow::Result<()> {
            bp.property(view, &VisibleTimeRanges::new(everything.clone()))?;
            bp.property(
                view,
                &TimeAxis::update_fields().with_view_range(TimeRange::EVERYTHING),
            )?;
            bp.property(
                view,
                &PlotLegend::update_fields().with_corner(Corner2D::LeftTop),
            )
        };

        // Left: a column per track, a row per quantity along d, and the
        // mu history below them (its columns are the same grid points).
        let quantities: [(&str, TrackEntity); 4] = [
            ("mu", |t| &t.mu),
            ("adhesion T/N", |t| &t.adhesion),
            ("rail product (mg)", |t| &t.rail_mass),
            ("wheel product (mg)", |t| &t.wheel_mass),
        ];
        let mut grid = Vec::new();
        for (quantity, pick) in quantities {
            for track in &self.tracks {
                let view = bp.view(
                    "BarChart",
                    &format!("{}: {quantity} along d [m]", track.label),
                    [format!("+ {}", pick(track))],
                )?;
                // The title names the track; the legend would only repeat
                // the entity path.
                bp.property(&view, &PlotLegend::update_fields().with_visible(false))?;
                grid.push(view);
            }
        }
        if self.options.history_rows > 0 {
            // 0.36 draws no colour bar next to a tensor: the title says it.
            let [low, high] = self.mu_color_range();
            for track in &self.tracks {
                let view = bp.view(
                    "Tensor",
                    &format!("{}: mu history, colour {low:.2} → {high:.2}", track.label),
                    [format!("+ {}", track.mu_history)],
                )?;
                // Stretched: a few trains by 600 points is a strip otherwise.
                bp.property(
                    &view,
                    &TensorViewFit::update_fields().with_scaling(ViewFit::Fill),
                )?;
                bp.property(
                    &view,
                    &TensorScalarMapping::update_fields()
                        .with_colormap(Colormap::Viridis)
                        .with_mag_filter(MagnificationFilter::Nearest),
                )?;
                grid.push(view);
            }
        }
        // The heatmap's row a little taller than a profile's.
        let row_shares = [1.0, 1.0, 1.0, 1.0, 1.6].map(RowShare::from);
        let rows = grid.len() / self.tracks.len().max(1);
        let profiles = bp.container(
            ContainerKind::Grid,
            "Along the section (a column per rail/band)",
            grid,
            |c| {
                c.with_grid_columns(GridColumns::from(self.tracks.len().max(1) as u32))
                    .with_row_shares(row_shares.into_iter().take(rows))
            },
        )?;

        // Right, top: a tab per site; in it a row per quantity measured
        // there and a plot per rail, like the profiles.
        let mut sites = Vec::new();
        for (&site, quantities) in &self.measured {
            let Some((site_id, position_m)) = layout.sites.get(site) else {
                continue;
            };
            let mut rows = Vec::new();
            for (quantity, rails) in quantities.values() {
                let mut views = Vec::new();
                for &rail in rails {
                    let Some(rail) = layout.rails.get(rail) else {
                        continue;
                    };
                    let view = bp.view(
                        "TimeSeries",
                        &format!("{site_id}, {rail} rail: {}", quantity_label(*quantity)),
                        [format!(
                            "+ {}/**",
                            entity(&["sites", site_id, rail, quantity.as_str()])
                        )],
                    )?;
                    whole_run(&bp, &view)?;
                    views.push(view);
                }
                rows.push(bp.container(
                    ContainerKind::Horizontal,
                    &format!("site {site_id}: {}", quantity_label(*quantity)),
                    views,
                    |c| c,
                )?);
            }
            sites.push(bp.container(
                ContainerKind::Vertical,
                &format!("site {site_id} ({position_m:.1} m)"),
                rows,
                |c| c,
            )?);
        }

        // Right, bottom: the context.
        let trains = bp.view("TextLog", "Trains", ["+ /trains"])?;
        let pulses = bp.view(
            "TimeSeries",
            "Applicator pulses (g)",
            self.pulsed.iter().map(|p| format!("+ {p}")),
        )?;
        whole_run(&bp, &pulses)?;
        let section = bp.view("TextDocument", "Section", ["+ /section/description"])?;
        let map = bp.view("2D", "Section map", ["+ /section/map/**"])?;
        let summary = bp.view("TextDocument", "Run summary", ["+ /run/summary"])?;
        let context = bp.container(
            ContainerKind::Tabs,
            "Run",
            vec![trains, pulses, section, map, summary],
            |c| c,
        )?;

        let mut right = Vec::new();
        let mut shares = Vec::new();
        if !sites.is_empty() {
            right.push(bp.container(ContainerKind::Tabs, "Sites", sites, |c| c)?);
            shares.push(0.62);
        }
        right.push(context);
        shares.push(0.38);
        let right = bp.container(ContainerKind::Vertical, "Sites and run", right, |c| {
            c.with_row_shares(shares.iter().map(|&s| RowShare::from(s)))
        })?;
        let root = bp.container(
            ContainerKind::Horizontal,
            "tortwin",
            vec![profiles, right],
            |c| c.with_col_shares([0.55, 0.45].map(ColumnShare::from)),
        )?;

        rec.log(
            "viewport",
            &ViewportBlueprint::new()
                .with_root_container(RootContainer::from(root.id))
                .with_auto_layout(AutoLayout::from(false))
                .with_auto_views(AutoViews::from(false)),
        )?;
        for panel in ["blueprint_panel", "selection_panel"] {
            rec.log(
                panel,
                &PanelBlueprint::new().with_state(PanelState::Collapsed),
            )?;
        }
        // Follow the data: the viewer opens at the end of the run (0.36 has
        // no blueprint field for the time cursor itself).
        let span_s = self
            .time_span_ns
            .map_or(0.0, |[first, last]| (last - first) as f64 * 1e-9);
        rec.log(
            "time_panel",
            &TimePanelBlueprint::new()
                .with_state(PanelState::Collapsed)
                .with_timeline(TimelineName::from(TIMELINE_TIME))
                .with_play_state(PlayState::Following)
                .with_playback_speed(PlaybackSpeed::from((span_s / PLAYBACK_S).max(1.0)))
                .with_fps(Fps::from((self.wheel_pass as f64 / PLAYBACK_S).max(30.0))),
        )?;
        Ok(storage.take())
    }
}

/// A view or container logged to a blueprint store.
struct BlueprintItem {
    id: Uuid,
    path: String,
}

/// Logs containers, views and view properties as the viewer reads them.
struct BlueprintWriter<'r> {
    rec: &'r RecordingStream,
}

impl BlueprintWriter<'_> {
    /// A view of `class` showing what the `+ /path` queries include.
    fn view(
        &self,
        class: &str,
        name: &str,
        queries: impl IntoIterator<Item = impl Into<String>>,
    ) -> anyhow::Result<BlueprintItem> {
        let id = Uuid::new_v4();
        let path = format!("view/{id}");
        self.rec.log(
            format!("{path}/ViewContents"),
            &ViewContents::new(queries.into_iter().map(|q| QueryExpression::from(q.into()))),
        )?;
        self.rec.log(
            path.as_str(),
            &ViewBlueprint::new(ViewClass::from(class))
                .with_display_name(Name::from(name))
                .with_space_origin("/"),
        )?;
        Ok(BlueprintItem { id, path })
    }

    /// A view property: `view/<id>/<Archetype>`, where the viewer looks.
    fn property<A: Archetype + AsComponents>(
        &self,
        view: &BlueprintItem,
        property: &A,
    ) -> anyhow::Result<()> {
        self.rec.log(
            format!("{}/{}", view.path, A::name().short_name()),
            property,
        )?;
        Ok(())
    }

    fn container(
        &self,
        kind: ContainerKind,
        name: &str,
        children: Vec<BlueprintItem>,
        extra: impl FnOnce(ContainerBlueprint) -> ContainerBlueprint,
    ) -> anyhow::Result<BlueprintItem> {
        let id = Uuid::new_v4();
        let path = format!("container/{id}");
        let contents: Vec<IncludedContent> = children
            .iter()
            .map(|child| IncludedContent::from(child.path.as_str()))
            .collect();
        self.rec.log(
            path.as_str(),
            &extra(
                ContainerBlueprint::new(kind)
                    .with_display_name(Name::from(name))
                    .with_contents(contents),
            ),
        )?;
        Ok(BlueprintItem { id, path })
    }
}

impl Sink for RerunSink {
    fn begin(&mut self, info: &SectionInfo<'_>) -> tortwin_engine::sink::SinkResult {
        self.grid_len = info.grid_d_m.len();
        self.profile_chunk_rows = (BATCH_CHUNK_BYTES as usize
            / (self.grid_len * std::mem::size_of::<f32>()).max(1))
        .clamp(1, SERIES_CHUNK_ROWS);
        self.layout = Some(Layout {
            rails: info.section.rails.clone(),
            sites: info
                .section
                .sites
                .iter()
                .map(|s| (s.id.clone(), s.position_m))
                .collect(),
        });
        self.tracks = info
            .tracks
            .iter()
            .map(|t| {
                let path = |leaf: &str| entity(&["field", &t.rail_name, &t.band, leaf]);
                TrackState {
                    label: track_label(t),
                    color: track_color(t, info.tracks),
                    mu: path("mu"),
                    adhesion: path("adhesion"),
                    rail_mass: path("rail_mass_mg"),
                    wheel_mass: path("wheel_mass_mg"),
                    mu_history: path("mu_history"),
                    history: VecDeque::new(),
                    history_unlogged: 0,
                    last_train: None,
                    pending: PendingProfiles::default(),
                }
            })
            .collect();
        Ok(self
            .log_context(info)
            .with_context(|| format!("rerun output {}", self.file.temp_path().display()))?)
    }

    fn train(&mut self, train: &TrainEvent<'_>) -> tortwin_engine::sink::SinkResult {
        self.set_time(train.log_time_ns, Some(self.wheel_pass))?;
        let direction = match train.direction {
            Direction::Up => "up (d increasing)",
            Direction::Down => "down (d decreasing)",
        };
        let text = format!(
            "train {} {direction}, {:.1} m/s ({:.0} km/h), {} axles",
            train.train_id,
            train.speed_mps,
            train.speed_mps * 3.6,
            train.axles
        );
        self.rec()?
            .log(
                "trains",
                &rerun::TextLog::new(text).with_level(TextLogLevel::INFO),
            )
            .with_context(|| format!("rerun output: train {}", train.train_id))?;
        Ok(())
    }

    fn pulse(&mut self, pulse: &PulseEvent<'_>) -> tortwin_engine::sink::SinkResult {
        let path = entity(&["applicator", pulse.applicator_id, pulse.rail_name]);
        let name = format!("{} on {} rail (g)", pulse.applicator_id, pulse.rail_name);
        self.style_once(
            &path,
            &[&rerun::SeriesPoints::new()
                .with_names([name])
                .with_colors([rail_color(pulse.rail)])
                .with_markers([MarkerShape::Diamond])
                .with_marker_sizes([3.0])],
        )?;
        self.pulsed.insert(path.clone());
        Ok(self
            .push_series(path, pulse.log_time_ns, pulse.mass_kg * G_PER_KG)
            .with_context(|| format!("rerun output: pulse of {}", pulse.applicator_id))?)
    }

    fn measurement(&mut self, m: &MeasurementOutput<'_>) -> tortwin_engine::sink::SinkResult {
        let quantity = m.quantity.as_str();
        let base = ["sites", m.site_id, m.rail_name, quantity];
        let measured = entity(&[&base[..], &["measured"]].concat());
        let simulated = entity(&[&base[..], &["simulated"]].concat());
        let color = rail_color(m.rail);
        let pale = lighten(color, 0.45);
        self.style_once(
            &measured,
            &[&rerun::SeriesPoints::new()
                .with_names(["measured"])
                .with_colors([color])
                .with_markers([MarkerShape::Circle])
                .with_marker_sizes([2.5])],
        )?;
        // Points and a line: a lone simulated value still shows.
        self.style_once(
            &simulated,
            &[
                &rerun::SeriesLines::new()
                    .with_names(["simulated (twin)"])
                    .with_colors([pale])
                    .with_widths([1.5]),
                &rerun::SeriesPoints::new()
                    .with_names(["simulated (twin)"])
                    .with_colors([pale])
                    .with_markers([MarkerShape::Circle])
                    .with_marker_sizes([1.5]),
            ],
        )?;
        let rank = QUANTITIES
            .iter()
            .position(|&q| q == m.quantity)
            .unwrap_or(QUANTITIES.len());
        self.measured
            .entry(m.site)
            .or_default()
            .entry(rank)
            .or_insert_with(|| (m.quantity, BTreeSet::new()))
            .1
            .insert(m.rail);
        Ok(self
            .push_series(measured, m.log_time_ns, m.measured)
            .and_then(|()| self.push_series(simulated, m.log_time_ns, m.simulated))
            .with_context(|| {
                format!(
                    "rerun output: measurement {} at site {}",
                    m.index_in_file, m.site_id
                )
            })?)
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> tortwin_engine::sink::SinkResult {
        let grid_len = self.grid_len;
        let lengths = [
            ("d_m", f.d_m.len()),
            ("mu", f.mu.len()),
            ("adhesion", f.adhesion.len()),
            ("rail_mass_kg", f.rail_mass_kg.len()),
            ("wheel_mass_kg", f.wheel_mass_kg.len()),
        ];
        if let Some((name, len)) = lengths.iter().find(|(_, len)| *len != grid_len) {
            return Err(anyhow!(
                "rerun output: field snapshot of train {} on {}/{}: {name} has {len} points, the grid {grid_len}",
                f.train_id,
                f.rail_name,
                f.band
            ).into());
        }
        if f.track >= self.tracks.len() {
            return Err(anyhow!(
                "rerun output: field snapshot for track {} but the section has {} tracks",
                f.track,
                self.tracks.len()
            )
            .into());
        }

        self.wheel_pass = self.wheel_pass.max(f.wheel_pass);
        let wheel_pass = self.wheel_pass;
        let time_ns = self.set_time(f.log_time_ns, Some(wheel_pass))?;
        let wheel_pass_seq = i64::try_from(wheel_pass)
            .with_context(|| format!("wheel_pass {wheel_pass} out of range"))?;
        let history_rows = self.options.history_rows;
        if f.kind == SnapshotKind::Train && history_rows > 0 {
            for &mu in f.mu.iter().filter(|mu| mu.is_finite()) {
                self.mu_seen = Some(match self.mu_seen {
                    Some([low, high]) => [low.min(mu), high.max(mu)],
                    None => [mu, mu],
                });
            }
        }
        let Some(rec) = self.rec.as_ref() else {
            return Err(anyhow!(
                "rerun output {}: already finished",
                self.file.final_path().display()
            )
            .into());
        };
        let Some(track) = self.tracks.get_mut(f.track) else {
            return Err(anyhow!("rerun output: no track {}", f.track).into());
        };
        let label = track.label.clone();
        let context = || format!("rerun output: field of train {} on {label}", f.train_id);
        let pending = &mut track.pending;
        pending.times_ns.push(time_ns);
        pending.wheel_passes.push(wheel_pass_seq);
        let profiles = [
            (f.mu, 1.0),
            (f.adhesion, 1.0),
            (f.rail_mass_kg, MG_PER_KG),
            (f.wheel_mass_kg, MG_PER_KG),
        ];
        for (rows, (values, scale)) in pending.values.iter_mut().zip(profiles) {
            rows.push(values.iter().map(|&v| (v * scale) as f32).collect());
        }
        if pending.times_ns.len() >= self.profile_chunk_rows {
            send_profiles(rec, track).with_context(context)?;
        }

        if f.kind == SnapshotKind::Train && history_rows > 0 {
            while track.history.len() >= history_rows {
                track.history.pop_front();
            }
            track
                .history
                .push_back(f.mu.iter().map(|&mu| F16::from_f64(mu)).collect());
            track.history_unlogged += 1;
            track.last_train = Some((f.log_time_ns, wheel_pass));
            if track.history_unlogged >= self.options.history_every.max(1) {
                log_history(rec, track, grid_len).with_context(context)?;
            }
        }
        Ok(())
    }

    fn finish(&mut self, summary: &RunSummary) -> tortwin_engine::sink::SinkResult {
        let temp_path = self.file.temp_path().to_path_buf();
        let context = || format!("rerun output {}", temp_path.display());
        self.flush_series()
            .with_context(|| format!("{}: pulses and measurements", context()))?;
        if let Some(rec) = self.rec.as_ref() {
            for track in &mut self.tracks {
                send_profiles(rec, track).with_context(|| format!("{}: profiles", context()))?;
            }
        }
        // The last train's heatmap, where its snapshot was, if not yet logged.
        for index in 0..self.tracks.len() {
            let track = &self.tracks[index];
            let Some((log_time_ns, wheel_pass)) = track.last_train else {
                continue;
            };
            if track.history_unlogged == 0 {
                continue;
            }
            self.set_time(log_time_ns, Some(wheel_pass))?;
            let rec = self
                .rec
                .as_ref()
                .ok_or_else(|| anyhow!("{}: already finished", context()))?;
            log_history(rec, &mut self.tracks[index], self.grid_len)
                .with_context(|| format!("{}: last heatmap", context()))?;
        }
        let [low, high] = self.mu_color_range();
        let rec = self.rec()?;
        let history = (self.options.history_rows, self.options.history_every.max(1));
        rec.log_static(
            "run/summary",
            &rerun::TextDocument::from_markdown(summarize(summary, [low, high], history)),
        )
        .with_context(|| format!("{}: summary", context()))?;
        if self.options.mu_color_range.is_none() {
            for track in &self.tracks {
                rec.log_static(
                    track.mu_history.clone(),
                    &rerun::Tensor::update_fields().with_value_range(ValueRange::new(low, high)),
                )
                .with_context(|| format!("{}: heatmap colour range", context()))?;
            }
        }
        if self.options.blueprint {
            let blueprint = self
                .blueprint()
                .with_context(|| format!("{}: blueprint", context()))?;
            let Some(blueprint_id) = blueprint.first().map(|msg| msg.store_id().clone()) else {
                return Err(anyhow!("{}: blueprint: no messages", context()).into());
            };
            self.rec()?.send_blueprint(
                blueprint,
                BlueprintActivationCommand {
                    blueprint_id,
                    make_active: true,
                    make_default: true,
                },
            );
        }

        let rec = self.rec.take().ok_or_else(|| {
            anyhow!(
                "rerun output {}: already finished",
                self.file.final_path().display()
            )
        })?;
        rec.flush_blocking().with_context(|| {
            format!("flushing rerun output {}", self.file.temp_path().display())
        })?;
        // Dropping the only handle joins the SDK's threads; the file sink
        // writes the rrd footer and closes the file before this returns.
        drop(rec);
        Ok(self.file.commit()?)
    }
}

impl Drop for RerunSink {
    fn drop(&mut self) {
        // Close the stream first so no writer thread still holds the file;
        // then the `file` field, dropped after this, deletes it unless finished.
        drop(self.rec.take());
    }
}

/// Sends a track's buffered profiles, a chunk per quantity.
fn send_profiles(rec: &RecordingStream, track: &mut TrackState) -> anyhow::Result<()> {
    let pending = std::mem::take(&mut track.pending);
    if pending.times_ns.is_empty() {
        return Ok(());
    }
    let paths = [
        &track.mu,
        &track.adhesion,
        &track.rail_mass,
        &track.wheel_mass,
    ];
    for (path, rows) in paths.into_iter().zip(pending.values) {
        let indexes = [
            TimeColumn::new_timestamp_nanos_since_epoch(
                TIMELINE_TIME,
                pending.times_ns.iter().copied(),
            ),
            TimeColumn::new_sequence(TIMELINE_WHEEL_PASS, pending.wheel_passes.iter().copied()),
        ];
        rec.send_columns(
            path.clone(),
            indexes,
            rerun::BarChart::update_fields()
                .with_many_values(rows)
                .columns_of_unit_batches()?,
        )?;
    }
    Ok(())
}

/// Logs a track's heatmap: its history as it stands, at the thread's time.
fn log_history(
    rec: &RecordingStream,
    track: &mut TrackState,
    grid_len: usize,
) -> anyhow::Result<()> {
    let rows = track.history.len();
    let flat: Vec<F16> = track.history.iter().flatten().copied().collect();
    let heatmap = TensorData::new(
        vec![rows as u64, grid_len as u64],
        TensorBuffer::F16(flat.into()),
    )
    .with_dim_names(["train (newest at the bottom)", "grid point i (d = i*C)"]);
    rec.log(track.mu_history.clone(), &rerun::Tensor::new(heatmap))?;
    track.history_unlogged = 0;
    Ok(())
}

/// Sends a buffered series as one chunk on `time`.
fn send_series(rec: &RecordingStream, path: EntityPath, series: Series) -> anyhow::Result<()> {
    let time = TimeColumn::new_timestamp_nanos_since_epoch(TIMELINE_TIME, series.times_ns);
    rec.send_columns(
        path,
        [time],
        rerun::Scalars::new(series.values).columns_of_unit_batches()?,
    )?;
    Ok(())
}

/// An entity path from verbatim names (rail names may hold any character).
fn entity(parts: &[&str]) -> EntityPath {
    EntityPath::new(parts.iter().map(|p| EntityPathPart::new(*p)).collect())
}

/// "high rail (top band)", "high rail (gauge corner band)".
fn track_label(track: &TrackInfo) -> String {
    format!(
        "{} rail ({} band)",
        track.rail_name,
        track.band.replace('_', " ")
    )
}

/// The order of a site's plots.
const QUANTITIES: [Quantity; 3] = [Quantity::Mu, Quantity::Adhesion, Quantity::RailMu];

fn quantity_label(quantity: Quantity) -> &'static str {
    match quantity {
        Quantity::Mu => "wheel-rail mu per axle",
        Quantity::Adhesion => "adhesion T/N per axle",
        Quantity::RailMu => "rail mu (tribometer)",
    }
}

const RAIL_COLORS: [(u8, u8, u8); 4] = [
    (66, 135, 245),
    (235, 87, 70),
    (160, 100, 220),
    (240, 200, 60),
];
/// A second shade per rail, for its bands other than `top`.
const BAND_COLORS: [(u8, u8, u8); 4] = [
    (60, 200, 200),
    (245, 160, 50),
    (220, 120, 200),
    (150, 200, 70),
];

fn rail_color(rail: usize) -> Color {
    let (r, g, b) = RAIL_COLORS[rail % RAIL_COLORS.len()];
    Color::from_rgb(r, g, b)
}

/// The rail's colour for its `top` band (or its only one), a second shade
/// for another band: the same rail reads alike in every plot.
fn track_color(track: &TrackInfo, tracks: &[TrackInfo]) -> Color {
    let single_band = tracks.iter().filter(|t| t.rail == track.rail).count() == 1;
    if track.band == "top" || single_band {
        rail_color(track.rail)
    } else {
        let (r, g, b) = BAND_COLORS[track.rail % BAND_COLORS.len()];
        Color::from_rgb(r, g, b)
    }
}

/// `color` blended towards white by `amount` (0 to 1).
fn lighten(color: Color, amount: f32) -> Color {
    let [r, g, b, _] = color.to_array();
    let blend = |c: u8| (f32::from(c) + (255.0 - f32::from(c)) * amount).round() as u8;
    Color::from_rgb(blend(r), blend(g), blend(b))
}

/// The section as a markdown page.
fn describe(info: &SectionInfo<'_>) -> String {
    let section = info.section;
    let mut md = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(md, "# Section {}\n", section.section_id);
    let _ = writeln!(md, "- length: {:.1} m", section.length_m);
    let _ = writeln!(md, "- rails: {}", section.rails.join(", "));
    match section.curve_radius_m {
        Some(radius) => {
            let _ = writeln!(md, "- curve radius: {radius:.0} m");
        }
        None => {
            let _ = writeln!(md, "- tangent track");
        }
    }
    let _ = writeln!(
        md,
        "- rail head radius: {:.3} m, nominal wheel diameter: {:.3} m",
        section.rail_head_radius_m, section.nominal_wheel_diameter_m
    );
    let spacing = match info.grid_d_m {
        [first, second, ..] => format!(", spacing C = {:.3} m", second - first),
        _ => String::new(),
    };
    let _ = writeln!(md, "- grid: {} points{spacing}", info.grid_d_m.len());
    let tracks: Vec<String> = info
        .tracks
        .iter()
        .map(|t| format!("{}/{}", t.rail_name, t.band))
        .collect();
    let _ = writeln!(md, "- tracks (rail/band): {}", tracks.join(", "));

    let _ = writeln!(md, "\n## Applicators\n");
    let _ = writeln!(
        md,
        "| id | position (m) | grid point | rails | nominal pulse (g) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|");
    for (index, applicator) in section.applicators.iter().enumerate() {
        let rails: Vec<&str> = applicator
            .rails
            .iter()
            .map(|&r| section.rails.get(r).map_or("?", String::as_str))
            .collect();
        let point = info
            .applicator_points
            .get(index)
            .map_or_else(|| "?".to_owned(), usize::to_string);
        let _ = writeln!(
            md,
            "| {} | {:.1} | {point} | {} | {:.2} |",
            applicator.id,
            applicator.position_m,
            rails.join(", "),
            applicator.nominal_pulse_kg * G_PER_KG
        );
    }

    let _ = writeln!(md, "\n## Measurement sites\n");
    let _ = writeln!(md, "| id | position (m) | grid point |");
    let _ = writeln!(md, "|---|---|---|");
    for (index, site) in section.sites.iter().enumerate() {
        let point = info
            .site_points
            .get(index)
            .map_or_else(|| "?".to_owned(), usize::to_string);
        let _ = writeln!(md, "| {} | {:.1} | {point} |", site.id, site.position_m);
    }
    md
}

/// The end-of-run figures as a markdown page; `history` is `(K, E)`.
fn summarize(summary: &RunSummary, mu_color_range: [f64; 2], history: (usize, usize)) -> String {
    let mut md = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(md, "# Run summary\n");
    let _ = writeln!(
        md,
        "- {} trains, {} wheels, {} contacts, {} pulses, {} measurements",
        summary.trains, summary.wheels, summary.contacts, summary.pulses, summary.measurements
    );
    let _ = writeln!(
        md,
        "- {} weather messages, {} messages on unknown topics",
        summary.weather_messages, summary.unknown_topic_messages
    );
    if !summary.rmse.is_empty() {
        let _ = writeln!(md, "\n## Measured vs simulated\n");
        let _ = writeln!(md, "| quantity | measurements | RMSE |");
        let _ = writeln!(md, "|---|---|---|");
        for (quantity, count, rmse) in &summary.rmse {
            let _ = writeln!(md, "| {quantity} | {count} | {rmse:.4} |");
        }
    }
    let balance = &summary.mass_balance;
    let _ = writeln!(md, "\n## Product mass balance (g)\n");
    let _ = writeln!(md, "| term | mass (g) |");
    let _ = writeln!(md, "|---|---|");
    for (term, kg) in [
        ("on rail at start", balance.on_rail_start_kg),
        ("applied", balance.applied_kg),
        ("on rail at end", balance.on_rail_end_kg),
        ("carried out on wheels", balance.carried_out_kg),
        ("consumed", balance.consumed_kg),
        ("capped at m_max", balance.capped_kg),
        ("lost to time effects", balance.effects_lost_kg),
    ] {
        let _ = writeln!(md, "| {term} | {:.3} |", kg * G_PER_KG);
    }
    let _ = writeln!(
        md,
        "\nrelative closing error: {:.2e}",
        balance.closing_error()
    );
    let [low, high] = mu_color_range;
    let (rows, every) = history;
    let _ = writeln!(md, "\n## Reading the views\n");
    if rows > 0 {
        let _ = writeln!(
            md,
            "- mu history heatmaps: one row per train (the last {rows}), newest at the bottom, \
             one column per grid point, updated every {every} trains and after the last one; \
             colour Viridis from mu = {low:.2} (dark purple) to {high:.2} (yellow)"
        );
    }
    let _ = writeln!(
        md,
        "- site plots: dots are the measurements, the pale line through small dots the twin"
    );
    md
}
