//! `msreg monitor`: the on-vehicle calibration health monitor (estimator/src/health.rs)
//! replayed on the host over an IMU and `N` pose sensors (`pose0`, e.g. LiDAR odometry;
//! `pose1`, e.g. a camera's visual odometry; ... up to [`MAX_POSE_SENSORS`]), all in one
//! filter (`N` extrinsics and time offsets, two clones per sensor, no target frame; with two
//! sensors the joint layout `MonitorEkf`), started from the vehicle's calibration of record.
//!
//! Two runs over the same data:
//! - the **monitor**: extrinsics and time offsets start at the calibration of record with its
//!   sigmas; the health monitor's step detectors and windowed NIS test flag what changes
//!   (alarms: time, sensor, kind);
//! - the **observability** run: the same filter with wide extrinsic priors and no alarms, so
//!   how far each sigma shrinks says what this drive itself can observe, per DoF, in words
//!   (`calibrate::observability`), independent of how tight the calibration of record is.
//!
//! With planar motion (detected from `pose0`'s rotation increments against the gyro,
//! `calibrate::planar`) the lever arm of both sensors along the rotation axis is held at the
//! calibration of record (not observable; a Schmidt direction).

pub mod drive_bag;
mod files;
mod replay;
pub mod start;
pub mod timeline;
mod verdict;

use serde::Serialize;

use crate::calibrate::observability::DofObservability;
use crate::dataset::{ExtrinsicEstimate, ImuNoiseYaml, ImuRecord, PoseRecord, PoseSensorYaml};

pub use files::{DriveFiles, DriveFilesError};
pub use replay::{
    monitor, monitor_prior, pose_steps, MonitorOptions, PoseStep, ZERO_VELOCITY_EVERY,
};
pub use start::FilterPrior;
pub use verdict::{
    RotationChange, SensorVerdict, TranslationChange, Verdict, VerdictWords, AXIS_NAMES,
};

/// The most pose sensors one monitor filter takes (its layout is fixed at compile time:
/// `15 + 7 N + 12 N` error states, one instantiation per `N`).
pub const MAX_POSE_SENSORS: usize = 4;

/// Sensor names, by filter index.
pub const SENSOR_NAMES: [&str; MAX_POSE_SENSORS] = ["pose0", "pose1", "pose2", "pose3"];

/// What the monitor replays.
/// `poses`, `pose_noise` and `prior` have one entry per pose sensor (`pose0`, `pose1`, ...,
/// 1 to [`MAX_POSE_SENSORS`] of them, the same number in each).
#[derive(Debug, Clone)]
pub struct MonitorInput<'a> {
    /// `imu0/data.csv`.
    pub imu: &'a [ImuRecord],
    /// `imu0/imu.yaml`.
    pub imu_noise: &'a ImuNoiseYaml,
    /// `poseN/data.csv` of every pose sensor.
    pub poses: Vec<&'a [PoseRecord]>,
    /// `poseN/sensor.yaml` of every pose sensor.
    pub pose_noise: Vec<&'a PoseSensorYaml>,
    /// The calibration of record, `poseN` of every pose sensor.
    pub prior: Vec<ExtrinsicEstimate>,
}

/// Why the monitor could not run.
#[derive(Debug, thiserror::Error)]
pub enum MonitorError {
    /// `imu0/data.csv` has fewer than two samples.
    #[error("imu0/data.csv: fewer than two IMU samples")]
    TooFewImuSamples,
    /// A pose sensor has fewer than two poses.
    #[error("{sensor}/data.csv: fewer than two poses")]
    TooFewPoses {
        /// `pose0`, `pose1`, ...
        sensor: &'static str,
    },
    /// No pose sensor, more than [`MAX_POSE_SENSORS`], or inputs of different lengths.
    #[error(
        "the monitor takes 1 to {max} pose sensors (pose0/ ... with a calibration of record \
         each); got {poses} odometries, {noise} sensor.yaml, {prior} calibrations of record{needed}"
    )]
    PoseSensorCount {
        /// Odometries given.
        poses: usize,
        /// `sensor.yaml` files given.
        noise: usize,
        /// Calibration-of-record sections given.
        prior: usize,
        /// Largest number the monitor takes.
        max: usize,
        /// What this use of the monitor needs beyond that (empty, or e.g. "; the device's
        /// monitoring layout takes exactly two").
        needed: &'static str,
    },
    /// The mean accelerometer reading of the standstill is not gravity.
    #[error(
        "imu0/data.csv: mean accelerometer reading {accel_norm:.2} m/s^2 at rest is not gravity"
    )]
    NotGravity {
        /// Norm of the mean reading, m/s^2.
        accel_norm: f64,
    },
    /// The filter refused an IMU sample.
    #[error("imu0/data.csv: {error:?} at the sample stamped {stamp_ns} ns (sample {sample} of the file)")]
    ImuSample {
        /// The estimator's reason.
        error: msreg_estimator::Error,
        /// Stamp of the sample, ns.
        stamp_ns: u64,
        /// 1-based index of the sample in the file.
        sample: usize,
    },
    /// The filter refused the noise figures or the calibration of record.
    #[error("imu0/imu.yaml or prior: {error}")]
    InvalidPrior {
        /// The estimator's reason.
        error: msreg_estimator::Error,
    },
    /// The dynamic alignment of a moving start failed.
    #[error("the monitor could not start: dynamic alignment with pose0 failed: {reason}")]
    NoAlignment {
        /// Why.
        reason: crate::calibrate::driver::MovingStartFailure,
    },
    /// No IMU state could be formed at the start.
    #[error("the monitor could not start: no IMU prior")]
    NoImuPrior,
    /// The planar lever-arm axis could not be held.
    #[error("the monitor could not start: planar axis: {error}")]
    PlanarAxis {
        /// The estimator's reason.
        error: msreg_estimator::Error,
    },
}

