//! `tortwin replay` end to end, as a user runs it: the outputs are read back
//! by independent readers (the Python `mcap` + `jsonschema` packages and
//! `rerun-sdk` 0.36.3, installed by .ci/run), the field ties back to the
//! reference values, and bad input gives exit status 2, a message that says
//! where, and no output file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

mod common;
use common::recording::copy_recording;
use common::{python, tortwin};

fn reference(name: &str) -> PathBuf {
    common::reference_recording(name)
}

/// The `/twin/field` and `/twin/section` messages of an output MCAP.
fn read_mcap(path: &Path) -> (serde_json::Value, Vec<serde_json::Value>) {
    let bytes = std::fs::read(path).unwrap();
    let mut section = serde_json::Value::Null;
    let mut fields = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
        match m.channel.topic.as_str() {
            "/twin/section" => section = v,
            "/twin/field" => fields.push(v),
            _ => {}
        }
    }
    (section, fields)
}

#[test]
fn replay_outputs_read_back_with_independent_readers() {
    let dir = tempfile::tempdir().unwrap();
    let (mcap_out, rrd_out) = (dir.path().join("day.mcap"), dir.path().join("day.rrd"));
    let out = tortwin()
        .arg("replay")
        .arg(reference("tangent_day.mcap"))
        .arg("--out-mcap")
        .arg(&mcap_out)
        .arg("--out-rrd")
        .arg(&rrd_out)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("trains 32") && stdout.contains("measurements 7198"),
        "{stdout}"
    );
    assert!(
        stdout.contains("mass balance") && stdout.contains("rerun out")
            || stdout.contains("rerun "),
        "{stdout}"
    );

    // Every message decodes and validates against its channel's schema;
    // one /twin/measurement per input measurement, one field per train and rail.
    let check = python(
        "check_mcap.py",
        &[
            mcap_out.as_os_str(),
            "--expect-count".as_ref(),
            "/twin/measurement=7198".as_ref(),
            "--expect-count".as_ref(),
            "/twin/field=64".as_ref(),
        ],
    );
    assert!(
        check.status.success(),
        "{}{}",
        String::from_utf8_lossy(&check.stdout),
        String::from_utf8_lossy(&check.stderr)
    );

    // Pick a measured train: the mu its last axle saw at a site, in the
    // reference's expected.csv, is the field's mu at that site's grid point.
    let (section, fields) = read_mcap(&mcap_out);
    let site_point: HashMap<String, usize> = section["sites"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["id"].as_str().unwrap().to_string(),
                s["grid_index"].as_u64().unwrap() as usize,
            )
        })
        .collect();
    let expected = std::fs::read_to_string(reference("tangent_day.expected.csv")).unwrap();
    let mut checked = 0;
    let mut chosen = None;
    for field in &fields {
        let train = field["train_id"].as_str().unwrap();
        let rail = field["rail"].as_str().unwrap();
        let last_axle = expected
            .lines()
            .filter(|l| l.contains(&format!(",{train},")))
            .filter_map(|l| l.split(',').nth(6).and_then(|a| a.parse::<usize>().ok()))
            .max();
        let Some(last_axle) = last_axle else { continue };
        for line in expected.lines().skip(1) {
            let f: Vec<&str> = line.split(',').collect();
            if f[5] == train && f[3] == rail && f[4] == "mu" && f[6] == last_axle.to_string() {
                let want: f64 = f[8].parse().unwrap();
                // /twin/field holds mu to 1e-4 (docs/spec/interfaces.md).
                let got = field["mu"][site_point[f[2]]].as_f64().unwrap();
                assert!(
                    (got - want).abs() <= 0.5e-4 + 1e-12,
                    "{train} {rail} {}: field {got} vs reference {want}",
                    f[2]
                );
                checked += 1;
                chosen.get_or_insert(field.clone());
            }
        }
    }
    assert!(checked > 0, "no measured last axle to tie the field to");

    // The rerun recording verifies, and its mu field for that pass is the same.
    let field = chosen.unwrap();
    let expect = serde_json::json!({
        "rail": field["rail"], "band": field["band"], "wheel_pass": field["wheel_pass"],
        "mu": field["mu"], "mu_rounded": 1e-4, "d_m": section["grid_d_m"],
        "section": {
            "length_m": section["length_m"],
            "curve_radius_m": section["curve_radius_m"],
            "rails": section["rails"],
        },
        "blueprint": true,
    });
    let expect_path = dir.path().join("expected.json");
    std::fs::write(&expect_path, expect.to_string()).unwrap();
    let check = python(
        "check_rrd.py",
        &[rrd_out.as_os_str(), expect_path.as_os_str()],
    );
    assert!(
        check.status.success(),
        "{}{}",
        String::from_utf8_lossy(&check.stdout),
        String::from_utf8_lossy(&check.stderr)
    );
}

