//! The hand-eye rotation start of LiDAR-IMU calibration: raw-scan NDT rotation increments against
//! the integrated gyro, with the gyro bias fitted to the motion when there is no standstill.

use super::*;
use crate::calibrate::driver::{hand_eye_and_gyro_bias, HAND_EYE_MIN_PAIRS};
use crate::calibrate::gyro_bias::GyroBiasEstimate;
use crate::calibrate::init::{self, RotationInit, Standstill};
use crate::calibrate::InputError;
use crate::dataset::ImuRecord;
use crate::lidar::ScanSource;
use crate::ndt::{align, NdtTarget};
use crate::pointcloud::voxel_downsample;
use nalgebra::{Isometry3, Vector3};

/// Largest residual `|r_I - R r_L|` kept, rad, however small the median.
pub(crate) const MIN_OUTLIER_THRESHOLD_RAD: f64 = 0.01;

/// The hand-eye rotation (or why not), the gyro bias fitted to the motion (without a
/// standstill) and the number of pairs dropped as outliers.
pub(crate) type RotationStart = (
    Result<RotationInit, msreg_estimator::HandEyeError<f64>>,
    Option<GyroBiasEstimate>,
    usize,
);

/// Hand-eye rotation and, without a standstill, the gyro bias from raw-scan NDT rotations
/// over the first `init_duration_s`.
pub(crate) fn rotation_init(
    imu: &[ImuRecord],
    scans: &dyn ScanSource,
    standstill: Option<&Standstill>,
    options: &LidarImuOptions,
) -> Result<RotationStart, InputError> {
    let r = rotation_start(imu, scans, standstill, options)?;
    Ok((r.rotation, r.gyro_bias, r.outliers))
}

/// [`rotation_init`]'s result with the increments it kept.
pub(crate) struct RawRotations {
    /// The hand-eye rotation, or why not.
    pub(crate) rotation: Result<RotationInit, msreg_estimator::HandEyeError<f64>>,
    /// The gyro bias fitted to the motion (without a standstill).
    pub(crate) gyro_bias: Option<GyroBiasEstimate>,
    /// Pairs dropped as outliers.
    pub(crate) outliers: usize,
    /// The raw-scan NDT rotation increments kept, mid-sweep stamps (LiDAR clock).
    pub(crate) increments: Vec<init::RotationIncrement>,
}

/// [`rotation_init`] with the increments it kept.
pub(crate) fn rotation_start(
    imu: &[ImuRecord],
    scans: &dyn ScanSource,
    standstill: Option<&Standstill>,
    options: &LidarImuOptions,
) -> Result<RawRotations, InputError> {
    let first = imu.first().map_or(0, |r| r.stamp_ns);
    let until = first.saturating_add((options.init_duration_s * 1e9) as u64);
    let mut increments = Vec::new();
    let mut previous: Option<(u64, NdtTarget)> = None;
    for k in 0..scans.len() {
        let stamp = scans.stamp_ns(k);
        if stamp > until {
            break;
        }
        let Some(cloud) = load(scans, k)? else {
            previous = None;
            continue;
        };
        let mid = stamp.saturating_add(last_firing_ns(&cloud) / 2);
        let points = voxel_downsample(&cloud, options.voxel_m).positions();
        if points.len() < options.min_points {
            previous = None;
            continue;
        }
        if let Some((prev_mid, target)) = &previous {
            if mid > *prev_mid {
                if let Ok(r) = align(target, &points, &Isometry3::identity(), &options.ndt) {
                    if r.converged && r.fitness >= options.min_fitness {
                        increments.push((*prev_mid, mid, r.t_target_source.rotation));
                    }
                }
            }
        }
        previous = NdtTarget::build(&points, &options.ndt)
            .ok()
            .map(|t| (mid, t));
    }
    // Outliers (NDT failures) are cut against a first hand-eye solution before the final
    // hand-eye and bias fit.
    let first_bias = standstill.map_or_else(Vector3::zeros, |s| s.gyro_mean);
    // Each increment inside the IMU data with its (gyro, sensor) rotation-vector pair.
    let paired: Vec<_> = increments
        .iter()
        .filter_map(|inc| Some((*inc, init::rotation_pairs(imu, [*inc], &first_bias).pop()?)))
        .collect();
    let pairs: Vec<_> = paired.iter().map(|(_, pair)| *pair).collect();
    let first_pass = init::hand_eye_from_pairs(pairs.iter().copied(), HAND_EYE_MIN_PAIRS);
    let Ok(first_solution) = first_pass else {
        return Ok(RawRotations {
            rotation: first_pass,
            gyro_bias: None,
            outliers: 0,
            increments,
        });
    };
    let r = first_solution.rotation;
    let residuals: Vec<f64> = pairs.iter().map(|(ri, rl)| (ri - r * rl).norm()).collect();
    let mut sorted = residuals.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
    let threshold = (5.0 * median).max(MIN_OUTLIER_THRESHOLD_RAD);
    let kept: Vec<init::RotationIncrement> = paired
        .iter()
        .zip(&residuals)
        .filter(|(_, e)| **e <= threshold)
        .map(|((inc, _), _)| *inc)
        .collect();
    let outliers = pairs.len() - kept.len();
    let (rotation, gyro_bias) = hand_eye_and_gyro_bias(imu, &kept, standstill);
    Ok(RawRotations {
        rotation,
        gyro_bias,
        outliers,
        increments: kept,
    })
}
