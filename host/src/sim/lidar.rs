//! The LiDAR-IMU simulator: a spinning LiDAR (Ouster OS1-like) rigidly mounted on the
//! hand-held IMU of the pose-IMU simulator, ray-cast against a box world.
//!
//! - Motion: the same [`Trajectory`] and IMU synthesis as the pose-IMU simulator (VN-300-class
//!   IMU at 400 Hz). The default trajectory stays within about +-1.9 m of the room centre
//!   horizontally and 0.1-1.9 m above the floor, so the sensor never leaves the free space of
//!   the 10 x 8 x 3 m room ([`Environment::Indoor`]).
//! - LiDAR: `rings` beams spread uniformly over +-22.5 deg elevation, `columns` azimuths per
//!   sweep at `scan_rate_hz`. Column `c` of scan `k` fires at LiDAR time
//!   `stamp_k + c / (columns * rate)` (so scans are motion-distorted: every column is cast
//!   from the sensor pose at its own firing instant), i.e. at IMU time `+ t_d`. Each
//!   return gets Gaussian range noise and an intensity from the surface's reflectivity and
//!   the incidence angle; returns closer than `min_range_m` (the rig itself) or beyond
//!   `max_range_m` are dropped.
//! - Files: `lidar0/<stamp_k>.pcd` (binary, fields `x y z intensity t ring`, `t` the firing
//!   offset from the stamp in ns), `lidar0/lidar.yaml`, `imu0/`, `groundtruth/` with a
//!   `lidar0` section (docs/formats.md).
//! - Scans are generated on demand ([`LidarImuSim::scan`]) and deterministic per seed and
//!   scan index, so a 60 s 128 x 1024 recording (1.7 GB of PCD) never has to sit in memory.

use std::collections::BTreeMap;
use std::f64::consts::{PI, TAU};
use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

use super::box_world::BoxWorld;
use super::clock::Clock;
use super::config::{ImuSimConfig, SimError, DEFAULT_START_STAMP_NS};
use super::imu::imu_noise_yaml;
use super::plate::Plate;
use super::trajectory::{Trajectory, TrajectoryConfig};
use super::write::{create_dirs, write_scan};
use super::{frame_rng, rng_for, simulate_motion, Stream};
use crate::dataset::{
    write_groundtruth_csv, write_imu_csv, CalibrationResult, DatasetError, DatasetYaml,
    ExtrinsicEstimate, GroundTruthRecord, ImuNoiseYaml, ImuRecord, LidarYaml, SectionName,
    DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML, GROUNDTRUTH_TRAJECTORY_CSV, IMU_CSV, IMU_YAML,
    LIDAR_DIR,
};
use crate::lidar::ScanSource;
use crate::pointcloud::{Point, PointCloud};

/// The scene the LiDAR sees.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Environment {
    /// A 10 x 8 x 3 m room with pillars, cabinets, a shelf and a ceiling beam.
    #[default]
    Indoor,
    /// Sparser outdoor-like structure: ground, a few building faces and posts within 40 m,
    /// no ceiling (many rays return nothing).
    Outdoor,
}

