//! The model configuration: the built-in defaults (the paper's Table 2, the
//! contact constants and Polach's dry set, `crates/model/config/default.toml`) overlaid by
//! a user's TOML file that sets only the keys it changes
//! (docs/spec/interfaces.md).
//!
//! The overlay is parsed into a mirror of [`ModelConfig`] whose fields are all
//! optional and whose tables deny unknown keys, so a misspelt key, a wrong
//! type or a missing effect parameter is a serde error that names the key.
//! Ranges are checked once, after merging, by [`ModelConfig::validate`], which
//! names the dotted key of the first bad value.

pub mod alerts;
pub mod terms;

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::contact::PolachParams;
use crate::effects::Named;
use crate::error::ConfigError;
use crate::product::{ProductKey, ProductParams};

pub use terms::{format_utc, GenericTerm, TermEffect};

/// The text of `config/default.toml`, compiled in.
pub(crate) const DEFAULT_TOML: &str = include_str!("../../config/default.toml");

/// Steel and wheel profile (contact.md, "Hertz").
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactParams {
    pub e_pa: f64,
    pub nu: f64,
    /// R_wy, the wheel's transverse profile radius; infinite = flat.
    pub wheel_profile_radius_m: f64,
}

/// Polach's creep force parameters (contact.md).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolachConfig {
    pub p_a: f64,
    pub p_b_s_per_m: f64,
    pub k_a: f64,
    pub k_s: f64,
}

impl PolachConfig {
    pub fn params(&self) -> PolachParams {
        PolachParams {
            p_a: self.p_a,
            p_b_s_per_m: self.p_b_s_per_m,
            k_a: self.k_a,
            k_s: self.k_s,
        }
    }
}

/// The candidate effects of effects.md and the generic terms: the named
/// effects that are on, each with its parameters in the order of its row in
/// [`crate::effects::EFFECTS`] (the table is their one description: name,
/// parameters, units, ranges), and the generic terms (none by default).
///
/// In TOML and JSON a named effect is a table `[effects.NAME]` of its
/// parameters (`[effects.rail_ageing]` with `tau_s = 7200.0`; an effect
/// without parameters is an empty table), and the generic terms are the
/// array of tables `[[effects.generic]]`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Effects {
    named: BTreeMap<Named, Vec<f64>>,
    /// `[[effects.generic]]`: factors outside the catalogue (effects.md,
    /// "Generic terms"), in the order they were given.
    pub generic: Vec<GenericTerm>,
}

impl Effects {
    /// The parameters of `effect` (in the order of its row), `None` if off.
    pub fn get(&self, effect: Named) -> Option<&[f64]> {
        self.named.get(&effect).map(Vec::as_slice)
    }

    /// Parameter `k` of `effect` (its row's order), `None` if off.
    pub fn param(&self, effect: Named, k: usize) -> Option<f64> {
        self.get(effect).and_then(|p| p.get(k).copied())
    }

    pub fn is_on(&self, effect: Named) -> bool {
        self.named.contains_key(&effect)
    }

    /// Switches `effect` on with `params` (in the order of its row; a
    /// missing one is NaN, which [`ModelConfig::validate`] refuses).
    pub fn set(&mut self, effect: Named, params: &[f64]) {
        let n = effect.spec().params.len();
        let values = (0..n)
            .map(|k| params.get(k).copied().unwrap_or(f64::NAN))
            .collect();
        self.named.insert(effect, values);
    }

    /// Switches `effect` off.
    pub fn unset(&mut self, effect: Named) {
        self.named.remove(&effect);
    }

    /// The names of the effects that are on, in the order of effects.md.
    pub fn names(&self) -> Vec<&'static str> {
        self.named.keys().map(|e| e.name()).collect()
    }
}

/// One named effect's parameters as a table, in the order of its row.
struct ParamTable<'a>(&'static [crate::effects::Param], &'a [f64]);

impl Serialize for ParamTable<'_> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = serializer.serialize_map(Some(self.0.len()))?;
        for (param, value) in self.0.iter().zip(self.1) {
            map.serialize_entry(param.name, value)?;
        }
        map.end()
    }
}

