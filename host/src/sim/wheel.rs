//! A ground vehicle with 2-D wheel odometry (`nav_msgs/Odometry` of a differential or
//! skid-steer base, REP-105's `odom` frame): the vehicle drives the planar figure-eight of
//! [`super::drive`], its base frame `B` (`x` forward along the velocity, `z` up) is the
//! trajectory's frame, and the IMU is mounted on it with a rotation `R_I_B` (no lever arm).
//!
//! - IMU: the base frame's body rate and specific force (exact, from the trajectory) plus
//!   noise and biases ([`super::synthesize_imu`]), rotated into the IMU: `w_I = R_I_B w_B`,
//!   `f_I = R_I_B f_B`.
//! - Wheel odometry, from the trajectory alone: the wheels measure the speed along the
//!   base's forward axis (`v . x_B`, with white noise per odometry period) and a yaw rate
//!   `yaw_rate_scale` times the base's rate about its own `z` (a skid-steer base slips in
//!   turns and reads several times the true turn); both are integrated in the plane at ten
//!   sub-steps per period (`theta += k w dt`, `p += s dt (cos, sin) theta_mid`), so the
//!   odometry is level (`z`, roll and pitch exactly zero) and its heading drifts with the
//!   slip, as a real one does.

use nalgebra::{UnitQuaternion, Vector3};
use rand_distr::{Distribution, StandardNormal};

use super::{imu_noise_yaml, TrajectoryConfig, DEFAULT_START_STAMP_NS};
use super::{rng_for, simulate_motion, DriveConfig, ImuSimConfig, MotionKind, Stream};
use crate::dataset::{ImuNoiseYaml, ImuRecord, PoseRecord};

/// Options of the wheel-odometry drive.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelDriveConfig {
    /// Seed of every random draw.
    pub seed: u64,
    /// Length of the recording, s.
    pub duration_s: f64,
    /// The drive's shape.
    pub drive: DriveConfig,
    /// The IMU.
    pub imu: ImuSimConfig,
    /// The IMU's mounting on the base, `R_I_B` (the truth of `R_I_S`).
    pub r_i_b: UnitQuaternion<f64>,
    /// Odometry rate, Hz.
    pub rate_hz: f64,
    /// White noise of the wheel speed, per odometry period, m/s.
    pub speed_noise_m_s: f64,
    /// Odometry yaw rate / true yaw rate (1: no slip; the Jackal's: about 4).
    pub yaw_rate_scale: f64,
}

impl Default for WheelDriveConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            duration_s: 60.0,
            drive: DriveConfig::default(),
            imu: ImuSimConfig {
                rate_hz: 100.0,
                ..ImuSimConfig::default()
            },
            r_i_b: UnitQuaternion::identity(),
            rate_hz: 50.0,
            speed_noise_m_s: 0.02,
            yaw_rate_scale: 1.0,
        }
    }
}

/// A simulated wheel-odometry drive.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelDriveSim {
    /// IMU samples.
    pub imu: Vec<ImuRecord>,
    /// Their noise figures.
    pub imu_noise: ImuNoiseYaml,
    /// The 2-D wheel odometry of the base.
    pub poses: Vec<PoseRecord>,
    /// The truth `R_I_S` (= `R_I_B`).
    pub r_i_s: UnitQuaternion<f64>,
}

/// Sub-steps of the odometry's planar integration per period.
const SUBSTEPS: usize = 10;

/// Simulates the drive (see the module docs).
pub fn simulate_wheel_drive(config: &WheelDriveConfig) -> WheelDriveSim {
    let trajectory = TrajectoryConfig {
        motion: MotionKind::Drive(config.drive.clone()),
        ..TrajectoryConfig::default()
    };
    let (clock, trajectory, imu) = simulate_motion(
        config.seed,
        DEFAULT_START_STAMP_NS,
        &trajectory,
        &config.imu,
        config.duration_s,
    );
    let imu: Vec<ImuRecord> = imu
        .records
        .iter()
        .map(|r| ImuRecord {
            stamp_ns: r.stamp_ns,
            gyro: config.r_i_b * r.gyro,
            accel: config.r_i_b * r.accel,
        })
        .collect();
    let mut rng = rng_for(config.seed, Stream::WheelOdometry);
    let period = 1.0 / config.rate_hz;
    let dt = period / SUBSTEPS as f64;
    let (mut heading, mut position) = (0.0f64, Vector3::zeros());
    let count = (config.duration_s / period).floor() as u64;
    let mut poses = Vec::with_capacity(count as usize + 1);
    for k in 0..=count {
        let t0 = k as f64 * period;
        poses.push(PoseRecord {
            stamp_ns: clock.stamp((t0 * 1e9).round() as u64),
            position,
            rotation: UnitQuaternion::from_euler_angles(0.0, 0.0, heading),
        });
        let noise: f64 = StandardNormal.sample(&mut rng);
        let speed_noise = config.speed_noise_m_s * noise;
        for j in 0..SUBSTEPS {
            let t = t0 + (j as f64 + 0.5) * dt;
            let (r_g_b, _) = trajectory.pose(t);
            let speed = trajectory.velocity(t).dot(&(r_g_b * Vector3::x())) + speed_noise;
            let turn = config.yaw_rate_scale * trajectory.body_rate(t).z * dt;
            let mid = heading + 0.5 * turn;
            position += speed * dt * Vector3::new(mid.cos(), mid.sin(), 0.0);
            heading += turn;
        }
    }
    WheelDriveSim {
        imu,
        imu_noise: imu_noise_yaml(&config.imu),
        poses,
        r_i_s: config.r_i_b,
    }
}

/// A Jackal-like drive: a small, slow figure-eight (about 1 m/s, 15-20 s loops) with
/// lane-change wiggles, its suspension and bumps as a car's.
pub fn small_robot_drive() -> DriveConfig {
    DriveConfig {
        loop_period_s: (15.0, 20.0),
        long_speed_m_s: 1.0,
        cross_speed_m_s: 0.7,
        wiggle_amplitude_m: 0.1,
        height_m: 0.2,
        ..DriveConfig::default()
    }
}
