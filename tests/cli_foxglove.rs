//! The MCAP output in Foxglove: every message on a `foxglove.*` channel
//! validates against Foxglove's own JSON Schemas (the `@foxglove/schemas`
//! npm package that .ci/run installs into tests/js, read through node by
//! tests/python/check_foxglove.py), and the layout shipped in
//! docs/foxglove names only topics, sites and rails the file has and is the
//! one scripts/foxglove_layout.py makes from the demo day today.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use common::{python, tortwin};

fn shipped_layout() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/foxglove/tortwin-layout.json")
}

/// The same panels in the export format of Foxglove Studio 1.48 and
/// Lichtblick.
fn shipped_studio_layout() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/foxglove/tortwin-layout-studio.json")
}

fn check(mcap: &Path, layout: Option<&Path>) -> std::process::Output {
    let mut args = vec![mcap.as_os_str().to_owned()];
    if let Some(layout) = layout {
        args.push("--layout".into());
        args.push(layout.as_os_str().to_owned());
    }
    let output = python("check_foxglove.py", &args);
    assert_ne!(
        output.status.code(),
        Some(3),
        "check_foxglove.py lacks a tool: pip install -r tests/python/requirements.txt and \
         npm ci --prefix tests/js\n{}",
        String::from_utf8_lossy(&output.stderr)
    );
    output
}

/// check_foxglove.py's report on a file that passes.
fn passes(mcap: &Path, layout: Option<&Path>) -> String {
    let output = check(mcap, layout);
    let stdout = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "{stdout}{}",
        String::from_utf8_lossy(&output.stderr)
    );
    stdout
}

/// check_foxglove.py fails (exit 1) and says `says`.
fn fails_saying(mcap: &Path, layout: Option<&Path>, says: &str) {
    let output = check(mcap, layout);
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains(says), "{stderr}");
}

/// An MCAP file of one JSON message on `topic`, with the schema
/// `(name, JSON Schema)`.
fn one_message_file(path: &Path, (name, schema): (&str, &[u8]), topic: &str, data: &[u8]) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut writer = mcap::Writer::new(file).unwrap();
    let schema_id = writer.add_schema(name, "jsonschema", schema).unwrap();
    let channel = writer
        .add_channel(schema_id, topic, "json", &BTreeMap::new())
        .unwrap();
    writer
        .write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: 0,
                log_time: 1,
                publish_time: 1,
            },
            data,
        )
        .unwrap();
    writer.finish().unwrap();
}

#[test]
fn foxglove_topics_validate_against_foxglove_schemas_and_the_layout_fits() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = common::replay_demo_mcap(dir.path());

    let stdout = passes(&mcap, Some(&shipped_layout()));
    // One scene per train (40 on the demo day), a log line per train and more.
    assert!(
        stdout.contains("/foxglove/track\tfoxglove.SceneUpdate\t40 messages valid"),
        "{stdout}"
    );
    assert!(stdout.contains("/foxglove/log\tfoxglove.Log"), "{stdout}");
    assert!(stdout.contains("layout: 3 topics"), "{stdout}");
    let stdout = passes(&mcap, Some(&shipped_studio_layout()));
    assert!(
        stdout.contains("layout: 3 topics, 22 plot paths, all in the file"),
        "{stdout}"
    );

    // The shipped layouts are what the script makes of this output today.
    let fresh = dir.path().join("layout.json");
    let fresh_studio = dir.path().join("layout-studio.json");
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scripts/foxglove_layout.py");
    let python = std::env::var("TORTWIN_PYTHON").unwrap_or_else(|_| "python3".to_owned());
    let out = std::process::Command::new(python)
        .arg(script)
        .arg(&mcap)
        .arg(&fresh)
        .arg(&fresh_studio)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read_to_string(&fresh).unwrap(),
        std::fs::read_to_string(shipped_layout()).unwrap(),
        "docs/foxglove/tortwin-layout.json is stale: rerun scripts/foxglove_layout.py on \
         the demo day's output"
    );
    assert_eq!(
        std::fs::read_to_string(&fresh_studio).unwrap(),
        std::fs::read_to_string(shipped_studio_layout()).unwrap(),
        "docs/foxglove/tortwin-layout-studio.json is stale: rerun scripts/foxglove_layout.py \
         on the demo day's output"
    );
}

