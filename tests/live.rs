//! `tortwin live` follows recordings while a logger writes them. The logger
//! is tests/python/live_writer.py: the Python mcap package's writer (not
//! tortwin's), 4 kB chunks, every write to the file cut in two halves with
//! a pause between, the messages paced by their log_time at [`SPEED`] times
//! real time. What the follower writes is checked by
//! tests/python/check_live.py against `tortwin replay` of the finished
//! files, message for message.
//!
//! The pace: 3 days at 10 000 times real time take 26 s of the test; the
//! issue's 100-1000 times (4.3 minutes at 1000) is the same code waiting
//! longer between polls (scripts/live-demo.sh runs it).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use common::{check, python, tortwin};

const SPEED: &str = "10000";

/// A 3-day synthetic recording of the default section, its applicator's
/// nozzle clogged from day 2 (so that the outputs hold alerts too).
fn three_days(dir: &Path) -> PathBuf {
    let rec = dir.join("rec.mcap");
    let clogged = "generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,\
                   t0_utc=2024-04-09T00:00:00Z,f=0.3";
    let o = tortwin()
        .args([
            "synth", "--days", "3", "--seed", "3", "--hidden", clogged, "--out",
        ])
        .arg(&rec)
        .arg("-q")
        .output()
        .unwrap();
    check(&o, "tortwin synth");
    rec
}

/// Starts the logger writing `input` again into `output` (a file, or with
/// `hourly` a folder of hourly files); returns once `output` exists.
fn logger(input: &Path, output: &Path, hourly: bool) -> Child {
    let python = std::env::var("TORTWIN_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/live_writer.py");
    let mut cmd = Command::new(python);
    cmd.arg(script)
        .arg(input)
        .arg(output)
        .args(["--speed", SPEED]);
    if hourly {
        cmd.arg("--hourly");
    }
    let mut child = cmd
        .spawn()
        .expect("python3 runs tests/python/live_writer.py");
    let t0 = Instant::now();
    while !output.exists() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("the logger ended before writing anything: {status}");
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "no {}",
            output.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child
}

/// `rerun --port P --save FILE` (rerun-sdk's own program, the gRPC server a
/// viewer runs), listening once this returns; and the URL to connect to.
fn rerun_server(save: &Path) -> (Child, String) {
    let python = std::env::var("TORTWIN_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let port = free_port();
    let mut server = Command::new(python);
    server
        .args(["-m", "rerun", "--port", &port.to_string(), "--save"])
        .arg(save)
        .env("CI", "1")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null());
    // The test ends the server with SIGINT, which a shell's background job
    // inherits ignored (a CI started with `&` from a script): the server
    // then never ended and the test hung. SIGINT back to its default.
    // SAFETY: between fork and exec only `signal`, async-signal-safe.
    unsafe {
        std::os::unix::process::CommandExt::pre_exec(&mut server, || {
            libc::signal(libc::SIGINT, libc::SIG_DFL);
            Ok(())
        });
    }
    let mut child = server
        .spawn()
        .expect("python3 -m rerun (pip install rerun-sdk)");
    let t0 = Instant::now();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("rerun --save ended before listening: {status}");
        }
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "rerun never listened"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    (child, format!("rerun+http://127.0.0.1:{port}/proxy"))
}

/// `tortwin live INPUT --out-dir OUT`, to which a test adds its flags.
fn live(input: &Path, out: &Path) -> Command {
    let mut cmd = tortwin();
    cmd.arg("live").arg(input).arg("--out-dir").arg(out);
    cmd
}

fn finished(mut logger: Child) {
    let status = logger.wait().unwrap();
    assert!(status.success(), "the logger failed: {status}");
}

fn replay(rec: &Path, out: &Path, state_in: Option<&Path>, state_out: Option<&Path>) {
    let mut cmd = tortwin();
    cmd.arg("replay")
        .arg(rec)
        .arg("--out-mcap")
        .arg(out)
        .arg("-q");
    if let Some(s) = state_in {
        cmd.arg("--state-in").arg(s);
    }
    if let Some(s) = state_out {
        cmd.arg("--state-out").arg(s);
    }
    check(&cmd.output().unwrap(), "tortwin replay");
}

