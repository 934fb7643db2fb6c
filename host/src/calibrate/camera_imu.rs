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

pub mod frames;

use std::time::Instant;

use msreg_estimator::camera::Camera;
use msreg_estimator::{
    CameraImuEkf, CornerObservation, CornerSet, Ekf, Error as FilterError, FilterConfig,
    InitialState, Scalar,
};
use nalgebra::{Isometry3, Matrix6, Vector2, Vector3};
use serde::Serialize;

use super::convert;
use super::extrinsic::ImuExtrinsicCalibration;
use super::gyro_bias;
use super::init;
use super::pose_imu::{
    self, describe_moving_start, drive_imu, finish, initial_state, moving_start, with_gyro_bias,
    with_moving_start, ImuHooks, PoseImuOptions, PoseImuReport, Run, Timing,
};
use super::InputError;
use crate::dataset::{ExtrinsicEstimate, ImuNoiseYaml, ImuRecord, PoseRecord, PoseSensorYaml};
use crate::vision::pnp::{solve_pnp, PnpSolution};

pub use frames::{detect_corner_frames, DetectionSummary};

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
        }
    }
}

/// Smallest corner noise assumed, pixels: below it detector biases dominate.
const MIN_PIXEL_SIGMA: f64 = 0.05;
/// Fewest corners an image needs for PnP and the update.
pub const MIN_CORNERS: usize = 6;
/// The filter's static frame of the target.
const TARGET: usize = 0;

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

/// The outcome: `T_imu_cam` (the filter's state; the result file stores its inverse
/// `T_cam_imu`) with its covariance, the time offset `t_d` (= Kalibr's
/// `timeshift_cam_imu`), and the report.
pub type CameraImuCalibration = ImuExtrinsicCalibration<CameraImuReport>;

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

impl CameraImuCalibration {
    /// The `cam0` section of the result file: `T_cam_imu` (the inverse of the filter's
    /// `T_imu_cam`) with its sigmas.
    pub fn cam_imu_estimate(&self) -> ExtrinsicEstimate {
        let (t_cam_imu, covariance) = invert_with_covariance(&self.t_imu_sensor, &self.covariance);
        ExtrinsicEstimate::from_covariance(t_cam_imu, self.time_offset_s, &covariance)
    }
}

/// `T^-1` and the covariance of its right-perturbation error, given those of `T`:
/// `(R Exp(d))^T = R^T Exp(-R d)` and `-(R Exp(d))^T (p + dp) = p' - R^T dp - [R^T p]x d`.
pub fn invert_with_covariance(
    t: &Isometry3<f64>,
    covariance: &Matrix6<f64>,
) -> (Isometry3<f64>, Matrix6<f64>) {
    let r = t.rotation.to_rotation_matrix().into_inner();
    let rt_p = r.transpose() * t.translation.vector;
    let mut j = Matrix6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&(-r));
    j.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(-msreg_estimator::lie::skew(&rt_p)));
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(&(-r.transpose()));
    (t.inverse(), j * covariance * j.transpose())
}

/// A PnP pose of one image.
pub(crate) struct FramePose {
    stamp_ns: u64,
    /// Corners the PnP used.
    points: usize,
    pnp: PnpSolution,
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
        CameraUpdate::Reprojection => reprojection_calibration::<T>(
            input,
            options,
            &Start {
                motion: &motion,
                pixel_sigma,
                poses: &poses,
            },
            ExtrinsicPrior::AroundStart,
            started,
            &mut |f| progress(0.3 + 0.6 * f),
        )?,
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

/// 1-sigma of the target frame's orientation (rad) and position (m) when it is set from one
/// image's PnP pose at `distance_m`: the extrinsic prior's error seen at the target's
/// distance, plus 0.02 rad for the IMU attitude and the PnP.
pub fn target_prior_sigmas(prior: &PoseImuOptions, distance_m: f64) -> (f64, f64) {
    let sigma_rotation = prior.rotation_sigma_rad + 0.02;
    (
        sigma_rotation,
        prior.translation_sigma_m + sigma_rotation * distance_m,
    )
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
    let noise = increment_noise(poses);
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
        filter,
    });
    Ok((motion, pixel_sigma))
}

