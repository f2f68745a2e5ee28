//! Output files that never look complete before they are.
//!
//! Every file tortwin writes (MCAP and rerun outputs, synthetic recordings,
//! states, reports, figures) is written to a temporary file beside its final
//! path, `.NAME.partial-XXXXXX`, and moved into place only when complete
//! (`tempfile`'s `persist`, a rename within the folder). Until then the
//! temporary file is owned by a `tempfile::TempPath`, which deletes it when
//! dropped: a failed run leaves nothing a user could mistake for a result.
//!
//! An output folder that does not exist yet is made, as a user of
//! `--out-rrd out/demo.rrd` expects; one that cannot be made is a
//! [`UsageError`] (exit status 2) under a [`FileError`] that names it.
//! So is an output the machine refuses to write: a full disk, a file-size
//! limit, a read-only folder (see [`is_environment`]).
//!
//! A run killed outright (SIGKILL, power loss) cannot delete its temporary
//! files. Every temporary file is locked (`flock`) by the run writing it,
//! and making a new one sweeps the folder of its own leftovers: a
//! `.NAME.partial-*` beside the same output that no run holds locked and
//! that has not changed for [`STALE_AFTER`]. So they do not pile up over
//! runs, and two runs writing one output path each write their own
//! temporary file and rename it into place whole: the last to finish wins,
//! never a mix.

use std::ffi::OsString;
use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use tempfile::{NamedTempFile, TempPath};
use tortwin_model::error::UsageError;

/// Why an output file could not be written; every variant names the path.
#[derive(Debug, thiserror::Error)]
pub enum FileError {
    #[error("{}: not a file name", path.display())]
    NotAFileName { path: PathBuf },
    /// The source is a [`UsageError`]: the user asked for a folder that
    /// cannot be.
    #[error("cannot create the output folder {}", folder.display())]
    Folder {
        folder: PathBuf,
        #[source]
        source: UsageError,
    },
    /// The folder exists but no file can be made in it (not writable, full).
    #[error("cannot create a file in the output folder {}", folder.display())]
    Temporary {
        folder: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot write {}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("cannot move {} to {}", temp.display(), path.display())]
    Persist {
        temp: PathBuf,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// [`PartialFile::commit`] called twice.
    #[error("{} is already in place", path.display())]
    AlreadyCommitted { path: PathBuf },
}

impl FileError {
    /// Whether the user has to fix it (exit status 2): an output folder that
    /// cannot be made, or a file the machine refuses to write (full disk,
    /// read-only folder: [`is_environment`]).
    pub fn is_input(&self) -> bool {
        match self {
            FileError::Folder { .. } => true,
            FileError::Temporary { source, .. }
            | FileError::Write { source, .. }
            | FileError::Persist { source, .. } => is_environment(source),
            FileError::NotAFileName { .. } | FileError::AlreadyCommitted { .. } => false,
        }
    }
}

pub use tortwin_model::error::{caused_by_environment, is_environment};

/// A leftover temporary file that nobody holds locked and that has not
/// changed for this long is deleted by the next run writing beside it.
pub const STALE_AFTER: Duration = Duration::from_secs(60);

/// A file being written under a temporary name beside its final path, for
/// writers that open a path themselves (the MCAP and rerun writers).
#[derive(Debug)]
pub struct PartialFile {
    /// `None` once moved into place.
    temp: Option<TempPath>,
    /// Holds the temporary file's lock while it is written (module
    /// documentation).
    _lock: File,
    final_path: PathBuf,
}

impl PartialFile {
    /// Creates an empty `.NAME.partial-XXXXXX` in the folder of
    /// `final_path` (made if missing); the writer opens it by
    /// [`PartialFile::temp_path`] and truncates it.
    pub fn beside(final_path: &Path) -> Result<Self, FileError> {
        let (lock, temp) = temporary_beside(final_path)?.into_parts();
        Ok(Self {
            temp: Some(temp),
            _lock: lock,
            final_path: final_path.to_path_buf(),
        })
    }

    /// After a writer that reports no cause failed (rerun's file writer
    /// thread only says it stopped): what writing to the temporary file
    /// says now, e.g. "No space left on device".
    pub fn probe_write(&self) -> std::io::Result<()> {
        let mut file = File::options().append(true).open(self.temp_path())?;
        file.write_all(&[0u8; 4096])?;
        file.sync_data()
    }

    /// Where to write: the temporary file, or the final path once committed.
    pub fn temp_path(&self) -> &Path {
        self.temp.as_deref().unwrap_or(&self.final_path)
    }

    /// Where the file goes when complete.
    pub(crate) fn final_path(&self) -> &Path {
        &self.final_path
    }

    /// The file is complete: moves it into place (replacing a file there).
    pub fn commit(&mut self) -> Result<(), FileError> {
        let temp = self
            .temp
            .take()
            .ok_or_else(|| FileError::AlreadyCommitted {
                path: self.final_path.clone(),
            })?;
        let temp_path = temp.to_path_buf();
        // On failure the error owns the temporary file and deletes it.
        temp.persist(&self.final_path)
            .map_err(|err| FileError::Persist {
                temp: temp_path,
                path: self.final_path.clone(),
                source: err.error,
            })
    }
}

/// Writes `bytes` to `path`, whole or not at all.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let mut temp = temporary_beside(path)?;
    temp.write_all(bytes).map_err(|source| FileError::Write {
        path: path.to_path_buf(),
        source,
    })?;
    let temp_path = temp.path().to_path_buf();
    temp.persist(path).map_err(|err| FileError::Persist {
        temp: temp_path,
        path: path.to_path_buf(),
        source: err.error,
    })?;
    Ok(())
}

