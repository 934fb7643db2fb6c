//! Reprojection of a known target point (checkerboard corner), dissertation eq. 4.2, 4.15
//! and A.16-A.36, rederived for Hamilton quaternions and right perturbations.
//!
//! A corner `p_T` of the target T (static in G) is seen by camera C, mounted at `T_I_C` on
//! the IMU at pose `T_G_I`:
//!
//! `p_C = T_I_C^-1 T_G_I^-1 T_G_T p_T`, `z = pi(p_C)` through the camera model.
//!
//! The residual is `z_measured - pi(p_C)` (pixels). The Jacobians w.r.t. the IMU pose, the
//! extrinsic and the target pose are the camera's `d pi / d p_C` times the rows below; the
//! time offset enters as `H_theta_I w + H_p_I v` (see `Ekf::clone_imu_pose`).

use crate::camera::Camera;
use crate::lie::{skew, Pose};
use crate::scalar::Scalar;
use crate::Error;
use nalgebra::{Matrix2x3, Vector2, Vector3};

/// One target corner found in an image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CornerObservation<T: Scalar> {
    /// The corner in the target frame T, m (e.g. `(col * spacing, row * spacing, 0)`).
    pub point_in_target: Vector3<T>,
    /// Where the detector found it, pixels.
    pub pixel: Vector2<T>,
}

/// The corners of one image: the measurement of a reprojection update.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CornerSet<'a, T: Scalar> {
    /// Image stamp, ns (camera clock).
    pub stamp_ns: u64,
    /// The corners; all of them are gated together.
    pub corners: &'a [CornerObservation<T>],
    /// 1-sigma of the detector, pixels, per axis.
    pub pixel_sigma: T,
}

impl<T: Scalar> CornerSet<'_, T> {
    /// Checks that there is something to fuse and that every value is usable.
    pub fn validate(&self) -> Result<(), Error> {
        if self.corners.is_empty() {
            return Err(Error::EmptyMeasurement);
        }
        let finite = self.corners.iter().all(|c| {
            c.point_in_target.iter().all(|x| x.is_finite()) && c.pixel.iter().all(|x| x.is_finite())
        });
        if !finite || !self.pixel_sigma.is_finite() {
            return Err(Error::NonFinite);
        }
        if self.pixel_sigma <= T::zero() {
            return Err(Error::InvalidConfig);
        }
        Ok(())
    }
}

/// Residual and Jacobian blocks of one corner observation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReprojectionJacobians<T: Scalar> {
    /// `z - pi(p_C)`, pixels.
    pub residual: Vector2<T>,
    /// The corner in the camera frame.
    pub point_in_camera: Vector3<T>,
    /// w.r.t. the IMU orientation `dtheta_I` and position `dp_I`.
    pub imu_rotation: Matrix2x3<T>,
    /// w.r.t. `dp_I`.
    pub imu_position: Matrix2x3<T>,
    /// w.r.t. the extrinsic rotation `dtheta_I_C`.
    pub extrinsic_rotation: Matrix2x3<T>,
    /// w.r.t. the extrinsic translation `dp_I_C`.
    pub extrinsic_translation: Matrix2x3<T>,
    /// w.r.t. the target orientation `dtheta_G_T`.
    pub target_rotation: Matrix2x3<T>,
    /// w.r.t. the target position `dp_G_T`.
    pub target_position: Matrix2x3<T>,
}

/// The corner in the camera frame.
pub fn point_in_camera<T: Scalar>(
    t_g_i: &Pose<T>,
    t_i_c: &Pose<T>,
    t_g_t: &Pose<T>,
    point_in_target: &Vector3<T>,
) -> Vector3<T> {
    let point_in_g = t_g_t.transform_point(point_in_target);
    let point_in_imu = t_g_i.inverse().transform_point(&point_in_g);
    t_i_c.inverse().transform_point(&point_in_imu)
}

