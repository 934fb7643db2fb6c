//! Pose-IMU calibration (motion based, dissertation ch. 3.5 / 4.4 with a generic pose
//! sensor): hand-eye rotation init, then the error-state EKF fed with IMU samples and the
//! odometry's relative poses, estimating `T_imu_pose` and the time offset.
//!
//! Event order: a pose stamped `t_S` belongs at IMU time `t_S + t_d`; it is fused as soon as
//! the filter holds an IMU sample at or after that time (`Ekf::is_due`; the filter
//! propagates over the readings interpolated to it), with the current estimate of `t_d`.

use super::InputError;
use std::time::Instant;

use msreg_estimator::{
    health::HealthEvent, Ekf, Error as FilterError, FilterConfig, ImuSample, InitialState,
    PoseImuEkf, RelativePose, Scalar, UpdateReport,
};
use nalgebra::{Isometry3, Matrix6, Vector3};
use serde::Serialize;

use super::convert;
use super::dynamic_init::{self, DynamicInitInput, DynamicInitOptions, FilterPrior};
use super::extrinsic::ImuExtrinsicCalibration;
use super::gyro_bias::{self, GyroBiasEstimate};
use super::init::{self, Standstill};
use super::observability::{self, DofObservability, HeldDirection};
use super::planar::{self, PlanarStart};
use crate::dataset::{ImuNoiseYaml, ImuRecord, PoseRecord, PoseSensorYaml};

/// What the pipeline reads.
#[derive(Debug, Clone, Copy)]
pub struct PoseImuInput<'a> {
    /// IMU samples, strictly increasing stamps.
    pub imu: &'a [ImuRecord],
    /// IMU noise densities.
    pub imu_noise: &'a ImuNoiseYaml,
    /// Odometry of the pose sensor (arbitrary origin).
    pub poses: &'a [PoseRecord],
    /// Noise of one odometry increment.
    pub pose_noise: &'a PoseSensorYaml,
}

/// Tuning of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseImuOptions {
    /// Estimate the pose sensor's time offset.
    pub estimate_time_offset: bool,
    /// Prior 1-sigma of the time offset, s.
    pub time_offset_sigma_s: f64,
    /// Prior 1-sigma of the extrinsic rotation after the hand-eye init, rad.
    pub rotation_sigma_rad: f64,
    /// Prior 1-sigma of the extrinsic translation (initialised at zero), m.
    pub translation_sigma_m: f64,
    /// Shortest standstill at the start that is used for the gravity/bias initialisation, s.
    pub min_standstill_s: f64,
}

impl Default for PoseImuOptions {
    fn default() -> Self {
        Self {
            estimate_time_offset: true,
            time_offset_sigma_s: 0.05,
            rotation_sigma_rad: 2f64.to_radians(),
            translation_sigma_m: 0.5,
            min_standstill_s: 0.3,
        }
    }
}

/// One point of the convergence history (after each relative-pose update).
#[derive(Debug, Clone, Serialize)]
pub struct HistoryPoint {
    /// Seconds since the first IMU sample.
    pub t_s: f64,
    /// Extrinsic rotation as a rotation vector, rad.
    pub rotation_vector: [f64; 3],
    /// Extrinsic translation, m.
    pub translation_m: [f64; 3],
    /// 1-sigma rotation, deg.
    pub sigma_rot_deg: [f64; 3],
    /// 1-sigma translation, m.
    pub sigma_trans_m: [f64; 3],
    /// Time offset, s.
    pub time_offset_s: f64,
    /// 1-sigma time offset, s.
    pub sigma_time_offset_s: f64,
    /// NIS of the update.
    pub nis: f64,
    /// Whether the gate accepted it.
    pub accepted: bool,
}

/// A health event, for the report.
#[derive(Debug, Clone, Serialize)]
pub struct EventRecord {
    /// Seconds since the first IMU sample.
    pub t_s: f64,
    /// `rotation_step` or `translation_step`.
    pub kind: &'static str,
    /// GLR statistic.
    pub statistic: f64,
    /// Estimated step size (rad or m).
    pub magnitude: f64,
}