/// How RepErrCal's extrinsic and time-offset prior is set around its starting estimate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ExtrinsicPrior {
    /// The start's covariance, floored by [`REPROJECTION_PRIOR_FLOOR`]: calibrate.
    AroundStart,
    /// [`HELD_SIGMA`]: the extrinsic and time offset stay at the start (verification).
    Held,
}

/// Largest scale of an image's corner noise when the gate rejects it at its own noise
/// (`FilterConfig::max_noise_scale`): images up to NIS / dof = 9 are fused down-weighted,
/// beyond that they are outliers.
pub const MAX_NOISE_SCALE: f64 = 3.0;

/// Prior 1-sigma (rad, m, s) that holds the extrinsic and time offset in the verification
/// pass: far below what the data resolve, far above the scalar's rounding.
const HELD_SIGMA: f64 = 1e-6;

/// Smallest prior 1-sigma of RepErrCal around the MoCal estimate: wide enough that the
/// prior carries almost none of the information (the same data produced it), narrow enough
/// that the first images are linearised close to the truth. The time offset's only at a
/// standstill start (see [`reprojection_prior`]).
const REPROJECTION_PRIOR_FLOOR: (f64, f64, f64) = (0.5 * std::f64::consts::PI / 180.0, 0.01, 0.005);

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
    let mut feed = CornerFeed::new(input, options, start, prior, 0);
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
    let mut calibration = finish(
        &ekf,
        run,
        standstill.as_ref(),
        &rotation_init,
        Timing {
            init: init_s,
            filter: filter_s,
        },
    );
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
    Ok(calibration.map_report(|filter| CameraImuReport {
        update: CameraUpdate::Reprojection,
        pixel_sigma,
        frames_with_pose,
        mean_reprojection_error_px: accepted.iter().sum::<f64>() / accepted.len().max(1) as f64,
        verification_reprojection_error_px: f64::NAN,
        frames: reprojection,
        initialization: Some(initialization),
        sample,
        filter,
    }))
}

/// What RepErrCal starts from: the MoCal (or final) estimate, the recording's corner noise
/// and every image's PnP pose (computed once per calibration).
#[derive(Clone, Copy)]
pub(crate) struct Start<'a> {
    pub(crate) motion: &'a CameraImuCalibration,
    pub(crate) pixel_sigma: f64,
    pub(crate) poses: &'a [FramePose],
}

/// The RepErrCal filter at the MoCal estimate, with its prior.
struct StartFromMotion<T: Scalar> {
    ekf: CameraImuEkf<T>,
    prior: PoseImuOptions,
    rotation_init: init::RotationInit,
    /// Where the starting gyro bias came from (report words).
    gyro_bias_init: String,
    /// The moving start's alignment (report words; empty after a standstill).
    moving_start: String,
}

/// RepErrCal's prior at the MoCal estimate: the IMU state and the camera as sensor 0, the
/// filter configuration, and what the report says of them.
pub(crate) struct PriorFromMotion<T: Scalar> {
    pub(crate) initial: InitialState<T, 1>,
    pub(crate) config: FilterConfig<T>,
    pub(crate) prior: PoseImuOptions,
    pub(crate) rotation_init: init::RotationInit,
    /// Where the starting gyro bias came from (report words).
    pub(crate) gyro_bias_init: String,
    /// The moving start's alignment (report words; empty after a standstill).
    pub(crate) moving_start: String,
}

fn start_from_motion<T: Scalar>(
    input: &CameraImuInput<'_>,
    options: &CameraImuOptions,
    standstill: Option<&init::Standstill>,
    start: &Start<'_>,
    extrinsic_prior: ExtrinsicPrior,
) -> Result<StartFromMotion<T>, InputError> {
    let PriorFromMotion {
        initial,
        config,
        prior,
        rotation_init,
        gyro_bias_init,
        moving_start,
    } = prior_from_motion(input, options, standstill, start, extrinsic_prior)?;
    let ekf = CameraImuEkf::<T>::new(&config, &initial)
        .map_err(|error| InputError::InvalidNoise { error })?;
    Ok(StartFromMotion {
        ekf,
        prior,
        rotation_init,
        gyro_bias_init,
        moving_start,
    })
}

