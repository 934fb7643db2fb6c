//! The LiDAR-IMU tests' scenario and error, in one home (`lidar_imu_accuracy.rs`,
//! `lidar_imu_rig.rs`).
#![allow(dead_code)]

use msreg_host::sim::{LidarImuSimConfig, LidarSimConfig};
use nalgebra::{Isometry3, Vector6};

/// The hand-held room scenario: `duration_s` of a `rings` x `columns` LiDAR, its time offset
/// drawn from the seed in [-10, 10] ms.
pub fn config(seed: u64, duration_s: f64, rings: usize, columns: usize) -> LidarImuSimConfig {
    LidarImuSimConfig {
        seed,
        duration_s,
        lidar: LidarSimConfig {
            rings,
            columns,
            time_offset_s: ((seed * 7919) % 21) as f64 * 1e-3 - 0.010,
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    }
}

/// `[dtheta; dp]` of `estimate` against `truth` (rotation as the right perturbation, rad; m).
pub fn error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> Vector6<f64> {
    let r = (estimate.rotation.inverse() * truth.rotation).scaled_axis();
    let p = truth.translation.vector - estimate.translation.vector;
    Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z)
}
