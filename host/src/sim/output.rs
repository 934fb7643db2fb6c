//! The simulated dataset in memory and its writer to the dataset layout
//! (docs/formats.md), ground truth included.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::Isometry3;

use super::clock::Clock;
use super::config::SimConfig;
use super::trajectory::Trajectory;
use crate::dataset::{
    write_groundtruth_csv, write_imu_csv, write_pose_csv, CalibrationResult, DatasetError,
    DatasetYaml, ExtrinsicEstimate, GroundTruthRecord, ImuNoiseYaml, ImuRecord, PoseRecord,
    PoseSensorYaml, SectionName, DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML,
    GROUNDTRUTH_TRAJECTORY_CSV, IMU_CSV, IMU_YAML, POSE_CSV, POSE_SENSOR_YAML,
};

/// A simulated pose-IMU dataset with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct SimDataset {
    /// The options it was made with.
    pub config: SimConfig,
    /// The exact motion of `I` (time in seconds after `config.start_stamp_ns`).
    pub trajectory: Trajectory,
    /// `imu0/data.csv`.
    pub imu: Vec<ImuRecord>,
    /// `imu0/imu.yaml`.
    pub imu_noise: ImuNoiseYaml,
    /// `pose0/data.csv`: `T_odom_S`.
    pub pose: Vec<PoseRecord>,
    /// `pose0/sensor.yaml`.
    pub pose_sensor: PoseSensorYaml,
    /// `groundtruth/trajectory.csv`: state of `I` at every IMU stamp.
    pub groundtruth: Vec<GroundTruthRecord>,
    /// True `T_imu_pose`.
    pub t_imu_pose: Isometry3<f64>,
    /// True `t_d` of the pose sensor (s) (`timeshift_pose_imu`).
    pub time_offset_s: f64,
}

impl SimDataset {
    /// `T_imu_pose` at the end of the recording (differs from `t_imu_pose` after a knock).
    pub fn final_t_imu_pose(&self) -> Isometry3<f64> {
        super::odometry::mounting_at(&self.t_imu_pose, &self.config.pose, f64::INFINITY)
    }

    /// Seconds after the start stamp.
    pub fn seconds(&self, stamp_ns: u64) -> f64 {
        Clock {
            start_ns: self.config.start_stamp_ns,
        }
        .seconds(stamp_ns)
    }

    /// The true extrinsics at the end of the recording in result-file form (sigmas zero):
    /// after a knock, the knocked mounting.
    pub fn extrinsics(&self) -> CalibrationResult {
        CalibrationResult::new().with_extrinsic(
            SectionName::POSE0,
            ExtrinsicEstimate::exact(self.final_t_imu_pose(), self.time_offset_s),
        )
    }

    /// `dataset.yaml` contents.
    pub fn metadata(&self) -> DatasetYaml {
        let c = &self.config;
        DatasetYaml {
            sensors: vec!["imu0".into(), "pose0".into()],
            description: format!(
                "msreg simulator: pose-IMU, seed {}, {} s, IMU {} Hz, pose {} Hz, \
                 time offset {} s, jitter {}, gap {:?}",
                c.seed,
                c.duration_s,
                c.imu.rate_hz,
                c.pose.rate_hz,
                c.pose.time_offset_s,
                c.pose.jitter_fraction,
                c.pose.gap_s
            ),
            rates_hz: BTreeMap::from([
                ("imu0".to_string(), c.imu.rate_hz),
                ("pose0".to_string(), c.pose.rate_hz),
            ]),
        }
    }

    /// Writes the dataset layout under `dir` (created if needed).
    pub fn write(&self, dir: impl AsRef<Path>) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        super::write::create_dirs(dir, &["imu0", "pose0", "groundtruth"])?;
        self.metadata().write(dir.join(DATASET_YAML))?;
        write_imu_csv(dir.join(IMU_CSV), &self.imu)?;
        self.imu_noise.write(dir.join(IMU_YAML))?;
        write_pose_csv(dir.join(POSE_CSV), &self.pose)?;
        self.pose_sensor.write(dir.join(POSE_SENSOR_YAML))?;
        write_groundtruth_csv(dir.join(GROUNDTRUTH_TRAJECTORY_CSV), &self.groundtruth)?;
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))
    }
}
