//! Files tortwin reads and writes: inputs only from regular files, outputs
//! that never look complete before they are and never destroy what they
//! should not (docs/spec/interfaces.md, "Files").
//!
//! **Outputs.** Every file tortwin writes (MCAP and rerun outputs, tables,
//! synthetic recordings, states, reports, figures) is written to a temporary
//! file beside its final path, `.NAME.partial-XXXXXX`, and moved into place
//! only when complete (`tempfile`'s `persist`, a rename within the folder).
//! Until then the temporary file is owned by a `tempfile::TempPath`, which
//! deletes it when dropped: a failed run leaves nothing a user could
//! mistake for a result. A report folder (discover, calibrate, strategy) is
//! written whole into a temporary folder beside it and its files moved into
//! place together at the end ([`StagedFolder`]): a run that fails leaves
//! none of them under their final names.
//!
//! Before anything is written, the final path is checked: one that holds
//! one of the run's inputs (the same file: device and inode, whatever the
//! path that names it) is refused ([`FileError::IsAnInput`]), as is one
//! that holds anything but a regular file: a named pipe, a device, a socket
//! or a folder is never replaced ([`FileError::NotARegularFile`]). A
//! symbolic link is followed: the file it points to is replaced, the link
//! stays; a link to nothing is refused. All are exit status 2.
//!
//! An output folder that does not exist yet is made, as a user of
//! `--out-rrd out/demo.rrd` expects; one that cannot be made is a
//! [`UsageError`] (exit status 2) under a [`FileError`] that names it.
//! So is an output the machine refuses to write: a full disk, a file-size
//! limit, a read-only folder (see [`is_environment`]).
//!
//! **Interrupted runs.** SIGINT and SIGTERM delete the run's temporary files
//! and folders before the process exits with 130 or 143
//! ([`clean_up_on_signals`], installed by the command line). A run killed
//! outright (SIGKILL, power loss) cannot: every temporary file is locked
//! (`flock`) by the run writing it, and making a new one sweeps the folder
//! of its own leftovers: a `.NAME.partial-*` beside the same output that no
//! run holds locked and that has not changed for [`STALE_AFTER`]. So they
//! do not pile up over runs, and two runs writing one output path each
//! write their own temporary file and rename it into place whole: the last
//! to finish wins, never a mix.
//!
//! **Inputs.** [`open_input`] and [`check_input`] accept only regular files
//! (a named pipe would block the run forever, a device never ends) and
//! remember them as the run's inputs, which no output may replace.

use std::ffi::OsString;
use std::fs::File;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, SystemTime};

use tempfile::{NamedTempFile, TempDir, TempPath};
use usage::UsageError;
pub mod usage;
mod writeback;
pub use usage::{caused_by_environment, is_environment};
pub use writeback::Writeback;

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
    /// The output would replace one of the run's inputs. The source is a
    /// [`UsageError`] saying so (so layers that know only that type, the
    /// engine's sink errors, classify it as the user's).
    #[error("{}", path.display())]
    IsAnInput {
        path: PathBuf,
        input: PathBuf,
        #[source]
        reason: UsageError,
    },
    /// The output path holds something an output must not replace.
    #[error("{}", path.display())]
    NotARegularFile {
        path: PathBuf,
        what: &'static str,
        #[source]
        reason: UsageError,
    },
    /// A symbolic link whose target does not exist.
    #[error("{}", path.display())]
    DanglingLink {
        path: PathBuf,
        #[source]
        reason: UsageError,
    },
}

impl FileError {
    fn is_an_input(path: &Path, input: PathBuf) -> Self {
        let reason = UsageError(format!(
            "this output is the input {}; choose another name (nothing was written)",
            input.display()
        ));
        FileError::IsAnInput {
            path: path.to_path_buf(),
            input,
            reason,
        }
    }

    fn not_a_regular_file(path: &Path, what: &'static str) -> Self {
        FileError::NotARegularFile {
            path: path.to_path_buf(),
            what,
            reason: UsageError(format!(
                "is {what}, not a regular file; an output never replaces one"
            )),
        }
    }

    fn dangling_link(path: &Path) -> Self {
        FileError::DanglingLink {
            path: path.to_path_buf(),
            reason: UsageError(
                "a symbolic link to nothing; an output follows a link only to an existing file"
                    .into(),
            ),
        }
    }
}

