//! The LiDAR-camera simulator behind every accuracy claim of chapter 2: a static suite (a
//! spinning LiDAR and a 1280x960 camera, rigidly mounted with a known `T_cam_lidar`) and a
//! plain bright board held still at `poses` places 2-6 m away, in front of a darker
//! textured wall above a ground plane.
//!
//! - World: the LiDAR frame `L` (x forward, z up); wall `x = 8.5 m`, ground `z = -1.4 m`.
//! - Board poses: centre on a random camera ray 2-6 m out, facing the camera within
//!   +-30 deg of tilt about two axes, rolled 30-60 deg about its normal so that all four
//!   edges cross the rings (each edge spans at least 5 ring elevations); all corners
//!   inside the image with a 30 px margin and the centre inside the LiDAR's dense
//!   elevation band.
//! - LiDAR ([`LidarModel`]): VLP-32C-like (32 rings at the Velodyne's non-uniform
//!   elevations, 1800 columns, 1 cm range noise) or Ouster OS1-64-like (64 uniform rings
//!   over +-16.6 deg, 2048 columns, 3 cm range noise); only the forward +-80 deg sector is
//!   cast (the rest can never be in the camera's view and would only inflate the files).
//! - Camera: pinhole with radial-tangential distortion; every pixel corner's bearing is
//!   computed once per dataset and cast once per frame; pixels crossed by a board edge are
//!   supersampled 6x6 (anti-aliased edges, as in [`crate::vision::render`]), others take
//!   the mean of their corners; then a 0.6 px Gaussian blur and 2 grey levels of noise.
//! - Bad frames (option): board out of view, board cut by the image border, board seen
//!   almost edge-on (84 deg) — the calibration must reject each with a reason.
//! - Randomness: `super::seeded_rng` seeded with `seed`, one stream per component
//!   (`Stream`), each scan's and image's draws from their own block (`super::frame_rng`).

use std::path::Path;

use msreg_estimator::camera::{radtan::RadTan, Camera, Distortion, Intrinsics, Projection};
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

use super::write::{create_dirs, write_png, write_scan, write_text};
use super::{frame_rng, seeded_rng, SimError, DEFAULT_START_STAMP_NS};
use crate::camera_yaml::{board_yaml_string, camera_yaml_string, Board};
use crate::dataset::{
    write_camera_csv, write_pose_csv, CalibrationResult, CameraFrame, DatasetError, DatasetYaml,
    ExtrinsicEstimate, LidarYaml, PoseRecord, SectionName, CAMERA_CSV, CAMERA_DATA_DIR,
    CAMERA_YAML, DATASET_YAML, GROUNDTRUTH_EXTRINSICS_YAML, GROUNDTRUTH_TARGET_POSES_CSV,
    LIDAR_DIR, LIDAR_YAML, TARGET_YAML,
};
use crate::pointcloud::{Point, PointCloud};
use crate::vision::render::add_noise;
use crate::vision::GrayImage;

/// Wall plane `x = WALL_X` in `L`, m.
const WALL_X: f64 = 8.5;
/// Ground plane `z = GROUND_Z` in `L`, m.
const GROUND_Z: f64 = -1.4;
/// Half-width of the cast azimuth sector, deg.
const SECTOR_DEG: f64 = 80.0;
/// Grey level of the board.
const BOARD_GREY: f32 = 215.0;

/// The spinning LiDAR's beam layout and noise.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum LidarModel {
    /// Velodyne VLP-32C-like: non-uniform rings dense near the horizon, 1 cm noise.
    #[default]
    Vlp32,
    /// Ouster OS1-64-like: uniform rings, 3 cm noise (the dissertation's noisy LiDAR).
    Ouster,
}

/// VLP-32C beam elevations, deg, lowest first.
const VLP32_ELEVATIONS: [f64; 32] = [
    -25.0, -15.639, -11.31, -8.843, -7.254, -6.148, -5.333, -4.667, -4.0, -3.667, -3.333, -3.0,
    -2.667, -2.333, -2.0, -1.667, -1.333, -1.0, -0.667, -0.333, 0.0, 0.333, 0.667, 1.0, 1.333,
    1.667, 2.333, 3.333, 4.667, 7.0, 10.333, 15.0,
];