/// The JSON report of a pose-IMU calibration.
#[derive(Debug, Clone, Serialize)]
pub struct PoseImuReport {
    /// True when all convergence checks passed.
    pub converged: bool,
    /// Why not, when not.
    pub reasons: Vec<String>,
    /// Scalar type the filter ran in.
    pub scalar: &'static str,
    /// Standstill used for initialisation, s (0 when none).
    pub standstill_s: f64,
    /// How the IMU state was initialised without a standstill: the dynamic alignment's
    /// result, or why it could not run (empty with a standstill).
    pub moving_start: String,
    /// Where the gyro bias the filter started from came from: the standstill, a fit to the
    /// rotation increments (with its sigma), or nowhere (zero, wide prior).
    pub gyro_bias_init: String,
    /// Planar motion (rotation about one axis) and how the rotation about it was found;
    /// empty when the motion turns about more than one axis.
    pub planar: String,
    /// Per DoF: observed, weak or not observable, and why.
    pub observability: Vec<DofObservability>,
    /// The lever-arm direction held at its prior (unit, IMU frame), if any.
    pub held_axis: Option<[f64; 3]>,
    /// Hand-eye pairs used.
    pub hand_eye_pairs: usize,
    /// Second/first eigenvalue of the rotation scatter (excitation about two axes).
    pub hand_eye_axis_ratio: f64,
    /// Hand-eye rotation (rotation vector, rad) the filter started from.
    pub hand_eye_rotation_vector: [f64; 3],
    /// Relative-pose updates fused.
    pub updates_accepted: usize,
    /// Relative-pose updates rejected by the gate.
    pub updates_rejected: usize,
    /// Poses skipped (before the IMU, after a filter error), with reasons.
    pub poses_skipped: Vec<String>,
    /// Mean NIS per degree of freedom of all relative-pose updates (1 if consistent).
    pub mean_nis_per_dof: f64,
    /// Excitation per extrinsic DoF: 1 - sigma/prior (rx, ry, rz, tx, ty, tz, t_d).
    pub excitation: [f64; 7],
    /// Health events.
    pub events: Vec<EventRecord>,
    /// Wall time of the stages, s.
    pub timing_s: Timing,
    /// Convergence history.
    pub history: Vec<HistoryPoint>,
}

/// Wall time per stage.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct Timing {
    /// Standstill detection and hand-eye rotation.
    pub init: f64,
    /// The filter over the whole recording.
    pub filter: f64,
}

/// The outcome: `T_imu_pose` with its covariance, the time offset, and the report.
pub type PoseImuCalibration = ImuExtrinsicCalibration<PoseImuReport>;

/// Runs the calibration with the filter in scalar type `T`; `progress` gets the fraction
/// of the recording processed.
pub fn calibrate<T: Scalar>(
    input: &PoseImuInput<'_>,
    options: &PoseImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<PoseImuCalibration, InputError> {
    let (imu, poses) = (input.imu, input.poses);
    let (Some(first_imu), Some(_)) = (imu.first(), imu.last()) else {
        return Err(InputError::NoImuSamples);
    };
    if poses.len() < 3 {
        return Err(InputError::TooFew {
            file: "pose0/data.csv",
            what: "poses",
            found: poses.len(),
            needed: 3,
        });
    }
    let started = Instant::now();
    let standstill = init::detect_standstill(imu, options.min_standstill_s);
    let period_ns = nominal_period_ns(poses);
    let max_interval_ns = period_ns.saturating_mul(3) / 2;
    let increments = init::pose_increments(poses, max_interval_ns);
    let (rotation, gyro_bias) = hand_eye_and_gyro_bias(imu, &increments, standstill.as_ref());
    let bias = starting_gyro_bias(standstill.as_ref(), gyro_bias.as_ref());
    let pairs = init::rotation_pairs(imu, increments.iter().copied(), &bias);
    let scale_problem = rotation_scale_problem(&pairs);
    let planar = planar::planar_start(
        (imu, poses),
        (&increments, &pairs),
        (bias, standstill.is_some()),
        input.imu_noise.accelerometer_noise_density,
    );
    let (rotation, gyro_bias) = match &planar {
        Some(p) => (Ok(p.rotation_init()), p.gyro_bias.or(gyro_bias)),
        None => (rotation, gyro_bias),
    };
    let init_s = started.elapsed().as_secs_f64();
    let FilterStart {
        mut ekf,
        rotation_init,
        init_problem,
        moving_start,
        gyro_bias_init,
    } = start_filter::<T>(
        imu,
        input.imu_noise,
        (standstill.as_ref(), poses),
        (rotation, gyro_bias.as_ref()),
        (options, planar.as_ref()),
    )?;

    let started = Instant::now();
    let mut feed = PoseFeed {
        run: Run::new(first_imu.stamp_ns, period_ns),
        poses,
        next_pose: 0,
        sigma_r: input.pose_noise.rotation_noise_rad,
        sigma_t: input.pose_noise.translation_noise_m,
    };
    drive_imu(&mut ekf, imu, standstill.as_ref(), progress, &mut feed)?;
    let PoseFeed {
        mut run, next_pose, ..
    } = feed;
    for pose in &poses[next_pose..] {
        run.skip(pose.stamp_ns, "after the last IMU sample");
    }
    progress(1.0);
    let filter_s = started.elapsed().as_secs_f64();

    let mut calibration = finish(
        &ekf,
        run,
        standstill.as_ref(),
        &rotation_init,
        Timing {
            init: init_s,
            filter: filter_s,
        },
    );
    if let Some(problem) = init_problem {
        calibration.report.reasons.insert(0, problem);
        calibration.report.converged = false;
    }
    if let Some(problem) = scale_problem {
        calibration.report.reasons.insert(0, problem);
        calibration.report.converged = false;
    }
    calibration.report.moving_start = describe_moving_start(&moving_start);
    calibration.report.gyro_bias_init = gyro_bias_init;
    calibration.report.planar = planar.as_ref().map_or_else(String::new, |p| p.describe());
    Ok(calibration)
}

/// Largest factor by which the pose sensor's and the gyro's total rotation may differ: a few
/// percent is noise and slip; a gyro in deg/s reads 57x, skid-steer wheel odometry
/// several times the true turn.
const MAX_ROTATION_SCALE: f64 = 1.25;

/// The reason to distrust the result when the pose sensor and the gyro disagree on how much
/// the body turned (see [`init::rotation_scale`]).
fn rotation_scale_problem(pairs: &[planar::RotationPair]) -> Option<String> {
    let scale = init::rotation_scale(pairs)?;
    (!(1.0 / MAX_ROTATION_SCALE..=MAX_ROTATION_SCALE).contains(&scale)).then(|| {
        format!(
            "pose0 turns {scale:.2}x as much as the gyro over the same intervals: the odometry's \
             rotation is not the body's (wheel slip of a skid-steer base, or a unit error in \
             pose0 or imu0)"
        )
    })
}

/// The gyro bias known before the filter: the standstill's mean, else the motion fit, else
/// zero.
fn starting_gyro_bias(
    standstill: Option<&Standstill>,
    fitted: Option<&GyroBiasEstimate>,
) -> Vector3<f64> {
    match (standstill, fitted) {
        (Some(s), _) => s.gyro_mean,
        (None, Some(f)) => f.bias,
        (None, None) => Vector3::zeros(),
    }
}

/// The hand-eye rotation from the rotation `increments` and the gyro bias: at a standstill
/// the hand-eye at its mean gyro reading (no fit: the standstill measures the bias), else
/// both from the motion ([`gyro_bias::hand_eye_with_gyro_bias`]).
pub(crate) fn hand_eye_and_gyro_bias(
    imu: &[ImuRecord],
    increments: &[init::RotationIncrement],
    standstill: Option<&Standstill>,
) -> (
    Result<init::RotationInit, msreg_estimator::HandEyeError<f64>>,
    Option<GyroBiasEstimate>,
) {
    match standstill {
        Some(s) => {
            let pairs = init::rotation_pairs(imu, increments.iter().copied(), &s.gyro_mean);
            (init::hand_eye_from_pairs(pairs, HAND_EYE_MIN_PAIRS), None)
        }
        None => gyro_bias::hand_eye_with_gyro_bias(imu, increments, HAND_EYE_MIN_PAIRS),
    }
}

/// Fewest rotation increments for the hand-eye rotation.
pub(crate) const HAND_EYE_MIN_PAIRS: usize = 10;

/// The pose-IMU pipeline's measurement feed: fuses every pose whose IMU time has come.
struct PoseFeed<'a> {
    run: Run,
    poses: &'a [PoseRecord],
    next_pose: usize,
    sigma_r: f64,
    sigma_t: f64,
}

