//! The rerun SDK, from the crates it is made of: what the `rerun` crate's
//! `sdk` feature exports, without the `rerun` crate itself. That crate
//! always brings rerun's own command line, its viewer-side stores and its
//! server clients (51 crates more than `re_sdk`: `re_entity_db`,
//! `re_redap_client`, `sysinfo`, `ureq`, ...), which tortwin never calls and
//! every build and lint compiled.

pub use re_sdk::log::TimeColumn;
pub use re_sdk::*;
pub use re_sdk_types::archetypes::*;
pub use re_sdk_types::{self, archetypes, components, datatypes, AnyValues};
