//! The outcome every IMU-to-sensor calibration shares: the filter's extrinsic `T_imu_sensor`
//! and time offset with their uncertainty, and the pipeline's own report.

use nalgebra::{Isometry3, Matrix6};

use crate::dataset::ExtrinsicEstimate;

/// An IMU-to-sensor calibration result; each pipeline names it (`PoseImuCalibration`,
/// `LidarImuCalibration`, `CameraImuCalibration`).
#[derive(Debug, Clone)]
pub struct ImuExtrinsicCalibration<R> {
    /// `T_imu_sensor`, the filter's extrinsic state.
    pub t_imu_sensor: Isometry3<f64>,
    /// Time offset `t_d`, s: a measurement stamped `t_S` was taken at IMU time `t_S + t_d`.
    pub time_offset_s: f64,
    /// 1-sigma of the time offset, s.
    pub time_offset_sigma_s: f64,
    /// Covariance of the `T_imu_sensor` error `[dtheta (right perturbation); dp]`.
    pub covariance: Matrix6<f64>,
    /// The pipeline's report.
    pub report: R,
}

impl<R> ImuExtrinsicCalibration<R> {
    /// `T_imu_sensor` with its sigmas and the time offset, as the `pose0` and `lidar0`
    /// sections of the result file store it (`cam0` stores the inverse: see
    /// `CameraImuCalibration::cam_imu_estimate`).
    pub fn imu_sensor_estimate(&self) -> ExtrinsicEstimate {
        ExtrinsicEstimate::from_covariance(self.t_imu_sensor, self.time_offset_s, &self.covariance)
    }

    /// The same estimate with the report made from this one (a pipeline built on another
    /// one's filter wraps its report).
    pub fn map_report<Q>(self, f: impl FnOnce(R) -> Q) -> ImuExtrinsicCalibration<Q> {
        ImuExtrinsicCalibration {
            t_imu_sensor: self.t_imu_sensor,
            time_offset_s: self.time_offset_s,
            time_offset_sigma_s: self.time_offset_sigma_s,
            covariance: self.covariance,
            report: f(self.report),
        }
    }
}
