//! The dataset directory as a whole: file names of the layout and a loader
//! that reads every part present, so a task asks for what it needs and gets
//! an error naming the missing file otherwise.

use std::path::{Path, PathBuf};

use super::error::DatasetError;
use super::groundtruth::{read_groundtruth_csv, GroundTruthRecord};
use super::imu::{check_imu_units, read_imu_csv, to_instantaneous, ImuNoiseYaml, ImuRecord};
use super::lidar::{list_scans, LidarYaml, ScanFile, LIDAR_DIR, LIDAR_YAML};
use super::meta::DatasetYaml;
use super::pose::{read_pose_csv, PoseRecord, PoseSensorYaml};
use super::result::{CalibrationResult, SensorId, SensorKind};

/// `dataset.yaml`, relative to the dataset root.
pub const DATASET_YAML: &str = "dataset.yaml";
/// IMU samples.
pub const IMU_CSV: &str = "imu0/data.csv";
/// IMU noise (Kalibr).
pub const IMU_YAML: &str = "imu0/imu.yaml";
/// Pose-sensor odometry.
pub const POSE_CSV: &str = "pose0/data.csv";
/// Pose-sensor increment noise.
pub const POSE_SENSOR_YAML: &str = "pose0/sensor.yaml";
/// Ground-truth IMU trajectory (simulator output).
pub const GROUNDTRUTH_TRAJECTORY_CSV: &str = "groundtruth/trajectory.csv";
/// Ground-truth extrinsics (simulator output, result-file format).
pub const GROUNDTRUTH_EXTRINSICS_YAML: &str = "groundtruth/extrinsics.yaml";

/// A dataset directory with every supported part that is present loaded.
///
/// Loading is eager: a present but malformed file is an error at
/// [`Dataset::open`], even when the task would not have needed it.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// The dataset directory.
    pub root: PathBuf,
    /// `dataset.yaml`.
    pub meta: Option<DatasetYaml>,
    /// `imu0/data.csv`.
    pub imu: Option<Vec<ImuRecord>>,
    /// `imu0/imu.yaml`.
    pub imu_noise: Option<ImuNoiseYaml>,
    /// `pose0/data.csv`.
    pub pose0: Option<Vec<PoseRecord>>,
    /// `pose0/sensor.yaml`.
    pub pose0_sensor: Option<PoseSensorYaml>,
    /// `groundtruth/trajectory.csv`.
    pub groundtruth_trajectory: Option<Vec<GroundTruthRecord>>,
    /// `groundtruth/extrinsics.yaml`.
    pub groundtruth_extrinsics: Option<CalibrationResult>,
}

impl Dataset {
    /// Opens `dir` and reads every part present. Absent files are `None`;
    /// present but malformed ones are errors.
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, DatasetError> {
        let root = dir.as_ref().to_path_buf();
        if !root.is_dir() {
            return Err(DatasetError::MissingDirectory { path: root });
        }
        let imu_noise = optional(root.join(IMU_YAML), ImuNoiseYaml::read)?;
        let mut imu = optional(root.join(IMU_CSV), read_imu_csv)?;
        if let Some(records) = imu.as_mut() {
            check_imu_units(&root.join(IMU_CSV), records)?;
            let timing = imu_noise.as_ref().and_then(|n| n.sample_timing);
            to_instantaneous(records, timing.unwrap_or_default());
        }
        Ok(Self {
            meta: optional(root.join(DATASET_YAML), DatasetYaml::read)?,
            imu,
            imu_noise,
            pose0: optional(root.join(POSE_CSV), read_pose_csv)?,
            pose0_sensor: optional(root.join(POSE_SENSOR_YAML), PoseSensorYaml::read)?,
            groundtruth_trajectory: optional(
                root.join(GROUNDTRUTH_TRAJECTORY_CSV),
                read_groundtruth_csv,
            )?,
            groundtruth_extrinsics: optional(
                root.join(GROUNDTRUTH_EXTRINSICS_YAML),
                CalibrationResult::read,
            )?,
            root,
        })
    }

    /// `relative` (one of the layout constants) under the dataset root.
    pub fn path(&self, relative: &str) -> PathBuf {
        self.root.join(relative)
    }

