//! A rig of several IMUs on one hand-held trajectory (`msreg simulate imu-imu`): `imu0` is the
//! reference, each `imuN` sits at its own mounting `T_imu0_imuN` with its own rate, noise,
//! biases and clock offset. Every IMU is sampled from the trajectory alone
//! ([`Trajectory::remounted`]: rate and specific force of the mounted body, lever-arm terms
//! analytic) by the same [`synthesize_imu`] as the pose-IMU simulator's `imu0`.

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::clock::Clock;
use super::config::{ImuSimConfig, SimError, DEFAULT_START_STAMP_NS};
use super::imu::{gaussian3, imu_noise_yaml, synthesize_imu};
use super::trajectory::{Trajectory, TrajectoryConfig};
use crate::dataset::{
    write_imu_csv, CalibrationResult, DatasetError, DatasetYaml, ExtrinsicEstimate, ImuNoiseYaml,
    ImuRecord, SectionName, SensorId, DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML,
};

/// Options of a simulated IMU rig.
#[derive(Debug, Clone, PartialEq)]
pub struct ImusSimConfig {
    /// Seed of everything random (trajectory, mountings, noise).
    pub seed: u64,
    /// Number of IMUs, `imu0` included (>= 2).
    pub imus: usize,
    /// Length of the recording (s).
    pub duration_s: f64,
    /// The motion.
    pub trajectory: TrajectoryConfig,
    /// `imu0`'s rate and noise; every `imuN` has the same noise at a random rate in
    /// [`Self::rate_range_hz`].
    pub imu: ImuSimConfig,
    /// Rates drawn for `imuN`, N >= 1 (Hz).
    pub rate_range_hz: (f64, f64),
    /// Lever arms drawn for `imuN` (m), in any direction.
    pub lever_range_m: (f64, f64),
    /// Largest |clock offset| drawn for `imuN` (s).
    pub max_timeshift_s: f64,
}

impl Default for ImusSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            imus: 2,
            duration_s: 20.0,
            trajectory: TrajectoryConfig::default(),
            imu: ImuSimConfig {
                rate_hz: 200.0,
                ..ImuSimConfig::default()
            },
            rate_range_hz: (100.0, 400.0),
            lever_range_m: (0.05, 0.30),
            max_timeshift_s: 0.05,
        }
    }
}

impl ImusSimConfig {
    fn validate(&self) -> Result<(), SimError> {
        let invalid = |option: &'static str, requirement: &str| {
            Err(SimError::InvalidOption {
                option,
                message: format!("must be {requirement}"),
            })
        };
        if self.imus < 2 || self.imus > 16 {
            return invalid("imus", "between 2 and 16");
        }
        if !(self.duration_s.is_finite() && self.duration_s > 1.0) {
            return invalid("duration_s", "> 1 s");
        }
        let (lo, hi) = self.rate_range_hz;
        if !(lo.is_finite() && lo > 0.0 && hi >= lo) {
            return invalid("rate_range_hz", "0 < low <= high");
        }
        let (lo, hi) = self.lever_range_m;
        if !(lo.is_finite() && lo >= 0.0 && hi >= lo) {
            return invalid("lever_range_m", "0 <= low <= high");
        }
        if !(self.max_timeshift_s.is_finite() && (0.0..1.0).contains(&self.max_timeshift_s)) {
            return invalid("max_timeshift_s", "in [0, 1) s");
        }
        Ok(())
    }
}

/// One simulated IMU of the rig.
#[derive(Debug, Clone, PartialEq)]
pub struct SimImu {
    /// `imuN/data.csv`, stamped in the IMU's own clock.
    pub records: Vec<ImuRecord>,
    /// `imuN/imu.yaml`.
    pub noise: ImuNoiseYaml,
    /// True `T_imu0_imu` (identity for `imu0`).
    pub t_imu0_imu: Isometry3<f64>,
    /// True `timeshift_imu_imu0` (s): a sample stamped `t` was taken at imu0 time
    /// `t + timeshift_s` (0 for `imu0`).
    pub timeshift_s: f64,
}

/// A simulated IMU rig with its ground truth.
#[derive(Debug, Clone, PartialEq)]
pub struct ImusSim {
    /// The options it was made with.
    pub config: ImusSimConfig,
    /// The motion of `imu0`.
    pub trajectory: Trajectory,
    /// `imu0`, `imu1`, ...
    pub imus: Vec<SimImu>,
}

/// Simulates the rig of `config`.
pub fn simulate_imus(config: &ImusSimConfig) -> Result<ImusSim, SimError> {
    config.validate()?;
    let mut rng = ChaCha8Rng::seed_from_u64(config.seed);
    let trajectory = Trajectory::random(&config.trajectory, &mut rng);
    let mut imus = Vec::with_capacity(config.imus);
    for n in 0..config.imus {
        let (t_imu0_imu, timeshift_s, imu) = if n == 0 {
            (Isometry3::identity(), 0.0, config.imu.clone())
        } else {
            draw_mounting(config, &mut rng)
        };
        // Stamped `t - timeshift` at true (imu0) time `t`: a clock started `timeshift` early.
        let shift_ns = (timeshift_s * 1e9).round() as i64;
        let clock = Clock {
            start_ns: DEFAULT_START_STAMP_NS.saturating_add_signed(-shift_ns),
        };
        let body = trajectory.remounted(&t_imu0_imu);
        let synthesis = synthesize_imu(&body, &imu, clock, config.duration_s, &mut rng);
        imus.push(SimImu {
            records: synthesis.records,
            noise: imu_noise_yaml(&imu),
            t_imu0_imu,
            timeshift_s: shift_ns as f64 * 1e-9,
        });
    }
    Ok(ImusSim {
        config: config.clone(),
        trajectory,
        imus,
    })
}