impl MonitorError {
    /// True when the input was fine but the filter could not be started on this recording
    /// (exit code 1, not 2).
    pub fn is_no_start(&self) -> bool {
        matches!(
            self,
            MonitorError::NoAlignment { .. }
                | MonitorError::NoImuPrior
                | MonitorError::PlanarAxis { .. }
        )
    }
}

/// One alarm.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct Alarm {
    /// IMU time, s after the first IMU sample.
    pub t_s: f64,
    /// `pose0`, `pose1`, ...
    pub sensor: &'static str,
    /// `rotation_step`, `translation_step` (the GLR step detectors); among the warnings,
    /// `nis_high` (the windowed NIS crossed its upper chi-square bound).
    pub kind: &'static str,
    /// The test statistic (chi-square(3) for steps, the window's NIS sum otherwise).
    pub statistic: f64,
    /// Estimated step: rotation in deg or translation in mm, per axis (zero for `nis_high`).
    pub step: [f64; 3],
}

/// One update of one sensor.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct NisPoint {
    /// IMU time, s after the first IMU sample.
    pub t_s: f64,
    /// NIS / dof of this update.
    pub nis_per_dof: f64,
    /// The gate / dof (99.9 % chi-square).
    pub gate_per_dof: f64,
    /// Fused (inside the gate, not held out).
    pub accepted: bool,
    /// Held out: a knock candidate of the sensor was pending (`SensorReport::held_out`).
    pub held_out: bool,
    /// The windowed NIS / dof of the health monitor.
    pub window_nis_per_dof: f64,
    /// The rotation step detector's GLR test after this update (`None` while disarmed or
    /// with no resolvable direction).
    pub rotation_glr: Option<GlrPoint>,
    /// The translation step detector's GLR test after this update.
    pub translation_glr: Option<GlrPoint>,
    /// The pending knock candidate after this update, if any.
    pub jump: Option<JumpPoint>,
}

/// A knock candidate (an increment whose rotation residual reads as the mounting moving
/// inside it) and the test of the increments since (docs/monitor.md, "The method").
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct JumpPoint {
    /// The jump's statistic (chi-square(3) under "no change").
    pub statistic: f64,
    /// The jump, deg.
    pub step_deg: f64,
    /// The sequential test's log-likelihood ratio of the increments since ("the mounting
    /// moved by the jump" against "no change"); below `ln(0.01)` the candidate is dropped.
    pub confirmation: f64,
    /// The threshold it must exceed, `ln(1 / alpha)` with `alpha = 1 - step_confidence`.
    pub threshold: f64,
    /// Increments since the candidate.
    pub updates: u32,
}

/// A step detector's GLR test at one update (docs/monitor.md, "False alarms").
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct GlrPoint {
    /// The statistic (chi-square with `dof` degrees of freedom under "no change").
    pub statistic: f64,
    /// Directions tested.
    pub dof: usize,
    /// The threshold it must exceed (`HealthConfig::step_confidence`).
    pub threshold: f64,
    /// Length of the estimated step: deg (rotation) or mm (translation).
    pub step: f64,
}

/// Per-DoF excitation (`1 - sigma / prior`) of the observability run at one update: rotation
/// x, y, z, translation x, y, z, time offset.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct ExcitationPoint {
    /// IMU time, s after the first IMU sample.
    pub t_s: f64,
    /// Excitation per DoF.
    pub excitation: [f64; 7],
}

/// The estimate of one sensor's extrinsic after an update, against the calibration of
/// record (the timeline's estimate panels).
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct EstimatePoint {
    /// IMU time, s after the first IMU sample.
    pub t_s: f64,
    /// Rotation from the record to the estimate, `log(R_record^T R)` (a right perturbation:
    /// the sensor's own axes), deg.
    pub rotation_deg: [f64; 3],
    /// Translation `t_imu_pose` of the estimate minus the record's (IMU frame), mm.
    pub translation_mm: [f64; 3],
    /// The filter's 1-sigma per rotation axis, deg.
    pub sigma_rotation_deg: [f64; 3],
    /// The filter's 1-sigma per translation axis, mm.
    pub sigma_translation_mm: [f64; 3],
}

