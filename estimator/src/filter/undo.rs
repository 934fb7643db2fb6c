//! What an update may have to take back when it fails after it has started changing the
//! filter, without copying the filter: "every error leaves the state untouched".
//!
//! - [`StepUndo`] + [`ColumnsUndo`]: a relative-pose update propagates to its end stamp and
//!   clones the IMU pose before it linearises; an image propagates and brings `P_IX` up to
//!   date. The propagation itself writes only the small state and `P_II`, so [`StepUndo`]
//!   (`O(1)` in `N`) is all that is held across its deep call chain; the `N x 15` IMU columns
//!   (and the clone slot's `N x 6`) are saved after it, in [`ColumnsUndo`], O(N m).
//! - [`PropagationUndo`]: a single update at the measurement's IMU time (a board plane, an
//!   image's compressed corners) propagates first; it saves the small state and the IMU
//!   columns, `N x 15`.

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
    yaw_chain: [nalgebra::Vector3<T>; 3],
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
            yaw_chain: self.yaw_chain,
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
        self.yaw_chain = small.yaw_chain;
    }

    /// Writes saved columns `idx..idx + W` of the (symmetric) covariance and their rows,
    /// element by element (a transposed `N x W` copy would cost that much stack on the
    /// error path).
    fn restore_columns<const W: usize>(&mut self, idx: usize, cols: &SMatrix<T, N, W>) {
        for k in 0..W {
            for r in 0..N {
                let x = cols[(r, k)];
                self.cov[(r, idx + k)] = x;
                self.cov[(idx + k, r)] = x;
            }
        }
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

/// Undo of a propagation alone, `O(1)` in `N`: `Ekf::advance_to` writes the small state and
/// `P_II` only (`P_IX` lags behind through the pending transition), so that is all it saves.
/// Held across the propagation's deep call chain instead of the `N x 15` columns; whatever
/// runs after the propagation saves what it writes itself ([`ColumnsUndo`]), and is undone
/// first.
pub(super) struct StepUndo<T: Scalar, const S: usize, const C: usize, const F: usize> {
    small: Small<T, S, C, F>,
    p_ii: SMatrix<T, 15, 15>,
}

impl<T: Scalar, const S: usize, const C: usize, const F: usize> StepUndo<T, S, C, F> {
    /// Saves what a propagation will overwrite.
    pub(super) fn save<const N: usize>(ekf: &Ekf<T, S, C, N, F>) -> Self {
        Self {
            small: ekf.small(),
            p_ii: ekf.cov.fixed_view::<15, 15>(0, 0).clone_owned(),
        }
    }

    /// Puts the filter back as it was at [`StepUndo::save`] (after every [`ColumnsUndo`]
    /// taken since has been restored).
    pub(super) fn restore<const N: usize>(&self, ekf: &mut Ekf<T, S, C, N, F>) {
        ekf.restore_small(&self.small);
        ekf.cov.fixed_view_mut::<15, 15>(0, 0).copy_from(&self.p_ii);
    }
}

/// Undo of what follows a propagation and may fail after it: bringing `P_IX` up to date (the
/// IMU columns) and, for a clone into `slot`, that slot's columns. `O(N)`. Filled in place
/// ([`ColumnsUndo::save`] into a [`ColumnsUndo::new`]): built by value and moved, the
/// `N x 21` record was held twice in the update's frame on the M4F.
pub(super) struct ColumnsUndo<T: Scalar, const N: usize> {
    imu_columns: SMatrix<T, N, 15>,
    slot_columns: SMatrix<T, N, 6>,
    slot: Option<usize>,
}

impl<T: Scalar, const N: usize> ColumnsUndo<T, N> {
    /// An empty record (restores nothing until [`ColumnsUndo::save`]).
    pub(super) fn new() -> Self {
        Self {
            imu_columns: SMatrix::zeros(),
            slot_columns: SMatrix::zeros(),
            slot: None,
        }
    }

    /// Saves the IMU columns and, with `Some(slot)`, those of that clone slot.
    pub(super) fn save<const S: usize, const C: usize, const F: usize>(
        &mut self,
        ekf: &Ekf<T, S, C, N, F>,
        slot: Option<usize>,
    ) {
        self.imu_columns
            .copy_from(&ekf.cov.fixed_view::<N, 15>(0, imu::ORIENTATION.idx));
        if let Some(slot) = slot {
            let c = Layout::<S, C>::clone_orientation(slot).idx;
            self.slot_columns
                .copy_from(&ekf.cov.fixed_view::<N, 6>(0, c));
        }
        self.slot = slot;
    }

    /// Writes the saved columns back (the small state is the [`StepUndo`]'s).
    pub(super) fn restore<const S: usize, const C: usize, const F: usize>(
        &self,
        ekf: &mut Ekf<T, S, C, N, F>,
    ) {
        ekf.restore_columns(imu::ORIENTATION.idx, &self.imu_columns);
        if let Some(slot) = self.slot {
            let c = Layout::<S, C>::clone_orientation(slot).idx;
            ekf.restore_columns(c, &self.slot_columns);
        }
    }
}
