//! A static frame initialised from a relative measurement, with its full cross-covariance:
//! a sensor sees frame `F` at pose `T_S_F` (e.g. a PnP pose of the checkerboard), so
//! `T_G_F = T_G_I(t) T_I_S T_S_F` at the measurement's IMU time `t = stamp + t_d`. Like a
//! clone (`clones.rs`), the new frame's error is a linear function of the state's errors
//! plus the measurement's: `dx_F = J dx + J_m n`, so
//!
//! `P_FF = J P J^T + J_m R J_m^T`,  `P_F,x = J P`.
//!
//! Initialising the frame with independent sigmas instead counts the errors of the IMU pose
//! and of the extrinsic it was composed through twice: once in their own blocks and once,
//! as if independent, in the frame's.
//!
//! Errors: right perturbations of every rotation, additive translations
//! ([`Pose::boxplus`]); the measurement noise `R` is the covariance of `[d_rho, d_q]` with
//! `T_S_F = T_S_F_hat (Exp(d_rho), + d_q)`, the convention of the host's PnP covariance.

use super::undo::PropagationUndo;
use super::Ekf;
use crate::ids::{FrameId, SensorId};
use crate::lie::{skew, Pose};
use crate::scalar::Scalar;
use crate::state::{imu, Layout};
use crate::Error;
use nalgebra::{Matrix3, SMatrix, Vector3};

/// The Jacobians of `T_G_F = T_G_I T_I_S T_S_F` (frame error `[d_theta_F; dp_F]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameJacobians<T: Scalar> {
    /// The composed pose `T_G_F`.
    pub pose: Pose<T>,
    /// w.r.t. the IMU orientation, position, extrinsic rotation and extrinsic translation.
    pub state: [SMatrix<T, 6, 3>; 4],
    /// w.r.t. the measurement's `[d_rho, d_q]`.
    pub measurement: SMatrix<T, 6, 6>,
}

/// `T_G_F` from the IMU pose `T_G_I`, the extrinsic `T_I_S` and the measurement `T_S_F`,
/// with its Jacobians.
pub fn compose_frame<T: Scalar>(
    t_g_i: &Pose<T>,
    t_i_s: &Pose<T>,
    t_s_f: &Pose<T>,
) -> FrameJacobians<T> {
    let r_gi = t_g_i.rotation.to_rotation_matrix().into_inner();
    let r_is = t_i_s.rotation.to_rotation_matrix().into_inner();
    let r_sf = t_s_f.rotation.to_rotation_matrix().into_inner();
    let p_f_in_i = r_is * t_s_f.translation + t_i_s.translation;
    let block = |rot: Matrix3<T>, pos: Matrix3<T>| {
        let mut m = SMatrix::<T, 6, 3>::zeros();
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot);
        m.fixed_view_mut::<3, 3>(3, 0).copy_from(&pos);
        m
    };
    let zero = Matrix3::zeros();
    let state = [
        block((r_is * r_sf).transpose(), -(r_gi * skew(&p_f_in_i))),
        block(zero, Matrix3::identity()),
        block(r_sf.transpose(), -(r_gi * r_is * skew(&t_s_f.translation))),
        block(zero, r_gi),
    ];
    let mut measurement = SMatrix::<T, 6, 6>::zeros();
    measurement
        .fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    measurement
        .fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(r_gi * r_is));
    FrameJacobians {
        pose: t_g_i.compose(t_i_s).compose(t_s_f),
        state,
        measurement,
    }
}

