//! Grid growing (after Geiger et al., "Automatic camera and range sensor calibration using a
//! single shot", ICRA 2012): a 3x3 seed from a candidate and its neighbours along its four
//! edges, then whole rows/columns added on each side by extrapolating every line (the next
//! step predicted from the last two as `d1^2 / d2` in complex numbers, which follows both
//! perspective foreshortening and fisheye bending). A missing candidate is searched for
//! locally (sub-pixel saddle + ring test at the prediction). Growth stops at the board's
//! border, where no X-junctions remain.

use super::gray::GrayImage;
use super::saddle::{ring_test, Saddle, GUIDED_RING};
use super::subpix::{refine_corner, SubpixParams};
use nalgebra::Vector2;

/// A rectangular grid of corner pixels, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct Grid {
    /// Rows of the grid.
    pub rows: usize,
    /// Columns of the grid.
    pub cols: usize,
    /// `rows * cols` pixels, row-major.
    pub pixels: Vec<Vector2<f64>>,
}

impl Grid {
    /// The pixel at `(r, c)`.
    pub fn at(&self, r: usize, c: usize) -> Vector2<f64> {
        self.pixels[r * self.cols + c]
    }
}

/// Candidates with a bucket index (a flat grid of 16 px cells) for radius queries, and
/// their edge directions as unit vectors.
pub struct Candidates {
    saddles: Vec<Saddle>,
    edge_dirs: Vec<[Vector2<f64>; 4]>,
    cell: f64,
    nx: usize,
    ny: usize,
    buckets: Vec<Vec<usize>>,
}

impl Candidates {
    /// Indexes the candidates of a `width` x `height` image (candidates outside it are
    /// kept in the border cells).
    pub fn new(saddles: Vec<Saddle>, width: usize, height: usize) -> Self {
        let cell = 16.0;
        let nx = (width as f64 / cell).ceil().max(1.0) as usize;
        let ny = (height as f64 / cell).ceil().max(1.0) as usize;
        let mut c = Self {
            saddles: Vec::with_capacity(saddles.len()),
            edge_dirs: Vec::with_capacity(saddles.len()),
            cell,
            nx,
            ny,
            buckets: vec![Vec::new(); nx * ny],
        };
        for s in saddles {
            c.push(s);
        }
        c
    }

    /// The cell column and row of `p`, clamped to the grid.
    fn key(&self, p: &Vector2<f64>) -> (usize, usize) {
        let k = |v: f64, n: usize| ((v / self.cell).floor().max(0.0) as usize).min(n - 1);
        (k(p.x, self.nx), k(p.y, self.ny))
    }

    fn push(&mut self, s: Saddle) -> usize {
        let i = self.saddles.len();
        let (kx, ky) = self.key(&s.pixel);
        self.buckets[ky * self.nx + kx].push(i);
        self.edge_dirs
            .push(s.edges.map(|e| Vector2::new(e.cos(), e.sin())));
        self.saddles.push(s);
        i
    }

    /// The candidates.
    pub fn saddles(&self) -> &[Saddle] {
        &self.saddles
    }

    /// Calls `f(i, distance)` for every candidate within `radius` of `p`.
    fn for_each_within(&self, p: &Vector2<f64>, radius: f64, mut f: impl FnMut(usize, f64)) {
        let (kx0, ky0) = self.key(&(p - Vector2::new(radius, radius)));
        let (kx1, ky1) = self.key(&(p + Vector2::new(radius, radius)));
        for ky in ky0..=ky1 {
            for kx in kx0..=kx1 {
                for &i in &self.buckets[ky * self.nx + kx] {
                    let dist = (self.saddles[i].pixel - p).norm();
                    if dist <= radius {
                        f(i, dist);
                    }
                }
            }
        }
    }

    fn nearest(&self, p: &Vector2<f64>, radius: f64, used: &[bool]) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        self.for_each_within(p, radius, |i, dist| {
            let free = !used.get(i).copied().unwrap_or(false);
            if free && best.is_none_or(|(_, bd)| dist < bd) {
                best = Some((i, dist));
            }
        });
        best.map(|(i, _)| i)
    }

    /// True when an edge of candidate `i` points along `d` (length `dist`) within the
    /// angle whose cosine is `cos_max`.
    fn edge_points(&self, i: usize, d: &Vector2<f64>, dist: f64, cos_max: f64) -> bool {
        self.edge_dirs[i].iter().any(|e| e.dot(d) > cos_max * dist)
    }
}