impl Serialize for Effects {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let generic = usize::from(!self.generic.is_empty());
        let mut map = serializer.serialize_map(Some(self.named.len() + generic))?;
        for (effect, values) in &self.named {
            let spec = effect.spec();
            map.serialize_entry(spec.name, &ParamTable(spec.params, values))?;
        }
        if !self.generic.is_empty() {
            map.serialize_entry("generic", &self.generic)?;
        }
        map.end()
    }
}

/// A named effect's table read by its row: every parameter present, no
/// other key. The error says which, as serde's own do.
fn named_params<E: serde::de::Error>(
    effect: Named,
    mut table: BTreeMap<String, f64>,
) -> Result<Vec<f64>, E> {
    let spec = effect.spec();
    let values = spec
        .params
        .iter()
        .map(|param| {
            table
                .remove(param.name)
                .ok_or_else(|| E::missing_field(param.name))
        })
        .collect::<Result<Vec<f64>, E>>()?;
    if let Some(extra) = table.keys().next() {
        return Err(E::custom(format!(
            "unknown field `{extra}` of `{}`, expected {}",
            spec.name,
            one_of(spec.params.iter().map(|p| p.name))
        )));
    }
    Ok(values)
}

/// `` `a`, `b` or `c` `` (`no field` for none), as serde's messages say it.
fn one_of<'a>(names: impl Iterator<Item = &'a str>) -> String {
    let names: Vec<String> = names.map(|n| format!("`{n}`")).collect();
    match names.as_slice() {
        [] => "no field".into(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} or {last}", init.join(", ")),
    }
}

/// The named effects that are on, with their parameters.
type NamedParams = BTreeMap<Named, Vec<f64>>;

/// Reads `[effects]` by the table: a named effect's key, then its table;
/// `generic` with `read_generic`.
fn read_effects<'de, A, G>(
    mut map: A,
    mut read_generic: impl FnMut(&mut A) -> Result<G, A::Error>,
) -> Result<(NamedParams, Option<G>), A::Error>
where
    A: serde::de::MapAccess<'de>,
{
    use serde::de::Error as _;
    let mut named = BTreeMap::new();
    let mut generic = None;
    while let Some(key) = map.next_key::<String>()? {
        if key == "generic" {
            generic = Some(read_generic(&mut map)?);
            continue;
        }
        let Some(effect) = Named::from_name(&key) else {
            return Err(A::Error::custom(format!(
                "unknown field `{key}`, expected {}",
                one_of(Named::ALL.iter().map(|e| e.name()).chain(["generic"]))
            )));
        };
        let table: BTreeMap<String, f64> = map.next_value()?;
        named.insert(effect, named_params(effect, table)?);
    }
    Ok((named, generic))
}

impl<'de> Deserialize<'de> for Effects {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Effects;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table of effects")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> Result<Effects, A::Error> {
                let (named, generic) = read_effects(map, |m| m.next_value::<Vec<GenericTerm>>())?;
                Ok(Effects {
                    named,
                    generic: generic.unwrap_or_default(),
                })
            }
        }
        deserializer.deserialize_map(Visitor)
    }
}

/// Everything the engine needs to know about the physics.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelConfig {
    pub product: ProductParams,
    pub contact: ContactParams,
    pub polach: PolachConfig,
    #[serde(default)]
    pub effects: Effects,
}

/// The overlay: every key optional, unknown keys refused.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Overlay {
    #[serde(default)]
    product: ProductOverlay,
    #[serde(default)]
    contact: ContactOverlay,
    #[serde(default)]
    polach: PolachOverlay,
    #[serde(default)]
    effects: EffectsOverlay,
    /// The alerts' thresholds: read by [`alerts::AlertConfig`], not the model.
    #[serde(default, rename = "alerts")]
    _alerts: Option<toml::Table>,
}

