//! Kalibr's camera chain `T_cn_cnm1` (`p_camN = T_cn_cnm1 p_cam(N-1)`) from two cameras'
//! extrinsics against the IMU, with its covariance through the Jacobians of the composition
//! and the filter's cross-covariance of the two extrinsics.

use nalgebra::{Isometry3, Matrix3, Matrix6};

/// `T_cn_cnm1` of camera `n >= 1` and its covariance `[dtheta (right, rad); dp (m)]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraChainLink {
    /// `T_cn_cnm1`: a point of camera `n - 1` in camera `n`.
    pub t_cn_cnm1: Isometry3<f64>,
    /// Its covariance, rotation (right perturbation) then translation.
    pub covariance: Matrix6<f64>,
}

/// `T_b_a = T_imu_b^-1 T_imu_a` from `(T_imu_b, covariance)`, `(T_imu_a, covariance)` and
/// their cross-covariance `ba = E[e_b e_a^T]` (zero for two independent runs), covariances
/// `[dtheta (right); dp]` as the filter holds its extrinsics. For the chain, `b` is camera
/// `n` and `a` camera `n - 1`.
pub fn compose_chain(
    (t_i_b, bb): (&Isometry3<f64>, &Matrix6<f64>),
    (t_i_a, aa): (&Isometry3<f64>, &Matrix6<f64>),
    ba: &Matrix6<f64>,
) -> CameraChainLink {
    let t_b_a = t_i_b.inverse() * t_i_a;
    let (j_b, j_a) = chain_jacobians(t_i_b, &t_b_a);
    let cov = j_b * bb * j_b.transpose()
        + j_b * ba * j_a.transpose()
        + j_a * ba.transpose() * j_b.transpose()
        + j_a * aa * j_a.transpose();
    CameraChainLink {
        t_cn_cnm1: t_b_a,
        covariance: (cov + cov.transpose()) * 0.5,
    }
}

/// Derivatives of `T_b_a`'s error w.r.t. the errors of `T_imu_b` and `T_imu_a` (right
/// rotation perturbations, additive translations).
pub(crate) fn chain_jacobians(
    t_i_b: &Isometry3<f64>,
    t_b_a: &Isometry3<f64>,
) -> (Matrix6<f64>, Matrix6<f64>) {
    let r_ib = t_i_b.rotation.to_rotation_matrix().into_inner();
    let r_ba = t_b_a.rotation.to_rotation_matrix().into_inner();
    let mut j_b = Matrix6::zeros();
    j_b.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-r_ba.transpose()));
    j_b.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&msreg_estimator::lie::skew(&t_b_a.translation.vector));
    j_b.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(-r_ib.transpose()));
    let mut j_a = Matrix6::zeros();
    j_a.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j_a.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&r_ib.transpose());
    (j_b, j_a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector6};

    /// `t` moved by the error `e = [dtheta (right); dp]`.
    fn perturbed(t: &Isometry3<f64>, e: &Vector6<f64>) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::from(t.translation.vector + e.fixed_rows::<3>(3)),
            t.rotation * UnitQuaternion::from_scaled_axis(e.fixed_rows::<3>(0).into_owned()),
        )
    }

    /// The error of `t` against `reference`, as [`perturbed`] applies it.
    fn error(t: &Isometry3<f64>, reference: &Isometry3<f64>) -> Vector6<f64> {
        let r = (reference.rotation.inverse() * t.rotation).scaled_axis();
        let p = t.translation.vector - reference.translation.vector;
        Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z)
    }

    #[test]
    fn chain_jacobians_match_central_differences() {
        // Given a stereo-like pair: camera 1 11 cm beside camera 0, both rotated into the IMU
        let t_i_a = Isometry3::from_parts(
            Translation3::new(0.05, -0.02, 0.01),
            UnitQuaternion::from_euler_angles(-1.5, 0.03, -1.6),
        );
        let t_i_b = t_i_a
            * Isometry3::from_parts(
                Translation3::new(0.11, 0.002, -0.003),
                UnitQuaternion::from_euler_angles(0.01, -0.02, 0.005),
            );
        let t_b_a = t_i_b.inverse() * t_i_a;
        let (j_b, j_a) = chain_jacobians(&t_i_b, &t_b_a);
        // When each extrinsic's error direction is perturbed
        let h = 1e-6;
        for i in 0..6 {
            let mut e = Vector6::zeros();
            e[i] = h;
            let d_b = (error(&(perturbed(&t_i_b, &e).inverse() * t_i_a), &t_b_a)
                - error(&(perturbed(&t_i_b, &(-e)).inverse() * t_i_a), &t_b_a))
                / (2.0 * h);
            let d_a = (error(&(t_i_b.inverse() * perturbed(&t_i_a, &e)), &t_b_a)
                - error(&(t_i_b.inverse() * perturbed(&t_i_a, &(-e))), &t_b_a))
                / (2.0 * h);
            // Then the analytic columns agree (measured worst difference ~1e-10)
            assert!(
                (j_b.column(i) - d_b).amax() < 1e-8,
                "b {i}: {d_b} vs {}",
                j_b.column(i)
            );
            assert!(
                (j_a.column(i) - d_a).amax() < 1e-8,
                "a {i}: {d_a} vs {}",
                j_a.column(i)
            );
        }
    }

    #[test]
    fn fully_correlated_extrinsics_give_an_exact_chain() {
        // Given two extrinsics whose errors are one common IMU-side error (a rotation of the
        // IMU frame moves both, leaving the chain untouched): e_b = J e, e_a = K e
        let t_i_a = Isometry3::from_parts(
            Translation3::new(0.05, -0.02, 0.01),
            UnitQuaternion::from_euler_angles(0.3, 0.1, -0.4),
        );
        let t_i_b = t_i_a * Isometry3::translation(0.11, 0.0, 0.0);
        let t_b_a = t_i_b.inverse() * t_i_a;
        // A common translation of both cameras in the IMU frame: dp_a = dp_b = d.
        let mut common = Matrix6::zeros();
        common
            .fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&(Matrix3::identity() * 1e-4));
        // When the chain is composed with and without the cross terms
        let with = compose_chain((&t_i_b, &common), (&t_i_a, &common), &common);
        let without = compose_chain((&t_i_b, &common), (&t_i_a, &common), &Matrix6::zeros());
        // Then the common error cancels only with them
        assert!(with.covariance.amax() < 1e-18, "{}", with.covariance);
        assert!((without.covariance[(3, 3)] - 2e-4).abs() < 1e-12);
        assert!((with.t_cn_cnm1.translation.vector - t_b_a.translation.vector).norm() < 1e-15);
    }
}
