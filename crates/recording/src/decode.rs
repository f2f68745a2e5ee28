//! A message's bytes -> its wire struct -> a typed event.
//!
//! [`parse`] is the grammar: serde turns the JSON into the topic's wire
//! struct ([`crate::wire`]), and a failure names the field by its path
//! (serde_path_to_error), e.g. `axles[1].creepage.right`. [`section`] and
//! [`Decoder`] are the rules of docs/spec/recording-format.md that
//! span fields, messages or the section: values in range, units converted
//! (g -> kg, kN -> N), rails, applicators, sites and trains resolved to
//! indices, train ids unique and one train in the section at a time.
//!
//! Errors are sentences without a location ([`DecodeError`]); the reader
//! adds the file, topic, log_time and message index, and the CSV import
//! (`tables`) the file, line and column of the field the error names.

use std::collections::HashMap;

use serde_json::Value;

use crate::event::{
    Applicator, Axle, AxleRef, AxleSegment, BogiePosition, Creepage, Direction, Measured,
    Measurement, Passage, Pulse, Quantity, Section, Site, Weather,
};
use crate::limits::{self, Range};
use crate::line::{axle_at_ends_s, Line};
use crate::wire::json::FromJson;
use crate::wire::{
    AxleSegmentMsg, CreepageMsg, MeasurementMsg, PassageMsg, PerRail, PulseMsg, RawJson,
    SectionMsg, WeatherMsg,
};

mod compact;
pub(crate) use compact::{compact_measurement, compact_passage, compact_pulse};

/// An `/applicator/pulse` message's fields, borrowed: from its wire
/// struct, or straight from its text ([`compact_pulse`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct PulseFields<'a> {
    pub applicator_id: &'a str,
    pub rail: &'a str,
    pub mass_g: f64,
}

impl<'a> From<&'a PulseMsg> for PulseFields<'a> {
    fn from(msg: &'a PulseMsg) -> Self {
        Self {
            applicator_id: &msg.applicator_id,
            rail: &msg.rail,
            mass_g: msg.mass_g,
        }
    }
}

/// A `/measurement/friction` message's fields, borrowed: from its wire
/// struct, or straight from its text ([`compact_measurement`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct MeasurementFields<'a> {
    pub site_id: &'a str,
    pub rail: &'a str,
    pub quantity: Quantity,
    pub train_id: Option<&'a str>,
    pub axle_index: Option<usize>,
    pub value: f64,
}

impl<'a> From<&'a MeasurementMsg> for MeasurementFields<'a> {
    fn from(msg: &'a MeasurementMsg) -> Self {
        Self {
            site_id: &msg.site_id,
            rail: &msg.rail,
            quantity: msg.quantity,
            train_id: msg.train_id.as_deref(),
            axle_index: msg.axle_index,
            value: msg.value,
        }
    }
}

/// A `/train/passage` message's fields, borrowed: from its wire struct, or
/// straight from its text ([`compact_passage`]). The axles' per-rail
/// values are kept in two lists for the whole train (one allocation each,
/// not two maps and four names per axle), each axle holding its range of
/// them, in the order written.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PassageFields<'a> {
    pub train_id: &'a str,
    pub direction: Direction,
    pub speed_mps: f64,
    pub axles: Vec<AxleFields<'a>>,
    /// `wheel_load_kN` of every axle: (rail name, kN).
    pub wheel_loads_kn: Vec<(&'a str, f64)>,
    /// `creepage` of every axle: (rail name, creepages).
    pub creepages: Vec<(&'a str, CreepageMsg)>,
}

/// An axle of [`PassageFields`].
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct AxleFields<'a> {
    pub offset_m: f64,
    pub bogie_position: BogiePosition,
    pub wheel_diameter_m: f64,
    /// Its entries of [`PassageFields::wheel_loads_kn`].
    pub wheel_load_kn: std::ops::Range<usize>,
    /// Its entries of [`PassageFields::creepages`].
    pub creepage: std::ops::Range<usize>,
    pub segments: Option<&'a RawJson>,
}

