//! Measurement updates: one module per measurement model (residual and Jacobian), and the
//! one generic Kalman step they all share (gain, chi-square gate, Joseph-form covariance
//! update, NIS record).

pub mod board_plane;
pub mod compress;
pub mod relative_pose;
pub mod reprojection;
mod sparse;
pub mod zero_velocity;

use crate::ids::SensorId;
use crate::scalar::Scalar;
use nalgebra::{SMatrix, Vector3};

/// Which measurement model produced an update.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpdateKind {
    /// Relative pose of a sensor between two stamps (eq. 3.19-3.21 / 4.11-4.13).
    RelativePose,
    /// Zero-velocity update at standstill.
    ZeroVelocity,
    /// Known target corners reprojected into a camera (eq. 4.2, 4.15; RepErrCal).
    Reprojection,
    /// A LiDAR's board points against the target plane (joint calibration; eq. 5.12 in
    /// its target-frame form, see `update::board_plane`).
    BoardPlane,
}

/// The per-update diagnostic record read by the health monitor, reports, the firmware link
/// and the tests.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateReport<T: Scalar> {
    /// Measurement model.
    pub kind: UpdateKind,
    /// The sensor; `None` for updates that belong to no sensor (zero velocity), which
    /// then enter no sensor's health window.
    pub sensor: Option<SensorId>,
    /// Measurement stamp, ns (sensor clock).
    pub stamp_ns: u64,
    /// Residual dimension.
    pub dof: usize,
    /// Normalised innovation squared `r^T S^-1 r`.
    pub nis: T,
    /// Gate threshold the NIS was compared with.
    pub threshold: T,
    /// False when the gate rejected the measurement or it was held out (state then
    /// untouched by it).
    pub accepted: bool,
    /// Not fused because a knock candidate of its sensor was pending (the health monitor's
    /// jump-anchored detector): tested, not gated out. Implies `!accepted`.
    pub held_out: bool,
    /// A health event this update triggered (e.g. a detected extrinsic step).
    pub event: Option<crate::health::HealthEvent<T>>,
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
    /// Removes the gain's component along the held direction, in place, on the gain
    /// stored transposed (`K^T`, `M x N`).
    pub(crate) fn project<const M: usize, const N: usize>(&self, gain_t: &mut SMatrix<T, M, N>) {
        if self.block + 3 > N {
            return;
        }
        let mut columns = gain_t.fixed_columns_mut::<3>(self.block);
        let along = &columns * self.axis;
        columns -= along * self.axis.transpose();
    }
}

