//! What is logged once, statically, at the start: the section as a page
//! and as a plan, and the parts of every profile that never change.

use std::fmt::Write as _;

use rerun::components::{Color, Radius, ValueRange};
use rerun::datatypes::TensorData;
use rerun::{RecordingStream, RecordingStreamError};
use tortwin_engine::sink::SectionInfo;

use super::batch::TrackState;
use super::entities::rail_color;
use super::G_PER_KG;

/// Logs the section page, its map, and every profile's abscissa, bar width
/// and colour; with a fixed `mu_color_range`, the heatmaps' colour range.
pub(super) fn log_section(
    rec: &RecordingStream,
    info: &SectionInfo<'_>,
    tracks: &[TrackState],
    mu_color_range: Option<[f64; 2]>,
) -> Result<(), RecordingStreamError> {
    let section = info.section;
    rec.log_static(
        "section/description",
        &rerun::TextDocument::from_markdown(describe(info)),
    )?;

    // A schematic plan of the section: d along x, the rails drawn apart
    // so the labels do not collide (the gap is not to scale).
    let rail_gap = (section.length_m / 25.0).max(1.0) as f32;
    let rail_y = |rail: usize| rail as f32 * rail_gap;
    let length = section.length_m as f32;
    rec.log_static(
        "section/map/rails",
        &rerun::LineStrips2D::new(
            (0..section.rails.len()).map(|r| vec![[0.0, rail_y(r)], [length, rail_y(r)]]),
        )
        .with_labels(section.rails.iter().map(|r| format!("{r} rail")))
        .with_colors((0..section.rails.len()).map(rail_color))
        .with_radii([Radius::new_ui_points(2.0)]),
    )?;
    let mut positions = Vec::new();
    let mut labels = Vec::new();
    for applicator in &section.applicators {
        for &rail in &applicator.rails {
            positions.push([applicator.position_m as f32, rail_y(rail)]);
            labels.push(format!(
                "{} ({:.1} m)",
                applicator.id, applicator.position_m
            ));
        }
    }
    rec.log_static(
        "section/map/applicators",
        &rerun::Points2D::new(positions)
            .with_labels(labels)
            .with_show_labels(true)
            .with_colors([Color::from_rgb(230, 160, 30)])
            .with_radii([Radius::new_ui_points(6.0)]),
    )?;
    let mut positions = Vec::new();
    let mut labels = Vec::new();
    for site in &section.sites {
        positions.push([site.position_m as f32, -0.5 * rail_gap]);
        labels.push(format!("site {} ({:.1} m)", site.id, site.position_m));
    }
    rec.log_static(
        "section/map/sites",
        &rerun::Points2D::new(positions)
            .with_labels(labels)
            .with_show_labels(true)
            .with_colors([Color::from_rgb(90, 200, 120)])
            .with_radii([Radius::new_ui_points(6.0)]),
    )?;

    // The parts of every profile that never change: d, the bar width C
    // and the track's colour.
    let spacing_m = match info.grid_d_m {
        [first, second, ..] => (second - first) as f32,
        _ => 1.0,
    };
    let abscissa = TensorData::from(info.grid_d_m);
    for track in tracks {
        let track = &track.entities;
        for path in [
            &track.mu,
            &track.adhesion,
            &track.rail_mass,
            &track.wheel_mass,
        ] {
            rec.log_static(
                path.clone(),
                &rerun::BarChart::update_fields()
                    .with_abscissa(abscissa.clone())
                    .with_widths(vec![spacing_m; info.grid_d_m.len()])
                    .with_color(track.color),
            )?;
        }
        if let Some([low, high]) = mu_color_range {
            rec.log_static(
                track.mu_history.clone(),
                &rerun::Tensor::update_fields().with_value_range(ValueRange::new(low, high)),
            )?;
        }
    }
    Ok(())
}

/// The section as a markdown page.
fn describe(info: &SectionInfo<'_>) -> String {
    let section = info.section;
    let mut md = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(md, "# Section {}\n", section.section_id);
    let _ = writeln!(md, "- length: {:.1} m", section.length_m);
    let _ = writeln!(md, "- rails: {}", section.rails.join(", "));
    match section.curve_radius_m {
        Some(radius) => {
            let _ = writeln!(md, "- curve radius: {radius:.0} m");
        }
        None => {
            let _ = writeln!(md, "- tangent track");
        }
    }
    let _ = writeln!(
        md,
        "- rail head radius: {:.3} m, nominal wheel diameter: {:.3} m",
        section.rail_head_radius_m, section.nominal_wheel_diameter_m
    );
    let spacing = match info.grid_d_m {
        [first, second, ..] => format!(", spacing C = {:.3} m", second - first),
        _ => String::new(),
    };
    let _ = writeln!(md, "- grid: {} points{spacing}", info.grid_d_m.len());
    let tracks: Vec<String> = info
        .tracks
        .iter()
        .map(|t| format!("{}/{}", t.rail_name, t.band))
        .collect();
    let _ = writeln!(md, "- tracks (rail/band): {}", tracks.join(", "));

    let _ = writeln!(md, "\n## Applicators\n");
    let _ = writeln!(
        md,
        "| id | position (m) | grid point | rails | nominal pulse (g) |"
    );
    let _ = writeln!(md, "|---|---|---|---|---|");
    for (index, applicator) in section.applicators.iter().enumerate() {
        let rails: Vec<&str> = applicator
            .rails
            .iter()
            .map(|&r| section.rails.get(r).map_or("?", String::as_str))
            .collect();
        let point = info
            .applicator_points
            .get(index)
            .map_or_else(|| "?".to_owned(), usize::to_string);
        let _ = writeln!(
            md,
            "| {} | {:.1} | {point} | {} | {:.2} |",
            applicator.id,
            applicator.position_m,
            rails.join(", "),
            applicator.nominal_pulse_kg * G_PER_KG
        );
    }

    let _ = writeln!(md, "\n## Measurement sites\n");
    let _ = writeln!(md, "| id | position (m) | grid point |");
    let _ = writeln!(md, "|---|---|---|");
    for (index, site) in section.sites.iter().enumerate() {
        let point = info
            .site_points
            .get(index)
            .map_or_else(|| "?".to_owned(), usize::to_string);
        let _ = writeln!(md, "| {} | {:.1} | {point} |", site.id, site.position_m);
    }
    md
}
