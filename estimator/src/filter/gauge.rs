//! The gauge of a filter with static frames, fixed at one of them.
//!
//! With gravity along `-z` of G, a filter whose measurements only relate the IMU to a static
//! frame (corners on a target, a board plane) cannot tell where G's origin is, nor its yaw:
//! moving every pose of the state (IMU, clones, frames) by one rotation about G's z axis and
//! one translation leaves every measurement unchanged. An EKF relinearised at moving
//! estimates does not see those four directions as exactly unobservable and gains spurious
//! information along them, which leaks into the calibration: the classic EKF inconsistency
//! of visual-inertial odometry, measured here as an extrinsic NEES above its band. Kalibr
//! avoids it by taking the target as the world frame. [`Ekf::fix_gauge`] does the same
//! inside the filter: it declares G to be the frame whose origin and yaw are those of frame
//! `f`'s current estimate, so the covariance of `f`'s position and yaw becomes zero and stays
//! zero (the frame is static, and no update can move a direction of zero variance).
//!
//! It is a change of coordinates, not a measurement: the error state is moved along the gauge
//! directions `V` (not conditioned), `dx' = T dx` with `T = I - V (A V)^-1 A`, where `A`
//! reads the frame's position and yaw. Every gauge-invariant quantity (the extrinsics, time
//! offsets, biases, the IMU pose relative to the frame) keeps its covariance exactly, because
//! its Jacobian `J` satisfies `J V = 0`, so `J T = J`.

use super::Ekf;
use crate::ids::FrameId;
use crate::lie::skew;
use crate::scalar::Scalar;
use crate::state::{imu, Block, Layout};
use crate::Error;
use nalgebra::{Matrix3, SMatrix, Vector3};

/// Gauge dimension: yaw about G's z axis, then translation along x, y, z of G.
const GAUGE: usize = 4;

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// Fixes the gauge at static frame `f`: from now on G's origin and yaw are those of the
    /// frame's current estimate, and the frame's position and rotation about gravity carry
    /// zero variance (see the module). The estimates do not move; only the covariance
    /// changes, and of it only the parts that depend on where G is. Call it once, right after
    /// the frame is initialised. Errors: `UnknownFrame`, `FrameNotInitialized`; on error the
    /// filter is unchanged.
    pub fn fix_gauge(&mut self, f: FrameId) -> Result<(), Error> {
        let anchor = self.frames[f.checked(F)?].ok_or(Error::FrameNotInitialized)?;
        self.flush_transition();
        // `K = V (A V)^-1`: the yaw column taken about the frame's origin, so that it leaves
        // the frame's position alone (`A V = [[1, 0], [z x p_F, I]]`).
        let mut k = self.gauge_directions();
        let lever = Vector3::<T>::z().cross(&anchor.translation);
        for i in 0..N {
            let shift = k.fixed_view::<1, 3>(i, 1) * lever;
            k[(i, 0)] -= shift[0];
        }
        // `A P`: the frame's yaw row and position rows of P, and `C = A P A^T`.
        let yaw_row =
            Vector3::<T>::z().transpose() * anchor.rotation.to_rotation_matrix().into_inner();
        let o = Layout::<S, C>::frame_orientation(f).idx;
        let p = Layout::<S, C>::frame_position(f).idx;
        let mut ap = SMatrix::<T, GAUGE, N>::zeros();
        ap.row_mut(0)
            .copy_from(&(yaw_row * self.cov.fixed_view::<3, N>(o, 0)));
        ap.fixed_view_mut::<3, N>(1, 0)
            .copy_from(&self.cov.fixed_view::<3, N>(p, 0));
        let mut c = SMatrix::<T, GAUGE, GAUGE>::zeros();
        for r in 0..GAUGE {
            c[(r, 0)] = (ap.fixed_view::<1, 3>(r, o) * yaw_row.transpose())[0];
            for j in 0..3 {
                c[(r, 1 + j)] = ap[(r, p + j)];
            }
        }
        // `P' = T P T^T = P - K B - B^T K^T` with `B = A P - C K^T / 2`, written into the
        // upper triangle and mirrored (no N x N temporary: this runs on the device too).
        let mut b = ap;
        b.gemm(-T::lit(0.5), &c, &k.transpose(), T::one());
        for i in 0..N {
            for j in i..N {
                let d = (k.row(i) * b.column(j))[0] + (k.row(j) * b.column(i))[0];
                let value = self.cov[(i, j)] - d;
                self.cov[(i, j)] = value;
                self.cov[(j, i)] = value;
            }
        }
        Ok(())
    }

    /// `V`: how the error state moves when every pose of the state is rotated by a small yaw
    /// about G's z axis (column 0) and translated along G's axes (columns 1-3). Right
    /// perturbations: a pose `R` turns by `R^T z`, a position `p` moves by `z x p + t`, the
    /// velocity by `z x v`. Biases, extrinsics and time offsets do not move.
    pub(super) fn gauge_directions(&self) -> SMatrix<T, N, GAUGE> {
        let mut v = SMatrix::<T, N, GAUGE>::zeros();
        let z = Vector3::z();
        let mut pose = |o: Block, p: Block, rotation: Matrix3<T>, position: &Vector3<T>| {
            v.fixed_view_mut::<3, 1>(o.idx, 0)
                .copy_from(&(rotation.transpose() * z));
            v.fixed_view_mut::<3, 1>(p.idx, 0)
                .copy_from(&(-skew(position) * z));
            v.fixed_view_mut::<3, 3>(p.idx, 1)
                .copy_from(&Matrix3::identity());
        };
        let imu_r = self.imu.rotation.to_rotation_matrix().into_inner();
        pose(imu::ORIENTATION, imu::POSITION, imu_r, &self.imu.position);
        for (c, clone) in self.clones.iter().enumerate() {
            if let Some(clone) = clone {
                let r = clone.pose.rotation.to_rotation_matrix().into_inner();
                let (o, p) = (
                    Layout::<S, C>::clone_orientation(c),
                    Layout::<S, C>::clone_position(c),
                );
                pose(o, p, r, &clone.pose.translation);
            }
        }
        for (f, frame) in FrameId::all::<F>().into_iter().zip(&self.frames) {
            if let Some(frame) = frame {
                let r = frame.rotation.to_rotation_matrix().into_inner();
                let (o, p) = (
                    Layout::<S, C>::frame_orientation(f),
                    Layout::<S, C>::frame_position(f),
                );
                pose(o, p, r, &frame.translation);
            }
        }
        v.fixed_view_mut::<3, 1>(imu::VELOCITY.idx, 0)
            .copy_from(&z.cross(&self.imu.velocity));
        v
    }
}
