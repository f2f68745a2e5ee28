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
//! Every 3D label must lie inside the panel (no label ink at its edges).
//! A line (the 10 km example of `synth --layout`) with the layout the
//! script makes for it: the line in view with every label inside, every
//! plot drawn; its one problem is `/twin/field`, whose schema allows null
//! (docs/spec/line.md), which Studio 1.48 cannot parse.
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
    let layout = root.join("docs/foxglove/tortwin-layout-studio.json");
    open_with_layout(mcap, &layout, screenshots, timeout_s, problems_only)
}

/// [`open_in_studio`] with another Studio layout.
fn open_with_layout(
    mcap: &Path,
    layout: &Path,
    screenshots: &Path,
    timeout_s: u32,
    problems_only: bool,
) -> Output {
    open_expecting(mcap, layout, screenshots, timeout_s, problems_only, None)
}

/// [`open_with_layout`], a problem containing `expect_problem` expected
/// (listed, and no failure).
fn open_expecting(
    mcap: &Path,
    layout: &Path,
    screenshots: &Path,
    timeout_s: u32,
    problems_only: bool,
    expect_problem: Option<&str>,
) -> Output {
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
        .arg(layout)
        .arg("--time")
        .arg(&end)
        .arg("--screenshots")
        .arg(screenshots)
        .arg("--timeout-s")
        .arg(timeout_s.to_string())
        .args(problems_only.then_some("--problems-only"))
        .args(
            expect_problem
                .map(|p| ["--expect-problem", p])
                .into_iter()
                .flatten(),
        )
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

/// The 10 km example line, one day (no tribometer readings: a day's three
/// lie too sparse to draw on a day-long plot; without sites M5 and M6,
/// where both rails are dry, 7 km from the two-rail applicator, and the
/// twin's two lines coincide: the one drawn first is hidden, which the
/// check cannot tell from a series not drawn), replayed, with the Studio
/// layout scripts/foxglove_layout.py makes for its output.
#[test]
fn a_line_opens_in_foxglove_studio_with_the_line_and_its_labels_in_view() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir = tempfile::tempdir().unwrap();
    let recording = dir.path().join("line.mcap");
    let example = std::fs::read_to_string(root.join("docs/examples/line-10km.toml")).unwrap();
    let cut = example
        .find("[[sites]]\nid = \"M5\"")
        .expect("site M5 in the example");
    let layout_toml = dir.path().join("line.toml");
    std::fs::write(&layout_toml, &example[..cut]).unwrap();
    let o = common::tortwin()
        .args(["synth", "--layout"])
        .arg(&layout_toml)
        .args([
            "--trains-per-day",
            "6",
            "--tribometer-per-day",
            "0",
            "-q",
            "--out",
        ])
        .arg(&recording)
        .output()
        .unwrap();
    common::check(&o, "synth --layout");
    let out = dir.path().join("line.out.mcap");
    let o = common::tortwin()
        .arg("replay")
        .arg(&recording)
        .arg("--out-mcap")
        .arg(&out)
        .arg("-q")
        .output()
        .unwrap();
    common::check(&o, "replay of the line");
    let layout = dir.path().join("layout-studio.json");
    let o = common::python(
        root.join("scripts/foxglove_layout.py").to_str().unwrap(),
        &[
            out.as_os_str(),
            dir.path().join("layout.json").as_os_str(),
            layout.as_os_str(),
        ],
    );
    common::check(&o, "scripts/foxglove_layout.py");
    let output = open_expecting(
        &out,
        &layout,
        &dir.path().join("screenshots"),
        240,
        false,
        Some("Error in topic /twin/field"),
    );
    assert!(
        output.status.success() && failures(&output).is_empty(),
        "Foxglove Studio 1.48 does not show the line as it should:\n{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let verdict: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    let problems = verdict["problems"].as_array().unwrap();
    assert_eq!(problems.len(), 1, "{problems:?}");
    assert!(problems[0].as_str().unwrap().contains("Unsupported type"));
}
