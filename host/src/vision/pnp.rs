//! Target pose from corner pixels (PnP for a planar target): a linear start from the
//! homography between the target plane and the unprojected bearings (DLT with
//! `b x (H X) = 0`, valid for any bearing, also beyond 90 degrees off axis), then the
//! SE(3) Levenberg-Marquardt of [`crate::solve`] minimising the reprojection error through
//! the camera model ([`Camera::project`] and its Jacobian). Perturbation: right on the rotation, additive on
//! the translation ([`Pose::boxplus`]); the covariance is `sigma^2 (J^T J)^-1` in that
//! order `[d_theta, d_p]`, `sigma^2` the residual variance (`SSR / (2N - 6)`).

use msreg_estimator::camera::Camera;
use msreg_estimator::lie::skew;
use msreg_estimator::Pose;
use nalgebra::{
    DMatrix, Matrix2x3, Matrix3, Matrix6, Rotation3, RowVector6, UnitQuaternion, Vector2, Vector3,
};

use crate::solve::{solve_se3, LmError, LmOptions, Residual, Se3Problem};

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

/// Refines `start` (`T_cam_target`) by the reprojection Levenberg-Marquardt on any 3-D
/// target points (not only planar ones), as the last step of [`solve_pnp`].
pub fn refine_pnp(
    camera: &Camera<f64>,
    points_in_target: &[Vector3<f64>],
    pixels: &[Vector2<f64>],
    start: Pose<f64>,
) -> Result<PnpSolution, PnpError> {
    if points_in_target.len() != pixels.len() || pixels.len() < 4 {
        return Err(PnpError::TooFewPoints {
            points: points_in_target.len(),
            pixels: pixels.len(),
        });
    }
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

/// Reprojection residuals (`projected - observed`, one scalar per pixel coordinate) for the
/// SE(3) Levenberg-Marquardt of [`crate::solve`]; a pose that cannot project every point is
/// invalid.
struct Reprojection<'a> {
    camera: &'a Camera<f64>,
    points: &'a [Vector3<f64>],
    pixels: &'a [Vector2<f64>],
}

impl Se3Problem for Reprojection<'_> {
    fn residuals(&self, pose: &Pose<f64>, out: &mut Vec<Residual>) -> bool {
        let rot = pose.rotation.to_rotation_matrix().into_inner();
        for (p, px) in self.points.iter().zip(self.pixels) {
            let Some(proj) = self.camera.project(&pose.transform_point(p)) else {
                return false;
            };
            // d p_cam / d theta = -R [p]x (right perturbation), d p_cam / d p = I.
            let j_rot: Matrix2x3<f64> = proj.jacobian * (-rot * skew(p));
            let r = proj.pixel - px;
            for k in 0..2 {
                let mut jacobian = RowVector6::zeros();
                jacobian
                    .fixed_view_mut::<1, 3>(0, 0)
                    .copy_from(&j_rot.row(k));
                jacobian
                    .fixed_view_mut::<1, 3>(0, 3)
                    .copy_from(&proj.jacobian.row(k));
                out.push(Residual {
                    value: r[k],
                    jacobian,
                    weight: 1.0,
                });
            }
        }
        true
    }
}

fn refine(
    camera: &Camera<f64>,
    points: &[Vector3<f64>],
    pixels: &[Vector2<f64>],
    start: Pose<f64>,
) -> Result<PnpSolution, PnpError> {
    let problem = Reprojection {
        camera,
        points,
        pixels,
    };
    let options = LmOptions {
        max_iterations: 100,
        initial_lambda: 1e-3,
        ..LmOptions::default()
    };
    let sol = solve_se3(&problem, start, &options).map_err(|e| match e {
        LmError::Degenerate => PnpError::Degenerate,
        _ => PnpError::NotConverged,
    })?;
    if !sol.pose.is_finite() {
        return Err(PnpError::NotConverged);
    }
    // The solver's covariance is sigma^2 (J^T J)^-1 with sigma^2 = SSR / (2N - 6).
    Ok(PnpSolution {
        t_cam_target: sol.pose,
        covariance: sol.covariance,
        rms_px: (sol.final_cost / points.len() as f64).sqrt(),
        iterations: sol.iterations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_estimator::camera::{equidistant::Equidistant, Distortion, Intrinsics, Projection};
    use nalgebra::Vector6;

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
    fn reprojection_jacobians_match_finite_differences() {
        let k = Intrinsics {
            fu: 500.0,
            fv: 480.0,
            cu: 320.0,
            cv: 240.0,
        };
        let d = Distortion::Equidistant(Equidistant {
            k1: -0.03,
            k2: -0.02,
            k3: 0.002,
            k4: 0.001,
        });
        let cam = Camera::new(Projection::Pinhole, k, d, (640, 480)).unwrap();
        let pose = Pose::new(
            UnitQuaternion::from_euler_angles(2.9, 0.2, -0.3),
            Vector3::new(-0.1, 0.05, 0.5),
        );
        let pts = grid();
        let px = vec![Vector2::new(300.0, 200.0); pts.len()];
        let problem = Reprojection {
            camera: &cam,
            points: &pts,
            pixels: &px,
        };
        let mut base = Vec::new();
        assert!(problem.residuals(&pose, &mut base));
        let h = 1e-6;
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let step = |d: Vector6<f64>| {
                pose.boxplus(
                    &d.fixed_rows::<3>(0).into_owned(),
                    &d.fixed_rows::<3>(3).into_owned(),
                )
            };
            let (mut a, mut b) = (Vec::new(), Vec::new());
            assert!(problem.residuals(&step(d), &mut a));
            assert!(problem.residuals(&step(-d), &mut b));
            for i in 0..base.len() {
                let numeric = (a[i].value - b[i].value) / (2.0 * h);
                let scale = base[i].jacobian[k].abs().max(1.0);
                assert!((numeric - base[i].jacobian[k]).abs() < 1e-5 * scale);
            }
        }
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