/// Settings of the grid growing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrowParams {
    /// Largest angle between an edge and the direction to the neighbour it leads to, rad.
    pub max_edge_angle: f64,
    /// Search radius around a prediction, as a fraction of the local step.
    pub search_fraction: f64,
    /// Ring radius of the local search, pixels (capped at 0.3 of the local step).
    pub ring_radius: f64,
    /// Minimum ring amplitude, grey levels.
    pub min_amplitude: f64,
    /// Grids stop growing beyond this many rows or columns.
    pub max_dim: usize,
}

/// Grows a grid from candidate `seed`; `None` when no 3x3 seed forms.
pub fn grow(
    cands: &mut Candidates,
    seed: usize,
    smooth: &GrayImage,
    params: &GrowParams,
) -> Option<(Grid, Vec<usize>)> {
    let mut used = vec![false; cands.saddles.len()];
    let mut g = seed_grid(cands, seed, params, &mut used)?;
    loop {
        let mut grew = false;
        for side in 0..4 {
            if (g.len() >= params.max_dim && side < 2)
                || (g[0].len() >= params.max_dim && side >= 2)
            {
                continue;
            }
            if let Some(line) = extend(cands, &g, side, smooth, params, &mut used) {
                insert_line(&mut g, side, line);
                grew = true;
            }
        }
        if !grew {
            break;
        }
    }
    let rows = g.len();
    let cols = g[0].len();
    let members: Vec<usize> = g.iter().flatten().copied().collect();
    let pixels = members.iter().map(|&i| cands.saddles[i].pixel).collect();
    Some((Grid { rows, cols, pixels }, members))
}

fn seed_grid(
    cands: &Candidates,
    seed: usize,
    params: &GrowParams,
    used: &mut Vec<bool>,
) -> Option<Vec<Vec<usize>>> {
    let s = cands.saddles[seed];
    let n = neighbours_along_edges(cands, seed, params)?;
    let p = |i: usize| cands.saddles[i].pixel;
    // e0 -> +c, e1 -> +r, e2 -> -c, e3 -> -r.
    let mut g = vec![vec![usize::MAX; 3]; 3];
    g[1][1] = seed;
    g[1][2] = n[0];
    g[2][1] = n[1];
    g[1][0] = n[2];
    g[0][1] = n[3];
    used.resize(cands.saddles.len(), false);
    for &i in &[seed, n[0], n[1], n[2], n[3]] {
        if used[i] {
            return None;
        }
        used[i] = true;
    }
    let diagonals = [
        ((2, 2), n[0], n[1]),
        ((0, 0), n[2], n[3]),
        ((0, 2), n[0], n[3]),
        ((2, 0), n[2], n[1]),
    ];
    for ((r, c), a, b) in diagonals {
        let pred = p(a) + p(b) - s.pixel;
        let step = (p(a) - s.pixel).norm().min((p(b) - s.pixel).norm());
        let j = cands.nearest(&pred, params.search_fraction * step, used)?;
        used[j] = true;
        g[r][c] = j;
    }
    Some(g)
}

/// For each of the four edges of candidate `i`, the nearest candidate along it whose own
/// edges point back (searched within 24, then 64, then 160 px); `None` when an edge has
/// none.
fn neighbours_along_edges(cands: &Candidates, i: usize, params: &GrowParams) -> Option<[usize; 4]> {
    let s = cands.saddles[i];
    let cos_max = params.max_edge_angle.cos();
    let dirs = cands.edge_dirs[i];
    let mut best: [Option<(usize, f64)>; 4] = [None; 4];
    let mut settled = [false; 4];
    for radius in [24.0, 64.0, 160.0] {
        cands.for_each_within(&s.pixel, radius, |j, dist| {
            if j == i || dist < 3.0 {
                return;
            }
            let d = cands.saddles[j].pixel - s.pixel;
            let mut points_back = None;
            for k in 0..4 {
                if settled[k] || dirs[k].dot(&d) <= cos_max * dist {
                    continue;
                }
                let back =
                    *points_back.get_or_insert_with(|| cands.edge_points(j, &-d, dist, cos_max));
                if back && best[k].is_none_or(|(_, bd)| dist < bd) {
                    best[k] = Some((j, dist));
                }
            }
        });
        for k in 0..4 {
            settled[k] = best[k].is_some();
        }
        if settled.iter().all(|&x| x) {
            break;
        }
    }
    Some([best[0]?.0, best[1]?.0, best[2]?.0, best[3]?.0])
}

