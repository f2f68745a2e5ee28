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
//!   `BATCH_CHUNK_BYTES`, and the rest at [`Sink::finish`]. A row logged
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
//!   cut into chunks by size (`BATCH_CHUNK_BYTES`, about the viewer's own
//!   chunk size, or [`SERIES_CHUNK_ROWS`] rows), not every 200 ms of wall
//!   clock, and the SDK's queues hold at most `MAX_BYTES_IN_FLIGHT`: few
//!   large chunks (the file's footer keeps an entry per chunk until the
//!   end) and a file that does not depend on how fast the machine ran.
//!
//! The sink's own collections are bounded by the section: a style flag per
//! series, the sites' quantities and rails, the applicators, up to
//! [`SERIES_CHUNK_ROWS`] values per series, about `BATCH_CHUNK_BYTES` of
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
//!
//! # Files
//! The recording is written to `.NAME.partial-XXXXXX` next to the target
//! ([`crate::files::PartialFile`]); [`Sink::finish`] sends the buffered
//! profiles and series and the last heatmaps, flushes the stream, closes it
//! (which writes the rrd footer) and moves the file into place. A sink
//! dropped without `finish` closes the stream and deletes the temporary
//! file.
//!
//! The code: `sink.rs` the [`RerunSink`] (time, the engine's events, finish);
//! `error.rs` [`RerunError`]; `batch.rs` what it holds back and sends as columns (profiles, series,
//! heatmaps); `entities.rs` the entity paths, labels and colours;
//! `section.rs` what is logged once at the start (the section page and
//! map); `summary.rs` the run summary page; `blueprint.rs` the layout.
//!
//! [`Sink::begin`]: tortwin_engine::sink::Sink::begin
//! [`Sink::finish`]: tortwin_engine::sink::Sink::finish
//! [`FieldSnapshot::wheel_pass`]: tortwin_engine::sink::FieldSnapshot::wheel_pass
//! [`RecordingStream::send_columns`]: rerun::RecordingStream::send_columns
//! [`RecordingStream::send_blueprint`]: rerun::RecordingStream::send_blueprint
//! [`EntityPath`]: rerun::EntityPath

mod batch;
mod blueprint;
mod entities;
mod error;
mod section;
mod sink;
mod summary;

pub use error::RerunError;
pub use sink::RerunSink;

use crate::provenance::Provenance;

/// Stores `provenance` as the recording property `provenance`: one text
/// per [`Provenance::to_pairs`] key, shown in the viewer's recording panel.
pub fn send_provenance(
    rec: &rerun::RecordingStream,
    provenance: &Provenance,
) -> rerun::RecordingStreamResult<()> {
    let mut values = rerun::AnyValues::default();
    for (key, text) in provenance.to_pairs() {
        // The keys are fixed, non-empty names: always valid.
        if let Ok(field) = rerun::ComponentIdentifier::try_new(&key) {
            values = values.with_component::<rerun::components::Text>(field, [text]);
        }
    }
    rec.send_property("provenance", &values)
}

/// Name of the sequence timeline: wheel passes so far.
pub(crate) const TIMELINE_WHEEL_PASS: &str = "wheel_pass";
/// Name of the timestamp timeline: the events' log_time.
pub(crate) const TIMELINE_TIME: &str = "time";

const MG_PER_KG: f64 = 1e6;
const G_PER_KG: f64 = 1e3;
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
pub(crate) const BATCH_CHUNK_BYTES: u64 = 384 * 1024;
/// The most the SDK's queues hold before `log` waits for the writer (rerun's
/// default is 100 MiB).
pub(crate) const MAX_BYTES_IN_FLIGHT: u64 = 8 * 1024 * 1024;

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
    /// last train at [`Sink::finish`](tortwin_engine::sink::Sink::finish); 1 (or 0) logs them at every train.
    /// Each log stores the whole heatmap (`K` rows), so this divides their
    /// share of the file.
    pub history_every: usize,
    /// The heatmap colour scale for mu, fixed for the whole run so a colour
    /// means the same mu at every train. `None`: the run's mu range, rounded
    /// out to 0.05 (known, and logged, at [`Sink::finish`](tortwin_engine::sink::Sink::finish)).
    pub mu_color_range: Option<[f64; 2]>,
    /// Send the default layout (see the module docs).
    pub blueprint: bool,
    /// Stored as the recording property `provenance` (one text per
    /// [`Provenance::to_pairs`] key), shown in the viewer's recording panel.
    pub provenance: Option<Provenance>,
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
            provenance: None,
        }
    }
}
