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
//! Memory grows with the section, not with the recording, and a year of
//! traffic (14 600 trains on a 1.5 km curve) stays under 150 MB:
//! - what is logged at every snapshot, pulse or measurement is not logged
//!   row by row: the sink buffers it and sends it as columns
//!   ([`RecordingStream::send_columns`]), a chunk per entity of
//!   [`SERIES_CHUNK_ROWS`] values or, for the snapshots, about
//!   `BATCH_CHUNK_BYTES`, and the rest at [`Sink::finish`] (a row logged
//!   through the SDK's batcher costs several times its data while it waits,
//!   and the batcher fell behind the engine);
//! - a snapshot is stored as what the views draw: a class id (u16) per grid
//!   point for the curve's two layers, and each profile as a line through
//!   the fewest points that stay within [`curve::MU_TOLERANCE`] of mu (or
//!   [`curve::DECADE_TOLERANCE`] of the product's decades): a few dozen
//!   points where the grid has hundreds (the exact values are in the MCAP
//!   output and the tables);
//! - the mu history is stored once per train (u8 classes), in blocks of
//!   [`RerunOptions::history_rows`] trains, each logged again as it grows
//!   every [`RerunOptions::history_every`] trains;
//! - what still goes through the batcher (trains, static data) is cut into
//!   chunks by size, not every 200 ms of wall clock, and the SDK's queues
//!   hold at most `MAX_BYTES_IN_FLIGHT`.
//!
//! # Entity layout
//! Rail and band names are taken verbatim (escaped by [`EntityPath`]).
//! The plan is [`crate::geometry`]'s, x and y in m; the colours are
//! [`crate::scale`]'s, given by annotation contexts (class id -> label and
//! colour) at `curve/mu`, `curve/product` and `history`.
//!
//! | entity                                         | archetype              | logged        |
//! |------------------------------------------------|------------------------|---------------|
//! | `section/description`                          | `TextDocument`         | static        |
//! | `curve/mu`, `curve/product`, `history`         | `AnnotationContext`    | static        |
//! | `curve/<layer>/rails/<rail>`                   | `LineStrips2D`         | static        |
//! | `curve/<layer>/tracks/<rail>/<band>`           | `Points2D`: positions static, class ids per snapshot | every snapshot |
//! | `curve/<layer>/applicators`, `…/sites`         | `Points2D` with labels | static        |
//! | `curve/<layer>/legend/bar`, `…/ticks`          | `Boxes2D`, `Points2D`  | static        |
//! | `profiles/mu/<rail>/<band>/mu`, `…/adhesion`   | `LineStrips2D` (x = d in m, y = -mu x L) | every snapshot |
//! | `profiles/product/<rail>/<band>/rail`, `…/wheel` | `LineStrips2D` (decades of mg) | every snapshot |
//! | `profiles/<view>/frame/**`                     | grid lines, labels, target band, applicators | static |
//! | `line/mu/<rail>/axle`, `…/next_axle`, `…/rail_mu` | `LineStrips2D` (as the mu profiles): on a line, mu the watched axle (`--line-axle`) and the next saw, what `rail_mu` reads on the crown | every train |
//! | `line/tread/<rail>/F`, `…/C`, `…/G`           | `LineStrips2D` (as the product profiles): the watched axle's tread bands | every train |
//! | `history/<rail>/<band>/block_NNNN`             | `SegmentationImage` (u8 mu classes), `Transform3D` (static: d in m across) | every `E` trains |
//! | `history/<rail>/<band>/distance`               | `Points2D` labelled every 100 m | static |
//! | `sites/<site>/<rail>/<quantity>`               | `Scalars` [measured, simulated] + `SeriesPoints` | measurement (`time`) |
//! | `applicator/<id>/<rail>`                       | `Scalars`: g since the previous train + `SeriesPoints` | train snapshot (`time`) |
//! | `trains`                                       | `TextLog`              | train         |
//! | `alerts`                                       | `TextLog` (ERROR, WARN, INFO when cleared) | alert raised or cleared |
//! | `run/summary`                                  | `TextDocument`         | static, at finish |
//!
//! # Blueprint
//! The layout is written by hand into a blueprint store rather than through
//! [`rerun_sdk::blueprint::Blueprint`]: the 0.36 Rust builder has no way to set
//! view properties (a time series' visible range, a plot legend), which
//! this layout needs. It logs the same archetypes the builder does plus
//! those properties under `view/<id>/<Archetype>`, and sends the store with
//! [`RecordingStream::send_blueprint`], so it lands in the same `.rrd`.
//! It is sent at [`Sink::finish`], when the run is known:
//! - left, tabs "curve: mu" and "curve: product" (the plan, coloured, with
//!   its legend) above the profiles (mu and adhesion; the product);
//!   On a line a third tab, open, shows per rail what the watched axles saw
//!   and the watched axle's tread bands;
//! - right, a tab per site (a plot per quantity and rail), the mu history
//!   per track, and tabs with the trains, pulses, section and run summary;
//! - the time panel on `time`, following the data (the viewer opens at the
//!   end of the run).
//!
//! What 0.36 cannot do: set the time cursor itself, draw axes in a 2D view
//! (the profiles carry their own grid lines and labels), or fill a box in
//! 2D (the band is a line as thick as the band).
//!
//! # Files
//! The recording is written to `.NAME.partial-XXXXXX` next to the target
//! ([`crate::files::PartialFile`]); [`Sink::finish`] sends the buffered
//! rows, series and last history blocks, flushes the stream, closes it
//! (which writes the rrd footer) and moves the file into place. A sink
//! dropped without `finish` closes the stream and deletes the temporary
//! file.
//!
//! The code: `sink.rs` the [`RerunSink`] (time, the engine's events, finish);
//! `error.rs` [`RerunError`]; `batch.rs` what it holds back and sends as columns (profiles, series,
//! history blocks); `curve.rs` the plan, the profiles' frames and lines;
//! `entities.rs` the entity paths, labels and colours;
//! `section.rs` the section page; `summary.rs` the run summary page; `blueprint.rs` the layout.
//!
//! [`Sink::begin`]: tortwin_engine::sink::Sink::begin
//! [`Sink::finish`]: tortwin_engine::sink::Sink::finish
//! [`FieldSnapshot::wheel_pass`]: tortwin_engine::sink::FieldSnapshot::wheel_pass
//! [`RecordingStream::send_columns`]: rerun_sdk::RecordingStream::send_columns
//! [`RecordingStream::send_blueprint`]: rerun_sdk::RecordingStream::send_blueprint
//! [`EntityPath`]: rerun_sdk::EntityPath

