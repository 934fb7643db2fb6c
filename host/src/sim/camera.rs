//! The camera-IMU simulator: a camera rigidly mounted on the hand-held IMU, waved in front of
//! a static Kalibr checkerboard, rendered frame by frame.
//!
//! - Motion: a look-at [`Trajectory`] ([`Trajectory::random_look_at`]): the camera moves
//!   about a nominal viewpoint `W` (random heading, looking 0-35 deg down) and keeps the board
//!   centre near its optical axis while turning at 1-2 rad/s about every axis, so the full
//!   board stays in view in nearly every frame. The IMU follows as `T_G_I = T_G_C T_cam_imu`,
//!   synthesised exactly as in the other scenarios (VN-300-class, 400 Hz).
//! - Board: `rows x cols` inner corners (default 6 x 7 at 6 cm, Kalibr ids), 0.75 m in front
//!   of the viewpoint, facing it within +-0.2 rad, turned in its plane within +-0.2 rad; or,
//!   with [`CameraImuSimConfig::aprilgrid`], a Kalibr AprilGrid (tag36h11, corner squares,
//!   Kalibr corner ids) placed the same way.
//! - Camera: pinhole + radtan (EuRoC cam0 intrinsics, 752 x 480) or pinhole + equidistant;
//!   frames at `rate_hz`, image stamped `t_C` shows the scene at IMU time `t_C + t_d`
//!   (mid-exposure). Rendering ([`crate::vision::render`]): anti-aliased edges (8 x 8
//!   supersampling), optional motion blur (the mean over `exposure_s` of sharp renders, enough
//!   of them that the image moves < 0.5 px between two), lighting gradient and Gaussian
//!   noise, then 8-bit PNG.
//! - Ground truth: `T_cam_imu`, `timeshift_cam_imu`, the IMU trajectory, the board pose
//!   `T_G_T` per frame and the true pixel of every corner with an in-image flag.

pub mod rig;

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use msreg_estimator::camera::{
    equidistant::Equidistant, radtan::RadTan, Camera, Distortion, Intrinsics, Projection,
};
use msreg_estimator::Pose;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

use super::clock::Clock;
use super::config::{ImuSimConfig, SimError, DEFAULT_START_STAMP_NS};
use super::imu::{imu_noise_yaml, synthesize_imu};
use super::trajectory::{LookAtConfig, Mount, Trajectory, TrajectoryConfig};
use super::write::{create_dirs, write_png, write_text};
use super::{frame_rng, rng_for, Stream};
use crate::camera_yaml::{
    aprilgrid_yaml_string, camera_yaml_string, checkerboard_yaml_string, AprilGridTarget,
    CheckerboardTarget, Target,
};
use crate::dataset::{
    write_camera_csv, write_corners_csv, write_groundtruth_csv, write_imu_csv, write_pose_csv,
    CalibrationResult, CameraFrame, CornerTruth, DatasetError, DatasetYaml, ExtrinsicEstimate,
    GroundTruthRecord, ImuNoiseYaml, ImuRecord, PoseRecord, SectionName, CAMERA_DATA_DIR,
    DATASET_YAML, GROUNDTRUTH_CORNERS_CSV, GROUNDTRUTH_EXTRINSICS_YAML,
    GROUNDTRUTH_TARGET_POSES_CSV, GROUNDTRUTH_TRAJECTORY_CSV, IMU_CSV, IMU_YAML, TARGET_YAML,
};
use crate::vision::aprilgrid::AprilGridPattern;
use crate::vision::render::{
    add_noise, apply_lighting_gradient, render_exposure, BoardPattern, PixelRays, RenderSettings,
};
use crate::vision::GrayImage;

/// The lens of the simulated camera.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum CameraModelChoice {
    /// EuRoC cam0: pinhole + radtan, 752 x 480, ~78 x 55 deg.
    #[default]
    PinholeRadtan,
    /// A wide-angle lens: pinhole + equidistant (Kannala-Brandt), 752 x 480, ~100 x 70 deg.
    PinholeEquidistant,
}