impl<'a> From<&'a PassageMsg> for PassageFields<'a> {
    fn from(msg: &'a PassageMsg) -> Self {
        let mut fields = PassageFields {
            train_id: &msg.train_id,
            direction: msg.direction,
            speed_mps: msg.speed_mps,
            axles: Vec::with_capacity(msg.axles.len()),
            wheel_loads_kn: Vec::new(),
            creepages: Vec::new(),
        };
        for a in &msg.axles {
            let loads = fields.wheel_loads_kn.len();
            fields.wheel_loads_kn.extend(borrowed(&a.wheel_load_kn));
            let creepages = fields.creepages.len();
            fields.creepages.extend(borrowed(&a.creepage));
            fields.axles.push(AxleFields {
                offset_m: a.offset_m,
                bogie_position: a.bogie_position,
                wheel_diameter_m: a.wheel_diameter_m,
                wheel_load_kn: loads..fields.wheel_loads_kn.len(),
                creepage: creepages..fields.creepages.len(),
                segments: a.segments.as_ref(),
            });
        }
        fields
    }
}

/// A per-rail map's entries with the rail names borrowed.
fn borrowed<T: Copy>(map: &PerRail<T>) -> impl Iterator<Item = (&str, T)> {
    map.0.iter().map(|(rail, value)| (rail.as_str(), *value))
}

/// Why a message breaks the format: a sentence, and the field it is about
/// (its path in the message, e.g. `axles[3].offset_m`; `log_time` for the
/// message's time) where there is one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct DecodeError {
    pub field: Option<String>,
    pub message: String,
}

impl DecodeError {
    pub(crate) fn at(field: impl Into<String>, message: String) -> Self {
        Self {
            field: Some(field.into()),
            message,
        }
    }
}

impl std::fmt::Display for DecodeError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl From<String> for DecodeError {
    /// A sentence about the whole message.
    fn from(message: String) -> Self {
        Self {
            field: None,
            message,
        }
    }
}

/// A message's JSON as the wire struct `T`, or why not.
pub(crate) fn parse<'de, T: FromJson<'de>>(data: &'de [u8]) -> Result<T, DecodeError> {
    // Tracking the path costs about a third of the parse: a message that
    // parses needs no path, and one that does not is parsed again with it
    // (the same bytes fail at the same place).
    // Text checked as UTF-8 once is parsed without checking each string
    // of it again (every key: a sixth of the parse, measured 2026-12-02);
    // bytes that are not UTF-8 fail below, where the error says where.
    if let Ok(text) = std::str::from_utf8(data) {
        let mut json = serde_json::Deserializer::from_str(text);
        if let Ok(value) = T::from_json(&mut json).and_then(|value| json.end().map(|()| value)) {
            return Ok(value);
        }
    }
    let mut json = serde_json::Deserializer::from_slice(data);
    let mut track = serde_path_to_error::Track::new();
    let parsed = T::from_json(serde_path_to_error::Deserializer::new(
        &mut json, &mut track,
    ))
    .and_then(|value| json.end().map(|()| value));
    parsed.map_err(|e| {
        let path = track.path();
        let field = path.iter().next().is_some().then(|| path.to_string());
        DecodeError {
            field,
            message: describe(data, &path, e),
        }
    })
}

/// The sentence for a message that does not parse as its wire struct.
fn describe(data: &[u8], path: &serde_path_to_error::Path, e: serde_json::Error) -> String {
    if !e.is_data() {
        // The path still says where the reader was: the field whose value
        // is not JSON (a NaN, an infinity, a number that overflows).
        let at = if path.iter().next().is_some() {
            format!("field `{path}`: ")
        } else {
            String::new()
        };
        return format!(
            "{at}the message is not valid JSON ({e}); NaN and infinity are not JSON numbers"
        );
    }
    // serde names an array or object only by its kind ("sequence", "map"):
    // show it, shortened. Only on this error path is the JSON parsed again.
    let root = serde_json::from_slice::<Value>(data).ok();
    let shown = root
        .as_ref()
        .and_then(|root| {
            path.iter().try_fold(root, |value, segment| match segment {
                serde_path_to_error::Segment::Seq { index } => value.get(*index),
                serde_path_to_error::Segment::Map { key } => value.get(key),
                _ => None,
            })
        })
        .filter(|v| v.is_array() || v.is_object())
        .map_or(String::new(), |v| format!(" (got {})", show(v)));
    if path.iter().next().is_none() {
        format!("{e}{shown}")
    } else {
        format!("field `{path}`: {e}{shown}")
    }
}

/// A JSON value for a message, shortened so a huge value cannot flood it.
fn show(value: &Value) -> String {
    const MAX_CHARS: usize = 60;
    let text = value.to_string();
    if text.chars().count() > MAX_CHARS {
        let short: String = text.chars().take(MAX_CHARS).collect();
        format!("{short}...")
    } else {
        text
    }
}