fn check_live(live: &Path, replays: &[PathBuf], whole: Option<&Path>) {
    let mut args: Vec<PathBuf> = vec![live.to_path_buf()];
    args.extend(replays.iter().cloned());
    if let Some(w) = whole {
        args.push("--whole".into());
        args.push(w.to_path_buf());
    }
    let o = python("check_live.py", &args);
    check(&o, "check_live.py");
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
}

fn mcap_names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|n| n.ends_with(".mcap") && !n.starts_with('.'))
        .collect();
    names.sort();
    names
}

#[test]
fn a_recording_followed_while_it_is_written_gives_the_replays_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let rec = three_days(dir.path());
    let growing = dir.path().join("logger.mcap");
    // A rerun gRPC server from rerun-sdk (its `rerun` program) that saves
    // what it receives; the follower streams to it as it goes.
    let received = dir.path().join("received.rrd");
    let (mut viewer, url) = rerun_server(&received);
    let writer = logger(&rec, &growing, false);
    let out = dir.path().join("live");
    let followed = live(&growing, &out)
        .arg("--json")
        .args(["--connect", &url])
        .output()
        .unwrap();
    check(&followed, "tortwin live");
    finished(writer);
    // Ctrl-C: the server writes the rest of what it received and ends.
    let int = Command::new("kill")
        .args(["-INT", &viewer.id().to_string()])
        .status()
        .unwrap();
    assert!(int.success());
    assert!(viewer.wait().unwrap().success() || received.exists());
    let want = dir.path().join("replay.rrd");
    let o = tortwin()
        .arg("replay")
        .arg(&rec)
        .arg("--out-rrd")
        .arg(&want)
        .arg("-q")
        .output()
        .unwrap();
    check(&o, "tortwin replay --out-rrd");
    let o = python("check_rrd_same.py", &[&received, &want]);
    check(&o, "check_rrd_same.py");
    eprintln!("rerun: {}", String::from_utf8_lossy(&o.stdout));
    let stdout = String::from_utf8_lossy(&followed.stdout);
    assert!(stdout.contains("logger.mcap: 120 trains"), "{stdout}");
    // --json: a line per train and rail as its field came out.
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    // The clogged nozzle's alert, as its line, between the trains' lines.
    let (alerts, lines): (Vec<_>, Vec<_>) = lines.into_iter().partition(|l| l["kind"] == "alert");
    assert_eq!(alerts.len(), 1, "{alerts:?}");
    assert_eq!(alerts[0]["alert"]["kind"], "applicator_fade", "{alerts:?}");
    assert_eq!(lines.len(), 240, "120 trains on two rails");
    for pair in lines.chunks(2) {
        assert_eq!(pair[0]["train_id"], pair[1]["train_id"]);
        assert_eq!([&pair[0]["rail"], &pair[1]["rail"]], ["high", "low"]);
        let mu_min = pair[0]["mu_min"].as_f64().unwrap();
        assert!((0.05..=0.8).contains(&mu_min), "{}", pair[0]);
    }
    // One file per day, each complete on its own.
    assert_eq!(
        mcap_names(&out),
        [
            "logger.2024-04-08.mcap",
            "logger.2024-04-09.mcap",
            "logger.2024-04-10.mcap"
        ]
    );
    let replayed = dir.path().join("replay.mcap");
    replay(&growing, &replayed, None, None);
    check_live(&out, &[replayed], None);
}

/// A free port: the system's choice, let go for a server to take.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// `python3 tests/python/SCRIPT ARGS`, running.
fn python_child(script: &str, args: &[&std::ffi::OsStr]) -> Child {
    let python = std::env::var("TORTWIN_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/python")
        .join(script);
    Command::new(python)
        .arg(path)
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("python3 runs a script of tests/python")
}