impl LidarModel {
    /// Beam elevations, deg, ring 0 lowest.
    pub fn elevations_deg(self) -> Vec<f64> {
        match self {
            Self::Vlp32 => VLP32_ELEVATIONS.to_vec(),
            Self::Ouster => (0..64).map(|r| -16.6 + 33.2 * r as f64 / 63.0).collect(),
        }
    }

    /// Firings per revolution.
    pub fn columns(self) -> usize {
        match self {
            Self::Vlp32 => 1800,
            Self::Ouster => 2048,
        }
    }

    /// 1-sigma range noise, m.
    pub fn range_noise_m(self) -> f64 {
        match self {
            Self::Vlp32 => 0.01,
            Self::Ouster => 0.03,
        }
    }

    /// Elevation band (deg) the board centre is kept in, where the rings are dense enough.
    fn centre_band_deg(self) -> (f64, f64) {
        match self {
            Self::Vlp32 => (-5.0, 2.5),
            Self::Ouster => (-9.0, 9.0),
        }
    }

    /// Name for descriptions and the CLI.
    pub fn name(self) -> &'static str {
        match self {
            Self::Vlp32 => "vlp32",
            Self::Ouster => "ouster",
        }
    }
}

/// What a frame shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameKind {
    /// The board fully in view of both sensors.
    Good,
    /// The board is behind the sensors: in neither view.
    Missing,
    /// Part of the board is outside the image.
    CutByBorder,
    /// The board is seen almost edge-on.
    EdgeOn,
}

/// One still pose of the board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimFrame {
    /// Stamp of the LiDAR scan (first firing), ns.
    pub scan_stamp_ns: u64,
    /// Stamp of the image, ns (20 ms after the scan; the board is still).
    pub image_stamp_ns: u64,
    /// Pose of the board in the LiDAR frame.
    pub t_lidar_target: Isometry3<f64>,
    /// What the frame shows.
    pub kind: FrameKind,
}

/// Everything [`simulate_lidar_camera`] needs; deterministic per `seed`.
#[derive(Clone, Debug, PartialEq)]
pub struct LidarCameraSimConfig {
    /// Seeds every random draw.
    pub seed: u64,
    /// The LiDAR.
    pub lidar: LidarModel,
    /// Good board poses.
    pub poses: usize,
    /// The board.
    pub board: Board,
    /// Append one frame of each bad kind (missing, cut by the border, edge-on).
    pub bad_frames: bool,
    /// Stamp of the first scan, ns.
    pub start_stamp_ns: u64,
    /// Image noise, grey levels (1 sigma).
    pub image_noise: f64,
    /// Optical blur, pixels (Gaussian sigma).
    pub blur_px: f64,
}

impl Default for LidarCameraSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            lidar: LidarModel::Vlp32,
            poses: 30,
            board: Board {
                width_m: 1.0,
                height_m: 0.8,
            },
            bad_frames: false,
            start_stamp_ns: DEFAULT_START_STAMP_NS,
            image_noise: 2.0,
            blur_px: 0.6,
        }
    }
}

/// Random stream of each component (this scenario's own numbering: its datasets do not
/// share draws with the pose-IMU family's `super::Stream`).
#[derive(Clone, Copy)]
enum Stream {
    Mounting = 1,
    Poses = 2,
    Range = 3,
    Image = 4,
}

/// The simulated recording; scans and images are made on demand.
#[derive(Clone, Debug)]
pub struct LidarCameraSim {
    /// The options it was made with.
    pub config: LidarCameraSimConfig,
    /// The camera (intrinsics and distortion as written to `cam0/camera.yaml`).
    pub camera: Camera<f64>,
    /// True `T_cam_lidar`.
    pub t_cam_lidar: Isometry3<f64>,
    /// The frames, in time order.
    pub frames: Vec<SimFrame>,
    /// Unit bearing of every pixel corner `(x - 0.5, y - 0.5)`, row-major, `(w+1) x (h+1)`.
    corner_bearings: Vec<[f32; 3]>,
}

