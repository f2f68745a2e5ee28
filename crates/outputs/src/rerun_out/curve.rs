//! The section on a plan (the curve itself, coloured by friction or by
//! product), the profiles along d as lines, and the mu history image: what
//! is logged once for them, and how a snapshot becomes a row of each.

use crate::rerun_sdk;
use crate::rerun_sdk::components::{Color, Radius};
use crate::rerun_sdk::datatypes::Rgba32;
use crate::rerun_sdk::{RecordingStream, RecordingStreamError};
use tortwin_engine::sink::SectionInfo;

use crate::geometry::Plan;
use crate::scale::{
    mass_class, mass_class_color, mass_class_label, mu_class, mu_class_color, mu_class_label,
    MASS_CLASSES, MU_CLASSES, TARGET_BAND,
};

use super::batch::TrackState;
use super::entities::entity;

/// Height of mu = 1 in a profile view, as a share of the section's length:
/// the views are about as tall as wide.
const PROFILE_HEIGHT_PER_LENGTH: f64 = 1.0;
/// Highest mu of the profile view's frame.
const PROFILE_MU_TOP: f64 = 0.8;
/// The product profile's decades: 1e-4 mg at the bottom, 1e2 mg at the top.
const PRODUCT_DECADES: [f64; 2] = [-4.0, 2.0];
/// A profile line is drawn through fewer points where it is straight: no
/// value is further than this from the line (in mu, and in decades of mg
/// for the product): half a tribometer's last digit, a fifth of a pixel
/// of a profile view 500 pixels high.
pub(super) const MU_TOLERANCE: f64 = 5e-4;
pub(super) const DECADE_TOLERANCE: f64 = 5e-3;

/// Where the views put things, from the section.
pub(super) struct Frames {
    pub(super) plan: Plan,
    /// Scene units of mu = 1 in the profile views (the product view's six
    /// decades span the same height as mu 0 to 0.8).
    pub(super) profile_height: f64,
    pub(super) length_m: f64,
    pub(super) spacing_m: f64,
}

impl Frames {
    pub(super) fn new(info: &SectionInfo<'_>) -> Frames {
        let length_m = info.section.length_m;
        Frames {
            plan: Plan::new(info),
            profile_height: length_m * PROFILE_HEIGHT_PER_LENGTH,
            length_m,
            spacing_m: match *info.grid_d_m {
                [a, b, ..] => b - a,
                _ => 1.0,
            },
        }
    }

    /// The profile view's y of mu (drawn upwards: the 2D view's y points down).
    pub(super) fn mu_y(&self, mu: f64) -> f64 {
        -mu.clamp(-0.05, PROFILE_MU_TOP + 0.05) * self.profile_height
    }

    /// The product view's y of a mass in mg, on decades from 1e-4 to 1e2 mg.
    pub(super) fn product_y(&self, mass_mg: f64) -> f64 {
        let [low, high] = PRODUCT_DECADES;
        let decades = if mass_mg > 0.0 {
            mass_mg.log10().clamp(low, high)
        } else {
            low
        };
        -(decades - low) / (high - low) * PROFILE_MU_TOP * self.profile_height
    }
}

/// What a 2D view shows: `[[x_min, x_max], [y_min, y_max]]`.
pub(super) type Bounds = [[f64; 2]; 2];

impl Frames {
    /// The plan with its labels and colour bar, a margin around.
    pub(super) fn plan_bounds(&self) -> Bounds {
        let plan = &self.plan;
        let (mut x, mut y) = (
            [f64::INFINITY, f64::NEG_INFINITY],
            [f64::INFINITY, f64::NEG_INFINITY],
        );
        for k in 0..=100 {
            let d = self.length_m * f64::from(k) / 100.0;
            for &o in &plan.rail_offsets_m {
                let [px, py] = plan.xy(d, o);
                x = [x[0].min(px), x[1].max(px)];
                y = [y[0].min(py), y[1].max(py)];
            }
        }
        let g = plan.gauge_m;
        // The labels outside the rails, the colour bar and its labels below.
        [
            [x[0] - 3.0 * g, x[1] + 3.0 * g],
            [y[0] - 3.0 * g, y[1] + 6.0 * g],
        ]
    }

