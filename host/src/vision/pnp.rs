//! Target pose from corner pixels (PnP for a planar target): a linear start from the
//! homography between the target plane and the unprojected bearings (DLT with
//! `b x (H X) = 0`, valid for any bearing, also beyond 90 degrees off axis), then
//! Levenberg-Marquardt on SE(3) minimising the reprojection error through the camera model
//! ([`Camera::project`] and its Jacobian). Perturbation: right on the rotation, additive on
//! the translation ([`Pose::boxplus`]); the covariance is `sigma^2 (J^T J)^-1` in that
//! order `[d_theta, d_p]`, `sigma^2` the residual variance (`SSR / (2N - 6)`).

use msreg_estimator::camera::Camera;
use msreg_estimator::lie::skew;
use msreg_estimator::Pose;
use nalgebra::{
    DMatrix, Matrix2x3, Matrix3, Matrix6, Rotation3, SMatrix, UnitQuaternion, Vector2, Vector3,
    Vector6,
};

/// Why no pose was found.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PnpError {
    /// Fewer than 4 correspondences, or slices of different lengths.
    #[error("PnP needs at least 4 point/pixel pairs of equal count (got {points} and {pixels})")]
    TooFewPoints {
        /// Target points.
        points: usize,
        /// Pixels.
        pixels: usize,
    },
    /// The target points are not on the plane z = 0 of the target frame.
    #[error("the target points are not planar (z = 0)")]
    NotPlanar,
    /// A pixel cannot be unprojected by the camera model.
    #[error("pixel {index} cannot be unprojected")]
    Unprojectable {
        /// Index of the pixel.
        index: usize,
    },
    /// The linear solution is degenerate (collinear points).
    #[error("degenerate configuration (collinear points?)")]
    Degenerate,
    /// The refinement left the camera's valid region or diverged.
    #[error("the refinement failed")]
    NotConverged,
}

/// A target pose with its uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PnpSolution {
    /// Pose of the target in the camera frame.
    pub t_cam_target: Pose<f64>,
    /// Covariance of `[d_theta (right), d_p]`, rad and m.
    pub covariance: Matrix6<f64>,
    /// RMS reprojection error, pixels (per point, over both coordinates' squared sum).
    pub rms_px: f64,
    /// LM iterations used.
    pub iterations: usize,
}

