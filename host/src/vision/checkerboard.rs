//! Checkerboard detection: the inner corners of a Kalibr checkerboard (`targetRows` x
//! `targetCols`) in a grey image, with sub-pixel refinement and Kalibr ids
//! (`id = r * cols + c`). Pipeline (docs/checkerboard.md): contrast-normalised saddle
//! candidates with a ring test ([`super::saddle`]), grid growing ([`super::grid`]), a
//! topology and colour check, the id order, then gradient-orthogonality refinement
//! ([`super::subpix`]). A board that is not entirely visible, or visible twice, is not
//! reported: [`NoDetection`] says why.
//!
//! Id order (the symmetric board's ambiguity, resolved deterministically):
//! 1. handedness: the camera sees the printed face, so `T`'s z axis points towards the
//!    camera; in the image `(u right, v down)` the row direction (+r) crossed with the column
//!    direction (+c) is negative;
//! 2. colour: the square between corners `0, 1, cols, cols + 1` is dark (decides whenever
//!    `rows + cols` is odd);
//! 3. otherwise (`rows + cols` even, or a square board's 90-degree turns) corner 0 is the
//!    candidate with the smallest `u + v` (nearest the image's top-left).

use super::gray::GrayImage;
use super::grid::{grow, Candidates, Grid, GrowParams};
use super::saddle::{find_saddles, SaddleParams};
use super::subpix::{refine_corner, SubpixParams};
use nalgebra::Vector2;

/// Why no board was reported for an image.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NoDetection {
    /// The image is smaller than a board could be.
    #[error("image too small ({width}x{height})")]
    ImageTooSmall {
        /// Width, pixels.
        width: usize,
        /// Height, pixels.
        height: usize,
    },
    /// The target has fewer than 3 inner corners along a side.
    #[error("target of {rows}x{cols} inner corners: at least 3x3 are needed")]
    TargetTooSmall {
        /// Target rows.
        rows: usize,
        /// Target columns.
        cols: usize,
    },
    /// No group of at least 3x3 corners was found.
    #[error("no checkerboard corners found")]
    NoCorners,
    /// Only part of the board is visible (or detectable).
    #[error("partial board: {found_rows}x{found_cols} of {rows}x{cols} inner corners found")]
    Partial {
        /// Rows of the largest grid found.
        found_rows: usize,
        /// Its columns.
        found_cols: usize,
        /// Target rows.
        rows: usize,
        /// Target columns.
        cols: usize,
    },
    /// A grid with more corners than the target: the target file is probably wrong.
    #[error(
        "found a {found_rows}x{found_cols} corner grid, larger than the {rows}x{cols} target \
         (wrong target size?)"
    )]
    LargerThanTarget {
        /// Rows of the grid found.
        found_rows: usize,
        /// Its columns.
        found_cols: usize,
        /// Target rows.
        rows: usize,
        /// Target columns.
        cols: usize,
    },
    /// More than one full board.
    #[error("{count} full boards found: ambiguous")]
    Ambiguous {
        /// Number of boards.
        count: usize,
    },
    /// A full-size grid failed the colour/topology check or its refinement.
    #[error("the corner grid is inconsistent (colours, geometry or refinement)")]
    Inconsistent,
    /// The AprilGrid detector found too little (the target is an AprilGrid).
    #[error(transparent)]
    AprilGrid(#[from] super::aprilgrid::NoAprilGrid),
}

/// Detector settings; the defaults work from ~8 px squares up, on 8-bit images.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectorParams {
    /// Candidate detector.
    pub saddle: SaddleParams,
    /// Largest half window of the final refinement, pixels (OpenCV-style `winSize`); the
    /// window used is `min(this, window_fraction * distance to the nearest corner)`, at
    /// least 2.
    pub max_half_window: usize,
    /// Largest half window as a fraction of the distance to the nearest corner.
    pub window_fraction: f64,
    /// Refinement iterations.
    pub max_iterations: usize,
    /// Refinement stop step, pixels.
    pub epsilon_px: f64,
    /// Largest refinement move from the grid position, as a fraction of the local step.
    pub max_refine_shift: f64,
    /// Search images of at least 240 x 240 at half resolution first (4x fewer pixels;
    /// corners still refined at full resolution), falling back to full resolution when
    /// that finds no board.
    pub coarse_first: bool,
}

impl Default for DetectorParams {
    fn default() -> Self {
        Self {
            saddle: SaddleParams::default(),
            max_half_window: 11,
            window_fraction: 0.5,
            max_iterations: 40,
            epsilon_px: 1e-4,
            max_refine_shift: 0.3,
            coarse_first: true,
        }
    }
}