fn positive(name: impl FnOnce() -> String, x: f64) -> Result<f64, DecodeError> {
    if x > 0.0 {
        Ok(x)
    } else {
        let name = name();
        let message = format!("field `{name}` must be positive, got {x:?}");
        Err(DecodeError::at(name, message))
    }
}

fn non_negative(name: impl FnOnce() -> String, x: f64) -> Result<f64, DecodeError> {
    if x >= 0.0 {
        Ok(x)
    } else {
        let name = name();
        let message = format!("field `{name}` must not be negative, got {x:?}");
        Err(DecodeError::at(name, message))
    }
}

/// `x` within its physical range ([`crate::limits`]).
fn within(range: &Range, name: impl FnOnce() -> String, x: f64) -> Result<f64, DecodeError> {
    if range.contains(x) {
        Ok(x)
    } else {
        let name = name();
        let unit = match range.unit {
            "" => String::new(),
            u => format!(" {u}"),
        };
        let message = format!(
            "field `{name}` = {x:?} is outside its physical range {} to {}{unit} ({})",
            range.lo, range.hi, range.why
        );
        Err(DecodeError::at(name, message))
    }
}

/// A message's log_time as the signed nanosecond count every time in
/// tortwin is: past [`limits::LAST_LOG_TIME_NS`] (2262-04-11) is an error.
pub(crate) fn log_time(log_time_ns: u64) -> Result<i64, DecodeError> {
    i64::try_from(log_time_ns).map_err(|_| {
        DecodeError::at(
            "log_time",
            format!(
                "log_time {log_time_ns} ns is after 2262-04-11T23:47:16.854775807Z, the last                  instant a signed 64-bit nanosecond count (every time tortwin reads and writes)                  holds"
            ),
        )
    })
}

fn non_empty<T>(name: &str, items: &[T]) -> Result<(), DecodeError> {
    if items.is_empty() {
        Err(DecodeError::at(
            name,
            format!("field `{name}` must not be empty"),
        ))
    } else {
        Ok(())
    }
}

/// The index of a rail name of the section.
fn resolve_rail(rails: &[String], name: &str, field: &str) -> Result<usize, DecodeError> {
    rails.iter().position(|r| r == name).ok_or_else(|| {
        DecodeError::at(
            field,
            format!(
                "field `{field}`: rail `{name}` is not a rail of the section (rails: {})",
                rails.join(", ")
            ),
        )
    })
}

/// An axle's wheel loads (`name`: the map's field path), kN -> N.
fn wheel_loads_n(
    map: &[(&str, f64)],
    rails: &[String],
    name: &dyn Fn() -> String,
) -> Result<Vec<f64>, DecodeError> {
    per_rail(map, rails, name, |kn, rail| {
        let name = || format!("{}.{rail}", name());
        Ok(within(&limits::WHEEL_LOAD_KN, name, positive(name, kn)?)? * 1e3)
    })
}

/// An axle's creepages (`name`: the map's field path).
fn creepages(
    map: &[(&str, CreepageMsg)],
    rails: &[String],
    name: &dyn Fn() -> String,
) -> Result<Vec<Creepage>, DecodeError> {
    per_rail(map, rails, name, |c, rail| {
        let name = |what: &str| format!("{}.{rail}.{what}", name());
        Ok(Creepage {
            cx: within(&limits::CREEPAGE, || name("cx"), c.cx)?,
            cy: within(&limits::CREEPAGE, || name("cy"), c.cy)?,
            spin_per_m: within(&limits::SPIN_PER_M, || name("spin_per_m"), c.spin_per_m)?,
        })
    })
}

