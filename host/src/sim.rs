//! The pose-IMU simulator behind every accuracy claim: an IMU and a pose
//! sensor (odometry) rigidly mounted with a known `T_imu_pose` and time
//! offset, moved along a smooth trajectory with exact analytic derivatives.
//!
//! - Motion ([`Trajectory`]): position and ZYX Euler angles are sums of random
//!   sinusoids (0.2-1.2 Hz) faded in after a still period by a C2 smooth
//!   step; body rate and specific force are exact, not differenced.
//! - IMU ([`ImuSimConfig`]): sample `k` stamped `t_k` is the truth at the instant `t_k`
//!   (body rate and specific force from the trajectory alone), as real IMUs and EuRoC /
//!   Kalibr / OpenVINS data are; an independent RK4 integrator checks that these samples
//!   reproduce the trajectory (`sim::tests`). White noise `density / sqrt(dt)`, bias
//!   random walk.
//! - Pose sensor ([`PoseSimConfig`]): `T_G_S(t_S) = T_G_I(t_S + t_d) T_imu_pose`,
//!   reported as odometry from noisy increments composed from an arbitrary
//!   origin; irregular rate, gaps and any rate are options.
//! - Time: stamps are `u64` ns from `start_stamp_ns`; the math uses `f64`
//!   seconds after the start, converted after the integer subtraction.
//! - Randomness: ChaCha8 seeded with `seed`, one stream per component
//!   (trajectory, mounting, IMU, odometry), so changing e.g. the odometry
//!   options leaves the trajectory and the IMU data unchanged; per-frame draws
//!   (a scan's range noise, an image's noise) start at their own block of the
//!   stream (`frame_rng`). Every simulator draws through `seeded_rng`.
//!
//! The other scenarios: [`camera`] (camera-IMU), [`lidar`] (LiDAR-IMU in a [`BoxWorld`]),
//! [`joint`], [`drive`] / [`drive_sim`] (on-vehicle monitoring), [`lidar_camera`] (a static
//! LiDAR-camera suite and a plain board, chapter 2) and [`prior_map`] (chapter 7); the
//! dataset writers share [`mod@write`].

mod box_world;
pub mod camera;
pub mod cameras;
mod clock;
mod config;
pub mod drive;
pub mod drive_sim;
#[cfg(test)]
mod drive_tests;
mod extrinsic;
mod imu;
pub mod imus;
pub mod joint;
pub mod lidar;
pub mod lidar_camera;
pub mod lidar_rig;
mod odometry;
mod output;
mod plate;
pub mod prior_map;
pub mod prior_map_scene;
mod signal;
mod trajectory;
pub mod wheel;
pub mod write;

#[cfg(test)]
mod tests;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

pub use box_world::BoxWorld;
pub use camera::{simulate_camera_imu, CameraImuSim, CameraImuSimConfig, CameraModelChoice};
pub use clock::Clock;
pub use config::{ImuSimConfig, Knock, PoseSimConfig, SimConfig, SimError, DEFAULT_START_STAMP_NS};
pub use drive::DriveConfig;
pub use drive_sim::{simulate_drive, DriveSim, DriveSimConfig, KnockTarget};
pub use extrinsic::{random_mounting, random_pose};
pub use imu::{imu_noise_yaml, synthesize_imu, ImuSynthesis};
pub use imus::{simulate_imus, ImusSim, ImusSimConfig, SimImu};
pub use joint::{simulate_joint, JointSim, JointSimConfig};
pub use lidar::{simulate_lidar_imu, Environment, LidarImuSim, LidarImuSimConfig, LidarSimConfig};
pub use lidar_camera::{
    simulate_lidar_camera, FrameKind, LidarCameraSim, LidarCameraSimConfig, LidarModel, SimFrame,
};
pub use lidar_rig::{simulate_lidar_rig, LidarRigSim, MAX_RIG_LIDARS};
pub use odometry::{pose_sensor_yaml, synthesize_odometry};
pub use output::SimDataset;
pub use plate::Plate;
pub use signal::{EnvelopedSignal, Jet, Sinusoid, SmoothStep};
pub use trajectory::{
    gravity_in_g, LookAtConfig, MotionKind, Mount, Trajectory, TrajectoryConfig, GRAVITY,
};

/// Random stream of each component (see the module docs).
#[derive(Clone, Copy)]
enum Stream {
    Trajectory = 1,
    Mounting = 2,
    Imu = 3,
    Odometry = 4,
    LidarMounting = 5,
    LidarNoise = 6,
    CameraMounting = 7,
    CameraScene = 8,
    CameraNoise = 9,
    JointLidarMounting = 10,
    DriveMounting = 11,
    DriveOdometry0 = 12,
    DriveOdometry1 = 13,
    WheelOdometry = 14,
}

fn rng_for(seed: u64, stream: Stream) -> ChaCha8Rng {
    seeded_rng(seed, stream as u64)
}

/// ChaCha8 seeded with `seed`, on its stream `stream`: the random source of every simulator
/// (each numbers its own streams: `Stream` here, its own enum in [`lidar_camera`], 100 and
/// up in [`prior_map`], 200 and 300 up in [`lidar_rig`]).
pub(crate) fn seeded_rng(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// `seeded_rng` positioned at the block of frame `frame` (word `frame << 40`), so that each
/// scan's or image's draws do not depend on how many the others took.
pub(crate) fn frame_rng(seed: u64, stream: u64, frame: usize) -> ChaCha8Rng {
    let mut rng = seeded_rng(seed, stream);
    rng.set_word_pos((frame as u128) << 40);
    rng
}

/// The motion every scenario shares: the clock, the seeded trajectory and the IMU along it.
fn simulate_motion(
    seed: u64,
    start_stamp_ns: u64,
    trajectory: &TrajectoryConfig,
    imu: &ImuSimConfig,
    duration_s: f64,
) -> (Clock, Trajectory, ImuSynthesis) {
    let clock = Clock {
        start_ns: start_stamp_ns,
    };
    let trajectory = Trajectory::random(trajectory, &mut rng_for(seed, Stream::Trajectory));
    let imu = synthesize_imu(
        &trajectory,
        imu,
        clock,
        duration_s,
        &mut rng_for(seed, Stream::Imu),
    );
    (clock, trajectory, imu)
}

/// Simulates the pose-IMU dataset described by `config`.
pub fn simulate_pose_imu(config: &SimConfig) -> Result<SimDataset, SimError> {
    config.validate()?;
    let (clock, trajectory, imu) = simulate_motion(
        config.seed,
        config.start_stamp_ns,
        &config.trajectory,
        &config.imu,
        config.duration_s,
    );
    let t_imu_pose = config
        .t_imu_pose
        .unwrap_or_else(|| random_mounting(&mut rng_for(config.seed, Stream::Mounting)));
    let pose = synthesize_odometry(
        &trajectory,
        &t_imu_pose,
        &config.pose,
        clock,
        config.duration_s,
        &mut rng_for(config.seed, Stream::Odometry),
    );
    Ok(SimDataset {
        config: config.clone(),
        trajectory,
        imu: imu.records,
        imu_noise: imu_noise_yaml(&config.imu),
        pose,
        pose_sensor: pose_sensor_yaml(&config.pose),
        groundtruth: imu.groundtruth,
        t_imu_pose,
        time_offset_s: config.pose.time_offset_s,
    })
}