/// Runs a replay that must fail with status 2; returns stderr.
fn replay_fails(recording: &Path, extra: &[&str], dir: &Path) -> String {
    let (mcap_out, rrd_out, state_out) =
        (dir.join("o.mcap"), dir.join("o.rrd"), dir.join("o.state"));
    let out = tortwin()
        .arg("replay")
        .arg(recording)
        .args([
            "--out-mcap".as_ref(),
            mcap_out.as_os_str(),
            "--out-rrd".as_ref(),
            rrd_out.as_os_str(),
        ])
        .args(["--state-out".as_ref(), state_out.as_os_str()])
        .args(extra)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    let left: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    for f in &left {
        let name = f.to_string_lossy();
        assert!(
            !name.starts_with("o.") && !name.contains("partial"),
            "left behind: {name} ({stderr})"
        );
    }
    stderr
}

#[test]
fn bad_input_exits_2_and_leaves_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("out");
    std::fs::create_dir(&work).unwrap();

    // A truncated recording.
    let bytes = std::fs::read(reference("tangent_day.mcap")).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let msg = replay_fails(&cut, &[], &work);
    assert!(msg.contains("cut.mcap"), "{msg}");

    // A missing recording.
    let msg = replay_fails(&dir.path().join("nope.mcap"), &[], &work);
    assert!(msg.contains("nope.mcap"), "{msg}");

    // A configuration with an unknown key and one with a value out of range.
    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, "[product]\nkm3 = 1.0\n").unwrap();
    let msg = replay_fails(
        &reference("tangent_day.mcap"),
        &["--config", cfg.to_str().unwrap()],
        &work,
    );
    assert!(msg.contains("km3") && msg.contains("bad.toml"), "{msg}");
    std::fs::write(&cfg, "[effects.rail_ageing]\ntau_s = -1\n").unwrap();
    let msg = replay_fails(
        &reference("tangent_day.mcap"),
        &["--config", cfg.to_str().unwrap()],
        &work,
    );
    assert!(msg.contains("effects.rail_ageing.tau_s"), "{msg}");

    // A usage error.
    let out = tortwin()
        .args(["replay", "--no-such-flag"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));

    // Two outputs on one path, whichever two.
    let same = work.join("same");
    for pair in [
        ["--out-mcap", "--out-rrd"],
        ["--out-mcap", "--state-out"],
        ["--out-rrd", "--state-out"],
    ] {
        let out = tortwin()
            .arg("replay")
            .arg(reference("tangent_day.mcap"))
            .args([
                pair[0].as_ref(),
                same.as_os_str(),
                pair[1].as_ref(),
                same.as_os_str(),
            ])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{pair:?}: {stderr}");
        assert!(
            stderr.contains("two outputs would be written to"),
            "{stderr}"
        );
        assert!(!same.exists(), "{pair:?}");
    }
}

#[test]
fn a_message_error_mid_recording_names_topic_time_and_index() {
    // Rewrite tangent_day with one pulse's mass made negative, half way through.
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.mcap");
    let mut index = 0;
    let mut pulses = 0;
    let mut spoiled = None;
    copy_recording(&reference("tangent_day.mcap"), &bad, |m| {
        if m.topic == "/applicator/pulse" {
            pulses += 1;
            if pulses == 1000 {
                let mut v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                v["mass_g"] = serde_json::json!(-0.1);
                m.data = serde_json::to_vec(&v).unwrap();
                spoiled = Some((index, m.log_time));
            }
        }
        index += 1;
        true
    });
    let (index, log_time) = spoiled.unwrap();
    let work = dir.path().join("out");
    std::fs::create_dir(&work).unwrap();
    let msg = replay_fails(&bad, &[], &work);
    assert!(msg.contains("/applicator/pulse"), "{msg}");
    assert!(msg.contains(&log_time.to_string()), "{msg}");
    assert!(msg.contains(&format!("message index {index}")), "{msg}");
    assert!(msg.contains("mass_g"), "{msg}");
}

