//! Inexact steps: conjugate gradients on the reduced system `S d = -b` without forming
//! `S` (each product `S x = (U + lambda diag U) x - sum_p W_p V_p^-1 W_p^T x` is one
//! pass over the cached `W` entries, as Ceres' `ITERATIVE_SCHUR`), preconditioned by the
//! Cholesky factor of an earlier iteration's exact `S`. Near the minimum `S` changes
//! little between iterations, so a few products replace the Schur complement and the
//! factorisation; when they do not converge the caller forms `S` again.

use nalgebra::{Matrix3, Matrix6x3, Vector3, Vector6};
use rayon::prelude::*;

use super::{damped_inverse, Lin, Structure};
use crate::infra::blocksym::Factor;

/// The damped reduced system of one linearisation, applied implicitly.
pub(super) struct Implicit<'a> {
    lin: &'a Lin,
    w: &'a [Matrix6x3<f64>],
    st: &'a Structure,
    lambda: f64,
    /// `(V_p + lambda diag V_p)^-1` per point (processing order).
    vinv: Vec<Matrix3<f64>>,
}

/// How a conjugate-gradient solve ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum End {
    /// The residual reached the tolerance.
    Converged,
    /// The product limit came first.
    Limit,
    /// `p^T S p` was not positive (or not finite).
    Breakdown,
}

/// The outcome of a conjugate-gradient solve.
pub(super) struct PcgOutcome {
    /// The last iterate (the step of the reduced unknowns when converged).
    pub x: Vec<f64>,
    pub end: End,
    /// Products with `S` used.
    pub products: usize,
}

impl<'a> Implicit<'a> {
    pub(super) fn new(
        lin: &'a Lin,
        w: &'a [Matrix6x3<f64>],
        st: &'a Structure,
        lambda: f64,
    ) -> Self {
        let vinv = lin
            .v
            .par_iter()
            .map(|v| damped_inverse(v, lambda))
            .collect();
        Self {
            lin,
            w,
            st,
            lambda,
            vinv,
        }
    }

    /// `sum_p W_p f_p(W_p^T x)` over every point, in parallel over the point ranges:
    /// `per_point(j, W_j^T x)` gives the point's 3-vector (`x` = `None`: `W^T x` = 0).
    fn point_sum<F>(&self, x: Option<&[f64]>, per_point: F) -> Vec<f64>
    where
        F: Fn(usize, Vector3<f64>) -> Vector3<f64> + Sync,
    {
        let (st, w) = (self.st, self.w);
        let n = 6 * st.lay.blocks();
        let parts: Vec<Vec<f64>> = st
            .chunks
            .par_iter()
            .map(|r| {
                let mut y = vec![0.0; n];
                for j in r.clone() {
                    let entries = st.w_ptr[j]..st.w_ptr[j + 1];
                    let pairs = || w[entries.clone()].iter().zip(&st.w_block[entries.clone()]);
                    let mut t = Vector3::zeros();
                    if let Some(x) = x {
                        for (we, &a) in pairs() {
                            t += we.tr_mul(&Vector6::from_column_slice(&x[6 * a..6 * a + 6]));
                        }
                    }
                    let u = per_point(j, t);
                    for (we, &a) in pairs() {
                        let v = we * u;
                        for k in 0..6 {
                            y[6 * a + k] += v[k];
                        }
                    }
                }
                y
            })
            .collect();
        let mut y = vec![0.0; n];
        for part in parts {
            for (a, b) in y.iter_mut().zip(part) {
                *a += b;
            }
        }
        y
    }

    /// The reduced right-hand side `g - sum_p W_p V_p^-1 g_p`.
    pub(super) fn rhs(&self) -> Vec<f64> {
        let mut b = self.point_sum(None, |j, _| -(self.vinv[j] * self.lin.gp[j]));
        for (b, g) in b.iter_mut().zip(&self.lin.g) {
            *b += g;
        }
        b
    }

    /// `S x`.
    pub(super) fn apply(&self, x: &[f64]) -> Vec<f64> {
        let mut y = self.point_sum(Some(x), |j, t| -(self.vinv[j] * t));
        for &(slot, a, b) in &self.st.u_slots {
            let mut m = self.lin.u[slot];
            if a == b {
                for k in 0..6 {
                    m[(k, k)] += self.lambda * m[(k, k)].max(1e-9);
                }
            }
            let xa = Vector6::from_column_slice(&x[6 * a..6 * a + 6]);
            let xb = Vector6::from_column_slice(&x[6 * b..6 * b + 6]);
            let ya = m * xb;
            for k in 0..6 {
                y[6 * a + k] += ya[k];
            }
            if a != b {
                let yb = m.transpose() * xa;
                for k in 0..6 {
                    y[6 * b + k] += yb[k];
                }
            }
        }
        y
    }

    /// Solves `S d = -b` (`b` from [`Implicit::rhs`]) by conjugate gradients
    /// preconditioned with the factor `m` (of an earlier `S`), to a residual of
    /// `tolerance` times `|b|` in at most `max_products` products with `S`.
    pub(super) fn solve(
        &self,
        b: &[f64],
        m: &Factor,
        tolerance: f64,
        max_products: usize,
    ) -> PcgOutcome {
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        let precondition = |r: &[f64]| {
            let mut z = faer::Mat::from_fn(r.len(), 1, |i, _| r[i]);
            self.st.pat.solve(m, &mut z);
            (0..r.len()).map(|i| z[(i, 0)]).collect::<Vec<f64>>()
        };
        let mut x = vec![0.0; b.len()];
        let mut r: Vec<f64> = b.iter().map(|v| -v).collect();
        let goal = tolerance * dot(&r, &r).sqrt();
        let mut z = precondition(&r);
        let mut p = z.clone();
        let mut rz = dot(&r, &z);
        for products in 1..=max_products {
            let q = self.apply(&p);
            let pq = dot(&p, &q);
            if !(pq > 0.0 && rz.is_finite()) {
                return PcgOutcome {
                    x,
                    end: End::Breakdown,
                    products,
                };
            }
            let alpha = rz / pq;
            for i in 0..x.len() {
                x[i] += alpha * p[i];
                r[i] -= alpha * q[i];
            }
            if dot(&r, &r).sqrt() <= goal {
                return PcgOutcome {
                    x,
                    end: End::Converged,
                    products,
                };
            }
            z = precondition(&r);
            let rz_next = dot(&r, &z);
            let beta = rz_next / rz;
            rz = rz_next;
            for i in 0..p.len() {
                p[i] = z[i] + beta * p[i];
            }
        }
        PcgOutcome {
            x,
            end: End::Limit,
            products: max_products,
        }
    }
}
