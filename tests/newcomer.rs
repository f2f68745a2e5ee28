//! The README as a newcomer meets it: the repository cloned into an empty
//! temporary folder (nothing beside it), the README's first command run
//! exactly as written there, its outputs checked, then every other example
//! command of the README's `sh` blocks.
//!
//! The clone builds with its own target folder (`target/newcomer`, made
//! anew each run). That folder starts with the third-party crates this
//! build has already compiled (hard links, [`seed_with_dependencies`]), as a
//! newcomer's machine has them after the first command's first build: the
//! clone compiles every tortwin crate from its own sources, but rerun and
//! the other dependencies are not compiled a second time within CI's time
//! (a cold build of them is what CI's own build from a clean clone does).
//! The test fails if the clone's builds compile any of them again but
//! pyo3's crates, which only the extension module uses, and the crates
//! built from the clone's own sources (third_party/mcap, a patched crate)
//! with those above them, whose fingerprints name the clone's folder
//! ([`built_from_the_clone`]): that is a feature
//! set that differs from the test build's (Cargo.toml, "feature
//! alignment"), and it costs every newcomer and CI minutes. Commands
//! written with `tortwin` run the clone's own build
//! on the PATH, as `cargo install --path .` in the clone would put it. Two
//! kinds of line are not run: `bash .ci/run` (the test command, which runs
//! this test) and the viewer (`pip install rerun-sdk ... && rerun FILE`, a
//! window).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The commands of the README's ```sh blocks, in order, with `\`
/// continuations joined and `#` comments dropped.
fn readme_commands(readme: &str) -> Vec<String> {
    let mut commands = Vec::new();
    let mut in_sh = false;
    let mut pending = String::new();
    for line in readme.lines() {
        let trimmed = line.trim();
        if trimmed.starts_with("```") {
            in_sh = !in_sh && trimmed == "```sh";
            continue;
        }
        if !in_sh || trimmed.is_empty() {
            continue;
        }
        let code = match trimmed.find("  #") {
            Some(k) => trimmed[..k].trim_end(),
            None => trimmed,
        };
        if let Some(head) = code.strip_suffix('\\') {
            pending.push_str(head);
            continue;
        }
        pending.push_str(code);
        commands.push(std::mem::take(&mut pending));
    }
    commands
}

