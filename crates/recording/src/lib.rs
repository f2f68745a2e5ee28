//! tortwin's recording format, docs/spec/recording-format.md, stated
//! once:
//!
//! - [`topic`]: the five topics, their tie-break order and their JSON
//!   Schemas ([`schema`]);
//! - [`wire`]: each topic's JSON message as a struct (units as on the wire:
//!   g, kN, rail names), serialized by the writer and deserialized by the
//!   reader;
//! - [`event`]: the typed events the engine takes: SI units, rails,
//!   applicators, sites and trains as indices;
//! - [`reader`]: MCAP in, events out in replay order, streaming;
//!   `decode` (private) turns a message's bytes into its wire struct and
//!   then into an event, checking every rule of the format;
//! - [`writer`]: the channels and wire messages of a recording, for
//!   `tortwin synth`, importers and tests;
//! - [`recording`]: a recording read whole into memory, for the studies
//!   that replay it many times;
//! - [`tables`]: a recording as the CSV files (and a section TOML) a
//!   wayside installation exports: imported with errors at file, line and
//!   column, and exported with the recording's own numbers;
//! - [`error`]: [`InputError`](error::InputError) names the file and, for
//!   a message, its topic, log_time and index in the file.
//!
//! Nothing after the reader handles raw JSON or re-checks a field: an
//! [`Event`] that exists is valid.

pub mod cut;
mod decode;
pub mod error;
pub mod event;
pub mod limits;
pub mod line;
pub mod reader;
pub mod recording;
pub mod schema;
pub mod tables;
pub mod topic;
pub mod wire;
pub mod writer;

pub use decode::{MAX_AXLES, MAX_GRID_POINTS};
pub use event::*;
pub use reader::{ReaderContext, RecordingReader, Wire};
pub use recording::Recording;
pub use topic::Topic;
pub use writer::RecordingWriter;
