//! `tortwin-fuzz`: seeded mutation fuzzing of tortwin's inputs (see the
//! library's documentation and the README's "Fuzzing").

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, ExitCode, Stdio};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use tortwin_fuzz::campaign::{self, current_file, save_finding, Stats, Verdict};
use tortwin_fuzz::meter::Meter;
use tortwin_fuzz::seeds::Seeds;
use tortwin_fuzz::targets::{Kind, Target};

#[global_allocator]
static METER: Meter = Meter;

#[derive(Parser)]
#[command(
    about = "Seeded mutation fuzzing of tortwin's inputs: every mutant must replay or be refused \
             with a clear input error; panics, other errors, huge allocations, hangs and deaths \
             are findings, saved under OUT/findings",
    after_help = "Exit status: 0 without findings, 1 with findings, 2 on a bad command line."
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Sub>,
    #[command(flatten)]
    run: RunArgs,
}

#[derive(clap::Args)]
struct RunArgs {
    /// Targets to fuzz (repeatable); default: all.
    #[arg(long = "target", value_enum)]
    targets: Vec<Kind>,
    /// Executions per target.
    #[arg(long, default_value_t = 10_000)]
    runs: u64,
    /// The campaign's seed: the same seed gives the same mutants.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Worker processes per target.
    #[arg(long, default_value_t = 2)]
    jobs: u64,
    /// Where findings, the workers' current inputs and summary.json go.
    #[arg(long, default_value = "out/fuzz")]
    out: PathBuf,
}

#[derive(Subcommand)]
enum Sub {
    /// Runs saved inputs (e.g. OUT/findings/*.bin or the regressions) once
    /// and prints how each ended.
    Replay {
        /// What kind of input the files are.
        #[arg(long, value_enum)]
        target: Kind,
        files: Vec<PathBuf>,
    },
    /// One worker (started by the campaign).
    #[command(hide = true)]
    Worker {
        #[arg(long, value_enum)]
        target: Kind,
        #[arg(long)]
        runs: u64,
        #[arg(long)]
        seed: u64,
        #[arg(long)]
        out: PathBuf,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Some(Sub::Worker {
            target,
            runs,
            seed,
            out,
        }) => worker(target, runs, seed, &out).map(|_| true),
        Some(Sub::Replay { target, files }) => replay(target, &files),
        None => run(&cli.run),
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn worker(kind: Kind, runs: u64, seed: u64, out: &std::path::Path) -> Result<Stats> {
    let seeds = Arc::new(Seeds::make()?);
    let target = Target::new(kind, seeds)?;
    campaign::work(&target, runs, seed, out)
}

fn replay(kind: Kind, files: &[PathBuf]) -> Result<bool> {
    let target = Target::new(kind.runner(), Arc::new(Seeds::make()?))?;
    let mut clean = true;
    for file in files {
        let input = std::fs::read(file).with_context(|| format!("reading {}", file.display()))?;
        let (verdict, reading, elapsed) = campaign::judge(&target, &input);
        clean &= !matches!(verdict, Verdict::Finding(..));
        println!(
            "{}: {verdict:?} (largest allocation {} bytes, {:.1} ms)",
            file.display(),
            reading.largest,
            elapsed.as_secs_f64() * 1e3
        );
    }
    Ok(clean)
}

fn run(args: &RunArgs) -> Result<bool> {
    if args.jobs == 0 {
        bail!("--jobs must be at least 1");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("making {}", args.out.display()))?;
    let targets = if args.targets.is_empty() {
        Kind::ALL.to_vec()
    } else {
        args.targets.clone()
    };
    let exe = std::env::current_exe()?;
    let mut summary: BTreeMap<&'static str, Stats> = BTreeMap::new();
    let started = std::time::Instant::now();
    for kind in targets {
        let mut total = Stats::default();
        let workers: Vec<_> = (0..args.jobs)
            .map(|j| {
                let runs = args.runs / args.jobs + u64::from(j < args.runs % args.jobs);
                let seed = args.seed * 1000 + j;
                let exe = exe.clone();
                let out = args.out.clone();
                std::thread::spawn(move || supervise(&exe, kind, runs, seed, &out))
            })
            .collect();
        for w in workers {
            let stats = w
                .join()
                .map_err(|_| anyhow::anyhow!("a supervisor thread panicked"))??;
            total.add(&stats);
        }
        println!(
            "{:<9} {:>9} executions: {:>8} accepted, {:>8} refused (input errors), {} findings; \
             largest allocation {:.0} kB, slowest {:.0} ms",
            kind.name(),
            total.executions,
            total.accepted,
            total.rejected,
            total.findings,
            total.largest_allocation_bytes as f64 / 1e3,
            total.slowest_ms
        );
        summary.insert(kind.name(), total);
    }
    let findings: u64 = summary.values().map(|s| s.findings).sum();
    let executions: u64 = summary.values().map(|s| s.executions).sum();
    println!(
        "{executions} executions in {:.0} s, {findings} findings{}",
        started.elapsed().as_secs_f64(),
        if findings > 0 {
            format!(" (inputs in {})", args.out.join("findings").display())
        } else {
            String::new()
        }
    );
    std::fs::write(
        args.out.join("summary.json"),
        serde_json::to_string_pretty(&summary)?,
    )?;
    Ok(findings == 0)
}

/// Runs a worker to the end, restarting it (with the next seed) when it
/// dies, and saving the input it died on.
fn supervise(
    exe: &std::path::Path,
    kind: Kind,
    runs: u64,
    seed: u64,
    out: &std::path::Path,
) -> Result<Stats> {
    let mut done = Stats::default();
    let mut seed = seed;
    let mut restarts = 0;
    while done.executions < runs {
        let mut child = Command::new(exe)
            .args(["worker", "--target", kind.name()])
            .arg("--runs")
            .arg((runs - done.executions).to_string())
            .arg("--seed")
            .arg(seed.to_string())
            .arg("--out")
            .arg(out)
            .stdout(Stdio::piped())
            .spawn()
            .context("starting a worker")?;
        let mut last = Stats::default();
        let stdout = child.stdout.take().context("no worker stdout")?;
        for line in BufReader::new(stdout).lines() {
            if let Ok(stats) = serde_json::from_str::<Stats>(&line?) {
                last = stats;
            }
        }
        let status = child.wait()?;
        done.add(&last);
        if status.success() {
            break;
        }
        // Died: the input it was running is the finding.
        let current = current_file(out, kind, seed);
        let input = std::fs::read(&current).unwrap_or_default();
        let path = save_finding(
            out,
            kind,
            "died",
            &input,
            &format!("the worker ended with {status}"),
        )?;
        eprintln!(
            "finding (died) {}: the worker ended with {status}",
            path.display()
        );
        let _ = std::fs::remove_file(&current);
        done.executions += 1;
        done.findings += 1;
        restarts += 1;
        if restarts > 50 {
            bail!("{} workers died; stopping", restarts);
        }
        seed += 1_000_000;
    }
    Ok(done)
}
