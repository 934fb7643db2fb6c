//! The dataset of an intrinsic calibration (docs/formats.md, sections 2 and 3):
//! `cam0/`, `cam1/`, ... each with `data.csv` and images and a `camera.yaml` that may carry
//! only `camera_model`, `distortion_model` and `resolution`; `target.yaml` at the top.
//!
//! Time sync: cameras must be triggered together. Camera `N >= 1` is compared with camera
//! `N - 1`: when the median distance from its stamps to the nearest stamp of the other
//! exceeds the tolerance, the dataset is refused, naming both cameras and the difference
//! ([`CamerasInputError::Unsynchronised`]); a per-camera time offset is not estimated.

use std::path::{Path, PathBuf};

use msreg_estimator::camera::model::ModelKind;
use msreg_estimator::camera::{Camera, Distortion, Intrinsics, Projection};

use super::{CameraInput, ImageCorners};
use crate::camera_yaml::{read_camera_spec, read_target_yaml, Target, YamlError};
use crate::dataset::{read_camera_csv, CameraFrame, DatasetError, TARGET_YAML};
use crate::vision::frames::{detect_frames, CameraInputError};
use crate::vision::{DetectorParams, GrayImage, ImageLoadError};

/// Why the dataset cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum CamerasInputError {
    /// A CSV is missing or malformed, or the directory does not exist.
    #[error(transparent)]
    Dataset(#[from] DatasetError),
    /// A YAML file is malformed.
    #[error(transparent)]
    Yaml(#[from] YamlError),
    /// An image cannot be read or has the wrong size.
    #[error(transparent)]
    Images(#[from] CameraInputError),
    /// An image cannot be read.
    #[error(transparent)]
    Image(#[from] ImageLoadError),
    /// `target.yaml` is a plain board.
    #[error("{}: target_type must be checkerboard or aprilgrid", path.display())]
    NotCornerTarget {
        /// The target file.
        path: PathBuf,
    },
    /// No `cam0/data.csv`.
    #[error("{}: no camera folder (cam0/data.csv) in the dataset", path.display())]
    NoCameras {
        /// The dataset.
        path: PathBuf,
    },
    /// A camera has neither a `camera.yaml` nor a `--model`.
    #[error("{}: missing; give the camera's model there or with --model {camera}=<model>", path.display())]
    NoModel {
        /// The camera.
        camera: String,
        /// The expected camera.yaml.
        path: PathBuf,
    },
    /// A `--model` names a camera the dataset does not have.
    #[error("--model {camera}=...: the dataset has no {camera}/")]
    UnknownCamera {
        /// The name given.
        camera: String,
    },
    /// Stamps of two cameras differ.
    #[error(
        "{camera} and {other} are not synchronised: the median distance from a {camera} stamp \
         to the nearest {other} stamp is {median_ms:.3} ms (tolerance {tolerance_ms:.3} ms). \
         Unsynchronised cameras are not supported: trigger them together or re-stamp the images"
    )]
    Unsynchronised {
        /// The later camera.
        camera: String,
        /// The camera it was compared with.
        other: String,
        /// The median stamp difference, ms.
        median_ms: f64,
        /// The tolerance, ms.
        tolerance_ms: f64,
    },
}

/// The calibration input and, per camera, `(images, images with corners)`.
pub type Detected = (Vec<CameraInput>, Vec<(usize, usize)>);

/// One camera of the dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct DatasetCamera {
    /// `camN`.
    pub name: String,
    /// The model to calibrate.
    pub kind: ModelKind,
    /// Image size.
    pub resolution: (u32, u32),
    /// The images.
    pub frames: Vec<CameraFrame>,
}

/// The cameras and target of a dataset.
#[derive(Clone, Debug, PartialEq)]
pub struct CamerasDataset {
    /// The target.
    pub target: Target,
    /// `cam0`, `cam1`, ... in order.
    pub cameras: Vec<DatasetCamera>,
}

impl CamerasDataset {
    /// Reads the target, every `camN/` and its model (`models` overrides camera.yaml:
    /// `(camN, kind)`).
    pub fn open(dir: &Path, models: &[(String, ModelKind)]) -> Result<Self, CamerasInputError> {
        if !dir.is_dir() {
            return Err(DatasetError::MissingDirectory {
                path: dir.to_path_buf(),
            }
            .into());
        }
        let target_path = dir.join(TARGET_YAML);
        let target = read_target_yaml(&target_path)?;
        if let Target::Board(_) = target {
            return Err(CamerasInputError::NotCornerTarget { path: target_path });
        }
        let mut cameras = Vec::new();
        while dir.join(format!("cam{}/data.csv", cameras.len())).is_file() {
            let name = format!("cam{}", cameras.len());
            cameras.push(open_camera(dir, &name, models)?);
        }
        if cameras.is_empty() {
            return Err(CamerasInputError::NoCameras {
                path: dir.to_path_buf(),
            });
        }
        if let Some((camera, _)) = models
            .iter()
            .find(|(c, _)| !cameras.iter().any(|d: &DatasetCamera| &d.name == c))
        {
            return Err(CamerasInputError::UnknownCamera {
                camera: camera.clone(),
            });
        }
        Ok(Self { target, cameras })
    }