impl FileError {
    /// Whether the user has to fix it (exit status 2): an output folder that
    /// cannot be made, an output path that holds an input or something
    /// other than a file, or a file the machine refuses to write (full disk,
    /// read-only folder: [`is_environment`]).
    pub fn is_input(&self) -> bool {
        match self {
            FileError::Folder { .. }
            | FileError::IsAnInput { .. }
            | FileError::NotARegularFile { .. }
            | FileError::DanglingLink { .. } => true,
            FileError::Temporary { source, .. }
            | FileError::Write { source, .. }
            | FileError::Persist { source, .. } => is_environment(source),
            FileError::NotAFileName { .. } | FileError::AlreadyCommitted { .. } => false,
        }
    }
}

/// A leftover temporary file that nobody holds locked and that has not
/// changed for this long is deleted by the next run writing beside it.
pub const STALE_AFTER: Duration = Duration::from_secs(60);

/// The longest file name kept whole in a temporary name: with the 16 bytes
/// of `.` and `.partial-XXXXXX` around it, a name at the file system's
/// limit (255 bytes) would not fit, so a longer one is shortened (at a
/// character boundary) and marked with `~`.
const NAME_KEPT: usize = 200;

// ---------------------------------------------------------------- inputs

/// The inputs of the jobs running: device, inode, the path they were read
/// by and the [`InputScope`] that read them (0: the process's).
static INPUTS: Mutex<Vec<(u64, u64, PathBuf, u64)>> = Mutex::new(Vec::new());

fn inputs() -> MutexGuard<'static, Vec<(u64, u64, PathBuf, u64)>> {
    INPUTS.lock().unwrap_or_else(|e| e.into_inner())
}

thread_local! {
    /// The scope inputs read on this thread belong to.
    static SCOPE: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}
static NEXT_SCOPE: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// One job's inputs: those read on this thread while it lives are its, and
/// stop being protected when it ends. A process that runs one job after
/// another (the Python package, a fleet, the tests) may write a file that
/// an earlier job read; while a job runs, no output replaces what it (or
/// any job running beside it) reads.
/// A scope entered inside another is the outer one: a job that calls
/// another (export runs a replay; the replay writes its state after the
/// stepping) keeps its inputs to its end.
#[derive(Debug)]
pub struct InputScope {
    /// The scope this guard ends, if it began it.
    owned: Option<u64>,
}

impl InputScope {
    /// Enters a new scope on this thread (until dropped), unless one is
    /// already open here.
    #[must_use]
    pub fn enter() -> Self {
        if SCOPE.with(std::cell::Cell::get) != 0 {
            return Self { owned: None };
        }
        let id = NEXT_SCOPE.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        SCOPE.with(|s| s.set(id));
        Self { owned: Some(id) }
    }
}

impl Drop for InputScope {
    fn drop(&mut self) {
        if let Some(id) = self.owned {
            SCOPE.with(|s| s.set(0));
            inputs().retain(|e| e.3 != id);
        }
    }
}

/// What a file system entry is, for a message.
fn kind_of(file_type: std::fs::FileType) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        if file_type.is_fifo() {
            return "a named pipe";
        }
        if file_type.is_char_device() || file_type.is_block_device() {
            return "a device";
        }
        if file_type.is_socket() {
            return "a socket";
        }
    }
    if file_type.is_dir() {
        "a folder"
    } else if file_type.is_symlink() {
        "a symbolic link"
    } else {
        "not a regular file"
    }
}

#[cfg(unix)]
fn identity(m: &std::fs::Metadata) -> (u64, u64) {
    use std::os::unix::fs::MetadataExt;
    (m.dev(), m.ino())
}

#[cfg(not(unix))]
fn identity(_: &std::fs::Metadata) -> (u64, u64) {
    (0, 0)
}

/// The input `path` is checked: it must be a regular file (following
/// links). Refused otherwise with an error that says what it is; a named
/// pipe is refused before it is opened, where opening it would block.
/// Recorded as one of the run's inputs.
pub fn check_input(path: &Path) -> std::io::Result<()> {
    remember_input(path, &std::fs::metadata(path)?)
}

/// Opens the input `path` for reading after [`check_input`]; the opened
/// file is checked again (it may have been swapped in between).
pub fn open_input(path: &Path) -> std::io::Result<File> {
    check_input(path)?;
    let file = File::open(path)?;
    remember_input(path, &file.metadata()?)?;
    Ok(file)
}