/// The simulated camera: 1280x960, about 63 x 49 deg, mild barrel distortion.
pub fn sim_camera() -> Result<Camera<f64>, SimError> {
    Camera::new(
        Projection::Pinhole,
        Intrinsics {
            fu: 1050.0,
            fv: 1048.0,
            cu: 641.3,
            cv: 479.1,
        },
        Distortion::RadTan(RadTan {
            k1: -0.12,
            k2: 0.08,
            p1: 0.0005,
            p2: -0.0003,
            k3: 0.0,
        }),
        (1280, 960),
    )
    .map_err(|e| SimError::InvalidOption {
        option: "camera",
        message: format!("{e:?}"),
    })
}

/// `T_cam_lidar`: the camera looks along the LiDAR's x axis (camera z = LiDAR x, camera
/// x = -LiDAR y), each axis tilted by N(0, 3 deg), mounted about 20 cm from the LiDAR.
pub fn random_camera_mounting(rng: &mut impl Rng) -> Isometry3<f64> {
    let r_l_c = Matrix3::new(0.0, 0.0, 1.0, -1.0, 0.0, 0.0, 0.0, -1.0, 0.0);
    let sigma = 3.0_f64.to_radians();
    let tilt = Vector3::from_fn(|_, _| sigma * rng.sample::<f64, _>(StandardNormal));
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r_l_c))
        * UnitQuaternion::from_scaled_axis(tilt);
    let p = Vector3::new(0.08, -0.15, -0.10) + Vector3::from_fn(|_, _| rng.gen_range(-0.05..0.05));
    let t_lidar_cam = Isometry3::from_parts(Translation3::from(p), rotation);
    t_lidar_cam.inverse()
}

impl LidarCameraSimConfig {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), SimError> {
        let bad = |option: &'static str, message: &str| {
            Err(SimError::InvalidOption {
                option,
                message: message.into(),
            })
        };
        if !(1..=1000).contains(&self.poses) {
            return bad("poses", "must be in 1..=1000");
        }
        let b = &self.board;
        if !(b.width_m >= 0.3 && b.width_m <= 2.0 && b.height_m >= 0.3 && b.height_m <= 2.0) {
            return bad("board", "width and height must be in [0.3, 2] m");
        }
        if !(self.image_noise.is_finite() && (0.0..50.0).contains(&self.image_noise)) {
            return bad("image_noise", "must be in [0, 50)");
        }
        if !(self.blur_px.is_finite() && (0.0..5.0).contains(&self.blur_px)) {
            return bad("blur_px", "must be in [0, 5)");
        }
        Ok(())
    }
}

/// Simulates the recording described by `config` (poses now, scans and images on demand).
pub fn simulate_lidar_camera(config: &LidarCameraSimConfig) -> Result<LidarCameraSim, SimError> {
    config.validate()?;
    let camera = sim_camera()?;
    let t_cam_lidar = random_camera_mounting(&mut seeded_rng(config.seed, Stream::Mounting as u64));
    let t_lidar_cam = t_cam_lidar.inverse();
    let mut rng = seeded_rng(config.seed, Stream::Poses as u64);
    let mut poses = Vec::with_capacity(config.poses + 3);
    while poses.len() < config.poses {
        if let Some(p) = sample_good_pose(config, &camera, &t_lidar_cam, &mut rng) {
            poses.push((p, FrameKind::Good));
        }
    }
    if config.bad_frames {
        poses.push((
            Isometry3::from_parts(
                Translation3::new(-3.0, 0.5, 0.0),
                UnitQuaternion::from_euler_angles(0.0, -std::f64::consts::FRAC_PI_2, 0.0),
            ),
            FrameKind::Missing,
        ));
        poses.push((
            facing_pose(
                &camera,
                &t_lidar_cam,
                (1230.0, 470.0),
                3.0,
                [0.0, 0.0, 45.0],
            ),
            FrameKind::CutByBorder,
        ));
        poses.push((
            facing_pose(
                &camera,
                &t_lidar_cam,
                (640.0, 520.0),
                3.5,
                [0.0, 84.0, 40.0],
            ),
            FrameKind::EdgeOn,
        ));
    }
    let frames = poses
        .into_iter()
        .enumerate()
        .map(|(k, (t_lidar_target, kind))| {
            let scan_stamp_ns = config.start_stamp_ns + k as u64 * 2_000_000_000;
            SimFrame {
                scan_stamp_ns,
                image_stamp_ns: scan_stamp_ns + 20_000_000,
                t_lidar_target,
                kind,
            }
        })
        .collect();
    let (w, h) = (camera.resolution.0 as usize, camera.resolution.1 as usize);
    let corner_bearings = (0..(w + 1) * (h + 1))
        .into_par_iter()
        .map(|i| {
            let (x, y) = (i % (w + 1), i / (w + 1));
            let b = camera
                .unproject(&Vector2::new(x as f64 - 0.5, y as f64 - 0.5))
                .unwrap_or_else(Vector3::z);
            [b.x as f32, b.y as f32, b.z as f32]
        })
        .collect();
    Ok(LidarCameraSim {
        config: config.clone(),
        camera,
        t_cam_lidar,
        frames,
        corner_bearings,
    })
}

