//! The format's JSON messages as they are on the wire: field names and units
//! of docs/spec/recording-format.md (g, kN, rail names), one struct per
//! topic. The writer serializes them and the reader deserializes them, so
//! the format is stated once.
//!
//! Deserializing is the format's grammar: a message that deserializes has
//! every field with the right JSON type (an integer is a valid float, `true`
//! is not a number, `axle_index` is a non-negative integer, a struct is a
//! JSON object and a list a JSON array). serde_json refuses NaN and infinite
//! numbers, and unknown extra fields are ignored. What needs more than one
//! field, or the section, is checked when the reader turns a wire message
//! into a typed event (`decode`).
//!
//! The helpers in `json` word serde's messages in JSON's terms (a JSON
//! number, not `f64`), and refuse what serde's derive would otherwise take:
//! a struct written as a JSON array of its fields in order.

use serde::{Deserialize, Serialize};
use tortwin_model::Quantity;

use crate::event::{BogiePosition, Direction};
use crate::topic::Topic;

/// A wire message and its topic: what the writer needs to put it on the
/// right channel.
pub trait WireMessage: Serialize {
    const TOPIC: Topic;
}

/// `/section`: the track section. Exactly one, first in time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct SectionMsg {
    pub section_id: String,
    #[serde(deserialize_with = "json::number")]
    pub length_m: f64,
    #[serde(deserialize_with = "json::array")]
    pub rails: Vec<String>,
    /// Absent (or `null`) on tangent track; written only when present.
    #[serde(
        default,
        deserialize_with = "json::nullable_number",
        skip_serializing_if = "Option::is_none"
    )]
    pub curve_radius_m: Option<f64>,
    #[serde(deserialize_with = "json::number")]
    pub rail_head_radius_m: f64,
    #[serde(deserialize_with = "json::number")]
    pub nominal_wheel_diameter_m: f64,
    #[serde(deserialize_with = "json::array")]
    pub applicators: Vec<ApplicatorMsg>,
    #[serde(deserialize_with = "json::array")]
    pub measurement_sites: Vec<SiteMsg>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct ApplicatorMsg {
    pub id: String,
    #[serde(deserialize_with = "json::number")]
    pub position_m: f64,
    /// Rail names of the section.
    #[serde(deserialize_with = "json::array")]
    pub rails: Vec<String>,
    #[serde(deserialize_with = "json::number")]
    pub nominal_pulse_g: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct SiteMsg {
    pub id: String,
    #[serde(deserialize_with = "json::number")]
    pub position_m: f64,
}

/// `/line`: the section cut into consecutive segments (line.md). At most
/// one, at the `/section`'s log_time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct LineMsg {
    pub line_id: String,
    #[serde(deserialize_with = "json::array")]
    pub segments: Vec<SegmentMsg>,
}

/// A segment as written. The keys that only some types use stay JSON
/// values, read only where the segment's type uses them: line.md ignores
/// them unchecked elsewhere (a tangent's `high_rail`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct SegmentMsg {
    pub id: String,
    /// `tangent`, `transition` or `curve`.
    #[serde(rename = "type")]
    pub kind: String,
    #[serde(deserialize_with = "json::number")]
    pub end_m: f64,
    /// A rail name (curve, transition).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub high_rail: Option<serde_json::Value>,
    /// `start` or `end` (transition).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub curve_at: Option<serde_json::Value>,
    /// A positive number (curve; descriptive).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<serde_json::Value>,
}

/// `/train/passage`: one train; log_time is when its front enters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct PassageMsg {
    pub train_id: String,
    #[serde(with = "DirectionName")]
    pub direction: Direction,
    #[serde(deserialize_with = "json::number")]
    pub speed_mps: f64,
    /// `freight` or `passenger`: written by `tortwin synth` for people and
    /// declared by the schema, but not part of the format, so never read
    /// (a recording may carry anything under that name).
    #[serde(default, skip_deserializing, skip_serializing_if = "Option::is_none")]
    pub consist: Option<String>,
    #[serde(deserialize_with = "json::array")]
    pub axles: Vec<AxleMsg>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct AxleMsg {
    /// Distance behind the train front.
    #[serde(deserialize_with = "json::number")]
    pub offset_m: f64,
    #[serde(with = "BogiePositionName")]
    pub bogie_position: BogiePosition,
    #[serde(deserialize_with = "json::number")]
    pub wheel_diameter_m: f64,
    /// Vertical wheel force Q per rail name, kN.
    #[serde(rename = "wheel_load_kN")]
    pub wheel_load_kn: PerRail<f64>,
    pub creepage: PerRail<CreepageMsg>,
    /// On a line (line.md): the segments where the axle's load or creepage
    /// differs from its own, by segment id. Kept as JSON: without `/line`
    /// it is an unknown extra field, ignored unchecked; with one the reader
    /// reads it as [`AxleSegmentMsg`]s.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segments: Option<RawJson>,
}

