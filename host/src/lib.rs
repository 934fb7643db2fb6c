//! msreg host library: dataset readers and writers, the simulator, the calibration
//! pipelines and their evaluation. The `msreg` binary is a thin CLI over it; the estimator
//! core it drives lives in `msreg-estimator` (no_std, shared with the firmware).

pub mod bag;
pub mod calibrate;
pub mod camera_yaml;
pub mod check;
pub mod dataset;
pub mod eval;
pub mod export;
pub mod infra;
pub mod lidar;
pub mod lidar_camera;
pub mod link;
pub mod mi;
pub mod monitor;
pub mod ndt;
pub mod plot;
pub mod pointcloud;
pub mod report;
pub mod shared_data;
pub mod sim;
pub mod solve;
pub mod vision;
