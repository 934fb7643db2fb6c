//! msreg-estimator: the no_std, allocation-free error-state EKF at the core of msreg.
//!
//! It estimates the IMU state, the extrinsic pose and time offset of every exteroceptive
//! sensor and a bounded window of stochastic clones of past IMU poses, from IMU samples and
//! sensor measurements (relative poses, zero velocity, and later reprojections and planes).
//! The same code runs in f64 on the host and in f32 on a Cortex-M4F.
//!
//! Conventions (docs: `docs/formats.md`): `T_a_b` is the pose of frame `b` in
//! frame `a`; quaternions are Hamilton; every rotation error is a right perturbation
//! `R = R_hat * Exp(dtheta)`; positions, velocities, biases and time offsets are additive.
//! Time is `u64` nanoseconds; a measurement of sensor S stamped `t_S` was taken at IMU time
//! `t_S + t_d`.
#![no_std]
#![warn(missing_docs)]
#![cfg_attr(not(test), warn(clippy::unwrap_used))]

pub use nalgebra as na;

pub mod camera;
pub mod chi2;
pub mod error;
pub mod filter;
pub mod hand_eye;
pub mod health;
pub mod ids;
pub mod lie;
pub mod propagate;
pub mod scalar;
pub mod state;
pub mod update;

pub use error::Error;
pub use filter::{
    CameraImuEkf, Ekf, FilterConfig, JointEkf, PoseImuEkf, JOINT_CAMERA, JOINT_LIDAR, SOLE_SENSOR,
    TARGET_FRAME,
};
pub use hand_eye::{HandEye, HandEyeError};
pub use health::{HealthConfig, HealthEvent, HealthMonitor, SensorHealth};
pub use ids::{FrameId, SensorId};
pub use lie::Pose;
pub use propagate::{ImuNoise, ImuSample};
pub use scalar::Scalar;
pub use state::{Block, ImuState, InitialState, Layout, SensorPrior, SensorState};
pub use update::relative_pose::RelativePose;
pub use update::reprojection::{CornerObservation, CornerSet};
pub use update::{UpdateKind, UpdateReport};

#[cfg(test)]
mod testing;
