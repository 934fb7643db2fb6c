//! A drive's files as `msreg monitor` (and `msreg link replay` of a drive) reads them:
//! `imu0/`, the pose sensors `pose0/` ... `poseN-1/` (discovered from the folders present) and
//! the calibration of record with a `poseN` section for each.

use std::path::{Path, PathBuf};

use super::{MonitorInput, MAX_POSE_SENSORS};
use crate::dataset::{
    CalibrationResult, Dataset, DatasetError, ExtrinsicEstimate, PoseRecord, PoseSensorYaml,
    SectionName, SensorId, SensorKind, CALIBRATION_OF_RECORD_YAML,
};

/// Why a drive's files could not be read.
#[derive(Debug, thiserror::Error)]
pub enum DriveFilesError {
    /// A dataset file is missing or malformed (names the file and line).
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// The pose sensors present are not `pose0/` ... `poseN-1/` without a gap (or there is
    /// none): the named folder is missing.
    #[error("{}: missing (the monitor reads pose0/ ... poseN-1/ without a gap)", path.display())]
    MissingPose {
        /// The missing folder.
        path: PathBuf,
    },
    /// More pose sensors than one monitor filter takes.
    #[error(
        "{}: {count} pose sensors; the monitor takes at most {max}",
        dir.display()
    )]
    TooManyPoseSensors {
        /// The dataset.
        dir: PathBuf,
        /// Pose sensors present.
        count: usize,
        /// [`MAX_POSE_SENSORS`].
        max: usize,
    },
    /// The calibration of record lacks a sensor's section.
    #[error("{}: no `{section}` section", path.display())]
    NoSection {
        /// The calibration file.
        path: PathBuf,
        /// `pose0`, `pose1`, ...
        section: String,
    },
}

/// The pose sensors of `dataset`: `pose0` ... `poseN-1`, each present.
fn pose_count(dataset: &Dataset, dir: &Path) -> Result<usize, DriveFilesError> {
    let present = dataset.sensors_of(SensorKind::Pose)?;
    let count = present.len().max(1);
    if let Some(k) = (0..count).find(|&k| present.get(k).map(|s| usize::from(s.index)) != Some(k)) {
        let missing = SensorId::pose(u16::try_from(k).unwrap_or(u16::MAX));
        return Err(DriveFilesError::MissingPose {
            path: dataset.path(&missing.to_string()),
        });
    }
    if count > MAX_POSE_SENSORS {
        return Err(DriveFilesError::TooManyPoseSensors {
            dir: dir.to_path_buf(),
            count,
            max: MAX_POSE_SENSORS,
        });
    }
    Ok(count)
}

/// A drive's files: the dataset, the pose sensors after `pose0` and the calibration of
/// record.
pub struct DriveFiles {
    dataset: Dataset,
    /// `pose1` ... `poseN-1` (`pose0` is the dataset's own).
    more_poses: Vec<(Vec<PoseRecord>, PoseSensorYaml)>,
    prior: Vec<ExtrinsicEstimate>,
}

impl DriveFiles {
    /// Reads `dir` and the calibration of record (`initial`, default
    /// `<dir>/calibration.yaml`); errors name the file.
    pub fn read(dir: &Path, initial: Option<&Path>) -> Result<Self, DriveFilesError> {
        let dataset = Dataset::open(dir)?;
        let count = pose_count(&dataset, dir)?;
        let more_poses = (1..count)
            .map(|k| dataset.read_pose_sensor(u16::try_from(k).unwrap_or(u16::MAX)))
            .collect::<Result<Vec<_>, _>>()?;
        let prior_path = initial.map_or_else(
            || dataset.path(CALIBRATION_OF_RECORD_YAML),
            Path::to_path_buf,
        );
        let record = CalibrationResult::read(&prior_path)?;
        let prior = (0..count)
            .map(|k| {
                let section = SectionName::pose(u16::try_from(k).unwrap_or(u16::MAX));
                record
                    .extrinsic(&section)
                    .copied()
                    .ok_or_else(|| DriveFilesError::NoSection {
                        path: prior_path.clone(),
                        section: section.to_string(),
                    })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            dataset,
            more_poses,
            prior,
        })
    }

    /// Number of pose sensors.
    pub fn pose_sensors(&self) -> usize {
        self.prior.len()
    }

    /// The monitor's input.
    pub fn input(&self) -> Result<MonitorInput<'_>, DriveFilesError> {
        let d = &self.dataset;
        let mut poses = vec![d.require_pose0()?];
        let mut pose_noise = vec![d.require_pose0_sensor()?];
        for (p, n) in &self.more_poses {
            poses.push(p.as_slice());
            pose_noise.push(n);
        }
        Ok(MonitorInput {
            imu: d.require_imu()?,
            imu_noise: d.require_imu_noise()?,
            poses,
            pose_noise,
            prior: self.prior.clone(),
        })
    }
}
