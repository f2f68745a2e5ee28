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
//! | `/twin/pulse`       | pulse that landed                             |
//! | `/twin/measurement` | input measurement, at its own log_time        |
//! | `/twin/field`       | train field snapshot ([`SnapshotKind::Train`]) |
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

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use serde::ser::{SerializeSeq, Serializer};
use serde::Serialize;

use crate::files::{FileError, PartialFile};
use crate::provenance::Provenance;
use tortwin_engine::sink::{
    FieldSnapshot, MeasurementOutput, PulseEvent, RunSummary, SectionInfo, Sink, SnapshotKind,
    TrainEvent,
};
use tortwin_recording::Direction;

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
            _ => false,
        }
    }
}

/// Writes the twin's output channels to an MCAP file (see the module docs).
pub struct McapSink {
    // Declared before `temp` so that on drop the writer closes the file
    // before the guard deletes it.
    writer: Option<mcap::Writer<BufWriter<File>>>,
    temp: PartialFile,
    channel_ids: [u16; Topic::ALL.len()],
    sequences: [u32; Topic::ALL.len()],
    /// Reused for every message so that serializing allocates only on growth.
    json: Vec<u8>,
}

impl McapSink {
    /// Opens `.NAME.partial-XXXXXX` next to `path` and registers every
    /// channel; with `provenance`, writes it as the metadata record
    /// `provenance` and the configuration as the attachment `model.toml`.
    pub fn create(path: &Path, provenance: Option<&Provenance>) -> Result<McapSink, McapError> {
        let temp = PartialFile::beside(path)?;
        let file = File::create(temp.temp_path()).map_err(|source| McapError::Io {
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
        // Several replays may run at once under rayon (sweeps): compress on the
        // calling thread instead of spawning a zstd pool per file.
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(mcap::WriteOptions::DEFAULT_CHUNK_SIZE))
            .compression_threads(0)
            .library(format!("tortwin {version} (mcap-rs)"));
        let mut writer = options
            .create(BufWriter::new(file))
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
                .add_schema(topic.schema_name(), "jsonschema", topic.schema().as_bytes())
                .map_err(mcap_error(&format!(
                    "adding the schema of {}",
                    topic.name()
                )))?;
            channel_ids[topic as usize] = writer
                .add_channel(schema_id, topic.name(), "json", &no_metadata)
                .map_err(mcap_error(&format!("adding channel {}", topic.name())))?;
        }

        Ok(McapSink {
            writer: Some(writer),
            temp,
            channel_ids,
            sequences: [0; Topic::ALL.len()],
            json: Vec::with_capacity(4096),
        })
    }

