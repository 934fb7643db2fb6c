//! `--report FILE` of every pipeline: the JSON report as it is for `*.json`, or one
//! self-contained HTML page for `*.html` / `*.htm` (docs/formats.md): the result table with
//! sigmas, convergence with 3-sigma bands, NIS against its chi-square bounds, residual
//! histograms, per-DoF excitation and sigmas, the reprojection of one image, embedded PNG
//! overlays and the health events, as far as the report carries them. Figures are inline
//! SVG; the page loads nothing and runs no script. See docs/report.md.

mod data;
mod figures;
mod html;
pub mod result_file;
mod slices;
mod svg;
#[cfg(test)]
mod tests;
mod topview;

use std::path::{Path, PathBuf};

use serde::Serialize;

pub use data::Kind;

/// Why a report could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ReportError {
    /// The report did not serialise.
    #[error("{path}: cannot serialise the report: {source}")]
    Serialize {
        /// Report path.
        path: PathBuf,
        /// Cause.
        source: serde_json::Error,
    },
    /// The result file's text is not YAML (a bug of the command that made it).
    #[error("{path}: the result file's text is not YAML: {source}")]
    ResultYaml {
        /// Result path.
        path: PathBuf,
        /// Cause.
        source: serde_yaml::Error,
    },
    /// The file could not be written, or an image to embed could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
}

/// Writes `report` to `path`: the HTML page for `*.html` / `*.htm`, pretty JSON otherwise.
pub fn write_report<R: Serialize + ?Sized>(path: &Path, report: &R) -> Result<(), ReportError> {
    write_report_with_images(path, report, &[])
}

/// [`write_report`], with PNG files (e.g. overlays written beside the report) embedded in
/// the HTML page; files that do not exist are left out, the JSON ignores them.
pub fn write_report_with_images<R: Serialize + ?Sized>(
    path: &Path,
    report: &R,
    images: &[PathBuf],
) -> Result<(), ReportError> {
    write_report_with_figures(path, report, images, &[])
}

/// An inline SVG figure a command draws itself (e.g. the monitor's timeline), for the HTML
/// page.
pub struct SvgFigure {
    /// Element id of the figure.
    pub id: String,
    /// Caption under it.
    pub caption: String,
    /// The `<svg>` element.
    pub svg: String,
}

/// [`write_report_with_images`], with inline SVG `figures` in the HTML page too.
pub fn write_report_with_figures<R: Serialize + ?Sized>(
    path: &Path,
    report: &R,
    images: &[PathBuf],
    figures: &[SvgFigure],
) -> Result<(), ReportError> {
    let serialize = |source| ReportError::Serialize {
        path: path.to_path_buf(),
        source,
    };
    let text = if is_html(path) {
        let value = serde_json::to_value(report).map_err(serialize)?;
        let mut pngs = Vec::new();
        for image in images.iter().filter(|p| p.is_file()) {
            let png = std::fs::read(image).map_err(|source| ReportError::Io {
                path: image.clone(),
                source,
            })?;
            pngs.push((image.display().to_string(), png));
        }
        let embedded: Vec<html::Image<'_>> = pngs
            .iter()
            .map(|(caption, png)| html::Image {
                caption: caption.clone(),
                png,
            })
            .collect();
        html::page(&value, &embedded, figures)
    } else {
        serde_json::to_string_pretty(report).map_err(serialize)?
    };
    std::fs::write(path, text).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Where a calibration's outputs go: the result file and, with `--report`, the report.
pub struct RunOutputs<'a> {
    /// The result file (`-o`).
    pub result_path: &'a Path,
    /// Its YAML text, as written (e.g. `CalibrationResult::to_yaml_string`).
    pub result_yaml: &'a str,
    /// The report (`--report`), if asked for.
    pub report_path: Option<&'a Path>,
    /// PNG files to embed in the HTML page (see [`write_report_with_images`]).
    pub images: &'a [PathBuf],
    /// SVG figures for the HTML page (see [`write_report_with_figures`]).
    pub figures: &'a [SvgFigure],
}

/// Writes the result file and the report from one source, the result's YAML text: the
/// report carries that text's numbers under `result_file` (parsed from it) and the HTML
/// page's result tables are drawn from them, so the two outputs cannot disagree.
pub fn write_result_and_report<R: Serialize + ?Sized>(
    outputs: &RunOutputs<'_>,
    report: &R,
) -> Result<(), ReportError> {
    let path = outputs.result_path;
    // Refuse text that is no YAML before anything is written.
    result_value(path, outputs.result_yaml)?;
    std::fs::write(path, outputs.result_yaml).map_err(|source| ReportError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    match outputs.report_path {
        Some(report_path) => write_report_for_result(
            report_path,
            report,
            (path, outputs.result_yaml),
            outputs.images,
            outputs.figures,
        ),
        None => Ok(()),
    }
}

/// The report alone, with the numbers of the result file `(path, yaml)` a command wrote
/// (see [`write_result_and_report`]), for commands that write the report later.
pub fn write_report_for_result<R: Serialize + ?Sized>(
    report_path: &Path,
    report: &R,
    (result_path, result_yaml): (&Path, &str),
    images: &[PathBuf],
    figures: &[SvgFigure],
) -> Result<(), ReportError> {
    let file = result_value(result_path, result_yaml)?;
    let mut value = serde_json::to_value(report).map_err(|source| ReportError::Serialize {
        path: report_path.to_path_buf(),
        source,
    })?;
    match value.as_object_mut() {
        Some(map) => {
            map.insert(result_file::KEY.to_string(), file);
        }
        None => value = serde_json::json!({ "report": value, result_file::KEY: file }),
    }
    write_report_with_figures(report_path, &value, images, figures)
}

fn result_value(path: &Path, yaml: &str) -> Result<serde_json::Value, ReportError> {
    result_file::value_of(yaml).map_err(|source| ReportError::ResultYaml {
        path: path.to_path_buf(),
        source,
    })
}

/// The HTML page of a JSON report (as [`write_report`] writes it for `*.html`).
pub fn render_html(report: &serde_json::Value) -> String {
    html::page(report, &[], &[])
}

/// Whether `path` asks for the HTML page.
pub fn is_html(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("html") || e.eq_ignore_ascii_case("htm"))
}
