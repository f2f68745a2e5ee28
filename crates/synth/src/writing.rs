//! The synthetic recording on disk: the recording crate's writer set up as
//! `tortwin synth` writes (zstd chunks, metadata naming the generator and
//! seed, no timestamp), under a temporary name until complete; and the wire
//! messages of what was planned, with the values as planned (kN, g), not
//! converted back from the typed events.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;

use super::params::SynthParams;
use super::traffic::TrainPlan;
use super::GENERATOR;
use tortwin_outputs::files::PartialFile;
use tortwin_recording::line::Line;
use tortwin_recording::wire::{
    ApplicatorMsg, AxleMsg, AxleSegmentMsg, CreepageMsg, MeasurementMsg, PassageMsg, PerRail,
    RawJson, SectionMsg, SiteMsg, WeatherMsg, WireMessage,
};
use tortwin_recording::{Creepage, Measurement, RecordingWriter, Section, Weather};
use tortwin_study::{Error, Result};

/// Writes the recording under `.NAME.partial-XXXXXX` and renames it into
/// place in [`SynthFile::finish`], which consumes it; dropped unfinished, it
/// deletes the temporary file.
pub(super) struct SynthFile {
    // Before `temp`: on drop the writer closes the file before it is deleted.
    writer: RecordingWriter<BufWriter<File>>,
    temp: PartialFile,
}

impl SynthFile {
    pub(super) fn create(path: &Path, p: &SynthParams) -> Result<Self> {
        let temp = PartialFile::beside(path)?;
        let file = temp
            .open_with(|path| File::create(path))
            .map_err(|source| Error::Io {
                what: "creating",
                path: temp.temp_path().to_path_buf(),
                source,
            })?;
        let version = env!("CARGO_PKG_VERSION");
        let options = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .chunk_size(Some(mcap::WriteOptions::DEFAULT_CHUNK_SIZE))
            .compression_threads(0)
            .library(format!("{GENERATOR} {version} (mcap-rs)"));
        let metadata = mcap::records::Metadata {
            name: "tortwin.synth".to_owned(),
            metadata: BTreeMap::from([
                ("generator".to_owned(), GENERATOR.to_owned()),
                ("version".to_owned(), version.to_owned()),
                ("seed".to_owned(), p.seed.to_string()),
                ("preset".to_owned(), p.preset.as_str().to_owned()),
            ]),
        };
        let writer = RecordingWriter::new(BufWriter::new(file), options, Some(&metadata)).map_err(
            |source| Error::Recording {
                what: "starting",
                path: temp.temp_path().to_path_buf(),
                source,
            },
        )?;
        Ok(SynthFile { writer, temp })
    }

    pub(super) fn write<M: WireMessage>(&mut self, log_time_ns: u64, message: &M) -> Result<()> {
        self.writer
            .write(log_time_ns, message)
            .map_err(|source| Error::Recording {
                what: "writing",
                path: self.temp.temp_path().to_path_buf(),
                source,
            })
    }

    /// Messages written so far.
    pub(super) fn messages(&self) -> u64 {
        self.writer.messages()
    }

    /// Finishes the file, renames it into place and returns its size.
    pub(super) fn finish(self) -> Result<u64> {
        let SynthFile { writer, mut temp } = self;
        let temp_path = temp.temp_path().to_path_buf();
        let io = |what: &'static str| {
            let path = temp_path.clone();
            move |source: std::io::Error| Error::Io { what, path, source }
        };
        let file = writer
            .finish()
            .map_err(|source| Error::Recording {
                what: "finishing",
                path: temp_path.clone(),
                source,
            })?
            .into_inner()
            .map_err(|e| e.into_error())
            .map_err(io("flushing"))?;
        file.sync_all().map_err(io("syncing"))?;
        let size = file.metadata().map_err(io("reading the size of"))?.len();
        drop(file);
        temp.commit()?;
        Ok(size)
    }
}