impl<T: Scalar> ImuHooks<T> for PoseFeed<'_> {
    fn fuse_due(
        &mut self,
        ekf: &mut PoseImuEkf<T>,
        index: usize,
        _rec: &ImuRecord,
    ) -> Result<(), InputError> {
        while let Some(pose) = self.poses.get(self.next_pose) {
            if !ekf.is_due(0, pose.stamp_ns) {
                break;
            }
            if index == 0 {
                self.run.skip(pose.stamp_ns, "before the first IMU sample");
            } else {
                self.run.fuse_pose(ekf, pose, self.sigma_r, self.sigma_t);
            }
            self.next_pose += 1;
        }
        Ok(())
    }
}

/// What a pipeline does around each IMU sample of [`drive_imu`], for a filter `E`.
pub(crate) trait ImuHooks<T: Scalar, E = PoseImuEkf<T>> {
    /// After sample `index` (`rec`) was fed (the filter stands at the previous sample and
    /// holds `rec` as its look-ahead): fuse every measurement that is now due
    /// (`msreg_estimator::Ekf::is_due`).
    fn fuse_due(&mut self, ekf: &mut E, index: usize, rec: &ImuRecord) -> Result<(), InputError>;

    /// After sample `rec` was fed (and a standstill ZUPT applied), before `fuse_due`.
    fn after_sample(&mut self, _ekf: &E, _rec: &ImuRecord) {}
}

