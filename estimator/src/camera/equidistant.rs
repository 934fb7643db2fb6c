//! Equidistant fisheye model (Kalibr `equidistant`, Kannala-Brandt with four
//! coefficients): the image radius grows with the angle off the axis,
//! `theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)`.

use crate::scalar::Scalar;
use nalgebra::{Matrix2x3, Matrix2x4, RowVector3, Vector2, Vector3};

/// The four coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Equidistant<T: Scalar> {
    /// theta^3 term.
    pub k1: T,
    /// theta^5 term.
    pub k2: T,
    /// theta^7 term.
    pub k3: T,
    /// theta^9 term.
    pub k4: T,
}

impl<T: Scalar> Equidistant<T> {
    /// True when every coefficient is finite.
    pub fn is_finite(&self) -> bool {
        [self.k1, self.k2, self.k3, self.k4]
            .iter()
            .all(|x| x.is_finite())
    }

    /// `theta_d(theta)` and its derivative.
    fn radius(&self, theta: T) -> (T, T) {
        let t2 = theta * theta;
        let poly = T::one() + t2 * (self.k1 + t2 * (self.k2 + t2 * (self.k3 + t2 * self.k4)));
        let dpoly = T::one()
            + t2 * (T::lit(3.0) * self.k1
                + t2 * (T::lit(5.0) * self.k2
                    + t2 * (T::lit(7.0) * self.k3 + t2 * T::lit(9.0) * self.k4)));
        (theta * poly, dpoly)
    }

    /// Distorted normalised point and its Jacobian w.r.t. the 3D point.
    pub fn project(&self, p: &Vector3<T>) -> Option<(Vector2<T>, Matrix2x3<T>)> {
        if !p.iter().all(|x| x.is_finite()) || p.norm() < T::lit(1e-12) {
            return None;
        }
        let rho2 = p.x * p.x + p.y * p.y;
        let rho = rho2.sqrt();
        let theta = rho.atan2(p.z);
        // Beyond ~180 deg the model is not invertible.
        if theta > T::lit(3.0) {
            return None;
        }
        let (theta_d, dtheta_d) = self.radius(theta);
        if rho < T::lit(1e-9) * p.z.abs().max(T::lit(1e-12)) {
            // On the axis the model is a pinhole (theta_d / rho -> 1 / z).
            let iz = T::one() / p.z;
            let m = Vector2::new(p.x * iz, p.y * iz);
            let j = Matrix2x3::new(iz, T::zero(), -m.x * iz, T::zero(), iz, -m.y * iz);
            return Some((m, j));
        }
        let s = theta_d / rho;
        let n2 = rho2 + p.z * p.z;
        let dtheta = RowVector3::new(p.z * p.x / rho, p.z * p.y / rho, -rho) / n2;
        let drho = RowVector3::new(p.x / rho, p.y / rho, T::zero());
        let ds = dtheta * (dtheta_d / rho) - drho * (theta_d / rho2);
        let mut j = Matrix2x3::zeros();
        j.set_row(0, &(ds * p.x + RowVector3::new(s, T::zero(), T::zero())));
        j.set_row(1, &(ds * p.y + RowVector3::new(T::zero(), s, T::zero())));
        Some((Vector2::new(s * p.x, s * p.y), j))
    }

    /// `d m / d [k1, k2, k3, k4]` of [`Equidistant::project`] at `p` (zero on the axis).
    pub fn coefficient_jacobian(&self, p: &Vector3<T>) -> Matrix2x4<T> {
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        if rho < T::lit(1e-9) * p.z.abs().max(T::lit(1e-12)) {
            return Matrix2x4::zeros();
        }
        let theta = rho.atan2(p.z);
        let t2 = theta * theta;
        let mut j = Matrix2x4::zeros();
        let mut power = theta * t2;
        for k in 0..4 {
            j[(0, k)] = power * p.x / rho;
            j[(1, k)] = power * p.y / rho;
            power *= t2;
        }
        j
    }

    /// Unit-free bearing of a distorted normalised point (Newton on `theta`).
    pub fn unproject(&self, m_d: &Vector2<T>) -> Option<Vector3<T>> {
        let theta_d = m_d.norm();
        if theta_d < T::lit(1e-12) {
            return Some(Vector3::new(m_d.x, m_d.y, T::one()));
        }
        let mut theta = theta_d;
        for _ in 0..30 {
            let (f, df) = self.radius(theta);
            if df <= T::zero() {
                return None;
            }
            let step = (f - theta_d) / df;
            theta -= step;
            if step.abs() < T::lit(1e-14) {
                break;
            }
        }
        if !theta.is_finite() || (self.radius(theta).0 - theta_d).abs() > T::lit(1e-6) {
            return None;
        }
        let s = theta.sin() / theta_d;
        Some(Vector3::new(m_d.x * s, m_d.y * s, theta.cos()))
    }
}