impl Environment {
    /// The scene as boxes (`G` frame, z up; the trajectory's base height is 1 m).
    pub fn world(self) -> BoxWorld {
        let b = |min: [f64; 3], max: [f64; 3]| (Vector3::from(min), Vector3::from(max));
        let (floor, ceiling) = (-0.3, 2.7);
        match self {
            Self::Indoor => BoxWorld {
                boxes: vec![
                    b([-5.2, -4.2, floor - 0.2], [5.2, 4.2, floor]),
                    b([-5.2, -4.2, ceiling], [5.2, 4.2, ceiling + 0.2]),
                    b([-5.2, -4.2, floor], [-5.0, 4.2, ceiling]),
                    b([5.0, -4.2, floor], [5.2, 4.2, ceiling]),
                    b([-5.0, -4.2, floor], [5.0, -4.0, ceiling]),
                    b([-5.0, 4.0, floor], [5.0, 4.2, ceiling]),
                    // Pillars.
                    b([2.6, 1.5, floor], [3.0, 1.9, ceiling]),
                    b([-3.4, -2.8, floor], [-3.0, -2.4, ceiling]),
                    b([4.6, 0.0, floor], [5.0, 0.6, ceiling]),
                    // Cabinet, crates, low table block, shelf.
                    b([-4.6, 1.8, floor], [-3.4, 3.2, 0.9]),
                    b([3.0, -3.5, floor], [4.2, -2.5, 0.5]),
                    b([-1.0, 2.6, floor], [0.5, 3.6, 0.45]),
                    b([0.5, -4.0, floor], [2.5, -3.6, 1.8]),
                    // Ceiling beam.
                    b([-5.0, -0.2, 2.4], [5.0, 0.2, ceiling]),
                ],
            },
            Self::Outdoor => BoxWorld {
                boxes: vec![
                    b([-40.0, -40.0, floor - 0.2], [40.0, 40.0, floor]),
                    b([8.0, -15.0, floor], [20.0, 3.0, 9.0]),
                    b([-25.0, 6.0, floor], [-6.0, 14.0, 6.0]),
                    b([-18.0, -22.0, floor], [2.0, -12.0, 12.0]),
                    b([4.0, 7.0, floor], [4.3, 7.3, 4.0]),
                    b([-4.0, -6.0, floor], [-3.7, -5.7, 4.0]),
                    b([6.0, -5.0, floor], [6.3, -4.7, 4.0]),
                    b([-2.0, 5.0, floor], [0.0, 6.0, 1.0]),
                ],
            },
        }
    }

    fn reflectivity(index: usize) -> f32 {
        // A fixed pseudo-random reflectivity per surface, 10-90 (Ouster-like units).
        let h = (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 40;
        10.0 + (h % 81) as f32
    }
}

/// The spinning LiDAR.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarSimConfig {
    /// Beams (128, 64, 32 or 16 for an OS1).
    pub rings: usize,
    /// Firings per sweep (1024 or 512).
    pub columns: usize,
    /// Sweeps per second.
    pub scan_rate_hz: f64,
    /// 1-sigma range noise, m (Ouster-class: 0.02-0.03).
    pub range_noise_m: f64,
    /// Returns closer than this are dropped, m.
    pub min_range_m: f64,
    /// Returns beyond this are dropped, m.
    pub max_range_m: f64,
    /// `t_d` (s): a point stamped `t_L` was taken at IMU time `t_L + t_d`.
    pub time_offset_s: f64,
    /// The scene.
    pub environment: Environment,
}

impl Default for LidarSimConfig {
    fn default() -> Self {
        Self {
            rings: 128,
            columns: 1024,
            scan_rate_hz: 10.0,
            range_noise_m: 0.02,
            min_range_m: 0.5,
            max_range_m: 100.0,
            time_offset_s: 0.0,
            environment: Environment::Indoor,
        }
    }
}

/// Everything [`simulate_lidar_imu`] needs; deterministic per `seed`.
#[derive(Debug, Clone, PartialEq)]
pub struct LidarImuSimConfig {
    /// Seeds every random draw.
    pub seed: u64,
    /// Length of the IMU record, s.
    pub duration_s: f64,
    /// Absolute stamp of the first IMU sample, ns.
    pub start_stamp_ns: u64,
    /// Shape of the motion.
    pub trajectory: TrajectoryConfig,
    /// IMU rate, noise and biases.
    pub imu: ImuSimConfig,
    /// The LiDAR.
    pub lidar: LidarSimConfig,
    /// Ground-truth `T_imu_lidar`; `None` draws a random realistic mounting.
    pub t_imu_lidar: Option<Isometry3<f64>>,
}

impl Default for LidarImuSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            duration_s: 60.0,
            start_stamp_ns: DEFAULT_START_STAMP_NS,
            trajectory: TrajectoryConfig::default(),
            imu: ImuSimConfig::default(),
            lidar: LidarSimConfig::default(),
            t_imu_lidar: None,
        }
    }
}