impl DetectorParams {
    /// OpenCV-compatible refinement: `cornerSubPix` with `winSize` (11, 11) (a 23 x 23
    /// window) whatever the square size, 30 iterations, epsilon 1e-4, as the reference
    /// corners of `../shared/data` were made. The default caps the window at half the
    /// corner spacing instead, which keeps neighbouring corners and the board's outline out
    /// of it (docs/checkerboard.md).
    pub fn opencv_compatible() -> Self {
        Self {
            window_fraction: f64::INFINITY,
            max_iterations: 30,
            max_refine_shift: f64::INFINITY,
            ..Self::default()
        }
    }
}

/// A full board: `rows * cols` corner pixels, index = Kalibr corner id `r * cols + c`.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckerboardDetection {
    /// Target rows (`targetRows`).
    pub rows: usize,
    /// Target columns (`targetCols`).
    pub cols: usize,
    /// Corner pixels by id.
    pub corners: Vec<Vector2<f64>>,
}

impl CheckerboardDetection {
    /// The pixel of corner `(r, c)`.
    pub fn corner(&self, r: usize, c: usize) -> Vector2<f64> {
        self.corners[r * self.cols + c]
    }
}

/// Detects the inner corners of a `rows` x `cols` checkerboard.
pub fn detect_checkerboard(
    img: &GrayImage,
    rows: usize,
    cols: usize,
    params: &DetectorParams,
) -> Result<CheckerboardDetection, NoDetection> {
    if rows < 3 || cols < 3 {
        return Err(NoDetection::TargetTooSmall { rows, cols });
    }
    if img.width() < 16 || img.height() < 16 {
        return Err(NoDetection::ImageTooSmall {
            width: img.width(),
            height: img.height(),
        });
    }
    if params.coarse_first && img.width().min(img.height()) >= COARSE_MIN_SIZE {
        // Candidates and grid at half resolution, corners refined at full resolution; any
        // failure falls back to the full-resolution search (small squares, low contrast).
        let half = img.half_size();
        if let Ok(ordered) = find_board(&half, rows, cols, params) {
            let scaled: Vec<Vector2<f64>> = ordered
                .iter()
                .map(|p| 2.0 * p + Vector2::new(0.5, 0.5))
                .collect();
            if let Ok(corners) = refine_all(img, &scaled, rows, cols, params) {
                return Ok(CheckerboardDetection {
                    rows,
                    cols,
                    corners,
                });
            }
        }
    }
    let ordered = find_board(img, rows, cols, params)?;
    let corners = refine_all(img, &ordered, rows, cols, params)?;
    Ok(CheckerboardDetection {
        rows,
        cols,
        corners,
    })
}

/// Images at least this large (both sides, pixels) are searched at half resolution first.
const COARSE_MIN_SIZE: usize = 240;

/// The board's grid corners in Kalibr id order, unrefined (candidates, grids, selection,
/// ids).
fn find_board(
    img: &GrayImage,
    rows: usize,
    cols: usize,
    params: &DetectorParams,
) -> Result<Vec<Vector2<f64>>, NoDetection> {
    let (smooth, saddles) = find_saddles(img, &params.saddle);
    let grids = find_grids(saddles, &smooth, rows, cols, &params.saddle);
    let grid = select_grid(grids, &smooth, rows, cols)?;
    order_kalibr(&grid, &smooth, rows, cols).ok_or(NoDetection::Inconsistent)
}

/// Grows a grid from every candidate not already in a grid at least as large as the
/// target (strongest response first).
fn find_grids(
    saddles: Vec<super::saddle::Saddle>,
    smooth: &GrayImage,
    rows: usize,
    cols: usize,
    sp: &SaddleParams,
) -> Vec<Grid> {
    let max_dim = rows.max(cols) + 2;
    let mut order: Vec<usize> = (0..saddles.len()).collect();
    order.sort_by(|&a, &b| saddles[b].response.total_cmp(&saddles[a].response));
    let mut cands = Candidates::new(saddles, smooth.width(), smooth.height());
    let gp = GrowParams {
        max_edge_angle: 0.4,
        search_fraction: 0.35,
        ring_radius: sp.ring_radii[0],
        min_amplitude: sp.min_amplitude,
        max_dim,
    };
    let mut consumed = vec![false; order.len()];
    let mut grids = Vec::new();
    for seed in order {
        if consumed[seed] {
            continue;
        }
        if let Some((grid, members)) = grow(&mut cands, seed, smooth, &gp) {
            if grid.rows * grid.cols >= rows * cols {
                for m in members {
                    if m < consumed.len() {
                        consumed[m] = true;
                    }
                }
            }
            grids.push(grid);
        }
    }
    grids
}

