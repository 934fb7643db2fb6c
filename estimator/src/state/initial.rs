//! Priors the filter starts from: IMU state, its uncertainty, and each sensor's calibration
//! prior.

use super::{ImuState, SensorState};
use crate::ids::SensorId;
use crate::lie::Pose;
use crate::scalar::Scalar;
use nalgebra::{UnitQuaternion, Vector3};

/// Prior of one sensor's calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorPrior<T: Scalar> {
    /// Initial extrinsic and time offset.
    pub state: SensorState<T>,
    /// 1-sigma of each extrinsic rotation axis, rad.
    pub sigma_rotation: T,
    /// 1-sigma of each extrinsic translation component, m.
    pub sigma_translation: T,
    /// 1-sigma of the time offset, s. Zero keeps the time offset fixed (not estimated).
    pub sigma_time_offset: T,
}

impl<T: Scalar> Default for SensorPrior<T> {
    fn default() -> Self {
        Self {
            state: SensorState {
                extrinsic: Pose::identity(),
                time_offset: T::zero(),
            },
            sigma_rotation: T::lit(0.1),
            sigma_translation: T::lit(0.3),
            sigma_time_offset: T::zero(),
        }
    }
}

/// Everything the filter starts from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InitialState<T: Scalar, const S: usize> {
    /// IMU state at the first IMU sample.
    pub imu: ImuState<T>,
    /// 1-sigma of the orientation error (each axis), rad.
    pub sigma_orientation: T,
    /// 1-sigma of the position (each axis), m. The origin is a gauge choice: keep it small.
    pub sigma_position: T,
    /// 1-sigma of the velocity (each axis), m/s.
    pub sigma_velocity: T,
    /// 1-sigma of the gyroscope bias, rad/s.
    pub sigma_gyro_bias: T,
    /// 1-sigma of the accelerometer bias, m/s^2.
    pub sigma_accel_bias: T,
    /// Calibration prior of every sensor.
    pub sensors: [SensorPrior<T>; S],
}

impl<T: Scalar, const S: usize> InitialState<T, S> {
    /// The IMU at rest at the origin, with roll and pitch from the mean accelerometer reading
    /// (yaw is a gauge freedom and set to that of the shortest rotation), zero velocity and
    /// zero biases. Returns `None` when `accel_mean` is not a plausible gravity reading.
    pub fn at_rest(accel_mean: Vector3<T>) -> Option<Self> {
        let norm = accel_mean.norm();
        if !norm.is_finite() || norm < T::lit(5.0) || norm > T::lit(15.0) {
            return None;
        }
        // At rest a_m = R_G_I^T (0, 0, g): rotate the measured "up" onto G's z axis.
        let rotation = UnitQuaternion::rotation_between(&accel_mean, &Vector3::z())
            .unwrap_or_else(UnitQuaternion::identity);
        let zero = Vector3::zeros();
        Some(Self {
            imu: ImuState {
                rotation,
                position: zero,
                velocity: zero,
                gyro_bias: zero,
                accel_bias: zero,
            },
            sigma_orientation: T::lit(0.01),
            sigma_position: T::lit(1e-3),
            sigma_velocity: T::lit(0.05),
            sigma_gyro_bias: T::lit(2e-3),
            sigma_accel_bias: T::lit(0.05),
            sensors: [SensorPrior::default(); S],
        })
    }

    /// Sets sensor `s`'s extrinsic prior `T_I_S` with per-axis sigmas (rad, m).
    /// An `s` beyond this layout's `S` (an id made for a larger one) is ignored.
    pub fn with_extrinsic(
        mut self,
        s: SensorId,
        t_imu_sensor: Pose<T>,
        sigma_rotation: T,
        sigma_translation: T,
    ) -> Self {
        if let Some(prior) = self.sensors.get_mut(s.index()) {
            prior.state.extrinsic = t_imu_sensor;
            prior.sigma_rotation = sigma_rotation;
            prior.sigma_translation = sigma_translation;
        }
        self
    }

    /// Sets sensor `s`'s time-offset prior; a zero sigma keeps it fixed.
    pub fn with_time_offset(mut self, s: SensorId, time_offset: T, sigma: T) -> Self {
        if let Some(prior) = self.sensors.get_mut(s.index()) {
            prior.state.time_offset = time_offset;
            prior.sigma_time_offset = sigma;
        }
        self
    }

    /// True when all values are finite and all sigmas non-negative.
    pub fn is_valid(&self) -> bool {
        let sig = [
            self.sigma_orientation,
            self.sigma_position,
            self.sigma_velocity,
            self.sigma_gyro_bias,
            self.sigma_accel_bias,
        ];
        let sensors_ok = self.sensors.iter().all(|p| {
            p.state.extrinsic.is_finite()
                && p.state.time_offset.is_finite()
                && [p.sigma_rotation, p.sigma_translation, p.sigma_time_offset]
                    .iter()
                    .all(|s| s.is_finite() && *s >= T::zero())
        });
        self.imu.is_finite() && sig.iter().all(|s| s.is_finite() && *s > T::zero()) && sensors_ok
    }
}
