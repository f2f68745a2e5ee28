//! The `[alerts]` table of a configuration file: the thresholds of the
//! twin's alerts (docs/spec/interfaces.md, "Alerts"). It lives in the same
//! file as the model's keys but is not part of the model: the model's
//! overlay accepts the table and leaves it to [`AlertConfig::from_config_str`].

use serde::{Deserialize, Serialize};

use crate::error::ConfigError;

/// Every threshold of the alerts; every key optional in the file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AlertConfig {
    /// Alerts on (`/twin/alert`, the Log panel, `live --json`).
    pub enabled: bool,
    /// `live` POSTs each alert's JSON to this `http://` URL.
    pub post_url: Option<String>,
    pub band: BandAlerts,
    pub pulses: PulseAlerts,
    pub residual: ResidualAlerts,
    pub stuck: StuckAlerts,
    pub data_gap: GapAlerts,
}

/// mu of the simulated field outside the target band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BandAlerts {
    pub lower_mu: f64,
    pub upper_mu: f64,
    /// `friction_low`: track length below `lower_mu`, anywhere on the section.
    pub below_length_m: f64,
    /// `friction_high`: track length above `upper_mu` within the protected stretch.
    pub above_length_m: f64,
    /// Consecutive trains that raise (and, without it, clear) an alert.
    pub trains: u32,
    /// The protected stretch; by default from the first applicator to the
    /// first site beyond it (the whole section without either).
    pub from_m: Option<f64>,
    pub to_m: Option<f64>,
}

/// An applicator rail that stops pulsing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PulseAlerts {
    /// Trains in a row with no pulse from a rail that has pulsed.
    pub trains: u32,
}

/// Residual (measured − simulated) charts per site, rail and quantity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ResidualAlerts {
    /// Samples (measured trains) that set a chart's baseline.
    pub warmup: u32,
    /// CUSUM reference value, in standard deviations.
    pub k: f64,
    /// CUSUM decision interval, in standard deviations.
    pub h: f64,
    /// Another chart of the same applicator at this share of `h` on the
    /// same side makes an alarm an applicator's, not a sensor's.
    pub corroborate: f64,
    /// Samples in a row within one standard deviation that clear an alarm.
    pub clear: u32,
}

/// A sensor that repeats one value while the model moves.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StuckAlerts {
    pub readings: u32,
    /// Readings this close to the first of the run count as the same.
    pub tolerance: f64,
    /// The least range of the simulated values over those readings.
    pub model_range: f64,
}

/// A regular input (weather) that stops coming.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GapAlerts {
    /// A gap longer than this many typical intervals.
    pub factor: f64,
    /// Intervals that make the typical one (their median); they must be
    /// within 10 % of it for the input to count as regular.
    pub intervals: u32,
}

impl Default for AlertConfig {
    fn default() -> Self {
        AlertConfig {
            enabled: true,
            post_url: None,
            band: BandAlerts::default(),
            pulses: PulseAlerts::default(),
            residual: ResidualAlerts::default(),
            stuck: StuckAlerts::default(),
            data_gap: GapAlerts::default(),
        }
    }
}

impl Default for BandAlerts {
    fn default() -> Self {
        BandAlerts {
            lower_mu: 0.30,
            upper_mu: 0.40,
            below_length_m: 10.0,
            above_length_m: 10.0,
            trains: 3,
            from_m: None,
            to_m: None,
        }
    }
}

impl Default for PulseAlerts {
    fn default() -> Self {
        PulseAlerts { trains: 5 }
    }
}

impl Default for ResidualAlerts {
    fn default() -> Self {
        ResidualAlerts {
            warmup: 10,
            k: 0.5,
            h: 8.0,
            corroborate: 0.5,
            clear: 10,
        }
    }
}

impl Default for StuckAlerts {
    fn default() -> Self {
        StuckAlerts {
            readings: 20,
            tolerance: 1e-9,
            model_range: 0.01,
        }
    }
}

impl Default for GapAlerts {
    fn default() -> Self {
        GapAlerts {
            factor: 3.0,
            intervals: 8,
        }
    }
}

/// The file as far as alerts go: every other key is the model's.
#[derive(Deserialize)]
struct File {
    #[serde(default)]
    alerts: AlertConfig,
}

