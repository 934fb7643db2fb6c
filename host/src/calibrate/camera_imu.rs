//! Camera-IMU calibration (dissertation ch. 4) from checkerboard corners, two ways:
//!
//! - **RepErrCal** (reprojection, eq. 4.2 and 4.15): the EKF fuses every image's corners
//!   through the IMU pose, the extrinsic `T_I_C`, the camera model and the pose of the
//!   static target `T_G_T`, which is a state of the filter. Gravity comes from the IMU at
//!   the stationary start (roll and pitch; yaw is a gauge the target pose absorbs), so no
//!   camera frame has to be taken as exact, unlike the dissertation's gauge at frame 0.
//! - **MoCal** (motion based, eq. 4.11-4.13): each image's PnP pose becomes odometry of the
//!   camera in the target frame, and the pose-IMU pipeline fuses its relative poses.
//!
//! Both start from the hand-eye rotation of PnP rotation increments against the integrated
//! gyro (eq. 4.5) and a zero translation (no tape measure).

mod chain;
mod feed;
pub mod frames;
mod model_error;
mod multi;
mod pnp;
mod report;
mod start;

use std::time::Instant;

use msreg_estimator::camera::Camera;
use msreg_estimator::{CornerObservation, Scalar, SOLE_SENSOR, TARGET_FRAME};
use nalgebra::Matrix6;
use serde::Serialize;

use super::extrinsic::ImuExtrinsicCalibration;
use super::init;
use super::pose_imu::{self};
use super::InputError;
use crate::calibrate::driver::drive_imu;
use crate::calibrate::driver::report::{PoseImuOptions, Timing};
use crate::calibrate::driver::verdict::finish;
use crate::dataset::{ExtrinsicEstimate, ImuNoiseYaml, ImuRecord, PoseRecord};

pub(crate) use self::{feed::*, pnp::*, start::*};
pub use chain::{compose_chain, CameraChainLink};
pub use frames::{detect_corner_frames, DetectionSummary};
pub use multi::{
    calibrate_cameras, CameraFrames, ChainModelError, MultiCameraImuCalibration,
    MultiCameraImuInput, MAX_CAMERAS,
};
pub use pnp::invert_with_covariance;
pub use report::{CameraImuReport, FrameReprojection, Initialization, ReprojectionSample};

/// The target corners found in one image.
#[derive(Debug, Clone, PartialEq)]
pub struct CornerFrame {
    /// Image stamp, ns (camera clock).
    pub stamp_ns: u64,
    /// Corners: position in the target frame (m) and pixel.
    pub corners: Vec<CornerObservation<f64>>,
}

/// What the pipeline reads.
#[derive(Debug, Clone, Copy)]
pub struct CameraImuInput<'a> {
    /// IMU samples, strictly increasing stamps.
    pub imu: &'a [ImuRecord],
    /// IMU noise densities.
    pub imu_noise: &'a ImuNoiseYaml,
    /// The camera model (intrinsics known, e.g. from Kalibr).
    pub camera: &'a Camera<f64>,
    /// Detected corners per image, increasing stamps.
    pub frames: &'a [CornerFrame],
}

/// Which measurement the filter fuses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CameraUpdate {
    /// Corner reprojection (RepErrCal).
    Reprojection,
    /// Relative poses of PnP (MoCal).
    Motion,
}

/// Tuning of the pipeline.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraImuOptions {
    /// Measurement model.
    pub update: CameraUpdate,
    /// Corner noise, 1-sigma per axis, pixels; `None` estimates it from the PnP residuals.
    pub pixel_sigma: Option<f64>,
    /// Extrinsic and time-offset priors, standstill detection (shared with pose-IMU).
    pub prior: PoseImuOptions,
    /// How RepErrCal weighs each image's corners.
    pub image_noise: ImageNoise,
    /// Whether RepErrCal also runs on each time block alone to measure the model error
    /// (`report.model_error`) and writes the larger sigma per axis to the result file
    /// (docs/camera_imu.md, "Covariances that hold"); costs about one more pass.
    pub model_error: bool,
}

/// How RepErrCal weighs each image's corners.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageNoise {
    /// Each image at its own corner noise (its PnP residual, floored at the recording's),
    /// and the frame-level robust weight up to [`MAX_NOISE_SCALE`]: what real images need.
    PerImage,
    /// One corner noise for all images and the plain gate: what the firmware runs (the link
    /// protocol carries one `pixel_sigma` per session), so the host can mirror it.
    Uniform,
}

impl Default for CameraImuOptions {
    fn default() -> Self {
        Self {
            update: CameraUpdate::Reprojection,
            pixel_sigma: None,
            prior: PoseImuOptions {
                translation_sigma_m: 0.2,
                ..PoseImuOptions::default()
            },
            image_noise: ImageNoise::PerImage,
            model_error: true,
        }
    }
}

