//! Hostile and unlucky paths around the files (issue 29, "Outputs never
//! destroy" and "Only regular files as inputs"): an output that names an
//! input, by whatever path; a pipe, a device node or a folder where an
//! output goes; a symbolic link; a signal in the middle of a run; a report
//! that fails half-way; a name at the file system's limit; a named pipe
//! as an input. Each one exits with the status and message the user needs
//! and destroys nothing.

mod common;

use std::collections::BTreeSet;
use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{check, demo_day, tortwin};

fn names_in(dir: &Path) -> BTreeSet<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exit status 2 with `needle` in the message.
fn refused(o: &Output, needle: &str) {
    assert_eq!(
        o.status.code(),
        Some(2),
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        stderr(o)
    );
    assert!(
        stderr(o).contains(needle),
        "{needle:?} not in: {}",
        stderr(o)
    );
}

/// A copy of the bundled recording in `dir`.
fn recording_in(dir: &Path) -> PathBuf {
    let rec = dir.join("in.mcap");
    std::fs::copy(demo_day(), &rec).unwrap();
    rec
}

fn sha(path: &Path) -> Vec<u8> {
    use sha2::Digest;
    sha2::Sha256::digest(std::fs::read(path).unwrap()).to_vec()
}

fn mkfifo(path: &Path) {
    let o = Command::new("mkfifo").arg(path).output().unwrap();
    check(&o, "mkfifo");
}

#[test]
fn an_output_that_is_the_input_is_refused_by_any_path() {
    let work = tempfile::tempdir().unwrap();
    let x = work.path().join("x");
    std::fs::create_dir(&x).unwrap();
    let rec = recording_in(&x);
    let before = sha(&rec);
    let dotted = x.join("../x/in.mcap");
    let absolute = std::fs::canonicalize(&rec).unwrap();
    for flag in ["--out-mcap", "--out-rrd", "--state-out"] {
        for out in [&rec, &dotted, &absolute] {
            let o = tortwin()
                .arg("replay")
                .arg(&rec)
                .arg("--quiet")
                .arg(flag)
                .arg(out)
                .output()
                .unwrap();
            refused(&o, "this output is the input");
            assert_eq!(sha(&rec), before, "{flag} {}", out.display());
        }
    }
    // A configuration or a state given as input is one too.
    let cfg = x.join("model.toml");
    std::fs::write(&cfg, "[product]\nmu_d = 0.55\n").unwrap();
    let o = tortwin()
        .arg("replay")
        .arg(&rec)
        .args(["--quiet", "--config"])
        .arg(&cfg)
        .arg("--state-out")
        .arg(&cfg)
        .output()
        .unwrap();
    refused(&o, "this output is the input");
    assert_eq!(
        std::fs::read_to_string(&cfg).unwrap(),
        "[product]\nmu_d = 0.55\n"
    );
    assert_eq!(
        names_in(&x),
        BTreeSet::from(["in.mcap".into(), "model.toml".into()])
    );
}

#[test]
fn export_and_discover_never_overwrite_an_input_in_their_folder() {
    let work = tempfile::tempdir().unwrap();
    // The recording sits in the export folder under an output's name.
    let out = work.path().join("tables");
    std::fs::create_dir(&out).unwrap();
    let rec = out.join("measurements.csv");
    std::fs::copy(demo_day(), &rec).unwrap();
    let before = sha(&rec);
    let o = tortwin()
        .arg("export")
        .arg(&rec)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    refused(&o, "this output is the input");
    assert_eq!(sha(&rec), before);
    assert_eq!(names_in(&out), BTreeSet::from(["measurements.csv".into()]));

    // discover's report folder holds its configuration as model.toml.
    let report = work.path().join("report");
    std::fs::create_dir(&report).unwrap();
    let cfg = report.join("model.toml");
    std::fs::write(&cfg, "[product]\nmu_d = 0.58\n").unwrap();
    let o = tortwin()
        .arg("calibrate")
        .arg(demo_day())
        .arg("--config")
        .arg(&cfg)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    refused(&o, "this output is the input");
    assert_eq!(
        std::fs::read_to_string(&cfg).unwrap(),
        "[product]\nmu_d = 0.58\n"
    );
    // Nothing else came: the report is moved in whole or not at all.
    assert_eq!(names_in(&report), BTreeSet::from(["model.toml".into()]));
    assert_eq!(
        names_in(work.path()),
        BTreeSet::from(["report".into(), "tables".into()])
    );
}