impl AlertConfig {
    /// The `[alerts]` table of a configuration's text (defaults for what it
    /// does not set); an unknown key or a value out of range names its
    /// dotted key.
    pub fn from_config_str(text: &str, source_name: &str) -> Result<AlertConfig, ConfigError> {
        let file: File = toml::from_str(text).map_err(|e| ConfigError {
            source_name: source_name.into(),
            key: super::overlay_error_key(&e, text),
            message: e.message().to_string(),
        })?;
        file.alerts.validate(source_name)?;
        Ok(file.alerts)
    }

    /// Checks every value's range; the error names the first bad key.
    pub fn validate(&self, source_name: &str) -> Result<(), ConfigError> {
        let bad = |key: &str, message: String| {
            Err(ConfigError {
                source_name: source_name.into(),
                key: format!("alerts.{key}"),
                message,
            })
        };
        let within = |key: &str, v: f64, lo: f64, hi: f64| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                bad(key, format!("is {v:?}; it must be within {lo} and {hi}"))
            }
        };
        let count = |key: &str, v: u32, lo: u32, hi: u32| {
            if (lo..=hi).contains(&v) {
                Ok(())
            } else {
                bad(key, format!("is {v}; it must be within {lo} and {hi}"))
            }
        };
        let b = &self.band;
        within("band.lower_mu", b.lower_mu, 0.0, 2.0)?;
        within("band.upper_mu", b.upper_mu, b.lower_mu, 2.0)?;
        within("band.below_length_m", b.below_length_m, 0.0, 1e6)?;
        within("band.above_length_m", b.above_length_m, 0.0, 1e6)?;
        count("band.trains", b.trains, 1, 10_000)?;
        if let Some(v) = b.from_m {
            within("band.from_m", v, 0.0, 1e6)?;
        }
        if let Some(v) = b.to_m {
            within("band.to_m", v, b.from_m.unwrap_or(0.0), 1e6)?;
        }
        count("pulses.trains", self.pulses.trains, 1, 10_000)?;
        let r = &self.residual;
        count("residual.warmup", r.warmup, 3, 100_000)?;
        within("residual.k", r.k, 0.0, 10.0)?;
        within("residual.h", r.h, 0.1, 1000.0)?;
        within("residual.corroborate", r.corroborate, 0.0, 1.0)?;
        count("residual.clear", r.clear, 1, 100_000)?;
        let s = &self.stuck;
        count("stuck.readings", s.readings, 2, 100_000)?;
        within("stuck.tolerance", s.tolerance, 0.0, 1.0)?;
        within("stuck.model_range", s.model_range, 0.0, 2.0)?;
        within("data_gap.factor", self.data_gap.factor, 1.0, 1e6)?;
        count("data_gap.intervals", self.data_gap.intervals, 2, 10_000)?;
        if let Some(url) = &self.post_url {
            if !url.starts_with("http://") || url.len() <= "http://".len() {
                return bad(
                    "post_url",
                    format!(
                        "is {url:?}; give an http:// URL (for https, a local relay: \
                         tortwin speaks plain HTTP/1.1)"
                    ),
                );
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_file_sets_only_its_keys_and_the_model_keys_are_left_alone() {
        let text = "[product]\ncn = 10.0\n[alerts.band]\ntrains = 4\n";
        let a = AlertConfig::from_config_str(text, "x.toml").unwrap();
        assert_eq!(a.band.trains, 4);
        assert_eq!(a.band.lower_mu, 0.30);
        assert!(a.enabled);
        let none = AlertConfig::from_config_str("[product]\ncn = 10.0\n", "x.toml").unwrap();
        assert_eq!(none, AlertConfig::default());
    }

    #[test]
    fn bad_keys_and_values_are_named() {
        let e = AlertConfig::from_config_str("[alerts.band]\ntrain = 4\n", "x.toml").unwrap_err();
        assert!(e.to_string().contains("alerts.band.train"), "{e}");
        let e =
            AlertConfig::from_config_str("[alerts.residual]\nh = -1.0\n", "x.toml").unwrap_err();
        assert!(e.to_string().contains("alerts.residual.h"), "{e}");
        let e = AlertConfig::from_config_str("[alerts]\npost_url = \"https://x\"\n", "x.toml")
            .unwrap_err();
        assert!(e.to_string().contains("alerts.post_url"), "{e}");
    }
}
