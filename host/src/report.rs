//! `--report FILE` of every pipeline: the JSON report as it is for `*.json`, or one
//! self-contained HTML page for `*.html` / `*.htm` (docs/formats.md): the result table with
//! sigmas, convergence with 3-sigma bands, NIS against its chi-square bounds, residual
//! histograms, per-DoF excitation and sigmas, the reprojection of one image, embedded PNG
//! overlays and the health events, as far as the report carries them. Figures are inline
//! SVG; the page loads nothing and runs no script. See docs/report.md.

mod data;
mod figures;
mod html;
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
