//! The joint LiDAR-IMU-camera simulator (issue 13): one hand-held rig of an IMU, a camera and
//! a spinning LiDAR, moved in front of a checkerboard printed on a board of known size that
//! both sensors see, inside the LiDAR-IMU simulator's room.
//!
//! - Motion, IMU, camera and board pose: the camera-IMU simulator ([`super::camera`]); its
//!   look-at trajectory keeps the board in the camera's view. Default: a 7 x 9 board of 8 cm
//!   squares 1.5 m away.
//! - The board is also a [`Plate`] in the LiDAR's room (the pattern plus its white margin),
//!   so the LiDAR ([`super::lidar`]) sees it among the room's boxes, each column from its own
//!   firing pose at its own IMU time `stamp + t + t_d`.
//! - LiDAR mounting: its z axis up in the camera frame (`-y_C`), x along the optical axis,
//!   then a uniform yaw about z and N(0, 3 deg) on every axis; each translation component
//!   uniform in +-0.1 m (0.1-0.2 m above the camera).
//! - Files: the camera-IMU layout (`imu0/`, `cam0/`, `target.yaml` with the board's
//!   `width_m` / `height_m`), `lidar0/`, and `groundtruth/extrinsics.yaml` with `cam0`,
//!   `lidar0` and `cam0_lidar0`.

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;

use super::camera::{simulate_camera_imu, CameraImuSim, CameraImuSimConfig};
use super::config::SimError;
use super::lidar::{LidarImuSim, LidarImuSimConfig, LidarSimConfig};
use super::plate::Plate;
use super::trajectory::LookAtConfig;
use super::{rng_for, Stream};
use crate::camera_yaml::{checkerboard_yaml_string, CheckerboardTarget};
use crate::dataset::{
    CalibrationResult, DatasetError, DatasetYaml, ExtrinsicEstimate, SectionName, DATASET_YAML,
    GROUNDTRUTH_EXTRINSICS_YAML, TARGET_YAML,
};
use crate::vision::render::BoardPattern;

/// Reflectivity of the board's white face (Ouster-like units).
const BOARD_REFLECTIVITY: f32 = 85.0;

/// Everything [`simulate_joint`] needs; deterministic per `camera.seed`.
#[derive(Debug, Clone, PartialEq)]
pub struct JointSimConfig {
    /// Seed, duration, motion, IMU, camera, board, camera time offset.
    pub camera: CameraImuSimConfig,
    /// The LiDAR (its `time_offset_s` is the LiDAR's `t_d`).
    pub lidar: LidarSimConfig,
    /// Ground-truth `T_imu_lidar`; `None` draws a mounting next to the camera.
    pub t_imu_lidar: Option<Isometry3<f64>>,
}

impl Default for JointSimConfig {
    fn default() -> Self {
        let camera = CameraImuSimConfig::default();
        Self {
            camera: CameraImuSimConfig {
                look_at: LookAtConfig {
                    distance_m: 1.5,
                    max_offset_m: [0.25, 0.15, 0.25],
                    ..camera.look_at
                },
                board: BoardPattern {
                    rows: 7,
                    cols: 9,
                    row_spacing_m: 0.08,
                    col_spacing_m: 0.08,
                    margin_m: 0.05,
                },
                ..camera
            },
            lidar: LidarSimConfig {
                rings: 64,
                columns: 1024,
                ..LidarSimConfig::default()
            },
            t_imu_lidar: None,
        }
    }
}

/// `T_cam_lidar` of a LiDAR mounted just above a camera (see the module docs).
pub fn random_lidar_above_camera(rng: &mut impl Rng) -> Isometry3<f64> {
    // LiDAR axes in the camera frame: x forward (z_C), y left (-x_C), z up (-y_C).
    let base = Matrix3::new(0.0, -1.0, 0.0, 0.0, 0.0, -1.0, 1.0, 0.0, 0.0);
    let base = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(base));
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.gen_range(-PI..PI));
    let sigma = 3.0_f64.to_radians();
    let jitter = Vector3::from_fn(|_, _| sigma * rng.sample::<f64, _>(StandardNormal));
    let translation = Translation3::new(
        rng.gen_range(-0.1..=0.1),
        rng.gen_range(-0.2..=-0.1),
        rng.gen_range(-0.1..=0.1),
    );
    Isometry3::from_parts(
        translation,
        base * yaw * UnitQuaternion::from_scaled_axis(jitter),
    )
}

/// A simulated joint recording: the camera-IMU part and the LiDAR on the same motion.
#[derive(Debug, Clone)]
pub struct JointSim {
    /// IMU, camera, board, trajectory.
    pub camera: CameraImuSim,
    /// The LiDAR on the same motion, seeing the room and the board.
    pub lidar: LidarImuSim,
}

