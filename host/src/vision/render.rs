//! A small renderer of a Kalibr checkerboard seen by a [`Camera`] at a pose, for tests and
//! the image simulator: exact ray casting through the camera model (distortion included),
//! anti-aliased by supersampling the pixels that straddle an edge, plus Gaussian noise and
//! blur. Pixel convention of CONVENTIONS.md; target frame: corner id `r * cols + c` at
//! `(r * row_spacing, c * col_spacing, 0)`, z out of the printed face.

use super::gray::GrayImage;
use msreg_estimator::camera::Camera;
use msreg_estimator::Pose;
use nalgebra::{Vector2, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};

/// The printed board.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardPattern {
    /// Inner corner rows (`targetRows`).
    pub rows: usize,
    /// Inner corner columns (`targetCols`).
    pub cols: usize,
    /// Distance between corner rows (along target x), metres.
    pub row_spacing_m: f64,
    /// Distance between corner columns (along target y), metres.
    pub col_spacing_m: f64,
    /// White margin around the squares, metres.
    pub margin_m: f64,
}

impl BoardPattern {
    /// Corner `id = r * cols + c` in the target frame.
    pub fn corner_in_target(&self, id: usize) -> Vector3<f64> {
        let (r, c) = (id / self.cols, id % self.cols);
        Vector3::new(
            r as f64 * self.row_spacing_m,
            c as f64 * self.col_spacing_m,
            0.0,
        )
    }

    /// The class of a point on the board plane.
    fn class(&self, x: f64, y: f64) -> Class {
        let (rs, cs) = (self.row_spacing_m, self.col_spacing_m);
        let (x0, x1) = (-rs, self.rows as f64 * rs);
        let (y0, y1) = (-cs, self.cols as f64 * cs);
        if x >= x0 && x < x1 && y >= y0 && y < y1 {
            // Dark iff floor(x/rs) + floor(y/cs) even: the square between corners
            // 0, 1, cols, cols + 1 is dark (the detector's id rule).
            let k = (x / rs).floor() as i64 + (y / cs).floor() as i64;
            if k.rem_euclid(2) == 0 {
                Class::Dark
            } else {
                Class::Light
            }
        } else if x >= x0 - self.margin_m
            && x < x1 + self.margin_m
            && y >= y0 - self.margin_m
            && y < y1 + self.margin_m
        {
            Class::Light
        } else {
            Class::Background
        }
    }
}

/// Grey levels and anti-aliasing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Dark squares.
    pub dark: f32,
    /// Light squares and margin.
    pub light: f32,
    /// Everything off the board.
    pub background: f32,
    /// Samples per pixel side on edge pixels.
    pub supersample: usize,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            dark: 30.0,
            light: 220.0,
            background: 110.0,
            supersample: 8,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Class {
    Background,
    Light,
    Dark,
}

/// Renders the board at `t_cam_target` (pose of the target in the camera frame).
pub fn render_checkerboard(
    camera: &Camera<f64>,
    t_cam_target: &Pose<f64>,
    board: &BoardPattern,
    settings: &RenderSettings,
) -> GrayImage {
    let (w, h) = (camera.resolution.0 as usize, camera.resolution.1 as usize);
    let t_target_cam = t_cam_target.inverse();
    let class_at = |u: f64, v: f64| -> Class {
        let Some(b) = camera.unproject(&Vector2::new(u, v)) else {
            return Class::Background;
        };
        let o = t_target_cam.translation;
        let d = t_target_cam.rotation * b;
        // Printed face only: the camera must be on the +z side.
        if o.z <= 0.0 || d.z >= 0.0 {
            return Class::Background;
        }
        let s = -o.z / d.z;
        board.class(o.x + s * d.x, o.y + s * d.y)
    };
    let value = |c: Class| match c {
        Class::Background => settings.background,
        Class::Light => settings.light,
        Class::Dark => settings.dark,
    };
    // Classes at pixel corners: a pixel whose corners and centre agree is uniform.
    let corners: Vec<Class> = (0..=h)
        .flat_map(|y| (0..=w).map(move |x| (x, y)))
        .map(|(x, y)| class_at(x as f64 - 0.5, y as f64 - 0.5))
        .collect();
    let n = settings.supersample.max(1);
    let mut data = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let c = [
                corners[y * (w + 1) + x],
                corners[y * (w + 1) + x + 1],
                corners[(y + 1) * (w + 1) + x],
                corners[(y + 1) * (w + 1) + x + 1],
            ];
            let centre = class_at(x as f64, y as f64);
            data[y * w + x] = if c.iter().all(|&k| k == centre) {
                value(centre)
            } else {
                let mut acc = 0.0;
                for sy in 0..n {
                    for sx in 0..n {
                        let u = x as f64 - 0.5 + (sx as f64 + 0.5) / n as f64;
                        let v = y as f64 - 0.5 + (sy as f64 + 0.5) / n as f64;
                        acc += value(class_at(u, v));
                    }
                }
                acc / (n * n) as f32
            };
        }
    }
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

/// The true pixel of every corner (`None` when it cannot be projected).
pub fn true_corners(
    camera: &Camera<f64>,
    t_cam_target: &Pose<f64>,
    board: &BoardPattern,
) -> Vec<Option<Vector2<f64>>> {
    (0..board.rows * board.cols)
        .map(|id| {
            camera
                .project(&t_cam_target.transform_point(&board.corner_in_target(id)))
                .map(|p| p.pixel)
        })
        .collect()
}

/// Adds zero-mean Gaussian noise of `sigma` grey levels, then clamps to 0..255 (nothing
/// for a negative or non-finite `sigma`).
pub fn add_noise(img: &mut GrayImage, sigma: f64, rng: &mut impl Rng) {
    let Ok(normal) = Normal::new(0.0, sigma) else {
        return;
    };
    for x in img.data_mut() {
        *x = (*x + normal.sample(rng) as f32).clamp(0.0, 255.0);
    }
}