    /// A profile view: d from before 0 (the level labels) to past the end,
    /// mu 0.85 to below 0 (the distance labels).
    pub(super) fn profile_bounds(&self) -> Bounds {
        let l = self.length_m;
        [
            [-0.08 * l, 1.03 * l],
            [self.mu_y(PROFILE_MU_TOP + 0.05), self.mu_y(0.0) + 0.08 * l],
        ]
    }
}

fn rgba([r, g, b]: [u8; 3]) -> Rgba32 {
    Rgba32::from_rgb(r, g, b)
}

/// Points with a label each, shown, in one colour.
fn labelled(
    positions: Vec<[f32; 2]>,
    labels: Vec<String>,
    color: Color,
    radius: Radius,
) -> rerun_sdk::Points2D {
    rerun_sdk::Points2D::new(positions)
        .with_labels(labels)
        .with_show_labels(true)
        .with_colors([color])
        .with_radii([radius])
}

/// Distance labels every 100 m (or a tenth of a shorter section) at `y`.
fn distance_ticks(length_m: f64, y: f64) -> (Vec<[f32; 2]>, Vec<String>) {
    let step = if length_m >= 500.0 {
        100.0
    } else {
        (length_m / 10.0).max(1.0)
    };
    (0..)
        .map(|k| f64::from(k) * step)
        .take_while(|&d| d <= length_m + 1e-9)
        .map(|d| ([d as f32, y as f32], format!("{d:.0} m")))
        .unzip()
}

/// The annotation context of the mu scale: class, label, colour.
fn mu_context() -> rerun_sdk::AnnotationContext {
    rerun_sdk::AnnotationContext::new(
        (0..=MU_CLASSES)
            .map(|c| (c, mu_class_label(c), rgba(mu_class_color(c))))
            .collect::<Vec<_>>()
            .iter()
            .map(|(c, label, color)| (*c, label.as_str(), *color))
            .collect::<Vec<_>>(),
    )
}

fn mass_context() -> rerun_sdk::AnnotationContext {
    rerun_sdk::AnnotationContext::new(
        (1..=MASS_CLASSES)
            .map(|c| (c, mass_class_label(c), rgba(mass_class_color(c))))
            .collect::<Vec<_>>()
            .iter()
            .map(|(c, label, color)| (*c, label.as_str(), *color))
            .collect::<Vec<_>>(),
    )
}