/// JSON kept as written and read when needed (an axle's `segments`: not
/// built into a tree for a reader that ignores it, parsed once into its
/// typed form by one that reads it).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(transparent)]
pub struct RawJson(pub Box<serde_json::value::RawValue>);

impl PartialEq for RawJson {
    fn eq(&self, other: &Self) -> bool {
        self.0.get() == other.0.get()
    }
}

/// An axle's load or creepage (or both) in one segment of a line, each
/// complete per rail like the axle's own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct AxleSegmentMsg {
    #[serde(
        rename = "wheel_load_kN",
        default,
        skip_serializing_if = "Option::is_none"
    )]
    pub wheel_load_kn: Option<PerRail<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub creepage: Option<PerRail<CreepageMsg>>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct CreepageMsg {
    #[serde(deserialize_with = "json::number")]
    pub cx: f64,
    #[serde(deserialize_with = "json::number")]
    pub cy: f64,
    #[serde(deserialize_with = "json::number")]
    pub spin_per_m: f64,
}

/// `/applicator/pulse`: one pump stroke.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct PulseMsg {
    pub applicator_id: String,
    pub rail: String,
    #[serde(deserialize_with = "json::number")]
    pub mass_g: f64,
}

/// `/measurement/friction`: `train_id` and `axle_index` are there for `mu`
/// and `adhesion` and absent for `rail_mu` (`null` counts as absent).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct MeasurementMsg {
    pub site_id: String,
    pub rail: String,
    pub quantity: Quantity,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train_id: Option<String>,
    #[serde(
        default,
        deserialize_with = "json::optional_index",
        skip_serializing_if = "Option::is_none"
    )]
    pub axle_index: Option<usize>,
    #[serde(deserialize_with = "json::number")]
    pub value: f64,
}

/// `/environment/weather`: in effect until the next one.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(expecting = "a JSON object")]
pub struct WeatherMsg {
    #[serde(deserialize_with = "json::number")]
    pub air_temperature_c: f64,
    #[serde(deserialize_with = "json::number")]
    pub relative_humidity: f64,
    #[serde(deserialize_with = "json::number")]
    pub precipitation_mm_h: f64,
}

impl WireMessage for SectionMsg {
    const TOPIC: Topic = Topic::Section;
}
impl WireMessage for LineMsg {
    const TOPIC: Topic = Topic::Line;
}
impl WireMessage for PassageMsg {
    const TOPIC: Topic = Topic::Passage;
}
impl WireMessage for PulseMsg {
    const TOPIC: Topic = Topic::Pulse;
}
impl WireMessage for MeasurementMsg {
    const TOPIC: Topic = Topic::Measurement;
}
impl WireMessage for WeatherMsg {
    const TOPIC: Topic = Topic::Weather;
}

/// A JSON object with one value per rail name, e.g. `{"high": 112.0, "low":
/// 98.0}`, kept in the order written (the writer writes the section's rail
/// order). Whether it names exactly the section's rails is the reader's
/// check; a rail named twice is kept twice so that the check can say so.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PerRail<T>(pub Vec<(String, T)>);

impl<T: Serialize> Serialize for PerRail<T> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (rail, value) in &self.0 {
            map.serialize_entry(rail, value)?;
        }
        map.end()
    }
}

impl<'de, T: json::FromJson<'de>> Deserialize<'de> for PerRail<T> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Entries<T>(std::marker::PhantomData<T>);
        impl<'de, T: json::FromJson<'de>> serde::de::Visitor<'de> for Entries<T> {
            type Value = PerRail<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a JSON object with a value per rail")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<PerRail<T>, A::Error> {
                let mut entries = Vec::with_capacity(map.size_hint().unwrap_or(2).min(16));
                while let Some(rail) = map.next_key::<String>()? {
                    let value = map.next_value_seed(json::Seed::<T>::default())?;
                    entries.push((rail, value));
                }
                Ok(PerRail(entries))
            }
        }
        deserializer.deserialize_map(Entries(std::marker::PhantomData))
    }
}

/// The wire names of [`Direction`].
#[derive(Serialize, Deserialize)]
#[serde(remote = "Direction", rename_all = "lowercase")]
enum DirectionName {
    Up,
    Down,
}

/// The wire names of [`BogiePosition`].
#[derive(Serialize, Deserialize)]
#[serde(remote = "BogiePosition", rename_all = "lowercase")]
enum BogiePositionName {
    Leading,
    Trailing,
}

/// Deserializing in JSON's terms (see the module documentation).
pub(crate) mod json {
    use std::fmt;
    use std::marker::PhantomData;

    use serde::de::{self, DeserializeSeed, Deserializer, SeqAccess, Visitor};
    use serde::Deserialize;

