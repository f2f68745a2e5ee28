//! A line (line.md): the `/section` cut into consecutive segments by one
//! `/line` message. The typed [`Line`] exists only valid: [`decode`]
//! checks every input error line.md lists for the message against the
//! section it belongs to. A recording without `/line` is a section, as it
//! always was.

use serde_json::Value;

use crate::decode::DecodeError;
use crate::event::Section;
use crate::wire::{LineMsg, SegmentMsg};

/// The `/line` message: the section's `[0, length_m]` cut into segments,
/// segment `k` covering `[end_m(k-1), end_m(k))` (`end_m(-1) = 0`), the
/// last one up to and including `length_m`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Line {
    pub line_id: String,
    /// Never empty; `end_m` strictly increasing, the last equal to the
    /// section's `length_m`.
    pub segments: Vec<Segment>,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Segment {
    pub id: String,
    pub kind: SegmentKind,
    pub end_m: f64,
    /// Descriptive (a plan drawing), like `curve_radius_m`: no equation
    /// uses it. Read for curves only.
    pub radius_m: Option<f64>,
}

/// What a segment is, with what its rows need: the outer rail of a curve
/// (an index into [`Section::rails`]) and the end of a transition that
/// meets its curve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SegmentKind {
    Tangent,
    Curve { high_rail: usize },
    Transition { high_rail: usize, curve_at: CurveAt },
}

/// The end of a transition where it meets its curve, in chainage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum CurveAt {
    Start,
    End,
}

impl Line {
    /// The segment holding chainage `d_m` (line.md: `e(k-1) <= d < e(k)`,
    /// the last segment also holding its end); `None` outside the line.
    pub fn segment_at(&self, d_m: f64) -> Option<usize> {
        if d_m.is_nan() || d_m < 0.0 {
            return None;
        }
        let k = self.segments.partition_point(|s| s.end_m <= d_m);
        if k < self.segments.len() {
            Some(k)
        } else {
            self.segments
                .last()
                .filter(|s| s.end_m == d_m)
                .map(|_| self.segments.len() - 1)
        }
    }

    /// Where segment `k` starts.
    pub fn start_m(&self, k: usize) -> f64 {
        k.checked_sub(1)
            .and_then(|j| self.segments.get(j))
            .map_or(0.0, |s| s.end_m)
    }

    /// The index of the segment called `id`.
    pub fn segment(&self, id: &str) -> Option<usize> {
        self.segments.iter().position(|s| s.id == id)
    }
}

impl Line {
    /// `msg` as the typed line of `section`, checked as the reader checks a
    /// `/line` message (for a writer that builds one, e.g. `tortwin synth`
    /// from a described layout); the error names the field.
    pub fn from_message(msg: &LineMsg, section: &Section) -> Result<Line, String> {
        decode(msg, section).map_err(|e| e.message)
    }
}

/// When an axle `offset_m` behind the front of a train that enters at
/// `t_passage_s` reaches the line's two ends `d = 0` and `d = L` (model.md's
/// time at a point, in its form): the reader's rule for trains sharing a
/// line compares these, and a writer planning trains uses the same
/// arithmetic.
pub fn axle_at_ends_s(
    t_passage_s: f64,
    up: bool,
    length_m: f64,
    offset_m: f64,
    speed_mps: f64,
) -> [f64; 2] {
    let d_entry_m = if up { 0.0 } else { length_m };
    [0.0, length_m].map(|x: f64| t_passage_s + ((x - d_entry_m).abs() + offset_m) / speed_mps)
}