/// Simulates the joint recording described by `config` (IMU now, images and scans on demand).
pub fn simulate_joint(config: &JointSimConfig) -> Result<JointSim, SimError> {
    let camera = simulate_camera_imu(&config.camera)?;
    let t_imu_lidar = config.t_imu_lidar.unwrap_or_else(|| {
        let mut rng = rng_for(config.camera.seed, Stream::JointLidarMounting);
        camera.t_cam_imu.inverse() * random_lidar_above_camera(&mut rng)
    });
    let lidar_config = LidarImuSimConfig {
        seed: config.camera.seed,
        duration_s: config.camera.duration_s,
        start_stamp_ns: config.camera.start_stamp_ns,
        trajectory: config.camera.trajectory.clone(),
        imu: config.camera.imu.clone(),
        lidar: config.lidar.clone(),
        t_imu_lidar: Some(t_imu_lidar),
    };
    let plate = board_plate(&config.camera.board, &camera.t_g_target);
    let motion = (
        camera.trajectory.clone(),
        camera.imu.clone(),
        camera.groundtruth.clone(),
    );
    let lidar = LidarImuSim::on_motion(&lidar_config, motion, t_imu_lidar, vec![plate])?;
    Ok(JointSim { camera, lidar })
}

/// The physical board of `pattern` at `T_G_T`: the squares plus the white margin, centred on
/// the pattern (target x along the rows, y along the columns).
fn board_plate(pattern: &BoardPattern, t_g_target: &Isometry3<f64>) -> Plate {
    let (w, h) = board_size(pattern);
    let centre = Vector3::new(
        (pattern.rows - 1) as f64 * pattern.row_spacing_m / 2.0,
        (pattern.cols - 1) as f64 * pattern.col_spacing_m / 2.0,
        0.0,
    );
    Plate {
        t_g_p: t_g_target * Translation3::from(centre),
        half_extents: (w / 2.0, h / 2.0),
        reflectivity: BOARD_REFLECTIVITY,
    }
}

/// Width (along target x) and height (along target y) of the board, m.
fn board_size(pattern: &BoardPattern) -> (f64, f64) {
    (
        (pattern.rows + 1) as f64 * pattern.row_spacing_m + 2.0 * pattern.margin_m,
        (pattern.cols + 1) as f64 * pattern.col_spacing_m + 2.0 * pattern.margin_m,
    )
}

impl JointSim {
    /// The Kalibr target with the board's physical size (`width_m` along target x).
    pub fn target(&self) -> CheckerboardTarget {
        let (w, h) = board_size(&self.camera.config.board);
        CheckerboardTarget {
            width_m: Some(w),
            height_m: Some(h),
            ..self.camera.target()
        }
    }

    /// True `T_cam_lidar`.
    pub fn t_cam_lidar(&self) -> Isometry3<f64> {
        self.camera.t_cam_imu * self.lidar.t_imu_lidar
    }

    /// The true extrinsics in result-file form (sigmas zero): `cam0`, `lidar0`,
    /// `cam0_lidar0`.
    pub fn extrinsics(&self) -> CalibrationResult {
        let mut truth = self.camera.extrinsics();
        if let Some(lidar0) = self.lidar.extrinsics().extrinsic(&SectionName::LIDAR0) {
            truth.set_extrinsic(SectionName::LIDAR0, *lidar0);
        }
        truth.with_extrinsic(
            SectionName::CAM0_LIDAR0,
            ExtrinsicEstimate::exact(self.t_cam_lidar(), 0.0),
        )
    }

    /// `dataset.yaml` contents.
    pub fn metadata(&self) -> DatasetYaml {
        let (camera, lidar) = (self.camera.metadata(), self.lidar.metadata());
        DatasetYaml {
            sensors: vec!["imu0".into(), "cam0".into(), "lidar0".into()],
            description: format!(
                "msreg simulator: joint LiDAR-IMU-camera; {}; {}",
                camera.description, lidar.description
            ),
            rates_hz: camera
                .rates_hz
                .into_iter()
                .chain(lidar.rates_hz)
                .collect::<BTreeMap<_, _>>(),
        }
    }

    /// Writes the dataset layout under `dir` (created if needed): the camera-IMU files
    /// (images rendered in parallel), then the scans; `progress` gets the fraction done.
    pub fn write(
        &self,
        dir: impl AsRef<Path>,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        self.camera.write(dir, &|f| progress(0.5 * f))?;
        self.metadata().write(dir.join(DATASET_YAML))?;
        super::write::write_text(
            &dir.join(TARGET_YAML),
            &checkerboard_yaml_string(&self.target()),
        )?;
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))?;
        self.lidar
            .write_lidar(dir, &mut |f| progress(0.5 + 0.5 * f))
    }
}

#[cfg(test)]
#[path = "joint_tests.rs"]
mod tests;
