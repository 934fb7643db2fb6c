//! SO(3) and SE(3) helpers: skew, Exp, Log, the right Jacobian and its inverse, and a
//! rigid-body [`Pose`]. Small-angle branches use Taylor series so f32 keeps full precision.

use crate::scalar::Scalar;
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Angles below this (rad) use series expansions.
fn small_angle<T: Scalar>() -> T {
    T::lit(1e-4)
}

/// The skew-symmetric matrix `[v]x` with `[v]x w = v x w`.
pub fn skew<T: Scalar>(v: &Vector3<T>) -> Matrix3<T> {
    Matrix3::new(
        T::zero(),
        -v.z,
        v.y,
        v.z,
        T::zero(),
        -v.x,
        -v.y,
        v.x,
        T::zero(),
    )
}

/// Exp: rotation vector -> unit quaternion.
pub fn exp<T: Scalar>(phi: &Vector3<T>) -> UnitQuaternion<T> {
    let theta2 = phi.norm_squared();
    let theta = theta2.sqrt();
    let half = T::lit(0.5);
    let (w, k) = if theta < small_angle() {
        // sin(theta/2)/theta = 1/2 - theta^2/48
        (
            T::one() - theta2 / T::lit(8.0),
            half - theta2 / T::lit(48.0),
        )
    } else {
        ((theta * half).cos(), (theta * half).sin() / theta)
    };
    UnitQuaternion::new_unchecked(Quaternion::new(w, phi.x * k, phi.y * k, phi.z * k))
}

/// Log: unit quaternion -> rotation vector with angle in [0, pi].
///
/// Uses `atan2` rather than `acos`, which loses all precision near identity in f32.
pub fn log<T: Scalar>(q: &UnitQuaternion<T>) -> Vector3<T> {
    let q = q.quaternion();
    // q and -q are the same rotation: pick w >= 0 so the angle is in [0, pi].
    let (w, v) = if q.w < T::zero() {
        (-q.w, -q.imag())
    } else {
        (q.w, q.imag())
    };
    let s = v.norm();
    let k = if s < small_angle() {
        // 2 atan(s/w)/s = 2/w (1 - s^2/(3 w^2))
        T::lit(2.0) / w * (T::one() - s * s / (T::lit(3.0) * w * w))
    } else {
        T::lit(2.0) * s.atan2(w) / s
    };
    v * k
}

/// Right Jacobian of SO(3): `Exp(phi + d) = Exp(phi) Exp(Jr(phi) d)` to first order.
pub fn right_jacobian<T: Scalar>(phi: &Vector3<T>) -> Matrix3<T> {
    let theta2 = phi.norm_squared();
    let theta = theta2.sqrt();
    let k = skew(phi);
    let (a, b) = if theta < small_angle() {
        (
            T::lit(0.5) - theta2 / T::lit(24.0),
            T::lit(1.0 / 6.0) - theta2 / T::lit(120.0),
        )
    } else {
        (
            (T::one() - theta.cos()) / theta2,
            (theta - theta.sin()) / (theta2 * theta),
        )
    };
    Matrix3::identity() - k * a + k * k * b
}

/// Inverse of the right Jacobian of SO(3).
pub fn right_jacobian_inv<T: Scalar>(phi: &Vector3<T>) -> Matrix3<T> {
    let theta2 = phi.norm_squared();
    let theta = theta2.sqrt();
    let k = skew(phi);
    let b = if theta < small_angle() {
        T::lit(1.0 / 12.0) + theta2 / T::lit(720.0)
    } else {
        T::one() / theta2 - (T::one() + theta.cos()) / (T::lit(2.0) * theta * theta.sin())
    };
    Matrix3::identity() + k * T::lit(0.5) + k * k * b
}

/// A rigid-body transform `T_a_b`: the pose of frame `b` in frame `a` (`p_a = T_a_b * p_b`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose<T: Scalar> {
    /// `R_a_b`.
    pub rotation: UnitQuaternion<T>,
    /// `p_a_b`: the origin of `b` in `a`.
    pub translation: Vector3<T>,
}

impl<T: Scalar> Default for Pose<T> {
    fn default() -> Self {
        Self::identity()
    }
}

