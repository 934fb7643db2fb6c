//! The two cost functions of chapter 2 on [`crate::solve::solve_se3`], the closed-form
//! start they are run from, and the association of LiDAR edges with image edges.
//!
//! - PPC-Cal (eq. 2.4-2.5): `n_i . (R P_im + t) - d_i` for every LiDAR board point and the
//!   camera's board plane, each frame weighted by `1 / p_i` (scaled by the mean count so
//!   that the residuals stay whitened by `sigma_plane`).
//! - PBPC-Cal (eq. 2.6-2.7): `n_ij . (R Q_ijn + t)` for every LiDAR edge point and the
//!   back-projected plane of its image edge, weighted by `1 / q_ij`; started from PPC.
//! - Start ([`plane_alignment`]): rotation aligning the LiDAR board normals with the
//!   camera's (Kabsch), translation from the plane offsets by linear least squares.
//! - Edges ([`associate_edges`]): per frame, the permutation of the four LiDAR edges onto
//!   the four image edges with the smallest mean angle of the points from the planes.

use msreg_estimator::Pose;
use nalgebra::{Matrix3, RowVector6, UnitQuaternion, Vector3};

use crate::solve::{Residual, Se3Problem};

/// The board plane seen by both sensors in one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneObservation {
    /// LiDAR board points `P_im`.
    pub points_lidar: Vec<Vector3<f64>>,
    /// Camera board normal `n_i` (unit).
    pub normal_cam: Vector3<f64>,
    /// Camera board offset `d_i` (`n_i . X = d_i`).
    pub offset_cam: f64,
}

/// One board edge seen by both sensors.
#[derive(Clone, Debug, PartialEq)]
pub struct EdgeObservation {
    /// LiDAR edge points `Q_ijn`.
    pub points_lidar: Vec<Vector3<f64>>,
    /// Unit normal of the image edge's back-projected plane `n_ij`.
    pub normal_cam: Vector3<f64>,
}

/// Residuals `n . (R p + t) - d` of points on one plane `(n, d)`, with
/// `d r / d theta = -(n^T R [p]x) = -(a x p)^T` for `a = R^T n` (computed once per plane)
/// and `d r / d t = n^T`.
fn plane_residuals(
    pose: &Pose<f64>,
    n: &Vector3<f64>,
    d: f64,
    points: &[Vector3<f64>],
    weight: f64,
    out: &mut Vec<Residual>,
) {
    let a = pose.rotation.inverse() * n;
    let c = n.dot(&pose.translation) - d;
    out.extend(points.iter().map(|p| {
        let j_rot = -a.cross(p);
        Residual {
            value: a.dot(p) + c,
            jacobian: RowVector6::new(j_rot.x, j_rot.y, j_rot.z, n.x, n.y, n.z),
            weight,
        }
    }));
}

/// PPC-Cal's cost (eq. 2.4) over `T_cam_lidar`.
pub struct PointToPlane<'a> {
    /// The frames.
    pub planes: &'a [PlaneObservation],
    /// Assumed 1-sigma of a board point's distance from the plane, m.
    pub sigma_m: f64,
}

impl Se3Problem for PointToPlane<'_> {
    fn residuals(&self, pose: &Pose<f64>, out: &mut Vec<Residual>) -> bool {
        let total: usize = self.planes.iter().map(|p| p.points_lidar.len()).sum();
        let mean = total as f64 / self.planes.len().max(1) as f64;
        for plane in self.planes {
            let w = mean / plane.points_lidar.len().max(1) as f64 / (self.sigma_m * self.sigma_m);
            plane_residuals(
                pose,
                &plane.normal_cam,
                plane.offset_cam,
                &plane.points_lidar,
                w,
                out,
            );
        }
        true
    }
}

/// PBPC-Cal's cost (eq. 2.6) over `T_cam_lidar`.
pub struct PointToBackProjectedPlane<'a> {
    /// Every associated edge of every frame.
    pub edges: &'a [EdgeObservation],
    /// Assumed 1-sigma of an edge point's distance from its back-projected plane, m.
    pub sigma_m: f64,
}

impl Se3Problem for PointToBackProjectedPlane<'_> {
    fn residuals(&self, pose: &Pose<f64>, out: &mut Vec<Residual>) -> bool {
        let total: usize = self.edges.iter().map(|e| e.points_lidar.len()).sum();
        let mean = total as f64 / self.edges.len().max(1) as f64;
        for edge in self.edges {
            let w = mean / edge.points_lidar.len().max(1) as f64 / (self.sigma_m * self.sigma_m);
            plane_residuals(pose, &edge.normal_cam, 0.0, &edge.points_lidar, w, out);
        }
        true
    }
}

