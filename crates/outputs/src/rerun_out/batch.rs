//! What the sink holds back and sends as columns (see "Memory and size" in
//! the module docs): a track's rows (the curve's classes and the profile
//! lines of each snapshot), a pulse or measurement series
//! ([`super::SERIES_CHUNK_ROWS`] values), and the block of the mu history
//! being filled.

use crate::rerun_sdk;
use crate::rerun_sdk::components::ClassId;
use crate::rerun_sdk::datatypes::ChannelDatatype;
use crate::rerun_sdk::{EntityPath, RecordingStream, RecordingStreamError, TimeColumn};

use super::entities::TrackEntities;
use super::{TIMELINE_TIME, TIMELINE_WHEEL_PASS};

/// A track's entities and what the sink holds back for it.
pub(super) struct TrackState {
    /// The track's index in the engine's order.
    pub(super) index: usize,
    pub(super) entities: TrackEntities,
    /// Rows not sent yet.
    pub(super) pending: PendingRows,
    /// The mu classes of the trains of the block being filled, a row of
    /// grid points per train (u8: the scale has 80 classes).
    pub(super) block: Vec<u8>,
    /// Index of that block (rows `block_index * B ..`).
    pub(super) block_index: usize,
    /// Trains added to the block since it was last logged.
    pub(super) block_unlogged: usize,
    /// `(log_time_ns, wheel_pass)` of the last train snapshot: where the
    /// block is logged at finish if it was not.
    pub(super) last_train: Option<(u64, u64)>,
}

impl TrackState {
    pub(super) fn new(index: usize, entities: TrackEntities) -> Self {
        TrackState {
            index,
            entities,
            pending: PendingRows::default(),
            block: Vec::new(),
            block_index: 0,
            block_unlogged: 0,
            last_train: None,
        }
    }
}

/// A track's snapshots not sent yet; the entities share the times.
#[derive(Default)]
pub(super) struct PendingRows {
    pub(super) times_ns: Vec<i64>,
    pub(super) wheel_passes: Vec<i64>,
    /// The curve's mu classes, every snapshot's grid points one after the other.
    pub(super) mu_ids: Vec<u16>,
    /// The curve's rail product classes, likewise.
    pub(super) mass_ids: Vec<u16>,
    /// Simplified lines per snapshot: mu, adhesion, rail product, wheel
    /// product, in their views' coordinates; one per run of points with a
    /// value (a line's band no wheel used at some points has gaps there).
    pub(super) strips: [Vec<Vec<[f32; 2]>>; 4],
    /// How many of `strips` each snapshot has, per profile.
    pub(super) strips_per_row: [Vec<usize>; 4],
}

impl PendingRows {
    pub(super) fn len(&self) -> usize {
        self.times_ns.len()
    }
}

/// A scalar series on `time` (`width` values per row), buffered until it
/// is sent as columns.
#[derive(Default)]
pub(super) struct Series {
    pub(super) width: usize,
    pub(super) times_ns: Vec<i64>,
    pub(super) values: Vec<f64>,
}

/// Sends a track's buffered rows: a chunk per entity.
pub(super) fn send_rows(
    rec: &RecordingStream,
    track: &mut TrackState,
    grid_len: usize,
) -> Result<(), RecordingStreamError> {
    let pending = std::mem::take(&mut track.pending);
    let rows = pending.len();
    if rows == 0 {
        return Ok(());
    }
    let indexes = || {
        [
            TimeColumn::new_timestamp_nanos_since_epoch(
                TIMELINE_TIME,
                pending.times_ns.iter().copied(),
            ),
            TimeColumn::new_sequence(TIMELINE_WHEEL_PASS, pending.wheel_passes.iter().copied()),
        ]
    };
    let lengths = std::iter::repeat_n(grid_len, rows);
    for (path, ids) in [
        (&track.entities.curve_mu, pending.mu_ids),
        (&track.entities.curve_product, pending.mass_ids),
    ] {
        rec.send_columns(
            path.clone(),
            indexes(),
            rerun_sdk::Points2D::update_fields()
                .with_class_ids(ids.into_iter().map(ClassId::from))
                .columns(lengths.clone())?,
        )?;
    }
    let profiles = pending.strips.into_iter().zip(pending.strips_per_row);
    for (path, (strips, per_row)) in track.entities.profiles().into_iter().zip(profiles) {
        rec.send_columns(
            path.clone(),
            indexes(),
            rerun_sdk::LineStrips2D::update_fields()
                .with_strips(strips)
                .columns(per_row)?,
        )?;
    }
    Ok(())
}

/// Sends the block being filled as a segmentation image (a row per train,
/// a column per grid point) at `time_ns` and `wheel_pass`: as a chunk of
/// its own, not through the batcher, which would hold every block of a
/// long run until the end (a block's few logs never reach its size limit).
pub(super) fn log_block(
    rec: &RecordingStream,
    track: &mut TrackState,
    grid_len: usize,
    time_ns: i64,
    wheel_pass: i64,
) -> Result<(), RecordingStreamError> {
    let rows = track.block.len() / grid_len.max(1);
    if rows == 0 {
        return Ok(());
    }
    let path = block_path(&track.entities.history, track.block_index);
    rec.send_columns(
        path,
        [
            TimeColumn::new_timestamp_nanos_since_epoch(TIMELINE_TIME, [time_ns]),
            TimeColumn::new_sequence(TIMELINE_WHEEL_PASS, [wheel_pass]),
        ],
        rerun_sdk::SegmentationImage::new(
            track.block.clone(),
            rerun_sdk::components::ImageFormat::segmentation(
                [grid_len as u32, rows as u32],
                ChannelDatatype::U8,
            ),
        )
        .columns_of_unit_batches()?,
    )?;
    track.block_unlogged = 0;
    Ok(())
}

/// `history/<rail>/<band>/block_0003`.
pub(super) fn block_path(history: &EntityPath, block: usize) -> EntityPath {
    history.join(&EntityPath::from_single_string(format!("block_{block:04}")))
}

/// Sends a buffered series as one chunk on `time`.
pub(super) fn send_series(
    rec: &RecordingStream,
    path: EntityPath,
    series: Series,
) -> Result<(), RecordingStreamError> {
    let rows = series.times_ns.len();
    let time = TimeColumn::new_timestamp_nanos_since_epoch(TIMELINE_TIME, series.times_ns);
    rec.send_columns(
        path,
        [time],
        rerun_sdk::Scalars::new(series.values)
            .columns(std::iter::repeat_n(series.width.max(1), rows))?,
    )?;
    Ok(())
}