/// Axle `i`'s field `segments` on `line` (line.md): per segment id, a
/// load, a creepage or both, each complete per rail; an entry with neither
/// and an unknown segment id are input errors.
fn axle_segments(
    value: &RawJson,
    line: &Line,
    rails: &[String],
    i: usize,
) -> Result<Vec<AxleSegment>, DecodeError> {
    // As [`parse`]: the path is tracked only when the plain parse fails.
    let plain = serde_json::from_str::<PerRail<AxleSegmentMsg>>(value.0.get());
    let mut json = serde_json::Deserializer::from_str(value.0.get());
    let entries: PerRail<AxleSegmentMsg> = match plain {
        Ok(entries) => entries,
        Err(_) => serde_path_to_error::deserialize(&mut json).map_err(|e| {
            let path = e.path().to_string();
            let field = if path == "." {
                format!("axles[{i}].segments")
            } else {
                format!("axles[{i}].segments.{path}")
            };
            DecodeError::at(field.clone(), format!("field `{field}`: {}", e.inner()))
        })?,
    };
    let mut segments: Vec<AxleSegment> = Vec::with_capacity(entries.0.len());
    for (id, entry) in &entries.0 {
        let field = || format!("axles[{i}].segments.{id}");
        let Some(segment) = line.segment(id) else {
            return Err(DecodeError::at(
                field(),
                format!(
                    "`{}` names segment `{id}`, which the line does not have",
                    field()
                ),
            ));
        };
        if segments.iter().any(|s| s.segment == segment) {
            return Err(DecodeError::at(
                field(),
                format!("`axles[{i}].segments` names segment `{id}` twice"),
            ));
        }
        if entry.wheel_load_kn.is_none() && entry.creepage.is_none() {
            return Err(DecodeError::at(
                field(),
                format!("`{}` gives neither wheel_load_kN nor creepage", field()),
            ));
        }
        segments.push(AxleSegment {
            segment,
            wheel_load_n: entry
                .wheel_load_kn
                .as_ref()
                .map(|m| {
                    let m: Vec<_> = borrowed(m).collect();
                    wheel_loads_n(&m, rails, &|| format!("{}.wheel_load_kN", field()))
                })
                .transpose()?,
            creepage: entry
                .creepage
                .as_ref()
                .map(|m| {
                    let m: Vec<_> = borrowed(m).collect();
                    creepages(&m, rails, &|| format!("{}.creepage", field()))
                })
                .transpose()?,
        });
    }
    segments.sort_by_key(|s| s.segment);
    Ok(segments)
}

/// A per-rail map as one value per rail of the section, in rail order, each
/// made by `each` from the map's value and the rail's name: the map must
/// name every rail once and no other (`name()` is the map's field, for the
/// errors). Allocates only the result.
fn per_rail<T: Copy, U>(
    map: &[(&str, T)],
    rails: &[String],
    name: impl Fn() -> String,
    mut each: impl FnMut(T, &str) -> Result<U, DecodeError>,
) -> Result<Vec<U>, DecodeError> {
    // In the map's order: a rail the section lacks, or one named again. A
    // map of known rails repeats one by its (rails + 1)-th entry at the
    // latest, so this looks at no more than rails^2 pairs.
    for (j, &(rail, _)) in map.iter().enumerate() {
        if !rails.iter().any(|r| r == rail) {
            let name = name();
            return Err(DecodeError::at(
                format!("{name}.{rail}"),
                format!(
                    "`{name}` names rail `{rail}`, which the section does not have (rails: {})",
                    rails.join(", ")
                ),
            ));
        }
        if map[..j].iter().any(|&(earlier, _)| earlier == rail) {
            let name = name();
            return Err(DecodeError::at(
                format!("{name}.{rail}"),
                format!("`{name}` names rail `{rail}` twice"),
            ));
        }
    }
    let value = |rail: &String| map.iter().find(|&&(r, _)| r == rail).map(|&(_, v)| v);
    let lacks = |rail: &String| {
        let name = name();
        DecodeError::at(
            format!("{name}.{rail}"),
            format!("`{name}` lacks rail `{rail}`"),
        )
    };
    // Then, in the section's order, a rail the map lacks; only then the
    // values.
    if let Some(rail) = rails.iter().find(|rail| value(rail).is_none()) {
        return Err(lacks(rail));
    }
    rails
        .iter()
        .map(|rail| value(rail).map_or_else(|| Err(lacks(rail)), |v| each(v, rail)))
        .collect()
}

/// Grid points a rail may have, `floor(length_m / (pi *
/// nominal_wheel_diameter_m)) + 1`: 200 000 is a 578 km section of 0.92 m
/// wheels; the engine's memory is about 100 bytes a point, rail and band.
/// A bound so that a corrupt diameter or length cannot ask for gigabytes
/// (docs/spec/recording-format.md "Limits").
pub const MAX_GRID_POINTS: usize = 200_000;

/// Axles a `/train/passage` may have: the longest freight trains run about
/// 3 000.
pub const MAX_AXLES: usize = 10_000;

