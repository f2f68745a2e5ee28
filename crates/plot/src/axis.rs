//! The numbers along an axis: ranges from the data (padded, or checked when
//! given) and tick labels without float noise.

use crate::error::PlotError;

/// A tick value without float noise: 500 not 500.0, 0.3 not
/// 0.30000000000000004, and very small or large values in e notation.
pub(crate) fn tick_label(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e7).contains(&a) {
        return format!("{v:.2e}");
    }
    let text = format!("{v:.6}");
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// 0 for a value within a billionth of the axis span of it.
pub(crate) fn snap_to_zero(v: f64, span: f64) -> f64 {
    if v.abs() <= 1e-9 * span.abs() {
        0.0
    } else {
        v
    }
}

pub(crate) fn min_max(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// 5 % of the span on each side; a flat line gets a span of its own.
pub(crate) fn pad(lo: f64, hi: f64) -> (f64, f64) {
    let span = if hi > lo { hi - lo } else { lo.abs().max(1.0) };
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// From the smallest to the largest of `values`; padded when they are all
/// equal, 0..1 when there are none.
pub(crate) fn data_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    min_max(values).map_or(
        (0.0, 1.0),
        |(lo, hi)| if lo < hi { (lo, hi) } else { pad(lo, hi) },
    )
}

/// A range given for `axis` of the plot titled `title`, if it can be drawn.
pub(crate) fn checked_range(
    (lo, hi): (f64, f64),
    axis: &'static str,
    title: &str,
) -> Result<(f64, f64), PlotError> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Err(PlotError::Range {
            title: title.to_owned(),
            axis,
            lo,
            hi,
        });
    }
    Ok((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_have_no_float_noise() {
        assert_eq!(tick_label(500.0), "500");
        assert_eq!(tick_label(0.1 + 0.2), "0.3");
        assert_eq!(tick_label(-2.5), "-2.5");
        assert_eq!(tick_label(0.0), "0");
        assert_eq!(tick_label(1.5e-6), "1.50e-6");
        assert_eq!(tick_label(snap_to_zero(-0.15 + 3.0 * 0.05, 0.3)), "0");
        assert_eq!(tick_label(snap_to_zero(1.5e-6, 3e-6)), "1.50e-6");
    }
}
