//! The sink: the recording stream and its file, the time of each log, and
//! what each of the engine's events becomes.

use crate::rerun_sdk;
use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::Path;
use std::time::Duration;

use crate::rerun_sdk::components::{MarkerShape, TextLogLevel};
use crate::rerun_sdk::log::ChunkBatcherConfig;
use crate::rerun_sdk::sink::SinkFlushError;
use crate::rerun_sdk::{
    ApplicationId, AsComponents, EntityPath, RecordingStream, RecordingStreamBuilder, TimeCell,
};
use tortwin_engine::sink::{
    Alert, FieldSnapshot, LineWheels, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink,
    SinkResult, SnapshotKind, TrainEvent,
};
use tortwin_recording::{Direction, Quantity};

use super::batch::{block_path, log_block, send_rows, send_series, Series, TrackState};
use super::blueprint::{blueprint, send_blueprint, Layout, Measured, Run};
use super::curve::{self, Frames};
use super::entities::{entity, lighten, rail_color, LineWheelEntities, TrackEntities, QUANTITIES};
use super::error::{sdk_error, RerunError};
use super::section::log_description;
use super::summary::summarize;
use super::{
    send_provenance, RerunOptions, BATCH_CHUNK_BYTES, G_PER_KG, MAX_BYTES_IN_FLIGHT, MG_PER_KG,
    SERIES_CHUNK_ROWS, TIMELINE_TIME, TIMELINE_WHEEL_PASS,
};
use crate::files::PartialFile;

/// The application id of `options`, checked (`target` names the output).
fn checked_id(target: &Path, id: &str) -> Result<ApplicationId, RerunError> {
    ApplicationId::try_new(id).map_err(|source| RerunError::ApplicationId {
        path: target.to_path_buf(),
        id: id.to_owned(),
        source,
    })
}

/// How long the end of a recording waits for a viewer to take what was sent.
const STREAM_FLUSH_TIMEOUT: Duration = Duration::from_secs(10);

/// How long a flush into the file waits between looks at the file.
const FLUSH_STEP: Duration = Duration::from_millis(500);

/// A flush into the file is given up when the file has not grown for this
/// long ([`RerunSink::flush_file`]).
const STALLED_WRITER: Duration = Duration::from_secs(10);

/// Writes the twin's results to a rerun `.rrd` (see the module docs).
pub struct RerunSink {
    /// `None` once [`Sink::finish`] has closed the stream.
    rec: Option<RecordingStream>,
    /// The output under its temporary name; renamed at finish, deleted if
    /// dropped before. `None` for a stream to a viewer ([`RerunSink::connect`]).
    file: Option<PartialFile>,
    /// What errors name: the file's final path, or the viewer's URL.
    target: std::path::PathBuf,
    /// [`RerunOptions::application_id`], checked; the blueprint's too.
    application_id: ApplicationId,
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
    /// Each (site, rail, quantity) measured so far: its entity, styled and
    /// entered in `measured` when first seen (a measurement is then one
    /// lookup, not a path to intern and a style to build).
    measurement_paths: HashMap<(usize, usize, Quantity), EntityPath>,
    /// Per site index, per quantity (in [`QUANTITIES`] order): the
    /// quantity and the rails it was measured on.
    measured: Measured,
    /// Applicator entities that received a pulse.
    pulsed: BTreeSet<EntityPath>,
    /// Pulse and measurement values not sent yet, per entity.
    series: HashMap<EntityPath, Series>,
    /// Product of each applicator entity's pulses since the last snapshot (g).
    pulse_totals: BTreeMap<EntityPath, f64>,
    /// The views' coordinates, from [`Sink::begin`].
    frames: Option<Frames>,
    /// The grid, for the profile lines.
    grid_d_m: Vec<f64>,
    /// Reused: a snapshot's rail product in mg, and a line's values.
    scratch: Vec<f64>,
    /// First and last log_time of anything logged on `time`.
    time_span_ns: Option<[u64; 2]>,
    /// On a line: the axle the first [`Sink::line_wheels`] watched, and the
    /// rails it was given for.
    line_wheels: Option<(usize, BTreeSet<usize>)>,
}

