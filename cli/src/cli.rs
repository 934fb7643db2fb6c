//! The command-line modules of the `msreg` binary: argument parsing (clap), progress bars
//! (indicatif), error context (anyhow) and printing, over the `msreg_host` library. One
//! module per command; the library never names clap, indicatif or anyhow.

pub mod aruco;
pub mod camera_imu;
pub mod cameras;
pub mod check;
pub mod convert;
pub mod demo;
pub mod detect;
pub mod export;
pub mod imu_imu;
pub mod infra;
pub mod joint;
pub mod lidar_camera;
pub mod lidar_imu;
pub mod link;
pub mod match_cmd;
pub mod mi;
pub mod monitor;
pub mod outcome;
pub mod prior_map;
pub mod sim_camera;
pub mod sim_cameras;
pub mod sim_drive;
pub mod sim_joint;
pub mod sim_prior_map;
pub mod target;