#[test]
fn the_checker_rejects_a_broken_foxglove_message_and_a_layout_naming_a_missing_topic() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.mcap");
    let schema = std::fs::read(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("crates/outputs/schemas/foxglove/Log.json"),
    )
    .unwrap();
    // Level 9 does not exist, and `file` and `line` are missing.
    one_message_file(
        &bad,
        ("foxglove.Log", &schema),
        "/foxglove/log",
        br#"{"timestamp": {"sec": 1, "nsec": 0}, "level": 9, "message": "x", "name": "y"}"#,
    );
    fails_saying(&bad, None, "/foxglove/log message 0");
    fails_saying(&bad, None, "'file' is a required property");

    // A layout that names a topic the output does not have.
    let mcap = common::replay_demo_mcap(dir.path());
    let layout = std::fs::read_to_string(shipped_layout())
        .unwrap()
        .replace("/foxglove/log", "/foxglove/logs");
    let wrong = dir.path().join("wrong.json");
    std::fs::write(&wrong, layout).unwrap();
    fails_saying(
        &mcap,
        Some(&wrong),
        "/foxglove/logs, which the file does not have",
    );

    // The Studio format: a topic the file does not have, and a tree that
    // places a panel without a configuration.
    let studio = std::fs::read_to_string(shipped_studio_layout()).unwrap();
    let wrong = dir.path().join("wrong-studio.json");
    std::fs::write(&wrong, studio.replace("/foxglove/log", "/foxglove/logs")).unwrap();
    fails_saying(
        &mcap,
        Some(&wrong),
        "/foxglove/logs, which the file does not have",
    );
    std::fs::write(
        &wrong,
        studio.replace("\"first\": \"Tab!sites\"", "\"first\": \"Tab!site\""),
    )
    .unwrap();
    fails_saying(
        &mcap,
        Some(&wrong),
        "panel Tab!site is placed but has no configuration",
    );
}

/// The input recordings tortwin ships and writes (the bundled ones, an
/// import of the documented tables) open in Foxglove Studio 1.48 and
/// Lichtblick: every property of their schemas has one string `type`
/// (tests/python/check_mcap.py; an untyped `enum` or a `["number",
/// "null"]` type makes those apps drop the topic), every map by
/// `additionalProperties` also has `properties`, and every message
/// validates.
#[test]
fn bundled_and_imported_recordings_have_schemas_the_apps_parse() {
    let dir = tempfile::tempdir().unwrap();
    let imported = dir.path().join("imported.mcap");
    let o = tortwin()
        .arg("import")
        .arg(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("docs/examples/demo_day_tables"))
        .arg("--out")
        .arg(&imported)
        .arg("-q")
        .output()
        .unwrap();
    common::check(&o, "tortwin import");
    let mut files = vec![imported];
    let bundled = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("recordings");
    for entry in std::fs::read_dir(&bundled).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "mcap") {
            files.push(path);
        }
    }
    assert!(files.len() >= 5, "{files:?}");
    // What the rule refuses: the schemas before 2026-11-26 (a nullable
    // curve radius, a rail side as an untyped enum, a map per rail by
    // additionalProperties alone).
    let old = dir.path().join("old_schema.mcap");
    let schema = br#"{"type": "object", "properties": {
        "curve_radius_m": {"type": ["number", "null"]},
        "sides": {"type": "array", "items": {"type": "object",
            "properties": {"side": {"enum": ["high", "low"]}}}},
        "load_kN": {"type": "object", "additionalProperties": {"type": "number"}}}}"#;
    one_message_file(
        &old,
        ("tor_twin.Section", schema),
        "/section",
        br#"{"curve_radius_m": null, "sides": [{"side": "high"}]}"#,
    );
    let check = python("check_mcap.py", &[old.as_os_str()]);
    let stderr = String::from_utf8_lossy(&check.stderr);
    assert_eq!(check.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(
            "#/properties/curve_radius_m: type [\"number\", \"null\"], not a single string"
        ),
        "{stderr}"
    );
    assert!(
        stderr.contains("#/properties/sides/items/properties/side: type null"),
        "{stderr}"
    );
    assert!(
        stderr.contains("#/properties/load_kN: a map by additionalProperties without properties"),
        "{stderr}"
    );
    for file in &files {
        let check = python("check_mcap.py", &[file.as_os_str()]);
        assert!(
            check.status.success(),
            "{}: {}{}",
            file.display(),
            String::from_utf8_lossy(&check.stdout),
            String::from_utf8_lossy(&check.stderr)
        );
    }
}
