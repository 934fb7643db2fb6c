//! The intrinsics simulator (`msreg simulate cameras`): `N` cameras rigidly mounted on one
//! rig, waved in front of a static Kalibr checkerboard or AprilGrid, every image rendered
//! from the trajectory through the simulator's own camera models ([`models`]: the five
//! Kalibr models written from their papers, never the estimator's code).
//!
//! - Rig: cam0 and, for `n >= 1`, camN a random `baseline_m` (default 5-15 cm) to the right
//!   of cam(N-1), offset up to 5 mm along y and z, turned by N(0, 1.5 deg) about each axis:
//!   a stereo pair by default, a row of cameras with overlapping views for more.
//! - Lenses: every camera has the `model`'s nominal lens ([`nominal_camera`]) with its own
//!   random perturbation: focal lengths x(1 +- 3 %), principal point +-8 px, each
//!   coefficient x(1 +- 15 %), `xi` / `alpha` / `beta` +-0.03.
//! - Motion ([`motion`]): the target's centre sweeps a Lissajous figure over cam0's whole
//!   image (edges and corners), tilting +-35 deg, rolling and changing distance, one period
//!   over the recording; smooth in time.
//! - Time: frame `k` of cam0 is taken and stamped at `start + k / rate`; camN is triggered
//!   `n * unsynced_s` later and stamped when taken (0: all cameras share stamps).
//! - Images: anti-aliased (8 x 8 samples on edge pixels), optional motion blur (mean of sharp
//!   renders over the exposure), Gaussian noise and a lighting gradient, 8-bit PNG.
//! - Output: `camN/data.csv` + `camN/data/*.png`, `camN/camera.yaml` with only what a user
//!   knows before calibrating (`camera_model`, `distortion_model`, `resolution`),
//!   `target.yaml`, `dataset.yaml`, and the truth in `groundtruth/`: `extrinsics.yaml` (one
//!   `camN` section per camera: Kalibr intrinsics keys and, for N >= 1, `T_cn_cnm1`),
//!   `camN/corners.csv` (true pixel of every corner per image, `groundtruth/corners.csv`
//!   columns), `trajectory.csv` (pose of cam0 in `G` = the target frame, EuRoC columns) and
//!   `target_poses.csv` (the target in `G`: identity).

pub mod models;
pub mod motion;
pub mod render;

use std::path::Path;
use std::sync::OnceLock;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use rayon::prelude::*;

use self::models::{Lens, ModelKind, SimCamera};
use self::motion::{Sweep, TargetGeometry};
use self::render::{render, RayGrid};
use super::config::{SimError, DEFAULT_START_STAMP_NS};
use super::write::{create_dirs, write_png, write_text};
use super::{frame_rng, seeded_rng};
use crate::camera_yaml::{aprilgrid_yaml_string, checkerboard_yaml_string, Target};
use crate::dataset::{
    write_camera_csv, write_corners_csv, write_groundtruth_csv, write_pose_csv, CameraFrame,
    CornerTruth, DatasetError, DatasetYaml, GroundTruthRecord, PoseRecord, DATASET_YAML,
    GROUNDTRUTH_EXTRINSICS_YAML, GROUNDTRUTH_TARGET_POSES_CSV, GROUNDTRUTH_TRAJECTORY_CSV,
    TARGET_YAML,
};
use crate::sim::camera::CameraImuSimConfig;
use crate::vision::aprilgrid::AprilGridPattern;
use crate::vision::render::{add_noise, apply_lighting_gradient, BoardPattern, RenderSettings};
use crate::vision::GrayImage;

/// This simulator's random streams (`seeded_rng`), 200 and up.
#[derive(Clone, Copy)]
enum Stream {
    Rig = 200,
    Lenses = 201,
    Sweep = 202,
    Noise = 203,
}

/// The printed target.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SimTarget {
    /// A Kalibr checkerboard with its white margin.
    Checkerboard(BoardPattern),
    /// A Kalibr AprilGrid with its white margin.
    AprilGrid(AprilGridPattern),
}