/// Solves for `T_cam_target` from target points (z = 0) and their pixels.
pub fn solve_pnp(
    camera: &Camera<f64>,
    points_in_target: &[Vector3<f64>],
    pixels: &[Vector2<f64>],
) -> Result<PnpSolution, PnpError> {
    if points_in_target.len() != pixels.len() || pixels.len() < 4 {
        return Err(PnpError::TooFewPoints {
            points: points_in_target.len(),
            pixels: pixels.len(),
        });
    }
    let scale = points_in_target
        .iter()
        .map(|p| p.xy().norm())
        .fold(0.0, f64::max)
        .max(1e-9);
    if points_in_target
        .iter()
        .any(|p| p.z.abs() > 1e-9 * scale.max(1.0))
    {
        return Err(PnpError::NotPlanar);
    }
    let bearings = pixels
        .iter()
        .enumerate()
        .map(|(index, px)| {
            camera
                .unproject(px)
                .ok_or(PnpError::Unprojectable { index })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let start = homography_pose(points_in_target, &bearings)?;
    refine(camera, points_in_target, pixels, start)
}

/// The pose from the plane-to-bearing homography (Hartley-normalised target points).
fn homography_pose(
    points: &[Vector3<f64>],
    bearings: &[Vector3<f64>],
) -> Result<Pose<f64>, PnpError> {
    let n = points.len() as f64;
    let mean = points.iter().map(|p| p.xy()).sum::<Vector2<f64>>() / n;
    let spread = points.iter().map(|p| (p.xy() - mean).norm()).sum::<f64>() / n;
    if spread < 1e-12 {
        return Err(PnpError::Degenerate);
    }
    let s = std::f64::consts::SQRT_2 / spread;
    // X_n = N X, N = [s 0 -s mx; 0 s -s my; 0 0 1].
    let norm = Matrix3::new(s, 0.0, -s * mean.x, 0.0, s, -s * mean.y, 0.0, 0.0, 1.0);
    let mut a = DMatrix::<f64>::zeros(3 * points.len(), 9);
    for (i, (p, b)) in points.iter().zip(bearings).enumerate() {
        let x = norm * Vector3::new(p.x, p.y, 1.0);
        // b x (H x) = 0: rows of [b]_x (I kron x^T) h, h row-major.
        let bx = skew(b);
        for r in 0..3 {
            for k in 0..3 {
                for j in 0..3 {
                    a[(3 * i + r, 3 * k + j)] = bx[(r, k)] * x[j];
                }
            }
        }
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t.ok_or(PnpError::Degenerate)?;
    let (imin, _) = svd
        .singular_values
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))
        .ok_or(PnpError::Degenerate)?;
    let h = v_t.row(imin);
    let hn = Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], h[8]);
    let mut hm = hn * norm;
    // Sign: the points lie in front along their bearings.
    let front: f64 = points
        .iter()
        .zip(bearings)
        .map(|(p, b)| b.dot(&(hm * Vector3::new(p.x, p.y, 1.0))))
        .sum();
    if front < 0.0 {
        hm = -hm;
    }
    let (h1, h2, h3) = (hm.column(0), hm.column(1), hm.column(2));
    let lambda = 0.5 * (h1.norm() + h2.norm());
    if lambda < 1e-12 {
        return Err(PnpError::Degenerate);
    }
    let (r1, r2) = (h1 / lambda, h2 / lambda);
    let r = Matrix3::from_columns(&[r1.into_owned(), r2.into_owned(), r1.cross(&r2)]);
    let svd = r.svd(true, true);
    let (u, v_t) = (
        svd.u.ok_or(PnpError::Degenerate)?,
        svd.v_t.ok_or(PnpError::Degenerate)?,
    );
    let mut rot = u * v_t;
    if rot.determinant() < 0.0 {
        rot = -rot;
    }
    let q = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(rot));
    Ok(Pose::new(q, h3 / lambda))
}

type Jacobian = SMatrix<f64, 2, 6>;

/// Residuals (`projected - observed`) and their Jacobians; `None` when a point cannot be
/// projected.
fn linearise(
    camera: &Camera<f64>,
    points: &[Vector3<f64>],
    pixels: &[Vector2<f64>],
    pose: &Pose<f64>,
) -> Option<(Vec<Vector2<f64>>, Vec<Jacobian>)> {
    let rot = pose.rotation.to_rotation_matrix().into_inner();
    let mut res = Vec::with_capacity(points.len());
    let mut jac = Vec::with_capacity(points.len());
    for (p, px) in points.iter().zip(pixels) {
        let proj = camera.project(&pose.transform_point(p))?;
        // d p_cam / d theta = -R [p]_x (right perturbation), d p_cam / d p = I.
        let j_rot: Matrix2x3<f64> = proj.jacobian * (-rot * skew(p));
        let mut j = Jacobian::zeros();
        j.fixed_view_mut::<2, 3>(0, 0).copy_from(&j_rot);
        j.fixed_view_mut::<2, 3>(0, 3).copy_from(&proj.jacobian);
        res.push(proj.pixel - px);
        jac.push(j);
    }
    Some((res, jac))
}

fn cost(res: &[Vector2<f64>]) -> f64 {
    res.iter().map(|r| r.norm_squared()).sum()
}

