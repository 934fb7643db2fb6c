//! The files of a LiDAR-camera dataset: `cam0/camera.yaml`, `target.yaml` (a plain board),
//! `lidar0/*.pcd` and `cam0/data.csv` (each read by its one reader in [`crate::dataset`] or
//! [`crate::camera_yaml`]), and the typed error of reading them.

use std::path::{Path, PathBuf};

use msreg_estimator::camera::Camera;

use crate::camera_yaml::Board;
use crate::camera_yaml::{read_camera_yaml, read_target_yaml, Target, YamlError};
use crate::dataset::{
    list_scans, read_camera_csv, CameraFrame, DatasetError, CAMERA_CSV, CAMERA_YAML, LIDAR_DIR,
    TARGET_YAML,
};
use crate::pointcloud::PcdError;
use crate::vision::ImageLoadError;

/// Why a LiDAR-camera dataset could not be read (each variant names the file, and the line
/// where there is one).
#[derive(Debug, thiserror::Error)]
pub enum LidarCameraInputError {
    /// A dataset file is missing or malformed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// `cam0/camera.yaml` or `target.yaml` is malformed.
    #[error(transparent)]
    Yaml(#[from] YamlError),
    /// `target.yaml` is not a plain board.
    #[error(
        "{}: lidar-camera needs target_type 'board' (a plain rectangle), got a checkerboard",
        path.display()
    )]
    NotABoard {
        /// `target.yaml`.
        path: PathBuf,
    },
    /// A scan file cannot be read.
    #[error("{}: cannot read scan", path.display())]
    Scan {
        /// The scan file.
        path: PathBuf,
        /// Why.
        source: PcdError,
    },
    /// An image cannot be read.
    #[error("{}: cannot read image", path.display())]
    Image {
        /// The image file.
        path: PathBuf,
        /// Why.
        source: ImageLoadError,
    },
}

/// A LiDAR-camera dataset on disk (docs/formats.md layout).
#[derive(Clone, Debug)]
pub struct LidarCameraDataset {
    /// The dataset directory.
    pub root: PathBuf,
    /// `cam0/camera.yaml`.
    pub camera: Camera<f64>,
    /// `target.yaml` (a plain board).
    pub board: Board,
    /// `(scan stamp, scan file)`, sorted.
    pub scans: Vec<(u64, PathBuf)>,
    /// The images of `cam0/data.csv`, sorted.
    pub images: Vec<CameraFrame>,
}

impl LidarCameraDataset {
    /// Opens the dataset: camera, target, scan list and image list (contents are read
    /// per frame later).
    pub fn open(root: &Path) -> Result<Self, LidarCameraInputError> {
        if !root.is_dir() {
            return Err(DatasetError::MissingDirectory {
                path: root.to_path_buf(),
            }
            .into());
        }
        let camera = read_camera_yaml(&root.join(CAMERA_YAML))?;
        let target_path = root.join(TARGET_YAML);
        let board = match read_target_yaml(&target_path)? {
            Target::Board(board) => board,
            // A checkerboard's printed pattern breaks the uniform-region detector.
            Target::Checkerboard(_) | Target::AprilGrid(_) => {
                return Err(LidarCameraInputError::NotABoard { path: target_path })
            }
        };
        let scans = list_scans(&root.join(LIDAR_DIR))?
            .into_iter()
            .map(|s| (s.stamp_ns, s.path))
            .collect::<Vec<_>>();
        if scans.is_empty() {
            return Err(DatasetError::Empty {
                path: root.join(LIDAR_DIR),
            }
            .into());
        }
        let images = read_camera_csv(root.join(CAMERA_CSV))?;
        Ok(Self {
            root: root.to_path_buf(),
            camera,
            board,
            scans,
            images,
        })
    }

    /// Image index nearest to each scan (by stamp).
    pub fn pairs(&self) -> Vec<(usize, usize, u64)> {
        self.scans
            .iter()
            .enumerate()
            .filter_map(|(k, (s, _))| {
                let (i, gap) = self
                    .images
                    .iter()
                    .enumerate()
                    .map(|(i, image)| (i, s.abs_diff(image.stamp_ns)))
                    .min_by_key(|&(_, g)| g)?;
                Some((k, i, gap))
            })
            .collect()
    }
}
