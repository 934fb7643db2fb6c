//! Detections from images, for datasets that carry images instead of pre-detected CSV
//! (docs/formats.md, section 2.9): the robot's marker in an
//! infrastructure camera's frames (`infra/<id>/data.csv` + `data/`, ArUco with sub-pixel
//! corners in OpenCV order) and the bright blobs in F's keyframes (`cam0/data.csv` +
//! `data/`). Images are decoded and searched in parallel; a frame without the marker is
//! simply not a detection.

use std::path::Path;

use rayon::prelude::*;

use super::io::{Blob, InfraError, MarkerDetection};
use crate::dataset::{read_camera_csv, CameraFrame};
use crate::vision::aruco::{detect_markers, ArucoParams, Dictionary};
use crate::vision::blobs::{detect_blobs, BlobParams};
use crate::vision::GrayImage;

fn frames(csv: &Path) -> Result<Vec<CameraFrame>, InfraError> {
    read_camera_csv(csv).map_err(|e| InfraError::Parse {
        path: csv.to_path_buf(),
        line: 0,
        message: e.to_string(),
    })
}

fn load(frame: &CameraFrame) -> Result<GrayImage, InfraError> {
    GrayImage::load(&frame.path).map_err(|e| InfraError::Parse {
        path: frame.path.clone(),
        line: 0,
        message: e.to_string(),
    })
}

/// Marker `marker_id` of `dictionary` in every frame listed by `csv` (`data.csv`), in stamp
/// order; frames where it is not found are left out.
pub fn markers_from_images(
    csv: &Path,
    dictionary: Dictionary,
    marker_id: u32,
) -> Result<Vec<MarkerDetection>, InfraError> {
    // Edge-line corners: the default gradient refinement pulls the corners of the marker's
    // square inwards and would shrink it, biasing the VO scale (vision/aruco/edges.rs).
    let params = ArucoParams {
        edge_lines: true,
        ..ArucoParams::default()
    };
    let per_frame: Vec<Option<MarkerDetection>> = frames(csv)?
        .par_iter()
        .map(|frame| {
            let img = load(frame)?;
            let found = detect_markers(&img, dictionary, &params)
                .into_iter()
                .find(|m| m.id == marker_id as usize);
            Ok(found.map(|m| MarkerDetection {
                stamp_ns: frame.stamp_ns,
                marker_id,
                corners: m.corners,
            }))
        })
        .collect::<Result<_, InfraError>>()?;
    Ok(per_frame.into_iter().flatten().collect())
}

/// The bright blobs of every frame listed by `csv` (`cam0/data.csv`), in stamp order.
pub fn blobs_from_images(csv: &Path, params: &BlobParams) -> Result<Vec<Blob>, InfraError> {
    let per_frame: Vec<Vec<Blob>> = frames(csv)?
        .par_iter()
        .map(|frame| {
            let img = load(frame)?;
            Ok(detect_blobs(&img, params)
                .into_iter()
                .map(|b| Blob {
                    stamp_ns: frame.stamp_ns,
                    uv: nalgebra::Vector2::new(b.u, b.v),
                })
                .collect())
        })
        .collect::<Result<_, InfraError>>()?;
    Ok(per_frame.into_iter().flatten().collect())
}
