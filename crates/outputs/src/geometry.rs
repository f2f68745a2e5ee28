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

use tortwin_engine::sink::SectionInfo;

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
        if section.curve_radius_m.is_some() {
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
                if track.band == "top" {
                    rail
                } else {
                    // Towards the track centre line.
                    rail - rail.signum() * gauge_m / 5.0
                }
            })
            .collect();
        Plan {
            curve_radius_m: section.curve_radius_m,
            gauge_m,
            rail_offsets_m,
            track_offsets_m,
        }
    }

    /// The plan position of the point at `d_m` along the centre line and
    /// `offset_m` to its left.
    pub fn xy(&self, d_m: f64, offset_m: f64) -> [f64; 2] {
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
        match self.curve_radius_m {
            Some(radius) => {
                let theta = d_m / radius;
                [theta.cos(), -theta.sin()]
            }
            None => [1.0, 0.0],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(radius: Option<f64>, offsets: Vec<f64>) -> Plan {
        Plan {
            curve_radius_m: radius,
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
}