impl SimTarget {
    /// The `target.yaml` description.
    pub fn kalibr(&self) -> Target {
        match self {
            Self::Checkerboard(b) => Target::Checkerboard(crate::camera_yaml::CheckerboardTarget {
                rows: b.rows,
                cols: b.cols,
                row_spacing_m: b.row_spacing_m,
                col_spacing_m: b.col_spacing_m,
                width_m: None,
                height_m: None,
            }),
            Self::AprilGrid(g) => Target::AprilGrid(g.target),
        }
    }

    /// Centre, size and facing for the motion.
    fn geometry(&self) -> TargetGeometry {
        match self {
            Self::Checkerboard(b) => {
                let (x, y) = (
                    (b.rows - 1) as f64 * b.row_spacing_m,
                    (b.cols - 1) as f64 * b.col_spacing_m,
                );
                TargetGeometry {
                    centre: Vector3::new(x / 2.0, y / 2.0, 0.0),
                    size_m: x.max(y),
                    r_facing: TargetGeometry::checkerboard_facing(),
                }
            }
            Self::AprilGrid(g) => {
                let t = &g.target;
                let span =
                    |n: usize| (n as f64 * (1.0 + t.tag_spacing) - t.tag_spacing) * t.tag_size_m;
                let (x, y) = (span(t.tag_cols), span(t.tag_rows));
                TargetGeometry {
                    centre: Vector3::new(x / 2.0, y / 2.0, 0.0),
                    size_m: x.max(y),
                    r_facing: TargetGeometry::aprilgrid_facing(),
                }
            }
        }
    }

    fn render(
        &self,
        grid: &RayGrid,
        poses: &[Isometry3<f64>],
        settings: &RenderSettings,
    ) -> GrayImage {
        match self {
            Self::Checkerboard(b) => render(grid, poses, b, settings),
            Self::AprilGrid(g) => render(grid, poses, g, settings),
        }
    }
}

/// Everything [`simulate_cameras`] needs; deterministic per `seed`.
#[derive(Clone, Debug, PartialEq)]
pub struct CamerasSimConfig {
    /// Seeds every random draw.
    pub seed: u64,
    /// Number of cameras (1..=8).
    pub cameras: usize,
    /// The lens model of every camera.
    pub model: ModelKind,
    /// The printed target.
    pub target: SimTarget,
    /// Images per camera.
    pub frames: usize,
    /// Frame rate, Hz.
    pub rate_hz: f64,
    /// camN is triggered `n * unsynced_s` after cam0 (0: shared stamps).
    pub unsynced_s: f64,
    /// Baseline between neighbouring cameras, m: uniform in this range.
    pub baseline_m: [f64; 2],
    /// Exposure time for motion blur, s; `None`: sharp images.
    pub exposure_s: Option<f64>,
    /// Gaussian image noise, grey levels (0: none).
    pub noise_sigma: f64,
    /// Illumination gain across the image (u, v).
    pub lighting_gradient: [f32; 2],
    /// Grey levels and supersampling.
    pub render: RenderSettings,
    /// Stamp of cam0's first frame, ns.
    pub start_stamp_ns: u64,
}

impl Default for CamerasSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            cameras: 2,
            model: ModelKind::PinholeRadtan,
            target: SimTarget::Checkerboard(CameraImuSimConfig::default().board),
            frames: 100,
            rate_hz: 10.0,
            unsynced_s: 0.0,
            baseline_m: [0.05, 0.15],
            exposure_s: None,
            noise_sigma: 0.0,
            lighting_gradient: [0.0, 0.0],
            render: RenderSettings::default(),
            start_stamp_ns: DEFAULT_START_STAMP_NS,
        }
    }
}

impl CamerasSimConfig {
    /// The AprilGrid `--target aprilgrid` prints (camera-IMU's: 6 x 5 tags of 5 cm).
    pub fn default_aprilgrid() -> SimTarget {
        SimTarget::AprilGrid(CameraImuSimConfig::default_aprilgrid())
    }

