//! The one update core every measurement model goes through, over the state columns the
//! model touches (in the spirit of OpenVINS's `StateHelper::EKFUpdate` with its `H_order`).
//!
//! A model hands over its residual, its noise and the non-zero columns of its Jacobian
//! ([`SparseJacobian`]: `L` columns of `M` rows, each tagged with its error-state index).
//! [`Gain::compute`] forms `P H^T` from those columns of `P` only (`N L M` multiply-adds
//! instead of `N^2 M`), then `S`, the chi-square gate, the gain and the correction, and
//! checks everything that can fail. Nothing is written until [`Gain::apply_to`], which cannot
//! fail: the caller commits the state only once every check has passed.
//!
//! Covariance update: the Joseph form `(I - K H) P (I - K H)^T + K R K^T` expands, for any
//! gain, to `P - K (P H^T)^T - (P H^T) K^T + K S K^T = P + K C^T + C K^T` with
//! `C = K S / 2 - P H^T`. That is exact for any `K` (so also for a gain projected off a held
//! direction, see [`super::Hold`]), symmetric by construction, and costs `N (N + 1) M`
//! multiply-adds on the upper triangle with no `N x N` temporary.

use super::Hold;
use crate::scalar::Scalar;
use crate::Error;
use nalgebra::{Cholesky, SMatrix, SVector};

/// The non-zero columns of an `M`-row measurement Jacobian: stored column `l` is the
/// derivative w.r.t. error-state component `columns[l]` (a column listed twice adds up).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SparseJacobian<T: Scalar, const M: usize, const L: usize> {
    /// Error-state index of every stored column.
    pub columns: [usize; L],
    /// The stored columns, `M x L`.
    pub values: SMatrix<T, M, L>,
}

impl<T: Scalar, const M: usize, const L: usize> SparseJacobian<T, M, L> {
    /// All columns zero, at state index 0.
    pub fn zeros() -> Self {
        Self {
            columns: [0; L],
            values: SMatrix::zeros(),
        }
    }

    /// Stores `block` as columns `at..at + W`, the derivative w.r.t. error-state components
    /// `state..state + W`. Out-of-range `at` is ignored (a model's layout is fixed, so it
    /// would be a programming error; [`Gain::compute`] rejects bad state indices).
    pub fn set<const W: usize>(&mut self, at: usize, state: usize, block: &SMatrix<T, M, W>) {
        if at + W > L {
            return;
        }
        for k in 0..W {
            self.columns[at + k] = state + k;
            self.values.set_column(at + k, &block.column(k));
        }
    }

    /// The dense `M x N` Jacobian (for tests and diagnostics; the core never forms it).
    pub fn to_dense<const N: usize>(&self) -> SMatrix<T, M, N> {
        let mut h = SMatrix::<T, M, N>::zeros();
        for (l, &c) in self.columns.iter().enumerate() {
            if c < N {
                for r in 0..M {
                    h[(r, c)] += self.values[(r, l)];
                }
            }
        }
        h
    }

    /// The covariance of the stored columns, `P[columns, columns]` (`L x L`; a column
    /// listed twice appears twice, so `H P_sub H^T` is still `H P H^T`). Errors on a
    /// column outside `N`.
    pub fn sub_covariance<const N: usize>(
        &self,
        cov: &SMatrix<T, N, N>,
    ) -> Result<SMatrix<T, L, L>, Error> {
        if self.columns.iter().any(|&c| c >= N) {
            return Err(Error::InvalidConfig);
        }
        let p = cov.as_slice();
        Ok(SMatrix::from_fn(|r, c| {
            p[self.columns[c] * N + self.columns[r]]
        }))
    }

    /// `(P H^T)^T = H P` into `out_t` (`M x N`), from the stored columns of `P` only
    /// (plain slices: nalgebra's strided iterators cost several times more on the M4F).
    fn cov_times_transpose_into<const N: usize>(
        &self,
        cov: &SMatrix<T, N, N>,
        out_t: &mut SMatrix<T, M, N>,
    ) {
        out_t.fill(T::zero());
        let out = out_t.as_mut_slice();
        for (l, &c) in self.columns.iter().enumerate() {
            let p = &cov.as_slice()[c * N..(c + 1) * N];
            for r in 0..M {
                let h = self.values[(r, l)];
                if h != T::zero() {
                    for (o, x) in out.iter_mut().skip(r).step_by(M).zip(p) {
                        *o += h * *x;
                    }
                }
            }
        }
    }