#[test]
fn pipes_devices_and_folders_are_never_replaced_and_links_are_followed() {
    let work = tempfile::tempdir().unwrap();
    let rec = recording_in(work.path());
    let replay_to = |out: &Path| {
        tortwin()
            .arg("replay")
            .arg(&rec)
            .arg("--quiet")
            .arg("--out-mcap")
            .arg(out)
            .output()
            .unwrap()
    };
    let fifo = work.path().join("pipe.mcap");
    mkfifo(&fifo);
    refused(&replay_to(&fifo), "is a named pipe, not a regular file");
    assert!(std::fs::symlink_metadata(&fifo)
        .unwrap()
        .file_type()
        .is_fifo());

    let folder = work.path().join("folder.mcap");
    std::fs::create_dir(&folder).unwrap();
    refused(&replay_to(&folder), "is a folder, not a regular file");
    assert!(folder.is_dir());

    // A device node the test makes itself (root only: mknod needs it).
    let node = work.path().join("null.mcap");
    let made = Command::new("mknod")
        .arg(&node)
        .args(["c", "1", "3"])
        .output()
        .is_ok_and(|o| o.status.success());
    if made {
        refused(&replay_to(&node), "is a device, not a regular file");
        assert!(std::fs::symlink_metadata(&node)
            .unwrap()
            .file_type()
            .is_char_device());
    }

    // A link to a file: the file is replaced, the link stays.
    let real = work.path().join("real.mcap");
    std::fs::write(&real, b"old").unwrap();
    let link = work.path().join("link.mcap");
    std::os::unix::fs::symlink(&real, &link).unwrap();
    check(&replay_to(&link), "replay --out-mcap LINK");
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(std::fs::read(&real).unwrap().starts_with(b"\x89MCAP0\r\n"));
    // A link to the input is the input; a link to nothing is refused.
    let to_input = work.path().join("to_input.mcap");
    std::os::unix::fs::symlink(&rec, &to_input).unwrap();
    refused(&replay_to(&to_input), "this output is the input");
    let dangling = work.path().join("dangling.mcap");
    std::os::unix::fs::symlink(work.path().join("nowhere"), &dangling).unwrap();
    refused(&replay_to(&dangling), "a symbolic link to nothing");
    if made {
        // A link to a device is the device.
        let to_node = work.path().join("to_null.mcap");
        std::os::unix::fs::symlink(&node, &to_node).unwrap();
        refused(&replay_to(&to_node), "is a device");
    }
    let partials: Vec<String> = names_in(work.path())
        .into_iter()
        .filter(|n| n.contains(".partial-"))
        .collect();
    assert!(partials.is_empty(), "{partials:?}");
}

#[test]
fn a_named_pipe_as_input_is_refused_without_blocking() {
    let work = tempfile::tempdir().unwrap();
    let fifo = work.path().join("pipe.mcap");
    mkfifo(&fifo);
    let t0 = Instant::now();
    let o = tortwin()
        .arg("replay")
        .arg(&fifo)
        .arg("--quiet")
        .output()
        .unwrap();
    refused(&o, "a named pipe (an input must be a regular file)");
    assert!(t0.elapsed() < Duration::from_secs(30));

    // A table folder whose weather.csv is a pipe.
    let exported = work.path().join("exported");
    check(
        &tortwin()
            .arg("export")
            .arg(demo_day())
            .args(["--inputs", "--no-field", "--quiet", "--out"])
            .arg(&exported)
            .output()
            .unwrap(),
        "export --inputs",
    );
    let tables = exported.join("inputs");
    std::fs::remove_file(tables.join("weather.csv")).unwrap();
    mkfifo(&tables.join("weather.csv"));
    let o = tortwin()
        .arg("import")
        .arg(&tables)
        .arg("--out")
        .arg(work.path().join("back.mcap"))
        .output()
        .unwrap();
    refused(&o, "weather.csv");
    refused(&o, "a named pipe");

    // A configuration and a state that are pipes.
    let rec = recording_in(work.path());
    for flag in ["--config", "--state-in"] {
        let o = tortwin()
            .arg("replay")
            .arg(&rec)
            .arg("--quiet")
            .arg(flag)
            .arg(&fifo)
            .output()
            .unwrap();
        refused(&o, "a named pipe");
    }
}

