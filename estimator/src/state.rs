//! The filter state: nominal values and the layout of the error state.
//!
//! Error-state order (fixed at compile time by [`Layout`]):
//! `[IMU (15) | sensor 0 (7) | ... | sensor S-1 (7) | clone 0 (6) | ... | clone C-1 (6) |
//! frame 0 (6) | ... | frame F-1 (6)]`
//! with IMU = `[dtheta, dp, dv, dbg, dba]`, sensor = `[dtheta_I_S, dp_I_S, dt_d]`,
//! clone = `[dtheta, dp]` of a past IMU pose and frame = `[dtheta_G_F, dp_G_F]` of a static
//! frame such as a calibration target.

mod initial;
mod layout;

pub use initial::{InitialState, SensorPrior};
pub use layout::{imu, Block, Layout, CLONE_DIM, FRAME_DIM, SENSOR_DIM};

use crate::ids::SensorId;
use crate::lie::Pose;
use crate::scalar::Scalar;
use nalgebra::{UnitQuaternion, Vector3};

/// IMU state at the filter time: `T_G_I`, velocity in G and the two biases.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImuState<T: Scalar> {
    /// `R_G_I`: orientation of the IMU in G.
    pub rotation: UnitQuaternion<T>,
    /// `p_G_I`.
    pub position: Vector3<T>,
    /// `v_G_I`.
    pub velocity: Vector3<T>,
    /// Gyroscope bias, rad/s.
    pub gyro_bias: Vector3<T>,
    /// Accelerometer bias, m/s^2.
    pub accel_bias: Vector3<T>,
}

impl<T: Scalar> ImuState<T> {
    /// `T_G_I` as a [`Pose`].
    pub fn pose(&self) -> Pose<T> {
        Pose::new(self.rotation, self.position)
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.pose().is_finite()
            && [self.velocity, self.gyro_bias, self.accel_bias]
                .iter()
                .all(|v| v.iter().all(|x| x.is_finite()))
    }
}

/// Calibration of one exteroceptive sensor S.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorState<T: Scalar> {
    /// `T_I_S`: pose of the sensor in the IMU frame.
    pub extrinsic: Pose<T>,
    /// `t_d`, seconds: a measurement stamped `t_S` was taken at IMU time `t_S + t_d`.
    pub time_offset: T,
}

/// A stochastic clone: a copy of a past IMU pose that stays correlated with the state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CloneState<T: Scalar> {
    /// `T_G_I` at the clone's IMU time.
    pub pose: Pose<T>,
    /// Sensor stamp (ns) of the measurement that created the clone.
    pub stamp_ns: u64,
    /// The sensor that created it.
    pub sensor: SensorId,
    /// Orientation and position parts of the unobservable yaw direction when the clone was
    /// made (the observability constraint's chain, `filter/yaw_gauge.rs`; zero when off).
    pub yaw_direction: [nalgebra::Vector3<T>; 2],
}