/// The effects of an overlay: the named ones read by the table as in
/// [`Effects`]; the generic terms as raw tables, parsed one by one so that
/// an error names the term.
#[derive(Debug, Default)]
struct EffectsOverlay {
    named: BTreeMap<Named, Vec<f64>>,
    generic: Vec<toml::Value>,
}

impl<'de> Deserialize<'de> for EffectsOverlay {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = EffectsOverlay;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a table of effects")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                map: A,
            ) -> Result<EffectsOverlay, A::Error> {
                let (named, generic) = read_effects(map, |m| m.next_value::<Vec<toml::Value>>())?;
                Ok(EffectsOverlay {
                    named,
                    generic: generic.unwrap_or_default(),
                })
            }
        }
        deserializer.deserialize_map(Visitor)
    }
}

/// Declares an overlay struct of optional fields and its merge into the full one.
macro_rules! overlay {
    ($overlay:ident => $full:ty { $($field:ident),* $(,)? }) => {
        #[derive(Debug, Default, Deserialize)]
        #[serde(deny_unknown_fields)]
        struct $overlay {
            $($field: Option<f64>,)*
        }
        impl $overlay {
            fn merge_into(&self, full: &mut $full) {
                $(if let Some(v) = self.$field { full.$field = v; })*
            }
        }
    };
}

overlay!(ProductOverlay => ProductParams {
    k0_kg, km1_kg, km2, m0_kg, kp, kc, mu_d, mu_c, km_kg, kt, cm_kg, cn, m_max_kg,
});
overlay!(ContactOverlay => ContactParams { e_pa, nu, wheel_profile_radius_m });
overlay!(PolachOverlay => PolachConfig { p_a, p_b_s_per_m, k_a, k_s });

impl Default for ModelConfig {
    /// The built-in defaults. `config/default.toml` is checked by a test, so
    /// this cannot fail at run time.
    fn default() -> Self {
        Self::from_default_toml()
            .unwrap_or_else(|e| unreachable!("config/default.toml is compiled in and tested: {e}"))
    }
}

/// The largest friction level (`product.mu_d`, and so `mu_c`) accepted:
/// no wheel-rail contact reaches 1.
pub const MAX_FRICTION: f64 = 2.0;

impl ModelConfig {
    fn from_default_toml() -> Result<Self, ConfigError> {
        let cfg: ModelConfig = toml::from_str(DEFAULT_TOML).map_err(|e| ConfigError {
            source_name: "built-in defaults".into(),
            key: "-".into(),
            message: e.to_string(),
        })?;
        cfg.validate("built-in defaults")?;
        Ok(cfg)
    }

    /// The defaults overlaid with the TOML text `text` (from `source_name`).
    pub fn from_overlay_str(text: &str, source_name: &str) -> Result<Self, ConfigError> {
        let mut cfg = Self::default();
        cfg.overlay_str(text, source_name)?;
        Ok(cfg)
    }

