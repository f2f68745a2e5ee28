//! The JSON Schemas of the five input topics, stated once: the writer
//! declares them on their channels (`encoding = "jsonschema"`, as Foxglove
//! and the MCAP tools expect), so a recording describes itself to any
//! reader. They say what a JSON Schema can say of
//! docs/spec/recording-format.md; the rules across fields and messages
//! (rails named by the section, offsets never decreasing, one train at a
//! time) are the reader's (`decode`).
//!
//! The text is written into every recording byte for byte: changing it
//! changes the bytes `tortwin synth` writes for a seed.

pub const SECTION_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "section",
  "description": "The track section: geometry, rails, applicators and measurement sites. Exactly one, first in time.",
  "type": "object",
  "required": ["section_id", "length_m", "rails", "rail_head_radius_m",
               "nominal_wheel_diameter_m", "applicators", "measurement_sites"],
  "properties": {
    "section_id": {"type": "string"},
    "length_m": {"type": "number", "exclusiveMinimum": 0},
    "rails": {"type": "array", "minItems": 1, "uniqueItems": true, "items": {"type": "string"}},
    "curve_radius_m": {"type": "number", "exclusiveMinimum": 0, "description": "absent on tangent track"},
    "rail_head_radius_m": {"type": "number", "exclusiveMinimum": 0},
    "nominal_wheel_diameter_m": {"type": "number", "exclusiveMinimum": 0},
    "applicators": {
      "type": "array",
      "minItems": 1,
      "items": {
        "type": "object",
        "required": ["id", "position_m", "rails", "nominal_pulse_g"],
        "properties": {
          "id": {"type": "string"},
          "position_m": {"type": "number", "minimum": 0},
          "rails": {"type": "array", "minItems": 1, "uniqueItems": true, "items": {"type": "string"}},
          "nominal_pulse_g": {"type": "number", "minimum": 0}
        }
      }
    },
    "measurement_sites": {
      "type": "array",
      "items": {
        "type": "object",
        "required": ["id", "position_m"],
        "properties": {
          "id": {"type": "string"},
          "position_m": {"type": "number", "minimum": 0}
        }
      }
    }
  }
}"##;

pub const PASSAGE_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "train_passage",
  "description": "One train passing the section; log_time is when its front crosses the entry end (d = 0 up, d = length_m down).",
  "type": "object",
  "required": ["train_id", "direction", "speed_mps", "axles"],
  "properties": {
    "train_id": {"type": "string"},
    "direction": {"type": "string", "enum": ["up", "down"]},
    "speed_mps": {"type": "number", "exclusiveMinimum": 0},
    "consist": {"type": "string", "enum": ["freight", "passenger"], "description": "informative; not part of the format"},
    "axles": {
      "type": "array",
      "minItems": 1,
      "items": {
        "type": "object",
        "required": ["offset_m", "bogie_position", "wheel_diameter_m", "wheel_load_kN", "creepage"],
        "properties": {
          "offset_m": {"type": "number", "minimum": 0, "description": "distance behind the train front, m"},
          "bogie_position": {"type": "string", "enum": ["leading", "trailing"]},
          "wheel_diameter_m": {"type": "number", "exclusiveMinimum": 0},
          "wheel_load_kN": {
            "type": "object",
            "description": "vertical wheel force Q per rail name, kN",
            "properties": {},
            "additionalProperties": {"type": "number", "exclusiveMinimum": 0}
          },
          "creepage": {
            "type": "object",
            "description": "creepage estimate per rail name",
            "properties": {},
            "additionalProperties": {
              "type": "object",
              "required": ["cx", "cy", "spin_per_m"],
              "properties": {
                "cx": {"type": "number"},
                "cy": {"type": "number"},
                "spin_per_m": {"type": "number"}
              }
            }
          }
        }
      }
    }
  }
}"##;

pub const PULSE_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "applicator_pulse",
  "description": "One pump stroke; the mass lands on the rail at the applicator's grid point at log_time.",
  "type": "object",
  "required": ["applicator_id", "rail", "mass_g"],
  "properties": {
    "applicator_id": {"type": "string"},
    "rail": {"type": "string"},
    "mass_g": {"type": "number", "minimum": 0}
  }
}"##;

pub const MEASUREMENT_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "measurement_friction",
  "description": "Measured friction: mu or adhesion of one axle's contact at a site, or rail_mu from a hand tribometer.",
  "type": "object",
  "required": ["site_id", "rail", "quantity", "value"],
  "properties": {
    "site_id": {"type": "string"},
    "rail": {"type": "string"},
    "quantity": {"type": "string", "enum": ["mu", "adhesion", "rail_mu"]},
    "train_id": {"type": "string"},
    "axle_index": {"type": "integer", "minimum": 0},
    "value": {"type": "number"}
  },
  "if": {"properties": {"quantity": {"const": "rail_mu"}}},
  "then": {"not": {"anyOf": [{"required": ["train_id"]}, {"required": ["axle_index"]}]}},
  "else": {"required": ["train_id", "axle_index"]}
}"##;

pub const WEATHER_SCHEMA: &str = r##"{
  "$schema": "https://json-schema.org/draft/2020-12/schema",
  "title": "environment_weather",
  "description": "Weather, piecewise constant until the next message.",
  "type": "object",
  "required": ["air_temperature_c", "relative_humidity", "precipitation_mm_h"],
  "properties": {
    "air_temperature_c": {"type": "number"},
    "relative_humidity": {"type": "number", "minimum": 0, "maximum": 1},
    "precipitation_mm_h": {"type": "number", "minimum": 0}
  }
}"##;