impl CameraModelChoice {
    /// The camera with this lens.
    pub fn camera(self) -> Camera<f64> {
        let (intrinsics, distortion) = match self {
            Self::PinholeRadtan => (
                Intrinsics {
                    fu: 458.654,
                    fv: 457.296,
                    cu: 367.215,
                    cv: 248.375,
                },
                Distortion::RadTan(RadTan {
                    k1: -0.283_408_11,
                    k2: 0.073_959_07,
                    p1: 0.000_193_59,
                    p2: 1.761_871_14e-5,
                    k3: 0.0,
                }),
            ),
            Self::PinholeEquidistant => (
                Intrinsics {
                    fu: 320.2,
                    fv: 319.8,
                    cu: 377.4,
                    cv: 238.1,
                },
                Distortion::Equidistant(Equidistant {
                    k1: -0.012,
                    k2: 0.021,
                    k3: -0.011,
                    k4: 0.002,
                }),
            ),
        };
        // Valid constants: positive focal lengths, finite coefficients.
        Camera::new(Projection::Pinhole, intrinsics, distortion, (752, 480))
            .unwrap_or_else(|_| unreachable!("the built-in camera parameters are valid"))
    }
}

/// Everything [`simulate_camera_imu`] needs; deterministic per `seed`.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraImuSimConfig {
    /// Seeds every random draw.
    pub seed: u64,
    /// Length of the IMU record, s.
    pub duration_s: f64,
    /// Absolute stamp of the first IMU sample, ns.
    pub start_stamp_ns: u64,
    /// Frequencies, rate and speed amplitudes and the still start of the motion.
    pub trajectory: TrajectoryConfig,
    /// How far the hand-held camera wanders around the viewpoint.
    pub look_at: LookAtConfig,
    /// IMU rate, noise and biases.
    pub imu: ImuSimConfig,
    /// The camera.
    pub camera: Camera<f64>,
    /// Frame rate, Hz.
    pub rate_hz: f64,
    /// `t_d` (s): an image stamped `t_C` shows the scene at IMU time `t_C + t_d`.
    pub time_offset_s: f64,
    /// The board (Kalibr checkerboard plus white margin).
    pub board: BoardPattern,
    /// When set, the printed target is this Kalibr AprilGrid instead of `board` (rendered,
    /// written to `target.yaml`, its corners in the ground truth).
    pub aprilgrid: Option<AprilGridPattern>,
    /// Exposure time for motion blur, s; `None`: sharp images.
    pub exposure_s: Option<f64>,
    /// Gaussian image noise, grey levels (0: none).
    pub noise_sigma: f64,
    /// Illumination gain across the image (u, v) (0: uniform).
    pub lighting_gradient: [f32; 2],
    /// Grey levels and supersampling.
    pub render: RenderSettings,
    /// Ground-truth `T_cam_imu`; `None` draws a random realistic mounting.
    pub t_cam_imu: Option<Isometry3<f64>>,
}

impl Default for CameraImuSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            duration_s: 60.0,
            start_stamp_ns: DEFAULT_START_STAMP_NS,
            trajectory: TrajectoryConfig {
                min_frequency_hz: 0.5,
                max_frequency_hz: 1.5,
                rate_amplitude_rad_s: 0.9,
                speed_amplitude_m_s: 0.3,
                ..TrajectoryConfig::default()
            },
            look_at: LookAtConfig {
                distance_m: 0.75,
                max_offset_m: [0.15, 0.1, 0.12],
                max_deviation_rad: [0.15, 0.18, 0.35],
            },
            imu: ImuSimConfig::default(),
            camera: CameraModelChoice::default().camera(),
            rate_hz: 20.0,
            time_offset_s: 0.0,
            board: BoardPattern {
                rows: 6,
                cols: 7,
                row_spacing_m: 0.06,
                col_spacing_m: 0.06,
                margin_m: 0.03,
            },
            aprilgrid: None,
            exposure_s: None,
            noise_sigma: 0.0,
            lighting_gradient: [0.0, 0.0],
            render: RenderSettings::default(),
            t_cam_imu: None,
        }
    }
}

