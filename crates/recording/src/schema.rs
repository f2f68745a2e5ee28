//! The JSON Schemas of the input topics (five, and `/line` for a line), stated once: the writer
//! declares them on their channels (`encoding = "jsonschema"`, as Foxglove
//! and the MCAP tools expect), so a recording describes itself to any
//! reader. They say what a JSON Schema can say of
//! docs/spec/recording-format.md; the rules across fields and messages
//! (rails named by the section, offsets never decreasing, one train at a
//! time) are the reader's (`decode`).
//!
//! Each is a .json file in `crates/recording/schemas/` (see its README),
//! compiled in; the text is written into every recording byte for byte:
//! changing it changes the bytes `tortwin synth` writes for a seed.

pub const SECTION_SCHEMA: &str = include_str!("../schemas/section.json");

pub const LINE_SCHEMA: &str = include_str!("../schemas/line.json");

pub const PASSAGE_SCHEMA: &str = include_str!("../schemas/passage.json");

pub const PULSE_SCHEMA: &str = include_str!("../schemas/pulse.json");

pub const MEASUREMENT_SCHEMA: &str = include_str!("../schemas/measurement.json");

pub const WEATHER_SCHEMA: &str = include_str!("../schemas/weather.json");
