//! Sub-pixel corner refinement by gradient orthogonality (Förstner; OpenCV's
//! `cornerSubPix`): the corner `q` minimises `sum_i w_i (g_i . (p_i - q))^2` over a window,
//! `g_i` the image gradient at `p_i`, `w_i` a Gaussian weight; on an X-junction every
//! gradient is orthogonal to the edge through `q`. Iterated, re-sampling the window around
//! the new estimate (bilinear), as OpenCV does, so results agree with OpenCV-refined
//! reference corners when the same window is used.

use super::gray::{floor, GrayImage};
use nalgebra::Vector2;

/// Settings of the refinement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SubpixParams {
    /// Half window, pixels: the window is `(2 half + 1)^2` (OpenCV's `winSize`).
    pub half_window: usize,
    /// Maximum iterations.
    pub max_iterations: usize,
    /// Stop when a step is shorter than this, pixels.
    pub epsilon_px: f64,
    /// Give up when the estimate moves farther than this from the start (per axis),
    /// pixels; `None`: the half window (OpenCV).
    pub max_shift_px: Option<f64>,
}

impl Default for SubpixParams {
    fn default() -> Self {
        Self {
            half_window: 5,
            max_iterations: 40,
            epsilon_px: 1e-3,
            max_shift_px: None,
        }
    }
}

/// Refines one corner; `None` when the normal equations are singular (flat window) or the
/// estimate leaves the window around `start`.
pub fn refine_corner(
    img: &GrayImage,
    start: Vector2<f64>,
    params: &SubpixParams,
) -> Option<Vector2<f64>> {
    let half = params.half_window.max(1);
    let n = 2 * half + 1;
    let coeff = 1.0 / (half * half) as f64;
    let mask: Vec<f32> = (0..n)
        .map(|i| {
            let d = i as f64 - half as f64;
            (-d * d * coeff).exp() as f32
        })
        .collect();
    let offsets: Vec<f32> = (0..n).map(|j| j as f32 - half as f32).collect();
    let mut patch = vec![0.0f32; (n + 2) * (n + 2)];
    let mut q = start;
    let eps2 = params.epsilon_px * params.epsilon_px;
    for _ in 0..params.max_iterations.max(1) {
        sample_patch(img, q, n + 2, &mut patch);
        let [a, b, c, bb1, bb2] = normal_equations(&patch, &mask, &offsets);
        let det = a * c - b * b;
        if det.abs() <= 1e-12 * (a * c).abs().max(1e-30) {
            return None;
        }
        let step = Vector2::new((c * bb1 - b * bb2) / det, (a * bb2 - b * bb1) / det);
        q += step;
        let outside = (q - start).abs().max() > params.max_shift_px.unwrap_or(half as f64);
        if outside || !q.iter().all(|x| x.is_finite()) {
            return None;
        }
        if step.norm_squared() <= eps2 {
            break;
        }
    }
    Some(q)
}

/// `[sum w gx^2, sum w gx gy, sum w gy^2, sum w (gx^2 x + gx gy y), sum w (gx gy x + gy^2 y)]`
/// over the window (central-difference gradients of the `(n + 2)^2` patch, `x, y` the
/// offsets from its centre, `w` the separable Gaussian mask): each row in f32 (it
/// vectorises), the rows summed in f64.
fn normal_equations(patch: &[f32], mask: &[f32], offsets: &[f32]) -> [f64; 5] {
    let n = mask.len();
    let stride = n + 2;
    let mut sums = [0.0f64; 5];
    for i in 0..n {
        let row = (i + 1) * stride;
        let (centre, above, below) = (
            &patch[row..row + stride],
            &patch[row - stride + 1..row + 1 + n],
            &patch[row + stride + 1..row + stride + 1 + n],
        );
        let (mut a, mut b, mut c, mut ax, mut bx) = (0.0f32, 0.0f32, 0.0f32, 0.0f32, 0.0f32);
        for j in 0..n {
            let m = mask[i] * mask[j];
            let gx = centre[j + 2] - centre[j];
            let gy = below[j] - above[j];
            let (gxx, gxy, gyy) = (gx * gx * m, gx * gy * m, gy * gy * m);
            a += gxx;
            b += gxy;
            c += gyy;
            ax += gxx * offsets[j];
            bx += gxy * offsets[j];
        }
        let py = f64::from(offsets[i]);
        sums[0] += f64::from(a);
        sums[1] += f64::from(b);
        sums[2] += f64::from(c);
        sums[3] += f64::from(ax) + py * f64::from(b);
        sums[4] += f64::from(bx) + py * f64::from(c);
    }
    sums
}

