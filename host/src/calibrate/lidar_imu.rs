//! LiDAR-IMU calibration (dissertation ch. 3.5, Fig. 3.5b): the pose-IMU filter with a
//! LiDAR front-end.
//!
//! 1. **Rotation init** (eq. 3.2-3.5): NDT of consecutive raw (not deskewed) scans over the
//!    first `init_duration_s` gives LiDAR rotation increments; paired with the gyro
//!    integrated over the same sweeps (bias from the standstill) they give the hand-eye
//!    rotation in closed form. Pairs whose residual `|r_I - R r_L|` is an outlier (a wrong
//!    NDT match) are dropped and the rotation re-solved once.
//! 2. **Filter cycle**, per scan `k`, when the IMU stream passes the scan's reference time
//!    `t_ref = stamp + max t_i` (its last firing) `+ t_d`:
//!    predict (over the IMU readings interpolated up to `t_ref`) -> **deskew** every point to
//!    `t_ref` with the buffered filter poses and the current extrinsic (eq. 3.18) ->
//!    voxel filter -> **NDT** against a local map of the last `local_map_scans` deskewed
//!    scans (default 5; 0: the previous scan) from the IMU-predicted relative motion ->
//!    **update** with `T_L(k-1)_L(k)` as a relative pose between the two
//!    reference stamps (eq. 3.19-3.21). Deskewing to the *last* firing means the measurement
//!    time is one the IMU stream has just reached (the filter's one-sample look-ahead), so
//!    the filter clones its pose there (it cannot clone in the past).
//! 3. **Measurement noise**: NDT's inverse Hessian has the right shape but a size set by
//!    the score's constants and the cells' eigenvalue floor (~5x too large on the
//!    simulator). The filter uses `R = s * Sigma_NDT + diag(floor^2)` with `s` matched to
//!    the NIS online ([`NoiseAdaptation`]) and a final floor for NDT's time-correlated
//!    errors; `docs/lidar_imu.md` has the measurements against ground truth that chose it.
//!    Early on the extrinsic is far from the truth (rotation from the hand-eye init, zero
//!    translation) and a tight `R` lets the first updates jump along a wrong linearisation,
//!    after which the gate rejects everything. The floor therefore starts at
//!    `initial_*_floor` (0.2 deg / 10 mm, the pose-IMU odometry's level) and decays
//!    exponentially to the final floor over `anneal_updates` updates, and at least as fast
//!    as the filter's largest extrinsic sigma relative to its prior (`anneal_by_sigma`):
//!    a larger `R` only makes the filter more conservative, never inconsistent.
//!    NDT's increments also carry a small systematic error along the time-offset direction
//!    that no amount of data separates from `t_d`; it enters the reported time-offset sigma
//!    as a consider parameter (`time_shift_sigma_s`).
//! 4. Degenerate, non-converged or low-fitness matches are skipped (reported) and the
//!    odometry chain restarts at that scan; a scan with zero points is skipped; a malformed
//!    scan file stops the run with an error naming it.

mod feed;
pub mod moving;
mod options;
mod report;
mod rotation;
mod update;

use std::time::Instant;

use msreg_estimator::state::imu as imu_block;
use msreg_estimator::{Ekf, Scalar, SensorId, SOLE_SENSOR};

pub(crate) use self::{feed::*, rotation::*};
use super::extrinsic::ImuExtrinsicCalibration;
use super::init::{self, Standstill};
use super::InputError;
use crate::calibrate::driver::report::Timing;
use crate::calibrate::driver::verdict::finish;
use crate::calibrate::driver::{describe_moving_start, drive_imu, start_filter, FilterStart};
use crate::dataset::{ImuNoiseYaml, ImuRecord};
use crate::lidar::ScanSource;
use crate::pointcloud::PointCloud;
pub use options::{LidarImuOptions, NdtCovariance, NoiseAdaptation};
pub use report::{LidarImuReport, ScanRecord, StageTiming};

