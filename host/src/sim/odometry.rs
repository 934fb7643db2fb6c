//! The pose sensor S: odometry `T_odom_S` at `rate_hz` built from noisy
//! increments of the true sensor motion, starting at an arbitrary origin.
//!
//! A pose stamped `t_S` is the true `T_G_S = T_G_I(t_S + t_d) * T_imu_pose`.
//! Each true increment `dT = T_G_S(j-1)^-1 T_G_S(j)` is perturbed as
//! `(R Exp(n_theta), p + n_p)` with `n ~ N(0, sigma^2 I3)` and composed onto
//! the previous odometry pose, so odometry drifts like a real LiDAR or visual
//! odometry while its increments keep the stated noise. An increment that
//! spans `m` nominal periods (across a gap) gets noise scaled by `sqrt(m)`.

use nalgebra::{Isometry3, Translation3, UnitQuaternion};
use rand::Rng;

use super::clock::Clock;
use super::config::PoseSimConfig;
use super::extrinsic::random_pose;
use super::imu::gaussian3;
use super::trajectory::Trajectory;
use crate::dataset::{PoseRecord, PoseSensorYaml};

/// Stamps and odometry poses of the pose sensor over `[0, duration_s]` of IMU time.
pub fn synthesize_odometry(
    trajectory: &Trajectory,
    t_imu_pose: &Isometry3<f64>,
    config: &PoseSimConfig,
    clock: Clock,
    duration_s: f64,
    rng: &mut impl Rng,
) -> Vec<PoseRecord> {
    let t_odom_origin = config.odom_origin.unwrap_or_else(|| random_pose(rng));
    let stamps = pose_stamps(config, clock, duration_s, rng);
    let period_s = 1.0 / config.rate_hz;
    let true_pose = |stamp_ns: u64| {
        let t_imu = clock.seconds(stamp_ns) + config.time_offset_s;
        trajectory.isometry(t_imu) * mounting_at(t_imu_pose, config, t_imu)
    };

    let mut records = Vec::with_capacity(stamps.len());
    let mut previous: Option<(u64, Isometry3<f64>, Isometry3<f64>)> = None;
    for stamp_ns in stamps {
        let t_g_s = true_pose(stamp_ns);
        let t_odom_s = match previous {
            None => t_odom_origin,
            Some((previous_ns, previous_t_g_s, previous_t_odom_s)) => {
                let periods = ((clock.seconds(stamp_ns) - clock.seconds(previous_ns)) / period_s)
                    .round()
                    .max(1.0);
                let increment = previous_t_g_s.inverse() * t_g_s;
                renormalized(previous_t_odom_s * perturb(&increment, config, periods.sqrt(), rng))
            }
        };
        records.push(PoseRecord::from_isometry(stamp_ns, &t_odom_s));
        previous = Some((stamp_ns, t_g_s, t_odom_s));
    }
    records
}

/// `T_imu_pose` in force at IMU time `t_imu` (after a knock, the knocked mounting).
pub fn mounting_at(
    t_imu_pose: &Isometry3<f64>,
    config: &PoseSimConfig,
    t_imu: f64,
) -> Isometry3<f64> {
    match config.knock {
        Some(knock) if t_imu >= knock.at_s => t_imu_pose * knock.delta,
        _ => *t_imu_pose,
    }
}

/// The noise description of the simulated pose sensor.
pub fn pose_sensor_yaml(config: &PoseSimConfig) -> PoseSensorYaml {
    PoseSensorYaml {
        rotation_noise_rad: config.rotation_noise_rad,
        translation_noise_m: config.translation_noise_m,
        rate_hz: Some(config.rate_hz),
    }
}

/// Nominal stamps `j / rate_hz` plus jitter, without those in the gap and
/// those whose true time `t_S + t_d` falls outside the IMU record.
fn pose_stamps(
    config: &PoseSimConfig,
    clock: Clock,
    duration_s: f64,
    rng: &mut impl Rng,
) -> Vec<u64> {
    let period_ns = 1e9 / config.rate_hz;
    let last_index = (duration_s * config.rate_hz).ceil() as u64 + 1;
    let mut stamps = Vec::new();
    for j in 0..=last_index {
        let jitter = if config.jitter_fraction > 0.0 {
            rng.gen_range(-config.jitter_fraction..=config.jitter_fraction)
        } else {
            0.0
        };
        let offset_ns = (j as f64 * period_ns + jitter * period_ns).round();
        if offset_ns < 0.0 {
            continue;
        }
        let stamp_ns = clock.stamp(offset_ns as u64);
        let t_s = clock.seconds(stamp_ns);
        let in_gap = config
            .gap_s
            .is_some_and(|(start, end)| (start..=end).contains(&t_s));
        let t_imu = t_s + config.time_offset_s;
        if !in_gap && (0.0..=duration_s).contains(&t_imu) {
            stamps.push(stamp_ns);
        }
    }
    stamps
}

/// The pose with its quaternion renormalised, so rounding does not build up
/// over thousands of compositions.
fn renormalized(pose: Isometry3<f64>) -> Isometry3<f64> {
    Isometry3::from_parts(
        pose.translation,
        UnitQuaternion::new_normalize(pose.rotation.into_inner()),
    )
}

/// `(R Exp(n_theta), p + n_p)` with both noises scaled by `scale`.
fn perturb(
    increment: &Isometry3<f64>,
    config: &PoseSimConfig,
    scale: f64,
    rng: &mut impl Rng,
) -> Isometry3<f64> {
    let n_theta = gaussian3(rng, config.rotation_noise_rad * scale);
    let n_p = gaussian3(rng, config.translation_noise_m * scale);
    Isometry3::from_parts(
        Translation3::from(increment.translation.vector + n_p),
        increment.rotation * UnitQuaternion::from_scaled_axis(n_theta),
    )
}
