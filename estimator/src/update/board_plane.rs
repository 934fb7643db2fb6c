//! The camera-LiDAR board-plane residual of the joint calibration (issue 13; the
//! dissertation's eq. 5.12 / A.37 ties the same board seen by both sensors).
//!
//! The LiDAR sees the board as points `x_k` (deskewed to the scan stamp, in L). The board is
//! the plane `z = 0` of the target frame T, whose pose `T_G_T` is a state that the camera's
//! corner reprojections also observe. A board point satisfies `n . x + d = 0` with
//!
//! `n = R_G_L^T R_G_T e3` (the board normal in L), `d = e3 . (T_G_T^-1 p_G_L)`
//! (the LiDAR origin's height above the board), `T_G_L = T_G_I T_I_L`.
//!
//! Every board point's point-to-plane residual counts, yet the measurement stays 3 rows:
//! with the centroid `c`, the scatter `M = sum (x_k - c)(x_k - c)^T` and its in-plane
//! eigenpairs `(lambda_1, u_1)`, `(lambda_2, u_2)`,
//!
//! `sum_k (n . x_k + d)^2 = K (n . c + d)^2 + lambda_1 (u_1 . n)^2 + lambda_2 (u_2 . n)^2
//!  + lambda_3 (u_3 . n)^2`,
//!
//! and the last term only holds the points' scatter about the plane (the noise itself).
//! So `h = [sqrt(K) (n . c + d), sqrt(lambda_1) u_1 . n, sqrt(lambda_2) u_2 . n]`,
//! measured as zero with noise `sigma^2 I_3` (`sigma` the points' noise along the normal),
//! carries exactly the information of the K point-to-plane residuals.
//!
//! Why not eq. 5.12 as written (the camera's board plane from the image at the nearest
//! instant j against the LiDAR's at i): with the corners already fused, a camera plane from
//! the same image counts them twice and its noise is correlated with theirs; the LiDAR
//! plane at i against the camera plane at j also needs both clones and an interpolation
//! between i and j. Against the target-frame state, the plane is one update at the scan's
//! own IMU time, the camera enters through the corners that fix `T_G_T`, and the same
//! `T_I_C`, `T_I_L` coupling results.

use crate::lie::{skew, Pose};
use crate::scalar::Scalar;
use crate::Error;
use nalgebra::{Matrix3, RowVector3, Vector3};

/// The board as the LiDAR saw it in one scan: the moments of its points.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardPlane<T: Scalar> {
    /// Scan stamp, ns (LiDAR clock); the points are deskewed to it.
    pub stamp_ns: u64,
    /// Number of board points `K`.
    pub count: u32,
    /// Their centroid `c` in L, m.
    pub centroid: Vector3<T>,
    /// The two in-plane principal directions `u_1`, `u_2` of their scatter (unit, in L).
    pub in_plane: [Vector3<T>; 2],
    /// The matching scatter eigenvalues `lambda_1`, `lambda_2`, m^2 (sums over the points).
    pub spread: [T; 2],
    /// 1-sigma of a point along the board normal, m.
    pub sigma: T,
}

impl<T: Scalar> BoardPlane<T> {
    /// Checks that the moments describe a plane patch: at least 3 points, finite values,
    /// unit in-plane directions, positive spreads and sigma.
    pub fn validate(&self) -> Result<(), Error> {
        let finite = self.centroid.iter().all(|x| x.is_finite())
            && self
                .in_plane
                .iter()
                .all(|u| u.iter().all(|x| x.is_finite()))
            && self.spread.iter().all(|x| x.is_finite())
            && self.sigma.is_finite();
        if !finite {
            return Err(Error::NonFinite);
        }
        if self.count < 3 {
            return Err(Error::EmptyMeasurement);
        }
        let unit = |u: &Vector3<T>| (u.norm() - T::one()).abs() < T::lit(1e-3);
        let orthogonal = self.in_plane[0].dot(&self.in_plane[1]).abs() < T::lit(1e-3);
        let positive = self.spread.iter().all(|&x| x > T::zero()) && self.sigma > T::zero();
        if !(self.in_plane.iter().all(unit) && orthogonal && positive) {
            return Err(Error::InvalidConfig);
        }
        Ok(())
    }