/// The board centred on the ray of `pixel` at `distance`, facing the camera, then rotated
/// by `[tilt_x, tilt_y, roll]` deg about its own axes.
fn facing_pose(
    camera: &Camera<f64>,
    t_lidar_cam: &Isometry3<f64>,
    pixel: (f64, f64),
    distance: f64,
    angles_deg: [f64; 3],
) -> Isometry3<f64> {
    let bearing = camera
        .unproject(&Vector2::new(pixel.0, pixel.1))
        .unwrap_or_else(Vector3::z);
    let centre = t_lidar_cam * nalgebra::Point3::from(bearing * distance);
    let cam = t_lidar_cam.translation.vector;
    let z = (cam - centre.coords).normalize();
    let x = Vector3::z().cross(&z).normalize();
    let y = z.cross(&x);
    let base = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(
        Matrix3::from_columns(&[x, y, z]),
    ));
    let [a, b, c] = angles_deg.map(f64::to_radians);
    let rotation = base
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), a)
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), b)
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), c);
    Isometry3::from_parts(Translation3::from(centre.coords), rotation)
}

fn sample_good_pose(
    config: &LidarCameraSimConfig,
    camera: &Camera<f64>,
    t_lidar_cam: &Isometry3<f64>,
    rng: &mut ChaCha8Rng,
) -> Option<Isometry3<f64>> {
    let pixel = (rng.gen_range(200.0..1080.0), rng.gen_range(150.0..810.0));
    let distance = rng.gen_range(2.0..6.0);
    let roll = rng.gen_range(30.0..60.0) * if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
    let angles = [rng.gen_range(-30.0..30.0), rng.gen_range(-30.0..30.0), roll];
    let pose = facing_pose(camera, t_lidar_cam, pixel, distance, angles);
    let centre = pose.translation.vector;
    let elevation = centre.z.atan2(centre.xy().norm()).to_degrees();
    let (lo, hi) = config.lidar.centre_band_deg();
    if !(lo..=hi).contains(&elevation) {
        return None;
    }
    // Every edge must cross at least 5 rings (so the LiDAR can fit all four lines).
    let elevations = config.lidar.elevations_deg();
    let corners = config
        .board
        .corners()
        .map(|c| pose * nalgebra::Point3::from(c));
    for j in 0..4 {
        let el = |p: &nalgebra::Point3<f64>| p.z.atan2(p.coords.xy().norm()).to_degrees();
        let (a, b) = (el(&corners[j]), el(&corners[(j + 1) % 4]));
        let crossed = elevations
            .iter()
            .filter(|&&e| e > a.min(b) && e < a.max(b))
            .count();
        if crossed < 5 {
            return None;
        }
    }
    let t_cam_target = t_lidar_cam.inverse() * pose;
    for c in config.board.corners() {
        let in_l = pose * nalgebra::Point3::from(c);
        if in_l.z < GROUND_Z + 0.1 {
            return None;
        }
        let in_c = t_cam_target * nalgebra::Point3::from(c);
        let px = camera.project(&in_c.coords)?;
        if !camera.in_image(&px.pixel, 30.0) {
            return None;
        }
    }
    Some(pose)
}