/// Logs what never changes: the scales, the plan's rails, every track's
/// point positions, applicators, sites and legends; the profile views'
/// frames (grid lines, target band, applicators); the history's scale.
pub(super) fn log_static(
    rec: &RecordingStream,
    info: &SectionInfo<'_>,
    frames: &Frames,
    tracks: &[TrackState],
) -> Result<(), RecordingStreamError> {
    let section = &*info.section;
    let plan = &frames.plan;
    let gauge = plan.gauge_m;
    let xy = |d: f64, o: f64| {
        let [x, y] = plan.xy(d, o);
        [x as f32, y as f32]
    };

    rec.log_static("curve/mu", &mu_context())?;
    rec.log_static("curve/product", &mass_context())?;
    rec.log_static("history", &mu_context())?;

    // The rails under the coloured points, as thin grey lines.
    let fine: Vec<f64> = (0..=200)
        .map(|k| section.length_m * f64::from(k) / 200.0)
        .collect();
    for (rail, name) in section.rails.iter().enumerate() {
        let offset = plan.rail_offsets_m.get(rail).copied().unwrap_or(0.0);
        let strip: Vec<[f32; 2]> = fine.iter().map(|&d| xy(d, offset)).collect();
        for layer in ["mu", "product"] {
            rec.log_static(
                entity(&["curve", layer, "rails", name]),
                &rerun_sdk::LineStrips2D::new([strip.clone()])
                    .with_colors([Color::from_rgb(150, 150, 150)])
                    .with_radii([Radius::new_scene_units((gauge / 40.0) as f32)]),
            )?;
        }
    }
    // Each track's grid points; their class ids come with every snapshot.
    for state in tracks {
        let offset = plan
            .track_offsets_m
            .get(state.index)
            .copied()
            .unwrap_or(0.0);
        let points: Vec<[f32; 2]> = info.grid_d_m.iter().map(|&d| xy(d, offset)).collect();
        let radius = Radius::new_scene_units((gauge / 5.0) as f32);
        for layer in [&state.entities.curve_mu, &state.entities.curve_product] {
            rec.log_static(
                layer.clone(),
                &rerun_sdk::Points2D::new(points.clone()).with_radii([radius]),
            )?;
        }
        let color = state.entities.color;
        let pale = super::entities::lighten(color, 0.5);
        for (path, color, width) in [
            (&state.entities.mu, color, 1.5),
            (&state.entities.adhesion, pale, 1.0),
            (&state.entities.rail_mass, color, 1.5),
            (&state.entities.wheel_mass, pale, 1.0),
        ] {
            rec.log_static(
                path.clone(),
                &rerun_sdk::LineStrips2D::update_fields()
                    .with_colors([color])
                    .with_radii([Radius::new_ui_points(width)]),
            )?;
        }
    }
    // Applicators and sites, outside the leftmost rail.
    let outside = plan.rail_offsets_m.iter().copied().fold(0.0, f64::max) + gauge;
    for layer in ["mu", "product"] {
        let (positions, labels): (Vec<[f32; 2]>, Vec<String>) = section
            .applicators
            .iter()
            .map(|a| {
                (
                    xy(a.position_m, outside),
                    format!("{} ({:.0} m)", a.id, a.position_m),
                )
            })
            .unzip();
        let marker = Radius::new_scene_units((gauge / 2.5) as f32);
        rec.log_static(
            entity(&["curve", layer, "applicators"]),
            &labelled(positions, labels, Color::from_rgb(230, 160, 30), marker),
        )?;
        let (positions, labels): (Vec<[f32; 2]>, Vec<String>) = section
            .sites
            .iter()
            .map(|s| {
                (
                    xy(s.position_m, outside),
                    format!("site {} ({:.0} m)", s.id, s.position_m),
                )
            })
            .unzip();
        rec.log_static(
            entity(&["curve", layer, "sites"]),
            &labelled(positions, labels, Color::from_rgb(90, 90, 90), marker),
        )?;
        // A line's segments by name, at their middles, on the other side.
        let segments = Plan::segment_labels(info);
        if !segments.is_empty() {
            let (positions, labels): (Vec<[f32; 2]>, Vec<String>) = segments
                .into_iter()
                .map(|(d, id)| (xy(d, -outside), id))
                .unzip();
            rec.log_static(
                entity(&["curve", layer, "segments"]),
                &labelled(
                    positions,
                    labels,
                    Color::from_rgb(60, 90, 160),
                    Radius::new_scene_units((gauge / 5.0) as f32),
                ),
            )?;
        }
    }
    log_legends(rec, frames)?;
    log_profile_frames(rec, info, frames)?;
    // The history's distance scale, above its first row: d in m.
    let (positions, labels) = distance_ticks(frames.length_m, -3.0 * frames.spacing_m);
    for state in tracks {
        rec.log_static(
            state
                .entities
                .history
                .join(&rerun_sdk::EntityPath::from_single_string("distance")),
            &labelled(
                positions.clone(),
                labels.clone(),
                Color::from_rgb(160, 160, 160),
                Radius::new_ui_points(1.0),
            ),
        )?;
    }
    Ok(())
}

