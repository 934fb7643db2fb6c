//! The one error type of dataset input/output. Each variant names the file
//! (and line, where there is one) so a user can fix the input directly.

use std::path::PathBuf;

/// Why a dataset file could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DatasetError {
    /// The dataset directory does not exist or is not a directory.
    #[error("{}: dataset directory does not exist or is not a directory", path.display())]
    MissingDirectory {
        /// The directory that was asked for.
        path: PathBuf,
    },
    /// A file the task needs does not exist.
    #[error("{}: file is missing", path.display())]
    MissingFile {
        /// The missing file.
        path: PathBuf,
    },
    /// Any other I/O failure while reading or writing.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file being read or written.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A line that does not have the expected shape (column count, number syntax).
    #[error("{}:{line}: malformed line: expected {expected}", path.display())]
    MalformedLine {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What the line should have looked like, and what was found.
        expected: String,
    },
    /// A NaN or infinite number.
    #[error("{}:{line}: column {column} is not a finite number: `{value}`", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// 1-based column number.
        column: usize,
        /// The text found.
        value: String,
    },
    /// Timestamps must be strictly increasing.
    #[error(
        "{}:{line}: timestamp {stamp_ns} ns is not after the previous one ({previous_ns} ns); \
         timestamps must be strictly increasing",
        path.display()
    )]
    TimeNotIncreasing {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the offending row.
        line: usize,
        /// Its timestamp.
        stamp_ns: u64,
        /// The timestamp of the row before it.
        previous_ns: u64,
    },
    /// A quaternion whose norm is further than 1e-3 from 1 (probably wrong columns).
    #[error(
        "{}:{line}: quaternion (w, x, y, z) has norm {norm}, more than 1e-3 away from 1",
        path.display()
    )]
    NonUnitQuaternion {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// The norm found.
        norm: f64,
    },
    /// A data file with no data rows.
    #[error("{}: no data rows", path.display())]
    Empty {
        /// The file.
        path: PathBuf,
    },
    /// YAML that does not parse or does not have the expected keys and types.
    #[error("{}{}: {message}", path.display(), location(*line, *column))]
    Yaml {
        /// The file.
        path: PathBuf,
        /// 1-based line of the error, when serde knows it.
        line: Option<usize>,
        /// 1-based column of the error, when serde knows it.
        column: Option<usize>,
        /// serde's message.
        message: String,
    },
    /// A value that parses but is not acceptable (negative noise, non-rigid matrix, ...).
    #[error("{}: {message}", path.display())]
    InvalidValue {
        /// The file.
        path: PathBuf,
        /// Which key and why.
        message: String,
    },
}

/// `:line:column` when known, for compiler-style `file:line:column` messages.
fn location(line: Option<usize>, column: Option<usize>) -> String {
    match (line, column) {
        (Some(l), Some(c)) => format!(":{l}:{c}"),
        (Some(l), None) => format!(":{l}"),
        _ => String::new(),
    }
}
