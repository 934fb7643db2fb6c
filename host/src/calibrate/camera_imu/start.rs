//! The camera-IMU filter start: the IMU state from a standstill or the moving start, the extrinsic
//! and target priors (RepErrCal's from MoCal's result).

use super::*;
use crate::calibrate::convert;
use crate::calibrate::driver::report::PoseImuOptions;
use crate::calibrate::driver::{
    describe_moving_start, initial_state, moving_start, with_gyro_bias, with_moving_start,
};
use crate::calibrate::gyro_bias;
use crate::calibrate::init;
use crate::calibrate::InputError;
use crate::dataset::PoseRecord;
use msreg_estimator::{CameraImuEkf, FilterConfig, InitialState, Scalar};
use nalgebra::{Isometry3, Vector3};

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
pub(crate) const HELD_SIGMA: f64 = 1e-6;

/// Smallest prior 1-sigma of RepErrCal around the MoCal estimate: wide enough that the
/// prior carries almost none of the information (the same data produced it), narrow enough
/// that the first images are linearised close to the truth. The time offset's only at a
/// standstill start (see [`reprojection_prior`]).
pub(crate) const REPROJECTION_PRIOR_FLOOR: (f64, f64, f64) =
    (0.5 * std::f64::consts::PI / 180.0, 0.01, 0.005);

/// What RepErrCal starts from: the MoCal (or final) estimate, the recording's corner noise
/// and every image's PnP pose (computed once per calibration).
#[derive(Clone, Copy)]
pub(crate) struct Start<'a> {
    pub(crate) motion: &'a CameraImuCalibration,
    pub(crate) pixel_sigma: f64,
    pub(crate) poses: &'a [FramePose],
}

/// The RepErrCal filter at the MoCal estimate, with its prior.
pub(crate) struct StartFromMotion<T: Scalar> {
    pub(crate) ekf: CameraImuEkf<T>,
    pub(crate) prior: PoseImuOptions,
    pub(crate) rotation_init: init::RotationInit,
    /// Where the starting gyro bias came from (report words).
    pub(crate) gyro_bias_init: String,
    /// The moving start's alignment (report words; empty after a standstill).
    pub(crate) moving_start: String,
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

pub(crate) fn start_from_motion<T: Scalar>(
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
        SOLE_SENSOR,
        convert::pose::<T>(&motion.t_imu_sensor),
        T::lit(sigma_r),
        T::lit(sigma_t),
    );
    let initial = if prior.estimate_time_offset {
        initial.with_time_offset(SOLE_SENSOR, T::lit(motion.time_offset_s), T::lit(sigma_td))
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
pub(crate) fn moving_imu_state<T: Scalar>(
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
pub(crate) fn reprojection_prior(
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
pub(crate) fn rows(t: &Isometry3<f64>) -> [[f64; 4]; 4] {
    let m = t.to_homogeneous();
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// Median image spacing, ns.
pub(crate) fn nominal_frame_period_ns(frames: &[CornerFrame]) -> u64 {
    let mut d: Vec<u64> = frames
        .windows(2)
        .map(|w| w[1].stamp_ns.saturating_sub(w[0].stamp_ns))
        .collect();
    d.sort_unstable();
    d.get(d.len() / 2).copied().unwrap_or(50_000_000)
}