    /// `H X` for `X` given transposed (`X^T`, `M x N`; columns of `X^T` at the stored
    /// columns only).
    fn times_transposed<const N: usize>(&self, x_t: &SMatrix<T, M, N>) -> SMatrix<T, M, M> {
        let mut out = SMatrix::<T, M, M>::zeros();
        for (l, &c) in self.columns.iter().enumerate() {
            for j in 0..M {
                let xc = x_t[(j, c)];
                for r in 0..M {
                    out[(r, j)] += self.values[(r, l)] * xc;
                }
            }
        }
        out
    }
}

/// A linearised measurement `r = H dx + n`, `n ~ N(0, R)`, with `H` given by its non-zero
/// columns.
#[derive(Clone, Copy, Debug)]
pub struct Measurement<T: Scalar, const M: usize, const L: usize> {
    /// Residual `z - h(x_hat)` in the measurement's tangent space.
    pub residual: SVector<T, M>,
    /// `H`: derivative of the predicted measurement w.r.t. the error state.
    pub jacobian: SparseJacobian<T, M, L>,
    /// Measurement noise covariance `R`.
    pub noise: SMatrix<T, M, M>,
}

impl<T: Scalar, const M: usize, const L: usize> Measurement<T, M, L> {
    fn is_finite(&self) -> bool {
        let finite = |m: &[T]| m.iter().all(|x| x.is_finite());
        finite(self.residual.as_slice())
            && finite(self.jacobian.values.as_slice())
            && finite(self.noise.as_slice())
    }
}

/// What one update computed, checked and not yet applied.
#[derive(Clone, Debug)]
pub struct Gain<T: Scalar, const M: usize, const N: usize> {
    /// NIS `r^T S^-1 r` of the innovation.
    pub nis: T,
    /// Gate threshold.
    pub threshold: T,
    /// Whether the gate accepted the measurement.
    pub accepted: bool,
    /// Error-state correction `K r` (zero when rejected).
    pub correction: SVector<T, N>,
    /// `S^-1 r`, for the health monitor's step detector.
    pub weighted_residual: SVector<T, M>,
    /// `S^-1`.
    pub innovation_inverse: SMatrix<T, M, M>,
    /// `K^T` (zero when rejected): stored transposed, so a row of `K` is contiguous.
    gain_t: SMatrix<T, M, N>,
    /// `C^T`, `C = K S / 2 - P H^T` (zero when rejected), transposed as `K^T`.
    cross_t: SMatrix<T, M, N>,
}

impl<T: Scalar, const M: usize, const N: usize> Gain<T, M, N> {
    /// Innovation covariance, gate (NIS above `threshold`: rejected, nothing to apply; an
    /// infinite threshold never rejects), gain with every hold projected out, correction.
    /// Errors: a non-finite input, a state index outside `N`, `S` not positive definite, or
    /// a result that is not finite or could overflow the covariance.
    pub fn compute<const L: usize>(
        cov: &SMatrix<T, N, N>,
        meas: &Measurement<T, M, L>,
        threshold: T,
        holds: &[Hold<T>],
    ) -> Result<Self, Error> {
        let mut out = Self::empty();
        out.compute_into(cov, meas, threshold, holds)?;
        Ok(out)
    }

    /// A gain that applies nothing (rejected, NIS 0), to be filled by
    /// [`Gain::compute_into`].
    pub fn empty() -> Self {
        Self {
            nis: T::zero(),
            threshold: T::zero(),
            accepted: false,
            correction: SVector::zeros(),
            weighted_residual: SVector::zeros(),
            innovation_inverse: SMatrix::zeros(),
            gain_t: SMatrix::zeros(),
            cross_t: SMatrix::zeros(),
        }
    }

