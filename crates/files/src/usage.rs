//! The errors a user can fix, whatever layer meets them: a request that
//! asks for something impossible ([`UsageError`]) and the machine's refusal
//! to read or write a file ([`is_environment`], [`caused_by_environment`]).
//! The binary maps both to exit status 2 (docs/spec/interfaces.md). They
//! live here, at the bottom of the workspace, because every layer from the
//! engine up meets them and none of them is physics.

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
