//! A dataset as the message sequence the firmware needs: a [`Config`] with the same
//! initialisation as `calibrate::pose_imu` (standstill gravity and gyro bias, hand-eye
//! rotation, the same priors), then IMU batches with the odometry interleaved; or, for a
//! camera dataset ([`build_camera_stream`]), the configuration RepErrCal starts from
//! (`calibrate::camera_imu`: MoCal's estimate run here on the host) with target poses and
//! corner sets interleaved.
//!
//! Pose sequencing mirrors the host pipeline: the first pose due at or before the first IMU
//! sample is skipped; a pose after a gap longer than ten nominal periods (or the first one),
//! and a pose surely taken at rest (`pose_imu::rest_until_ns`), becomes an [`Anchor`]; every other pose becomes the increment from the previous one, with
//! sigmas scaled by the square root of the periods it spans. A pose message is sent
//! [`StreamOptions::pose_lead_ns`] ahead of the IMU samples around its stamp; the firmware
//! holds it until the IMU stream reaches `stamp + t_d`.
//!
//! Camera sequencing mirrors RepErrCal's corner feed: images due at or before the first IMU
//! sample and images with fewer than `MIN_CORNERS` corners are skipped; the first image
//! with a PnP pose sends a [`TargetPose`] (the device sets the target frame from it) and
//! every image from it on a [`CornerSet`] (several, evenly split, when it has more than
//! [`CORNER_SET_MAX`] corners), [`StreamOptions::camera_lead_ns`] ahead.

use msreg_estimator::camera::{Camera, Distortion, Projection};
use msreg_estimator::Scalar;
use msreg_protocol::{
    Anchor, Bounded, CameraDistortion, CameraProjection, CameraSetup, Config, Corner, CornerSet,
    Gate, HostMsg, ImuBatch, ImuNoise, ImuPrior, ImuSample, Pose, RelativePose, RestPrior,
    SensorPrior, SensorSet, TargetPose, CORNER_SET_MAX, IMU_BATCH_MAX,
};
use nalgebra::{Isometry3, Vector3};

use super::LinkError;
use crate::calibrate::camera_imu::{
    self, pnp_of, CameraImuInput, CameraImuOptions, CornerFrame, ReprojectionStart, MIN_CORNERS,
};
use crate::calibrate::driver::report::PoseImuOptions;
use crate::calibrate::driver::{nominal_period_ns, time_offset_sigma_s, ImuStartPrior};
use crate::calibrate::pose_imu::{confirmed_standstill, rest_until_ns, PoseImuInput};
use crate::calibrate::{init, InputError};
use crate::dataset::{ImuNoiseYaml, ImuRecord};

/// Options of the stream.
#[derive(Debug, Clone, Copy)]
pub struct StreamOptions {
    /// IMU samples per batch (1..=16).
    pub batch: usize,
    /// Send a pose this long before the IMU samples at its stamp, ns (covers `|t_d|`).
    pub pose_lead_ns: u64,
    /// Send a target pose or corner set this long before the IMU samples at its stamp, ns:
    /// covers `t_d` down to minus this, and keeps the device's camera queue short (each
    /// entry is a corner set's worth of RAM).
    pub camera_lead_ns: u64,
    /// Estimate period, ns (0: one estimate after each update).
    pub estimate_period_ns: u32,
    /// Pipeline options (priors) shared with `calibrate pose-imu`.
    pub pipeline: PoseImuOptions,
}

impl Default for StreamOptions {
    fn default() -> Self {
        Self {
            batch: 10,
            pose_lead_ns: 250_000_000,
            camera_lead_ns: 60_000_000,
            estimate_period_ns: 0,
            pipeline: PoseImuOptions::default(),
        }
    }
}

/// The messages of a replay, with the sensor stamp each is due at (for real-time pacing).
#[derive(Debug, Clone)]
pub struct ReplayStream {
    /// The configuration (sent first).
    pub config: Config,
    /// `(stamp_ns, message)`: IMU batches carry their last sample's stamp.
    pub messages: Vec<(u64, HostMsg)>,
    /// First IMU stamp, ns.
    pub start_ns: u64,
    /// Poses or images skipped (before the first IMU sample; for images also too few
    /// corners, or before the first PnP pose).
    pub skipped_poses: usize,
}

impl ReplayStream {
    /// `config`, then the IMU in batches of `batch` with `measurements` (stamp order) each
    /// sent `lead_ns` ahead of the IMU samples at its stamp.
    pub(super) fn interleaved(
        config: Config,
        imu: &[ImuRecord],
        measurements: &[(u64, HostMsg)],
        (lead_ns, batch): (u64, usize),
        skipped_poses: usize,
    ) -> Self {
        Self {
            config,
            messages: interleave(imu, measurements, lead_ns, batch),
            start_ns: imu.first().map_or(0, |r| r.stamp_ns),
            skipped_poses,
        }
    }
}