/// Closed-form `T_cam_lidar` from the board planes (see the module docs); `None` when the
/// normals do not span 3D (fewer than three non-parallel boards).
pub fn plane_alignment(planes: &[PlaneObservation]) -> Option<Pose<f64>> {
    let mut pairs = Vec::new();
    for plane in planes {
        let n = plane.points_lidar.len();
        if n < 3 {
            continue;
        }
        let centroid = plane.points_lidar.iter().sum::<Vector3<f64>>() / n as f64;
        let (mut normal, _, _) = super::lidar_features::fit_plane(&plane.points_lidar)?;
        // Both normals point to the sensors' side of the board.
        if normal.dot(&centroid) > 0.0 {
            normal = -normal;
        }
        pairs.push((normal, centroid, plane));
    }
    if pairs.len() < 3 {
        return None;
    }
    let mut h = Matrix3::zeros();
    for (n_l, _, plane) in &pairs {
        h += plane.normal_cam * n_l.transpose();
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let rot = u * d * v_t;
    let mut a = Matrix3::zeros();
    let mut b = Vector3::zeros();
    for (_, c, plane) in &pairs {
        let n = plane.normal_cam;
        a += n * n.transpose();
        b += n * (plane.offset_cam - n.dot(&(rot * c)));
    }
    let t = a.try_inverse()? * b;
    let q = UnitQuaternion::from_matrix(&rot);
    Some(Pose::new(q, t))
}

/// Mean angle (rad) of points, mapped into the camera, from a back-projected plane.
fn mean_angle(t_cam_lidar: &Pose<f64>, normal: &Vector3<f64>, points: &[Vector3<f64>]) -> f64 {
    let sum: f64 = points
        .iter()
        .map(|p| {
            let x = t_cam_lidar.transform_point(p);
            (normal.dot(&x) / x.norm().max(1e-9)).abs()
        })
        .sum();
    sum / points.len().max(1) as f64
}

/// For each LiDAR edge `j`, the image edge `perm[j]` (see the module docs).
pub fn associate_edges(
    t_cam_lidar: &Pose<f64>,
    lidar_edges: &[Vec<Vector3<f64>>],
    image_normals: &[Vector3<f64>],
) -> Option<[usize; 4]> {
    if lidar_edges.len() != 4 || image_normals.len() != 4 {
        return None;
    }
    let cost: Vec<Vec<f64>> = lidar_edges
        .iter()
        .map(|pts| {
            image_normals
                .iter()
                .map(|n| mean_angle(t_cam_lidar, n, pts))
                .collect()
        })
        .collect();
    let mut best: Option<(f64, [usize; 4])> = None;
    for a in 0..4 {
        for b in 0..4 {
            for c in 0..4 {
                let d = 6 - a - b - c;
                let perm = [a, b, c, d];
                if a == b || a == c || b == c || d > 3 || [a, b, c].contains(&d) {
                    continue;
                }
                let total: f64 = (0..4).map(|j| cost[j][perm[j]]).sum();
                if best.is_none_or(|(t, _)| total < t) {
                    best = Some((total, perm));
                }
            }
        }
    }
    best.map(|(_, p)| p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::solve::{solve_se3, LmOptions};
    use nalgebra::Vector6;

    fn truth() -> Pose<f64> {
        Pose::new(
            UnitQuaternion::from_euler_angles(-1.6, 0.05, -1.55),
            Vector3::new(0.1, -0.08, -0.12),
        )
    }

    /// Boards in the camera frame with points mapped back to the LiDAR frame.
    fn planes() -> Vec<PlaneObservation> {
        let t = truth();
        (0..6)
            .map(|k| {
                let k = k as f64;
                let normal =
                    Vector3::new(0.3 * (k - 2.5).sin(), 0.2 * (k * 1.3).cos(), -1.0).normalize();
                let centre = Vector3::new(0.4 * (k - 2.5), 0.1 * k - 0.3, 2.0 + 0.5 * k);
                let u = normal.cross(&Vector3::x()).normalize();
                let v = normal.cross(&u);
                let points_lidar = (0..50)
                    .map(|m| {
                        let (a, b) = ((m % 7) as f64 / 7.0 - 0.5, (m / 7) as f64 / 7.0 - 0.5);
                        t.inverse().transform_point(&(centre + u * a + v * b))
                    })
                    .collect();
                PlaneObservation {
                    points_lidar,
                    normal_cam: normal,
                    offset_cam: normal.dot(&centre),
                }
            })
            .collect()
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let planes = planes();
        let edges: Vec<EdgeObservation> = planes
            .iter()
            .map(|p| EdgeObservation {
                points_lidar: p.points_lidar[..10].to_vec(),
                normal_cam: Vector3::new(0.3, -0.9, 0.1).normalize(),
            })
            .collect();
        let pose = Pose::new(
            UnitQuaternion::from_euler_angles(0.3, 0.2, -0.4),
            Vector3::new(0.3, 0.1, -0.2),
        );
        let ppc = PointToPlane {
            planes: &planes,
            sigma_m: 0.02,
        };
        let pbpc = PointToBackProjectedPlane {
            edges: &edges,
            sigma_m: 0.01,
        };
        for problem in [&ppc as &dyn Se3Problem, &pbpc] {
            let mut base = Vec::new();
            problem.residuals(&pose, &mut base);
            for k in 0..6 {
                let mut d = Vector6::zeros();
                d[k] = 1e-6;
                let step = |s: f64| {
                    let dd = d * s;
                    pose.boxplus(
                        &dd.fixed_rows::<3>(0).into_owned(),
                        &dd.fixed_rows::<3>(3).into_owned(),
                    )
                };
                let (mut a, mut b) = (Vec::new(), Vec::new());
                problem.residuals(&step(1.0), &mut a);
                problem.residuals(&step(-1.0), &mut b);
                for i in 0..base.len() {
                    let numeric = (a[i].value - b[i].value) / 2e-6;
                    assert!(
                        (numeric - base[i].jacobian[k]).abs() < 1e-6,
                        "{numeric} vs {}",
                        base[i].jacobian[k]
                    );
                }
            }
        }
    }

    #[test]
    fn plane_alignment_and_ppc_recover_the_truth_without_noise() {
        let planes = planes();
        let start = plane_alignment(&planes).unwrap();
        assert!(start.rotation.angle_to(&truth().rotation) < 1e-9);
        assert!((start.translation - truth().translation).norm() < 1e-9);
        let ppc = PointToPlane {
            planes: &planes,
            sigma_m: 0.02,
        };
        let sol = solve_se3(&ppc, Pose::identity(), &LmOptions::default()).unwrap();
        assert!(sol.pose.rotation.angle_to(&truth().rotation) < 1e-7);
        assert!((sol.pose.translation - truth().translation).norm() < 1e-7);
    }
}