/// What the pipeline reads.
#[derive(Clone, Copy)]
pub struct LidarImuInput<'a> {
    /// IMU samples, strictly increasing stamps.
    pub imu: &'a [ImuRecord],
    /// IMU noise densities.
    pub imu_noise: &'a ImuNoiseYaml,
    /// The LiDAR sweeps.
    pub scans: &'a dyn ScanSource,
}

/// The outcome: `T_imu_lidar` with its covariance, the time offset, and the report.
pub type LidarImuCalibration = ImuExtrinsicCalibration<LidarImuReport>;

/// The first IMU sample, once the input and the options are usable: IMU samples, at least
/// three scans, valid NDT parameters, and the sandwich covariances computed if chosen.
fn check_input<'a>(
    input: &LidarImuInput<'a>,
    options: &LidarImuOptions,
) -> Result<&'a ImuRecord, InputError> {
    let first_imu = input.imu.first().ok_or(InputError::NoImuSamples)?;
    if input.scans.len() < 3 {
        return Err(InputError::TooFew {
            file: "lidar0/",
            what: "scans",
            found: input.scans.len(),
            needed: 3,
        });
    }
    options.ndt.validate()?;
    if options.ndt_covariance != NdtCovariance::Hessian && !options.ndt.sandwich_covariance {
        return Err(InputError::SandwichWithoutCovariance);
    }
    Ok(first_imu)
}