    /// Motion blur (4 ms), noise (2.5 grey levels) and a lighting gradient.
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
        if !(1..=8).contains(&self.cameras) {
            return bad("cameras", "1 to 8 cameras");
        }
        if !(3..=100_000).contains(&self.frames) {
            return bad("frames", "3 to 100000 frames");
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 200.0) {
            return bad("rate_hz", "must be in (0, 200] Hz");
        }
        let period = 1.0 / self.rate_hz;
        if !(self.unsynced_s.is_finite()
            && self.unsynced_s >= 0.0
            && self.unsynced_s * (self.cameras as f64) < period)
        {
            return bad(
                "unsynced_s",
                "must be >= 0 and the last camera's delay shorter than a frame",
            );
        }
        let [b0, b1] = self.baseline_m;
        if !(b0.is_finite() && b1.is_finite() && 0.0 < b0 && b0 <= b1 && b1 <= 1.0) {
            return bad("baseline_m", "0 < min <= max <= 1 m");
        }
        if let Some(e) = self.exposure_s {
            if !(e.is_finite() && e > 0.0 && e < 0.5 * period) {
                return bad("exposure_s", "must be > 0 and shorter than half a frame");
            }
        }
        if !(self.noise_sigma.is_finite() && (0.0..50.0).contains(&self.noise_sigma)) {
            return bad("noise_sigma", "must be in [0, 50) grey levels");
        }
        if !self.lighting_gradient.iter().all(|g| g.abs() < 1.0) {
            return bad("lighting_gradient", "each gain must be within (-1, 1)");
        }
        self.validate_target()
    }

    fn validate_target(&self) -> Result<(), SimError> {
        let ok = match &self.target {
            SimTarget::Checkerboard(b) => {
                b.rows >= 3
                    && b.cols >= 3
                    && b.row_spacing_m > 0.0
                    && b.col_spacing_m > 0.0
                    && b.margin_m >= 0.0
            }
            SimTarget::AprilGrid(g) => {
                let t = &g.target;
                t.tag_cols >= 2
                    && t.tag_rows >= 2
                    && t.tag_cols * t.tag_rows <= 587
                    && t.tag_size_m > 0.0
                    && t.tag_spacing > 0.0
                    && t.tag_spacing <= 1.0
                    && g.margin_m >= 0.0
            }
        };
        if ok {
            Ok(())
        } else {
            Err(SimError::InvalidOption {
                option: "target",
                message: "3 x 3 inner corners or 2 x 2 to 587 tags, positive sizes".into(),
            })
        }
    }
}

/// The nominal camera of each model: 752 x 480 (EuRoC's sensor size).
/// - pinhole-radtan: EuRoC cam0 (~78 x 55 deg);
/// - pinhole-equidistant: a wide-angle lens (~100 x 70 deg);
/// - omni-radtan: `xi` 0.9 (~125 x 85 deg);
/// - ds: `xi` -0.18, `alpha` 0.59 (~130 x 90 deg);
/// - eucm: `alpha` 0.6, `beta` 1.05 (~120 x 85 deg).
pub fn nominal_camera(model: ModelKind) -> SimCamera {
    let (lens, f, c) = match model {
        ModelKind::PinholeRadtan => (
            Lens::PinholeRadtan {
                k: [-0.283_408, 0.073_959, 0.000_194, 1.76e-5],
            },
            [458.654, 457.296],
            [367.215, 248.375],
        ),
        ModelKind::PinholeEquidistant => (
            Lens::PinholeEquidistant {
                k: [-0.012, 0.021, -0.011, 0.002],
            },
            [320.2, 319.8],
            [377.4, 238.1],
        ),
        ModelKind::OmniRadtan => (
            Lens::OmniRadtan {
                xi: 0.9,
                k: [-0.05, 0.02, 0.0005, -0.0003],
            },
            [610.0, 608.0],
            [372.0, 243.0],
        ),
        ModelKind::DoubleSphere => (
            Lens::DoubleSphere {
                xi: -0.18,
                alpha: 0.59,
            },
            [280.0, 279.5],
            [378.0, 236.0],
        ),
        ModelKind::Eucm => (
            Lens::Eucm {
                alpha: 0.6,
                beta: 1.05,
            },
            [350.0, 349.0],
            [374.0, 242.0],
        ),
    };
    SimCamera {
        lens,
        fu: f[0],
        fv: f[1],
        cu: c[0],
        cv: c[1],
        resolution: [752, 480],
    }
}