pub(super) fn f32x3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

/// A pose as the protocol carries it.
fn wire_pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    Pose {
        rotation_wxyz: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
        translation_m: f32x3(&iso.translation.vector),
    }
}

/// The configuration the pipeline would start from.
pub fn config(input: &PoseImuInput<'_>, options: &StreamOptions) -> Result<Config, LinkError> {
    let imu = input.imu;
    if imu.is_empty() {
        return Err(InputError::NoImuSamples.into());
    }
    if input.poses.len() < 3 {
        return Err(InputError::TooFew {
            file: "pose0/data.csv",
            what: "poses",
            found: input.poses.len(),
            needed: 3,
        }
        .into());
    }
    let p = &options.pipeline;
    let standstill = init::detect_standstill(imu, p.min_standstill_s);
    let gyro_bias = ImuStartPrior::of(imu, standstill.as_ref()).gyro_bias;
    let period_ns = nominal_period_ns(input.poses);
    let rotation = init::hand_eye_rotation(imu, input.poses, &gyro_bias, period_ns * 3 / 2)
        .map_err(|error| InputError::HandEyeRotation {
            sensor: "pose0/",
            error,
        })?;
    let base = imu_config(imu, input.imu_noise, options);
    Ok(Config {
        sensor: SensorPrior {
            extrinsic: wire_pose(&Isometry3::from_parts(
                Default::default(),
                rotation.rotation,
            )),
            ..base.sensor
        },
        ..base
    })
}

/// The IMU part of a configuration as the pipelines set it (standstill gravity and gyro
/// bias, zero-velocity updates while still), with the pipeline's extrinsic priors around
/// an identity extrinsic and a zero time offset.
fn imu_config(imu: &[ImuRecord], imu_noise: &ImuNoiseYaml, options: &StreamOptions) -> Config {
    let p = &options.pipeline;
    let standstill = init::detect_standstill(imu, p.min_standstill_s);
    let prior = ImuStartPrior::of(imu, standstill.as_ref());
    let (sigma_orientation_rad, sigma_velocity_m_s) = prior.moving_sigmas.unwrap_or((0.0, 0.0));
    let noise = crate::calibrate::convert::imu_noise::<f32>(imu_noise);
    Config {
        sensors: SensorSet::PoseImu,
        imu_noise: ImuNoise {
            gyro_noise_density: noise.gyro_noise_density.to_f64() as f32,
            accel_noise_density: noise.accel_noise_density.to_f64() as f32,
            gyro_random_walk: noise.gyro_random_walk.to_f64() as f32,
            accel_random_walk: noise.accel_random_walk.to_f64() as f32,
        },
        gate: Gate::P999,
        max_imu_gap_ns: 50_000_000,
        imu_prior: ImuPrior::AtRest(RestPrior {
            accel_mean: f32x3(&prior.accel_mean),
            gyro_bias: f32x3(&prior.gyro_bias),
            sigma_orientation_rad: sigma_orientation_rad as f32,
            sigma_velocity_m_s: sigma_velocity_m_s as f32,
        }),
        sensor: SensorPrior {
            extrinsic: Pose {
                rotation_wxyz: [1.0, 0.0, 0.0, 0.0],
                translation_m: [0.0; 3],
            },
            sigma_rotation_rad: p.rotation_sigma_rad as f32,
            sigma_translation_m: p.translation_sigma_m as f32,
            time_offset_s: 0.0,
            sigma_time_offset_s: time_offset_sigma_s(p) as f32,
        },
        zero_velocity_until_ns: standstill.map_or(0, |s| s.until_ns),
        zero_velocity_every: 20,
        estimate_period_ns: options.estimate_period_ns,
    }
}

