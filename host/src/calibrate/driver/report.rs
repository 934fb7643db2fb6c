//! What every IMU pipeline shares besides the loop: the filter tuning ([`PoseImuOptions`]), the
//! convergence history, health events, timing and the report of the filter run.

use crate::calibrate::extrinsic::ImuExtrinsicCalibration;
use crate::calibrate::observability::DofObservability;
use serde::Serialize;

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
    /// Keep the rotation about gravity unobservable (`FilterConfig::constrain_yaw`, the
    /// observability-constrained EKF). `None`: on under planar motion, where the plain
    /// EKF's spurious information about that rotation leaves the lever arm over-confident
    /// (docs/planar.md, "The start from the direction of travel, and the yaw constraint
    /// on"), off otherwise.
    pub constrain_yaw: Option<bool>,
    /// The start of the extrinsic and time offset from a prior file (`--prior`), in place of
    /// the hand-eye rotation, a zero lever arm and a zero time offset; its sigmas are the
    /// fields above (a zero translation sigma fixes the lever arm).
    pub start: Option<ExtrinsicStart>,
}

/// A given start of `T_imu_sensor` and the time offset (`PoseImuOptions::start`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtrinsicStart {
    /// `T_imu_sensor`.
    pub t_imu_sensor: nalgebra::Isometry3<f64>,
    /// Time offset, s.
    pub time_offset_s: f64,
}

impl Default for PoseImuOptions {
    fn default() -> Self {
        Self {
            estimate_time_offset: true,
            time_offset_sigma_s: 0.05,
            rotation_sigma_rad: 2f64.to_radians(),
            translation_sigma_m: 0.5,
            min_standstill_s: 0.3,
            constrain_yaw: None,
            start: None,
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
    /// Degrees of freedom of the update (6 for a relative pose, twice the corners of an
    /// image): the chi-square NIS is judged against.
    pub dof: usize,
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
    /// Poses taken surely at rest (the initial standstill), which anchor the odometry
    /// instead of being fused: an increment at rest tells neither the extrinsic nor the time
    /// offset.
    pub poses_at_rest: usize,
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

/// A held direction holds every axis of the result's frame it has at least this component
/// on (10 deg off an axis still holds only that axis).
const HELD_AXIS_COMPONENT: f64 = 0.17;

/// Which frame the result file's section uses for `T_imu_sensor`'s perturbations: the
/// filter's own (`pose0.T_imu_pose`, `lidar0.T_imu_lidar`) or its inverse (`camN.T_cam_imu`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SectionFrame {
    /// The section stores `T_imu_sensor` itself.
    ImuSensor,
    /// The section stores `T_sensor_imu`, the inverse of the filter's `T_imu_sensor` whose
    /// rotation `R_imu_sensor` is given.
    SensorImu(nalgebra::Rotation3<f64>),
}

impl PoseImuReport {
    /// The degrees of freedom the result holds at their prior, in the section's frame: every
    /// observability row `not observable` or `not trusted` (a held lever-arm direction holds
    /// the axes it has a component of at least 0.17 on), and the time shift when it was not
    /// estimated (no `time offset` row: its prior was 0).
    pub fn held_dofs(&self, frame: SectionFrame) -> Vec<crate::dataset::Dof> {
        use crate::dataset::Dof;
        use nalgebra::{Matrix3, Vector3};
        // Directions of the filter's perturbation [rotation in the sensor frame;
        // translation in the IMU frame] into the section's.
        let (rotation, translation) = match frame {
            SectionFrame::ImuSensor => (Matrix3::identity(), Matrix3::identity()),
            SectionFrame::SensorImu(r) => (*r.matrix(), r.matrix().transpose()),
        };
        let mut held = Vec::new();
        let hold_along = |held: &mut Vec<Dof>, frame: &Matrix3<f64>, d: Vector3<f64>, first| {
            let d = frame * d;
            for k in 0..3 {
                if d[k].abs() >= HELD_AXIS_COMPONENT {
                    held.extend(Dof::extrinsic(first + k));
                }
            }
        };
        let mut timeshift_row = false;
        for row in &self.observability {
            timeshift_row |= row.dof == "time offset";
            if row.status != "not observable" && row.status != "not trusted" {
                continue;
            }
            let axis = |name: &str| match name.chars().last() {
                Some('x') => Some(Vector3::x()),
                Some('y') => Some(Vector3::y()),
                Some('z') => Some(Vector3::z()),
                _ => None,
            };
            match row.dof.as_str() {
                "time offset" => held.push(Dof::Timeshift),
                d if d.starts_with("rotation ") => {
                    if let Some(a) = axis(d) {
                        hold_along(&mut held, &rotation, a, 0);
                    }
                }
                d if d.starts_with("translation along") => {
                    if let Some(a) = self.held_axis {
                        hold_along(&mut held, &translation, Vector3::from(a), 3);
                    }
                }
                d if d.starts_with("translation ") => {
                    if let Some(a) = axis(d) {
                        hold_along(&mut held, &translation, a, 3);
                    }
                }
                _ => {}
            }
        }
        if !timeshift_row {
            held.push(Dof::Timeshift);
        }
        held.sort();
        held.dedup();
        held
    }
}
