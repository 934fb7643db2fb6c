//! The board-plane update of the joint calibration: the board points a LiDAR saw in one
//! scan against the target frame that the camera's corners also observe
//! (`update::board_plane`).

use super::undo::PropagationUndo;
use super::Ekf;
use crate::ids::{FrameId, SensorId};
use crate::scalar::Scalar;
use crate::update::board_plane::{self, BoardPlane, BoardPlaneJacobians};
use crate::update::{Measurement, SparseJacobian, UpdateKind, UpdateReport};
use crate::Error;
use nalgebra::{Matrix3, SMatrix, Vector3};

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// Fuses the board plane of target frame `f` seen by LiDAR sensor `s` (extrinsic
    /// `T_I_L`) in the scan stamped `meas.stamp_ns`, at the scan's IMU time `stamp + t_d`
    /// (feed IMU samples until [`Ekf::is_due`] says so). Rejected by the gate: only the
    /// health monitor records it. On error the filter is unchanged.
    pub fn update_board_plane(
        &mut self,
        s: SensorId,
        f: FrameId,
        meas: &BoardPlane<T>,
    ) -> Result<UpdateReport<T>, Error> {
        self.check_target_model(s, f)?;
        meas.validate()?;
        let t = self.reachable_imu_time(s, meas.stamp_ns)?;
        let undo = PropagationUndo::save(self);
        let report = self.fuse_board_plane(s, f, meas, t);
        if report.is_err() {
            undo.restore(self);
        }
        report
    }

    fn fuse_board_plane(
        &mut self,
        s: SensorId,
        f: FrameId,
        meas: &BoardPlane<T>,
        t: u64,
    ) -> Result<UpdateReport<T>, Error> {
        self.advance_to(t)?;
        let last = self.imu_now.ok_or(Error::NotInitialized)?;
        let target = self.frames[f.index()].ok_or(Error::FrameNotInitialized)?;
        let lin = board_plane::linearize(
            &self.imu.pose(),
            &self.sensors[s.index()].extrinsic,
            &target,
            meas,
        );
        let mut extrinsic = SMatrix::<T, 3, 6>::zeros();
        extrinsic
            .fixed_columns_mut::<3>(0)
            .copy_from(&lin.extrinsic_rotation);
        extrinsic
            .fixed_columns_mut::<3>(3)
            .copy_from(&lin.extrinsic_translation);
        let measurement = Measurement {
            residual: lin.residual,
            jacobian: self.board_plane_jacobian(s, f, &lin, &last.gyro),
            noise: Matrix3::identity() * (meas.sigma * meas.sigma),
        };
        self.fuse(
            UpdateKind::BoardPlane,
            Some(s),
            meas.stamp_ns,
            &measurement,
            Some(&extrinsic),
            None,
        )
    }

    /// The 19 non-zero columns of the plane's 3 x N Jacobian (IMU pose, extrinsic, time
    /// offset, target pose), as for a corner.
    pub(super) fn board_plane_jacobian(
        &self,
        s: SensorId,
        f: FrameId,
        lin: &BoardPlaneJacobians<T>,
        held_gyro: &Vector3<T>,
    ) -> SparseJacobian<T, 3, 19> {
        self.target_model_jacobian(
            s,
            f,
            [
                &lin.imu_rotation,
                &lin.imu_position,
                &lin.extrinsic_rotation,
                &lin.extrinsic_translation,
                &lin.target_rotation,
                &lin.target_position,
            ],
            held_gyro,
        )
    }
}