fn refine(
    camera: &Camera<f64>,
    points: &[Vector3<f64>],
    pixels: &[Vector2<f64>],
    start: Pose<f64>,
) -> Result<PnpSolution, PnpError> {
    let mut pose = start;
    let (mut res, mut jac) =
        linearise(camera, points, pixels, &pose).ok_or(PnpError::NotConverged)?;
    let mut c = cost(&res);
    let mut mu = 1e-3;
    let mut iterations = 0;
    for it in 0..100 {
        iterations = it + 1;
        let mut jtj = Matrix6::<f64>::zeros();
        let mut jtr = Vector6::<f64>::zeros();
        for (r, j) in res.iter().zip(&jac) {
            jtj += j.transpose() * j;
            jtr += j.transpose() * r;
        }
        let mut improved = false;
        for _ in 0..10 {
            let mut damped = jtj;
            for k in 0..6 {
                damped[(k, k)] += mu * jtj[(k, k)].max(1e-12);
            }
            let Some(delta) = damped.cholesky().map(|ch| ch.solve(&(-jtr))) else {
                mu *= 10.0;
                continue;
            };
            let cand = pose.boxplus(
                &Vector3::new(delta[0], delta[1], delta[2]),
                &Vector3::new(delta[3], delta[4], delta[5]),
            );
            if let Some((r2, j2)) = linearise(camera, points, pixels, &cand) {
                let c2 = cost(&r2);
                if c2 < c {
                    let small = delta.norm() < 1e-12 || (c - c2) < 1e-14 * c.max(1e-30);
                    pose = cand;
                    res = r2;
                    jac = j2;
                    c = c2;
                    mu = (mu * 0.3).max(1e-12);
                    improved = !small;
                    break;
                }
            }
            mu *= 10.0;
        }
        if !improved {
            break;
        }
    }
    if !pose.is_finite() {
        return Err(PnpError::NotConverged);
    }
    let mut jtj = Matrix6::<f64>::zeros();
    for j in &jac {
        jtj += j.transpose() * j;
    }
    let dof = (2 * points.len()).saturating_sub(6).max(1) as f64;
    let sigma2 = c / dof;
    let covariance = jtj
        .try_inverse()
        .map(|inv| inv * sigma2)
        .ok_or(PnpError::Degenerate)?;
    Ok(PnpSolution {
        t_cam_target: pose,
        covariance,
        rms_px: (c / points.len() as f64).sqrt(),
        iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_estimator::camera::{equidistant::Equidistant, Distortion, Intrinsics, Projection};

    fn grid() -> Vec<Vector3<f64>> {
        (0..30)
            .map(|k| Vector3::new((k / 6) as f64 * 0.05, (k % 6) as f64 * 0.05, 0.0))
            .collect()
    }

    #[test]
    fn recovers_a_pose_seen_by_a_fisheye_exactly() {
        let k = Intrinsics {
            fu: 290.0,
            fv: 289.4,
            cu: 399.9,
            cv: 273.9,
        };
        let d = Distortion::Equidistant(Equidistant {
            k1: -0.03,
            k2: -0.02,
            k3: 0.002,
            k4: 0.001,
        });
        let cam = Camera::new(Projection::Pinhole, k, d, (800, 503)).unwrap();
        let truth = Pose::new(
            UnitQuaternion::from_euler_angles(2.8, 0.4, -0.3),
            Vector3::new(-0.2, 0.05, 0.35),
        );
        let pts = grid();
        let px: Vec<_> = pts
            .iter()
            .map(|p| cam.project(&truth.transform_point(p)).unwrap().pixel)
            .collect();
        let sol = solve_pnp(&cam, &pts, &px).unwrap();
        assert!((sol.t_cam_target.translation - truth.translation).norm() < 1e-8);
        assert!(sol.t_cam_target.rotation.angle_to(&truth.rotation) < 1e-8);
        assert!(sol.rms_px < 1e-6);
    }

    #[test]
    fn too_few_points_are_rejected() {
        let cam = Camera::new(
            Projection::Pinhole,
            Intrinsics {
                fu: 500.0,
                fv: 500.0,
                cu: 320.0,
                cv: 240.0,
            },
            Distortion::None,
            (640, 480),
        )
        .unwrap();
        let err = solve_pnp(&cam, &grid()[..3], &[Vector2::zeros(); 3]).unwrap_err();
        assert!(matches!(err, PnpError::TooFewPoints { .. }));
    }
}