    /// IMU samples, or an error naming `imu0/data.csv`.
    pub fn require_imu(&self) -> Result<&[ImuRecord], DatasetError> {
        self.require(self.imu.as_deref(), IMU_CSV)
    }

    /// IMU noise, or an error naming `imu0/imu.yaml`.
    pub fn require_imu_noise(&self) -> Result<&ImuNoiseYaml, DatasetError> {
        self.require(self.imu_noise.as_ref(), IMU_YAML)
    }

    /// Odometry poses, or an error naming `pose0/data.csv`.
    pub fn require_pose0(&self) -> Result<&[PoseRecord], DatasetError> {
        self.require(self.pose0.as_deref(), POSE_CSV)
    }

    /// Odometry noise, or an error naming `pose0/sensor.yaml`.
    pub fn require_pose0_sensor(&self) -> Result<&PoseSensorYaml, DatasetError> {
        self.require(self.pose0_sensor.as_ref(), POSE_SENSOR_YAML)
    }

    /// Ground-truth trajectory, or an error naming `groundtruth/trajectory.csv`.
    pub fn require_groundtruth_trajectory(&self) -> Result<&[GroundTruthRecord], DatasetError> {
        self.require(
            self.groundtruth_trajectory.as_deref(),
            GROUNDTRUTH_TRAJECTORY_CSV,
        )
    }

    /// Ground-truth extrinsics, or an error naming `groundtruth/extrinsics.yaml`.
    pub fn require_groundtruth_extrinsics(&self) -> Result<&CalibrationResult, DatasetError> {
        self.require(
            self.groundtruth_extrinsics.as_ref(),
            GROUNDTRUTH_EXTRINSICS_YAML,
        )
    }

    /// The LiDAR scans `lidar0/<stamp_ns>.pcd` sorted by stamp (listed, not read), or an
    /// error naming `lidar0/`.
    pub fn lidar0_scans(&self) -> Result<Vec<ScanFile>, DatasetError> {
        list_scans(&self.path(LIDAR_DIR))
    }

    /// `lidar0/lidar.yaml` if present (informative).
    pub fn lidar0_yaml(&self) -> Result<Option<LidarYaml>, DatasetError> {
        optional(self.path(LIDAR_YAML), LidarYaml::read)
    }

    /// The sensors whose folders are present (`imu0`, `cam1`, `lidar0`, ...), in result-file
    /// section order (cameras, LiDARs, pose sensors, IMUs; by index within a kind). A folder
    /// whose name is no sensor name (`groundtruth`, `camera0`) is not a sensor.
    pub fn sensors(&self) -> Result<Vec<SensorId>, DatasetError> {
        let entries = std::fs::read_dir(&self.root)
            .map_err(|source| super::csv::io_error(&self.root, source))?;
        let mut sensors: Vec<SensorId> = entries
            .filter_map(Result::ok)
            .filter(|e| e.path().is_dir())
            .filter_map(|e| e.file_name().to_str()?.parse().ok())
            .collect();
        sensors.sort();
        Ok(sensors)
    }

    /// The sensors of one kind present, by index.
    pub fn sensors_of(&self, kind: SensorKind) -> Result<Vec<SensorId>, DatasetError> {
        let mut all = self.sensors()?;
        all.retain(|s| s.kind == kind);
        Ok(all)
    }

    /// `<sensor>/<file>` under the dataset root (`cam1/data.csv`).
    pub fn sensor_path(&self, sensor: SensorId, file: &str) -> PathBuf {
        self.root.join(sensor.to_string()).join(file)
    }

    /// `imuN/data.csv` and `imuN/imu.yaml` of any IMU, read and converted as `imu0`'s are at
    /// [`Dataset::open`] (units checked, sample timing applied); errors name the file.
    pub fn read_imu(&self, index: u16) -> Result<(Vec<ImuRecord>, ImuNoiseYaml), DatasetError> {
        let imu = SensorId::imu(index);
        let noise = ImuNoiseYaml::read(self.sensor_path(imu, "imu.yaml"))?;
        let csv = self.sensor_path(imu, "data.csv");
        let mut records = read_imu_csv(&csv)?;
        check_imu_units(&csv, &records)?;
        to_instantaneous(&mut records, noise.sample_timing.unwrap_or_default());
        Ok((records, noise))
    }