/// A colour bar per layer below the plan (rerun's 2D y points down): a
/// short thick line per class, coloured by the class, with a label at every
/// tenth of mu (or every decade of mg).
fn log_legends(rec: &RecordingStream, frames: &Frames) -> Result<(), RecordingStreamError> {
    let plan = &frames.plan;
    let mut high_y = f64::NEG_INFINITY;
    let mut low_x = f64::INFINITY;
    let mut high_x = f64::NEG_INFINITY;
    for k in 0..=100 {
        let d = frames.length_m * f64::from(k) / 100.0;
        for &o in &plan.rail_offsets_m {
            let [x, y] = plan.xy(d, o);
            high_y = high_y.max(y);
            low_x = low_x.min(x);
            high_x = high_x.max(x);
        }
    }
    let width = (high_x - low_x).max(plan.gauge_m * 10.0);
    let height = plan.gauge_m;
    let middle = high_y + 3.0 * height;
    let mu_tick = |c: u16| {
        (c - 1)
            .is_multiple_of(10)
            .then(|| format!("{:.1}", f64::from(c - 1) / 100.0))
    };
    let mass_tick = |c: u16| {
        (c >= 2 && (c - 2).is_multiple_of(4))
            .then(|| format!("{:.0e}", 1e-4 * 10f64.powi(i32::from((c - 2) / 4))))
    };
    for (classes, path, title, tick) in [
        (
            MU_CLASSES,
            "curve/mu/legend",
            format!(
                "mu (target band {:.2}-{:.2})",
                TARGET_BAND[0], TARGET_BAND[1]
            ),
            &mu_tick as &dyn Fn(u16) -> Option<String>,
        ),
        (
            MASS_CLASSES,
            "curve/product/legend",
            "product on the rail, mg".to_owned(),
            &mass_tick,
        ),
    ] {
        let step = width / f64::from(classes);
        let at = |c: u16| (low_x + f64::from(c - 1) * step) as f32;
        let strips: Vec<Vec<[f32; 2]>> = (1..=classes)
            .map(|c| vec![[at(c), middle as f32], [at(c) + step as f32, middle as f32]])
            .collect();
        rec.log_static(
            format!("{path}/bar"),
            &rerun_sdk::LineStrips2D::new(strips)
                .with_class_ids(1..=classes)
                .with_radii([Radius::new_scene_units((height / 2.0) as f32)]),
        )?;
        let (mut ticks, mut labels): (Vec<[f32; 2]>, Vec<String>) = (1..=classes)
            .filter_map(|c| tick(c).map(|label| ([at(c), (middle + 1.5 * height) as f32], label)))
            .unzip();
        ticks.push([low_x as f32, (middle - 1.5 * height) as f32]);
        labels.push(title);
        rec.log_static(
            format!("{path}/ticks"),
            &labelled(
                ticks,
                labels,
                Color::from_rgb(200, 200, 200),
                Radius::new_ui_points(1.0),
            ),
        )?;
    }
    Ok(())
}

