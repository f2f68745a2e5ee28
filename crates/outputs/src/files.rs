//! Output files that never look complete before they are.
//!
//! Every file tortwin writes (MCAP and rerun outputs, synthetic recordings,
//! states, reports) goes to a temporary name beside its final path,
//! `.NAME.partial-<pid>`, and is renamed into place only when complete. If
//! the run fails first, dropping the [`PartialFile`] deletes the temporary
//! file, so a failed run leaves nothing a user could mistake for a result.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};

/// A file being written under a temporary name beside its final path.
#[derive(Debug)]
pub struct PartialFile {
    temp_path: PathBuf,
    final_path: PathBuf,
    committed: bool,
}

impl PartialFile {
    /// Reserves `.NAME.partial-<pid>` in the directory of `final_path`
    /// (nothing is created yet: the writer creates `temp_path()`).
    pub fn beside(final_path: &Path) -> Result<Self> {
        let file_name = final_path
            .file_name()
            .ok_or_else(|| anyhow!("{}: not a file name", final_path.display()))?;
        let dir = match final_path.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir,
            _ => Path::new("."),
        };
        // An output folder that does not exist yet is made, as a user of
        // `--out-rrd out/demo.rrd` expects; one that cannot be made is an
        // error that names it.
        std::fs::create_dir_all(dir).map_err(|e| {
            tortwin_model::error::UsageError(format!(
                "cannot create the output folder {}: {e}",
                dir.display()
            ))
        })?;
        let mut temp_name = std::ffi::OsString::from(".");
        temp_name.push(file_name);
        temp_name.push(format!(".partial-{}", std::process::id()));
        Ok(Self {
            temp_path: dir.join(temp_name),
            final_path: final_path.to_path_buf(),
            committed: false,
        })
    }

    /// Where to write.
    pub fn temp_path(&self) -> &Path {
        &self.temp_path
    }

    /// Where the file goes when complete.
    pub fn final_path(&self) -> &Path {
        &self.final_path
    }

    /// The file is complete: renames it into place.
    pub fn commit(&mut self) -> Result<()> {
        std::fs::rename(&self.temp_path, &self.final_path).with_context(|| {
            format!(
                "cannot move {} to {}",
                self.temp_path.display(),
                self.final_path.display()
            )
        })?;
        self.committed = true;
        Ok(())
    }
}

impl Drop for PartialFile {
    fn drop(&mut self) {
        if !self.committed {
            // Nothing useful to do if this fails while unwinding from another error.
            let _ = std::fs::remove_file(&self.temp_path);
        }
    }
}

/// Writes `bytes` to `path` through a [`PartialFile`].
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut file = PartialFile::beside(path)?;
    std::fs::write(file.temp_path(), bytes)
        .with_context(|| format!("cannot write {}", file.temp_path().display()))?;
    file.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "dropped: nothing left"
        );
        write_atomically(&target, b"whole").unwrap();
        assert_eq!(std::fs::read(&target).unwrap(), b"whole");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
