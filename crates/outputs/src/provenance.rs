//! Where an output came from: the input files (name, size, sha256), the
//! effective model configuration, the tortwin version and the command line.
//!
//! Every output carries it (docs/spec/interfaces.md, "Provenance"): the MCAP
//! output as a `provenance` metadata record and the configuration as the
//! attachment `model.toml`; the rerun recording as the recording property
//! `provenance`; report.json and strategy.json as a `provenance` object. A
//! result found months later can so be traced to the bytes and the model
//! that made it, and rerun with the same configuration.

use std::collections::BTreeMap;
use std::io::Read as _;
use std::path::Path;

use serde::Serialize;
use sha2::{Digest as _, Sha256};
use tortwin_model::config::ModelConfig;
use tortwin_recording::error::InputError;

/// One input file of a run.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct InputFile {
    /// The path as the user gave it.
    pub path: String,
    /// The same file as an absolute path (where the run was started).
    pub absolute_path: String,
    pub bytes: u64,
    /// Lower-case hex.
    pub sha256: String,
}

impl InputFile {
    /// Reads `path` once to hash it.
    pub fn hash(path: &Path) -> Result<Self, InputError> {
        let fail = |e: std::io::Error| InputError::file(path, format!("cannot read it: {e}"));
        let mut file = std::fs::File::open(path).map_err(fail)?;
        let mut hasher = Sha256::new();
        let mut buffer = vec![0u8; 1 << 16];
        let mut bytes = 0u64;
        loop {
            let n = file.read(&mut buffer).map_err(fail)?;
            if n == 0 {
                break;
            }
            bytes += n as u64;
            hasher.update(&buffer[..n]);
        }
        let sha256 = hasher
            .finalize()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        Ok(Self {
            path: path.display().to_string(),
            absolute_path: std::path::absolute(path)
                .unwrap_or_else(|_| path.to_path_buf())
                .display()
                .to_string(),
            bytes,
            sha256,
        })
    }
}

/// Where an output came from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Provenance {
    /// `tortwin X.Y.Z`.
    pub tool: String,
    /// The process's arguments, the program first.
    pub command_line: Vec<String>,
    pub inputs: Vec<InputFile>,
    /// The configuration the run used (the defaults with the user's
    /// overlay applied), as TOML that `--config` reads back.
    pub model_toml: String,
}

impl Provenance {
    /// The provenance of a run of this process on `inputs` with `config`.
    pub fn of_run(inputs: &[&Path], config: &ModelConfig) -> Result<Self, InputError> {
        Ok(Self {
            tool: format!("tortwin {}", env!("CARGO_PKG_VERSION")),
            command_line: std::env::args_os()
                .map(|a| a.to_string_lossy().into_owned())
                .collect(),
            inputs: inputs
                .iter()
                .map(|p| InputFile::hash(p))
                .collect::<Result<_, _>>()?,
            model_toml: config.to_toml(),
        })
    }

    /// The command line as one shell-readable line (arguments with spaces
    /// or quotes in single quotes).
    pub fn command(&self) -> String {
        self.command_line
            .iter()
            .map(|a| {
                if !a.is_empty()
                    && a.chars()
                        .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
                {
                    a.clone()
                } else {
                    format!("'{}'", a.replace('\'', r"'\''"))
                }
            })
            .collect::<Vec<_>>()
            .join(" ")
    }

    /// As flat string pairs (an MCAP metadata record, rerun properties):
    /// `tool`, `command_line`, `model_toml`, and per input `k`
    /// `input.k.path`, `input.k.absolute_path`, `input.k.bytes`,
    /// `input.k.sha256`.
    pub fn to_pairs(&self) -> BTreeMap<String, String> {
        let mut pairs = BTreeMap::from([
            ("tool".to_owned(), self.tool.clone()),
            ("command_line".to_owned(), self.command()),
            ("model_toml".to_owned(), self.model_toml.clone()),
        ]);
        for (k, input) in self.inputs.iter().enumerate() {
            pairs.insert(format!("input.{k}.path"), input.path.clone());
            pairs.insert(
                format!("input.{k}.absolute_path"),
                input.absolute_path.clone(),
            );
            pairs.insert(format!("input.{k}.bytes"), input.bytes.to_string());
            pairs.insert(format!("input.{k}.sha256"), input.sha256.clone());
        }
        pairs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hashes_a_file_as_sha256sum_does() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("abc.txt");
        std::fs::write(&path, b"abc").unwrap();
        let input = InputFile::hash(&path).unwrap();
        // FIPS 180-2, appendix B.1.
        assert_eq!(
            input.sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        assert_eq!(input.bytes, 3);
        assert!(Path::new(&input.absolute_path).is_absolute());
        let missing = InputFile::hash(&dir.path().join("nope")).unwrap_err();
        assert!(missing.to_string().contains("nope"), "{missing}");
    }

    #[test]
    fn quotes_only_what_a_shell_would_split() {
        let p = Provenance {
            tool: "tortwin 0".into(),
            command_line: vec![
                "tortwin".into(),
                "replay".into(),
                "my logs/a.mcap".into(),
                "it's".into(),
                "--out-rrd=out/a.rrd".into(),
            ],
            inputs: vec![],
            model_toml: String::new(),
        };
        assert_eq!(
            p.command(),
            r"tortwin replay 'my logs/a.mcap' 'it'\''s' --out-rrd=out/a.rrd"
        );
        assert_eq!(p.to_pairs()["command_line"], p.command());
    }
}