pub(crate) fn prior_from_motion<T: Scalar>(
    input: &CameraImuInput<'_>,
    options: &CameraImuOptions,
    standstill: Option<&init::Standstill>,
    start: &Start<'_>,
    extrinsic_prior: ExtrinsicPrior,
) -> Result<PriorFromMotion<T>, InputError> {
    let imu = input.imu;
    let motion = start.motion;
    let m = &motion.report.filter;
    let rotation_init = init::RotationInit {
        rotation: nalgebra::UnitQuaternion::from_scaled_axis(Vector3::from(
            m.hand_eye_rotation_vector,
        )),
        pairs: m.hand_eye_pairs,
        axis_ratio: m.hand_eye_axis_ratio,
    };
    let prior = reprojection_prior(options, motion, extrinsic_prior, standstill.is_some());
    let (sigma_r, sigma_t, sigma_td) = (
        prior.rotation_sigma_rad,
        prior.translation_sigma_m,
        prior.time_offset_sigma_s,
    );
    let initial = initial_state::<T>(imu, standstill, &motion.t_imu_sensor.rotation, &prior)?;
    let (initial, gyro_bias_init, moving_start) = match standstill {
        None => moving_imu_state(input, start, initial),
        Some(_) => (initial, "standstill mean".to_string(), String::new()),
    };
    let initial = initial.with_extrinsic(
        0,
        convert::pose::<T>(&motion.t_imu_sensor),
        T::lit(sigma_r),
        T::lit(sigma_t),
    );
    let initial = if prior.estimate_time_offset {
        initial.with_time_offset(0, T::lit(motion.time_offset_s), T::lit(sigma_td))
    } else {
        initial
    };
    let config = FilterConfig {
        max_noise_scale: T::lit(match options.image_noise {
            ImageNoise::PerImage => MAX_NOISE_SCALE,
            ImageNoise::Uniform => 1.0,
        }),
        ..FilterConfig::new(convert::imu_noise::<T>(input.imu_noise))
    };
    Ok(PriorFromMotion {
        initial,
        config,
        prior,
        rotation_init,
        gyro_bias_init,
        moving_start,
    })
}

/// A moving start: the IMU state (gravity, velocity, biases) from the dynamic alignment of
/// the PnP odometry with the pre-integrated IMU, at MoCal's time offset (with `t_d = 0`
/// the odometry is misplaced against the IMU by `t_d`: at the fastest rotation of the
/// simulated recordings, 2.7 rad/s and `t_d` = -6.7 ms, that tilted gravity by 1.6 deg
/// against a 0.46 deg sigma; 0.45 deg at MoCal's `t_d`). With the report's words for the
/// gyro bias and the alignment.
fn moving_imu_state<T: Scalar>(
    input: &CameraImuInput<'_>,
    start: &Start<'_>,
    initial: InitialState<T, 1>,
) -> (InitialState<T, 1>, String, String) {
    let (imu, motion) = (input.imu, start.motion);
    let odometry: Vec<PoseRecord> = start.poses.iter().map(camera_in_target).collect();
    let rotation = motion.t_imu_sensor.rotation;
    let increments = init::pose_increments(
        &odometry,
        nominal_frame_period_ns(input.frames).saturating_mul(3) / 2,
    );
    let bias = gyro_bias::estimate_gyro_bias(imu, &increments, &rotation, &Vector3::zeros());
    let (initial, gyro_words) = with_gyro_bias(initial, None, bias.as_ref());
    let aligned = moving_start(
        imu,
        &odometry,
        &rotation,
        (bias.as_ref(), motion.time_offset_s),
        input.imu_noise,
    );
    let words = describe_moving_start(&aligned);
    match aligned {
        Ok(p) => (with_moving_start(initial, &p), gyro_words, words),
        Err(_) => (initial, gyro_words, words),
    }
}