impl RerunSink {
    /// Opens `.NAME.partial-XXXXXX` next to `path` as the recording's file.
    pub fn create(path: &Path, options: RerunOptions) -> Result<RerunSink, RerunError> {
        let file = PartialFile::beside(path)?;
        let file_name = path.file_name().unwrap_or_default();

        let recording_name = options
            .recording_name
            .clone()
            .unwrap_or_else(|| file_name.to_string_lossy().into_owned());
        let application_id = checked_id(path, &options.application_id)?;
        // `enabled(true)`: the user asked for this file, so the `RERUN=off`
        // environment switch must not silently drop it.
        let builder = RecordingStreamBuilder::new(application_id.clone())
            .recording_name(recording_name)
            .enabled(true)
            .batcher_config(ChunkBatcherConfig {
                flush_tick: Duration::MAX,
                flush_num_bytes: BATCH_CHUNK_BYTES,
                flush_num_rows: SERIES_CHUNK_ROWS as u64,
                max_bytes_in_flight: MAX_BYTES_IN_FLIGHT,
                ..ChunkBatcherConfig::DEFAULT
            });
        // rerun's file sink creates the file by its path, at once.
        let rec = file
            .open_with(|temp| builder.save(temp))
            .map_err(sdk_error(path, || "starting the recording".to_owned()))?;
        rec.set_log_time_enabled(false);
        rec.set_log_tick_enabled(false);
        if let Some(provenance) = &options.provenance {
            send_provenance(&rec, provenance)
                .map_err(sdk_error(path, || "writing the provenance".to_owned()))?;
        }

        let target = file.final_path().to_path_buf();
        Ok(RerunSink::new(
            rec,
            Some(file),
            target,
            application_id,
            options,
        ))
    }

    /// A sink that has seen nothing yet, writing to `rec`.
    fn new(
        rec: RecordingStream,
        file: Option<PartialFile>,
        target: std::path::PathBuf,
        application_id: ApplicationId,
        options: RerunOptions,
    ) -> RerunSink {
        RerunSink {
            rec: Some(rec),
            file,
            target,
            application_id,
            options,
            layout: None,
            tracks: Vec::new(),
            grid_len: 0,
            profile_chunk_rows: 1,
            wheel_pass: 0,
            styled: HashSet::new(),
            measurement_paths: HashMap::new(),
            measured: BTreeMap::new(),
            pulsed: BTreeSet::new(),
            series: HashMap::new(),
            pulse_totals: BTreeMap::new(),
            frames: None,
            grid_d_m: Vec::new(),
            scratch: Vec::new(),
            time_span_ns: None,
            line_wheels: None,
        }
    }

    /// A stream to a running viewer, or to a gRPC server that relays to
    /// viewers, at `url` (`rerun+http://HOST:PORT/proxy`), as the recording
    /// `recording_id`, for [`RerunSink::on_stream`]: one stream for a whole
    /// follow, so that a folder's recordings add to one recording in the
    /// viewer. What the viewer has not taken waits in memory. Dropping the
    /// last handle waits for the viewer to take everything, for ever if it
    /// never comes: see [`RerunSink::let_go`].
    pub fn viewer_stream(
        url: &str,
        recording_id: &str,
        options: &RerunOptions,
    ) -> Result<RecordingStream, RerunError> {
        let target = std::path::PathBuf::from(url);
        let application_id = checked_id(&target, &options.application_id)?;
        let recording_name = options
            .recording_name
            .clone()
            .unwrap_or_else(|| recording_id.to_owned());
        let rec = RecordingStreamBuilder::new(application_id)
            .recording_id(recording_id.to_owned())
            .recording_name(recording_name)
            .enabled(true)
            .batcher_config(ChunkBatcherConfig {
                max_bytes_in_flight: MAX_BYTES_IN_FLIGHT,
                ..ChunkBatcherConfig::LOW_LATENCY
            })
            .connect_grpc_opts(url)
            .map_err(sdk_error(&target, || "connecting to the viewer".to_owned()))?;
        rec.set_log_time_enabled(false);
        rec.set_log_tick_enabled(false);
        if let Some(provenance) = &options.provenance {
            send_provenance(&rec, provenance)
                .map_err(sdk_error(&target, || "sending the provenance".to_owned()))?;
        }
        Ok(rec)
    }

    /// Ends a [`RerunSink::viewer_stream`]: waits up to 10 s for the viewer
    /// to take what is left; a viewer that is not there is said on stderr
    /// and the stream let go without waiting (its threads end with the
    /// process).
    pub fn let_go(rec: RecordingStream, url: &str) {
        match rec.flush_with_timeout(STREAM_FLUSH_TIMEOUT) {
            Ok(()) => drop(rec),
            Err(e) => {
                eprintln!("warning: the rerun viewer at {url} did not take everything: {e}");
                std::mem::forget(rec);
            }
        }
    }

