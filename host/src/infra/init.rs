//! Per-camera registration: marker PnP per detection, camera initialisation (eq. 6.10 with
//! Markley quaternion averaging), then a per-camera refinement of `T_vo_C` over the marker
//! corners (reprojection through the interpolated, scaled VO pose and `T_F_M`) and the blobs
//! the camera makes in the `F` keyframes (nearest neighbour, gated), Cauchy loss.
//!
//! Perturbation of `T_vo_C`: right on the rotation, additive on the position
//! ([`Pose::boxplus`]); with `p_C = R^T (P - t)`: `d p_C / d theta = [p_C]x`,
//! `d p_C / d t = -R^T`. A blob of camera C in keyframe F: `p_F = R_F^T (t - t_F)`,
//! `d p_F / d t = R_F^T`.

use msreg_estimator::camera::Camera;
use msreg_estimator::lie::skew;
use msreg_estimator::Pose;
use nalgebra::{
    Isometry3, Matrix3, Matrix4, Point3, RowVector6, Translation3, UnitQuaternion, Vector2, Vector3,
};

use super::io::{Blob, MarkerDetection, MarkerSpec};
use crate::solve::{solve_se3, LmOptions, Loss, Residual, Se3Problem};
use crate::vision::pnp::solve_pnp;

/// Largest per-detection PnP RMS accepted, px (larger: an outlier corner).
pub const PNP_GATE_PX: f64 = 1.5;
/// Blob association gate, px.
pub const BLOB_GATE_PX: f64 = 8.0;
/// Nominal corner noise used as weight, px.
pub const CORNER_SIGMA_PX: f64 = 0.5;
/// Nominal blob noise used as weight, px.
pub const BLOB_SIGMA_PX: f64 = 1.0;

/// A detection with its PnP pose.
#[derive(Clone, Copy, Debug)]
pub struct MarkerPose {
    /// The detection.
    pub detection: MarkerDetection,
    /// `T_C_M`.
    pub t_c_m: Isometry3<f64>,
}

fn iso(p: &Pose<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::from(p.translation), p.rotation)
}

fn pose(i: &Isometry3<f64>) -> Pose<f64> {
    Pose::new(i.rotation, i.translation.vector)
}

/// PnP of every detection; those with an RMS above [`PNP_GATE_PX`] are dropped.
pub fn marker_poses(
    camera: &Camera<f64>,
    marker: &MarkerSpec,
    detections: &[MarkerDetection],
) -> Vec<MarkerPose> {
    let corners = marker.corners_in_marker();
    detections
        .iter()
        .filter_map(|d| {
            let sol = solve_pnp(camera, &corners, &d.corners).ok()?;
            (sol.rms_px < PNP_GATE_PX).then(|| MarkerPose {
                detection: *d,
                t_c_m: iso(&sol.t_cam_target),
            })
        })
        .collect()
}

/// Markley's quaternion average (eigenvector of the largest eigenvalue of sum q q^T).
pub fn average_rotation(qs: &[UnitQuaternion<f64>]) -> Option<UnitQuaternion<f64>> {
    let mut m = Matrix4::zeros();
    for q in qs {
        let v = q.coords;
        m += v * v.transpose();
    }
    let eig = m.symmetric_eigen();
    let (k, _) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    let v = eig.eigenvectors.column(k);
    Some(UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        v[3], v[0], v[1], v[2],
    )))
}

/// Average pose: centroid of positions, Markley average of rotations.
pub fn average_pose(poses: &[Isometry3<f64>]) -> Option<Isometry3<f64>> {
    let qs: Vec<UnitQuaternion<f64>> = poses.iter().map(|p| p.rotation).collect();
    let q = average_rotation(&qs)?;
    let t = poses
        .iter()
        .map(|p| p.translation.vector)
        .sum::<Vector3<f64>>()
        / poses.len().max(1) as f64;
    Some(Isometry3::from_parts(Translation3::from(t), q))
}

