//! Where the section lies on a plan, for the curve views of rerun and
//! Foxglove (docs/spec/interfaces.md, "The section on a plan").
//!
//! Distance `d` runs along the track centre line from (0, 0) in +x. On a
//! curve of radius `R` the track bends to the right: the centre of the curve
//! is (0, -R) and the point at `d` is at angle `theta = d / R` from +y, so a
//! point at lateral offset `o` (positive to the left, away from the centre)
//! is `((R + o) sin theta, (R + o) cos theta - R)`; on tangent track it is
//! `(d, o)`. The rails are drawn apart at [`drawn_gauge_m`], far wider than
//! the real 1.435 m so they read apart on a plan of the whole section: the
//! rail named `high` outermost and `low` innermost on a curve, the others in
//! the section's order from left (outside) to right (inside). A rail's band
//! other than `top` (the gauge corner of `bogie_bands`) is drawn a fifth
//! of the drawn gauge towards the track centre.
//!
//! A line (docs/spec/line.md) is drawn from its segments: its centre line
//! starts at (0, 0) in +x and turns by its curvature, 0 on a tangent (and
//! on a curve without `radius_m`), `1 / radius_m` on a curve, bending away
//! from its `high_rail`, and changing linearly along a transition from 0 to
//! the curvature of the curve it meets (a clothoid; 0 when that curve has
//! no radius). Its rails keep the section's order from left to right; a
//! rail's crown `C` is drawn on the rail, its gauge corner `G` towards the
//! track centre.

use tortwin_engine::sink::SectionInfo;
use tortwin_recording::line::{CurveAt, Line, SegmentKind};

/// The gauge drawn on a plan of a section `length_m` long: a fortieth of
/// the length, at least 2 m.
pub fn drawn_gauge_m(length_m: f64) -> f64 {
    (length_m / 40.0).max(2.0)
}

/// The plan of a section: lateral offsets of its tracks and the mapping of
/// (d, offset) to x, y.
#[derive(Debug, Clone)]
pub struct Plan {
    pub curve_radius_m: Option<f64>,
    /// A line's centre line (then `curve_radius_m` is unused).
    pub centre: Option<CentreLine>,
    pub gauge_m: f64,
    /// Lateral offset of each rail (section order), positive to the left.
    pub rail_offsets_m: Vec<f64>,
    /// Lateral offset of each track (rail/band, engine order).
    pub track_offsets_m: Vec<f64>,
}

impl Plan {
    pub fn new(info: &SectionInfo<'_>) -> Plan {
        let section = &*info.section;
        let gauge_m = drawn_gauge_m(section.length_m);
        let rails = section.rails.len();
        // Order from the left (outside of a curve): `high` first and `low`
        // last on a curve, the others as listed.
        let mut order: Vec<usize> = (0..rails).collect();
        if section.curve_radius_m.is_some() && info.line.is_none() {
            let rank = |r: &usize| match section.rails[*r].as_str() {
                "high" => 0,
                "low" => 2,
                _ => 1,
            };
            order.sort_by_key(rank);
        }
        let mut rail_offsets_m = vec![0.0; rails];
        let span = (rails.max(1) - 1) as f64;
        for (place, &rail) in order.iter().enumerate() {
            rail_offsets_m[rail] = (span / 2.0 - place as f64) * gauge_m / span.max(1.0);
        }
        let track_offsets_m = info
            .tracks
            .iter()
            .map(|track| {
                let rail = rail_offsets_m.get(track.rail).copied().unwrap_or(0.0);
                if track.band == "top" || track.band == "C" {
                    rail
                } else {
                    // Towards the track centre line.
                    rail - rail.signum() * gauge_m / 5.0
                }
            })
            .collect();
        Plan {
            curve_radius_m: section.curve_radius_m,
            centre: info
                .line
                .as_deref()
                .map(|line| CentreLine::new(line, section.length_m)),
            gauge_m,
            rail_offsets_m,
            track_offsets_m,
        }
    }

    /// The smallest radius drawn (for how finely a curve is drawn): the
    /// section's, or the sharpest of a line's curves and transitions;
    /// `None` when everything is straight.
    pub fn min_radius_m(&self) -> Option<f64> {
        match &self.centre {
            Some(centre) => centre.min_radius_m,
            None => self.curve_radius_m,
        }
    }

    /// A line's segments to name on the plan: (the middle of the segment
    /// in m, its id); none on a section.
    pub fn segment_labels(info: &SectionInfo<'_>) -> Vec<(f64, String)> {
        let Some(line) = info.line.as_deref() else {
            return Vec::new();
        };
        let mut start = 0.0;
        line.segments
            .iter()
            .map(|s| {
                let mid = (start + s.end_m) / 2.0;
                start = s.end_m;
                (mid, s.id.clone())
            })
            .collect()
    }

