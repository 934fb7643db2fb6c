//! PNG plots of a calibration's convergence: one panel per estimated quantity, the estimate
//! over time with its +-1 sigma band (and the truth, when known).
//!
//! Rendering is pure Rust (plotters' bitmap backend, text with `ab_glyph`, PNG through the
//! `image` crate the project already uses), so building needs no system library. Text needs a
//! TrueType font at run time: DejaVu Sans from Debian's `fonts-dejavu-core` (installed by
//! `tools/setup.sh`), or any `.ttf` named by `MSREG_PLOT_FONT`.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::prelude::*;

/// One quantity's history.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvergenceSeries {
    /// Panel title, e.g. `rot x`.
    pub label: String,
    /// Unit of `value` and `sigma`, e.g. `deg`.
    pub unit: String,
    /// Time of each point, s.
    pub t_s: Vec<f64>,
    /// Estimate.
    pub value: Vec<f64>,
    /// 1-sigma of the estimate.
    pub sigma: Vec<f64>,
    /// The true value, when known (simulations).
    pub truth: Option<f64>,
}

/// Why a plot could not be written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// No usable font (text cannot be drawn).
    #[error(
        "plot: no font: {}: {problem} (install Debian's fonts-dejavu-core or set MSREG_PLOT_FONT \
         to a .ttf)",
        path.display()
    )]
    Font {
        /// The font file tried.
        path: PathBuf,
        /// What is wrong with it.
        problem: FontProblem,
    },
    /// Nothing to plot.
    #[error("plot: the convergence history is empty")]
    Empty,
    /// Drawing or encoding failed.
    #[error("plot {path}: {message}")]
    Draw {
        /// The output file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// What is wrong with the font file.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FontProblem {
    /// The file could not be read.
    #[error("{message}")]
    Unreadable {
        /// The kind of the I/O error.
        kind: std::io::ErrorKind,
        /// The I/O error's text (from the OS).
        message: String,
    },
    /// The bytes are not a TrueType font.
    #[error("not a TrueType font")]
    NotTrueType,
}

/// Where the font is looked for when `MSREG_PLOT_FONT` is not set.
const DEFAULT_FONT: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";
/// Family name the font is registered under.
const FAMILY: &str = "sans-serif";

/// Registers the font once per process (plotters keeps a `'static` reference to it).
fn register_font() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<Result<(), (PathBuf, FontProblem)>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            let path = std::env::var("MSREG_PLOT_FONT").unwrap_or_else(|_| DEFAULT_FONT.into());
            let path = PathBuf::from(path);
            let bytes = std::fs::read(&path).map_err(|e| {
                let problem = FontProblem::Unreadable {
                    kind: e.kind(),
                    message: e.to_string(),
                };
                (path.clone(), problem)
            })?;
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            plotters::style::register_font(FAMILY, FontStyle::Normal, bytes)
                .map_err(|_| (path.clone(), FontProblem::NotTrueType))
        })
        .clone()
        .map_err(|(path, problem)| PlotError::Font { path, problem })
}

/// Vertical range of a panel: every estimate, the truth and the final +-3 sigma (the early,
/// wide sigma band is clipped instead of flattening the converged part), padded by 10 %.
fn y_range(s: &ConvergenceSeries) -> (f64, f64) {
    let last = s.value.len().saturating_sub(1);
    let (v, sd) = (s.value[last], s.sigma[last]);
    let mut lo = v - 3.0 * sd;
    let mut hi = v + 3.0 * sd;
    for x in s.value.iter().chain(s.truth.iter()) {
        if x.is_finite() {
            lo = lo.min(*x);
            hi = hi.max(*x);
        }
    }
    let pad = ((hi - lo) * 0.1).max(1e-9);
    (lo - pad, hi + pad)
}

/// Draws `series` as a grid of panels (3 columns) into a `width` x `height` PNG at `path`.
pub fn write_convergence_png(
    path: &Path,
    title: &str,
    series: &[ConvergenceSeries],
    (width, height): (u32, u32),
) -> Result<(), PlotError> {
    if series.is_empty() || series.iter().any(|s| s.t_s.is_empty()) {
        return Err(PlotError::Empty);
    }
    register_font()?;
    let draw_err = |e: &dyn std::fmt::Display| PlotError::Draw {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let mut rgb = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let root = root.titled(title, (FAMILY, 22)).map_err(|e| draw_err(&e))?;
        let columns = 3.min(series.len());
        let rows = series.len().div_ceil(columns);
        for (area, s) in root.split_evenly((rows, columns)).iter().zip(series) {
            draw_panel(area, s).map_err(|e| draw_err(&e))?;
        }
        root.present().map_err(|e| draw_err(&e))?;
    }
    let image = image::RgbImage::from_raw(width, height, rgb)
        .ok_or_else(|| draw_err(&"pixel buffer size mismatch"))?;
    image.save(path).map_err(|e| draw_err(&e))
}

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;
type DrawResult<'a> =
    Result<(), DrawingAreaErrorKind<<BitMapBackend<'a> as DrawingBackend>::ErrorType>>;