    /// A value as the format has it in JSON: a struct from an object only, a
    /// number from any JSON number.
    pub trait FromJson<'de>: Sized {
        fn from_json<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error>;
    }

    impl<'de> FromJson<'de> for f64 {
        fn from_json<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
            number(deserializer)
        }
    }

    impl<'de> FromJson<'de> for String {
        fn from_json<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
            String::deserialize(deserializer)
        }
    }

    macro_rules! from_json_object {
        ($($t:ty),*) => {$(
            impl<'de> FromJson<'de> for $t {
                fn from_json<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                    <$t>::deserialize(ObjectOnly(deserializer))
                }
            }
        )*};
    }
    from_json_object!(
        super::SectionMsg,
        super::LineMsg,
        super::SegmentMsg,
        super::ApplicatorMsg,
        super::SiteMsg,
        super::PassageMsg,
        super::AxleMsg,
        super::AxleSegmentMsg,
        super::CreepageMsg,
        super::PulseMsg,
        super::MeasurementMsg,
        super::WeatherMsg
    );

    /// [`FromJson`] where serde wants a seed (array elements, map values).
    pub(crate) struct Seed<T>(PhantomData<T>);

    impl<T> Default for Seed<T> {
        fn default() -> Self {
            Seed(PhantomData)
        }
    }

    impl<'de, T: FromJson<'de>> DeserializeSeed<'de> for Seed<T> {
        type Value = T;
        fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<T, D::Error> {
            T::from_json(deserializer)
        }
    }

    /// Hands a derived struct a JSON object only: serde_json would also
    /// give it a JSON array of its fields in order, which the format does
    /// not allow. The derived struct asks for nothing but a struct, which
    /// this turns into a map.
    struct ObjectOnly<D>(D);

    impl<'de, D: Deserializer<'de>> Deserializer<'de> for ObjectOnly<D> {
        type Error = D::Error;
        fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, D::Error> {
            self.0.deserialize_map(visitor)
        }
        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string
            bytes byte_buf option unit unit_struct newtype_struct seq tuple
            tuple_struct map struct enum identifier ignored_any
        }
    }

    /// A finite JSON number; an integer is a valid float (converted as
    /// serde_json converts it), `true` is not.
    pub(crate) fn number<'de, D: Deserializer<'de>>(deserializer: D) -> Result<f64, D::Error> {
        struct Number;
        impl<'de> Visitor<'de> for Number {
            type Value = f64;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a JSON number")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<f64, E> {
                Ok(v)
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<f64, E> {
                Ok(v as f64)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<f64, E> {
                Ok(v as f64)
            }
        }
        deserializer.deserialize_f64(Number)
    }

    /// A JSON number or `null`; the field must be there.
    pub(crate) fn nullable_number<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<f64>, D::Error> {
        struct Nullable;
        impl<'de> Visitor<'de> for Nullable {
            type Value = Option<f64>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a JSON number or null")
            }
            fn visit_none<E: de::Error>(self) -> Result<Option<f64>, E> {
                Ok(None)
            }
            fn visit_unit<E: de::Error>(self) -> Result<Option<f64>, E> {
                Ok(None)
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Option<f64>, D::Error> {
                number(d).map(Some)
            }
        }
        deserializer.deserialize_option(Nullable)
    }

    /// A non-negative JSON integer (`7`, not `7.0`), absent or `null` for
    /// `None`.
    pub(crate) fn optional_index<'de, D: Deserializer<'de>>(
        deserializer: D,
    ) -> Result<Option<usize>, D::Error> {
        struct Index;
        impl<'de> Visitor<'de> for Index {
            type Value = Option<usize>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a non-negative integer")
            }
            fn visit_none<E: de::Error>(self) -> Result<Option<usize>, E> {
                Ok(None)
            }
            fn visit_unit<E: de::Error>(self) -> Result<Option<usize>, E> {
                Ok(None)
            }
            fn visit_some<D: Deserializer<'de>>(self, d: D) -> Result<Option<usize>, D::Error> {
                d.deserialize_u64(self)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Option<usize>, E> {
                usize::try_from(v)
                    .map(Some)
                    .map_err(|_| E::invalid_value(de::Unexpected::Unsigned(v), &self))
            }
        }
        deserializer.deserialize_option(Index)
    }

    /// A JSON array of [`FromJson`] values.
    pub(crate) fn array<'de, D: Deserializer<'de>, T: FromJson<'de>>(
        deserializer: D,
    ) -> Result<Vec<T>, D::Error> {
        struct Array<T>(PhantomData<T>);
        impl<'de, T: FromJson<'de>> Visitor<'de> for Array<T> {
            type Value = Vec<T>;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("a JSON array")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<T>, A::Error> {
                // The hint is the elements already parsed; a bound keeps a
                // wrong one from allocating much.
                let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(1024));
                while let Some(item) = seq.next_element_seed(Seed::<T>::default())? {
                    items.push(item);
                }
                Ok(items)
            }
        }
        deserializer.deserialize_seq(Array(PhantomData))
    }
}
