//! The rotation functions of one propagation step by their power series, for the angles an
//! IMU step turns through (`|theta|` up to [`SERIES_MAX_ANGLE`]), with the trigonometric
//! forms of [`crate::lie`] beyond.
//!
//! Why: on a Cortex-M4F, libm's `sinf` / `cosf` evaluate their kernels in `f64`, which the
//! single-precision FPU does not have: each call is ~20 software double operations, and one
//! step calls four of each (two `Exp`, two right Jacobians). The series are a handful of
//! single-precision multiply-adds. They are as accurate: truncated after the `theta^8` term,
//! the first term left out is below `0.1^10 / 10! < 3e-17` relative at the largest angle
//! used, under the rounding of `f64`; and they have no cancellation, where `(1 - cos t) / t^2`
//! and `(t - sin t) / t^3` lose ~4 and ~7 significant digits in `f32` at `t = 0.005 rad`.
//!
//! The results differ from the trigonometric forms by rounding only, so the filter uses them
//! on request ([`crate::FilterConfig::rotations`]): the default keeps the reference
//! numbers bit for bit.

use crate::lie::{self, skew};
use crate::scalar::Scalar;
use nalgebra::{Matrix3, Quaternion, UnitQuaternion, Vector3};

/// Largest rotation angle (rad) evaluated by series: 40 rad/s over a 400 Hz step.
pub const SERIES_MAX_ANGLE: f64 = 0.1;

/// `sum c_i x^i` by Horner's rule.
fn poly<T: Scalar>(x: T, c: &[f64; 5]) -> T {
    let mut acc = T::lit(c[4]);
    for &ci in c[..4].iter().rev() {
        acc = acc * x + T::lit(ci);
    }
    acc
}

/// `cos(t / 2)` in `x = t^2`.
const COS_HALF: [f64; 5] = [
    1.0,
    -1.0 / 8.0,
    1.0 / 384.0,
    -1.0 / 46_080.0,
    1.0 / 10_321_920.0,
];
/// `sin(t / 2) / t` in `x = t^2`.
const SIN_HALF_OVER: [f64; 5] = [
    1.0 / 2.0,
    -1.0 / 48.0,
    1.0 / 3_840.0,
    -1.0 / 645_120.0,
    1.0 / 185_794_560.0,
];
/// `(1 - cos t) / t^2` in `x = t^2`.
const ONE_MINUS_COS: [f64; 5] = [
    1.0 / 2.0,
    -1.0 / 24.0,
    1.0 / 720.0,
    -1.0 / 40_320.0,
    1.0 / 3_628_800.0,
];
/// `(t - sin t) / t^3` in `x = t^2`.
const T_MINUS_SIN: [f64; 5] = [
    1.0 / 6.0,
    -1.0 / 120.0,
    1.0 / 5_040.0,
    -1.0 / 362_880.0,
    1.0 / 39_916_800.0,
];

/// Which evaluation of the rotation functions a step uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Rotations {
    /// [`crate::lie::exp`] and [`crate::lie::right_jacobian`] (libm's trigonometry): the
    /// reference.
    #[default]
    Trigonometric,
    /// The power series up to [`SERIES_MAX_ANGLE`], the trigonometric forms beyond.
    Series,
}

impl Rotations {
    /// `Exp(phi)` as a unit quaternion.
    pub fn exp<T: Scalar>(self, phi: &Vector3<T>) -> UnitQuaternion<T> {
        let x = phi.norm_squared();
        if self == Rotations::Trigonometric || x > T::lit(SERIES_MAX_ANGLE * SERIES_MAX_ANGLE) {
            return lie::exp(phi);
        }
        let k = poly(x, &SIN_HALF_OVER);
        UnitQuaternion::new_unchecked(Quaternion::new(
            poly(x, &COS_HALF),
            phi.x * k,
            phi.y * k,
            phi.z * k,
        ))
    }

    /// The right Jacobian of SO(3) at `phi`: `I - a [phi]x + b [phi]x^2`.
    pub fn right_jacobian<T: Scalar>(self, phi: &Vector3<T>) -> Matrix3<T> {
        let x = phi.norm_squared();
        if self == Rotations::Trigonometric || x > T::lit(SERIES_MAX_ANGLE * SERIES_MAX_ANGLE) {
            return lie::right_jacobian(phi);
        }
        let k = skew(phi);
        Matrix3::identity() - k * poly(x, &ONE_MINUS_COS) + k * k * poly(x, &T_MINUS_SIN)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn angles() -> impl Iterator<Item = Vector3<f64>> {
        [1e-9, 1e-5, 1e-3, 0.005, 0.03, 0.0999, 0.1001, 0.5, 2.0]
            .into_iter()
            .map(|t| Vector3::new(0.6, -0.48, 0.64) * t)
    }

    #[test]
    fn series_agree_with_the_trigonometric_forms_to_rounding() {
        for phi in angles() {
            let (q_s, q_t) = (Rotations::Series.exp(&phi), lie::exp(&phi));
            assert!(
                (q_s.coords - q_t.coords).amax() < 4e-16,
                "{phi:?}: {}",
                (q_s.coords - q_t.coords).amax()
            );
            let (j_s, j_t) = (
                Rotations::Series.right_jacobian(&phi),
                lie::right_jacobian(&phi),
            );
            // The trigonometric form cancels for small angles (1 - cos t loses digits).
            let tol = 4e-16 + 4e-16 / phi.norm();
            assert!((j_s - j_t).amax() < tol, "{phi:?}: {}", (j_s - j_t).amax());
        }
    }

    #[test]
    fn series_in_f32_are_at_least_as_accurate_as_libm() {
        for phi in angles().filter(|p| p.norm() <= SERIES_MAX_ANGLE) {
            let phi32 = phi.cast::<f32>();
            let exact = lie::right_jacobian(&phi32.cast::<f64>());
            let err = |j: Matrix3<f32>| (j.cast::<f64>() - exact).amax();
            let (series, trig) = (
                err(Rotations::Series.right_jacobian(&phi32)),
                err(lie::right_jacobian(&phi32)),
            );
            assert!(
                series < 3e-7 && series <= trig + 1e-7,
                "{phi:?}: {series} vs {trig}"
            );
            let q_exact = lie::exp(&phi32.cast::<f64>());
            let q_err =
                (Rotations::Series.exp(&phi32).coords.cast::<f64>() - q_exact.coords).amax();
            assert!(q_err < 2e-7, "{phi:?}: {q_err}");
        }
    }

    #[test]
    fn trigonometric_is_the_reference_bit_for_bit() {
        for phi in angles() {
            assert_eq!(Rotations::Trigonometric.exp(&phi), lie::exp(&phi));
            assert_eq!(
                Rotations::Trigonometric.right_jacobian(&phi),
                lie::right_jacobian(&phi)
            );
        }
    }
}
