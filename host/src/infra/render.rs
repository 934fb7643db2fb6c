//! Images of the infrastructure-camera scenario (`msreg simulate infra --images`), rendered
//! from the geometry alone so that `calibrate infra` exercises its detectors end to end:
//!
//! - an infrastructure camera's frame: the robot's backlit ArUco marker ray-cast through the
//!   camera's own lens (any projection and distortion: every sample's pixel is unprojected
//!   to a ray and intersected with the marker plane), 4 x 4 samples per pixel, on a dim
//!   background, with sensor noise;
//! - a keyframe of the robot's upward fisheye `F`: the infrastructure cameras as bright
//!   round spots (their LEDs) at their true projections, and clutter spots, on a dim
//!   ceiling, with sensor noise.
//!
//! The detectors then find the corners and blobs with their own errors; nothing is copied
//! from the simulator's noisy CSV detections.

use msreg_estimator::camera::Camera;
use nalgebra::{Isometry3, Point3, Vector2};
use rand::Rng;

use crate::vision::aruco::render::{marker_value, Ink};
use crate::vision::aruco::Dictionary;
use crate::vision::render::add_noise;
use crate::vision::GrayImage;

/// Grey levels and noise of the rendered frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderLook {
    /// Background (room or ceiling), grey level.
    pub background: f32,
    /// The marker's print: black and white cells of the backlit face.
    pub ink: Ink,
    /// White quiet zone around the black square, in its sides.
    pub quiet: f64,
    /// Peak of a blob above the background.
    pub blob_peak: f32,
    /// Gaussian radius (sigma) of a blob, px.
    pub blob_sigma_px: f64,
    /// Sensor noise, grey levels (1 sigma).
    pub noise: f64,
}

impl Default for RenderLook {
    fn default() -> Self {
        Self {
            background: 35.0,
            ink: Ink {
                black: 25.0,
                white: 235.0,
            },
            quiet: 0.25,
            blob_peak: 215.0,
            blob_sigma_px: 1.6,
            noise: 2.0,
        }
    }
}

/// Samples per pixel side when ray-casting the marker.
const SUPERSAMPLE: usize = 4;

/// The frame of `camera` seeing marker `id` at pose `t_c_m` (`p_cam = t_c_m * p_marker`;
/// marker frame of docs/formats.md: centre origin, x right, y up, z out of the face).
pub fn marker_frame<R: Rng>(
    camera: &Camera<f64>,
    t_c_m: &Isometry3<f64>,
    side_m: f64,
    (dictionary, id): (Dictionary, usize),
    look: &RenderLook,
    rng: &mut R,
) -> GrayImage {
    let (w, h) = camera.resolution;
    let mut img = GrayImage::new(w as usize, h as usize, look.background);
    let view = MarkerView {
        camera,
        t_m_c: t_c_m.inverse(),
        side_m,
        dictionary,
        id,
        look,
    };
    if let Some((x0, y0, x1, y1)) = marker_box(camera, t_c_m, side_m * (1.0 + 2.0 * look.quiet)) {
        let width = img.width();
        for y in y0..=y1 {
            for x in x0..=x1 {
                img.data_mut()[y * width + x] = view.pixel(x, y);
            }
        }
    }
    add_noise(&mut img, look.noise, rng);
    img
}

/// One marker as one camera sees it.
struct MarkerView<'a> {
    camera: &'a Camera<f64>,
    t_m_c: Isometry3<f64>,
    side_m: f64,
    dictionary: Dictionary,
    id: usize,
    look: &'a RenderLook,
}

