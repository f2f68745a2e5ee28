//! A recording -> a folder of tables (module [`super`]): the inverse of
//! [`super::import`]. The recording is read and checked as a replay reads
//! it, in replay order, and each message written with the numbers it
//! carries (not the engine's SI values converted back), so that importing
//! the tables gives the same replay, bit for bit. Unknown topics and
//! unknown fields are not carried over.
//!
//! Every file is written under a temporary name and renamed when the whole
//! recording has been read: a failed export leaves no table that looks
//! complete.

use std::io::Write;
use std::path::{Path, PathBuf};

use super::{
    format_number, format_time, inert, rail_columns, MEASUREMENTS_FILE, MEASUREMENT_COLUMNS,
    PASSAGES_FILE, PASSAGE_COLUMNS, PULSES_FILE, PULSE_COLUMNS, SECTION_FILE, TIME_UTC,
    WEATHER_COLUMNS, WEATHER_FILE,
};
use crate::error::ConvertError;
use crate::event::{BogiePosition, Direction};
use crate::reader::{ReaderContext, RecordingReader, Wire};

/// Rows written per table.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct ExportSummary {
    pub trains: u64,
    pub axles: u64,
    pub pulses: u64,
    pub weather: u64,
    pub measurements: u64,
}

/// One table being written under a temporary name in the target folder.
struct Out {
    path: PathBuf,
    temp: tortwin_files::PartialFile,
    csv: csv::Writer<std::io::BufWriter<std::fs::File>>,
}

impl Out {
    fn create(dir: &Path, name: &str, header: &[String]) -> Result<Self, ConvertError> {
        let path = dir.join(name);
        let temp = tortwin_files::PartialFile::beside(&path)?;
        let file = temp
            .open_with(|path| std::fs::File::create(path))
            .map_err(|source| ConvertError::Io {
                what: "opening",
                path: temp.temp_path().to_path_buf(),
                source,
            })?;
        let csv = csv::Writer::from_writer(std::io::BufWriter::new(file));
        let mut out_header = vec![TIME_UTC.to_string()];
        out_header.extend(header.iter().cloned());
        // train_id first reads better in passages.csv.
        if name == PASSAGES_FILE {
            out_header.swap(0, 1);
        }
        let mut out = Self { path, temp, csv };
        out.row(&out_header)?;
        Ok(out)
    }

    fn row(&mut self, fields: &[String]) -> Result<(), ConvertError> {
        self.csv.write_record(fields).map_err(|e| ConvertError::Io {
            what: "writing",
            path: self.path.clone(),
            source: std::io::Error::other(e),
        })
    }

    fn finish(self) -> Result<(), ConvertError> {
        let Self {
            path,
            mut temp,
            csv,
        } = self;
        let mut file = csv.into_inner().map_err(|e| ConvertError::Io {
            what: "writing",
            path: path.clone(),
            source: std::io::Error::other(e.to_string()),
        })?;
        file.flush().map_err(|source| ConvertError::Io {
            what: "writing",
            path: path.clone(),
            source,
        })?;
        drop(file);
        temp.commit()?;
        Ok(())
    }
}