/// The whole replay of a dataset.
pub fn build_stream(
    input: &PoseImuInput<'_>,
    options: &StreamOptions,
) -> Result<ReplayStream, LinkError> {
    let config = config(input, options)?;
    let period_ns = nominal_period_ns(input.poses);
    let max_interval_ns = period_ns.saturating_mul(10);
    let (sigma_r, sigma_t) = (
        input.pose_noise.rotation_noise_rad,
        input.pose_noise.translation_noise_m,
    );
    let start_ns = input.imu[0].stamp_ns;
    // Poses due at or before the first IMU sample (with the prior t_d = 0) are skipped.
    let first = input
        .poses
        .iter()
        .position(|p| p.stamp_ns > start_ns)
        .unwrap_or(input.poses.len());
    // Poses surely taken at rest anchor the odometry, as in the pipeline.
    let rest_until = rest_until_ns(
        confirmed_standstill(input, &options.pipeline).as_ref(),
        &options.pipeline,
    );
    let mut previous: Option<&crate::dataset::PoseRecord> = None;
    let mut measurements = Vec::with_capacity(input.poses.len());
    for pose in &input.poses[first..] {
        let at_rest = rest_until.is_some_and(|t| pose.stamp_ns <= t);
        let moving_from = previous.filter(|p| pose.stamp_ns - p.stamp_ns <= max_interval_ns);
        let msg = match moving_from.filter(|_| !at_rest) {
            None => HostMsg::Anchor(Anchor {
                stamp_ns: pose.stamp_ns,
                sensor: 0,
            }),
            Some(prev) => {
                let periods = ((pose.stamp_ns - prev.stamp_ns) as f64 / period_ns as f64)
                    .round()
                    .max(1.0);
                let scale = periods.sqrt();
                let delta = prev.isometry().inverse() * pose.isometry();
                HostMsg::RelativePose(RelativePose {
                    stamp_from_ns: prev.stamp_ns,
                    stamp_to_ns: pose.stamp_ns,
                    delta: wire_pose(&delta),
                    sigma_rotation_rad: [(sigma_r * scale) as f32; 3],
                    sigma_translation_m: [(sigma_t * scale) as f32; 3],
                    sensor: 0,
                })
            }
        };
        previous = Some(pose);
        measurements.push((pose.stamp_ns, msg));
    }
    Ok(ReplayStream::interleaved(
        config,
        input.imu,
        &measurements,
        (options.pose_lead_ns, options.batch),
        first,
    ))
}

/// IMU batches of at most `batch` samples with the measurements (stamp order) between them:
/// each measurement goes out before the batch holding the IMU sample `lead_ns` before its
/// stamp.
fn interleave(
    imu: &[ImuRecord],
    measurements: &[(u64, HostMsg)],
    lead_ns: u64,
    batch: usize,
) -> Vec<(u64, HostMsg)> {
    let batch_len = batch.clamp(1, IMU_BATCH_MAX);
    let mut pending = measurements.iter().peekable();
    let mut messages = Vec::with_capacity(imu.len() / batch_len + measurements.len() + 1);
    let mut batch: Option<ImuBatch> = None;
    for rec in imu {
        while let Some(m) = pending.next_if(|(stamp, _)| *stamp <= rec.stamp_ns + lead_ns) {
            messages.push(*m);
        }
        let b = batch.get_or_insert_with(|| ImuBatch {
            base_stamp_ns: rec.stamp_ns,
            samples: Bounded::new(),
        });
        let offset = rec.stamp_ns.saturating_sub(b.base_stamp_ns);
        let sample = ImuSample {
            offset_ns: u32::try_from(offset).unwrap_or(u32::MAX),
            gyro: f32x3(&rec.gyro),
            accel: f32x3(&rec.accel),
        };
        // A full batch goes out; the samples' order is kept.
        if b.samples.push(sample).is_ok() && b.samples.len() < batch_len {
            continue;
        }
        if let Some(full) = batch.take() {
            messages.push((rec.stamp_ns, HostMsg::ImuBatch(full)));
        }
    }
    if let (Some(b), Some(last)) = (batch.take(), imu.last()) {
        messages.push((last.stamp_ns, HostMsg::ImuBatch(b)));
    }
    messages
}

/// The camera model and corner noise as the protocol carries them.
pub fn camera_setup(camera: &Camera<f64>, pixel_sigma: f64) -> CameraSetup {
    let i = camera.intrinsics();
    CameraSetup {
        projection: match *camera.projection() {
            Projection::Pinhole => CameraProjection::Pinhole,
            Projection::Omni { xi } => CameraProjection::Omni { xi: xi as f32 },
        },
        intrinsics: [i.fu, i.fv, i.cu, i.cv].map(|x| x as f32),
        distortion: match *camera.distortion() {
            Distortion::None => CameraDistortion::None,
            Distortion::RadTan(d) => {
                CameraDistortion::RadTan([d.k1, d.k2, d.p1, d.p2, d.k3].map(|x| x as f32))
            }
            Distortion::Equidistant(d) => {
                CameraDistortion::Equidistant([d.k1, d.k2, d.k3, d.k4].map(|x| x as f32))
            }
        },
        resolution: [camera.resolution.0, camera.resolution.1],
        pixel_sigma: pixel_sigma as f32,
    }
}

/// The configuration RepErrCal starts from: MoCal's `T_imu_cam` and time offset with the
/// prior around them.
pub fn camera_config(
    input: &CameraImuInput<'_>,
    start: &ReprojectionStart,
    options: &StreamOptions,
) -> Config {
    let prior = &start.prior;
    let (time_offset_s, sigma_time_offset_s) = if prior.estimate_time_offset {
        (start.motion.time_offset_s, prior.time_offset_sigma_s)
    } else {
        (0.0, 0.0)
    };
    Config {
        sensors: SensorSet::CameraImu(camera_setup(input.camera, start.pixel_sigma)),
        sensor: SensorPrior {
            extrinsic: wire_pose(&start.motion.t_imu_sensor),
            sigma_rotation_rad: prior.rotation_sigma_rad as f32,
            sigma_translation_m: prior.translation_sigma_m as f32,
            time_offset_s: time_offset_s as f32,
            sigma_time_offset_s: sigma_time_offset_s as f32,
        },
        ..imu_config(input.imu, input.imu_noise, options)
    }
}

