//! `msreg simulate prior-map`: a static downward fisheye at an intersection registered in
//! a prior map (dissertation chapter 7). The ground ([`super::prior_map_scene`]) is seen
//! three ways, each with its own appearance:
//!
//! - the LiDAR map `map/map.pcd`: points on z = 0 (1 cm height noise) whose intensity is the
//!   near-infrared reflectivity (grass bright, paint retro-reflective) plus noise;
//! - the metric satellite ortho image `map/satellite.png`: the visible albedo through another
//!   tone curve, building / tree shadows, area-averaged pixels and noise;
//! - the fisheye image `cam0/data/<stamp>.png`: ray-cast from the geometry with
//!   [`crate::mi::synthetic::ray_cast_ground`] (2 x 2 rays per pixel), with its own tone
//!   curve, gain, a lighting gradient, vignetting and noise.
//!
//! The camera stands 6-10 m above the ground near the centre, looking down with a few
//! degrees of tilt and any yaw. `prior.yaml` holds a GPS-like position 2-5 m off
//! horizontally (0.5 m vertically) and no yaw; `survey.csv` the true pixels of patch corners
//! and manhole centres; `groundtruth/extrinsics.yaml` the true `cam0.T_world_cam`.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use msreg_estimator::camera::{
    equidistant::Equidistant, radtan::RadTan, Camera, Distortion, Intrinsics, Projection,
};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use super::prior_map_scene::{Intersection, Shadows};
use super::seeded_rng;
use super::write::{create_dirs, write_png, write_scan, write_text};
use crate::camera_yaml::camera_yaml_string;
use crate::dataset::{
    write_camera_csv, CameraFrame, DatasetError, DatasetYaml, CAMERA_CSV, CAMERA_DATA_DIR,
    CAMERA_YAML, DATASET_YAML,
};
use crate::mi::prior_map::input::Survey;
use crate::mi::prior_map::t_world_cam_yaml;
use crate::mi::synthetic::ray_cast_ground;
use crate::pointcloud::{Point, PointCloud};
use crate::vision::GrayImage;

/// Stamp of the single fisheye image (ns).
pub const IMAGE_STAMP_NS: u64 = 1_700_000_000_000_000_000;

/// Fisheye camera model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FisheyeModel {
    /// Pinhole + equidistant (Kannala-Brandt) distortion.
    Equidistant,
    /// Mei's unified model (Kalibr `omni`) with small radtan distortion.
    Omni,
}

/// Simulator settings.
#[derive(Clone, Debug, PartialEq)]
pub struct PriorMapSimConfig {
    /// Random seed.
    pub seed: u64,
    /// Camera model.
    pub model: FisheyeModel,
    /// Square image size (px).
    pub resolution: u32,
    /// The map covers |x|, |y| < this (m).
    pub map_half_m: f64,
    /// LiDAR map points.
    pub map_points: usize,
    /// Satellite ground sampling (m per px).
    pub satellite_m_per_px: f64,
    /// Horizontal GPS error (m); `None` draws 2-5 m.
    pub prior_offset_m: Option<f64>,
    /// Fisheye image noise (grey levels, 1 sigma).
    pub image_noise: f64,
}

impl Default for PriorMapSimConfig {
    fn default() -> Self {
        Self {
            seed: 0,
            model: FisheyeModel::Equidistant,
            resolution: 800,
            map_half_m: 30.0,
            map_points: 150_000,
            satellite_m_per_px: 0.08,
            prior_offset_m: None,
            image_noise: 3.0,
        }
    }
}

impl PriorMapSimConfig {
    /// A small problem for CI: 400 px image, 20 m map, 40k points, 0.1 m satellite pixels.
    pub fn small(seed: u64) -> Self {
        Self {
            seed,
            resolution: 400,
            map_half_m: 20.0,
            map_points: 40_000,
            satellite_m_per_px: 0.1,
            ..Self::default()
        }
    }
}

/// The prior of `prior.yaml`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsPrior {
    /// Position of the camera in W (m).
    pub position: Vector3<f64>,
    /// 1-sigma per axis (m).
    pub sigma_m: Vector3<f64>,
}