impl LidarImuSimConfig {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |option: &'static str, message: &str| {
            Err(SimError::InvalidOption {
                option,
                message: message.into(),
            })
        };
        let pose_like = super::SimConfig {
            seed: self.seed,
            duration_s: self.duration_s,
            start_stamp_ns: self.start_stamp_ns,
            trajectory: self.trajectory.clone(),
            imu: self.imu.clone(),
            ..super::SimConfig::default()
        };
        pose_like.validate()?;
        let l = &self.lidar;
        if !(2..=1024).contains(&l.rings) {
            return bad("lidar.rings", "must be in 2..=1024");
        }
        if !(8..=8192).contains(&l.columns) {
            return bad("lidar.columns", "must be in 8..=8192");
        }
        if !(l.scan_rate_hz.is_finite() && l.scan_rate_hz >= 1.0 && l.scan_rate_hz <= 100.0) {
            return bad("lidar.scan_rate_hz", "must be in [1, 100]");
        }
        if !(l.range_noise_m.is_finite() && l.range_noise_m >= 0.0 && l.range_noise_m < 1.0) {
            return bad("lidar.range_noise_m", "must be in [0, 1)");
        }
        if !(l.min_range_m >= 0.0 && l.max_range_m > l.min_range_m && l.max_range_m.is_finite()) {
            return bad(
                "lidar.min_range_m",
                "0 <= min_range_m < max_range_m, finite",
            );
        }
        if !(l.time_offset_s.is_finite() && l.time_offset_s.abs() <= 0.1) {
            return bad("lidar.time_offset_s", "must be finite and within +-0.1 s");
        }
        if self.duration_s < 3.0 / l.scan_rate_hz + 0.3 {
            return bad("duration_s", "too short for three scans");
        }
        Ok(())
    }
}

/// `T_imu_lidar`: yaw uniform, roll and pitch N(0, 5 deg), optionally upside down (half of
/// the seeds); each translation component uniform in [-0.15, 0.15] m (a LiDAR bolted to a
/// hand-held rig next to its IMU).
pub fn random_lidar_mounting(rng: &mut impl Rng) -> Isometry3<f64> {
    let sigma = 5.0_f64.to_radians();
    let flip = if rng.gen_bool(0.5) { PI } else { 0.0 };
    let roll = flip + sigma * rng.sample::<f64, _>(StandardNormal);
    let pitch = sigma * rng.sample::<f64, _>(StandardNormal);
    let yaw = rng.gen_range(-PI..PI);
    let translation = Translation3::new(
        rng.gen_range(-0.15..=0.15),
        rng.gen_range(-0.15..=0.15),
        rng.gen_range(-0.15..=0.15),
    );
    Isometry3::from_parts(
        translation,
        UnitQuaternion::from_euler_angles(roll, pitch, yaw),
    )
}

/// A simulated LiDAR-IMU recording; scans are made on demand.
#[derive(Debug, Clone)]
pub struct LidarImuSim {
    /// The options it was made with.
    pub config: LidarImuSimConfig,
    /// The exact motion of `I` (s after `config.start_stamp_ns`).
    pub trajectory: Trajectory,
    /// `imu0/data.csv`.
    pub imu: Vec<ImuRecord>,
    /// `imu0/imu.yaml`.
    pub imu_noise: ImuNoiseYaml,
    /// `groundtruth/trajectory.csv`.
    pub groundtruth: Vec<GroundTruthRecord>,
    /// True `T_imu_lidar`.
    pub t_imu_lidar: Isometry3<f64>,
    /// First-firing stamp of every scan (LiDAR clock), ns.
    pub scan_stamps: Vec<u64>,
    world: BoxWorld,
    /// Plates in the room besides its boxes (the board of a joint rig).
    plates: Vec<Plate>,
    /// Random stream of the range noise (lidar0's, or its own for every further LiDAR of a
    /// rig: [`super::lidar_rig`]).
    noise_stream: u64,
}

