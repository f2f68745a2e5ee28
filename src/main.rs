//! The `tortwin` command line: parses the arguments, runs the job from the
//! library (`tortwin_studies::jobs`), shows its progress on stderr, prints
//! its summary and maps errors to exit codes (../shared/spec/interfaces.md):
//! 2 for bad input (recording, configuration, command line), 1 otherwise.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use anyhow::Result;
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

use tortwin_studies::jobs::{discover, paper, replay, strategy, summary, synth};
use tortwin_studies::Progress;

#[derive(Debug, Parser)]
#[command(
    name = "tortwin",
    version,
    about = "Digital twin of a track section for top-of-rail friction management"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Replay a recording of a track section and publish the friction field.
    Replay(replay::ReplayArgs),
    /// Recompute the paper's Figures 7 and 13–17 as CSV and SVG.
    Paper(paper::PaperArgs),
    /// Write a synthetic recording (traffic, pulses, weather, noisy
    /// measurements from a truth model with optional hidden effects).
    Synth(synth::SynthArgs),
    /// Find the effects the model misses in a recording: residuals,
    /// covariates, candidate effects fitted and selected (BIC, share of the
    /// excess over the noise, cross-validation by day and by site); writes
    /// report.json, report.md with plots, model.toml and residuals.rrd.
    Discover(discover::DiscoverArgs),
    /// Evaluate application strategies (pulse mass, interval, applicator
    /// positions, rails) over a section's traffic: share of the section in
    /// the target band, carry-on distance, over-application, product per
    /// day; search, Pareto front, recommendation; writes strategy.json,
    /// report.md with plots and recommended.rrd.
    Strategy(strategy::StrategyArgs),
}

fn main() -> ExitCode {
    match run(Cli::parse().command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("error: {err:#}");
            if is_input_error(&err) {
                ExitCode::from(2)
            } else {
                ExitCode::from(1)
            }
        }
    }
}

/// True when the error is bad user input (exit status 2): the library
/// classifies its own errors; writing the summary to stdout is never the
/// input's fault.
fn is_input_error(err: &anyhow::Error) -> bool {
    err.downcast_ref::<tortwin_studies::Error>()
        .is_some_and(tortwin_studies::Error::is_input)
}

fn run(command: Command) -> Result<()> {
    match command {
        Command::Replay(args) => {
            let bar = Spinner::new(args.quiet, "{spinner} {elapsed} {msg}");
            let result = replay::replay_with(&args, &mut [], &bar);
            bar.0.finish_and_clear();
            let run = result?;
            if !args.quiet {
                say(&summary::render(&args.recording, &run))?;
                say(&replay::render_outputs(&args))?;
            }
        }
        Command::Paper(args) => {
            let report = paper::paper(&args)?;
            say(&paper::render(&report))?;
        }
        Command::Synth(args) => {
            let (report, key_path) = synth::synth(&args)?;
            if !args.quiet {
                say(&synth::render(&args.out, &key_path, &report))?;
            }
        }
        Command::Discover(args) => {
            let t0 = Instant::now();
            let bar = Spinner::new(args.quiet, "{spinner} {elapsed} {pos} engine runs  {msg}");
            let result = discover::run_with(&args, &bar);
            bar.0.finish_and_clear();
            let discovery = result?;
            if !args.quiet {
                let elapsed_s = t0.elapsed().as_secs_f64();
                say(&discover::render(&args, &discovery, elapsed_s))?;
            }
        }
        Command::Strategy(args) => {
            let t0 = Instant::now();
            let bar = Spinner::new(args.quiet, "{spinner} {elapsed} {pos} strategies  {msg}");
            let result = strategy::run_with(&args, &bar);
            bar.0.finish_and_clear();
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
fn say(text: &str) -> std::io::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        result => result,
    }
}

/// A spinner on stderr for a long command (indicatif hides it when stderr
/// is not a terminal; `quiet` hides it always). `template` is indicatif's.
struct Spinner(ProgressBar);

impl Spinner {
    fn new(quiet: bool, template: &str) -> Self {
        let bar = ProgressBar::new_spinner();
        if quiet {
            bar.set_draw_target(ProgressDrawTarget::hidden());
        }
        bar.set_style(
            ProgressStyle::with_template(template)
                .unwrap_or_else(|_| ProgressStyle::default_spinner()),
        );
        bar.enable_steady_tick(Duration::from_millis(120));
        Self(bar)
    }
}

impl Progress for Spinner {
    fn stage(&self, message: &str) {
        self.0.set_message(message.to_string());
    }
    fn done(&self, done: usize) {
        self.0.set_position(done as u64);
    }
}