/// The simulated dataset.
#[derive(Clone, Debug)]
pub struct PriorMapSim {
    /// Settings.
    pub config: PriorMapSimConfig,
    /// The LiDAR map (W).
    pub map: PointCloud,
    /// Satellite ortho image (0-255).
    pub satellite: GrayImage,
    /// W (x, y) of the satellite's top-left pixel centre.
    pub satellite_top_left: Vector2<f64>,
    /// The camera.
    pub camera: Camera<f64>,
    /// The fisheye image (0-255).
    pub image: GrayImage,
    /// True `T_world_cam`.
    pub t_world_cam: Isometry3<f64>,
    /// The GPS prior.
    pub prior: GpsPrior,
    /// Check points.
    pub survey: Vec<Survey>,
}

/// The random stream `stream` of the prior-map scenario (streams 100 and up of [`seeded_rng`]).
fn rng(seed: u64, stream: u64) -> ChaCha8Rng {
    seeded_rng(seed, 100 + stream)
}

/// The fisheye of `model` for a square image of `size` px (about 190 deg field of view).
pub fn fisheye_camera(model: FisheyeModel, size: u32) -> Camera<f64> {
    let c = (size as f64 - 1.0) / 2.0;
    let (projection, f, distortion) = match model {
        // Equidistant: r = f theta, 95 deg at 0.97 of the half size.
        FisheyeModel::Equidistant => (
            Projection::Pinhole,
            0.97 * c / 95f64.to_radians(),
            Distortion::Equidistant(Equidistant {
                k1: 0.015,
                k2: -0.004,
                k3: 0.0,
                k4: 0.0,
            }),
        ),
        // Unified: r = f sin(theta) / (cos(theta) + xi), 90 deg at 0.95 of the half size.
        FisheyeModel::Omni => (
            Projection::Omni { xi: 0.9 },
            0.95 * c * 0.9,
            Distortion::RadTan(RadTan {
                k1: -0.03,
                k2: 0.004,
                p1: 2e-4,
                p2: -1e-4,
                k3: 0.0,
            }),
        ),
    };
    Camera::new(
        projection,
        Intrinsics {
            fu: f,
            fv: f * 1.002,
            cu: c + 1.3,
            cv: c - 0.8,
        },
        distortion,
        (size, size),
    )
    .unwrap_or_else(|_| unreachable!("valid constants"))
}

/// Simulates the dataset.
pub fn simulate_prior_map(config: &PriorMapSimConfig) -> PriorMapSim {
    let half = config.map_half_m;
    let scene = Intersection::random(&mut rng(config.seed, 0), half);
    let mut pose_rng = rng(config.seed, 1);
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let yaw = UnitQuaternion::from_axis_angle(
        &Vector3::z_axis(),
        pose_rng.gen_range(-std::f64::consts::PI..std::f64::consts::PI),
    );
    let tilt_max = 4f64.to_radians();
    let tilt = UnitQuaternion::from_scaled_axis(Vector3::new(
        pose_rng.gen_range(-tilt_max..tilt_max),
        pose_rng.gen_range(-tilt_max..tilt_max),
        0.0,
    ));
    let t_world_cam = Isometry3::from_parts(
        Translation3::new(
            pose_rng.gen_range(-3.0..3.0),
            pose_rng.gen_range(-3.0..3.0),
            pose_rng.gen_range(6.0..10.0),
        ),
        yaw * down * tilt,
    );
    let offset = config
        .prior_offset_m
        .unwrap_or_else(|| pose_rng.gen_range(2.0..5.0));
    let heading = pose_rng.gen_range(0.0..std::f64::consts::TAU);
    let prior = GpsPrior {
        position: t_world_cam.translation.vector
            + Vector3::new(
                offset * heading.cos(),
                offset * heading.sin(),
                pose_rng.gen_range(-0.5..0.5),
            ),
        sigma_m: Vector3::new(3.0, 3.0, 1.0),
    };
    let camera = fisheye_camera(config.model, config.resolution);
    let map = lidar_map(&scene, config, &mut rng(config.seed, 2));
    let (satellite, satellite_top_left) = satellite(&scene, config, &mut rng(config.seed, 3));
    let image = fisheye_image(&scene, &camera, &t_world_cam, config);
    let survey = survey(&scene, &camera, &t_world_cam);
    PriorMapSim {
        config: config.clone(),
        map,
        satellite,
        satellite_top_left,
        camera,
        image,
        t_world_cam,
        prior,
        survey,
    }
}