/// The most bytes a text input (a configuration, a strategy space, a
/// section description) may hold: the longest written by hand or by
/// tortwin are a few kB; a file of gigabytes named by mistake is refused
/// before it is read.
pub const MAX_TEXT_INPUT_BYTES: u64 = 1 << 20;

/// The most bytes a state file may hold: a section at the grid limit
/// (200 000 points) writes about 14 MB a rail and band.
pub const MAX_STATE_BYTES: u64 = 256 << 20;

/// The text of the input `path` (checked as [`open_input`] does), at most
/// `limit` bytes: a longer file is refused with its size, and only
/// `limit + 1` bytes of it are read.
pub fn read_text_input(path: &Path, limit: u64) -> std::io::Result<String> {
    use std::io::Read as _;
    let file = open_input(path)?;
    // A regular file says its size: one over the limit is refused unread
    // (a 300 MB state took 270 MB of memory to refuse).
    let size = file.metadata()?.len();
    if size > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{size} bytes; a file of this kind holds at most {limit}"),
        ));
    }
    let mut text = String::new();
    // Still bounded: the file may grow while it is read.
    file.take(limit + 1).read_to_string(&mut text)?;
    if text.len() as u64 > limit {
        let size = std::fs::metadata(path).map_or(text.len() as u64, |m| m.len());
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{size} bytes; a file of this kind holds at most {limit}"),
        ));
    }
    Ok(text)
}

/// Refuses what is not a regular file, and records one as an input.
fn remember_input(path: &Path, metadata: &std::fs::Metadata) -> std::io::Result<()> {
    if !metadata.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "{} (an input must be a regular file)",
                kind_of(metadata.file_type())
            ),
        ));
    }
    let (dev, ino) = identity(metadata);
    if cfg!(not(unix)) {
        return Ok(());
    }
    let scope = SCOPE.with(std::cell::Cell::get);
    let mut known = inputs();
    if !known
        .iter()
        .any(|&(d, i, _, s)| d == dev && i == ino && s == scope)
    {
        known.push((dev, ino, path.to_path_buf(), scope));
    }
    Ok(())
}

/// The input an existing file is, if it is one of the run's.
fn input_at(metadata: &std::fs::Metadata) -> Option<PathBuf> {
    if cfg!(not(unix)) {
        return None;
    }
    let (dev, ino) = identity(metadata);
    // Still that file under the name it was read by: an input deleted
    // since may have passed its inode on to a new file.
    inputs()
        .iter()
        .find(|&&(d, i, ref p, _)| {
            d == dev && i == ino && std::fs::metadata(p).is_ok_and(|m| identity(&m) == (d, i))
        })
        .map(|(_, _, p, _)| p.clone())
}

// --------------------------------------------------------------- outputs

/// Where an output given as `path` goes: `path` itself, or the file a
/// symbolic link there points to. Refused when that holds one of the
/// run's inputs or anything but a regular file.
pub fn output_target(path: &Path) -> Result<PathBuf, FileError> {
    let target = match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_symlink() => {
            std::fs::canonicalize(path).map_err(|_| FileError::dangling_link(path))?
        }
        _ => path.to_path_buf(),
    };
    if let Ok(m) = std::fs::metadata(&target) {
        if !m.is_file() {
            return Err(FileError::not_a_regular_file(path, kind_of(m.file_type())));
        }
        if let Some(input) = input_at(&m) {
            return Err(FileError::is_an_input(path, input));
        }
    }
    Ok(target)
}

/// The temporary files and folders this process has open, deleted by
/// [`clean_up_on_signals`]'s handler. Temporary files are made while it is
/// held, so the handler, which takes it and never gives it back, cannot
/// miss one being made.
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// A temporary file or folder listed in [`LIVE`] while it exists.
#[derive(Debug)]
struct Live(PathBuf);

impl Drop for Live {
    fn drop(&mut self) {
        let mut live = live();
        if let Some(i) = live.iter().position(|p| *p == self.0) {
            live.swap_remove(i);
        }
    }
}

/// Deletes the run's temporary files and folders when SIGINT or SIGTERM
/// arrives, then exits with 130 or 143 (128 + the signal), as a shell
/// expects. For a program's `main`; a library leaves signals to its host.
pub fn clean_up_on_signals() -> std::io::Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGINT, SIGTERM])?;
    std::thread::Builder::new()
        .name("tortwin-signals".into())
        .spawn(move || {
            if let Some(signal) = signals.forever().next() {
                // Held until the process ends: no temporary file is made
                // after the sweep.
                let live = live();
                for path in live.iter() {
                    if path.is_dir() {
                        let _ = std::fs::remove_dir_all(path);
                    } else {
                        let _ = std::fs::remove_file(path);
                    }
                }
                std::process::exit(128 + signal);
            }
        })?;
    Ok(())
}

