//! Degeneracy of a registration from the eigenvalues of its Hessian.
//!
//! The 6x6 Hessian `H` (w.r.t. `[t; theta]`) mixes metres and radians, so it
//! is split into the marginal information of translation and of rotation
//! (Schur complements `H_tt - H_tr H_rr^-1 H_rt` and
//! `H_rr - H_rt H_tt^-1 H_tr`, the inverses of the covariance blocks). A
//! block is degenerate when its `lambda_min / lambda_max` is below
//! `NdtParams::degeneracy_ratio` (or it is not positive definite): e.g. the
//! translation along a corridor, where only the in-plane curvature of the
//! cell Gaussians resists motion (measured ratio about 0.014 for two walls and
//! a floor, against 0.12-0.30 for a furnished room and the two real pairs).

use nalgebra::{Matrix3, Matrix6, SymmetricEigen, Vector3};

/// Why a registration is not trustworthy in some direction.
#[derive(Debug, Clone, PartialEq)]
pub struct DegeneracyReport {
    /// `lambda_min / lambda_max` of the marginal translation information
    /// (negative or zero when not positive definite).
    pub translation_ratio: f64,
    /// The same for rotation.
    pub rotation_ratio: f64,
    /// The threshold both were compared with.
    pub threshold: f64,
    /// Unit direction (target frame) of the weakest translation, when the
    /// translation block is degenerate.
    pub weak_translation: Option<Vector3<f64>>,
    /// Unit axis (source frame, right perturbation) of the weakest rotation,
    /// when the rotation block is degenerate.
    pub weak_rotation: Option<Vector3<f64>>,
}

/// Ratio and weakest eigenvector of the Schur complement `a - b c^-1 b^T`.
fn marginal(a: &Matrix3<f64>, b: &Matrix3<f64>, c: &Matrix3<f64>) -> (f64, Vector3<f64>) {
    let Some(c_inv) = c.cholesky().map(|ch| ch.inverse()) else {
        return (0.0, Vector3::zeros());
    };
    let schur = a - b * c_inv * b.transpose();
    let eig = SymmetricEigen::new(0.5 * (schur + schur.transpose()));
    let (imin, min) = eig.eigenvalues.argmin();
    let max = eig.eigenvalues.max();
    let ratio = if max > 0.0 {
        min / max
    } else {
        f64::NEG_INFINITY
    };
    (ratio, eig.eigenvectors.column(imin).into_owned())
}

/// Returns a report when `hessian` (w.r.t. `[t; theta]`) is degenerate.
pub(crate) fn analyse(hessian: &Matrix6<f64>, threshold: f64) -> Option<DegeneracyReport> {
    let h_tt = hessian.fixed_view::<3, 3>(0, 0).into_owned();
    let h_tr = hessian.fixed_view::<3, 3>(0, 3).into_owned();
    let h_rr = hessian.fixed_view::<3, 3>(3, 3).into_owned();
    let (translation_ratio, t_dir) = marginal(&h_tt, &h_tr, &h_rr);
    let (rotation_ratio, r_dir) = marginal(&h_rr, &h_tr.transpose(), &h_tt);
    let weak = |ratio: f64, dir: Vector3<f64>| (ratio.is_nan() || ratio < threshold).then_some(dir);
    let weak_translation = weak(translation_ratio, t_dir);
    let weak_rotation = weak(rotation_ratio, r_dir);
    (weak_translation.is_some() || weak_rotation.is_some()).then_some(DegeneracyReport {
        translation_ratio,
        rotation_ratio,
        threshold,
        weak_translation,
        weak_rotation,
    })
}