/// A reader that stops early (`tortwin replay | head -1`) is not an error of
/// the run: no panic, exit status 0.
#[test]
fn a_closed_stdout_is_not_a_panic() {
    let mut child = common::tortwin()
        .arg("replay")
        .arg(reference("tangent_day.mcap"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
}

/// In a log (stderr not a terminal) a long command says where it is: a line
/// per stage with the elapsed time and what it counts, and the count it
/// reached; with --quiet, nothing.
#[test]
fn progress_in_a_log_is_one_line_per_stage_with_counts() {
    let recording = reference("tangent_day.mcap");
    let out = tortwin().arg("replay").arg(&recording).output().unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 2, "{stderr}");
    let stage = regex_free_parse(lines[0]);
    assert!(
        stage.1.starts_with("replaying ") && stage.1.ends_with(" to do)"),
        "{stderr}"
    );
    // The count is the file's messages, and the end line reaches it.
    let total: u64 = stage
        .1
        .rsplit_once('(')
        .and_then(|(_, n)| n.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no count in {stderr}"));
    let end = regex_free_parse(lines[1]);
    let took: f64 = end
        .1
        .trim()
        .strip_prefix(&format!("{total}/{total} done in "))
        .and_then(|t| t.strip_suffix(" s"))
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("not an end line: {stderr}"));
    // Each figure is rounded to 0.1 s.
    assert!((took - (end.0 - stage.0)).abs() <= 0.15, "{stderr}");
    let quiet = tortwin()
        .arg("replay")
        .arg(&recording)
        .arg("-q")
        .output()
        .unwrap();
    assert!(quiet.stderr.is_empty() && quiet.stdout.is_empty());
}

/// `[   12.3 s] text` as (12.3, "text").
fn regex_free_parse(line: &str) -> (f64, String) {
    let (head, text) = line
        .strip_prefix('[')
        .and_then(|l| l.split_once(" s] "))
        .unwrap_or_else(|| panic!("not a stage line: {line:?}"));
    (head.trim().parse().unwrap(), text.to_string())
}

/// The MCAP project's conformance files (crates/recording/tests/
/// mcap-conformance): none is a tortwin recording.
#[path = "../crates/recording/tests/support/conformance.rs"]
mod conformance;

fn conformance_files() -> Vec<PathBuf> {
    conformance::conformance_files(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("crates/recording/tests/mcap-conformance/data"),
    )
}

#[test]
fn tortwin_replay_refuses_every_conformance_file_clearly() {
    let dir = tempfile::tempdir().unwrap();
    for path in conformance_files() {
        let out = tortwin()
            .arg("replay")
            .arg(&path)
            .arg("--out-mcap")
            .arg(dir.path().join("out.mcap"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{}: {stderr}", path.display());
        assert!(
            stderr.contains(&*path.to_string_lossy())
                && stderr.contains("the recording has no /section message"),
            "{}: {stderr}",
            path.display()
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        0,
        "nothing written"
    );
}

/// Runs `cmd` to its end, or fails the test after two minutes (a replay of
/// a reference day takes a fraction of a second).
fn output_within_two_minutes(cmd: &mut std::process::Command) -> std::process::Output {
    let mut child = cmd
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while child.try_wait().unwrap().is_none() {
        if std::time::Instant::now() > deadline {
            child.kill().unwrap();
            panic!("still running after two minutes: {cmd:?}");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// The layout pass runs beside the replay of a short recording on a thread
/// of its own: with rayon's pool only the thread that replays (one core,
/// or RAYON_NUM_THREADS=1) the replay still ends, with the same state.
#[test]
fn a_replay_with_one_thread_in_the_pool_ends_with_the_same_state() {
    let dir = tempfile::tempdir().unwrap();
    let mut states = Vec::new();
    for threads in ["1", "2"] {
        let state = dir.path().join(format!("state-{threads}.json"));
        let out = output_within_two_minutes(
            tortwin()
                .env("RAYON_NUM_THREADS", threads)
                .arg("replay")
                .arg(reference("curve_2day.mcap"))
                .arg("--state-out")
                .arg(&state)
                .arg("-q"),
        );
        common::check(&out, &format!("replay with {threads} rayon threads"));
        states.push(std::fs::read_to_string(&state).unwrap());
    }
    assert_eq!(states[0], states[1]);
}

/// Beside the replay, what the layout pass finds wrong with the recording
/// is the error even when the replay stops first on one of its own (a
/// state from another section), as it was when the pass came first.
#[test]
fn a_broken_chunk_is_the_error_before_a_state_that_does_not_fit() {
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("out");
    std::fs::create_dir(&work).unwrap();
    // A state of the tangent's section, for the curve.
    let state = dir.path().join("tangent.json");
    let out = tortwin()
        .arg("replay")
        .arg(reference("tangent_day.mcap"))
        .arg("--state-out")
        .arg(&state)
        .arg("-q")
        .output()
        .unwrap();
    common::check(&out, "the tangent's replay");
    let state_in = ["--state-in", state.to_str().unwrap()];
    let sound = reference("curve_2day.mcap");
    let msg = replay_fails(&sound, &state_in, &work);
    assert!(msg.contains("tangent.json"), "{msg}");
    // The curve's last chunk's CRC broken (bytes 24..28 of a chunk's body).
    let mut bytes = std::fs::read(&sound).unwrap();
    let (mut offset, mut last) = (8, None);
    loop {
        let len = u64::from_le_bytes(bytes[offset + 1..offset + 9].try_into().unwrap()) as usize;
        match bytes[offset] {
            0x06 => last = Some(offset),
            0x0f => break,
            _ => {}
        }
        offset += 9 + len;
    }
    let last = last.expect("a chunk");
    bytes[last + 9 + 24] ^= 0xff;
    let broken = dir.path().join("broken.mcap");
    std::fs::write(&broken, &bytes).unwrap();
    let msg = replay_fails(&broken, &state_in, &work);
    assert!(
        msg.contains(&format!("unreadable chunk at byte {last}")),
        "{msg}"
    );
    let msg = replay_fails(&broken, &[], &work);
    assert!(
        msg.contains(&format!("unreadable chunk at byte {last}")),
        "{msg}"
    );
}
