//! Seeded mutation fuzzing of everything tortwin reads, on stable Rust.
//!
//! A campaign ([`campaign`]) takes seed inputs ([`seeds`]), mutates them
//! ([`mutate`]: bytes for MCAP files, tokens and lines for JSON, TOML and
//! CSV text) and runs each mutant through a [`targets::Target`]: the same
//! library calls the `tortwin` commands make, from reading the input to the
//! end of the replay it feeds. A target must return `Ok` or a clear input
//! error; a panic, an error that is not the input's (exit status 1 instead
//! of 2), an allocation over [`meter::FINDING_BYTES`], an execution over
//! the time limit, or a process that dies is a finding, saved as a file
//! that `tests/regressions.rs` replays from then on.
//!
//! Everything is seeded: the same `--seed` gives the same mutants.

pub mod campaign;
pub mod meter;
pub mod mutate;
pub mod seeds;
pub mod targets;
pub mod values;
