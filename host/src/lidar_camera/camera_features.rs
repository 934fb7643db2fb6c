//! The plain board in one image: its four edge lines with sub-pixel accuracy, the corners
//! as line intersections, the board plane `pi_C` from PnP with the known board size, and
//! the back-projected plane of each edge (eq. 2.3).
//!
//! - Segmentation: Otsu's threshold, then the largest bright connected region whose
//!   interior is uniform and which stands out from its surroundings (a plain board; a
//!   bright patch of wall texture is neither) is the board. A region touching the image
//!   border is a board cut by the border.
//! - Quadrilateral: four extreme boundary pixels (farthest from the centroid, farthest from
//!   it, farthest on either side of their line); the region must fill the quadrilateral.
//! - Sub-pixel edges: along each side, the gradient maximum across the edge (parabola fit
//!   on a lightly blurred image) every 2 px. Distortion is handled by undistorting those
//!   points to normalised coordinates, where the edge is straight and the fitted line
//!   `l = (a, b, c)` *is* the back-projected plane normal (`n = K^T l` with `K = I`). A
//!   second pass samples along the curved image of the first lines.
//! - Ordering: the 8 cyclic/mirrored assignments of image corners to board corners are
//!   tried in PnP; the one with the lowest reprojection error facing the camera wins.

use msreg_estimator::camera::Camera;
use msreg_estimator::Pose;
use nalgebra::{Matrix3, SymmetricEigen, Vector2, Vector3};
use serde::Serialize;

use crate::camera_yaml::Board;
use crate::vision::{solve_pnp, GrayImage};

/// Thresholds of the camera side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraFeatureParams {
    /// Smallest board region, pixels.
    pub min_area_px: usize,
    /// Largest standard deviation of the grey level inside the board.
    pub max_interior_std: f64,
    /// Smallest fraction of the quadrilateral the region must fill.
    pub min_fill: f64,
    /// Smallest grey-level difference between the board and its surroundings.
    pub min_board_contrast: f64,
    /// Search half-length across an edge, pixels.
    pub search_px: f64,
    /// Smallest grey-level step across an edge.
    pub min_contrast: f64,
    /// Fewest accepted samples per edge.
    pub min_edge_samples: usize,
    /// Largest angle between the board normal and the line of sight, deg.
    pub max_incidence_deg: f64,
}

impl Default for CameraFeatureParams {
    fn default() -> Self {
        Self {
            min_area_px: 2000,
            max_interior_std: 15.0,
            min_fill: 0.93,
            min_board_contrast: 60.0,
            search_px: 6.0,
            min_contrast: 30.0,
            min_edge_samples: 15,
            max_incidence_deg: 70.0,
        }
    }
}

/// One board edge in the image.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageEdge {
    /// Unit normal of the back-projected plane in the camera frame (`n . X = 0`).
    pub normal: Vector3<f64>,
    /// Sub-pixel edge points (distorted pixels) the line was fitted to.
    pub samples: Vec<Vector2<f64>>,
    /// RMS distance of the samples from the line, pixels (focal-length scaled).
    pub rms_px: f64,
}

/// Quality numbers of one image (for the report).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CameraQuality {
    /// Board region, pixels.
    pub area_px: usize,
    /// Accepted sub-pixel samples per edge.
    pub edge_samples: [usize; 4],
    /// RMS line fit per edge, pixels.
    pub edge_rms_px: [f64; 4],
    /// RMS reprojection error of the four corners in PnP, pixels.
    pub pnp_rms_px: f64,
    /// Angle between the board normal and the line of sight, deg.
    pub incidence_deg: f64,
    /// Distance of the board centre, m.
    pub distance_m: f64,
}

/// The board in one image.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraBoardFeatures {
    /// Corners (pixels), edge `j` from corner `j` to `j + 1`.
    pub corners_px: [Vector2<f64>; 4],
    /// The four edges.
    pub edges: Vec<ImageEdge>,
    /// Board pose from PnP.
    pub t_cam_target: Pose<f64>,
    /// Unit board normal in the camera frame (towards the camera side).
    pub normal: Vector3<f64>,
    /// `normal . X = offset` on the board.
    pub offset: f64,
    /// Quality numbers.
    pub quality: CameraQuality,
}

