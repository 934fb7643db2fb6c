//! Candidate X-junctions: the saddle response `sqrt(Ixy^2 - Ixx Iyy)` of the smoothed
//! image's Hessian, normalised by the local contrast (uneven lighting), non-maximum
//! suppressed; then a ring test keeps points around which the intensity alternates
//! dark/bright exactly twice, with the four edges crossing the ring in two opposite pairs
//! (the local signature of an inner checkerboard corner, also under fisheye distortion).
//! The ring test also yields the four edge directions, which guide the grid growing.

use std::f64::consts::PI;
use std::sync::OnceLock;

use super::gray::GrayImage;
use nalgebra::Vector2;
use rayon::prelude::*;

/// An X-junction candidate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Saddle {
    /// Pixel position.
    pub pixel: Vector2<f64>,
    /// Normalised saddle response.
    pub response: f64,
    /// The four edge directions (radians, atan2(dv, du), increasing), each pointing from
    /// the corner along one edge towards a neighbouring corner.
    pub edges: [f64; 4],
    /// Half the dark/bright amplitude on the ring, grey levels.
    pub amplitude: f64,
}

/// Settings of the candidate detector.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SaddleParams {
    /// Smoothing before the Hessian, pixels.
    pub sigma: f64,
    /// Minimum contrast-normalised saddle response.
    pub min_response: f64,
    /// Half size of the local contrast window, pixels.
    pub contrast_radius: usize,
    /// Ring radii tried in the ring test, pixels.
    pub ring_radii: [f64; 2],
    /// Minimum ring amplitude (half dark-to-bright difference), grey levels.
    pub min_amplitude: f64,
    /// Most candidates kept (strongest first).
    pub max_candidates: usize,
}

impl Default for SaddleParams {
    fn default() -> Self {
        Self {
            sigma: 1.5,
            min_response: 0.04,
            contrast_radius: 6,
            ring_radii: [6.0, 3.5],
            min_amplitude: 4.0,
            max_candidates: 4000,
        }
    }
}

/// The smoothed image and its candidates.
pub fn find_saddles(img: &GrayImage, params: &SaddleParams) -> (GrayImage, Vec<Saddle>) {
    let smooth = img.gaussian_blur(params.sigma);
    let response = saddle_response(&smooth, params.contrast_radius);
    let mut peaks = local_maxima(&response, params.min_response);

    peaks.sort_by(|a, b| b.1.total_cmp(&a.1));
    peaks.truncate(params.max_candidates);
    let saddles = peaks
        .into_par_iter()
        .filter_map(|(p, r)| {
            params
                .ring_radii
                .iter()
                .find_map(|&radius| {
                    ring_test(&smooth, p, radius, params.min_amplitude, &STRICT_RING)
                })
                .map(|(edges, amplitude)| Saddle {
                    pixel: p,
                    response: r,
                    edges,
                    amplitude,
                })
        })
        .collect::<Vec<Saddle>>();
    (smooth, saddles)
}

/// Grey levels added to the local standard deviation before normalising: keeps flat,
/// noisy areas from matching real corners.
const CONTRAST_FLOOR: f32 = 10.0;

/// `sqrt(max(Ixy^2 - Ixx Iyy, 0)) / (local std + CONTRAST_FLOOR)` per pixel (zero on the
/// border).
fn saddle_response(smooth: &GrayImage, contrast_radius: usize) -> GrayImage {
    let (w, h) = (smooth.width(), smooth.height());
    let mut out = GrayImage::new(w, h, 0.0);
    if w < 3 || h < 3 {
        return out;
    }
    let std = local_std(smooth, contrast_radius);
    let d = smooth.data();
    let rows = out.data_mut().par_chunks_mut(w).enumerate();
    rows.skip(1).take(h - 2).for_each(|(y, o)| {
        for (x, ox) in o.iter_mut().enumerate().take(w - 1).skip(1) {
            let i = y * w + x;
            let ixx = d[i + 1] - 2.0 * d[i] + d[i - 1];
            let iyy = d[i + w] - 2.0 * d[i] + d[i - w];
            let ixy = 0.25 * (d[i + w + 1] - d[i + w - 1] - d[i - w + 1] + d[i - w - 1]);
            let s = ixy * ixy - ixx * iyy;
            if s > 0.0 {
                *ox = s.sqrt() / (std[i] + CONTRAST_FLOOR);
            }
        }
    });
    out
}