/// A surface hit along a ray: distance and what was hit.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Hit {
    Board,
    /// Wall point (y, z).
    Wall(f64, f64),
    /// Ground point (x, y).
    Ground(f64, f64),
}

/// The board of one frame, precomputed for ray casting.
struct Scene {
    half: (f64, f64),
    centre: Vector3<f64>,
    normal: Vector3<f64>,
    x_axis: Vector3<f64>,
    y_axis: Vector3<f64>,
}

impl Scene {
    fn new(board: &Board, t_l_t: &Isometry3<f64>) -> Self {
        let r = t_l_t.rotation.to_rotation_matrix().into_inner();
        Self {
            half: (0.5 * board.width_m, 0.5 * board.height_m),
            centre: t_l_t.translation.vector,
            normal: r.column(2).into_owned(),
            x_axis: r.column(0).into_owned(),
            y_axis: r.column(1).into_owned(),
        }
    }

    /// First hit of the ray `origin + s dir` (`s > 0`).
    fn cast(&self, origin: &Vector3<f64>, dir: &Vector3<f64>) -> Option<(f64, Hit)> {
        let mut best: Option<(f64, Hit)> = None;
        let mut consider = |s: f64, hit: Hit| {
            if s > 1e-9 && best.is_none_or(|(b, _)| s < b) {
                best = Some((s, hit));
            }
        };
        let denom = self.normal.dot(dir);
        if denom.abs() > 1e-12 {
            let s = self.normal.dot(&(self.centre - origin)) / denom;
            let d = origin + dir * s - self.centre;
            if self.x_axis.dot(&d).abs() <= self.half.0 && self.y_axis.dot(&d).abs() <= self.half.1
            {
                consider(s, Hit::Board);
            }
        }
        if dir.x > 1e-12 {
            let s = (WALL_X - origin.x) / dir.x;
            let p = origin + dir * s;
            consider(s, Hit::Wall(p.y, p.z));
        }
        if dir.z < -1e-12 {
            let s = (GROUND_Z - origin.z) / dir.z;
            let p = origin + dir * s;
            consider(s, Hit::Ground(p.x, p.y));
        }
        best
    }
}