/// The `/line` message as the typed [`Line`] of `section`.
pub(crate) fn decode(msg: &LineMsg, section: &Section) -> Result<Line, DecodeError> {
    if section.rails.len() != 2 {
        return Err(format!(
            "a line needs a /section with exactly two rails; this one has {}",
            section.rails.len()
        )
        .into());
    }
    if msg.segments.is_empty() {
        return Err(DecodeError::at(
            "segments",
            "`segments` is empty: a line has at least one".into(),
        ));
    }
    let mut segments: Vec<Segment> = Vec::with_capacity(msg.segments.len());
    for (k, s) in msg.segments.iter().enumerate() {
        if let Some(j) = segments.iter().position(|g| g.id == s.id) {
            return Err(DecodeError::at(
                format!("segments[{k}].id"),
                format!(
                    "`segments[{k}].id`: duplicate segment id `{}` (segments[{j}] has it too)",
                    s.id
                ),
            ));
        }
        let before = segments.last().map_or(0.0, |g| g.end_m);
        // A NaN cannot come through JSON, but is refused too.
        if s.end_m.is_nan() || s.end_m <= before {
            let than = segments.last().map_or("0".to_string(), |g| {
                format!("segments[{}].end_m = {before:?} (`{}`)", k - 1, g.id)
            });
            return Err(DecodeError::at(
                format!("segments[{k}].end_m"),
                format!(
                    "segments[{k}].end_m = {:?} is not greater than {than}",
                    s.end_m
                ),
            ));
        }
        let (kind, radius_m) = match s.kind.as_str() {
            "tangent" => (SegmentKind::Tangent, None),
            "curve" => (
                SegmentKind::Curve {
                    high_rail: high_rail(k, s, section)?,
                },
                radius(k, s)?,
            ),
            "transition" => (
                SegmentKind::Transition {
                    high_rail: high_rail(k, s, section)?,
                    curve_at: curve_at(k, s)?,
                },
                None,
            ),
            other => {
                return Err(DecodeError::at(
                    format!("segments[{k}].type"),
                    format!(
                        "`segments[{k}].type`: unknown segment type `{other}` (tangent, transition or curve)"
                    ),
                ))
            }
        };
        segments.push(Segment {
            id: s.id.clone(),
            kind,
            end_m: s.end_m,
            radius_m,
        });
    }
    let k = segments.len() - 1;
    let last = segments[k].end_m;
    if last != section.length_m {
        return Err(DecodeError::at(
            format!("segments[{k}].end_m"),
            format!(
                "`segments[{k}].end_m` = {last:?}: the last segment ends there, not at the section's length_m = {:?} m",
                section.length_m
            ),
        ));
    }
    Ok(Line {
        line_id: msg.line_id.clone(),
        segments,
    })
}

/// A curve's or transition's outer rail, as an index into the section's.
fn high_rail(k: usize, s: &SegmentMsg, section: &Section) -> Result<usize, DecodeError> {
    let field = format!("segments[{k}].high_rail");
    match &s.high_rail {
        None => Err(DecodeError::at(
            &field,
            format!("missing field `{field}`: a {} names its outer rail", s.kind),
        )),
        Some(Value::String(name)) => {
            section.rails.iter().position(|r| r == name).ok_or_else(|| {
                DecodeError::at(
                    &field,
                    format!(
                        "`{field}` = `{name}` names no rail of the section ({})",
                        section.rails.join(", ")
                    ),
                )
            })
        }
        Some(other) => Err(DecodeError::at(
            &field,
            format!("`{field}` = {other} is not a rail name (a JSON string)"),
        )),
    }
}

/// A transition's end that meets its curve.
fn curve_at(k: usize, s: &SegmentMsg) -> Result<CurveAt, DecodeError> {
    let field = format!("segments[{k}].curve_at");
    match &s.curve_at {
        None => Err(DecodeError::at(
            &field,
            format!("missing field `{field}`: a transition says which end meets its curve"),
        )),
        Some(Value::String(v)) if v == "start" => Ok(CurveAt::Start),
        Some(Value::String(v)) if v == "end" => Ok(CurveAt::End),
        Some(other) => Err(DecodeError::at(
            &field,
            format!("unknown `{field}` {other} (\"start\" or \"end\")"),
        )),
    }
}