    /// Serializes `message` into the reused buffer and writes it with
    /// log_time = publish_time = `log_time_ns`.
    fn write<T: Serialize>(
        &mut self,
        topic: Topic,
        log_time_ns: u64,
        message: &T,
    ) -> Result<(), McapError> {
        let path = self.temp.final_path();
        let writer = self.writer.as_mut().ok_or_else(|| McapError::Finished {
            path: path.to_path_buf(),
        })?;
        self.json.clear();
        serde_json::to_writer(&mut self.json, message).map_err(|source| McapError::Json {
            path: path.to_path_buf(),
            topic: topic.name(),
            source,
        })?;
        let sequence = &mut self.sequences[topic as usize];
        *sequence = sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: self.channel_ids[topic as usize],
            sequence: *sequence,
            log_time: log_time_ns,
            publish_time: log_time_ns,
        };
        writer
            .write_to_known_channel(&header, &self.json)
            .map_err(|source| McapError::Mcap {
                path: path.to_path_buf(),
                what: format!("writing {}", topic.name()),
                source,
            })
    }

    /// An error for what the engine handed over on `topic`.
    fn inconsistent(&self, topic: Topic, problem: String) -> McapError {
        McapError::Inconsistent {
            path: self.temp.final_path().to_path_buf(),
            topic: topic.name(),
            problem,
        }
    }

    /// Writes the summary, flushes and syncs the file, moves it into place.
    fn finish_file(&mut self) -> Result<(), McapError> {
        let path = self.temp.final_path().to_path_buf();
        let mut writer = self
            .writer
            .take()
            .ok_or_else(|| McapError::Finished { path: path.clone() })?;
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
            .map_err(io_error("flushing"))?;
        file.sync_all().map_err(io_error("syncing"))?;
        drop(file);
        Ok(self.temp.commit()?)
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
        let section = info.section;
        let check = |field, value| finite(topic, field, log_time_ns, value);
        check("length_m", section.length_m)?;
        if let Some(radius_m) = section.curve_radius_m {
            check("curve_radius_m", radius_m)?;
        }
        check("rail_head_radius_m", section.rail_head_radius_m)?;
        check("nominal_wheel_diameter_m", section.nominal_wheel_diameter_m)?;
        finite_all(topic, "grid_d_m", log_time_ns, info.grid_d_m, 1.0)?;

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
        for (applicator, &grid_index) in section.applicators.iter().zip(info.applicator_points) {
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
        for (site, &grid_index) in section.sites.iter().zip(info.site_points) {
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
            grid_d_m: info.grid_d_m,
            tracks,
            applicators,
            sites,
        };
        Ok(self.write(topic, log_time_ns, &message)?)
    }

    fn train(&mut self, train: &TrainEvent<'_>) -> tortwin_engine::sink::SinkResult {
        let topic = Topic::Train;
        finite(topic, "speed_mps", train.log_time_ns, train.speed_mps)?;
        let message = TrainMsg {
            train_id: train.train_id,
            direction: match train.direction {
                Direction::Up => "up",
                Direction::Down => "down",
            },
            speed_mps: train.speed_mps,
            axles: train.axles,
            end_time_ns: train.end_ns,
            duration_s: train.end_ns.saturating_sub(train.log_time_ns) as f64 * 1e-9,
        };
        Ok(self.write(topic, train.log_time_ns, &message)?)
    }

    fn pulse(&mut self, pulse: &PulseEvent<'_>) -> tortwin_engine::sink::SinkResult {
        let topic = Topic::Pulse;
        let mass_g = pulse.mass_kg * G_PER_KG;
        finite(topic, "mass_g", pulse.log_time_ns, mass_g)?;
        let message = PulseMsg {
            applicator_id: pulse.applicator_id,
            rail: pulse.rail_name,
            mass_g,
        };
        Ok(self.write(topic, pulse.log_time_ns, &message)?)
    }

    fn measurement(&mut self, m: &MeasurementOutput<'_>) -> tortwin_engine::sink::SinkResult {
        let topic = Topic::Measurement;
        finite(topic, "measured", m.log_time_ns, m.measured)?;
        finite(topic, "simulated", m.log_time_ns, m.simulated)?;
        let message = MeasurementMsg {
            site_id: m.site_id,
            rail: m.rail_name,
            quantity: m.quantity.as_str(),
            train_id: m.train_id,
            axle_index: m.axle_index,
            measured: m.measured,
            simulated: m.simulated,
            index_in_file: m.index_in_file,
        };
        Ok(self.write(topic, m.log_time_ns, &message)?)
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
        finite_all(topic, "d_m", t, f.d_m, 1.0)?;
        finite_all(topic, "mu", t, f.mu, 1.0)?;
        finite_all(topic, "adhesion", t, f.adhesion, 1.0)?;
        finite_all(topic, "rail_mass_mg", t, f.rail_mass_kg, MG_PER_KG)?;
        finite_all(topic, "wheel_mass_mg", t, f.wheel_mass_kg, MG_PER_KG)?;
        let message = FieldMsg {
            train_id: f.train_id,
            rail: f.rail_name,
            band: f.band,
            wheel_pass: f.wheel_pass,
            d_m: f.d_m,
            mu: f.mu,
            adhesion: f.adhesion,
            rail_mass_mg: Scaled(f.rail_mass_kg, MG_PER_KG),
            wheel_mass_mg: Scaled(f.wheel_mass_kg, MG_PER_KG),
        };
        Ok(self.write(topic, t, &message)?)
    }

    fn finish(&mut self, _summary: &RunSummary) -> tortwin_engine::sink::SinkResult {
        Ok(self.finish_file()?)
    }
}

