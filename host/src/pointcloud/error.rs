//! The one error type of PCD input/output; every variant names the file, and
//! the header line or the byte counts where they apply.

use std::path::PathBuf;

/// Why a PCD file could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PcdError {
    /// The file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A header line that is malformed, inconsistent with another one, or
    /// missing (then `line` is the line where it was expected: `DATA`'s).
    #[error("{}:{line}: bad PCD header: {message}", path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A `TYPE`/`SIZE` combination this reader does not decode.
    #[error(
        "{}:{line}: field `{field}` has unsupported TYPE {kind} SIZE {size} \
         (supported: F 4/8, U 1/2/4/8, I 1/2/4/8)",
        path.display()
    )]
    UnsupportedType {
        /// The file.
        path: PathBuf,
        /// 1-based line number of the `TYPE` line.
        line: usize,
        /// The field name.
        field: String,
        /// The `TYPE` letter.
        kind: char,
        /// The `SIZE` in bytes.
        size: usize,
    },
    /// The data section ends before `POINTS` points.
    #[error(
        "{}: truncated data: expected {expected} {unit} of point data, found {actual}",
        path.display()
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Amount the header promises.
        expected: usize,
        /// Amount actually present.
        actual: usize,
        /// `bytes` (binary), `compressed bytes` or `points` (ascii lines).
        unit: &'static str,
    },
    /// An ascii data line that does not parse.
    #[error("{}:{line}: bad ascii point: {message}", path.display())]
    AsciiData {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A `binary_compressed` block that does not decompress.
    #[error("{}: corrupt binary_compressed (LZF) data: {message}", path.display())]
    Compressed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The file holds no point (or none with finite coordinates).
    #[error("{}: the point cloud has zero points{detail}", path.display())]
    ZeroPoints {
        /// The file.
        path: PathBuf,
        /// Extra context (e.g. how many non-finite points were dropped).
        detail: String,
    },
}
