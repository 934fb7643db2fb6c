//! ORB features (Rublee et al. 2011): FAST-9 corners with non-maximum suppression, spread
//! over a grid of cells; orientation from the intensity centroid; a steered 256-bit BRIEF
//! descriptor (the pattern rotated by the keypoint's angle) on a Gaussian-smoothed image;
//! brute-force Hamming matching with Lowe's ratio test and a mutual check.
//!
//! BRIEF's bits are intensity comparisons, so a monotonic change of appearance (another
//! tone curve, gain, smooth shading) leaves them unchanged; the orientation makes them
//! independent of the unknown yaw between the rectified fisheye and the north-up satellite.

use nalgebra::Vector2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::vision::GrayImage;

/// The 16 offsets of the FAST circle of radius 3, in order around it.
const CIRCLE: [(isize, isize); 16] = [
    (0, -3),
    (1, -3),
    (2, -2),
    (3, -1),
    (3, 0),
    (3, 1),
    (2, 2),
    (1, 3),
    (0, 3),
    (-1, 3),
    (-2, 2),
    (-3, 1),
    (-3, 0),
    (-3, -1),
    (-2, -2),
    (-1, -3),
];

/// Radius of the orientation patch and of the BRIEF pattern (px).
const PATCH_RADIUS: isize = 15;
/// Pixels a keypoint must keep from the border / invalid area.
pub const BORDER: usize = 18;

/// A keypoint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Keypoint {
    /// Pixel.
    pub xy: Vector2<f64>,
    /// Orientation (rad, image axes).
    pub angle: f64,
    /// FAST score.
    pub score: f32,
}

/// A 256-bit descriptor.
pub type Descriptor = [u64; 4];

/// Keypoints with their descriptors.
#[derive(Clone, Debug, Default)]
pub struct Features {
    /// Keypoints.
    pub keypoints: Vec<Keypoint>,
    /// Their descriptors.
    pub descriptors: Vec<Descriptor>,
}

/// Detector settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OrbOptions {
    /// FAST threshold as a fraction of the image's 5-95 % intensity range.
    pub threshold: f64,
    /// Most keypoints kept.
    pub max_features: usize,
    /// Cell size of the spatial spreading (px).
    pub cell_px: usize,
}

impl Default for OrbOptions {
    fn default() -> Self {
        Self {
            threshold: 0.08,
            max_features: 1500,
            cell_px: 24,
        }
    }
}

/// FAST-9 score of pixel `(x, y)` (sum of the excess over `t` on the longest arc), 0 if not
/// a corner.
fn fast_score(img: &GrayImage, x: usize, y: usize, t: f32) -> f32 {
    let p = img.at(x, y);
    let ring: [f32; 16] = std::array::from_fn(|k| {
        let (dx, dy) = CIRCLE[k];
        img.at((x as isize + dx) as usize, (y as isize + dy) as usize)
    });
    let mut best = 0.0f32;
    for sign in [1.0f32, -1.0] {
        let (mut run, mut sum, mut best_sum) = (0, 0.0f32, 0.0f32);
        let mut longest = 0;
        for k in 0..32 {
            let d = sign * (ring[k % 16] - p) - t;
            if d > 0.0 {
                run += 1;
                sum += d;
                if run > longest || (run == longest && sum > best_sum) {
                    longest = run.min(16);
                    best_sum = sum;
                }
            } else {
                run = 0;
                sum = 0.0;
            }
        }
        if longest >= 9 {
            best = best.max(best_sum);
        }
    }
    best
}

/// The intensity range between the 5 % and 95 % quantiles of the valid pixels.
fn contrast(img: &GrayImage, valid: &[bool]) -> f32 {
    let mut v: Vec<f32> = img
        .data()
        .iter()
        .zip(valid)
        .filter(|(_, ok)| **ok)
        .map(|(x, _)| *x)
        .collect();
    if v.len() < 20 {
        return 1.0;
    }
    v.sort_by(f32::total_cmp);
    (v[v.len() * 95 / 100] - v[v.len() * 5 / 100]).max(1.0)
}

/// `valid` shrunk by `r` px (a pixel stays valid when its whole (2r+1) square is).
pub fn erode(valid: &[bool], width: usize, height: usize, r: usize) -> Vec<bool> {
    let mut integral = vec![0u32; (width + 1) * (height + 1)];
    for y in 0..height {
        for x in 0..width {
            integral[(y + 1) * (width + 1) + x + 1] = u32::from(!valid[y * width + x])
                + integral[y * (width + 1) + x + 1]
                + integral[(y + 1) * (width + 1) + x]
                - integral[y * (width + 1) + x];
        }
    }
    (0..width * height)
        .map(|i| {
            let (x, y) = (i % width, i / width);
            if x < r || y < r || x + r >= width || y + r >= height {
                return false;
            }
            let (x0, y0, x1, y1) = (x - r, y - r, x + r + 1, y + r + 1);
            integral[y1 * (width + 1) + x1] + integral[y0 * (width + 1) + x0]
                - integral[y0 * (width + 1) + x1]
                - integral[y1 * (width + 1) + x0]
                == 0
        })
        .collect()
}

/// A corner: pixel and FAST score.
type Corner = (usize, usize, f32);