/// Why an image gave no board.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CameraReject {
    /// No uniform bright region large enough.
    #[error("camera: no board in the image")]
    NoBoard,
    /// The board region touches the image border.
    #[error("camera: board cut by the image border")]
    CutByBorder,
    /// The region is not a filled quadrilateral.
    #[error("camera: board region is not a quadrilateral (fill {fill:.2})")]
    NotQuadrilateral {
        /// Region area over quadrilateral area.
        fill: f64,
    },
    /// Too few sub-pixel samples on an edge.
    #[error("camera: edge {edge} has only {samples} sub-pixel samples")]
    WeakEdge {
        /// Edge index.
        edge: usize,
        /// Samples found.
        samples: usize,
    },
    /// PnP failed.
    #[error("camera: PnP of the corners failed")]
    Pnp,
    /// Seen too obliquely.
    #[error("camera: board seen edge-on ({incidence_deg:.1} deg from its normal)")]
    EdgeOn {
        /// Angle between normal and line of sight.
        incidence_deg: f64,
    },
}

/// Otsu's threshold of an 8-bit-range image.
fn otsu(img: &GrayImage) -> f32 {
    let mut hist = [0usize; 256];
    for &v in img.data() {
        hist[v.round().clamp(0.0, 255.0) as usize] += 1;
    }
    let total = img.data().len() as f64;
    let sum: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &c)| i as f64 * c as f64)
        .sum();
    let (mut w0, mut sum0, mut best, mut thr) = (0.0, 0.0, -1.0, 128.0);
    for (i, &c) in hist.iter().enumerate() {
        w0 += c as f64;
        sum0 += i as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 <= 0.0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0, (sum - sum0) / w1);
        let between = w0 * w1 * (m0 - m1).powi(2);
        if between > best {
            best = between;
            thr = i as f64 + 0.5;
        }
    }
    thr as f32
}

/// A bright connected region.
struct Region {
    pixels: Vec<(usize, usize)>,
    touches_border: bool,
}

