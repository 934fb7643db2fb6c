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

pub mod moving;

use std::time::Instant;

use msreg_estimator::state::imu as imu_block;
use msreg_estimator::{Ekf, Error as FilterError, RelativePose, Scalar};
use nalgebra::{Isometry3, Matrix6, Vector3, Vector6};
use serde::Serialize;

use super::convert;
use super::extrinsic::ImuExtrinsicCalibration;
use super::gyro_bias::GyroBiasEstimate;
use super::init::{self, RotationInit, Standstill};
use super::pose_imu::{
    describe_moving_start, drive_imu, finish, hand_eye_and_gyro_bias, start_filter, FilterStart,
    ImuHooks, PoseImuOptions, PoseImuReport, Run, Timing, HAND_EYE_MIN_PAIRS,
};
use super::InputError;
use crate::dataset::{ImuNoiseYaml, ImuRecord};
use crate::lidar::deskew::{imu_time, DeskewedScan};
use crate::lidar::{deskew_scan, PoseBuffer, ScanSource};
use crate::ndt::{align, LocalMap, NdtParams, NdtResult, NdtTarget};
use crate::pointcloud::{voxel_downsample, PointCloud};

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

/// Tuning of the pipeline.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarImuOptions {
    /// Priors, time offset and standstill options shared with the pose-IMU pipeline.
    pub filter: PoseImuOptions,
    /// Deskew scans (eq. 3.18); `false` matches raw scans stamped at mid-sweep (Fig. 3.11).
    pub deskew: bool,
    /// Voxel-filter leaf after deskewing, m.
    pub voxel_m: f64,
    /// NDT options.
    pub ndt: NdtParams,
    /// Scans from the first this many seconds feed the hand-eye rotation init.
    pub init_duration_s: f64,
    /// Which NDT covariance the measurement noise starts from.
    pub ndt_covariance: NdtCovariance,
    /// Factors on NDT's covariance, `[rotation block, translation block]` (see the module
    /// docs: measured per-increment error variance times the autocorrelation inflation).
    pub covariance_scale: [f64; 2],
    /// Per-axis 1-sigma rotation added to every increment, rad: stands for the part of
    /// NDT's error that is correlated from scan to scan, which the white measurement model
    /// cannot represent; it depends on the matching (see [`LidarImuOptions::scan_to_scan`]).
    pub rotation_floor_rad: f64,
    /// Per-axis 1-sigma translation added to every increment, m.
    pub translation_floor_m: f64,
    /// Per-axis 1-sigma rotation floor of the first update, rad; the floor decays from it to
    /// `rotation_floor_rad` with time constant `anneal_updates` (see the module docs).
    pub initial_rotation_floor_rad: f64,
    /// Per-axis 1-sigma translation floor of the first update, m.
    pub initial_translation_floor_m: f64,
    /// Decay constant of the floor, in updates.
    pub anneal_updates: f64,
    /// Also shrink the floor's excess with the filter's own extrinsic sigma: the excess is
    /// scaled by `min(exp(-updates / anneal_updates), max_i sigma_i / prior_sigma_i)` over
    /// the six extrinsic axes. The floor stands for the linearisation error of an extrinsic
    /// still far from the truth, which the filter's sigma bounds; a well-excited recording
    /// then reaches the final floor within seconds instead of `anneal_updates` updates
    /// (docs/lidar_imu.md, "The floor annealed by the filter's sigma").
    pub anneal_by_sigma: bool,
    /// 1-sigma of the front end's systematic time shift, s: NDT's increments carry a
    /// scene-dependent error along the time-offset direction that does not average out over
    /// a recording (docs/lidar_imu.md, "The time offset's systematic error"). It is
    /// collinear with `t_d`, so the filter attributes all of it to `t_d`; as a consider
    /// parameter it adds in quadrature to the reported time-offset sigma (the extrinsic is
    /// unaffected to first order).
    pub time_shift_sigma_s: f64,
    /// Adapt the factor on NDT's covariance so the NIS matches its expectation
    /// ([`NoiseAdaptation`]); `None` keeps `covariance_scale` fixed.
    pub adapt: Option<NoiseAdaptation>,
    /// Matches with a lower NDT fitness are skipped.
    pub min_fitness: f64,
    /// Scans with fewer points after voxel filtering are skipped.
    pub min_points: usize,
    /// Match each scan against a sliding map of this many recent deskewed scans
    /// (scan-to-local-map) instead of the previous scan; 0 = scan-to-scan. The increment
    /// fused is still `T_L(k-1)_L(k)`, from the two scans' poses in the map. Default 5:
    /// more accurate than scan-to-scan, whose positively correlated increment errors make
    /// the filter overconfident on long, dense recordings (docs/lidar_imu.md). The floor
    /// depends on it: change it through [`LidarImuOptions::for_local_map`].
    pub local_map_scans: usize,
}

