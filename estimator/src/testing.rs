//! Shared test helpers: central differences on the manifold, used by every Jacobian test.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Step of the central differences.
pub const STEP: f64 = 1e-6;

/// Numeric Jacobian of `f: R^3 -> R^3` at 0 by central differences.
pub fn central_diff_so3(f: impl Fn(Vector3<f64>) -> Vector3<f64>) -> Matrix3<f64> {
    central_diff::<3, 3>(f)
}

/// Numeric Jacobian of `f: R^K -> R^M` at 0 by central differences.
pub fn central_diff<const M: usize, const K: usize>(
    f: impl Fn(SVector<f64, K>) -> SVector<f64, M>,
) -> SMatrix<f64, M, K> {
    let mut jac = SMatrix::<f64, M, K>::zeros();
    for k in 0..K {
        let mut d = SVector::<f64, K>::zeros();
        d[k] = STEP;
        let col = (f(d) - f(-d)) / (2.0 * STEP);
        jac.set_column(k, &col);
    }
    jac
}

/// Asserts two matrices agree element-wise within `tol` (absolute, scaled by magnitude).
pub fn assert_mat_close<const R: usize, const C: usize>(
    analytic: &SMatrix<f64, R, C>,
    numeric: &SMatrix<f64, R, C>,
    tol: f64,
) {
    let scale = 1.0 + numeric.amax();
    let err = (analytic - numeric).amax();
    assert!(
        err < tol * scale,
        "max error {err:e} > {tol:e}\nanalytic: {analytic}\nnumeric: {numeric}"
    );
}
