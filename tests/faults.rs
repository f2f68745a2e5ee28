//! Faults around the outputs (issue 15): a run killed outright, two runs on
//! one output path, a full disk, a read-only folder. Never a file under a
//! final name that is not complete, never a pile of temporary files, exit
//! status 2 naming the path for what the user has to fix.

mod common;

use std::collections::BTreeSet;
use std::fs::File;
use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant, SystemTime};

use common::{check, demo_day, tortwin};

fn names_in(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

fn partials_in(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .contains(".partial-")
        })
        .collect();
    v.sort();
    v
}

fn age(path: &Path, by: Duration) {
    let file = File::options().write(true).open(path).unwrap();
    file.set_modified(SystemTime::now() - by).unwrap();
}

/// The replay's three outputs, written into `dir`.
fn replay_into(recording: &Path, dir: &Path) -> Command {
    let mut c = tortwin();
    c.arg("replay")
        .arg(recording)
        .arg("--quiet")
        .arg("--out-mcap")
        .arg(dir.join("out.mcap"))
        .arg("--out-rrd")
        .arg(dir.join("out.rrd"))
        .arg("--state-out")
        .arg(dir.join("state.json"));
    c
}

#[test]
fn a_killed_run_leaves_no_output_and_its_leftovers_are_swept_by_a_later_run() {
    let work = tempfile::tempdir().unwrap();
    // Four days: long enough to be killed in the middle.
    let recording = common::four_days(work.path());
    let out = work.path().join("out");
    std::fs::create_dir(&out).unwrap();

    // Killed once its temporary MCAP holds data.
    let mut child = replay_into(&recording, &out)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        let written = partials_in(&out)
            .iter()
            .any(|p| std::fs::metadata(p).map(|m| m.len() > 0).unwrap_or(false));
        if written || t0.elapsed() > Duration::from_secs(60) {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL: no destructor runs.
    let status = child.wait().unwrap();
    assert!(!status.success(), "the run ended before it was killed");
    let names = names_in(&out);
    for output in ["out.mcap", "out.rrd", "state.json"] {
        assert!(!names.contains(output), "{output} after a kill: {names:?}");
    }
    let leftovers = partials_in(&out);
    assert!(!leftovers.is_empty(), "SIGKILL leaves its temporary files");

    // A run at once keeps them (they may still be a live run's, for all it
    // can tell by their age); a run after STALE_AFTER deletes them.
    check(&replay_into(&demo_day(), &out).output().unwrap(), "replay");
    for p in &leftovers {
        assert!(p.exists(), "{} swept while young", p.display());
        age(p, Duration::from_secs(120));
    }
    // A leftover that a live run holds locked is never swept, however old.
    let held = out.join(".out.mcap.partial-held");
    std::fs::write(&held, b"a live run's").unwrap();
    age(&held, Duration::from_secs(3600));
    let lock = File::open(&held).unwrap();
    lock.lock().unwrap();
    check(&replay_into(&demo_day(), &out).output().unwrap(), "replay");
    for p in &leftovers {
        assert!(!p.exists(), "{} left", p.display());
    }
    assert!(held.exists(), "a locked temporary file was swept");
    drop(lock);
    let expected: BTreeSet<String> = [
        "out.mcap",
        "out.rrd",
        "state.json",
        ".out.mcap.partial-held",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    assert_eq!(names_in(&out), expected);
    // The outputs are whole: the state reads back, the MCAP has its summary.
    let state = std::fs::read_to_string(out.join("state.json")).unwrap();
    serde_json::from_str::<serde_json::Value>(&state).unwrap();
    let bytes = std::fs::read(out.join("out.mcap")).unwrap();
    assert!(mcap::Summary::read(&bytes).unwrap().is_some());
}

/// The /twin/measurement payloads of an MCAP output.
fn measurements(path: &Path) -> Vec<Vec<u8>> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .filter(|m| m.channel.topic == "/twin/measurement")
        .map(|m| m.data.into_owned())
        .collect()
}

#[test]
fn two_runs_writing_one_output_path_do_not_interleave() {
    let work = tempfile::tempdir().unwrap();
    let recordings = [demo_day(), common::reference_recording("tangent_day.mcap")];
    // Each recording alone.
    let alone: Vec<(Vec<Vec<u8>>, Vec<u8>)> = recordings
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let dir = work.path().join(format!("alone{i}"));
            std::fs::create_dir(&dir).unwrap();
            check(&replay_into(r, &dir).output().unwrap(), "replay");
            (
                measurements(&dir.join("out.mcap")),
                std::fs::read(dir.join("state.json")).unwrap(),
            )
        })
        .collect();
    assert_ne!(alone[0].0, alone[1].0);
    let shared = work.path().join("shared");
    for round in 0..3 {
        let children: Vec<_> = recordings
            .iter()
            .map(|r| {
                replay_into(r, &shared)
                    .stderr(Stdio::piped())
                    .spawn()
                    .unwrap()
            })
            .collect();
        for child in children {
            let o = child.wait_with_output().unwrap();
            check(&o, "a concurrent replay");
        }
        let got = measurements(&shared.join("out.mcap"));
        let state = std::fs::read(shared.join("state.json")).unwrap();
        assert!(
            alone.iter().any(|(m, _)| *m == got),
            "round {round}: the MCAP is neither run's"
        );
        assert!(
            alone.iter().any(|(_, s)| *s == state),
            "round {round}: the state is neither run's"
        );
        let names = names_in(&shared);
        assert_eq!(names.len(), 3, "round {round}: {names:?}");
    }
}