    /// `poseN/data.csv` and `poseN/sensor.yaml` of any pose sensor; errors name the file.
    pub fn read_pose_sensor(
        &self,
        index: u16,
    ) -> Result<(Vec<PoseRecord>, PoseSensorYaml), DatasetError> {
        let pose = SensorId::pose(index);
        let records = read_pose_csv(self.sensor_path(pose, "data.csv"))?;
        let noise = PoseSensorYaml::read(self.sensor_path(pose, "sensor.yaml"))?;
        Ok((records, noise))
    }

    fn require<'a, T: ?Sized>(
        &self,
        part: Option<&'a T>,
        relative: &str,
    ) -> Result<&'a T, DatasetError> {
        part.ok_or_else(|| DatasetError::MissingFile {
            path: self.path(relative),
        })
    }
}

/// Reads `path` with `read`, mapping a missing file to `None`.
fn optional<T>(
    path: PathBuf,
    read: impl FnOnce(PathBuf) -> Result<T, DatasetError>,
) -> Result<Option<T>, DatasetError> {
    match read(path) {
        Ok(value) => Ok(Some(value)),
        Err(DatasetError::MissingFile { .. }) => Ok(None),
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    type TestResult = Result<(), Box<dyn std::error::Error>>;

    #[test]
    fn missing_directory_is_an_error() {
        let err = Dataset::open("/definitely/not/here");
        assert!(matches!(err, Err(DatasetError::MissingDirectory { .. })));
    }

    #[test]
    fn absent_parts_are_none_and_required_ones_name_the_file() -> TestResult {
        let dir = tempfile::tempdir()?;
        std::fs::create_dir(dir.path().join("imu0"))?;
        std::fs::write(
            dir.path().join(IMU_CSV),
            "1,0,0,0,0,0,9.81\n2,0,0,0,0,0,9.81\n",
        )?;
        let dataset = Dataset::open(dir.path())?;
        assert_eq!(dataset.require_imu()?.len(), 2);
        assert!(dataset.pose0.is_none() && dataset.meta.is_none());
        let err = dataset
            .require_imu_noise()
            .err()
            .ok_or("expected an error")?;
        assert!(err.to_string().contains("imu0/imu.yaml"), "{err}");
        let err = dataset.require_pose0().err().ok_or("expected an error")?;
        assert!(
            matches!(&err, DatasetError::MissingFile { path } if path.ends_with(POSE_CSV)),
            "{err}"
        );
        Ok(())
    }

    #[test]
    fn sensors_are_discovered_from_the_folders_present() -> TestResult {
        let dir = tempfile::tempdir()?;
        for folder in [
            "imu1",
            "imu0",
            "cam1",
            "cam0",
            "lidar0",
            "pose2",
            "groundtruth",
            "cam01",
        ] {
            std::fs::create_dir(dir.path().join(folder))?;
        }
        std::fs::write(dir.path().join("lidar3"), "a file, not a folder")?;
        let dataset = Dataset::open(dir.path())?;
        let names: Vec<String> = dataset.sensors()?.iter().map(ToString::to_string).collect();
        assert_eq!(names, ["cam0", "cam1", "lidar0", "pose2", "imu0", "imu1"]);
        assert_eq!(dataset.sensors_of(SensorKind::Imu)?.len(), 2);
        let err = dataset.read_imu(1).err().ok_or("expected an error")?;
        assert!(err.to_string().contains("imu1/imu.yaml"), "{err}");
        Ok(())
    }

    #[test]
    fn a_malformed_present_part_fails_open() -> TestResult {
        let dir = tempfile::tempdir()?;
        std::fs::create_dir(dir.path().join("pose0"))?;
        std::fs::write(dir.path().join(POSE_SENSOR_YAML), "rotation_noise_rad: [\n")?;
        let err = Dataset::open(dir.path()).err().ok_or("expected an error")?;
        assert!(err.to_string().contains("sensor.yaml"), "{err}");
        Ok(())
    }
}
