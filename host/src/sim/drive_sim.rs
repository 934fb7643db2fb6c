//! `msreg simulate drive`: the on-vehicle monitoring scenario (issue 13, item 4). A car drives
//! the planar figure-eight of [`super::drive`] (turns, suspension roll and pitch) with three
//! sensors:
//! - `imu0`: the IMU at the rear axle (x forward, y left, z up);
//! - `pose0`: LiDAR odometry (NDT scan-to-scan relative poses) at 10 Hz, its own mounting
//!   ([`super::random_mounting`]) and time offset;
//! - `pose1`: the visual odometry of a forward-looking camera at 20 Hz (optical axis along
//!   the vehicle's x), its own mounting and time offset. VO is modelled **metric** (a stereo
//!   camera or a VIO front end); a monocular VO, known only up to scale, would need a scale
//!   state this filter does not have.
//!
//! That is the default of two pose sensors; [`DriveSimConfig::pose_sensors`] takes any number
//! from one (`pose0` alone, drawn exactly as in the two-sensor drive of the same seed) up:
//! `pose2`, `pose3`, ... are further LiDAR odometries ([`DriveSimConfig::extra`]), each with
//! its own mounting ([`super::random_mounting`]), time offset and noise, drawn from random
//! streams of their own ([`EXTRA_SENSOR_STREAMS`]), so adding a sensor leaves the others'
//! data unchanged.
//!
//! Any sensor can be knocked (a 1 deg rotation of its mounting, by default the camera's,
//! partway through). Every odometry comes from [`super::synthesize_odometry`]: each increment
//! of the true sensor motion (the trajectory and the sensor's own mounting) perturbed by the
//! noise its `sensor.yaml` states.
//!
//! The vehicle also carries its calibration of record: `calibration.yaml` in the dataset, the
//! true mountings and time offsets before any knock, each perturbed by the sigmas it states
//! (an end-of-line target calibration: [`DriveSimConfig::prior_sigma_rot_deg`] etc.). The
//! ground truth (`groundtruth/extrinsics.yaml`: the mountings at the end; `knock.yaml`:
//! before, after and when) is for judging only.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

use super::config::{ImuSimConfig, Knock, PoseSimConfig, SimError, DEFAULT_START_STAMP_NS};
use super::drive::DriveConfig;
use super::odometry::{mounting_at, pose_sensor_yaml};
use super::trajectory::{MotionKind, Trajectory, TrajectoryConfig};
use super::{
    imu_noise_yaml, random_mounting, rng_for, seeded_rng, simulate_motion, synthesize_odometry,
    Stream,
};
use crate::dataset::{
    write_groundtruth_csv, write_imu_csv, write_pose_csv, CalibrationResult, DatasetError,
    DatasetYaml, ExtrinsicEstimate, GroundTruthRecord, ImuRecord, PoseRecord, SectionName,
    CALIBRATION_OF_RECORD_YAML, DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML,
    GROUNDTRUTH_TRAJECTORY_CSV, IMU_CSV, IMU_YAML,
};

/// Random streams of the pose sensors after the first two: sensor `k >= 2` draws its
/// mounting, time offset, knock axis and calibration of record from stream
/// `EXTRA_SENSOR_STREAMS + 2 k` and its odometry noise from the next (the simulators' other
/// streams are below 300: `sim.rs`).
pub const EXTRA_SENSOR_STREAMS: u64 = 300;

/// The knock's ground truth.
pub const GROUNDTRUTH_KNOCK_YAML: &str = "groundtruth/knock.yaml";

/// Which sensor is knocked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KnockTarget {
    /// No knock.
    None,
    /// `pose0`, the LiDAR.
    Pose0,
    /// `pose1`, the camera.
    Pose1,
    /// `poseK` of any index `K` (`Pose(0)` is `Pose0`, `Pose(1)` is `Pose1`).
    Pose(usize),
}

impl KnockTarget {
    /// The knocked sensor's index, if any.
    pub fn index(&self) -> Option<usize> {
        match *self {
            KnockTarget::None => None,
            KnockTarget::Pose0 => Some(0),
            KnockTarget::Pose1 => Some(1),
            KnockTarget::Pose(k) => Some(k),
        }
    }
}