    /// Writes to `rec`, a [`RerunSink::viewer_stream`] (`url` names it in
    /// errors): the same entities and values as [`RerunSink::create`]'s
    /// file; each train's profiles and series are sent once its field is
    /// in (a file batches them), and the layout at the start and again at
    /// the end.
    pub fn on_stream(
        rec: RecordingStream,
        url: &str,
        options: RerunOptions,
    ) -> Result<RerunSink, RerunError> {
        let target = std::path::PathBuf::from(url);
        let application_id = checked_id(&target, &options.application_id)?;
        Ok(RerunSink::new(rec, None, target, application_id, options))
    }

    /// Flushes `rec` into the file. rerun 0.36's file sink can leave a
    /// flush unanswered when its writer thread has stopped on a write
    /// error (seen under a file-size limit: a replay waited in
    /// `flush_blocking` for ever, now and then). So the flush is waited for
    /// in steps, and given up as [`SinkFlushError::Timeout`] once the file
    /// has not grown for [`STALLED_WRITER`]: a writer that is writing
    /// makes the file grow.
    fn flush_file(&self, rec: &RecordingStream) -> Result<(), SinkFlushError> {
        let size = || {
            self.file
                .as_ref()
                .and_then(|f| std::fs::metadata(f.temp_path()).ok())
                .map(|m| m.len())
        };
        let mut last = (size(), std::time::Instant::now());
        loop {
            match rec.flush_with_timeout(FLUSH_STEP) {
                Err(SinkFlushError::Timeout) => {
                    let now = size();
                    if now != last.0 {
                        last = (now, std::time::Instant::now());
                    } else if last.1.elapsed() >= STALLED_WRITER {
                        return Err(SinkFlushError::Timeout);
                    }
                }
                done => return done,
            }
        }
    }

    /// The output's final path (or the viewer's URL), which the errors name.
    fn path(&self) -> &Path {
        &self.target
    }

    fn rec(&self) -> Result<&RecordingStream, RerunError> {
        self.rec.as_ref().ok_or_else(|| RerunError::Finished {
            path: self.path().to_path_buf(),
        })
    }

