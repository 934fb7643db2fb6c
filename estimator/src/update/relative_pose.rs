//! Relative-pose (motion-based) measurement, dissertation eq. 3.19-3.21 / 4.11-4.13 and
//! Appendix A.2, rederived for Hamilton quaternions and right perturbations.
//!
//! A pose sensor S (LiDAR odometry, visual odometry, PnP) reports its motion between two
//! stamps, `T_Si_Sj`. With the IMU poses `T_G_Ii`, `T_G_Ij` (stochastic clones at the
//! stamps shifted by the time offset) and the extrinsic `T_I_S`:
//!
//! `T_Si_Sj = T_I_S^-1 T_G_Ii^-1 T_G_Ij T_I_S`
//!
//! Residual: `r = [Log(R_hat^T R_z); p_z - p_hat]` (rotation in the measurement's tangent
//! space). The time offset enters through the clones' correlation with it (see
//! `Ekf::clone_imu_pose`), as in OpenVINS.

use crate::lie::{log, skew, Pose};
use crate::scalar::Scalar;
use nalgebra::{Matrix3, Matrix6, SMatrix, Vector6};

/// A measured relative pose of sensor S between two of its stamps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelativePose<T: Scalar> {
    /// Sensor stamp of the start pose, ns.
    pub stamp_from_ns: u64,
    /// Sensor stamp of the end pose, ns.
    pub stamp_to_ns: u64,
    /// `T_Sfrom_Sto`: the motion of S between the stamps.
    pub delta: Pose<T>,
    /// Covariance of the increment, ordered `[rotation (rad); translation (m)]`, rotation as
    /// a right perturbation of `R_Sfrom_Sto`.
    pub covariance: Matrix6<T>,
}

impl<T: Scalar> RelativePose<T> {
    /// A measurement with isotropic rotation and translation sigmas.
    pub fn with_sigmas(
        stamp_from_ns: u64,
        stamp_to_ns: u64,
        delta: Pose<T>,
        rotation_sigma: T,
        translation_sigma: T,
    ) -> Self {
        let mut covariance = Matrix6::zeros();
        for i in 0..3 {
            covariance[(i, i)] = rotation_sigma * rotation_sigma;
            covariance[(i + 3, i + 3)] = translation_sigma * translation_sigma;
        }
        Self {
            stamp_from_ns,
            stamp_to_ns,
            delta,
            covariance,
        }
    }

    /// True when the pose and covariance are finite and the covariance diagonal positive.
    pub fn is_valid(&self) -> bool {
        self.delta.is_finite()
            && self.covariance.iter().all(|x| x.is_finite())
            && (0..6).all(|i| self.covariance[(i, i)] > T::zero())
            && self.stamp_to_ns > self.stamp_from_ns
    }
}

/// Residual and Jacobian blocks of one relative-pose measurement.
#[derive(Clone, Debug)]
pub struct RelativePoseJacobians<T: Scalar> {
    /// `[rotation; translation]` residual.
    pub residual: Vector6<T>,
    /// w.r.t. `[dtheta_i, dp_i]` of the start clone.
    pub clone_from: SMatrix<T, 6, 6>,
    /// w.r.t. `[dtheta_j, dp_j]` of the end clone.
    pub clone_to: SMatrix<T, 6, 6>,
    /// w.r.t. the extrinsic `[dtheta_I_S, dp_I_S]`.
    pub extrinsic: SMatrix<T, 6, 6>,
    /// w.r.t. a rotation of the mounting at the end stamp only, `R_I_S Exp(dtheta)` there
    /// and `R_I_S` at the start: the signature of a knock inside the increment (the health
    /// monitor's jump test). `[I; 0]`: the rotation residual is that rotation.
    pub extrinsic_end_rotation: SMatrix<T, 6, 3>,
}

/// The predicted motion `T_Si_Sj` of the sensor.
pub fn predict<T: Scalar>(t_g_ii: &Pose<T>, t_g_ij: &Pose<T>, t_i_s: &Pose<T>) -> Pose<T> {
    t_i_s
        .inverse()
        .compose(&t_g_ii.inverse())
        .compose(t_g_ij)
        .compose(t_i_s)
}

