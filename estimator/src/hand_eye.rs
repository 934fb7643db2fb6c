//! Extrinsic rotation initialisation from the hand-eye rotation constraint (eq. 3.2-3.5).
//!
//! Paired rotation increments of the IMU (integrated gyro) and of the sensor (odometry,
//! NDT, PnP) satisfy `r_I = R_I_S r_S` for their rotation vectors (eq. 3.3). The least-squares
//! `R_I_S` (eq. 3.4) is the orthogonal Procrustes solution of `M = sum r_I r_S^T`, found in
//! closed form by an SVD; no iterative solver is needed. The accumulator holds only 3x3
//! sums, so it also runs on the microcontroller.
//!
//! The constraint fixes `R_I_S` only when the sensor rotated about at least two axes: the
//! second eigenvalue of `sum r_S r_S^T` must be a sizeable fraction of the first.

use crate::scalar::Scalar;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};

/// Why no rotation could be computed.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HandEyeError<T: Scalar> {
    /// Fewer pairs than `min_pairs`.
    TooFewPairs {
        /// Pairs accumulated.
        pairs: usize,
    },
    /// Rotation about fewer than two axes: `ratio` = second / first eigenvalue of the
    /// rotation scatter.
    Degenerate {
        /// Second / first eigenvalue.
        ratio: T,
    },
    /// The SVD did not converge or the input was not finite.
    Numerical,
}

/// Accumulates rotation-increment pairs and solves for `R_I_S`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HandEye<T: Scalar> {
    correlation: Matrix3<T>,
    scatter: Matrix3<T>,
    pairs: usize,
}

impl<T: Scalar> Default for HandEye<T> {
    fn default() -> Self {
        Self {
            correlation: Matrix3::zeros(),
            scatter: Matrix3::zeros(),
            pairs: 0,
        }
    }
}

/// Smallest second/first eigenvalue ratio of the rotation scatter accepted as two-axis
/// excitation.
pub const MIN_AXIS_RATIO: f64 = 0.02;

impl<T: Scalar> HandEye<T> {
    /// Adds one pair of rotation increments: of the IMU (`r_imu`) and of the sensor
    /// (`r_sensor`) over the same interval, as rotation vectors. Non-finite pairs are ignored
    /// and reported as `false`.
    pub fn add(&mut self, r_imu: &Vector3<T>, r_sensor: &Vector3<T>) -> bool {
        if !r_imu.iter().chain(r_sensor.iter()).all(|x| x.is_finite()) {
            return false;
        }
        self.correlation += r_imu * r_sensor.transpose();
        self.scatter += r_sensor * r_sensor.transpose();
        self.pairs += 1;
        true
    }

    /// Pairs accumulated.
    pub fn pairs(&self) -> usize {
        self.pairs
    }

    /// Second / first eigenvalue of the sensor rotation scatter (0 = one axis only).
    pub fn axis_ratio(&self) -> T {
        let eig = self.scatter.symmetric_eigenvalues();
        let largest = eig.max();
        let smallest = eig.min();
        let middle = eig.sum() - largest - smallest;
        if largest <= T::zero() {
            return T::zero();
        }
        middle / largest
    }

    /// The least-squares `R_I_S`.
    pub fn solve(&self, min_pairs: usize) -> Result<UnitQuaternion<T>, HandEyeError<T>> {
        if self.pairs < min_pairs.max(2) {
            return Err(HandEyeError::TooFewPairs { pairs: self.pairs });
        }
        let ratio = self.axis_ratio();
        if ratio < T::lit(MIN_AXIS_RATIO) {
            return Err(HandEyeError::Degenerate { ratio });
        }
        let svd = self.correlation.svd(true, true);
        let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
            return Err(HandEyeError::Numerical);
        };
        // R = U diag(1, 1, det(U V^T)) V^T: the closest proper rotation.
        let d = (u * v_t).determinant();
        let mut fix = Matrix3::identity();
        fix[(2, 2)] = if d < T::zero() { -T::one() } else { T::one() };
        // SVD orders singular values descending, so the sign fix lands on the smallest.
        let r = u * fix * v_t;
        if !r.iter().all(|x| x.is_finite()) {
            return Err(HandEyeError::Numerical);
        }
        Ok(UnitQuaternion::from_matrix(&r))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn truth() -> UnitQuaternion<f64> {
        UnitQuaternion::from_euler_angles(3.1, 0.1, -0.7)
    }

    #[test]
    fn recovers_rotation_from_exact_pairs() {
        let mut he = HandEye::default();
        for k in 0..20 {
            let t = k as f64 * 0.37;
            let r_s = Vector3::new(t.sin(), (1.3 * t).cos(), 0.5 * (0.7 * t).sin()) * 0.2;
            he.add(&(truth() * r_s), &r_s);
        }
        let r = he.solve(5).unwrap();
        assert!(r.angle_to(&truth()) < 1e-9);
    }

    #[test]
    fn single_axis_motion_is_degenerate() {
        let mut he = HandEye::default();
        for k in 0..20 {
            let r_s = Vector3::new(0.0, 0.0, 0.1 * (k as f64).sin());
            he.add(&(truth() * r_s), &r_s);
        }
        assert!(matches!(he.solve(5), Err(HandEyeError::Degenerate { .. })));
    }

    #[test]
    fn nan_pairs_are_ignored() {
        let mut he = HandEye::<f64>::default();
        assert!(!he.add(&Vector3::new(f64::NAN, 0.0, 0.0), &Vector3::zeros()));
        assert_eq!(he.pairs(), 0);
        assert!(matches!(he.solve(1), Err(HandEyeError::TooFewPairs { .. })));
    }
}
