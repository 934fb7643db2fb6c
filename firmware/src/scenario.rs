//! The embedded sensor sequence: a 400 Hz IMU and a 10 Hz pose sensor (LiDAR or visual
//! odometry) on the [`Trajectory`], generated on the fly in `f32`, with deterministic noise
//! at the datasheet levels the filter is told about.
//!
//! The sequence is an iterator of [`Event`]s in time order; at a stamp shared by an IMU
//! sample and a pose, the IMU sample comes first, so the filter has propagated to the
//! pose's stamp when it sees the pose.

use libm::sqrtf;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::noise::Noise;
use crate::trajectory::Trajectory;

/// Noise levels of the simulated sensors (continuous-time densities for the IMU, per
/// increment for the pose sensor), shared by the generator and the filter configuration.
#[derive(Clone, Copy, Debug)]
pub struct SensorSpec {
    /// Gyroscope white noise density, rad/s/sqrt(Hz).
    pub gyro_noise_density: f32,
    /// Accelerometer white noise density, m/s^2/sqrt(Hz).
    pub accel_noise_density: f32,
    /// Gyroscope bias random walk, rad/s^2/sqrt(Hz) (the filter's model; the generator
    /// keeps the true bias at zero).
    pub gyro_random_walk: f32,
    /// Accelerometer bias random walk, m/s^3/sqrt(Hz) (as above).
    pub accel_random_walk: f32,
    /// 1-sigma rotation noise of one pose increment, rad.
    pub rotation_sigma: f32,
    /// 1-sigma translation noise of one pose increment, m.
    pub translation_sigma: f32,
}

impl SensorSpec {
    /// An ADIS16448-class IMU (EuRoC's `imu.yaml`) and a LiDAR odometry of 0.1 deg / 5 mm.
    pub const MEMS_LIDAR: Self = Self {
        gyro_noise_density: 1.6968e-4,
        accel_noise_density: 2.0e-3,
        gyro_random_walk: 1.9393e-5,
        accel_random_walk: 3.0e-3,
        rotation_sigma: 1.745e-3,
        translation_sigma: 5.0e-3,
    };
}

/// Everything that defines one run of the sequence.
#[derive(Clone, Copy, Debug)]
pub struct ScenarioConfig {
    /// Stamp of the first IMU sample, ns.
    pub start_ns: u64,
    /// Length of the run, ns.
    pub duration_ns: u64,
    /// IMU sample period, ns.
    pub imu_period_ns: u64,
    /// Pose sensor period, ns (a multiple of `imu_period_ns`).
    pub pose_period_ns: u64,
    /// Noise levels.
    pub spec: SensorSpec,
    /// Ground truth `T_i_s`: pose of the pose sensor S in the IMU frame.
    pub t_i_s: Isometry3<f32>,
    /// Seed of the noise source; 0 still gives a fixed sequence.
    pub seed: u32,
    /// Scale of all noise (1 = datasheet levels, 0 = exact readings).
    pub noise_scale: f32,
}

impl ScenarioConfig {
    /// 3 s at 400 Hz IMU / 10 Hz poses, a LiDAR mounted 90 deg yawed and offset by
    /// (0.10, -0.05, 0.20) m.
    pub fn default_run() -> Self {
        Self {
            start_ns: 1_000_000_000,
            duration_ns: 3_000_000_000,
            imu_period_ns: 2_500_000,
            pose_period_ns: 100_000_000,
            spec: SensorSpec::MEMS_LIDAR,
            t_i_s: truth_t_i_s(),
            seed: 0x5EED_0001,
            noise_scale: 1.0,
        }
    }

    /// Number of IMU samples in the run (both ends included).
    pub fn imu_count(&self) -> u64 {
        self.duration_ns / self.imu_period_ns + 1
    }

    /// Number of poses in the run (both ends included): one anchor plus increments.
    pub fn pose_count(&self) -> u64 {
        self.duration_ns / self.pose_period_ns + 1
    }
}

/// The true extrinsic of the default run.
pub fn truth_t_i_s() -> Isometry3<f32> {
    Isometry3::from_parts(
        Translation3::new(0.10, -0.05, 0.20),
        UnitQuaternion::from_euler_angles(0.02, -0.03, core::f32::consts::FRAC_PI_2),
    )
}

