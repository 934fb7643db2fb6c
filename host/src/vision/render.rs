//! A small renderer of a Kalibr checkerboard seen by a [`Camera`] at a pose, for tests and
//! the image simulator: ray casting through the camera model (distortion included, rays
//! cached per camera in [`PixelRays`]), anti-aliased by supersampling the pixels that
//! straddle an edge, motion blur by averaging poses over the exposure, Gaussian noise and a
//! lighting gradient. Pixel convention of docs/formats.md; target frame: corner id `r * cols + c` at
//! `(r * row_spacing, c * col_spacing, 0)`, z out of the printed face.

use super::gray::GrayImage;
use msreg_estimator::camera::Camera;
use msreg_estimator::Pose;
use nalgebra::{Vector2, Vector3};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use rayon::prelude::*;

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
}

impl PrintedTarget for BoardPattern {
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

    fn outline(&self) -> [f64; 4] {
        let (rs, cs, m) = (self.row_spacing_m, self.col_spacing_m, self.margin_m);
        [
            -rs - m,
            self.rows as f64 * rs + m,
            -cs - m,
            self.cols as f64 * cs + m,
        ]
    }
}

/// A printed calibration target as the renderer sees it: the ink at every point of its
/// plane (target frame, z = 0) and the rectangle that holds all of it.
pub trait PrintedTarget: Sync {
    /// The class of the target-plane point `(x, y)`.
    fn class(&self, x: f64, y: f64) -> Class;
    /// `[x_min, x_max, y_min, y_max]` of the printed sheet (margin included), metres;
    /// everything outside is [`Class::Background`].
    fn outline(&self) -> [f64; 4];
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

/// What a point of the target plane shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// Off the printed sheet.
    Background,
    /// White paper.
    Light,
    /// Black ink.
    Dark,
}

/// The unit rays of a camera's pixel-corner grid (`(w + 1) x (h + 1)` points at
/// `(x - 0.5, y - 0.5)`), computed once per camera: unprojection (iterative for radtan) is
/// the expensive part of rendering and does not depend on the pose, so a sequence of frames
/// shares it. Inside a pixel the board-plane point is interpolated bilinearly between the
/// four corner intersections (the map's curvature over one pixel moves edges by < 1e-3 px
/// for the lenses used here).
#[derive(Clone, Debug)]
pub struct PixelRays {
    camera: Camera<f64>,
    width: usize,
    height: usize,
    /// Row-major over the corner grid; NaN where the pixel cannot be unprojected.
    rays: Vec<Vector3<f64>>,
}

impl PixelRays {
    /// The rays of `camera`'s pixel corners.
    pub fn new(camera: &Camera<f64>) -> Self {
        let (w, h) = (camera.resolution.0 as usize, camera.resolution.1 as usize);
        let mut rays = vec![Vector3::repeat(f64::NAN); (w + 1) * (h + 1)];
        rays.par_chunks_mut(w + 1).enumerate().for_each(|(y, row)| {
            for (x, r) in row.iter_mut().enumerate() {
                let pixel = Vector2::new(x as f64 - 0.5, y as f64 - 0.5);
                if let Some(b) = camera.unproject(&pixel) {
                    *r = b;
                }
            }
        });
        Self {
            camera: *camera,
            width: w,
            height: h,
            rays,
        }
    }

    /// The camera.
    pub fn camera(&self) -> &Camera<f64> {
        &self.camera
    }
}

/// Renders the board at `t_cam_target` (pose of the target in the camera frame).
pub fn render_checkerboard(
    camera: &Camera<f64>,
    t_cam_target: &Pose<f64>,
    board: &impl PrintedTarget,
    settings: &RenderSettings,
) -> GrayImage {
    render_exposure(
        &PixelRays::new(camera),
        std::slice::from_ref(t_cam_target),
        board,
        settings,
    )
}

/// Renders the mean image over `poses` (`T_cam_target` at instants spread over the
/// exposure: motion blur as the time integral of the irradiance); one pose is a sharp image.
pub fn render_exposure(
    rays: &PixelRays,
    poses: &[Pose<f64>],
    board: &impl PrintedTarget,
    settings: &RenderSettings,
) -> GrayImage {
    let (w, h) = (rays.width, rays.height);
    let mut sum = vec![0.0f32; w * h];
    let mut plane = vec![Vector2::repeat(f64::NAN); (w + 1) * (h + 1)];
    let mut classes = vec![Class::Background; (w + 1) * (h + 1)];
    let (x0, x1, y0, y1) = board_region(&rays.camera, poses, board);
    for pose in poses {
        let t_target_cam = pose.inverse();
        // Board-plane intersection and class of every corner ray of the region.
        plane
            .par_chunks_mut(w + 1)
            .zip(classes.par_chunks_mut(w + 1))
            .zip(rays.rays.par_chunks(w + 1))
            .enumerate()
            .filter(|(y, _)| (y0..=y1).contains(y))
            .for_each(|(_, ((out, cls), row))| {
                for x in x0..=x1 {
                    let q = intersect(&t_target_cam, &row[x]);
                    out[x] = q.unwrap_or(Vector2::repeat(f64::NAN));
                    cls[x] = q.map_or(Class::Background, |q| board.class(q.x, q.y));
                }
            });
        let (plane, classes) = (&plane, &classes);
        sum.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, acc) in row.iter_mut().enumerate() {
                *acc += if (y0..y1).contains(&y) && (x0..x1).contains(&x) {
                    shade_pixel(rays, &t_target_cam, plane, classes, x, y, board, settings)
                } else {
                    settings.background
                };
            }
        });
    }
    let n = poses.len().max(1) as f32;
    let data = sum.into_iter().map(|v| v / n).collect();
    GrayImage::from_vec(w, h, data).unwrap_or_else(|| GrayImage::new(w, h, 0.0))
}