/// The corners of one image as corner sets of at most [`CORNER_SET_MAX`], evenly split.
fn corner_sets(frame: &CornerFrame) -> Vec<HostMsg> {
    let n = frame.corners.len();
    let chunk = n.div_ceil(n.div_ceil(CORNER_SET_MAX).max(1)).max(1);
    frame
        .corners
        .chunks(chunk)
        .map(|part| {
            HostMsg::CornerSet(CornerSet {
                stamp_ns: frame.stamp_ns,
                corners: part
                    .iter()
                    .map(|c| Corner {
                        point_in_target_m: f32x3(&c.point_in_target),
                        pixel: [c.pixel.x as f32, c.pixel.y as f32],
                    })
                    .collect(),
            })
        })
        .collect()
}

/// The whole replay of a camera dataset: MoCal runs here (f64) for RepErrCal's start, as
/// `msreg calibrate camera-imu` does, then the device fuses the corners.
pub fn build_camera_stream(
    input: &CameraImuInput<'_>,
    camera_options: &CameraImuOptions,
    options: &StreamOptions,
) -> Result<ReplayStream, LinkError> {
    let Some(first_imu) = input.imu.first() else {
        return Err(InputError::NoImuSamples.into());
    };
    let start = camera_imu::reprojection_start::<f64>(input, camera_options, &mut |_| {})?;
    let config = camera_config(input, &start, options);
    let start_ns = first_imu.stamp_ns;
    let td_ns = (f64::from(config.sensor.time_offset_s) * 1e9) as i128;
    let mut measurements = Vec::with_capacity(input.frames.len() + 1);
    let mut skipped = 0;
    for frame in input.frames {
        let due_after_start = i128::from(frame.stamp_ns) + td_ns > i128::from(start_ns);
        if !due_after_start || frame.corners.len() < MIN_CORNERS {
            skipped += 1;
            continue;
        }
        if measurements.is_empty() {
            // The target frame comes from the first image with a PnP pose.
            let Ok(pnp) = pnp_of(input.camera, frame) else {
                skipped += 1;
                continue;
            };
            let t_cam_target = crate::calibrate::convert::isometry(&pnp.t_cam_target);
            let (sigma_rotation, sigma_position) = camera_imu::target_prior_sigmas(
                &start.prior,
                t_cam_target.translation.vector.norm(),
            );
            measurements.push((
                frame.stamp_ns,
                HostMsg::TargetPose(TargetPose {
                    stamp_ns: frame.stamp_ns,
                    t_cam_target: wire_pose(&t_cam_target),
                    sigma_rotation_rad: sigma_rotation as f32,
                    sigma_position_m: sigma_position as f32,
                }),
            ));
        }
        measurements.extend(corner_sets(frame).into_iter().map(|m| (frame.stamp_ns, m)));
    }
    Ok(ReplayStream::interleaved(
        config,
        input.imu,
        &measurements,
        (options.camera_lead_ns, options.batch),
        skipped,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_estimator::CornerObservation;
    use nalgebra::Vector2;

    fn frame(n: usize) -> CornerFrame {
        CornerFrame {
            stamp_ns: 77,
            corners: (0..n)
                .map(|k| CornerObservation {
                    point_in_target: Vector3::new(k as f64, 0.0, 0.0),
                    pixel: Vector2::new(k as f64, 1.0),
                })
                .collect(),
        }
    }

    #[test]
    fn corner_sets_split_evenly_under_the_bound_and_keep_order() {
        for (n, parts) in [
            (1, vec![1]),
            (42, vec![42]),
            (48, vec![48]),
            (50, vec![25, 25]),
            (144, vec![48, 48, 48]),
            (145, vec![37, 37, 37, 34]),
        ] {
            let sets = corner_sets(&frame(n));
            let mut next = 0usize;
            let mut sizes = Vec::new();
            for msg in &sets {
                let HostMsg::CornerSet(set) = msg else {
                    panic!("not a corner set: {msg:?}");
                };
                assert_eq!(set.stamp_ns, 77);
                sizes.push(set.corners.len());
                for c in set.corners.as_slice() {
                    assert_eq!(c.point_in_target_m[0] as usize, next);
                    next += 1;
                }
            }
            assert_eq!(sizes, parts, "{n} corners");
        }
    }
}