/// What [`drive_imu`] needs of a filter, whatever its layout.
pub(crate) trait ImuFilter<T: Scalar> {
    /// Feeds one IMU sample.
    fn propagate(&mut self, sample: &ImuSample<T>) -> Result<(), FilterError>;
    /// Zero-velocity update with the latest sample.
    fn update_zero_velocity(&mut self) -> Result<UpdateReport<T>, FilterError>;
    /// The IMU stream's period, once two samples are in (a ZUPT needs it).
    fn imu_period_ns(&self) -> Option<u64>;
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> ImuFilter<T>
    for Ekf<T, S, C, N, F>
{
    fn propagate(&mut self, sample: &ImuSample<T>) -> Result<(), FilterError> {
        Ekf::propagate(self, sample)
    }

    fn update_zero_velocity(&mut self) -> Result<UpdateReport<T>, FilterError> {
        Ekf::update_zero_velocity(self)
    }

    fn imu_period_ns(&self) -> Option<u64> {
        Ekf::imu_period_ns(self)
    }
}

/// Runs the filter over the IMU record: measurements via `hooks`, propagation, zero-velocity
/// updates during the initial standstill, progress.
pub(crate) fn drive_imu<T: Scalar, E: ImuFilter<T>>(
    ekf: &mut E,
    imu: &[ImuRecord],
    standstill: Option<&Standstill>,
    progress: &mut dyn FnMut(f64),
    hooks: &mut dyn ImuHooks<T, E>,
) -> Result<(), InputError> {
    let (Some(first_imu), Some(last_imu)) = (imu.first(), imu.last()) else {
        return Ok(());
    };
    let total = (last_imu.stamp_ns - first_imu.stamp_ns).max(1) as f64;
    for (i, rec) in imu.iter().enumerate() {
        ekf.propagate(&convert::imu_sample::<T>(rec))
            .map_err(|error| InputError::ImuSample {
                error,
                stamp_ns: rec.stamp_ns,
                sample: i + 1,
            })?;
        let at_rest = standstill.is_some_and(|s| rec.stamp_ns <= s.until_ns);
        if at_rest && i % 20 == 0 && ekf.imu_period_ns().is_some() {
            // A gated-out ZUPT is a report, not an error; an error is one.
            ekf.update_zero_velocity()
                .map_err(|error| InputError::ZeroVelocity {
                    error,
                    stamp_ns: rec.stamp_ns,
                    sample: i + 1,
                })?;
        }
        hooks.after_sample(ekf, rec);
        hooks.fuse_due(ekf, i, rec)?;
        if i % 2000 == 0 {
            progress((rec.stamp_ns - first_imu.stamp_ns) as f64 / total);
        }
    }
    Ok(())
}

/// A filter ready to run, with how its extrinsic rotation was initialised.
pub(crate) struct FilterStart<T: Scalar> {
    pub(crate) ekf: PoseImuEkf<T>,
    pub(crate) rotation_init: init::RotationInit,
    /// Why the hand-eye initialisation failed, when it did.
    pub(crate) init_problem: Option<String>,
    /// The moving-start prior, or why there is none.
    pub(crate) moving_start: Result<FilterPrior, MovingStart>,
    /// Where the starting gyro bias came from (report words).
    pub(crate) gyro_bias_init: String,
}

/// Builds the filter from the standstill and the hand-eye result. Without rotation about two
/// axes the hand-eye rotation is undetermined: the filter still runs (from identity, wide
/// open) so the result and report exist, but it cannot converge.
pub(crate) fn start_filter<T: Scalar>(
    imu: &[ImuRecord],
    imu_noise: &ImuNoiseYaml,
    (standstill, odometry): (Option<&Standstill>, &[PoseRecord]),
    (rotation, gyro_bias): (
        Result<init::RotationInit, msreg_estimator::HandEyeError<f64>>,
        Option<&GyroBiasEstimate>,
    ),
    (options, planar): (&PoseImuOptions, Option<&PlanarStart>),
) -> Result<FilterStart<T>, InputError> {
    let (rotation_init, init_problem) = match rotation {
        Ok(r) => (r, None),
        Err(e) => (
            init::RotationInit {
                rotation: nalgebra::UnitQuaternion::identity(),
                pairs: 0,
                axis_ratio: 0.0,
            },
            Some(format!(
                "hand-eye rotation initialisation failed ({e:?}): the recording needs \
                 rotation about at least two axes"
            )),
        ),
    };
    let mut options = *options;
    if init_problem.is_some() {
        options.rotation_sigma_rad = 0.5;
    }
    if let Some(p) = planar {
        options.rotation_sigma_rad = p.rotation_sigma(options.rotation_sigma_rad);
    }
    let moving = match (standstill, init_problem.is_none()) {
        (None, true) => moving_start(
            imu,
            odometry,
            &rotation_init.rotation,
            (gyro_bias, 0.0),
            imu_noise,
        ),
        _ => Err(MovingStart::NotNeeded),
    };
    let initial = initial_state::<T>(imu, standstill, &rotation_init.rotation, &options)?;
    let (initial, gyro_bias_init) = with_gyro_bias(initial, standstill, gyro_bias);
    let initial = match &moving {
        Ok(prior) => with_moving_start(initial, prior),
        Err(_) => initial,
    };
    let config = FilterConfig::new(convert::imu_noise::<T>(imu_noise));
    let initial = match planar {
        Some(p) => p.with_lever_arm_prior(initial),
        None => initial,
    };
    let mut ekf = PoseImuEkf::<T>::new(&config, &initial)
        .map_err(|error| InputError::InvalidNoise { error })?;
    if let Some(p) = planar {
        ekf.hold_translation_axis(0, Some(convert::vec3(&p.motion.axis_imu)))
            .map_err(|error| InputError::PlanarAxis { error })?;
    }
    Ok(FilterStart {
        ekf,
        rotation_init,
        init_problem,
        moving_start: moving,
        gyro_bias_init,
    })
}

/// Smallest 1-sigma of a gyro bias fitted to motion, rad/s: the fit's own sigma ignores
/// the correlation of consecutive increments and the bias's drift over the recording.
const MIN_FITTED_GYRO_BIAS_SIGMA: f64 = 2e-3;
/// 1-sigma of the gyro bias when nothing measured it (no standstill, no fit), rad/s: MEMS
/// turn-on biases of a few deg/s (the EuRoC ADIS16448 reads 4.4 deg/s) are inside 1 sigma.
const UNKNOWN_GYRO_BIAS_SIGMA: f64 = 0.1;

/// The prior's gyro bias without a standstill: the motion fit with its (floored) sigma, or
/// zero with [`UNKNOWN_GYRO_BIAS_SIGMA`]; with the report's words for it.
pub(crate) fn with_gyro_bias<T: Scalar>(
    mut initial: InitialState<T, 1>,
    standstill: Option<&Standstill>,
    fit: Option<&GyroBiasEstimate>,
) -> (InitialState<T, 1>, String) {
    let words = match (standstill, fit) {
        (Some(_), _) => "standstill mean".to_string(),
        (None, Some(f)) => {
            initial.imu.gyro_bias = convert::vec3(&f.bias);
            initial.sigma_gyro_bias = T::lit(f.sigma.amax().max(MIN_FITTED_GYRO_BIAS_SIGMA));
            format!(
                "fitted to {} rotation increments: [{:.4}, {:.4}, {:.4}] rad/s (sigma [{:.4}, \
                 {:.4}, {:.4}])",
                f.pairs, f.bias.x, f.bias.y, f.bias.z, f.sigma.x, f.sigma.y, f.sigma.z
            )
        }
        (None, None) => {
            initial.sigma_gyro_bias = T::lit(UNKNOWN_GYRO_BIAS_SIGMA);
            format!("unknown: zero with sigma {UNKNOWN_GYRO_BIAS_SIGMA} rad/s")
        }
    };
    (initial, words)
}

/// Why no moving-start prior was used.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum MovingStart {
    /// A standstill gives gravity and the gyro bias directly, or the hand-eye rotation
    /// failed (nothing to align with).
    NotNeeded,
    /// The dynamic initialisation could not run (its reason).
    Failed(MovingStartFailure),
}

