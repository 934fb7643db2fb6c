//! What an update may have to take back when it fails after it has started changing the
//! filter, without copying the filter: "every error leaves the state untouched".
//!
//! - [`CloneUndo`]: a relative-pose update propagates to its end stamp and clones the IMU
//!   pose before it linearises, so it saves what those two steps write (the IMU and clone-slot
//!   columns of the covariance, `N x 21`, and the small state), O(N m).
//! - [`PropagationUndo`]: a single update at the measurement's IMU time (a board plane)
//!   propagates first; it saves the small state and the IMU columns, `N x 15`.
//! - [`Checkpoint`]: a reprojection update fuses its corners one by one and gates the image as
//!   a whole afterwards, so a rejected image takes back 2 K corner steps; it keeps the
//!   covariance itself (`N^2` entries, fewer than the `N x 2K` of the image's gain at K = 42).

use super::Ekf;
use crate::propagate::ImuSample;
use crate::scalar::Scalar;
use crate::state::{imu, CloneState, ImuState, Layout, SensorState};
use nalgebra::SMatrix;

/// The filter's small state (everything but the covariance and the health monitor).
#[derive(Clone, Copy)]
struct Small<T: Scalar, const S: usize, const C: usize, const F: usize> {
    time_ns: u64,
    imu_now: Option<ImuSample<T>>,
    imu: ImuState<T>,
    sensors: [SensorState<T>; S],
    clones: [Option<CloneState<T>>; C],
    anchors: [Option<usize>; S],
    frames: [Option<crate::lie::Pose<T>>; F],
    pending_transition: SMatrix<T, 15, 15>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    fn small(&self) -> Small<T, S, C, F> {
        Small {
            time_ns: self.time_ns,
            imu_now: self.imu_now,
            imu: self.imu,
            sensors: self.sensors,
            clones: self.clones,
            anchors: self.anchors,
            frames: self.frames,
            pending_transition: self.pending_transition,
        }
    }

    fn restore_small(&mut self, small: &Small<T, S, C, F>) {
        self.time_ns = small.time_ns;
        self.imu_now = small.imu_now;
        self.imu = small.imu;
        self.sensors = small.sensors;
        self.clones = small.clones;
        self.anchors = small.anchors;
        self.frames = small.frames;
        self.pending_transition = small.pending_transition;
    }

    /// Writes saved columns `idx..idx + W` of the (symmetric) covariance and their rows.
    fn restore_columns<const W: usize>(&mut self, idx: usize, cols: &SMatrix<T, N, W>) {
        self.cov.fixed_view_mut::<N, W>(0, idx).copy_from(cols);
        self.cov
            .fixed_view_mut::<W, N>(idx, 0)
            .copy_from(&cols.transpose());
    }
}

/// Undo of a propagation to a measurement's time: the small state and the IMU columns of
/// the covariance (propagation and bringing `P_IX` up to date write nothing else), O(N).
pub(super) struct PropagationUndo<
    T: Scalar,
    const S: usize,
    const C: usize,
    const N: usize,
    const F: usize,
> {
    small: Small<T, S, C, F>,
    imu_columns: SMatrix<T, N, 15>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    PropagationUndo<T, S, C, N, F>
{
    /// Saves what a propagation will overwrite.
    pub(super) fn save(ekf: &Ekf<T, S, C, N, F>) -> Self {
        Self {
            small: ekf.small(),
            imu_columns: ekf
                .cov
                .fixed_view::<N, 15>(0, imu::ORIENTATION.idx)
                .clone_owned(),
        }
    }

    /// Puts the filter back as it was at [`PropagationUndo::save`].
    pub(super) fn restore(&self, ekf: &mut Ekf<T, S, C, N, F>) {
        ekf.restore_small(&self.small);
        ekf.restore_columns(imu::ORIENTATION.idx, &self.imu_columns);
    }
}

/// Undo of "propagate, then clone the IMU pose into `slot`".
pub(super) struct CloneUndo<
    T: Scalar,
    const S: usize,
    const C: usize,
    const N: usize,
    const F: usize,
> {
    propagation: PropagationUndo<T, S, C, N, F>,
    slot: usize,
    slot_columns: SMatrix<T, N, 6>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    CloneUndo<T, S, C, N, F>
{
    /// Saves what propagation and a clone into `slot` will overwrite.
    pub(super) fn save(ekf: &Ekf<T, S, C, N, F>, slot: usize) -> Self {
        let c = Layout::<S, C>::clone_orientation(slot).idx;
        Self {
            propagation: PropagationUndo::save(ekf),
            slot,
            slot_columns: ekf.cov.fixed_view::<N, 6>(0, c).clone_owned(),
        }
    }

    /// Puts the filter back as it was at [`CloneUndo::save`].
    pub(super) fn restore(&self, ekf: &mut Ekf<T, S, C, N, F>) {
        self.propagation.restore(ekf);
        let c = Layout::<S, C>::clone_orientation(self.slot).idx;
        ekf.restore_columns(c, &self.slot_columns);
    }
}

/// The whole filter state but the health monitor.
pub(super) struct Checkpoint<
    T: Scalar,
    const S: usize,
    const C: usize,
    const N: usize,
    const F: usize,
> {
    small: Small<T, S, C, F>,
    cov: SMatrix<T, N, N>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    Checkpoint<T, S, C, N, F>
{
    /// Saves the state.
    pub(super) fn save(ekf: &Ekf<T, S, C, N, F>) -> Self {
        Self {
            small: ekf.small(),
            cov: ekf.cov,
        }
    }

    /// Puts the filter back as it was at [`Checkpoint::save`].
    pub(super) fn restore(&self, ekf: &mut Ekf<T, S, C, N, F>) {
        ekf.restore_small(&self.small);
        ekf.cov = self.cov;
    }
}