impl CameraImuSimConfig {
    /// The AprilGrid of `msreg simulate camera-imu --aprilgrid`: 6 x 5 tag36h11 tags of 5 cm,
    /// spacing 0.3 (0.375 x 0.31 m, about the default checkerboard's extent), 3 cm margin.
    pub fn default_aprilgrid() -> AprilGridPattern {
        AprilGridPattern {
            target: AprilGridTarget {
                tag_cols: 6,
                tag_rows: 5,
                tag_size_m: 0.05,
                tag_spacing: 0.3,
            },
            margin_m: 0.03,
        }
    }

    /// Motion blur (4 ms exposure), noise (sigma 2.5 grey levels) and a lighting gradient:
    /// the realistic-image variant.
    pub fn with_blur_and_noise(mut self) -> Self {
        self.exposure_s = Some(0.004);
        self.noise_sigma = 2.5;
        self.lighting_gradient = [0.35, -0.2];
        self
    }

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
        let l = &self.look_at;
        if !(l.distance_m.is_finite() && l.distance_m > 0.1) {
            return bad("look_at.distance_m", "must be > 0.1 m");
        }
        if l.max_offset_m
            .iter()
            .chain(&l.max_deviation_rad)
            .any(|x| !(x.is_finite() && *x >= 0.0))
            || l.max_offset_m[2] >= 0.5 * l.distance_m
            || l.max_deviation_rad.iter().any(|&x| x > 1.0)
        {
            return bad(
                "look_at",
                "offsets >= 0 (depth < half the distance), deviations in [0, 1] rad",
            );
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 200.0) {
            return bad("rate_hz", "must be in (0, 200] Hz");
        }
        if !(self.time_offset_s.is_finite() && self.time_offset_s.abs() <= 0.1) {
            return bad("time_offset_s", "must be finite and within +-0.1 s");
        }
        let b = &self.board;
        if b.rows < 3
            || b.cols < 3
            || !(b.row_spacing_m > 0.0 && b.col_spacing_m > 0.0 && b.margin_m >= 0.0)
        {
            return bad("board", "at least 3 x 3 inner corners, positive spacings");
        }
        if let Some(g) = &self.aprilgrid {
            let t = &g.target;
            if t.tag_cols < 2
                || t.tag_rows < 2
                || t.tag_cols * t.tag_rows > 587
                || !(t.tag_size_m > 0.0 && t.tag_spacing > 0.0 && t.tag_spacing <= 1.0)
                || !(g.margin_m.is_finite() && g.margin_m >= 0.0)
            {
                return bad(
                    "aprilgrid",
                    "2 x 2 to 587 tags, positive size, spacing in (0, 1], margin >= 0",
                );
            }
        }
        if let Some(e) = self.exposure_s {
            if !(e.is_finite() && e > 0.0 && e < 0.5 / self.rate_hz) {
                return bad("exposure_s", "must be > 0 and shorter than half a frame");
            }
        }
        if !(self.noise_sigma.is_finite() && (0.0..50.0).contains(&self.noise_sigma)) {
            return bad("noise_sigma", "must be in [0, 50) grey levels");
        }
        if !self.lighting_gradient.iter().all(|g| g.abs() < 1.0) {
            return bad("lighting_gradient", "each gain must be within (-1, 1)");
        }
        if self.duration_s < 0.3 + 3.0 / self.rate_hz {
            return bad("duration_s", "too short for three frames");
        }
        Ok(())
    }
}