    /// The moments of `points` (board points in L, deskewed to `stamp_ns`) with the given
    /// normal noise `sigma`. `EmptyMeasurement` under 3 points; `InvalidConfig` when they do
    /// not span a plane (a line or a blob: the in-plane spreads must be positive and the
    /// normal's scatter the smallest of the three by a clear margin).
    pub fn from_points(stamp_ns: u64, points: &[Vector3<T>], sigma: T) -> Result<Self, Error> {
        if points.len() < 3 {
            return Err(Error::EmptyMeasurement);
        }
        if points.iter().any(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(Error::NonFinite);
        }
        let (centroid, scatter) = centroid_and_scatter(points);
        let eig = scatter.symmetric_eigen();
        let mut order = [0usize, 1, 2];
        order.sort_unstable_by(|&a, &b| {
            eig.eigenvalues[b]
                .partial_cmp(&eig.eigenvalues[a])
                .unwrap_or(core::cmp::Ordering::Equal)
        });
        let value = |i: usize| eig.eigenvalues[order[i]];
        let vector = |i: usize| eig.eigenvectors.column(order[i]).into_owned();
        if !(value(1) > T::lit(4.0) * value(2).max(T::zero()) && value(1) > T::zero()) {
            return Err(Error::InvalidConfig);
        }
        let plane = Self {
            stamp_ns,
            count: u32::try_from(points.len()).map_err(|_| Error::OutOfRange)?,
            centroid,
            in_plane: [vector(0), vector(1)],
            spread: [value(0), value(1)],
            sigma,
        };
        plane.validate()?;
        Ok(plane)
    }

    /// The unit normal of the fitted plane, `u_1 x u_2`.
    pub fn normal(&self) -> Vector3<T> {
        self.in_plane[0].cross(&self.in_plane[1])
    }

    /// The RMS distance of `points` from this plane, over `K - 3` degrees of freedom (for the
    /// points it was fitted to: an estimate of their noise along the normal); `None` under
    /// 4 points.
    pub fn distance_rms(&self, points: &[Vector3<T>]) -> Option<T> {
        if points.len() < 4 {
            return None;
        }
        let n = self.normal();
        let sum = points.iter().fold(T::zero(), |a, p| {
            let d = (p - self.centroid).dot(&n);
            a + d * d
        });
        Some((sum / T::lit(points.len() as f64 - 3.0)).sqrt())
    }

    /// The whitening weights `[sqrt(K), sqrt(lambda_1), sqrt(lambda_2)]` of the three rows.
    fn weights(&self) -> [T; 3] {
        [
            T::lit(f64::from(self.count)).sqrt(),
            self.spread[0].sqrt(),
            self.spread[1].sqrt(),
        ]
    }
}

/// The centroid of `points` and their scatter `sum (x - c)(x - c)^T` about it.
fn centroid_and_scatter<T: Scalar>(points: &[Vector3<T>]) -> (Vector3<T>, Matrix3<T>) {
    let k = T::lit(points.len() as f64);
    let centroid = points.iter().fold(Vector3::zeros(), |a, p| a + p) / k;
    let scatter = points.iter().fold(Matrix3::zeros(), |a, p| {
        let d = p - centroid;
        a + d * d.transpose()
    });
    (centroid, scatter)
}

/// Residual and Jacobian blocks (3 rows) of one board plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoardPlaneJacobians<T: Scalar> {
    /// `0 - h(x)`, m (whitened by the point count and spreads; noise `sigma^2 I_3`).
    pub residual: Vector3<T>,
    /// w.r.t. the IMU orientation `dtheta_I`.
    pub imu_rotation: Matrix3<T>,
    /// w.r.t. the IMU position `dp_I`.
    pub imu_position: Matrix3<T>,
    /// w.r.t. the extrinsic rotation `dtheta_I_L`.
    pub extrinsic_rotation: Matrix3<T>,
    /// w.r.t. the extrinsic translation `dp_I_L`.
    pub extrinsic_translation: Matrix3<T>,
    /// w.r.t. the target orientation `dtheta_G_T`.
    pub target_rotation: Matrix3<T>,
    /// w.r.t. the target position `dp_G_T`.
    pub target_position: Matrix3<T>,
}

/// The board normal `n` in L and the LiDAR's height `d` above the board.
pub fn plane_in_lidar<T: Scalar>(
    t_g_i: &Pose<T>,
    t_i_l: &Pose<T>,
    t_g_t: &Pose<T>,
) -> (Vector3<T>, T) {
    let t_g_l = t_g_i.compose(t_i_l);
    let m = t_g_t.rotation * Vector3::z();
    let n = t_g_l.rotation.inverse() * m;
    (n, m.dot(&(t_g_l.translation - t_g_t.translation)))
}