/// Spawns `command`, waits until a temporary file beside `dir`'s outputs
/// holds data, sends `signal`, and returns the exit status.
fn interrupted(mut command: Command, dir: &Path, signal: &str) -> std::process::ExitStatus {
    let mut child = command
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let t0 = Instant::now();
    loop {
        let started = std::fs::read_dir(dir).unwrap().flatten().any(|e| {
            e.file_name().to_string_lossy().contains(".partial-")
                && e.metadata().is_ok_and(|m| m.len() > 0)
        });
        if started || t0.elapsed() > Duration::from_secs(120) {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let o = Command::new("kill")
        .args(["-s", signal])
        .arg(child.id().to_string())
        .output()
        .unwrap();
    check(&o, "kill");
    child.wait().unwrap()
}

#[test]
fn sigint_and_sigterm_leave_nothing_behind() {
    let work = tempfile::tempdir().unwrap();
    // Four days: long enough to be interrupted in the middle.
    let recording = common::four_days(work.path());
    for (signal, code) in [("INT", 130), ("TERM", 143)] {
        let out = work.path().join(format!("out-{signal}"));
        std::fs::create_dir(&out).unwrap();
        let mut c = tortwin();
        c.arg("replay")
            .arg(&recording)
            .arg("--quiet")
            .arg("--out-mcap")
            .arg(out.join("out.mcap"))
            .arg("--out-rrd")
            .arg(out.join("out.rrd"));
        let status = interrupted(c, &out, signal);
        assert_eq!(status.code(), Some(code), "SIG{signal}: {status}");
        assert!(
            names_in(&out).is_empty(),
            "SIG{signal}: {:?}",
            names_in(&out)
        );
    }
}

#[test]
fn a_report_that_fails_half_way_leaves_none_of_its_files() {
    let work = tempfile::tempdir().unwrap();
    let report = work.path().join("report");
    std::fs::create_dir(&report).unwrap();
    // A folder where the report's last file (report.md) goes: every other
    // file could be written, none may appear.
    std::fs::create_dir(report.join("report.md")).unwrap();
    let o = tortwin()
        .arg("calibrate")
        .arg(demo_day())
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    refused(&o, "report.md: is a folder, not a regular file");
    assert_eq!(names_in(&report), BTreeSet::from(["report.md".into()]));
    assert_eq!(names_in(work.path()), BTreeSet::from(["report".into()]));
}

#[test]
fn an_output_name_at_the_file_systems_limit_is_written() {
    let work = tempfile::tempdir().unwrap();
    let rec = recording_in(work.path());
    // 255 bytes, the limit of ext4, tmpfs and most others; two-byte
    // characters, so a shortened temporary name must cut at a boundary.
    let name = format!("{}.mcap", "é".repeat(125));
    assert_eq!(name.len(), 255);
    let out = work.path().join(&name);
    let o = tortwin()
        .arg("replay")
        .arg(&rec)
        .arg("--quiet")
        .arg("--out-mcap")
        .arg(&out)
        .output()
        .unwrap();
    check(&o, "replay --out-mcap with a 255-byte name");
    assert!(std::fs::read(&out).unwrap().starts_with(b"\x89MCAP0\r\n"));
    assert_eq!(
        names_in(work.path()),
        BTreeSet::from(["in.mcap".into(), name])
    );
}