/// `tortwin ARGS` under a file-size limit of `kb` kB (SIGXFSZ ignored, so a
/// write past it fails with EFBIG as a full disk fails with ENOSPC: both
/// are I/O errors of the kinds the commands exit 2 for).
fn with_file_size_limit(kb: u32, args: &[&std::ffi::OsStr]) -> Output {
    let mut c = Command::new("sh");
    c.arg("-c")
        .arg(format!("trap '' XFSZ; ulimit -f {kb}; exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_tortwin"))
        .args(args);
    c.output().unwrap()
}

#[test]
fn a_full_disk_is_exit_2_naming_the_file_with_nothing_left() {
    let work = tempfile::tempdir().unwrap();
    let demo = demo_day();
    let cases: Vec<(&str, Vec<String>, &str)> = vec![
        (
            "mcap",
            vec![
                "replay".into(),
                demo.display().to_string(),
                "--quiet".into(),
                "--out-mcap".into(),
                "OUT/out.mcap".into(),
            ],
            "out.mcap",
        ),
        (
            "rrd",
            vec![
                "replay".into(),
                demo.display().to_string(),
                "--quiet".into(),
                "--out-rrd".into(),
                "OUT/out.rrd".into(),
            ],
            "out.rrd",
        ),
        (
            "state",
            vec![
                "replay".into(),
                demo.display().to_string(),
                "--quiet".into(),
                "--state-out".into(),
                "OUT/state.json".into(),
            ],
            "state.json",
        ),
        (
            "export",
            vec![
                "export".into(),
                demo.display().to_string(),
                "--quiet".into(),
                "--out".into(),
                "OUT".into(),
            ],
            ".csv",
        ),
        (
            "split",
            vec![
                "split".into(),
                demo.display().to_string(),
                "--quiet".into(),
                "--out".into(),
                "OUT/days".into(),
            ],
            ".mcap",
        ),
        (
            "merge",
            vec![
                "merge".into(),
                demo.display().to_string(),
                demo.display().to_string(),
                "--quiet".into(),
                "--out".into(),
                "OUT/merged.mcap".into(),
            ],
            "merged.mcap",
        ),
        (
            "synth",
            vec![
                "synth".into(),
                "--quiet".into(),
                "--out".into(),
                "OUT/synth.mcap".into(),
            ],
            "synth.mcap",
        ),
    ];
    for (name, args, named) in cases {
        let out = work.path().join(name);
        std::fs::create_dir(&out).unwrap();
        let args: Vec<String> = args
            .into_iter()
            .map(|a| a.replace("OUT", &out.display().to_string()))
            .collect();
        let os: Vec<&std::ffi::OsStr> = args.iter().map(|a| a.as_ref()).collect();
        let o = with_file_size_limit(16, &os);
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{name}: {stderr}");
        assert!(
            stderr.contains(&*out.display().to_string()) && stderr.contains(named),
            "{name}: {stderr}"
        );
        assert!(stderr.contains("File too large"), "{name}: {stderr}");
        assert!(!stderr.contains("panicked"), "{name}: {stderr}");
        assert!(names_in(&out).is_empty(), "{name}: {:?}", names_in(&out));
    }
}

#[test]
fn a_read_only_folder_is_exit_2_naming_it_with_nothing_left() {
    let work = tempfile::tempdir().unwrap();
    std::fs::set_permissions(work.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    let recording = work.path().join("demo_day.mcap");
    std::fs::copy(demo_day(), &recording).unwrap();
    std::fs::set_permissions(&recording, std::fs::Permissions::from_mode(0o644)).unwrap();
    let locked = work.path().join("locked");
    std::fs::create_dir(&locked).unwrap();
    std::fs::set_permissions(&locked, std::fs::Permissions::from_mode(0o555)).unwrap();
    // Root writes anywhere: the run is then made as user `nobody`.
    let as_root = std::fs::write(locked.join("probe"), b"").is_ok();
    let _ = std::fs::remove_file(locked.join("probe"));
    for output in ["--out-mcap", "--out-rrd", "--state-out"] {
        let mut c = tortwin();
        c.arg("replay")
            .arg(&recording)
            .arg("--quiet")
            .arg(output)
            .arg(locked.join("out"));
        if as_root {
            c.uid(65534).gid(65534);
        }
        let o = c.output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{output}: {stderr}");
        assert!(
            stderr.contains(&format!(
                "cannot create a file in the output folder {}",
                locked.display()
            )) && stderr.contains("Permission denied"),
            "{output}: {stderr}"
        );
        assert!(names_in(&locked).is_empty());
    }
}
