//! The one-screen summary printed at the end of a replay.

use std::fmt::Write;
use std::path::Path;

use tortwin_engine::sink::RunSummary;

pub fn render(recording: &Path, s: &RunSummary) -> String {
    let mut out = String::new();
    let b = &s.mass_balance;
    let g = |kg: f64| kg * 1e3;
    // Writing to a String cannot fail.
    let _ = writeln!(out, "replayed {}", recording.display());
    let _ = writeln!(
        out,
        "  trains {}, wheels {}, contacts {}, pulses {}, measurements {}, weather messages {}",
        s.trains, s.wheels, s.contacts, s.pulses, s.measurements, s.weather_messages
    );
    if s.unknown_topic_messages > 0 {
        let _ = writeln!(
            out,
            "  ignored {} messages on unknown topics",
            s.unknown_topic_messages
        );
    }
    if s.rmse.is_empty() {
        let _ = writeln!(out, "  no measurements to compare");
    }
    for (quantity, n, rmse) in &s.rmse {
        let _ = writeln!(
            out,
            "  RMSE measured vs simulated {quantity:>8}: {rmse:.5} (n = {n})"
        );
    }
    let _ = writeln!(out, "  mass balance (g):");
    let _ = writeln!(
        out,
        "    on the rails at the start {:>12.6}",
        g(b.on_rail_start_kg)
    );
    let _ = writeln!(
        out,
        "    applied                   {:>12.6}",
        g(b.applied_kg)
    );
    let _ = writeln!(
        out,
        "    on the rails at the end   {:>12.6}",
        g(b.on_rail_end_kg)
    );
    let _ = writeln!(
        out,
        "    carried out on wheels     {:>12.6}",
        g(b.carried_out_kg)
    );
    let _ = writeln!(
        out,
        "    consumed                  {:>12.6}",
        g(b.consumed_kg)
    );
    let _ = writeln!(
        out,
        "    squeezed out (cap)        {:>12.6}",
        g(b.capped_kg)
    );
    if b.effects_lost_kg != 0.0 {
        let _ = writeln!(
            out,
            "    lost to ageing and rain   {:>12.6}",
            g(b.effects_lost_kg)
        );
    }
    let _ = writeln!(out, "    closes to {:.1e} (relative)", b.closing_error());
    out
}
