//! Options of the pose-IMU simulation with the defaults of the accuracy
//! experiments (VN-300-class IMU at 400 Hz, 10 Hz odometry), and their
//! validation so a bad scenario fails with a message instead of producing
//! NaNs or looping.

use nalgebra::Isometry3;

use super::trajectory::{MotionKind, TrajectoryConfig};

/// Default absolute start stamp (ns) (Nov 2023, like real recordings).
pub const DEFAULT_START_STAMP_NS: u64 = 1_700_000_000_000_000_000;

/// A simulation option that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// The named option is out of range.
    #[error("invalid simulation option `{option}`: {message}")]
    InvalidOption {
        /// Option path, e.g. `pose.rate_hz`.
        option: &'static str,
        /// Why.
        message: String,
    },
}

/// Everything [`super::simulate_pose_imu`] needs; deterministic per `seed`.
#[derive(Debug, Clone, PartialEq)]
pub struct SimConfig {
    /// Seeds every random draw (trajectory, extrinsic, noises, origin).
    pub seed: u64,
    /// Length of the IMU record (s).
    pub duration_s: f64,
    /// Absolute stamp of the first IMU sample (ns).
    pub start_stamp_ns: u64,
    /// Shape of the motion.
    pub trajectory: TrajectoryConfig,
    /// IMU rate, noise and biases.
    pub imu: ImuSimConfig,
    /// Pose sensor (odometry) rate, noise, time offset and scenarios.
    pub pose: PoseSimConfig,
    /// Ground-truth `T_imu_pose`; `None` draws a realistic random mounting.
    pub t_imu_pose: Option<Isometry3<f64>>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            duration_s: 60.0,
            start_stamp_ns: DEFAULT_START_STAMP_NS,
            trajectory: TrajectoryConfig::default(),
            imu: ImuSimConfig::default(),
            pose: PoseSimConfig::default(),
            t_imu_pose: None,
        }
    }
}

impl SimConfig {
    /// The same scenario with every noise, initial bias and bias random walk
    /// set to zero (for exactness tests).
    pub fn without_noise(mut self) -> Self {
        self.imu.gyroscope_noise_density = 0.0;
        self.imu.gyroscope_random_walk = 0.0;
        self.imu.accelerometer_noise_density = 0.0;
        self.imu.accelerometer_random_walk = 0.0;
        self.imu.initial_gyro_bias_sigma = 0.0;
        self.imu.initial_accel_bias_sigma = 0.0;
        self.pose.rotation_noise_rad = 0.0;
        self.pose.translation_noise_m = 0.0;
        self
    }

    /// Checks every option's range.
    pub fn validate(&self) -> Result<(), SimError> {
        let duration_ns = self.duration_s * 1e9;
        check(
            "duration_s",
            self.duration_s.is_finite()
                && self.duration_s > 0.0
                && duration_ns < (u64::MAX - self.start_stamp_ns) as f64,
            "must be > 0 and end before u64 nanoseconds overflow",
        )?;
        let t = &self.trajectory;
        check(
            "trajectory.stationary_s",
            non_negative(t.stationary_s),
            ">= 0",
        )?;
        check("trajectory.ramp_s", positive(t.ramp_s), "> 0")?;
        check(
            "trajectory.min_frequency_hz",
            positive(t.min_frequency_hz) && t.min_frequency_hz <= t.max_frequency_hz,
            "> 0 and <= max_frequency_hz",
        )?;
        check(
            "trajectory.max_frequency_hz",
            positive(t.max_frequency_hz),
            "> 0",
        )?;
        for (option, value) in [
            ("trajectory.rate_amplitude_rad_s", t.rate_amplitude_rad_s),
            ("trajectory.speed_amplitude_m_s", t.speed_amplitude_m_s),
            (
                "trajectory.max_roll_amplitude_rad",
                t.max_roll_amplitude_rad,
            ),
            (
                "trajectory.max_pitch_amplitude_rad",
                t.max_pitch_amplitude_rad,
            ),
        ] {
            check(option, non_negative(value), ">= 0")?;
        }
        check(
            "trajectory.max_pitch_amplitude_rad",
            t.max_pitch_amplitude_rad < 1.3,
            "< 1.3 rad (the Euler angles are singular at pitch +-90 deg)",
        )?;
        if let MotionKind::Drive(drive) = &t.motion {
            validate_drive(drive)?;
        }
        self.imu.validate()?;
        self.pose.validate(self.imu.rate_hz, self.duration_s)
    }
}

