//! The P2D-NDT score with its analytic gradient and Hessian (Magnusson 2009,
//! eq. 6.8-6.13), evaluated in parallel over source points.

use nalgebra::{Matrix3, Matrix6, Vector3, Vector6};
use rayon::prelude::*;

use super::map::NdtMap;
use super::Neighbourhood;
use crate::pointcloud::VoxelKey;

/// Points per rayon task.
const CHUNK: usize = 1024;

/// Terms with `d2/2 m` above this contribute less than e^-30 and are skipped.
const EXPONENT_CUTOFF: f64 = 30.0;

/// The Gaussian fit `d1 exp(-d2/2 m)` to the negative log of the
/// outlier-mixture likelihood (Magnusson eq. 6.8); `d1 < 0`, `d2 > 0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct GaussFit {
    pub(crate) d1: f64,
    pub(crate) d2: f64,
}

impl GaussFit {
    /// Constants for cells of side `resolution` and outlier ratio `p_outlier`.
    pub(crate) fn new(resolution: f64, p_outlier: f64) -> Self {
        let c1 = 10.0 * (1.0 - p_outlier);
        let c2 = p_outlier / resolution.powi(3);
        let d3 = -c2.ln();
        let d1 = -(c1 + c2).ln() - d3;
        let d2 = -2.0 * ((-(c1 * (-0.5f64).exp() + c2).ln() - d3) / d1).ln();
        Self { d1, d2 }
    }
}

/// A pose as applied to source points: `x = R p + t`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PoseMat {
    pub(crate) rotation: Matrix3<f64>,
    pub(crate) translation: Vector3<f64>,
}

/// Score sum with derivatives w.r.t. `(dt, phi)` at zero (module docs of `ndt`).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Evaluation {
    /// `sum d1 exp(-d2/2 m)` (negative; lower is better).
    pub(crate) score: f64,
    pub(crate) gradient: Vector6<f64>,
    pub(crate) hessian: Matrix6<f64>,
    /// Source points that touched at least one Gaussian.
    pub(crate) hits: usize,
}

#[derive(Clone, Copy)]
struct Acc {
    score: f64,
    g_t: Vector3<f64>,
    g_r: Vector3<f64>,
    h_tt: Matrix3<f64>,
    h_tr: Matrix3<f64>,
    h_rr: Matrix3<f64>,
    hits: usize,
}

impl Acc {
    fn zero() -> Self {
        Self {
            score: 0.0,
            g_t: Vector3::zeros(),
            g_r: Vector3::zeros(),
            h_tt: Matrix3::zeros(),
            h_tr: Matrix3::zeros(),
            h_rr: Matrix3::zeros(),
            hits: 0,
        }
    }

    fn merge(mut self, o: Self) -> Self {
        self.score += o.score;
        self.g_t += o.g_t;
        self.g_r += o.g_r;
        self.h_tt += o.h_tt;
        self.h_tr += o.h_tr;
        self.h_rr += o.h_rr;
        self.hits += o.hits;
        self
    }
}

/// Evaluates the score (and, with `derivatives`, gradient and Hessian) of
/// `source` moved by `pose` against `map`.
pub(crate) fn evaluate(
    map: &NdtMap,
    source: &[Vector3<f64>],
    pose: &PoseMat,
    gauss: GaussFit,
    neighbourhood: Neighbourhood,
    derivatives: bool,
) -> Evaluation {
    let inv_res = map.resolution().recip();
    let offsets = neighbourhood.offsets();
    let acc = source
        .par_chunks(CHUNK)
        .map(|chunk| {
            let mut acc = Acc::zero();
            for p in chunk {
                let q = pose.rotation * p;
                let x = q + pose.translation;
                point_terms(map, &q, &x, inv_res, offsets, gauss, derivatives, &mut acc);
            }
            acc
        })
        .reduce(Acc::zero, Acc::merge);
    let mut hessian = Matrix6::zeros();
    if derivatives {
        hessian.fixed_view_mut::<3, 3>(0, 0).copy_from(&acc.h_tt);
        hessian.fixed_view_mut::<3, 3>(0, 3).copy_from(&acc.h_tr);
        hessian
            .fixed_view_mut::<3, 3>(3, 0)
            .copy_from(&acc.h_tr.transpose());
        hessian.fixed_view_mut::<3, 3>(3, 3).copy_from(&acc.h_rr);
    }
    let mut gradient = Vector6::zeros();
    gradient.fixed_rows_mut::<3>(0).copy_from(&acc.g_t);
    gradient.fixed_rows_mut::<3>(3).copy_from(&acc.g_r);
    Evaluation {
        score: acc.score,
        gradient,
        hessian,
        hits: acc.hits,
    }
}

