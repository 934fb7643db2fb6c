//! A rig of several spinning LiDARs on one IMU: `lidar0` is the LiDAR of
//! [`simulate_lidar_imu`]; every further `lidarN` rides the same motion with its own random
//! mounting (stream `LIDAR_MOUNTING_STREAM + N`), its own time offset (`-4 ms * N` from
//! lidar0's) and its own range-noise draws (stream `LIDAR_NOISE_STREAM + N`). All fire on the
//! same scan stamps of their own clocks and see the same room.
//!
//! Files: `imu0/`, `lidar0/` .. `lidarN-1/`, `groundtruth/` with one `lidarN` section each.

use std::collections::BTreeMap;
use std::path::Path;

use super::config::SimError;
use super::lidar::{random_lidar_mounting, simulate_lidar_imu, LidarImuSim, LidarImuSimConfig};
use super::seeded_rng;
use super::write::create_dirs;
use crate::dataset::{
    write_groundtruth_csv, write_imu_csv, CalibrationResult, DatasetError, DatasetYaml,
    ExtrinsicEstimate, SectionName, SensorId, DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML,
    GROUNDTRUTH_TRAJECTORY_CSV, IMU_CSV, IMU_YAML,
};

/// The most LiDARs a simulated rig carries.
pub const MAX_RIG_LIDARS: usize = 4;
/// Random stream of lidarN's mounting is this + N (N >= 1).
const LIDAR_MOUNTING_STREAM: u64 = 200;
/// Random stream of lidarN's range noise is this + N (N >= 1).
const LIDAR_NOISE_STREAM: u64 = 300;
/// Time offset of lidarN relative to lidar0's, per index, s.
const TIME_OFFSET_STEP_S: f64 = -0.004;

/// A simulated rig of LiDARs on one motion; `lidars[n]` is `lidarN`.
#[derive(Debug, Clone)]
pub struct LidarRigSim {
    /// Every LiDAR, sharing the trajectory, IMU record and ground truth of `lidars[0]`.
    pub lidars: Vec<LidarImuSim>,
}

/// Simulates `count` LiDARs (1 to [`MAX_RIG_LIDARS`]) on the motion of `config`.
pub fn simulate_lidar_rig(
    config: &LidarImuSimConfig,
    count: usize,
) -> Result<LidarRigSim, SimError> {
    if !(1..=MAX_RIG_LIDARS).contains(&count) {
        return Err(SimError::InvalidOption {
            option: "lidars",
            message: format!("must be 1 to {MAX_RIG_LIDARS}"),
        });
    }
    let first = simulate_lidar_imu(config)?;
    let mut lidars = vec![first.clone()];
    for n in 1..count {
        let mut own = config.clone();
        own.lidar.time_offset_s += TIME_OFFSET_STEP_S * n as f64;
        let mut rng = seeded_rng(config.seed, LIDAR_MOUNTING_STREAM + n as u64);
        let motion = (
            first.trajectory.clone(),
            first.imu.clone(),
            first.groundtruth.clone(),
        );
        let lidar = LidarImuSim::on_motion(&own, motion, random_lidar_mounting(&mut rng), vec![])?
            .with_noise_stream(LIDAR_NOISE_STREAM + n as u64);
        lidars.push(lidar);
    }
    Ok(LidarRigSim { lidars })
}

impl LidarRigSim {
    /// Every LiDAR's true extrinsic and time offset (`lidarN` sections, sigmas zero).
    pub fn extrinsics(&self) -> CalibrationResult {
        self.lidars
            .iter()
            .enumerate()
            .fold(CalibrationResult::new(), |result, (n, lidar)| {
                result.with_extrinsic(
                    SectionName::Sensor(SensorId::lidar(n as u16)),
                    ExtrinsicEstimate::exact(lidar.t_imu_lidar, lidar.config.lidar.time_offset_s),
                )
            })
    }