    /// The defaults overlaid with the file at `path`.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let source_name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| ConfigError {
            source_name: source_name.clone(),
            key: "-".into(),
            message: format!("cannot read: {e}"),
        })?;
        Self::from_overlay_str(&text, &source_name)
    }

    /// Overlays `text` on `self`: keys it sets replace ours; effects it
    /// switches on replace ours (an effect it does not name stays as it is);
    /// its generic terms are added after ours.
    pub fn overlay_str(&mut self, text: &str, source_name: &str) -> Result<(), ConfigError> {
        let overlay: Overlay = toml::from_str(text).map_err(|e| ConfigError {
            source_name: source_name.into(),
            key: overlay_error_key(&e, text),
            message: e.message().to_string(),
        })?;
        overlay.product.merge_into(&mut self.product);
        overlay.contact.merge_into(&mut self.contact);
        overlay.polach.merge_into(&mut self.polach);
        let e = overlay.effects;
        let first = self.effects.generic.len();
        for (k, value) in e.generic.into_iter().enumerate() {
            let term = GenericTerm::from_toml(value).map_err(|(key, message)| ConfigError {
                source_name: source_name.into(),
                key: format!("effects.generic[{}].{key}", first + k),
                message,
            })?;
            self.effects.generic.push(term);
        }
        self.effects.named.extend(e.named);
        self.validate(source_name)
    }

    /// The whole configuration as TOML (for `discover`'s model.toml).
    pub fn to_toml(&self) -> String {
        // A struct of f64s and tables always serializes; infinity is valid TOML.
        toml::to_string(self).unwrap_or_else(|e| unreachable!("ModelConfig serializes: {e}"))
    }

    /// Checks every value's range; the error names the first bad key. A
    /// physical bound says its reason (docs/spec/interfaces.md,
    /// "Configuration"); a value within every range that still takes the
    /// model's arithmetic beyond finite numbers is caught by the engine
    /// (`EngineError::NotFinite`).
    pub fn validate(&self, source_name: &str) -> Result<(), ConfigError> {
        let bad = |key: &str, message: String| ConfigError {
            source_name: source_name.into(),
            key: key.into(),
            message,
        };
        let check = |key: &str, v: f64, ok: bool, what: &str| {
            if v.is_nan() {
                Err(bad(key, "is NaN; a finite number is required".into()))
            } else if !ok {
                Err(bad(key, format!("is {v:?}; it must be {what}")))
            } else {
                Ok(())
            }
        };
        let p = &self.product;
        // Physical ranges (docs/spec/interfaces.md "Configuration ranges").
        let within = |key: &str, v: f64, (lo, hi): (f64, f64), why: &str| {
            check(
                key,
                v,
                (lo..=hi).contains(&v),
                &format!("within {lo:e} and {hi:e} ({why})"),
            )
        };
        for key in ProductKey::ALL {
            let v = key.get(p);
            let (lo, hi, why) = key.physical_range();
            let name = format!("product.{}", key.name());
            if key == ProductKey::M0Kg && v == 0.0 {
                continue; // no saturation term (model.md)
            }
            within(&name, v, (lo, hi), why)?;
        }
        check(
            "product.mu_d",
            p.mu_d,
            p.mu_d >= p.mu_c,
            ">= product.mu_c (dry friction above boundary friction)",
        )?;
        let c = &self.contact;
        check(
            "contact.e_pa",
            c.e_pa,
            (1e6..=1e13).contains(&c.e_pa),
            "within 1e6 and 1e13 Pa (rubber to diamond; steel is 2.1e11)",
        )?;
        check(
            "contact.nu",
            c.nu,
            (0.0..0.5).contains(&c.nu),
            "in [0, 0.5)",
        )?;
        let r = c.wheel_profile_radius_m;
        check(
            "contact.wheel_profile_radius_m",
            r,
            r >= 0.01,
            ">= 0.01 m (inf = flat)",
        )?;
        let k = &self.polach;
        check(
            "polach.p_a",
            k.p_a,
            (0.0..=1.0).contains(&k.p_a),
            "in [0, 1]",
        )?;
        within(
            "polach.p_b_s_per_m",
            k.p_b_s_per_m,
            (0.0, 1e3),
            "Polach's B is 0.6 s/m; at 1000 s/m friction is at its asymptote below 1 mm/s of slip",
        )?;
        check(
            "polach.k_a",
            k.k_a,
            k.k_a > 0.0 && k.k_a <= 10.0,
            "> 0 and <= 10 (Polach's reduction factors are at most 1)",
        )?;
        check(
            "polach.k_s",
            k.k_s,
            k.k_s > 0.0 && k.k_s <= 10.0,
            "> 0 and <= 10 (Polach's reduction factors are at most 1)",
        )?;
        let e = &self.effects;
        for (effect, values) in &e.named {
            let spec = effect.spec();
            for (param, &x) in spec.params.iter().zip(values) {
                let key = format!("effects.{}.{}", spec.name, param.name);
                check(&key, x, param.is_valid(x), &param.rule())?;
            }
        }
        for (k, term) in e.generic.iter().enumerate() {
            term.check()
                .map_err(|(key, message)| bad(&format!("effects.generic[{k}].{key}"), message))?;
        }
        Ok(())
    }
}