/// The drive's options (`trajectory.motion: drive`): the pose-IMU scenario selects it with
/// `SimConfig::trajectory.motion` (CLI `msreg simulate pose-imu --motion drive`).
fn validate_drive(d: &super::drive::DriveConfig) -> Result<(), SimError> {
    check(
        "trajectory.motion.drive.loop_period_s",
        positive(d.loop_period_s.0) && d.loop_period_s.0 <= d.loop_period_s.1,
        "> 0 and min <= max",
    )?;
    check(
        "trajectory.motion.drive.long_speed_m_s",
        positive(d.long_speed_m_s) && positive(d.cross_speed_m_s),
        "long and cross speeds > 0 (the vehicle never stops)",
    )?;
    check(
        "trajectory.motion.drive.wiggle_frequency_hz",
        positive(d.wiggle_frequency_hz.0) && d.wiggle_frequency_hz.0 <= d.wiggle_frequency_hz.1,
        "> 0 and min <= max",
    )?;
    check(
        "trajectory.motion.drive.bump_frequency_hz",
        positive(d.bump_frequency_hz.0) && d.bump_frequency_hz.0 <= d.bump_frequency_hz.1,
        "> 0 and min <= max",
    )?;
    for (option, value) in [
        (
            "trajectory.motion.drive.wiggle_amplitude_m",
            d.wiggle_amplitude_m,
        ),
        (
            "trajectory.motion.drive.suspension_rad_per_m_s2",
            d.suspension_rad_per_m_s2,
        ),
        (
            "trajectory.motion.drive.bump_amplitude_rad",
            d.bump_amplitude_rad,
        ),
    ] {
        check(option, non_negative(value), ">= 0")?;
    }
    check(
        "trajectory.motion.drive.height_m",
        d.height_m.is_finite(),
        "finite",
    )
}

/// IMU rate and noise; defaults are a VN-300-class MEMS IMU at 400 Hz.
#[derive(Debug, Clone, PartialEq)]
pub struct ImuSimConfig {
    /// Sample rate (Hz).
    pub rate_hz: f64,
    /// [rad/s/sqrt(Hz)].
    pub gyroscope_noise_density: f64,
    /// [rad/s^2/sqrt(Hz)].
    pub gyroscope_random_walk: f64,
    /// [m/s^2/sqrt(Hz)].
    pub accelerometer_noise_density: f64,
    /// [m/s^3/sqrt(Hz)].
    pub accelerometer_random_walk: f64,
    /// 1-sigma of each initial gyroscope bias component [rad/s].
    pub initial_gyro_bias_sigma: f64,
    /// 1-sigma of each initial accelerometer bias component [m/s^2].
    pub initial_accel_bias_sigma: f64,
}

impl Default for ImuSimConfig {
    fn default() -> Self {
        Self {
            rate_hz: 400.0,
            gyroscope_noise_density: 6.1e-5,
            gyroscope_random_walk: 4.0e-6,
            accelerometer_noise_density: 1.4e-3,
            accelerometer_random_walk: 8.0e-5,
            initial_gyro_bias_sigma: 1e-3,
            initial_accel_bias_sigma: 0.02,
        }
    }
}

