//! The board in one LiDAR scan (dissertation Fig. 2.7): field-of-view filter, RANSAC plane
//! segmentation until a plane's largest cluster has the board's size, edge points from range
//! discontinuities along each ring, a planarity re-check, and a sequential RANSAC fit of the
//! four edge lines, with a per-frame quality report.
//!
//! Edge points are placed where the edge most likely is, not on the last return: a ring's
//! last board return is up to one azimuth step inside the true edge and the first
//! background return's ray crosses the board plane up to one step outside it, so the
//! midpoint of the two rays' intersections with the fitted plane is unbiased (uniform error
//! within +-half a step) and free of range noise. Without it every edge would be biased
//! inwards by half a step (1.7 px at the simulated camera), which no solver can undo.

use std::collections::HashMap;

use nalgebra::{Matrix3, SymmetricEigen, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::camera_yaml::Board;
use crate::pointcloud::PointCloud;

/// Thresholds of the LiDAR side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LidarFeatureParams {
    /// FoV filter: keep `|azimuth|` up to this (LiDAR x forward), deg.
    pub max_azimuth_deg: f64,
    /// FoV filter: range window, m.
    pub min_range_m: f64,
    /// FoV filter: range window, m.
    pub max_range_m: f64,
    /// RANSAC plane inlier distance, m.
    pub plane_threshold_m: f64,
    /// RANSAC samples per plane.
    pub ransac_iterations: usize,
    /// Planes tried before giving up on finding the board.
    pub max_planes: usize,
    /// Points closer than this belong to one cluster, m.
    pub cluster_radius_m: f64,
    /// A neighbour this much farther than a board return makes it an edge, m.
    pub discontinuity_m: f64,
    /// RANSAC line inlier distance, m.
    pub line_threshold_m: f64,
    /// Fewest points on the board plane.
    pub min_plane_points: usize,
    /// Fewest points on each edge line.
    pub min_edge_points: usize,
    /// Largest deviation of the edge quadrilateral's angles from 90 deg.
    pub max_corner_error_deg: f64,
}

impl Default for LidarFeatureParams {
    fn default() -> Self {
        Self {
            max_azimuth_deg: 60.0,
            min_range_m: 1.0,
            max_range_m: 8.0,
            plane_threshold_m: 0.08,
            ransac_iterations: 300,
            max_planes: 6,
            cluster_radius_m: 0.2,
            discontinuity_m: 0.3,
            line_threshold_m: 0.03,
            min_plane_points: 60,
            min_edge_points: 4,
            max_corner_error_deg: 20.0,
        }
    }
}

/// One edge line of the board in the LiDAR frame.
#[derive(Clone, Debug, PartialEq)]
pub struct LidarEdge {
    /// The edge points `Q_ijn` (on the board plane).
    pub points: Vec<Vector3<f64>>,
    /// A point on the fitted line (centroid).
    pub centroid: Vector3<f64>,
    /// Unit direction.
    pub direction: Vector3<f64>,
    /// RMS distance of the points from the line, m.
    pub rms_m: f64,
}

/// Quality numbers of one frame (for the report).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LidarQuality {
    /// Points on the board plane.
    pub plane_points: usize,
    /// RMS distance of the board points from their plane, m.
    pub plane_rms_m: f64,
    /// Edge points found before line fitting.
    pub edge_candidates: usize,
    /// Points on each fitted edge line.
    pub edge_points: [usize; 4],
    /// RMS distance from each line, m.
    pub edge_rms_m: [f64; 4],
    /// Side lengths of the quadrilateral of the four lines, m.
    pub side_lengths_m: [f64; 4],
    /// Its corner angles, deg.
    pub corner_angles_deg: [f64; 4],
}

/// The board in one scan.
#[derive(Clone, Debug, PartialEq)]
pub struct LidarBoardFeatures {
    /// Points on the board `P_im`.
    pub plane_points: Vec<Vector3<f64>>,
    /// Unit normal of the fitted plane.
    pub normal: Vector3<f64>,
    /// Plane offset: `normal . p = offset`.
    pub offset: f64,
    /// The four edges, in cyclic order around the board.
    pub edges: Vec<LidarEdge>,
    /// Quality numbers.
    pub quality: LidarQuality,
}

