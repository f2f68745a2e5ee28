//! MCAP output sink: the twin's results as a recording Foxglove can open.
//!
//! Every channel speaks the convention of the input recordings
//! (docs/spec/recording-format.md): `message_encoding = "json"` and a
//! `jsonschema` schema, so Foxglove plots the fields and
//! `tests/python/check_mcap.py` can validate every message against its
//! channel's schema. A message's log_time is the time of the event it reports
//! (docs/spec/interfaces.md, "Output MCAP topics"):
//!
//! | topic               | one message per                               |
//! |---------------------|-----------------------------------------------|
//! | `/twin/section`     | [`Sink::begin`], at the recording's origin    |
//! | `/twin/train`       | train, at the time its front entered          |
//! | `/twin/pulse`       | applicator and rail that pulsed, at the next train snapshot: count, mass, first and last time |
//! | `/twin/measurement` | input measurement, at its own log_time        |
//! | `/twin/field`       | train field snapshot ([`SnapshotKind::Train`]), per rail and band |
//! | `/foxglove/track`   | train: a `foxglove.SceneUpdate`, every rail's mu on the plan |
//! | `/foxglove/log`     | train, pulse, warning, alert: a `foxglove.Log` |
//! | `/twin/alert`       | alert raised or cleared, with its evidence     |
//!
//! `/twin/field` holds no distances (they are `grid_d_m` of
//! `/twin/section`) and its numbers at the precision the data has
//! ([`MU_DECIMALS`], [`MASS_DIGITS`], [`MASS_FLOOR_MG`]): a year of trains on
//! a 1.5 km section fits in about 100 MB. The two Foxglove topics use
//! Foxglove's own schemas ([`crate::foxglove`]): the 3D panel draws the track
//! coloured by the fixed mu scale of [`crate::scale`], the Log panel lists
//! the trains, the pulses (under the applicator's id) and a warning for each
//! rail a train leaves below the target band. The scene update of a train is
//! written once all its rails' snapshots are in, before the next message.
//!
//! The file is written as `.NAME.partial-XXXXXX` next to the target and only
//! [`Sink::finish`] writes the summary and renames it into place; a sink
//! dropped without `finish` (the run failed) deletes its temporary file, so a
//! file under the final name is always complete.
//!
//! JSON has no NaN or infinity and serde_json would quietly write `null`, so
//! every float is checked first and a non-finite one is a [`NonFiniteValue`]
//! error that names the topic, the field and the log_time. Every other
//! failure is a [`McapError`] that names the file.

mod numbers;
mod writer;
mod ws;

pub use ws::{FoxgloveServer, FoxgloveServerError};

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Serialize;

use self::numbers::Precision;
use crate::files::{FileError, PartialFile, Writeback};
use crate::foxglove::{below_band_warning, Label, Log, LogLevel, TrackScene};
use crate::geometry::Plan;
use crate::provenance::Provenance;
use crate::scale::TARGET_BAND;
use tortwin_engine::sink::{
    Alert, FieldSnapshot, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink,
    SnapshotKind, TrainEvent,
};
use tortwin_recording::Direction;
use writer::WriterThread;

/// A float the sink was asked to write is NaN or infinite.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error(
    "MCAP output {topic}, log_time {log_time_ns} ns: {field} is {value}, which JSON cannot hold"
)]
pub struct NonFiniteValue {
    pub topic: &'static str,
    pub field: &'static str,
    pub log_time_ns: u64,
    pub value: f64,
}

/// Why the MCAP output could not be written (a float JSON cannot hold is a
/// [`NonFiniteValue`] instead); every variant names the output by its final
/// path.
#[derive(Debug, thiserror::Error)]
pub enum McapError {
    #[error(transparent)]
    File(#[from] FileError),
    #[error("MCAP output {}: {what}", path.display())]
    Io {
        path: PathBuf,
        what: &'static str,
        #[source]
        source: std::io::Error,
    },
    /// The mcap writer failed at `what` ("starting", "writing /twin/train", ...).
    #[error("MCAP output {}: {what}", path.display())]
    Mcap {
        path: PathBuf,
        what: String,
        #[source]
        source: mcap::McapError,
    },
    #[error("MCAP output {}: serializing {topic}", path.display())]
    Json {
        path: PathBuf,
        topic: &'static str,
        #[source]
        source: serde_json::Error,
    },
    #[error("MCAP output {}: already finished", path.display())]
    Finished { path: PathBuf },
    /// What the engine handed over does not fit together.
    #[error("MCAP output {}: {topic}: {problem}", path.display())]
    Inconsistent {
        path: PathBuf,
        topic: &'static str,
        problem: String,
    },
}

impl McapError {
    /// Whether the user asked for the impossible (see
    /// [`FileError::is_input`]).
    pub fn is_input(&self) -> bool {
        match self {
            McapError::File(e) => e.is_input(),
            // A full disk, a file-size limit: the user's to fix.
            other => crate::files::caused_by_environment(other),
        }
    }
}

/// Writes the twin's output channels to an MCAP file (see the module docs),
/// or to one file per UTC day ([`McapSink::daily`]).
pub struct McapSink {
    /// The file being written; `None` while a day already written before a
    /// restart is stepped again ([`McapSink::daily`]).
    file: Option<McapFile>,
    /// The file messages go to (for errors): the current day's.
    path: PathBuf,
    /// Per UTC day: where the days go.
    daily: Option<Daily>,
    /// The coloured track of `/foxglove/track`, from [`Sink::begin`].
    scene: Option<TrackScene>,
    /// log_time of track snapshots not yet written as a scene update.
    scene_pending: Option<u64>,
    /// Tracks whose snapshot is in the pending scene update.
    scene_dirty: Vec<bool>,
    /// The grid, for the warnings' distances.
    grid_d_m: Vec<f64>,
    /// Per track, "high rail" or "high rail (gauge corner band)".
    track_labels: Vec<String>,
    /// Reused text of a log message.
    text: String,
    /// The latest log_time written.
    last_log_time_ns: u64,
    /// Pulses since the last train snapshot, per applicator and rail.
    pulses: Vec<PulseTally>,
    /// Where every message also goes, as it is written
    /// ([`McapSink::publishing`]).
    server: Option<Arc<FoxgloveServer>>,
    /// A message's bytes for the server and the file.
    tee: Vec<u8>,
}

/// An MCAP file being written: under a temporary name until it is finished.
struct McapFile {
    // Declared before `temp` so that on drop the writer closes the file
    // before the guard deletes it.
    writer: WriterThread,
    temp: PartialFile,
    channel_ids: [u16; Topic::ALL.len()],
    /// Whether the writer thread runs behind the engine.
    behind: bool,
}

/// How a daily output names and opens its files.
struct Daily {
    folder: PathBuf,
    stem: String,
    provenance: Option<Provenance>,
    line: bool,
    /// The UTC day (days since the epoch) of the file being written.
    day: Option<u64>,
    /// `/twin/section` and its log_time (the origin's), to open every day
    /// with: the first at that log_time, later ones at their first
    /// message's (the origin may be days before).
    section: Option<(Vec<u8>, u64)>,
}

const NS_PER_DAY: u64 = 86_400_000_000_000;

/// An applicator's pulses on one rail since the last train snapshot.
#[derive(Debug, Clone)]
struct PulseTally {
    applicator_id: String,
    rail: String,
    pulses: u64,
    mass_g: f64,
    first_ns: u64,
    last_ns: u64,
}

impl McapSink {
    /// The output of a replay of `input_messages` messages (the reader's
    /// count, known from its layout pass before the first is stepped): the
    /// sink chooses how hard it compresses
    /// ([`McapCompression::for_recording`]), [`McapSink::create`] the rest.
    /// `line`: the recording is a line (line.md), whose `/twin/field`
    /// holds nulls where no wheel used a band ([`LINE_FIELD_SCHEMA`]).
    pub fn for_replay(
        path: &Path,
        provenance: Option<&Provenance>,
        input_messages: u64,
        line: bool,
    ) -> Result<McapSink, McapError> {
        let compression = McapCompression::for_recording(input_messages);
        Self::open(path, provenance, compression, line)
    }