/// The largest mass a configuration constant may be: a kilogram on one
/// contact patch is 5000 times the laboratory's cap (0.2 g).
pub const MASS_MAX_KG: f64 = 1.0;
/// The smallest positive mass constant: a picogram, below what a balance or
/// a film measurement resolves (and 1 / x stays finite).
pub const MASS_MIN_KG: f64 = 1e-15;
const MASS_WHY: &str = "kg: a picogram to a kilogram, 5000 times the laboratory's cap of 0.2 g";
const SLOPE_WHY: &str =
    "a hundredfold change per reference pressure or creepage; Table 2 has 1.84 and 0.57";

impl ProductKey {
    /// The physical range of the constant, `lo ..= hi`, and why (`m0_kg`
    /// may also be 0: no saturation term). A calibration stays inside it.
    pub fn physical_range(self) -> (f64, f64, &'static str) {
        match self {
            ProductKey::MuD | ProductKey::MuC => {
                (0.0, MAX_FRICTION, "no wheel-rail contact reaches 1")
            }
            ProductKey::K0Kg | ProductKey::Km1Kg => (0.0, MASS_MAX_KG, MASS_WHY),
            ProductKey::M0Kg | ProductKey::KmKg | ProductKey::CmKg | ProductKey::MMaxKg => {
                (MASS_MIN_KG, MASS_MAX_KG, MASS_WHY)
            }
            ProductKey::Km2 => (1e-3, 1e3, "a dimensionless scale of m0; Table 2 has 0.53"),
            ProductKey::Kp | ProductKey::Kc => (-100.0, 100.0, SLOPE_WHY),
            ProductKey::Kt => (
                0.0,
                100.0,
                "the transfer fraction is capped at 0.5; Table 2 has 0.5",
            ),
            ProductKey::Cn => (
                1e-2,
                1e9,
                "wheel revolutions: a hundredth to a billion; Table 2 has 12.1",
            ),
        }
    }
}

