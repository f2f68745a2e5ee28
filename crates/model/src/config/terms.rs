//! `[[effects.generic]]`: one table per generic term (effects.md "Generic
//! terms", interfaces.md). The table is flat: `acts_on`, the scope keys,
//! `driver`, `form` and the form's parameters, or `offset` for a term on
//! `measurement`. [`GenericTerm`] is the parsed, checked term; it writes
//! itself back as the same flat table (model.toml, the state file).

use serde::{Deserialize, Serialize};

use crate::generic::{ActsOn, Driver, Form, FormKind, FACTOR_MAX, OFFSET_MAX};
use crate::Quantity;

/// What a term does: a factor `g(x)` or, on `measurement`, an offset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TermEffect {
    /// For `driver = time` the step's `x0` is the threshold in seconds since
    /// the Unix epoch (`t0_utc` in the table).
    Factor {
        driver: Driver,
        form: Form,
    },
    Offset {
        offset: f64,
    },
}

/// One generic term, checked: the names in its scope are checked against a
/// section by the engine (`tortwin_engine::terms::check_terms_against`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawTerm", into = "RawTerm")]
pub struct GenericTerm {
    pub acts_on: ActsOn,
    pub applicator: Option<String>,
    pub rail: Option<String>,
    pub site: Option<String>,
    pub quantity: Option<Quantity>,
    pub effect: TermEffect,
}

/// The flat table as written.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTerm {
    acts_on: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    applicator: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    rail: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    site: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    quantity: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    driver: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    form: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    beta: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    n: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    gamma: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    x0: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    t0_utc: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    f: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    offset: Option<f64>,
}

/// A problem with one key of a term: (key, message).
pub type TermError = (String, String);

/// How a [`TermError`] reads where serde reports it (the state file).
pub(crate) struct TermErrorText(TermError);

impl std::fmt::Display for TermErrorText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: {}", self.0 .0, self.0 .1)
    }
}

pub fn err(key: &str, message: impl Into<String>) -> TermError {
    (key.to_string(), message.into())
}

/// `t0_utc` as seconds since the Unix epoch.
fn parse_utc(text: &str) -> Result<f64, TermError> {
    let t = chrono::DateTime::parse_from_rfc3339(text).map_err(|e| {
        err(
            "t0_utc",
            format!("`{text}` is not an RFC 3339 time such as \"2024-04-16T12:00:00Z\": {e}"),
        )
    })?;
    Ok(t.timestamp() as f64 + f64::from(t.timestamp_subsec_nanos()) * 1e-9)
}

/// Seconds since the Unix epoch as RFC 3339 UTC (to the microsecond, trailing
/// zeros dropped).
pub fn format_utc(unix_s: f64) -> String {
    let micros = (unix_s * 1e6).round() as i64;
    let secs = micros.div_euclid(1_000_000);
    let nanos = (micros.rem_euclid(1_000_000) * 1000) as u32;
    chrono::DateTime::from_timestamp(secs, nanos).map_or_else(
        || format!("{unix_s} s"),
        |t| t.to_rfc3339_opts(chrono::SecondsFormat::AutoSi, true),
    )
}

impl GenericTerm {
    /// Whether the term changes nothing: a factor whose form is neutral
    /// ([`crate::generic::Form::is_neutral`]) or an offset of 0.
    pub fn is_neutral(&self) -> bool {
        match self.effect {
            TermEffect::Factor { form, .. } => form.is_neutral(),
            TermEffect::Offset { offset } => offset == 0.0,
        }
    }

    /// Parses one `[[effects.generic]]` table; the error names the key.
    pub(crate) fn from_toml(value: toml::Value) -> Result<Self, TermError> {
        let raw = RawTerm::deserialize(value).map_err(|e| {
            let message = e.message().to_string();
            // "unknown field `x`, expected one of ..." / "missing field `x`"
            let key = message
                .split('`')
                .nth(1)
                .map_or_else(|| "-".to_string(), str::to_string);
            (key, message)
        })?;
        Self::from_raw(raw)
    }

    /// The scope's key/value pairs, in the order of effects.md.
    pub fn scope(&self) -> Vec<(&'static str, String)> {
        let mut scope = Vec::new();
        if let Some(a) = &self.applicator {
            scope.push(("applicator", a.clone()));
        }
        if let Some(r) = &self.rail {
            scope.push(("rail", r.clone()));
        }
        if let Some(s) = &self.site {
            scope.push(("site", s.clone()));
        }
        if let Some(q) = self.quantity {
            scope.push(("quantity", q.as_str().to_string()));
        }
        scope
    }