impl MarkerView<'_> {
    /// Mean of `SUPERSAMPLE^2` samples over pixel `(x, y)` (it covers `x +- 0.5`).
    fn pixel(&self, x: usize, y: usize) -> f32 {
        let step = 1.0 / SUPERSAMPLE as f64;
        let mut sum = 0.0f32;
        for sy in 0..SUPERSAMPLE {
            for sx in 0..SUPERSAMPLE {
                let pixel = Vector2::new(
                    x as f64 - 0.5 + (sx as f64 + 0.5) * step,
                    y as f64 - 0.5 + (sy as f64 + 0.5) * step,
                );
                sum += self.sample(pixel).unwrap_or(self.look.background);
            }
        }
        sum / (SUPERSAMPLE * SUPERSAMPLE) as f32
    }

    /// The grey level where the ray through `pixel` meets the marker's face, if it does.
    fn sample(&self, pixel: Vector2<f64>) -> Option<f32> {
        let ray = self.t_m_c.rotation * self.camera.unproject(&pixel)?;
        let origin = self.t_m_c.translation.vector;
        if ray.z.abs() < 1e-12 {
            return None;
        }
        let lambda = -origin.z / ray.z;
        if lambda <= 0.0 {
            return None;
        }
        let p = origin + ray * lambda;
        // Printed top-left at (-s/2, s/2): s to the right, t downwards, in sides.
        let s = (p.x + self.side_m / 2.0) / self.side_m;
        let t = (self.side_m / 2.0 - p.y) / self.side_m;
        marker_value(
            self.dictionary,
            self.id,
            s,
            t,
            self.look.quiet,
            self.look.ink,
        )
    }
}

/// Pixel bounding box (inclusive, clipped to the image, 2 px margin) of the marker square of
/// side `outer_m` centred on the marker; `None` when a corner does not project.
fn marker_box(
    camera: &Camera<f64>,
    t_c_m: &Isometry3<f64>,
    outer_m: f64,
) -> Option<(usize, usize, usize, usize)> {
    let h = outer_m / 2.0;
    let (mut lo, mut hi) = (Vector2::repeat(f64::MAX), Vector2::repeat(f64::MIN));
    // The edges' midpoints too: a fisheye bends the sides outwards.
    for (x, y) in [
        (-h, h),
        (0.0, h),
        (h, h),
        (h, 0.0),
        (h, -h),
        (0.0, -h),
        (-h, -h),
        (-h, 0.0),
    ] {
        let q = camera.project(&(t_c_m * Point3::new(x, y, 0.0)).coords)?;
        lo = lo.inf(&q.pixel);
        hi = hi.sup(&q.pixel);
    }
    let (w, hgt) = (
        f64::from(camera.resolution.0),
        f64::from(camera.resolution.1),
    );
    let x0 = (lo.x - 2.0).floor().clamp(0.0, w - 1.0) as usize;
    let y0 = (lo.y - 2.0).floor().clamp(0.0, hgt - 1.0) as usize;
    let x1 = (hi.x + 2.0).ceil().clamp(0.0, w - 1.0) as usize;
    let y1 = (hi.y + 2.0).ceil().clamp(0.0, hgt - 1.0) as usize;
    Some((x0, y0, x1, y1))
}

/// A keyframe of `F`: a round spot of [`RenderLook::blob_peak`] at each of `spots`.
pub fn blob_frame<R: Rng>(
    f: &Camera<f64>,
    spots: &[Vector2<f64>],
    look: &RenderLook,
    rng: &mut R,
) -> GrayImage {
    let (w, h) = (f.resolution.0 as usize, f.resolution.1 as usize);
    let mut img = GrayImage::new(w, h, look.background);
    let radius = (4.0 * look.blob_sigma_px).ceil() as isize;
    let inv = 1.0 / (2.0 * look.blob_sigma_px * look.blob_sigma_px);
    for spot in spots {
        let (cx, cy) = (spot.x.round() as isize, spot.y.round() as isize);
        for y in (cy - radius).max(0)..=(cy + radius).min(h as isize - 1) {
            for x in (cx - radius).max(0)..=(cx + radius).min(w as isize - 1) {
                let d2 = (x as f64 - spot.x).powi(2) + (y as f64 - spot.y).powi(2);
                let v = look.blob_peak * (-d2 * inv).exp() as f32;
                let px = &mut img.data_mut()[y as usize * w + x as usize];
                *px = (*px + v).min(255.0);
            }
        }
    }
    add_noise(&mut img, look.noise, rng);
    img
}