/// Adds one point's terms. With `w = -d1 d2 e` per cell, `a = Sigma^-1 (x-mu)`:
/// gradient `J^T sum w a`, Hessian `J^T [sum w (Sigma^-1 - d2 a a^T)] J`
/// plus the second-derivative term of the rotation, `J = [I, -[q]x]`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn point_terms(
    map: &NdtMap,
    q: &Vector3<f64>,
    x: &Vector3<f64>,
    inv_res: f64,
    offsets: &[[i32; 3]],
    gauss: GaussFit,
    derivatives: bool,
    acc: &mut Acc,
) {
    let key = VoxelKey::of(x, inv_res);
    let mut s1 = Vector3::zeros();
    let mut m = Matrix3::zeros();
    let mut hit = false;
    for &d in offsets {
        let Some(cell) = map.get(key.offset(d)) else {
            continue;
        };
        let diff = x - cell.mean;
        let a = cell.inv_cov * diff;
        let half_d2_m = 0.5 * gauss.d2 * diff.dot(&a);
        if half_d2_m.is_nan() || half_d2_m >= EXPONENT_CUTOFF {
            continue;
        }
        hit = true;
        let e = (-half_d2_m).exp();
        acc.score += gauss.d1 * e;
        let w = -gauss.d1 * gauss.d2 * e;
        s1 += w * a;
        if derivatives {
            m += w * (cell.inv_cov - gauss.d2 * a * a.transpose());
        }
    }
    if !hit {
        return;
    }
    acc.hits += 1;
    acc.g_t += s1;
    acc.g_r += q.cross(&s1);
    if derivatives {
        // J_r = K = -[q]x and K^T = [q]x, so H_tr = M K, H_rr = [q]x (M K).
        let qx = q.cross_matrix();
        let mk = -(m * qx);
        acc.h_tt += m;
        acc.h_tr += mk;
        acc.h_rr += qx * mk;
        let bq = s1.dot(q);
        let sym = 0.5 * (q * s1.transpose() + s1 * q.transpose());
        acc.h_rr += sym - Matrix3::from_diagonal_element(bq);
    }
}

/// Outer products of the per-point score gradients at a pose (the "meat" of the sandwich
/// covariance `H^-1 S H^-1` of an M-estimator).
#[derive(Debug, Clone, Copy)]
pub(crate) struct GradientScatter {
    /// `sum_i g_i g_i^T`: points independent.
    pub(crate) per_point: Matrix6<f64>,
    /// `sum_c (sum_{i in c} g_i)(sum_{i in c} g_i)^T` over the cells containing the points:
    /// points scored against the same target cell share its estimated mean and covariance,
    /// so their errors are correlated (cluster-robust sandwich).
    pub(crate) per_cell: Matrix6<f64>,
}

/// The gradient of one point's score w.r.t. `(dt, phi)`, and the key of the cell that
/// contains it; `None` when it touches no Gaussian.
fn point_gradient(
    map: &NdtMap,
    q: &Vector3<f64>,
    x: &Vector3<f64>,
    inv_res: f64,
    offsets: &[[i32; 3]],
    gauss: GaussFit,
) -> Option<(VoxelKey, Vector6<f64>)> {
    let mut acc = Acc::zero();
    point_terms(map, q, x, inv_res, offsets, gauss, false, &mut acc);
    (acc.hits > 0).then(|| {
        let mut g = Vector6::zeros();
        g.fixed_rows_mut::<3>(0).copy_from(&acc.g_t);
        g.fixed_rows_mut::<3>(3).copy_from(&acc.g_r);
        (VoxelKey::of(x, inv_res), g)
    })
}

/// [`GradientScatter`] of `source` moved by `pose` against `map`.
pub(crate) fn gradient_scatter(
    map: &NdtMap,
    source: &[Vector3<f64>],
    pose: &PoseMat,
    gauss: GaussFit,
    neighbourhood: Neighbourhood,
) -> GradientScatter {
    let inv_res = map.resolution().recip();
    let offsets = neighbourhood.offsets();
    let gradients: Vec<(VoxelKey, Vector6<f64>)> = source
        .par_chunks(CHUNK)
        .flat_map_iter(|chunk| {
            chunk.iter().filter_map(|p| {
                let q = pose.rotation * p;
                let x = q + pose.translation;
                point_gradient(map, &q, &x, inv_res, offsets, gauss)
            })
        })
        .collect();
    let mut per_point = Matrix6::zeros();
    let mut cells: crate::pointcloud::VoxelMap<Vector6<f64>> = Default::default();
    for (key, g) in &gradients {
        per_point += g * g.transpose();
        *cells.entry(*key).or_insert_with(Vector6::zeros) += g;
    }
    let per_cell = cells
        .values()
        .fold(Matrix6::zeros(), |s, g| s + g * g.transpose());
    GradientScatter {
        per_point,
        per_cell,
    }
}