/// LiDAR map: uniform points, reflectivity `255 (0.04 + 0.9 nir^1.3)` + 4 units noise.
fn lidar_map(scene: &Intersection, config: &PriorMapSimConfig, rng: &mut ChaCha8Rng) -> PointCloud {
    let half = config.map_half_m;
    let z_noise = Normal::new(0.0, 0.01).unwrap_or_else(|_| unreachable!("positive sigma"));
    let r_noise = Normal::new(0.0, 4.0).unwrap_or_else(|_| unreachable!("positive sigma"));
    let points = (0..config.map_points)
        .map(|_| {
            let (x, y) = (rng.gen_range(-half..half), rng.gen_range(-half..half));
            let nir = scene.surface(x, y).nir;
            let r = 255.0 * (0.04 + 0.9 * nir.powf(1.3)) + r_noise.sample(rng);
            Point {
                xyz: Vector3::new(x, y, z_noise.sample(rng)),
                intensity: r.clamp(0.0, 255.0) as f32,
                ..Point::default()
            }
        })
        .collect();
    PointCloud::new(points)
}

/// Satellite ortho image over the map, north up: `255 (0.08 + 0.8 vis^0.8) light` averaged
/// over 3 x 3 samples per pixel, shadows 45 % deep, noise 2 grey levels.
fn satellite(
    scene: &Intersection,
    config: &PriorMapSimConfig,
    rng: &mut ChaCha8Rng,
) -> (GrayImage, Vector2<f64>) {
    let m = config.satellite_m_per_px;
    let n = (2.0 * config.map_half_m / m).floor() as usize;
    let top_left = Vector2::new(-config.map_half_m + 0.5 * m, config.map_half_m - 0.5 * m);
    let shadows = Shadows::random(rng, 6, config.map_half_m * 0.8, 0.45);
    let values: Vec<f64> = (0..n * n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = (
                top_left.x + (i % n) as f64 * m,
                top_left.y - (i / n) as f64 * m,
            );
            let mut sum = 0.0;
            for a in [-1.0, 0.0, 1.0] {
                for b in [-1.0, 0.0, 1.0] {
                    let (sx, sy) = (x + a * m / 3.0, y + b * m / 3.0);
                    let vis = scene.surface(sx, sy).visible;
                    sum += (0.08 + 0.8 * vis.powf(0.8)) * shadows.light(sx, sy);
                }
            }
            255.0 * sum / 9.0
        })
        .collect();
    let noise = Normal::new(0.0, 2.0).unwrap_or_else(|_| unreachable!("positive sigma"));
    let data = values
        .iter()
        .map(|v| (v + noise.sample(rng)).clamp(0.0, 255.0) as f32)
        .collect();
    let image = GrayImage::from_vec(n, n, data).unwrap_or_else(|| GrayImage::new(n, n, 0.0));
    (image, top_left)
}

/// The fisheye image: `255 gain (0.03 + 0.85 vis^1.25)`, a lighting gradient of +-15 %
/// across the scene, 40 % vignetting at the image corner, noise; sky 235 where rays miss.
fn fisheye_image(
    scene: &Intersection,
    camera: &Camera<f64>,
    t_world_cam: &Isometry3<f64>,
    config: &PriorMapSimConfig,
) -> GrayImage {
    let mut rng = rng(config.seed, 4);
    let gain = rng.gen_range(0.85..1.1);
    let light_dir = rng.gen_range(0.0..std::f64::consts::TAU);
    let (dx, dy) = (light_dir.cos(), light_dir.sin());
    let size = config.resolution as usize;
    let c = (size as f64 - 1.0) / 2.0;
    let shaded = ray_cast_ground(camera, t_world_cam, 2, |g, px| {
        let vis = scene.surface(g.x, g.y).visible;
        let light = 1.0 + 0.15 * ((g.x * dx + g.y * dy) / 25.0).tanh();
        let r2 = ((px.x - c).powi(2) + (px.y - c).powi(2)) / (2.0 * c * c);
        255.0 * gain * (0.03 + 0.85 * vis.powf(1.25)) * light * (1.0 - 0.4 * r2)
    });
    let noise =
        Normal::new(0.0, config.image_noise.max(1e-9)).unwrap_or_else(|_| unreachable!("sigma"));
    let data = shaded
        .iter()
        .map(|v| (v.unwrap_or(235.0) + noise.sample(&mut rng)).clamp(0.0, 255.0) as f32)
        .collect();
    GrayImage::from_vec(size, size, data).unwrap_or_else(|| GrayImage::new(size, size, 0.0))
}