/// `T_imu_cam` of a camera bolted next to the IMU: its axes along one of the 24 axis-aligned
/// orientations of the IMU box, each perturbed by N(0, 3 deg); each translation component
/// uniform in [-0.1, 0.1] m.
pub fn random_camera_mounting(rng: &mut impl Rng) -> Isometry3<f64> {
    let axes = [Vector3::x(), Vector3::y(), Vector3::z()];
    let k = rng.gen_range(0..24usize);
    // Camera z (optical axis) along +-one IMU axis, camera x along +-another.
    let (z_axis, z_sign) = (k / 8, if (k / 4) % 2 == 0 { 1.0 } else { -1.0 });
    let x_axis = (z_axis + 1 + (k / 2) % 2) % 3;
    let x_sign = if k % 2 == 0 { 1.0 } else { -1.0 };
    let z = axes[z_axis] * z_sign;
    let x = axes[x_axis] * x_sign;
    let y = z.cross(&x);
    let base = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
        Matrix3::from_columns(&[x, y, z]),
    ));
    let sigma = 3.0_f64.to_radians();
    let jitter = Vector3::from_fn(|_, _| sigma * rng.sample::<f64, _>(StandardNormal));
    let translation = Translation3::new(
        rng.gen_range(-0.1..=0.1),
        rng.gen_range(-0.1..=0.1),
        rng.gen_range(-0.1..=0.1),
    );
    Isometry3::from_parts(translation, base * UnitQuaternion::from_scaled_axis(jitter))
}

/// The viewpoint frame `W` (x right, y down, z forward) and the board `T_G_T`.
fn random_scene(
    config: &CameraImuSimConfig,
    rng: &mut impl Rng,
) -> (Isometry3<f64>, Isometry3<f64>) {
    let heading: f64 = rng.gen_range(-PI..PI);
    let elevation: f64 = rng.gen_range(0.0..0.6);
    let forward = Vector3::new(
        elevation.cos() * heading.cos(),
        elevation.cos() * heading.sin(),
        -elevation.sin(),
    );
    let right = forward.cross(&Vector3::z()).normalize();
    let down = forward.cross(&right);
    let r_g_w = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
        Matrix3::from_columns(&[right, down, forward]),
    ));
    let origin = Vector3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 1.3);
    let t_g_w = Isometry3::from_parts(Translation3::from(origin), r_g_w);
    // Board: target x along W y (down), y along W x (right), z = -W z (facing the camera);
    // then a turn in its plane and a tilt.
    let facing = Matrix3::new(0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0);
    let r_facing = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(facing));
    let spin = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.gen_range(-0.2..0.2));
    let tilt =
        UnitQuaternion::from_euler_angles(rng.gen_range(-0.2..0.2), rng.gen_range(-0.2..0.2), 0.0);
    let r_w_t = tilt * spin * r_facing;
    let centre_t = match &config.aprilgrid {
        None => {
            let b = &config.board;
            Vector3::new(
                (b.rows - 1) as f64 * b.row_spacing_m / 2.0,
                (b.cols - 1) as f64 * b.col_spacing_m / 2.0,
                0.0,
            )
        }
        Some(g) => {
            let t = &g.target;
            let span = |n: usize| (n as f64 * (1.0 + t.tag_spacing) - t.tag_spacing) * t.tag_size_m;
            Vector3::new(span(t.tag_cols) / 2.0, span(t.tag_rows) / 2.0, 0.0)
        }
    };
    let p_w_t = Vector3::new(0.0, 0.0, config.look_at.distance_m) - r_w_t * centre_t;
    let t_w_t = Isometry3::from_parts(Translation3::from(p_w_t), r_w_t);
    (t_g_w, t_g_w * t_w_t)
}