/// The `/section` message as the typed [`Section`].
pub(crate) fn section(msg: &SectionMsg) -> Result<Section, DecodeError> {
    let length_m = within(
        &limits::SECTION_LENGTH_M,
        || "length_m".into(),
        msg.length_m,
    )?;

    non_empty("rails", &msg.rails)?;
    let counts = [
        ("rails", msg.rails.len(), limits::MAX_RAILS),
        (
            "applicators",
            msg.applicators.len(),
            limits::MAX_APPLICATORS,
        ),
        (
            "measurement_sites",
            msg.measurement_sites.len(),
            limits::MAX_SITES,
        ),
    ];
    for (field, n, most) in counts {
        if n > most {
            return Err(DecodeError::at(
                field,
                format!("{n} entries in `{field}`; a section has at most {most}"),
            ));
        }
    }
    let mut rails: Vec<String> = Vec::with_capacity(msg.rails.len());
    for (j, name) in msg.rails.iter().enumerate() {
        if rails.contains(name) {
            return Err(DecodeError::at(
                format!("rails[{j}]"),
                format!("duplicate rail `{name}` in `rails`"),
            ));
        }
        rails.push(name.clone());
    }

    let curve_radius_m = msg
        .curve_radius_m
        .map(|r| within(&limits::CURVE_RADIUS_M, || "curve_radius_m".into(), r))
        .transpose()?;

    let in_section = |name: &dyn Fn() -> String, x: f64| -> Result<f64, DecodeError> {
        if (0.0..=length_m).contains(&x) {
            Ok(x)
        } else {
            let name = name();
            let message = format!(
                "field `{name}` = {x:?} is outside the section (0 to length_m = {length_m:?} m)"
            );
            Err(DecodeError::at(name, message))
        }
    };

    non_empty("applicators", &msg.applicators)?;
    let mut applicators: Vec<Applicator> = Vec::with_capacity(msg.applicators.len());
    for (i, a) in msg.applicators.iter().enumerate() {
        if applicators.iter().any(|known| known.id == a.id) {
            return Err(DecodeError::at(
                format!("applicators[{i}].id"),
                format!("duplicate applicator id `{}`", a.id),
            ));
        }
        let field = format!("applicators[{i}].rails");
        non_empty(&field, &a.rails)?;
        let mut applicator_rails = Vec::with_capacity(a.rails.len());
        for (j, name) in a.rails.iter().enumerate() {
            let index = resolve_rail(&rails, name, &format!("{field}[{j}]"))?;
            if applicator_rails.contains(&index) {
                return Err(DecodeError::at(
                    format!("{field}[{j}]"),
                    format!("duplicate rail `{name}` in `{field}`"),
                ));
            }
            applicator_rails.push(index);
        }
        applicators.push(Applicator {
            id: a.id.clone(),
            position_m: in_section(&|| format!("applicators[{i}].position_m"), a.position_m)?,
            rails: applicator_rails,
            nominal_pulse_kg: within(
                &limits::PULSE_G,
                || format!("applicators[{i}].nominal_pulse_g"),
                non_negative(
                    || format!("applicators[{i}].nominal_pulse_g"),
                    a.nominal_pulse_g,
                )?,
            )? * 1e-3,
        });
    }

    let mut sites: Vec<Site> = Vec::with_capacity(msg.measurement_sites.len());
    for (i, s) in msg.measurement_sites.iter().enumerate() {
        if sites.iter().any(|known| known.id == s.id) {
            return Err(DecodeError::at(
                format!("measurement_sites[{i}].id"),
                format!("duplicate measurement site id `{}`", s.id),
            ));
        }
        sites.push(Site {
            id: s.id.clone(),
            position_m: in_section(
                &|| format!("measurement_sites[{i}].position_m"),
                s.position_m,
            )?,
        });
    }

    let nominal_wheel_diameter_m = within(
        &limits::WHEEL_DIAMETER_M,
        || "nominal_wheel_diameter_m".into(),
        positive(
            || "nominal_wheel_diameter_m".into(),
            msg.nominal_wheel_diameter_m,
        )?,
    )?;
    let points = (length_m / (std::f64::consts::PI * nominal_wheel_diameter_m)).floor() + 1.0;
    if points > MAX_GRID_POINTS as f64 {
        return Err(DecodeError::at(
            "nominal_wheel_diameter_m",
            format!(
                "length_m = {length_m} and nominal_wheel_diameter_m = {nominal_wheel_diameter_m} \
                 make a grid of {points:.0} points a rail (one per wheel circumference); \
                 at most {MAX_GRID_POINTS} are accepted"
            ),
        ));
    }

    Ok(Section {
        section_id: msg.section_id.clone(),
        length_m,
        rails,
        curve_radius_m,
        rail_head_radius_m: within(
            &limits::RAIL_HEAD_RADIUS_M,
            || "rail_head_radius_m".into(),
            positive(|| "rail_head_radius_m".into(), msg.rail_head_radius_m)?,
        )?,
        nominal_wheel_diameter_m,
        applicators,
        sites,
    })
}

