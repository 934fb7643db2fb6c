//! LiDAR-camera extrinsic calibration with a plain rectangular board (dissertation
//! chapter 2): PPC-Cal (LiDAR board points on the camera's board plane, eq. 2.4-2.5) and
//! PBPC-Cal (then LiDAR edge points on the back-projected planes of the image edges,
//! eq. 2.6-2.7), judged by the mean line reprojection error (MLRE, section 2.7.3).
//! Method, design decisions and measured numbers: docs/lidar_camera.md.
//!
//! - [`board`]: the target geometry; [`sim`]: the simulator.
//! - [`lidar_features`]: board plane and the four edge lines in a scan.
//! - [`camera_features`]: the four edge lines, corners and board plane in an image.
//! - [`solver`]: the two cost functions on the SE(3) Levenberg-Marquardt of
//!   [`crate::solve`]; [`mlre`]: the independent metric.
//! - [`pipeline`]: dataset to result (pairing, feature extraction, rejection with reasons,
//!   solve, report); [`cli`]: the `msreg` subcommands.

pub mod board;
pub mod camera_features;
pub mod dataset;
pub mod lidar_features;
pub mod mlre;
pub mod pipeline;
pub mod sim;
pub mod solver;

#[cfg(test)]
mod tests;

pub use board::Board;
pub use dataset::{read_image_list, LidarCameraDataset, LidarCameraInputError};
pub use sim::{simulate_lidar_camera, LidarCameraSim, LidarCameraSimConfig, LidarModel};