/// Simulates the LiDAR-IMU recording described by `config` (IMU now, scans on demand).
pub fn simulate_lidar_imu(config: &LidarImuSimConfig) -> Result<LidarImuSim, SimError> {
    config.validate()?;
    let (_, trajectory, imu) = simulate_motion(
        config.seed,
        config.start_stamp_ns,
        &config.trajectory,
        &config.imu,
        config.duration_s,
    );
    let t_imu_lidar = config
        .t_imu_lidar
        .unwrap_or_else(|| random_lidar_mounting(&mut rng_for(config.seed, Stream::LidarMounting)));
    let scan_stamps = scan_stamps(config);
    Ok(LidarImuSim {
        config: config.clone(),
        trajectory,
        imu: imu.records,
        imu_noise: imu_noise_yaml(&config.imu),
        groundtruth: imu.groundtruth,
        t_imu_lidar,
        scan_stamps,
        world: config.lidar.environment.world(),
        plates: Vec::new(),
        noise_stream: Stream::LidarNoise as u64,
    })
}

/// First-firing stamp of every scan: the first 0.1 s after the IMU starts, and every firing
/// inside the IMU record.
fn scan_stamps(config: &LidarImuSimConfig) -> Vec<u64> {
    let lidar = &config.lidar;
    let period_ns = (1e9 / lidar.scan_rate_hz).round() as u64;
    let td_ns = (lidar.time_offset_s * 1e9).round() as i64;
    let first = (config.start_stamp_ns as i128 + 100_000_000 - i128::from(td_ns.min(0))) as u64;
    let last_ok = config.start_stamp_ns as i128 + (config.duration_s * 1e9) as i128
        - 20_000_000
        - i128::from(td_ns.max(0));
    (0u64..)
        .map(|k| first + k * period_ns)
        .take_while(|s| (*s + period_ns) as i128 <= last_ok)
        .collect()
}

impl LidarImuSim {
    /// A LiDAR on a motion made elsewhere (the trajectory, IMU record and ground truth of
    /// another simulator, e.g. the camera-IMU one of a joint rig), mounted at `t_imu_lidar`,
    /// seeing the room of `config.lidar.environment` and `plates`. `config.trajectory` and
    /// `config.imu` only describe that motion (they are not drawn again).
    pub fn on_motion(
        config: &LidarImuSimConfig,
        motion: (Trajectory, Vec<ImuRecord>, Vec<GroundTruthRecord>),
        t_imu_lidar: Isometry3<f64>,
        plates: Vec<Plate>,
    ) -> Result<Self, SimError> {
        config.validate()?;
        let (trajectory, imu, groundtruth) = motion;
        Ok(Self {
            config: config.clone(),
            trajectory,
            imu,
            imu_noise: imu_noise_yaml(&config.imu),
            groundtruth,
            t_imu_lidar,
            scan_stamps: scan_stamps(config),
            world: config.lidar.environment.world(),
            plates,
            noise_stream: Stream::LidarNoise as u64,
        })
    }

    /// The same LiDAR drawing its range noise from stream `stream` (a rig's further LiDARs:
    /// [`super::lidar_rig`]).
    pub(crate) fn with_noise_stream(mut self, stream: u64) -> Self {
        self.noise_stream = stream;
        self
    }