/// The profile views' frames: grid lines with labels, the target band
/// shaded, the applicators marked, distance ticks.
fn log_profile_frames(
    rec: &RecordingStream,
    info: &SectionInfo<'_>,
    frames: &Frames,
) -> Result<(), RecordingStreamError> {
    let length = frames.length_m;
    let grid_color = Color::from_rgb(90, 90, 90);
    let thin = Radius::new_ui_points(0.5);
    let label_x = (-0.02 * length) as f32;
    for (view, levels) in [
        (
            "profiles/mu",
            (0..=8)
                .map(|k| {
                    let mu = f64::from(k) / 10.0;
                    (frames.mu_y(mu), format!("{mu:.1}"))
                })
                .collect::<Vec<_>>(),
        ),
        (
            "profiles/product",
            (-4..=2)
                .map(|e| (frames.product_y(10f64.powi(e)), format!("1e{e} mg")))
                .collect(),
        ),
    ] {
        let strips: Vec<Vec<[f32; 2]>> = levels
            .iter()
            .map(|(y, _)| vec![[0.0, *y as f32], [length as f32, *y as f32]])
            .collect();
        rec.log_static(
            format!("{view}/frame/levels"),
            &rerun_sdk::LineStrips2D::new(strips)
                .with_colors([grid_color])
                .with_radii([thin]),
        )?;
        let (positions, labels): (Vec<[f32; 2]>, Vec<String>) = levels
            .into_iter()
            .map(|(y, label)| ([label_x, y as f32], label))
            .unzip();
        rec.log_static(
            format!("{view}/frame/level_labels"),
            &labelled(positions, labels, grid_color, Radius::new_ui_points(0.5)),
        )?;
        let bottom = if view == "profiles/mu" {
            frames.mu_y(0.0)
        } else {
            frames.product_y(0.0)
        } + 0.04 * length;
        let (positions, labels) = distance_ticks(length, bottom);
        rec.log_static(
            format!("{view}/frame/distance"),
            &labelled(positions, labels, grid_color, Radius::new_ui_points(1.0)),
        )?;
        // The applicators as vertical lines.
        let top = if view == "profiles/mu" {
            frames.mu_y(PROFILE_MU_TOP)
        } else {
            frames.product_y(1e2)
        };
        let strips: Vec<Vec<[f32; 2]>> = info
            .section
            .applicators
            .iter()
            .map(|a| {
                vec![
                    [a.position_m as f32, top as f32],
                    [a.position_m as f32, (bottom - 0.04 * length) as f32],
                ]
            })
            .collect();
        let orange = Color::from_rgb(230, 160, 30);
        rec.log_static(
            format!("{view}/frame/applicators"),
            &rerun_sdk::LineStrips2D::new(strips)
                .with_colors([orange])
                .with_radii([Radius::new_ui_points(1.0)]),
        )?;
        let (positions, labels): (Vec<[f32; 2]>, Vec<String>) = info
            .section
            .applicators
            .iter()
            .map(|a| {
                (
                    [a.position_m as f32, (top - 0.03 * length) as f32],
                    format!("{} ({:.0} m)", a.id, a.position_m),
                )
            })
            .unzip();
        rec.log_static(
            format!("{view}/frame/applicator_labels"),
            &labelled(positions, labels, orange, Radius::new_ui_points(1.0)),
        )?;
    }
    // The target band, shaded: a line as thick as the band along its middle.
    let [low, high] = TARGET_BAND;
    let middle = frames.mu_y((low + high) / 2.0) as f32;
    // The line's round caps reach half its thickness beyond its ends.
    let cap = ((high - low) / 2.0 * frames.profile_height) as f32;
    rec.log_static(
        "profiles/mu/frame/target_band",
        &rerun_sdk::LineStrips2D::new([vec![[cap, middle], [length as f32 - cap, middle]]])
            .with_labels([format!("target band {low:.2}-{high:.2}")])
            .with_show_labels(true)
            .with_colors([Color::from_unmultiplied_rgba(60, 180, 90, 60)])
            .with_radii([Radius::new_scene_units(
                ((high - low) / 2.0 * frames.profile_height) as f32,
            )]),
    )?;
    Ok(())
}

/// The class of every grid point's mu and rail product for the curve.
pub(super) fn classes(
    mu: &[f64],
    rail_mass_mg: impl Iterator<Item = f64>,
    mu_ids: &mut Vec<u16>,
    mass_ids: &mut Vec<u16>,
) {
    mu_ids.extend(mu.iter().map(|&m| mu_class(m)));
    mass_ids.extend(rail_mass_mg.map(mass_class));
}

impl Frames {
    /// A mu profile (mu, adhesion) as the lines the mu view draws: through
    /// the fewest grid points within [`MU_TOLERANCE`], broken where a value
    /// is missing (NaN: no wheel on a line's band there).
    pub(super) fn mu_strips(&self, d_m: &[f64], values: &[f64]) -> Vec<Vec<[f32; 2]>> {
        strips(d_m, values, MU_TOLERANCE, &|v| self.mu_y(v))
    }

