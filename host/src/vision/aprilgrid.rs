//! AprilGrid detection (Kalibr's default target: tag36h11 tags with a 2-bit black border and
//! black squares in the gaps at their corners), built on the ArUco detector's steps
//! ([`crate::vision::aruco`]) with no third-party detector:
//! 1. dark pixels by adaptive threshold at two window sizes, then eroded by one pixel (3 x 3):
//!    each tag corner touches a corner square only at a point (a saddle), and the erosion
//!    cuts that contact so every tag's black border is a component of its own;
//! 2. outer boundaries simplified to convex quadrilaterals (the ArUco candidate gates);
//! 3. each quadrilateral's 8 x 8 inner cells (the inner ring of the border and the 6 x 6 data
//!    bits) read by Otsu's threshold and looked up among the grid's first
//!    `tag_cols * tag_rows` tag36h11 codes in four rotations, up to
//!    [`AprilGridParams::max_bit_errors`] wrong bits; every id of the grid is printed once,
//!    so a repeat of a found id (the other threshold window) is dropped;
//! 4. every tag corner refined to sub-pixel by gradient orthogonality
//!    ([`crate::vision::subpix`], OpenCV's `cornerSubPix`, as Kalibr does): with the corner
//!    squares each tag corner is a symmetric saddle, where that refinement is unbiased; a tag
//!    whose corner does not converge or moves further than
//!    [`AprilGridParams::max_corner_shift_bits`] is dropped (Kalibr drops it too).
//!
//! Corner ids are Kalibr's (`4 * tag + k`, `k` counter-clockwise from the tag's lower-left
//! corner on the sheet: the numbering of [`AprilGridTarget::corner`] and of
//! `cam0/corners.csv`). The printed pattern for the renderer is [`pattern`]. Method and
//! measured accuracy: docs/aprilgrid.md.

pub mod pattern;
mod tag36h11;

use nalgebra::Vector2;

use super::aruco::decode::{apply as apply_homography, homography_4pt, read_bits};
use super::aruco::dictionary::identify_in;
use super::aruco::quad::{adaptive_threshold, quads_of_mask, Quad};
use super::aruco::ArucoParams;
use super::gray::GrayImage;
use super::subpix::{refine_corner, SubpixParams};
use crate::camera_yaml::AprilGridTarget;

pub use pattern::AprilGridPattern;

/// Data bits per tag side (tag36h11).
const DATA_BITS: usize = 6;
/// Cells per tag side: the data and Kalibr's 2-bit black border on each side.
const TAG_CELLS: f64 = 10.0;

/// The tag36h11 code of tag `id` (the AprilTag family Kalibr's AprilGrid prints), `None`
/// past the family's 587 codes.
pub fn tag36h11_code(id: usize) -> Option<u64> {
    tag36h11::TAG36H11.get(id).copied()
}

/// Why an image gave no AprilGrid corners.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NoAprilGrid {
    /// No tag of the target was decoded.
    #[error("no tag of the aprilgrid found")]
    NoTags,
    /// Fewer tags than [`AprilGridParams::min_tags`].
    #[error("{found} aprilgrid tags found, at least {min} are needed")]
    TooFewTags {
        /// Tags found.
        found: usize,
        /// The minimum.
        min: usize,
    },
}

/// Detector settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AprilGridParams {
    /// Fewest tags for an image to count (Kalibr's `minTagsForValidObs` is 4; partial views
    /// are the point of the AprilGrid).
    pub min_tags: usize,
    /// Adaptive-threshold windows, pixels (odd): a pixel is dark below its window's mean
    /// minus [`Self::threshold_constant`].
    pub threshold_windows: [usize; 2],
    /// See [`Self::threshold_windows`], grey levels.
    pub threshold_constant: f32,
    /// Most wrong data bits in a decoded tag (tag36h11 codes are at least 11 bits apart).
    pub max_bit_errors: usize,
    /// Most black-border cells read white, of the 28 of the inner border ring.
    pub max_border_errors: usize,
    /// Sub-pixel half window in bit cells, clamped to 2..=8 px (1.5: chosen on seed 3 of
    /// `aprilgrid_bench`, median / max error 0.060 / 0.159 px against 0.074 / 0.179 at 1.0
    /// and 0.055 / 0.253 at 2.0).
    pub refine_window_bits: f64,
    /// Largest move of a corner by the refinement, in bit cells.
    pub max_corner_shift_bits: f64,
}

impl Default for AprilGridParams {
    fn default() -> Self {
        Self {
            min_tags: 4,
            threshold_windows: [13, 31],
            threshold_constant: 7.0,
            max_bit_errors: 3,
            max_border_errors: 6,
            refine_window_bits: 1.5,
            max_corner_shift_bits: 1.0,
        }
    }
}

/// The corners found in one image.
#[derive(Clone, Debug, PartialEq)]
pub struct AprilGridDetection {
    /// Kalibr corner ids, ascending.
    pub ids: Vec<usize>,
    /// The pixel of each id (OpenCV convention).
    pub pixels: Vec<Vector2<f64>>,
}

/// One decoded tag: its id and its corners in Kalibr's order (unrefined).
struct Tag {
    id: usize,
    corners: [Vector2<f64>; 4],
}