/// A random mounting, clock offset and rate for `imuN`, N >= 1.
fn draw_mounting(
    config: &ImusSimConfig,
    rng: &mut ChaCha8Rng,
) -> (Isometry3<f64>, f64, ImuSimConfig) {
    let axis_angle = gaussian3(rng, 1.0);
    let rotation = UnitQuaternion::from_scaled_axis(axis_angle);
    let direction = gaussian3(rng, 1.0).normalize();
    let (lo, hi) = config.lever_range_m;
    let lever: Vector3<f64> = direction * rng.gen_range(lo..=hi);
    let max = config.max_timeshift_s;
    let timeshift_s = if max > 0.0 {
        rng.gen_range(-max..max)
    } else {
        0.0
    };
    let (lo, hi) = config.rate_range_hz;
    let imu = ImuSimConfig {
        rate_hz: rng.gen_range(lo..=hi).round(),
        ..config.imu.clone()
    };
    (
        Isometry3::from_parts(Translation3::from(lever), rotation),
        timeshift_s,
        imu,
    )
}

impl ImusSim {
    /// The true calibration in result-file form: an `imuN` section per IMU N >= 1.
    pub fn extrinsics(&self) -> CalibrationResult {
        let mut result = CalibrationResult::new();
        for (n, imu) in self.imus.iter().enumerate().skip(1) {
            result.set_extrinsic(
                SectionName::imu(n as u16),
                ExtrinsicEstimate::exact(imu.t_imu0_imu, imu.timeshift_s),
            );
        }
        result
    }

    /// `dataset.yaml` contents.
    pub fn metadata(&self) -> DatasetYaml {
        let c = &self.config;
        let names = (0..self.imus.len()).map(|n| SensorId::imu(n as u16).to_string());
        DatasetYaml {
            sensors: names.clone().collect(),
            description: format!(
                "msreg simulator: IMU rig, seed {}, {} IMUs, {} s",
                c.seed, c.imus, c.duration_s
            ),
            rates_hz: names
                .zip(&self.imus)
                .map(|(name, imu)| (name, imu.noise.update_rate))
                .collect::<BTreeMap<_, _>>(),
        }
    }

    /// Writes `dataset.yaml`, `imuN/data.csv`, `imuN/imu.yaml` and
    /// `groundtruth/extrinsics.yaml` under `dir`.
    pub fn write(&self, dir: impl AsRef<Path>) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let names: Vec<String> = (0..self.imus.len())
            .map(|n| SensorId::imu(n as u16).to_string())
            .collect();
        let mut subs: Vec<&str> = names.iter().map(String::as_str).collect();
        subs.push("groundtruth");
        super::write::create_dirs(dir, &subs)?;
        self.metadata().write(dir.join(DATASET_YAML))?;
        for (name, imu) in names.iter().zip(&self.imus) {
            write_imu_csv(dir.join(name).join("data.csv"), &imu.records)?;
            imu.noise.write(dir.join(name).join("imu.yaml"))?;
        }
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The second IMU's samples agree with a finite-difference rigid-body model of the
    /// trajectory (central differences of the mounted position, not the lever-arm formula).
    #[test]
    fn second_imu_matches_a_finite_difference_rigid_body() {
        let config = ImusSimConfig {
            imu: ImuSimConfig {
                gyroscope_noise_density: 0.0,
                gyroscope_random_walk: 0.0,
                accelerometer_noise_density: 0.0,
                accelerometer_random_walk: 0.0,
                initial_gyro_bias_sigma: 0.0,
                initial_accel_bias_sigma: 0.0,
                ..ImuSimConfig::default()
            },
            duration_s: 4.0,
            ..ImusSimConfig::default()
        };
        let sim = simulate_imus(&config).expect("valid");
        let imu1 = &sim.imus[1];
        let clock = Clock {
            start_ns: DEFAULT_START_STAMP_NS,
        };
        let h = 1e-4;
        let pos = |t: f64| {
            (sim.trajectory.isometry(t) * imu1.t_imu0_imu)
                .translation
                .vector
        };
        let mut worst = (0.0f64, 0.0f64);
        for r in imu1.records.iter().step_by(37) {
            let t = clock.seconds(r.stamp_ns) + imu1.timeshift_s;
            if !(0.01..3.99).contains(&t) {
                continue;
            }
            let iso = sim.trajectory.isometry(t) * imu1.t_imu0_imu;
            let acc = (pos(t + h) - 2.0 * pos(t) + pos(t - h)) / (h * h);
            let f = iso
                .rotation
                .inverse_transform_vector(&(acc - super::super::trajectory::gravity_in_g()));
            let r_next = (sim.trajectory.isometry(t + h) * imu1.t_imu0_imu).rotation;
            let r_prev = (sim.trajectory.isometry(t - h) * imu1.t_imu0_imu).rotation;
            let w = (r_prev.inverse() * r_next).scaled_axis() / (2.0 * h);
            worst.0 = worst.0.max((r.accel - f).norm());
            worst.1 = worst.1.max((r.gyro - w).norm());
        }
        // Central differences at h = 1e-4 s: truncation ~1e-6, round-off ~1e-8 / h^2 ~ 1e-3 m/s^2.
        assert!(worst.0 < 5e-3, "specific force off by {} m/s^2", worst.0);
        assert!(worst.1 < 1e-5, "rate off by {} rad/s", worst.1);
    }
}
