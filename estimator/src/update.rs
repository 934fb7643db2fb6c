//! Measurement updates: one module per measurement model (residual and Jacobian), and the
//! one generic Kalman step they all share (gain, chi-square gate, Joseph-form covariance
//! update, NIS record).

pub mod relative_pose;
pub mod reprojection;
pub mod zero_velocity;

use crate::chi2::{self, Confidence};
use crate::scalar::Scalar;
use crate::Error;
use nalgebra::{Cholesky, SMatrix, SVector, Vector3};

/// Which measurement model produced an update.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpdateKind {
    /// Relative pose of a sensor between two stamps (eq. 3.19-3.21 / 4.11-4.13).
    RelativePose,
    /// Zero-velocity update at standstill.
    ZeroVelocity,
    /// Known target corners reprojected into a camera (eq. 4.2, 4.15; RepErrCal).
    Reprojection,
}

/// The per-update diagnostic record read by the health monitor, reports, the firmware link
/// and the tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateReport<T: Scalar> {
    /// Measurement model.
    pub kind: UpdateKind,
    /// Sensor index (0 for sensor-less updates such as zero velocity).
    pub sensor: usize,
    /// Measurement stamp, ns (sensor clock).
    pub stamp_ns: u64,
    /// Residual dimension.
    pub dof: usize,
    /// Normalised innovation squared `r^T S^-1 r`.
    pub nis: T,
    /// Gate threshold the NIS was compared with.
    pub threshold: T,
    /// False when the gate rejected the measurement (state then untouched by it).
    pub accepted: bool,
    /// A health event this update triggered (e.g. a detected extrinsic step).
    pub event: Option<crate::health::HealthEvent<T>>,
}

/// A linearised measurement: `r = H dx + n`, `n ~ N(0, R)`.
#[derive(Clone, Debug)]
pub struct Linearization<T: Scalar, const M: usize, const N: usize> {
    /// Residual `z - h(x_hat)` in the measurement's tangent space.
    pub residual: SVector<T, M>,
    /// `H`: derivative of the predicted measurement w.r.t. the error state.
    pub jacobian: SMatrix<T, M, N>,
    /// Measurement noise covariance `R`.
    pub noise: SMatrix<T, M, M>,
}

/// What the Kalman step computed; the caller commits it only if the corrected state is
/// finite.
#[derive(Clone, Debug)]
pub struct KalmanStep<T: Scalar, const M: usize, const N: usize> {
    /// NIS of the innovation.
    pub nis: T,
    /// Gate threshold.
    pub threshold: T,
    /// Whether the gate accepted the measurement.
    pub accepted: bool,
    /// Error-state correction `K r` (zero when rejected).
    pub correction: SVector<T, N>,
    /// Updated covariance (the prior when rejected).
    pub covariance: SMatrix<T, N, N>,
    /// `S^-1 r`, for the health monitor's step detector.
    pub weighted_residual: SVector<T, M>,
    /// `S^-1`.
    pub innovation_inverse: SMatrix<T, M, M>,
}

/// A direction of a 3-dof state block that no update may change (a Schmidt "consider"
/// direction): the gain's component along it is removed, so the estimate keeps its prior
/// value and variance there while its uncertainty still enters every innovation covariance
/// and its correlations stay exact (the Joseph form holds for any gain). Used for what the
/// data cannot observe, e.g. the lever arm along the rotation axis of planar driving,
/// where the little the data says is dominated by model error.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hold<T: Scalar> {
    /// First index of the 3-dof block in the error state.
    pub block: usize,
    /// Unit direction within the block.
    pub axis: Vector3<T>,
}

impl<T: Scalar> Hold<T> {
    /// Removes the gain's component along the held direction, in place.
    fn project<const M: usize, const N: usize>(&self, gain: &mut SMatrix<T, N, M>) {
        if self.block + 3 > N {
            return;
        }
        let mut rows = gain.fixed_rows_mut::<3>(self.block);
        let along = self.axis.transpose() * &rows;
        rows -= self.axis * along;
    }
}

