//! Stochastic clones: the window of past IMU poses relative measurements tie together.

use super::Ekf;
use crate::ids::SensorId;
use crate::scalar::Scalar;
use crate::state::{imu, CloneState, Layout};
use crate::Error;
use nalgebra::Vector3;

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// IMU time of sensor `s`'s measurement stamped `stamp_ns`, checked to be reachable by
    /// propagation: not before the filter time (up to `max_late_ns`, then the filter time
    /// itself), not beyond the newest IMU sample.
    pub(super) fn reachable_imu_time(&self, s: SensorId, stamp_ns: u64) -> Result<u64, Error> {
        let horizon = self.imu_horizon_ns().ok_or(Error::NotInitialized)?;
        let t = self.imu_time(s, stamp_ns)?;
        if t < self.time_ns && self.time_ns - t <= self.config.max_late_ns {
            return Ok(self.time_ns);
        }
        if t < self.time_ns {
            return Err(Error::TimeWentBackwards {
                filter_ns: self.time_ns,
                stamp_ns: t,
            });
        }
        if t > horizon {
            return Err(Error::NotYetDue {
                imu_time_ns: t,
                horizon_ns: horizon,
            });
        }
        Ok(t)
    }

    /// Chooses the slot for a new clone: a free one, else the oldest that no sensor anchors.
    pub(super) fn free_slot(&self) -> Result<usize, Error> {
        if let Some(i) = self.clones.iter().position(Option::is_none) {
            return Ok(i);
        }
        (0..C)
            .filter(|i| !self.anchors.contains(&Some(*i)))
            .min_by_key(|i| self.clones[*i].map(|c| c.stamp_ns).unwrap_or(0))
            .ok_or(Error::CloneWindowFull)
    }

    /// Removes clone `slot` from the state (marginalisation: its rows and columns go).
    pub(super) fn drop_clone(&mut self, slot: usize) {
        let b = Layout::<S, C>::clone_orientation(slot).idx;
        for k in 0..6 {
            self.cov.row_mut(b + k).fill(T::zero());
            self.cov.column_mut(b + k).fill(T::zero());
        }
        self.clones[slot] = None;
    }

    /// Clones the current IMU pose into `slot` for sensor `s`'s measurement at `stamp_ns`.
    ///
    /// The clone is the pose at the measurement's true IMU time `stamp + t_d`, so its error is
    /// `[dtheta + w dt_d; dp + v dt_d]`: the clone carries the time-offset correlation
    /// through the angular and linear velocity (OpenVINS).
    pub(super) fn clone_imu_pose(&mut self, s: SensorId, slot: usize, stamp_ns: u64) {
        self.flush_transition();
        self.drop_clone(slot);
        let w = self
            .imu_now
            .map(|m| m.gyro - self.imu.gyro_bias)
            .unwrap_or_else(Vector3::zeros);
        let v = self.imu.velocity;
        let td = Layout::<S, C>::time_offset(s).idx;
        let c = Layout::<S, C>::clone_orientation(slot).idx;
        let source = |k: usize| {
            if k < 3 {
                (imu::ORIENTATION.idx + k, w[k])
            } else {
                (imu::POSITION.idx + k - 3, v[k - 3])
            }
        };
        for k in 0..6 {
            let (src, coeff) = source(k);
            for j in 0..N {
                let value = self.cov[(src, j)] + self.cov[(td, j)] * coeff;
                self.cov[(c + k, j)] = value;
                self.cov[(j, c + k)] = value;
            }
        }
        for k in 0..6 {
            for l in 0..6 {
                let (src, coeff) = source(l);
                self.cov[(c + k, c + l)] = self.cov[(c + k, src)] + self.cov[(c + k, td)] * coeff;
            }
        }
        self.clones[slot] = Some(CloneState {
            pose: self.imu.pose(),
            stamp_ns,
            sensor: s,
            yaw_direction: [self.yaw_chain[0], self.yaw_chain[1]],
        });
    }

    /// Starts an odometry segment of sensor `s`: clones the IMU pose at `stamp_ns + t_d` as
    /// the start of the next relative measurement.
    pub fn anchor(&mut self, s: SensorId, stamp_ns: u64) -> Result<(), Error> {
        let i = s.checked(S)?;
        // Nothing after the (atomic) propagation can fail.
        let slot = self.prepare_clone(s, stamp_ns)?;
        if let Some(old) = self.anchors[i] {
            self.drop_clone(old);
        }
        self.clone_imu_pose(s, slot, stamp_ns);
        self.anchors[i] = Some(slot);
        Ok(())
    }

    /// Propagates to the measurement time and picks a clone slot.
    pub(super) fn prepare_clone(&mut self, s: SensorId, stamp_ns: u64) -> Result<usize, Error> {
        let t = self.reachable_imu_time(s, stamp_ns)?;
        let slot = self.free_slot()?;
        self.advance_to(t)?;
        Ok(slot)
    }
}
