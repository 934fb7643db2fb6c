//! Line parsing and writing shared by the EuRoC-style CSV files: a timestamp
//! in integer nanoseconds followed by a fixed number of finite floats.
//!
//! Tolerant where real files differ (lines starting with `#` are headers or
//! comments, blank lines are skipped, whitespace around fields is ignored, a
//! line without commas is split on whitespace) and strict where a silent
//! mistake would corrupt a calibration (column count, NaN/Inf, timestamps
//! that do not strictly increase).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::error::DatasetError;

/// One data row: its 1-based line number, timestamp and `N` values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Row<const N: usize> {
    /// 1-based line number in the file, for later error messages.
    pub line: usize,
    /// First column, integer nanoseconds.
    pub stamp_ns: u64,
    /// The remaining columns.
    pub values: [f64; N],
}

/// Reads a whole text file, mapping "not found" to [`DatasetError::MissingFile`].
pub(crate) fn read_text(path: &Path) -> Result<String, DatasetError> {
    std::fs::read_to_string(path).map_err(|source| io_error(path, source))
}

/// Maps an I/O error on `path`, singling out a missing file.
pub(crate) fn io_error(path: &Path, source: std::io::Error) -> DatasetError {
    if source.kind() == std::io::ErrorKind::NotFound {
        DatasetError::MissingFile {
            path: path.to_path_buf(),
        }
    } else {
        DatasetError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Reads `path` as rows of a timestamp and `N` floats; `columns` describes
/// the expected columns for error messages. Rejects files without data rows.
pub(crate) fn read_rows<const N: usize>(
    path: &Path,
    columns: &str,
) -> Result<Vec<Row<N>>, DatasetError> {
    let text = read_text(path)?;
    let rows = parse_rows::<N>(path, &text, columns)?;
    if rows.is_empty() {
        return Err(DatasetError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(rows)
}

/// Parses `text` (the content of `path`) into rows; see [`read_rows`].
pub(crate) fn parse_rows<const N: usize>(
    path: &Path,
    text: &str,
    columns: &str,
) -> Result<Vec<Row<N>>, DatasetError> {
    let mut rows: Vec<Row<N>> = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        let trimmed = raw.trim();
        if trimmed.is_empty() || trimmed.starts_with('#') {
            continue;
        }
        let row = parse_row::<N>(path, line, trimmed, columns)?;
        if let Some(previous) = rows.last() {
            if row.stamp_ns <= previous.stamp_ns {
                return Err(DatasetError::TimeNotIncreasing {
                    path: path.to_path_buf(),
                    line,
                    stamp_ns: row.stamp_ns,
                    previous_ns: previous.stamp_ns,
                });
            }
        }
        rows.push(row);
    }
    Ok(rows)
}

pub(crate) fn parse_row<const N: usize>(
    path: &Path,
    line: usize,
    text: &str,
    columns: &str,
) -> Result<Row<N>, DatasetError> {
    let fields: Vec<&str> = if text.contains(',') {
        text.split(',').map(str::trim).collect()
    } else {
        text.split_whitespace().collect()
    };
    let malformed = |expected: String| DatasetError::MalformedLine {
        path: path.to_path_buf(),
        line,
        expected,
    };
    if fields.len() != N + 1 {
        return Err(malformed(format!(
            "{} comma-separated columns ({columns}), found {}",
            N + 1,
            fields.len()
        )));
    }
    let stamp_ns = fields[0].parse::<u64>().map_err(|_| {
        malformed(format!(
            "an integer timestamp in nanoseconds in column 1, found `{}`",
            fields[0]
        ))
    })?;
    let mut values = [0.0; N];
    for (k, (value, field)) in values.iter_mut().zip(&fields[1..]).enumerate() {
        let column = k + 2;
        let parsed = field
            .parse::<f64>()
            .map_err(|_| malformed(format!("a number in column {column}, found `{field}`")))?;
        if !parsed.is_finite() {
            return Err(DatasetError::NonFinite {
                path: path.to_path_buf(),
                line,
                column,
                value: (*field).to_string(),
            });
        }
        *value = parsed;
    }
    Ok(Row {
        line,
        stamp_ns,
        values,
    })
}

/// Shortest decimal text that parses back to exactly `x` (plain notation for
/// ordinary magnitudes, scientific otherwise).
pub(crate) fn fmt_f64(x: f64) -> String {
    let magnitude = x.abs();
    if magnitude == 0.0 || (1e-5..1e16).contains(&magnitude) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// Writes a CSV file: one header line, then one line per row of a timestamp
/// and floats.
pub(crate) fn write_rows<I>(path: &Path, header: &str, rows: I) -> Result<(), DatasetError>
where
    I: IntoIterator<Item = (u64, Vec<f64>)>,
{
    let file = File::create(path).map_err(|source| io_error(path, source))?;
    let mut out = BufWriter::new(file);
    let write = || -> std::io::Result<()> {
        writeln!(out, "{header}")?;
        for (stamp_ns, values) in rows {
            write!(out, "{stamp_ns}")?;
            for v in values {
                write!(out, ",{}", fmt_f64(v))?;
            }
            writeln!(out)?;
        }
        out.flush()
    };
    write().map_err(|source| io_error(path, source))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fmt_f64_round_trips_exactly() {
        for x in [
            0.0,
            -0.0,
            1.0,
            0.1,
            -9.81,
            1e-7,
            6.1e-5,
            1.234_567_890_123_456_7e-12,
            3.0e20,
            f64::MIN_POSITIVE,
            std::f64::consts::PI,
        ] {
            let back: f64 = fmt_f64(x).parse().unwrap_or(f64::NAN);
            assert_eq!(back.to_bits(), x.to_bits(), "{x} -> {}", fmt_f64(x));
        }
    }

    #[test]
    fn whitespace_separated_lines_are_accepted() {
        let rows = parse_rows::<2>(Path::new("x.csv"), "1 2.0 3.0\n2\t4 5\n", "t, a, b");
        let rows = rows.unwrap_or_default();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].stamp_ns, 2);
    }

    #[test]
    fn float_timestamp_is_rejected_with_line() {
        let err = parse_rows::<1>(Path::new("x.csv"), "#h\n1.5e18,2\n", "t, a");
        assert!(matches!(
            err,
            Err(DatasetError::MalformedLine { line: 2, .. })
        ));
    }
}