    /// The plan position of the point at `d_m` along the centre line and
    /// `offset_m` to its left.
    pub fn xy(&self, d_m: f64, offset_m: f64) -> [f64; 2] {
        if let Some(centre) = &self.centre {
            return centre.xy(d_m, offset_m);
        }
        match self.curve_radius_m {
            Some(radius) => {
                let theta = d_m / radius;
                let r = radius + offset_m;
                [r * theta.sin(), r * theta.cos() - radius]
            }
            None => [d_m, offset_m],
        }
    }

    /// The direction of increasing d at `d_m`, a unit vector.
    pub fn tangent(&self, d_m: f64) -> [f64; 2] {
        if let Some(centre) = &self.centre {
            let heading = centre.heading(d_m);
            return [heading.cos(), heading.sin()];
        }
        match self.curve_radius_m {
            Some(radius) => {
                let theta = d_m / radius;
                [theta.cos(), -theta.sin()]
            }
            None => [1.0, 0.0],
        }
    }
}

/// A line's centre line on the plan: position and heading every
/// [`CentreLine::STEP_M`] from d = 0, integrated from the curvature.
#[derive(Debug, Clone)]
pub struct CentreLine {
    /// Per sample: x, y and the heading (radians from +x, counterclockwise).
    samples: Vec<[f64; 3]>,
    min_radius_m: Option<f64>,
}

impl CentreLine {
    /// The spacing of the samples, m: a chord of 0.5 m strays less than
    /// 0.1 mm from an arc of 300 m.
    pub const STEP_M: f64 = 0.5;

    pub fn new(line: &Line, length_m: f64) -> CentreLine {
        // Signed curvature of a curve segment: positive turns left, away
        // from a high rail on the right (rail 1 is drawn on the right).
        let curvature = |k: usize| -> f64 {
            match line.segments.get(k).map(|s| (s.kind, s.radius_m)) {
                Some((SegmentKind::Curve { high_rail }, Some(r))) if r > 0.0 => {
                    if high_rail == 0 {
                        -1.0 / r
                    } else {
                        1.0 / r
                    }
                }
                _ => 0.0,
            }
        };
        let at = |d: f64| -> f64 {
            let k = line.segment_at(d).unwrap_or(line.segments.len() - 1);
            let start = k.checked_sub(1).map_or(0.0, |j| line.segments[j].end_m);
            let s = &line.segments[k];
            match s.kind {
                SegmentKind::Tangent => 0.0,
                SegmentKind::Curve { .. } => curvature(k),
                SegmentKind::Transition { curve_at, .. } => {
                    let share = ((d - start) / (s.end_m - start)).clamp(0.0, 1.0);
                    match curve_at {
                        CurveAt::End => curvature(k + 1) * share,
                        CurveAt::Start => k.checked_sub(1).map_or(0.0, curvature) * (1.0 - share),
                    }
                }
            }
        };
        let n = (length_m / Self::STEP_M).ceil() as usize + 1;
        let mut samples = Vec::with_capacity(n + 1);
        let (mut x, mut y, mut heading) = (0.0_f64, 0.0_f64, 0.0_f64);
        samples.push([x, y, heading]);
        for k in 0..n {
            let d = k as f64 * Self::STEP_M;
            // The midpoint rule: the heading halfway along the step.
            let mid = heading + at(d + Self::STEP_M / 4.0) * Self::STEP_M / 2.0;
            x += mid.cos() * Self::STEP_M;
            y += mid.sin() * Self::STEP_M;
            heading += at(d + Self::STEP_M / 2.0) * Self::STEP_M;
            samples.push([x, y, heading]);
        }
        let min_radius_m = (0..line.segments.len())
            .map(curvature)
            .filter(|c| *c != 0.0)
            // A transition's sharpest end is its curve's radius.
            .map(|c| 1.0 / c.abs())
            .fold(None, |m: Option<f64>, r| Some(m.map_or(r, |m| m.min(r))));
        CentreLine {
            samples,
            min_radius_m,
        }
    }

    /// The sample before `d_m` and how far past it `d_m` lies, 0 to 1.
    fn place(&self, d_m: f64) -> (usize, f64) {
        let u = (d_m / Self::STEP_M).max(0.0);
        let k = (u.floor() as usize).min(self.samples.len() - 2);
        (k, (u - k as f64).clamp(0.0, 1.0))
    }

