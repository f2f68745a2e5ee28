//! An alert as JSON: the `/twin/alert` message (schema
//! `schemas/tortwin/alert.json`), `live --json`'s line and what `live`
//! POSTs, the same object everywhere.

use serde_json::{Map, Value};
use tortwin_engine::sink::Alert;

/// The level a person reads: `error` (braking risk raised), `warning`
/// (another alert raised) or `info` (cleared).
pub fn level(alert: &Alert) -> &'static str {
    match (alert.error, alert.state) {
        (_, tortwin_engine::alerts::AlertState::Cleared) => "info",
        (true, _) => "error",
        (false, _) => "warning",
    }
}

/// The alert's JSON object; `None` if an evidence value is not a finite
/// number (JSON has none; the caller names it).
pub fn alert_json(alert: &Alert) -> Result<Map<String, Value>, &'static str> {
    let mut o = Map::new();
    o.insert("kind".into(), alert.kind.as_str().into());
    o.insert("state".into(), alert.state.as_str().into());
    o.insert("level".into(), level(alert).into());
    let optional = [
        ("applicator_id", &alert.applicator_id),
        ("site_id", &alert.site_id),
        ("rail", &alert.rail),
        ("band", &alert.band),
        ("train_id", &alert.train_id),
    ];
    for (key, value) in optional {
        if let Some(v) = value {
            o.insert(key.into(), v.as_str().into());
        }
    }
    if let Some(q) = alert.quantity {
        o.insert("quantity".into(), q.as_str().into());
    }
    if !alert.sites.is_empty() {
        o.insert("sites".into(), alert.sites.clone().into());
    }
    o.insert("message".into(), alert.message.as_str().into());
    let mut evidence = Map::new();
    for &(name, value) in &alert.evidence {
        let number = serde_json::Number::from_f64(value).ok_or(name)?;
        evidence.insert(name.into(), Value::Number(number));
    }
    o.insert("evidence".into(), Value::Object(evidence));
    Ok(o)
}
