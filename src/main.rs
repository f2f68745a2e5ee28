//! The `tortwin` command line: parses the arguments, runs the job from the
//! library (`tortwin_jobs`), shows its progress on stderr, prints
//! its summary and maps errors to exit codes (docs/spec/interfaces.md): 2
//! for bad input (recording, tables, configuration, command line), 1
//! otherwise.

use std::io::IsTerminal as _;
use std::process::ExitCode;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use anyhow::Result;
use clap::Parser as _;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use tortwin_jobs::{
    self as jobs, discover, live, paper, recordings, replay, strategy, summary, synth, tables,
};
use tortwin_jobs::{Cli, Command};
use tortwin_study::Progress;

fn main() -> ExitCode {
    let command = Cli::parse().command;
    if let Command::Replay(args) = &command {
        keep_freed_memory();
        let short =
            std::fs::metadata(&args.recording).is_ok_and(|m| m.len() < SHORT_RECORDING_BYTES);
        if short {
            one_heap_in_huge_pages();
        }
        tortwin_jobs::join_rayon_pool_when_wanted();
    } else {
        tortwin_jobs::join_rayon_pool();
    }
    // Ctrl-C or a SIGTERM deletes the run's temporary files before exiting
    // (130, 143): nothing half-written is left behind.
    if let Err(err) = tortwin_files::clean_up_on_signals() {
        eprintln!("error: cannot watch for SIGINT and SIGTERM: {err}");
        return ExitCode::from(1);
    }
    match run(command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {}", jobs::printable(&format!("{err:#}"), false));
            if is_input_error(&err) {
                ExitCode::from(2)
            } else {
                ExitCode::from(1)
            }
        }
    }
}

/// Memory freed during a run stays with the process for its next
/// allocations rather than going back to the system at once: glibc serves
/// blocks of up to 4 MiB from its heaps (by default each block from
/// 128 KiB up is a mapping of its own, unmapped when freed, the threshold
/// then moving up) and trims a heap's top once 4 MiB are free there (by
/// default 128 KiB). Each page the system hands out costs a fault and a
/// zeroed page: 1.3-1.5 µs on the project's 2-core machine (a VM), where a
/// replay of the 3-day curve took about 5 800 of them in 80 ms (4 900-5 400
/// with these settings). The price is memory held between peaks: the
/// year's replay peaks at 67-72 MB instead of 60-63 (32 MiB and 128 MiB
/// gave 89 MB for no fewer faults). For `replay` alone: discover's
/// parallel replays ran about 9 % slower with it (the clogged nozzle: 11.5
/// against 10.6 s).
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt takes two integers and changes the allocator's
    // settings; called in main before any other thread exists.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 4 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 4 << 20);
    }
}

/// Recordings under this size (a few days of a section: the 3-day curve's
/// is 1.8 MB) are replayed with [`one_heap_in_huge_pages`].
const SHORT_RECORDING_BYTES: u64 = 4 << 20;

