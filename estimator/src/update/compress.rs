//! Measurement compression (OpenVINS's `UpdaterHelper::measurement_compress_inplace`): many
//! rows `r = H dx + n` with isotropic noise `n ~ N(0, sigma^2 I)` whose Jacobians share the
//! same `A` state columns carry no more information than `A` rows.
//!
//! With the thin QR `[H | r] = Q [U | r1]` (`U` upper triangular `A x A`) and the full `Q`
//! completed by `Q2`, `Q^T n` is again `N(0, sigma^2 I)`, so the measurement splits into
//! `r1 = U dx + n1` (what the update uses) and `r2 = Q2^T r = 0 dx + n2`, which says nothing
//! about the state. Its squared norm still belongs to the innovation: for
//! `S = H P H^T + sigma^2 I`, `r^T S^-1 r = r1^T (U P U^T + sigma^2 I)^-1 r1 + |r2|^2 / sigma^2`,
//! so the NIS of the stacked rows is that of the compressed ones plus [`Compressor::leftover`]
//! over `sigma^2`, with the stacked row count as its dof.
//!
//! [`Compressor`] folds rows in one at a time with Givens rotations, so any number of rows
//! costs `A x (A + 1)` memory and about `2 A^2` multiply-adds per row; it never stores the
//! stack.

use crate::scalar::Scalar;
use nalgebra::{SMatrix, SVector};

/// The running triangular factor `[U | r1]` of the rows folded in so far, and `|r2|^2`.
#[derive(Clone, Copy, Debug)]
pub struct Compressor<T: Scalar, const A: usize> {
    /// `U`, upper triangular (rows are the compressed measurement rows).
    upper: SMatrix<T, A, A>,
    /// `r1`.
    residual: SVector<T, A>,
    /// `|r2|^2`: the part of the residual no combination of the columns explains.
    leftover: T,
    /// Rows folded in.
    rows: usize,
}

impl<T: Scalar, const A: usize> Compressor<T, A> {
    /// No rows yet.
    pub fn new() -> Self {
        Self {
            upper: SMatrix::zeros(),
            residual: SVector::zeros(),
            leftover: T::zero(),
            rows: 0,
        }
    }

    /// Folds in the rows of `h` (`M x A`) with residuals `r`.
    pub fn add_rows<const M: usize>(&mut self, h: &SMatrix<T, M, A>, r: &SVector<T, M>) {
        for m in 0..M {
            let mut row: [T; A] = core::array::from_fn(|k| h[(m, k)]);
            self.add_row(&mut row, r[m]);
        }
    }

    /// Folds in one row `a` with residual `b` (`a` is consumed: zeroed by the rotations).
    fn add_row(&mut self, a: &mut [T; A], mut b: T) {
        let u = self.upper.as_mut_slice();
        for j in 0..A {
            let aj = a[j];
            if aj == T::zero() {
                continue;
            }
            let ujj = u[j * A + j];
            let rho = (ujj * ujj + aj * aj).sqrt();
            let (c, s) = (ujj / rho, aj / rho);
            u[j * A + j] = rho;
            // Column-major: row j's entries right of the diagonal are `A` apart.
            for (k, ak) in a.iter_mut().enumerate().skip(j + 1) {
                let x = u[k * A + j];
                u[k * A + j] = c * x + s * *ak;
                *ak = c * *ak - s * x;
            }
            let x = self.residual[j];
            self.residual[j] = c * x + s * b;
            b = c * b - s * x;
        }
        self.leftover += b * b;
        self.rows += 1;
    }

    /// `U`: the compressed Jacobian over the `A` columns.
    pub fn upper(&self) -> &SMatrix<T, A, A> {
        &self.upper
    }

    /// `r1`: the compressed residual.
    pub fn residual(&self) -> &SVector<T, A> {
        &self.residual
    }

    /// `|r2|^2`, in the rows' units squared (divide by `sigma^2` for its NIS share).
    pub fn leftover(&self) -> T {
        self.leftover
    }

    /// Rows folded in.
    pub fn rows(&self) -> usize {
        self.rows
    }
}

impl<T: Scalar, const A: usize> Default for Compressor<T, A> {
    fn default() -> Self {
        Self::new()
    }
}

