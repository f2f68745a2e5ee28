//! A campaign: a worker process mutates and runs inputs in a loop; the
//! parent ([`crate`]'s binary) starts workers, restarts one that dies (an
//! abort, a refused allocation, a hang) and keeps the input that killed it.
//!
//! A worker writes every input to `OUT/current-TARGET-SEED.bin` before
//! running it, so the input is on disk whatever happens to the process.

use std::collections::HashSet;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Result;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use sha2::{Digest, Sha256};

use crate::meter;
use crate::targets::{Kind, Outcome, Target};

/// An execution longer than this is a finding (the seeds replay in
/// milliseconds); one longer than [`HANG`] stops the worker.
pub const SLOW: Duration = Duration::from_secs(5);
pub const HANG: Duration = Duration::from_secs(60);

/// What a worker counted.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Stats {
    pub executions: u64,
    /// Accepted and replayed.
    pub accepted: u64,
    /// Refused with a clear input error (exit status 2).
    pub rejected: u64,
    /// Panics, errors that are not the input's, errors that name no file,
    /// allocations over the limit, slow runs, deaths.
    pub findings: u64,
    pub largest_allocation_bytes: u64,
    pub slowest_ms: f64,
}

impl Stats {
    pub fn add(&mut self, o: &Stats) {
        self.executions += o.executions;
        self.accepted += o.accepted;
        self.rejected += o.rejected;
        self.findings += o.findings;
        self.largest_allocation_bytes = self
            .largest_allocation_bytes
            .max(o.largest_allocation_bytes);
        self.slowest_ms = self.slowest_ms.max(o.slowest_ms);
    }
}

/// Where a worker keeps its current input.
pub fn current_file(out: &Path, kind: Kind, seed: u64) -> PathBuf {
    out.join(format!("current-{}-{seed}.bin", kind.name()))
}

/// Saves a finding's input as `OUT/findings/TARGET-WHAT-HASH.bin` (with the
/// message beside it, `.txt`) and returns the path.
pub fn save_finding(
    out: &Path,
    kind: Kind,
    what: &str,
    input: &[u8],
    message: &str,
) -> Result<PathBuf> {
    let dir = out.join("findings");
    std::fs::create_dir_all(&dir)?;
    let hash = Sha256::digest(input);
    let hex: String = hash.iter().take(6).map(|b| format!("{b:02x}")).collect();
    let path = dir.join(format!("{}-{what}-{hex}.bin", kind.runner().name()));
    std::fs::write(&path, input)?;
    std::fs::write(
        path.with_extension("txt"),
        format!("{}: {message}\n", kind.name()),
    )?;
    Ok(path)
}

static PANIC_MESSAGE: Mutex<String> = Mutex::new(String::new());

/// Panics are caught and recorded, not printed.
fn quiet_panics() {
    std::panic::set_hook(Box::new(|info| {
        let mut message = info.to_string();
        message.truncate(2000);
        if let Ok(mut m) = PANIC_MESSAGE.lock() {
            *m = message;
        }
    }));
}

/// One input through the target, judged.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    Accepted,
    /// Refused with a clear input error: the message.
    Rejected(String),
    /// A finding: what (panic, not-input, unclear, allocation, slow) and
    /// the message.
    Finding(&'static str, String),
}

/// Runs `input` and judges the run (the meter only counts when the binary
/// installed it).
pub fn judge(target: &Target, input: &[u8]) -> (Verdict, meter::Reading, Duration) {
    let start_live = meter::reset();
    let t0 = Instant::now();
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| target.run(input)));
    let elapsed = t0.elapsed();
    let reading = meter::read(start_live);
    let verdict = match result {
        Err(_) => {
            let message = PANIC_MESSAGE.lock().map(|m| m.clone()).unwrap_or_default();
            Verdict::Finding("panic", message)
        }
        Ok(Err(e)) => Verdict::Finding("harness", format!("{e:#}")),
        Ok(Ok(Outcome::NotInput(m))) => Verdict::Finding("not-input", m),
        Ok(Ok(Outcome::Rejected(m))) if !target.names_a_file(&m) => Verdict::Finding("unclear", m),
        Ok(Ok(Outcome::Rejected(m))) if !names_the_field(&target.field_names(input), &m) => {
            Verdict::Finding("unnamed-field", m)
        }
        Ok(Ok(_)) if reading.largest > meter::FINDING_BYTES => Verdict::Finding(
            "allocation",
            format!("a single allocation of {} bytes", reading.largest),
        ),
        Ok(Ok(_)) if elapsed > SLOW => {
            Verdict::Finding("slow", format!("{:.1} s", elapsed.as_secs_f64()))
        }
        Ok(Ok(Outcome::Rejected(m))) => Verdict::Rejected(m),
        Ok(Ok(Outcome::Accepted)) => Verdict::Accepted,
    };
    (verdict, reading, elapsed)
}