/// The predicted measurement `h(x)` (zero at the truth, up to noise).
pub fn predict<T: Scalar>(
    t_g_i: &Pose<T>,
    t_i_l: &Pose<T>,
    t_g_t: &Pose<T>,
    plane: &BoardPlane<T>,
) -> Vector3<T> {
    let (n, d) = plane_in_lidar(t_g_i, t_i_l, t_g_t);
    let [wk, w1, w2] = plane.weights();
    Vector3::new(
        wk * (n.dot(&plane.centroid) + d),
        w1 * plane.in_plane[0].dot(&n),
        w2 * plane.in_plane[1].dot(&n),
    )
}

/// Residual and Jacobians at the current estimate (right perturbations of every rotation,
/// additive translations; see the module documentation for `n` and `d`).
pub fn linearize<T: Scalar>(
    t_g_i: &Pose<T>,
    t_i_l: &Pose<T>,
    t_g_t: &Pose<T>,
    plane: &BoardPlane<T>,
) -> BoardPlaneJacobians<T> {
    let rot = |q: &nalgebra::UnitQuaternion<T>| q.to_rotation_matrix().into_inner();
    let (r_i, r_e, r_t) = (
        rot(&t_g_i.rotation),
        rot(&t_i_l.rotation),
        rot(&t_g_t.rotation),
    );
    let (n, _) = plane_in_lidar(t_g_i, t_i_l, t_g_t);
    let m = r_t * Vector3::z();
    let r_gl = r_i * r_e;
    let p_gl = t_g_i.translation + r_i * t_i_l.translation;
    let n_skew = skew(&n);
    let e3_skew = skew(&Vector3::z());
    let m_t = m.transpose();
    // d n / d x and d d / d x for each block (n: 3 x 3, d: 1 x 3).
    let dn_imu_rotation = n_skew * r_e.transpose();
    let dd_imu_rotation = -(m_t * r_i * skew(&t_i_l.translation));
    let dn_target = -(r_gl.transpose() * r_t * e3_skew);
    let dd_target = -((p_gl - t_g_t.translation).transpose() * r_t * e3_skew);
    let zero = Matrix3::zeros();
    let no_d = RowVector3::zeros();
    let rows = |dn: &Matrix3<T>, dd: &RowVector3<T>| block(plane, dn, dd);
    BoardPlaneJacobians {
        residual: -predict(t_g_i, t_i_l, t_g_t, plane),
        imu_rotation: rows(&dn_imu_rotation, &dd_imu_rotation),
        imu_position: rows(&zero, &m_t),
        extrinsic_rotation: rows(&n_skew, &no_d),
        extrinsic_translation: rows(&zero, &(m_t * r_i)),
        target_rotation: rows(&dn_target, &dd_target),
        target_position: rows(&zero, &-m_t),
    }
}