/// One panel: +-1 sigma band, estimate, truth.
fn draw_panel<'a>(area: &Area<'a>, s: &ConvergenceSeries) -> DrawResult<'a> {
    let t0 = s.t_s.first().copied().unwrap_or(0.0);
    let t1 = s.t_s.last().copied().unwrap_or(1.0).max(t0 + 1e-6);
    let (y0, y1) = y_range(s);
    let clamp = |y: f64| if y.is_finite() { y.clamp(y0, y1) } else { y1 };
    let mut chart = ChartBuilder::on(area)
        .caption(&s.label, (FAMILY, 16))
        .margin(8)
        .x_label_area_size(34)
        .y_label_area_size(64)
        .build_cartesian_2d(t0..t1, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc("time [s]")
        .y_desc(s.unit.as_str())
        .label_style((FAMILY, 12))
        .axis_desc_style((FAMILY, 13))
        .light_line_style(WHITE)
        .draw()?;
    let upper = s
        .t_s
        .iter()
        .zip(s.value.iter().zip(&s.sigma))
        .map(|(t, (v, sd))| (*t, clamp(v + sd)));
    let lower = s
        .t_s
        .iter()
        .zip(s.value.iter().zip(&s.sigma))
        .rev()
        .map(|(t, (v, sd))| (*t, clamp(v - sd)));
    let band: Vec<(f64, f64)> = upper.chain(lower).collect();
    chart.draw_series(std::iter::once(Polygon::new(band, BLUE.mix(0.2).filled())))?;
    chart.draw_series(LineSeries::new(
        s.t_s.iter().zip(&s.value).map(|(t, v)| (*t, clamp(*v))),
        BLUE.stroke_width(2),
    ))?;
    if let Some(truth) = s.truth {
        chart.draw_series(LineSeries::new(
            [(t0, truth), (t1, truth)],
            RED.stroke_width(1),
        ))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(n: usize) -> ConvergenceSeries {
        ConvergenceSeries {
            label: "rot x".into(),
            unit: "deg".into(),
            t_s: (0..n).map(|i| i as f64 * 0.1).collect(),
            value: (0..n).map(|i| 1.0 / (1.0 + i as f64)).collect(),
            sigma: (0..n).map(|i| 2.0 / (1.0 + i as f64).sqrt()).collect(),
            truth: Some(0.0),
        }
    }

    #[test]
    fn y_range_holds_estimates_truth_and_final_three_sigma() {
        let s = series(100);
        let (lo, hi) = y_range(&s);
        let final_3sd = 3.0 * s.sigma[99];
        assert!(lo < s.value[99] - final_3sd && hi > s.value[99] + final_3sd);
        assert!(hi >= 1.0 && lo <= 0.0);
        // The first, wide sigma (2) is clipped rather than setting the range.
        assert!(hi < s.value[0] + s.sigma[0]);
    }

    #[test]
    fn writes_a_png_or_reports_the_missing_font() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("conv.png");
        let all: Vec<_> = (0..7).map(|_| series(50)).collect();
        match write_convergence_png(&path, "test", &all, (900, 700)) {
            Ok(()) => {
                let img = image::open(&path).expect("readable PNG").to_rgb8();
                assert_eq!(img.dimensions(), (900, 700));
                // Something was drawn: not every pixel is white.
                assert!(img.pixels().any(|p| p.0 != [255, 255, 255]));
            }
            Err(e @ PlotError::Font { .. }) => println!("skipped: {e}"),
            Err(e) => panic!("{e}"),
        }
    }

    #[test]
    fn empty_history_is_an_error() {
        let dir = tempfile::tempdir().expect("tempdir");
        let r = write_convergence_png(&dir.path().join("x.png"), "t", &[], (100, 100));
        assert!(matches!(r, Err(PlotError::Empty)));
    }
}