/// Line `k` of the grid seen from `side`, ordered from the border inwards:
/// side 0 = below the last row, 1 = above the first, 2 = right of the last column,
/// 3 = left of the first.
fn line_towards(g: &[Vec<usize>], side: usize, k: usize, depth: usize) -> Option<usize> {
    let (rows, cols) = (g.len(), g[0].len());
    match side {
        0 => (depth < rows).then(|| g[rows - 1 - depth][k]),
        1 => (depth < rows).then(|| g[depth][k]),
        2 => (depth < cols).then(|| g[k][cols - 1 - depth]),
        _ => (depth < cols).then(|| g[k][depth]),
    }
}

fn extend(
    cands: &mut Candidates,
    g: &[Vec<usize>],
    side: usize,
    smooth: &GrayImage,
    params: &GrowParams,
    used: &mut Vec<bool>,
) -> Option<Vec<usize>> {
    let len = if side < 2 { g[0].len() } else { g.len() };
    let mut line = Vec::with_capacity(len);
    let mut claimed = Vec::new();
    for k in 0..len {
        let p0 = cands.saddles[line_towards(g, side, k, 0)?].pixel;
        let p1 = cands.saddles[line_towards(g, side, k, 1)?].pixel;
        let d1 = p0 - p1;
        let d = match line_towards(g, side, k, 2) {
            Some(i2) => {
                let d2 = p1 - cands.saddles[i2].pixel;
                complex_ratio_step(d1, d2)
            }
            None => d1,
        };
        let pred = p0 + d;
        let step = d1.norm();
        let radius = params.search_fraction * step;
        used.resize(cands.saddles.len(), false);
        let border = line_towards(g, side, k, 0)?;
        let found = match cands.nearest(&pred, radius, used) {
            Some(j) if edges_link(cands, border, j, params.max_edge_angle) => Some(j),
            _ => local_search(cands, smooth, pred, step, radius, params)
                .filter(|&j| edges_link(cands, border, j, params.max_edge_angle)),
        };
        let Some(j) = found else {
            for &c in &claimed {
                used[c] = false;
            }
            return None;
        };
        used.resize(cands.saddles.len(), false);
        used[j] = true;
        claimed.push(j);
        line.push(j);
    }
    if !new_squares_alternate(cands, g, side, &line, smooth, params.min_amplitude) {
        for &c in &claimed {
            used[c] = false;
        }
        return None;
    }
    Some(line)
}

/// True when an edge of `a` points at `b` and an edge of `b` points at `a`.
fn edges_link(cands: &Candidates, a: usize, b: usize, max_angle: f64) -> bool {
    let d = cands.saddles[b].pixel - cands.saddles[a].pixel;
    let (dist, cos_max) = (d.norm(), max_angle.cos());
    cands.edge_points(a, &d, dist, cos_max) && cands.edge_points(b, &-d, dist, cos_max)
}