    /// Sets the calling thread's time: `time` always, `wheel_pass` if given
    /// (else that timeline is cleared). The next logs land there. Returns
    /// the time as rerun takes it.
    fn set_time(&mut self, log_time_ns: u64, wheel_pass: Option<u64>) -> Result<i64, RerunError> {
        let time_ns = self.note_time(log_time_ns)?;
        let wheel_pass = wheel_pass.map(|w| self.sequence(w)).transpose()?;
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

    /// A wheel pass count as the `wheel_pass` timeline takes it.
    fn sequence(&self, wheel_pass: u64) -> Result<i64, RerunError> {
        i64::try_from(wheel_pass).map_err(|_| RerunError::OutOfRange {
            path: self.path().to_path_buf(),
            what: "wheel_pass",
            value: wheel_pass,
        })
    }

    /// Checks a log_time and widens the run's time span by it.
    fn note_time(&mut self, log_time_ns: u64) -> Result<i64, RerunError> {
        let time_ns = i64::try_from(log_time_ns).map_err(|_| RerunError::OutOfRange {
            path: self.path().to_path_buf(),
            what: "log_time (ns)",
            value: log_time_ns,
        })?;
        self.time_span_ns = Some(match self.time_span_ns {
            Some([first, last]) => [first.min(log_time_ns), last.max(log_time_ns)],
            None => [log_time_ns, log_time_ns],
        });
        Ok(time_ns)
    }

    /// Adds a value to the series at `path` on `time`; sends the series once
    /// it holds [`SERIES_CHUNK_ROWS`] values. `what` names the event in an
    /// error.
    fn push_series(
        &mut self,
        path: EntityPath,
        log_time_ns: u64,
        values: &[f64],
        what: impl FnOnce() -> String,
    ) -> Result<(), RerunError> {
        let time_ns = self.note_time(log_time_ns)?;
        let series = self.series.entry(path.clone()).or_insert_with(|| Series {
            width: values.len(),
            ..Series::default()
        });
        series.times_ns.push(time_ns);
        series.values.extend_from_slice(values);
        if series.times_ns.len() >= SERIES_CHUNK_ROWS {
            // The entity keeps its width for the rows still to come.
            let series = std::mem::replace(
                series,
                Series {
                    width: values.len(),
                    ..Series::default()
                },
            );
            send_series(self.rec()?, path, series).map_err(sdk_error(self.path(), what))?;
        }
        Ok(())
    }

    /// Adds the pulses since the last snapshot to the applicators' series,
    /// at `log_time_ns`.
    fn flush_pulses(&mut self, log_time_ns: u64) -> Result<(), RerunError> {
        for (path, grams) in std::mem::take(&mut self.pulse_totals) {
            self.push_series(path, log_time_ns, &[grams], || "pulses".to_owned())?;
        }
        Ok(())
    }

    /// Sends every buffered series.
    fn flush_series(&mut self) -> Result<(), RerunError> {
        let rec = self.rec.as_ref().ok_or_else(|| RerunError::Finished {
            path: self.target.clone(),
        })?;
        // In the entities' order, whatever the map's.
        let mut all: Vec<_> = std::mem::take(&mut self.series).into_iter().collect();
        all.sort_by(|a, b| a.0.cmp(&b.0));
        for (path, series) in all {
            if !series.values.is_empty() {
                send_series(rec, path, series).map_err(sdk_error(&self.target, || {
                    "pulses and measurements".to_owned()
                }))?;
            }
        }
        Ok(())
    }

    /// The first measurement of its site, rail and quantity: the entity,
    /// its style, and the blueprint's note that it was measured.
    fn first_measurement(&mut self, m: &MeasurementOutput) -> Result<EntityPath, RerunError> {
        let path = entity(&["sites", &m.site_id, &m.rail_name, m.quantity.as_str()]);
        let color = rail_color(m.rail);
        let pale = lighten(color, 0.45);
        // Measured and simulated share a row (and its time): the measured
        // value as a dot in the rail's colour, the twin's as a smaller pale
        // one beside it.
        self.style_once(
            &path,
            &[&rerun_sdk::SeriesPoints::new()
                .with_names(["measured", "simulated (twin)"])
                .with_colors([color, pale])
                .with_markers([MarkerShape::Circle, MarkerShape::Circle])
                .with_marker_sizes([2.5, 1.5])],
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
        Ok(path)
    }

    /// Logs a time series style once per entity, statically.
    fn style_once(
        &mut self,
        path: &EntityPath,
        styles: &[&dyn AsComponents],
    ) -> Result<(), RerunError> {
        if self.styled.contains(path) {
            return Ok(());
        }
        for style in styles {
            self.rec()?
                .log_static(path.clone(), *style)
                .map_err(sdk_error(self.path(), || format!("style of {path}")))?;
        }
        self.styled.insert(path.clone());
        Ok(())
    }

    /// Sends the blueprint (unless the options say not to) for what the
    /// run has shown so far.
    fn send_layout(&self) -> Result<(), RerunError> {
        if !self.options.blueprint {
            return Ok(());
        }
        let rec = self.rec()?;
        let Some(layout) = &self.layout else {
            return Err(RerunError::NotBegun {
                path: self.path().to_path_buf(),
            });
        };
        let blueprint = blueprint(&Run {
            application_id: &self.application_id,
            layout,
            tracks: self.tracks.iter().map(|t| &t.entities).collect(),
            measured: &self.measured,
            pulsed: &self.pulsed,
            history_rows: self.options.history_rows,
            time_span_ns: self.time_span_ns,
            wheel_pass: self.wheel_pass,
            line_wheels: self.line_wheels.as_ref(),
        })
        .map_err(sdk_error(self.path(), || "blueprint".to_owned()))?;
        if !send_blueprint(rec, blueprint) {
            return Err(RerunError::EmptyBlueprint {
                path: self.path().to_path_buf(),
            });
        }
        Ok(())
    }

    /// Sends what is still buffered, the last heatmaps, the summary and the
    /// blueprint; closes the stream and moves the file into place.
    fn finish_run(&mut self, summary: &RunSummary) -> Result<(), RerunError> {
        if let Some([_, last]) = self.time_span_ns {
            self.flush_pulses(last)?;
        }
        self.flush_series()?;
        let grid_len = self.grid_len;
        if let Some(rec) = self.rec.as_ref() {
            for track in &mut self.tracks {
                send_rows(rec, track, grid_len)
                    .map_err(sdk_error(&self.target, || "profiles".to_owned()))?;
            }
        }
        // The last block of each history, where its last train was, if not yet logged.
        for index in 0..self.tracks.len() {
            let track = &self.tracks[index];
            let Some((log_time_ns, wheel_pass)) = track.last_train else {
                continue;
            };
            if track.block_unlogged == 0 {
                continue;
            }
            let time_ns = self.note_time(log_time_ns)?;
            let wheel_pass = self.sequence(wheel_pass)?;
            let rec = self.rec.as_ref().ok_or_else(|| RerunError::Finished {
                path: self.target.clone(),
            })?;
            log_block(rec, &mut self.tracks[index], grid_len, time_ns, wheel_pass)
                .map_err(sdk_error(&self.target, || "last history".to_owned()))?;
        }
        let rec = self.rec()?;
        let history = (self.options.history_rows, self.options.history_every.max(1));
        rec.log_static(
            "run/summary",
            &rerun_sdk::TextDocument::from_markdown(summarize(summary, history)),
        )
        .map_err(sdk_error(self.path(), || "summary".to_owned()))?;
        self.send_layout()?;

        let rec = self.rec.take().ok_or_else(|| RerunError::Finished {
            path: self.target.clone(),
        })?;
        if self.file.is_none() {
            // A viewer is a view, not the record (the MCAP output is): the
            // stream's owner lets it go (RerunSink::let_go); this handle
            // is not the last.
            let _ = rec.flush_async();
            return Ok(());
        }
        if let Err(source) = self.flush_file(&rec) {
            // The SDK's error does not say why; the file does.
            let error = match self.file.as_ref().map_or(Ok(()), PartialFile::probe_write) {
                Err(io) => RerunError::Write {
                    path: self.path().to_path_buf(),
                    source: io,
                },
                Ok(()) => RerunError::Flush {
                    path: self.path().to_path_buf(),
                    source,
                },
            };
            // Its threads may be waiting on the flush that never ends:
            // dropping the handle would join them. The temporary file is
            // deleted with the sink.
            std::mem::forget(rec);
            return Err(error);
        }
        // Dropping the only handle joins the SDK's threads; the file sink
        // writes the rrd footer and closes the file before this returns.
        drop(rec);
        match self.file.take() {
            Some(mut file) => Ok(file.commit()?),
            None => Ok(()),
        }
    }
}

/// Every method's error is a [`RerunError`].
impl Sink for RerunSink {
    fn begin(&mut self, info: &SectionInfo<'_>) -> SinkResult {
        self.grid_len = info.grid_d_m.len();
        // Two class ids per grid point, and the lines.
        self.profile_chunk_rows = (BATCH_CHUNK_BYTES as usize
            / (self.grid_len * 2 * std::mem::size_of::<u16>()).max(1))
        .clamp(1, SERIES_CHUNK_ROWS);
        let frames = Frames::new(info);
        self.layout = Some(Layout {
            rails: info.section.rails.clone(),
            plan_bounds: frames.plan_bounds(),
            profile_bounds: frames.profile_bounds(),
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
            .enumerate()
            .map(|(i, t)| TrackState::new(i, TrackEntities::new(t, &info.tracks)))
            .collect();
        let rec = self.rec()?;
        log_description(rec, info).map_err(sdk_error(self.path(), || "section".to_owned()))?;
        curve::log_static(rec, info, &frames, &self.tracks)
            .map_err(sdk_error(self.path(), || "the section's plan".to_owned()))?;
        self.frames = Some(frames);
        self.grid_d_m = info.grid_d_m.to_vec();
        if self.file.is_none() {
            // A viewer watching: each train's rows go at once, and the
            // layout now (again at the end, with the sites measured).
            self.profile_chunk_rows = 1;
            self.send_layout()?;
        }
        Ok(())
    }

    fn train(&mut self, train: &TrainEvent<'_>) -> SinkResult {
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
                &rerun_sdk::TextLog::new(text).with_level(TextLogLevel::INFO),
            )
            .map_err(sdk_error(self.path(), || {
                format!("train {}", train.train_id)
            }))?;
        Ok(())
    }

    fn alert(&mut self, alert: &Alert) -> SinkResult {
        self.set_time(alert.log_time_ns, Some(self.wheel_pass))?;
        let level = match crate::alerts::level(alert) {
            "error" => TextLogLevel::ERROR,
            "warning" => TextLogLevel::WARN,
            _ => TextLogLevel::INFO,
        };
        let text = format!("{}: {}", alert.kind.as_str(), alert.message);
        self.rec()?
            .log("alerts", &rerun_sdk::TextLog::new(text).with_level(level))
            .map_err(sdk_error(self.path(), || {
                format!("alert {}", alert.kind.as_str())
            }))?;
        Ok(())
    }

    fn pulse(&mut self, pulse: &PulseEvent<'_>) -> SinkResult {
        let path = entity(&["applicator", &pulse.applicator_id, &pulse.rail_name]);
        if !self.pulsed.contains(&path) {
            let name = format!(
                "{} on {} rail: g per train",
                pulse.applicator_id, pulse.rail_name
            );
            self.style_once(
                &path,
                &[&rerun_sdk::SeriesPoints::new()
                    .with_names([name])
                    .with_colors([rail_color(pulse.rail)])
                    .with_markers([MarkerShape::Diamond])
                    .with_marker_sizes([3.0])],
            )?;
            self.pulsed.insert(path.clone());
        }
        self.note_time(pulse.log_time_ns)?;
        *self.pulse_totals.entry(path).or_insert(0.0) += pulse.mass_kg * G_PER_KG;
        Ok(())
    }

    fn measurement(&mut self, m: &MeasurementOutput) -> SinkResult {
        let key = (m.site, m.rail, m.quantity);
        let path = match self.measurement_paths.get(&key) {
            Some(path) => path.clone(),
            None => {
                let path = self.first_measurement(m)?;
                self.measurement_paths.insert(key, path.clone());
                path
            }
        };
        let what = || format!("measurement {} at site {}", m.index_in_file, m.site_id);
        self.push_series(path, m.log_time_ns, &[m.measured, m.simulated], what)?;
        Ok(())
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> SinkResult {
        let grid_len = self.grid_len;
        let lengths = [
            ("d_m", f.d_m.len()),
            ("mu", f.mu.len()),
            ("adhesion", f.adhesion.len()),
            ("rail_mass_kg", f.rail_mass_kg.len()),
            ("wheel_mass_kg", f.wheel_mass_kg.len()),
        ];
        if let Some(&(field, len)) = lengths.iter().find(|(_, len)| *len != grid_len) {
            return Err(RerunError::SnapshotLength {
                path: self.path().to_path_buf(),
                train_id: f.train_id.to_string(),
                track: format!("{}/{}", f.rail_name, f.band),
                field,
                len,
                grid: grid_len,
            }
            .into());
        }
        // Checked before the sink's time and wheel passes move.
        if f.track >= self.tracks.len() {
            return Err(RerunError::NoTrack {
                path: self.path().to_path_buf(),
                track: f.track,
                tracks: self.tracks.len(),
            }
            .into());
        }

        self.flush_pulses(f.log_time_ns)?;
        self.wheel_pass = self.wheel_pass.max(f.wheel_pass);
        let wheel_pass = self.wheel_pass;
        let time_ns = self.set_time(f.log_time_ns, Some(wheel_pass))?;
        let wheel_pass_seq = self.sequence(wheel_pass)?;
        let path = self.target.as_path();
        let (Some(rec), Some(frames)) = (self.rec.as_ref(), self.frames.as_ref()) else {
            return Err(RerunError::Finished {
                path: path.to_path_buf(),
            }
            .into());
        };
        let tracks = self.tracks.len();
        let Some(track) = self.tracks.get_mut(f.track) else {
            return Err(RerunError::NoTrack {
                path: path.to_path_buf(),
                track: f.track,
                tracks,
            }
            .into());
        };
        let label = track.entities.label.clone();
        let what = || format!("field of train {} on {label}", f.train_id);
        let pending = &mut track.pending;
        pending.times_ns.push(time_ns);
        pending.wheel_passes.push(wheel_pass_seq);
        let scratch = &mut self.scratch;
        scratch.clear();
        scratch.extend(f.rail_mass_kg.iter().map(|&m| m * MG_PER_KG));
        curve::classes(
            &f.mu,
            scratch.iter().copied(),
            &mut pending.mu_ids,
            &mut pending.mass_ids,
        );
        // The profile lines, through fewer points where they are straight,
        // broken where a value is missing (NaN: no wheel on a line's band).
        let d = &self.grid_d_m;
        let profiles = [
            frames.mu_strips(d, &f.mu),
            frames.mu_strips(d, &f.adhesion),
            frames.product_strips(d, &f.rail_mass_kg),
            frames.product_strips(d, &f.wheel_mass_kg),
        ];
        for (k, strips) in profiles.into_iter().enumerate() {
            pending.strips_per_row[k].push(strips.len());
            pending.strips[k].extend(strips);
        }
        if pending.len() >= self.profile_chunk_rows {
            send_rows(rec, track, grid_len).map_err(sdk_error(path, what))?;
        }

        let block_rows = self.options.history_rows;
        if f.kind == SnapshotKind::Train && block_rows > 0 {
            if track.block.is_empty() {
                // A new block: its place below the previous ones, d in m.
                let spacing = frames.spacing_m as f32;
                let top = (track.block_index * block_rows) as f32 * spacing;
                rec.log_static(
                    block_path(&track.entities.history, track.block_index),
                    &rerun_sdk::Transform3D::from_translation_scale(
                        [0.0, top, 0.0],
                        rerun_sdk::components::Scale3D::from([spacing, spacing, 1.0]),
                    ),
                )
                .map_err(sdk_error(path, what))?;
            }
            track
                .block
                .extend(f.mu.iter().map(|&mu| crate::scale::mu_class(mu) as u8));
            track.block_unlogged += 1;
            track.last_train = Some((f.log_time_ns, wheel_pass));
            let full = track.block.len() >= block_rows * grid_len;
            if full || track.block_unlogged >= self.options.history_every.max(1) {
                log_block(rec, track, grid_len, time_ns, wheel_pass_seq)
                    .map_err(sdk_error(path, what))?;
            }
            if full {
                track.block.clear();
                track.block_index += 1;
            }
        }
        if self.file.is_none() {
            // A viewer watching: the pulses and readings up to this train.
            self.flush_series()?;
        }
        Ok(())
    }

    fn line_wheels(&mut self, w: &LineWheels<'_>) -> SinkResult {
        let grid_len = self.grid_len;
        let lengths = [
            ("mu", w.mu[0].len()),
            ("mu", w.mu[1].len()),
            ("rail_mu", w.rail_mu.len()),
            ("bands_kg", w.bands_kg[0].len()),
            ("bands_kg", w.bands_kg[1].len()),
            ("bands_kg", w.bands_kg[2].len()),
        ];
        if let Some(&(field, len)) = lengths.iter().find(|(_, len)| *len != grid_len) {
            return Err(RerunError::SnapshotLength {
                path: self.path().to_path_buf(),
                train_id: w.train_id.to_string(),
                track: format!("{} (line wheels)", w.rail_name),
                field,
                len,
                grid: grid_len,
            }
            .into());
        }
        let entities = LineWheelEntities::new(&w.rail_name);
        if !self.styled.contains(&entities.mu[0]) {
            let styles = entities.styles(w.rail);
            for (path, style) in &styles {
                self.style_once(path, &[style])?;
            }
            let (_, rails) = self
                .line_wheels
                .get_or_insert_with(|| (w.axles[0], BTreeSet::new()));
            rails.insert(w.rail);
        }
        self.set_time(w.log_time_ns, Some(self.wheel_pass))?;
        let frames = self.frames.as_ref().ok_or_else(|| RerunError::NotBegun {
            path: self.path().to_path_buf(),
        })?;
        let d = &self.grid_d_m;
        let mut strips = vec![
            (&entities.mu[0], frames.mu_strips(d, &w.mu[0])),
            (&entities.mu[1], frames.mu_strips(d, &w.mu[1])),
            (&entities.rail_mu, frames.mu_strips(d, &w.rail_mu)),
        ];
        for (path, band) in entities.bands.iter().zip(&w.bands_kg) {
            strips.push((path, frames.product_strips(d, band)));
        }
        let rec = self.rec()?;
        for (path, strips) in strips {
            rec.log(
                path.clone(),
                &rerun_sdk::LineStrips2D::update_fields().with_strips(strips),
            )
            .map_err(sdk_error(self.path(), || {
                format!(
                    "line wheels of train {} on {} rail",
                    w.train_id, w.rail_name
                )
            }))?;
        }
        Ok(())
    }

    fn finish(&mut self, summary: &RunSummary) -> SinkResult {
        Ok(self.finish_run(summary)?)
    }
}

impl Drop for RerunSink {
    fn drop(&mut self) {
        // Close the stream first so no writer thread still holds the file;
        // then the `file` field, dropped after this, deletes it unless finished.
        drop(self.rec.take());
    }
}