    /// `dataset.yaml`: lidar0's, listing every LiDAR.
    pub fn metadata(&self) -> DatasetYaml {
        let mut metadata = self.lidars[0].metadata();
        metadata.sensors = std::iter::once("imu0".to_string())
            .chain((0..self.lidars.len()).map(|n| format!("lidar{n}")))
            .collect();
        let rate = self.lidars[0].config.lidar.scan_rate_hz;
        metadata.rates_hz =
            std::iter::once(("imu0".to_string(), self.lidars[0].config.imu.rate_hz))
                .chain((0..self.lidars.len()).map(|n| (format!("lidar{n}"), rate)))
                .collect::<BTreeMap<_, _>>();
        metadata.description = format!(
            "{} LiDARs on one IMU (lidarN: own mounting, time offset -4 ms * N from lidar0's); {}",
            self.lidars.len(),
            metadata.description
        );
        metadata
    }

    /// Writes the dataset under `dir` (created if needed); `progress` gets the fraction of
    /// all scans written.
    pub fn write(
        &self,
        dir: impl AsRef<Path>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let first = &self.lidars[0];
        create_dirs(dir, &["imu0", "groundtruth"])?;
        self.metadata().write(dir.join(DATASET_YAML))?;
        write_imu_csv(dir.join(IMU_CSV), &first.imu)?;
        first.imu_noise.write(dir.join(IMU_YAML))?;
        write_groundtruth_csv(dir.join(GROUNDTRUTH_TRAJECTORY_CSV), &first.groundtruth)?;
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))?;
        let count = self.lidars.len() as f64;
        for (n, lidar) in self.lidars.iter().enumerate() {
            lidar.write_lidar_folder(dir, &format!("lidar{n}"), &mut |f| {
                progress((n as f64 + f) / count);
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::LidarSimConfig;

    fn small() -> LidarImuSimConfig {
        LidarImuSimConfig {
            seed: 5,
            duration_s: 2.0,
            lidar: LidarSimConfig {
                rings: 8,
                columns: 64,
                ..LidarSimConfig::default()
            },
            ..LidarImuSimConfig::default()
        }
    }

    #[test]
    fn lidars_share_the_motion_but_not_mounting_offset_or_noise() -> Result<(), SimError> {
        let rig = simulate_lidar_rig(&small(), 3)?;
        let single = simulate_lidar_imu(&small())?;
        let [a, b, c] = &rig.lidars[..] else {
            panic!("three LiDARs");
        };
        // lidar0 is exactly the single-LiDAR simulation.
        assert_eq!(a.scan(3), single.scan(3));
        assert_eq!(a.t_imu_lidar, single.t_imu_lidar);
        for other in [b, c] {
            assert_eq!(other.imu, a.imu);
            // Each fires every 100 ms of its own clock, its first stamp inside the IMU record.
            assert!(other
                .scan_stamps
                .windows(2)
                .all(|w| w[1] - w[0] == 100_000_000));
            assert!(other.scan_stamps.len().abs_diff(a.scan_stamps.len()) <= 1);
            assert!(other.t_imu_lidar.rotation.angle_to(&a.t_imu_lidar.rotation) > 1e-3);
        }
        assert!(b.t_imu_lidar.rotation.angle_to(&c.t_imu_lidar.rotation) > 1e-3);
        let offsets: Vec<f64> = rig
            .lidars
            .iter()
            .map(|l| l.config.lidar.time_offset_s)
            .collect();
        assert!(
            (offsets[1] - offsets[0] + 0.004).abs() < 1e-12,
            "{offsets:?}"
        );
        assert!(
            (offsets[2] - offsets[0] + 0.008).abs() < 1e-12,
            "{offsets:?}"
        );
        // The same LiDAR at the same mounting with another noise stream differs in range only.
        let twin = b.clone().with_noise_stream(6);
        assert_ne!(twin.scan(2), b.scan(2));
        Ok(())
    }

    #[test]
    fn counts_outside_one_to_four_are_refused() {
        assert!(simulate_lidar_rig(&small(), 0).is_err());
        assert!(simulate_lidar_rig(&small(), MAX_RIG_LIDARS + 1).is_err());
    }
}
