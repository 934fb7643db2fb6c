//! LiDAR-camera extrinsic calibration with a plain rectangular board (dissertation
//! chapter 2): PPC-Cal (LiDAR board points on the camera's board plane, eq. 2.4-2.5) and
//! PBPC-Cal (then LiDAR edge points on the back-projected planes of the image edges,
//! eq. 2.6-2.7), judged by the mean line reprojection error (MLRE, section 2.7.3).
//! Method, design decisions and measured numbers: docs/lidar_camera.md.
//!
//! - The target geometry is [`crate::camera_yaml::Board`]; the simulator is
//!   [`crate::sim::lidar_camera`].
//! - [`lidar_features`]: board plane and the four edge lines in a scan.
//! - [`camera_features`]: the four edge lines, corners and board plane in an image.
//! - [`solver`]: the two cost functions on the SE(3) Levenberg-Marquardt of
//!   [`crate::solve`]; [`mlre`]: the independent metric.
//! - [`dataset`]: the dataset's files and their typed error; [`pipeline`]: dataset to result
//!   (pairing, feature extraction, rejection with reasons, solve, report). The `msreg`
//!   commands are the binary's `cli/lidar_camera.rs`.

pub mod camera_features;
pub mod dataset;
pub mod lidar_features;
pub mod mlre;
pub mod pipeline;
pub mod solver;

#[cfg(test)]
mod tests;

pub use crate::camera_yaml::Board;
pub use dataset::{LidarCameraDataset, LidarCameraInputError};