/// One marker observation for the refinement: the marker pose in vo at the detection.
#[derive(Clone, Copy, Debug)]
pub struct CornerObs {
    /// `T_vo_M` = interpolated `T_vo_F(t)` times `T_F_M`.
    pub t_vo_m: Isometry3<f64>,
    /// The detection.
    pub detection: MarkerDetection,
}

/// One associated blob: keyframe pose and pixel.
#[derive(Clone, Copy, Debug)]
pub struct BlobObs {
    /// `T_vo_F` of the keyframe.
    pub t_vo_f: Isometry3<f64>,
    /// Pixel.
    pub uv: Vector2<f64>,
}

/// The per-camera refinement problem over `T_vo_C`.
pub struct CameraProblem<'a> {
    /// The infrastructure camera.
    pub camera: &'a Camera<f64>,
    /// The robot's fisheye.
    pub f_camera: &'a Camera<f64>,
    /// Marker corners in M.
    pub corners: [Vector3<f64>; 4],
    /// Marker observations.
    pub markers: Vec<CornerObs>,
    /// Associated blobs.
    pub blobs: Vec<BlobObs>,
}

fn push_pixel(
    out: &mut Vec<Residual>,
    meas: &Vector2<f64>,
    px: &Vector2<f64>,
    j: &nalgebra::Matrix2x6<f64>,
    sigma: f64,
) {
    let w = 1.0 / (sigma * sigma);
    for r in 0..2 {
        out.push(Residual {
            value: meas[r] - px[r],
            jacobian: -RowVector6::from_iterator(j.row(r).iter().copied()),
            weight: w,
        });
    }
}

impl Se3Problem for CameraProblem<'_> {
    fn residuals(&self, t_vo_c: &Pose<f64>, out: &mut Vec<Residual>) -> bool {
        let rt: Matrix3<f64> = t_vo_c.rotation.to_rotation_matrix().matrix().transpose();
        for m in &self.markers {
            for (c, uv) in self.corners.iter().zip(&m.detection.corners) {
                let p_vo = (m.t_vo_m * Point3::from(*c)).coords;
                let p_c = rt * (p_vo - t_vo_c.translation);
                let Some(proj) = self.camera.project(&p_c) else {
                    return false;
                };
                let mut dp = nalgebra::Matrix3x6::zeros();
                dp.fixed_view_mut::<3, 3>(0, 0).copy_from(&skew(&p_c));
                dp.fixed_view_mut::<3, 3>(0, 3).copy_from(&(-rt));
                push_pixel(out, uv, &proj.pixel, &(proj.jacobian * dp), CORNER_SIGMA_PX);
            }
        }
        for b in &self.blobs {
            let rf = b.t_vo_f.rotation.to_rotation_matrix().matrix().transpose();
            let p_f = rf * (t_vo_c.translation - b.t_vo_f.translation.vector);
            let Some(proj) = self.f_camera.project(&p_f) else {
                continue;
            };
            let mut dp = nalgebra::Matrix3x6::zeros();
            dp.fixed_view_mut::<3, 3>(0, 3).copy_from(&rf);
            push_pixel(
                out,
                &b.uv,
                &proj.pixel,
                &(proj.jacobian * dp),
                BLOB_SIGMA_PX,
            );
        }
        true
    }
}

/// Nearest blob of each keyframe within [`BLOB_GATE_PX`] of the camera centre's projection.
pub fn associate_blobs(
    f_camera: &Camera<f64>,
    centre_vo: &Vector3<f64>,
    keyframes: &[(u64, Isometry3<f64>)],
    blobs: &[Blob],
) -> Vec<BlobObs> {
    let mut out = Vec::new();
    for (stamp, t_vo_f) in keyframes {
        let p_f = t_vo_f
            .inverse_transform_point(&Point3::from(*centre_vo))
            .coords;
        let Some(pred) = f_camera.project(&p_f) else {
            continue;
        };
        let lo = blobs.partition_point(|b| b.stamp_ns < *stamp);
        let best = blobs[lo..]
            .iter()
            .take_while(|b| b.stamp_ns == *stamp)
            .map(|b| ((b.uv - pred.pixel).norm(), b.uv))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        if let Some((d, uv)) = best {
            if d < BLOB_GATE_PX {
                out.push(BlobObs {
                    t_vo_f: *t_vo_f,
                    uv,
                });
            }
        }
    }
    out
}