    /// First hit of a unit ray from `origin` in G: range, reflectivity and the cosine of
    /// the incidence angle.
    fn first_hit(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<(f64, f32, f32)> {
        let boxes = self
            .world
            .first_hit(origin, dir)
            .map(|(range, index, normal_axis)| {
                let cos_incidence = dir[normal_axis].abs() as f32;
                (range, Environment::reflectivity(index), cos_incidence)
            });
        self.plates
            .iter()
            .filter_map(|p| {
                p.hit(origin, dir)
                    .map(|(range, cos)| (range, p.reflectivity, cos))
            })
            .chain(boxes)
            .min_by(|a, b| a.0.total_cmp(&b.0))
    }

    /// Seconds after the start stamp of an IMU-clock stamp.
    pub fn seconds(&self, stamp_ns: u64) -> f64 {
        Clock {
            start_ns: self.config.start_stamp_ns,
        }
        .seconds(stamp_ns)
    }

    /// The true `T_G_L` at IMU time `t` (s after the start stamp).
    pub fn t_g_l(&self, t: f64) -> Isometry3<f64> {
        self.trajectory.isometry(t) * self.t_imu_lidar
    }

    /// Firing offset of column `c` from the scan stamp, ns.
    pub fn column_offset_ns(&self, column: usize) -> u32 {
        let l = &self.config.lidar;
        (column as f64 * 1e9 / (l.scan_rate_hz * l.columns as f64)).round() as u32
    }

    /// Scan `k`: every column cast from the LiDAR pose at its own firing time.
    pub fn scan(&self, k: usize) -> PointCloud {
        let Some(&stamp) = self.scan_stamps.get(k) else {
            return PointCloud::default();
        };
        let l = &self.config.lidar;
        let base_t = self.seconds(stamp) + l.time_offset_s;
        let elevations: Vec<f64> = (0..l.rings)
            .map(|r| (-22.5 + 45.0 * r as f64 / (l.rings - 1) as f64).to_radians())
            .collect();
        // Ranges in parallel (deterministic), noise afterwards in a fixed order.
        let hits: Vec<Vec<(usize, f64, f32)>> = (0..l.columns)
            .into_par_iter()
            .map(|c| {
                let offset = self.column_offset_ns(c);
                let pose = self.t_g_l(base_t + f64::from(offset) * 1e-9);
                let origin = pose.translation.vector;
                let az = TAU * c as f64 / l.columns as f64;
                let (sa, ca) = az.sin_cos();
                elevations
                    .iter()
                    .enumerate()
                    .filter_map(|(r, el)| {
                        let (se, ce) = el.sin_cos();
                        let dir_l = Vector3::new(ce * ca, ce * sa, se);
                        let dir_g = pose.rotation * dir_l;
                        let (range, reflectivity, cos_incidence) =
                            self.first_hit(&origin, &dir_g)?;
                        let intensity = reflectivity * cos_incidence.max(0.05);
                        Some((r, range, intensity))
                    })
                    .collect()
            })
            .collect();
        let mut rng = frame_rng(self.config.seed, self.noise_stream, k);
        let mut points = Vec::with_capacity(l.columns * l.rings);
        for (c, column) in hits.iter().enumerate() {
            let t_ns = self.column_offset_ns(c);
            let az = TAU * c as f64 / l.columns as f64;
            let (sa, ca) = az.sin_cos();
            for &(r, range, intensity) in column {
                let noisy = range + l.range_noise_m * rng.sample::<f64, _>(StandardNormal);
                if noisy < l.min_range_m || noisy > l.max_range_m {
                    continue;
                }
                let (se, ce) = elevations[r].sin_cos();
                points.push(Point {
                    xyz: Vector3::new(ce * ca, ce * sa, se) * noisy,
                    intensity,
                    t_ns,
                    ring: r as u16,
                });
            }
        }
        PointCloud::new(points)
    }

    /// The true extrinsic in result-file form (sigmas zero).
    pub fn extrinsics(&self) -> CalibrationResult {
        CalibrationResult::new().with_extrinsic(
            SectionName::LIDAR0,
            ExtrinsicEstimate::exact(self.t_imu_lidar, self.config.lidar.time_offset_s),
        )
    }

    /// `lidar0/lidar.yaml`.
    pub fn lidar_yaml(&self) -> LidarYaml {
        let l = &self.config.lidar;
        LidarYaml {
            rings: Some(l.rings as u32),
            columns: Some(l.columns as u32),
            scan_rate_hz: Some(l.scan_rate_hz),
            range_noise_m: Some(l.range_noise_m),
        }
    }

    /// `dataset.yaml` contents.
    pub fn metadata(&self) -> DatasetYaml {
        let c = &self.config;
        DatasetYaml {
            sensors: vec!["imu0".into(), "lidar0".into()],
            description: format!(
                "msreg simulator: LiDAR-IMU, seed {}, {} s, IMU {} Hz, LiDAR {}x{} at {} Hz \
                 ({:?}), range noise {} m, time offset {} s",
                c.seed,
                c.duration_s,
                c.imu.rate_hz,
                c.lidar.rings,
                c.lidar.columns,
                c.lidar.scan_rate_hz,
                c.lidar.environment,
                c.lidar.range_noise_m,
                c.lidar.time_offset_s
            ),
            rates_hz: BTreeMap::from([
                ("imu0".to_string(), c.imu.rate_hz),
                ("lidar0".to_string(), c.lidar.scan_rate_hz),
            ]),
        }
    }

    /// Writes the dataset layout under `dir` (created if needed); `progress` gets the
    /// fraction of scans written.
    pub fn write(
        &self,
        dir: impl AsRef<Path>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        create_dirs(dir, &["imu0", "groundtruth"])?;
        self.metadata().write(dir.join(DATASET_YAML))?;
        write_imu_csv(dir.join(IMU_CSV), &self.imu)?;
        self.imu_noise.write(dir.join(IMU_YAML))?;
        write_groundtruth_csv(dir.join(GROUNDTRUTH_TRAJECTORY_CSV), &self.groundtruth)?;
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))?;
        self.write_lidar(dir, progress)
    }

    /// Writes `lidar0/` (lidar.yaml and every scan) under `dir`; `progress` gets the fraction
    /// of scans written.
    pub fn write_lidar(
        &self,
        dir: &Path,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(), DatasetError> {
        self.write_lidar_folder(dir, LIDAR_DIR, progress)
    }

    /// Writes the folder `folder` (`lidar0`, `lidar1`, ...: lidar.yaml and every scan) under
    /// `dir`; `progress` gets the fraction of scans written.
    pub fn write_lidar_folder(
        &self,
        dir: &Path,
        folder: &str,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(), DatasetError> {
        create_dirs(dir, &[folder])?;
        let yaml = dir.join(folder).join("lidar.yaml");
        self.lidar_yaml().write(yaml)?;
        for (k, stamp) in self.scan_stamps.iter().enumerate() {
            write_scan(
                &dir.join(folder).join(format!("{stamp}.pcd")),
                &self.scan(k),
            )?;
            progress((k + 1) as f64 / self.scan_stamps.len() as f64);
        }
        Ok(())
    }
}

impl ScanSource for LidarImuSim {
    fn len(&self) -> usize {
        self.scan_stamps.len()
    }

    fn stamp_ns(&self, index: usize) -> u64 {
        self.scan_stamps.get(index).copied().unwrap_or(0)
    }

    fn name(&self, index: usize) -> String {
        format!("simulated scan {index}")
    }

    fn load(&self, index: usize) -> Result<PointCloud, crate::lidar::ScanLoadError> {
        Ok(self.scan(index))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> LidarImuSimConfig {
        LidarImuSimConfig {
            seed: 3,
            duration_s: 4.0,
            lidar: LidarSimConfig {
                rings: 16,
                columns: 256,
                ..LidarSimConfig::default()
            },
            ..LidarImuSimConfig::default()
        }
    }

    #[test]
    fn scans_are_deterministic_and_in_the_room() -> Result<(), SimError> {
        let sim = simulate_lidar_imu(&small())?;
        assert!(sim.scan_stamps.len() >= 30);
        let a = sim.scan(5);
        assert_eq!(a, sim.scan(5));
        assert!(a.len() > 16 * 256 * 9 / 10, "{} points", a.len());
        // Every return is inside the room's diagonal.
        assert!(a.points.iter().all(|p| p.xyz.norm() < 14.0));
        assert!(a.points.iter().any(|p| p.t_ns > 90_000_000));
        Ok(())
    }

    #[test]
    fn a_still_sensor_sees_the_room_where_the_truth_says() -> Result<(), SimError> {
        let mut config = small();
        config.lidar.range_noise_m = 0.0;
        config.trajectory.stationary_s = 10.0;
        let sim = simulate_lidar_imu(&config)?;
        let scan = sim.scan(0);
        let pose = sim.t_g_l(sim.seconds(sim.scan_stamps[0]));
        // Points mapped to G lie on a box surface: casting towards them hits at their range.
        for p in scan.points.iter().step_by(97) {
            let g = pose * nalgebra::Point3::from(p.xyz);
            let dir = (g.coords - pose.translation.vector).normalize();
            let hit = sim.world.cast(&pose.translation.vector, &dir);
            assert!(hit.is_some_and(|r| (r - p.xyz.norm()).abs() < 1e-6));
        }
        Ok(())
    }
}
