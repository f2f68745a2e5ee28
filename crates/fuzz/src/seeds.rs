//! The seed inputs, made fresh by the library itself: two small days of a
//! synthetic tangent section (every topic of the format, tribometer readings
//! out of time order), the state after the first day, its tables, and the
//! configurations the repository ships.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Parser;
use tortwin_jobs::replay::{replay, ReplayArgs};
use tortwin_jobs::synth::{synth, SynthArgs};
use tortwin_model::config::ModelConfig;
use tortwin_study::Silent;

/// The configurations of the repository, as seeds for the config target.
const CONFIG_SEEDS: [&str; 2] = [
    include_str!("../../../docs/examples/bands-rain.toml"),
    include_str!("../../../tests/reference/recordings/generic_day.config.toml"),
];

#[derive(Parser)]
struct Synth {
    #[command(flatten)]
    args: SynthArgs,
}

/// Seed files in a folder of their own (deleted with it).
pub struct Seeds {
    dir: tempfile::TempDir,
    /// Day 1 and day 2 of the same section.
    pub day1: PathBuf,
    pub day2: PathBuf,
    /// The state after day 1 (what `--state-out` writes).
    pub state1: Vec<u8>,
    /// Day 1 as tables (`tortwin export`'s inputs: section.toml and CSV).
    pub tables: PathBuf,
    /// Configuration texts: the defaults written out whole, and the files
    /// the repository ships.
    pub configs: Vec<Vec<u8>>,
}

impl Seeds {
    pub fn make() -> Result<Self> {
        let dir = tempfile::tempdir()?;
        let day = |name: &str, start: &str| -> Result<PathBuf> {
            let out = dir.path().join(name);
            let out_arg = out.display().to_string();
            let synth_args = Synth::try_parse_from([
                "synth",
                "--out",
                &out_arg,
                "--preset",
                "tangent",
                "--length-m",
                "40",
                "--trains-per-day",
                "3",
                "--weather-interval-s",
                "14400",
                "--tribometer-per-day",
                "1",
                "--measured-train-share",
                "0.4",
                "--outlier-share",
                "0.05",
                "--start",
                start,
                "--quiet",
            ])?;
            synth(&synth_args.args).with_context(|| format!("writing the seed {name}"))?;
            Ok(out)
        };
        let day1 = day("day1.mcap", "2024-04-08T00:00:00Z")?;
        let day2 = day("day2.mcap", "2024-04-09T00:00:00Z")?;
        let state = replay(&ReplayArgs::new(&day1), None, &mut [], &Silent)
            .context("replaying the seed day 1")?
            .state;
        let state1 = serde_json::to_vec_pretty(&state)?;
        let tables = dir.path().join("tables");
        tortwin_recording::tables::export::export_dir(&day1, &tables)
            .context("exporting the seed day 1 as tables")?;
        let mut configs: Vec<Vec<u8>> =
            CONFIG_SEEDS.iter().map(|c| c.as_bytes().to_vec()).collect();
        configs.push(toml::to_string(&ModelConfig::default())?.into_bytes());
        Ok(Self {
            dir,
            day1,
            day2,
            state1,
            tables,
            configs,
        })
    }

    /// The folder the seeds are in.
    pub fn folder(&self) -> &Path {
        self.dir.path()
    }

    /// The table files of day 1, by name.
    pub fn table_files(&self) -> Result<Vec<(String, Vec<u8>)>> {
        table_files(&self.tables)
    }
}

fn table_files(dir: &Path) -> Result<Vec<(String, Vec<u8>)>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name().to_string_lossy().into_owned();
        files.push((name, std::fs::read(entry.path())?));
    }
    files.sort();
    Ok(files)
}
