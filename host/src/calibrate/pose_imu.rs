//! Pose-IMU calibration (motion based, dissertation ch. 3.5 / 4.4 with a generic pose
//! sensor): hand-eye rotation init, then the error-state EKF fed with IMU samples and the
//! odometry's relative poses, estimating `T_imu_pose` and the time offset.
//!
//! Event order: a pose stamped `t_S` belongs at IMU time `t_S + t_d`; it is fused as soon as
//! the filter holds an IMU sample at or after that time (`Ekf::is_due`; the filter
//! propagates over the readings interpolated to it), with the current estimate of `t_d`.

use super::InputError;
use std::time::Instant;

use msreg_estimator::{PoseImuEkf, Scalar};
use serde::Serialize;

use super::driver::verdict::{finish, Run};
use super::driver::{
    describe_moving_start, drive_imu, hand_eye_and_gyro_bias, nominal_period_ns, start_filter,
    starting_gyro_bias, FilterStart, ImuHooks,
};
use super::extrinsic::ImuExtrinsicCalibration;
use super::init::{self};
use super::observability::DofObservability;
use super::planar::{self};
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