/// Whether a refusal names the field a `values` mutant changed (any of
/// its names; no names: nothing to check).
fn names_the_field(names: &[String], message: &str) -> bool {
    names.is_empty() || names.iter().any(|n| message.contains(n.as_str()))
}

/// The worker loop: `runs` mutants of `target`'s seeds from `seed`.
/// Prints a progress line (JSON [`Stats`]) every 200 executions and at the
/// end, and a line for the first finding of each kind and message.
pub fn work(target: &Target, runs: u64, seed: u64, out: &Path) -> Result<Stats> {
    quiet_panics();
    std::fs::create_dir_all(out)?;
    let current = current_file(out, target.kind, seed);
    let started_ms = Arc::new(AtomicU64::new(0));
    let clock = Instant::now();
    watchdog(
        clock,
        Arc::clone(&started_ms),
        current.clone(),
        out.to_path_buf(),
        target.kind,
    );
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut stats = Stats::default();
    let mut seen: HashSet<(&'static str, String)> = HashSet::new();
    for _ in 0..runs {
        let input = target.mutant(&mut rng)?;
        std::fs::write(&current, &input)?;
        started_ms.store(clock.elapsed().as_millis() as u64 + 1, Ordering::SeqCst);
        let (verdict, reading, elapsed) = judge(target, &input);
        started_ms.store(0, Ordering::SeqCst);
        stats.executions += 1;
        stats.largest_allocation_bytes = stats.largest_allocation_bytes.max(reading.largest as u64);
        stats.slowest_ms = stats.slowest_ms.max(elapsed.as_secs_f64() * 1e3);
        match verdict {
            Verdict::Accepted => stats.accepted += 1,
            Verdict::Rejected(_) => stats.rejected += 1,
            Verdict::Finding(what, message) => {
                stats.findings += 1;
                // One file per kind and message shape (digits dropped).
                let shape: String = message
                    .chars()
                    .filter(|c| !c.is_ascii_digit())
                    .take(160)
                    .collect();
                if seen.insert((what, shape)) {
                    let path = save_finding(out, target.kind, what, &input, &message)?;
                    eprintln!("finding ({what}) {}: {message}", path.display());
                }
            }
        }
        if stats.executions % 200 == 0 {
            println!("{}", serde_json::to_string(&stats)?);
            std::io::stdout().flush()?;
        }
    }
    println!("{}", serde_json::to_string(&stats)?);
    let _ = std::fs::remove_file(&current);
    Ok(stats)
}

/// Stops the worker (exit status 3) when one execution runs past [`HANG`],
/// keeping its input as a finding.
fn watchdog(
    clock: Instant,
    started_ms: Arc<AtomicU64>,
    current: PathBuf,
    out: PathBuf,
    kind: Kind,
) {
    std::thread::spawn(move || loop {
        std::thread::sleep(Duration::from_secs(1));
        let started = started_ms.load(Ordering::SeqCst);
        let now = clock.elapsed().as_millis() as u64;
        if started != 0 && now.saturating_sub(started) > HANG.as_millis() as u64 {
            let input = std::fs::read(&current).unwrap_or_default();
            let message = format!("no result after {} s", HANG.as_secs());
            if let Ok(path) = save_finding(&out, kind, "hang", &input, &message) {
                eprintln!("finding (hang) {}: {message}", path.display());
            }
            std::process::exit(3);
        }
    });
}