    /// Refuses cameras whose stamps differ (module docs).
    pub fn check_sync(&self, tolerance_ns: u64) -> Result<(), CamerasInputError> {
        for pair in self.cameras.windows(2) {
            let (other, cam) = (&pair[0], &pair[1]);
            let mut theirs: Vec<u64> = other.frames.iter().map(|f| f.stamp_ns).collect();
            theirs.sort_unstable();
            let mut diffs: Vec<u64> = cam
                .frames
                .iter()
                .map(|f| nearest_distance(&theirs, f.stamp_ns))
                .collect();
            diffs.sort_unstable();
            let median = diffs.get(diffs.len() / 2).copied().unwrap_or(u64::MAX);
            if median > tolerance_ns {
                return Err(CamerasInputError::Unsynchronised {
                    camera: cam.name.clone(),
                    other: other.name.clone(),
                    median_ms: median as f64 * 1e-6,
                    tolerance_ms: tolerance_ns as f64 * 1e-6,
                });
            }
        }
        Ok(())
    }

    /// Detects the target in every image; returns the calibration input and, per camera,
    /// `(images, images with corners)`.
    pub fn detect(
        &self,
        params: &DetectorParams,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<Detected, CamerasInputError> {
        let mut inputs = Vec::new();
        let mut counts = Vec::new();
        for cam in &self.cameras {
            let (w, h) = cam.resolution;
            let k = Intrinsics {
                fu: 1.0,
                fv: 1.0,
                cu: 0.5 * f64::from(w),
                cv: 0.5 * f64::from(h),
            };
            // Only its resolution is used: detect_frames checks every image's size.
            let sizer = Camera::new(Projection::Pinhole, k, Distortion::None, cam.resolution).ok();
            let results =
                detect_frames(&cam.frames, &self.target, sizer.as_ref(), params, progress)?;
            let images: Vec<ImageCorners> = results
                .into_iter()
                .filter_map(|r| {
                    let corners = r.corners.ok()?;
                    Some(ImageCorners {
                        stamp_ns: r.stamp_ns,
                        name: r
                            .path
                            .file_name()
                            .map_or_else(String::new, |n| n.to_string_lossy().into_owned()),
                        points: corners.target_points(&self.target),
                        pixels: corners.pixels,
                    })
                })
                .collect();
            counts.push((cam.frames.len(), images.len()));
            inputs.push(CameraInput {
                name: cam.name.clone(),
                kind: cam.kind,
                resolution: cam.resolution,
                images,
            });
        }
        Ok((inputs, counts))
    }
}

fn nearest_distance(sorted: &[u64], stamp: u64) -> u64 {
    let i = sorted.partition_point(|&s| s < stamp);
    let after = sorted.get(i).map(|s| s - stamp);
    let before = i.checked_sub(1).map(|j| stamp - sorted[j]);
    after.into_iter().chain(before).min().unwrap_or(u64::MAX)
}

fn open_camera(
    dir: &Path,
    name: &str,
    models: &[(String, ModelKind)],
) -> Result<DatasetCamera, CamerasInputError> {
    let frames = read_camera_csv(dir.join(format!("{name}/data.csv")))?;
    let yaml = dir.join(format!("{name}/camera.yaml"));
    let spec = if yaml.is_file() {
        Some(read_camera_spec(&yaml)?)
    } else {
        None
    };
    let kind = models
        .iter()
        .find(|(c, _)| c == name)
        .map(|(_, k)| *k)
        .or(spec.map(|s| s.kind))
        .ok_or_else(|| CamerasInputError::NoModel {
            camera: name.to_string(),
            path: yaml.clone(),
        })?;
    let resolution = match (spec, frames.first()) {
        (Some(s), _) => s.resolution,
        (None, Some(f)) => {
            let image = GrayImage::load(&f.path)?;
            (image.width() as u32, image.height() as u32)
        }
        (None, None) => (1, 1),
    };
    Ok(DatasetCamera {
        name: name.to_string(),
        kind,
        resolution,
        frames,
    })
}
