//! IMU synthesis from the analytic trajectory.
//!
//! Sample `k`, stamped `t_k`, is what a real IMU reports (EuRoC, Kalibr, OpenVINS): the body
//! rate and specific force at the instant `t_k`, evaluated from the trajectory alone, plus the
//! bias at `t_k` and white noise of standard deviation `density / sqrt(dt)`. Nothing here
//! knows how the estimator integrates; `sim::tests` checks these samples against the
//! trajectory with an independent fine-step integrator.
//! Biases follow a random walk: `b_{k+1} = b_k + N(0, random_walk^2 dt)`.

use nalgebra::Vector3;
use rand::Rng;
use rand_distr::StandardNormal;

use super::clock::Clock;
use super::config::ImuSimConfig;
use super::trajectory::Trajectory;
use crate::dataset::{GroundTruthRecord, ImuNoiseYaml, ImuRecord};

/// The IMU samples and the ground-truth state at each sample stamp.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuSynthesis {
    /// Noisy, biased samples.
    pub records: Vec<ImuRecord>,
    /// Pose, velocity and biases at each sample stamp.
    pub groundtruth: Vec<GroundTruthRecord>,
}

/// Samples `trajectory` from time 0 to `duration_s` (inclusive) at `config.rate_hz`.
pub fn synthesize_imu(
    trajectory: &Trajectory,
    config: &ImuSimConfig,
    clock: Clock,
    duration_s: f64,
    rng: &mut impl Rng,
) -> ImuSynthesis {
    let rate = config.rate_hz;
    let dt = 1.0 / rate;
    let count = (duration_s * rate + 1e-9).floor() as u64 + 1;
    let gyro_white = config.gyroscope_noise_density / dt.sqrt();
    let accel_white = config.accelerometer_noise_density / dt.sqrt();
    let gyro_step = config.gyroscope_random_walk * dt.sqrt();
    let accel_step = config.accelerometer_random_walk * dt.sqrt();

    let mut gyro_bias = gaussian3(rng, config.initial_gyro_bias_sigma);
    let mut accel_bias = gaussian3(rng, config.initial_accel_bias_sigma);
    let mut records = Vec::with_capacity(count as usize);
    let mut groundtruth = Vec::with_capacity(count as usize);
    for k in 0..count {
        let offset_ns = Clock::sample_offset_ns(k, rate);
        let stamp_ns = clock.stamp(offset_ns);
        let t = clock.seconds(stamp_ns);

        let (r_g_i, p_g_i) = trajectory.pose(t);
        groundtruth.push(GroundTruthRecord {
            stamp_ns,
            position: p_g_i,
            rotation: r_g_i,
            velocity: trajectory.velocity(t),
            gyro_bias,
            accel_bias,
        });
        records.push(ImuRecord {
            stamp_ns,
            gyro: trajectory.body_rate(t) + gyro_bias + gaussian3(rng, gyro_white),
            accel: trajectory.specific_force(t) + accel_bias + gaussian3(rng, accel_white),
        });
        gyro_bias += gaussian3(rng, gyro_step);
        accel_bias += gaussian3(rng, accel_step);
    }
    ImuSynthesis {
        records,
        groundtruth,
    }
}

/// The Kalibr noise description of the simulated IMU.
pub fn imu_noise_yaml(config: &ImuSimConfig) -> ImuNoiseYaml {
    ImuNoiseYaml {
        accelerometer_noise_density: config.accelerometer_noise_density,
        accelerometer_random_walk: config.accelerometer_random_walk,
        gyroscope_noise_density: config.gyroscope_noise_density,
        gyroscope_random_walk: config.gyroscope_random_walk,
        update_rate: config.rate_hz,
        rostopic: None,
        sample_timing: None,
    }
}

/// Three independent N(0, sigma^2) draws (always drawn, so the random stream
/// does not depend on which sigmas are zero).
pub(crate) fn gaussian3(rng: &mut impl Rng, sigma: f64) -> Vector3<f64> {
    Vector3::from_fn(|_, _| sigma * rng.sample::<f64, _>(StandardNormal))
}
