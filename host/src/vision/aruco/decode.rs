//! Reading a candidate's bits: the quadrilateral is unwarped by its homography to a
//! canonical square of `cells x pixels_per_cell` pixels (nearest-neighbour samples, as
//! OpenCV's `warpPerspective` with `INTER_NEAREST`), binarised by Otsu's threshold, and each
//! cell's majority is its bit (white 1). The outer ring of cells must be black (the marker
//! border) up to a tolerated count of errors.

use nalgebra::{Matrix3, SMatrix, SVector, Vector2, Vector3};

use super::ArucoParams;
use crate::vision::gray::GrayImage;

/// The homography `H` with `H * (src_i, 1) ~ (dst_i, 1)` for four point pairs; `None` when
/// three of them are collinear.
pub fn homography_4pt(src: &[Vector2<f64>; 4], dst: &[Vector2<f64>; 4]) -> Option<Matrix3<f64>> {
    let mut a = SMatrix::<f64, 8, 8>::zeros();
    let mut b = SVector::<f64, 8>::zeros();
    for i in 0..4 {
        let (x, y) = (src[i].x, src[i].y);
        let (u, v) = (dst[i].x, dst[i].y);
        let r = 2 * i;
        a.row_mut(r)
            .copy_from_slice(&[x, y, 1.0, 0.0, 0.0, 0.0, -u * x, -u * y]);
        a.row_mut(r + 1)
            .copy_from_slice(&[0.0, 0.0, 0.0, x, y, 1.0, -v * x, -v * y]);
        b[r] = u;
        b[r + 1] = v;
    }
    let h = a.lu().solve(&b)?;
    h.iter()
        .all(|x| x.is_finite())
        .then(|| Matrix3::new(h[0], h[1], h[2], h[3], h[4], h[5], h[6], h[7], 1.0))
}

/// `H * (p, 1)`, dehomogenised.
pub fn apply(h: &Matrix3<f64>, p: Vector2<f64>) -> Vector2<f64> {
    let q = h * Vector3::new(p.x, p.y, 1.0);
    Vector2::new(q.x / q.z, q.y / q.z)
}

/// The bits of a candidate with `bits` inner bits per side: `(code, border errors)`, code
/// row-major from the canonical top-left (corner 0), first bit most significant; `None`
/// when the unwarp is degenerate.
pub(crate) fn read_bits(
    img: &GrayImage,
    corners: &[Vector2<f64>; 4],
    bits: usize,
    params: &ArucoParams,
) -> Option<(u64, usize)> {
    let cells = bits + 2;
    let ppc = params.pixels_per_cell;
    let side = cells * ppc;
    let last = (side - 1) as f64;
    let square = [
        Vector2::new(0.0, 0.0),
        Vector2::new(last, 0.0),
        Vector2::new(last, last),
        Vector2::new(0.0, last),
    ];
    let h = homography_4pt(&square, corners)?;
    let patch: Vec<u8> = (0..side * side)
        .map(|i| {
            let p = apply(&h, Vector2::new((i % side) as f64, (i / side) as f64));
            let (x, y) = (p.x.round() as isize, p.y.round() as isize);
            img.at_clamped(x, y).round().clamp(0.0, 255.0) as u8
        })
        .collect();
    let white = binarise(&patch, params.min_otsu_std_dev);
    let margin = (params.ignored_margin_per_cell * ppc as f64) as usize;
    let inner = ppc - 2 * margin;
    let mut code = 0u64;
    let mut border_errors = 0;
    for r in 0..cells {
        for c in 0..cells {
            let count = (0..inner * inner)
                .filter(|k| {
                    let y = r * ppc + margin + k / inner;
                    let x = c * ppc + margin + k % inner;
                    white[y * side + x]
                })
                .count();
            let is_white = count > inner * inner / 2;
            if r == 0 || c == 0 || r == cells - 1 || c == cells - 1 {
                border_errors += usize::from(is_white);
            } else {
                code = (code << 1) | u64::from(is_white);
            }
        }
    }
    Some((code, border_errors))
}

/// Otsu binarisation of a patch; a patch whose standard deviation is below `min_std` is all
/// white or all black by its mean.
fn binarise(patch: &[u8], min_std: f64) -> Vec<bool> {
    let n = patch.len() as f64;
    let mean = patch.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let var = patch
        .iter()
        .map(|&v| (f64::from(v) - mean).powi(2))
        .sum::<f64>()
        / n;
    if var.sqrt() < min_std {
        return vec![mean > 127.0; patch.len()];
    }
    let t = otsu(patch);
    patch.iter().map(|&v| v > t).collect()
}

/// Otsu's threshold of 8-bit values: pixels `> t` are the bright class.
pub fn otsu(values: &[u8]) -> u8 {
    let mut hist = [0usize; 256];
    values.iter().for_each(|&v| hist[v as usize] += 1);
    let total = values.len() as f64;
    let sum_all: f64 = hist
        .iter()
        .enumerate()
        .map(|(i, &c)| i as f64 * c as f64)
        .sum();
    let (mut w0, mut sum0) = (0.0, 0.0);
    let (mut best, mut best_t) = (-1.0, 0u8);
    for (t, &c) in hist.iter().enumerate() {
        w0 += c as f64;
        sum0 += t as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0, (sum_all - sum0) / w1);
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            best_t = t as u8;
        }
    }
    best_t
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homography_maps_the_four_points() {
        let src = [
            Vector2::new(0.0, 0.0),
            Vector2::new(1.0, 0.0),
            Vector2::new(1.0, 1.0),
            Vector2::new(0.0, 1.0),
        ];
        let dst = [
            Vector2::new(10.0, 12.0),
            Vector2::new(40.0, 9.0),
            Vector2::new(45.0, 50.0),
            Vector2::new(8.0, 41.0),
        ];
        let h = homography_4pt(&src, &dst).unwrap();
        for (s, d) in src.iter().zip(&dst) {
            assert!((apply(&h, *s) - d).norm() < 1e-9);
        }
    }

    #[test]
    fn otsu_splits_two_levels() {
        let v: Vec<u8> = [20u8; 50].iter().chain(&[200u8; 30]).copied().collect();
        let t = otsu(&v);
        assert!((20..200).contains(&t), "{t}");
    }
}
