//! Rigid and similarity alignment of point sets (Umeyama / Horn), used to define the VO
//! scale and to judge camera poses frame-free.

use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};

fn centroid(p: &[Vector3<f64>]) -> Vector3<f64> {
    p.iter().sum::<Vector3<f64>>() / p.len().max(1) as f64
}

/// Rotation and scale of the least-squares similarity `b ~ s R a + t`.
fn umeyama(
    a: &[Vector3<f64>],
    b: &[Vector3<f64>],
) -> (Matrix3<f64>, f64, Vector3<f64>, Vector3<f64>) {
    let (ca, cb) = (centroid(a), centroid(b));
    let mut cov = Matrix3::zeros();
    let mut var_a = 0.0;
    for (x, y) in a.iter().zip(b) {
        cov += (y - cb) * (x - ca).transpose();
        var_a += (x - ca).norm_squared();
    }
    let svd = cov.svd(true, true);
    let (u, vt) = (
        svd.u.unwrap_or_else(Matrix3::identity),
        svd.v_t.unwrap_or_else(Matrix3::identity),
    );
    let mut d = Matrix3::identity();
    if (u * vt).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * vt;
    let s = (svd.singular_values.component_mul(&d.diagonal())).sum() / var_a.max(1e-300);
    (r, s, ca, cb)
}

/// Scale of the least-squares similarity mapping `a` onto `b`.
pub fn similarity_scale(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    umeyama(a, b).1
}

/// The least-squares rigid transform `T` with `b ~ T a` (no scale): Umeyama's rotation
/// (which does not depend on the scale) and the centroids.
pub fn rigid(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> Isometry3<f64> {
    let (r, _, ca, cb) = umeyama(a, b);
    let r = nalgebra::Rotation3::from_matrix_unchecked(r);
    let q = UnitQuaternion::from_rotation_matrix(&r);
    Isometry3::from_parts(Translation3::from(cb - q * ca), q)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_similarity() {
        let q = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
        let a: Vec<Vector3<f64>> = (0..10)
            .map(|i| Vector3::new(i as f64, (i * i) as f64 * 0.1, (i % 3) as f64))
            .collect();
        let b: Vec<Vector3<f64>> = a
            .iter()
            .map(|x| q * x * 2.5 + Vector3::new(1.0, 2.0, 3.0))
            .collect();
        assert!((similarity_scale(&a, &b) - 2.5).abs() < 1e-12);
        let b1: Vec<Vector3<f64>> = a
            .iter()
            .map(|x| q * x + Vector3::new(1.0, 2.0, 3.0))
            .collect();
        let t = rigid(&a, &b1);
        assert!(t.rotation.angle_to(&q) < 1e-12);
        assert!((t.translation.vector - Vector3::new(1.0, 2.0, 3.0)).norm() < 1e-12);
    }
}