    fn heading(&self, d_m: f64) -> f64 {
        let (k, f) = self.place(d_m);
        self.samples[k][2] * (1.0 - f) + self.samples[k + 1][2] * f
    }

    fn xy(&self, d_m: f64, offset_m: f64) -> [f64; 2] {
        let (k, f) = self.place(d_m);
        let [x0, y0, _] = self.samples[k];
        let [x1, y1, _] = self.samples[k + 1];
        let heading = self.heading(d_m);
        let (x, y) = (x0 + (x1 - x0) * f, y0 + (y1 - y0) * f);
        // To the left of the direction of increasing d.
        [x - offset_m * heading.sin(), y + offset_m * heading.cos()]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tortwin_recording::line::Segment;

    fn plan(radius: Option<f64>, offsets: Vec<f64>) -> Plan {
        Plan {
            curve_radius_m: radius,
            centre: None,
            gauge_m: 15.0,
            rail_offsets_m: offsets.clone(),
            track_offsets_m: offsets,
        }
    }

    #[test]
    fn points_lie_on_the_arc_of_their_radius() {
        let p = plan(Some(400.0), vec![7.5, -7.5]);
        for d in [0.0, 100.0, 599.0] {
            for o in [7.5, -7.5] {
                let [x, y] = p.xy(d, o);
                let r = (x * x + (y + 400.0).powi(2)).sqrt();
                assert!((r - (400.0 + o)).abs() < 1e-9);
                // The arc length along the centre line is d.
                let theta = x.atan2(y + 400.0);
                assert!((theta * 400.0 - d).abs() < 1e-9);
            }
        }
        assert_eq!(plan(None, vec![0.0]).xy(12.0, 3.0), [12.0, 3.0]);
    }

    fn segment(id: &str, kind: SegmentKind, end_m: f64, radius_m: Option<f64>) -> Segment {
        Segment {
            id: id.into(),
            kind,
            end_m,
            radius_m,
        }
    }

    /// A line of one curve is drawn as the section's curve of that radius
    /// (rail 0 high: bending to the right, as a section's curve), to a
    /// millimetre.
    #[test]
    fn a_line_of_one_curve_lies_on_its_arc() {
        let line = Line {
            line_id: "l".into(),
            segments: vec![segment(
                "C",
                SegmentKind::Curve { high_rail: 0 },
                600.0,
                Some(400.0),
            )],
        };
        let centre = CentreLine::new(&line, 600.0);
        let arc = plan(Some(400.0), vec![7.5, -7.5]);
        for d in [0.0, 123.4, 599.0, 600.0] {
            for o in [7.5, 0.0, -7.5] {
                let [x, y] = centre.xy(d, o);
                let [ax, ay] = arc.xy(d, o);
                assert!((x - ax).abs() < 1e-3 && (y - ay).abs() < 1e-3, "{d} {o}");
            }
        }
    }

    /// Tangent, transition, curve (right rail high: a left turn),
    /// transition, tangent: the heading turns by the curve's length over its
    /// radius plus half of each transition's, and stays put on the tangents;
    /// a curve without a radius is straight.
    #[test]
    fn a_line_turns_through_its_transitions_and_curves() {
        let right_high = SegmentKind::Curve { high_rail: 1 };
        let into = SegmentKind::Transition {
            high_rail: 1,
            curve_at: CurveAt::End,
        };
        let out = SegmentKind::Transition {
            high_rail: 1,
            curve_at: CurveAt::Start,
        };
        let line = Line {
            line_id: "l".into(),
            segments: vec![
                segment("T0", SegmentKind::Tangent, 100.0, None),
                segment("X1", into, 160.0, None),
                segment("C1", right_high, 460.0, Some(300.0)),
                segment("X2", out, 520.0, None),
                segment("T1", SegmentKind::Tangent, 700.0, None),
                segment("C2", SegmentKind::Curve { high_rail: 0 }, 800.0, None),
            ],
        };
        let centre = CentreLine::new(&line, 800.0);
        let turn = (300.0 + 60.0) / 300.0;
        assert!(centre.heading(50.0).abs() < 1e-12);
        assert!(
            (centre.heading(600.0) - turn).abs() < 1e-9,
            "{}",
            centre.heading(600.0)
        );
        assert!((centre.heading(800.0) - turn).abs() < 1e-9);
        // On the tangent after the curve the track runs straight.
        let [x0, y0] = centre.xy(560.0, 0.0);
        let [x1, y1] = centre.xy(700.0, 0.0);
        assert!(((x1 - x0).hypot(y1 - y0) - 140.0).abs() < 1e-6);
        assert_eq!(centre.min_radius_m, Some(300.0));
    }
}