/// Why the dynamic initialisation of a moving start could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MovingStartFailure {
    /// The alignment of the odometry with the pre-integrated IMU failed.
    #[error(transparent)]
    Alignment(#[from] dynamic_init::DynamicInitError),
    /// The first IMU sample lies outside the aligned odometry.
    #[error("the first IMU sample is outside the data")]
    OutsideData,
    /// No LiDAR odometry in the first seconds to align with.
    #[error("no LiDAR odometry in the first seconds")]
    NoOdometry,
}

/// The report's words for a moving start.
pub(crate) fn describe_moving_start(m: &Result<FilterPrior, MovingStart>) -> String {
    match m {
        Ok(p) => format!(
            "dynamic alignment: gravity tilt sigma {:.3} deg, velocity sigma {:.3} m/s, lever \
             arm [{:.3}, {:.3}, {:.3}] m (sigma [{:.3}, {:.3}, {:.3}])",
            p.sigma_orientation.to_degrees(),
            p.sigma_velocity,
            p.t_imu_sensor.translation.x,
            p.t_imu_sensor.translation.y,
            p.t_imu_sensor.translation.z,
            p.sigma_translation.x,
            p.sigma_translation.y,
            p.sigma_translation.z
        ),
        Err(MovingStart::NotNeeded) => String::new(),
        Err(MovingStart::Failed(why)) => {
            format!("dynamic alignment failed ({why}): level start with wide sigmas")
        }
    }
}

/// Floors of the moving-start prior's sigmas. The alignment assumes `t_d = 0`; an offset
/// of `sigma_td` (5-20 ms) moves the odometry against the IMU by `|a| sigma_td`, ~0.1 m/s at
/// 5 m/s^2 and 20 ms, and tilts gravity by that over |g|, ~0.6 deg: floors of that size
/// keep the prior honest whatever the offset.
const MOVING_START_MIN_SIGMA_VELOCITY: f64 = 0.1;
const MOVING_START_MIN_SIGMA_TILT_RAD: f64 = 0.6 * std::f64::consts::PI / 180.0;

