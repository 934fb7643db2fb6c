//! Double sphere projection (Usenko et al. 2018, Kalibr `ds`): a point goes onto a unit
//! sphere, then onto a second unit sphere shifted by `xi` along the axis, then through the
//! pinhole of the unified model with parameter `alpha`. Works on the normalised plane: the
//! focal lengths and principal point are applied by the caller.

use crate::scalar::Scalar;
use nalgebra::{Matrix2, Matrix2x3, RowVector3, Vector2, Vector3};

/// Normalised point, its Jacobian w.r.t. the 3D point and w.r.t. `[xi, alpha]`; `None`
/// outside the model's valid region.
pub fn project<T: Scalar>(
    p: &Vector3<T>,
    xi: T,
    alpha: T,
) -> Option<(Vector2<T>, Matrix2x3<T>, Matrix2<T>)> {
    let d1 = p.norm();
    if !d1.is_finite() || d1 < T::lit(1e-12) || !in_region(p, d1, xi, alpha) {
        return None;
    }
    let one = T::one();
    let k = xi * d1 + p.z;
    let d2 = (p.x * p.x + p.y * p.y + k * k).sqrt();
    let den = alpha * d2 + (one - alpha) * k;
    if den <= T::lit(1e-12) {
        return None;
    }
    let m = Vector2::new(p.x / den, p.y / den);
    let dk = RowVector3::new(xi * p.x / d1, xi * p.y / d1, xi * p.z / d1 + one);
    let dd2 = RowVector3::new(p.x / d2, p.y / d2, T::zero()) + dk * (k / d2);
    let dden = dd2 * alpha + dk * (one - alpha);
    let jp = Matrix2x3::new(
        one / den,
        T::zero(),
        T::zero(),
        T::zero(),
        one / den,
        T::zero(),
    ) - m * dden / den;
    let dden_dxi = alpha * k * d1 / d2 + (one - alpha) * d1;
    let dden_dalpha = d2 - k;
    let jm = Matrix2::new(
        -m.x * dden_dxi / den,
        -m.x * dden_dalpha / den,
        -m.y * dden_dxi / den,
        -m.y * dden_dalpha / den,
    );
    Some((m, jp, jm))
}

/// The model's valid region `z > -w2 |p|` (Usenko et al., eq. 43).
fn in_region<T: Scalar>(p: &Vector3<T>, d1: T, xi: T, alpha: T) -> bool {
    let one = T::one();
    let w1 = if alpha <= T::lit(0.5) {
        alpha / (one - alpha)
    } else {
        (one - alpha) / alpha
    };
    let w2 = (w1 + xi) / (T::lit(2.0) * w1 * xi + xi * xi + one).sqrt();
    p.z > -w2 * d1
}

/// Unit bearing of a normalised point; `None` outside the valid region.
pub fn unproject<T: Scalar>(m: &Vector2<T>, xi: T, alpha: T) -> Option<Vector3<T>> {
    let one = T::one();
    let r2 = m.norm_squared();
    let disc = one - (T::lit(2.0) * alpha - one) * r2;
    if disc < T::zero() {
        return None;
    }
    let mz = (one - alpha * alpha * r2) / (alpha * disc.sqrt() + one - alpha);
    let disc2 = mz * mz + (one - xi * xi) * r2;
    if disc2 < T::zero() {
        return None;
    }
    let s = (mz * xi + disc2.sqrt()) / (mz * mz + r2);
    let b = Vector3::new(s * m.x, s * m.y, s * mz - xi);
    b.try_normalize(T::zero())
}
