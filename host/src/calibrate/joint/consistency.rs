//! Loop consistency (the dissertation's Fig. 5.5 question): `T_cam_lidar` from the joint
//! filter against chaining the camera-IMU and LiDAR-IMU pipelines run separately on the same
//! recording, `T_imu_cam^-1 T_imu_lidar`.
//!
//! The difference `d = [Log(R_joint^T R_chained); p_chained - p_joint]` is reported in
//! degrees and millimetres, and as a Hausman statistic: the joint filter uses every
//! measurement the two pairwise runs use plus the board planes, so when both are consistent
//! `Cov(d) = P_chained - P_joint` and `d^T (P_chained - P_joint)^-1 d` is chi-square with 6
//! degrees of freedom (not computed when the difference of covariances is not positive
//! definite: the pairwise runs then claim more than the joint one).

use nalgebra::{Isometry3, Matrix6, Vector3, Vector6};
use serde::Serialize;

use super::{compose_cam_lidar, JointCalibration, JointInput, JointOptions};
use crate::calibrate::camera_imu::{self, CameraImuCalibration, CameraImuInput};
use crate::calibrate::lidar_imu::{self, LidarImuCalibration, LidarImuInput};
use crate::calibrate::InputError;

/// The two pairwise runs on the joint recording.
#[derive(Debug, Clone)]
pub struct PairwiseRuns {
    /// Camera-IMU (RepErrCal) on the IMU and the corners.
    pub camera: CameraImuCalibration,
    /// LiDAR-IMU on the IMU and the scans.
    pub lidar: LidarImuCalibration,
}

impl PairwiseRuns {
    /// `T_cam_lidar` chained from the two runs, its covariance (the runs independent).
    pub fn t_cam_lidar(&self) -> (Isometry3<f64>, Matrix6<f64>) {
        compose_cam_lidar(
            (&self.camera.t_imu_sensor, &self.camera.covariance),
            (&self.lidar.t_imu_sensor, &self.lidar.covariance),
            &Matrix6::zeros(),
        )
    }

    /// True when both runs passed their checks.
    pub fn converged(&self) -> bool {
        self.camera.report.filter.converged && self.lidar.report.filter.converged
    }
}

/// Runs the camera-IMU and LiDAR-IMU pipelines separately on the joint recording, with the
/// joint run's options for each sensor; `progress` gets the fraction done.
pub fn chained_pairwise(
    input: &JointInput<'_>,
    options: &JointOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<PairwiseRuns, InputError> {
    let camera = camera_imu::calibrate::<f64>(
        &CameraImuInput {
            imu: input.imu,
            imu_noise: input.imu_noise,
            camera: input.camera,
            frames: input.frames,
        },
        &options.camera,
        &mut |f| progress(0.5 * f),
    )?;
    let lidar = lidar_imu::calibrate::<f64>(
        &LidarImuInput {
            imu: input.imu,
            imu_noise: input.imu_noise,
            scans: input.scans,
        },
        &options.lidar,
        &mut |f| progress(0.5 + 0.5 * f),
    )?;
    Ok(PairwiseRuns { camera, lidar })
}

/// A `T_cam_lidar` in the report: rotation vector (deg), translation (m), 1-sigmas.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CamLidarSummary {
    /// Rotation vector of `R_cam_lidar`, deg.
    pub rotation_deg: [f64; 3],
    /// `p_cam_lidar`, m.
    pub translation_m: [f64; 3],
    /// 1-sigma per rotation axis (right perturbation), deg.
    pub sigma_rotation_deg: [f64; 3],
    /// 1-sigma per translation axis, m.
    pub sigma_translation_m: [f64; 3],
}

impl CamLidarSummary {
    fn of(t: &Isometry3<f64>, covariance: &Matrix6<f64>) -> Self {
        let sigma = |i: usize| covariance[(i, i)].max(0.0).sqrt();
        Self {
            rotation_deg: (t.rotation.scaled_axis() * 1f64.to_degrees()).into(),
            translation_m: t.translation.vector.into(),
            sigma_rotation_deg: [0, 1, 2].map(|i| sigma(i).to_degrees()),
            sigma_translation_m: [3, 4, 5].map(sigma),
        }
    }
}

/// Joint against chained pairwise `T_cam_lidar`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LoopConsistency {
    /// The joint filter's.
    pub joint: CamLidarSummary,
    /// Chained from the pairwise runs.
    pub chained: CamLidarSummary,
    /// Rotation between the two, deg.
    pub difference_deg: f64,
    /// Translation between the two, mm.
    pub difference_mm: f64,
    /// `d^T (P_chained - P_joint)^-1 d` (chi-square, 6 dof, when both are consistent);
    /// `None` when `P_chained - P_joint` is not positive definite.
    pub hausman: Option<f64>,
    /// Whether both pairwise runs passed their checks.
    pub pairwise_converged: bool,
}

impl LoopConsistency {
    /// Compares the joint result with the chained pairwise runs.
    pub fn of(joint: &JointCalibration, pairwise: &PairwiseRuns) -> Self {
        let (chained, chained_cov) = pairwise.t_cam_lidar();
        let d = difference(&joint.t_cam_lidar, &chained);
        let hausman = (chained_cov - joint.cam_lidar_covariance)
            .cholesky()
            .map(|c| d.dot(&c.solve(&d)));
        Self {
            joint: CamLidarSummary::of(&joint.t_cam_lidar, &joint.cam_lidar_covariance),
            chained: CamLidarSummary::of(&chained, &chained_cov),
            difference_deg: d.fixed_rows::<3>(0).norm().to_degrees(),
            difference_mm: d.fixed_rows::<3>(3).norm() * 1e3,
            hausman,
            pairwise_converged: pairwise.converged(),
        }
    }
}

/// `[Log(R_a^T R_b); p_b - p_a]`: `b` as a right perturbation of `a`.
fn difference(a: &Isometry3<f64>, b: &Isometry3<f64>) -> Vector6<f64> {
    let rotation: Vector3<f64> = (a.rotation.inverse() * b.rotation).scaled_axis();
    let translation = b.translation.vector - a.translation.vector;
    Vector6::new(
        rotation.x,
        rotation.y,
        rotation.z,
        translation.x,
        translation.y,
        translation.z,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn the_difference_is_a_right_perturbation() {
        let a = Isometry3::from_parts(
            Translation3::new(0.1, -0.2, 0.3),
            UnitQuaternion::from_euler_angles(0.3, -0.1, 1.2),
        );
        let delta = Vector3::new(1e-3, -2e-3, 0.5e-3);
        let b = Isometry3::from_parts(
            Translation3::from(a.translation.vector + Vector3::new(0.002, 0.0, -0.001)),
            a.rotation * UnitQuaternion::from_scaled_axis(delta),
        );
        let d = difference(&a, &b);
        assert!((d.fixed_rows::<3>(0) - delta).norm() < 1e-12);
        assert!((d.fixed_rows::<3>(3) - Vector3::new(0.002, 0.0, -0.001)).norm() < 1e-12);
    }
}
