//! The run summary page: the engine's end-of-run figures and how to read
//! the views.

use std::fmt::Write as _;

use tortwin_engine::sink::RunSummary;

use super::G_PER_KG;
use crate::scale::TARGET_BAND;

/// The end-of-run figures as a markdown page; `history` is `(B, E)`.
pub(super) fn summarize(summary: &RunSummary, history: (usize, usize)) -> String {
    let mut md = String::new();
    // Writing to a String cannot fail.
    let _ = writeln!(md, "# Run summary\n");
    let _ = writeln!(
        md,
        "- {} trains, {} wheels, {} contacts, {} pulses, {} measurements",
        summary.trains, summary.wheels, summary.contacts, summary.pulses, summary.measurements
    );
    let _ = writeln!(
        md,
        "- {} weather messages, {} messages on unknown topics",
        summary.weather_messages, summary.unknown_topic_messages
    );
    if !summary.rmse.is_empty() {
        let _ = writeln!(md, "\n## Measured vs simulated\n");
        let _ = writeln!(md, "| quantity | measurements | RMSE |");
        let _ = writeln!(md, "|---|---|---|");
        for (quantity, count, rmse) in &summary.rmse {
            let _ = writeln!(md, "| {quantity} | {count} | {rmse:.4} |");
        }
    }
    let balance = &summary.mass_balance;
    let _ = writeln!(md, "\n## Product mass balance (g)\n");
    let _ = writeln!(md, "| term | mass (g) |");
    let _ = writeln!(md, "|---|---|");
    for (term, kg) in [
        ("on rail at start", balance.on_rail_start_kg),
        ("applied", balance.applied_kg),
        ("on rail at end", balance.on_rail_end_kg),
        ("carried out on wheels", balance.carried_out_kg),
        ("consumed", balance.consumed_kg),
        ("capped at m_max", balance.capped_kg),
        ("lost to time effects", balance.effects_lost_kg),
    ] {
        let _ = writeln!(md, "| {term} | {:.3} |", kg * G_PER_KG);
    }
    let _ = writeln!(
        md,
        "\nrelative closing error: {:.2e}",
        balance.closing_error()
    );
    let (rows, every) = history;
    let [band_low, band_high] = TARGET_BAND;
    let _ = writeln!(md, "\n## Reading the views\n");
    let _ = writeln!(
        md,
        "- colours of mu, the same in every tortwin file: classes 0.01 wide; blue below \
         the target band {band_low:.2}-{band_high:.2} (too much product, braking risk), \
         green inside it, yellow to dark red above it (dry); hover a point for its class. \
         The product layer: grey below 1e-4 mg, then viridis by quarter decades up to 100 mg"
    );
    let _ = writeln!(
        md,
        "- the curve: each rail's grid points on the section's plan (the gauge drawn wide), \
         as they were after the train at the time cursor"
    );
    let _ = writeln!(
        md,
        "- profiles: mu (rail colour) and adhesion T/N (paler) along d in m, the target band \
         shaded; the product on the rail (rail colour) and on the last wheel (paler) on \
         decades of mg"
    );
    if rows > 0 {
        let _ = writeln!(
            md,
            "- mu history: one row per train, newest at the bottom, d in m across, in blocks \
             of {rows} trains, updated every {every} trains and after the last one, \
             coloured by the mu scale"
        );
    }
    let _ = writeln!(
        md,
        "- site plots: dots are the measurements, the pale line through small dots the twin"
    );
    md
}