/// A train the replay has seen, for measurements and the duplicate check.
#[derive(Debug, Clone, Copy)]
struct TrainSeen {
    train_seq: usize,
    axle_count: usize,
    log_time_ns: u64,
}

/// The rules that need what came before in the replay: the section, the
/// trains seen so far (their number grows with the recording, one entry a
/// train) and the section's occupation.
#[derive(Debug, Clone)]
pub(crate) struct Decoder {
    section: Section,
    /// The section's `/line`, if the recording is a line.
    line: Option<Line>,
    origin_ns: i64,
    /// By id, the key shared by the train's measurements' [`AxleRef`]s.
    trains: HashMap<std::sync::Arc<str>, TrainSeen>,
    /// `train_id` of the last passage, for the two-trains message.
    last_train_id: Option<String>,
    occupied_until_s: f64,
    /// On a line: when the last passage's last axle reaches each end of the
    /// line (`d = 0`, `d = L`), for the rule that no train catches up with
    /// the one before it.
    last_axle_at_ends_s: Option<[f64; 2]>,
}

impl Decoder {
    /// `occupied_until_s`: when the last train before this recording left
    /// the section (s from `origin_ns`; `NEG_INFINITY` for none).
    pub(crate) fn new(
        section: Section,
        line: Option<Line>,
        origin_ns: i64,
        occupied_until_s: f64,
    ) -> Self {
        Self {
            section,
            line,
            origin_ns,
            trains: HashMap::new(),
            last_train_id: None,
            occupied_until_s,
            last_axle_at_ends_s: None,
        }
    }

    pub(crate) fn section(&self) -> &Section {
        &self.section
    }

    pub(crate) fn line(&self) -> Option<&Line> {
        self.line.as_ref()
    }

    pub(crate) fn origin_ns(&self) -> i64 {
        self.origin_ns
    }

    pub(crate) fn occupied_until_s(&self) -> f64 {
        self.occupied_until_s
    }

    /// Time in s from the origin, as model.md "Units and time" defines it.
    fn time_s(&self, log_time_ns: u64) -> Option<f64> {
        let t = i64::try_from(log_time_ns).ok()?;
        Some(t.checked_sub(self.origin_ns)? as f64 * 1e-9)
    }