/// RepErrCal's extrinsic and time-offset prior around the start `motion`; `at_rest` when
/// the recording starts with a standstill.
fn reprojection_prior(
    options: &CameraImuOptions,
    motion: &CameraImuCalibration,
    extrinsic_prior: ExtrinsicPrior,
    at_rest: bool,
) -> PoseImuOptions {
    let (sigma_r, sigma_t, sigma_td) = match extrinsic_prior {
        ExtrinsicPrior::AroundStart => {
            let (floor_r, floor_t, floor_td) = REPROJECTION_PRIOR_FLOOR;
            // MoCal's sigmas hold only as far as its noise model does: scaled up by its
            // mean NIS per dof when that exceeds 1 (3-4 on EuRoC `imu_april`, whose PnP
            // depth errors are correlated from image to image).
            let inflation = motion.report.filter.mean_nis_per_dof.max(1.0).sqrt();
            let sd = |i: usize| motion.covariance[(i, i)].max(0.0).sqrt() * inflation;
            // The time offset's floor only where the first images are still. In motion an
            // error `e` of `t_d` shifts an image by `w e`, and the update relinearises the
            // pose at every corner but not that shift (the `t_d` column of its Jacobian):
            // with the 5 ms floor at 2.7 rad/s the first image of a moving start had NIS
            // 1.4e6 and RepErrCal diverged. MoCal's own (inflated) sigma is used there.
            let td = motion.time_offset_sigma_s * inflation;
            (
                (0..3).map(sd).fold(floor_r, f64::max),
                (3..6).map(sd).fold(floor_t, f64::max),
                if at_rest { td.max(floor_td) } else { td },
            )
        }
        ExtrinsicPrior::Held => (HELD_SIGMA, HELD_SIGMA, HELD_SIGMA),
    };
    PoseImuOptions {
        rotation_sigma_rad: sigma_r,
        translation_sigma_m: sigma_t,
        time_offset_sigma_s: sigma_td,
        ..options.prior
    }
}