/// Options of the drive scenario.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveSimConfig {
    /// Random seed.
    pub seed: u64,
    /// Recording length, s.
    pub duration_s: f64,
    /// The drive's shape.
    pub drive: DriveConfig,
    /// The IMU.
    pub imu: ImuSimConfig,
    /// LiDAR odometry (`pose0`); its `time_offset_s` and `knock` are set by the simulator.
    pub lidar: PoseSimConfig,
    /// Camera VO (`pose1`); likewise.
    pub camera: PoseSimConfig,
    /// Number of pose sensors (at least 1): `pose0` the LiDAR, `pose1` the camera, `pose2`
    /// on further LiDAR odometries with [`DriveSimConfig::extra`].
    pub pose_sensors: usize,
    /// LiDAR odometry of `pose2`, `pose3`, ...; likewise.
    pub extra: PoseSimConfig,
    /// Time offsets are drawn uniformly in +- this, s.
    pub max_time_offset_s: f64,
    /// Knocked sensor.
    pub knock_target: KnockTarget,
    /// Knock time, s of IMU time after the start.
    pub knock_at_s: f64,
    /// Knock angle, deg (about a random axis across the vehicle's forward direction).
    pub knock_deg: f64,
    /// 1-sigma of the calibration of record: rotation per axis, deg.
    pub prior_sigma_rot_deg: f64,
    /// Translation per axis, m.
    pub prior_sigma_trans_m: f64,
    /// Time offset, s.
    pub prior_sigma_time_offset_s: f64,
}

impl Default for DriveSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            duration_s: 60.0,
            drive: DriveConfig::default(),
            imu: ImuSimConfig::default(),
            // Scan-to-scan NDT on a 64-beam LiDAR: a few hundredths of a degree and about a
            // centimetre per 0.1 s increment.
            lidar: PoseSimConfig {
                rate_hz: 10.0,
                rotation_noise_rad: 0.05f64.to_radians(),
                translation_noise_m: 0.01,
                ..PoseSimConfig::default()
            },
            // Stereo VO at 20 Hz: 0.1 deg and 1 cm per increment (~1-2 % of the 0.5 m a
            // frame travels at speed).
            camera: PoseSimConfig {
                rate_hz: 20.0,
                rotation_noise_rad: 0.1f64.to_radians(),
                translation_noise_m: 0.01,
                ..PoseSimConfig::default()
            },
            pose_sensors: 2,
            // A second LiDAR's scan-to-scan odometry, as pose0's.
            extra: PoseSimConfig {
                rate_hz: 10.0,
                rotation_noise_rad: 0.05f64.to_radians(),
                translation_noise_m: 0.01,
                ..PoseSimConfig::default()
            },
            max_time_offset_s: 0.02,
            knock_target: KnockTarget::Pose1,
            knock_at_s: 30.0,
            knock_deg: 1.0,
            prior_sigma_rot_deg: 0.05,
            prior_sigma_trans_m: 0.003,
            prior_sigma_time_offset_s: 0.0005,
        }
    }
}

/// One simulated pose sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseSensorSim {
    /// Its options (time offset and knock filled in).
    pub config: PoseSimConfig,
    /// True `T_imu_pose` before any knock.
    pub t_imu_pose: Isometry3<f64>,
    /// The odometry `T_odom_S`.
    pub poses: Vec<PoseRecord>,
    /// The calibration of record (prior) for it.
    pub prior: ExtrinsicEstimate,
}

impl PoseSensorSim {
    /// True `T_imu_pose` at the end of the recording.
    pub fn final_t_imu_pose(&self) -> Isometry3<f64> {
        mounting_at(&self.t_imu_pose, &self.config, f64::INFINITY)
    }
}

/// A simulated drive dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct DriveSim {
    /// Its options.
    pub config: DriveSimConfig,
    /// The motion of `I`.
    pub trajectory: Trajectory,
    /// `imu0/data.csv`.
    pub imu: Vec<ImuRecord>,
    /// `groundtruth/trajectory.csv`.
    pub groundtruth: Vec<GroundTruthRecord>,
    /// `pose0` (LiDAR odometry), `pose1` (camera VO), `pose2`, ... (LiDAR odometries): as
    /// many as [`DriveSimConfig::pose_sensors`].
    pub sensors: Vec<PoseSensorSim>,
}