/// NIS `r^T S^-1 r` of a 2-row block with `S = H P_sub H^T + sigma2 I` (`P_sub` the covariance
/// of the block's columns): the per-corner outlier test, without touching the rest of `P`.
/// `None` when `S` is not positive definite or the NIS not finite.
pub fn pair_nis<T: Scalar, const A: usize>(
    p_sub: &SMatrix<T, A, A>,
    h: &SMatrix<T, 2, A>,
    r: &SVector<T, 2>,
    sigma2: T,
) -> Option<T> {
    let hp = h * p_sub;
    let s00 = hp.row(0).dot(&h.row(0)) + sigma2;
    let s01 = hp.row(0).dot(&h.row(1));
    let s11 = hp.row(1).dot(&h.row(1)) + sigma2;
    let det = s00 * s11 - s01 * s01;
    if !(det > T::zero() && s00 > T::zero()) {
        return None;
    }
    let nis = (s11 * r[0] * r[0] - T::lit(2.0) * s01 * r[0] * r[1] + s00 * r[1] * r[1]) / det;
    nis.is_finite().then_some(nis)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{SMatrix, SVector};

    /// A deterministic `M x A` stack with a few exact zeros (as a corner's time-offset
    /// column at rest).
    fn stack<const M: usize, const A: usize>() -> (SMatrix<f64, M, A>, SVector<f64, M>) {
        let h = SMatrix::<f64, M, A>::from_fn(|r, c| {
            if c == 2 && r % 3 == 0 {
                0.0
            } else {
                ((r * A + c) as f64 * 0.731).sin() * 300.0
            }
        });
        let r = SVector::<f64, M>::from_fn(|r, _| ((r as f64) * 1.37).cos());
        (h, r)
    }

    #[test]
    fn compressed_rows_keep_the_normal_equations_and_the_residual_norm() {
        let (h, r) = stack::<14, 5>();
        let mut c = Compressor::<f64, 5>::new();
        for k in 0..7 {
            let rows = h.fixed_rows::<2>(2 * k).clone_owned();
            let res = r.fixed_rows::<2>(2 * k).clone_owned();
            c.add_rows(&rows, &res);
        }
        assert_eq!(c.rows(), 14);
        let u = c.upper();
        // U is upper triangular, U^T U = H^T H, U^T r1 = H^T r, |r1|^2 + |r2|^2 = |r|^2.
        for i in 0..5 {
            for j in 0..i {
                assert!(u[(i, j)].abs() < f64::MIN_POSITIVE);
            }
        }
        let scale = (h.transpose() * h).amax();
        assert!((u.transpose() * u - h.transpose() * h).amax() < 1e-13 * scale);
        assert!((u.transpose() * c.residual() - h.transpose() * r).amax() < 1e-12 * scale);
        let total = c.residual().norm_squared() + c.leftover();
        assert!((total - r.norm_squared()).abs() < 1e-12 * r.norm_squared());
    }

    #[test]
    fn fewer_rows_than_columns_leave_zero_rows() {
        let (h, r) = stack::<3, 5>();
        let mut c = Compressor::<f64, 5>::new();
        c.add_rows(&h, &r);
        assert!((c.upper().transpose() * c.upper() - h.transpose() * h).amax() < 1e-9);
        assert!(c.leftover().abs() < 1e-20);
        assert!(c.upper().fixed_rows::<2>(3).amax() < f64::MIN_POSITIVE);
    }

    #[test]
    fn pair_nis_is_the_textbook_one() {
        let a = SMatrix::<f64, 4, 4>::from_fn(|r, c| ((r * 4 + c) as f64 * 0.43).cos());
        let p = a * a.transpose() + SMatrix::<f64, 4, 4>::identity() * 0.1;
        let h = SMatrix::<f64, 2, 4>::new(1.0, 0.2, -0.3, 0.5, 0.0, 0.7, 0.4, -1.1);
        let r = SVector::<f64, 2>::new(0.3, -0.8);
        let s = h * p * h.transpose() + SMatrix::<f64, 2, 2>::identity() * 0.25;
        let want = (r.transpose() * s.try_inverse().expect("pd") * r)[0];
        let got = pair_nis(&p, &h, &r, 0.25).expect("pd");
        assert!((got - want).abs() < 1e-12 * want);
        assert_eq!(pair_nis(&p, &h, &r, -100.0), None);
    }
}
