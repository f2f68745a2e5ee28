//! A model configuration that cannot be used ([`ConfigError`], naming the
//! key). The other errors of bad input live where they are met: a request
//! that asks for something impossible and the machine's refusals that the
//! user can fix in `tortwin_files::usage`, a recording that breaks its format
//! in `tortwin_recording::error::InputError`. The binary maps all three to
//! exit status 2 and anything else to 1 (docs/spec/interfaces.md).

/// A model configuration that cannot be used: names the key.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("configuration {source_name}: {key}: {message}")]
pub struct ConfigError {
    /// The file (or "built-in defaults") the bad value came from.
    pub source_name: String,
    /// The dotted key, e.g. `product.km1_kg` or `effects.rail_ageing.tau_s`.
    pub key: String,
    pub message: String,
}
