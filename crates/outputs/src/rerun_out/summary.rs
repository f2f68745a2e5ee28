//! The run summary page: the engine's end-of-run figures and how to read
//! the views.

use std::fmt::Write as _;

use tortwin_engine::sink::RunSummary;

use super::G_PER_KG;

/// The end-of-run figures as a markdown page; `history` is `(K, E)`.
pub(super) fn summarize(
    summary: &RunSummary,
    mu_color_range: [f64; 2],
    history: (usize, usize),
) -> String {
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
    let [low, high] = mu_color_range;
    let (rows, every) = history;
    let _ = writeln!(md, "\n## Reading the views\n");
    if rows > 0 {
        let _ = writeln!(
            md,
            "- mu history heatmaps: one row per train (the last {rows}), newest at the bottom, \
             one column per grid point, updated every {every} trains and after the last one; \
             colour Viridis from mu = {low:.2} (dark purple) to {high:.2} (yellow)"
        );
    }
    let _ = writeln!(
        md,
        "- site plots: dots are the measurements, the pale line through small dots the twin"
    );
    md
}