impl ImuSimConfig {
    fn validate(&self) -> Result<(), SimError> {
        check("imu.rate_hz", positive(self.rate_hz), "> 0")?;
        for (option, value) in [
            ("imu.gyroscope_noise_density", self.gyroscope_noise_density),
            ("imu.gyroscope_random_walk", self.gyroscope_random_walk),
            (
                "imu.accelerometer_noise_density",
                self.accelerometer_noise_density,
            ),
            (
                "imu.accelerometer_random_walk",
                self.accelerometer_random_walk,
            ),
            ("imu.initial_gyro_bias_sigma", self.initial_gyro_bias_sigma),
            (
                "imu.initial_accel_bias_sigma",
                self.initial_accel_bias_sigma,
            ),
        ] {
            check(option, non_negative(value), ">= 0")?;
        }
        Ok(())
    }
}

/// The pose sensor (odometry of a LiDAR or camera) and its robustness scenarios.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseSimConfig {
    /// Nominal rate (Hz) (5-50 Hz in the experiments).
    pub rate_hz: f64,
    /// 1-sigma rotation noise per axis of one increment (rad).
    pub rotation_noise_rad: f64,
    /// 1-sigma translation noise per axis of one increment (m).
    pub translation_noise_m: f64,
    /// `t_d` (s): a pose stamped `t_S` was taken at IMU time `t_S + t_d`.
    pub time_offset_s: f64,
    /// Stamp jitter, uniform in +-`jitter_fraction` of the period (0.2 for
    /// the irregular-rate scenario); must be < 0.5 to keep stamps ordered.
    pub jitter_fraction: f64,
    /// No poses stamped within `[start, end]` [s after the start stamp].
    pub gap_s: Option<(f64, f64)>,
    /// `T_odom_S` of the first pose; `None` draws a random pose, so
    /// consumers cannot rely on the odometry frame matching `G`.
    pub odom_origin: Option<Isometry3<f64>>,
    /// A knock: from IMU time `at_s` on, the sensor is mounted at `T_imu_pose * delta`
    /// (the health monitor's step detection is tested with it).
    pub knock: Option<Knock>,
}

/// A sudden change of the sensor's mounting during the recording.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Knock {
    /// IMU time of the knock, s after the start stamp.
    pub at_s: f64,
    /// `T_old_new`: the new mounting relative to the old, in the sensor frame.
    pub delta: Isometry3<f64>,
}

impl Default for PoseSimConfig {
    fn default() -> Self {
        Self {
            rate_hz: 10.0,
            rotation_noise_rad: 0.2_f64.to_radians(),
            translation_noise_m: 0.005,
            time_offset_s: 0.0,
            jitter_fraction: 0.0,
            gap_s: None,
            odom_origin: None,
            knock: None,
        }
    }
}

impl PoseSimConfig {
    fn validate(&self, imu_rate_hz: f64, duration_s: f64) -> Result<(), SimError> {
        check(
            "pose.rate_hz",
            positive(self.rate_hz) && self.rate_hz <= imu_rate_hz,
            "> 0 and <= imu.rate_hz",
        )?;
        check(
            "pose.rotation_noise_rad",
            non_negative(self.rotation_noise_rad),
            ">= 0",
        )?;
        check(
            "pose.translation_noise_m",
            non_negative(self.translation_noise_m),
            ">= 0",
        )?;
        check(
            "pose.time_offset_s",
            self.time_offset_s.is_finite() && self.time_offset_s.abs() < 0.5 * duration_s,
            "finite and shorter than half the duration",
        )?;
        check(
            "pose.jitter_fraction",
            non_negative(self.jitter_fraction) && self.jitter_fraction < 0.5,
            "in [0, 0.5)",
        )?;
        if let Some((start, end)) = self.gap_s {
            check(
                "pose.gap_s",
                start.is_finite() && end.is_finite() && start < end,
                "start < end, both finite",
            )?;
        }
        Ok(())
    }
}

fn positive(x: f64) -> bool {
    x.is_finite() && x > 0.0
}

fn non_negative(x: f64) -> bool {
    x.is_finite() && x >= 0.0
}

fn check(option: &'static str, ok: bool, requirement: &str) -> Result<(), SimError> {
    if ok {
        Ok(())
    } else {
        Err(SimError::InvalidOption {
            option,
            message: format!("must be {requirement}"),
        })
    }
}