    /// Opens `.NAME.partial-XXXXXX` next to `path` and registers every
    /// channel; with `provenance`, writes it as the metadata record
    /// `provenance` and the configuration as the attachment `model.toml`;
    /// the chunks are compressed as `compression` says.
    pub fn create(
        path: &Path,
        provenance: Option<&Provenance>,
        compression: McapCompression,
    ) -> Result<McapSink, McapError> {
        Self::open(path, provenance, compression, false)
    }

    fn open(
        path: &Path,
        provenance: Option<&Provenance>,
        compression: McapCompression,
        line: bool,
    ) -> Result<McapSink, McapError> {
        let behind = compression.runs_behind_the_engine();
        let file = McapFile::create(path, provenance, compression, line, behind)?;
        Ok(Self::with_file(Some(file), path.to_path_buf(), None))
    }

    /// The output of a replay as one file per UTC day of the messages'
    /// log_times, `folder/STEM.YYYY-MM-DD.mcap`, each complete on its own
    /// (it opens with `/twin/section`) and moved into place when the next
    /// day's first message comes (the last at [`Sink::finish`]). A day whose
    /// file is there already is not written again: `tortwin live` steps
    /// the messages since its last checkpoint again after a restart, and
    /// the days finished before it are kept as they were written.
    pub fn daily(
        folder: &Path,
        stem: &str,
        provenance: Option<&Provenance>,
        line: bool,
    ) -> McapSink {
        let daily = Daily {
            folder: folder.to_path_buf(),
            stem: stem.to_string(),
            provenance: provenance.cloned(),
            line,
            day: None,
            section: None,
        };
        Self::with_file(None, folder.to_path_buf(), Some(daily))
    }

    /// The file of UTC day `day` of a daily output.
    pub fn daily_path(folder: &Path, stem: &str, day_start_ns: u64) -> PathBuf {
        let date = chrono::DateTime::from_timestamp_nanos(day_start_ns as i64)
            .format("%Y-%m-%d")
            .to_string();
        folder.join(format!("{stem}.{date}.mcap"))
    }

    /// Whether the file's writer thread runs behind the engine
    /// ([`McapCompression::runs_behind_the_engine`]), so that the thread
    /// feeding it may too.
    pub fn writer_runs_behind(&self) -> bool {
        self.file.as_ref().is_none_or(|f| f.behind)
    }

    fn with_file(file: Option<McapFile>, path: PathBuf, daily: Option<Daily>) -> McapSink {
        McapSink {
            file,
            path,
            daily,
            scene: None,
            scene_pending: None,
            scene_dirty: Vec::new(),
            grid_d_m: Vec::new(),
            track_labels: Vec::new(),
            text: String::new(),
            last_log_time_ns: 0,
            pulses: Vec::new(),
            server: None,
            tee: Vec::new(),
        }
    }

    /// Also sends every message, the same bytes at the same log_time, to
    /// the clients of a Foxglove WebSocket server (`tortwin live
    /// --foxglove`), a day already written before a restart included.
    pub fn publishing(mut self, server: Arc<FoxgloveServer>) -> McapSink {
        self.server = Some(server);
        self
    }

    /// A daily output's next file: the day of `log_time_ns`, opened with
    /// the `/twin/section` message at that time (unless it is the first).
    fn next_day(&mut self, log_time_ns: u64) -> Result<(), McapError> {
        let Some(daily) = self.daily.as_mut() else {
            return Ok(());
        };
        let day = log_time_ns / NS_PER_DAY;
        if daily.day.is_some_and(|d| d >= day) {
            return Ok(());
        }
        let section = daily.section.as_ref().map(|(json, at)| {
            let at = if daily.day.is_none() {
                *at
            } else {
                log_time_ns
            };
            (json.clone(), at)
        });
        daily.day = Some(day);
        let path = Self::daily_path(&daily.folder, &daily.stem, day * NS_PER_DAY);
        let (provenance, line) = (daily.provenance.clone(), daily.line);
        if let Some(file) = self.file.take() {
            file.finish()?;
        }
        self.path = path.clone();
        if let (Some(server), Some((json, at))) = (&self.server, &section) {
            server.publish(Topic::Section, *at, json);
        }
        if path.exists() {
            return Ok(());
        }
        // Not behind the engine: a live twin's day must reach its file while
        // other work at normal priority has the cores.
        let mut file = McapFile::create(
            &path,
            provenance.as_ref(),
            McapCompression::Fast,
            line,
            false,
        )?;
        if let Some((json, at)) = section {
            file.write_raw(Topic::Section, at, &json)?;
        }
        self.file = Some(file);
        Ok(())
    }
}

impl McapFile {
    /// Opens `.NAME.partial-XXXXXX` next to `path` and registers every
    /// channel (see [`McapSink::create`]); `behind`: the writer thread runs
    /// behind the engine ([`tortwin_handover::behind_the_engine`]).
    fn create(
        path: &Path,
        provenance: Option<&Provenance>,
        compression: McapCompression,
        line: bool,
        behind: bool,
    ) -> Result<McapFile, McapError> {
        let temp = PartialFile::beside(path)?;
        let file = temp
            .open_with(|path| File::create(path))
            .map_err(|source| McapError::Io {
                path: path.to_path_buf(),
                what: "opening",
                source,
            })?;
        let mcap_error = |what: &str| {
            let what = what.to_owned();
            move |source| McapError::Mcap {
                path: path.to_path_buf(),
                what,
                source,
            }
        };

        let version = env!("CARGO_PKG_VERSION");
        // Compress on the writer thread, as the messages come, in zstd's
        // streaming mode: with a zstd worker thread (threads >= 1) a whole
        // 8 MiB chunk is one job, compressed only once it is full, so the
        // last chunk's compression ran after the engine had finished
        // (0.06 s of the 0.22 s of the 3-day benchmark). Several replays
        // may run at once under rayon (sweeps): no zstd pool per file.
        let mut writer = compression
            .write_options()
            .library(format!("tortwin {version} (mcap-rs)"))
            .create(BufWriter::new(Writeback::new(file)))
            .map_err(mcap_error("starting"))?;

        writer
            .write_metadata(&mcap::records::Metadata {
                name: "tortwin".to_owned(),
                metadata: BTreeMap::from([
                    ("tool".to_owned(), "tortwin".to_owned()),
                    ("version".to_owned(), version.to_owned()),
                ]),
            })
            .map_err(mcap_error("writing the metadata"))?;
        if let Some(p) = provenance {
            writer
                .write_metadata(&mcap::records::Metadata {
                    name: "provenance".to_owned(),
                    metadata: p.to_pairs(),
                })
                .map_err(mcap_error("writing the provenance"))?;
            writer
                .attach(&mcap::Attachment {
                    log_time: 0,
                    create_time: 0,
                    name: "model.toml".to_owned(),
                    media_type: "application/toml".to_owned(),
                    data: std::borrow::Cow::Borrowed(p.model_toml.as_bytes()),
                })
                .map_err(mcap_error("attaching the configuration"))?;
        }

        let no_metadata = BTreeMap::new();
        let mut channel_ids = [0; Topic::ALL.len()];
        for topic in Topic::ALL {
            let schema_id = writer
                .add_schema(
                    topic.schema_name(),
                    "jsonschema",
                    topic.schema(line).as_bytes(),
                )
                .map_err(mcap_error(&format!(
                    "adding the schema of {}",
                    topic.name()
                )))?;
            channel_ids[topic as usize] = writer
                .add_channel(schema_id, topic.name(), "json", &no_metadata)
                .map_err(mcap_error(&format!("adding channel {}", topic.name())))?;
        }

        Ok(McapFile {
            writer: WriterThread::start(writer, path, behind)?,
            temp,
            channel_ids,
            behind,
        })
    }

