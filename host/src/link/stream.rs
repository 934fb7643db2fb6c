//! A dataset as the message sequence the firmware needs: a [`Config`] with the same
//! initialisation as `calibrate::pose_imu` (standstill gravity and gyro bias, hand-eye
//! rotation, the same priors), then IMU batches with the odometry interleaved.
//!
//! Pose sequencing mirrors the host pipeline: the first pose due at or before the first IMU
//! sample is skipped; a pose after a gap longer than ten nominal periods (or the first one)
//! becomes an [`Anchor`]; every other pose becomes the increment from the previous one, with
//! sigmas scaled by the square root of the periods it spans. A pose message is sent
//! [`StreamOptions::pose_lead_ns`] ahead of the IMU samples around its stamp; the firmware
//! holds it until the IMU stream reaches `stamp + t_d`.

use msreg_estimator::Scalar;
use msreg_protocol::{
    Anchor, Bounded, Config, Gate, HostMsg, ImuBatch, ImuNoise, ImuPrior, ImuSample, Pose,
    RelativePose, SensorSet, IMU_BATCH_MAX,
};
use nalgebra::{Isometry3, Vector3};

use super::LinkError;
use crate::calibrate::init;
use crate::calibrate::pose_imu::{PoseImuInput, PoseImuOptions};

/// Options of the stream.
#[derive(Debug, Clone, Copy)]
pub struct StreamOptions {
    /// IMU samples per batch (1..=16).
    pub batch: usize,
    /// Send a pose this long before the IMU samples at its stamp, ns (covers `|t_d|`).
    pub pose_lead_ns: u64,
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
    /// Poses skipped (before the first IMU sample).
    pub skipped_poses: usize,
}

fn f32x3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

fn wire_pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    Pose {
        rotation_wxyz: [q.w as f32, q.i as f32, q.j as f32, q.k as f32],
        translation_m: f32x3(&iso.translation.vector),
    }
}

/// Median spacing of the odometry, ns (as the pipeline).
fn nominal_period_ns(input: &PoseImuInput<'_>) -> u64 {
    let mut d: Vec<u64> = input
        .poses
        .windows(2)
        .map(|w| w[1].stamp_ns.saturating_sub(w[0].stamp_ns))
        .collect();
    d.sort_unstable();
    d.get(d.len() / 2).copied().unwrap_or(100_000_000)
}

/// The configuration the pipeline would start from.
pub fn config(input: &PoseImuInput<'_>, options: &StreamOptions) -> Result<Config, LinkError> {
    let imu = input.imu;
    if imu.is_empty() || input.poses.len() < 3 {
        return Err(LinkError::Dataset(
            "the dataset needs IMU samples and at least 3 poses".into(),
        ));
    }
    let p = &options.pipeline;
    let standstill = init::detect_standstill(imu, p.min_standstill_s);
    let gyro_bias = standstill.map_or_else(Vector3::zeros, |s| s.gyro_mean);
    let period_ns = nominal_period_ns(input);
    let rotation = init::hand_eye_rotation(imu, input.poses, &gyro_bias, period_ns * 3 / 2)
        .map_err(|e| {
            LinkError::Dataset(format!(
                "hand-eye rotation initialisation failed ({e:?}): the recording needs rotation \
                 about at least two axes"
            ))
        })?;
    let accel_mean = standstill.map_or_else(
        || {
            let n = imu.len().min(400);
            imu[..n].iter().map(|r| r.accel).sum::<Vector3<f64>>() / n as f64
        },
        |s| s.accel_mean,
    );
    let (sigma_orientation_rad, sigma_velocity_m_s) = if standstill.is_some() {
        (0.0, 0.0)
    } else {
        (0.1, 1.0)
    };
    let noise = crate::calibrate::convert::imu_noise::<f32>(input.imu_noise);
    Ok(Config {
        sensors: SensorSet::PoseImu,
        imu_noise: ImuNoise {
            gyro_noise_density: noise.gyro_noise_density.to_f64() as f32,
            accel_noise_density: noise.accel_noise_density.to_f64() as f32,
            gyro_random_walk: noise.gyro_random_walk.to_f64() as f32,
            accel_random_walk: noise.accel_random_walk.to_f64() as f32,
        },
        gate: Gate::P999,
        max_imu_gap_ns: 50_000_000,
        imu_prior: ImuPrior {
            accel_mean: f32x3(&accel_mean),
            gyro_bias: f32x3(&gyro_bias),
            sigma_orientation_rad,
            sigma_velocity_m_s,
        },
        extrinsic: wire_pose(&Isometry3::from_parts(
            Default::default(),
            rotation.rotation,
        )),
        sigma_rotation_rad: p.rotation_sigma_rad as f32,
        sigma_translation_m: p.translation_sigma_m as f32,
        time_offset_s: 0.0,
        sigma_time_offset_s: if p.estimate_time_offset {
            p.time_offset_sigma_s as f32
        } else {
            0.0
        },
        zero_velocity_until_ns: standstill.map_or(0, |s| s.until_ns),
        zero_velocity_every: 20,
        estimate_period_ns: options.estimate_period_ns,
    })
}

/// The whole replay of a dataset.
pub fn build_stream(
    input: &PoseImuInput<'_>,
    options: &StreamOptions,
) -> Result<ReplayStream, LinkError> {
    let config = config(input, options)?;
    let batch_len = options.batch.clamp(1, IMU_BATCH_MAX);
    let period_ns = nominal_period_ns(input);
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
    let mut poses = input.poses[first..].iter().peekable();
    let mut previous: Option<&crate::dataset::PoseRecord> = None;
    let mut messages = Vec::with_capacity(input.imu.len() / batch_len + input.poses.len() + 1);
    let mut batch: Option<ImuBatch> = None;
    for rec in input.imu {
        while let Some(pose) = poses.next_if(|p| p.stamp_ns <= rec.stamp_ns + options.pose_lead_ns)
        {
            let msg = match previous.filter(|p| pose.stamp_ns - p.stamp_ns <= max_interval_ns) {
                None => HostMsg::Anchor(Anchor {
                    stamp_ns: pose.stamp_ns,
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
                    })
                }
            };
            previous = Some(pose);
            messages.push((pose.stamp_ns, msg));
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
    if let (Some(b), Some(last)) = (batch.take(), input.imu.last()) {
        messages.push((last.stamp_ns, HostMsg::ImuBatch(b)));
    }
    Ok(ReplayStream {
        config,
        messages,
        start_ns,
        skipped_poses: first,
    })
}