/// Detects the AprilGrid `target` in `image`.
pub fn detect_aprilgrid(
    image: &GrayImage,
    target: &AprilGridTarget,
    params: &AprilGridParams,
) -> Result<AprilGridDetection, NoAprilGrid> {
    let codes = &tag36h11::TAG36H11[..(target.tag_cols * target.tag_rows).min(587)];
    let (w, h) = (image.width(), image.height());
    let quad_gates = ArucoParams::default();
    let mut tags: Vec<Tag> = Vec::new();
    for &window in &params.threshold_windows {
        let mask = erode(
            &adaptive_threshold(image, window.max(3) | 1, params.threshold_constant),
            w,
            h,
        );
        for quad in quads_of_mask(&mask, w, h, &quad_gates) {
            if let Some(tag) = decode_tag(image, &quad, codes, params, &quad_gates) {
                if tags.iter().all(|t| t.id != tag.id) {
                    tags.push(tag);
                }
            }
        }
    }
    let mut corners: Vec<(usize, Vector2<f64>)> = tags
        .iter()
        .filter_map(|tag| refine_tag(image, tag, params))
        .flatten()
        .collect();
    let found = corners.len() / 4;
    if found == 0 {
        return Err(NoAprilGrid::NoTags);
    }
    if found < params.min_tags {
        return Err(NoAprilGrid::TooFewTags {
            found,
            min: params.min_tags,
        });
    }
    corners.sort_by_key(|c| c.0);
    Ok(AprilGridDetection {
        ids: corners.iter().map(|c| c.0).collect(),
        pixels: corners.iter().map(|c| c.1).collect(),
    })
}

/// A dark mask eroded by one pixel (3 x 3 minimum): cuts the point contacts of a tag's
/// corners with the corner squares.
fn erode(mask: &[bool], width: usize, height: usize) -> Vec<bool> {
    let at = |x: usize, y: usize| mask[y * width + x];
    let mut rows = vec![false; mask.len()];
    for y in 0..height {
        for x in 1..width.saturating_sub(1) {
            rows[y * width + x] = at(x - 1, y) && at(x, y) && at(x + 1, y);
        }
    }
    let mut out = vec![false; mask.len()];
    for y in 1..height.saturating_sub(1) {
        for x in 0..width {
            let i = y * width + x;
            out[i] = rows[i - width] && rows[i] && rows[i + width];
        }
    }
    out
}

/// Reads the tag inside a candidate quadrilateral (the outline of its black border): the
/// id among `codes` and the corners in Kalibr's order, or `None`.
fn decode_tag(
    image: &GrayImage,
    quad: &Quad,
    codes: &[u64],
    params: &AprilGridParams,
    read: &ArucoParams,
) -> Option<Tag> {
    // The 8 x 8 inner cells: one cell in from the outline on every side.
    let cells = [
        Vector2::new(0.0, 0.0),
        Vector2::new(TAG_CELLS, 0.0),
        Vector2::new(TAG_CELLS, TAG_CELLS),
        Vector2::new(0.0, TAG_CELLS),
    ];
    let h = homography_4pt(&cells, &quad.corners)?;
    let inner = [(1.0, 1.0), (9.0, 1.0), (9.0, 9.0), (1.0, 9.0)]
        .map(|(x, y)| apply_homography(&h, Vector2::new(x, y)));
    let (code, border_errors) = read_bits(image, &inner, DATA_BITS, read)?;
    if border_errors > params.max_border_errors {
        return None;
    }
    let (id, turns, _) = identify_in(codes, DATA_BITS, code, params.max_bit_errors)?;
    // OpenCV order (the printed top-left first, clockwise on screen) starts at candidate
    // corner `turns`; Kalibr's corner k (counter-clockwise from the bottom-left) is OpenCV's
    // corner 3 - k.
    let corners = std::array::from_fn(|k| quad.corners[(3 - k + turns) % 4]);
    Some(Tag { id, corners })
}

/// The tag's four corners refined, with their Kalibr ids; `None` when one fails.
fn refine_tag(
    image: &GrayImage,
    tag: &Tag,
    params: &AprilGridParams,
) -> Option<[(usize, Vector2<f64>); 4]> {
    let side = (0..4)
        .map(|i| (tag.corners[i] - tag.corners[(i + 1) % 4]).norm())
        .sum::<f64>()
        / 4.0;
    let bit = side / TAG_CELLS;
    let half = (params.refine_window_bits * bit).round().clamp(2.0, 8.0) as usize;
    let subpix = SubpixParams {
        half_window: half,
        max_iterations: 40,
        epsilon_px: 1e-3,
        max_shift_px: Some(params.max_corner_shift_bits * bit + 1.5),
    };
    let mut out = [(0, Vector2::zeros()); 4];
    for (k, start) in tag.corners.iter().enumerate() {
        out[k] = (4 * tag.id + k, refine_corner(image, *start, &subpix)?);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erosion_cuts_a_diagonal_contact() {
        // Two 3 x 3 dark squares touching at one corner, inside a 9 x 9 image.
        let (w, h) = (9, 9);
        let mut mask = vec![false; w * h];
        for (x0, y0) in [(1, 1), (4, 4)] {
            for y in y0..y0 + 3 {
                for x in x0..x0 + 3 {
                    mask[y * w + x] = true;
                }
            }
        }
        let eroded = erode(&mask, w, h);
        let dark: Vec<usize> = (0..w * h).filter(|&i| eroded[i]).collect();
        assert_eq!(dark, vec![2 * w + 2, 5 * w + 5]);
    }

    #[test]
    fn the_table_is_tag36h11() {
        // First and last codes of the published family.
        assert_eq!(tag36h11_code(0), Some(0xd5d628584));
        assert_eq!(tag36h11_code(586), Some(0xe83be4b73));
        assert_eq!(tag36h11_code(587), None);
    }
}
