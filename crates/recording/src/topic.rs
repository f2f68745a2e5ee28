//! The topics of docs/spec/recording-format.md: their names, their
//! order for ties in the replay, and what a writer declares for each.

use crate::schema;

/// The topics of the format, in their tie-break order (a replay orders
/// equal log_times by this, then by file order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Topic {
    Section,
    /// Optional (line.md): the section cut into segments.
    Line,
    Passage,
    Pulse,
    Measurement,
    Weather,
}

impl Topic {
    pub const ALL: [Topic; 6] = [
        Topic::Section,
        Topic::Line,
        Topic::Passage,
        Topic::Pulse,
        Topic::Measurement,
        Topic::Weather,
    ];

    /// The topic's name in a recording.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Section => "/section",
            Topic::Line => "/line",
            Topic::Passage => "/train/passage",
            Topic::Pulse => "/applicator/pulse",
            Topic::Measurement => "/measurement/friction",
            Topic::Weather => "/environment/weather",
        }
    }

    /// The topic of a channel name; `None` for a topic the format does not know.
    pub fn from_name(name: &str) -> Option<Topic> {
        Topic::ALL.into_iter().find(|t| t.name() == name)
    }

    /// The name of the topic's schema record.
    pub fn schema_name(self) -> &'static str {
        match self {
            Topic::Section => "tortwin.input.Section",
            Topic::Line => "tortwin.input.Line",
            Topic::Passage => "tortwin.input.TrainPassage",
            Topic::Pulse => "tortwin.input.ApplicatorPulse",
            Topic::Measurement => "tortwin.input.MeasurementFriction",
            Topic::Weather => "tortwin.input.EnvironmentWeather",
        }
    }

    /// The topic's JSON Schema (draft 2020-12).
    pub fn schema(self) -> &'static str {
        match self {
            Topic::Section => schema::SECTION_SCHEMA,
            Topic::Line => schema::LINE_SCHEMA,
            Topic::Passage => schema::PASSAGE_SCHEMA,
            Topic::Pulse => schema::PULSE_SCHEMA,
            Topic::Measurement => schema::MEASUREMENT_SCHEMA,
            Topic::Weather => schema::WEATHER_SCHEMA,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_schemas_are_json_schemas() {
        for topic in Topic::ALL {
            assert_eq!(Topic::from_name(topic.name()), Some(topic));
            let schema: serde_json::Value =
                serde_json::from_str(topic.schema()).expect("a schema is JSON");
            assert_eq!(
                schema["$schema"],
                "https://json-schema.org/draft/2020-12/schema"
            );
            assert_eq!(schema["type"], "object");
        }
        assert_eq!(Topic::from_name("/diagnostics/heartbeat"), None);
    }
}