/// The filter prior at the first IMU sample from a moving start: gravity, velocity, biases
/// and lever arm by the dynamic initialisation (VINS-Mono-style alignment of the odometry
/// with the pre-integrated IMU; `dynamic_init`), given the gyro bias and the time offset
/// `t_d` of the odometry (0 when unknown, as for pose-IMU; camera-IMU passes MoCal's).
pub(crate) fn moving_start(
    imu: &[ImuRecord],
    odometry: &[PoseRecord],
    rotation: &nalgebra::UnitQuaternion<f64>,
    (gyro_bias, time_offset_s): (Option<&GyroBiasEstimate>, f64),
    imu_noise: &ImuNoiseYaml,
) -> Result<FilterPrior, MovingStart> {
    let input = DynamicInitInput {
        imu,
        poses: odometry,
        r_i_s: *rotation,
        gyro_bias: gyro_bias.map_or_else(Vector3::zeros, |g| g.bias),
        time_offset_s,
    };
    let options = DynamicInitOptions {
        accel_noise_density: imu_noise.accelerometer_noise_density,
        ..DynamicInitOptions::default()
    };
    let solution =
        dynamic_init::initialise(&input, &options).map_err(|e| MovingStart::Failed(e.into()))?;
    solution
        .filter_prior(imu, 0.0)
        .ok_or(MovingStart::Failed(MovingStartFailure::OutsideData))
}

/// The prior with the moving start's IMU state: orientation, velocity and biases with their
/// sigmas (floored, see above); the extrinsic translation starts at the aligned lever arm
/// with the pipeline's own (wide) sigma, so the alignment improves the linearisation point
/// without claiming its precision.
pub(crate) fn with_moving_start<T: Scalar>(
    mut initial: InitialState<T, 1>,
    prior: &FilterPrior,
) -> InitialState<T, 1> {
    let pose = convert::pose::<T>(&Isometry3::from_parts(Default::default(), prior.rotation));
    initial.imu.rotation = pose.rotation;
    initial.imu.velocity = convert::vec3(&prior.velocity);
    initial.imu.gyro_bias = convert::vec3(&prior.gyro_bias);
    initial.imu.accel_bias = convert::vec3(&prior.accel_bias);
    initial.sigma_orientation =
        T::lit(prior.sigma_orientation.max(MOVING_START_MIN_SIGMA_TILT_RAD));
    initial.sigma_velocity = T::lit(prior.sigma_velocity.max(MOVING_START_MIN_SIGMA_VELOCITY));
    initial.sensors[0].state.extrinsic.translation =
        convert::vec3(&prior.t_imu_sensor.translation.vector);
    initial
}

/// Median spacing of the odometry, ns.
pub(crate) fn nominal_period_ns(poses: &[PoseRecord]) -> u64 {
    let mut d: Vec<u64> = poses
        .windows(2)
        .map(|w| w[1].stamp_ns - w[0].stamp_ns)
        .collect();
    d.sort_unstable();
    d.get(d.len() / 2).copied().unwrap_or(100_000_000)
}

/// The filter prior: at rest if the recording starts still, else level with large sigmas.
pub(crate) fn initial_state<T: Scalar>(
    imu: &[ImuRecord],
    standstill: Option<&Standstill>,
    rotation: &nalgebra::UnitQuaternion<f64>,
    options: &PoseImuOptions,
) -> Result<InitialState<T, 1>, InputError> {
    let accel = standstill.map_or_else(
        || {
            let n = imu.len().min(400);
            imu[..n].iter().map(|r| r.accel).sum::<Vector3<f64>>() / n as f64
        },
        |s| s.accel_mean,
    );
    let mut state =
        InitialState::<T, 1>::at_rest(convert::vec3(&accel)).ok_or(InputError::NotGravity {
            accel_norm: accel.norm(),
        })?;
    match standstill {
        Some(s) => {
            state.imu.gyro_bias = convert::vec3(&s.gyro_mean);
        }
        None => {
            // Moving start: gravity direction and velocity are only roughly known.
            state.sigma_orientation = T::lit(0.1);
            state.sigma_velocity = T::lit(1.0);
        }
    }
    let extrinsic = msreg_estimator::Pose::new(
        convert::pose::<T>(&Isometry3::from_parts(Default::default(), *rotation)).rotation,
        Vector3::zeros(),
    );
    let td_sigma = if options.estimate_time_offset {
        options.time_offset_sigma_s
    } else {
        0.0
    };
    Ok(state
        .with_extrinsic(
            0,
            extrinsic,
            T::lit(options.rotation_sigma_rad),
            T::lit(options.translation_sigma_m),
        )
        .with_time_offset(0, T::zero(), T::lit(td_sigma)))
}