/// Writes the inputs of `recording` as tables into `dir` (created if
/// missing).
pub fn export_dir(recording: &Path, dir: &Path) -> Result<ExportSummary, ConvertError> {
    std::fs::create_dir_all(dir).map_err(|source| ConvertError::Io {
        what: "creating the folder",
        path: dir.to_path_buf(),
        source,
    })?;
    let mut reader = RecordingReader::open(recording, ReaderContext::default())?;
    let section = reader.section_msg().clone();
    let rails = section.rails.clone();

    let mut passage_header: Vec<String> = PASSAGE_COLUMNS.iter().map(|c| c.to_string()).collect();
    for rail in &rails {
        passage_header.extend(rail_columns(rail));
    }
    let strings = |cols: &[&str]| cols.iter().map(|c| c.to_string()).collect::<Vec<_>>();
    let mut passages = Out::create(dir, PASSAGES_FILE, &passage_header)?;
    let mut pulses = Out::create(dir, PULSES_FILE, &strings(&PULSE_COLUMNS))?;
    let mut weather = Out::create(dir, WEATHER_FILE, &strings(&WEATHER_COLUMNS))?;
    let mut measurements = Out::create(dir, MEASUREMENTS_FILE, &strings(&MEASUREMENT_COLUMNS))?;
    let mut summary = ExportSummary::default();
    while let Some(next) = reader.next_with_wire() {
        let (event, wire) = next?;
        let time = format_time(event.log_time_ns);
        match wire {
            Wire::Passage(p) => {
                summary.trains += 1;
                for axle in &p.axles {
                    summary.axles += 1;
                    let mut row = vec![
                        inert(&p.train_id).into_owned(),
                        time.clone(),
                        match p.direction {
                            Direction::Up => "up",
                            Direction::Down => "down",
                        }
                        .to_string(),
                        format_number(p.speed_mps),
                        format_number(axle.offset_m),
                        match axle.bogie_position {
                            BogiePosition::Leading => "leading",
                            BogiePosition::Trailing => "trailing",
                        }
                        .to_string(),
                        format_number(axle.wheel_diameter_m),
                    ];
                    // In the section's rail order (the reader checked that
                    // each map names every rail once).
                    for rail in &rails {
                        let load = axle.wheel_load_kn.0.iter().find(|(r, _)| r == rail);
                        let c = axle.creepage.0.iter().find(|(r, _)| r == rail);
                        row.push(load.map_or(String::new(), |(_, q)| format_number(*q)));
                        for v in [
                            c.map(|x| x.1.cx),
                            c.map(|x| x.1.cy),
                            c.map(|x| x.1.spin_per_m),
                        ] {
                            row.push(v.map_or(String::new(), format_number));
                        }
                    }
                    passages.row(&row)?;
                }
            }
            Wire::Pulse(p) => {
                summary.pulses += 1;
                pulses.row(&[
                    time,
                    inert(&p.applicator_id).into_owned(),
                    inert(&p.rail).into_owned(),
                    format_number(p.mass_g),
                ])?;
            }
            Wire::Weather(w) => {
                summary.weather += 1;
                weather.row(&[
                    time,
                    format_number(w.air_temperature_c),
                    format_number(w.relative_humidity),
                    format_number(w.precipitation_mm_h),
                ])?;
            }
            Wire::Measurement(m) => {
                summary.measurements += 1;
                measurements.row(&[
                    time,
                    inert(&m.site_id).into_owned(),
                    inert(&m.rail).into_owned(),
                    m.quantity.as_str().to_string(),
                    m.train_id
                        .as_deref()
                        .map_or(String::new(), |t| inert(t).into_owned()),
                    m.axle_index.map_or(String::new(), |a| a.to_string()),
                    format_number(m.value),
                ])?;
            }
        }
    }

    // section.toml last: written whole once the recording has read through.
    let toml = section_toml(&section, reader.section_log_time_ns());
    for out in [passages, pulses, weather, measurements] {
        out.finish()?;
    }
    tortwin_files::write_atomically(&dir.join(SECTION_FILE), toml.as_bytes())?;
    Ok(summary)
}

/// `section.toml` for a `/section` message taking effect at `log_time_ns`.
fn section_toml(s: &crate::wire::SectionMsg, log_time_ns: u64) -> String {
    use std::fmt::Write as _;
    let q = |x: &str| toml::Value::String(x.to_string()).to_string();
    let list = |xs: &[String]| {
        let items: Vec<String> = xs.iter().map(|x| q(x)).collect();
        format!("[{}]", items.join(", "))
    };
    // `{:?}` writes a float TOML reads back exactly (always with a point).
    let mut t = String::new();
    let _ = writeln!(
        t,
        "# The track section (docs/spec/recording-format.md, /section)."
    );
    let _ = writeln!(t, "section_id = {}", q(&s.section_id));
    let _ = writeln!(
        t,
        "# When this description takes effect (the /section log_time)."
    );
    let _ = writeln!(t, "time_utc = {}", q(&format_time(log_time_ns)));
    let _ = writeln!(t, "length_m = {:?}", s.length_m);
    let _ = writeln!(t, "rails = {}", list(&s.rails));
    match s.curve_radius_m {
        Some(r) => {
            let _ = writeln!(t, "curve_radius_m = {r:?}");
        }
        None => {
            let _ = writeln!(t, "# tangent track: no curve_radius_m");
        }
    }
    let _ = writeln!(t, "rail_head_radius_m = {:?}", s.rail_head_radius_m);
    let _ = writeln!(
        t,
        "nominal_wheel_diameter_m = {:?}",
        s.nominal_wheel_diameter_m
    );
    for a in &s.applicators {
        let _ = writeln!(t, "\n[[applicators]]");
        let _ = writeln!(t, "id = {}", q(&a.id));
        let _ = writeln!(t, "position_m = {:?}", a.position_m);
        let _ = writeln!(t, "rails = {}", list(&a.rails));
        let _ = writeln!(t, "nominal_pulse_g = {:?}", a.nominal_pulse_g);
    }
    for site in &s.measurement_sites {
        let _ = writeln!(t, "\n[[measurement_sites]]");
        let _ = writeln!(t, "id = {}", q(&site.id));
        let _ = writeln!(t, "position_m = {:?}", site.position_m);
    }
    t
}