/// Timeline and summary of one sensor.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct SensorReport {
    /// `pose0`, `pose1`, ...
    pub name: &'static str,
    /// Every update of the monitor run.
    pub nis: Vec<NisPoint>,
    /// The extrinsic estimate after every update of the monitor run, against the record.
    pub estimates: Vec<EstimatePoint>,
    /// Excitation over time (observability run).
    pub excitation: Vec<ExcitationPoint>,
    /// Per-DoF observability at the end of the observability run.
    pub observability: Vec<DofObservability>,
    /// Updates fused / rejected by the gate / held out / skipped (with reasons in `skipped`).
    pub accepted: usize,
    /// Rejected by the gate.
    pub rejected: usize,
    /// Tested but not fused because a knock candidate of the sensor was pending
    /// (`HealthMonitor::holds_out`).
    pub held_out: usize,
    /// Measurements that could not be used, with the reason.
    pub skipped: Vec<String>,
    /// The monitor's final estimate (in the report as `final_*`).
    #[serde(skip)]
    pub estimate: ExtrinsicEstimate,
    /// The calibration of record the monitor started from (`MonitorInput::prior`).
    #[serde(skip)]
    pub record: ExtrinsicEstimate,
    /// Final covariance of the extrinsic, `[rotation (rad, right perturbation); translation
    /// (m)]`, row-major.
    pub final_covariance: [[f64; 6]; 6],
    /// Final `T_imu_pose` (4x4, row-major).
    pub final_t_imu_pose: [[f64; 4]; 4],
    /// Final time offset, s.
    pub final_timeshift_s: f64,
    /// Final 1-sigma per rotation axis, deg.
    pub final_sigma_rot_deg: [f64; 3],
    /// Final 1-sigma per translation axis, m.
    pub final_sigma_trans_m: [f64; 3],
    /// Rotation between the calibration of record and the final estimate, deg.
    pub rotation_change_deg: f64,
    /// Translation change, m.
    pub translation_change_m: f64,
}

/// What the monitor found.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct MonitorReport {
    /// First IMU stamp, ns (times are seconds after it).
    pub start_stamp_ns: u64,
    /// Length of the IMU record, s.
    pub duration_s: f64,
    /// How the IMU state was started.
    pub start: String,
    /// The planar rotation axis (IMU frame) and the axis ratio, when the motion is planar.
    pub planar_axis: Option<[f64; 3]>,
    /// Second / first eigenvalue of the rotation scatter, when planar.
    pub planar_axis_ratio: Option<f64>,
    /// Every alarm (a detected step) in time order.
    pub alarms: Vec<Alarm>,
    /// Warnings in time order: the windowed NIS test crossing its upper bound (`nis_high`),
    /// a consistency signal, not a detection (docs/monitor.md has its measured rate).
    pub warnings: Vec<Alarm>,
    /// `pose0`, `pose1`, ... (one per pose sensor).
    pub sensors: Vec<SensorReport>,
    /// Zero-velocity updates (of no sensor) the filter refused, with the reason.
    pub zero_velocity_skipped: Vec<String>,
}

impl MonitorReport {
    /// The observability rows that are not observed, as `"<sensor> <dof>: <status>: <reason>"`.
    pub fn unobservable_words(&self) -> Vec<String> {
        self.sensors
            .iter()
            .flat_map(|s| {
                s.observability
                    .iter()
                    .filter(|r| r.status != "observed")
                    .map(move |r| format!("{} {}: {}: {}", s.name, r.dof, r.status, r.reason))
            })
            .collect()
    }

    /// What the operator should know and do (see [`Verdict`]).
    pub fn verdict(&self) -> Verdict {
        Verdict::of(self)
    }

    /// The re-estimated calibration: the monitor's final estimate of every sensor with its
    /// sigmas, in the result file's sections (`pose0`, `pose1`, ..., one per sensor).
    pub fn calibration(&self) -> crate::dataset::CalibrationResult {
        let mut result = crate::dataset::CalibrationResult::new();
        for (k, s) in self.sensors.iter().enumerate() {
            let index = u16::try_from(k).unwrap_or(u16::MAX);
            result.set_extrinsic(crate::dataset::SectionName::pose(index), s.estimate);
        }
        result
    }

    /// The first alarm of `sensor` at or after `t_s`.
    pub fn first_alarm_after(&self, sensor: &str, t_s: f64) -> Option<&Alarm> {
        self.alarms
            .iter()
            .find(|a| a.sensor == sensor && a.t_s >= t_s)
    }
}