/// Smooth value noise in [0, 1] on a unit grid (bilinear between hashed lattice values).
fn value_noise(x: f64, y: f64, salt: u64) -> f64 {
    let lattice = |i: i64, j: i64| -> f64 {
        let h = (i as u64)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add((j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
            .wrapping_add(salt.wrapping_mul(0x1656_67B1_9E37_79F9));
        let h = (h ^ (h >> 29)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        ((h >> 40) & 0xFFFF) as f64 / 65535.0
    };
    let (fx, fy) = (x.floor(), y.floor());
    let (i, j) = (fx as i64, fy as i64);
    let (u, v) = (x - fx, y - fy);
    let a = lattice(i, j) * (1.0 - u) + lattice(i + 1, j) * u;
    let b = lattice(i, j + 1) * (1.0 - u) + lattice(i + 1, j + 1) * u;
    a * (1.0 - v) + b * v
}

fn grey(hit: Hit) -> f32 {
    match hit {
        Hit::Board => BOARD_GREY,
        Hit::Wall(y, z) => {
            (40.0
                + 55.0 * value_noise(y / 0.12, z / 0.12, 1)
                + 25.0 * value_noise(y / 0.03, z / 0.03, 2)) as f32
        }
        Hit::Ground(x, y) => (60.0 + 50.0 * value_noise(x / 0.2, y / 0.2, 3)) as f32,
    }
}

impl LidarCameraSim {
    /// `T_cam_target` of frame `k`.
    pub fn t_cam_target(&self, k: usize) -> Option<Isometry3<f64>> {
        Some(self.t_cam_lidar * self.frames.get(k)?.t_lidar_target)
    }

    /// The LiDAR scan of frame `k` (forward sector only, see the module docs).
    pub fn scan(&self, k: usize) -> PointCloud {
        let Some(frame) = self.frames.get(k) else {
            return PointCloud::default();
        };
        let model = self.config.lidar;
        let columns = model.columns();
        let elevations = model.elevations_deg();
        let mut rng = frame_rng(self.config.seed, Stream::Range as u64, k);
        let mut points = Vec::new();
        let origin = Vector3::zeros();
        let scene = Scene::new(&self.config.board, &frame.t_lidar_target);
        for c in 0..columns {
            let mut az = 360.0 * c as f64 / columns as f64;
            if az > 180.0 {
                az -= 360.0;
            }
            if az.abs() > SECTOR_DEG {
                continue;
            }
            let (sa, ca) = az.to_radians().sin_cos();
            let t_ns = (c as f64 * 1e8 / columns as f64).round() as u32;
            for (r, el) in elevations.iter().enumerate() {
                let (se, ce) = el.to_radians().sin_cos();
                let dir = Vector3::new(ce * ca, ce * sa, se);
                let noise = model.range_noise_m() * rng.sample::<f64, _>(StandardNormal);
                let Some((range, hit)) = scene.cast(&origin, &dir) else {
                    continue;
                };
                let intensity = match hit {
                    Hit::Board => 180.0,
                    Hit::Wall(..) => 40.0,
                    Hit::Ground(..) => 20.0,
                };
                let range = range + noise;
                if !(0.5..=100.0).contains(&range) {
                    continue;
                }
                points.push(Point {
                    xyz: dir * range,
                    intensity,
                    t_ns,
                    ring: r as u16,
                });
            }
        }
        PointCloud::new(points)
    }

    /// The image of frame `k`.
    pub fn image(&self, k: usize) -> GrayImage {
        let (w, h) = (
            self.camera.resolution.0 as usize,
            self.camera.resolution.1 as usize,
        );
        let Some(frame) = self.frames.get(k) else {
            return GrayImage::new(w, h, 0.0);
        };
        let t_lidar_cam = self.t_cam_lidar.inverse();
        let origin = t_lidar_cam.translation.vector;
        let rot = t_lidar_cam.rotation.to_rotation_matrix().into_inner();
        let scene = Scene::new(&self.config.board, &frame.t_lidar_target);
        let hit_of = |b: &Vector3<f64>| scene.cast(&origin, &(rot * b)).map(|(_, hit)| hit);
        // Surface kind and grey level at every pixel corner, cast once.
        let kind = |h: Option<Hit>| match h {
            None => 0u8,
            Some(Hit::Board) => 1,
            Some(Hit::Wall(..)) => 2,
            Some(Hit::Ground(..)) => 3,
        };
        let corners: Vec<(u8, f32)> = self
            .corner_bearings
            .par_iter()
            .map(|b| {
                let b = Vector3::new(f64::from(b[0]), f64::from(b[1]), f64::from(b[2]));
                let hit = hit_of(&b);
                (kind(hit), hit.map_or(0.0, grey))
            })
            .collect();
        let data: Vec<f32> = (0..w * h)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let c = [
                    corners[y * (w + 1) + x],
                    corners[y * (w + 1) + x + 1],
                    corners[(y + 1) * (w + 1) + x],
                    corners[(y + 1) * (w + 1) + x + 1],
                ];
                if c.iter().all(|k| k.0 == c[0].0) || c.iter().all(|k| k.0 != 1) {
                    // One surface (or only background, smooth at pixel scale): average the
                    // corners.
                    return 0.25 * c.iter().map(|k| k.1).sum::<f32>();
                }
                // A board edge crosses the pixel: 6x6 samples, bearings interpolated between
                // the corners' (distortion is linear to 1e-6 px within a pixel).
                let b = |xx: usize, yy: usize| {
                    let b = self.corner_bearings[yy * (w + 1) + xx];
                    Vector3::new(f64::from(b[0]), f64::from(b[1]), f64::from(b[2]))
                };
                let (b00, b10, b01, b11) = (b(x, y), b(x + 1, y), b(x, y + 1), b(x + 1, y + 1));
                let n = 6;
                let mut acc = 0.0;
                for sy in 0..n {
                    for sx in 0..n {
                        let u = (sx as f64 + 0.5) / n as f64;
                        let v = (sy as f64 + 0.5) / n as f64;
                        let bearing = (b00 * (1.0 - u) + b10 * u) * (1.0 - v)
                            + (b01 * (1.0 - u) + b11 * u) * v;
                        acc += hit_of(&bearing).map_or(0.0, grey);
                    }
                }
                acc / (n * n) as f32
            })
            .collect();
        let img = GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0));
        let mut img = img.gaussian_blur(self.config.blur_px);
        add_noise(
            &mut img,
            self.config.image_noise,
            &mut frame_rng(self.config.seed, Stream::Image as u64, k),
        );
        img
    }

    /// The true extrinsic in result-file form (sigmas zero).
    pub fn extrinsics(&self) -> CalibrationResult {
        CalibrationResult::new().with_extrinsic(
            SectionName::CAM0_LIDAR0,
            ExtrinsicEstimate::exact(self.t_cam_lidar, 0.0),
        )
    }

    /// Writes the dataset layout under `dir` (created if needed); `progress` gets the
    /// fraction of frames written.
    pub fn write(
        &self,
        dir: impl AsRef<Path>,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(), DatasetError> {
        let dir = dir.as_ref();
        create_dirs(dir, &[LIDAR_DIR, CAMERA_DATA_DIR, "groundtruth"])?;
        let c = &self.config;
        self.metadata().write(dir.join(DATASET_YAML))?;
        LidarYaml {
            rings: Some(c.lidar.elevations_deg().len() as u32),
            columns: Some(c.lidar.columns() as u32),
            scan_rate_hz: Some(10.0),
            range_noise_m: Some(c.lidar.range_noise_m()),
        }
        .write(dir.join(LIDAR_YAML))?;
        write_text(&dir.join(CAMERA_YAML), &camera_yaml_string(&self.camera))?;
        write_text(&dir.join(TARGET_YAML), &board_yaml_string(&c.board))?;
        self.extrinsics()
            .write(dir.join(GROUNDTRUTH_EXTRINSICS_YAML))?;
        let mut images = Vec::with_capacity(self.frames.len());
        for (k, frame) in self.frames.iter().enumerate() {
            let scan = dir
                .join(LIDAR_DIR)
                .join(format!("{}.pcd", frame.scan_stamp_ns));
            write_scan(&scan, &self.scan(k))?;
            let image = CameraFrame {
                stamp_ns: frame.image_stamp_ns,
                path: dir
                    .join(CAMERA_DATA_DIR)
                    .join(format!("{}.png", frame.image_stamp_ns)),
            };
            write_png(&image.path, &self.image(k))?;
            images.push(image);
            progress((k + 1) as f64 / self.frames.len() as f64);
        }
        write_camera_csv(dir.join(CAMERA_CSV), &images)?;
        // The board's pose in G = the LiDAR frame, stamped with its scan.
        let targets: Vec<PoseRecord> = self
            .frames
            .iter()
            .map(|f| PoseRecord::from_isometry(f.scan_stamp_ns, &f.t_lidar_target))
            .collect();
        write_pose_csv(dir.join(GROUNDTRUTH_TARGET_POSES_CSV), &targets)
    }

    /// `dataset.yaml` contents.
    pub fn metadata(&self) -> DatasetYaml {
        let c = &self.config;
        DatasetYaml {
            sensors: vec!["lidar0".into(), "cam0".into()],
            description: format!(
                "msreg simulator: LiDAR-camera (static suite, plain board), seed {}, LiDAR {}, \
                 {} board poses{}",
                c.seed,
                c.lidar.name(),
                c.poses,
                if c.bad_frames { " + 3 bad frames" } else { "" }
            ),
            rates_hz: Default::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn good_poses_put_the_board_in_both_views() -> Result<(), SimError> {
        let sim = simulate_lidar_camera(&LidarCameraSimConfig {
            poses: 4,
            ..LidarCameraSimConfig::default()
        })?;
        for k in 0..4 {
            let scan = sim.scan(k);
            let on_board = scan.points.iter().filter(|p| p.intensity > 100.0).count();
            assert!(on_board > 100, "frame {k}: {on_board} board returns");
        }
        let img = sim.image(0);
        let bright = img.data().iter().filter(|&&v| v > 180.0).count();
        assert!(bright > 5000, "{bright} bright pixels");
        Ok(())
    }
}