/// A forward-looking camera: optical axis (z) along the vehicle's x, image x to its right
/// (-y), image y down (-z); a few degrees of mounting tolerance; on the roof front.
fn camera_mounting(rng: &mut impl Rng) -> Isometry3<f64> {
    let nominal = UnitQuaternion::from_rotation_matrix(&nalgebra::Rotation3::from_matrix(
        &nalgebra::Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0),
    ));
    let tilt = Vector3::from_fn(|_, _| 3f64.to_radians() * rng.sample::<f64, _>(StandardNormal));
    let translation = Translation3::new(
        rng.gen_range(1.2..=1.8),
        rng.gen_range(-0.3..=0.3),
        rng.gen_range(0.9..=1.3),
    );
    Isometry3::from_parts(
        translation,
        nominal * UnitQuaternion::from_scaled_axis(tilt),
    )
}

/// A knock of `deg` about a random axis across the vehicle's forward direction (IMU x),
/// expressed in the sensor frame: a mounting bent up/down or sideways. (A rotation about the
/// direction of travel barely changes what an odometry measures while driving straight; see
/// docs/monitor.md.)
fn knock_delta(t_imu_pose: &Isometry3<f64>, deg: f64, rng: &mut impl Rng) -> Isometry3<f64> {
    let a = rng.gen_range(-PI..PI);
    let axis_imu = Vector3::new(0.0, a.cos(), a.sin());
    let axis_sensor = t_imu_pose.rotation.inverse() * axis_imu;
    Isometry3::from_parts(
        Translation3::identity(),
        UnitQuaternion::from_scaled_axis(axis_sensor * deg.to_radians()),
    )
}

/// The calibration of record: the truth perturbed by the stated sigmas.
fn prior_of(
    t_imu_pose: &Isometry3<f64>,
    time_offset_s: f64,
    c: &DriveSimConfig,
    rng: &mut impl Rng,
) -> ExtrinsicEstimate {
    let mut n = |sigma: f64| sigma * rng.sample::<f64, _>(StandardNormal);
    let dr = Vector3::new(0, 1, 2).map(|_| n(c.prior_sigma_rot_deg.to_radians()));
    let dp = Vector3::new(0, 1, 2).map(|_| n(c.prior_sigma_trans_m));
    let td = time_offset_s + n(c.prior_sigma_time_offset_s);
    let transform = Isometry3::from_parts(
        Translation3::from(t_imu_pose.translation.vector + dp),
        t_imu_pose.rotation * UnitQuaternion::from_scaled_axis(dr),
    );
    ExtrinsicEstimate {
        transform,
        timeshift_s: td,
        sigma_rot_deg: Vector3::repeat(c.prior_sigma_rot_deg),
        sigma_trans_m: Vector3::repeat(c.prior_sigma_trans_m),
    }
}

