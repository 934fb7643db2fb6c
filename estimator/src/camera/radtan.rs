//! Radial-tangential distortion on the normalised plane (Kalibr `radtan`, OpenCV).

use crate::scalar::Scalar;
use nalgebra::{Matrix2, Matrix2x4, Vector2};

/// Coefficients `k1, k2, p1, p2` (Kalibr order) and OpenCV's optional `k3`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RadTan<T: Scalar> {
    /// Radial r^2.
    pub k1: T,
    /// Radial r^4.
    pub k2: T,
    /// Tangential 1.
    pub p1: T,
    /// Tangential 2.
    pub p2: T,
    /// Radial r^6 (zero for Kalibr's 4 coefficients).
    pub k3: T,
}

impl<T: Scalar> RadTan<T> {
    /// True when every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        [self.k1, self.k2, self.p1, self.p2, self.k3]
            .iter()
            .all(|x| x.is_finite())
    }

    /// Distorted point and `d distorted / d undistorted`.
    pub fn distort(&self, m: &Vector2<T>) -> (Vector2<T>, Matrix2<T>) {
        let (x, y) = (m.x, m.y);
        let two = T::lit(2.0);
        let r2 = x * x + y * y;
        let radial = T::one() + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        // d radial / d r2, times 2 (d r2 / dx = 2x).
        let d = two * (self.k1 + r2 * (two * self.k2 + T::lit(3.0) * r2 * self.k3));
        let xd = x * radial + two * self.p1 * x * y + self.p2 * (r2 + two * x * x);
        let yd = y * radial + self.p1 * (r2 + two * y * y) + two * self.p2 * x * y;
        let six = T::lit(6.0);
        let j = Matrix2::new(
            radial + x * d * x + two * self.p1 * y + six * self.p2 * x,
            x * d * y + two * self.p1 * x + two * self.p2 * y,
            y * d * x + two * self.p1 * x + two * self.p2 * y,
            radial + y * d * y + six * self.p1 * y + two * self.p2 * x,
        );
        (Vector2::new(xd, yd), j)
    }

    /// `d distorted / d [k1, k2, p1, p2]` at the undistorted point `m` (Kalibr's four
    /// coefficients; `k3` is not a calibrated parameter).
    pub fn coefficient_jacobian(&self, m: &Vector2<T>) -> Matrix2x4<T> {
        let (x, y) = (m.x, m.y);
        let two = T::lit(2.0);
        let r2 = x * x + y * y;
        let r4 = r2 * r2;
        Matrix2x4::new(
            x * r2,
            x * r4,
            two * x * y,
            r2 + two * x * x,
            y * r2,
            y * r4,
            r2 + two * y * y,
            two * x * y,
        )
    }

    /// Inverts [`RadTan::distort`] by Gauss-Newton from the distorted point; `None` when
    /// it does not converge (far outside the lens's field of view).
    pub fn undistort(&self, m_d: &Vector2<T>) -> Option<Vector2<T>> {
        let mut m = *m_d;
        for _ in 0..30 {
            let (d, j) = self.distort(&m);
            let err = d - m_d;
            if err.norm_squared() < T::lit(1e-26) {
                return Some(m);
            }
            m -= j.try_inverse()? * err;
        }
        let err = self.distort(&m).0 - m_d;
        (err.norm() < T::lit(1e-6)).then_some(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_mat_close, central_diff};

    #[test]
    fn jacobian_matches_central_differences() {
        let d = RadTan {
            k1: -0.27,
            k2: 0.1,
            p1: 0.002,
            p2: -0.001,
            k3: 0.05,
        };
        let m = Vector2::new(0.3, -0.2);
        let numeric = central_diff::<2, 2>(|e| d.distort(&(m + e)).0);
        assert_mat_close(&d.distort(&m).1, &numeric, 1e-8);
    }

    #[test]
    fn coefficient_jacobian_matches_central_differences() {
        let d = RadTan {
            k1: -0.27,
            k2: 0.1,
            p1: 0.002,
            p2: -0.001,
            k3: 0.0,
        };
        let m = Vector2::new(0.3, -0.2);
        let numeric = central_diff::<2, 4>(|e| {
            let c = RadTan {
                k1: d.k1 + e[0],
                k2: d.k2 + e[1],
                p1: d.p1 + e[2],
                p2: d.p2 + e[3],
                k3: 0.0,
            };
            c.distort(&m).0
        });
        assert_mat_close(&d.coefficient_jacobian(&m), &numeric, 1e-8);
    }
}