    /// The term's parameters by their names in the table (`t0_utc` as a
    /// string is not among them: see [`GenericTerm::t0_utc`]).
    pub fn params(&self) -> Vec<(&'static str, f64)> {
        match self.effect {
            TermEffect::Offset { offset } => vec![("offset", offset)],
            TermEffect::Factor { driver, form } => match form {
                Form::Exp { beta } => vec![("beta", beta)],
                Form::Power { n } => vec![("n", n)],
                Form::Linear { gamma } => vec![("gamma", gamma)],
                Form::Step { x0, f } if driver == Driver::Time => {
                    let _ = x0;
                    vec![("f", f)]
                }
                Form::Step { x0, f } => vec![("x0", x0), ("f", f)],
            },
        }
    }

    /// A time step's threshold as RFC 3339 UTC.
    pub fn t0_utc(&self) -> Option<String> {
        match self.effect {
            TermEffect::Factor {
                driver: Driver::Time,
                form: Form::Step { x0, .. },
            } => Some(format_utc(x0)),
            _ => None,
        }
    }

    /// Ranges of the parameters: every one finite, a step's `f` >= 0.
    pub(crate) fn check(&self) -> Result<(), TermError> {
        for (name, v) in self.params() {
            if !v.is_finite() {
                return Err(err(name, format!("is {v:?}; a finite number is required")));
            }
            if name == "f" && !(0.0..=FACTOR_MAX).contains(&v) {
                return Err(err(
                    name,
                    format!("is {v:?}; it must be within 0 and {FACTOR_MAX:e} (a factor)"),
                ));
            }
            if name == "offset" && v.abs() > OFFSET_MAX {
                return Err(err(
                    name,
                    format!(
                        "is {v:?}; it must be within -{OFFSET_MAX} and {OFFSET_MAX} (no reading \
                         lies beyond +-10: docs/spec/recording-format.md \"Limits\")"
                    ),
                ));
            }
        }
        if let TermEffect::Factor {
            form: Form::Step { x0, .. },
            ..
        } = self.effect
        {
            if !x0.is_finite() {
                return Err(err("x0", format!("is {x0}; a finite number is required")));
            }
        }
        Ok(())
    }
}

impl TryFrom<RawTerm> for GenericTerm {
    type Error = TermErrorText;

    fn try_from(raw: RawTerm) -> Result<Self, TermErrorText> {
        Self::from_raw(raw).map_err(TermErrorText)
    }
}