/// The 4x4 matrix of `t`, row by row.
fn rows(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = t.to_homogeneous();
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// Median image spacing, ns.
fn nominal_frame_period_ns(frames: &[CornerFrame]) -> u64 {
    let mut d: Vec<u64> = frames
        .windows(2)
        .map(|w| w[1].stamp_ns.saturating_sub(w[0].stamp_ns))
        .collect();
    d.sort_unstable();
    d.get(d.len() / 2).copied().unwrap_or(50_000_000)
}

/// The RepErrCal measurement feed: fuses every image whose IMU time has come, initialising
/// the target pose from the first image's PnP.
pub(crate) struct CornerFeed<'a, T: Scalar> {
    /// The filter's index of the camera (its target is static frame 0).
    sensor: usize,
    run: Run,
    frames: &'a [CornerFrame],
    next: usize,
    camera: Camera<T>,
    /// Corner noise of the recording (the median image's), and the floor of each image's.
    pixel_sigma: T,
    /// Each image's own corner noise from its PnP fit, by stamp: motion blur doubles it in
    /// the fast part of EuRoC `imu_april` (medians 0.2-0.3 px at rest, 0.4-0.55 px at 2 rad/s).
    frame_sigma: std::collections::HashMap<u64, f64>,
    prior: PoseImuOptions,
    reprojection: Vec<FrameReprojection>,
    buffer: Vec<CornerObservation<T>>,
    /// The first accepted image from this stamp on becomes the report's sample.
    sample_from_ns: u64,
    sample: Option<ReprojectionSample>,
    /// Whether the target, once placed, fixes the gauge ([`CornerFeed::with_gauge_at_target`]).
    gauge_at_target: bool,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    ImuHooks<T, Ekf<T, S, C, N, F>> for CornerFeed<'_, T>
{
    fn fuse_due(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
        _rec: &ImuRecord,
    ) -> Result<(), InputError> {
        while self.next_due(ekf).is_some() {
            self.fuse_next(ekf, index);
        }
        Ok(())
    }
}

impl<'a, T: Scalar> CornerFeed<'a, T> {
    /// The feed of the camera that is sensor `sensor` of the filter, over `input`'s images.
    pub(crate) fn new(
        input: &CameraImuInput<'a>,
        options: &CameraImuOptions,
        start: &Start<'_>,
        prior: PoseImuOptions,
        sensor: usize,
    ) -> Self {
        let frames = input.frames;
        Self {
            sensor,
            run: Run::new(
                input.imu.first().map_or(0, |r| r.stamp_ns),
                nominal_frame_period_ns(frames),
            )
            .for_sensor(sensor),
            frames,
            next: 0,
            camera: input.camera.cast::<T>(),
            pixel_sigma: T::lit(start.pixel_sigma),
            frame_sigma: match options.image_noise {
                ImageNoise::PerImage => start
                    .poses
                    .iter()
                    .filter_map(|p| Some((p.stamp_ns, frame_pixel_sigma(p)?)))
                    .collect(),
                ImageNoise::Uniform => Default::default(),
            },
            prior,
            reprojection: Vec::new(),
            buffer: Vec::new(),
            sample_from_ns: frames.get(frames.len() / 2).map_or(0, |f| f.stamp_ns),
            sample: None,
            gauge_at_target: false,
        }
    }

    /// Once the target is placed, it fixes the gauge ([`Ekf::fix_gauge`]): G's origin and yaw
    /// become the target's, as Kalibr takes the target as its world frame, so the filter
    /// cannot gain spurious information along the four directions no measurement sees. The
    /// joint pipeline uses it (10 seeds: camera NEES 145.7 -> 91.6, LiDAR 91.1 -> 69.9;
    /// docs/joint.md). The camera-IMU pipeline does not: its NEES cells barely moved, and
    /// the device's f32 filter then drifted 0.85 sigma from the host's in the HIL test.
    pub(crate) fn with_gauge_at_target(mut self) -> Self {
        self.gauge_at_target = true;
        self
    }

    /// The stamp of the next image when it is due (its IMU time is within reach).
    pub(crate) fn next_due<const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> Option<u64> {
        let frame = self.frames.get(self.next)?;
        ekf.is_due(self.sensor, frame.stamp_ns)
            .then_some(frame.stamp_ns)
    }

    /// Books every image not reached as after the last IMU sample.
    pub(crate) fn skip_remaining(&mut self) {
        for frame in &self.frames[self.next..] {
            self.run
                .skip_measurement("cam0", frame.stamp_ns, "after the last IMU sample");
        }
        self.next = self.frames.len();
    }

    /// The run's bookkeeping, every image not reached booked as after the last IMU sample.
    pub(crate) fn into_run(mut self) -> Run {
        self.skip_remaining();
        self.run
    }

    /// Fuses the image [`CornerFeed::next_due`] found due (`index`: the IMU sample fed
    /// last), initialising the target from it when none is yet.
    pub(crate) fn fuse_next<const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
    ) {
        let Some(frame) = self.frames.get(self.next) else {
            return;
        };
        self.next += 1;
        if index == 0 {
            self.run
                .skip_measurement("cam0", frame.stamp_ns, "before the first IMU sample");
            return;
        }
        if frame.corners.len() < MIN_CORNERS {
            self.run
                .skip_measurement("cam0", frame.stamp_ns, "too few corners");
            return;
        }
        if ekf.frame(TARGET).is_none() {
            if let Err(why) = self.init_target(ekf, frame) {
                self.run.skip_measurement("cam0", frame.stamp_ns, &why);
                return;
            }
        }
        self.fuse(ekf, frame);
    }

    /// `T_G_T = T_G_I T_I_C T_C_T(PnP)` at the image's IMU time, with its full
    /// cross-covariance with the IMU pose, the extrinsic and the time offset
    /// ([`Ekf::init_frame_relative`]): the extrinsic prior's error is in the target's pose
    /// once, as a correlation, not a second time as independent sigmas. The PnP pose gets
    /// the documented conservative sigmas of [`target_prior_sigmas`] (independent per axis),
    /// the same the `link` replay sends the device in its `TargetPose`, so that host and
    /// device start alike (the PnP fit's own covariance, `sigma^2 (J^T J)^-1`, is tighter;
    /// with it the host's f64 RepErrCal and the device's f32 differed by 2.8 host sigma in
    /// translation in the camera HIL test). With [`CornerFeed::with_gauge_at_target`] the
    /// target then fixes the gauge. The image is then also fused.
    fn init_target<const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &mut Ekf<T, S, C, N, F>,
        frame: &CornerFrame,
    ) -> Result<(), String> {
        let camera = self.camera.cast::<f64>();
        let pnp = pnp_of(&camera, frame).map_err(|e| format!("no PnP pose for the target: {e}"))?;
        let (r, p) = target_prior_sigmas(&self.prior, pnp.t_cam_target.translation.norm());
        let cov = Matrix6::from_diagonal(&nalgebra::Vector6::new(
            r * r,
            r * r,
            r * r,
            p * p,
            p * p,
            p * p,
        ))
        .map(T::lit);
        ekf.init_frame_relative(
            TARGET,
            self.sensor,
            frame.stamp_ns,
            &convert::pose::<T>(&convert::isometry(&pnp.t_cam_target)),
            &cov,
        )
        .and_then(|()| {
            if self.gauge_at_target {
                ekf.fix_gauge(TARGET)
            } else {
                Ok(())
            }
        })
        .map_err(|e| format!("cannot initialise the target: {e}"))
    }

    fn fuse<const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        frame: &CornerFrame,
    ) {
        self.buffer.clear();
        self.buffer
            .extend(frame.corners.iter().map(|c| CornerObservation {
                point_in_target: convert::vec3(&c.point_in_target),
                pixel: Vector2::new(T::lit(c.pixel.x), T::lit(c.pixel.y)),
            }));
        let before = self.mean_error(ekf);
        let own = self
            .frame_sigma
            .get(&frame.stamp_ns)
            .copied()
            .unwrap_or(0.0);
        let meas = CornerSet {
            stamp_ns: frame.stamp_ns,
            corners: &self.buffer,
            pixel_sigma: self.pixel_sigma.max(T::lit(own)),
        };
        match ekf.update_reprojection(self.sensor, TARGET, &self.camera, &meas) {
            Ok(report) => {
                self.run.record_update(ekf, frame.stamp_ns, &report);
                let after = self.mean_error(ekf);
                if report.accepted && self.sample.is_none() && frame.stamp_ns >= self.sample_from_ns
                {
                    self.sample = self.reprojection_sample(ekf, frame.stamp_ns);
                }
                self.reprojection.push(FrameReprojection {
                    t_s: self.run.seconds(frame.stamp_ns),
                    corners: frame.corners.len(),
                    mean_error_before_px: before,
                    mean_error_px: after,
                    accepted: report.accepted,
                });
            }
            Err(FilterError::NotProjectable) => self.run.skip_measurement(
                "cam0",
                frame.stamp_ns,
                "corners not projectable at the estimate",
            ),
            Err(e) => self
                .run
                .skip_measurement("cam0", frame.stamp_ns, &format!("{e}")),
        }
    }

    /// The buffered corners and their reprojection at the current state.
    fn reprojection_sample<const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
        stamp_ns: u64,
    ) -> Option<ReprojectionSample> {
        let target = ekf.frame(TARGET)?;
        let pixel = |p: &Vector2<T>| Vector2::new(p.x.to_f64(), p.y.to_f64());
        let reprojected = self
            .buffer
            .iter()
            .map(|c| {
                let p = msreg_estimator::update::reprojection::point_in_camera(
                    &ekf.imu().pose(),
                    &ekf.extrinsic(self.sensor),
                    &target,
                    &c.point_in_target,
                );
                self.camera.project(&p).map(|x| pixel(&x.pixel))
            })
            .collect::<Option<Vec<_>>>()?;
        Some(ReprojectionSample {
            stamp_ns,
            detected: self.buffer.iter().map(|c| pixel(&c.pixel)).collect(),
            reprojected,
        })
    }

    /// Mean distance between the buffered corners and their projection at the filter's
    /// current state (NaN when one does not project).
    fn mean_error<const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> f64 {
        let Some(target) = ekf.frame(TARGET) else {
            return f64::NAN;
        };
        let imu = ekf.imu().pose();
        let extrinsic = ekf.extrinsic(self.sensor);
        let mut sum = 0.0;
        for c in &self.buffer {
            let p = msreg_estimator::update::reprojection::point_in_camera(
                &imu,
                &extrinsic,
                &target,
                &c.point_in_target,
            );
            match self.camera.project(&p) {
                Some(projected) => sum += (projected.pixel - c.pixel).norm().to_f64(),
                None => return f64::NAN,
            }
        }
        sum / self.buffer.len().max(1) as f64
    }
}