/// Survey points: patch corners and manhole centres at most 70 deg off the optical axis and
/// 10 px inside the image, with their true pixels.
fn survey(scene: &Intersection, camera: &Camera<f64>, t_world_cam: &Isometry3<f64>) -> Vec<Survey> {
    let t_cam_world = t_world_cam.inverse();
    scene
        .survey_candidates()
        .into_iter()
        .filter_map(|g| {
            let xyz = Vector3::new(g.x, g.y, 0.0);
            let pc = t_cam_world * nalgebra::Point3::from(xyz);
            if pc.z < pc.coords.norm() * 70f64.to_radians().cos() {
                return None;
            }
            let q = camera.project(&pc.coords)?;
            camera
                .in_image(&q.pixel, 10.0)
                .then_some(Survey { xyz, uv: q.pixel })
        })
        .collect()
}

impl PriorMapSim {
    /// Writes the layout of docs/formats.md section 2.9 under `dir`.
    pub fn write(&self, dir: &Path) -> Result<(), DatasetError> {
        create_dirs(dir, &["map", CAMERA_DATA_DIR, "groundtruth"])?;
        write_scan(&dir.join("map/map.pcd"), &self.map)?;
        write_png(&dir.join("map/satellite.png"), &self.satellite)?;
        write_text(
            &dir.join("map/satellite.yaml"),
            &format!(
                "# metric ortho image, north up: pixel (c, r) is at W (x0 + c m, y0 - r m)\n\
                 metres_per_pixel: {}\ntop_left: [{}, {}]\n",
                self.config.satellite_m_per_px,
                self.satellite_top_left.x,
                self.satellite_top_left.y
            ),
        )?;
        write_text(&dir.join(CAMERA_YAML), &camera_yaml_string(&self.camera))?;
        let frame = CameraFrame {
            stamp_ns: IMAGE_STAMP_NS,
            path: dir
                .join(CAMERA_DATA_DIR)
                .join(format!("{IMAGE_STAMP_NS}.png")),
        };
        write_png(&frame.path, &self.image)?;
        write_camera_csv(dir.join(CAMERA_CSV), &[frame])?;
        let p = &self.prior;
        write_text(
            &dir.join("prior.yaml"),
            &format!(
                "# GPS prior of cam0 in W; yaw unknown\nposition: [{}, {}, {}]\n\
                 sigma_position_m: [{}, {}, {}]\n",
                p.position.x, p.position.y, p.position.z, p.sigma_m.x, p.sigma_m.y, p.sigma_m.z
            ),
        )?;
        let mut csv = String::from("# x [m], y [m], z [m], u [px], v [px]\n");
        for s in &self.survey {
            let _ = writeln!(
                csv,
                "{},{},{},{},{}",
                s.xyz.x, s.xyz.y, s.xyz.z, s.uv.x, s.uv.y
            );
        }
        write_text(&dir.join("survey.csv"), &csv)?;
        write_text(
            &dir.join("groundtruth/extrinsics.yaml"),
            &t_world_cam_yaml(&self.t_world_cam, [0.0; 3], [0.0; 3]),
        )?;
        DatasetYaml {
            sensors: vec!["cam0".into(), "map".into()],
            description: format!(
                "msreg simulator: prior-map, seed {}, {:?} fisheye {} px, {} map points",
                self.config.seed,
                self.config.model,
                self.config.resolution,
                self.map.len()
            ),
            rates_hz: BTreeMap::new(),
        }
        .write(dir.join(DATASET_YAML))
    }
}
