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

/// Whether an I/O error is the machine's refusal that the user can fix: no
/// space or quota left, a file larger than the process may write, a
/// read-only file system, no permission, a folder missing or in the way.
/// The commands exit with status 2 for these, naming the path.
pub fn is_environment(e: &std::io::Error) -> bool {
    use std::io::ErrorKind::*;
    matches!(
        e.kind(),
        StorageFull
            | QuotaExceeded
            | FileTooLarge
            | ReadOnlyFilesystem
            | PermissionDenied
            | NotFound
            | NotADirectory
            | IsADirectory
            | AlreadyExists
            | DirectoryNotEmpty
            | InvalidFilename
    )
}

/// Whether `e` or any error under it is an I/O error of
/// [`is_environment`]'s kinds: how an output error that wraps the file
/// system's answer (a writer thread's, a Parquet or CSV writer's) is
/// classified.
pub fn caused_by_environment(e: &(dyn std::error::Error + 'static)) -> bool {
    let mut next = Some(e);
    while let Some(e) = next {
        if e.downcast_ref::<std::io::Error>()
            .is_some_and(is_environment)
        {
            return true;
        }
        next = e.source();
    }
    false
}