/// True when `m` is finite, symmetric (to a relative 1e-6) and positive definite.
fn is_covariance<T: Scalar>(m: &SMatrix<T, 6, 6>) -> bool {
    if !m.iter().all(|x| x.is_finite()) {
        return false;
    }
    let scale = m.amax();
    let symmetric = (m - m.transpose()).amax() <= T::lit(1e-6) * scale;
    symmetric && scale > T::zero() && m.clone_owned().cholesky().is_some()
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// (Re-)initialises static frame `f` from sensor `s`'s measurement `t_s_f` (pose of the
    /// frame in the sensor, covariance `cov` of `[d_rho, d_q]`, rad and m) stamped
    /// `stamp_ns` on the sensor's clock: `T_G_F = T_G_I(stamp + t_d) T_I_S T_S_F` with its
    /// cross-covariance with every state (see the module). The filter propagates to the
    /// measurement's IMU time, as for a clone; any previous estimate of the frame is
    /// dropped. On error the filter is unchanged.
    pub fn init_frame_relative(
        &mut self,
        f: FrameId,
        s: SensorId,
        stamp_ns: u64,
        t_s_f: &Pose<T>,
        cov: &SMatrix<T, 6, 6>,
    ) -> Result<(), Error> {
        f.checked(F)?;
        s.checked(S)?;
        if !t_s_f.is_finite() || !cov.iter().all(|x| x.is_finite()) {
            return Err(Error::NonFinite);
        }
        if !is_covariance(cov) {
            return Err(Error::InvalidConfig);
        }
        let t = self.reachable_imu_time(s, stamp_ns)?;
        let undo = PropagationUndo::save(self);
        let result = self.advance_to(t).and_then(|()| {
            self.flush_transition();
            self.write_frame_from(f, s, t_s_f, cov)
        });
        if result.is_err() {
            undo.restore(self);
        }
        result
    }

    /// The frame's rows of `J P` and its block `J P J^T + J_m R J_m^T`, written only when
    /// all are finite.
    fn write_frame_from(
        &mut self,
        f: FrameId,
        s: SensorId,
        t_s_f: &Pose<T>,
        cov: &SMatrix<T, 6, 6>,
    ) -> Result<(), Error> {
        let jac = compose_frame(&self.imu.pose(), &self.sensors[s.index()].extrinsic, t_s_f);
        // The measurement happened at the IMU time `stamp + t_d`: a time-offset error moves
        // the pose it was composed through by `[w; v] dt_d` (as a clone's).
        let w = self
            .imu_now
            .map(|m| m.gyro - self.imu.gyro_bias)
            .unwrap_or_else(Vector3::zeros);
        let j_td = jac.state[0] * w + jac.state[1] * self.imu.velocity;
        let cols = [
            imu::ORIENTATION.idx,
            imu::POSITION.idx,
            Layout::<S, C>::extrinsic_rotation(s).idx,
            Layout::<S, C>::extrinsic_translation(s).idx,
        ];
        let td = Layout::<S, C>::time_offset(s).idx;
        let mut jp = j_td * self.cov.fixed_view::<1, N>(td, 0);
        for (c, b) in cols.iter().zip(jac.state.iter()) {
            jp += b * self.cov.fixed_view::<3, N>(*c, 0);
        }
        let fb = Self::frame_block(f);
        for k in fb.idx..fb.end() {
            jp.column_mut(k).fill(T::zero());
        }
        let mut p_ff = jp.fixed_view::<6, 1>(0, td) * j_td.transpose()
            + jac.measurement * cov * jac.measurement.transpose();
        for (c, b) in cols.iter().zip(jac.state.iter()) {
            p_ff += jp.fixed_view::<6, 3>(0, *c) * b.transpose();
        }
        let p_ff = (p_ff + p_ff.transpose()) * T::lit(0.5);
        if !jac.pose.is_finite() || !jp.iter().chain(p_ff.iter()).all(|x| x.is_finite()) {
            return Err(Error::DivergentUpdate);
        }
        for k in 0..6 {
            self.cov.row_mut(fb.idx + k).copy_from(&jp.row(k));
            self.cov
                .column_mut(fb.idx + k)
                .copy_from(&jp.row(k).transpose());
        }
        self.cov
            .fixed_view_mut::<6, 6>(fb.idx, fb.idx)
            .copy_from(&p_ff);
        self.frames[f.index()] = Some(jac.pose);
        Ok(())
    }
}