impl GenericTerm {
    fn from_raw(raw: RawTerm) -> Result<Self, TermError> {
        let acts_on = ActsOn::from_name(&raw.acts_on).ok_or_else(|| {
            let names: Vec<&str> = ActsOn::ALL.iter().map(|a| a.name()).collect();
            err(
                "acts_on",
                format!(
                    "unknown `{}`; expected one of {}",
                    raw.acts_on,
                    names.join(", ")
                ),
            )
        })?;
        let allowed = acts_on.scope_keys();
        for (key, present) in [
            ("applicator", raw.applicator.is_some()),
            ("rail", raw.rail.is_some()),
            ("site", raw.site.is_some()),
            ("quantity", raw.quantity.is_some()),
        ] {
            if present && !allowed.contains(&key) {
                return Err(err(
                    key,
                    format!(
                        "not a scope key of a `{}` term (its scope keys: {})",
                        acts_on.name(),
                        allowed.join(", ")
                    ),
                ));
            }
        }
        let quantity = match raw.quantity.as_deref() {
            None => None,
            Some("mu") => Some(Quantity::Mu),
            Some("adhesion") => Some(Quantity::Adhesion),
            Some("rail_mu") => Some(Quantity::RailMu),
            Some(q) => {
                return Err(err(
                    "quantity",
                    format!("unknown quantity `{q}`; expected mu, adhesion or rail_mu"),
                ))
            }
        };
        // Every parameter key given, to refuse those the form does not take.
        let given: Vec<(&str, bool)> = vec![
            ("beta", raw.beta.is_some()),
            ("n", raw.n.is_some()),
            ("gamma", raw.gamma.is_some()),
            ("x0", raw.x0.is_some()),
            ("t0_utc", raw.t0_utc.is_some()),
            ("f", raw.f.is_some()),
            ("offset", raw.offset.is_some()),
        ];
        let refuse_others = |takes: &[&str], what: &str| -> Result<(), TermError> {
            match given
                .iter()
                .find(|(key, present)| *present && !takes.contains(key))
            {
                Some((key, _)) => Err(err(
                    key,
                    format!("not a parameter of {what} (it takes {})", takes.join(", ")),
                )),
                None => Ok(()),
            }
        };
        let need = |key: &str, v: Option<f64>| v.ok_or_else(|| err(key, "missing parameter"));
        let effect = if acts_on == ActsOn::Measurement {
            for (key, present) in [
                ("driver", raw.driver.is_some()),
                ("form", raw.form.is_some()),
            ] {
                if present {
                    return Err(err(
                        key,
                        "a `measurement` term has no driver or form: its one parameter is `offset`",
                    ));
                }
            }
            refuse_others(&["offset"], "a `measurement` term")?;
            TermEffect::Offset {
                offset: need("offset", raw.offset)?,
            }
        } else {
            let driver_name = raw
                .driver
                .as_deref()
                .ok_or_else(|| err("driver", "missing"))?;
            let driver = Driver::from_name(driver_name).ok_or_else(|| {
                let names: Vec<&str> = Driver::ALL.iter().map(|d| d.name()).collect();
                err(
                    "driver",
                    format!(
                        "unknown `{driver_name}`; expected one of {}",
                        names.join(", ")
                    ),
                )
            })?;
            if acts_on == ActsOn::PulseMass && driver.is_wheel() {
                return Err(err(
                    "driver",
                    format!(
                        "`{}` has no value at a pulse: a `pulse_mass` term takes time or a weather driver",
                        driver.name()
                    ),
                ));
            }
            let form_name = raw.form.as_deref().ok_or_else(|| err("form", "missing"))?;
            let kind = FormKind::from_name(form_name).ok_or_else(|| {
                err(
                    "form",
                    format!("unknown `{form_name}`; expected exp, power, linear or step"),
                )
            })?;
            if !driver.allows(kind) {
                return Err(err(
                    "form",
                    format!(
                        "`{}` is not a form for driver `{}` (time takes only step; power is not for precipitation_mm_h or time)",
                        kind.name(),
                        driver.name()
                    ),
                ));
            }
            let what = format!("form `{}`", kind.name());
            let form = match kind {
                FormKind::Exp => {
                    refuse_others(&["beta"], &what)?;
                    Form::Exp {
                        beta: need("beta", raw.beta)?,
                    }
                }
                FormKind::Power => {
                    refuse_others(&["n"], &what)?;
                    Form::Power {
                        n: need("n", raw.n)?,
                    }
                }
                FormKind::Linear => {
                    refuse_others(&["gamma"], &what)?;
                    Form::Linear {
                        gamma: need("gamma", raw.gamma)?,
                    }
                }
                FormKind::Step if driver == Driver::Time => {
                    refuse_others(&["t0_utc", "f"], "a step on time")?;
                    let text = raw
                        .t0_utc
                        .as_deref()
                        .ok_or_else(|| err("t0_utc", "missing parameter"))?;
                    Form::Step {
                        x0: parse_utc(text)?,
                        f: need("f", raw.f)?,
                    }
                }
                FormKind::Step => {
                    refuse_others(&["x0", "f"], &what)?;
                    Form::Step {
                        x0: need("x0", raw.x0)?,
                        f: need("f", raw.f)?,
                    }
                }
            };
            TermEffect::Factor { driver, form }
        };
        let term = GenericTerm {
            acts_on,
            applicator: raw.applicator,
            rail: raw.rail,
            site: raw.site,
            quantity,
            effect,
        };
        term.check()?;
        Ok(term)
    }
}

impl From<GenericTerm> for RawTerm {
    fn from(t: GenericTerm) -> Self {
        let mut raw = RawTerm {
            acts_on: t.acts_on.name().to_string(),
            applicator: t.applicator.clone(),
            rail: t.rail.clone(),
            site: t.site.clone(),
            quantity: t.quantity.map(|q| q.as_str().to_string()),
            t0_utc: t.t0_utc(),
            ..RawTerm::default()
        };
        match t.effect {
            TermEffect::Offset { offset } => raw.offset = Some(offset),
            TermEffect::Factor { driver, form } => {
                raw.driver = Some(driver.name().to_string());
                raw.form = Some(form.kind().name().to_string());
                match form {
                    Form::Exp { beta } => raw.beta = Some(beta),
                    Form::Power { n } => raw.n = Some(n),
                    Form::Linear { gamma } => raw.gamma = Some(gamma),
                    Form::Step { x0, f } => {
                        if driver != Driver::Time {
                            raw.x0 = Some(x0);
                        }
                        raw.f = Some(f);
                    }
                }
            }
        }
        raw
    }
}

#[cfg(test)]
mod tests {
    use crate::config::ModelConfig;
    use crate::error::ConfigError;
    use crate::generic::{ActsOn, Driver, Form};

    use super::TermEffect;

    fn err(text: &str) -> ConfigError {
        ModelConfig::from_overlay_str(text, "bad.toml").unwrap_err()
    }