/// FAST keypoints where `valid` (eroded by [`BORDER`]), non-maximum suppressed, best few per
/// cell, at most `max_features`.
fn detect(img: &GrayImage, valid: &[bool], options: &OrbOptions) -> Vec<Corner> {
    let (w, h) = (img.width(), img.height());
    let inner = erode(valid, w, h, BORDER);
    let t = options.threshold as f32 * contrast(img, valid);
    let mut score = vec![0.0f32; w * h];
    for y in 3..h.saturating_sub(3) {
        for x in 3..w.saturating_sub(3) {
            if inner[y * w + x] {
                score[y * w + x] = fast_score(img, x, y, t);
            }
        }
    }
    let mut cells: std::collections::BTreeMap<(usize, usize), Vec<Corner>> =
        std::collections::BTreeMap::new();
    for y in 1..h.saturating_sub(1) {
        for x in 1..w.saturating_sub(1) {
            let s = score[y * w + x];
            let is_max = s > 0.0
                && (0..9).all(|k| {
                    let (dx, dy) = (k % 3, k / 3);
                    k == 4 || score[(y + dy - 1) * w + x + dx - 1] < s
                });
            if is_max {
                let cell = (x / options.cell_px.max(1), y / options.cell_px.max(1));
                cells.entry(cell).or_default().push((x, y, s));
            }
        }
    }
    let n_cells = cells.len().max(1);
    let per_cell = (options.max_features / n_cells).max(2);
    let mut out: Vec<Corner> = cells
        .into_values()
        .flat_map(|mut v| {
            v.sort_by(|a, b| b.2.total_cmp(&a.2));
            v.truncate(per_cell);
            v
        })
        .collect();
    out.sort_by(|a, b| b.2.total_cmp(&a.2));
    out.truncate(options.max_features);
    out
}

/// Orientation by the intensity centroid of the disc of radius [`PATCH_RADIUS`].
fn orientation(img: &GrayImage, x: usize, y: usize) -> f64 {
    let (mut m10, mut m01) = (0.0f64, 0.0f64);
    let r = PATCH_RADIUS;
    for dy in -r..=r {
        for dx in -r..=r {
            if dx * dx + dy * dy <= r * r {
                let v = f64::from(img.at((x as isize + dx) as usize, (y as isize + dy) as usize));
                m10 += dx as f64 * v;
                m01 += dy as f64 * v;
            }
        }
    }
    m01.atan2(m10)
}

/// The fixed BRIEF pattern: 256 point pairs, Gaussian (sigma 5 px) inside radius 13.
fn pattern() -> Vec<[Vector2<f64>; 2]> {
    let mut rng = ChaCha8Rng::seed_from_u64(0x0b1e_f00d);
    let mut point = || loop {
        let p = Vector2::new(
            rng.gen_range(-1.0..1.0f64) + rng.gen_range(-1.0..1.0) + rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0f64) + rng.gen_range(-1.0..1.0) + rng.gen_range(-1.0..1.0),
        ) * 5.0;
        if p.norm() <= 13.0 {
            return p;
        }
    };
    (0..256).map(|_| [point(), point()]).collect()
}

/// ORB features of `image` (0-255 or any scale) where `valid` (row-major, same size).
pub fn orb(image: &GrayImage, valid: &[bool], options: &OrbOptions) -> Features {
    let smooth = image.gaussian_blur(2.0);
    let corners = detect(image, valid, options);
    let pattern = pattern();
    let mut features = Features::default();
    for (x, y, score) in corners {
        let angle = orientation(&smooth, x, y);
        let (s, c) = angle.sin_cos();
        let mut d: Descriptor = [0; 4];
        for (k, [a, b]) in pattern.iter().enumerate() {
            let rot =
                |p: &Vector2<f64>| (x as f64 + c * p.x - s * p.y, y as f64 + s * p.x + c * p.y);
            let (ax, ay) = rot(a);
            let (bx, by) = rot(b);
            if smooth.sample(ax, ay) < smooth.sample(bx, by) {
                d[k / 64] |= 1 << (k % 64);
            }
        }
        features.keypoints.push(Keypoint {
            xy: Vector2::new(x as f64, y as f64),
            angle,
            score,
        });
        features.descriptors.push(d);
    }
    features
}

/// Hamming distance.
pub fn hamming(a: &Descriptor, b: &Descriptor) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x ^ y).count_ones()).sum()
}

/// The best and second-best distance and the best index of `d` in `set`.
fn nearest(d: &Descriptor, set: &[Descriptor]) -> (u32, u32, usize) {
    let mut best = (u32::MAX, u32::MAX, 0);
    for (j, e) in set.iter().enumerate() {
        let h = hamming(d, e);
        if h < best.0 {
            best = (h, best.0, j);
        } else if h < best.1 {
            best.1 = h;
        }
    }
    best
}

/// Matches `(i in a, j in b)`: distance below `max_distance`, below `ratio` times the
/// second best, and mutual nearest neighbours.
pub fn match_features(
    a: &Features,
    b: &Features,
    max_distance: u32,
    ratio: f64,
) -> Vec<(usize, usize)> {
    use rayon::prelude::*;
    a.descriptors
        .par_iter()
        .enumerate()
        .filter_map(|(i, d)| {
            let (best, second, j) = nearest(d, &b.descriptors);
            let distinct = f64::from(best) < ratio * f64::from(second);
            let back = nearest(&b.descriptors[j], &a.descriptors).2;
            (best <= max_distance && distinct && back == i).then_some((i, j))
        })
        .collect()
}