/// For a short replay, whose fresh memory is a large part of its work:
/// one heap for every thread, grown once, ahead, and backed by pages of
/// 2 MiB.
///
/// The 3-day curve's replay still took about 5 300 page faults after
/// [`keep_freed_memory`], 8 % of its CPU (`perf`): memory is fresh to a
/// process once, so this cost does not grow with the recording. A
/// transparent huge page costs about as much as 30-60 pages of 4 KiB and
/// holds 512 (a C loop touching 8 MiB: 0.15-0.4 µs per 4 KiB).
///
/// - One arena for every thread (`M_ARENA_MAX`): the layout pass's, the
///   reader's, the output threads' and rayon's blocks come from the main
///   heap, where by default glibc gives threads arenas of their own
///   (mappings grown a few pages at a time, out of reach of the advice
///   below). Small blocks still come from each thread's cache without a
///   lock.
/// - The main heap grown once by [`HEAP_IN_HUGE_PAGES`] (`M_TOP_PAD` for
///   that one growth) and advised as huge pages (`MADV_HUGEPAGE`, which
///   Linux honours where transparent huge pages are `madvise` or
///   `always`), so that its pages come 2 MiB at a time as they are first
///   touched. Untouched, it costs address space only. glibc trims the
///   heap's top only once twice that is free there (`M_TRIM_THRESHOLD`),
///   so the advised heap stays; beyond it the heap grows in pages of 4 KiB.
///
/// The 3-day curve: 5 300 faults -> 700-1 000, CPU 5-7 % less, the replay
/// 2-4 % faster (median pair ratios of 40-60 interleaved runs, 2026-12-06),
/// the same output. Not for longer recordings: one arena's lock is shared
/// by threads that allocate all along (a day of the example line with two
/// tracks in parallel, 6.3 MB: 1.8-2.1 % slower, though with 1.7 % less
/// CPU; the year on the 1.5 km curve within the noise with it, 14.6
/// against 14.4 s in the mean of five, though its peak memory was 52-54 MB
/// instead of 66-70).
fn one_heap_in_huge_pages() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt takes two integers and changes the allocator's
    // settings, called in main before any other thread exists. The block
    // malloc returns (or null) is freed unused. sbrk(0) only reads the
    // program break; madvise is given whole pages of the heap between the
    // break before it grew and after (mapped, read-write, the allocator's
    // own), and MADV_HUGEPAGE changes how they are backed, not their
    // contents.
    unsafe {
        libc::mallopt(
            libc::M_TRIM_THRESHOLD,
            2 * HEAP_IN_HUGE_PAGES as libc::c_int,
        );
        libc::mallopt(libc::M_ARENA_MAX, 1);
        libc::mallopt(libc::M_TOP_PAD, HEAP_IN_HUGE_PAGES as libc::c_int);
        let before = libc::sbrk(0) as usize;
        // More than the young heap's top holds, less than a mapping of its
        // own: the heap grows by it and the pad. (black_box: a block freed
        // unused is otherwise optimised away, malloc and all.)
        libc::free(std::hint::black_box(libc::malloc(1 << 20)));
        let after = libc::sbrk(0) as usize;
        // Later growth with glibc's default pad: a limit on the address
        // space (ulimit -v) then fails no allocation it did not fail before.
        libc::mallopt(libc::M_TOP_PAD, 128 << 10);
        let page = libc::sysconf(libc::_SC_PAGESIZE).max(4096) as usize;
        let start = before.next_multiple_of(page);
        let end = after - after % page;
        if end > start {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
}

/// How far the heap is grown ahead for a short replay
/// ([`one_heap_in_huge_pages`]): several times the 3-day curve's 20 MB of
/// heap.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
const HEAP_IN_HUGE_PAGES: usize = 128 << 20;

/// True when the error is bad user input (exit status 2): the library
/// classifies its own errors; writing the summary to stdout is never the
/// input's fault.
fn is_input_error(err: &anyhow::Error) -> bool {
    err.downcast_ref::<tortwin_study::Error>()
        .is_some_and(tortwin_study::Error::is_input)
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Replay(args) => {
            let display = Display::new(args.quiet);
            let result = replay::replay(&args, None, &mut [], &display).map(|run| run.summary);
            display.finish();
            let run = result?;
            if !args.quiet {
                say(&summary::render(&args.recording, &run))?;
                say(&replay::render_outputs(&args))?;
            }
        }
        Command::Live(args) => {
            let quiet = args.quiet;
            let mut said = Ok(());
            let mut on_recording = |followed: &live::Followed| {
                if !quiet && said.is_ok() {
                    said = say(&live::render_followed(followed));
                }
            };
            let hooks = live::LiveHooks {
                on_recording: &mut on_recording,
                on_line: None,
                stop: None,
            };
            live::live(&args, hooks)?;
            said?;
        }
        Command::Import(args) => {
            let display = Display::new(args.quiet);
            let result = tables::import(&args, &display);
            display.finish();
            let imported = result?;
            if !args.quiet {
                say(&tables::render_import(&args, &imported))?;
            }
        }
        Command::Split(args) => {
            let display = Display::new(args.quiet);
            let result = recordings::split(&args, &display);
            display.finish();
            let days = result?;
            if !args.quiet {
                say(&recordings::render_split(&days))?;
            }
        }
        Command::Merge(args) => {
            let display = Display::new(args.quiet);
            let result = recordings::merge(&args, &display);
            display.finish();
            let messages = result?;
            if !args.quiet {
                say(&recordings::render_merge(&args, messages))?;
            }
        }
        Command::Export(args) => {
            let display = Display::new(args.quiet);
            let result = tables::export(&args, &display);
            display.finish();
            let exported = result?;
            if !args.quiet {
                say(&tables::render_export(&args, &exported))?;
            }
        }
        Command::Paper(args) => {
            let report = paper::paper(&args)?;
            say(&paper::render(&report))?;
        }
        Command::Synth(args) => {
            let display = Display::new(args.quiet);
            let result = synth::synth_with(&args, &display);
            display.finish();
            let (report, key_path) = result?;
            if !args.quiet {
                say(&synth::render(&args.out, &key_path, &report))?;
            }
        }
        Command::Discover(args) => {
            let t0 = Instant::now();
            let display = Display::new(args.quiet);
            let result = discover::run_with(&args, &display);
            display.finish();
            let discovery = result?;
            if !args.quiet {
                let elapsed_s = t0.elapsed().as_secs_f64();
                say(&discover::render(&args, &discovery, elapsed_s))?;
            }
        }
        Command::Calibrate(args) => {
            let t0 = Instant::now();
            let display = Display::new(args.quiet);
            let result = discover::calibrate_with(&args, &display);
            display.finish();
            let found = result?;
            if !args.quiet {
                let elapsed_s = t0.elapsed().as_secs_f64();
                say(&discover::render_calibration(&args, &found, elapsed_s))?;
            }
        }
        Command::Strategy(args) => {
            let t0 = Instant::now();
            let display = Display::new(args.quiet);
            let result = strategy::run_with(&args, &display);
            display.finish();
            let (traffic, study) = result?;
            if !args.quiet {
                let elapsed_s = t0.elapsed().as_secs_f64();
                say(&strategy::render(&args, &traffic, &study, elapsed_s))?;
            }
        }
    }
    Ok(())
}