/// Simulates the drive.
pub fn simulate_drive(config: &DriveSimConfig) -> Result<DriveSim, SimError> {
    let trajectory_config = TrajectoryConfig {
        motion: MotionKind::Drive(config.drive.clone()),
        ..TrajectoryConfig::default()
    };
    let check = super::SimConfig {
        seed: config.seed,
        duration_s: config.duration_s,
        trajectory: trajectory_config.clone(),
        imu: config.imu.clone(),
        ..super::SimConfig::default()
    };
    check.validate()?;
    if !(config.knock_deg.is_finite() && config.knock_at_s.is_finite()) {
        return Err(SimError::InvalidOption {
            option: "knock",
            message: "knock time and angle must be finite".into(),
        });
    }
    if config.pose_sensors == 0 {
        return Err(SimError::InvalidOption {
            option: "pose-sensors",
            message: "a drive needs at least one pose sensor".into(),
        });
    }
    if let Some(k) = config
        .knock_target
        .index()
        .filter(|&k| k >= config.pose_sensors)
    {
        return Err(SimError::InvalidOption {
            option: "knock-sensor",
            message: format!(
                "pose{k} is knocked but the drive has {} pose sensor(s)",
                config.pose_sensors
            ),
        });
    }
    let (clock, trajectory, imu) = simulate_motion(
        config.seed,
        DEFAULT_START_STAMP_NS,
        &trajectory_config,
        &config.imu,
        config.duration_s,
    );
    let mut rng = rng_for(config.seed, Stream::DriveMounting);
    let mountings = [random_mounting(&mut rng), camera_mounting(&mut rng)];
    let bases = [&config.lidar, &config.camera];
    let streams = [Stream::DriveOdometry0, Stream::DriveOdometry1];
    let mut sensors = Vec::with_capacity(config.pose_sensors);
    for k in 0..config.pose_sensors {
        let sensor = if k < 2 {
            let odometry = &mut rng_for(config.seed, streams[k]);
            let sensor = SensorDraw::new(mountings[k], bases[k], config, k, &mut rng);
            sensor.simulate(&trajectory, clock, config, odometry)
        } else {
            let stream = EXTRA_SENSOR_STREAMS + 2 * k as u64;
            let mut own = seeded_rng(config.seed, stream);
            let mounting = random_mounting(&mut own);
            let sensor = SensorDraw::new(mounting, &config.extra, config, k, &mut own);
            let odometry = &mut seeded_rng(config.seed, stream + 1);
            sensor.simulate(&trajectory, clock, config, odometry)
        };
        sensors.push(sensor);
    }
    Ok(DriveSim {
        config: config.clone(),
        trajectory,
        imu: imu.records,
        groundtruth: imu.groundtruth,
        sensors,
    })
}

/// What is drawn for one pose sensor before its odometry.
struct SensorDraw {
    mounting: Isometry3<f64>,
    config: PoseSimConfig,
    prior: ExtrinsicEstimate,
}

impl SensorDraw {
    /// Time offset, knock and calibration of record of sensor `k`, mounted at `mounting`,
    /// drawn from `rng` in this order.
    fn new(
        mounting: Isometry3<f64>,
        base: &PoseSimConfig,
        c: &DriveSimConfig,
        k: usize,
        rng: &mut impl Rng,
    ) -> Self {
        let mut config = base.clone();
        config.time_offset_s = rng.gen_range(-1.0..=1.0) * c.max_time_offset_s;
        let delta = knock_delta(&mounting, c.knock_deg, rng);
        config.knock = (c.knock_target.index() == Some(k)).then_some(Knock {
            at_s: c.knock_at_s,
            delta,
        });
        let prior = prior_of(&mounting, config.time_offset_s, c, rng);
        Self {
            mounting,
            config,
            prior,
        }
    }

    /// The sensor with its odometry along `trajectory`, noise from `rng`.
    fn simulate(
        self,
        trajectory: &Trajectory,
        clock: super::Clock,
        c: &DriveSimConfig,
        rng: &mut impl Rng,
    ) -> PoseSensorSim {
        let poses = synthesize_odometry(
            trajectory,
            &self.mounting,
            &self.config,
            clock,
            c.duration_s,
            rng,
        );
        PoseSensorSim {
            config: self.config,
            t_imu_pose: self.mounting,
            poses,
            prior: self.prior,
        }
    }
}

/// The result file with `poseK` = `estimate(sensor K)` for every sensor.
fn pose_sections(
    sensors: &[PoseSensorSim],
    estimate: impl Fn(&PoseSensorSim) -> ExtrinsicEstimate,
) -> CalibrationResult {
    let mut result = CalibrationResult::new();
    for (k, s) in sensors.iter().enumerate() {
        let index = u16::try_from(k).unwrap_or(u16::MAX);
        result.set_extrinsic(SectionName::pose(index), estimate(s));
    }
    result
}

impl DriveSim {
    /// The calibration of record, a `poseK` section per sensor.
    pub fn prior(&self) -> CalibrationResult {
        pose_sections(&self.sensors, |s| s.prior)
    }