/// The standard deviation over the `(2r+1)^2` box around every pixel, border replicated:
/// running sums of the values and their squares (f64, so the variance does not cancel),
/// down the columns, then along each row: O(1) per pixel whatever `r`.
fn local_std(img: &GrayImage, r: usize) -> Vec<f32> {
    let (w, h) = (img.width(), img.height());
    let d = img.data();
    let row = |y: isize| {
        let y = y.clamp(0, h as isize - 1) as usize;
        &d[y * w..(y + 1) * w]
    };
    let (mut s1, mut s2) = (vec![0.0f64; w], vec![0.0f64; w]);
    let ri = r as isize;
    for k in -ri..=ri {
        for (x, &v) in row(k).iter().enumerate() {
            s1[x] += f64::from(v);
            s2[x] += f64::from(v) * f64::from(v);
        }
    }
    let n = ((2 * r + 1) * (2 * r + 1)) as f64;
    let mut out = vec![0.0f32; w * h];
    for y in 0..h {
        if y > 0 {
            let (add, sub) = (row(y as isize + ri), row(y as isize - 1 - ri));
            for x in 0..w {
                let (a, b) = (f64::from(add[x]), f64::from(sub[x]));
                s1[x] += a - b;
                s2[x] += a * a - b * b;
            }
        }
        let (mut t1, mut t2) = (0.0, 0.0);
        for k in -ri..=ri {
            let x = k.clamp(0, w as isize - 1) as usize;
            t1 += s1[x];
            t2 += s2[x];
        }
        for x in 0..w {
            if x > 0 {
                let (a, b) = ((x + r).min(w - 1), x.saturating_sub(r + 1));
                t1 += s1[a] - s1[b];
                t2 += s2[a] - s2[b];
            }
            let mean = t1 / n;
            out[y * w + x] = (t2 / n - mean * mean).max(0.0).sqrt() as f32;
        }
    }
    out
}

/// Strict maxima of their 5x5 neighbourhood above `min`, refined to sub-pixel by a
/// quadratic fit.
fn local_maxima(resp: &GrayImage, min: f64) -> Vec<(Vector2<f64>, f64)> {
    let (w, h) = (resp.width(), resp.height());
    let d = resp.data();
    let mut out = Vec::new();
    let r = 2;
    if w <= 2 * r || h <= 2 * r {
        return out;
    }
    for y in r..h - r {
        for x in r..w - r {
            let v = d[y * w + x];
            if f64::from(v) < min {
                continue;
            }
            let mut is_max = true;
            'n: for yy in y - r..=y + r {
                for xx in x - r..=x + r {
                    let o = d[yy * w + xx];
                    if o > v || (o >= v && (yy, xx) < (y, x)) {
                        is_max = false;
                        break 'n;
                    }
                }
            }
            if is_max {
                let fx = quadratic_offset(d[y * w + x - 1], v, d[y * w + x + 1]);
                let fy = quadratic_offset(d[(y - 1) * w + x], v, d[(y + 1) * w + x]);
                out.push((Vector2::new(x as f64 + fx, y as f64 + fy), f64::from(v)));
            }
        }
    }
    out
}

fn quadratic_offset(a: f32, b: f32, c: f32) -> f64 {
    let den = f64::from(a - 2.0 * b + c);
    if den.abs() < 1e-12 {
        0.0
    } else {
        (0.5 * f64::from(a - c) / den).clamp(-0.5, 0.5)
    }
}

const RING_SAMPLES: usize = 48;

/// Tolerances of the ring test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RingTolerance {
    /// Largest deviation from 180 degrees between opposite edges, rad.
    pub opposite: f64,
    /// Largest point asymmetry `mean |I(a) - I(a + pi)| / (2 amplitude)` (0 for an ideal
    /// X-junction, ~1 for an edge or an L-corner).
    pub asymmetry: f64,
}

/// The ring test of the candidate detector.
pub const STRICT_RING: RingTolerance = RingTolerance {
    opposite: 0.45,
    asymmetry: 0.35,
};

/// The ring test of the grid's guided local search (blurred or misprinted junctions).
pub const GUIDED_RING: RingTolerance = RingTolerance {
    opposite: 1.0,
    asymmetry: 0.35,
};