/// Bookkeeping of one run over the recording.
pub(crate) struct Run {
    /// The filter's index of the sensor whose measurements this run books.
    sensor: usize,
    start_ns: u64,
    max_interval_ns: u64,
    period_ns: u64,
    previous: Option<PoseRecord>,
    history: Vec<HistoryPoint>,
    events: Vec<EventRecord>,
    /// Measurements skipped, with reasons (report).
    pub(crate) skipped: Vec<String>,
    accepted: usize,
    rejected: usize,
    nis_sum: f64,
    nis_dof: usize,
}

impl Run {
    pub(crate) fn new(start_ns: u64, period_ns: u64) -> Self {
        Self {
            sensor: 0,
            start_ns,
            max_interval_ns: period_ns.saturating_mul(10),
            period_ns,
            previous: None,
            history: Vec::new(),
            events: Vec::new(),
            skipped: Vec::new(),
            accepted: 0,
            rejected: 0,
            nis_sum: 0.0,
            nis_dof: 0,
        }
    }

    /// The same run booking sensor `s` of the filter (0 unless the filter has several).
    pub(crate) fn for_sensor(mut self, s: usize) -> Self {
        self.sensor = s;
        self
    }

    pub(crate) fn seconds(&self, stamp_ns: u64) -> f64 {
        stamp_ns.saturating_sub(self.start_ns) as f64 * 1e-9
    }

    fn skip(&mut self, stamp_ns: u64, why: &str) {
        self.skip_measurement("pose0", stamp_ns, why);
    }

    /// Books a measurement of `sensor` that was not fused, with the reason.
    pub(crate) fn skip_measurement(&mut self, sensor: &str, stamp_ns: u64, why: &str) {
        self.skipped
            .push(format!("{sensor} stamp {stamp_ns}: {why}"));
    }

    /// Anchors a new odometry segment or fuses the increment from the previous pose.
    fn fuse_pose<T: Scalar>(
        &mut self,
        ekf: &mut PoseImuEkf<T>,
        pose: &PoseRecord,
        sigma_r: f64,
        sigma_t: f64,
    ) {
        let previous = self
            .previous
            .filter(|p| pose.stamp_ns - p.stamp_ns <= self.max_interval_ns);
        let Some(prev) = previous else {
            match ekf.anchor(0, pose.stamp_ns) {
                Ok(()) => self.previous = Some(*pose),
                Err(e) => self.skip(pose.stamp_ns, &format!("cannot anchor: {e}")),
            }
            return;
        };
        // Odometry noise accumulates per increment: an interval spanning several nominal
        // periods (a gap) carries the noise of all of them.
        let periods = ((pose.stamp_ns - prev.stamp_ns) as f64 / self.period_ns as f64)
            .round()
            .max(1.0);
        let scale = periods.sqrt();
        let delta = prev.isometry().inverse() * pose.isometry();
        let meas = RelativePose::with_sigmas(
            prev.stamp_ns,
            pose.stamp_ns,
            convert::pose::<T>(&delta),
            T::lit(sigma_r * scale),
            T::lit(sigma_t * scale),
        );
        match ekf.update_relative_pose(0, &meas) {
            Ok(report) => {
                self.previous = Some(*pose);
                self.record_update(ekf, pose.stamp_ns, &report);
            }
            Err(FilterError::NoAnchor | FilterError::OlderThanWindow) => {
                self.previous = None;
                self.fuse_pose(ekf, pose, sigma_r, sigma_t);
            }
            Err(e) => self.skip(pose.stamp_ns, &format!("{e}")),
        }
    }

    /// Books a relative-pose update of the measurement stamped `stamp_ns`: counts, NIS,
    /// health events and a history point.
    pub(crate) fn record_update<
        T: Scalar,
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
        stamp_ns: u64,
        report: &msreg_estimator::UpdateReport<T>,
    ) {
        if report.accepted {
            self.accepted += 1;
        } else {
            self.rejected += 1;
        }
        self.nis_sum += report.nis.to_f64();
        self.nis_dof += report.dof;
        if let Some(event) = report.event {
            self.events.push(self.event_record(&event));
        }
        self.history.push(history_point(
            ekf,
            self.sensor,
            self.seconds(stamp_ns),
            report.nis.to_f64(),
            report.accepted,
        ));
    }

    fn event_record<T: Scalar>(&self, event: &HealthEvent<T>) -> EventRecord {
        match *event {
            HealthEvent::RotationStep {
                stamp_ns,
                statistic,
                step,
                ..
            } => EventRecord {
                t_s: self.seconds(stamp_ns),
                kind: "rotation_step",
                statistic: statistic.to_f64(),
                magnitude: step.norm().to_f64(),
            },
            HealthEvent::TranslationStep {
                stamp_ns,
                statistic,
                step,
                ..
            } => EventRecord {
                t_s: self.seconds(stamp_ns),
                kind: "translation_step",
                statistic: statistic.to_f64(),
                magnitude: step.norm().to_f64(),
            },
        }
    }
}