/// The one full, consistent grid; otherwise why there is none.
fn select_grid(
    grids: Vec<Grid>,
    smooth: &GrayImage,
    rows: usize,
    cols: usize,
) -> Result<Grid, NoDetection> {
    let consistent = |g: &Grid| colours_alternate(smooth, g) && lines_are_smooth(g);
    let grids: Vec<Grid> = grids.into_iter().filter(|g| consistent(g)).collect();
    let fits = |g: &Grid| (g.rows, g.cols) == (rows, cols) || (g.rows, g.cols) == (cols, rows);
    let larger = |g: &Grid| {
        !fits(g) && ((g.rows >= rows && g.cols >= cols) || (g.rows >= cols && g.cols >= rows))
    };
    if let Some(g) = grids.iter().find(|g| larger(g)) {
        return Err(NoDetection::LargerThanTarget {
            found_rows: g.rows,
            found_cols: g.cols,
            rows,
            cols,
        });
    }
    let mut full: Vec<Grid> = Vec::new();
    for g in grids.iter().filter(|g| fits(g)) {
        if !full.iter().any(|f| same_board(f, g)) {
            full.push(g.clone());
        }
    }
    match full.len() {
        1 => Ok(full.remove(0)),
        0 => match grids.iter().max_by_key(|g| g.rows * g.cols) {
            Some(g) => Err(NoDetection::Partial {
                found_rows: g.rows,
                found_cols: g.cols,
                rows,
                cols,
            }),
            None => Err(NoDetection::NoCorners),
        },
        count => Err(NoDetection::Ambiguous { count }),
    }
}

/// True when most corners of `b` lie on corners of `a` (one board grown twice).
fn same_board(a: &Grid, b: &Grid) -> bool {
    let step = (a.at(0, 0) - a.at(0, 1))
        .norm()
        .min((a.at(0, 0) - a.at(1, 0)).norm());
    let shared = b
        .pixels
        .iter()
        .filter(|p| a.pixels.iter().any(|q| (*p - q).norm() < 0.3 * step))
        .count();
    2 * shared >= b.pixels.len()
}

/// Square centres alternate dark/bright against each right and lower neighbour.
fn colours_alternate(smooth: &GrayImage, g: &Grid) -> bool {
    let (sr, sc) = (g.rows - 1, g.cols - 1);
    let m: Vec<f64> = (0..sr * sc)
        .map(|k| {
            let (r, c) = (k / sc, k % sc);
            let centre = (g.at(r, c) + g.at(r + 1, c) + g.at(r, c + 1) + g.at(r + 1, c + 1)) / 4.0;
            f64::from(smooth.sample(centre.x, centre.y))
        })
        .collect();
    let parity = |r: usize, c: usize| if (r + c) % 2 == 0 { 1.0 } else { -1.0 };
    let mut sign: Option<bool> = None;
    for r in 0..sr {
        for c in 0..sc {
            let here = m[r * sc + c];
            let mut pairs = Vec::with_capacity(2);
            if c + 1 < sc {
                pairs.push(m[r * sc + c + 1]);
            }
            if r + 1 < sr {
                pairs.push(m[(r + 1) * sc + c]);
            }
            for other in pairs {
                let s = (here - other) * parity(r, c);
                if s.abs() < 1e-6 || sign.is_some_and(|p| p != (s > 0.0)) {
                    return false;
                }
                sign = Some(s > 0.0);
            }
        }
    }
    true
}

/// Along every row and column, consecutive steps change by less than their length.
fn lines_are_smooth(g: &Grid) -> bool {
    let check = |a: Vector2<f64>, b: Vector2<f64>, c: Vector2<f64>| {
        let (d1, d2) = (b - a, c - b);
        let (n1, n2) = (d1.norm(), d2.norm());
        n1 > 2.0 && n2 > 2.0 && (d2 - d1).norm() < 0.6 * n1.max(n2) && n1.max(n2) < 2.5 * n1.min(n2)
    };
    for r in 0..g.rows {
        for c in 0..g.cols.saturating_sub(2) {
            if !check(g.at(r, c), g.at(r, c + 1), g.at(r, c + 2)) {
                return false;
            }
        }
    }
    for c in 0..g.cols {
        for r in 0..g.rows.saturating_sub(2) {
            if !check(g.at(r, c), g.at(r + 1, c), g.at(r + 2, c)) {
                return false;
            }
        }
    }
    true
}

