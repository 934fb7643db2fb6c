//! Marker candidates: adaptive threshold (dark pixels below the local mean minus a
//! constant), connected components, their outer boundaries, a closed Douglas-Peucker
//! polygon and the quadrilateral gates (size, convexity, corner spacing, image border).

use nalgebra::Vector2;

use super::ArucoParams;
use crate::vision::components::Labels;
use crate::vision::gray::GrayImage;

/// A convex quadrilateral, corners clockwise on screen, integer contour points.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Quad {
    /// The corners.
    pub corners: [Vector2<f64>; 4],
    /// Boundary length of the contour it came from, pixels (contour points).
    pub perimeter: usize,
}

/// Dark pixels: `img <= mean over a window x window box - constant`, the mean rounded
/// to a grey level as in 8-bit images.
pub(crate) fn adaptive_threshold(img: &GrayImage, window: usize, constant: f32) -> Vec<bool> {
    let mean = img.box_mean(window / 2);
    img.data()
        .iter()
        .zip(mean.data())
        .map(|(&v, &m)| v <= m.round() - constant)
        .collect()
}

/// Quadrilateral candidates of one binary mask.
pub(crate) fn quads_of_mask(
    mask: &[bool],
    width: usize,
    height: usize,
    params: &ArucoParams,
) -> Vec<Quad> {
    let labels = Labels::new(mask, width, height);
    let max_dim = width.max(height) as f64;
    let min_perimeter = params.min_perimeter_rate * max_dim;
    let max_perimeter = params.max_perimeter_rate * max_dim;
    let mut out = Vec::new();
    for (k, comp) in labels.components.iter().enumerate() {
        let (w, h) = comp.size();
        // The boundary is at least twice the larger side: cheap reject of specks.
        if ((2 * (w + h)) as f64) < min_perimeter {
            continue;
        }
        let contour = labels.outer_boundary(k);
        let n = contour.len() as f64;
        if n < min_perimeter || n > max_perimeter {
            continue;
        }
        let poly = approx_closed(&contour, n * params.polygon_accuracy_rate);
        if let Some(q) = quad_of_polygon(&poly, contour.len(), width, height, params) {
            out.push(q);
        }
    }
    out
}

/// The gates of OpenCV's candidate filter on a polygon: four vertices, convex, corners at
/// least `min_corner_distance_rate * perimeter` apart and `min_distance_to_border` px from
/// the image border. Reorders the corners clockwise on screen.
fn quad_of_polygon(
    poly: &[(i32, i32)],
    perimeter: usize,
    width: usize,
    height: usize,
    params: &ArucoParams,
) -> Option<Quad> {
    if poly.len() != 4 {
        return None;
    }
    let mut c: [Vector2<f64>; 4] =
        std::array::from_fn(|i| Vector2::new(f64::from(poly[i].0), f64::from(poly[i].1)));
    let cross = |a: Vector2<f64>, b: Vector2<f64>, o: Vector2<f64>| {
        (a - o).x * (b - o).y - (a - o).y * (b - o).x
    };
    let signs: Vec<f64> = (0..4)
        .map(|i| cross(c[(i + 1) % 4], c[(i + 2) % 4], c[i]))
        .collect();
    let convex = signs.iter().all(|&s| s > 0.0) || signs.iter().all(|&s| s < 0.0);
    if !convex {
        return None;
    }
    if signs[0] < 0.0 {
        c.swap(1, 3);
    }
    let min_dist = params.min_corner_distance_rate * perimeter as f64;
    let too_close = (0..4).any(|i| (c[i] - c[(i + 1) % 4]).norm() < min_dist);
    let b = params.min_distance_to_border as f64;
    let near_border = c.iter().any(|p| {
        p.x < b || p.y < b || p.x > width as f64 - 1.0 - b || p.y > height as f64 - 1.0 - b
    });
    (!too_close && !near_border).then_some(Quad {
        corners: c,
        perimeter,
    })
}

/// Douglas-Peucker simplification of a closed contour with tolerance `eps` px: split at
/// the point farthest from the first point and at the point farthest from that one, then
/// simplify both chains.
pub(super) fn approx_closed(contour: &[(i32, i32)], eps: f64) -> Vec<(i32, i32)> {
    let n = contour.len();
    if n < 3 {
        return contour.to_vec();
    }
    let d2 = |a: (i32, i32), b: (i32, i32)| {
        let (dx, dy) = (f64::from(a.0 - b.0), f64::from(a.1 - b.1));
        dx * dx + dy * dy
    };
    let far_from = |i: usize| {
        (0..n).max_by(|&a, &b| d2(contour[a], contour[i]).total_cmp(&d2(contour[b], contour[i])))
    };
    let a = far_from(0).unwrap_or(0);
    let b = far_from(a).unwrap_or(0);
    let (a, b) = (a.min(b), a.max(b));
    if a == b {
        return vec![contour[a]];
    }
    let first: Vec<(i32, i32)> = contour[a..=b].to_vec();
    let second: Vec<(i32, i32)> = contour[b..].iter().chain(&contour[..=a]).copied().collect();
    let mut out = douglas_peucker(&first, eps);
    out.pop();
    let mut rest = douglas_peucker(&second, eps);
    rest.pop();
    out.extend(rest);
    out
}

/// Open-chain Douglas-Peucker; keeps both end points.
fn douglas_peucker(chain: &[(i32, i32)], eps: f64) -> Vec<(i32, i32)> {
    let n = chain.len();
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[n - 1] = true;
    let mut stack = vec![(0, n - 1)];
    while let Some((i, j)) = stack.pop() {
        if j <= i + 1 {
            continue;
        }
        let (p, q) = (chain[i], chain[j]);
        let (dx, dy) = (f64::from(q.0 - p.0), f64::from(q.1 - p.1));
        let len = dx.hypot(dy);
        let dist = |r: (i32, i32)| {
            let (rx, ry) = (f64::from(r.0 - p.0), f64::from(r.1 - p.1));
            if len > 0.0 {
                (dx * ry - dy * rx).abs() / len
            } else {
                rx.hypot(ry)
            }
        };
        let (k, dmax) = (i + 1..j)
            .map(|k| (k, dist(chain[k])))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((i, 0.0));
        if dmax > eps {
            keep[k] = true;
            stack.push((i, k));
            stack.push((k, j));
        }
    }
    chain
        .iter()
        .zip(keep)
        .filter_map(|(&p, k)| k.then_some(p))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_contour_simplifies_to_its_four_corners() {
        let mut contour = Vec::new();
        for x in 0..10 {
            contour.push((x, 0));
        }
        for y in 1..10 {
            contour.push((9, y));
        }
        for x in (0..9).rev() {
            contour.push((x, 9));
        }
        for y in (1..9).rev() {
            contour.push((0, y));
        }
        let mut poly = approx_closed(&contour, 1.0);
        poly.sort();
        assert_eq!(poly, vec![(0, 0), (0, 9), (9, 0), (9, 9)]);
    }
}
