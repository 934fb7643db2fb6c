//! What the `msreg` commands share: how a calibration ended (exit code 0 or 1) and the
//! progress bar of long work.

use indicatif::{ProgressBar, ProgressStyle};

/// How a calibration ended, bad input aside (that is an error, exit code 2).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Outcome {
    /// All checks passed (exit code 0).
    Converged,
    /// The result was written but a check failed: the reasons (exit code 1).
    NotConverged(String),
}

impl Outcome {
    /// `Converged` when `converged`, else the `reasons` joined.
    pub fn of(converged: bool, reasons: &[String]) -> Self {
        if converged {
            Outcome::Converged
        } else {
            Outcome::NotConverged(reasons.join("; "))
        }
    }
}

/// A progress bar of `len` steps on stderr drawn with the indicatif `template`.
pub fn progress_bar(len: u64, template: &str) -> ProgressBar {
    let bar = ProgressBar::new(len);
    if let Ok(style) = ProgressStyle::with_template(template) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar
}

/// Writes `result` to `output` and, when asked, `report` to `report_path` carrying the
/// same numbers (one YAML text for both: `report::write_result_and_report`).
pub fn write_outputs<R: serde::Serialize + ?Sized>(
    result: &msreg_host::dataset::CalibrationResult,
    output: &std::path::Path,
    report_path: Option<&std::path::Path>,
    report: &R,
) -> Result<(), msreg_host::report::ReportError> {
    msreg_host::report::write_result_and_report(
        &msreg_host::report::RunOutputs {
            result_path: output,
            result_yaml: &result.to_yaml_string(),
            report_path,
            images: &[],
            figures: &[],
        },
        report,
    )
}