/// A simulated camera-IMU recording; images are rendered on demand.
#[derive(Debug, Clone)]
pub struct CameraImuSim {
    /// The options it was made with.
    pub config: CameraImuSimConfig,
    /// The exact motion of `I` (s after `config.start_stamp_ns`).
    pub trajectory: Trajectory,
    /// `imu0/data.csv`.
    pub imu: Vec<ImuRecord>,
    /// `imu0/imu.yaml`.
    pub imu_noise: ImuNoiseYaml,
    /// `groundtruth/trajectory.csv`.
    pub groundtruth: Vec<GroundTruthRecord>,
    /// True `T_cam_imu` (`p_cam = T_cam_imu p_imu`).
    pub t_cam_imu: Isometry3<f64>,
    /// True board pose `T_G_T` (static).
    pub t_g_target: Isometry3<f64>,
    /// Stamp of every frame (camera clock), ns.
    pub frame_stamps: Vec<u64>,
    rays: PixelRays,
}

/// Simulates the camera-IMU recording described by `config` (IMU now, images on demand).
pub fn simulate_camera_imu(config: &CameraImuSimConfig) -> Result<CameraImuSim, SimError> {
    config.validate()?;
    let t_cam_imu = config.t_cam_imu.unwrap_or_else(|| {
        random_camera_mounting(&mut rng_for(config.seed, Stream::CameraMounting)).inverse()
    });
    let (t_g_w, t_g_target) = random_scene(config, &mut rng_for(config.seed, Stream::CameraScene));
    let mount = Mount {
        t_g_w,
        t_f_i: t_cam_imu,
    };
    let trajectory = Trajectory::random_look_at(
        &config.trajectory,
        &config.look_at,
        mount,
        &mut rng_for(config.seed, Stream::Trajectory),
    );
    let clock = Clock {
        start_ns: config.start_stamp_ns,
    };
    let imu = synthesize_imu(
        &trajectory,
        &config.imu,
        clock,
        config.duration_s,
        &mut rng_for(config.seed, Stream::Imu),
    );
    let frame_stamps = frame_stamps(config);
    Ok(CameraImuSim {
        config: config.clone(),
        trajectory,
        imu: imu.records,
        imu_noise: imu_noise_yaml(&config.imu),
        groundtruth: imu.groundtruth,
        t_cam_imu,
        t_g_target,
        frame_stamps,
        rays: PixelRays::new(&config.camera),
    })
}

/// Stamp of every frame (camera clock), ns: every exposure inside the IMU record, 50 ms of
/// margin at the start.
fn frame_stamps(config: &CameraImuSimConfig) -> Vec<u64> {
    let period_ns = (1e9 / config.rate_hz).round() as u64;
    let td_ns = (config.time_offset_s * 1e9).round() as i64;
    let half_exposure_ns = config.exposure_s.map_or(0, |e| (e * 0.5e9).ceil() as i64);
    let first = (config.start_stamp_ns as i128 + 50_000_000 + i128::from(half_exposure_ns)
        - i128::from(td_ns.min(0))) as u64;
    let last_ok = config.start_stamp_ns as i128 + (config.duration_s * 1e9) as i128
        - 10_000_000
        - i128::from(half_exposure_ns)
        - i128::from(td_ns.max(0));
    (0u64..)
        .map(|k| first + k * period_ns)
        .take_while(|s| *s as i128 <= last_ok)
        .collect()
}

impl CameraImuSim {
    /// Another camera on the same rig: the same motion, IMU record and target, seen through
    /// `camera` mounted at `t_cam_imu` with its own time offset (s) and image-noise seed.
    pub fn with_camera(
        &self,
        camera: Camera<f64>,
        t_cam_imu: Isometry3<f64>,
        time_offset_s: f64,
        seed: u64,
    ) -> Result<CameraImuSim, SimError> {
        let config = CameraImuSimConfig {
            camera,
            time_offset_s,
            seed,
            t_cam_imu: Some(t_cam_imu),
            ..self.config.clone()
        };
        config.validate()?;
        Ok(CameraImuSim {
            frame_stamps: frame_stamps(&config),
            rays: PixelRays::new(&config.camera),
            t_cam_imu,
            trajectory: self.trajectory.clone(),
            imu: self.imu.clone(),
            imu_noise: self.imu_noise.clone(),
            groundtruth: self.groundtruth.clone(),
            t_g_target: self.t_g_target,
            config,
        })
    }

