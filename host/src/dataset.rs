//! Readers and writers of the dataset directory layout and the calibration
//! result file (docs/formats.md, section 2 and "Calibration
//! result").
//!
//! Every reader validates what it reads and fails with a [`DatasetError`]
//! naming the file and, for line-oriented formats, the 1-based line, so the
//! CLI can report bad input (exit code 2) instead of panicking. Every writer
//! emits floats in their shortest exact decimal form, so a write followed by a
//! read reproduces the values bit for bit.

mod camera;
mod csv;
mod error;
mod groundtruth;
mod imu;
mod layout;
mod lidar;
mod meta;
mod observed_corners;
mod pose;
mod pose_pair;
mod prior;
mod result;
mod yaml;

pub use camera::{
    read_camera_csv, read_corners_csv, read_target_poses_csv, write_camera_csv, write_corners_csv,
    CameraFrame, CornerTruth, CAMERA_CSV, CAMERA_DATA_DIR, CAMERA_YAML, GROUNDTRUTH_CORNERS_CSV,
    GROUNDTRUTH_TARGET_POSES_CSV, TARGET_YAML,
};
pub use error::DatasetError;
pub use groundtruth::{read_groundtruth_csv, write_groundtruth_csv, GroundTruthRecord};
pub use imu::{
    check_imu_units, read_imu_csv, to_instantaneous, write_imu_csv, ImuNoiseYaml, ImuRecord,
    SampleTiming,
};
pub use layout::{
    Dataset, DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML, GROUNDTRUTH_TRAJECTORY_CSV, IMU_CSV,
    IMU_YAML, POSE_CSV, POSE_SENSOR_YAML,
};
pub use lidar::{list_scans, LidarYaml, ScanFile, LIDAR_DIR, LIDAR_YAML};
pub use meta::DatasetYaml;
pub use observed_corners::{
    read_observed_corners, ObservedCorner, ObservedImage, OBSERVED_CORNERS_CSV,
};
pub use pose::{read_pose_csv, write_pose_csv, PoseRecord, PoseSensorYaml};
pub use pose_pair::{PosePairCalibration, CALIBRATION_OF_RECORD_YAML};
pub use prior::{ExtrinsicPrior, PriorError, PriorFile};
pub use result::{
    isometry_from_matrix, read_t_world_cam, BadName, CalibrationResult, CameraIntrinsics, Dof,
    ExtrinsicEstimate, ExtrinsicKeys, ResultSection, SectionName, SensorId, SensorKind,
};
