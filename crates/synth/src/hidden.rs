//! The truth configuration: the model a synthetic recording's measurements
//! come from, with the effects hidden in it (`--hidden`).

use tortwin_study::ConfigSource;

use tortwin_files::usage::UsageError;
use tortwin_model::config::ModelConfig;
use tortwin_study::Result;

/// Builds the truth configuration: the defaults, overlaid by `truth_config`
/// (a TOML file) and then by every `--hidden` effect in turn, with the
/// validation of [`ModelConfig`] (a bad effect names the key).
pub fn truth_config(truth_config: Option<&ConfigSource>, hidden: &[String]) -> Result<ModelConfig> {
    let mut cfg = match truth_config {
        Some(source) => source.load()?,
        None => ModelConfig::default(),
    };
    for spec in hidden {
        let toml = hidden_effect_toml(spec)?;
        cfg.overlay_str(&toml, &format!("--hidden {spec}"))?;
    }
    Ok(cfg)
}

/// `NAME:param=value[,param=value]` (or a bare `NAME`) as the TOML table
/// `[effects.NAME]` that switches the effect on; `generic:key=value,...` as
/// one `[[effects.generic]]` table (e.g.
/// `generic:acts_on=pulse_mass,applicator=A1,driver=time,form=step,t0_utc=2024-04-09T12:00:00Z,f=0.6`).
pub(crate) fn hidden_effect_toml(spec: &str) -> Result<String, UsageError> {
    let bare_key = |s: &str| {
        !s.is_empty()
            && s.chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
    };
    let (name, params) = match spec.split_once(':') {
        Some((name, params)) => (name.trim(), params.trim()),
        None => (spec.trim(), ""),
    };
    if !bare_key(name) {
        return Err(UsageError(format!(
            "--hidden {spec}: `{name}` is not an effect name; expected NAME or \
             NAME:param=value[,param=value], e.g. rail_ageing:tau_s=7200"
        )));
    }
    // `generic:acts_on=...,driver=...,form=...,param=value`: one more
    // `[[effects.generic]]` table, whose names are strings.
    let generic = name == "generic";
    let mut toml = if generic {
        "[[effects.generic]]\n".to_string()
    } else {
        format!("[effects.{name}]\n")
    };
    for pair in params.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let Some((key, value)) = pair.split_once('=') else {
            return Err(UsageError(format!(
                "--hidden {spec}: `{pair}` is not param=value"
            )));
        };
        let (key, value) = (key.trim(), value.trim());
        if !bare_key(key) {
            return Err(UsageError(format!(
                "--hidden {spec}: `{key}` is not a parameter name"
            )));
        }
        if generic && value.parse::<f64>().is_err() {
            toml.push_str(&format!(
                "{key} = {}\n",
                toml::Value::String(value.to_string())
            ));
            continue;
        }
        let number: f64 = value.parse().map_err(|_| {
            UsageError(format!(
                "--hidden {spec}: effects.{name}.{key} = `{value}` is not a number"
            ))
        })?;
        // `{:?}` writes a float TOML reads back exactly (inf and nan included).
        toml.push_str(&format!("{key} = {number:?}\n"));
    }
    Ok(toml)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hidden_effects_become_effect_tables() {
        assert_eq!(
            hidden_effect_toml("rail_ageing:tau_s=7200").unwrap(),
            "[effects.rail_ageing]\ntau_s = 7200.0\n"
        );
        assert_eq!(
            hidden_effect_toml("wheel_edge_reservoir:alpha=0.2, r=0.05").unwrap(),
            "[effects.wheel_edge_reservoir]\nalpha = 0.2\nr = 0.05\n"
        );
        assert_eq!(
            hidden_effect_toml("bogie_bands").unwrap(),
            "[effects.bogie_bands]\n"
        );
        assert!(hidden_effect_toml("rail_ageing:tau_s=abc").is_err());
        assert!(hidden_effect_toml("rail ageing").is_err());
        assert!(hidden_effect_toml("x]\n[product:cn=1").is_err());
        let cfg = truth_config(None, &["rail_ageing:tau_s=7200".into()]).unwrap();
        assert_eq!(
            cfg.effects
                .param(tortwin_model::effects::Named::RailAgeing, 0),
            Some(7200.0)
        );
        assert!(truth_config(None, &["rail_ageing:tau_s=-1".into()]).is_err());
        assert!(truth_config(None, &["no_such_effect".into()]).is_err());
    }
}