/// Smallest corner noise assumed, pixels: below it detector biases dominate.
const MIN_PIXEL_SIGMA: f64 = 0.05;
/// Fewest corners an image needs for PnP and the update.
pub const MIN_CORNERS: usize = 6;

/// The outcome: `T_imu_cam` (the filter's state; the result file stores its inverse
/// `T_cam_imu`) with its covariance, the time offset `t_d` (= Kalibr's
/// `timeshift_cam_imu`), and the report.
pub type CameraImuCalibration = ImuExtrinsicCalibration<CameraImuReport>;

impl CameraImuCalibration {
    /// The `cam0` section of the result file: `T_cam_imu` (the inverse of the filter's
    /// `T_imu_cam`) with the written sigmas: the model error's
    /// ([`CameraImuReport::written`]) when it was measured, else the filter's.
    pub fn cam_imu_estimate(&self) -> ExtrinsicEstimate {
        let (t_cam_imu, covariance) = invert_with_covariance(&self.t_imu_sensor, &self.covariance);
        let covariance = self
            .report
            .written
            .map_or(covariance, |w| w.extrinsic_covariance());
        ExtrinsicEstimate::from_covariance(t_cam_imu, self.time_offset_s, &covariance)
    }

    /// The written covariance of `T_imu_cam` (the filter's frame) and the time offset's
    /// written sigma: the result file's, as [`CameraImuCalibration::cam_imu_estimate`].
    pub fn written_covariance(&self) -> (Matrix6<f64>, f64) {
        match &self.report.written {
            Some(w) => (
                invert_with_covariance(&w.transform, &w.extrinsic_covariance()).1,
                w.time_offset_sigma_s(),
            ),
            None => (self.covariance, self.time_offset_sigma_s),
        }
    }
}

