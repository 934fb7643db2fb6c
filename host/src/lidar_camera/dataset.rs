//! The files of a LiDAR-camera dataset: `cam0/camera.yaml`, `target.yaml` (a plain board),
//! `lidar0/*.pcd` and `cam0/data.csv`, and the typed error of reading them.

use std::path::{Path, PathBuf};

use msreg_estimator::camera::Camera;

use super::board::Board;
use crate::camera_yaml::{read_camera_yaml, read_target_yaml, Target, YamlError};
use crate::dataset::{list_scans, DatasetError, LIDAR_DIR};
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
    /// A timestamp of `cam0/data.csv` is not an integer.
    #[error("{}:{line}: timestamp `{text}` is not an integer in ns", path.display())]
    BadStamp {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The text found.
        text: String,
    },
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

/// A LiDAR-camera dataset on disk (CONVENTIONS.md layout).
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
    /// `(image stamp, image file)` from `cam0/data.csv`, sorted.
    pub images: Vec<(u64, PathBuf)>,
}

/// Reads `cam0/data.csv` (`timestamp [ns], filename`), naming file and line on errors.
pub fn read_image_list(path: &Path) -> Result<Vec<(u64, PathBuf)>, LidarCameraInputError> {
    let text = std::fs::read_to_string(path).map_err(|source| DatasetError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let dir = path.parent().map(|p| p.join("data")).unwrap_or_default();
    let mut out: Vec<(u64, PathBuf)> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let mut parts = line.splitn(2, ',');
        let (Some(stamp), Some(name)) = (parts.next(), parts.next()) else {
            return Err(DatasetError::MalformedLine {
                path: path.to_path_buf(),
                line: i + 1,
                expected: "`timestamp [ns],filename`".into(),
            }
            .into());
        };
        let stamp: u64 = stamp
            .trim()
            .parse()
            .map_err(|_| LidarCameraInputError::BadStamp {
                path: path.to_path_buf(),
                line: i + 1,
                text: stamp.trim().to_string(),
            })?;
        if let Some((prev, _)) = out.last() {
            if stamp <= *prev {
                return Err(DatasetError::TimeNotIncreasing {
                    path: path.to_path_buf(),
                    line: i + 1,
                    stamp_ns: stamp,
                    previous_ns: *prev,
                }
                .into());
            }
        }
        out.push((stamp, dir.join(name.trim())));
    }
    if out.is_empty() {
        return Err(DatasetError::Empty {
            path: path.to_path_buf(),
        }
        .into());
    }
    Ok(out)
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
        let camera = read_camera_yaml(&root.join("cam0/camera.yaml"))?;
        let target_path = root.join("target.yaml");
        let board = match read_target_yaml(&target_path)? {
            Target::Board { width_m, height_m } => Board { width_m, height_m },
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
        let images = read_image_list(&root.join("cam0/data.csv"))?;
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
                    .map(|(i, (t, _))| (i, s.abs_diff(*t)))
                    .min_by_key(|&(_, g)| g)?;
                Some((k, i, gap))
            })
            .collect()
    }
}
