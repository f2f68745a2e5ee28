//! What the sink holds back and sends as columns (see "Memory and size" in
//! the module docs): a track's profiles, a chunk of about
//! [`super::BATCH_CHUNK_BYTES`] per quantity; a pulse or measurement series,
//! [`super::SERIES_CHUNK_ROWS`] values; and a track's mu history, logged
//! whole as a heatmap.

use std::collections::VecDeque;

use rerun::datatypes::{TensorBuffer, TensorData};
use rerun::external::arrow::datatypes::{ArrowPrimitiveType, Float16Type};
use rerun::{EntityPath, RecordingStream, RecordingStreamError, TimeColumn};

use super::entities::TrackEntities;
use super::{TIMELINE_TIME, TIMELINE_WHEEL_PASS};

/// `half::f16`, named through arrow so the crate needs no `half` dependency.
pub(super) type F16 = <Float16Type as ArrowPrimitiveType>::Native;

/// A track's entities and what the sink holds back for it.
pub(super) struct TrackState {
    pub(super) entities: TrackEntities,
    /// mu after each of the last K trains, oldest first.
    pub(super) history: VecDeque<Vec<F16>>,
    /// Trains added to `history` since it was last logged.
    pub(super) history_unlogged: usize,
    /// `(log_time_ns, wheel_pass)` of the last train snapshot: where the
    /// heatmap is logged at finish if that train's was not.
    pub(super) last_train: Option<(u64, u64)>,
    /// Profiles not sent yet.
    pub(super) pending: PendingProfiles,
}

impl TrackState {
    pub(super) fn new(entities: TrackEntities) -> Self {
        TrackState {
            entities,
            history: VecDeque::new(),
            history_unlogged: 0,
            last_train: None,
            pending: PendingProfiles::default(),
        }
    }
}

/// A track's profiles not sent yet, a row per snapshot; the quantities
/// share the times.
#[derive(Default)]
pub(super) struct PendingProfiles {
    pub(super) times_ns: Vec<i64>,
    pub(super) wheel_passes: Vec<i64>,
    /// mu, adhesion, rail product (mg), wheel product (mg), as f32.
    pub(super) values: [Vec<Vec<f32>>; 4],
}

/// A scalar series on `time`, buffered until it is sent as columns.
#[derive(Default)]
pub(super) struct Series {
    pub(super) times_ns: Vec<i64>,
    pub(super) values: Vec<f64>,
}

/// Sends a track's buffered profiles, a chunk per quantity.
pub(super) fn send_profiles(
    rec: &RecordingStream,
    track: &mut TrackState,
) -> Result<(), RecordingStreamError> {
    let pending = std::mem::take(&mut track.pending);
    if pending.times_ns.is_empty() {
        return Ok(());
    }
    for (path, rows) in track.entities.profiles().into_iter().zip(pending.values) {
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
pub(super) fn log_history(
    rec: &RecordingStream,
    track: &mut TrackState,
    grid_len: usize,
) -> Result<(), RecordingStreamError> {
    let rows = track.history.len();
    let flat: Vec<F16> = track.history.iter().flatten().copied().collect();
    let heatmap = TensorData::new(
        vec![rows as u64, grid_len as u64],
        TensorBuffer::F16(flat.into()),
    )
    .with_dim_names(["train (newest at the bottom)", "grid point i (d = i*C)"]);
    rec.log(
        track.entities.mu_history.clone(),
        &rerun::Tensor::new(heatmap),
    )?;
    track.history_unlogged = 0;
    Ok(())
}

/// Sends a buffered series as one chunk on `time`.
pub(super) fn send_series(
    rec: &RecordingStream,
    path: EntityPath,
    series: Series,
) -> Result<(), RecordingStreamError> {
    let time = TimeColumn::new_timestamp_nanos_since_epoch(TIMELINE_TIME, series.times_ns);
    rec.send_columns(
        path,
        [time],
        rerun::Scalars::new(series.values).columns_of_unit_batches()?,
    )?;
    Ok(())
}
