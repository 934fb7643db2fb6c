//! Pose-IMU calibration (motion based, dissertation ch. 3.5 / 4.4 with a generic pose
//! sensor): hand-eye rotation init, then the error-state EKF fed with IMU samples and the
//! odometry's relative poses, estimating `T_imu_pose` and the time offset.
//!
//! Event order: a pose stamped `t_S` belongs at IMU time `t_S + t_d`; it is fused as soon as
//! the filter holds an IMU sample at or after that time (`Ekf::is_due`; the filter
//! propagates over the readings interpolated to it), with the current estimate of `t_d`.

use super::InputError;
use std::time::Instant;

use msreg_estimator::{HealthConfig, PoseImuEkf, Scalar, SOLE_SENSOR};
use nalgebra::Vector3;

use super::driver::report::{PoseImuCalibration, PoseImuOptions, Timing};
use super::driver::verdict::{finish, Run};
use super::driver::{
    describe_moving_start, drive_imu, hand_eye_and_gyro_bias, nominal_period_ns,
    start_filter_with_health, starting_gyro_bias, time_offset_sigma_s, FilterStart, ImuHooks,
};
use super::init::{self};
use super::planar::{self};
use crate::dataset::{ImuNoiseYaml, ImuRecord, PoseRecord, PoseSensorYaml};

pub mod model_error;
mod steps;
mod trust;

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

/// Runs the calibration with the filter in scalar type `T`; `progress` gets the fraction
/// of the recording processed.
///
/// When the filter's health monitor reacted to extrinsic steps, the recording is filtered
/// again with the extrinsic held constant, and the two explanations of the data are compared
/// ([`steps::judge`]): the steps stand only when they explain the odometry better than one
/// constant extrinsic does. On real recordings the step detector fires on unmodelled errors
/// (EuRoC `imu_april` with PnP odometry: eight "steps", 1.3 deg excursions, and an end 0.28
/// deg / 33 mm from Kalibr instead of 0.26 deg / 11 mm; docs/pose-imu.md).
pub fn calibrate<T: Scalar>(
    input: &PoseImuInput<'_>,
    options: &PoseImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<PoseImuCalibration, InputError> {
    let reacting = calibrate_with::<T>(input, options, HealthConfig::default(), progress)?;
    if reacting.report.events.is_empty() {
        return Ok(reacting);
    }
    let constant = calibrate_with::<T>(input, options, steps::constant_extrinsic(), &mut |_| {})?;
    Ok(steps::judge(reacting, constant))
}

/// The calibration with the filter's health monitor set to `health`.
fn calibrate_with<T: Scalar>(
    input: &PoseImuInput<'_>,
    options: &PoseImuOptions,
    health: HealthConfig<T>,
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
    let standstill = confirmed_standstill(input, options);
    let period_ns = nominal_period_ns(poses);
    let max_interval_ns = period_ns.saturating_mul(3) / 2;
    let increments = init::pose_increments(poses, max_interval_ns);
    let (rotation, gyro_bias) = hand_eye_and_gyro_bias(imu, &increments, standstill.as_ref());
    let bias = starting_gyro_bias(standstill.as_ref(), gyro_bias.as_ref());
    let pairs = init::rotation_pairs(imu, increments.iter().copied(), &bias);
    let scale_problem = trust::rotation_scale_problem(&pairs);
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
    } = start_filter_with_health::<T>(
        imu,
        input.imu_noise,
        (standstill.as_ref(), poses),
        (rotation, gyro_bias.as_ref()),
        (options, planar.as_ref()),
        health,
    )?;

    let started = Instant::now();
    let mut feed = PoseFeed {
        run: Run::new(first_imu.stamp_ns, period_ns),
        poses,
        next_pose: 0,
        rest_until_ns: rest_until_ns(standstill.as_ref(), options),
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
    annotate(
        &mut calibration,
        (init_problem, scale_problem),
        (planar.as_ref(), options, &bias),
        (imu, poses),
    );
    calibration.report.moving_start = describe_moving_start(&moving_start);
    calibration.report.gyro_bias_init = gyro_bias_init;
    Ok(calibration)
}

/// The start's problems and the planar start in the report; a rotation the odometry's
/// scale contradicts is refused.
fn annotate(
    calibration: &mut PoseImuCalibration,
    (init_problem, scale_problem): (Option<String>, Option<String>),
    (planar, options, bias): (Option<&planar::PlanarStart>, &PoseImuOptions, &Vector3<f64>),
    (imu, poses): (&[ImuRecord], &[PoseRecord]),
) {
    if let Some(problem) = init_problem {
        calibration.report.reasons.insert(0, problem);
        calibration.report.converged = false;
    }
    calibration.report.planar = planar.map_or_else(String::new, |p| describe_planar(p, options));
    if let Some(problem) = scale_problem {
        trust::refuse_rotation(
            calibration,
            &problem,
            (planar.is_some(), bias),
            (imu, poses),
        );
    }
}

/// The report's words for a planar start, and whether the filter kept the rotation about
/// gravity unobservable (on by default under planar motion).
fn describe_planar(start: &planar::PlanarStart, options: &PoseImuOptions) -> String {
    let how = if options.constrain_yaw.unwrap_or(true) {
        "kept"
    } else {
        "not kept"
    };
    format!(
        "{}; the rotation about gravity {how} unobservable (`constrain_yaw`)",
        start.describe()
    )
}

/// The standstill at the start of the recording that the odometry confirms: an IMU moving
/// at constant velocity without turning reads as at rest ([`init::Standstill::odometry_agrees`]).
pub(crate) fn confirmed_standstill(
    input: &PoseImuInput<'_>,
    options: &PoseImuOptions,
) -> Option<init::Standstill> {
    init::detect_standstill(input.imu, options.min_standstill_s)
        .filter(|s| s.odometry_agrees(input.poses, input.pose_noise.translation_noise_m))
}

/// Poses stamped up to this time were taken at rest whatever the time offset (within 3
/// sigma of its prior): they anchor the odometry instead of being fused (see
/// `PoseFeed::fuse_due`). The firmware's replay stream follows the same rule.
pub(crate) fn rest_until_ns(
    standstill: Option<&init::Standstill>,
    options: &PoseImuOptions,
) -> Option<u64> {
    standstill.map(|s| s.surely_at_rest_until_ns(time_offset_sigma_s(options)))
}

/// The pose-IMU pipeline's measurement feed: fuses every pose whose IMU time has come.
struct PoseFeed<'a> {
    run: Run,
    poses: &'a [PoseRecord],
    next_pose: usize,
    /// Poses stamped up to here were taken at rest whatever the time offset: they anchor
    /// the odometry instead of being fused (see `fuse_due`).
    rest_until_ns: Option<u64>,
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
            if !ekf.is_due(SOLE_SENSOR, pose.stamp_ns) {
                break;
            }
            if index == 0 {
                self.run.skip(pose.stamp_ns, "before the first IMU sample");
            } else if self.rest_until_ns.is_some_and(|t| pose.stamp_ns <= t) {
                // An increment at rest is the identity whatever the extrinsic and the time
                // offset, so it tells neither. Fused, its time-offset Jacobian (built from
                // the estimated velocity and noisy rates) lets the offset wander tens of ms
                // across its unobservable prior, outside the linear range of the motion that
                // follows (docs/initialisation.md). The ZUPTs hold the IMU meanwhile.
                self.run.anchor_at_rest(ekf, pose);
            } else {
                self.run.fuse_pose(ekf, pose, self.sigma_r, self.sigma_t);
            }
            self.next_pose += 1;
        }
        Ok(())
    }
}
