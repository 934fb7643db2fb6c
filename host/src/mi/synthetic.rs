//! A synthetic MI problem for tests and the benchmark: a textured ground plane (lane
//! stripes and asphalt blobs in the map reflectivity) seen by a downward equidistant
//! fisheye 8 m up. The image is rendered by casting every pixel's ray onto the plane, with
//! its own appearance (another monotonic intensity mapping, vignetting, noise), so the MI
//! is not trivially maximal; the map points sample the reflectivity directly.

use msreg_estimator::camera::{
    equidistant::Equidistant, Camera, Distortion, Intrinsics, Projection,
};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector2, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

use crate::vision::GrayImage;

/// The problem.
#[derive(Clone, Debug)]
pub struct SyntheticGround {
    /// Map points on the plane z = 0 (world frame).
    pub points: Vec<Vector3<f64>>,
    /// Their reflectivity.
    pub intensities: Vec<f32>,
    /// The rendered fisheye image.
    pub image: GrayImage,
    /// The camera.
    pub camera: Camera<f64>,
    /// True `T_world_cam`.
    pub t_world_cam: Isometry3<f64>,
}

/// Reflectivity texture: blobs plus lane stripes.
struct Texture {
    blobs: Vec<(Vector2<f64>, f64, f64)>,
}

impl Texture {
    fn new(rng: &mut ChaCha8Rng) -> Self {
        let blobs = (0..400)
            .map(|_| {
                let c = Vector2::new(rng.gen_range(-14.0..14.0), rng.gen_range(-14.0..14.0));
                (c, rng.gen_range(0.2..1.0), rng.gen_range(-0.3..0.3))
            })
            .collect();
        Self { blobs }
    }

    fn at(&self, x: f64, y: f64) -> f64 {
        let mut v = 0.35;
        for (c, r, a) in &self.blobs {
            let d2 = (x - c.x).powi(2) + (y - c.y).powi(2);
            if d2 < 9.0 * r * r {
                v += a * (-d2 / (2.0 * r * r)).exp();
            }
        }
        let stripe = |s: f64| ((s / 3.5).rem_euclid(1.0) - 0.5).abs() < 0.05;
        let dash = (y / 3.0).rem_euclid(1.0) < 0.6;
        if (stripe(x) && dash) || (y.abs() > 4.0 && y.abs() < 4.4) {
            v = 0.95;
        }
        v.clamp(0.0, 1.0)
    }
}

/// A downward equidistant fisheye, 640 x 480.
pub fn fisheye() -> Camera<f64> {
    Camera::new(
        Projection::Pinhole,
        Intrinsics {
            fu: 190.0,
            fv: 190.0,
            cu: 319.5,
            cv: 239.5,
        },
        Distortion::Equidistant(Equidistant {
            k1: 0.02,
            k2: -0.01,
            k3: 0.0,
            k4: 0.0,
        }),
        (640, 480),
    )
    .unwrap_or_else(|_| unreachable!("valid constants"))
}

/// Builds the problem with `n_points` map points.
pub fn synthetic_ground(seed: u64, n_points: usize) -> SyntheticGround {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let texture = Texture::new(&mut rng);
    let camera = fisheye();
    // Camera looking down (z_cam = -z_world), yawed, 8 m up.
    let down = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI);
    let yaw = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), rng.gen_range(-3.0..3.0));
    let tilt = UnitQuaternion::from_scaled_axis(Vector3::new(0.05, -0.04, 0.0));
    let t_world_cam = Isometry3::from_parts(
        Translation3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 8.0),
        yaw * down * tilt,
    );
    let points: Vec<Vector3<f64>> = (0..n_points)
        .map(|_| Vector3::new(rng.gen_range(-13.0..13.0), rng.gen_range(-13.0..13.0), 0.0))
        .collect();
    let intensities = points.iter().map(|p| texture.at(p.x, p.y) as f32).collect();
    let image = render(&camera, &t_world_cam, &texture, &mut rng);
    SyntheticGround {
        points,
        intensities,
        image,
        camera,
        t_world_cam,
    }
}

/// Ray-casts every pixel of `camera` at `t_world_cam` onto the ground plane z = 0 of the
/// world and shades the hit point: `shade(ground, pixel)` with `ground` the world (x, y)
/// of the hit, averaged over `samples` x `samples` sub-pixel rays; `None` where the
/// pixel's centre ray misses the ground (above the horizon). Row-major, parallel over rows.
pub fn ray_cast_ground<F>(
    camera: &Camera<f64>,
    t_world_cam: &Isometry3<f64>,
    samples: usize,
    shade: F,
) -> Vec<Option<f64>>
where
    F: Fn(Vector2<f64>, Vector2<f64>) -> f64 + Sync,
{
    let (w, h) = (camera.resolution.0 as usize, camera.resolution.1 as usize);
    let n = samples.max(1);
    let hit = |u: f64, v: f64| -> Option<Vector2<f64>> {
        let d = t_world_cam.rotation * camera.unproject(&Vector2::new(u, v))?;
        if d.z >= -1e-3 {
            return None;
        }
        let s = -t_world_cam.translation.vector.z / d.z;
        Some((t_world_cam.translation.vector + d * s).xy())
    };
    (0..w * h)
        .into_par_iter()
        .with_min_len(w.max(1))
        .map(|i| {
            let (u, v) = ((i % w) as f64, (i / w) as f64);
            hit(u, v)?;
            let mut sum = 0.0;
            let mut count = 0.0;
            for a in 0..n {
                for b in 0..n {
                    let du = (a as f64 + 0.5) / n as f64 - 0.5;
                    let dv = (b as f64 + 0.5) / n as f64 - 0.5;
                    if let Some(g) = hit(u + du, v + dv) {
                        sum += shade(g, Vector2::new(u + du, v + dv));
                        count += 1.0;
                    }
                }
            }
            Some(sum / count)
        })
        .collect()
}

/// Ray-casts every pixel onto z = 0; appearance: gamma 0.6, vignetting, noise 3 grey levels.
fn render(
    camera: &Camera<f64>,
    t_world_cam: &Isometry3<f64>,
    texture: &Texture,
    rng: &mut ChaCha8Rng,
) -> GrayImage {
    let (w, h) = (camera.resolution.0 as usize, camera.resolution.1 as usize);
    let noise = Normal::new(0.0, 3.0).unwrap_or_else(|_| unreachable!("positive sigma"));
    let shaded = ray_cast_ground(camera, t_world_cam, 1, |g, px| {
        let r2 = ((px.x - 319.5).powi(2) + (px.y - 239.5).powi(2)) / (320.0f64 * 320.0);
        (30.0 + 200.0 * texture.at(g.x, g.y).powf(0.6)) * (1.0 - 0.35 * r2)
    });
    let data = shaded
        .iter()
        .map(|value| (value.unwrap_or(20.0) + noise.sample(rng)) as f32)
        .collect();
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}