    /// A message's header: log_time = publish_time. Sequence 0, "not used"
    /// (MCAP spec): a file has no gaps to detect, and counters in every
    /// header cost a year's file 5 %.
    fn header(&self, topic: Topic, log_time_ns: u64) -> mcap::records::MessageHeader {
        mcap::records::MessageHeader {
            channel_id: self.channel_ids[topic as usize],
            sequence: 0,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        }
    }

    /// Writes a message already serialized.
    fn write_raw(&mut self, topic: Topic, log_time_ns: u64, json: &[u8]) -> Result<(), McapError> {
        let header = self.header(topic, log_time_ns);
        self.writer.push(header, topic.name(), |bytes| {
            bytes.extend_from_slice(json);
            Ok(())
        })
    }

    /// Writes the summary, flushes and syncs the file, moves it into place.
    fn finish(mut self) -> Result<(), McapError> {
        let path = self.temp.final_path().to_path_buf();
        let mut writer = self.writer.close()?;
        writer.finish().map_err(|source| McapError::Mcap {
            path: path.clone(),
            what: "finishing".to_owned(),
            source,
        })?;
        let io_error = |what| {
            let path = path.clone();
            move |source| McapError::Io { path, what, source }
        };
        let file = writer
            .into_inner()
            .into_inner()
            .map_err(|e| e.into_error())
            .map_err(io_error("flushing"))?
            .into_inner();
        file.sync_all().map_err(io_error("syncing"))?;
        drop(file);
        Ok(self.temp.commit()?)
    }
}

impl McapSink {
    /// Serializes `message` into the reused buffer and writes it with
    /// log_time = publish_time = `log_time_ns`.
    fn write<T: Serialize>(
        &mut self,
        topic: Topic,
        log_time_ns: u64,
        message: &T,
    ) -> Result<(), McapError> {
        self.write_with(topic, log_time_ns, |buf| {
            serde_json::to_writer(buf, message)
        })
    }

    /// Writes the message `json` appends to the buffer it is given, with
    /// log_time = publish_time = `log_time_ns`.
    fn write_with(
        &mut self,
        topic: Topic,
        log_time_ns: u64,
        json: impl FnOnce(&mut Vec<u8>) -> serde_json::Result<()>,
    ) -> Result<(), McapError> {
        self.last_log_time_ns = self.last_log_time_ns.max(log_time_ns);
        self.next_day(log_time_ns)?;
        let path = &self.path;
        let json_error = |source| McapError::Json {
            path: path.to_path_buf(),
            topic: topic.name(),
            source,
        };
        if let Some(server) = &self.server {
            self.tee.clear();
            json(&mut self.tee).map_err(json_error)?;
            server.publish(topic, log_time_ns, &self.tee);
            return match self.file.as_mut() {
                Some(file) => file.write_raw(topic, log_time_ns, &self.tee),
                None => Ok(()),
            };
        }
        let Some(file) = self.file.as_mut() else {
            // A day written before a restart.
            return Ok(());
        };
        let header = file.header(topic, log_time_ns);
        file.writer.push(header, topic.name(), |bytes| {
            json(bytes).map_err(json_error)
        })
    }

    /// An error for what the engine handed over on `topic`.
    fn inconsistent(&self, topic: Topic, problem: String) -> McapError {
        McapError::Inconsistent {
            path: self.path.clone(),
            topic: topic.name(),
            problem,
        }
    }

    /// Writes a `foxglove.Log` on `/foxglove/log`.
    fn log(
        &mut self,
        log_time_ns: u64,
        level: LogLevel,
        name: &str,
        message: &str,
    ) -> Result<(), McapError> {
        self.write(
            Topic::Log,
            log_time_ns,
            &Log::new(log_time_ns, level, name, message),
        )
    }

    /// Writes the pulses since the last train snapshot, one `/twin/pulse`
    /// and one log line per applicator and rail, at `log_time_ns`.
    fn flush_pulses(&mut self, log_time_ns: u64) -> Result<(), McapError> {
        let mut tallies = std::mem::take(&mut self.pulses);
        let mut text = std::mem::take(&mut self.text);
        let mut written = Ok(());
        for tally in tallies.iter_mut().filter(|t| t.pulses > 0) {
            let message = PulseMsg {
                applicator_id: &tally.applicator_id,
                rail: &tally.rail,
                pulses: tally.pulses,
                mass_g: tally.mass_g,
                first_time_ns: tally.first_ns,
                last_time_ns: tally.last_ns,
            };
            text.clear();
            let plural = if tally.pulses == 1 { "" } else { "s" };
            let _ = write!(
                text,
                "{} pulse{plural}, {:.3} g in all, on the {} rail",
                tally.pulses, tally.mass_g, tally.rail
            );
            written = self
                .write(Topic::Pulse, log_time_ns, &message)
                .and_then(|()| self.log(log_time_ns, LogLevel::Info, &tally.applicator_id, &text));
            if written.is_err() {
                break;
            }
            tally.pulses = 0;
        }
        self.pulses = tallies;
        self.text = text;
        written
    }

    /// Writes the scene update of the snapshots so far, if one is pending:
    /// before any later message, and before a second snapshot of a track.
    fn flush_scene(&mut self) -> Result<(), McapError> {
        let Some(log_time_ns) = self.scene_pending.take() else {
            return Ok(());
        };
        self.scene_dirty.iter_mut().for_each(|d| *d = false);
        let Some(scene) = self.scene.take() else {
            return Ok(());
        };
        let written = self.write(Topic::Scene, log_time_ns, &scene.update(log_time_ns));
        self.scene = Some(scene);
        written
    }

