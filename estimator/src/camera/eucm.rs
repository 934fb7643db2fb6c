//! Extended unified camera model (Khomutenko et al. 2016, Kalibr `eucm`): the unified
//! model's sphere becomes an ellipsoid of shape `beta`. Works on the normalised plane: the
//! focal lengths and principal point are applied by the caller.

use crate::scalar::Scalar;
use nalgebra::{Matrix2, Matrix2x3, RowVector3, Vector2, Vector3};

/// Normalised point, its Jacobian w.r.t. the 3D point and w.r.t. `[alpha, beta]`; `None`
/// outside the model's valid region.
pub fn project<T: Scalar>(
    p: &Vector3<T>,
    alpha: T,
    beta: T,
) -> Option<(Vector2<T>, Matrix2x3<T>, Matrix2<T>)> {
    if !p.iter().all(|x| x.is_finite()) || beta <= T::zero() {
        return None;
    }
    let one = T::one();
    let rho2 = p.x * p.x + p.y * p.y;
    let d = (beta * rho2 + p.z * p.z).sqrt();
    if d < T::lit(1e-12) {
        return None;
    }
    let w = if alpha <= T::lit(0.5) {
        alpha / (one - alpha)
    } else {
        (one - alpha) / alpha
    };
    if alpha > T::lit(0.5) && p.z <= -w * d {
        return None;
    }
    let den = alpha * d + (one - alpha) * p.z;
    if den <= T::lit(1e-12) {
        return None;
    }
    let m = Vector2::new(p.x / den, p.y / den);
    let dd = RowVector3::new(beta * p.x / d, beta * p.y / d, p.z / d);
    let dden = dd * alpha + RowVector3::new(T::zero(), T::zero(), one - alpha);
    let jp = Matrix2x3::new(
        one / den,
        T::zero(),
        T::zero(),
        T::zero(),
        one / den,
        T::zero(),
    ) - m * dden / den;
    let dden_dalpha = d - p.z;
    let dden_dbeta = alpha * rho2 / (T::lit(2.0) * d);
    let jm = Matrix2::new(
        -m.x * dden_dalpha / den,
        -m.x * dden_dbeta / den,
        -m.y * dden_dalpha / den,
        -m.y * dden_dbeta / den,
    );
    Some((m, jp, jm))
}

/// Unit bearing of a normalised point; `None` outside the valid region.
pub fn unproject<T: Scalar>(m: &Vector2<T>, alpha: T, beta: T) -> Option<Vector3<T>> {
    let one = T::one();
    let r2 = m.norm_squared();
    let disc = one - (T::lit(2.0) * alpha - one) * beta * r2;
    if disc < T::zero() {
        return None;
    }
    let mz = (one - beta * alpha * alpha * r2) / (alpha * disc.sqrt() + one - alpha);
    Vector3::new(m.x, m.y, mz).try_normalize(T::zero())
}
