//! PnP poses of the images as odometry (MoCal, the start of RepErrCal): the camera in the target,
//! increments with their noise, the pixel sigma from the PnP residuals.

use super::*;
use crate::calibrate::convert;
use crate::dataset::{PoseRecord, PoseSensorYaml};
use crate::vision::pnp::{solve_pnp, PnpSolution};
use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Matrix6, Vector2, Vector3};

/// `T^-1` and the covariance of its right-perturbation error, given those of `T`:
/// `(R Exp(d))^T = R^T Exp(-R d)` and `-(R Exp(d))^T (p + dp) = p' - R^T dp - [R^T p]x d`.
pub fn invert_with_covariance(
    t: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
) -> (Isometry3<f64>, Matrix6<f64>) {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let rt_p = r.transpose() * t.translation.vector;
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-r));
    j.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(-msreg_estimator::lie::skew(&rt_p)));
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-r.transpose()));
    (t.inverse(), j * covariance * j.transpose())
}

/// A PnP pose of one image.
pub(crate) struct FramePose {
    pub(crate) stamp_ns: u64,
    /// Corners the PnP used.
    pub(crate) points: usize,
    pub(crate) pnp: PnpSolution,
}

/// PnP pose of the target in one image.
pub fn pnp_of(camera: &Camera<f64>, frame: &CornerFrame) -> Result<PnpSolution, String> {
    let points: Vec<Vector3<f64>> = frame.corners.iter().map(|c| c.point_in_target).collect();
    let pixels: Vec<Vector2<f64>> = frame.corners.iter().map(|c| c.pixel).collect();
    solve_pnp(camera, &points, &pixels).map_err(|e| e.to_string())
}

/// PnP of every image with enough corners.
pub(crate) fn frame_poses(camera: &Camera<f64>, frames: &[CornerFrame]) -> Vec<FramePose> {
    use rayon::prelude::*;
    frames
        .par_iter()
        .filter(|f| f.corners.len() >= MIN_CORNERS)
        .filter_map(|f| {
            pnp_of(camera, f).ok().map(|pnp| FramePose {
                stamp_ns: f.stamp_ns,
                points: f.corners.len(),
                pnp,
            })
        })
        .collect()
}

/// The camera's pose in the target frame as odometry (`T_T_C`, origin = target).
pub(crate) fn camera_in_target(pose: &FramePose) -> PoseRecord {
    let t_t_c = convert::isometry(&pose.pnp.t_cam_target).inverse();
    PoseRecord {
        stamp_ns: pose.stamp_ns,
        position: t_t_c.translation.vector,
        rotation: t_t_c.rotation,
    }
}

/// Per-axis corner noise from the PnP fits: the median RMS residual, per axis, corrected
/// for the 6 DoF the fit absorbs.
pub(crate) fn pixel_sigma_from_pnp(poses: &[FramePose]) -> f64 {
    let mut per_axis: Vec<f64> = poses.iter().filter_map(frame_pixel_sigma).collect();
    per_axis.sort_by(f64::total_cmp);
    per_axis
        .get(per_axis.len() / 2)
        .copied()
        .unwrap_or(MIN_PIXEL_SIGMA)
        .max(MIN_PIXEL_SIGMA)
}

/// One image's per-axis corner noise from its PnP fit: the RMS residual corrected for the
/// 6 DoF the fit absorbs; `None` with too few corners to say.
pub(crate) fn frame_pixel_sigma(pose: &FramePose) -> Option<f64> {
    let n = pose.points as f64;
    (pose.points > 3).then(|| pose.pnp.rms_px / 2f64.sqrt() * (2.0 * n / (2.0 * n - 6.0)).sqrt())
}

/// MoCal's odometry noise per increment: two independent PnP poses, each with the median
/// of the frames' largest per-axis sigma of `T_T_C`. Each PnP covariance is
/// `own^2 (J^T J)^-1` with the frame's own residual sigma; it is rescaled to
/// `max(floor, own)`, `floor` the smallest corner noise any image is credited with. Without
/// that, exact corners (the simulator's truth, `own` ~ 1e-3 px) made MoCal's odometry noise
/// ~50x too small: MoCal then locked onto its first IMU-noise-biased estimate and RepErrCal's
/// prior around it held the result 0.10 deg / 1.2 mm off, four times outside its 3 sigma
/// (seed 11, AprilGrid; docs/aprilgrid.md). A floor at the recording's median instead
/// widened the sharper half of EuRoC's images and took MoCal from 33 to 58 mm off Kalibr
/// (docs/camera_imu.md).
pub(crate) fn increment_noise(poses: &[FramePose], floor: f64) -> PoseSensorYaml {
    let mut rotation = Vec::with_capacity(poses.len());
    let mut translation = Vec::with_capacity(poses.len());
    for p in poses {
        let Some(own) = frame_pixel_sigma(p).filter(|s| *s > 0.0) else {
            continue;
        };
        let scale = (floor.max(own) / own).powi(2);
        let t_c_t = convert::isometry(&p.pnp.t_cam_target);
        let (_, cov) = invert_with_covariance(&t_c_t, &(p.pnp.covariance * scale));
        let max_sd = |b: usize| {
            (0..3)
                .map(|i| cov[(b + i, b + i)].max(0.0).sqrt())
                .fold(0.0, f64::max)
        };
        rotation.push(max_sd(0));
        translation.push(max_sd(3));
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    PoseSensorYaml {
        rotation_noise_rad: median(&mut rotation) * 2f64.sqrt(),
        translation_noise_m: median(&mut translation) * 2f64.sqrt(),
        rate_hz: None,
    }
}