fn history_point<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
    ekf: &Ekf<T, S, C, N, F>,
    s: usize,
    t_s: f64,
    nis: f64,
    accepted: bool,
) -> HistoryPoint {
    let x = convert::isometry(&ekf.extrinsic(s));
    let (sr, st) = ekf.extrinsic_sigma(s);
    let rv = x.rotation.scaled_axis();
    HistoryPoint {
        t_s,
        rotation_vector: [rv.x, rv.y, rv.z],
        translation_m: [x.translation.x, x.translation.y, x.translation.z],
        sigma_rot_deg: [0, 1, 2].map(|i| sr[i].to_f64().to_degrees()),
        sigma_trans_m: [0, 1, 2].map(|i| st[i].to_f64()),
        time_offset_s: ekf.time_offset(s).to_f64(),
        sigma_time_offset_s: ekf.time_offset_sigma(s).to_f64(),
        nis,
        accepted,
    }
}

/// Largest final 1-sigma rotation (deg) of a converged calibration.
const CONVERGED_SIGMA_ROT_DEG: f64 = 0.5;
/// Largest final 1-sigma translation (m) of a converged calibration.
const CONVERGED_SIGMA_TRANS_M: f64 = 0.02;

pub(crate) fn finish<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
    ekf: &Ekf<T, S, C, N, F>,
    run: Run,
    standstill: Option<&Standstill>,
    rotation_init: &init::RotationInit,
    timing: Timing,
) -> PoseImuCalibration {
    let s = run.sensor;
    let covariance = Matrix6::from_fn(|r, c| ekf.extrinsic_covariance(s)[(r, c)].to_f64());
    let (sr, st) = ekf.extrinsic_sigma(s);
    let mut reasons = Vec::new();
    let max_sr = sr.amax().to_f64().to_degrees();
    let held = ekf.held_translation_axis(s).map(|a| HeldDirection {
        axis: convert::vec3_f64(&a),
        reason: "planar motion (rotation about one axis)".to_string(),
    });
    let translation_cov = covariance.fixed_view::<3, 3>(3, 3).clone_owned();
    let (max_st, worst) =
        observability::largest_sigma_across(&translation_cov, held.as_ref().map(|h| &h.axis));
    if max_sr > CONVERGED_SIGMA_ROT_DEG {
        let axes = observability::axes_above(
            &sr.map(|x| x.to_f64().to_degrees()),
            CONVERGED_SIGMA_ROT_DEG,
        );
        reasons.push(format!(
            "rotation about {axes}: sigma up to {max_sr:.3} deg > {CONVERGED_SIGMA_ROT_DEG} deg: \
             not enough rotation"
        ));
    }
    if max_st > CONVERGED_SIGMA_TRANS_M {
        reasons.push(format!(
            "translation along [{:.2}, {:.2}, {:.2}]: sigma {max_st:.4} m > \
             {CONVERGED_SIGMA_TRANS_M} m: not enough rotation to observe the lever arm",
            worst.x, worst.y, worst.z
        ));
    }
    let total = run.accepted + run.rejected;
    if total == 0 || run.rejected * 10 > total {
        reasons.push(format!(
            "{} of {} relative poses rejected by the gate: odometry noise or time offset \
             mismatched",
            run.rejected, total
        ));
    }
    let mean_nis = run.nis_sum / run.nis_dof.max(1) as f64;
    let rv = rotation_init.rotation.scaled_axis();
    let excitation = ekf.excitation(s).map(|x| x.to_f64());
    let sigma = [sr.x, sr.y, sr.z, st.x, st.y, st.z, ekf.time_offset_sigma(s)].map(|x| x.to_f64());
    let prior = ekf.prior_sigma(s).map(|x| x.to_f64());
    let report = PoseImuReport {
        converged: reasons.is_empty(),
        reasons,
        scalar: core::any::type_name::<T>(),
        standstill_s: standstill.map_or(0.0, |s| run.seconds(s.until_ns)),
        moving_start: String::new(),
        gyro_bias_init: String::new(),
        planar: String::new(),
        observability: observability::table(&sigma, &prior, &translation_cov, held.as_ref()),
        held_axis: held.as_ref().map(|h| [h.axis.x, h.axis.y, h.axis.z]),
        hand_eye_pairs: rotation_init.pairs,
        hand_eye_axis_ratio: rotation_init.axis_ratio,
        hand_eye_rotation_vector: [rv.x, rv.y, rv.z],
        updates_accepted: run.accepted,
        updates_rejected: run.rejected,
        poses_skipped: run.skipped,
        mean_nis_per_dof: mean_nis,
        excitation,
        events: run.events,
        timing_s: timing,
        history: run.history,
    };
    PoseImuCalibration {
        t_imu_sensor: convert::isometry(&ekf.extrinsic(s)),
        time_offset_s: ekf.time_offset(s).to_f64(),
        time_offset_sigma_s: ekf.time_offset_sigma(s).to_f64(),
        covariance,
        report,
    }
}
