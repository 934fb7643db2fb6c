//! The files each pipeline needs, and every one of them that is missing.

use std::path::Path;

use super::Finding;
use crate::dataset::{
    CAMERA_CSV, CAMERA_YAML, IMU_CSV, IMU_YAML, LIDAR_DIR, OBSERVED_CORNERS_CSV, POSE_CSV,
    POSE_SENSOR_YAML, TARGET_YAML,
};

/// What the calibration that follows needs (`msreg check` alone: [`Needs::Any`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Needs {
    /// Whatever is present is checked; some sensor data must be.
    Any,
    /// `calibrate pose-imu`.
    PoseImu,
    /// `calibrate camera-imu`.
    CameraImu,
    /// `calibrate lidar-imu`.
    LidarImu,
    /// `calibrate joint`.
    Joint,
}

impl Needs {
    /// The pipeline's command name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Any => "check",
            Self::PoseImu => "calibrate pose-imu",
            Self::CameraImu => "calibrate camera-imu",
            Self::LidarImu => "calibrate lidar-imu",
            Self::Joint => "calibrate joint",
        }
    }

    /// The files needed; alternatives are listed in one entry.
    fn files(self) -> Vec<&'static [&'static str]> {
        let imu: [&'static [&'static str]; 2] = [&[IMU_CSV], &[IMU_YAML]];
        let camera: [&'static [&'static str]; 3] = [
            &[CAMERA_YAML],
            &[CAMERA_CSV, OBSERVED_CORNERS_CSV],
            &[TARGET_YAML],
        ];
        let lidar: &'static [&'static str] = &[LIDAR_DIR];
        match self {
            Self::Any => Vec::new(),
            Self::PoseImu => [imu.as_slice(), &[&[POSE_CSV], &[POSE_SENSOR_YAML]]].concat(),
            Self::CameraImu => [imu.as_slice(), &camera].concat(),
            Self::LidarImu => [imu.as_slice(), &[lidar]].concat(),
            Self::Joint => [imu.as_slice(), &camera, &[lidar]].concat(),
        }
    }
}

/// Sensor files a dataset may hold, for the message when there is none.
const ANY_DATA: [&str; 4] = [IMU_CSV, POSE_CSV, CAMERA_CSV, LIDAR_DIR];

/// Every file `needs` asks for that `root` lacks, in one finding; for [`Needs::Any`], a
/// finding when no sensor data is present at all.
pub fn missing(root: &Path, needs: Needs) -> Vec<Finding> {
    if needs == Needs::Any {
        let present = ANY_DATA
            .iter()
            .chain([&OBSERVED_CORNERS_CSV])
            .any(|f| root.join(f).exists());
        return match present {
            true => Vec::new(),
            false => vec![Finding::NoSensorData {
                looked_for: ANY_DATA
                    .iter()
                    .map(|f| root.join(f).display().to_string())
                    .collect(),
            }],
        };
    }
    let mut files: Vec<&'static [&'static str]> = needs.files();
    // corners.csv with x, y, z places its corners without target.yaml; the loader decides.
    if root.join(OBSERVED_CORNERS_CSV).is_file() {
        files.retain(|alternatives| alternatives != &[TARGET_YAML]);
    }
    let missing: Vec<String> = files
        .iter()
        .filter(|alternatives| !alternatives.iter().any(|f| root.join(f).exists()))
        .map(|alternatives| {
            let names: Vec<String> = alternatives
                .iter()
                .map(|f| root.join(f).display().to_string())
                .collect();
            names.join(" or ")
        })
        .collect();
    match missing.is_empty() {
        true => Vec::new(),
        false => vec![Finding::MissingFiles {
            pipeline: needs.name(),
            files: missing,
        }],
    }
}