    /// Finishes the file being written (the last day's; a daily output of
    /// nothing but the section: the section's day).
    fn finish_file(&mut self) -> Result<(), McapError> {
        if let Some((_, at)) = self
            .daily
            .as_ref()
            .filter(|d| d.day.is_none())
            .and_then(|d| d.section.as_ref())
        {
            self.next_day(*at)?;
        }
        match self.file.take() {
            Some(file) => file.finish(),
            None => Ok(()),
        }
    }
}

/// Every method's error is a [`McapError`], or a [`NonFiniteValue`] for a
/// float JSON cannot hold.
impl Sink for McapSink {
    fn begin(&mut self, info: &SectionInfo<'_>) -> tortwin_engine::sink::SinkResult {
        let topic = Topic::Section;
        let log_time_ns = u64::try_from(info.origin_ns).map_err(|_| {
            self.inconsistent(
                topic,
                format!("origin {} ns is before the Unix epoch", info.origin_ns),
            )
        })?;
        let section = &*info.section;
        let check = |field, value| finite(topic, field, log_time_ns, value);
        check("length_m", section.length_m)?;
        if let Some(radius_m) = section.curve_radius_m {
            check("curve_radius_m", radius_m)?;
        }
        check("rail_head_radius_m", section.rail_head_radius_m)?;
        check("nominal_wheel_diameter_m", section.nominal_wheel_diameter_m)?;
        finite_all(topic, "grid_d_m", log_time_ns, &info.grid_d_m, 1.0)?;

        let rail_name = |rail: usize| {
            section.rails.get(rail).map(String::as_str).ok_or_else(|| {
                self.inconsistent(topic, format!("rail index {rail} is not in the section"))
            })
        };
        let grid_d_m = |point: usize| {
            info.grid_d_m.get(point).copied().ok_or_else(|| {
                self.inconsistent(
                    topic,
                    format!(
                        "grid index {point} is beyond the grid of {} points",
                        info.grid_d_m.len()
                    ),
                )
            })
        };
        if info.applicator_points.len() != section.applicators.len()
            || info.site_points.len() != section.sites.len()
        {
            let problem = format!(
                "{} applicator and {} site grid points for {} applicators and {} sites",
                info.applicator_points.len(),
                info.site_points.len(),
                section.applicators.len(),
                section.sites.len()
            );
            return Err(self.inconsistent(topic, problem).into());
        }

        let mut applicators = Vec::with_capacity(section.applicators.len());
        for (applicator, &grid_index) in section
            .applicators
            .iter()
            .zip(info.applicator_points.iter())
        {
            check("applicators.position_m", applicator.position_m)?;
            let nominal_pulse_g = applicator.nominal_pulse_kg * G_PER_KG;
            check("applicators.nominal_pulse_g", nominal_pulse_g)?;
            applicators.push(ApplicatorMsg {
                id: &applicator.id,
                position_m: applicator.position_m,
                rails: applicator
                    .rails
                    .iter()
                    .map(|&rail| rail_name(rail))
                    .collect::<Result<_, _>>()?,
                nominal_pulse_g,
                grid_index,
                grid_d_m: grid_d_m(grid_index)?,
            });
        }
        let mut sites = Vec::with_capacity(section.sites.len());
        for (site, &grid_index) in section.sites.iter().zip(info.site_points.iter()) {
            check("sites.position_m", site.position_m)?;
            sites.push(SiteMsg {
                id: &site.id,
                position_m: site.position_m,
                grid_index,
                grid_d_m: grid_d_m(grid_index)?,
            });
        }
        let mut tracks = Vec::with_capacity(info.tracks.len());
        for (track, info) in info.tracks.iter().enumerate() {
            rail_name(info.rail)?;
            tracks.push(TrackMsg {
                track,
                rail: &info.rail_name,
                band: &info.band,
            });
        }

        let message = SectionMsg {
            section_id: &section.section_id,
            length_m: section.length_m,
            rails: &section.rails,
            curve_radius_m: section.curve_radius_m,
            rail_head_radius_m: section.rail_head_radius_m,
            nominal_wheel_diameter_m: section.nominal_wheel_diameter_m,
            grid_d_m: &info.grid_d_m,
            tracks,
            applicators,
            sites,
        };
        match self.daily.as_mut() {
            // Written when the first day's file opens, at its log_time.
            Some(daily) => {
                let json = serde_json::to_vec(&message).map_err(|source| McapError::Json {
                    path: self.path.clone(),
                    topic: topic.name(),
                    source,
                })?;
                daily.section = Some((json, log_time_ns));
            }
            None => self.write(topic, log_time_ns, &message)?,
        }

        let plan = Plan::new(info);
        let mut labels: Vec<Label> = section
            .applicators
            .iter()
            .map(|a| (a.position_m, format!("{} ({:.0} m)", a.id, a.position_m)))
            .collect();
        labels.extend(section.sites.iter().map(|s| {
            (
                s.position_m,
                format!("site {} ({:.0} m)", s.id, s.position_m),
            )
        }));

        let tracks: Vec<(String, String)> = info
            .tracks
            .iter()
            .map(|t| (t.rail_name.clone(), t.band.clone()))
            .collect();
        // A line's segments by name, at their middles.
        let segments = Plan::segment_labels(info);
        self.scene = Some(TrackScene::new(
            &plan,
            &info.grid_d_m,
            &tracks,
            &labels,
            &segments,
        ));
        self.scene_dirty = vec![false; tracks.len()];
        self.grid_d_m = info.grid_d_m.to_vec();
        let single_band = |rail: usize| info.tracks.iter().filter(|t| t.rail == rail).count() == 1;
        self.track_labels = info
            .tracks
            .iter()
            .map(|t| {
                if single_band(t.rail) {
                    format!("{} rail", t.rail_name)
                } else {
                    format!("{} rail ({} band)", t.rail_name, t.band.replace('_', " "))
                }
            })
            .collect();
        Ok(())
    }

    fn train(&mut self, train: &TrainEvent<'_>) -> tortwin_engine::sink::SinkResult {
        let topic = Topic::Train;
        finite(topic, "speed_mps", train.log_time_ns, train.speed_mps)?;
        let message = TrainMsg {
            train_id: &train.train_id,
            direction: match train.direction {
                Direction::Up => "up",
                Direction::Down => "down",
            },
            speed_mps: train.speed_mps,
            axles: train.axles,
            end_time_ns: train.end_ns,
            duration_s: train.end_ns.saturating_sub(train.log_time_ns) as f64 * 1e-9,
        };
        self.flush_scene()?;
        self.write(topic, train.log_time_ns, &message)?;
        let mut text = std::mem::take(&mut self.text);
        text.clear();
        // Writing to a String cannot fail.
        let _ = write!(
            text,
            "train {} {}, {:.1} m/s ({:.0} km/h), {} axles",
            train.train_id,
            message.direction,
            train.speed_mps,
            train.speed_mps * 3.6,
            train.axles
        );
        let logged = self.log(train.log_time_ns, LogLevel::Info, "trains", &text);
        self.text = text;
        Ok(logged?)
    }