/// A curve's radius, if given: a positive number.
fn radius(k: usize, s: &SegmentMsg) -> Result<Option<f64>, DecodeError> {
    match &s.radius_m {
        None => Ok(None),
        Some(v) => match v.as_f64() {
            Some(r) if r > 0.0 => Ok(Some(r)),
            _ => {
                let field = format!("segments[{k}].radius_m");
                Err(DecodeError::at(
                    &field,
                    format!("`{field}` = {v} is not a positive number"),
                ))
            }
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decode::parse;

    fn section(rails: &[&str], length_m: f64) -> Section {
        Section {
            section_id: "s".into(),
            length_m,
            rails: rails.iter().map(|r| r.to_string()).collect(),
            curve_radius_m: None,
            rail_head_radius_m: 0.3,
            nominal_wheel_diameter_m: 0.92,
            applicators: Vec::new(),
            sites: Vec::new(),
        }
    }

    fn read(json: &str, section: &Section) -> Result<Line, DecodeError> {
        decode(&parse::<LineMsg>(json.as_bytes())?, section)
    }

    /// line.md's example, ending at the section's length.
    const EXAMPLE: &str = r#"{"line_id": "ore-line-km12",
        "segments": [
          {"id": "T0", "type": "tangent", "end_m": 150.0},
          {"id": "X1", "type": "transition", "end_m": 210.0, "high_rail": "right", "curve_at": "end"},
          {"id": "C1", "type": "curve", "end_m": 810.0, "high_rail": "right", "radius_m": 400.0}]}"#;

    #[test]
    fn line_md_s_example_reads_as_its_segments() {
        let line = read(EXAMPLE, &section(&["left", "right"], 810.0)).expect("valid");
        assert_eq!(line.line_id, "ore-line-km12");
        let kinds: Vec<SegmentKind> = line.segments.iter().map(|s| s.kind).collect();
        assert_eq!(
            kinds,
            [
                SegmentKind::Tangent,
                SegmentKind::Transition {
                    high_rail: 1,
                    curve_at: CurveAt::End
                },
                SegmentKind::Curve { high_rail: 1 }
            ]
        );
        assert_eq!(line.segments[2].radius_m, Some(400.0));
        assert_eq!(line.segment("X1"), Some(1));
        // [e(k-1), e(k)); the last segment holds the line's end.
        let at = |d| line.segment_at(d);
        assert_eq!(
            [
                at(0.0),
                at(149.999),
                at(150.0),
                at(210.0),
                at(810.0),
                at(810.1),
                at(-0.1)
            ],
            [Some(0), Some(0), Some(1), Some(2), Some(2), None, None]
        );
        assert_eq!((line.start_m(0), line.start_m(2)), (0.0, 210.0));
    }

    #[test]
    fn keys_a_type_does_not_use_are_ignored_unchecked() {
        let json = r#"{"line_id": "l", "segments": [
            {"id": "T", "type": "tangent", "end_m": 10, "high_rail": 5, "curve_at": [], "radius_m": -1},
            {"id": "X", "type": "transition", "end_m": 20, "high_rail": "a", "curve_at": "start", "radius_m": "wide"}]}"#;
        let line = read(json, &section(&["a", "b"], 20.0)).expect("valid");
        assert_eq!(line.segments[0].kind, SegmentKind::Tangent);
        assert_eq!(line.segments[1].radius_m, None);
    }

    /// Every input error line.md lists for the message itself, each with
    /// the field it names and words of its sentence.
    #[test]
    fn every_input_error_of_the_message_is_refused_naming_its_field() {
        let two = section(&["left", "right"], 810.0);
        let cases: [(&str, &Section, Option<&str>, &str); 14] = [
            (
                EXAMPLE,
                &section(&["left", "right", "third"], 810.0),
                None,
                "exactly two rails",
            ),
            (
                EXAMPLE,
                &section(&["right"], 810.0),
                None,
                "exactly two rails",
            ),
            (
                r#"{"line_id": "l", "segments": []}"#,
                &two,
                Some("segments"),
                "empty",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "tangent", "end_m": 5}, {"id": "A", "type": "tangent", "end_m": 810}]}"#,
                &two,
                Some("segments[1].id"),
                "duplicate segment id `A`",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "spiral", "end_m": 810}]}"#,
                &two,
                Some("segments[0].type"),
                "unknown segment type `spiral`",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "transition", "end_m": 810, "high_rail": "left", "curve_at": "middle"}]}"#,
                &two,
                Some("segments[0].curve_at"),
                "unknown",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "curve", "end_m": 810}]}"#,
                &two,
                Some("segments[0].high_rail"),
                "missing",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "transition", "end_m": 810, "curve_at": "end"}]}"#,
                &two,
                Some("segments[0].high_rail"),
                "missing",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "curve", "end_m": 810, "high_rail": "outer"}]}"#,
                &two,
                Some("segments[0].high_rail"),
                "names no rail",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "transition", "end_m": 810, "high_rail": "left"}]}"#,
                &two,
                Some("segments[0].curve_at"),
                "missing",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "tangent", "end_m": 0}, {"id": "B", "type": "tangent", "end_m": 810}]}"#,
                &two,
                Some("segments[0].end_m"),
                "not greater than 0",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "tangent", "end_m": 300}, {"id": "B", "type": "tangent", "end_m": 300}, {"id": "C", "type": "tangent", "end_m": 810}]}"#,
                &two,
                Some("segments[1].end_m"),
                "not greater than segments[0].end_m",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "tangent", "end_m": 809.9999999}]}"#,
                &two,
                Some("segments[0].end_m"),
                "length_m",
            ),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "curve", "end_m": 810, "high_rail": "left", "radius_m": 0}]}"#,
                &two,
                Some("segments[0].radius_m"),
                "not a positive number",
            ),
        ];
        for (json, section, field, words) in cases {
            let e = read(json, section).expect_err(json);
            assert_eq!(e.field.as_deref(), field, "{json}: {}", e.message);
            assert!(e.message.contains(words), "{json}: {}", e.message);
        }
    }

    #[test]
    fn a_segment_of_the_wrong_json_type_is_refused_by_the_grammar() {
        let two = section(&["left", "right"], 810.0);
        for (json, field) in [
            (r#"{"line_id": "l", "segments": {}}"#, "segments"),
            (
                r#"{"line_id": "l", "segments": [{"id": "A", "type": "tangent", "end_m": "810"}]}"#,
                "segments[0].end_m",
            ),
            (r#"{"line_id": 7, "segments": []}"#, "line_id"),
            (r#"{"segments": []}"#, "line_id"),
        ] {
            let e = read(json, &two).expect_err(json);
            assert!(
                e.field.as_deref() == Some(field) || e.message.contains(field),
                "{json}: {:?} {}",
                e.field,
                e.message
            );
        }
    }
}
