//! Rendering through the simulator's own camera models ([`super::models`]): the unit ray
//! of every pixel corner (`(w + 1) x (h + 1)` points at `(x - 0.5, y - 0.5)`) is found once
//! per camera by unprojection, each frame intersects them with the target plane, and a pixel
//! takes the mean ink over its area: one class where its four corners and centre agree,
//! else `n x n` samples interpolated bilinearly between the corner intersections (as
//! [`crate::vision::render`] does for the estimator's cameras). A pixel with a corner no ray
//! reaches (the rim of a fisheye's image circle) casts each sample's own ray.

use nalgebra::{Isometry3, Vector2, Vector3};
use rayon::prelude::*;

use super::models::SimCamera;
use crate::vision::render::{Class, PrintedTarget, RenderSettings};
use crate::vision::GrayImage;

/// The unit rays of a camera's pixel-corner grid; NaN where no ray projects there.
#[derive(Clone, Debug)]
pub struct RayGrid {
    camera: SimCamera,
    max_angle: f64,
    width: usize,
    height: usize,
    rays: Vec<Vector3<f64>>,
}

impl RayGrid {
    /// The rays of `camera`'s pixel corners.
    pub fn new(camera: &SimCamera) -> Self {
        let [w, h] = camera.resolution.map(|n| n as usize);
        let max_angle = camera.max_angle();
        let mut rays = vec![Vector3::repeat(f64::NAN); (w + 1) * (h + 1)];
        rays.par_chunks_mut(w + 1).enumerate().for_each(|(y, row)| {
            for (x, r) in row.iter_mut().enumerate() {
                let pixel = Vector2::new(x as f64 - 0.5, y as f64 - 0.5);
                if let Some(b) = camera.unproject_within(&pixel, max_angle) {
                    *r = b;
                }
            }
        });
        Self {
            camera: *camera,
            max_angle,
            width: w,
            height: h,
            rays,
        }
    }

    /// The camera.
    pub fn camera(&self) -> &SimCamera {
        &self.camera
    }
}

/// The target-plane point hit by camera ray `b` from the front, `t_target_cam` the pose of
/// the camera in the target frame.
fn intersect(t_target_cam: &Isometry3<f64>, b: &Vector3<f64>) -> Option<Vector2<f64>> {
    let o = t_target_cam.translation.vector;
    let d = t_target_cam.rotation * b;
    if !(o.z > 0.0 && d.z < 0.0) {
        return None;
    }
    let s = -o.z / d.z;
    Some(Vector2::new(o.x + s * d.x, o.y + s * d.y))
}

/// The mean image over `poses` (`T_cam_target` at instants spread over the exposure; one
/// pose: a sharp image).
pub fn render(
    grid: &RayGrid,
    poses: &[Isometry3<f64>],
    target: &impl PrintedTarget,
    settings: &RenderSettings,
) -> GrayImage {
    let (w, h) = (grid.width, grid.height);
    let mut sum = vec![0.0f32; w * h];
    let mut plane = vec![Vector2::repeat(f64::NAN); (w + 1) * (h + 1)];
    for pose in poses {
        let t_target_cam = pose.inverse();
        plane
            .par_chunks_mut(w + 1)
            .zip(grid.rays.par_chunks(w + 1))
            .for_each(|(out, rays)| {
                for (q, b) in out.iter_mut().zip(rays) {
                    *q = intersect(&t_target_cam, b).unwrap_or(Vector2::repeat(f64::NAN));
                }
            });
        let plane = &plane;
        sum.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, acc) in row.iter_mut().enumerate() {
                *acc += shade(grid, &t_target_cam, plane, x, y, target, settings);
            }
        });
    }
    let n = poses.len().max(1) as f32;
    let data = sum.into_iter().map(|v| v / n).collect();
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

/// The grey level of `class`.
fn value(class: Class, settings: &RenderSettings) -> f32 {
    match class {
        Class::Background => settings.background,
        Class::Light => settings.light,
        Class::Dark => settings.dark,
    }
}

/// Mean grey level over pixel `(x, y)`.
fn shade(
    grid: &RayGrid,
    t_target_cam: &Isometry3<f64>,
    plane: &[Vector2<f64>],
    x: usize,
    y: usize,
    target: &impl PrintedTarget,
    settings: &RenderSettings,
) -> f32 {
    let stride = grid.width + 1;
    let p = [
        plane[y * stride + x],
        plane[y * stride + x + 1],
        plane[(y + 1) * stride + x],
        plane[(y + 1) * stride + x + 1],
    ];
    let n = settings.supersample.max(1);
    let class = |q: Vector2<f64>| target.class(q.x, q.y);
    let hits = p.iter().filter(|q| q.x.is_finite()).count();
    if hits == 4 {
        let centre = class((p[0] + p[1] + p[2] + p[3]) / 4.0);
        if p.iter().all(|&q| class(q) == centre) {
            return value(centre, settings);
        }
        let mut acc = 0.0;
        for sy in 0..n {
            let fy = (sy as f64 + 0.5) / n as f64;
            let (left, right) = (p[0] + (p[2] - p[0]) * fy, p[1] + (p[3] - p[1]) * fy);
            for sx in 0..n {
                let fx = (sx as f64 + 0.5) / n as f64;
                acc += value(class(left + (right - left) * fx), settings);
            }
        }
        return acc / (n * n) as f32;
    }
    let corner_rays = [(0, 0), (1, 0), (0, 1), (1, 1)]
        .iter()
        .filter(|(dx, dy)| grid.rays[(y + dy) * stride + x + dx].x.is_finite())
        .count();
    if hits == 0 && corner_rays == 4 {
        // Every corner ray misses the target's plane from the front.
        return settings.background;
    }
    // The rim of the image circle or the plane's horizon: every sample cast exactly.
    let mut acc = 0.0;
    for sy in 0..n {
        for sx in 0..n {
            let u = x as f64 - 0.5 + (sx as f64 + 0.5) / n as f64;
            let v = y as f64 - 0.5 + (sy as f64 + 0.5) / n as f64;
            let c = grid
                .camera
                .unproject_within(&Vector2::new(u, v), grid.max_angle)
                .and_then(|b| intersect(t_target_cam, &b))
                .map_or(Class::Background, class);
            acc += value(c, settings);
        }
    }
    acc / (n * n) as f32
}