    #[test]
    fn the_interfaces_example_loads() {
        let c = ModelConfig::from_overlay_str(
            "[[effects.generic]]\nacts_on = \"consumption\"\nrail = \"low\"\n\
             driver = \"air_temperature_c\"\nform = \"linear\"\ngamma = 0.02\n\
             [[effects.generic]]\nacts_on = \"pulse_mass\"\napplicator = \"A2\"\n\
             driver = \"time\"\nform = \"step\"\nt0_utc = \"2024-05-02T08:00:00Z\"\nf = 0\n",
            "t",
        )
        .unwrap();
        let g = &c.effects.generic;
        assert_eq!(g.len(), 2);
        assert_eq!(g[0].acts_on, ActsOn::Consumption);
        assert_eq!(g[0].rail.as_deref(), Some("low"));
        assert_eq!(
            g[0].effect,
            TermEffect::Factor {
                driver: Driver::AirTemperatureC,
                form: Form::Linear { gamma: 0.02 }
            }
        );
        assert_eq!(g[1].t0_utc().as_deref(), Some("2024-05-02T08:00:00Z"));
        // 2024-05-02T08:00:00Z = 1714636800 s.
        assert_eq!(
            g[1].effect,
            TermEffect::Factor {
                driver: Driver::Time,
                form: Form::Step {
                    x0: 1_714_636_800.0,
                    f: 0.0
                }
            }
        );
        // Written back and read again: the same terms.
        let back = ModelConfig::from_overlay_str(&c.to_toml(), "round trip").unwrap();
        assert_eq!(back, c);
        let json = serde_json::to_string(&c.effects).unwrap();
        let back: crate::config::Effects = serde_json::from_str(&json).unwrap();
        assert_eq!(back, c.effects);
    }

    #[test]
    fn bad_terms_name_the_term_and_key() {
        let head = "[[effects.generic]]\nacts_on = \"consumption\"\ndriver = \"creepage\"\nform = \"power\"\nn = 0.3\n";
        let cases: &[(&str, &str)] = &[
            ("acts_on = \"moon\"\n", "effects.generic[1].acts_on"),
            ("acts_on = \"transfer\"\ndriver = \"tide\"\nform = \"exp\"\nbeta = 1\n", "effects.generic[1].driver"),
            ("acts_on = \"transfer\"\ndriver = \"speed_mps\"\nform = \"cubic\"\nbeta = 1\n", "effects.generic[1].form"),
            ("acts_on = \"transfer\"\ndriver = \"time\"\nform = \"exp\"\nbeta = 1\n", "effects.generic[1].form"),
            ("acts_on = \"transfer\"\ndriver = \"precipitation_mm_h\"\nform = \"power\"\nn = 1\n", "effects.generic[1].form"),
            ("acts_on = \"pulse_mass\"\ndriver = \"speed_mps\"\nform = \"exp\"\nbeta = 1\n", "effects.generic[1].driver"),
            ("acts_on = \"transfer\"\ndriver = \"speed_mps\"\nform = \"exp\"\n", "effects.generic[1].beta"),
            ("acts_on = \"transfer\"\ndriver = \"speed_mps\"\nform = \"exp\"\nbeta = 1\ngamma = 2\n", "effects.generic[1].gamma"),
            ("acts_on = \"transfer\"\ndriver = \"speed_mps\"\nform = \"exp\"\nbeta = nan\n", "effects.generic[1].beta"),
            ("acts_on = \"transfer\"\ndriver = \"speed_mps\"\nform = \"step\"\nx0 = 20\nf = -1\n", "effects.generic[1].f"),
            ("acts_on = \"transfer\"\ndriver = \"time\"\nform = \"step\"\nx0 = 20\nf = 1\n", "effects.generic[1].x0"),
            ("acts_on = \"transfer\"\ndriver = \"time\"\nform = \"step\"\nt0_utc = \"yesterday\"\nf = 1\n", "effects.generic[1].t0_utc"),
            ("acts_on = \"transfer\"\nsite = \"M1\"\ndriver = \"speed_mps\"\nform = \"exp\"\nbeta = 1\n", "effects.generic[1].site"),
            ("acts_on = \"measurement\"\nquantity = \"torque\"\noffset = 1\n", "effects.generic[1].quantity"),
            ("acts_on = \"measurement\"\ndriver = \"time\"\noffset = 1\n", "effects.generic[1].driver"),
            ("acts_on = \"measurement\"\nsite = \"M1\"\n", "effects.generic[1].offset"),
            ("acts_on = \"transfer\"\nnozzle = \"A1\"\n", "effects.generic[1].nozzle"),
        ];
        for (body, key) in cases {
            let e = err(&format!("{head}[[effects.generic]]\n{body}"));
            assert_eq!(e.key, *key, "{body}: {e}");
            assert!(e.to_string().contains("bad.toml"), "{e}");
        }
    }
}
