//! ArUco marker detection (the infrastructure cameras' view of the robot's marker,
//! chapter 6): adaptive thresholds at several window sizes, outer boundaries of the dark
//! components simplified to convex quadrilaterals, each unwarped and read (border check,
//! dictionary look-up in four rotations), corners put in OpenCV's order (clockwise from the
//! printed marker's top-left) and refined to sub-pixel accuracy by gradient orthogonality
//! ([`crate::vision::subpix`], OpenCV's `cornerSubPix`). Defaults follow OpenCV's
//! `DetectorParameters` with `CORNER_REFINE_SUBPIX`. Method and accuracy against OpenCV on
//! real photos: docs/aruco.md.

pub(crate) mod decode;
mod dictionaries;
pub mod dictionary;
mod edges;
pub(crate) mod quad;
pub mod render;

pub use decode::{apply as apply_homography, homography_4pt, otsu};
pub use dictionary::{Dictionary, UnknownDictionary};

use nalgebra::Vector2;

use super::gray::GrayImage;
use super::subpix::{refine_corner, SubpixParams};

/// Detector settings (OpenCV's `DetectorParameters` defaults).
#[derive(Clone, Debug, PartialEq)]
pub struct ArucoParams {
    /// Adaptive-threshold window sizes, pixels (odd).
    pub threshold_windows: Vec<usize>,
    /// A pixel is dark when below the window mean minus this.
    pub threshold_constant: f32,
    /// Smallest contour length, as a fraction of the larger image side.
    pub min_perimeter_rate: f64,
    /// Largest contour length, as a multiple of the larger image side.
    pub max_perimeter_rate: f64,
    /// Douglas-Peucker tolerance as a fraction of the contour length.
    pub polygon_accuracy_rate: f64,
    /// Smallest side as a fraction of the contour length.
    pub min_corner_distance_rate: f64,
    /// Corners closer than this to the image border are rejected, pixels.
    pub min_distance_to_border: usize,
    /// Two candidates whose mean corner distance is below this fraction of the smaller
    /// one's contour length are one marker (the longer contour is kept).
    pub min_marker_distance_rate: f64,
    /// Canonical-image pixels per bit cell.
    pub pixels_per_cell: usize,
    /// Fraction of a cell ignored at each side when counting (OpenCV's margin, truncated
    /// to whole pixels).
    pub ignored_margin_per_cell: f64,
    /// Below this standard deviation the unwarped patch is uniform.
    pub min_otsu_std_dev: f64,
    /// Tolerated white border cells, as a fraction of the inner bit count.
    pub max_border_error_rate: f64,
    /// Correctable bits, as a fraction of the dictionary's correction capacity.
    pub error_correction_rate: f64,
    /// Corner refinement; `None` leaves the integer contour corners.
    pub subpix: Option<CornerRefinement>,
    /// Then moves each corner to the intersection of lines fitted to its two sides' edge
    /// points (`aruco/edges.rs`): unbiased at the square's L-corners, where the gradient
    /// refinement above (OpenCV's default, kept for agreement with it) is pulled inwards.
    /// Off by default; `calibrate infra` turns it on.
    pub edge_lines: bool,
}

/// Sub-pixel refinement settings (OpenCV's `cornerRefinement*`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CornerRefinement {
    /// Largest half window, pixels (`cornerRefinementWinSize`).
    pub max_half_window: usize,
    /// Half window as a fraction of the marker's bit-cell size
    /// (`relativeCornerRefinmentWinSize`), capped by `max_half_window`.
    pub relative_half_window: f64,
    /// Maximum iterations.
    pub max_iterations: usize,
    /// Stop when a step is shorter than this, pixels.
    pub min_step_px: f64,
}

impl Default for ArucoParams {
    fn default() -> Self {
        Self {
            threshold_windows: vec![3, 13, 23],
            threshold_constant: 7.0,
            min_perimeter_rate: 0.03,
            max_perimeter_rate: 4.0,
            polygon_accuracy_rate: 0.03,
            min_corner_distance_rate: 0.05,
            min_distance_to_border: 3,
            min_marker_distance_rate: 0.125,
            pixels_per_cell: 4,
            ignored_margin_per_cell: 0.13,
            min_otsu_std_dev: 5.0,
            max_border_error_rate: 0.35,
            error_correction_rate: 0.6,
            subpix: Some(CornerRefinement {
                max_half_window: 5,
                relative_half_window: 0.3,
                max_iterations: 30,
                min_step_px: 0.1,
            }),
            edge_lines: false,
        }
    }
}

/// One decoded marker.
#[derive(Clone, Debug, PartialEq)]
pub struct Marker {
    /// Marker id in the dictionary.
    pub id: usize,
    /// Corners in OpenCV order: top-left, top-right, bottom-right, bottom-left of the
    /// printed marker (clockwise on screen when seen from the front), pixels.
    pub corners: [Vector2<f64>; 4],
    /// Bits corrected by the dictionary look-up.
    pub corrected_bits: usize,
}

