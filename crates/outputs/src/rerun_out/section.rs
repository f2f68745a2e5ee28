//! The section as a page, logged once at the start (the plan and the
//! profiles' frames are in `curve.rs`).

use crate::rerun_sdk;
use std::fmt::Write as _;

use crate::rerun_sdk::{RecordingStream, RecordingStreamError};
use tortwin_engine::sink::SectionInfo;

use super::G_PER_KG;

/// Logs the section page.
pub(super) fn log_description(
    rec: &RecordingStream,
    info: &SectionInfo<'_>,
) -> Result<(), RecordingStreamError> {
    rec.log_static(
        "section/description",
        &rerun_sdk::TextDocument::from_markdown(describe(info)),
    )
}

/// The section as a markdown page.
fn describe(info: &SectionInfo<'_>) -> String {
    let section = &*info.section;
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
    let spacing = match *info.grid_d_m {
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
