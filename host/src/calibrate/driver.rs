//! The machinery every IMU pipeline shares (pose-IMU, camera-IMU, LiDAR-IMU, joint): the filter
//! start (standstill or moving start, hand-eye rotation, gyro bias), the loop over the IMU record
//! with the pipeline's measurement feed as hooks ([`drive_imu`], generic over the filter layout `E`
//! and the sensor's [`ImuHooks`]), and in [`verdict`] the convergence checks and the report.

use crate::calibrate::convert;
use crate::calibrate::driver::report::PoseImuOptions;
use crate::calibrate::dynamic_init::{self, DynamicInitInput, DynamicInitOptions, FilterPrior};
use crate::calibrate::gyro_bias::{self, GyroBiasEstimate};
use crate::calibrate::init::{self, Standstill};
use crate::calibrate::planar::PlanarStart;
use crate::calibrate::InputError;
use crate::dataset::{ImuNoiseYaml, ImuRecord, PoseRecord};
use msreg_estimator::{
    Ekf, Error as FilterError, FilterConfig, ImuSample, InitialState, PoseImuEkf, Scalar,
    UpdateReport, SOLE_SENSOR,
};
use nalgebra::{Isometry3, Vector3};

pub mod report;
pub mod verdict;

/// The gyro bias known before the filter: the standstill's mean, else the motion fit, else
/// zero.
pub(crate) fn starting_gyro_bias(
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
    start_filter_with_health(
        imu,
        imu_noise,
        (standstill, odometry),
        (rotation, gyro_bias),
        (options, planar),
        msreg_estimator::HealthConfig::default(),
    )
}

/// [`start_filter`] with the filter's health monitor set to `health` (the pose-IMU
/// pipeline's constant-extrinsic pass turns its step reaction off).
pub(crate) fn start_filter_with_health<T: Scalar>(
    imu: &[ImuRecord],
    imu_noise: &ImuNoiseYaml,
    (standstill, odometry): (Option<&Standstill>, &[PoseRecord]),
    (rotation, gyro_bias): (
        Result<init::RotationInit, msreg_estimator::HandEyeError<f64>>,
        Option<&GyroBiasEstimate>,
    ),
    (options, planar): (&PoseImuOptions, Option<&PlanarStart>),
    health: msreg_estimator::HealthConfig<T>,
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
    let config = FilterConfig {
        constrain_yaw: options.constrain_yaw.unwrap_or(planar.is_some()),
        health,
        ..FilterConfig::new(convert::imu_noise::<T>(imu_noise))
    };
    let initial = match (planar, options.start) {
        (Some(p), None) => p.with_lever_arm_prior(initial),
        _ => initial,
    };
    let mut ekf = PoseImuEkf::<T>::new(&config, &initial)
        .map_err(|error| InputError::InvalidNoise { error })?;
    if let Some(p) = planar {
        ekf.hold_translation_axis(SOLE_SENSOR, Some(convert::vec3(&p.motion.axis_imu)))
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
pub(crate) const MIN_FITTED_GYRO_BIAS_SIGMA: f64 = 2e-3;

/// 1-sigma of the gyro bias when nothing measured it (no standstill, no fit), rad/s: MEMS
/// turn-on biases of a few deg/s (the EuRoC ADIS16448 reads 4.4 deg/s) are inside 1 sigma.
pub(crate) const UNKNOWN_GYRO_BIAS_SIGMA: f64 = 0.1;

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
pub(crate) const MOVING_START_MIN_SIGMA_VELOCITY: f64 = 0.1;

pub(crate) const MOVING_START_MIN_SIGMA_TILT_RAD: f64 = 0.6 * std::f64::consts::PI / 180.0;

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
pub fn nominal_period_ns(poses: &[PoseRecord]) -> u64 {
    let mut d: Vec<u64> = poses
        .windows(2)
        .map(|w| w[1].stamp_ns - w[0].stamp_ns)
        .collect();
    d.sort_unstable();
    d.get(d.len() / 2).copied().unwrap_or(100_000_000)
}

/// The IMU part of the filter prior, the one definition the host pipelines and the wire
/// `Config` of `msreg link replay` share: at rest (gravity and gyro bias of the standstill)
/// if the recording starts still, else level from the mean of the first 400 samples with
/// large orientation and velocity sigmas (the sigmas are zero at rest: the prior's own).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuStartPrior {
    /// Mean accelerometer reading that sets gravity, m/s^2.
    pub accel_mean: Vector3<f64>,
    /// Starting gyro bias (the standstill's mean; zero when moving), rad/s.
    pub gyro_bias: Vector3<f64>,
    /// Orientation (rad) and velocity (m/s) sigmas of a moving start; `None` at rest.
    pub moving_sigmas: Option<(f64, f64)>,
}

/// Orientation (rad) and velocity (m/s) sigmas of a moving start: gravity direction and
/// velocity are only roughly known.
const MOVING_START_SIGMAS: (f64, f64) = (0.1, 1.0);

impl ImuStartPrior {
    /// The prior of `imu` with its initial standstill, if any.
    pub fn of(imu: &[ImuRecord], standstill: Option<&Standstill>) -> Self {
        let accel_mean = standstill.map_or_else(
            || {
                let n = imu.len().min(400);
                imu[..n].iter().map(|r| r.accel).sum::<Vector3<f64>>() / n as f64
            },
            |s| s.accel_mean,
        );
        Self {
            accel_mean,
            gyro_bias: standstill.map_or_else(Vector3::zeros, |s| s.gyro_mean),
            moving_sigmas: standstill.is_none().then_some(MOVING_START_SIGMAS),
        }
    }
}

/// Sigma of the time-offset prior: the option's when the offset is estimated, else zero.
pub fn time_offset_sigma_s(options: &PoseImuOptions) -> f64 {
    if options.estimate_time_offset {
        options.time_offset_sigma_s
    } else {
        0.0
    }
}

/// The filter prior: at rest if the recording starts still, else level with large sigmas.
pub(crate) fn initial_state<T: Scalar>(
    imu: &[ImuRecord],
    standstill: Option<&Standstill>,
    rotation: &nalgebra::UnitQuaternion<f64>,
    options: &PoseImuOptions,
) -> Result<InitialState<T, 1>, InputError> {
    let prior = ImuStartPrior::of(imu, standstill);
    let accel = prior.accel_mean;
    let mut state =
        InitialState::<T, 1>::at_rest(convert::vec3(&accel)).ok_or(InputError::NotGravity {
            accel_norm: accel.norm(),
        })?;
    match prior.moving_sigmas {
        None => {
            state.imu.gyro_bias = convert::vec3(&prior.gyro_bias);
        }
        Some((orientation, velocity)) => {
            state.sigma_orientation = T::lit(orientation);
            state.sigma_velocity = T::lit(velocity);
        }
    }
    let (extrinsic, time_offset) = match &options.start {
        Some(s) => (convert::pose::<T>(&s.t_imu_sensor), T::lit(s.time_offset_s)),
        None => (
            msreg_estimator::Pose::new(
                convert::pose::<T>(&Isometry3::from_parts(Default::default(), *rotation)).rotation,
                Vector3::zeros(),
            ),
            T::zero(),
        ),
    };
    Ok(state
        .with_extrinsic(
            SOLE_SENSOR,
            extrinsic,
            T::lit(options.rotation_sigma_rad),
            T::lit(options.translation_sigma_m),
        )
        .with_time_offset(
            SOLE_SENSOR,
            time_offset,
            T::lit(time_offset_sigma_s(options)),
        ))
}