const G_PER_KG: f64 = 1e3;
const MG_PER_KG: f64 = 1e6;

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
    match values.iter().map(|&v| v * scale).find(|v| !v.is_finite()) {
        None => Ok(()),
        Some(value) => finite(topic, field, log_time_ns, value),
    }
}

/// A slice written as `values[i] * factor`, without a scaled copy.
struct Scaled<'a>(&'a [f64], f64);

impl Serialize for Scaled<'_> {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut seq = serializer.serialize_seq(Some(self.0.len()))?;
        for &v in self.0 {
            seq.serialize_element(&(v * self.1))?;
        }
        seq.end()
    }
}

#[derive(Serialize)]
struct SectionMsg<'a> {
    section_id: &'a str,
    length_m: f64,
    rails: &'a [String],
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
    mass_g: f64,
}

#[derive(Serialize)]
struct MeasurementMsg<'a> {
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

#[derive(Serialize)]
struct FieldMsg<'a> {
    train_id: &'a str,
    rail: &'a str,
    band: &'a str,
    wheel_pass: u64,
    d_m: &'a [f64],
    mu: &'a [f64],
    adhesion: &'a [f64],
    rail_mass_mg: Scaled<'a>,
    wheel_mass_mg: Scaled<'a>,
}

/// The output channels, in the order they are registered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Topic {
    Section,
    Train,
    Pulse,
    Measurement,
    Field,
}

impl Topic {
    const ALL: [Topic; 5] = [
        Topic::Section,
        Topic::Train,
        Topic::Pulse,
        Topic::Measurement,
        Topic::Field,
    ];

    fn name(self) -> &'static str {
        match self {
            Topic::Section => "/twin/section",
            Topic::Train => "/twin/train",
            Topic::Pulse => "/twin/pulse",
            Topic::Measurement => "/twin/measurement",
            Topic::Field => "/twin/field",
        }
    }

    fn schema_name(self) -> &'static str {
        match self {
            Topic::Section => "tortwin.Section",
            Topic::Train => "tortwin.Train",
            Topic::Pulse => "tortwin.Pulse",
            Topic::Measurement => "tortwin.Measurement",
            Topic::Field => "tortwin.Field",
        }
    }

    /// The JSON Schema (draft 2020-12) of the channel's messages. Extra
    /// properties are allowed so that readers keep working when a field is added.
    fn schema(self) -> &'static str {
        match self {
            Topic::Section => SECTION_SCHEMA,
            Topic::Train => TRAIN_SCHEMA,
            Topic::Pulse => PULSE_SCHEMA,
            Topic::Measurement => MEASUREMENT_SCHEMA,
            Topic::Field => FIELD_SCHEMA,
        }
    }
}

const SECTION_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "tortwin.Section",
  "description": "The track section and the twin's calculation grid, at the recording's origin.",
  "type": "object",
  "required": ["section_id", "length_m", "rails", "curve_radius_m", "rail_head_radius_m",
               "nominal_wheel_diameter_m", "grid_d_m", "tracks", "applicators", "sites"],
  "properties": {
    "section_id": {"type": "string"},
    "length_m": {"type": "number", "exclusiveMinimum": 0},
    "rails": {"type": "array", "minItems": 1, "items": {"type": "string"}},
    "curve_radius_m": {"type": ["number", "null"], "description": "null on tangent track"},
    "rail_head_radius_m": {"type": "number", "exclusiveMinimum": 0},
    "nominal_wheel_diameter_m": {"type": "number", "exclusiveMinimum": 0},
    "grid_d_m": {"type": "array", "items": {"type": "number"},
                 "description": "grid point positions d_i = i * C in m"},
    "tracks": {
      "type": "array",
      "description": "every surface the twin keeps: one per rail, two on the high rail with bogie bands",
      "items": {
        "type": "object",
        "required": ["track", "rail", "band"],
        "properties": {
          "track": {"type": "integer", "minimum": 0},
          "rail": {"type": "string"},
          "band": {"type": "string"}
        }
      }
    },
    "applicators": {
      "type": "array",
      "items": {
        "type": "object",
        "required": ["id", "position_m", "rails", "nominal_pulse_g", "grid_index", "grid_d_m"],
        "properties": {
          "id": {"type": "string"},
          "position_m": {"type": "number"},
          "rails": {"type": "array", "items": {"type": "string"}},
          "nominal_pulse_g": {"type": "number", "minimum": 0},
          "grid_index": {"type": "integer", "minimum": 0},
          "grid_d_m": {"type": "number"}
        }
      }
    },
    "sites": {
      "type": "array",
      "items": {
        "type": "object",
        "required": ["id", "position_m", "grid_index", "grid_d_m"],
        "properties": {
          "id": {"type": "string"},
          "position_m": {"type": "number"},
          "grid_index": {"type": "integer", "minimum": 0},
          "grid_d_m": {"type": "number"}
        }
      }
    }
  }
}"##;