    /// A `/train/passage` at `log_time_ns`; it becomes the next train.
    pub(crate) fn passage(
        &mut self,
        msg: PassageFields<'_>,
        log_time_ns: u64,
    ) -> Result<Passage, DecodeError> {
        let rails = &self.section.rails;
        let speed_mps = within(
            &limits::SPEED_MPS,
            || "speed_mps".into(),
            positive(|| "speed_mps".into(), msg.speed_mps)?,
        )?;
        non_empty("axles", &msg.axles)?;
        if msg.axles.len() > MAX_AXLES {
            return Err(DecodeError::at(
                "axles",
                format!(
                    "{} axles; a train may have at most {MAX_AXLES}",
                    msg.axles.len()
                ),
            ));
        }
        let mut axles: Vec<Axle> = Vec::with_capacity(msg.axles.len());
        for (i, a) in msg.axles.iter().enumerate() {
            let offset_m = within(
                &limits::OFFSET_M,
                || format!("axles[{i}].offset_m"),
                non_negative(|| format!("axles[{i}].offset_m"), a.offset_m)?,
            )?;
            if let Some(previous) = axles.last() {
                if offset_m < previous.offset_m {
                    return Err(DecodeError::at(
                        format!("axles[{i}].offset_m"),
                        format!(
                            "field `axles[{i}].offset_m` = {offset_m} is less than the previous \
                             axle's {}; offsets never decrease along the train",
                            previous.offset_m
                        ),
                    ));
                }
            }
            let wheel_load_n =
                wheel_loads_n(&msg.wheel_loads_kn[a.wheel_load_kn.clone()], rails, &|| {
                    format!("axles[{i}].wheel_load_kN")
                })?;
            let creepage = creepages(&msg.creepages[a.creepage.clone()], rails, &|| {
                format!("axles[{i}].creepage")
            })?;
            // Without a line the field is unknown and ignored (line.md).
            let segments = match (&self.line, a.segments) {
                (Some(line), Some(value)) => axle_segments(value, line, rails, i)?,
                _ => Vec::new(),
            };
            axles.push(Axle {
                offset_m,
                bogie_position: a.bogie_position,
                wheel_diameter_m: within(
                    &limits::WHEEL_DIAMETER_M,
                    || format!("axles[{i}].wheel_diameter_m"),
                    positive(
                        || format!("axles[{i}].wheel_diameter_m"),
                        a.wheel_diameter_m,
                    )?,
                )?,
                wheel_load_n,
                creepage,
                segments,
            });
        }

        let train_seq = self.trains.len();
        if let Some(seen) = self.trains.get(msg.train_id) {
            return Err(DecodeError::at(
                "train_id",
                format!(
                    "duplicate train_id `{}`: passage {} at log_time {} ns already has it",
                    msg.train_id, seen.train_seq, seen.log_time_ns
                ),
            ));
        }
        let t_passage_s = self.time_s(log_time_ns).ok_or_else(|| {
            DecodeError::at(
                "log_time",
                format!(
                    "log_time {log_time_ns} ns is out of range for the time origin {} ns",
                    self.origin_ns
                ),
            )
        })?;
        let up = msg.direction == Direction::Up;
        let length_m = self.section.length_m;
        let first_offset_m = axles.first().map_or(0.0, |a| a.offset_m);
        if let (Some(_), Some(before)) = (&self.line, self.last_axle_at_ends_s) {
            // line.md: trains may share a line as long as none catches up
            // with the one before it; speeds are constant, so the ends
            // decide (equal is allowed).
            let front = axle_at_ends_s(t_passage_s, up, length_m, first_offset_m, speed_mps);
            if let Some(end) = (0..2).find(|&k| front[k] < before[k]) {
                return Err(DecodeError::at(
                    "log_time",
                    format!(
                        "train `{}` catches up with train `{}` on the line: its first axle \
                         reaches d = {} m at {} s, before the other's last axle at {} s \
                         (docs/spec/line.md: trains share a line while none catches up with \
                         another)",
                        msg.train_id,
                        self.last_train_id.as_deref().unwrap_or("?"),
                        [0.0, length_m][end],
                        front[end],
                        before[end]
                    ),
                ));
            }
        } else if t_passage_s < self.occupied_until_s {
            let previous = match &self.last_train_id {
                Some(id) => format!("train `{id}`"),
                None => "the last train of the previous recording".to_string(),
            };
            // A line's first train after a state: the state was cut where
            // no train was on the line.
            let line = match self.line {
                Some(_) => " (a state is cut where no train is on the line)",
                None => "",
            };
            return Err(DecodeError::at(
                "log_time",
                format!(
                    "two trains in the section at once: train `{}` enters at {t_passage_s} s, \
                     before {previous} has left it at {} s{line}",
                    msg.train_id, self.occupied_until_s
                ),
            ));
        }
        let last_offset_m = axles.last().map_or(0.0, |a| a.offset_m);
        let leaves_s = t_passage_s + (self.section.length_m + last_offset_m) / speed_mps;
        let leaves_ns = self.origin_ns as f64 + leaves_s * 1e9;
        if leaves_ns >= limits::LAST_LOG_TIME_NS as f64 {
            return Err(DecodeError::at(
                "speed_mps",
                format!(
                    "train `{}` at {speed_mps} m/s leaves the section {leaves_s} s after the time                      origin, after 2262-04-11T23:47:16Z, the last instant a signed 64-bit                      nanosecond count holds",
                    msg.train_id
                ),
            ));
        }
        self.occupied_until_s = self.occupied_until_s.max(leaves_s);
        self.last_axle_at_ends_s = Some(axle_at_ends_s(
            t_passage_s,
            up,
            length_m,
            last_offset_m,
            speed_mps,
        ));
        self.trains.insert(
            msg.train_id.into(),
            TrainSeen {
                train_seq,
                axle_count: axles.len(),
                log_time_ns,
            },
        );
        self.last_train_id = Some(msg.train_id.to_string());
        Ok(Passage {
            train_id: msg.train_id.to_string(),
            train_seq,
            direction: msg.direction,
            speed_mps,
            axles,
        })
    }