    fn pulse(&mut self, pulse: &PulseEvent<'_>) -> tortwin_engine::sink::SinkResult {
        let mass_g = pulse.mass_kg * G_PER_KG;
        finite(Topic::Pulse, "mass_g", pulse.log_time_ns, mass_g)?;
        let t = pulse.log_time_ns;
        match self
            .pulses
            .iter_mut()
            .find(|p| p.applicator_id == pulse.applicator_id && p.rail == pulse.rail_name)
        {
            Some(tally) if tally.pulses > 0 => {
                tally.pulses += 1;
                tally.mass_g += mass_g;
                tally.first_ns = tally.first_ns.min(t);
                tally.last_ns = tally.last_ns.max(t);
            }
            Some(tally) => {
                *tally = PulseTally {
                    pulses: 1,
                    mass_g,
                    first_ns: t,
                    last_ns: t,
                    ..tally.clone()
                };
            }
            None => self.pulses.push(PulseTally {
                applicator_id: pulse.applicator_id.to_string(),
                rail: pulse.rail_name.to_string(),
                pulses: 1,
                mass_g,
                first_ns: t,
                last_ns: t,
            }),
        }
        Ok(())
    }

    fn measurement(&mut self, m: &MeasurementOutput) -> tortwin_engine::sink::SinkResult {
        let topic = Topic::Measurement;
        finite(topic, "measured", m.log_time_ns, m.measured)?;
        finite(topic, "simulated", m.log_time_ns, m.simulated)?;
        self.flush_scene()?;
        Ok(self.write_with(topic, m.log_time_ns, |buf| measurement_json(buf, m))?)
    }

    fn field(&mut self, f: &FieldSnapshot<'_>) -> tortwin_engine::sink::SinkResult {
        if f.kind != SnapshotKind::Train {
            return Ok(());
        }
        let topic = Topic::Field;
        let t = f.log_time_ns;
        let points = f.d_m.len();
        for (name, len) in [
            ("mu", f.mu.len()),
            ("adhesion", f.adhesion.len()),
            ("rail_mass_mg", f.rail_mass_kg.len()),
            ("wheel_mass_mg", f.wheel_mass_kg.len()),
        ] {
            if len != points {
                let problem = format!(
                    "log_time {t} ns, train {}: {name} has {len} values for {points} grid points",
                    f.train_id
                );
                return Err(self.inconsistent(topic, problem).into());
            }
        }
        // What the last wheel saw is missing (NaN, written as null) where no
        // wheel of the train used the band: on a line's bands (line.md).
        finite_or_missing(topic, "mu", t, &f.mu, 1.0)?;
        finite_or_missing(topic, "adhesion", t, &f.adhesion, 1.0)?;
        finite_all(topic, "rail_mass_mg", t, &f.rail_mass_kg, MG_PER_KG)?;
        finite_or_missing(topic, "wheel_mass_mg", t, &f.wheel_mass_kg, MG_PER_KG)?;
        // The scene of the train before this one is complete.
        let dirty = self.scene_dirty.get(f.track).copied().unwrap_or(false);
        if self.scene_pending.is_some_and(|pending| pending != t) || dirty {
            self.flush_scene()?;
        }
        self.flush_pulses(t)?;
        self.write_with(topic, t, |buf| field_json(buf, f))?;
        if let Some(scene) = self.scene.as_mut() {
            scene.set(f.track, &f.mu, &f.train_id, f.wheel_pass);
            if let Some(d) = self.scene_dirty.get_mut(f.track) {
                *d = true;
            }
            self.scene_pending = Some(t);
        }
        let label = self
            .track_labels
            .get(f.track)
            .map_or(&*f.rail_name, String::as_str);
        if let Some(warning) =
            below_band_warning(label, &f.train_id, &self.grid_d_m, &f.mu, TARGET_BAND[0])
        {
            self.log(t, LogLevel::Warning, "friction", &warning)?;
        }
        Ok(())
    }

    fn alert(&mut self, a: &Alert) -> tortwin_engine::sink::SinkResult {
        let topic = Topic::Alert;
        let message = crate::alerts::alert_json(a).map_err(|field| NonFiniteValue {
            topic: topic.name(),
            field,
            log_time_ns: a.log_time_ns,
            value: a
                .evidence
                .iter()
                .find(|e| e.0 == field)
                .map_or(f64::NAN, |e| e.1),
        })?;
        self.flush_scene()?;
        self.write(topic, a.log_time_ns, &message)?;
        let level = match crate::alerts::level(a) {
            "error" => LogLevel::Error,
            "warning" => LogLevel::Warning,
            _ => LogLevel::Info,
        };
        Ok(self.log(a.log_time_ns, level, "alerts", &a.message)?)
    }

    fn finish(&mut self, summary: &RunSummary) -> tortwin_engine::sink::SinkResult {
        self.flush_scene()?;
        let last_pulse_ns = self
            .pulses
            .iter()
            .filter(|p| p.pulses > 0)
            .map(|p| p.last_ns)
            .max();
        if let Some(t) = last_pulse_ns {
            self.flush_pulses(t.max(self.last_log_time_ns))?;
        }
        if summary.unknown_topic_messages > 0 {
            let text = format!(
                "{} messages on topics the twin does not read were skipped",
                summary.unknown_topic_messages
            );
            self.log(self.last_log_time_ns, LogLevel::Warning, "replay", &text)?;
        }
        Ok(self.finish_file()?)
    }
}

const G_PER_KG: f64 = 1e3;
const MG_PER_KG: f64 = 1e6;
/// Uncompressed size of a chunk. Successive scene updates and field
/// snapshots repeat most of each other, and zstd finds that only within a
/// chunk: 8 MiB writes a month of a 1.5 km section in 8 % less than the
/// mcap crate's 1 MiB, for 8 MiB of memory.
const CHUNK_BYTES: u64 = 8 * 1024 * 1024;
/// How hard the chunks are compressed: a trade of the writer thread's time
/// against the file's size, which matters for long recordings only.
///
/// zstd at level 8 writes a month of a 1.5 km section in 11.7 MB where its
/// default level 3 writes 14.1 MB and level 1 14.6 MB, and a year (issue
/// 12: at most 150 MB) in 146.6 MB where levels 3 to 7 write 155-176 MB;
/// level 9 writes the same size as 8 in 12 % more time (a week's chunks).
/// But level 8 costs about five times level 1's time (the 3-day
/// benchmark's 9 MB on one thread: 64-75 ms at level 8, 18 ms at level 3,
/// 13 ms at level 1), and on two cores that time is taken from the engine:
/// the 3-day replay runs about a sixth faster at level 1, for a file of
/// 1.87 instead of 1.60 MB (level 3: 1.85 MB, 4 % slower than level 1).
/// zstd's fast level -3 compresses a fifth faster again than level 1
/// (`zstd -b` on the 3-day output's 8.7 MB of messages, an Intel Xeon of
/// the project's: 640 against 494 MB/s), for a file of 2.7 instead of
/// 1.9 MB; the 3-day replay about 2 % faster (median pair ratios 0.981 and
/// 0.980, 150 interleaved runs each; level -1: 0.985 and a 2.5 MB file).
///
/// Level 8 looks for matches of 5 bytes or more, with two lazy
/// evaluations (zstd's `lazy2`). In these JSON messages, matches of 6 bytes
/// and one evaluation (`lazy`) find as much: on the year's first 128 MB of
/// messages in 8 MiB chunks, 13.99 MB where level 8 writes 14.06 MB (level
/// 7, with 5 bytes and `lazy`, 15.06 MB) at 114-129 MB/s where level 8
/// compresses 94-100 MB/s on one core of the project's 2-core machine;
/// the year's file 149.1 MB instead of 149.6 MB, and 3.4 s less CPU.
/// The mcap crate takes only a level: third_party/mcap adds the
/// parameters (third_party/mcap/TORTWIN.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum McapCompression {
    /// zstd level -3, one of its fast levels.
    Fast,
    /// zstd level 8 with matches of at least 6 bytes found with one lazy
    /// evaluation: about a sixth smaller than [`McapCompression::Fast`].
    Small,
}