/// Hourly files appear in a folder while the follower serves Foxglove's
/// WebSocket protocol: a client (tests/python/foxglove_client.py, the
/// `websockets` package) subscribed before the first file receives what
/// the MCAP output holds, and one connecting after the last gets the
/// section at once.
#[test]
fn hourly_recordings_in_a_folder_are_followed_one_after_the_other() {
    let dir = tempfile::tempdir().unwrap();
    let rec = three_days(dir.path());
    let hours = dir.path().join("hours");
    std::fs::create_dir(&hours).unwrap();
    let out = dir.path().join("live");
    let state = dir.path().join("live.state.json");
    let address = format!("127.0.0.1:{}", free_port());
    let url = format!("ws://{address}");
    let follower = live(&hours, &out)
        .arg("--state-out")
        .arg(&state)
        .args(["--idle-exit-s", "8", "-q", "--foxglove", &address])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let received = dir.path().join("received.json");
    let ready = dir.path().join("subscribed");
    let client = python_child(
        "foxglove_client.py",
        &[
            url.as_ref(),
            "--out".as_ref(),
            received.as_os_str(),
            "--ready".as_ref(),
            ready.as_os_str(),
        ],
    );
    let t0 = Instant::now();
    while !ready.exists() {
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "the Foxglove client never subscribed"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let writer = logger(&rec, &hours, true);
    finished(writer);
    // A viewer connecting after the last file (the follower waits 8 s for
    // another): the section comes when it subscribes.
    let late = dir.path().join("late.json");
    let o = python(
        "foxglove_client.py",
        &[
            url.as_ref(),
            "--out".as_ref(),
            late.as_os_str(),
            "--until-section".as_ref(),
            "--timeout".as_ref(),
            "6".as_ref(),
        ],
    );
    check(&o, "foxglove_client.py --until-section");
    check(&follower.wait_with_output().unwrap(), "tortwin live");
    check(&client.wait_with_output().unwrap(), "foxglove_client.py");
    let o = python("check_foxglove_ws.py", &[&received, &out]);
    check(&o, "check_foxglove_ws.py");
    eprintln!("foxglove: {}", String::from_utf8_lossy(&o.stdout));
    let late: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&late).unwrap()).unwrap();
    let all: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&received).unwrap()).unwrap();
    let last_section = all["messages"]
        .as_array()
        .unwrap()
        .iter()
        .rfind(|m| m["topic"] == "/twin/section")
        .unwrap();
    assert_eq!(late["messages"].as_array().unwrap().len(), 1, "{late}");
    assert_eq!(&late["messages"][0], last_section);
    // The replays of the hourly files one after the other, each from the
    // state the one before left.
    let parts = mcap_names(&hours);
    assert!(parts.len() > 40, "{parts:?}");
    let seq = dir.path().join("seq");
    std::fs::create_dir(&seq).unwrap();
    let mut replays = Vec::new();
    let mut prev: Option<PathBuf> = None;
    for part in &parts {
        let out = seq.join(part);
        let next = seq.join(format!("{part}.state.json"));
        replay(&hours.join(part), &out, prev.as_deref(), Some(&next));
        replays.push(out);
        prev = Some(next);
    }
    // And the replay of the recording the logger cut into hours: the same
    // trains, fields and measurements.
    let whole = dir.path().join("whole.mcap");
    replay(&rec, &whole, None, None);
    check_live(&out, &replays, Some(&whole));
    let live_state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&state).unwrap()).unwrap();
    let replay_state: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(prev.unwrap()).unwrap()).unwrap();
    assert!(
        live_state == replay_state,
        "--state-out is not the replays' state"
    );
}

#[test]
fn a_follower_killed_ten_times_continues_without_stepping_a_train_twice() {
    let dir = tempfile::tempdir().unwrap();
    let rec = three_days(dir.path());
    let growing = dir.path().join("logger.mcap");
    let writer = logger(&rec, &growing, false);
    let out = dir.path().join("live");
    let follower = || live(&growing, &out).arg("-q").spawn().unwrap();
    // Kill moments from a fixed xorshift sequence: 0.3-3 s apart, across
    // the logger's 26 s.
    let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
    let mut days_in_place = Vec::new();
    for _ in 0..10 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let wait = Duration::from_millis(300 + x % 2700);
        let mut child = follower();
        std::thread::sleep(wait);
        // SIGKILL: no clean-up runs.
        child.kill().unwrap();
        child.wait().unwrap();
        days_in_place.push(mcap_names(&out).len());
    }
    eprintln!("days in place after each kill: {days_in_place:?}");
    let o = follower().wait_with_output().unwrap();
    check(&o, "tortwin live after ten kills");
    finished(writer);
    let replayed = dir.path().join("replay.mcap");
    replay(&growing, &replayed, None, None);
    check_live(&out, &[replayed], None);
}