    /// An `/applicator/pulse`: on a rail its applicator lists.
    pub(crate) fn pulse(&self, msg: PulseFields<'_>) -> Result<Pulse, DecodeError> {
        let section = &self.section;
        let id = msg.applicator_id;
        let Some((applicator, a)) = section
            .applicators
            .iter()
            .enumerate()
            .find(|(_, a)| a.id == id)
        else {
            return Err(DecodeError::at(
                "applicator_id",
                format!("field `applicator_id`: unknown applicator `{id}`"),
            ));
        };
        let rail = resolve_rail(&section.rails, msg.rail, "rail")?;
        if !a.rails.contains(&rail) {
            let listed: Vec<&str> = a
                .rails
                .iter()
                .filter_map(|&r| section.rails.get(r).map(String::as_str))
                .collect();
            return Err(DecodeError::at(
                "rail",
                format!(
                    "field `rail`: applicator `{id}` does not apply to rail `{}` (its rails: {})",
                    msg.rail,
                    listed.join(", ")
                ),
            ));
        }
        Ok(Pulse {
            applicator,
            rail,
            mass_kg: within(
                &limits::PULSE_G,
                || "mass_g".into(),
                non_negative(|| "mass_g".into(), msg.mass_g)?,
            )? * 1e-3,
        })
    }

    /// A `/measurement/friction`: a `mu` or `adhesion` measurement names a
    /// train already seen and one of its axles.
    pub(crate) fn measurement(
        &self,
        msg: MeasurementFields<'_>,
    ) -> Result<Measurement, DecodeError> {
        let section = &self.section;
        let site = section
            .sites
            .iter()
            .position(|s| s.id == msg.site_id)
            .ok_or_else(|| {
                DecodeError::at(
                    "site_id",
                    format!(
                        "field `site_id`: unknown measurement site `{}`",
                        msg.site_id
                    ),
                )
            })?;
        let rail = resolve_rail(&section.rails, msg.rail, "rail")?;
        let of = match msg.quantity {
            Quantity::RailMu => {
                if let Some(train_id) = msg.train_id {
                    return Err(DecodeError::at(
                        "train_id",
                        format!(
                            "a `rail_mu` measurement is of the rail alone, but it has \
                             `train_id` = {}",
                            Value::from(train_id)
                        ),
                    ));
                }
                if let Some(axle_index) = msg.axle_index {
                    return Err(DecodeError::at(
                        "axle_index",
                        format!(
                            "a `rail_mu` measurement is of the rail alone, but it has \
                             `axle_index` = {axle_index}"
                        ),
                    ));
                }
                Measured::RailMu
            }
            Quantity::Mu | Quantity::Adhesion => {
                let what = msg.quantity.as_str();
                let train_id = msg.train_id.ok_or_else(|| {
                    DecodeError::at(
                        "train_id",
                        format!(
                            "missing field `train_id` (a `{what}` measurement names its train)"
                        ),
                    )
                })?;
                let axle_index = msg.axle_index.ok_or_else(|| {
                    DecodeError::at(
                        "axle_index",
                        format!(
                            "missing field `axle_index` (a `{what}` measurement names its axle)"
                        ),
                    )
                })?;
                let Some((id, train)) = self.trains.get_key_value(train_id) else {
                    return Err(DecodeError::at(
                        "train_id",
                        format!(
                            "train_id `{train_id}` is unknown: no /train/passage with it \
                             comes before this measurement"
                        ),
                    ));
                };
                if axle_index >= train.axle_count {
                    return Err(DecodeError::at(
                        "axle_index",
                        format!(
                            "axle_index {axle_index} is out of range: train `{train_id}` has {} \
                             axles",
                            train.axle_count
                        ),
                    ));
                }
                let axle = AxleRef {
                    train_id: std::sync::Arc::clone(id),
                    train_seq: train.train_seq,
                    axle_index,
                };
                if msg.quantity == Quantity::Mu {
                    Measured::Mu(axle)
                } else {
                    Measured::Adhesion(axle)
                }
            }
        };
        Ok(Measurement {
            site,
            rail,
            of,
            value: within(&limits::MEASURED_VALUE, || "value".into(), msg.value)?,
        })
    }

    /// An `/environment/weather`.
    pub(crate) fn weather(&self, msg: &WeatherMsg) -> Result<Weather, DecodeError> {
        Ok(Weather {
            air_temperature_c: within(
                &limits::AIR_TEMPERATURE_C,
                || "air_temperature_c".into(),
                msg.air_temperature_c,
            )?,
            relative_humidity: within(
                &limits::RELATIVE_HUMIDITY,
                || "relative_humidity".into(),
                msg.relative_humidity,
            )?,
            precipitation_mm_h: within(
                &limits::PRECIPITATION_MM_H,
                || "precipitation_mm_h".into(),
                non_negative(|| "precipitation_mm_h".into(), msg.precipitation_mm_h)?,
            )?,
        })
    }
}