/// Residual and Jacobians at the current estimate.
pub fn linearize<T: Scalar>(
    t_g_ii: &Pose<T>,
    t_g_ij: &Pose<T>,
    t_i_s: &Pose<T>,
    measured: &Pose<T>,
) -> RelativePoseJacobians<T> {
    let predicted = predict(t_g_ii, t_g_ij, t_i_s);
    let mut residual = Vector6::zeros();
    residual
        .fixed_rows_mut::<3>(0)
        .copy_from(&log(&(predicted.rotation.inverse() * measured.rotation)));
    residual
        .fixed_rows_mut::<3>(3)
        .copy_from(&(measured.translation - predicted.translation));

    let rot = |q: &nalgebra::UnitQuaternion<T>| q.to_rotation_matrix().into_inner();
    let r_i = rot(&t_g_ii.rotation);
    let r_j = rot(&t_g_ij.rotation);
    let r_c = rot(&t_i_s.rotation);
    let p_c = t_i_s.translation;
    let r_z = rot(&predicted.rotation);
    let r_ct = r_c.transpose();
    let r_it = r_i.transpose();
    let eye = Matrix3::identity();
    // w = R_i^T (p_j - p_i) + R_i^T R_j p_c: the translation before the extrinsic terms.
    let w = r_it * (t_g_ij.translation - t_g_ii.translation) + r_it * r_j * p_c;

    let mut clone_from = SMatrix::<T, 6, 6>::zeros();
    clone_from
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-(r_ct * r_j.transpose() * r_i)));
    clone_from
        .fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(r_ct * skew(&w)));
    clone_from
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(-(r_ct * r_it)));

    let mut clone_to = SMatrix::<T, 6, 6>::zeros();
    clone_to.fixed_view_mut::<3, 3>(0, 0).copy_from(&r_ct);
    clone_to
        .fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&(-(r_ct * r_it * r_j * skew(&p_c))));
    clone_to
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(r_ct * r_it));

    let mut extrinsic = SMatrix::<T, 6, 6>::zeros();
    extrinsic
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(eye - r_z.transpose()));
    extrinsic
        .fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&skew(&predicted.translation));
    extrinsic
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(r_ct * (r_it * r_j - eye)));

    let mut extrinsic_end_rotation = SMatrix::<T, 6, 3>::zeros();
    extrinsic_end_rotation
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&eye);
    RelativePoseJacobians {
        residual,
        clone_from,
        clone_to,
        extrinsic,
        extrinsic_end_rotation,
    }
}

/// The Student-t weight of a relative pose whose NIS at its stated noise is `nis` (of `dof`
/// degrees of freedom), for a noise with `nu` degrees of freedom: the conditional mean of the
/// noise's precision scale `lambda` given the residual, `E[lambda | r] = (nu + m) / (nu +
/// d^2)` (the E-step of the Student-t as a scale mixture of Gaussians, `lambda ~ Gamma(nu /
/// 2, nu / 2)`, evaluated at the prior innovation covariance), capped at 1: an increment is
/// never trusted beyond its stated noise, only down-weighted when it is outlying. 1 for an
/// infinite or invalid `nu`, or a NIS that is not finite and positive.
pub fn student_t_weight<T: Scalar>(nis: T, dof: usize, nu: T) -> T {
    let m = T::lit(dof as f64);
    let valid = nu.is_finite() && nu > T::zero() && nis.is_finite() && nis > m;
    if !valid {
        return T::one();
    }
    (nu + m) / (nu + nis)
}

/// `h(x ⊞ d)` expressed in the tangent space at `h(x)`: used by the Jacobian tests.
#[cfg(test)]
fn perturbed_prediction(
    t_g_ii: &Pose<f64>,
    t_g_ij: &Pose<f64>,
    t_i_s: &Pose<f64>,
    d: &nalgebra::SVector<f64, 18>,
) -> Vector6<f64> {
    use nalgebra::Vector3;
    let v = |k: usize| Vector3::new(d[k], d[k + 1], d[k + 2]);
    let pert = |p: &Pose<f64>, k: usize| p.boxplus(&v(k), &v(k + 3));
    let nominal = predict(t_g_ii, t_g_ij, t_i_s);
    let moved = predict(&pert(t_g_ii, 0), &pert(t_g_ij, 6), &pert(t_i_s, 12));
    tangent_at(&nominal, &moved)
}

