//! A described line (docs/spec/line.md) for `tortwin synth --layout FILE`:
//! its segments as the `/line` message writes them, plus what only the
//! generator needs (a curve's superelevation), the applicators with the
//! rails they spray and the measurement sites. The segments are checked by
//! the reader's own rules ([`Line::from_message`]), so a layout the
//! generator accepts is a `/line` every reader accepts.
//!
//! What a train meets on a segment is drawn from the segment's geometry:
//! on a curve of radius R the creepages of [`super::traffic::creepages`]
//! for R on its outer (`high_rail`) and inner rail, and the load shifted to
//! the outer rail by the cant deficiency at the train's speed; on a
//! transition the same for a curve of twice the radius of the curve it
//! meets (its mean curvature, half the curve's) with half its cant; on a
//! tangent the axle's own small creepages and equal loads. A train's axles
//! carry the tangent values as their own and the others in their field
//! `segments`.

use serde::{Deserialize, Serialize};

use super::params::SiteParam;
use tortwin_recording::line::{CurveAt, Line, SegmentKind};
use tortwin_recording::wire::{LineMsg, SegmentMsg};
use tortwin_recording::Section;

/// The radius a curve without `radius_m` is drawn with (the creepage ranges'
/// reference), m.
pub(crate) const DEFAULT_RADIUS_M: f64 = 400.0;
/// A curve's superelevation when the layout gives none, m.
const DEFAULT_CANT_M: f64 = 0.10;

/// The layout file: a TOML document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LineLayout {
    pub line_id: String,
    /// Default `["left", "right"]`; a line has exactly two.
    #[serde(default = "default_rails")]
    pub rails: Vec<String>,
    pub segments: Vec<LayoutSegment>,
    #[serde(default)]
    pub applicators: Vec<LayoutApplicator>,
    #[serde(default)]
    pub sites: Vec<SiteParam>,
    /// The site that measures adhesion; default `--adhesion-site`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adhesion_site: Option<String>,
    /// Where the layout was read from, for messages (not in the file).
    #[serde(skip)]
    pub source: String,
}

fn default_rails() -> Vec<String> {
    vec!["left".to_string(), "right".to_string()]
}

/// A segment with the keys of line.md's `/line` and the generator's
/// `cant_m`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayoutSegment {
    pub id: String,
    #[serde(rename = "type")]
    pub kind: String,
    pub end_m: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub high_rail: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub curve_at: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius_m: Option<f64>,
    /// A curve's superelevation (default 0.10 m); not written to the
    /// recording.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cant_m: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayoutApplicator {
    pub id: String,
    pub position_m: f64,
    /// The rails it sprays; default both.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rails: Option<Vec<String>>,
    /// Nominal pulse mass; default `--pulse-g`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub nominal_pulse_g: Option<f64>,
}

/// What a train meets on one segment that is not tangent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Bend {
    pub(crate) segment: usize,
    pub(crate) high_rail: usize,
    /// The radius the creepages are drawn for, m.
    pub(crate) radius_m: f64,
    /// The superelevation the load shift is computed with, m.
    pub(crate) cant_m: f64,
}

impl LineLayout {
    /// The layout in `text` (TOML) read from `source`; the error says
    /// where: `source:line:column: message`.
    pub fn from_toml(text: &str, source: &str) -> Result<Self, String> {
        let mut layout: LineLayout = toml::from_str(text).map_err(|e| {
            let at = e.span().map_or_else(String::new, |span| {
                let before = &text[..span.start.min(text.len())];
                let line = before.matches('\n').count() + 1;
                let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
                format!(":{line}:{column}")
            });
            format!("{source}{at}: {}", e.message())
        })?;
        layout.source = source.to_string();
        Ok(layout)
    }

    /// `message` about this layout, naming where it was read from.
    pub(crate) fn error(&self, message: String) -> String {
        format!("--layout {}: {message}", self.source)
    }

    /// The section's length: the last segment's end.
    pub fn length_m(&self) -> f64 {
        self.segments.last().map_or(0.0, |s| s.end_m)
    }

    /// The `/line` message (without the generator's keys).
    pub(crate) fn line_msg(&self) -> LineMsg {
        let string = |v: &Option<String>| v.clone().map(serde_json::Value::String);
        LineMsg {
            line_id: self.line_id.clone(),
            segments: self
                .segments
                .iter()
                .map(|s| SegmentMsg {
                    id: s.id.clone(),
                    kind: s.kind.clone(),
                    end_m: s.end_m,
                    high_rail: string(&s.high_rail),
                    curve_at: string(&s.curve_at),
                    radius_m: s.radius_m.map(serde_json::Value::from),
                })
                .collect(),
        }
    }

