//! What the engine's results are written to: the MCAP output for Foxglove
//! ([`mcap_out`]), the rerun recording ([`rerun_out`]), Parquet and CSV
//! tables ([`tables`]), all [`tortwin_engine::sink::Sink`]s, and files that
//! appear only when complete ([`files`]).

pub use tortwin_files as files;
pub mod alerts;
pub mod foxglove;
pub mod geometry;
pub mod mcap_out;
pub mod provenance;
pub mod rerun_out;
pub mod rerun_sdk;
pub mod scale;
pub mod tables;
