//! A drive's files as `msreg monitor` (and `msreg link replay` of a drive) reads them:
//! `imu0/`, `pose0/`, `pose1/` and the calibration of record.

use std::path::{Path, PathBuf};

use super::MonitorInput;
use crate::dataset::{
    read_pose_csv, Dataset, DatasetError, ExtrinsicEstimate, PosePairCalibration, PoseRecord,
    PoseSensorYaml, CALIBRATION_OF_RECORD_YAML,
};

/// Why a drive's files could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DriveFilesError {
    /// A dataset file is missing or malformed (names the file and line).
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// `pose1/data.csv` or `pose1/sensor.yaml` is missing.
    #[error("{}: missing (the monitor needs a second pose sensor)", path.display())]
    NoPose1 {
        /// The missing file.
        path: PathBuf,
    },
    /// The calibration of record lacks a sensor's section.
    #[error("{}: no `{section}` section", path.display())]
    NoSection {
        /// The calibration file.
        path: PathBuf,
        /// `pose0` or `pose1`.
        section: &'static str,
    },
}

fn pose1(dataset: &Dataset) -> Result<(Vec<PoseRecord>, PoseSensorYaml), DriveFilesError> {
    let csv = dataset.path("pose1/data.csv");
    let yaml = dataset.path("pose1/sensor.yaml");
    for p in [&csv, &yaml] {
        if !p.is_file() {
            return Err(DriveFilesError::NoPose1 { path: p.clone() });
        }
    }
    Ok((read_pose_csv(&csv)?, PoseSensorYaml::read(&yaml)?))
}

/// A drive's files: the dataset, the second pose sensor and the calibration of record.
pub struct DriveFiles {
    dataset: Dataset,
    poses1: Vec<PoseRecord>,
    noise1: PoseSensorYaml,
    prior: [ExtrinsicEstimate; 2],
}

impl DriveFiles {
    /// Reads `dir` and the calibration of record (`initial`, default
    /// `<dir>/calibration.yaml`); errors name the file.
    pub fn read(dir: &Path, initial: Option<&Path>) -> Result<Self, DriveFilesError> {
        let dataset = Dataset::open(dir)?;
        let (poses1, noise1) = pose1(&dataset)?;
        let prior_path = initial.map_or_else(
            || dataset.path(CALIBRATION_OF_RECORD_YAML),
            Path::to_path_buf,
        );
        let prior = PosePairCalibration::read(&prior_path)?;
        let missing = |section| DriveFilesError::NoSection {
            path: prior_path.clone(),
            section,
        };
        let prior = [
            prior.pose0.ok_or_else(|| missing("pose0"))?,
            prior.pose1.ok_or_else(|| missing("pose1"))?,
        ];
        Ok(Self {
            dataset,
            poses1,
            noise1,
            prior,
        })
    }

    /// The monitor's input.
    pub fn input(&self) -> Result<MonitorInput<'_>, DriveFilesError> {
        let d = &self.dataset;
        Ok(MonitorInput {
            imu: d.require_imu()?,
            imu_noise: d.require_imu_noise()?,
            poses: [d.require_pose0()?, &self.poses1],
            pose_noise: [d.require_pose0_sensor()?, &self.noise1],
            prior: self.prior,
        })
    }
}
