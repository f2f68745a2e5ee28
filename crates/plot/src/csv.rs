//! Small CSV tables of f64 columns, the numbers behind a figure, written so
//! that reading them back gives the same bits.

use std::fmt::Write as _;
use std::path::Path;

use crate::error::PlotError;

/// CSV text: the header, then one line per row, each value in Rust's
/// shortest round-trip form (`{}` of f64), so reading the file back gives
/// the same bits. Every row must have as many values as the header.
pub fn csv_text<R: AsRef<[f64]>>(
    header: &[&str],
    rows: impl IntoIterator<Item = R>,
) -> Result<String, PlotError> {
    let mut out = header.join(",");
    out.push('\n');
    for (k, row) in rows.into_iter().enumerate() {
        let row = row.as_ref();
        if row.len() != header.len() {
            return Err(PlotError::CsvRow {
                row: k,
                values: row.len(),
                columns: header.len(),
                header: header.join(","),
            });
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

/// Writes [`csv_text`] to `path` (whole or not at all, see
/// [`tortwin_files`]).
pub fn write_csv<R: AsRef<[f64]>>(
    path: &Path,
    header: &[&str],
    rows: impl IntoIterator<Item = R>,
) -> Result<(), PlotError> {
    let text = csv_text(header, rows).map_err(|e| e.for_file(path))?;
    tortwin_files::write_atomically(path, text.as_bytes())?;
    Ok(())
}

/// Writes columns of equal length as a CSV file: `(name, values)` in order.
pub fn write_csv_columns(path: &Path, columns: &[(&str, &[f64])]) -> Result<(), PlotError> {
    let len = columns.first().map_or(0, |(_, c)| c.len());
    if let Some((name, c)) = columns.iter().find(|(_, c)| c.len() != len) {
        let uneven = PlotError::CsvColumn {
            name: (*name).to_owned(),
            values: c.len(),
            first: len,
        };
        return Err(uneven.for_file(path));
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
        assert!(matches!(
            csv_text(&["a", "b"], [vec![1.0]]),
            Err(PlotError::CsvRow { row: 0, .. })
        ));
    }

    #[test]
    fn a_table_that_cannot_be_written_names_the_file_and_leaves_none() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fig.csv");
        let err = write_csv_columns(&path, &[("d_m", &[0.0, 1.0]), ("mu", &[0.3])]).unwrap_err();
        let text = format!("{err}: {}", std::error::Error::source(&err).unwrap());
        assert!(
            text.contains("fig.csv") && text.contains("column mu"),
            "{text}"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);

        write_csv_columns(&path, &[("d_m", &[0.0, 1.0]), ("mu", &[0.3, 0.4])]).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "d_m,mu\n0,0.3\n1,0.4\n"
        );
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