/// A file being written under a temporary name beside its final path, for
/// writers that open a path themselves (the MCAP and rerun writers).
#[derive(Debug)]
pub struct PartialFile {
    /// `None` once moved into place.
    temp: Option<TempPath>,
    /// Holds the temporary file's lock while it is written (module
    /// documentation).
    _lock: File,
    _live: Live,
    /// Where it goes (a link's target).
    target: PathBuf,
    /// The path as given.
    final_path: PathBuf,
}

impl PartialFile {
    /// Creates an empty `.NAME.partial-XXXXXX` in the folder of
    /// `final_path` (made if missing); the writer opens it by
    /// [`PartialFile::temp_path`] and truncates it.
    pub fn beside(final_path: &Path) -> Result<Self, FileError> {
        let target = output_target(final_path)?;
        let (temp, live) = temporary_beside(&target)?;
        let (lock, temp) = temp.into_parts();
        Ok(Self {
            temp: Some(temp),
            _lock: lock,
            _live: live,
            target,
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

    /// Runs `open` on [`PartialFile::temp_path`] while no signal's sweep
    /// can run ([`clean_up_on_signals`] takes [`LIVE`], held here): a writer
    /// that creates or truncates the file by its path does so before a
    /// sweep deletes it (and writes on to a file without a name), never
    /// after, when it would make the file anew and leave it behind. Seen
    /// once in `sigint_and_sigterm_leave_nothing_behind`: a SIGTERM between
    /// this file's creation and the rerun writer's `File::create` of it
    /// left `.out.rrd.partial-XXXXXX` after the process had exited.
    pub fn open_with<T>(&self, open: impl FnOnce(&Path) -> T) -> T {
        let _sweep_waits = live();
        open(self.temp_path())
    }

    /// Where to write: the temporary file, or the final path once committed.
    pub fn temp_path(&self) -> &Path {
        self.temp.as_deref().unwrap_or(&self.final_path)
    }

    /// Where the file goes when complete, as given.
    pub fn final_path(&self) -> &Path {
        &self.final_path
    }

    /// The file is complete: moves it into place (replacing a file there;
    /// checked again, as the run may have taken long).
    pub fn commit(&mut self) -> Result<(), FileError> {
        let temp = self
            .temp
            .take()
            .ok_or_else(|| FileError::AlreadyCommitted {
                path: self.final_path.clone(),
            })?;
        output_target(&self.final_path)?;
        let temp_path = temp.to_path_buf();
        // On failure the error owns the temporary file and deletes it.
        temp.persist(&self.target)
            .map_err(|err| FileError::Persist {
                temp: temp_path,
                path: self.final_path.clone(),
                source: err.error,
            })
    }
}

/// Writes `bytes` to `path`, whole or not at all.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), FileError> {
    let target = output_target(path)?;
    let (mut temp, _live) = temporary_beside(&target)?;
    temp.write_all(bytes).map_err(|source| FileError::Write {
        path: path.to_path_buf(),
        source,
    })?;
    let temp_path = temp.path().to_path_buf();
    temp.persist(&target).map_err(|err| FileError::Persist {
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

/// The folder of `path` (`.` for a bare name).
fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(folder) if !folder.as_os_str().is_empty() => folder,
        _ => Path::new("."),
    }
}

/// `.NAME.partial-` for a final name (shortened past [`NAME_KEPT`] bytes).
fn temporary_prefix(final_path: &Path) -> Result<OsString, FileError> {
    let file_name = final_path
        .file_name()
        .ok_or_else(|| FileError::NotAFileName {
            path: final_path.to_path_buf(),
        })?;
    let mut prefix = OsString::from(".");
    if file_name.len() > NAME_KEPT {
        let lossy = file_name.to_string_lossy();
        let mut end = NAME_KEPT;
        while !lossy.is_char_boundary(end) {
            end -= 1;
        }
        prefix.push(&lossy[..end]);
        prefix.push("~");
    } else {
        prefix.push(file_name);
    }
    prefix.push(".partial-");
    Ok(prefix)
}

/// An empty `.NAME.partial-XXXXXX` in the folder of `final_path`, which is
/// made if missing, listed as live.
fn temporary_beside(final_path: &Path) -> Result<(NamedTempFile, Live), FileError> {
    let prefix = temporary_prefix(final_path)?;
    let folder = folder_of(final_path);
    make_folder(folder)?;
    sweep_leftovers(folder, &prefix);
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix);
    // tempfile makes 0600 files; an output is made like any new file
    // (0666 less the umask), as it was before it went through a temporary.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    let mut live = live();
    let temp = builder
        .tempfile_in(folder)
        .map_err(|source| FileError::Temporary {
            folder: folder.to_path_buf(),
            source,
        })?;
    live.push(temp.path().to_path_buf());
    drop(live);
    // Locked at once; the sweep leaves files younger than STALE_AFTER
    // alone, so a file cannot be swept between its creation and its lock.
    // A file system without locks (some network mounts) only loses the
    // sweep's protection of a live run's file, after STALE_AFTER without a
    // write.
    let _ = temp.as_file().try_lock();
    let path = temp.path().to_path_buf();
    Ok((temp, Live(path)))
}

/// A report folder written whole beside its final place and moved there
/// at the end: `.NAME.partial-XXXXXX/` until [`StagedFolder::commit`],
/// deleted with everything in it when dropped before.
#[derive(Debug)]
pub struct StagedFolder {
    temp: Option<TempDir>,
    _lock: Option<File>,
    _live: Live,
    final_dir: PathBuf,
}

impl StagedFolder {
    /// Makes the temporary folder beside `final_dir` (whose parent is made
    /// if missing). `final_dir` must not be a file.
    pub fn beside(final_dir: &Path) -> Result<Self, FileError> {
        if let Ok(m) = std::fs::metadata(final_dir) {
            if !m.is_dir() {
                return Err(FileError::Folder {
                    folder: final_dir.to_path_buf(),
                    source: UsageError(format!(
                        "{} is {}; a report folder is made here",
                        final_dir.display(),
                        kind_of(m.file_type())
                    )),
                });
            }
        }
        // Beside the folder's real place: a link to a folder is followed.
        let real = std::fs::canonicalize(final_dir).unwrap_or_else(|_| final_dir.to_path_buf());
        let prefix = temporary_prefix(&real)?;
        let parent = folder_of(&real);
        make_folder(parent)?;
        sweep_leftovers(parent, &prefix);
        let mut live = live();
        let temp = tempfile::Builder::new()
            .prefix(&prefix)
            .tempdir_in(parent)
            .map_err(|source| FileError::Temporary {
                folder: parent.to_path_buf(),
                source,
            })?;
        live.push(temp.path().to_path_buf());
        drop(live);
        let lock = File::open(temp.path()).ok();
        if let Some(lock) = &lock {
            let _ = lock.try_lock();
        }
        let path = temp.path().to_path_buf();
        Ok(Self {
            temp: Some(temp),
            _lock: lock,
            _live: Live(path),
            final_dir: final_dir.to_path_buf(),
        })
    }

    /// Where the report is written meanwhile.
    pub fn path(&self) -> &Path {
        self.temp.as_ref().map_or(&self.final_dir, |t| t.path())
    }

    /// The report is complete: every file is checked against its final
    /// place first ([`output_target`]), then all are moved there. Returns
    /// the final paths, in name order.
    pub fn commit(mut self) -> Result<Vec<PathBuf>, FileError> {
        let Some(temp) = self.temp.take() else {
            return Ok(Vec::new());
        };
        let listing = |source| FileError::Temporary {
            folder: temp.path().to_path_buf(),
            source,
        };
        let mut names: Vec<OsString> = std::fs::read_dir(temp.path())
            .map_err(listing)?
            .map(|e| e.map(|e| e.file_name()))
            .collect::<Result<_, _>>()
            .map_err(listing)?;
        names.sort();
        make_folder(&self.final_dir)?;
        let mut moves = Vec::with_capacity(names.len());
        for name in &names {
            let final_path = self.final_dir.join(name);
            let target = output_target(&final_path)?;
            moves.push((temp.path().join(name), target, final_path));
        }
        let mut written = Vec::with_capacity(moves.len());
        for (from, target, final_path) in moves {
            std::fs::rename(&from, &target).map_err(|source| FileError::Persist {
                temp: from.clone(),
                path: final_path.clone(),
                source,
            })?;
            written.push(final_path);
        }
        // Dropping `temp` deletes the (now empty) folder.
        Ok(written)
    }
}

/// Deletes `folder/PREFIX*` files and folders that no run holds locked and
/// that have not changed for [`STALE_AFTER`]: what a killed run left. Best
/// effort: an entry that cannot be checked or deleted is left.
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
        let Ok(m) = std::fs::symlink_metadata(&path) else {
            continue;
        };
        let stale = (m.is_file() || m.is_dir())
            && m.modified()
                .ok()
                .and_then(|t| now.duration_since(t).ok())
                .is_some_and(|age| age >= STALE_AFTER);
        if !stale {
            continue;
        }
        let Ok(file) = File::options().read(true).open(&path) else {
            continue;
        };
        if file.try_lock().is_ok() {
            if m.is_dir() {
                let _ = std::fs::remove_dir_all(&path);
            } else {
                let _ = std::fs::remove_file(&path);
            }
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

    #[test]
    fn a_staged_folder_appears_whole_or_not_at_all() {
        let dir = tempfile::tempdir().unwrap();
        let report = dir.path().join("report");
        {
            let staged = StagedFolder::beside(&report).unwrap();
            write_atomically(&staged.path().join("a.json"), b"{}").unwrap();
            assert!(staged
                .path()
                .file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with(".report.partial-"));
        }
        assert!(names_in(dir.path()).is_empty(), "dropped: nothing left");

        let staged = StagedFolder::beside(&report).unwrap();
        write_atomically(&staged.path().join("a.json"), b"{}").unwrap();
        write_atomically(&staged.path().join("b.md"), b"# b").unwrap();
        let written = staged.commit().unwrap();
        assert_eq!(written, [report.join("a.json"), report.join("b.md")]);
        assert_eq!(names_in(dir.path()), ["report"]);
        assert_eq!(names_in(&report), ["a.json", "b.md"]);

        // One file that cannot go in: none goes in.
        std::fs::remove_file(report.join("b.md")).unwrap();
        std::fs::create_dir(report.join("b.md")).unwrap();
        let staged = StagedFolder::beside(&report).unwrap();
        write_atomically(&staged.path().join("a.json"), b"[]").unwrap();
        write_atomically(&staged.path().join("b.md"), b"# b").unwrap();
        let err = staged.commit().unwrap_err();
        assert!(
            matches!(
                err,
                FileError::NotARegularFile {
                    what: "a folder",
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(err.is_input());
        assert_eq!(std::fs::read(report.join("a.json")).unwrap(), b"{}");
        assert_eq!(names_in(dir.path()), ["report"]);
    }

    #[test]
    fn long_names_are_shortened_in_the_temporary_name_only() {
        let dir = tempfile::tempdir().unwrap();
        let name = format!("{}.json", "ß".repeat(125));
        assert_eq!(name.len(), 255);
        let prefix = temporary_prefix(&dir.path().join(&name)).unwrap();
        let prefix = prefix.to_str().unwrap();
        assert!(prefix.len() + 6 <= 255, "{}", prefix.len());
        assert!(prefix.ends_with("~.partial-"), "{prefix}");
        write_atomically(&dir.path().join(&name), b"x").unwrap();
        assert_eq!(names_in(dir.path()), [name]);
    }

    #[test]
    fn an_input_is_never_an_output() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.mcap");
        std::fs::write(&input, b"data").unwrap();
        open_input(&input).unwrap();
        let again = dir.path().join(".").join("in.mcap");
        let err = write_atomically(&again, b"x").unwrap_err();
        assert!(matches!(err, FileError::IsAnInput { .. }), "{err:?}");
        assert!(err.is_input());
        let err = PartialFile::beside(&input).unwrap_err();
        let why = std::error::Error::source(&err).unwrap().to_string();
        assert!(why.contains("this output is the input"), "{why}");
        assert_eq!(std::fs::read(&input).unwrap(), b"data");
        assert_eq!(names_in(dir.path()), ["in.mcap"]);
        // Once the job that read it has ended, it may be written.
        let later = dir.path().join("later.json");
        std::fs::write(&later, b"{}").unwrap();
        {
            let _job = InputScope::enter();
            check_input(&later).unwrap();
            assert!(write_atomically(&later, b"[]").is_err());
        }
        write_atomically(&later, b"[]").unwrap();
        // A folder is no input.
        let err = check_input(dir.path()).unwrap_err();
        assert_eq!(err.kind(), std::io::ErrorKind::InvalidInput);
        assert!(err.to_string().contains("a folder"), "{err}");
    }
}
