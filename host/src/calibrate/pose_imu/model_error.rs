//! Pose-IMU's data-driven model error ([`crate::calibrate::jackknife`]): the pipeline on each
//! time block of the recording alone, the blocks' spread against their own covariances, in
//! the result file's frame (`T_imu_pose`).

use std::time::Instant;

use rayon::prelude::*;

use super::{calibrate, PoseImuInput};
use crate::calibrate::driver::report::{PoseImuCalibration, PoseImuOptions};
use crate::calibrate::jackknife::{self, Estimate, Matrix7, ModelErrorReport};
use msreg_estimator::Scalar;

/// `calibration`'s estimate as the result file holds it.
fn estimate(c: &PoseImuCalibration) -> Estimate {
    Estimate::new(
        c.t_imu_sensor,
        &c.covariance,
        c.time_offset_s,
        c.time_offset_sigma_s,
    )
}

/// The model error of the whole run `calibration` of `input`: the pipeline on every time
/// block alone (in parallel), and the covariance to write (`[dtheta; dp; dt_d]` of
/// `T_imu_pose`: per axis the larger of the filter's and the data's sigma) with the report.
pub fn model_error<T: Scalar>(
    input: &PoseImuInput<'_>,
    options: &PoseImuOptions,
    calibration: &PoseImuCalibration,
) -> (Matrix7, ModelErrorReport) {
    let started = Instant::now();
    let blocks = match (input.imu.first(), input.imu.last()) {
        (Some(a), Some(b)) => jackknife::time_blocks(a.stamp_ns, b.stamp_ns),
        _ => Vec::new(),
    };
    let runs: Vec<Result<Estimate, String>> = blocks
        .par_iter()
        .map(|&(from, to)| {
            let a = input.imu.partition_point(|r| r.stamp_ns < from);
            let b = input.imu.partition_point(|r| r.stamp_ns < to);
            let c = input.poses.partition_point(|p| p.stamp_ns < from);
            let d = input.poses.partition_point(|p| p.stamp_ns < to);
            let block = PoseImuInput {
                imu: &input.imu[a..b.max(a)],
                poses: &input.poses[c..d.max(c)],
                ..*input
            };
            calibrate::<T>(&block, options, &mut |_| {})
                .map(|c| estimate(&c))
                .map_err(|e| e.to_string())
        })
        .collect();
    jackknife::model_error(
        &estimate(calibration),
        &runs,
        started.elapsed().as_secs_f64(),
    )
}
