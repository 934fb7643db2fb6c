//! Calibration pipelines: one function from a dataset to a result plus a report per task.
//! The CLI is a thin layer over them.

pub mod camera_imu;
pub mod cameras;
pub mod convergence;
pub mod convert;
pub mod driver;
pub mod dynamic_init;
pub mod error;
pub mod extrinsic;
pub mod gyro_bias;
pub mod imu_imu;
pub mod init;
pub mod jackknife;
pub mod joint;
pub mod lidar_imu;
pub mod observability;
pub mod planar;
pub mod pnp_odometry;
pub mod pose_imu;

pub use error::InputError;