impl Default for LidarImuOptions {
    fn default() -> Self {
        Self {
            filter: PoseImuOptions {
                rotation_sigma_rad: 3f64.to_radians(),
                ..PoseImuOptions::default()
            },
            deskew: true,
            voxel_m: 0.15,
            ndt: NdtParams {
                resolutions: vec![2.0, 1.0, 0.5],
                ..NdtParams::default()
            },
            init_duration_s: 15.0,
            ndt_covariance: NdtCovariance::Hessian,
            covariance_scale: [0.2, 0.2],
            // Half the scan-to-scan floor: map-based increments are more accurate and their
            // errors not positively correlated (docs/lidar_imu.md).
            rotation_floor_rad: 0.0025f64.to_radians(),
            translation_floor_m: 0.00025,
            initial_rotation_floor_rad: 0.2f64.to_radians(),
            initial_translation_floor_m: 0.01,
            anneal_updates: 100.0,
            anneal_by_sigma: true,
            time_shift_sigma_s: TIME_SHIFT_SIGMA_S,
            adapt: Some(NoiseAdaptation::default()),
            min_fitness: 0.05,
            min_points: 200,
            local_map_scans: 5,
        }
    }
}

impl LidarImuOptions {
    /// The defaults for matching against `local_map_scans` scans (0 = scan-to-scan), with
    /// that mode's floor.
    pub fn for_local_map(local_map_scans: usize) -> Self {
        if local_map_scans == 0 {
            Self::scan_to_scan()
        } else {
            Self {
                local_map_scans,
                ..Self::default()
            }
        }
    }

    /// Scan-to-scan matching (`local_map_scans = 0`) with its own floor, 0.005 deg / 0.5 mm:
    /// the size of scan-to-scan NDT's per-increment errors on dense scans, whose positive
    /// correlation from scan to scan it stands for (docs/lidar_imu.md, noise model).
    pub fn scan_to_scan() -> Self {
        Self {
            local_map_scans: 0,
            rotation_floor_rad: 0.005f64.to_radians(),
            translation_floor_m: 0.0005,
            ..Self::default()
        }
    }
}

/// Default [`LidarImuOptions::time_shift_sigma_s`], s: the RMS time shift of the NDT
/// increments measured against the simulator's truth on tuning seeds 500-509
/// (docs/lidar_imu.md, "The time offset's systematic error"), validated on other seeds.
pub const TIME_SHIFT_SIGMA_S: f64 = 0.027e-3;

/// Covariance matching of the NDT noise scale (Mehra 1972; Myers and Tapley 1976, with a
/// single scale factor): NDT's inverse Hessian has the right *shape* (which directions the
/// scene constrains) but a scale set by the score's constants, the target cells' eigenvalue
/// floor and unmodelled correlations, none of which the matcher can know. The filter
/// measures it: the NIS of an update falls when `R` is too large and rises when too small,
/// with expectation `dof` when consistent. Every `every` updates, after
/// `start_after_anneals * anneal_updates` updates, the factor is multiplied by
/// `(mean NIS/dof)^(w/2)` over the last `window` updates (each NIS/dof clipped at `clip`, so
/// one wrong match cannot blow it up), `w` the NDT term's mean share of the diagonal of `R`
/// (while the annealed floor dominates, the NIS says little about the NDT scale), the step
/// limited to `[1/max_step, max_step]` and the factor to `bounds`. The exponent 1/2 halves
/// each step: NIS is roughly proportional to `1/scale`, and damping averages the
/// chi-square sampling noise of the window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseAdaptation {
    /// Updates between adjustments.
    pub every: usize,
    /// Updates whose NIS is averaged.
    pub window: usize,
    /// Adaptation starts after this many `anneal_updates`.
    pub start_after_anneals: f64,
    /// Largest NIS/dof one update contributes.
    pub clip: f64,
    /// Largest factor of one adjustment.
    pub max_step: f64,
    /// Range of the scale factor.
    pub bounds: [f64; 2],
    /// Consecutive innovation pairs over which their lag-1 autocorrelation is measured
    /// (0 = no correlation inflation).
    pub correlation_window: usize,
    /// Largest inflation for correlated errors.
    pub max_inflation: f64,
}

impl Default for NoiseAdaptation {
    fn default() -> Self {
        Self {
            every: 20,
            window: 40,
            start_after_anneals: 1.0,
            clip: 5.0,
            max_step: 1.4,
            bounds: [0.01, 10.0],
            correlation_window: 0,
            max_inflation: 4.0,
        }
    }
}

/// The NDT covariance estimate the measurement noise is built from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NdtCovariance {
    /// Inverse Hessian of the score (Laplace approximation).
    Hessian,
    /// Sandwich `H^-1 S H^-1` with per-point gradients.
    Sandwich,
    /// Sandwich with gradients summed per target cell.
    Clustered,
}

