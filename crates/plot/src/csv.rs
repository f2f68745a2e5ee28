//! Small CSV tables of f64 columns, the numbers behind a figure, written so
//! that reading them back gives the same bits.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};

/// CSV text: the header, then one line per row, each value in Rust's
/// shortest round-trip form (`{}` of f64), so reading the file back gives
/// the same bits. Every row must have as many values as the header.
pub fn csv_text<R: AsRef<[f64]>>(
    header: &[&str],
    rows: impl IntoIterator<Item = R>,
) -> Result<String> {
    let mut out = header.join(",");
    out.push('\n');
    for (k, row) in rows.into_iter().enumerate() {
        let row = row.as_ref();
        if row.len() != header.len() {
            bail!(
                "CSV row {k} has {} values for {} columns ({})",
                row.len(),
                header.len(),
                header.join(",")
            );
        }
        for (j, v) in row.iter().enumerate() {
            if j > 0 {
                out.push(',');
            }
            // Writing to a String cannot fail.
            let _ = write!(out, "{v}");
        }
        out.push('\n');
    }
    Ok(out)
}

/// Writes [`csv_text`] to `path`.
pub fn write_csv<R: AsRef<[f64]>>(
    path: &Path,
    header: &[&str],
    rows: impl IntoIterator<Item = R>,
) -> Result<()> {
    let text =
        csv_text(header, rows).with_context(|| format!("cannot write {}", path.display()))?;
    std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))
}

/// Writes columns of equal length as a CSV file: `(name, values)` in order.
pub fn write_csv_columns(path: &Path, columns: &[(&str, &[f64])]) -> Result<()> {
    let len = columns.first().map_or(0, |(_, c)| c.len());
    if let Some((name, c)) = columns.iter().find(|(_, c)| c.len() != len) {
        bail!(
            "cannot write {}: column {name} has {} values, the first has {len}",
            path.display(),
            c.len()
        );
    }
    let header: Vec<&str> = columns.iter().map(|(name, _)| *name).collect();
    let rows = (0..len).map(|i| columns.iter().map(|(_, c)| c[i]).collect::<Vec<f64>>());
    write_csv(path, &header, rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_round_trips_f64() {
        let values = [0.1 + 0.2, 1e-300, -2.5, 1.0 / 3.0];
        let text = csv_text(
            &["a", "b"],
            [[values[0], values[1]], [values[2], values[3]]],
        )
        .unwrap();
        let parsed: Vec<f64> = text
            .lines()
            .skip(1)
            .flat_map(|l| l.split(','))
            .map(|v| v.parse().unwrap())
            .collect();
        assert_eq!(parsed, values);
        assert!(text.starts_with("a,b\n"));
    }

    #[test]
    fn csv_refuses_ragged_rows() {
        assert!(csv_text(&["a", "b"], [vec![1.0]]).is_err());
    }
}