mod batch;
mod blueprint;
mod curve;
mod entities;
mod error;
mod section;
mod sink;
mod summary;

pub use blueprint::{blueprint_store, send_blueprint, BlueprintItem, BlueprintWriter};
pub use error::RerunError;
pub use sink::RerunSink;

use crate::provenance::Provenance;
use crate::rerun_sdk;

/// Stores `provenance` as the recording property `provenance`: one text
/// per [`Provenance::to_pairs`] key, shown in the viewer's recording panel.
pub fn send_provenance(
    rec: &rerun_sdk::RecordingStream,
    provenance: &Provenance,
) -> rerun_sdk::RecordingStreamResult<()> {
    let mut values = rerun_sdk::AnyValues::default();
    for (key, text) in provenance.to_pairs() {
        // The keys are fixed, non-empty names: always valid.
        if let Ok(field) = rerun_sdk::ComponentIdentifier::try_new(&key) {
            values = values.with_component::<rerun_sdk::components::Text>(field, [text]);
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
    /// `B`: trains per block of the mu history; 0 logs no history.
    pub history_rows: usize,
    /// `E`: the block being filled is logged after every `E`-th train, and
    /// after the last train at [`Sink::finish`](tortwin_engine::sink::Sink::finish);
    /// a full block once more. Each log stores the block so far, so
    /// this trades how far the history lags behind the cursor against size.
    pub history_every: usize,
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
            history_rows: 64,
            // B / 4: the history is never more than 15 trains behind the
            // cursor, and every train's row is stored 2.5 times.
            history_every: 16,
            blueprint: true,
            provenance: None,
        }
    }
}