/// One scan's fate, for the report.
#[derive(Debug, Clone, Serialize)]
pub struct ScanRecord {
    /// Scan stamp (LiDAR clock), ns.
    pub stamp_ns: u64,
    /// Reference (measurement) stamp, LiDAR clock, ns.
    pub reference_stamp_ns: u64,
    /// Seconds since the first IMU sample.
    pub t_s: f64,
    /// Points read.
    pub points: usize,
    /// Points after the voxel filter.
    pub points_filtered: usize,
    /// `matched`, `anchor` (first of a chain) or why it was skipped.
    pub status: String,
    /// NDT fitness (mean normalised score per point), when matched.
    pub fitness: Option<f64>,
    /// NDT iterations.
    pub iterations: Option<usize>,
    /// NIS of the update.
    pub nis: Option<f64>,
    /// Measured `T_L(k-1)_L(k)`: rotation vector, rad.
    pub delta_rotation: Option<[f64; 3]>,
    /// Measured `T_L(k-1)_L(k)`: translation, m.
    pub delta_translation: Option<[f64; 3]>,
    /// Measurement 1-sigma (after inflation) [rot x, y, z (rad); trans x, y, z (m)].
    pub sigma: Option<[f64; 6]>,
    /// The NDT result behind the measurement (in-process studies of the noise model).
    #[serde(skip)]
    pub ndt: Option<NdtResult>,
    /// The filter's prediction of `T_L(k-1)_L(k)`, NDT's initial guess (in-process studies).
    #[serde(skip)]
    pub predicted: Option<Isometry3<f64>>,
}

impl ScanRecord {
    /// A scan that has not (or not yet) been matched: no NDT or filter results.
    fn unmatched(
        stamp_ns: u64,
        reference_stamp_ns: u64,
        t_s: f64,
        points: usize,
        status: String,
    ) -> Self {
        Self {
            stamp_ns,
            reference_stamp_ns,
            t_s,
            points,
            points_filtered: 0,
            status,
            fitness: None,
            iterations: None,
            nis: None,
            delta_rotation: None,
            delta_translation: None,
            sigma: None,
            ndt: None,
            predicted: None,
        }
    }
}

/// Wall time per stage, s.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct StageTiming {
    /// Standstill detection, raw NDT and hand-eye rotation.
    pub rotation_init: f64,
    /// Reading scans (filter pass).
    pub load: f64,
    /// Deskewing.
    pub deskew: f64,
    /// Voxel filter and NDT target build.
    pub voxel_and_target: f64,
    /// NDT registration.
    pub ndt: f64,
    /// Filter (propagation and updates), the rest of the filter pass.
    pub filter: f64,
    /// The whole filter pass.
    pub total_filter_pass: f64,
}

/// The JSON report of a LiDAR-IMU calibration.
#[derive(Debug, Clone, Serialize)]
pub struct LidarImuReport {
    /// The filter's report (convergence checks, hand-eye init, history of 6 DoF + sigmas).
    #[serde(flatten)]
    pub filter: PoseImuReport,
    /// Whether scans were deskewed.
    pub deskew: bool,
    /// Scans in the recording.
    pub scans_total: usize,
    /// Scans fused as relative poses.
    pub scans_matched: usize,
    /// Scans skipped, with reasons.
    pub scans_skipped: Vec<String>,
    /// Mean NIS per DoF of the updates after the floor's annealing settled (from update
    /// `3 * anneal_updates` on; 1 when the final noise model is consistent; NaN if none).
    pub settled_nis_per_dof: f64,
    /// Pairs the rotation init dropped as outliers.
    pub hand_eye_outliers: usize,
    /// The measurement noise model: `[covariance scale rotation, covariance scale
    /// translation, rotation floor (deg), translation floor (m)]`.
    pub measurement_noise: [f64; 4],
    /// Effective factor on the NDT covariance at the end (adapted scale times the
    /// correlation inflation; the configured rotation factor when not adapted).
    pub final_covariance_scale: f64,
    /// The inflation for time-correlated NDT errors at the end, `(1 + rho) / (1 - rho)`.
    pub correlation_inflation: f64,
    /// The filter's own time-offset sigma, s, before the front end's systematic time shift
    /// (`LidarImuOptions::time_shift_sigma_s`) is added in quadrature.
    pub time_offset_filter_sigma_s: f64,
    /// Wall time per stage.
    pub stage_timing_s: StageTiming,
    /// Per scan: points, NDT fitness, NIS.
    pub scans: Vec<ScanRecord>,
}

/// The outcome: `T_imu_lidar` with its covariance, the time offset, and the report.
pub type LidarImuCalibration = ImuExtrinsicCalibration<LidarImuReport>;