/// PnP pose of the target in one image.
pub fn pnp_of(camera: &Camera<f64>, frame: &CornerFrame) -> Result<PnpSolution, String> {
    let points: Vec<Vector3<f64>> = frame.corners.iter().map(|c| c.point_in_target).collect();
    let pixels: Vec<Vector2<f64>> = frame.corners.iter().map(|c| c.pixel).collect();
    solve_pnp(camera, &points, &pixels).map_err(|e| e.to_string())
}

/// PnP of every image with enough corners.
pub(crate) fn frame_poses(camera: &Camera<f64>, frames: &[CornerFrame]) -> Vec<FramePose> {
    use rayon::prelude::*;
    frames
        .par_iter()
        .filter(|f| f.corners.len() >= MIN_CORNERS)
        .filter_map(|f| {
            pnp_of(camera, f).ok().map(|pnp| FramePose {
                stamp_ns: f.stamp_ns,
                points: f.corners.len(),
                pnp,
            })
        })
        .collect()
}

/// The camera's pose in the target frame as odometry (`T_T_C`, origin = target).
fn camera_in_target(pose: &FramePose) -> PoseRecord {
    let t_t_c = convert::isometry(&pose.pnp.t_cam_target).inverse();
    PoseRecord {
        stamp_ns: pose.stamp_ns,
        position: t_t_c.translation.vector,
        rotation: t_t_c.rotation,
    }
}