/// Residual and Jacobians at the current estimate; `None` when the corner cannot be
/// projected (behind the camera, outside the model).
pub fn linearize<T: Scalar>(
    camera: &Camera<T>,
    t_g_i: &Pose<T>,
    t_i_c: &Pose<T>,
    t_g_t: &Pose<T>,
    point_in_target: &Vector3<T>,
    measured: &Vector2<T>,
) -> Option<ReprojectionJacobians<T>> {
    let p_c = point_in_camera(t_g_i, t_i_c, t_g_t, point_in_target);
    let projected = camera.project(&p_c)?;
    let rot = |q: &nalgebra::UnitQuaternion<T>| q.to_rotation_matrix().into_inner();
    let r_ct = rot(&t_i_c.rotation).transpose();
    let r_it = rot(&t_g_i.rotation).transpose();
    let r_t = rot(&t_g_t.rotation);
    // The corner in the IMU frame.
    let u = r_it * (t_g_t.transform_point(point_in_target) - t_g_i.translation);
    let j = projected.jacobian;
    Some(ReprojectionJacobians {
        residual: measured - projected.pixel,
        point_in_camera: p_c,
        imu_rotation: j * r_ct * skew(&u),
        imu_position: -(j * r_ct * r_it),
        extrinsic_rotation: j * skew(&p_c),
        extrinsic_translation: -(j * r_ct),
        target_rotation: -(j * r_ct * r_it * r_t * skew(point_in_target)),
        target_position: j * r_ct * r_it,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{radtan::RadTan, Distortion, Intrinsics, Projection};
    use crate::testing::{assert_mat_close, central_diff};
    use nalgebra::{SMatrix, SVector, UnitQuaternion};

    #[test]
    fn jacobians_match_central_differences() {
        let camera = Camera::new(
            Projection::Pinhole,
            Intrinsics {
                fu: 800.0,
                fv: 790.0,
                cu: 640.0,
                cv: 480.0,
            },
            Distortion::RadTan(RadTan {
                k1: -0.2,
                k2: 0.05,
                p1: 0.001,
                p2: -0.002,
                k3: 0.0,
            }),
            (1280, 960),
        )
        .unwrap();
        // IMU 2 m in front of a target on a wall; camera looking along the IMU's x axis.
        let t_g_i = Pose::new(
            UnitQuaternion::from_euler_angles(0.1, -0.05, 0.2),
            Vector3::new(-2.0, 0.1, 1.0),
        );
        let t_i_c = Pose::new(
            UnitQuaternion::from_euler_angles(-1.57, 0.02, -1.57),
            Vector3::new(0.05, -0.02, 0.1),
        );
        let t_g_t = Pose::new(
            UnitQuaternion::from_euler_angles(1.5, 0.0, -1.6),
            Vector3::new(0.0, -0.2, 0.8),
        );
        let corner = Vector3::new(0.12, 0.08, 0.0);
        let measured = Vector2::new(600.0, 500.0);
        let lin = linearize(&camera, &t_g_i, &t_i_c, &t_g_t, &corner, &measured).unwrap();
        let predicted = |d: SVector<f64, 18>| {
            let v = |k: usize| Vector3::new(d[k], d[k + 1], d[k + 2]);
            let i = t_g_i.boxplus(&v(0), &v(3));
            let c = t_i_c.boxplus(&v(6), &v(9));
            let t = t_g_t.boxplus(&v(12), &v(15));
            camera
                .project(&point_in_camera(&i, &c, &t, &corner))
                .unwrap()
                .pixel
        };
        let numeric = central_diff::<2, 18>(predicted);
        let mut analytic = SMatrix::<f64, 2, 18>::zeros();
        for (k, block) in [
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
            analytic.fixed_view_mut::<2, 3>(0, 3 * k).copy_from(block);
        }
        assert_mat_close(&(analytic / 1000.0), &(numeric / 1000.0), 1e-6);
    }
}