/// Runs the calibration with the filter in scalar type `T`.
pub fn calibrate<T: Scalar>(
    input: &LidarImuInput<'_>,
    options: &LidarImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<LidarImuCalibration, InputError> {
    let imu = input.imu;
    let Some(first_imu) = imu.first() else {
        return Err(InputError::NoImuSamples);
    };
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
    let mut feed = LidarFeed::new(input.scans, options, first_imu.stamp_ns, (0, false));
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
    s: usize,
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

/// Largest residual `|r_I - R r_L|` kept, rad, however small the median.
const MIN_OUTLIER_THRESHOLD_RAD: f64 = 0.01;

/// The hand-eye rotation (or why not), the gyro bias fitted to the motion (without a
/// standstill) and the number of pairs dropped as outliers.
type RotationStart = (
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
fn rotation_start(
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

/// A scan read and waiting for the IMU to reach its reference time.
struct Pending {
    index: usize,
    stamp_ns: u64,
    ref_offset_ns: u64,
    cloud: PointCloud,
}

/// The last deskewed scan: the target of the next match.
struct Previous {
    /// Reference stamp, LiDAR clock (the filter's anchor stamp).
    ref_stamp_ns: u64,
    /// Its IMU time when it was processed.
    imu_time_ns: u64,
    target: NdtTarget,
    /// The voxel-filtered deskewed scan (scan-to-local-map only).
    cloud: Option<PointCloud>,
    /// Its pose in the local map's frame (identity at a chain's anchor).
    t_map: Isometry3<f64>,
}

/// The LiDAR front-end of the filter loop.
pub(crate) struct LidarFeed<'a> {
    /// The filter's index of the LiDAR.
    sensor: usize,
    /// Keep every deskewed scan for [`LidarFeed::take_deskewed`] (the joint calibration's
    /// board planes).
    keep_deskewed: bool,
    deskewed: Option<(u64, DeskewedScan)>,
    run: Run,
    scans: &'a dyn ScanSource,
    options: &'a LidarImuOptions,
    next: usize,
    pending: Option<Pending>,
    previous: Option<Previous>,
    last_end_ns: Option<u64>,
    buffer: PoseBuffer,
    records: Vec<ScanRecord>,
    timing: StageTiming,
    first_imu_ns: u64,
    /// Relative poses formed so far (drives the floor's annealing).
    updates: usize,
    /// Factor on `covariance_scale` from the NIS adaptation (1 until it starts).
    adaptive_factor: f64,
    /// NIS/dof of the updates and the NDT term's share of their `R`, in order (adaptation).
    nis_per_dof: Vec<(f64, f64)>,
    /// Scan-to-local-map target (`local_map_scans > 0`), in the frame of the chain's anchor.
    map: Option<LocalMap>,
    /// The previous update's innovation, normalised per component by `sqrt(R_ii)` (within
    /// an odometry chain).
    last_innovation: Option<Vector6<f64>>,
    /// Per consecutive pair of innovations: `(sum u_k u_k-1, sum (u_k^2 + u_k-1^2) / 2)`.
    innovation_pairs: Vec<(f64, f64)>,
    /// Inflation of the NDT term for time-correlated errors, `(1 + rho) / (1 - rho)`.
    inflation: f64,
    /// Anneal the floor by the IMU velocity's sigma too (a moving start, see
    /// [`LidarFeed::annealed_by_imu_state`]): `None` off, `Some(None)` on and the sigma at
    /// the first scan not yet read, `Some(Some(sigma))` on.
    imu_anneal: Option<Option<f64>>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    ImuHooks<T, Ekf<T, S, C, N, F>> for LidarFeed<'_>
{
    fn fuse_due(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
        _rec: &ImuRecord,
    ) -> Result<(), InputError> {
        while self.next_due(ekf)?.is_some() {
            self.fuse_next(ekf, index);
        }
        Ok(())
    }

    fn after_sample(&mut self, ekf: &Ekf<T, S, C, N, F>, _rec: &ImuRecord) {
        self.buffer
            .push(ekf.time_ns(), convert::isometry(&ekf.imu().pose()));
    }
}

impl<'a> LidarFeed<'a> {
    /// The feed of sensor `sensor` of the filter; `keep_deskewed` keeps each deskewed scan
    /// for [`LidarFeed::take_deskewed`].
    pub(crate) fn new(
        scans: &'a dyn ScanSource,
        options: &'a LidarImuOptions,
        first_imu_ns: u64,
        (sensor, keep_deskewed): (usize, bool),
    ) -> Self {
        Self {
            sensor,
            keep_deskewed,
            deskewed: None,
            run: Run::new(first_imu_ns, 100_000_000).for_sensor(sensor),
            scans,
            options,
            next: 0,
            pending: None,
            previous: None,
            last_end_ns: None,
            buffer: PoseBuffer::new(2_000_000_000),
            records: Vec::new(),
            timing: StageTiming::default(),
            first_imu_ns,
            updates: 0,
            adaptive_factor: 1.0,
            nis_per_dof: Vec::new(),
            last_innovation: None,
            innovation_pairs: Vec::new(),
            inflation: 1.0,
            imu_anneal: None,
            map: (options.local_map_scans > 0)
                .then(|| {
                    LocalMap::new(
                        options.local_map_scans,
                        options.voxel_m,
                        options.ndt.clone(),
                    )
                })
                .and_then(Result::ok),
        }
    }

    /// Also anneals the floor by the IMU velocity's sigma relative to its value at the
    /// first scan: the floor's excess then shrinks no faster than the larger of the
    /// extrinsic's and the velocity's sigma ratios. For a moving start, whose IMU state comes
    /// from the dynamic alignment with a wide velocity sigma (0.1 m/s): at peak motion the
    /// extrinsic sigma falls to a few per cent of its prior within a second, while the
    /// velocity, with which the scans are deskewed and the increments predicted, is still
    /// settling; the floor stands for that error until the filter has settled it
    /// (docs/lidar_imu.md, "Moving start: the floor and the IMU state").
    pub(crate) fn annealed_by_imu_state(mut self) -> Self {
        self.imu_anneal = Some(None);
        self
    }

    /// The velocity sigma ratio of [`LidarFeed::annealed_by_imu_state`] (0 when off).
    fn imu_sigma_ratio<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> f64 {
        let Some(stored) = self.imu_anneal else {
            return 0.0;
        };
        let now = velocity_sigma(ekf);
        let first = stored.unwrap_or(now);
        self.imu_anneal = Some(Some(first));
        if first > 0.0 {
            now / first
        } else {
            0.0
        }
    }

    /// Reads the next scan once its stamp is due and returns its reference stamp (LiDAR
    /// clock) when that is due too: the scan can be processed now ([`LidarFeed::fuse_next`]).
    pub(crate) fn next_due<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> Result<Option<u64>, InputError> {
        loop {
            if let Some(p) = self.pending.as_ref() {
                let reference = p.stamp_ns.saturating_add(p.ref_offset_ns);
                return Ok(ekf.is_due(self.sensor, reference).then_some(reference));
            }
            if self.next >= self.scans.len() {
                return Ok(None);
            }
            let k = self.next;
            let stamp = self.scans.stamp_ns(k);
            if !ekf.is_due(self.sensor, stamp) {
                return Ok(None);
            }
            self.next += 1;
            let started = Instant::now();
            let cloud = load(self.scans, k);
            self.timing.load += started.elapsed().as_secs_f64();
            let Some(cloud) = cloud? else {
                self.skip(k, stamp, "zero points");
                continue;
            };
            let last = last_firing_ns(&cloud);
            let ref_offset_ns = if self.options.deskew { last } else { last / 2 };
            let ref_stamp = stamp.saturating_add(ref_offset_ns);
            if self.last_end_ns.is_some_and(|e| ref_stamp <= e) {
                self.skip(
                    k,
                    stamp,
                    "stamp not after the previous scan's (out of order)",
                );
                continue;
            }
            self.pending = Some(Pending {
                index: k,
                stamp_ns: stamp,
                ref_offset_ns,
                cloud,
            });
        }
    }

    /// Processes the scan [`LidarFeed::next_due`] found due (`index`: the IMU sample fed
    /// last).
    pub(crate) fn fuse_next<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
    ) {
        let Some(p) = self.pending.take() else {
            return;
        };
        if index > 0 {
            self.process(ekf, p);
        } else {
            self.skip(p.index, p.stamp_ns, "before the first IMU sample");
        }
    }

    /// Another sensor's update moved the filter's pose at `time_ns` from `before` to
    /// `after`: the buffered poses move with it, so that deskewing sees one continuous
    /// motion (as after the LiDAR's own updates).
    pub(crate) fn filter_corrected(
        &mut self,
        time_ns: u64,
        before: &Isometry3<f64>,
        after: &Isometry3<f64>,
    ) {
        self.buffer.reanchor(&(after * before.inverse()));
        self.buffer.push(time_ns, *after);
    }

    /// Books every scan not reached (pending or unread) as after the last IMU sample.
    pub(crate) fn skip_remaining(&mut self) {
        if let Some(p) = self.pending.take() {
            self.skip(p.index, p.stamp_ns, "after the last IMU sample");
        }
        for k in self.next..self.scans.len() {
            self.skip(k, self.scans.stamp_ns(k), "after the last IMU sample");
        }
        self.next = self.scans.len();
    }

    /// The run's bookkeeping, every scan not reached booked as after the last IMU sample.
    pub(crate) fn into_run(mut self) -> Run {
        self.skip_remaining();
        self.run
    }

    /// The last processed scan, deskewed to its reference stamp (LiDAR clock), when the feed
    /// keeps them.
    pub(crate) fn take_deskewed(&mut self) -> Option<(u64, DeskewedScan)> {
        self.deskewed.take()
    }

    fn skip(&mut self, index: usize, stamp_ns: u64, why: &str) {
        self.run.skipped.push(format!(
            "lidar0 scan {} ({}): {why}",
            stamp_ns,
            self.scans.name(index)
        ));
        let t_s = stamp_ns.saturating_sub(self.first_imu_ns) as f64 * 1e-9;
        self.records.push(ScanRecord::unmatched(
            stamp_ns,
            stamp_ns,
            t_s,
            0,
            why.to_string(),
        ));
    }

    /// Predict -> deskew -> NDT -> update for one scan whose reference time has come.
    #[allow(clippy::too_many_lines)]
    fn process<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        p: Pending,
    ) {
        let td_ns = (ekf.time_offset(self.sensor).to_f64() * 1e9).round() as i64;
        let ref_stamp = p.stamp_ns.saturating_add(p.ref_offset_ns);
        let due = imu_time(p.stamp_ns, p.ref_offset_ns, td_ns);
        // Predict: the filter's pose at `due`, over the same interpolated IMU readings the
        // filter will propagate with (the scan is due, so `due` is within reach).
        let predicted = match ekf.predict_imu(due.max(ekf.time_ns())) {
            Ok(state) => convert::isometry(&state.pose()),
            Err(_) => convert::isometry(&ekf.imu().pose()),
        };
        self.buffer.push(due, predicted);
        let t_i_l = convert::isometry(&ekf.extrinsic(self.sensor));

        let t_s = due.saturating_sub(self.first_imu_ns) as f64 * 1e-9;
        let mut record =
            ScanRecord::unmatched(p.stamp_ns, ref_stamp, t_s, p.cloud.len(), String::new());
        let started = Instant::now();
        let deskewed = if self.options.deskew {
            deskew_scan(
                &p.cloud,
                p.stamp_ns,
                p.ref_offset_ns,
                td_ns,
                &t_i_l,
                &self.buffer,
            )
        } else {
            Some(DeskewedScan::undistorted(p.cloud))
        };
        self.timing.deskew += started.elapsed().as_secs_f64();
        let Some(deskewed) = deskewed else {
            self.reject(ekf, record, ref_stamp, "no IMU poses to deskew with");
            return;
        };
        let started = Instant::now();
        let filtered = voxel_downsample(&deskewed.cloud, self.options.voxel_m);
        if self.keep_deskewed {
            self.deskewed = Some((ref_stamp, deskewed));
        }
        let points = filtered.positions();
        record.points_filtered = points.len();
        let target = NdtTarget::build(&points, &self.options.ndt);
        self.timing.voxel_and_target += started.elapsed().as_secs_f64();
        if points.len() < self.options.min_points {
            self.reject(
                ekf,
                record,
                ref_stamp,
                "too few points after voxel filtering",
            );
            return;
        }
        let target = match target {
            Ok(t) => t,
            Err(e) => {
                self.reject(ekf, record, ref_stamp, &format!("no NDT target: {e}"));
                return;
            }
        };
        let mut this = Previous {
            ref_stamp_ns: ref_stamp,
            imu_time_ns: due,
            target,
            cloud: self.map.is_some().then_some(filtered),
            t_map: Isometry3::identity(),
        };
        let Some(prev) = self.previous.take() else {
            self.start_chain(ekf, record, this, "anchor");
            return;
        };
        let guess = match self.buffer.at(prev.imu_time_ns) {
            Some(t_g_prev) => t_i_l.inverse() * t_g_prev.inverse() * predicted * t_i_l,
            None => Isometry3::identity(),
        };
        let started = Instant::now();
        let matched = match (&mut self.map, &this.cloud) {
            (Some(map), Some(cloud)) => map.align(cloud, &(prev.t_map * guess)).map(|mut r| {
                // T_prev_this = T_map_prev^-1 T_map_this; the covariance of `[t; theta]`
                // moves with it: translation rotated into the previous scan's frame,
                // rotation (a right perturbation of this scan's pose) unchanged.
                this.t_map = r.t_target_source;
                r.t_target_source = prev.t_map.inverse() * r.t_target_source;
                let mut j = Matrix6::identity();
                j.fixed_view_mut::<3, 3>(0, 0)
                    .copy_from(prev.t_map.rotation.inverse().to_rotation_matrix().matrix());
                r.covariance = j * r.covariance * j.transpose();
                for c in [&mut r.covariance_sandwich, &mut r.covariance_clustered] {
                    *c = c.map(|c| j * c * j.transpose());
                }
                r
            }),
            _ => align(&prev.target, &points, &guess, &self.options.ndt),
        };
        self.timing.ndt += started.elapsed().as_secs_f64();
        let result = match matched {
            Ok(r) if r.converged && r.fitness >= self.options.min_fitness => r,
            Ok(r) => {
                record.fitness = Some(r.fitness);
                record.iterations = Some(r.iterations);
                let why = if let Some(d) = &r.degenerate {
                    format!("degenerate NDT match ({d:?})")
                } else if !r.converged {
                    "NDT did not converge".to_string()
                } else {
                    format!(
                        "NDT fitness {:.3} below {}",
                        r.fitness, self.options.min_fitness
                    )
                };
                self.start_chain(ekf, record, this, &why);
                return;
            }
            Err(e) => {
                self.start_chain(ekf, record, this, &format!("NDT failed: {e}"));
                return;
            }
        };
        record.fitness = Some(result.fitness);
        record.iterations = Some(result.iterations);
        let sigma_ratio = extrinsic_sigma_ratio(ekf, self.sensor).max(self.imu_sigma_ratio(ekf));
        let (covariance, ndt_share) = self.measurement_covariance(
            match self.options.ndt_covariance {
                NdtCovariance::Hessian => &result.covariance,
                // `calibrate` checked that `ndt.sandwich_covariance` computes these.
                NdtCovariance::Sandwich => result
                    .covariance_sandwich
                    .as_ref()
                    .unwrap_or(&result.covariance),
                NdtCovariance::Clustered => result
                    .covariance_clustered
                    .as_ref()
                    .unwrap_or(&result.covariance),
            },
            sigma_ratio,
        );
        self.updates += 1;
        let delta = result.t_target_source;
        self.book_innovation(&guess, &delta, &covariance);
        let rv = delta.rotation.scaled_axis();
        record.delta_rotation = Some([rv.x, rv.y, rv.z]);
        record.delta_translation = Some(delta.translation.vector.into());
        record.sigma = Some(std::array::from_fn(|i| covariance[(i, i)].sqrt()));
        record.ndt = Some(result.clone());
        record.predicted = Some(guess);
        let meas = RelativePose {
            stamp_from_ns: prev.ref_stamp_ns,
            stamp_to_ns: ref_stamp,
            delta: convert::pose::<T>(&delta),
            covariance: Matrix6::from_fn(|r, c| T::lit(covariance[(r, c)])),
        };
        match ekf.update_relative_pose(self.sensor, &meas) {
            Ok(report) => {
                // The update moved the current pose: keep the buffer continuous.
                let after = convert::isometry(&ekf.imu().pose());
                self.buffer.reanchor(&(after * predicted.inverse()));
                self.buffer.push(ekf.time_ns(), after);
                self.run.record_update(ekf, ref_stamp, &report);
                record.nis = Some(report.nis.to_f64());
                self.adapt(report.nis.to_f64() / report.dof.max(1) as f64, ndt_share);
                record.status = if report.accepted {
                    "matched".into()
                } else {
                    "rejected by the gate".into()
                };
                self.last_end_ns = Some(ref_stamp);
                if let (Some(map), Some(cloud)) = (&mut self.map, &this.cloud) {
                    map.insert(cloud, &this.t_map);
                }
                self.previous = Some(this);
                self.records.push(record);
            }
            Err(FilterError::NoAnchor | FilterError::OlderThanWindow) => {
                self.start_chain(ekf, record, this, "filter lost the anchor; restarted");
            }
            Err(e) => {
                self.reject(ekf, record, ref_stamp, &format!("update failed: {e}"));
            }
        }
    }

    /// Books one update's NIS/dof (and the NDT term's share of `R`) and, when due, adjusts
    /// the noise scale ([`NoiseAdaptation`]).
    fn adapt(&mut self, nis_per_dof: f64, ndt_share: f64) {
        let Some(a) = self.options.adapt else {
            return;
        };
        self.nis_per_dof.push((nis_per_dof.min(a.clip), ndt_share));
        let start = (a.start_after_anneals * self.options.anneal_updates).ceil() as usize;
        let n = self.nis_per_dof.len();
        if n < start + a.window.min(a.every) || n % a.every.max(1) != 0 {
            return;
        }
        let recent = &self.nis_per_dof[n - a.window.min(n - start)..];
        let count = recent.len().max(1) as f64;
        let mean = recent.iter().map(|(x, _)| x).sum::<f64>() / count;
        let share = recent.iter().map(|(_, w)| w).sum::<f64>() / count;
        if !mean.is_finite() || mean <= 0.0 || !share.is_finite() {
            return;
        }
        // Only the NDT term's share of the mismatch is the scale's to correct: while the
        // floor dominates `R`, the NIS says little about the scale.
        // With the NDT term inflated by `inflation` for correlated errors, a consistent
        // NIS/dof is about 1/inflation.
        let step = (mean * self.inflation)
            .powf(0.5 * share.clamp(0.0, 1.0))
            .clamp(1.0 / a.max_step, a.max_step);
        let base = self.options.covariance_scale[0].max(f64::MIN_POSITIVE);
        let scale = (base * self.adaptive_factor * step).clamp(a.bounds[0], a.bounds[1]);
        self.adaptive_factor = scale / base;
        if a.correlation_window > 0 {
            let pairs = &self.innovation_pairs[self
                .innovation_pairs
                .len()
                .saturating_sub(a.correlation_window)..];
            let (num, den) = pairs
                .iter()
                .fold((0.0, 0.0), |(n, d), (x, y)| (n + x, d + y));
            if pairs.len() * 2 >= a.correlation_window && den > 0.0 {
                let rho = (num / den).clamp(0.0, 0.95);
                self.inflation = ((1.0 + rho) / (1.0 - rho)).min(a.max_inflation);
            }
        }
    }

    /// Books the innovation `delta (-) guess` (the filter's prediction of the increment),
    /// normalised by `sqrt(R_ii)`, for the lag-1 autocorrelation of consecutive ones.
    fn book_innovation(
        &mut self,
        guess: &Isometry3<f64>,
        delta: &Isometry3<f64>,
        covariance: &Matrix6<f64>,
    ) {
        let r = (guess.rotation.inverse() * delta.rotation).scaled_axis();
        let t = delta.translation.vector - guess.translation.vector;
        let nu = Vector6::new(r.x, r.y, r.z, t.x, t.y, t.z);
        let u = Vector6::from_fn(|i, _| nu[i] / covariance[(i, i)].max(f64::MIN_POSITIVE).sqrt());
        if let Some(p) = self.last_innovation {
            self.innovation_pairs
                .push((u.dot(&p), 0.5 * (u.norm_squared() + p.norm_squared())));
        }
        self.last_innovation = Some(u);
    }

    /// `R = scale * Sigma_NDT + floor`, reordered from NDT's `[t; theta]` to the filter's
    /// `[theta; t]` (both: rotation a right perturbation, translation additive in the
    /// target = `from` frame).
    ///
    /// Also returns the NDT term's mean share of the diagonal of `R` (the adaptation's weight).
    ///
    /// The floor's excess over its final value decays with the update count and, with
    /// `anneal_by_sigma`, at least as fast as `sigma_ratio` (the filter's largest extrinsic
    /// sigma relative to its prior).
    fn measurement_covariance(&self, ndt: &Matrix6<f64>, sigma_ratio: f64) -> (Matrix6<f64>, f64) {
        let o = self.options;
        let mut decay = if o.anneal_updates > 0.0 {
            (-(self.updates as f64) / o.anneal_updates).exp()
        } else {
            0.0
        };
        if o.anneal_by_sigma && sigma_ratio.is_finite() {
            decay = decay.min(sigma_ratio.clamp(0.0, 1.0));
        }
        let floor = |initial: f64, last: f64| last + (initial - last).max(0.0) * decay;
        let floor_r = floor(o.initial_rotation_floor_rad, o.rotation_floor_rad);
        let floor_t = floor(o.initial_translation_floor_m, o.translation_floor_m);
        // S Sigma S with S = diag(sqrt(s_rot) I, sqrt(s_trans) I) keeps `c` positive definite.
        let s = |i: usize| {
            (o.covariance_scale[usize::from(i >= 3)] * self.adaptive_factor * self.inflation)
                .max(0.0)
                .sqrt()
        };
        let mut c = Matrix6::from_fn(|r, col| ndt[((r + 3) % 6, (col + 3) % 6)] * s(r) * s(col));
        let ndt_diagonal = c.diagonal();
        for i in 0..3 {
            c[(i, i)] += floor_r.powi(2);
            c[(i + 3, i + 3)] += floor_t.powi(2);
        }
        let share = (0..6)
            .map(|i| ndt_diagonal[i] / c[(i, i)].max(f64::MIN_POSITIVE))
            .sum::<f64>()
            / 6.0;
        ((c + c.transpose()) * 0.5, share)
    }

    /// Starts a new odometry chain at this scan (first scan, or after a failed match).
    fn start_chain<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        mut record: ScanRecord,
        mut this: Previous,
        why: &str,
    ) {
        match ekf.anchor(self.sensor, this.ref_stamp_ns) {
            Ok(()) => {
                // A new chain: the local map restarts in this scan's frame.
                this.t_map = Isometry3::identity();
                self.last_innovation = None;
                if let (Some(map), Some(cloud)) = (&mut self.map, &this.cloud) {
                    map.clear();
                    map.insert(cloud, &this.t_map);
                }
                if why != "anchor" {
                    self.run.skipped.push(format!(
                        "lidar0 scan {}: {why}; odometry restarted here",
                        record.stamp_ns
                    ));
                }
                record.status = why.to_string();
                self.last_end_ns = Some(this.ref_stamp_ns);
                self.previous = Some(this);
                self.records.push(record);
            }
            Err(e) => {
                let stamp = this.ref_stamp_ns;
                self.reject(ekf, record, stamp, &format!("cannot anchor: {e}"));
            }
        }
    }

    /// Skips a processed scan and breaks the odometry chain.
    fn reject<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        _ekf: &mut Ekf<T, S, C, N, F>,
        mut record: ScanRecord,
        ref_stamp: u64,
        why: &str,
    ) {
        self.run
            .skipped
            .push(format!("lidar0 scan {}: {why}", record.stamp_ns));
        record.status = why.to_string();
        self.previous = None;
        self.last_innovation = None;
        self.last_end_ns = Some(ref_stamp);
        self.records.push(record);
    }
}