impl McapCompression {
    /// Recordings of at least this many messages (about three months of the
    /// year benchmark's 1.5 km section, an output of 40 MB) are written
    /// [`McapCompression::Small`], shorter ones [`McapCompression::Fast`].
    pub const SMALL_FROM_MESSAGES: u64 = 1_000_000;

    /// The compression for the output of a replay of `messages` input
    /// messages (its length, known from the reader's layout pass before the
    /// first is stepped).
    pub fn for_recording(messages: u64) -> Self {
        if messages >= Self::SMALL_FROM_MESSAGES {
            McapCompression::Small
        } else {
            McapCompression::Fast
        }
    }

    fn zstd_level(self) -> i32 {
        match self {
            McapCompression::Fast => -3,
            McapCompression::Small => 8,
        }
    }

    /// Whether a replay's MCAP writer thread, and the thread that feeds it,
    /// run behind the engine ([`tortwin_handover::behind_the_engine`]).
    /// At a fast level they are light, and behind the engine they cannot
    /// take a core it wants (the 3-day benchmark, medians of 20: 79.4 ms
    /// behind, 82.4 ms not). At level 8 the writer's work is about the engine's
    /// (the year: 8 to 12 CPU-s against 9.5). Behind it, the engine's
    /// thread slept 7.3 s of the year's 16.8 s on their full queues, and
    /// a core idled 4.8 s (`perf sched`: threads of the idle policy waited,
    /// runnable, behind each other on one core while the other had
    /// nothing); at normal priority the year ran 12.8-14.0 s where it ran
    /// 13.1-14.2 s behind (four runs each, this option its only
    /// difference, the project's 2-core machine).
    pub fn runs_behind_the_engine(self) -> bool {
        self == McapCompression::Fast
    }

    /// The mcap writer's options for these chunks.
    fn write_options(self) -> mcap::WriteOptions {
        mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(CHUNK_BYTES))
            // The mcap crate takes zstd's (signed) level as a u32 and reads
            // it back with `as i32`: the same bits both ways.
            .compression_level(self.zstd_level() as u32)
            .zstd_parameters(self.zstd_parameters())
            .compression_threads(0)
    }

    /// The parameters set over [`McapCompression::zstd_level`]'s.
    fn zstd_parameters(self) -> Vec<zstd::stream::raw::CParameter> {
        use zstd::stream::raw::CParameter;
        match self {
            McapCompression::Fast => Vec::new(),
            McapCompression::Small => vec![
                CParameter::MinMatch(6),
                CParameter::Strategy(zstd::zstd_safe::Strategy::ZSTD_lazy),
            ],
        }
    }
}

fn finite(
    topic: Topic,
    field: &'static str,
    log_time_ns: u64,
    value: f64,
) -> Result<(), NonFiniteValue> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(NonFiniteValue {
            topic: topic.name(),
            field,
            log_time_ns,
            value,
        })
    }
}

/// Checks `values[i] * scale`, the numbers that will be written.
fn finite_all(
    topic: Topic,
    field: &'static str,
    log_time_ns: u64,
    values: &[f64],
    scale: f64,
) -> Result<(), NonFiniteValue> {
    check_values(topic, field, log_time_ns, values, scale, |v| v.is_finite())
}

/// [`finite_all`] but for NaN, which stands for a missing value (null).
fn finite_or_missing(
    topic: Topic,
    field: &'static str,
    log_time_ns: u64,
    values: &[f64],
    scale: f64,
) -> Result<(), NonFiniteValue> {
    check_values(topic, field, log_time_ns, values, scale, |v| {
        !v.is_infinite()
    })
}

fn check_values(
    topic: Topic,
    field: &'static str,
    log_time_ns: u64,
    values: &[f64],
    scale: f64,
    good: fn(&f64) -> bool,
) -> Result<(), NonFiniteValue> {
    match values.iter().map(|&v| v * scale).find(|v| !good(v)) {
        None => Ok(()),
        Some(value) => finite(topic, field, log_time_ns, value),
    }
}

/// Decimals of mu and adhesion in `/twin/field`: 1e-4, ten times finer
/// than a tribometer reads.
pub const MU_DECIMALS: i32 = 4;
/// Significant digits of the product masses in `/twin/field`.
pub const MASS_DIGITS: i32 = 3;
/// Product masses below this (mg) are written as 0 in `/twin/field`: by
/// eq. 4 (km = 163 mg) such a mass moves mu by less than 3e-7, far below
/// the 1e-4 mu is written to; it is also the lowest class of the product
/// colour scale.
pub const MASS_FLOOR_MG: f64 = 1e-4;

#[derive(Serialize)]
struct SectionMsg<'a> {
    section_id: &'a str,
    length_m: f64,
    rails: &'a [String],
    /// Left out on tangent track.
    #[serde(skip_serializing_if = "Option::is_none")]
    curve_radius_m: Option<f64>,
    rail_head_radius_m: f64,
    nominal_wheel_diameter_m: f64,
    grid_d_m: &'a [f64],
    tracks: Vec<TrackMsg<'a>>,
    applicators: Vec<ApplicatorMsg<'a>>,
    sites: Vec<SiteMsg<'a>>,
}

#[derive(Serialize)]
struct TrackMsg<'a> {
    track: usize,
    rail: &'a str,
    band: &'a str,
}

#[derive(Serialize)]
struct ApplicatorMsg<'a> {
    id: &'a str,
    position_m: f64,
    rails: Vec<&'a str>,
    nominal_pulse_g: f64,
    grid_index: usize,
    grid_d_m: f64,
}

#[derive(Serialize)]
struct SiteMsg<'a> {
    id: &'a str,
    position_m: f64,
    grid_index: usize,
    grid_d_m: f64,
}

#[derive(Serialize)]
struct TrainMsg<'a> {
    train_id: &'a str,
    direction: &'static str,
    speed_mps: f64,
    axles: usize,
    end_time_ns: u64,
    duration_s: f64,
}

#[derive(Serialize)]
struct PulseMsg<'a> {
    applicator_id: &'a str,
    rail: &'a str,
    pulses: u64,
    mass_g: f64,
    first_time_ns: u64,
    last_time_ns: u64,
}