    /// The typed line on `section`, checked by the reader's rules.
    pub(crate) fn line(&self, section: &Section) -> Result<Line, String> {
        Line::from_message(&self.line_msg(), section)
    }

    /// The segments that are not tangent, with what a train meets there.
    pub(crate) fn bends(&self, line: &Line) -> Vec<Bend> {
        let radius = |k: usize| {
            line.segments
                .get(k)
                .filter(|s| matches!(s.kind, SegmentKind::Curve { .. }))
                .map(|s| (s.radius_m.unwrap_or(DEFAULT_RADIUS_M), self.cant(k)))
        };
        line.segments
            .iter()
            .enumerate()
            .filter_map(|(k, s)| match s.kind {
                SegmentKind::Tangent => None,
                SegmentKind::Curve { high_rail } => Some(Bend {
                    segment: k,
                    high_rail,
                    radius_m: s.radius_m.unwrap_or(DEFAULT_RADIUS_M),
                    cant_m: self.cant(k),
                }),
                SegmentKind::Transition {
                    high_rail,
                    curve_at,
                } => {
                    let meets = match curve_at {
                        CurveAt::End => radius(k + 1),
                        CurveAt::Start => k.checked_sub(1).and_then(radius),
                    };
                    let (radius_m, cant_m) = meets.unwrap_or((DEFAULT_RADIUS_M, DEFAULT_CANT_M));
                    Some(Bend {
                        segment: k,
                        high_rail,
                        radius_m: 2.0 * radius_m,
                        cant_m: cant_m / 2.0,
                    })
                }
            })
            .collect()
    }

    fn cant(&self, k: usize) -> f64 {
        self.segments
            .get(k)
            .and_then(|s| s.cant_m)
            .unwrap_or(DEFAULT_CANT_M)
    }

    /// The checks the reader does not make: the generator's own keys.
    pub(crate) fn validate(&self) -> Result<(), String> {
        if self.rails.len() != 2 || self.rails[0] == self.rails[1] {
            return Err(format!(
                "rails = {:?}: a line has exactly two rails with different names",
                self.rails
            ));
        }
        for (k, s) in self.segments.iter().enumerate() {
            if let Some(cant) = s.cant_m {
                if !(cant.is_finite() && (0.0..=0.2).contains(&cant)) {
                    return Err(format!(
                        "segments[{k}].cant_m = {cant}: it must be in [0, 0.2] m"
                    ));
                }
            }
            if !s.end_m.is_finite() {
                return Err(format!("segments[{k}].end_m = {}: not finite", s.end_m));
            }
        }
        let mut ids: Vec<&str> = Vec::new();
        for (a, app) in self.applicators.iter().enumerate() {
            if ids.contains(&app.id.as_str()) {
                return Err(format!(
                    "applicators[{a}].id: duplicate applicator id `{}`",
                    app.id
                ));
            }
            ids.push(&app.id);
            if !(0.0..=self.length_m()).contains(&app.position_m) {
                return Err(format!(
                    "applicators[{a}].position_m = {}: it must lie on the line (0 to {} m)",
                    app.position_m,
                    self.length_m()
                ));
            }
            for rail in app.rails.iter().flatten() {
                if !self.rails.contains(rail) {
                    return Err(format!(
                        "applicators[{a}].rails: `{rail}` is not a rail of the line ({})",
                        self.rails.join(", ")
                    ));
                }
            }
            if app.rails.as_ref().is_some_and(Vec::is_empty) {
                return Err(format!("applicators[{a}].rails is empty"));
            }
            if let Some(g) = app.nominal_pulse_g {
                if !(g.is_finite() && g >= 0.0) {
                    return Err(format!(
                        "applicators[{a}].nominal_pulse_g = {g}: it must be finite and >= 0"
                    ));
                }
            }
        }
        let mut ids: Vec<&str> = Vec::new();
        for (i, site) in self.sites.iter().enumerate() {
            if ids.contains(&site.id.as_str()) {
                return Err(format!("sites[{i}].id: duplicate site id `{}`", site.id));
            }
            ids.push(&site.id);
        }
        Ok(())
    }
}
