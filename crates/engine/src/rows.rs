//! Which bands meet on a line (line.md, "Which bands meet"): for a rail,
//! a bogie position and a grid point, the wheel tread band and the rail
//! head band in contact there; and the rail bands a pulse lands on.
//!
//! | rows | rail | leading axle (wheel–rail) | trailing axle |
//! |---|---|---|---|
//! | tangent | either | C–C | C–C |
//! | curve | high | G–G | C–C |
//! | curve | low | F–C | F–C |
//!
//! A transition takes the curve rows on its half at `curve_at` and the
//! tangent rows on the other; its halves are `[start, mid)` and
//! `[mid, end)`, `mid = (start + end) / 2`, the last segment's second half
//! `[mid, L]`, all in chainage whatever the direction of travel.

use tortwin_recording::line::{CurveAt, Line, SegmentKind};
use tortwin_recording::BogiePosition;

/// A band across the wheel's tread.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum WheelBand {
    /// Field side.
    F,
    /// Centre: the running band on tangent track.
    C,
    /// Flange root.
    G,
}

/// A band across the rail head (no row puts a contact on its field side).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum RailBand {
    /// Crown, the top of rail (`rail_mu` reads it).
    C,
    /// Gauge corner.
    G,
}

/// The pair of bands in contact.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Row {
    pub wheel: WheelBand,
    pub rail: RailBand,
}

const TANGENT: Row = Row {
    wheel: WheelBand::C,
    rail: RailBand::C,
};

/// What a point's segment asks of its rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Rows {
    Tangent,
    Curve { high_rail: usize },
}

/// The rows in force at chainage `d_m` (a grid point of the line).
fn rows_at(line: &Line, d_m: f64) -> Rows {
    let Some(k) = line.segment_at(d_m) else {
        return Rows::Tangent;
    };
    match line.segments[k].kind {
        SegmentKind::Tangent => Rows::Tangent,
        SegmentKind::Curve { high_rail } => Rows::Curve { high_rail },
        SegmentKind::Transition {
            high_rail,
            curve_at,
        } => {
            let (start, end) = (line.start_m(k), line.segments[k].end_m);
            let first_half = d_m < (start + end) / 2.0;
            if first_half == (curve_at == CurveAt::Start) {
                Rows::Curve { high_rail }
            } else {
                Rows::Tangent
            }
        }
    }
}

/// The bands that meet at chainage `d_m` on `rail` under an axle at
/// `bogie` position.
pub fn row(line: &Line, rail: usize, bogie: BogiePosition, d_m: f64) -> Row {
    match rows_at(line, d_m) {
        Rows::Tangent => TANGENT,
        Rows::Curve { high_rail } if rail == high_rail => match bogie {
            BogiePosition::Leading => Row {
                wheel: WheelBand::G,
                rail: RailBand::G,
            },
            BogiePosition::Trailing => TANGENT,
        },
        Rows::Curve { .. } => Row {
            wheel: WheelBand::F,
            rail: RailBand::C,
        },
    }
}

/// The rail bands a pulse at chainage `d_m` on `rail` lands on, in equal
/// shares: the bands the rows there use on that rail (`C` alone on
/// tangent rows and on the low rail, `C` and `G` on the high rail in
/// curve rows).
pub fn pulse_bands(line: &Line, rail: usize, d_m: f64) -> &'static [RailBand] {
    match rows_at(line, d_m) {
        Rows::Curve { high_rail } if rail == high_rail => &[RailBand::C, RailBand::G],
        _ => &[RailBand::C],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tortwin_recording::line::Segment;

    fn segment(id: &str, kind: SegmentKind, end_m: f64) -> Segment {
        Segment {
            id: id.into(),
            kind,
            end_m,
            radius_m: None,
        }
    }

    /// Tangent to 100 m, a transition into a curve (`right` = rail 1 high)
    /// to 200 m, the curve to 300 m, a transition out of it to 400 m.
    fn line() -> Line {
        let high_rail = 1;
        Line {
            line_id: "rows".into(),
            segments: vec![
                segment("T0", SegmentKind::Tangent, 100.0),
                segment(
                    "X1",
                    SegmentKind::Transition {
                        high_rail,
                        curve_at: CurveAt::End,
                    },
                    200.0,
                ),
                segment("C1", SegmentKind::Curve { high_rail }, 300.0),
                segment(
                    "X2",
                    SegmentKind::Transition {
                        high_rail,
                        curve_at: CurveAt::Start,
                    },
                    400.0,
                ),
            ],
        }
    }

    fn pair(r: Row) -> (WheelBand, RailBand) {
        (r.wheel, r.rail)
    }

    #[test]
    fn the_table_of_line_md() {
        use BogiePosition::{Leading, Trailing};
        use RailBand as R;
        use WheelBand as W;
        let line = line();
        let at = |rail, bogie, d| pair(row(&line, rail, bogie, d));
        for d in [0.0, 99.9] {
            for rail in [0, 1] {
                for bogie in [Leading, Trailing] {
                    assert_eq!(at(rail, bogie, d), (W::C, R::C), "tangent {d}");
                }
            }
        }
        // The curve: high rail leading G–G, trailing C–C; low rail F–C.
        assert_eq!(at(1, Leading, 250.0), (W::G, R::G));
        assert_eq!(at(1, Trailing, 250.0), (W::C, R::C));
        assert_eq!(at(0, Leading, 250.0), (W::F, R::C));
        assert_eq!(at(0, Trailing, 250.0), (W::F, R::C));
    }

    #[test]
    fn a_transition_takes_the_curve_rows_on_its_half_at_curve_at() {
        use BogiePosition::Leading;
        let line = line();
        let high_leading = |d| pair(row(&line, 1, Leading, d));
        let curve = (WheelBand::G, RailBand::G);
        let tangent = (WheelBand::C, RailBand::C);
        // X1 [100, 200), curve at its end: [150, 200) curve rows.
        assert_eq!(high_leading(100.0), tangent);
        assert_eq!(high_leading(149.999), tangent);
        assert_eq!(high_leading(150.0), curve);
        assert_eq!(high_leading(199.999), curve);
        // X2 [300, 400], curve at its start, the last segment: its second
        // half holds the line's end.
        assert_eq!(high_leading(300.0), curve);
        assert_eq!(high_leading(349.999), curve);
        assert_eq!(high_leading(350.0), tangent);
        assert_eq!(high_leading(400.0), tangent);
    }

    #[test]
    fn a_pulse_lands_on_the_bands_the_rows_use() {
        let line = line();
        assert_eq!(pulse_bands(&line, 1, 250.0), [RailBand::C, RailBand::G]);
        assert_eq!(pulse_bands(&line, 0, 250.0), [RailBand::C]);
        assert_eq!(pulse_bands(&line, 1, 50.0), [RailBand::C]);
        assert_eq!(pulse_bands(&line, 1, 175.0), [RailBand::C, RailBand::G]);
        assert_eq!(pulse_bands(&line, 1, 125.0), [RailBand::C]);
    }
}
