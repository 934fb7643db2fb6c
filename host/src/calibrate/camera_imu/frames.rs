//! Checkerboard corners of every image of a camera dataset as filter input, and what the
//! detector found.

use std::collections::BTreeMap;
use std::time::Instant;

use msreg_estimator::CornerObservation;
use serde::Serialize;

use super::CornerFrame;
use crate::vision::frames::{CameraDataset, CameraInputError};
use crate::vision::DetectorParams;

/// What the detector found over the dataset.
#[derive(Debug, Clone, Serialize)]
pub struct DetectionSummary {
    /// Images listed in `cam0/data.csv`.
    pub images: usize,
    /// Images with the full board.
    pub detected: usize,
    /// Rejected images per reason.
    pub rejected: BTreeMap<String, usize>,
    /// Wall time of detection, s.
    pub time_s: f64,
}

/// Detects the checkerboard in every image of the dataset: the corners as filter input,
/// and the detection summary. `progress` receives the fraction of images done.
pub fn detect_corner_frames(
    data: &CameraDataset,
    params: &DetectorParams,
    progress: &(dyn Fn(f64) + Sync),
) -> Result<(Vec<CornerFrame>, DetectionSummary), CameraInputError> {
    let started = Instant::now();
    let results = data.detect(params, progress)?;
    let mut rejected = BTreeMap::new();
    let mut frames = Vec::with_capacity(results.len());
    for result in &results {
        match &result.corners {
            Ok(found) => frames.push(CornerFrame {
                stamp_ns: result.stamp_ns,
                corners: found
                    .target_points(&data.target)
                    .into_iter()
                    .zip(&found.pixels)
                    .map(|(point_in_target, pixel)| CornerObservation {
                        point_in_target,
                        pixel: *pixel,
                    })
                    .collect(),
            }),
            Err(why) => *rejected.entry(why.to_string()).or_insert(0) += 1,
        }
    }
    let summary = DetectionSummary {
        images: results.len(),
        detected: frames.len(),
        rejected,
        time_s: started.elapsed().as_secs_f64(),
    };
    Ok((frames, summary))
}