/// The 3 rows of `h` for one block from that block's `d n` and `d d`.
fn block<T: Scalar>(plane: &BoardPlane<T>, dn: &Matrix3<T>, dd: &RowVector3<T>) -> Matrix3<T> {
    let [wk, w1, w2] = plane.weights();
    let r0 = (plane.centroid.transpose() * dn + dd) * wk;
    let r1 = plane.in_plane[0].transpose() * dn * w1;
    let r2 = plane.in_plane[1].transpose() * dn * w2;
    Matrix3::from_rows(&[r0, r1, r2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_mat_close, central_diff};
    use nalgebra::{SMatrix, SVector, UnitQuaternion};

    fn plane() -> BoardPlane<f64> {
        let u1 = Vector3::new(0.3, -0.9, 0.2).normalize();
        let u2 = u1.cross(&Vector3::new(0.1, 0.2, 1.0)).normalize();
        BoardPlane {
            stamp_ns: 0,
            count: 400,
            centroid: Vector3::new(1.2, 0.4, -0.1),
            in_plane: [u1, u2],
            spread: [9.0, 4.0],
            sigma: 0.02,
        }
    }

    fn poses() -> [Pose<f64>; 3] {
        [
            Pose::new(
                UnitQuaternion::from_euler_angles(0.1, -0.05, 0.2),
                Vector3::new(-2.0, 0.1, 1.0),
            ),
            Pose::new(
                UnitQuaternion::from_euler_angles(0.3, 0.02, -1.2),
                Vector3::new(0.05, -0.08, 0.12),
            ),
            Pose::new(
                UnitQuaternion::from_euler_angles(1.5, 0.1, -1.6),
                Vector3::new(0.0, -0.2, 0.8),
            ),
        ]
    }

    #[test]
    fn jacobians_match_central_differences() {
        let [t_g_i, t_i_l, t_g_t] = poses();
        let plane = plane();
        let lin = linearize(&t_g_i, &t_i_l, &t_g_t, &plane);
        let predicted = |d: SVector<f64, 18>| {
            let v = |k: usize| Vector3::new(d[k], d[k + 1], d[k + 2]);
            let i = t_g_i.boxplus(&v(0), &v(3));
            let l = t_i_l.boxplus(&v(6), &v(9));
            let t = t_g_t.boxplus(&v(12), &v(15));
            predict(&i, &l, &t, &plane)
        };
        let numeric = central_diff::<3, 18>(predicted);
        let mut analytic = SMatrix::<f64, 3, 18>::zeros();
        for (k, b) in [
            lin.imu_rotation,
            lin.imu_position,
            lin.extrinsic_rotation,
            lin.extrinsic_translation,
            lin.target_rotation,
            lin.target_position,
        ]
        .iter()
        .enumerate()
        {
            analytic.fixed_view_mut::<3, 3>(0, 3 * k).copy_from(b);
        }
        assert_mat_close(&analytic, &numeric, 1e-6);
        assert!((lin.residual + predict(&t_g_i, &t_i_l, &t_g_t, &plane)).norm() == 0.0);
    }

    /// Points on the board seen from the true LiDAR pose: the predicted measurement is zero,
    /// and the moments' identity holds (sum of squared point-to-plane distances).
    #[test]
    fn board_points_predict_zero_and_the_moments_carry_every_point() {
        let [t_g_i, t_i_l, t_g_t] = poses();
        let t_l_t = t_g_i.compose(&t_i_l).inverse().compose(&t_g_t);
        let points: [Vector3<f64>; 48] = core::array::from_fn(|i| {
            let (a, b) = (i / 6, i % 6);
            let wobble = 0.003 * (((a * 7 + b * 3) % 5) as f64 - 2.0);
            t_l_t.transform_point(&Vector3::new(0.1 * a as f64, 0.08 * b as f64, wobble))
        });
        let moments = BoardPlane::from_points(0, &points, 0.003).unwrap();
        let (c, scatter) = centroid_and_scatter(&points);
        let eig = scatter.symmetric_eigen();
        let smallest = eig.eigenvalues.imin();
        // A wrong LiDAR pose: the three rows plus the normal's scatter term equal the sum of
        // squared point-to-plane distances.
        let wrong = t_i_l.boxplus(
            &Vector3::new(0.02, -0.01, 0.03),
            &Vector3::new(0.01, 0.0, 0.02),
        );
        let (n, d) = plane_in_lidar(&t_g_i, &wrong, &t_g_t);
        let direct: f64 = points.iter().map(|p| (n.dot(p) + d).powi(2)).sum();
        let h = predict(&t_g_i, &wrong, &t_g_t, &moments);
        let u3 = eig.eigenvectors.column(smallest).into_owned();
        let rest = eig.eigenvalues[smallest] * u3.dot(&n).powi(2);
        assert!((moments.centroid - c).norm() < 1e-12);
        // The RMS distance is the normal's scatter over K - 3.
        let rms = moments.distance_rms(&points).unwrap();
        let expected = (eig.eigenvalues[smallest] / (points.len() as f64 - 3.0)).sqrt();
        assert!((rms - expected).abs() < 1e-12, "{rms} vs {expected}");
        assert!((h.norm_squared() + rest - direct).abs() < 1e-9 * direct.max(1.0));
        // At the truth the in-plane rows vanish; the centroid row is the wobble's mean.
        let h = predict(&t_g_i, &t_i_l, &t_g_t, &moments);
        assert!(h.norm() < 0.05, "{h}");
    }

    #[test]
    fn bad_moments_are_refused() {
        let mut p = plane();
        p.count = 2;
        assert_eq!(p.validate(), Err(Error::EmptyMeasurement));
        let mut p = plane();
        p.spread[1] = 0.0;
        assert_eq!(p.validate(), Err(Error::InvalidConfig));
        let mut p = plane();
        p.in_plane[1] = p.in_plane[0];
        assert_eq!(p.validate(), Err(Error::InvalidConfig));
        let mut p = plane();
        p.centroid.x = f64::NAN;
        assert_eq!(p.validate(), Err(Error::NonFinite));
        // Points on a line span no plane; two points are not a measurement.
        let line: [Vector3<f64>; 10] = core::array::from_fn(|i| Vector3::new(i as f64, 0.0, 1.0));
        assert_eq!(
            BoardPlane::from_points(0, &line, 0.01),
            Err(Error::InvalidConfig)
        );
        assert_eq!(
            BoardPlane::from_points(0, &line[..2], 0.01),
            Err(Error::EmptyMeasurement)
        );
    }
}