/// Why a scan gave no board.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LidarReject {
    /// Nothing survived the field-of-view filter.
    #[error("LiDAR: no points inside the field-of-view filter")]
    Empty,
    /// No plane cluster of the board's size.
    #[error("LiDAR: no board-sized plane found ({planes} planes tried)")]
    NoBoard {
        /// Planes tried.
        planes: usize,
    },
    /// Too few edge points for four lines.
    #[error("LiDAR: only {found} edge points (board edge-on or too far?)")]
    TooFewEdgePoints {
        /// Edge points found.
        found: usize,
    },
    /// Fewer than four edge lines.
    #[error("LiDAR: only {found} of 4 edge lines found with >= {min} points each")]
    MissingEdges {
        /// Lines found.
        found: usize,
        /// Points needed per line.
        min: usize,
    },
    /// The four lines do not make a rectangle.
    #[error("LiDAR: edge lines are not a rectangle (corner angles {angles:?} deg)")]
    NotRectangle {
        /// Corner angles, deg.
        angles: [f64; 4],
    },
}

/// Centroid and eigen-decomposition of the scatter of `points` (at least one point).
fn scatter(points: &[Vector3<f64>]) -> (Vector3<f64>, SymmetricEigen<f64, nalgebra::U3>) {
    let n = points.len() as f64;
    let mean = points.iter().sum::<Vector3<f64>>() / n;
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p - mean;
        cov += d * d.transpose();
    }
    (mean, SymmetricEigen::new(cov / n))
}

/// The eigenvector of the smallest (`largest = false`) or largest eigenvalue.
fn extreme_axis(eig: &SymmetricEigen<f64, nalgebra::U3>, largest: bool) -> Option<Vector3<f64>> {
    let values = eig.eigenvalues.iter().enumerate();
    let (i, _) = if largest {
        values.max_by(|a, b| a.1.total_cmp(b.1))?
    } else {
        values.min_by(|a, b| a.1.total_cmp(b.1))?
    };
    Some(eig.eigenvectors.column(i).into_owned())
}

/// Root mean square of `distance` over `points`.
fn rms(points: &[Vector3<f64>], distance: impl Fn(&Vector3<f64>) -> f64) -> f64 {
    (points.iter().map(|p| distance(p).powi(2)).sum::<f64>() / points.len() as f64).sqrt()
}

/// Least-squares plane through points: unit normal, offset and RMS distance.
pub fn fit_plane(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, f64, f64)> {
    if points.len() < 3 {
        return None;
    }
    let (mean, eig) = scatter(points);
    let normal = extreme_axis(&eig, false)?;
    let offset = normal.dot(&mean);
    Some((normal, offset, rms(points, |p| normal.dot(p) - offset)))
}

/// Least-squares line: centroid, unit direction and RMS distance.
fn fit_line(points: &[Vector3<f64>]) -> Option<(Vector3<f64>, Vector3<f64>, f64)> {
    if points.len() < 2 {
        return None;
    }
    let (mean, eig) = scatter(points);
    let dir = extreme_axis(&eig, true)?;
    Some((mean, dir, rms(points, |p| line_distance(p, &mean, &dir))))
}

fn line_distance(p: &Vector3<f64>, c: &Vector3<f64>, dir: &Vector3<f64>) -> f64 {
    (p - c).cross(dir).norm()
}