/// Refines `T_vo_C` from `start`; returns the pose and its 6x6 covariance.
pub fn refine(
    problem: &CameraProblem<'_>,
    start: &Isometry3<f64>,
) -> Option<(Isometry3<f64>, nalgebra::Matrix6<f64>)> {
    let options = LmOptions {
        loss: Loss::Cauchy(3.0),
        max_iterations: 100,
        ..LmOptions::default()
    };
    let s = solve_se3(problem, pose(start), &options).ok()?;
    Some((iso(&s.pose), s.covariance))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::infra::scene::{look_at, robot_fisheye};

    #[test]
    fn refinement_jacobians_match_finite_differences() {
        let f = robot_fisheye();
        let cam = f;
        let spec = MarkerSpec {
            dictionary: "DICT_4X4_50".into(),
            id: 7,
            side_m: 0.5,
        };
        let t_vo_c = look_at(
            &Vector3::new(2.0, 1.0, 3.0),
            &Vector3::new(0.0, 0.0, 0.5),
            0.2,
        );
        let det = MarkerDetection {
            stamp_ns: 0,
            marker_id: 7,
            corners: [Vector2::new(500.0, 500.0); 4],
        };
        let t_vo_m = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.55),
            UnitQuaternion::from_euler_angles(0.02, 0.01, 0.7),
        );
        let t_vo_f = Isometry3::from_parts(
            Translation3::new(-1.0, 0.5, 0.5),
            UnitQuaternion::from_euler_angles(0.01, -0.02, 0.3),
        );
        let problem = CameraProblem {
            camera: &cam,
            f_camera: &f,
            corners: spec.corners_in_marker(),
            markers: vec![CornerObs {
                t_vo_m,
                detection: det,
            }],
            blobs: vec![BlobObs {
                t_vo_f,
                uv: Vector2::new(400.0, 600.0),
            }],
        };
        let p0 = pose(&t_vo_c);
        let mut r0 = Vec::new();
        assert!(problem.residuals(&p0, &mut r0));
        assert_eq!(r0.len(), 10);
        let h = 1e-6;
        for k in 0..6 {
            let mut d = [Vector3::zeros(), Vector3::zeros()];
            d[k / 3][k % 3] = h;
            let (mut rp, mut rm) = (Vec::new(), Vec::new());
            problem.residuals(&p0.boxplus(&d[0], &d[1]), &mut rp);
            problem.residuals(&p0.boxplus(&-d[0], &-d[1]), &mut rm);
            for i in 0..r0.len() {
                let num = (rp[i].value - rm[i].value) / (2.0 * h);
                let ana = r0[i].jacobian[k];
                assert!(
                    (num - ana).abs() < 1e-4 * (1.0 + num.abs()),
                    "residual {i} col {k}: {num} vs {ana}"
                );
            }
        }
    }

    #[test]
    fn markley_average_of_symmetric_spread_is_the_centre() {
        let c = UnitQuaternion::from_euler_angles(0.3, -0.1, 2.0);
        let qs: Vec<UnitQuaternion<f64>> = [0.1, -0.1]
            .iter()
            .flat_map(|&a| {
                [Vector3::x(), Vector3::y(), Vector3::z()]
                    .map(|v| c * UnitQuaternion::from_scaled_axis(v * a))
            })
            .map(|q| {
                if q.w < 0.0 {
                    UnitQuaternion::new_unchecked(-q.into_inner())
                } else {
                    q
                }
            })
            .collect();
        let avg = average_rotation(&qs).expect("average");
        assert!(avg.angle_to(&c) < 1e-9);
    }
}