/// Runs the calibration with the filter in scalar type `T`; `progress` gets the fraction
/// of the recording processed.
pub fn calibrate<T: Scalar>(
    input: &CameraImuInput<'_>,
    options: &CameraImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<CameraImuCalibration, InputError> {
    let started = Instant::now();
    let poses = frame_poses(input.camera, input.frames);
    let (motion, pixel_sigma) =
        motion_calibration::<T>(input, &poses, options, &mut |f| progress(0.3 * f))?;
    let mut calibration = match options.update {
        CameraUpdate::Motion => motion,
        CameraUpdate::Reprojection => {
            let start = Start {
                motion: &motion,
                pixel_sigma,
                poses: &poses,
            };
            let mut c = reprojection_calibration::<T>(
                input,
                options,
                &start,
                ExtrinsicPrior::AroundStart,
                started,
                &mut |f| progress(0.3 + 0.5 * f),
            )?;
            if options.model_error {
                model_error::add_model_error::<T>(input, options, &start, &mut c);
            }
            progress(0.9);
            c
        }
    };
    let verification = reprojection_calibration::<T>(
        input,
        options,
        &Start {
            motion: &calibration,
            pixel_sigma,
            poses: &poses,
        },
        ExtrinsicPrior::Held,
        Instant::now(),
        &mut |f| progress(0.9 + 0.1 * f),
    )?;
    calibration.report.verification_reprojection_error_px =
        verification.report.mean_reprojection_error_px;
    progress(1.0);
    Ok(calibration)
}

/// Where RepErrCal starts (what `msreg link replay` sends the device): MoCal's estimate,
/// the prior around it, and the corner noise.
#[derive(Debug, Clone)]
pub struct ReprojectionStart {
    /// The MoCal calibration.
    pub motion: CameraImuCalibration,
    /// RepErrCal's extrinsic and time-offset prior around it.
    pub prior: PoseImuOptions,
    /// Corner noise, 1-sigma per axis, pixels.
    pub pixel_sigma: f64,
}

/// MoCal on the PnP odometry in scalar type `T`, and RepErrCal's prior around its estimate.
pub fn reprojection_start<T: Scalar>(
    input: &CameraImuInput<'_>,
    options: &CameraImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<ReprojectionStart, InputError> {
    let poses = frame_poses(input.camera, input.frames);
    let (motion, pixel_sigma) = motion_calibration::<T>(input, &poses, options, progress)?;
    let at_rest = init::detect_standstill(input.imu, options.prior.min_standstill_s).is_some();
    let prior = reprojection_prior(options, &motion, ExtrinsicPrior::AroundStart, at_rest);
    Ok(ReprojectionStart {
        motion,
        prior,
        pixel_sigma,
    })
}

/// MoCal (the pose-IMU pipeline on the PnP poses of the camera in the target) and the
/// corner noise.
pub(crate) fn motion_calibration<T: Scalar>(
    input: &CameraImuInput<'_>,
    poses: &[FramePose],
    options: &CameraImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<(CameraImuCalibration, f64), InputError> {
    if poses.len() < 3 {
        return Err(InputError::TooFewTargetPoses {
            found: poses.len(),
            images: input.frames.len(),
            needed: 3,
        });
    }
    let pixel_sigma = options
        .pixel_sigma
        .unwrap_or_else(|| pixel_sigma_from_pnp(poses));
    let odometry: Vec<PoseRecord> = poses.iter().map(camera_in_target).collect();
    let noise = increment_noise(poses, MIN_PIXEL_SIGMA);
    let motion = pose_imu::calibrate::<T>(
        &pose_imu::PoseImuInput {
            imu: input.imu,
            imu_noise: input.imu_noise,
            poses: &odometry,
            pose_noise: &noise,
        },
        &options.prior,
        progress,
    )?;
    let motion = motion.map_report(|filter| CameraImuReport {
        update: CameraUpdate::Motion,
        pixel_sigma,
        frames_with_pose: poses.len(),
        mean_reprojection_error_px: f64::NAN,
        verification_reprojection_error_px: f64::NAN,
        frames: Vec::new(),
        initialization: None,
        sample: None,
        model_error: None,
        written: None,
        filter,
    });
    Ok((motion, pixel_sigma))
}

/// RepErrCal, started from the MoCal estimate. Started from the hand-eye rotation and a zero
/// translation instead, the first images after the standstill are linearised centimetres
/// from the truth while their corners are 0.1 px precise: the rotation-times-lever-arm
/// term of that error is not in the linear model, and the filter locks onto a wrong
/// solution (seen on the simulator: 7 px innovations and most images gated out).
fn reprojection_calibration<T: Scalar>(
    input: &CameraImuInput<'_>,
    options: &CameraImuOptions,
    start: &Start<'_>,
    extrinsic_prior: ExtrinsicPrior,
    started: Instant,
    progress: &mut dyn FnMut(f64),
) -> Result<CameraImuCalibration, InputError> {
    let Start {
        motion,
        pixel_sigma,
        ..
    } = *start;
    let imu = input.imu;
    if imu.is_empty() {
        return Err(InputError::NoImuSamples);
    }
    let standstill = init::detect_standstill(imu, options.prior.min_standstill_s);
    let StartFromMotion {
        mut ekf,
        prior,
        rotation_init,
        gyro_bias_init,
        moving_start,
    } = start_from_motion::<T>(input, options, standstill.as_ref(), start, extrinsic_prior)?;
    let init_s = started.elapsed().as_secs_f64();

    let started = Instant::now();
    let mut feed = CornerFeed::new(input, options, start, prior, SOLE_SENSOR);
    drive_imu(&mut ekf, imu, standstill.as_ref(), progress, &mut feed)?;
    feed.skip_remaining();
    let CornerFeed {
        run,
        reprojection,
        sample,
        ..
    } = feed;
    progress(1.0);
    let filter_s = started.elapsed().as_secs_f64();
    let calibration = finish(
        &ekf,
        run,
        standstill.as_ref(),
        &rotation_init,
        Timing {
            init: init_s,
            filter: filter_s,
        },
    );
    Ok(reprojection_report(
        calibration,
        (reprojection, sample),
        (motion, &prior, pixel_sigma),
        (gyro_bias_init, moving_start),
    ))
}

/// A RepErrCal run's result with its camera report: the filter's verdict `calibration`, the
/// feed's per-image reprojection and sample, where it started (`motion`, the prior, the
/// corner noise) and the report words of the IMU start (gyro bias, moving start).
pub(crate) fn reprojection_report(
    mut calibration: crate::calibrate::driver::report::PoseImuCalibration,
    (reprojection, sample): (Vec<FrameReprojection>, Option<ReprojectionSample>),
    (motion, prior, pixel_sigma): (&CameraImuCalibration, &PoseImuOptions, f64),
    (gyro_bias_init, moving_start): (String, String),
) -> CameraImuCalibration {
    calibration.report.gyro_bias_init = gyro_bias_init;
    calibration.report.moving_start = moving_start;
    let accepted: Vec<f64> = reprojection
        .iter()
        .filter(|f| f.accepted)
        .map(|f| f.mean_error_px)
        .collect();
    let frames_with_pose = motion.report.frames_with_pose;
    let initialization = Initialization {
        method: "MoCal (motion-based EKF on PnP poses), then RepErrCal from its estimate",
        t_imu_cam: rows(&motion.t_imu_sensor),
        time_offset_s: motion.time_offset_s,
        prior_sigma_rot_deg: prior.rotation_sigma_rad.to_degrees(),
        prior_sigma_trans_m: prior.translation_sigma_m,
        prior_sigma_time_offset_s: prior.time_offset_sigma_s,
    };
    calibration.map_report(|filter| CameraImuReport {
        update: CameraUpdate::Reprojection,
        pixel_sigma,
        frames_with_pose,
        mean_reprojection_error_px: accepted.iter().sum::<f64>() / accepted.len().max(1) as f64,
        verification_reprojection_error_px: f64::NAN,
        frames: reprojection,
        initialization: Some(initialization),
        sample,
        model_error: None,
        written: None,
        filter,
    })
}