/// `camera` with its own random perturbation (module docs).
fn perturbed(camera: &SimCamera, rng: &mut impl Rng) -> SimCamera {
    let mut c = *camera;
    c.fu *= 1.0 + rng.gen_range(-0.03..=0.03);
    c.fv = c.fu * camera.fv / camera.fu * (1.0 + rng.gen_range(-0.002..=0.002));
    let mut shift = |x: f64| x + rng.gen_range(-0.03..=0.03);
    c.lens = match camera.lens {
        Lens::PinholeRadtan { k } => Lens::PinholeRadtan { k },
        Lens::PinholeEquidistant { k } => Lens::PinholeEquidistant { k },
        Lens::OmniRadtan { xi, k } => Lens::OmniRadtan { xi: shift(xi), k },
        Lens::DoubleSphere { xi, alpha } => Lens::DoubleSphere {
            xi: shift(xi),
            alpha: shift(alpha),
        },
        Lens::Eucm { alpha, beta } => Lens::Eucm {
            alpha: shift(alpha),
            beta: shift(beta),
        },
    };
    let scale = |k: [f64; 4], rng: &mut dyn rand::RngCore| {
        k.map(|x| x * (1.0 + rng.gen_range(-0.15..=0.15)))
    };
    match &mut c.lens {
        Lens::PinholeRadtan { k } | Lens::PinholeEquidistant { k } | Lens::OmniRadtan { k, .. } => {
            *k = scale(*k, rng);
        }
        Lens::DoubleSphere { .. } | Lens::Eucm { .. } => {}
    }
    c.cu += rng.gen_range(-8.0..=8.0);
    c.cv += rng.gen_range(-8.0..=8.0);
    c
}

/// `T_cn_cnm1` of a camera `baseline` to the right of its neighbour (module docs).
fn random_neighbour(baseline: [f64; 2], rng: &mut impl Rng) -> Isometry3<f64> {
    let sigma = 1.5_f64.to_radians();
    let turn = Vector3::from_fn(|_, _| sigma * rng.sample::<f64, _>(StandardNormal));
    let r = UnitQuaternion::from_scaled_axis(turn);
    // The centre of camN in cam(N-1)'s frame.
    let centre = Vector3::new(
        rng.gen_range(baseline[0]..=baseline[1]),
        rng.gen_range(-0.005..=0.005),
        rng.gen_range(-0.005..=0.005),
    );
    // p_cnm1 = R p_cn + centre, so T_cn_cnm1 = (R^T, -R^T centre).
    let r_inv = r.inverse();
    Isometry3::from_parts(Translation3::from(-(r_inv * centre)), r_inv)
}

/// A simulated intrinsics recording; images are rendered on demand.
#[derive(Clone, Debug)]
pub struct CamerasSim {
    /// The options it was made with.
    pub config: CamerasSimConfig,
    /// The true camera of each camN.
    pub cameras: Vec<SimCamera>,
    /// `T_cn_c0` of each camera (identity for cam0).
    pub t_cn_c0: Vec<Isometry3<f64>>,
    /// The motion.
    pub sweep: Sweep,
    /// Each camera's pixel rays, computed on first use.
    grids: Vec<OnceLock<RayGrid>>,
}

/// Simulates the recording described by `config` (images on demand).
pub fn simulate_cameras(config: &CamerasSimConfig) -> Result<CamerasSim, SimError> {
    config.validate()?;
    let mut lenses = seeded_rng(config.seed, Stream::Lenses as u64);
    let nominal = nominal_camera(config.model);
    let cameras: Vec<SimCamera> = (0..config.cameras)
        .map(|_| perturbed(&nominal, &mut lenses))
        .collect();
    let mut rig = seeded_rng(config.seed, Stream::Rig as u64);
    let mut t_cn_c0 = vec![Isometry3::identity()];
    for n in 1..config.cameras {
        let t = random_neighbour(config.baseline_m, &mut rig) * t_cn_c0[n - 1];
        t_cn_c0.push(t);
    }
    let sweep = Sweep::new(
        &cameras[0],
        &config.target.geometry(),
        0.35,
        0.2,
        35f64.to_radians(),
        &mut seeded_rng(config.seed, Stream::Sweep as u64),
    )
    .ok_or(SimError::InvalidOption {
        option: "model",
        message: "the camera cannot unproject its own image centre".into(),
    })?;
    let grids = cameras.iter().map(|_| OnceLock::new()).collect();
    Ok(CamerasSim {
        config: config.clone(),
        cameras,
        t_cn_c0,
        sweep,
        grids,
    })
}