/// RANSAC plane among `points[idx]`: inlier indices of the best plane.
fn ransac_plane(
    points: &[Vector3<f64>],
    idx: &[usize],
    threshold: f64,
    iterations: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<usize> {
    let mut best: Vec<usize> = Vec::new();
    if idx.len() < 3 {
        return best;
    }
    for _ in 0..iterations {
        let a = points[idx[rng.gen_range(0..idx.len())]];
        let b = points[idx[rng.gen_range(0..idx.len())]];
        let c = points[idx[rng.gen_range(0..idx.len())]];
        let Some(n) = (b - a).cross(&(c - a)).try_normalize(1e-9) else {
            continue;
        };
        let d = n.dot(&a);
        let count = idx
            .iter()
            .filter(|&&i| (n.dot(&points[i]) - d).abs() < threshold)
            .count();
        if count > best.len() {
            best = idx
                .iter()
                .copied()
                .filter(|&i| (n.dot(&points[i]) - d).abs() < threshold)
                .collect();
        }
    }
    best
}

/// The largest cluster (points within `radius` chained) among `points[idx]`.
fn largest_cluster(points: &[Vector3<f64>], idx: &[usize], radius: f64) -> Vec<usize> {
    let key = |p: &Vector3<f64>| {
        [
            (p.x / radius).floor() as i64,
            (p.y / radius).floor() as i64,
            (p.z / radius).floor() as i64,
        ]
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (k, &i) in idx.iter().enumerate() {
        grid.entry(key(&points[i])).or_default().push(k);
    }
    let mut label = vec![usize::MAX; idx.len()];
    let mut best: Vec<usize> = Vec::new();
    for start in 0..idx.len() {
        if label[start] != usize::MAX {
            continue;
        }
        label[start] = start;
        let mut stack = vec![start];
        let mut members = Vec::new();
        while let Some(k) = stack.pop() {
            members.push(idx[k]);
            let p = points[idx[k]];
            let c = key(&p);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(cell) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                            continue;
                        };
                        for &m in cell {
                            if label[m] == usize::MAX && (points[idx[m]] - p).norm() < radius {
                                label[m] = start;
                                stack.push(m);
                            }
                        }
                    }
                }
            }
        }
        if members.len() > best.len() {
            best = members;
        }
    }
    best
}

/// Largest extent of points in a plane (max over 36 directions of the projected spread).
fn diameter(points: &[Vector3<f64>], normal: &Vector3<f64>) -> f64 {
    let u = normal
        .cross(&Vector3::x())
        .try_normalize(1e-6)
        .unwrap_or_else(|| normal.cross(&Vector3::y()).normalize());
    let v = normal.cross(&u);
    (0..36)
        .map(|k| {
            let a = k as f64 * std::f64::consts::PI / 36.0;
            let d = u * a.cos() + v * a.sin();
            let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
                let x = d.dot(p);
                (lo.min(x), hi.max(x))
            });
            hi - lo
        })
        .fold(0.0, f64::max)
}

/// Intersection of the ray through `p` (from the LiDAR origin) with the plane.
fn on_plane(p: &Vector3<f64>, normal: &Vector3<f64>, offset: f64) -> Option<Vector3<f64>> {
    let denom = normal.dot(p);
    (denom.abs() > 1e-9).then(|| p * (offset / denom))
}