/// `patch[i][j] = img(q + (j - (size-1)/2, i - (size-1)/2))`, bilinear (OpenCV
/// `getRectSubPix`).
fn sample_patch(img: &GrayImage, q: Vector2<f64>, size: usize, patch: &mut [f32]) {
    let half = (size as f64 - 1.0) / 2.0;
    let (u0, v0) = (q.x - half, q.y - half);
    // One set of bilinear weights for the whole patch: integer offsets.
    let (x0, y0) = (floor(u0), floor(v0));
    let (fx, fy) = ((u0 - x0 as f64) as f32, (v0 - y0 as f64) as f32);
    let inside = x0 >= 0
        && y0 >= 0
        && (x0 as usize) + size < img.width()
        && (y0 as usize) + size < img.height();
    let w = img.width();
    let data = img.data();
    for i in 0..size {
        for j in 0..size {
            let (a, b, c, d) = if inside {
                let k = (y0 as usize + i) * w + x0 as usize + j;
                (data[k], data[k + 1], data[k + w], data[k + w + 1])
            } else {
                let (x, y) = (x0 + j as isize, y0 + i as isize);
                (
                    img.at_clamped(x, y),
                    img.at_clamped(x + 1, y),
                    img.at_clamped(x, y + 1),
                    img.at_clamped(x + 1, y + 1),
                )
            };
            let top = a + (b - a) * fx;
            let bottom = c + (d - c) * fx;
            patch[i * size + j] = top + (bottom - top) * fy;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An anti-aliased X-junction at `(cx, cy)` (exact area coverage by supersampling).
    fn x_junction(cx: f64, cy: f64) -> GrayImage {
        let (w, h) = (31, 31);
        let mut data = vec![0.0f32; w * h];
        let s = 16;
        for y in 0..h {
            for x in 0..w {
                let mut acc = 0.0;
                for sy in 0..s {
                    for sx in 0..s {
                        let u = x as f64 - 0.5 + (sx as f64 + 0.5) / s as f64 - cx;
                        let v = y as f64 - 0.5 + (sy as f64 + 0.5) / s as f64 - cy;
                        // Skewed lines: through the corner with slopes 0.3 and -2.
                        let a = v - 0.3 * u;
                        let b = u + 0.5 * v;
                        acc += if (a > 0.0) == (b > 0.0) { 200.0 } else { 30.0 };
                    }
                }
                data[y * w + x] = acc / (s * s) as f32;
            }
        }
        GrayImage::from_vec(w, h, data).unwrap()
    }

    #[test]
    fn refines_a_skewed_x_junction_to_a_twentieth_of_a_pixel() {
        let truth = Vector2::new(15.37, 14.81);
        let img = x_junction(truth.x, truth.y);
        let q = refine_corner(&img, Vector2::new(16.0, 14.0), &SubpixParams::default()).unwrap();
        assert!((q - truth).norm() < 0.06, "{q:?}");
    }

    #[test]
    fn a_flat_window_is_rejected() {
        let img = GrayImage::new(20, 20, 100.0);
        assert!(refine_corner(&img, Vector2::new(10.0, 10.0), &SubpixParams::default()).is_none());
    }
}
