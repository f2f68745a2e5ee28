//! Where a study's model configuration comes from: a TOML file or text
//! held in memory, overlaid on the built-in defaults.

use std::path::{Path, PathBuf};

use tortwin_model::config::alerts::AlertConfig;
use tortwin_model::config::ModelConfig;
use tortwin_model::error::ConfigError;

/// Where a job's model configuration comes from: the keys it changes are
/// overlaid on the built-in defaults.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigSource {
    /// A TOML file (`--config PATH`).
    File(PathBuf),
    /// TOML text held in memory (the Python package's dictionaries); `name`
    /// stands for it in error messages.
    Text { text: String, name: String },
}

impl ConfigSource {
    /// The file, when the configuration is one (for provenance and the
    /// commands a report suggests).
    pub fn path(&self) -> Option<&Path> {
        match self {
            ConfigSource::File(p) => Some(p),
            ConfigSource::Text { .. } => None,
        }
    }

    /// What error messages call it.
    pub fn name(&self) -> String {
        match self {
            ConfigSource::File(p) => p.display().to_string(),
            ConfigSource::Text { name, .. } => name.clone(),
        }
    }

    /// The defaults overlaid with this configuration.
    pub fn load(&self) -> Result<ModelConfig, ConfigError> {
        self.parse(ModelConfig::from_overlay_str)
    }

    /// `parse` of the configuration's text and name.
    fn parse<T>(
        &self,
        parse: impl FnOnce(&str, &str) -> Result<T, ConfigError>,
    ) -> Result<T, ConfigError> {
        match self {
            ConfigSource::File(p) => {
                let text = tortwin_outputs::files::read_text_input(
                    p,
                    tortwin_outputs::files::MAX_TEXT_INPUT_BYTES,
                )
                .map_err(|e| ConfigError {
                    source_name: p.display().to_string(),
                    key: "-".into(),
                    message: format!("cannot read: {e}"),
                })?;
                parse(&text, &p.display().to_string())
            }
            ConfigSource::Text { text, name } => parse(text, name),
        }
    }
}

impl ConfigSource {
    /// The `[alerts]` table of this configuration (defaults for what it
    /// does not set).
    pub fn load_alerts(&self) -> Result<AlertConfig, ConfigError> {
        self.parse(AlertConfig::from_config_str)
    }
}

impl From<PathBuf> for ConfigSource {
    fn from(path: PathBuf) -> Self {
        ConfigSource::File(path)
    }
}

/// `--config PATH` on the command line.
impl std::str::FromStr for ConfigSource {
    type Err = std::convert::Infallible;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(ConfigSource::File(s.into()))
    }
}
