//! The errors of bad user input that every layer can meet: a configuration
//! that cannot be used ([`ConfigError`], naming the key) and a request that
//! asks for something impossible ([`UsageError`]). A recording that breaks
//! its format is `tortwin_recording::error::InputError`. The binary maps all
//! three to exit status 2 and anything else to 1
//! (docs/spec/interfaces.md).

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

/// A command line that asks for something impossible (exit status 2).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct UsageError(pub String);