/// Per-axis corner noise from the PnP fits: the median RMS residual, per axis, corrected
/// for the 6 DoF the fit absorbs.
fn pixel_sigma_from_pnp(poses: &[FramePose]) -> f64 {
    let mut per_axis: Vec<f64> = poses.iter().filter_map(frame_pixel_sigma).collect();
    per_axis.sort_by(f64::total_cmp);
    per_axis
        .get(per_axis.len() / 2)
        .copied()
        .unwrap_or(MIN_PIXEL_SIGMA)
        .max(MIN_PIXEL_SIGMA)
}

/// One image's per-axis corner noise from its PnP fit: the RMS residual corrected for the
/// 6 DoF the fit absorbs; `None` with too few corners to say.
fn frame_pixel_sigma(pose: &FramePose) -> Option<f64> {
    let n = pose.points as f64;
    (pose.points > 3).then(|| pose.pnp.rms_px / 2f64.sqrt() * (2.0 * n / (2.0 * n - 6.0)).sqrt())
}

/// MoCal's odometry noise per increment: two independent PnP poses, each with the median
/// of the frames' largest per-axis sigma of `T_T_C`.
fn increment_noise(poses: &[FramePose]) -> PoseSensorYaml {
    let mut rotation = Vec::with_capacity(poses.len());
    let mut translation = Vec::with_capacity(poses.len());
    for p in poses {
        let t_c_t = convert::isometry(&p.pnp.t_cam_target);
        let (_, cov) = invert_with_covariance(&t_c_t, &p.pnp.covariance);
        let max_sd = |b: usize| {
            (0..3)
                .map(|i| cov[(b + i, b + i)].max(0.0).sqrt())
                .fold(0.0, f64::max)
        };
        rotation.push(max_sd(0));
        translation.push(max_sd(3));
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    PoseSensorYaml {
        rotation_noise_rad: median(&mut rotation) * 2f64.sqrt(),
        translation_noise_m: median(&mut translation) * 2f64.sqrt(),
        rate_hz: None,
    }
}