/// Makes `folder` (and its parents) if missing, as an output folder: one
/// that cannot be made is the user's to fix ([`FileError::Folder`]).
pub fn make_folder(folder: &Path) -> Result<(), FileError> {
    std::fs::create_dir_all(folder).map_err(|err| FileError::Folder {
        folder: folder.to_path_buf(),
        source: UsageError(err.to_string()),
    })
}

/// An empty `.NAME.partial-XXXXXX` in the folder of `final_path`, which is
/// made if missing.
fn temporary_beside(final_path: &Path) -> Result<NamedTempFile, FileError> {
    let file_name = final_path
        .file_name()
        .ok_or_else(|| FileError::NotAFileName {
            path: final_path.to_path_buf(),
        })?;
    let folder = match final_path.parent() {
        Some(folder) if !folder.as_os_str().is_empty() => folder,
        _ => Path::new("."),
    };
    make_folder(folder)?;
    let mut prefix = OsString::from(".");
    prefix.push(file_name);
    prefix.push(".partial-");
    sweep_leftovers(folder, &prefix);
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix);
    // tempfile makes 0600 files; an output is made like any new file
    // (0666 less the umask), as it was before it went through a temporary.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let temp = builder
        .tempfile_in(folder)
        .map_err(|source| FileError::Temporary {
            folder: folder.to_path_buf(),
            source,
        })?;
    // Locked at once; the sweep leaves files younger than STALE_AFTER
    // alone, so a file cannot be swept between its creation and its lock.
    // A file system without locks (some network mounts) only loses the
    // sweep's protection of a live run's file, after STALE_AFTER without a
    // write.
    let _ = temp.as_file().try_lock();
    Ok(temp)
}

/// Deletes `folder/PREFIX*` files that no run holds locked and that have
/// not changed for [`STALE_AFTER`]: what a killed run left. Best effort: a
/// file that cannot be checked or deleted is left.
fn sweep_leftovers(folder: &Path, prefix: &OsString) {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return;
    };
    let prefix = prefix.as_encoded_bytes();
    let now = SystemTime::now();
    for entry in entries.flatten() {
        if !entry.file_name().as_encoded_bytes().starts_with(prefix) {
            continue;
        }
        let path = entry.path();
        let stale = std::fs::symlink_metadata(&path).is_ok_and(|m| {
            m.is_file()
                && m.modified()
                    .ok()
                    .and_then(|t| now.duration_since(t).ok())
                    .is_some_and(|age| age >= STALE_AFTER)
        });
        if !stale {
            continue;
        }
        let Ok(file) = File::options().read(true).open(&path) else {
            continue;
        };
        if file.try_lock().is_ok() {
            let _ = std::fs::remove_file(&path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names_in(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn commits_or_leaves_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.json");
        {
            let file = PartialFile::beside(&target).unwrap();
            std::fs::write(file.temp_path(), b"half").unwrap();
            assert!(file
                .temp_path()
                .file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with(".out.json.partial-"));
        }
        assert!(names_in(dir.path()).is_empty(), "dropped: nothing left");

        let mut file = PartialFile::beside(&target).unwrap();
        std::fs::write(file.temp_path(), b"whole").unwrap();
        file.commit().unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"whole");
        assert_eq!(file.temp_path(), target);
        assert!(matches!(
            file.commit(),
            Err(FileError::AlreadyCommitted { .. })
        ));
        drop(file);
        assert_eq!(names_in(dir.path()), ["out.json"]);

        write_atomically(&target, b"again").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"again");
        assert_eq!(names_in(dir.path()), ["out.json"]);
    }

    #[test]
    fn makes_missing_folders_and_names_the_one_it_cannot() {
        let dir = tempfile::tempdir().unwrap();
        let nested = dir.path().join("a/b/fig.svg");
        write_atomically(&nested, b"<svg/>").unwrap();
        assert_eq!(std::fs::read(&nested).unwrap(), b"<svg/>");

        // A folder where a file is: it cannot be made.
        let blocked = dir.path().join("fig.svg");
        std::fs::write(&blocked, b"").unwrap();
        let err = write_atomically(&blocked.join("x/out.csv"), b"").unwrap_err();
        assert!(matches!(err, FileError::Folder { .. }), "{err:?}");
        assert!(err.to_string().contains("fig.svg/x"), "{err}");
        assert!(std::error::Error::source(&err)
            .and_then(|s| s.downcast_ref::<UsageError>())
            .is_some());
    }

    #[cfg(unix)]
    #[test]
    fn outputs_get_the_mode_of_a_new_file_and_unwritable_folders_are_named() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let target = dir.path().join("out.mcap");
        write_atomically(&target, b"x").unwrap();
        let plain = dir.path().join("plain");
        std::fs::write(&plain, b"x").unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&target), mode(&plain));

        let locked = dir.path().join("locked");
        std::fs::create_dir(&locked).unwrap();
        std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o555)).unwrap();
        // Root writes anywhere: the check means nothing then.
        if std::fs::write(locked.join("probe"), b"").is_err() {
            let err = write_atomically(&locked.join("out.mcap"), b"x").unwrap_err();
            assert!(matches!(err, FileError::Temporary { .. }), "{err:?}");
            assert!(err.to_string().contains("locked"), "{err}");
        }
    }
}