#[test]
fn a_follower_refuses_what_is_not_its_own_with_exit_2() {
    let dir = tempfile::tempdir().unwrap();
    let rec = three_days(dir.path());
    let out = dir.path().join("live");
    // An output folder with MCAP files but no checkpoint.
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("other.mcap"), b"").unwrap();
    let o = live(&rec, &out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("other.mcap") && err.contains("live-checkpoint.json"),
        "{err}"
    );
    std::fs::remove_file(out.join("other.mcap")).unwrap();
    // A finished recording is followed to its end; the folder is then
    // this recording's, and another input is refused.
    let o = live(&rec, &out).output().unwrap();
    check(&o, "tortwin live of a finished recording");
    let other = dir.path().join("other.mcap");
    std::fs::copy(&rec, &other).unwrap();
    let o = live(&other, &out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("continues a follower of"), "{err}");
    // Not an MCAP file: named, exit 2.
    let bad = dir.path().join("bad.mcap");
    std::fs::write(&bad, b"this is not an MCAP file at all").unwrap();
    let o = live(&bad, &dir.path().join("live-bad")).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("bad.mcap") && err.contains("magic"), "{err}");
}

#[test]
fn a_recording_its_logger_left_unfinished_ends_when_a_later_one_is_there() {
    // A logger that crashed a day into its file and began the next day's:
    // the first file stops at 60 % of its bytes, mid-record, with no end.
    let dir = tempfile::tempdir().unwrap();
    let rec = three_days(dir.path());
    let days = dir.path().join("days");
    check(
        &tortwin()
            .arg("split")
            .arg(&rec)
            .arg("--out")
            .arg(&days)
            .arg("-q")
            .output()
            .unwrap(),
        "tortwin split",
    );
    let names = mcap_names(&days);
    assert_eq!(names.len(), 3, "{names:?}");
    let folder = dir.path().join("logger");
    std::fs::create_dir(&folder).unwrap();
    let first = std::fs::read(days.join(&names[0])).unwrap();
    std::fs::write(folder.join(&names[0]), &first[..first.len() * 6 / 10]).unwrap();
    for name in &names[1..] {
        std::fs::copy(days.join(name), folder.join(name)).unwrap();
    }
    let out = dir.path().join("live");
    // Bounded: a follower that waits on the left file for ever fails here.
    let child = live(&folder, &out)
        .args(["--abandon-s", "1", "--idle-exit-s", "2"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id();
    let (done, ended) = std::sync::mpsc::channel::<()>();
    let watchdog = std::thread::spawn(move || {
        if ended.recv_timeout(Duration::from_secs(60)).is_err() {
            let _ = Command::new("kill")
                .args(["-KILL", &pid.to_string()])
                .status();
        }
    });
    let o = child.wait_with_output().unwrap();
    done.send(()).unwrap();
    watchdog.join().unwrap();
    check(&o, "tortwin live (killed after 60 s if it kept waiting)");
    let stdout = String::from_utf8_lossy(&o.stdout);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains(&format!("{} ended without its end record", names[0])),
        "{stderr}"
    );
    // The first file's whole records were stepped; the next two in full.
    let trains: Vec<u64> = stdout
        .lines()
        .filter_map(|l| l.split(": ").nth(1)?.split(' ').next()?.parse().ok())
        .collect();
    assert_eq!(trains.len(), 3, "{stdout}");
    assert!((1..40).contains(&trains[0]), "{stdout}");
    assert_eq!(trains[1..], [40, 40], "{stdout}");
    assert_eq!(mcap_names(&out).len(), 3, "{:?}", mcap_names(&out));
    // Without a later recording the follower keeps waiting: a file that
    // merely paused is not left.
    let alone = dir.path().join("alone");
    std::fs::create_dir(&alone).unwrap();
    std::fs::write(alone.join(&names[0]), &first[..first.len() * 6 / 10]).unwrap();
    let mut child = live(&alone, &dir.path().join("live-alone"))
        .args(["--abandon-s", "1", "-q"])
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_secs(3));
    assert!(child.try_wait().unwrap().is_none(), "it stopped waiting");
    child.kill().unwrap();
    child.wait().unwrap();
}