    /// Seconds after the start stamp of an IMU-clock stamp.
    pub fn seconds(&self, stamp_ns: u64) -> f64 {
        Clock {
            start_ns: self.config.start_stamp_ns,
        }
        .seconds(stamp_ns)
    }

    /// IMU time (s after the start stamp) of frame `k`'s mid-exposure.
    pub fn frame_time(&self, k: usize) -> f64 {
        let stamp = self.frame_stamps.get(k).copied().unwrap_or(0);
        self.seconds(stamp) + self.config.time_offset_s
    }

    /// `T_cam_target` at IMU time `t` (s after the start stamp).
    pub fn t_cam_target(&self, t: f64) -> Pose<f64> {
        let t_c_t = self.t_cam_imu * self.trajectory.isometry(t).inverse() * self.t_g_target;
        Pose::new(t_c_t.rotation, t_c_t.translation.vector)
    }

    /// The Kalibr target of `target.yaml`: the AprilGrid when there is one, else the
    /// checkerboard.
    pub fn printed_target(&self) -> Target {
        match &self.config.aprilgrid {
            Some(g) => Target::AprilGrid(g.target),
            None => Target::Checkerboard(self.target()),
        }
    }

    /// The Kalibr target of the checkerboard.
    pub fn target(&self) -> CheckerboardTarget {
        let b = &self.config.board;
        CheckerboardTarget {
            rows: b.rows,
            cols: b.cols,
            row_spacing_m: b.row_spacing_m,
            col_spacing_m: b.col_spacing_m,
            width_m: None,
            height_m: None,
        }
    }

    /// The true pixel of every corner of frame `k` (`None`: not projectable).
    pub fn true_corners(&self, k: usize) -> Vec<Option<Vector2<f64>>> {
        let target = self.printed_target();
        let t_cam_target = self.t_cam_target(self.frame_time(k));
        (0..target.corner_count())
            .map(|id| {
                let p = target.corner(id)?;
                let q = self
                    .config
                    .camera
                    .project(&t_cam_target.transform_point(&p))?;
                Some(q.pixel)
            })
            .collect()
    }

    /// True when every corner of frame `k` projects inside the image.
    pub fn full_board_in_view(&self, k: usize) -> bool {
        self.true_corners(k)
            .iter()
            .all(|p| p.is_some_and(|p| self.config.camera.in_image(&p, 0.0)))
    }

    /// Frame `k` as rendered (blur, lighting and noise as configured), before 8-bit
    /// quantisation.
    pub fn image(&self, k: usize) -> GrayImage {
        let c = &self.config;
        let t = self.frame_time(k);
        let poses = match c.exposure_s {
            None => vec![self.t_cam_target(t)],
            Some(e) => {
                let n = self.blur_steps(t, e);
                (0..n)
                    .map(|j| self.t_cam_target(t + e * ((j as f64 + 0.5) / n as f64 - 0.5)))
                    .collect()
            }
        };
        let mut img = match &c.aprilgrid {
            Some(grid) => render_exposure(&self.rays, &poses, grid, &c.render),
            None => render_exposure(&self.rays, &poses, &c.board, &c.render),
        };
        let [gu, gv] = c.lighting_gradient;
        if gu != 0.0 || gv != 0.0 {
            apply_lighting_gradient(&mut img, gu, gv);
        }
        if c.noise_sigma > 0.0 {
            let mut rng = frame_rng(c.seed, Stream::CameraNoise as u64, k);
            add_noise(&mut img, c.noise_sigma, &mut rng);
        }
        img
    }