impl CamerasSim {
    /// Seconds after cam0's first frame at which camera `n` takes frame `k`.
    pub fn capture_time(&self, n: usize, k: usize) -> f64 {
        k as f64 / self.config.rate_hz + n as f64 * self.config.unsynced_s
    }

    /// Stamp of frame `k` of camera `n`, ns (its capture time).
    pub fn stamp_ns(&self, n: usize, k: usize) -> u64 {
        self.config.start_stamp_ns + (self.capture_time(n, k) * 1e9).round() as u64
    }

    /// `T_cn_target` at `t` s after cam0's first frame.
    pub fn t_cam_target(&self, n: usize, t: f64) -> Isometry3<f64> {
        let period = self.config.frames as f64 / self.config.rate_hz;
        let t_c0_t = self
            .sweep
            .t_cam_target(&self.cameras[0], t / period)
            .unwrap_or_else(Isometry3::identity);
        self.t_cn_c0[n] * t_c0_t
    }

    /// `T_cn_cnm1` of camera `n >= 1`.
    pub fn t_cn_cnm1(&self, n: usize) -> Isometry3<f64> {
        self.t_cn_c0[n] * self.t_cn_c0[n - 1].inverse()
    }

    /// The true pixel of every corner in frame `k` of camera `n` (`None`: not projectable).
    pub fn true_corners(&self, n: usize, k: usize) -> Vec<Option<Vector2<f64>>> {
        let target = self.config.target.kalibr();
        let pose = self.t_cam_target(n, self.capture_time(n, k));
        (0..target.corner_count())
            .map(|id| {
                let p = Point3::from(target.corner(id)?);
                self.cameras[n].project(&pose.transform_point(&p).coords)
            })
            .collect()
    }

    /// Frame `k` of camera `n` as rendered (blur, lighting and noise as configured), before
    /// 8-bit quantisation.
    pub fn image(&self, n: usize, k: usize) -> GrayImage {
        let c = &self.config;
        let t = self.capture_time(n, k);
        let poses: Vec<Isometry3<f64>> = match c.exposure_s {
            None => vec![self.t_cam_target(n, t)],
            Some(e) => {
                let steps = self.blur_steps(n, t, e);
                (0..steps)
                    .map(|j| self.t_cam_target(n, t + e * ((j as f64 + 0.5) / steps as f64 - 0.5)))
                    .collect()
            }
        };
        let grid = self.grids[n].get_or_init(|| RayGrid::new(&self.cameras[n]));
        let mut img = c.target.render(grid, &poses, &c.render);
        let [gu, gv] = c.lighting_gradient;
        if gu != 0.0 || gv != 0.0 {
            apply_lighting_gradient(&mut img, gu, gv);
        }
        if c.noise_sigma > 0.0 {
            let stream = Stream::Noise as u64 + 16 * n as u64;
            add_noise(&mut img, c.noise_sigma, &mut frame_rng(c.seed, stream, k));
        }
        img
    }

    /// Sharp renders over an exposure `e` at `t`: the largest corner motion over it in
    /// steps of 0.5 px, 2..=64.
    fn blur_steps(&self, n: usize, t: f64, e: f64) -> usize {
        let target = self.config.target.kalibr();
        let (a, b) = (
            self.t_cam_target(n, t - e / 2.0),
            self.t_cam_target(n, t + e / 2.0),
        );
        let cam = &self.cameras[n];
        let last = target.corner_count() - 1;
        let motion = [0, last / 2, last]
            .iter()
            .filter_map(|&id| {
                let p = Point3::from(target.corner(id)?);
                let pa = cam.project(&a.transform_point(&p).coords)?;
                let pb = cam.project(&b.transform_point(&p).coords)?;
                Some((pa - pb).norm())
            })
            .fold(0.0, f64::max);
        ((motion / 0.5).ceil() as usize).clamp(2, 64)
    }
}

mod write_dataset;

pub use write_dataset::{camera_dir, groundtruth_corners_csv};

#[cfg(test)]
mod tests;
