//! What camera-IMU calibration reports: per-image reprojection, the initialisation, a reprojection
//! sample for the overlay.

use super::*;
use crate::calibrate::driver::report::PoseImuReport;
use crate::calibrate::jackknife::{Estimate, ModelErrorReport};
use nalgebra::Vector2;
use serde::Serialize;

/// Reprojection statistics of one image, after its update.
#[derive(Debug, Clone, Serialize)]
pub struct FrameReprojection {
    /// Seconds since the first IMU sample.
    pub t_s: f64,
    /// Corners fused.
    pub corners: usize,
    /// Mean reprojection error before the update (the innovation), pixels.
    pub mean_error_before_px: f64,
    /// Mean reprojection error after it, pixels.
    pub mean_error_px: f64,
    /// Whether the gate accepted the image.
    pub accepted: bool,
}

/// The JSON report of a camera-IMU calibration.
#[derive(Debug, Clone, Serialize)]
pub struct CameraImuReport {
    /// Measurement model used.
    pub update: CameraUpdate,
    /// Corner noise used, pixels (1-sigma per axis).
    pub pixel_sigma: f64,
    /// Images with a PnP pose (of those given).
    pub frames_with_pose: usize,
    /// Mean reprojection error over the accepted images, after their update, pixels
    /// (RepErrCal; NaN for MoCal).
    pub mean_reprojection_error_px: f64,
    /// Mean reprojection error of a second pass over all images with the extrinsic and time
    /// offset held at the final estimate: the same metric for both models (Table 4.4).
    pub verification_reprojection_error_px: f64,
    /// Per image (RepErrCal only).
    pub frames: Vec<FrameReprojection>,
    /// How RepErrCal was initialised (None for MoCal).
    pub initialization: Option<Initialization>,
    /// One image's corners with their final reprojection (RepErrCal; the dissertation's
    /// Fig. 4.4); drawn by the HTML report.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sample: Option<ReprojectionSample>,
    /// The data-driven model error and the result file's sigmas (RepErrCal with
    /// `CameraImuOptions::model_error`; docs/camera_imu.md, "Covariances that hold").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub model_error: Option<ModelErrorReport>,
    /// The result file's estimate: `T_cam_imu` and the time offset with the written
    /// covariance (`None`: the filter's is written).
    #[serde(skip)]
    pub written: Option<Estimate>,
    /// Filter report: convergence, NIS, excitation, health events, history.
    #[serde(flatten)]
    pub filter: PoseImuReport,
}

/// RepErrCal's starting point.
#[derive(Debug, Clone, Serialize)]
pub struct Initialization {
    /// How it was obtained.
    pub method: &'static str,
    /// `T_imu_cam` the filter started from.
    pub t_imu_cam: [[f64; 4]; 4],
    /// Time offset it started from, s.
    pub time_offset_s: f64,
    /// Prior 1-sigma of the extrinsic rotation, deg.
    pub prior_sigma_rot_deg: f64,
    /// Prior 1-sigma of the extrinsic translation, m.
    pub prior_sigma_trans_m: f64,
    /// Prior 1-sigma of the time offset, s.
    pub prior_sigma_time_offset_s: f64,
}

/// Detected corners of one image and where the filter reprojects them after its update.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ReprojectionSample {
    /// Image stamp, ns.
    pub stamp_ns: u64,
    /// Detected pixels.
    pub detected: Vec<Vector2<f64>>,
    /// Reprojected pixels, same order.
    pub reprojected: Vec<Vector2<f64>>,
}