/// The dotted key a TOML error points at (e.g. `product.cn`): the key on the
/// line of the error's span, under the last table header before it; else the
/// name a message like "unknown field `x`" quotes.
fn overlay_error_key(e: &toml::de::Error, text: &str) -> String {
    if let Some(span) = e.span() {
        let start = span.start.min(text.len());
        let line_start = text[..start].rfind('\n').map_or(0, |p| p + 1);
        let line_end = text[start..].find('\n').map_or(text.len(), |p| start + p);
        let line = text[line_start..line_end].trim();
        let table = text[..line_start]
            .lines()
            .rev()
            .map(str::trim)
            .find(|l| l.starts_with('[') && l.ends_with(']'))
            .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
        if let Some((key, _)) = line.split_once('=') {
            let key = key.trim().trim_matches('"');
            return match table {
                Some(t) => format!("{t}.{key}"),
                None => key.to_string(),
            };
        }
        if line.starts_with('[') {
            return line
                .trim_matches(|c| c == '[' || c == ']')
                .trim()
                .to_string();
        }
    }
    let msg = e.message();
    if let Some(start) = msg.find('`') {
        if let Some(len) = msg[start + 1..].find('`') {
            return msg[start + 1..start + 1 + len].to_string();
        }
    }
    "-".into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_table_2() {
        let c = ModelConfig::default();
        assert_eq!(c.product.k0_kg, 1.0449e-9);
        assert_eq!(c.product.km1_kg, 1.1617e-6);
        assert_eq!(c.product.km2, 0.53);
        assert_eq!(c.product.m0_kg, 1.0e-4); // model.md, not Table 2
        assert_eq!(c.product.kp, 1.84);
        assert_eq!(c.product.kc, 0.57);
        assert_eq!(c.product.mu_d, 0.58);
        assert_eq!(c.product.mu_c, 0.15);
        assert_eq!(c.product.km_kg, 1.6290e-4);
        assert_eq!(c.product.kt, 0.5);
        assert_eq!(c.product.cm_kg, 3.5e-5);
        assert_eq!(c.product.cn, 12.1);
        assert_eq!(c.product.m_max_kg, 2.0e-4);
        assert_eq!(c.contact.e_pa, 210e9);
        assert_eq!(c.contact.nu, 0.3);
        assert!(c.contact.wheel_profile_radius_m.is_infinite());
        assert_eq!((c.polach.p_a, c.polach.p_b_s_per_m), (0.40, 0.60));
        assert_eq!((c.polach.k_a, c.polach.k_s), (1.00, 0.40));
        assert!(c.effects.names().is_empty());
    }

    #[test]
    fn overlay_sets_only_its_keys() {
        let c = ModelConfig::from_overlay_str("[product]\ncn = 6\n", "t.toml").unwrap();
        assert_eq!(c.product.cn, 6.0); // an integer is a valid float
        assert_eq!(c.product.cm_kg, 3.5e-5);
        let c =
            ModelConfig::from_overlay_str("[effects.rail_ageing]\ntau_s = 7200.0\n", "t").unwrap();
        assert_eq!(c.effects.get(Named::RailAgeing), Some(&[7200.0][..]));
        assert_eq!(c.product, ModelConfig::default().product);
        let c = ModelConfig::from_overlay_str("[effects.bogie_bands]\n", "t").unwrap();
        assert!(c.effects.is_on(Named::BogieBands));
        assert_eq!(c.effects.get(Named::BogieBands), Some(&[][..]));
    }

    fn err(text: &str) -> ConfigError {
        ModelConfig::from_overlay_str(text, "bad.toml").unwrap_err()
    }

    #[test]
    fn bad_overlays_name_the_key() {
        let e = err("[product]\nkm3 = 1.0\n");
        assert_eq!(e.key, "product.km3", "{e}");
        let e = err("[product]\ncn = \"twelve\"\n");
        assert_eq!(e.key, "product.cn", "{e}");
        let e = err("[polach]\nk_a = 1\n[product]\nkt = 0.5\ncn = true\n");
        assert_eq!(e.key, "product.cn", "{e}");
        let e = err("[product]\ncn = nan\n");
        assert_eq!(e.key, "product.cn", "{e}");
        let e = err("[product]\ncm_kg = -1.0\n");
        assert_eq!(e.key, "product.cm_kg", "{e}");
        let e = err("[product]\nm0_kg = -1e-4\n");
        assert_eq!(e.key, "product.m0_kg", "{e}");
        assert!(ModelConfig::from_overlay_str("[product]\nm0_kg = 0\n", "t").is_ok());
        let e = err("[effects.rail_ageing]\ntau_s = -5.0\n");
        assert_eq!(e.key, "effects.rail_ageing.tau_s", "{e}");
        let e = err("[effects.rail_ageing]\n");
        assert!(e.to_string().contains("tau_s"), "{e}");
        let e = err("[effects.rail_ageing]\ntau_s = 1.0\nbeta = 2.0\n");
        assert!(e.to_string().contains("beta"), "{e}");
        let e = err("[effects.rail_ageing]\ntau_s = \"long\"\n");
        assert_eq!(e.key, "effects.rail_ageing.tau_s", "{e}");
        let e = err("[effects.moon_phase]\nx = 1\n");
        assert!(e.key.contains("moon_phase"), "{e}");
        let e = err("[effects.speed_transfer]\nn = 11\n");
        assert_eq!(e.key, "effects.speed_transfer.n", "{e}");
        let e = err("[nonsense]\n");
        assert!(e.key.contains("nonsense"), "{e}");
        let e = err("[product\n");
        assert!(e.to_string().contains("bad.toml"), "{e}");
    }

    #[test]
    fn round_trips_through_toml() {
        let mut c = ModelConfig::default();
        c.effects.set(Named::RailAgeing, &[3600.0]);
        c.effects.set(Named::BogieBands, &[]);
        let text = c.to_toml();
        let back = ModelConfig::from_overlay_str(&text, "round trip").unwrap();
        assert_eq!(back, c);
    }
}