/// The squares between a new line and the border line alternate in colour along the line
/// and against the squares just inside the border.
fn new_squares_alternate(
    cands: &Candidates,
    g: &[Vec<usize>],
    side: usize,
    line: &[usize],
    smooth: &GrayImage,
    min_contrast: f64,
) -> bool {
    let px = |i: usize| cands.saddles[i].pixel;
    let centre = |a: Vector2<f64>, b: Vector2<f64>, c: Vector2<f64>, d: Vector2<f64>| {
        let m = (a + b + c + d) / 4.0;
        f64::from(smooth.sample(m.x, m.y))
    };
    let mut sign: Option<bool> = None;
    for k in 0..line.len().saturating_sub(1) {
        let (Some(b0), Some(b1), Some(i0), Some(i1)) = (
            line_towards(g, side, k, 0),
            line_towards(g, side, k + 1, 0),
            line_towards(g, side, k, 1),
            line_towards(g, side, k + 1, 1),
        ) else {
            return false;
        };
        let new = centre(px(line[k]), px(line[k + 1]), px(b0), px(b1));
        let inner = centre(px(b0), px(b1), px(i0), px(i1));
        // An inner corner line has squares beyond it too (the board's outline has not).
        let mid_new = (px(line[k]) + px(line[k + 1])) / 2.0;
        let mid_border = (px(b0) + px(b1)) / 2.0;
        let far_at = mid_new + 0.25 * (mid_new - mid_border);
        let far = f64::from(smooth.sample(far_at.x, far_at.y));
        let alt = if k % 2 == 0 { 1.0 } else { -1.0 };
        let across = (new - inner) * alt;
        let beyond = (new - far) * alt;
        if across.abs() < min_contrast
            || beyond.abs() < min_contrast.max(0.4 * across.abs())
            || (beyond > 0.0) != (across > 0.0)
            || sign.is_some_and(|p| p != (across > 0.0))
        {
            return false;
        }
        sign = Some(across > 0.0);
        if k + 2 < line.len() {
            let Some(b2) = line_towards(g, side, k + 2, 0) else {
                return false;
            };
            let next = centre(px(line[k + 1]), px(line[k + 2]), px(b1), px(b2));
            let along = (new - next) * alt;
            if along.abs() < min_contrast || (along > 0.0) != (across > 0.0) {
                return false;
            }
        }
    }
    true
}

/// `d1 * (d1 / d2)` as complex numbers, the ratio's modulus clamped to [0.5, 2].
fn complex_ratio_step(d1: Vector2<f64>, d2: Vector2<f64>) -> Vector2<f64> {
    let n2 = d2.norm_squared();
    if n2 < 1e-9 {
        return d1;
    }
    // ratio = d1 / d2
    let (mut rx, mut ry) = (
        (d1.x * d2.x + d1.y * d2.y) / n2,
        (d1.y * d2.x - d1.x * d2.y) / n2,
    );
    let m = (rx * rx + ry * ry).sqrt();
    if m > 0.0 {
        let mc = m.clamp(0.5, 2.0);
        rx *= mc / m;
        ry *= mc / m;
    }
    Vector2::new(d1.x * rx - d1.y * ry, d1.x * ry + d1.y * rx)
}

/// A saddle near `pred` that the candidate detector missed (weak, blurred).
fn local_search(
    cands: &mut Candidates,
    smooth: &GrayImage,
    pred: Vector2<f64>,
    step: f64,
    radius: f64,
    params: &GrowParams,
) -> Option<usize> {
    let (w, h) = (smooth.width() as f64, smooth.height() as f64);
    let margin = 2.0;
    if pred.x < margin || pred.y < margin || pred.x > w - 1.0 - margin || pred.y > h - 1.0 - margin
    {
        return None;
    }
    let half = ((0.3 * step).round() as usize).clamp(2, 6);
    let sp = SubpixParams {
        half_window: half,
        max_iterations: 30,
        epsilon_px: 0.01,
        max_shift_px: Some(radius),
    };
    let q = refine_corner(smooth, pred, &sp)?;
    if (q - pred).norm() > radius {
        return None;
    }
    if q.x < margin || q.y < margin || q.x > w - 1.0 - margin || q.y > h - 1.0 - margin {
        return None;
    }
    // Guided by the prediction: a looser ring test (blurred or misprinted junctions).
    let ring = params.ring_radius.min(0.3 * step).max(2.0);
    let (edges, amplitude) = [ring, 0.6 * ring]
        .into_iter()
        .find_map(|r| ring_test(smooth, q, r.max(2.0), params.min_amplitude, &GUIDED_RING))?;
    Some(cands.push(Saddle {
        pixel: q,
        response: 0.0,
        edges,
        amplitude,
    }))
}

fn insert_line(g: &mut Vec<Vec<usize>>, side: usize, line: Vec<usize>) {
    match side {
        0 => g.push(line),
        1 => g.insert(0, line),
        2 => {
            for (row, j) in g.iter_mut().zip(line) {
                row.push(j);
            }
        }
        _ => {
            for (row, j) in g.iter_mut().zip(line) {
                row.insert(0, j);
            }
        }
    }
}