    /// Masses in kg as the lines the product view draws: decades of mg
    /// (1e-4 mg at least) within [`DECADE_TOLERANCE`], broken at NaN.
    pub(super) fn product_strips(&self, d_m: &[f64], masses_kg: &[f64]) -> Vec<Vec<[f32; 2]>> {
        let decades: Vec<f64> = masses_kg
            .iter()
            .map(|&m| match m.is_nan() {
                true => f64::NAN,
                false => (m * super::MG_PER_KG).max(1e-4).log10(),
            })
            .collect();
        strips(d_m, &decades, DECADE_TOLERANCE, &|v| {
            self.product_y(10f64.powf(v))
        })
    }
}

/// A line per run of values that are not NaN, through the fewest grid
/// points within `tolerance`, at `(d, y(value))`.
fn strips(
    d_m: &[f64],
    values: &[f64],
    tolerance: f64,
    y: &dyn Fn(f64) -> f64,
) -> Vec<Vec<[f32; 2]>> {
    runs(values)
        .map(|run| {
            simplify(&d_m[run.clone()], &values[run.clone()], tolerance)
                .into_iter()
                .map(|k| [d_m[run.start + k] as f32, y(values[run.start + k]) as f32])
                .collect()
        })
        .collect()
}

/// The runs of consecutive values that are not NaN: the whole profile on
/// a section, the stretches a line's band was in contact otherwise.
pub(super) fn runs(values: &[f64]) -> impl Iterator<Item = std::ops::Range<usize>> + '_ {
    let mut i = 0;
    std::iter::from_fn(move || {
        while values.get(i).is_some_and(|v| v.is_nan()) {
            i += 1;
        }
        let start = i;
        while values.get(i).is_some_and(|v| !v.is_nan()) {
            i += 1;
        }
        (i > start).then_some(start..i)
    })
}

/// A profile through fewer points: Ramer-Douglas-Peucker on (d, value),
/// keeping every point whose value is further than `tolerance` from the
/// line through the kept ones (measured vertically).
pub(super) fn simplify(d_m: &[f64], values: &[f64], tolerance: f64) -> Vec<usize> {
    let n = d_m.len().min(values.len());
    if n <= 2 {
        return (0..n).collect();
    }
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0, n - 1)];
    while let Some((a, b)) = stack.pop() {
        let (da, va, db, vb) = (d_m[a], values[a], d_m[b], values[b]);
        // The line's slope once per segment, not a division per point.
        let slope = (vb - va) / (db - da);
        let mut worst = (0.0, a);
        for i in a + 1..b {
            let off = (values[i] - (va + (d_m[i] - da) * slope)).abs();
            if off > worst.0 || off.is_nan() {
                worst = (if off.is_nan() { f64::INFINITY } else { off }, i);
            }
        }
        if worst.0 > tolerance {
            keep[worst.1] = true;
            stack.push((a, worst.1));
            stack.push((worst.1, b));
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

#[cfg(test)]
mod tests {
    use super::simplify;

    #[test]
    fn simplified_lines_stay_within_the_tolerance() {
        let d: Vec<f64> = (0..500).map(|i| f64::from(i) * 2.0).collect();
        let v: Vec<f64> = d
            .iter()
            .map(|x| 0.2 + 0.3 * (1.0 - (-x / 150.0).exp()))
            .collect();
        let kept = simplify(&d, &v, 1e-4);
        assert!(kept.len() < 100, "{}", kept.len());
        for w in kept.windows(2) {
            let (a, b) = (w[0], w[1]);
            for i in a..=b {
                let t = (d[i] - d[a]) / (d[b] - d[a]);
                let line = v[a] + t * (v[b] - v[a]);
                assert!((v[i] - line).abs() <= 1e-4 + 1e-12);
            }
        }
        let flat = vec![0.58; 500];
        assert_eq!(simplify(&d, &flat, 1e-4), vec![0, 499]);
    }
}
