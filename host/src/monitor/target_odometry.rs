//! A camera looking at a calibration target as one of the monitor's pose sensors: each
//! image's PnP pose of the camera in the target frame (`T_T_C`, the target is the odometry's
//! origin) with MoCal's increment noise, through the camera-IMU pipeline's PnP
//! (`calibrate::camera_imu`, read-only). For monitoring a real camera recording (EuRoC
//! `imu_april`, host/tests/monitor_real.rs) with Kalibr's extrinsic as the calibration of
//! record.

use msreg_estimator::camera::Camera;

use crate::calibrate::camera_imu::{camera_in_target, frame_poses, increment_noise, CornerFrame};
use crate::dataset::{PoseRecord, PoseSensorYaml};

/// Smallest corner noise any image is credited with, pixels (MoCal's floor, as
/// `camera_imu`'s): the increment noise of this odometry is MoCal's.
const PIXEL_SIGMA_FLOOR: f64 = 0.05;

/// The camera's PnP poses in the target frame (one per image with enough corners and a PnP
/// solution, camera clock) and the stated noise of one increment.
pub fn target_odometry(
    camera: &Camera<f64>,
    frames: &[CornerFrame],
) -> (Vec<PoseRecord>, PoseSensorYaml) {
    let poses = frame_poses(camera, frames);
    let odometry = poses.iter().map(camera_in_target).collect();
    (odometry, increment_noise(&poses, PIXEL_SIGMA_FLOOR))
}