/// Runs the calibration with the filter in scalar type `T`.
pub fn calibrate<T: Scalar>(
    input: &LidarImuInput<'_>,
    options: &LidarImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<LidarImuCalibration, InputError> {
    let imu = input.imu;
    let first_imu = check_input(input, options)?;
    let started = Instant::now();
    let standstill = init::detect_standstill(imu, options.filter.min_standstill_s);
    let raw = rotation_start(imu, input.scans, standstill.as_ref(), options)?;
    let outliers = raw.outliers;
    let (start, moving) = start_filter_for::<T>(input, options, standstill.as_ref(), raw)?;
    let FilterStart {
        mut ekf,
        rotation_init,
        init_problem,
        moving_start,
        gyro_bias_init,
    } = start;
    let init_s = started.elapsed().as_secs_f64();

    let started = Instant::now();
    let mut feed = LidarFeed::new(
        input.scans,
        options,
        first_imu.stamp_ns,
        (SOLE_SENSOR, false),
    );
    if moving.is_some() {
        feed = feed.annealed_by_imu_state();
    }
    drive_imu(&mut ekf, imu, standstill.as_ref(), progress, &mut feed)?;
    feed.skip_remaining();
    progress(1.0);
    let filter_s = started.elapsed().as_secs_f64();
    let mut timing = feed.timing;
    timing.rotation_init = init_s;
    timing.total_filter_pass = filter_s;
    timing.filter = filter_s - timing.load - timing.deskew - timing.voxel_and_target - timing.ndt;

    let final_scale = options.covariance_scale[0] * feed.adaptive_factor * feed.inflation;
    let inflation = feed.inflation;
    let LidarFeed {
        mut run, records, ..
    } = feed;
    let scans_skipped = std::mem::take(&mut run.skipped);
    let pose = finish(
        &ekf,
        run,
        standstill.as_ref(),
        &rotation_init,
        Timing {
            init: init_s,
            filter: filter_s,
        },
    );
    let mut calibration = pose.map_report(|filter| LidarImuReport {
        filter,
        deskew: options.deskew,
        scans_total: input.scans.len(),
        scans_matched: records.iter().filter(|r| r.status == "matched").count(),
        scans_skipped,
        settled_nis_per_dof: settled_nis(&records, options),
        hand_eye_outliers: outliers,
        measurement_noise: [
            options.covariance_scale[0],
            options.covariance_scale[1],
            options.rotation_floor_rad.to_degrees(),
            options.translation_floor_m,
        ],
        stage_timing_s: timing,
        final_covariance_scale: final_scale,
        correlation_inflation: inflation,
        time_offset_filter_sigma_s: 0.0,
        scans: records,
    });
    let filter_sigma = calibration.time_offset_sigma_s;
    calibration.report.time_offset_filter_sigma_s = filter_sigma;
    if options.filter.estimate_time_offset {
        calibration.time_offset_sigma_s = filter_sigma.hypot(options.time_shift_sigma_s);
    }
    if let Some(problem) = init_problem {
        calibration.report.filter.reasons.insert(0, problem);
        calibration.report.filter.converged = false;
    }
    calibration.report.filter.gyro_bias_init = gyro_bias_init;
    calibration.report.filter.moving_start = match moving {
        Some(m) => m.describe(&moving_start),
        None => describe_moving_start(&moving_start),
    };
    Ok(calibration)
}

/// The filter and how it started: at a standstill (or without a hand-eye rotation) as the
/// pose-IMU pipeline, else the moving start of [`moving`] (with what it found).
fn start_filter_for<T: Scalar>(
    input: &LidarImuInput<'_>,
    options: &LidarImuOptions,
    standstill: Option<&Standstill>,
    raw: RawRotations,
) -> Result<(FilterStart<T>, Option<moving::MovingStartReport>), InputError> {
    let imu = input.imu;
    Ok(match (standstill, raw.rotation) {
        (None, Ok(rotation)) => {
            let (start, report) = moving::start::<T>(
                (imu, input.imu_noise, input.scans),
                options,
                (rotation, raw.gyro_bias),
                &raw.increments,
            )?;
            (start, Some(report))
        }
        (_, rotation) => {
            let start = start_filter::<T>(
                imu,
                input.imu_noise,
                (standstill, &[]),
                (rotation, raw.gyro_bias.as_ref()),
                (&options.filter, None),
            )?;
            (start, None)
        }
    })
}

/// Mean NIS/dof of the matched scans after `3 * anneal_updates` updates.
fn settled_nis(records: &[ScanRecord], options: &LidarImuOptions) -> f64 {
    let skip = (3.0 * options.anneal_updates).ceil() as usize;
    let nis: Vec<f64> = records.iter().filter_map(|r| r.nis).skip(skip).collect();
    nis.iter().sum::<f64>() / (6 * nis.len()) as f64
}

/// Loads scan `k`: `Ok(None)` for a documented skip (zero points), an error for bad input.
fn load(scans: &dyn ScanSource, k: usize) -> Result<Option<PointCloud>, InputError> {
    match scans.load(k) {
        Ok(c) if c.is_empty() => Ok(None),
        Ok(c) => Ok(Some(c)),
        Err(e) if e.is_empty_scan() => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// The filter's largest extrinsic sigma of sensor `s` relative to its prior, over the six
/// axes (1 at the start, -> 0 as the extrinsic is learned; 1 when the prior is unknown).
fn extrinsic_sigma_ratio<
    T: Scalar,
    const S: usize,
    const C: usize,
    const N: usize,
    const F: usize,
>(
    ekf: &Ekf<T, S, C, N, F>,
    s: SensorId,
) -> f64 {
    let (rotation, translation) = ekf.extrinsic_sigma(s);
    let prior = ekf.prior_sigma(s);
    (0..6)
        .map(|i| {
            let sigma = if i < 3 {
                rotation[i]
            } else {
                translation[i - 3]
            }
            .to_f64();
            let p = prior[i].to_f64();
            if p > 0.0 {
                sigma / p
            } else {
                1.0
            }
        })
        .fold(0.0, f64::max)
}

/// The filter's largest velocity sigma, m/s.
fn velocity_sigma<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
    ekf: &Ekf<T, S, C, N, F>,
) -> f64 {
    let cov = ekf.covariance();
    let v = imu_block::VELOCITY.idx;
    (v..v + 3)
        .map(|i| cov[(i, i)].to_f64())
        .fold(0.0, f64::max)
        .sqrt()
}

/// Last firing offset of a scan, ns.
fn last_firing_ns(cloud: &PointCloud) -> u64 {
    cloud
        .points
        .iter()
        .map(|p| u64::from(p.t_ns))
        .max()
        .unwrap_or(0)
}
