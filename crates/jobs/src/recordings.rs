//! `tortwin split` and `tortwin merge`: a recording of several days cut
//! into one recording per service day, and consecutive days of one section
//! merged into one recording (`tortwin_recording::cut`, streaming: the
//! messages as written, never all in memory). The fleet's studies merge a
//! section's days; its tests cut a synthetic recording into days.

use std::fmt::Write as _;
use std::path::PathBuf;

use tortwin_files::usage::UsageError;
use tortwin_recording::cut::{self, Day};
use tortwin_study::progress::Progress;
use tortwin_study::Result;

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SplitArgs {
    /// The recording to cut (MCAP).
    pub recording: PathBuf,
    /// The folder of the days, `YYYY-MM-DD.mcap` each (made if missing;
    /// files of those names in it are replaced).
    #[cfg_attr(feature = "cli", arg(long))]
    pub out: PathBuf,
    /// Do not print the days.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct MergeArgs {
    /// The recordings to merge, consecutive days of one section in order
    /// (MCAP).
    #[cfg_attr(feature = "cli", arg(required = true))]
    pub recordings: Vec<PathBuf>,
    /// The recording to write (MCAP); its folder is made if missing.
    #[cfg_attr(feature = "cli", arg(long))]
    pub out: PathBuf,
    /// Do not print the summary.
    #[cfg_attr(feature = "cli", arg(long, short))]
    pub quiet: bool,
}

/// Cuts `args.recording` into its service days in `args.out`.
pub fn split(args: &SplitArgs, progress: &dyn Progress) -> Result<Vec<Day>> {
    let _inputs = tortwin_outputs::files::InputScope::enter();
    if args.out.is_file() {
        return Err(UsageError(format!(
            "--out {}: is a file; it must be a folder (made if missing)",
            args.out.display()
        ))
        .into());
    }
    progress.stage(&format!("cutting {} into days", args.recording.display()));
    Ok(cut::split_by_day(&args.recording, &args.out)?)
}

/// Merges `args.recordings` into `args.out`; the messages written.
pub fn merge(args: &MergeArgs, progress: &dyn Progress) -> Result<u64> {
    let _inputs = tortwin_outputs::files::InputScope::enter();
    if args.recordings.is_empty() {
        return Err(UsageError("merge: no recording given".into()).into());
    }
    if let Some(folder) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        tortwin_outputs::files::make_folder(folder)?;
    }
    progress.stage(&format!(
        "merging {} recordings into {}",
        args.recordings.len(),
        args.out.display()
    ));
    Ok(cut::merge(&args.recordings, &args.out)?)
}

/// What `tortwin split` prints: a line a day.
pub fn render_split(days: &[Day]) -> String {
    let mut text = String::new();
    for d in days {
        let _ = writeln!(
            text,
            "{}  {:>8} messages  {}",
            d.date,
            d.messages,
            d.path.display()
        );
    }
    text
}

/// What `tortwin merge` prints.
pub fn render_merge(args: &MergeArgs, messages: u64) -> String {
    format!(
        "{}: {messages} messages from {} recordings\n",
        args.out.display(),
        args.recordings.len()
    )
}
