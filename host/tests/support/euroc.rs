//! The real EuRoC `imu_april` cam0 recording as the real-data tests read it: Kalibr's
//! extrinsic (the reference) and the AprilGrid corners of every image.
#![allow(dead_code)]

use std::path::Path;

use msreg_estimator::CornerObservation;
use msreg_host::calibrate::camera_imu::CornerFrame;
use msreg_host::dataset::read_observed_corners;
use nalgebra::{Isometry3, Matrix4, Rotation3, Translation3, UnitQuaternion};

/// The recording under the shared data folder.
pub const SET: &str = "real/euroc-imu-april-cam0";

/// Kalibr's `T_imu_cam` of cam0 (the inverse of `groundtruth/extrinsics.yaml`'s `T_cam_imu`).
pub fn kalibr_t_imu_cam(dir: &Path) -> Isometry3<f64> {
    let path = dir.join("groundtruth/extrinsics.yaml");
    let doc: serde_yaml::Value =
        serde_yaml::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    let rows = doc["cam0"]["T_cam_imu"].as_sequence().unwrap();
    let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().unwrap());
    let rotation = Rotation3::from_matrix_unchecked(m.fixed_view::<3, 3>(0, 0).into_owned());
    Isometry3::from_parts(
        Translation3::from(m.fixed_view::<3, 1>(0, 3).into_owned()),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
    .inverse()
}

/// The corners of every image (their target points from the file).
pub fn corner_frames(dir: &Path) -> Vec<CornerFrame> {
    read_observed_corners(dir.join("cam0/corners.csv"))
        .unwrap()
        .into_iter()
        .map(|image| CornerFrame {
            stamp_ns: image.stamp_ns,
            corners: image
                .corners
                .iter()
                .map(|c| CornerObservation {
                    point_in_target: c.point.unwrap(),
                    pixel: c.pixel,
                })
                .collect(),
        })
        .collect()
}