/// The `/section` message of the generated section.
pub(super) fn section_msg(s: &Section, p: &SynthParams) -> SectionMsg {
    SectionMsg {
        section_id: s.section_id.clone(),
        length_m: s.length_m,
        rails: s.rails.clone(),
        curve_radius_m: s.curve_radius_m,
        rail_head_radius_m: s.rail_head_radius_m,
        nominal_wheel_diameter_m: s.nominal_wheel_diameter_m,
        applicators: s
            .applicators
            .iter()
            .enumerate()
            .map(|(k, a)| ApplicatorMsg {
                id: a.id.clone(),
                position_m: a.position_m,
                rails: a.rails.iter().map(|&r| s.rails[r].clone()).collect(),
                // The grams the section's kg were converted from.
                nominal_pulse_g: p.nominal_pulse_g(k),
            })
            .collect(),
        measurement_sites: s
            .sites
            .iter()
            .map(|site| SiteMsg {
                id: site.id.clone(),
                position_m: site.position_m,
            })
            .collect(),
    }
}

/// A planned train's `/train/passage`, its wheel loads in kN as drawn; on
/// `line`, each axle's loads and creepages per segment in its field
/// `segments`.
pub(super) fn passage_msg(
    train: &TrainPlan,
    rails: &[String],
    line: Option<&Line>,
) -> Result<PassageMsg> {
    let per_rail_creepage = |c: &[Creepage]| {
        PerRail(
            rails
                .iter()
                .cloned()
                .zip(c.iter().map(|c| CreepageMsg {
                    cx: c.cx,
                    cy: c.cy,
                    spin_per_m: c.spin_per_m,
                }))
                .collect(),
        )
    };
    let per_rail_load =
        |kn: &[f64]| PerRail(rails.iter().cloned().zip(kn.iter().copied()).collect());
    let n = rails.len();
    let passage = &train.passage;
    Ok(PassageMsg {
        train_id: passage.train_id.clone(),
        direction: passage.direction,
        speed_mps: passage.speed_mps,
        consist: Some(train.kind.as_str().to_owned()),
        axles: passage
            .axles
            .iter()
            .enumerate()
            .map(|(i, a)| {
                Ok(AxleMsg {
                    offset_m: a.offset_m,
                    bogie_position: a.bogie_position,
                    wheel_diameter_m: a.wheel_diameter_m,
                    wheel_load_kn: per_rail_load(&train.load_kn[i * n..(i + 1) * n]),
                    creepage: per_rail_creepage(&a.creepage),
                    segments: line
                        .filter(|_| !a.segments.is_empty())
                        .map(|line| {
                            let entries = a
                                .segments
                                .iter()
                                .zip(&train.segment_load_kn[i])
                                .map(|(s, kn)| {
                                    let entry = AxleSegmentMsg {
                                        wheel_load_kn: Some(per_rail_load(kn)),
                                        creepage: s.creepage.as_deref().map(per_rail_creepage),
                                    };
                                    (line.segments[s.segment].id.clone(), entry)
                                })
                                .collect();
                            serde_json::value::to_raw_value(&PerRail(entries))
                                .map(RawJson)
                                .map_err(|source| Error::Json {
                                    what: "an axle's segments",
                                    source,
                                })
                        })
                        .transpose()?,
                })
            })
            .collect::<Result<_>>()?,
    })
}

pub(super) fn weather_msg(w: &Weather) -> WeatherMsg {
    WeatherMsg {
        air_temperature_c: w.air_temperature_c,
        relative_humidity: w.relative_humidity,
        precipitation_mm_h: w.precipitation_mm_h,
    }
}

/// A measurement's `/measurement/friction` with the measured `value`;
/// `None` when `value` is not finite (JSON cannot hold it) or outside the
/// format's range (`limits::MEASURED_VALUE`: the reader refuses it).
pub(super) fn measurement_msg(
    section: &Section,
    m: &Measurement,
    value: f64,
) -> Option<MeasurementMsg> {
    // What the reader would refuse is not written: a truth model that
    // drives friction out of any physical range (a hidden power law of
    // the creepage with a negative exponent, near zero creepage) is an
    // error here, not a recording that no replay reads.
    if !tortwin_recording::limits::MEASURED_VALUE.contains(value) {
        return None;
    }
    Some(MeasurementMsg {
        site_id: section.sites[m.site].id.clone(),
        rail: section.rails[m.rail].clone(),
        quantity: m.quantity(),
        train_id: m.axle().map(|a| a.train_id.to_string()),
        axle_index: m.axle().map(|a| a.axle_index),
        value,
    })
}
