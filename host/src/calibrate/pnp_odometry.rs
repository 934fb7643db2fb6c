//! A camera looking at a calibration target as a pose sensor: each image's PnP pose of the
//! camera in the target frame becomes odometry, with MoCal's increment noise (the same
//! odometry `camera_imu::motion_calibration` hands the pose-IMU pipeline). For running the
//! pose-IMU pipeline, or a batch fit, on a real camera recording.

use msreg_estimator::camera::Camera;

use super::camera_imu::{camera_in_target, frame_poses, increment_noise, CornerFrame};
use crate::dataset::{PoseRecord, PoseSensorYaml};

/// Smallest corner noise any image is credited with, pixels: MoCal's floor
/// (`camera_imu`'s `MIN_PIXEL_SIGMA`), so this odometry is MoCal's.
const PIXEL_SIGMA_FLOOR: f64 = 0.05;

/// The camera's PnP poses in the target frame (`T_T_C`, one per image with enough corners
/// and a PnP solution, camera clock) and the noise of one increment.
pub fn pnp_odometry(
    camera: &Camera<f64>,
    frames: &[CornerFrame],
) -> (Vec<PoseRecord>, PoseSensorYaml) {
    let poses = frame_poses(camera, frames);
    let odometry = poses.iter().map(camera_in_target).collect();
    (odometry, increment_noise(&poses, PIXEL_SIGMA_FLOOR))
}
