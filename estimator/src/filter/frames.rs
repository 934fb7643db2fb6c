//! Static frames: rigid bodies at rest in G whose pose the filter estimates beside the
//! calibration, e.g. the checkerboard of a camera-IMU calibration. Estimating the target pose
//! instead of fixing the gauge at the first camera frame (as the dissertation does) keeps
//! that frame's PnP error out of the result and lets gravity come from the IMU alone.

use super::Ekf;
use crate::ids::{FrameId, SensorId};
use crate::lie::Pose;
use crate::scalar::Scalar;
use crate::state::{Block, Layout, FRAME_DIM};
use crate::Error;
use nalgebra::SMatrix;

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// Both blocks of frame `f` (orientation then position).
    pub(super) const fn frame_block(f: FrameId) -> Block {
        Block {
            idx: Layout::<S, C>::frame_orientation(f).idx,
            dof: FRAME_DIM,
        }
    }

    /// (Re-)initialises static frame `f` at `T_G_F = pose` with independent per-axis sigmas
    /// (rad, m). Its previous correlations are dropped: call it before the first measurement
    /// of the frame, with sigmas that cover the error of the guess (e.g. a PnP pose composed
    /// with the current IMU pose and extrinsic).
    pub fn init_frame(
        &mut self,
        f: FrameId,
        pose: Pose<T>,
        sigma_rotation: T,
        sigma_position: T,
    ) -> Result<(), Error> {
        let i = f.checked(F)?;
        if !pose.is_finite() {
            return Err(Error::NonFinite);
        }
        let valid = |s: T| s.is_finite() && s > T::zero();
        if !valid(sigma_rotation) || !valid(sigma_position) {
            return Err(Error::InvalidConfig);
        }
        self.flush_transition();
        let b = Self::frame_block(f);
        for k in b.idx..b.end() {
            self.cov.row_mut(k).fill(T::zero());
            self.cov.column_mut(k).fill(T::zero());
        }
        self.inflate(Layout::<S, C>::frame_orientation(f), sigma_rotation);
        self.inflate(Layout::<S, C>::frame_position(f), sigma_position);
        self.frames[i] = Some(pose);
        Ok(())
    }

    /// Checks a measurement of static frame `f` through sensor `s` against this layout:
    /// `UnknownSensor`, `UnknownFrame`, `FrameNotInitialized` (an id made for a larger
    /// layout can reach a smaller filter; the types rule out everything else).
    pub(super) fn check_target_model(&self, s: SensorId, f: FrameId) -> Result<(), Error> {
        s.checked(S)?;
        match self.frames[f.checked(F)?] {
            Some(_) => Ok(()),
            None => Err(Error::FrameNotInitialized),
        }
    }

    /// `T_G_F` of static frame `f`, once initialised.
    pub fn frame(&self, f: FrameId) -> Option<Pose<T>> {
        self.frames.get(f.index()).copied().flatten()
    }

    /// 6x6 covariance of frame `f` (`[orientation; position]`), zero for an unknown frame.
    pub fn frame_covariance(&self, f: FrameId) -> SMatrix<T, 6, 6> {
        if f.checked(F).is_err() {
            return SMatrix::zeros();
        }
        let b = Self::frame_block(f).idx;
        self.cov.fixed_view::<6, 6>(b, b).clone_owned()
    }
}