/// The shared Kalman step: innovation covariance, gate, gain and Joseph-form update.
pub fn kalman_step<T: Scalar, const M: usize, const N: usize>(
    cov: &SMatrix<T, N, N>,
    lin: &Linearization<T, M, N>,
    gate: Confidence,
    holds: &[Hold<T>],
) -> Result<KalmanStep<T, M, N>, Error> {
    kalman_step_gated_at(cov, lin, chi2::quantile::<T>(M, gate), holds)
}

/// [`kalman_step`] with an explicit NIS threshold; an infinite one never rejects (used for
/// the parts of a sequentially processed measurement that is gated as a whole).
pub fn kalman_step_gated_at<T: Scalar, const M: usize, const N: usize>(
    cov: &SMatrix<T, N, N>,
    lin: &Linearization<T, M, N>,
    threshold: T,
    holds: &[Hold<T>],
) -> Result<KalmanStep<T, M, N>, Error> {
    let finite = lin.residual.iter().all(|x| x.is_finite())
        && lin.jacobian.iter().all(|x| x.is_finite())
        && lin.noise.iter().all(|x| x.is_finite());
    if !finite {
        return Err(Error::NonFinite);
    }
    let ph_t = cov * lin.jacobian.transpose();
    let s = lin.jacobian * ph_t + lin.noise;
    let s = (s + s.transpose()) * T::lit(0.5);
    let chol = Cholesky::new(s).ok_or(Error::SingularInnovation)?;
    let s_inv = chol.inverse();
    let weighted_residual = s_inv * lin.residual;
    let nis = lin.residual.dot(&weighted_residual);
    if !nis.is_finite() {
        return Err(Error::DivergentUpdate);
    }
    if nis > threshold {
        return Ok(KalmanStep {
            nis,
            threshold,
            accepted: false,
            correction: SVector::zeros(),
            covariance: *cov,
            weighted_residual,
            innovation_inverse: s_inv,
        });
    }
    let mut gain = ph_t * s_inv;
    for hold in holds {
        hold.project(&mut gain);
    }
    let correction = gain * lin.residual;
    // Joseph form (I - K H) P (I - K H)^T + K R K^T, associated so that no N x N x N product
    // is formed: B = (I - K H) P = P - K (P H^T)^T, then B (I - K H)^T = B - (B H^T) K^T.
    // O(N^2 M) instead of O(N^3), same value for any gain.
    let b = cov - gain * ph_t.transpose();
    let bh_t = b * lin.jacobian.transpose();
    let joseph = b - bh_t * gain.transpose() + gain * lin.noise * gain.transpose();
    let covariance = (joseph + joseph.transpose()) * T::lit(0.5);
    let finite =
        correction.iter().all(|x| x.is_finite()) && covariance.iter().all(|x| x.is_finite());
    if !finite {
        return Err(Error::DivergentUpdate);
    }
    Ok(KalmanStep {
        nis,
        threshold,
        accepted: true,
        correction,
        covariance,
        weighted_residual,
        innovation_inverse: s_inv,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Vector2};

    #[test]
    fn scalar_update_matches_textbook() {
        let cov = Matrix2::new(4.0, 0.0, 0.0, 1.0);
        let lin = Linearization {
            residual: SVector::<f64, 1>::new(1.0),
            jacobian: SMatrix::<f64, 1, 2>::new(1.0, 0.0),
            noise: SMatrix::<f64, 1, 1>::new(4.0),
        };
        let step = kalman_step(&cov, &lin, Confidence::P99, &[]).unwrap();
        assert!(step.accepted);
        assert!((step.correction - Vector2::new(0.5, 0.0)).norm() < 1e-12);
        assert!((step.covariance[(0, 0)] - 2.0).abs() < 1e-12);
        assert!((step.nis - 1.0 / 8.0).abs() < 1e-12);
    }

    #[test]
    fn reassociated_joseph_form_equals_the_textbook_product() {
        // A correlated 4-state prior and a 2-dof measurement.
        let a = SMatrix::<f64, 4, 4>::from_fn(|r, c| ((r * 4 + c) as f64 * 0.37).sin());
        let cov = a * a.transpose() + SMatrix::<f64, 4, 4>::identity() * 0.1;
        let lin = Linearization {
            residual: SVector::<f64, 2>::new(0.3, -0.2),
            jacobian: SMatrix::<f64, 2, 4>::new(1.0, 0.5, 0.0, -0.2, 0.0, 0.3, 1.0, 0.7),
            noise: SMatrix::<f64, 2, 2>::new(0.5, 0.1, 0.1, 0.4),
        };
        let step = kalman_step(&cov, &lin, Confidence::P99999, &[]).unwrap();
        let s = lin.jacobian * cov * lin.jacobian.transpose() + lin.noise;
        let k = cov * lin.jacobian.transpose() * s.try_inverse().unwrap();
        let i_kh = SMatrix::<f64, 4, 4>::identity() - k * lin.jacobian;
        let textbook = i_kh * cov * i_kh.transpose() + k * lin.noise * k.transpose();
        assert!((step.covariance - textbook).amax() < 1e-14);
    }

    #[test]
    fn held_direction_keeps_its_prior_and_the_covariance_stays_joseph() {
        let a = SMatrix::<f64, 5, 5>::from_fn(|r, c| ((r * 5 + c) as f64 * 0.61).cos());
        let cov = a * a.transpose() + SMatrix::<f64, 5, 5>::identity() * 0.2;
        let lin = Linearization {
            residual: SVector::<f64, 2>::new(0.4, -0.3),
            jacobian: SMatrix::<f64, 2, 5>::new(
                0.2, 1.0, 0.3, -0.5, 0.1, //
                0.0, -0.4, 0.8, 0.6, 1.0,
            ),
            noise: SMatrix::<f64, 2, 2>::new(0.3, 0.05, 0.05, 0.2),
        };
        let axis = Vector3::new(1.0, 2.0, -2.0) / 3.0;
        let hold = Hold { block: 1, axis };
        let step = kalman_step(&cov, &lin, Confidence::P99999, &[hold]).unwrap();
        let mut u = SVector::<f64, 5>::zeros();
        u.fixed_rows_mut::<3>(1).copy_from(&axis);
        assert!(u.dot(&step.correction).abs() < 1e-14);
        let (before, after) = (
            (u.transpose() * cov * u)[0],
            (u.transpose() * step.covariance * u)[0],
        );
        assert!((before - after).abs() < 1e-12, "{before} -> {after}");
        // The Joseph form with the projected gain, written out.
        let s = lin.jacobian * cov * lin.jacobian.transpose() + lin.noise;
        let k = cov * lin.jacobian.transpose() * s.try_inverse().unwrap();
        let k = (SMatrix::<f64, 5, 5>::identity() - u * u.transpose()) * k;
        let i_kh = SMatrix::<f64, 5, 5>::identity() - k * lin.jacobian;
        let textbook = i_kh * cov * i_kh.transpose() + k * lin.noise * k.transpose();
        assert!((step.covariance - textbook).amax() < 1e-13);
        // The other directions still learn: the trace drops.
        assert!(step.covariance.trace() < cov.trace() - 0.1);
    }

    #[test]
    fn outlier_is_gated_and_covariance_kept() {
        let cov = Matrix2::identity();
        let lin = Linearization {
            residual: SVector::<f64, 1>::new(100.0),
            jacobian: SMatrix::<f64, 1, 2>::new(1.0, 0.0),
            noise: SMatrix::<f64, 1, 1>::new(1.0),
        };
        let step = kalman_step(&cov, &lin, Confidence::P99, &[]).unwrap();
        assert!(!step.accepted);
        assert_eq!(step.covariance, cov);
        assert_eq!(step.correction, Vector2::zeros());
    }

    #[test]
    fn nan_residual_is_an_error() {
        let lin = Linearization {
            residual: SVector::<f64, 1>::new(f64::NAN),
            jacobian: SMatrix::<f64, 1, 2>::new(1.0, 0.0),
            noise: SMatrix::<f64, 1, 1>::new(1.0),
        };
        assert_eq!(
            kalman_step(&Matrix2::identity(), &lin, Confidence::P99, &[]).unwrap_err(),
            Error::NonFinite
        );
    }
}