pub use sparse::{Gain, Measurement, SparseJacobian};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::chi2::{self, Confidence};
    use crate::Error;
    use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

    /// A dense `M x N` Jacobian as a sparse one with every column stored.
    fn all_columns<const M: usize, const N: usize>(
        h: &SMatrix<f64, M, N>,
    ) -> SparseJacobian<f64, M, N> {
        SparseJacobian {
            columns: core::array::from_fn(|c| c),
            values: *h,
        }
    }

    /// One update through the core: the gain and the updated covariance.
    fn step<const M: usize, const N: usize, const L: usize>(
        cov: &SMatrix<f64, N, N>,
        meas: &Measurement<f64, M, L>,
        confidence: Confidence,
        holds: &[Hold<f64>],
    ) -> Result<(Gain<f64, M, N>, SMatrix<f64, N, N>), Error> {
        let gain = Gain::compute(cov, meas, chi2::quantile(M, confidence), holds)?;
        let mut out = *cov;
        gain.apply_to(&mut out);
        Ok((gain, out))
    }

    /// The textbook Joseph form with gain `k`.
    fn joseph<const M: usize, const N: usize>(
        cov: &SMatrix<f64, N, N>,
        h: &SMatrix<f64, M, N>,
        noise: &SMatrix<f64, M, M>,
        k: &SMatrix<f64, N, M>,
    ) -> SMatrix<f64, N, N> {
        let i_kh = SMatrix::<f64, N, N>::identity() - k * h;
        i_kh * cov * i_kh.transpose() + k * noise * k.transpose()
    }

    #[test]
    fn scalar_update_matches_textbook() {
        let cov = Matrix2::new(4.0, 0.0, 0.0, 1.0);
        let meas = Measurement {
            residual: SVector::<f64, 1>::new(1.0),
            jacobian: all_columns(&SMatrix::<f64, 1, 2>::new(1.0, 0.0)),
            noise: SMatrix::<f64, 1, 1>::new(4.0),
        };
        let (gain, after) = step(&cov, &meas, Confidence::P99, &[]).unwrap();
        assert!(gain.accepted);
        assert!((gain.correction - Vector2::new(0.5, 0.0)).norm() < 1e-12);
        assert!((after[(0, 0)] - 2.0).abs() < 1e-12);
        assert!((gain.nis - 1.0 / 8.0).abs() < 1e-12);
    }

    #[test]
    fn sparse_update_equals_the_textbook_joseph_form_of_the_dense_jacobian() {
        // A correlated 6-state prior and a 2-dof measurement touching states 1, 3 and 4,
        // stored out of order and with state 3 split over two columns.
        let a = SMatrix::<f64, 6, 6>::from_fn(|r, c| ((r * 6 + c) as f64 * 0.37).sin());
        let cov = a * a.transpose() + SMatrix::<f64, 6, 6>::identity() * 0.1;
        let jacobian = SparseJacobian {
            columns: [4, 1, 3, 3],
            values: SMatrix::<f64, 2, 4>::new(1.0, 0.5, -0.2, 0.1, 0.0, 0.3, 0.7, 0.2),
        };
        let meas = Measurement {
            residual: SVector::<f64, 2>::new(0.3, -0.2),
            jacobian,
            noise: SMatrix::<f64, 2, 2>::new(0.5, 0.1, 0.1, 0.4),
        };
        let (gain, after) = step(&cov, &meas, Confidence::P99999, &[]).unwrap();
        let h: SMatrix<f64, 2, 6> = jacobian.to_dense();
        assert!((h[(0, 3)] - (-0.2 + 0.1)).abs() < 1e-15);
        let s = h * cov * h.transpose() + meas.noise;
        let k = cov * h.transpose() * s.try_inverse().unwrap();
        assert!((after - joseph(&cov, &h, &meas.noise, &k)).amax() < 1e-14);
        assert!((gain.correction - k * meas.residual).amax() < 1e-14);
        assert!(
            (gain.nis - (meas.residual.transpose() * s.try_inverse().unwrap() * meas.residual)[0])
                .abs()
                < 1e-13
        );
        assert_eq!(after, after.transpose());
    }

    #[test]
    fn held_direction_keeps_its_prior_and_the_covariance_stays_joseph() {
        let a = SMatrix::<f64, 5, 5>::from_fn(|r, c| ((r * 5 + c) as f64 * 0.61).cos());
        let cov = a * a.transpose() + SMatrix::<f64, 5, 5>::identity() * 0.2;
        let h = SMatrix::<f64, 2, 5>::new(
            0.2, 1.0, 0.3, -0.5, 0.1, //
            0.0, -0.4, 0.8, 0.6, 1.0,
        );
        let meas = Measurement {
            residual: SVector::<f64, 2>::new(0.4, -0.3),
            jacobian: all_columns(&h),
            noise: SMatrix::<f64, 2, 2>::new(0.3, 0.05, 0.05, 0.2),
        };
        let axis = Vector3::new(1.0, 2.0, -2.0) / 3.0;
        let hold = Hold { block: 1, axis };
        let (gain, after) = step(&cov, &meas, Confidence::P99999, &[hold]).unwrap();
        let mut u = SVector::<f64, 5>::zeros();
        u.fixed_rows_mut::<3>(1).copy_from(&axis);
        assert!(u.dot(&gain.correction).abs() < 1e-14);
        let (before, held) = ((u.transpose() * cov * u)[0], (u.transpose() * after * u)[0]);
        assert!((before - held).abs() < 1e-12, "{before} -> {held}");
        // The Joseph form with the projected gain, written out.
        let s = h * cov * h.transpose() + meas.noise;
        let k = cov * h.transpose() * s.try_inverse().unwrap();
        let k = (SMatrix::<f64, 5, 5>::identity() - u * u.transpose()) * k;
        assert!((after - joseph(&cov, &h, &meas.noise, &k)).amax() < 1e-13);
        // The other directions still learn: the trace drops.
        assert!(after.trace() < cov.trace() - 0.1);
    }

    #[test]
    fn outlier_is_gated_and_covariance_kept() {
        let cov = Matrix2::identity();
        let meas = Measurement {
            residual: SVector::<f64, 1>::new(100.0),
            jacobian: all_columns(&SMatrix::<f64, 1, 2>::new(1.0, 0.0)),
            noise: SMatrix::<f64, 1, 1>::new(1.0),
        };
        let (gain, after) = step(&cov, &meas, Confidence::P99, &[]).unwrap();
        assert!(!gain.accepted);
        assert_eq!(after, cov);
        assert_eq!(gain.correction, Vector2::zeros());
    }

    #[test]
    fn bad_measurements_are_errors() {
        let cov = Matrix2::identity();
        let nan = Measurement {
            residual: SVector::<f64, 1>::new(f64::NAN),
            jacobian: all_columns(&SMatrix::<f64, 1, 2>::new(1.0, 0.0)),
            noise: SMatrix::<f64, 1, 1>::new(1.0),
        };
        assert_eq!(
            step(&cov, &nan, Confidence::P99, &[]).unwrap_err(),
            Error::NonFinite
        );
        let outside = Measurement {
            residual: SVector::<f64, 1>::new(1.0),
            jacobian: SparseJacobian {
                columns: [2],
                values: SMatrix::<f64, 1, 1>::new(1.0),
            },
            noise: SMatrix::<f64, 1, 1>::new(1.0),
        };
        assert_eq!(
            step(&cov, &outside, Confidence::P99, &[]).unwrap_err(),
            Error::InvalidConfig
        );
        let singular = Measurement {
            residual: SVector::<f64, 1>::new(1.0),
            jacobian: all_columns(&SMatrix::<f64, 1, 2>::new(0.0, 0.0)),
            noise: SMatrix::<f64, 1, 1>::new(-1.0),
        };
        assert_eq!(
            step(&cov, &singular, Confidence::P99, &[]).unwrap_err(),
            Error::SingularInnovation
        );
        // A covariance at the edge of the range: the update could overflow it.
        let edge = Measurement {
            residual: SVector::<f64, 1>::new(1.0),
            jacobian: all_columns(&SMatrix::<f64, 1, 2>::new(1.0, 0.0)),
            noise: SMatrix::<f64, 1, 1>::new(1.0),
        };
        assert_eq!(
            step(&(cov * 1e308), &edge, Confidence::P99, &[]).unwrap_err(),
            Error::DivergentUpdate
        );
    }
}