/// Maps the grid to Kalibr ids (module docs: handedness, colour, top-left).
fn order_kalibr(
    g: &Grid,
    smooth: &GrayImage,
    rows: usize,
    cols: usize,
) -> Option<Vec<Vector2<f64>>> {
    let mut best: Option<(bool, f64, Vec<Vector2<f64>>)> = None;
    for t in 0..8 {
        let Some(pix) = remap(g, t, rows, cols) else {
            continue;
        };
        let at = |r: usize, c: usize| pix[r * cols + c];
        // Handedness at the centre of the board.
        let (rm, cm) = (rows / 2, cols / 2);
        let dr = at(rm, cm) - at(rm - 1, cm);
        let dc = at(rm, cm) - at(rm, cm - 1);
        if dr.x * dc.y - dr.y * dc.x >= 0.0 {
            continue;
        }
        let first = (at(0, 0) + at(0, 1) + at(1, 0) + at(1, 1)) / 4.0;
        let second = (at(0, 1) + at(0, 2) + at(1, 1) + at(1, 2)) / 4.0;
        let dark = smooth.sample(first.x, first.y) < smooth.sample(second.x, second.y);
        let tl = at(0, 0).x + at(0, 0).y;
        let better = match &best {
            None => true,
            Some((bd, btl, _)) => (dark && !bd) || (dark == *bd && tl < *btl),
        };
        if better {
            best = Some((dark, tl, pix));
        }
    }
    best.map(|(_, _, p)| p)
}

/// The grid under dihedral map `t` (bit 0: transpose, bit 1: flip rows, bit 2: flip
/// columns) as a `rows x cols` row-major list; `None` when the shape does not fit.
fn remap(g: &Grid, t: usize, rows: usize, cols: usize) -> Option<Vec<Vector2<f64>>> {
    let transpose = t & 1 == 1;
    let (gr, gc) = if transpose {
        (g.cols, g.rows)
    } else {
        (g.rows, g.cols)
    };
    if (gr, gc) != (rows, cols) {
        return None;
    }
    let mut out = Vec::with_capacity(rows * cols);
    for r in 0..rows {
        for c in 0..cols {
            let r2 = if t & 2 == 2 { rows - 1 - r } else { r };
            let c2 = if t & 4 == 4 { cols - 1 - c } else { c };
            out.push(if transpose {
                g.at(c2, r2)
            } else {
                g.at(r2, c2)
            });
        }
    }
    Some(out)
}

fn refine_all(
    img: &GrayImage,
    pixels: &[Vector2<f64>],
    rows: usize,
    cols: usize,
    params: &DetectorParams,
) -> Result<Vec<Vector2<f64>>, NoDetection> {
    let mut out = Vec::with_capacity(pixels.len());
    for r in 0..rows {
        for c in 0..cols {
            let p = pixels[r * cols + c];
            let nearest = neighbours(rows, cols, r, c)
                .map(|(rr, cc)| (pixels[rr * cols + cc] - p).norm())
                .fold(f64::MAX, f64::min);
            let half = (params.window_fraction * nearest)
                .floor()
                .clamp(2.0, params.max_half_window.max(2) as f64) as usize;
            let sp = SubpixParams {
                half_window: half,
                max_iterations: params.max_iterations,
                epsilon_px: params.epsilon_px,
                max_shift_px: None,
            };
            let q = refine_corner(img, p, &sp).ok_or(NoDetection::Inconsistent)?;
            if out
                .iter()
                .any(|o: &Vector2<f64>| (o - q).norm() < 0.3 * nearest)
            {
                return Err(NoDetection::Inconsistent);
            }
            if (q - p).norm() > params.max_refine_shift * nearest {
                return Err(NoDetection::Inconsistent);
            }
            out.push(q);
        }
    }
    Ok(out)
}

fn neighbours(
    rows: usize,
    cols: usize,
    r: usize,
    c: usize,
) -> impl Iterator<Item = (usize, usize)> {
    let cand = [
        (r.wrapping_sub(1), c),
        (r + 1, c),
        (r, c.wrapping_sub(1)),
        (r, c + 1),
    ];
    cand.into_iter().filter(move |&(a, b)| a < rows && b < cols)
}