    /// Sharp renders over an exposure of `e` s at `t`: the largest corner motion over the
    /// exposure divided by 0.5 px, 2..=64 (sharp renders half a pixel apart average to the
    /// continuous blur within a small symmetric error that does not move corners).
    fn blur_steps(&self, t: f64, e: f64) -> usize {
        let cam = &self.config.camera;
        let (a, b) = (
            self.t_cam_target(t - e / 2.0),
            self.t_cam_target(t + e / 2.0),
        );
        let target = self.printed_target();
        let last = target.corner_count() - 1;
        // Three extreme corners: first, end of the first row, last.
        let corners = match target {
            Target::Checkerboard(t) => [0, t.cols - 1, last],
            Target::AprilGrid(t) => [0, 4 * (t.tag_cols - 1) + 1, last],
            Target::Board { .. } => [0, 0, 0],
        };
        let motion = corners
            .iter()
            .filter_map(|&id| {
                let p = target.corner(id)?;
                let pa = cam.project(&a.transform_point(&p))?.pixel;
                let pb = cam.project(&b.transform_point(&p))?.pixel;
                Some((pa - pb).norm())
            })
            .fold(0.0, f64::max);
        ((motion / 0.5).ceil() as usize).clamp(2, 64)
    }

    /// `groundtruth/corners.csv` rows of every frame.
    pub fn corner_truth(&self) -> Vec<CornerTruth> {
        let cam = &self.config.camera;
        (0..self.frame_stamps.len())
            .into_par_iter()
            .flat_map_iter(|k| {
                let stamp_ns = self.frame_stamps[k];
                self.true_corners(k)
                    .into_iter()
                    .enumerate()
                    .filter_map(move |(corner_id, p)| {
                        p.map(|pixel| CornerTruth {
                            stamp_ns,
                            corner_id,
                            pixel,
                            in_image: cam.in_image(&pixel, 0.0),
                        })
                    })
            })
            .collect()
    }

    /// The true extrinsic in result-file form (sigmas zero).
    pub fn extrinsics(&self) -> CalibrationResult {
        CalibrationResult::new().with_extrinsic(
            SectionName::CAM0,
            ExtrinsicEstimate::exact(self.t_cam_imu, self.config.time_offset_s),
        )
    }

    /// `dataset.yaml` contents.
    pub fn metadata(&self) -> DatasetYaml {
        let c = &self.config;
        DatasetYaml {
            sensors: vec!["imu0".into(), "cam0".into()],
            description: format!(
                "msreg simulator: camera-IMU, seed {}, {} s, IMU {} Hz, camera {} Hz {}x{}, \
                 {}, exposure {:?} s, noise {} grey levels, time offset {} s",
                c.seed,
                c.duration_s,
                c.imu.rate_hz,
                c.rate_hz,
                c.camera.resolution.0,
                c.camera.resolution.1,
                match &c.aprilgrid {
                    Some(g) => format!(
                        "aprilgrid {}x{} tags of {} m",
                        g.target.tag_cols, g.target.tag_rows, g.target.tag_size_m
                    ),
                    None => format!(
                        "board {}x{} inner corners at {} m",
                        c.board.rows, c.board.cols, c.board.row_spacing_m
                    ),
                },
                c.exposure_s,
                c.noise_sigma,
                c.time_offset_s
            ),
            rates_hz: BTreeMap::from([
                ("imu0".to_string(), c.imu.rate_hz),
                ("cam0".to_string(), c.rate_hz),
            ]),
        }
    }