/// The board's points among `candidates`: planes are found by RANSAC one after the other
/// (each removed before the next), and the first whose largest cluster has the board's size
/// is the board.
fn board_cluster(
    points: &[Vector3<f64>],
    candidates: Vec<usize>,
    board: &Board,
    params: &LidarFeatureParams,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<usize>, LidarReject> {
    let mut remaining = candidates;
    for _ in 0..params.max_planes {
        let inliers = ransac_plane(
            points,
            &remaining,
            params.plane_threshold_m,
            params.ransac_iterations,
            rng,
        );
        if inliers.len() < params.min_plane_points {
            break;
        }
        let cluster = largest_cluster(points, &inliers, params.cluster_radius_m);
        let cluster_points: Vec<Vector3<f64>> = cluster.iter().map(|&i| points[i]).collect();
        if let Some((normal, _, _)) = fit_plane(&cluster_points) {
            let size = diameter(&cluster_points, &normal);
            if cluster.len() >= params.min_plane_points
                && size <= board.diagonal() + 0.15
                && size >= 0.5 * board.width_m.min(board.height_m)
            {
                return Ok(cluster);
            }
        }
        let drop: std::collections::HashSet<usize> = inliers.into_iter().collect();
        remaining.retain(|i| !drop.contains(i));
    }
    Err(LidarReject::NoBoard {
        planes: params.max_planes,
    })
}

/// Extracts the board from a scan (see the module docs).
pub fn extract_lidar_board(
    cloud: &PointCloud,
    board: &Board,
    params: &LidarFeatureParams,
) -> Result<LidarBoardFeatures, LidarReject> {
    let points: Vec<Vector3<f64>> = cloud.points.iter().map(|p| p.xyz).collect();
    let in_fov: Vec<usize> = (0..points.len())
        .filter(|&i| {
            let p = &points[i];
            let range = p.norm();
            p.y.atan2(p.x).to_degrees().abs() <= params.max_azimuth_deg
                && range >= params.min_range_m
                && range <= params.max_range_m
        })
        .collect();
    if in_fov.is_empty() {
        return Err(LidarReject::Empty);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(0x5EED);
    let cluster = board_cluster(&points, in_fov, board, params, &mut rng)?;
    // Refit with a 3-sigma re-check of the cluster.
    let pts: Vec<Vector3<f64>> = cluster.iter().map(|&i| points[i]).collect();
    let (normal, offset, rms) = fit_plane(&pts).ok_or(LidarReject::NoBoard { planes: 1 })?;
    let keep = (3.0 * rms).max(0.01);
    let mut kept: Vec<usize> = cluster
        .iter()
        .copied()
        .filter(|&i| (normal.dot(&points[i]) - offset).abs() < keep)
        .collect();
    // Scan order, so that the result does not depend on hashing.
    kept.sort_unstable();
    let plane_points: Vec<Vector3<f64>> = kept.iter().map(|&i| points[i]).collect();
    let on_board: std::collections::HashSet<usize> = kept.into_iter().collect();
    let (normal, offset, plane_rms) =
        fit_plane(&plane_points).ok_or(LidarReject::NoBoard { planes: 1 })?;
    let candidates = edge_points(cloud, &on_board, &normal, offset, params, plane_rms);
    if candidates.len() < 4 * params.min_edge_points {
        return Err(LidarReject::TooFewEdgePoints {
            found: candidates.len(),
        });
    }
    let edges = fit_edges(&candidates, &normal, params, &mut rng)?;
    let quality_geometry = quadrilateral(&edges, &normal);
    let quality = LidarQuality {
        plane_points: plane_points.len(),
        plane_rms_m: plane_rms,
        edge_candidates: candidates.len(),
        edge_points: std::array::from_fn(|j| edges[j].points.len()),
        edge_rms_m: std::array::from_fn(|j| edges[j].rms_m),
        side_lengths_m: quality_geometry.0,
        corner_angles_deg: quality_geometry.1,
    };
    if quality
        .corner_angles_deg
        .iter()
        .any(|a| (a - 90.0).abs() > params.max_corner_error_deg)
    {
        return Err(LidarReject::NotRectangle {
            angles: quality.corner_angles_deg,
        });
    }
    Ok(LidarBoardFeatures {
        plane_points,
        normal,
        offset,
        edges,
        quality,
    })
}

/// Edge points: per ring, the outermost board returns whose outward neighbour is much
/// farther (or missing), moved to the midpoint described in the module docs.
fn edge_points(
    cloud: &PointCloud,
    on_board: &std::collections::HashSet<usize>,
    normal: &Vector3<f64>,
    offset: f64,
    params: &LidarFeatureParams,
    plane_rms: f64,
) -> Vec<Vector3<f64>> {
    // Ordered by ring, so that the line RANSAC sees the candidates in a fixed order.
    let mut rings: std::collections::BTreeMap<u16, Vec<(f64, usize)>> = Default::default();
    for (i, p) in cloud.points.iter().enumerate() {
        rings
            .entry(p.ring)
            .or_default()
            .push((p.xyz.y.atan2(p.xyz.x), i));
    }
    let mut out = Vec::new();
    for ring in rings.values_mut() {
        ring.sort_by(|a, b| a.0.total_cmp(&b.0));
        let steps: Vec<f64> = ring.windows(2).map(|w| w[1].0 - w[0].0).collect();
        let mut sorted = steps.clone();
        sorted.sort_by(f64::total_cmp);
        let step = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        let board: Vec<usize> = (0..ring.len())
            .filter(|&k| on_board.contains(&ring[k].1))
            .collect();
        let (Some(&first), Some(&last)) = (board.first(), board.last()) else {
            continue;
        };
        for (k, outward) in [(first, -1isize), (last, 1isize)] {
            let p = cloud.points[ring[k].1].xyz;
            // Planarity re-check of the edge return itself.
            if (normal.dot(&p) - offset).abs() > (3.0 * plane_rms).max(0.01) {
                continue;
            }
            let Some(inside) = on_plane(&p, normal, offset) else {
                continue;
            };
            let j = k as isize + outward;
            let neighbour = (j >= 0 && (j as usize) < ring.len())
                .then(|| ring[j as usize])
                .filter(|(az, _)| (az - ring[k].0).abs() < 1.5 * step);
            match neighbour {
                Some((_, n)) => {
                    let q = cloud.points[n].xyz;
                    if q.norm() < p.norm() + params.discontinuity_m {
                        continue; // occluded or not a depth edge
                    }
                    if let Some(outside) = on_plane(&q, normal, offset) {
                        out.push(0.5 * (inside + outside));
                    }
                }
                // No return next to it (sky, absorbing surface): the last return is all we have.
                None => out.push(inside),
            }
        }
    }
    out
}

/// Sequential RANSAC of four lines, refined by least squares, in cyclic order.
fn fit_edges(
    candidates: &[Vector3<f64>],
    normal: &Vector3<f64>,
    params: &LidarFeatureParams,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<LidarEdge>, LidarReject> {
    let mut remaining: Vec<Vector3<f64>> = candidates.to_vec();
    let mut edges = Vec::new();
    while edges.len() < 4 && remaining.len() >= params.min_edge_points {
        let mut best: Vec<usize> = Vec::new();
        for _ in 0..200 {
            let a = remaining[rng.gen_range(0..remaining.len())];
            let b = remaining[rng.gen_range(0..remaining.len())];
            let Some(dir) = (b - a).try_normalize(1e-6) else {
                continue;
            };
            let inliers: Vec<usize> = (0..remaining.len())
                .filter(|&i| line_distance(&remaining[i], &a, &dir) < params.line_threshold_m)
                .collect();
            if inliers.len() > best.len() {
                best = inliers;
            }
        }
        if best.len() < params.min_edge_points {
            break;
        }
        let pts: Vec<Vector3<f64>> = best.iter().map(|&i| remaining[i]).collect();
        let Some((c, dir, _)) = fit_line(&pts) else {
            break;
        };
        // Re-collect with the refined line, then refit.
        let (inl, rest): (Vec<Vector3<f64>>, Vec<Vector3<f64>>) = remaining
            .iter()
            .partition(|p| line_distance(p, &c, &dir) < params.line_threshold_m);
        if inl.len() < params.min_edge_points {
            break;
        }
        let Some((centroid, direction, rms_m)) = fit_line(&inl) else {
            break;
        };
        edges.push(LidarEdge {
            points: inl,
            centroid,
            direction,
            rms_m,
        });
        remaining = rest;
    }
    if edges.len() < 4 {
        return Err(LidarReject::MissingEdges {
            found: edges.len(),
            min: params.min_edge_points,
        });
    }
    // Cyclic order: by the angle of each line's centroid around the board centre.
    let centre = edges.iter().map(|e| e.centroid).sum::<Vector3<f64>>() / 4.0;
    let u = edges[0].direction;
    let v = normal.cross(&u);
    edges.sort_by(|a, b| {
        let ang = |e: &LidarEdge| {
            let d = e.centroid - centre;
            v.dot(&d).atan2(u.dot(&d))
        };
        ang(a).total_cmp(&ang(b))
    });
    Ok(edges)
}

/// Side lengths and corner angles of the quadrilateral of four cyclic lines (in-plane).
fn quadrilateral(edges: &[LidarEdge], normal: &Vector3<f64>) -> ([f64; 4], [f64; 4]) {
    let u = edges[0].direction;
    let v = normal.cross(&u);
    let to2 = |p: &Vector3<f64>| Vector2::new(u.dot(p), v.dot(p));
    let corner = |a: &LidarEdge, b: &LidarEdge| -> Vector2<f64> {
        let (p, d) = (to2(&a.centroid), to2(&a.direction));
        let (q, e) = (to2(&b.centroid), to2(&b.direction));
        let det = d.x * (-e.y) - d.y * (-e.x);
        if det.abs() < 1e-12 {
            return p;
        }
        let r = q - p;
        let s = (r.x * (-e.y) - r.y * (-e.x)) / det;
        p + d * s
    };
    let corners: [Vector2<f64>; 4] =
        std::array::from_fn(|j| corner(&edges[j], &edges[(j + 1) % 4]));
    let sides = std::array::from_fn(|j| (corners[(j + 1) % 4] - corners[j]).norm());
    // Angle between adjacent lines, 0-90 deg (90 for a rectangle).
    let angles = std::array::from_fn(|j| {
        let d = edges[j].direction.dot(&edges[(j + 1) % 4].direction);
        d.abs().min(1.0).acos().to_degrees()
    });
    (sides, angles)
}
