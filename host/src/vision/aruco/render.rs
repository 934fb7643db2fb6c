//! Renders a printed ArUco marker into a grey image through a homography (a planar marker
//! under any pinhole view), anti-aliased by supersampling the pixel area: for the tests and
//! the image simulator. Pixel `(x, y)` covers `[x - 0.5, x + 0.5] x [y - 0.5, y + 0.5]`
//! (docs/formats.md).

use nalgebra::{Matrix3, Vector2};

use super::decode::{apply, homography_4pt};
use super::dictionary::{bit, Dictionary};
use crate::vision::gray::GrayImage;

/// Grey levels of the print.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ink {
    /// Black cells.
    pub black: f32,
    /// White cells and the white quiet zone.
    pub white: f32,
}

/// The marker-plane value at `(s, t)`, both in units of the black square's side with the
/// printed top-left at (0, 0) and the bottom-right at (1, 1); `None` outside the white
/// quiet zone of `quiet` sides.
pub fn marker_value(
    dictionary: Dictionary,
    id: usize,
    s: f64,
    t: f64,
    quiet: f64,
    ink: Ink,
) -> Option<f32> {
    if s < -quiet || t < -quiet || s >= 1.0 + quiet || t >= 1.0 + quiet {
        return None;
    }
    if !(0.0..1.0).contains(&s) || !(0.0..1.0).contains(&t) {
        return Some(ink.white);
    }
    let n = dictionary.bits();
    let cells = (n + 2) as f64;
    let (c, r) = ((s * cells) as usize, (t * cells) as usize);
    if r == 0 || c == 0 || r == n + 1 || c == n + 1 {
        return Some(ink.black);
    }
    let code = dictionary.codes().get(id).copied().unwrap_or(0);
    Some(if bit(code, n, r - 1, c - 1) {
        ink.white
    } else {
        ink.black
    })
}

/// Paints marker `id` (with a white quiet zone `quiet` sides wide) whose black square's
/// corners appear at `corners` (OpenCV order: printed top-left, top-right, bottom-right,
/// bottom-left), `supersample^2` samples per pixel. Returns false when the corners are
/// degenerate.
pub fn render_marker(
    img: &mut GrayImage,
    dictionary: Dictionary,
    id: usize,
    corners: &[Vector2<f64>; 4],
    quiet: f64,
    ink: Ink,
    supersample: usize,
) -> bool {
    let unit = [
        Vector2::new(0.0, 0.0),
        Vector2::new(1.0, 0.0),
        Vector2::new(1.0, 1.0),
        Vector2::new(0.0, 1.0),
    ];
    let Some(h) = homography_4pt(corners, &unit) else {
        return false;
    };
    let Some(h_inv) = h.try_inverse() else {
        return false;
    };
    let outer: Vec<Vector2<f64>> = [
        (-quiet, -quiet),
        (1.0 + quiet, -quiet),
        (1.0 + quiet, 1.0 + quiet),
        (-quiet, 1.0 + quiet),
    ]
    .iter()
    .map(|&(s, t)| apply(&h_inv, Vector2::new(s, t)))
    .collect();
    let (w, hgt) = (img.width() as f64, img.height() as f64);
    let lo = |f: fn(&Vector2<f64>) -> f64| outer.iter().map(f).fold(f64::INFINITY, f64::min);
    let hi = |f: fn(&Vector2<f64>) -> f64| outer.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
    let x0 = lo(|p| p.x).floor().max(0.0) as usize;
    let y0 = lo(|p| p.y).floor().max(0.0) as usize;
    let x1 = hi(|p| p.x).ceil().min(w - 1.0).max(0.0) as usize;
    let y1 = hi(|p| p.y).ceil().min(hgt - 1.0).max(0.0) as usize;
    let width = img.width();
    for y in y0..=y1 {
        for x in x0..=x1 {
            if let Some(v) = pixel_value(&h, x, y, supersample, img.at(x, y), |s, t| {
                marker_value(dictionary, id, s, t, quiet, ink)
            }) {
                img.data_mut()[y * width + x] = v;
            }
        }
    }
    true
}

/// The area average of a pixel, `value(s, t)` where the marker covers the sample and the
/// old value elsewhere; `None` when no sample hits the marker.
fn pixel_value(
    h: &Matrix3<f64>,
    x: usize,
    y: usize,
    supersample: usize,
    old: f32,
    value: impl Fn(f64, f64) -> Option<f32>,
) -> Option<f32> {
    let s = supersample.max(1);
    let mut acc = 0.0f32;
    let mut hit = false;
    for j in 0..s {
        for i in 0..s {
            let u = x as f64 - 0.5 + (i as f64 + 0.5) / s as f64;
            let v = y as f64 - 0.5 + (j as f64 + 0.5) / s as f64;
            let p = apply(h, Vector2::new(u, v));
            match value(p.x, p.y) {
                Some(val) => {
                    acc += val;
                    hit = true;
                }
                None => acc += old,
            }
        }
    }
    hit.then_some(acc / (s * s) as f32)
}