    /// Writes the dataset layout under `dir` (created if needed), rendering the frames in
    /// parallel; `progress` gets the fraction of images written.
    pub fn write(
        &self,
        dir: impl AsRef<Path>,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        create_dirs(dir, &["imu0", CAMERA_DATA_DIR, "groundtruth"])?;
        let text = |relative: &str, content: String| write_text(&dir.join(relative), &content);
        self.metadata().write(dir.join(DATASET_YAML))?;
        write_imu_csv(dir.join(IMU_CSV), &self.imu)?;
        self.imu_noise.write(dir.join(IMU_YAML))?;
        let target_yaml = match self.printed_target() {
            Target::AprilGrid(t) => aprilgrid_yaml_string(&t),
            _ => checkerboard_yaml_string(&self.target()),
        };
        text(TARGET_YAML, target_yaml)?;
        write_groundtruth_csv(dir.join(GROUNDTRUTH_TRAJECTORY_CSV), &self.groundtruth)?;
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))?;
        let target_poses: Vec<PoseRecord> = self
            .frame_stamps
            .iter()
            .map(|&s| PoseRecord::from_isometry(s, &self.t_g_target))
            .collect();
        write_pose_csv(dir.join(GROUNDTRUTH_TARGET_POSES_CSV), &target_poses)?;
        write_corners_csv(dir.join(GROUNDTRUTH_CORNERS_CSV), &self.corner_truth())?;
        self.write_camera(dir, "cam0", progress)
    }

    /// Writes this camera's folder `name/` under `dir`: `camera.yaml`, the rendered frames in
    /// `data/` (in parallel; `progress` gets the fraction written) and `data.csv`.
    pub fn write_camera(
        &self,
        dir: &Path,
        name: &str,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Result<(), DatasetError> {
        let data_dir = format!("{name}/data");
        create_dirs(dir, &[data_dir.as_str()])?;
        write_text(
            &dir.join(name).join("camera.yaml"),
            &camera_yaml_string(&self.config.camera),
        )?;
        let frames: Vec<CameraFrame> = self
            .frame_stamps
            .iter()
            .map(|&stamp_ns| CameraFrame {
                stamp_ns,
                path: dir.join(&data_dir).join(format!("{stamp_ns}.png")),
            })
            .collect();
        let done = AtomicUsize::new(0);
        frames
            .par_iter()
            .enumerate()
            .try_for_each(|(k, frame)| -> Result<(), DatasetError> {
                write_png(&frame.path, &self.image(k))?;
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                progress(n as f64 / frames.len() as f64);
                Ok(())
            })?;
        write_camera_csv(dir.join(name).join("data.csv"), &frames)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn short(seed: u64) -> CameraImuSimConfig {
        CameraImuSimConfig {
            seed,
            duration_s: 20.0,
            ..CameraImuSimConfig::default()
        }
    }

    #[test]
    fn mountings_are_rotations_near_an_axis_aligned_one() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
        for _ in 0..50 {
            let m = random_camera_mounting(&mut rng);
            let r = m.rotation.to_rotation_matrix();
            // Every column has one entry near +-1.
            for c in 0..3 {
                let big = r.matrix().column(c).amax();
                assert!(big > 0.98, "{r}");
            }
            assert!(m.translation.vector.amax() <= 0.1);
        }
    }

    #[test]
    fn the_board_stays_in_view_and_the_camera_turns_fast_on_every_axis() -> Result<(), SimError> {
        for seed in 0..6 {
            let sim = simulate_camera_imu(&short(seed))?;
            let n = sim.frame_stamps.len();
            assert!(n >= 19 * 20, "{n} frames");
            let in_view = (0..n).filter(|&k| sim.full_board_in_view(k)).count();
            let mut max_rate = Vector3::<f64>::zeros();
            let r_c_i = sim.t_cam_imu.rotation;
            for k in 0..4000 {
                let t = 2.0 + 0.0045 * f64::from(k);
                let w_c = r_c_i * sim.trajectory.body_rate(t);
                max_rate = max_rate.zip_map(&w_c, |m, w| m.max(w.abs()));
            }
            println!(
                "seed {seed}: {in_view}/{n} frames with the full board, max rates {:?}",
                max_rate.as_slice()
            );
            assert!(
                in_view as f64 >= 0.95 * n as f64,
                "seed {seed}: {in_view}/{n}"
            );
            assert!(
                max_rate.iter().all(|&w| (0.8..3.0).contains(&w)),
                "seed {seed}: {max_rate}"
            );
        }
        Ok(())
    }
}
