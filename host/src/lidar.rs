//! LiDAR front-end of the LiDAR-IMU filter: where scans come from ([`ScanSource`]: files
//! of the dataset layout or the simulator, read one at a time) and motion compensation
//! ([`deskew`], eq. 3.18) from a buffer of the filter's IMU poses ([`PoseBuffer`]).

pub mod deskew;
mod source;

pub use deskew::{deskew_scan, PoseBuffer};
pub use source::{FileScans, ScanLoadError, ScanSource};