/// Runs `command` in `dir` with a newcomer's environment: this test's own
/// less the variables cargo sets for a test (`CARGO_MANIFEST_DIR`,
/// `CARGO_PKG_NAME`, ...). A newcomer's shell has none of them, and build
/// scripts that ask to run again when one changes (ring's, under rustls and
/// rerun's gRPC client) ran again in the clone and every crate above them
/// was compiled a second time.
fn run(command: &str, dir: &Path, path_var: &str, target: &Path) {
    eprintln!("$ {command}");
    let mut bash = Command::new("bash");
    for (name, _) in std::env::vars_os() {
        let name = name.to_string_lossy();
        if (name.starts_with("CARGO_") && name != "CARGO_HOME") || name == "CARGO" {
            bash.env_remove(&*name);
        }
    }
    let o = bash
        .arg("-c")
        .arg(command)
        .current_dir(dir)
        .env("PATH", path_var)
        .env("CARGO_TARGET_DIR", target)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "`{command}` failed in a fresh clone ({})\n{}\n{}",
        o.status,
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn the_readme_commands_work_in_a_fresh_clone() {
    let repository = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let empty = tempfile::tempdir().unwrap();
    let clone = empty.path().join("tortwin");
    let o = Command::new("git")
        .arg("clone")
        .arg("--quiet")
        .arg(&repository)
        .arg(&clone)
        .output()
        .expect("git is needed to clone the repository");
    common::check(&o, "git clone");

    let readme = std::fs::read_to_string(clone.join("README.md")).unwrap();
    let commands = readme_commands(&readme);
    assert_eq!(
        commands.get(1).map(String::as_str),
        Some("bash .ci/run"),
        "the README's first block is the main job and the test command: {commands:?}"
    );
    let main_job = &commands[0];
    assert!(
        main_job.starts_with("cargo run --release -- "),
        "{main_job}"
    );

    let target = PathBuf::from(env!("CARGO_BIN_EXE_tortwin"))
        .ancestors()
        .nth(2)
        .unwrap()
        .join("newcomer");
    if target.exists() {
        std::fs::remove_dir_all(&target).unwrap();
    }
    let seeded = std::time::SystemTime::now();
    seed_with_dependencies(&target);
    let bin = target.join("release");
    let path_var = format!(
        "{}:{}",
        bin.display(),
        std::env::var("PATH").unwrap_or_default()
    );

    run(main_job, &clone, &path_var, &target);
    for output in ["out/demo.mcap", "out/demo.rrd"] {
        assert!(clone.join(output).is_file(), "{output} missing");
    }
    let check = common::python(
        "check_provenance.py",
        &[
            clone.join("out/demo.mcap"),
            clone.join("recordings/demo_day.mcap"),
        ],
    );
    common::check(&check, "check_provenance.py out/demo.mcap");

    let mut ran = 1;
    for command in &commands[2..] {
        if command == "bash .ci/run" || command.contains("&& rerun ") {
            continue;
        }
        run(command, &clone, &path_var, &target);
        ran += 1;
    }
    assert!(ran >= 8, "only {ran} README commands ran: {commands:?}");
    let ours = built_from_the_clone(&clone);
    let compiled_again: Vec<String> = third_party_compiled_since(&target, seeded)
        .into_iter()
        .filter(|unit| {
            let name = unit
                .rsplit_once('-')
                .map_or(unit.as_str(), |(name, _)| name);
            !ours.contains(name)
        })
        .collect();
    assert!(
        compiled_again.is_empty(),
        "the clone's builds compiled these third-party crates again, with \
         other features than the workspace's test build (Cargo.toml, \"feature \
         alignment\"; the seed is that build's, as `cargo test --release \
         --workspace` leaves it): {compiled_again:?}"
    );
    // What the README says the commands make.
    for output in [
        "out/imported.mcap",
        "out/tables/measurements.parquet",
        "out/site/model.toml",
        "out/discover/model.toml",
        "out/clog/report.md",
        "out/strategy/strategy.json",
        "out/fleet/summary.md",
    ] {
        assert!(clone.join(output).is_file(), "{output} missing");
    }
}

/// Starts the clone's target folder `target` with this build's compiled
/// third-party crates: cargo's fingerprints and build-script outputs
/// copied, the dependencies' libraries (`lib*`: rlib, rmeta, proc-macro
/// .so) hard-linked. The workspace's own libraries (`libtortwin*`) are left
/// out, so the clone builds every tortwin crate from its sources. Where the
/// clone compiles a dependency again (a build script that reads another
/// environment, pyo3 under maturin), rustc writes a new file and the link
/// to this build's file is dropped, not written through. Made under a
/// temporary name, renamed when complete.
fn seed_with_dependencies(target: &Path) {
    let ours = PathBuf::from(env!("CARGO_BIN_EXE_tortwin"))
        .parent()
        .unwrap()
        .to_path_buf();
    let seeding = target.with_extension("seeding");
    if seeding.exists() {
        std::fs::remove_dir_all(&seeding).unwrap();
    }
    let release = seeding.join("release");
    std::fs::create_dir_all(release.join("deps")).unwrap();
    let script = r#"set -e
cp -a "$1/.fingerprint" "$1/build" "$2/"
find "$1/deps" -maxdepth 1 -type f -name 'lib*' ! -name 'libtortwin*' \
  -exec ln -t "$2/deps" {} +"#;
    let o = Command::new("bash")
        .arg("-c")
        .arg(script)
        .arg("seed")
        .arg(&ours)
        .arg(&release)
        .output()
        .unwrap();
    common::check(&o, "seeding the clone's target folder");
    std::fs::rename(&seeding, target).unwrap();
}

/// The packages of the clone's build whose units are the clone's own: those
/// built from its folders (the workspace's crates and third_party/mcap,
/// which `[patch.crates-io]` puts in the crates.io crate's place) and every
/// package that depends on one of them (foxglove on mcap). Their
/// fingerprints depend on the clone's path, so the clone compiles them
/// whatever the features; from `cargo metadata`'s resolved graph.
fn built_from_the_clone(clone: &Path) -> std::collections::BTreeSet<String> {
    let o = Command::new(env!("CARGO"))
        .args(["metadata", "--format-version", "1"])
        .current_dir(clone)
        .output()
        .expect("cargo runs");
    common::check(&o, "cargo metadata in the clone");
    let metadata: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let packages = metadata["packages"].as_array().unwrap();
    let name_of = |id: &str| {
        packages
            .iter()
            .find(|p| p["id"] == id)
            .and_then(|p| p["name"].as_str())
            .unwrap()
            .to_owned()
    };
    let mut ours: std::collections::BTreeSet<String> = packages
        .iter()
        .filter(|p| p["source"].is_null())
        .map(|p| p["id"].as_str().unwrap().to_owned())
        .collect();
    let nodes = metadata["resolve"]["nodes"].as_array().unwrap();
    loop {
        let above: Vec<String> = nodes
            .iter()
            .filter(|n| !ours.contains(n["id"].as_str().unwrap()))
            .filter(|n| {
                n["dependencies"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .any(|d| ours.contains(d.as_str().unwrap()))
            })
            .map(|n| n["id"].as_str().unwrap().to_owned())
            .collect();
        if above.is_empty() {
            break;
        }
        ours.extend(above);
    }
    ours.iter().map(|id| name_of(id)).collect()
}

/// The third-party units (cargo's fingerprint folders, `name-hash`) that a
/// build in `target` wrote after `seeded`, but pyo3's crates, which only the
/// extension module uses and the test build does not compile. The seed's
/// own fingerprints keep their times (`cp -a`).
fn third_party_compiled_since(target: &Path, seeded: std::time::SystemTime) -> Vec<String> {
    let only_the_extension = ["pyo3", "target-lexicon"];
    let mut units = Vec::new();
    for unit in std::fs::read_dir(target.join("release/.fingerprint")).unwrap() {
        let unit = unit.unwrap();
        let name = unit.file_name().to_string_lossy().into_owned();
        if name.starts_with("tortwin") || only_the_extension.iter().any(|p| name.starts_with(p)) {
            continue;
        }
        let written = std::fs::read_dir(unit.path()).unwrap().any(|f| {
            f.unwrap()
                .metadata()
                .and_then(|m| m.modified())
                .is_ok_and(|t| t >= seeded)
        });
        if written {
            units.push(name);
        }
    }
    units.sort();
    units
}

#[test]
fn the_readme_is_read_as_a_newcomer_reads_it() {
    let readme = "x\n```sh\ncargo run -- a   # comment\nbash .ci/run\n```\n```toml\nk = 1\n```\n\
                  ```sh\ntortwin b \\\n  --c d\n```\n";
    assert_eq!(
        readme_commands(readme),
        ["cargo run -- a", "bash .ci/run", "tortwin b --c d"]
    );
}