/// Detects the markers of `dictionary` in a grey image, at most one per place (sorted by
/// id, then by position).
pub fn detect_markers(
    img: &GrayImage,
    dictionary: Dictionary,
    params: &ArucoParams,
) -> Vec<Marker> {
    let mut quads = Vec::new();
    for &window in &params.threshold_windows {
        let mask = quad::adaptive_threshold(img, window.max(3) | 1, params.threshold_constant);
        quads.extend(quad::quads_of_mask(
            &mask,
            img.width(),
            img.height(),
            params,
        ));
    }
    let groups = group_duplicates(quads, params.min_marker_distance_rate);
    let n = dictionary.bits();
    let max_border = (n as f64 * n as f64 * params.max_border_error_rate) as usize;
    let max_errors =
        (dictionary.max_correction_bits() as f64 * params.error_correction_rate) as usize;
    let mut markers: Vec<Marker> = groups
        .iter()
        .filter_map(|group| {
            group
                .iter()
                .find_map(|q| decode_quad(img, q, dictionary, max_border, max_errors, params))
        })
        .collect();
    remove_same_marker_twice(&mut markers);
    if let Some(refinement) = &params.subpix {
        markers
            .iter_mut()
            .for_each(|m| refine_marker(img, m, n, refinement));
    }
    if params.edge_lines {
        for m in &mut markers {
            let cell = mean_side(&m.corners) / (n + 2) as f64;
            edges::refine_by_edge_lines(img, &mut m.corners, cell);
        }
    }
    markers.sort_by(|a, b| {
        (a.id, a.corners[0].y, a.corners[0].x)
            .partial_cmp(&(b.id, b.corners[0].y, b.corners[0].x))
            .unwrap_or(std::cmp::Ordering::Equal)
    });
    markers
}

/// Drops a decoded marker whose id and centre repeat an earlier one's (centres closer than
/// a quarter of its mean side): candidates of one marker that escaped the grouping.
fn remove_same_marker_twice(markers: &mut Vec<Marker>) {
    let centre = |m: &Marker| m.corners.iter().sum::<Vector2<f64>>() / 4.0;
    let side = |m: &Marker| {
        (0..4)
            .map(|i| (m.corners[i] - m.corners[(i + 1) % 4]).norm())
            .sum::<f64>()
            / 4.0
    };
    let mut kept: Vec<Marker> = Vec::with_capacity(markers.len());
    for m in markers.drain(..) {
        let repeat = kept
            .iter()
            .any(|k| k.id == m.id && (centre(k) - centre(&m)).norm() < 0.25 * side(k));
        if !repeat {
            kept.push(m);
        }
    }
    *markers = kept;
}

/// Decodes one candidate: the marker with its corners in OpenCV order, unrefined.
fn decode_quad(
    img: &GrayImage,
    q: &quad::Quad,
    dictionary: Dictionary,
    max_border: usize,
    max_errors: usize,
    params: &ArucoParams,
) -> Option<Marker> {
    let (code, border) = decode::read_bits(img, &q.corners, dictionary.bits(), params)?;
    if border > max_border {
        return None;
    }
    let (id, turns, corrected_bits) = dictionary.identify(code, max_errors)?;
    // The printed top-left shows at candidate corner `turns`.
    let corners = std::array::from_fn(|i| q.corners[(i + turns) % 4]);
    Some(Marker {
        id,
        corners,
        corrected_bits,
    })
}

/// Groups candidates closer than `rate` times the smaller contour length (mean corner
/// distance, best cyclic correspondence): one group per place, longest contour first (the
/// others are tried when it does not decode).
fn group_duplicates(mut quads: Vec<quad::Quad>, rate: f64) -> Vec<Vec<quad::Quad>> {
    quads.sort_by_key(|q| std::cmp::Reverse(q.perimeter));
    let mut groups: Vec<Vec<quad::Quad>> = Vec::new();
    for q in quads {
        let close = |k: &quad::Quad| {
            let limit = rate * k.perimeter.min(q.perimeter) as f64;
            (0..4).any(|s| {
                let mean = (0..4)
                    .map(|i| (k.corners[i] - q.corners[(i + s) % 4]).norm())
                    .sum::<f64>()
                    / 4.0;
                mean < limit
            })
        };
        match groups.iter_mut().find(|g| close(&g[0])) {
            Some(g) => g.push(q),
            None => groups.push(vec![q]),
        }
    }
    groups
}

fn mean_side(c: &[Vector2<f64>; 4]) -> f64 {
    (0..4).map(|i| (c[i] - c[(i + 1) % 4]).norm()).sum::<f64>() / 4.0
}

/// Refines the four corners with a window of `relative_half_window` bit cells (at most
/// `max_half_window` px); a corner that does not converge keeps its start.
fn refine_marker(img: &GrayImage, marker: &mut Marker, bits: usize, r: &CornerRefinement) {
    let cell = mean_side(&marker.corners) / (bits + 2) as f64;
    let half =
        ((r.relative_half_window * cell).round() as usize).clamp(1, r.max_half_window.max(1));
    let params = SubpixParams {
        half_window: half,
        max_iterations: r.max_iterations,
        epsilon_px: r.min_step_px,
        max_shift_px: None,
    };
    for corner in marker.corners.iter_mut() {
        if let Some(p) = refine_corner(img, *corner, &params) {
            *corner = p;
        }
    }
}