const TRAIN_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "tortwin.Train",
  "description": "A train that entered the section; log_time is when its front crossed the entry end.",
  "type": "object",
  "required": ["train_id", "direction", "speed_mps", "axles", "end_time_ns", "duration_s"],
  "properties": {
    "train_id": {"type": "string"},
    "direction": {"enum": ["up", "down"]},
    "speed_mps": {"type": "number", "exclusiveMinimum": 0},
    "axles": {"type": "integer", "minimum": 1},
    "end_time_ns": {"type": "integer", "minimum": 0,
                    "description": "ns since the Unix epoch when the last axle left the section"},
    "duration_s": {"type": "number", "minimum": 0}
  }
}"##;

const PULSE_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "tortwin.Pulse",
  "description": "A pulse of product that landed on a rail at its applicator's grid point.",
  "type": "object",
  "required": ["applicator_id", "rail", "mass_g"],
  "properties": {
    "applicator_id": {"type": "string"},
    "rail": {"type": "string"},
    "mass_g": {"type": "number", "minimum": 0}
  }
}"##;

const MEASUREMENT_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "tortwin.Measurement",
  "description": "An input measurement and the twin's value for it, at the measurement's log_time.",
  "type": "object",
  "required": ["site_id", "rail", "quantity", "measured", "simulated"],
  "properties": {
    "site_id": {"type": "string"},
    "rail": {"type": "string"},
    "quantity": {"enum": ["mu", "adhesion", "rail_mu"]},
    "train_id": {"type": "string"},
    "axle_index": {"type": "integer", "minimum": 0},
    "measured": {"type": "number"},
    "simulated": {"type": "number"},
    "index_in_file": {"type": "integer", "minimum": 0,
                      "description": "the input message's index in its recording"}
  },
  "if": {"properties": {"quantity": {"const": "rail_mu"}}},
  "then": {"not": {"anyOf": [{"required": ["train_id"]}, {"required": ["axle_index"]}]}},
  "else": {"required": ["train_id", "axle_index"]}
}"##;

const FIELD_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "tortwin.Field",
  "description": "The friction field of one rail band after a train. mu, adhesion and wheel_mass_mg are those seen by the train's last wheel on that rail; all arrays run over the grid points d_m.",
  "type": "object",
  "required": ["train_id", "rail", "band", "wheel_pass", "d_m", "mu", "adhesion",
               "rail_mass_mg", "wheel_mass_mg"],
  "properties": {
    "train_id": {"type": "string"},
    "rail": {"type": "string"},
    "band": {"type": "string"},
    "wheel_pass": {"type": "integer", "minimum": 0,
                   "description": "wheels that have rolled over this rail so far"},
    "d_m": {"type": "array", "items": {"type": "number"}},
    "mu": {"type": "array", "items": {"type": "number"}},
    "adhesion": {"type": "array", "items": {"type": "number"}},
    "rail_mass_mg": {"type": "array", "items": {"type": "number"}},
    "wheel_mass_mg": {"type": "array", "items": {"type": "number"}}
  }
}"##;