    /// [`Gain::compute`] into `self`, with no `N x M` temporary: `(P H^T)^T` is formed in
    /// the storage of `C^T` and turned into `C^T` in place (on the M4F a returned gain and
    /// its temporaries were several `N x M` copies on the stack). On error `self` is
    /// unspecified.
    #[inline(never)]
    pub fn compute_into<const L: usize>(
        &mut self,
        cov: &SMatrix<T, N, N>,
        meas: &Measurement<T, M, L>,
        threshold: T,
        holds: &[Hold<T>],
    ) -> Result<(), Error> {
        if !meas.is_finite() {
            return Err(Error::NonFinite);
        }
        if meas.jacobian.columns.iter().any(|&c| c >= N) {
            return Err(Error::InvalidConfig);
        }
        self.threshold = threshold;
        self.accepted = false;
        self.correction.fill(T::zero());
        self.gain_t.fill(T::zero());
        // (P H^T)^T, kept in the storage of C^T until C^T is formed.
        meas.jacobian
            .cov_times_transpose_into(cov, &mut self.cross_t);
        let s = meas.jacobian.times_transposed(&self.cross_t) + meas.noise;
        let s = (s + s.transpose()) * T::lit(0.5);
        let chol = Cholesky::new(s).ok_or(Error::SingularInnovation)?;
        self.innovation_inverse = chol.inverse();
        self.weighted_residual = self.innovation_inverse * meas.residual;
        self.nis = meas.residual.dot(&self.weighted_residual);
        if !self.nis.is_finite() {
            return Err(Error::DivergentUpdate);
        }
        if self.nis > threshold {
            self.cross_t.fill(T::zero());
            return Ok(());
        }
        // K^T = S^-1 (P H^T)^T (S^-1 symmetric), every hold projected out.
        self.innovation_inverse
            .mul_to(&self.cross_t, &mut self.gain_t);
        for hold in holds {
            hold.project(&mut self.gain_t);
        }
        self.gain_t.tr_mul_to(&meas.residual, &mut self.correction);
        // C^T = S K^T / 2 - (P H^T)^T, column by column in place.
        let half = T::lit(0.5);
        let rows = self.gain_t.as_slice().chunks_exact(M);
        for (c, k) in self.cross_t.as_mut_slice().chunks_exact_mut(M).zip(rows) {
            for (r, c) in c.iter_mut().enumerate() {
                let sk = (0..M).fold(T::zero(), |a, q| a + s[(r, q)] * k[q]);
                *c = half * sk - *c;
            }
        }
        self.accepted = true;
        if !self.fits(cov) {
            return Err(Error::DivergentUpdate);
        }
        Ok(())
    }

    /// True when the correction is finite and `P + K C^T + C K^T` cannot overflow: every
    /// entry of a covariance is at most its largest diagonal entry in magnitude, and every
    /// entry of the update at most `2 M max|K| max|C|`. Sums of magnitudes bound the maxima
    /// and carry any NaN or infinity along, in one pass and without `max` (a library call
    /// on the M4F).
    fn fits(&self, cov: &SMatrix<T, N, N>) -> bool {
        let sum = |m: &[T]| m.iter().fold(T::zero(), |a, x| a + x.abs());
        let diag = (0..N).fold(T::zero(), |a, i| a + cov[(i, i)].abs());
        let bound = T::lit(2.0) * diag
            + T::lit(2.0 * M as f64) * sum(self.gain_t.as_slice()) * sum(self.cross_t.as_slice());
        bound.is_finite() && sum(self.correction.as_slice()).is_finite()
    }

    /// `P <- P + K C^T + C K^T` (the Joseph form, see the module doc), upper triangle then
    /// mirrored; nothing when the gate rejected.
    #[inline(never)]
    pub fn apply_to(&self, cov: &mut SMatrix<T, N, N>) {
        if !self.accepted {
            return;
        }
        // Rows of K and C are the contiguous columns of K^T and C^T: no copies.
        let k = self.gain_t.as_slice();
        let c = self.cross_t.as_slice();
        for (j, column) in cov.as_mut_slice().chunks_exact_mut(N).enumerate() {
            let (kj, cj) = (&k[j * M..(j + 1) * M], &c[j * M..(j + 1) * M]);
            let rows = k.chunks_exact(M).zip(c.chunks_exact(M));
            for (p, (ki, ci)) in column[..=j].iter_mut().zip(rows) {
                let mut d = T::zero();
                for r in 0..M {
                    d += ki[r] * cj[r] + ci[r] * kj[r];
                }
                *p += d;
            }
        }
        let p = cov.as_mut_slice();
        for j in 1..N {
            for i in 0..j {
                p[i * N + j] = p[j * N + i];
            }
        }
    }
}