impl<T: Scalar> Pose<T> {
    /// A pose from its rotation and translation.
    pub fn new(rotation: UnitQuaternion<T>, translation: Vector3<T>) -> Self {
        Self {
            rotation,
            translation,
        }
    }

    /// The identity transform.
    pub fn identity() -> Self {
        Self::new(UnitQuaternion::identity(), Vector3::zeros())
    }

    /// `T_a_c = T_a_b * T_b_c`.
    pub fn compose(&self, other: &Pose<T>) -> Pose<T> {
        Pose::new(
            self.rotation * other.rotation,
            self.rotation * other.translation + self.translation,
        )
    }

    /// `T_b_a` from `T_a_b`.
    pub fn inverse(&self) -> Pose<T> {
        let r_inv = self.rotation.inverse();
        Pose::new(r_inv, -(r_inv * self.translation))
    }

    /// `p_a = T_a_b * p_b`.
    pub fn transform_point(&self, p_b: &Vector3<T>) -> Vector3<T> {
        self.rotation * p_b + self.translation
    }

    /// Right perturbation of the rotation, additive translation: the error convention of
    /// every pose in the filter state.
    pub fn boxplus(&self, d_rotation: &Vector3<T>, d_translation: &Vector3<T>) -> Pose<T> {
        Pose::new(
            renormalize(self.rotation * exp(d_rotation)),
            self.translation + d_translation,
        )
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        let q = self.rotation.quaternion();
        q.coords.iter().all(|x| x.is_finite()) && self.translation.iter().all(|x| x.is_finite())
    }
}

/// Re-normalises a quaternion after many compositions (keeps f32 on the manifold).
pub fn renormalize<T: Scalar>(q: UnitQuaternion<T>) -> UnitQuaternion<T> {
    UnitQuaternion::new_normalize(q.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_mat_close, central_diff_so3};

    fn vecs() -> [Vector3<f64>; 5] {
        [
            Vector3::new(0.1, -0.2, 0.3),
            Vector3::new(1e-6, 2e-7, -3e-6),
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(2.0, 1.0, -0.5),
            Vector3::new(0.0, 3.1, 0.0),
        ]
    }

    #[test]
    fn exp_log_round_trip() {
        for v in vecs() {
            let back = log(&exp(&v));
            assert!((back - v).norm() < 1e-12, "{v:?} -> {back:?}");
        }
    }

    #[test]
    fn exp_matches_nalgebra() {
        for v in vecs() {
            let a = exp(&v);
            let b = UnitQuaternion::from_scaled_axis(v);
            assert!(a.angle_to(&b) < 1e-12);
        }
    }

    #[test]
    fn log_keeps_precision_near_identity_in_f32() {
        let v = Vector3::new(1e-4f32, -2e-4, 3e-5);
        let back = log(&exp(&v));
        assert!((back - v).norm() < 1e-9, "{back:?}");
    }

    #[test]
    fn right_jacobian_matches_central_differences() {
        for phi in vecs() {
            // d/dd Log(Exp(phi)^-1 Exp(phi + d)) = Jr(phi)
            let numeric = central_diff_so3(|d| log(&(exp(&phi).inverse() * exp(&(phi + d)))));
            assert_mat_close(&right_jacobian(&phi), &numeric, 1e-7);
        }
    }

    #[test]
    fn right_jacobian_inverse_is_inverse() {
        for phi in vecs() {
            let prod = right_jacobian(&phi) * right_jacobian_inv(&phi);
            assert_mat_close(&prod, &Matrix3::identity(), 1e-9);
        }
    }

    #[test]
    fn skew_is_cross_product() {
        let a = Vector3::new(1.0, 2.0, 3.0);
        let b = Vector3::new(-0.5, 0.25, 4.0);
        assert!((skew(&a) * b - a.cross(&b)).norm() < 1e-15);
    }

    #[test]
    fn pose_inverse_and_compose() {
        let t = Pose::new(
            exp(&Vector3::new(0.3, -1.0, 2.0)),
            Vector3::new(1.0, 2.0, 3.0),
        );
        let id = t.compose(&t.inverse());
        assert!(id.rotation.angle() < 1e-12 && id.translation.norm() < 1e-12);
        let p = Vector3::new(0.5, -0.5, 2.0);
        let q = t.inverse().transform_point(&t.transform_point(&p));
        assert!((q - p).norm() < 1e-12);
    }
}