/// The ring test at `radius`: exactly four sign changes of `I - mean` (with hysteresis),
/// edges in two pairs opposite within `opposite_tolerance`; returns the edge angles and the
/// amplitude.
pub fn ring_test(
    smooth: &GrayImage,
    p: Vector2<f64>,
    radius: f64,
    min_amplitude: f64,
    tolerance: &RingTolerance,
) -> Option<([f64; 4], f64)> {
    let mut v = [0.0f64; RING_SAMPLES];
    for (x, (c, s)) in v.iter_mut().zip(ring_directions()) {
        *x = f64::from(smooth.sample(p.x + radius * c, p.y + radius * s));
    }
    let (lo, hi) = v
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    let amplitude = 0.5 * (hi - lo);
    if amplitude < min_amplitude {
        return None;
    }
    let half_turn = RING_SAMPLES / 2;
    let asymmetry = (0..half_turn)
        .map(|k| (v[k] - v[k + half_turn]).abs())
        .sum::<f64>()
        / (half_turn as f64 * 2.0 * amplitude);
    if asymmetry > tolerance.asymmetry {
        return None;
    }
    // The ring's mean separates dark from bright even when one dark square is fainter.
    let mid = v.iter().sum::<f64>() / RING_SAMPLES as f64;
    let band = 0.15 * amplitude;
    // Hysteresis labels: +1 above mid+band, -1 below mid-band, 0 between.
    let labels: [i8; RING_SAMPLES] = std::array::from_fn(|k| {
        if v[k] > mid + band {
            1
        } else if v[k] < mid - band {
            -1
        } else {
            0
        }
    });
    let first = labels.iter().position(|&l| l != 0)?;
    let mut crossings = [0.0; 4];
    let mut found = 0;
    let mut last = first;
    for step in 1..=RING_SAMPLES {
        let k = (first + step) % RING_SAMPLES;
        if labels[k] == 0 {
            continue;
        }
        if labels[k] != labels[last] {
            if found == 4 {
                return None;
            }
            crossings[found] = crossing_angle(&v, last, k, mid);
            found += 1;
        }
        last = k;
    }
    if found != 4 {
        return None;
    }
    crossings.sort_by(f64::total_cmp);
    let opposite = |a: f64, b: f64| (wrap(b - a).abs() - PI).abs() < tolerance.opposite;
    if !opposite(crossings[0], crossings[2]) || !opposite(crossings[1], crossings[3]) {
        return None;
    }
    // Each sector at least ~15 degrees.
    for k in 0..4 {
        let next = if k == 3 {
            crossings[0] + 2.0 * PI
        } else {
            crossings[k + 1]
        };
        if next - crossings[k] < 0.26 {
            return None;
        }
    }
    Some((crossings, amplitude))
}

/// `(cos, sin)` of the ring's sample angles `2 pi k / RING_SAMPLES`.
fn ring_directions() -> &'static [(f64, f64); RING_SAMPLES] {
    static TABLE: OnceLock<[(f64, f64); RING_SAMPLES]> = OnceLock::new();
    TABLE.get_or_init(|| {
        std::array::from_fn(|k| {
            let a = 2.0 * PI * k as f64 / RING_SAMPLES as f64;
            (a.cos(), a.sin())
        })
    })
}

/// The angle where the ring crosses `mid` between samples `from` and `to` (circular).
fn crossing_angle(v: &[f64; RING_SAMPLES], from: usize, to: usize, mid: f64) -> f64 {
    let n = RING_SAMPLES;
    let span = (to + n - from) % n;
    let mut k = from;
    for _ in 0..span {
        let k1 = (k + 1) % n;
        let (a, b) = (v[k] - mid, v[k1] - mid);
        if (a <= 0.0) != (b <= 0.0) || b == 0.0 {
            let t = if (a - b).abs() > 1e-12 {
                a / (a - b)
            } else {
                0.5
            };
            let idx = k as f64 + t.clamp(0.0, 1.0);
            return (2.0 * PI * idx / n as f64).rem_euclid(2.0 * PI);
        }
        k = k1;
    }
    (2.0 * PI * (from as f64 + 0.5 * span as f64) / n as f64).rem_euclid(2.0 * PI)
}

/// An angle wrapped to (-pi, pi].
pub fn wrap(a: f64) -> f64 {
    let r = (a + PI).rem_euclid(2.0 * PI) - PI;
    if r <= -PI {
        r + 2.0 * PI
    } else {
        r
    }
}