/// Prints a command's summary on stdout. A reader that has gone (`tortwin
/// replay | head`) is not an error of the run: the rest is dropped.
/// Any other failure names standard output; a full device is the user's
/// to fix (exit status 2, as for a full disk under an output file).
fn say(text: &str) -> Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    let text = jobs::printable(text, true);
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        Err(e) if tortwin_files::usage::is_environment(&e) => Err(tortwin_study::Error::from(
            tortwin_files::usage::UsageError(format!(
                "writing the summary to standard output: {e}"
            )),
        )
        .into()),
        Err(e) => Err(anyhow::Error::new(e).context("writing the summary to standard output")),
        Ok(()) => Ok(()),
    }
}

/// A long command's progress on stderr. On a terminal: a bar with the
/// count, the rate and the time left for a stage whose length is known, a
/// spinner with the elapsed time otherwise. Not on a terminal (a batch
/// run's log): one line per stage with the elapsed time, and the count a
/// stage reached when it ends. Nothing with `--quiet`.
struct Display {
    bar: ProgressBar,
    lines: bool,
    t0: Instant,
    stage: Mutex<Stage>,
}

/// The stage being shown.
#[derive(Default)]
struct Stage {
    total: Option<u64>,
    done: u64,
    started: Option<Instant>,
}

/// indicatif's templates.
const BAR: &str =
    "{msg}\n[{elapsed_precise}] {wide_bar} {human_pos}/{human_len} ({per_sec}, {eta} left)";
const SPINNER: &str = "{spinner} [{elapsed_precise}] {msg}";

impl Display {
    fn new(quiet: bool) -> Self {
        let terminal = std::io::stderr().is_terminal();
        let bar = ProgressBar::new_spinner();
        if quiet || !terminal {
            bar.set_draw_target(ProgressDrawTarget::hidden());
        } else {
            bar.enable_steady_tick(Duration::from_millis(120));
        }
        Self {
            bar,
            lines: !quiet && !terminal,
            t0: Instant::now(),
            stage: Mutex::new(Stage::default()),
        }
    }

    fn style(&self, template: &str) {
        if let Ok(style) = ProgressStyle::with_template(template) {
            self.bar.set_style(style);
        }
    }

    /// Starts a stage: ends the one before, prints its line.
    fn begin(&self, message: &str, total: Option<u64>) {
        let mut stage = self.stage.lock().unwrap_or_else(|e| e.into_inner());
        self.end(&stage);
        *stage = Stage {
            total,
            done: 0,
            started: Some(Instant::now()),
        };
        if self.lines {
            let count = total.map_or(String::new(), |n| format!(" ({n} to do)"));
            eprintln!(
                "[{:8.1} s] {}{count}",
                self.elapsed(),
                jobs::printable(message, false)
            );
        }
        match total {
            Some(n) => {
                self.style(BAR);
                self.bar.reset_eta();
                self.bar.set_length(n);
                self.bar.set_position(0);
            }
            None => {
                self.style(SPINNER);
                self.bar.unset_length();
            }
        }
        self.bar
            .set_message(jobs::printable(message, false).into_owned());
    }

    /// The line that closes a stage with a count, when writing lines.
    fn end(&self, stage: &Stage) {
        if let (true, Some(total), Some(started)) = (self.lines, stage.total, stage.started) {
            eprintln!(
                "[{:8.1} s]   {}/{total} done in {:.1} s",
                self.elapsed(),
                stage.done,
                started.elapsed().as_secs_f64()
            );
        }
    }

    fn elapsed(&self) -> f64 {
        self.t0.elapsed().as_secs_f64()
    }

    /// The job has returned: closes the last stage and clears the bar.
    fn finish(&self) {
        let stage = self.stage.lock().unwrap_or_else(|e| e.into_inner());
        self.end(&stage);
        self.bar.finish_and_clear();
    }
}

impl Progress for Display {
    fn stage(&self, message: &str) {
        self.begin(message, None);
    }
    fn stage_of(&self, message: &str, total: u64) {
        self.begin(message, Some(total));
    }
    fn done(&self, done: u64) {
        let mut stage = self.stage.lock().unwrap_or_else(|e| e.into_inner());
        stage.done = stage.done.max(done);
        self.bar.set_position(stage.done);
    }
}