/// One IMU sample.
#[derive(Clone, Copy, Debug)]
pub struct ImuReading {
    /// Stamp, ns.
    pub stamp_ns: u64,
    /// Angular rate in the IMU frame, rad/s.
    pub gyro: Vector3<f32>,
    /// Specific force in the IMU frame, m/s^2.
    pub accel: Vector3<f32>,
}

/// One odometry increment of the pose sensor: `T_s_from_s_to`.
#[derive(Clone, Copy, Debug)]
pub struct PoseIncrement {
    /// Stamp of the earlier pose, ns.
    pub stamp_from_ns: u64,
    /// Stamp of the later pose, ns.
    pub stamp_to_ns: u64,
    /// Pose of S at `stamp_to_ns` in S at `stamp_from_ns`.
    pub delta: Isometry3<f32>,
}

/// One item of the sequence.
#[derive(Clone, Copy, Debug)]
pub enum Event {
    /// An IMU sample.
    Imu(ImuReading),
    /// The first pose of the odometry: it only fixes where increments start.
    Anchor {
        /// Stamp of the first pose, ns.
        stamp_ns: u64,
    },
    /// An odometry increment from the previous pose to this one.
    Increment(PoseIncrement),
}

/// The sequence as an iterator of [`Event`]s.
#[derive(Clone, Debug)]
pub struct Scenario {
    config: ScenarioConfig,
    trajectory: Trajectory,
    noise: Noise,
    next_imu: u64,
    next_pose: u64,
}

impl Scenario {
    /// The sequence of `config` on the hand-held trajectory.
    pub fn new(config: ScenarioConfig) -> Self {
        Self {
            config,
            trajectory: Trajectory::handheld(),
            noise: Noise::new(config.seed),
            next_imu: 0,
            next_pose: 0,
        }
    }

    /// The configuration this sequence was made from.
    pub fn config(&self) -> &ScenarioConfig {
        &self.config
    }

    /// The motion the sequence samples.
    pub fn trajectory(&self) -> &Trajectory {
        &self.trajectory
    }

    fn seconds(&self, stamp_ns: u64) -> f32 {
        (stamp_ns - self.config.start_ns) as f32 * 1e-9
    }

    fn imu(&mut self, stamp_ns: u64) -> ImuReading {
        let c = &self.config;
        let rate_sqrt = sqrtf(1e9 / c.imu_period_ns as f32);
        let gyro_sigma = c.noise_scale * c.spec.gyro_noise_density * rate_sqrt;
        let accel_sigma = c.noise_scale * c.spec.accel_noise_density * rate_sqrt;
        let k = self.trajectory.kinematics(self.seconds(stamp_ns));
        ImuReading {
            stamp_ns,
            gyro: k.omega_in_imu + self.noise.vector3(gyro_sigma),
            accel: k.specific_force_in_imu + self.noise.vector3(accel_sigma),
        }
    }

    fn increment(&mut self, stamp_to_ns: u64) -> PoseIncrement {
        let stamp_from_ns = stamp_to_ns - self.config.pose_period_ns;
        let exact = self.trajectory.sensor_increment(
            &self.config.t_i_s,
            self.seconds(stamp_from_ns),
            self.seconds(stamp_to_ns),
        );
        let c = self.config;
        let d_rot = self.noise.vector3(c.noise_scale * c.spec.rotation_sigma);
        let d_trans = self.noise.vector3(c.noise_scale * c.spec.translation_sigma);
        let noisy = Isometry3::from_parts(
            Translation3::from(exact.translation.vector + d_trans),
            exact.rotation * UnitQuaternion::from_scaled_axis(d_rot),
        );
        PoseIncrement {
            stamp_from_ns,
            stamp_to_ns,
            delta: noisy,
        }
    }
}

impl Iterator for Scenario {
    type Item = Event;

    fn next(&mut self) -> Option<Event> {
        let c = self.config;
        let imu_ns = c.start_ns + self.next_imu * c.imu_period_ns;
        let pose_ns = c.start_ns + self.next_pose * c.pose_period_ns;
        let imu_left = self.next_imu < c.imu_count();
        let pose_left = self.next_pose < c.pose_count();
        if imu_left && (!pose_left || imu_ns <= pose_ns) {
            self.next_imu += 1;
            return Some(Event::Imu(self.imu(imu_ns)));
        }
        if !pose_left {
            return None;
        }
        self.next_pose += 1;
        if self.next_pose == 1 {
            Some(Event::Anchor { stamp_ns: pose_ns })
        } else {
            Some(Event::Increment(self.increment(pose_ns)))
        }
    }
}