fn bright_regions(img: &GrayImage, threshold: f32, min_area: usize) -> Vec<Region> {
    let (w, h) = (img.width(), img.height());
    let mut seen = vec![false; w * h];
    let mut regions = Vec::new();
    for start in 0..w * h {
        if seen[start] || img.data()[start] <= threshold {
            continue;
        }
        seen[start] = true;
        let mut stack = vec![start];
        let mut pixels = Vec::new();
        let mut touches_border = false;
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            pixels.push((x, y));
            touches_border |= x == 0 || y == 0 || x + 1 == w || y + 1 == h;
            let mut visit = |j: usize| {
                if !seen[j] && img.data()[j] > threshold {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        if pixels.len() >= min_area {
            regions.push(Region {
                pixels,
                touches_border,
            });
        }
    }
    regions.sort_by_key(|r| std::cmp::Reverse(r.pixels.len()));
    regions
}

/// Grey-level standard deviation of the region's pixels at least 3 px from its boundary.
fn interior_std(img: &GrayImage, region: &Region) -> f64 {
    let (w, h) = (img.width(), img.height());
    let mut mask = vec![false; w * h];
    for &(x, y) in &region.pixels {
        mask[y * w + x] = true;
    }
    let inside = |x: usize, y: usize| {
        (-3i64..=3).all(|d| {
            let (xa, ya) = (x as i64 + d, y as i64 + d);
            let ok = |xx: i64, yy: i64| {
                xx >= 0
                    && yy >= 0
                    && (xx as usize) < w
                    && (yy as usize) < h
                    && mask[yy as usize * w + xx as usize]
            };
            ok(xa, y as i64) && ok(x as i64, ya)
        })
    };
    let vals: Vec<f64> = region
        .pixels
        .iter()
        .filter(|&&(x, y)| inside(x, y))
        .map(|&(x, y)| f64::from(img.at(x, y)))
        .collect();
    if vals.len() < 10 {
        return f64::INFINITY;
    }
    let mean = vals.iter().sum::<f64>() / vals.len() as f64;
    (vals.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / vals.len() as f64).sqrt()
}

/// Mean grey level of the region minus that of the pixels 4 px outside its boundary: a
/// board stands out from the wall, a bright patch of wall texture does not.
fn border_contrast(img: &GrayImage, region: &Region) -> f64 {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let mut mask = vec![false; (w * h) as usize];
    for &(x, y) in &region.pixels {
        mask[(y * w as usize) + x] = true;
    }
    let at = |x: i64, y: i64| (x >= 0 && y >= 0 && x < w && y < h).then(|| (y * w + x) as usize);
    let (mut inside, mut outside) = ((0.0, 0usize), (0.0, 0usize));
    for &(x, y) in &region.pixels {
        inside.0 += f64::from(img.at(x, y));
        inside.1 += 1;
        for (dx, dy) in [(1i64, 0i64), (-1, 0), (0, 1), (0, -1)] {
            let (x, y) = (x as i64, y as i64);
            if at(x + dx, y + dy).is_some_and(|i| !mask[i]) {
                if let Some(i) = at(x + 4 * dx, y + 4 * dy).filter(|&i| !mask[i]) {
                    outside.0 += f64::from(img.data()[i]);
                    outside.1 += 1;
                }
            }
        }
    }
    if inside.1 == 0 || outside.1 == 0 {
        return 0.0;
    }
    inside.0 / inside.1 as f64 - outside.0 / outside.1 as f64
}

/// Four corners of a convex region, in cyclic order.
fn quad_corners(region: &Region) -> [Vector2<f64>; 4] {
    let pts: Vec<Vector2<f64>> = region
        .pixels
        .iter()
        .map(|&(x, y)| Vector2::new(x as f64, y as f64))
        .collect();
    let centroid = pts.iter().sum::<Vector2<f64>>() / pts.len() as f64;
    let farthest = |from: &Vector2<f64>| {
        pts.iter()
            .copied()
            .max_by(|a, b| {
                (a - from)
                    .norm_squared()
                    .total_cmp(&(b - from).norm_squared())
            })
            .unwrap_or(*from)
    };
    let c0 = farthest(&centroid);
    let c1 = farthest(&c0);
    let d = c1 - c0;
    let side = |p: &Vector2<f64>| d.x * (p.y - c0.y) - d.y * (p.x - c0.x);
    let c2 = pts
        .iter()
        .copied()
        .max_by(|a, b| side(a).total_cmp(&side(b)))
        .unwrap_or(c0);
    let c3 = pts
        .iter()
        .copied()
        .min_by(|a, b| side(a).total_cmp(&side(b)))
        .unwrap_or(c1);
    let mut corners = [c0, c2, c1, c3];
    let centre = corners.iter().sum::<Vector2<f64>>() / 4.0;
    corners.sort_by(|a, b| {
        let ang = |p: &Vector2<f64>| (p.y - centre.y).atan2(p.x - centre.x);
        ang(a).total_cmp(&ang(b))
    });
    corners
}

fn quad_area(c: &[Vector2<f64>; 4]) -> f64 {
    let mut a = 0.0;
    for j in 0..4 {
        let (p, q) = (c[j], c[(j + 1) % 4]);
        a += p.x * q.y - q.x * p.y;
    }
    0.5 * a.abs()
}

/// Sub-pixel edge position along the normal through `p` (gradient peak, parabola fit).
fn edge_across(
    img: &GrayImage,
    p: &Vector2<f64>,
    normal: &Vector2<f64>,
    params: &CameraFeatureParams,
) -> Option<Vector2<f64>> {
    let step = 0.25;
    let n = (params.search_px / step) as i64;
    let profile: Vec<f64> = (-n - 1..=n + 1)
        .map(|k| {
            let q = p + normal * (k as f64 * step);
            f64::from(img.sample(q.x, q.y))
        })
        .collect();
    let contrast = (profile[0] - profile[profile.len() - 1]).abs();
    if contrast < params.min_contrast {
        return None;
    }
    let grad: Vec<f64> = (1..profile.len() - 1)
        .map(|i| (profile[i + 1] - profile[i - 1]).abs())
        .collect();
    let (imax, _) = grad.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    if imax == 0 || imax + 1 >= grad.len() {
        return None;
    }
    let (a, b, c) = (grad[imax - 1], grad[imax], grad[imax + 1]);
    let denom = a - 2.0 * b + c;
    let frac = if denom.abs() > 1e-12 {
        0.5 * (a - c) / denom
    } else {
        0.0
    };
    let offset = (imax as f64 - n as f64 + frac) * step;
    Some(p + normal * offset)
}

/// Total-least-squares line `a x + b y + c = 0` (with `a^2 + b^2 = 1`) through points.
fn fit_line_2d(points: &[Vector2<f64>]) -> Option<Vector3<f64>> {
    if points.len() < 2 {
        return None;
    }
    let mean = points.iter().sum::<Vector2<f64>>() / points.len() as f64;
    let mut cov = nalgebra::Matrix2::zeros();
    for p in points {
        let d = p - mean;
        cov += d * d.transpose();
    }
    let eig = SymmetricEigen::new(cov);
    let imin = if eig.eigenvalues[0] < eig.eigenvalues[1] {
        0
    } else {
        1
    };
    let nrm = eig.eigenvectors.column(imin).into_owned();
    Some(Vector3::new(nrm.x, nrm.y, -nrm.dot(&mean)))
}

/// Normalised image coordinates of a pixel (undistorted), `None` if it cannot be lifted.
fn normalised(camera: &Camera<f64>, px: &Vector2<f64>) -> Option<Vector2<f64>> {
    let b = camera.unproject(px)?;
    (b.z > 1e-6).then(|| Vector2::new(b.x / b.z, b.y / b.z))
}

/// A fitted edge: line in normalised coordinates, its samples (px), RMS (px).
type EdgeFit = (Vector3<f64>, Vec<Vector2<f64>>, f64);

/// Fits one edge from samples along the image curve `points(t)`, `t in [0.08, 0.92]`.
fn fit_edge(
    img: &GrayImage,
    camera: &Camera<f64>,
    along: &dyn Fn(f64) -> Option<Vector2<f64>>,
    length_px: f64,
    inward: &Vector2<f64>,
    params: &CameraFeatureParams,
) -> Option<EdgeFit> {
    let count = (length_px / 2.0).max(4.0) as usize;
    let mut samples = Vec::new();
    for k in 0..=count {
        let t = 0.08 + 0.84 * k as f64 / count as f64;
        let (Some(p), Some(q)) = (along(t), along(t + 1e-3)) else {
            continue;
        };
        let tangent = (q - p).try_normalize(1e-12)?;
        let mut nrm = Vector2::new(-tangent.y, tangent.x);
        if nrm.dot(inward) < 0.0 {
            nrm = -nrm;
        }
        if let Some(e) = edge_across(img, &p, &nrm, params) {
            samples.push(e);
        }
    }
    let focal = camera.intrinsics().fu;
    let mut kept = samples;
    let mut line = None;
    for _ in 0..3 {
        let norm: Vec<Vector2<f64>> = kept.iter().filter_map(|p| normalised(camera, p)).collect();
        let l = fit_line_2d(&norm)?;
        let res: Vec<f64> = norm
            .iter()
            .map(|m| (l.x * m.x + l.y * m.y + l.z).abs() * focal)
            .collect();
        let mut sorted = res.clone();
        sorted.sort_by(f64::total_cmp);
        let mad = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        let limit = (4.0 * 1.4826 * mad).max(0.3);
        let before = kept.len();
        kept = kept
            .iter()
            .zip(&res)
            .filter(|(_, r)| **r <= limit)
            .map(|(p, _)| *p)
            .collect();
        line = Some(l);
        if kept.len() == before {
            break;
        }
    }
    let l = line?;
    let norm: Vec<Vector2<f64>> = kept.iter().filter_map(|p| normalised(camera, p)).collect();
    let l = fit_line_2d(&norm).unwrap_or(l);
    let rms = (norm
        .iter()
        .map(|m| ((l.x * m.x + l.y * m.y + l.z) * focal).powi(2))
        .sum::<f64>()
        / norm.len().max(1) as f64)
        .sqrt();
    Some((l, kept, rms))
}

/// [`fit_edge`] with at least `min_edge_samples` samples, else the rejection of edge `j`.
fn checked_edge(
    img: &GrayImage,
    camera: &Camera<f64>,
    along: &dyn Fn(f64) -> Option<Vector2<f64>>,
    length_px: f64,
    inward: &Vector2<f64>,
    params: &CameraFeatureParams,
    j: usize,
) -> Result<EdgeFit, CameraReject> {
    let fit = fit_edge(img, camera, along, length_px, inward, params);
    let samples = fit.as_ref().map_or(0, |f| f.1.len());
    match fit {
        Some(f) if samples >= params.min_edge_samples => Ok(f),
        _ => Err(CameraReject::WeakEdge { edge: j, samples }),
    }
}

/// Intersection of two lines in normalised coordinates.
fn intersect(a: &Vector3<f64>, b: &Vector3<f64>) -> Option<Vector2<f64>> {
    let p = a.cross(b);
    (p.z.abs() > 1e-12).then(|| Vector2::new(p.x / p.z, p.y / p.z))
}

fn project_normalised(camera: &Camera<f64>, m: &Vector2<f64>) -> Option<Vector2<f64>> {
    camera
        .project(&Vector3::new(m.x, m.y, 1.0))
        .map(|p| p.pixel)
}

/// Normalised-image corners of four edge lines: corner `j` joins edges `j - 1` and `j`.
fn corners_of(lines: &[Vector3<f64>]) -> Option<[Vector2<f64>; 4]> {
    let c: Vec<Vector2<f64>> = (0..4)
        .filter_map(|j| intersect(&lines[(j + 3) % 4], &lines[j]))
        .collect();
    (c.len() == 4).then(|| [c[0], c[1], c[2], c[3]])
}

/// The four edges of the board region with corners `rough` in the (smoothed) image, in two
/// passes: straight sides between the rough corners, then along the (curved) image of the
/// pass-1 lines between their intersections. `fill` is the region's fill ratio (for the
/// rejection).
fn board_edges(
    smooth: &GrayImage,
    camera: &Camera<f64>,
    rough: &[Vector2<f64>; 4],
    params: &CameraFeatureParams,
    fill: f64,
) -> Result<Vec<ImageEdge>, CameraReject> {
    let centre = rough.iter().sum::<Vector2<f64>>() / 4.0;
    let mut lines: Vec<Vector3<f64>> = Vec::with_capacity(4);
    for j in 0..4 {
        let (a, b) = (rough[j], rough[(j + 1) % 4]);
        let inward = centre - 0.5 * (a + b);
        let along = |t: f64| Some(a + (b - a) * t);
        let (l, _, _) = checked_edge(smooth, camera, &along, (b - a).norm(), &inward, params, j)?;
        lines.push(l);
    }
    let corners = corners_of(&lines).ok_or(CameraReject::NotQuadrilateral { fill })?;
    let mut edges = Vec::with_capacity(4);
    for j in 0..4 {
        let (a, b) = (corners[j], corners[(j + 1) % 4]);
        let along = |t: f64| project_normalised(camera, &(a + (b - a) * t));
        let (Some(pa), Some(pb)) = (along(0.0), along(1.0)) else {
            return Err(CameraReject::NotQuadrilateral { fill });
        };
        let inward = centre - 0.5 * (pa + pb);
        let (l, samples, rms) =
            checked_edge(smooth, camera, &along, (pb - pa).norm(), &inward, params, j)?;
        edges.push(ImageEdge {
            normal: l.normalize(),
            samples,
            rms_px: rms,
        });
    }
    Ok(edges)
}

/// Extracts the board from an image (see the module docs).
pub fn extract_camera_board(
    img: &GrayImage,
    camera: &Camera<f64>,
    board: &Board,
    params: &CameraFeatureParams,
) -> Result<CameraBoardFeatures, CameraReject> {
    let threshold = otsu(img);
    let regions = bright_regions(img, threshold, params.min_area_px);
    let region = regions
        .iter()
        .find(|r| {
            interior_std(img, r) <= params.max_interior_std
                && border_contrast(img, r) >= params.min_board_contrast
        })
        .ok_or(CameraReject::NoBoard)?;
    if region.touches_border {
        return Err(CameraReject::CutByBorder);
    }
    let rough = quad_corners(region);
    let fill = region.pixels.len() as f64 / quad_area(&rough).max(1.0);
    if !(params.min_fill..=1.0 / params.min_fill).contains(&fill) {
        return Err(CameraReject::NotQuadrilateral { fill });
    }
    let edges = board_edges(&img.gaussian_blur(0.8), camera, &rough, params, fill)?;
    let lines: Vec<Vector3<f64>> = edges.iter().map(|e| e.normal).collect();
    let corners = corners_of(&lines).ok_or(CameraReject::NotQuadrilateral { fill })?;
    let corners_px: Vec<Vector2<f64>> = corners
        .iter()
        .filter_map(|m| project_normalised(camera, m))
        .collect();
    if corners_px.len() != 4 {
        return Err(CameraReject::NotQuadrilateral { fill });
    }
    let corners_px = [corners_px[0], corners_px[1], corners_px[2], corners_px[3]];
    let (t_cam_target, pnp_rms) =
        board_pose(camera, board, &corners_px).ok_or(CameraReject::Pnp)?;
    let normal = t_cam_target.rotation * Vector3::z();
    let offset = normal.dot(&t_cam_target.translation);
    let sight = t_cam_target.translation.normalize();
    let incidence_deg = (-normal.dot(&sight)).clamp(-1.0, 1.0).acos().to_degrees();
    if incidence_deg > params.max_incidence_deg {
        return Err(CameraReject::EdgeOn { incidence_deg });
    }
    let quality = CameraQuality {
        area_px: region.pixels.len(),
        edge_samples: std::array::from_fn(|j| edges[j].samples.len()),
        edge_rms_px: std::array::from_fn(|j| edges[j].rms_px),
        pnp_rms_px: pnp_rms,
        incidence_deg,
        distance_m: t_cam_target.translation.norm(),
    };
    Ok(CameraBoardFeatures {
        corners_px,
        edges,
        t_cam_target,
        normal,
        offset,
        quality,
    })
}

/// The board pose from its four image corners (edge `j` joins corners `j` and `j + 1`):
/// the cyclic or mirrored assignment to the board corners with the lowest PnP error that
/// puts the board in front of the camera, face on. Returns the pose and its RMS (px).
fn board_pose(
    camera: &Camera<f64>,
    board: &Board,
    corners_px: &[Vector2<f64>; 4],
) -> Option<(Pose<f64>, f64)> {
    let board_corners = board.corners();
    let mut best: Option<(f64, Pose<f64>, f64)> = None;
    for mirror in [false, true] {
        for shift in 0..4 {
            let pts: Vec<Vector3<f64>> = (0..4)
                .map(|k| {
                    let idx = if mirror {
                        (shift + 4 - k) % 4
                    } else {
                        (shift + k) % 4
                    };
                    board_corners[idx]
                })
                .collect();
            let Ok(sol) = solve_pnp(camera, &pts, corners_px) else {
                continue;
            };
            let t = &sol.t_cam_target;
            let n = t.rotation * Vector3::z();
            if t.translation.z <= 0.0 || n.dot(&t.translation) >= 0.0 {
                continue; // behind the camera or showing its back
            }
            if best.as_ref().is_none_or(|b| sol.rms_px < b.0) {
                best = Some((sol.rms_px, sol.t_cam_target, sol.rms_px));
            }
        }
    }
    best.map(|(rms, pose, _)| (pose, rms))
}

/// The 3x3 pinhole matrix `K` of a camera (for reporting lines in pixel form).
pub fn k_matrix(camera: &Camera<f64>) -> Matrix3<f64> {
    let i = camera.intrinsics();
    Matrix3::new(i.fu, 0.0, i.cu, 0.0, i.fv, i.cv, 0.0, 0.0, 1.0)
}
