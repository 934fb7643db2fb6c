//! Camera-IMU's data-driven model error ([`crate::calibrate::jackknife`]): RepErrCal on each
//! time block of the recording alone, from the same MoCal start and prior as the whole run,
//! the blocks' spread against their own covariances, and the result file's covariance from
//! it, in the result file's frame (`T_cam_imu`).

use std::time::Instant;

use rayon::prelude::*;

use super::*;
use crate::calibrate::jackknife::{self, Estimate, ModelErrorReport};

/// The window `[from_ns, to_ns)` of the input (IMU samples, images and their PnP poses).
pub(crate) struct Window<'a> {
    pub(crate) input: CameraImuInput<'a>,
    pub(crate) poses: &'a [FramePose],
}

impl<'a> Window<'a> {
    pub(crate) fn of(
        input: &CameraImuInput<'a>,
        poses: &'a [FramePose],
        (from_ns, to_ns): (u64, u64),
    ) -> Self {
        fn cut<X>(items: &[X], stamp: impl Fn(&X) -> u64, (from, to): (u64, u64)) -> &[X] {
            let a = items.partition_point(|x| stamp(x) < from);
            let b = items.partition_point(|x| stamp(x) < to);
            &items[a..b.max(a)]
        }
        let span = (from_ns, to_ns);
        Self {
            input: CameraImuInput {
                imu: cut(input.imu, |r| r.stamp_ns, span),
                frames: cut(input.frames, |f| f.stamp_ns, span),
                ..*input
            },
            poses: cut(poses, |p| p.stamp_ns, span),
        }
    }
}

/// The time blocks of `input`'s IMU record ([`jackknife::time_blocks`]).
pub(crate) fn blocks_of(imu: &[ImuRecord]) -> Vec<(u64, u64)> {
    match (imu.first(), imu.last()) {
        (Some(a), Some(b)) => jackknife::time_blocks(a.stamp_ns, b.stamp_ns),
        _ => Vec::new(),
    }
}

/// A calibration as the result file holds it: `T_cam_imu` with its covariance.
pub(crate) fn cam_imu(c: &CameraImuCalibration) -> Estimate {
    let (t, cov) = invert_with_covariance(&c.t_imu_sensor, &c.covariance);
    Estimate::new(t, &cov, c.time_offset_s, c.time_offset_sigma_s)
}

/// One block's estimate, or why there is none.
pub(crate) fn block_estimate(
    outcome: Result<CameraImuCalibration, InputError>,
) -> Result<Estimate, String> {
    finite(cam_imu(&outcome.map_err(|e| e.to_string())?))
}

/// `e` when every number of it is finite.
pub(crate) fn finite(e: Estimate) -> Result<Estimate, String> {
    let numbers = e
        .covariance
        .iter()
        .chain(e.transform.translation.vector.iter())
        .chain(e.transform.rotation.coords.iter());
    if numbers.copied().all(f64::is_finite) && e.time_offset_s.is_finite() {
        Ok(e)
    } else {
        Err("no finite estimate".to_string())
    }
}

/// RepErrCal on every time block alone (in parallel), from `start` (the whole run's MoCal
/// start), and the whole run `calibration`'s model error and written covariance.
pub(crate) fn add_model_error<T: Scalar>(
    input: &CameraImuInput<'_>,
    options: &CameraImuOptions,
    start: &Start<'_>,
    calibration: &mut CameraImuCalibration,
) {
    let started = Instant::now();
    let blocks = blocks_of(input.imu);
    let runs: Vec<Result<Estimate, String>> = blocks
        .par_iter()
        .map(|span| {
            let w = Window::of(input, start.poses, *span);
            let s = Start {
                poses: w.poses,
                ..*start
            };
            block_estimate(reprojection_calibration::<T>(
                &w.input,
                options,
                &s,
                ExtrinsicPrior::AroundStart,
                Instant::now(),
                &mut |_| {},
            ))
        })
        .collect();
    let (written, report) = jackknife::model_error(
        &cam_imu(calibration),
        &runs,
        started.elapsed().as_secs_f64(),
    );
    set_model_error(calibration, written, report);
}

/// Stores the written covariance (of `T_cam_imu`, with the time offset) and the report.
pub(crate) fn set_model_error(
    calibration: &mut CameraImuCalibration,
    written: jackknife::Matrix7,
    report: ModelErrorReport,
) {
    let full = cam_imu(calibration);
    calibration.report.written = Some(Estimate {
        covariance: written,
        ..full
    });
    calibration.report.model_error = Some(report);
}
