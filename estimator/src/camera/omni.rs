//! Mei's unified projection (Kalibr `omni`): a point is projected onto the unit sphere,
//! then onto the normalised plane from a centre `xi` above the sphere's.

use crate::scalar::Scalar;
use nalgebra::{Matrix2x3, Matrix3, Vector2, Vector3};

/// Normalised point (before distortion) and its Jacobian w.r.t. the 3D point.
pub fn project<T: Scalar>(p: &Vector3<T>, xi: T) -> Option<(Vector2<T>, Matrix2x3<T>)> {
    let norm = p.norm();
    if !norm.is_finite() || norm < T::lit(1e-12) {
        return None;
    }
    let s = p / norm;
    let z = s.z + xi;
    if z <= T::lit(1e-9) {
        return None;
    }
    let m = Vector2::new(s.x / z, s.y / z);
    let dm_ds = Matrix2x3::new(
        T::one() / z,
        T::zero(),
        -m.x / z,
        T::zero(),
        T::one() / z,
        -m.y / z,
    );
    let ds_dp = (Matrix3::identity() - s * s.transpose()) / norm;
    Some((m, dm_ds * ds_dp))
}

/// Lifts a normalised (undistorted) point back onto the unit sphere.
pub fn lift<T: Scalar>(m: &Vector2<T>, xi: T) -> Option<Vector3<T>> {
    let r2 = m.norm_squared();
    let disc = T::one() + (T::one() - xi * xi) * r2;
    if disc < T::zero() {
        return None;
    }
    let factor = (xi + disc.sqrt()) / (T::one() + r2);
    Some(Vector3::new(factor * m.x, factor * m.y, factor - xi))
}
