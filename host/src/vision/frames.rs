//! Corner detection over a whole dataset (the input of camera-IMU calibration): the camera,
//! target and image list of the dataset layout ([`CameraDataset`]), and the target's
//! detector (checkerboard or AprilGrid) run on every image in parallel ([`detect_frames`]),
//! one [`FrameResult`] per image in stamp order with the corners or the reason there are
//! none. Unreadable images and
//! images of the wrong size are bad input (an error naming the file), not a rejected frame.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use msreg_estimator::camera::Camera;
use nalgebra::{Vector2, Vector3};
use rayon::prelude::*;

use super::aprilgrid::{detect_aprilgrid, AprilGridParams};
use super::checkerboard::{detect_checkerboard, DetectorParams, NoDetection};
use super::gray::{GrayImage, ImageLoadError};
use crate::camera_yaml::{read_camera_yaml, read_target_yaml, Target, YamlError};
use crate::dataset::{
    read_camera_csv, CameraFrame, DatasetError, CAMERA_CSV, CAMERA_YAML, TARGET_YAML,
};

/// Why the camera part of a dataset cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CameraInputError {
    /// `cam0/data.csv` missing or malformed.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// `cam0/camera.yaml` or `target.yaml` missing or malformed.
    #[error(transparent)]
    Yaml(#[from] YamlError),
    /// `target.yaml` describes a plain board, not a corner target.
    #[error(
        "{}: target_type must be checkerboard or aprilgrid for corner detection",
        path.display()
    )]
    NotCornerTarget {
        /// The target file.
        path: PathBuf,
    },
    /// An image listed in `cam0/data.csv` is missing or cannot be decoded.
    #[error(transparent)]
    Image(#[from] ImageLoadError),
    /// An image whose size differs from `camera.yaml`'s resolution.
    #[error(
        "{}: {width}x{height} image, but the camera.yaml resolution is {expected_width}x{expected_height}",
        path.display()
    )]
    SizeMismatch {
        /// The image.
        path: PathBuf,
        /// Its width.
        width: usize,
        /// Its height.
        height: usize,
        /// `resolution[0]`.
        expected_width: u32,
        /// `resolution[1]`.
        expected_height: u32,
    },
}

/// The camera inputs of a dataset directory.
#[derive(Debug, Clone)]
pub struct CameraDataset {
    /// `cam0/camera.yaml`.
    pub camera: Camera<f64>,
    /// `target.yaml`: a checkerboard or an AprilGrid.
    pub target: Target,
    /// `cam0/data.csv`, stamps strictly increasing, paths resolved to `cam0/data/`.
    pub frames: Vec<CameraFrame>,
}

impl CameraDataset {
    /// Reads `cam0/camera.yaml`, `target.yaml` and `cam0/data.csv` under `dir` (images are
    /// not opened).
    pub fn open(dir: impl AsRef<Path>) -> Result<Self, CameraInputError> {
        let dir = dir.as_ref();
        if !dir.is_dir() {
            return Err(DatasetError::MissingDirectory {
                path: dir.to_path_buf(),
            }
            .into());
        }
        let camera = read_camera_yaml(&dir.join(CAMERA_YAML))?;
        let target_path = dir.join(TARGET_YAML);
        let target = read_target_yaml(&target_path)?;
        if let Target::Board { .. } = target {
            return Err(CameraInputError::NotCornerTarget { path: target_path });
        }
        let frames = read_camera_csv(dir.join(CAMERA_CSV))?;
        Ok(Self {
            camera,
            target,
            frames,
        })
    }

    /// [`detect_frames`] on every image of the dataset.
    pub fn detect(
        &self,
        params: &DetectorParams,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<Vec<FrameResult>, CameraInputError> {
        detect_frames(
            &self.frames,
            &self.target,
            Some(&self.camera),
            params,
            progress,
        )
    }
}

/// The corners found in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameCorners {
    /// Kalibr corner ids (checkerboard `r * cols + c`, AprilGrid `4 * tag + k`), ascending.
    pub ids: Vec<usize>,
    /// Refined pixel of each id.
    pub pixels: Vec<Vector2<f64>>,
}

impl FrameCorners {
    /// The target-frame point of every id (for PnP or a reprojection residual).
    pub fn target_points(&self, target: &Target) -> Vec<Vector3<f64>> {
        self.ids
            .iter()
            .filter_map(|&id| target.corner(id))
            .collect()
    }
}

/// The outcome for one image.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameResult {
    /// Image stamp (camera clock), ns.
    pub stamp_ns: u64,
    /// The image file.
    pub path: PathBuf,
    /// The corners, or why the frame was rejected (partial board, none, ambiguous ...).
    pub corners: Result<FrameCorners, NoDetection>,
}

/// Detects the target in every frame in parallel (rayon), results in the order of `frames`:
/// a checkerboard only when it is whole (that detector's rule), an AprilGrid from
/// [`AprilGridParams::min_tags`] tags up (partial views are its point). `camera`, when given,
/// checks every image's size. `progress` receives the fraction of images done.
pub fn detect_frames(
    frames: &[CameraFrame],
    target: &Target,
    camera: Option<&Camera<f64>>,
    params: &DetectorParams,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<Vec<FrameResult>, CameraInputError> {
    let done = AtomicUsize::new(0);
    frames
        .par_iter()
        .map(|frame| {
            let image = GrayImage::load(&frame.path)?;
            if let Some(camera) = camera {
                let (w, h) = camera.resolution;
                if (image.width(), image.height()) != (w as usize, h as usize) {
                    return Err(CameraInputError::SizeMismatch {
                        path: frame.path.clone(),
                        width: image.width(),
                        height: image.height(),
                        expected_width: w,
                        expected_height: h,
                    });
                }
            }
            let corners = detect_corners(&image, target, params);
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress(n as f64 / frames.len().max(1) as f64);
            Ok(FrameResult {
                stamp_ns: frame.stamp_ns,
                path: frame.path.clone(),
                corners,
            })
        })
        .collect()
}

/// The corners of `target` in one image: a whole checkerboard, or an AprilGrid from
/// [`AprilGridParams::min_tags`] tags up (its default parameters).
pub fn detect_corners(
    image: &GrayImage,
    target: &Target,
    params: &DetectorParams,
) -> Result<FrameCorners, NoDetection> {
    match target {
        Target::Checkerboard(t) => {
            detect_checkerboard(image, t.rows, t.cols, params).map(|d| FrameCorners {
                ids: (0..d.corners.len()).collect(),
                pixels: d.corners,
            })
        }
        Target::AprilGrid(t) => detect_aprilgrid(image, t, &AprilGridParams::default())
            .map(|d| FrameCorners {
                ids: d.ids,
                pixels: d.pixels,
            })
            .map_err(NoDetection::AprilGrid),
        Target::Board { .. } => Err(NoDetection::NoCorners),
    }
}