/// A `/twin/measurement` message as JSON, written by hand: one per input
/// measurement, the most numerous message of a long replay (serde's derive
/// spent about as long on escaping the constant keys as on the rest). The
/// keys in the schema's order; `train_id` and `axle_index` left out for
/// `rail_mu`; the strings escaped and the two values written by serde_json
/// (every digit).
fn measurement_json(buf: &mut Vec<u8>, m: &MeasurementOutput) -> serde_json::Result<()> {
    buf.extend_from_slice(br#"{"site_id":"#);
    serde_json::to_writer(&mut *buf, &*m.site_id)?;
    buf.extend_from_slice(br#","rail":"#);
    serde_json::to_writer(&mut *buf, &*m.rail_name)?;
    buf.extend_from_slice(br#","quantity":"#);
    serde_json::to_writer(&mut *buf, m.quantity.as_str())?;
    if let Some(train_id) = &m.train_id {
        buf.extend_from_slice(br#","train_id":"#);
        serde_json::to_writer(&mut *buf, &**train_id)?;
    }
    if let Some(axle_index) = m.axle_index {
        buf.extend_from_slice(br#","axle_index":"#);
        buf.extend_from_slice(itoa::Buffer::new().format(axle_index).as_bytes());
    }
    buf.extend_from_slice(br#","measured":"#);
    serde_json::to_writer(&mut *buf, &m.measured)?;
    buf.extend_from_slice(br#","simulated":"#);
    serde_json::to_writer(&mut *buf, &m.simulated)?;
    buf.extend_from_slice(br#","index_in_file":"#);
    buf.extend_from_slice(itoa::Buffer::new().format(m.index_in_file).as_bytes());
    buf.push(b'}');
    Ok(())
}

/// A `/twin/field` message as JSON, written by hand: its numbers are most
/// of a long replay's output ([`numbers`]). The keys in this order, as the
/// schema lists them; the strings escaped by serde_json.
fn field_json(buf: &mut Vec<u8>, f: &FieldSnapshot<'_>) -> serde_json::Result<()> {
    buf.extend_from_slice(br#"{"train_id":"#);
    serde_json::to_writer(&mut *buf, &*f.train_id)?;
    buf.extend_from_slice(br#","rail":"#);
    serde_json::to_writer(&mut *buf, &*f.rail_name)?;
    buf.extend_from_slice(br#","band":"#);
    serde_json::to_writer(&mut *buf, &*f.band)?;
    buf.extend_from_slice(br#","wheel_pass":"#);
    buf.extend_from_slice(itoa::Buffer::new().format(f.wheel_pass).as_bytes());
    buf.extend_from_slice(br#","mu":"#);
    numbers::push_array(buf, &f.mu, Precision::MU)?;
    buf.extend_from_slice(br#","adhesion":"#);
    numbers::push_array(buf, &f.adhesion, Precision::MU)?;
    buf.extend_from_slice(br#","rail_mass_mg":"#);
    numbers::push_array(buf, &f.rail_mass_kg, Precision::MASS_MG)?;
    buf.extend_from_slice(br#","wheel_mass_mg":"#);
    numbers::push_array(buf, &f.wheel_mass_kg, Precision::MASS_MG)?;
    buf.push(b'}');
    Ok(())
}

/// The output channels, in the order they are registered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Topic {
    Section,
    Train,
    Pulse,
    Measurement,
    Field,
    Scene,
    Log,
    Alert,
}

impl Topic {
    const ALL: [Topic; 8] = [
        Topic::Section,
        Topic::Train,
        Topic::Pulse,
        Topic::Measurement,
        Topic::Field,
        Topic::Scene,
        Topic::Log,
        Topic::Alert,
    ];

    fn name(self) -> &'static str {
        match self {
            Topic::Section => "/twin/section",
            Topic::Train => "/twin/train",
            Topic::Pulse => "/twin/pulse",
            Topic::Measurement => "/twin/measurement",
            Topic::Field => "/twin/field",
            Topic::Scene => "/foxglove/track",
            Topic::Log => "/foxglove/log",
            Topic::Alert => "/twin/alert",
        }
    }

    fn schema_name(self) -> &'static str {
        match self {
            Topic::Section => "tortwin.Section",
            Topic::Train => "tortwin.Train",
            Topic::Pulse => "tortwin.Pulse",
            Topic::Measurement => "tortwin.Measurement",
            Topic::Field => "tortwin.Field",
            Topic::Scene => "foxglove.SceneUpdate",
            Topic::Log => "foxglove.Log",
            Topic::Alert => "tortwin.Alert",
        }
    }

    /// The JSON Schema (draft 2020-12) of the channel's messages. Extra
    /// properties are allowed so that readers keep working when a field is added.
    /// `line`: the recording is a line, whose `/twin/field` has
    /// [`LINE_FIELD_SCHEMA`].
    fn schema(self, line: bool) -> &'static str {
        match self {
            Topic::Field if line => LINE_FIELD_SCHEMA,
            Topic::Section => SECTION_SCHEMA,
            Topic::Train => TRAIN_SCHEMA,
            Topic::Pulse => PULSE_SCHEMA,
            Topic::Measurement => MEASUREMENT_SCHEMA,
            Topic::Field => FIELD_SCHEMA,
            Topic::Scene => crate::foxglove::SCENE_UPDATE_SCHEMA,
            Topic::Log => crate::foxglove::LOG_SCHEMA,
            Topic::Alert => ALERT_SCHEMA,
        }
    }
}

// tortwin's own topics' schemas, .json files beside Foxglove's
// (crates/outputs/schemas/tortwin/README.md).
const SECTION_SCHEMA: &str = include_str!("../../schemas/tortwin/section.json");

const TRAIN_SCHEMA: &str = include_str!("../../schemas/tortwin/train.json");

const PULSE_SCHEMA: &str = include_str!("../../schemas/tortwin/pulse.json");

const MEASUREMENT_SCHEMA: &str = include_str!("../../schemas/tortwin/measurement.json");

const FIELD_SCHEMA: &str = include_str!("../../schemas/tortwin/field.json");

const ALERT_SCHEMA: &str = include_str!("../../schemas/tortwin/alert.json");

/// `/twin/field` of a line (docs/spec/line.md, "Outputs and state"): mu,
/// adhesion and the wheel mass are null where no wheel of the train used
/// the rail band. JSON Schema says so with `"type": ["number", "null"]`,
/// which Foxglove Studio 1.48 cannot parse (it drops the topic); a
/// section's field has no nulls and keeps [`FIELD_SCHEMA`].
pub const LINE_FIELD_SCHEMA: &str = include_str!("../../schemas/tortwin/line_field.json");

#[cfg(test)]
mod tests {
    use std::borrow::Cow;

    use serde::Serialize;
    use tortwin_engine::sink::{FieldSnapshot, MeasurementOutput, SnapshotKind};
    use tortwin_model::Quantity;

    use super::{field_json, measurement_json, McapCompression, Precision};

    /// The hand-written `/twin/measurement` message is serde_json's text of
    /// the same message derived, with and without the axle, for escaped
    /// strings and values of every size. It fails on a key out of order or
    /// an axle written for `rail_mu` (tried).
    #[test]
    fn a_measurement_message_is_what_serde_json_writes_for_it() {
        #[derive(Serialize)]
        struct Reference<'a> {
            site_id: &'a str,
            rail: &'a str,
            quantity: &'static str,
            #[serde(skip_serializing_if = "Option::is_none")]
            train_id: Option<&'a str>,
            #[serde(skip_serializing_if = "Option::is_none")]
            axle_index: Option<usize>,
            measured: f64,
            simulated: f64,
            index_in_file: u64,
        }
        let cases = [
            (
                Quantity::Mu,
                Some("F-00002"),
                Some(0),
                0.42975,
                0.424_731_557_681_380_05,
            ),
            (
                Quantity::Adhesion,
                Some("P\"1\"\n"),
                Some(127),
                -1e-300,
                1e300,
            ),
            (Quantity::RailMu, None, None, 0.3, 5e-324),
        ];
        for (quantity, train_id, axle_index, measured, simulated) in cases {
            let m = MeasurementOutput {
                log_time_ns: 7,
                index_in_file: u64::MAX,
                site_id: "M\u{e9}\\1".into(),
                site: 0,
                rail_name: "low".into(),
                rail: 1,
                quantity,
                train_id: train_id.map(Into::into),
                axle_index,
                measured,
                simulated,
                readout: None,
            };
            let reference = Reference {
                site_id: &m.site_id,
                rail: &m.rail_name,
                quantity: quantity.as_str(),
                train_id,
                axle_index,
                measured,
                simulated,
                index_in_file: m.index_in_file,
            };
            let mut ours = Vec::new();
            measurement_json(&mut ours, &m).unwrap();
            assert_eq!(
                String::from_utf8(ours).unwrap(),
                serde_json::to_string(&reference).unwrap()
            );
        }
    }

    /// The hand-written `/twin/field` message is serde_json's text of the
    /// same message derived: keys, escaped strings, rounded numbers and the
    /// null of a missing one. It fails on a key out of order or a string
    /// left unescaped (tried).
    #[test]
    fn a_field_message_is_what_serde_json_writes_for_it() {
        #[derive(Serialize)]
        struct Reference<'a> {
            train_id: &'a str,
            rail: &'a str,
            band: &'a str,
            wheel_pass: u64,
            mu: Vec<f64>,
            adhesion: Vec<f64>,
            rail_mass_mg: Vec<f64>,
            wheel_mass_mg: Vec<f64>,
        }
        let mu = [0.58, 0.382_649_9, f64::NAN, 0.1 + 0.2, 1.0];
        let adhesion = [0.21, 0.0, f64::NAN, 0.333_333_33, 0.5];
        let rail = [0.0, 3.105_157e-6, 0.123_456, 4.567_89e-9, 1e-12];
        let wheel = [1e-7, f64::NAN, 2.5e-5, 0.0, 7.77e-3];
        let snapshot = FieldSnapshot {
            kind: SnapshotKind::Train,
            log_time_ns: 1,
            train_id: Cow::Borrowed("F-\"quoted\"\t\u{e9}"),
            track: 0,
            rail_name: Cow::Borrowed("high"),
            band: Cow::Borrowed("top"),
            wheel_pass: 18_446_744_073_709_551_615,
            d_m: Cow::Owned(vec![0.0; 5]),
            mu: Cow::Borrowed(&mu),
            adhesion: Cow::Borrowed(&adhesion),
            rail_mass_kg: Cow::Borrowed(&rail),
            wheel_mass_kg: Cow::Borrowed(&wheel),
        };
        let decimals = Precision::MU;
        let round = |xs: &[f64], p: Precision| xs.iter().map(|&x| p.round(x)).collect();
        let reference = Reference {
            train_id: &snapshot.train_id,
            rail: &snapshot.rail_name,
            band: &snapshot.band,
            wheel_pass: snapshot.wheel_pass,
            mu: round(&mu, decimals),
            adhesion: round(&adhesion, decimals),
            rail_mass_mg: round(&rail, Precision::MASS_MG),
            wheel_mass_mg: round(&wheel, Precision::MASS_MG),
        };
        let mut ours = Vec::new();
        field_json(&mut ours, &snapshot).unwrap();
        assert_eq!(
            String::from_utf8(ours).unwrap(),
            serde_json::to_string(&reference).unwrap()
        );
    }

    #[test]
    fn field_numbers_are_written_at_the_precision_the_data_has() {
        let text = |p: Precision, x: f64| serde_json::to_string(&p.round(x)).unwrap();
        let mu = Precision::MU;
        assert_eq!(text(mu, 0.338_649_999_9), "0.3386");
        assert_eq!(text(mu, 0.1 + 0.2), "0.3");
        assert_eq!(text(mu, 0.580_000_000_1), "0.58");
        let mass = Precision::MASS_MG;
        // kg in, mg out, 3 significant digits.
        assert_eq!(text(mass, 3.105_157e-6), "3.11");
        assert_eq!(text(mass, 0.123_456), "123000.0");
        assert_eq!(text(mass, 4.567_89e-9), "0.00457");
        // Below 1e-4 mg: 0.
        assert_eq!(text(mass, 0.99e-10), "0.0");
        assert_eq!(text(mass, 1.0e-10), "0.0001");
    }

    /// The small chunks' parameters reach zstd through the patched mcap
    /// crate (third_party/mcap): the file differs from level 8's alone and
    /// reads back to the same messages. It fails where the writer drops the
    /// parameters (tried: the patch's loop taken out).
    #[test]
    fn small_chunks_are_compressed_with_their_own_parameters() {
        let messages: Vec<String> = (0..40_000u32)
            .map(|i| {
                let mu: Vec<String> = (0..60u32)
                    .map(|k| format!("{:.4}", 0.3 + f64::from((i * 7 + k * 13) % 97) * 1e-3))
                    .collect();
                format!("{{\"train_id\":\"T{}\",\"mu\":[{}]}}", i / 8, mu.join(","))
            })
            .collect();
        let write = |options: mcap::WriteOptions| {
            let mut out = std::io::Cursor::new(Vec::new());
            let mut writer = options.create(&mut out).expect("a writer");
            let channel = writer
                .add_channel(0, "/twin/field", "json", &Default::default())
                .expect("a channel");
            for (i, data) in messages.iter().enumerate() {
                let header = mcap::records::MessageHeader {
                    channel_id: channel,
                    sequence: 0,
                    log_time: i as u64,
                    publish_time: i as u64,
                };
                writer
                    .write_to_known_channel(&header, data.as_bytes())
                    .expect("written");
            }
            writer.finish().expect("finished");
            drop(writer);
            out.into_inner()
        };
        let small = write(McapCompression::Small.write_options());
        let level_only = write(
            McapCompression::Small
                .write_options()
                .zstd_parameters(Vec::new()),
        );
        assert_ne!(small, level_only, "the parameters changed nothing");
        for file in [&small, &level_only] {
            let read: Vec<Vec<u8>> = mcap::MessageStream::new(file)
                .expect("a stream")
                .map(|m| m.expect("a message").data.into_owned())
                .collect();
            assert_eq!(read.len(), messages.len());
            assert!(read.iter().zip(&messages).all(|(r, m)| r == m.as_bytes()));
        }
    }
}