    /// The true mountings at the end of the recording (zero sigmas).
    pub fn final_extrinsics(&self) -> CalibrationResult {
        pose_sections(&self.sensors, |s| {
            ExtrinsicEstimate::exact(s.final_t_imu_pose(), s.config.time_offset_s)
        })
    }

    /// The knocked sensor's name (`poseK`) and knock time, s after the start, if any.
    pub fn knock(&self) -> Option<(String, f64)> {
        self.sensors
            .iter()
            .enumerate()
            .find_map(|(k, s)| s.config.knock.map(|kn| (format!("pose{k}"), kn.at_s)))
    }

    /// `groundtruth/knock.yaml`.
    fn knock_yaml(&self) -> String {
        let mut text = String::from(
            "# msreg simulate drive: the knock (IMU time, s after the first IMU sample)\n",
        );
        match self.knock() {
            None => text.push_str("sensor: none\n"),
            Some((name, at_s)) => {
                text.push_str(&format!(
                    "sensor: {name}\nat_s: {at_s}\nangle_deg: {}\n",
                    self.config.knock_deg
                ));
                let before = pose_sections(&self.sensors, |s| {
                    ExtrinsicEstimate::exact(s.t_imu_pose, 0.0)
                });
                let indent = |t: String| t.lines().map(|l| format!("  {l}\n")).collect::<String>();
                text.push_str("before:\n");
                text.push_str(&indent(before.to_yaml_string()));
                text.push_str("after:\n");
                text.push_str(&indent(self.final_extrinsics().to_yaml_string()));
            }
        }
        text
    }

    /// `dataset.yaml`.
    fn metadata(&self) -> DatasetYaml {
        let c = &self.config;
        let names = self.pose_names();
        let kinds = [
            "pose0 = LiDAR odometry",
            "pose1 = metric camera visual odometry",
        ];
        let mut what: Vec<String> = kinds
            .iter()
            .take(names.len())
            .map(|k| k.to_string())
            .collect();
        if names.len() > 2 {
            what.push(format!(
                "pose2..{} = LiDAR odometries",
                names[names.len() - 1]
            ));
        }
        let mut rates_hz = BTreeMap::from([("imu0".to_string(), c.imu.rate_hz)]);
        for (name, s) in names.iter().zip(&self.sensors) {
            rates_hz.insert(name.clone(), s.config.rate_hz);
        }
        DatasetYaml {
            sensors: std::iter::once("imu0".to_string()).chain(names).collect(),
            description: format!(
                "msreg simulator: drive, seed {}, {} s; {}; knock {:?} at {} s by {} deg",
                c.seed,
                c.duration_s,
                what.join(", "),
                c.knock_target,
                c.knock_at_s,
                c.knock_deg
            ),
            rates_hz,
        }
    }

    /// `pose0`, `pose1`, ... of the sensors.
    fn pose_names(&self) -> Vec<String> {
        (0..self.sensors.len())
            .map(|k| format!("pose{k}"))
            .collect()
    }

    /// Writes the dataset under `dir`.
    pub fn write(&self, dir: impl AsRef<Path>) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        let names = self.pose_names();
        let mut dirs: Vec<&str> = vec!["imu0", "groundtruth"];
        dirs.extend(names.iter().map(String::as_str));
        super::write::create_dirs(dir, &dirs)?;
        self.metadata().write(dir.join(DATASET_YAML))?;
        write_imu_csv(dir.join(IMU_CSV), &self.imu)?;
        imu_noise_yaml(&self.config.imu).write(dir.join(IMU_YAML))?;
        for (k, s) in self.sensors.iter().enumerate() {
            write_pose_csv(dir.join(format!("pose{k}/data.csv")), &s.poses)?;
            pose_sensor_yaml(&s.config).write(dir.join(format!("pose{k}/sensor.yaml")))?;
        }
        self.prior().write(dir.join(CALIBRATION_OF_RECORD_YAML))?;
        write_groundtruth_csv(dir.join(GROUNDTRUTH_TRAJECTORY_CSV), &self.groundtruth)?;
        self.final_extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))?;
        super::write::write_text(&dir.join(GROUNDTRUTH_KNOCK_YAML), &self.knock_yaml())
    }
}