/// The pixels (`x0..x1`, `y0..y1`) that can show the board in any of `poses`: the bounding
/// box of its outline (margin included) projected into the image, padded by 3 px; the whole
/// image when part of the outline does not project inside it (a lens model can fold points
/// far outside its field of view back into the image, so those cannot bound anything).
fn board_region(
    camera: &Camera<f64>,
    poses: &[Pose<f64>],
    board: &impl PrintedTarget,
) -> (usize, usize, usize, usize) {
    let (w, h) = (camera.resolution.0 as usize, camera.resolution.1 as usize);
    let whole = (0, w, 0, h);
    let [ax, bx, ay, by] = board.outline();
    let steps = 64;
    let (mut lo, mut hi) = (Vector2::repeat(f64::MAX), Vector2::repeat(f64::MIN));
    for pose in poses {
        for k in 0..=steps {
            let f = k as f64 / steps as f64;
            let (x, y) = (ax + (bx - ax) * f, ay + (by - ay) * f);
            for p in [
                Vector3::new(x, ay, 0.0),
                Vector3::new(x, by, 0.0),
                Vector3::new(ax, y, 0.0),
                Vector3::new(bx, y, 0.0),
            ] {
                let Some(px) = camera.project(&pose.transform_point(&p)) else {
                    return whole;
                };
                if !camera.in_image(&px.pixel, 0.0) {
                    return whole;
                }
                lo = lo.inf(&px.pixel);
                hi = hi.sup(&px.pixel);
            }
        }
    }
    let clamp = |v: f64, n: usize| (v.max(0.0) as usize).min(n);
    (
        clamp(lo.x - 3.0, w),
        clamp(hi.x + 4.0, w),
        clamp(lo.y - 3.0, h),
        clamp(hi.y + 4.0, h),
    )
}

/// The board-plane point `(x, y)` hit by bearing `b` (camera frame), if the printed face
/// is hit from the front.
fn intersect(t_target_cam: &Pose<f64>, b: &Vector3<f64>) -> Option<Vector2<f64>> {
    let o = t_target_cam.translation;
    let d = t_target_cam.rotation * b;
    if !(o.z > 0.0 && d.z < 0.0) {
        return None;
    }
    let s = -o.z / d.z;
    Some(Vector2::new(o.x + s * d.x, o.y + s * d.y))
}

/// Mean grey value over pixel `(x, y)`: uniform pixels from their corners and centre,
/// edge pixels supersampled.
#[allow(clippy::too_many_arguments)]
fn shade_pixel(
    rays: &PixelRays,
    t_target_cam: &Pose<f64>,
    plane: &[Vector2<f64>],
    classes: &[Class],
    x: usize,
    y: usize,
    board: &impl PrintedTarget,
    settings: &RenderSettings,
) -> f32 {
    let value = |c: Class| match c {
        Class::Background => settings.background,
        Class::Light => settings.light,
        Class::Dark => settings.dark,
    };
    let stride = rays.width + 1;
    let p = [
        plane[y * stride + x],
        plane[y * stride + x + 1],
        plane[(y + 1) * stride + x],
        plane[(y + 1) * stride + x + 1],
    ];
    let n = settings.supersample.max(1);
    if p.iter().all(|q| q.x.is_finite()) {
        let class = |q: Vector2<f64>| board.class(q.x, q.y);
        let centre = class((p[0] + p[1] + p[2] + p[3]) / 4.0);
        let corner_classes = [
            classes[y * stride + x],
            classes[y * stride + x + 1],
            classes[(y + 1) * stride + x],
            classes[(y + 1) * stride + x + 1],
        ];
        if corner_classes.iter().all(|&c| c == centre) {
            return value(centre);
        }
        let mut acc = 0.0;
        for sy in 0..n {
            let fy = (sy as f64 + 0.5) / n as f64;
            let left = p[0] + (p[2] - p[0]) * fy;
            let right = p[1] + (p[3] - p[1]) * fy;
            for sx in 0..n {
                let fx = (sx as f64 + 0.5) / n as f64;
                acc += value(class(left + (right - left) * fx));
            }
        }
        return acc / (n * n) as f32;
    }
    // Rare: a pixel at the edge of the camera's valid region or of the board plane's
    // horizon; every sample is cast exactly.
    let mut acc = 0.0;
    for sy in 0..n {
        for sx in 0..n {
            let u = x as f64 - 0.5 + (sx as f64 + 0.5) / n as f64;
            let v = y as f64 - 0.5 + (sy as f64 + 0.5) / n as f64;
            let class = rays
                .camera
                .unproject(&Vector2::new(u, v))
                .and_then(|b| intersect(t_target_cam, &b))
                .map_or(Class::Background, |q| board.class(q.x, q.y));
            acc += value(class);
        }
    }
    acc / (n * n) as f32
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

/// Multiplies the image by a smooth illumination field `1 + gain_u x + gain_v y` with
/// `x, y` in -0.5..0.5 across the image (a lamp to one side), then clamps to 0..255.
pub fn apply_lighting_gradient(img: &mut GrayImage, gain_u: f32, gain_v: f32) {
    let (w, h) = (img.width(), img.height());
    img.data_mut()
        .par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let fy = (y as f32 + 0.5) / h as f32 - 0.5;
            for (x, v) in row.iter_mut().enumerate() {
                let fx = (x as f32 + 0.5) / w as f32 - 0.5;
                *v = (*v * (1.0 + gain_u * fx + gain_v * fy)).clamp(0.0, 255.0);
            }
        });
}