/// `moved` in the tangent space at `nominal`, in the residual's convention (rotation as a
/// right perturbation, translation as a difference).
#[cfg(test)]
fn tangent_at(nominal: &Pose<f64>, moved: &Pose<f64>) -> Vector6<f64> {
    let mut out = Vector6::zeros();
    out.fixed_rows_mut::<3>(0)
        .copy_from(&log(&(nominal.rotation.inverse() * moved.rotation)));
    out.fixed_rows_mut::<3>(3)
        .copy_from(&(moved.translation - nominal.translation));
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_mat_close, central_diff};
    use nalgebra::{SMatrix, UnitQuaternion, Vector3};

    fn poses() -> (Pose<f64>, Pose<f64>, Pose<f64>) {
        let ii = Pose::new(
            UnitQuaternion::from_euler_angles(0.3, -0.2, 2.0),
            Vector3::new(1.0, 2.0, 0.5),
        );
        let ij = Pose::new(
            UnitQuaternion::from_euler_angles(0.5, 0.1, 2.3),
            Vector3::new(1.1, 2.05, 0.45),
        );
        let ext = Pose::new(
            UnitQuaternion::from_euler_angles(3.1, 0.05, -1.0),
            Vector3::new(0.2, -0.1, 0.3),
        );
        (ii, ij, ext)
    }

    #[test]
    fn jacobians_match_central_differences() {
        let (ii, ij, ext) = poses();
        let lin = linearize(&ii, &ij, &ext, &predict(&ii, &ij, &ext));
        let numeric = central_diff::<6, 18>(|d| perturbed_prediction(&ii, &ij, &ext, &d));
        let mut analytic = SMatrix::<f64, 6, 18>::zeros();
        analytic
            .fixed_view_mut::<6, 6>(0, 0)
            .copy_from(&lin.clone_from);
        analytic
            .fixed_view_mut::<6, 6>(0, 6)
            .copy_from(&lin.clone_to);
        analytic
            .fixed_view_mut::<6, 6>(0, 12)
            .copy_from(&lin.extrinsic);
        assert_mat_close(&analytic, &numeric, 1e-7);
    }

    #[test]
    fn end_rotation_jacobian_matches_central_differences() {
        // The mounting rotated by d at the end stamp only: T_I_S^-1 T_Ii^-1 T_Ij T_I_S'.
        let (ii, ij, ext) = poses();
        let lin = linearize(&ii, &ij, &ext, &predict(&ii, &ij, &ext));
        let nominal = predict(&ii, &ij, &ext);
        let numeric = central_diff::<6, 3>(|d| {
            let moved = ext
                .inverse()
                .compose(&ii.inverse())
                .compose(&ij)
                .compose(&ext.boxplus(&d, &Vector3::zeros()));
            tangent_at(&nominal, &moved)
        });
        assert_mat_close(&lin.extrinsic_end_rotation, &numeric, 1e-7);
    }

    #[test]
    fn student_t_weight_down_weights_only_outlying_increments() {
        // (4 + 6) / (4 + 46) = 0.2 for a NIS of 46; 1 at or below the dof.
        assert!((student_t_weight(46.0f64, 6, 4.0) - 0.2).abs() < 1e-15);
        for nis in [0.0f64, 3.0, 6.0] {
            assert!((student_t_weight(nis, 6, 4.0) - 1.0).abs() < 1e-15);
        }
        // Gaussian (infinite nu) and bad inputs: no weighting.
        for (nis, nu) in [
            (50.0, f64::INFINITY),
            (50.0, 0.0),
            (f64::NAN, 4.0),
            (50.0, -1.0),
        ] {
            assert!(
                (student_t_weight(nis, 6, nu) - 1.0).abs() < 1e-15,
                "{nis} {nu}"
            );
        }
        // Monotone: a larger NIS never gets more weight; f32 alike.
        let w: [f32; 3] = [7.0, 20.0, 200.0].map(|d| student_t_weight(d, 6, 4.0f32));
        assert!(w[0] > w[1] && w[1] > w[2] && w[2] > 0.0, "{w:?}");
    }

    #[test]
    fn student_t_weight_is_the_posterior_mean_precision() {
        // With lambda ~ Gamma(nu / 2, rate nu / 2) and r | lambda ~ N(0, S / lambda) in m
        // dof, the posterior is Gamma((nu + m) / 2, rate (nu + d^2) / 2): its mean, by
        // numerical integration of lambda p(lambda) p(r | lambda) over lambda.
        let (nu, m) = (4.0f64, 6usize);
        for d2 in [8.0, 30.0, 120.0] {
            let density =
                |l: f64| l.powf((nu + m as f64) / 2.0 - 1.0) * (-(nu + d2) * l / 2.0).exp();
            let (mut num, mut den) = (0.0, 0.0);
            let h = 1e-4;
            for k in 1..200_000 {
                let l = k as f64 * h;
                num += l * density(l) * h;
                den += density(l) * h;
            }
            let w = student_t_weight(d2, m, nu);
            assert!(
                (num / den - w).abs() < 1e-4 * w,
                "{d2}: {} vs {w}",
                num / den
            );
        }
    }

    #[test]
    fn exact_measurement_has_zero_residual() {
        let (ii, ij, ext) = poses();
        let lin = linearize(&ii, &ij, &ext, &predict(&ii, &ij, &ext));
        assert!(lin.residual.norm() < 1e-12);
    }

    #[test]
    fn prediction_satisfies_hand_eye_relation() {
        // T_Ii_Ij X = X T_Si_Sj (eq. 3.1)
        let (ii, ij, ext) = poses();
        let z = predict(&ii, &ij, &ext);
        let lhs = ii.inverse().compose(&ij).compose(&ext);
        let rhs = ext.compose(&z);
        assert!(lhs.rotation.angle_to(&rhs.rotation) < 1e-12);
        assert!((lhs.translation - rhs.translation).norm() < 1e-12);
    }
}
