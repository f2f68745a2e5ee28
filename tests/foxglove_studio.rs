//! tortwin's MCAP output opened in a real Foxglove app: Foxglove Studio
//! 1.48 (the npm package `@foxglove/studio-base` 1.48.0, the app prebuilt;
//! the base of Lichtblick), headless in Debian's Chromium, driven by
//! tests/js/studio/open.js through puppeteer-core, with the Studio-format
//! layout shipped in docs/foxglove. .ci/run installs Chromium and the npm
//! packages.
//!
//! The replay output of the bundled day must open with an empty Problems
//! list, no panel in error, every plot drawing its series, the 3D view
//! showing the track near the panel's middle and the log showing rows.
//! The same file with one schema in the form that made Studio drop the
//! topic (issue 36: an `enum` without a `type`) must fail, for that reason.
//! The bundled input recording must open with an empty Problems list.
//!
//! `TORTWIN_STUDIO_SCREENSHOTS=DIR` keeps the screenshots of the passing
//! run there (the README's are docs/foxglove/screenshots/, taken so).

mod common;

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::{Arc, Mutex};

use common::demo_day;

/// One browser at a time: the app loads a 56 MB script and draws in
/// software, and two at once on two cores only make each one late.
static ONE_BROWSER: Mutex<()> = Mutex::new(());

/// `node tests/js/studio/open.js`: the app's verdict on `mcap` opened with
/// the shipped Studio layout at its last message.
fn open_in_studio(mcap: &Path, screenshots: &Path, timeout_s: u32, problems_only: bool) -> Output {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let bytes = std::fs::read(mcap).unwrap();
    let end_ns = mcap::Summary::read(&bytes)
        .unwrap()
        .and_then(|s| s.stats)
        .expect("the output has a statistics record")
        .message_end_time;
    // Rounded up to the microsecond, so that the last message is shown.
    let end = chrono::DateTime::from_timestamp_nanos(end_ns.div_ceil(1000) as i64 * 1000)
        .to_rfc3339_opts(chrono::SecondsFormat::Micros, true);
    let node = std::env::var("TORTWIN_NODE").unwrap_or_else(|_| "node".to_owned());
    let _one = ONE_BROWSER.lock().unwrap_or_else(|e| e.into_inner());
    let output = Command::new(&node)
        .arg(root.join("tests/js/studio/open.js"))
        .arg("--mcap")
        .arg(mcap)
        .arg("--layout")
        .arg(root.join("docs/foxglove/tortwin-layout-studio.json"))
        .arg("--time")
        .arg(&end)
        .arg("--screenshots")
        .arg(screenshots)
        .arg("--timeout-s")
        .arg(timeout_s.to_string())
        .args(problems_only.then_some("--problems-only"))
        .output()
        .unwrap_or_else(|e| panic!("cannot run {node} ({e}): Node.js is needed"));
    assert_ne!(
        output.status.code(),
        Some(2),
        "open.js could not run (Chromium at /usr/bin/chromium or $CHROMIUM, and \
         `npm ci --prefix tests/js`, are needed; .ci/run installs both):\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// The verdict's `failures`.
fn failures(output: &Output) -> Vec<String> {
    let verdict: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap_or_else(|e| {
        panic!(
            "open.js printed no verdict ({e}):\n{}",
            String::from_utf8_lossy(&output.stderr)
        )
    });
    verdict["failures"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap().to_owned())
        .collect()
}

#[test]
fn the_demo_output_opens_in_foxglove_studio_with_every_panel_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let out = common::replay_demo_mcap(dir.path());
    let screenshots = std::env::var_os("TORTWIN_STUDIO_SCREENSHOTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| dir.path().join("screenshots"));
    let output = open_in_studio(&out, &screenshots, 240, false);
    assert!(
        output.status.success() && failures(&output).is_empty(),
        "Foxglove Studio 1.48 does not show the demo output as it should:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    for shot in ["studio.png", "studio-Plot-siteM2.png"] {
        assert!(screenshots.join(shot).is_file(), "{shot} not taken");
    }
}

/// An input recording as tortwin writes them (the bundled day, written by
/// `tortwin synth`): Studio parses every one of its schemas.
#[test]
fn the_bundled_input_recording_opens_in_foxglove_studio_without_problems() {
    let dir = tempfile::tempdir().unwrap();
    let output = open_in_studio(&demo_day(), &dir.path().join("screenshots"), 240, true);
    assert!(
        output.status.success() && failures(&output).is_empty(),
        "Foxglove Studio 1.48 has problems with recordings/demo_day.mcap:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The demo output with `/twin/measurement`'s `quantity` an `enum` without
/// a `type`, as tortwin wrote it before issue 36.
fn with_untyped_quantity(out: &Path, broken: &Path) {
    let bytes = std::fs::read(out).unwrap();
    let mut writer = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(broken).unwrap(),
    ))
    .unwrap();
    let mut replaced: Option<Arc<mcap::Channel>> = None;
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let mut message = message.unwrap();
        if message.channel.topic == "/twin/measurement" {
            let channel = replaced.get_or_insert_with(|| {
                let schema = message.channel.schema.as_ref().unwrap();
                let mut json: serde_json::Value = serde_json::from_slice(&schema.data).unwrap();
                let quantity = &mut json["properties"]["quantity"];
                assert!(quantity["enum"].is_array(), "{quantity}");
                quantity.as_object_mut().unwrap().remove("type");
                let schema = mcap::Schema {
                    data: Cow::Owned(serde_json::to_vec(&json).unwrap()),
                    ..(**schema).clone()
                };
                Arc::new(mcap::Channel {
                    schema: Some(Arc::new(schema)),
                    ..(*message.channel).clone()
                })
            });
            message.channel = channel.clone();
        }
        writer.write(&message).unwrap();
    }
    writer.finish().unwrap();
}

#[test]
fn a_schema_studio_cannot_parse_fails_the_check() {
    let dir = tempfile::tempdir().unwrap();
    let out = common::replay_demo_mcap(dir.path());
    let broken = dir.path().join("untyped.mcap");
    with_untyped_quantity(&out, &broken);
    let output = open_in_studio(&broken, &dir.path().join("screenshots"), 90, false);
    let failures = failures(&output);
    eprintln!("what the app showed: {failures:#?}");
    assert_eq!(output.status.code(), Some(1), "{failures:?}");
    assert!(
        failures
            .iter()
            .any(|f| f.starts_with("Problems:") && f.contains("/twin/measurement")),
        "{failures:?}"
    );
    assert!(
        failures
            .iter()
            .any(|f| f.starts_with("Plot!siteM1") && f.contains("not drawn")),
        "{failures:?}"
    );
}
