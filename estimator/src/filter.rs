//! The error-state EKF: IMU propagation, stochastic cloning and measurement updates over a
//! compile-time layout of `S` sensors and `C` clones (`N = 15 + 7 S + 6 C`).
//!
//! Every public method either succeeds or returns an [`Error`] with the filter unchanged:
//! updates run on a draft copy that is committed only when everything (gate, finiteness)
//! went through.

use crate::chi2::Confidence;
use crate::health::{ExtrinsicInnovation, HealthConfig, HealthEvent, HealthMonitor};
use crate::lie::Pose;
use crate::propagate::{self, ImuNoise, ImuSample};
use crate::scalar::Scalar;
use crate::state::{imu, Block, CloneState, ImuState, InitialState, Layout, SensorState};
use crate::update::{self, relative_pose, zero_velocity, Linearization, UpdateKind, UpdateReport};
use crate::Error;
#[cfg(test)]
use crate::RelativePose;
use nalgebra::{SMatrix, SVector, Vector3};

/// Filter for one pose sensor and an IMU, with the two clones relative poses need.
pub type PoseImuEkf<T> = Ekf<T, 1, 2, 34>;
/// Filter for two sensors (e.g. LiDAR and camera) and an IMU, with four clones.
pub type JointEkf<T> = Ekf<T, 2, 4, 53>;

/// Filter tuning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FilterConfig<T: Scalar> {
    /// IMU noise densities.
    pub imu_noise: ImuNoise<T>,
    /// Chi-square gate of every update.
    pub gate: Confidence,
    /// Largest accepted spacing of IMU samples (and extrapolation beyond the last one), ns.
    pub max_imu_gap_ns: u64,
    /// Health monitor tuning.
    pub health: HealthConfig<T>,
    /// Zero-velocity update: 1-sigma of "not moving", m/s.
    pub zero_velocity_sigma: T,
}

impl<T: Scalar> FilterConfig<T> {
    /// Defaults around the given IMU noise.
    pub fn new(imu_noise: ImuNoise<T>) -> Self {
        Self {
            imu_noise,
            gate: Confidence::P999,
            max_imu_gap_ns: 50_000_000,
            health: HealthConfig::default(),
            zero_velocity_sigma: T::lit(0.01),
        }
    }
}

/// The error-state EKF.
#[derive(Clone, Debug)]
pub struct Ekf<T: Scalar, const S: usize, const C: usize, const N: usize> {
    config: FilterConfig<T>,
    time_ns: u64,
    last_imu: Option<ImuSample<T>>,
    imu: ImuState<T>,
    sensors: [SensorState<T>; S],
    prior_sigma: [[T; 7]; S],
    clones: [Option<CloneState<T>>; C],
    anchors: [Option<usize>; S],
    /// Covariance; its IMU-to-rest block `P_IX` lags by `pending_transition`.
    cov: SMatrix<T, N, N>,
    /// Product of the IMU transitions since `P_IX` was last brought up to date: static
    /// blocks only change through it, so it is applied once per update, not per sample.
    pending_transition: SMatrix<T, 15, 15>,
    health: HealthMonitor<T, S>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize> Ekf<T, S, C, N> {
    const LAYOUT_OK: () = assert!(N == Layout::<S, C>::DIM, "N must be 15 + 7 S + 6 C");

    /// A filter at the prior `init`; time starts at the first IMU sample.
    pub fn new(config: &FilterConfig<T>, init: &InitialState<T, S>) -> Result<Self, Error> {
        let () = Self::LAYOUT_OK;
        if !init.is_valid() || !config.imu_noise.is_valid() {
            return Err(Error::InvalidConfig);
        }
        let mut cov = SMatrix::<T, N, N>::zeros();
        let mut set = |b: Block, sigma: T| {
            for i in b.idx..b.end() {
                cov[(i, i)] = sigma * sigma;
            }
        };
        set(imu::ORIENTATION, init.sigma_orientation);
        set(imu::POSITION, init.sigma_position);
        set(imu::VELOCITY, init.sigma_velocity);
        set(imu::GYRO_BIAS, init.sigma_gyro_bias);
        set(imu::ACCEL_BIAS, init.sigma_accel_bias);
        let mut prior_sigma = [[T::zero(); 7]; S];
        for (s, p) in init.sensors.iter().enumerate() {
            set(Layout::<S, C>::extrinsic_rotation(s), p.sigma_rotation);
            set(
                Layout::<S, C>::extrinsic_translation(s),
                p.sigma_translation,
            );
            set(Layout::<S, C>::time_offset(s), p.sigma_time_offset);
            let r = p.sigma_rotation;
            let t = p.sigma_translation;
            prior_sigma[s] = [r, r, r, t, t, t, p.sigma_time_offset];
        }
        Ok(Self {
            config: *config,
            time_ns: 0,
            last_imu: None,
            imu: init.imu,
            sensors: core::array::from_fn(|s| init.sensors[s].state),
            prior_sigma,
            clones: [None; C],
            anchors: [None; S],
            cov,
            pending_transition: SMatrix::identity(),
            health: HealthMonitor::new(config.health),
        })
    }

    // ----- read access -------------------------------------------------------------------

    /// Filter time, ns (IMU clock). Zero before the first IMU sample.
    pub fn time_ns(&self) -> u64 {
        self.time_ns
    }

    /// Current IMU state.
    pub fn imu(&self) -> &ImuState<T> {
        &self.imu
    }

    /// Calibration state of sensor `s`.
    pub fn sensor(&self, s: usize) -> Option<&SensorState<T>> {
        self.sensors.get(s)
    }

    /// Extrinsic `T_I_S` of sensor `s` (identity for an unknown sensor).
    pub fn extrinsic(&self, s: usize) -> Pose<T> {
        self.sensors.get(s).map(|x| x.extrinsic).unwrap_or_default()
    }

    /// Time offset `t_d` of sensor `s`, seconds.
    pub fn time_offset(&self, s: usize) -> T {
        self.sensors
            .get(s)
            .map(|x| x.time_offset)
            .unwrap_or_default()
    }

    /// 1-sigma of the extrinsic of sensor `s`: (rotation axes, rad; translation, m).
    pub fn extrinsic_sigma(&self, s: usize) -> (Vector3<T>, Vector3<T>) {
        if s >= S {
            return (Vector3::zeros(), Vector3::zeros());
        }
        let r = Layout::<S, C>::extrinsic_rotation(s).idx;
        let t = Layout::<S, C>::extrinsic_translation(s).idx;
        let sd = |i: usize| self.cov[(i, i)].max(T::zero()).sqrt();
        (
            Vector3::new(sd(r), sd(r + 1), sd(r + 2)),
            Vector3::new(sd(t), sd(t + 1), sd(t + 2)),
        )
    }

    /// 1-sigma of the time offset of sensor `s`, seconds.
    pub fn time_offset_sigma(&self, s: usize) -> T {
        if s >= S {
            return T::zero();
        }
        let i = Layout::<S, C>::time_offset(s).idx;
        self.cov[(i, i)].max(T::zero()).sqrt()
    }

    /// 6x6 covariance of the extrinsic of sensor `s` (`[rotation; translation]`).
    pub fn extrinsic_covariance(&self, s: usize) -> SMatrix<T, 6, 6> {
        if s >= S {
            return SMatrix::zeros();
        }
        let b = Layout::<S, C>::extrinsic(s).idx;
        self.cov.fixed_view::<6, 6>(b, b).clone_owned()
    }

    /// Per-DoF excitation of sensor `s`: `1 - sigma / sigma_prior` for rotation x, y, z,
    /// translation x, y, z and time offset (0 = nothing learned, -> 1 = well observed).
    pub fn excitation(&self, s: usize) -> [T; 7] {
        let mut out = [T::zero(); 7];
        if s >= S {
            return out;
        }
        let base = Layout::<S, C>::extrinsic_rotation(s).idx;
        for (k, o) in out.iter_mut().enumerate() {
            let prior = self.prior_sigma[s][k];
            if prior > T::zero() {
                let sd = self.cov[(base + k, base + k)].max(T::zero()).sqrt();
                *o = (T::one() - sd / prior).max(T::zero());
            }
        }
        out
    }

    /// The whole error-state covariance (with the IMU cross-covariances brought up to date).
    pub fn covariance(&self) -> SMatrix<T, N, N> {
        let mut cov = self.cov;
        Self::apply_pending(&mut cov, &self.pending_transition);
        cov
    }

    /// `P_IX <- Phi_acc P_IX` for every column of the static and clone blocks.
    fn apply_pending(cov: &mut SMatrix<T, N, N>, phi: &SMatrix<T, 15, 15>) {
        for j in imu::DIM..N {
            let col = propagate::transition_mul(phi, &cov.fixed_view::<15, 1>(0, j).clone_owned());
            cov.fixed_view_mut::<15, 1>(0, j).copy_from(&col);
            cov.fixed_view_mut::<1, 15>(j, 0)
                .copy_from(&col.transpose());
        }
    }

    /// Brings `P_IX` up to date (before anything reads or changes it).
    fn flush_transition(&mut self) {
        if self.pending_transition != SMatrix::<T, 15, 15>::identity() {
            Self::apply_pending(&mut self.cov, &self.pending_transition);
            self.pending_transition = SMatrix::identity();
        }
    }

    /// The health monitor.
    pub fn health(&self) -> &HealthMonitor<T, S> {
        &self.health
    }

    /// The configuration.
    pub fn config(&self) -> &FilterConfig<T> {
        &self.config
    }

    // ----- propagation -------------------------------------------------------------------

    /// Feeds one IMU sample: propagates to its stamp with the previous sample held, then holds
    /// this one. The first sample only sets the filter time.
    pub fn propagate(&mut self, sample: &ImuSample<T>) -> Result<(), Error> {
        sample.validate()?;
        let Some(last) = self.last_imu else {
            self.time_ns = sample.stamp_ns;
            self.last_imu = Some(*sample);
            return Ok(());
        };
        if sample.stamp_ns < self.time_ns || sample.stamp_ns <= last.stamp_ns {
            return Err(Error::TimeWentBackwards {
                filter_ns: self.time_ns,
                stamp_ns: sample.stamp_ns,
            });
        }
        let gap = sample.stamp_ns - last.stamp_ns;
        if gap > self.config.max_imu_gap_ns {
            return Err(Error::ImuGap { gap_ns: gap });
        }
        self.advance_to(sample.stamp_ns)?;
        self.last_imu = Some(*sample);
        Ok(())
    }

    /// Propagates state and covariance to `t_ns` with the held sample. Only the IMU block
    /// changes now, `P_II <- Phi P_II Phi^T + Q` with the structured product; `P_IX <- Phi
    /// P_IX` is deferred by accumulating `Phi` (see `flush_transition`).
    fn advance_to(&mut self, t_ns: u64) -> Result<(), Error> {
        let last = self.last_imu.ok_or(Error::NotInitialized)?;
        if t_ns < self.time_ns {
            return Err(Error::TimeWentBackwards {
                filter_ns: self.time_ns,
                stamp_ns: t_ns,
            });
        }
        if t_ns == self.time_ns {
            return Ok(());
        }
        let dt = T::lit((t_ns - self.time_ns) as f64 * 1e-9);
        let step = propagate::step(
            &self.imu,
            &last.gyro,
            &last.accel,
            dt,
            &self.config.imu_noise,
        );
        let phi = step.transition;
        let p_ii = self.cov.fixed_view::<15, 15>(0, 0).clone_owned();
        let phi_p = propagate::transition_mul(&phi, &p_ii);
        let new_ii = propagate::transition_mul(&phi, &phi_p.transpose()).transpose() + step.noise;
        let new_ii = (new_ii + new_ii.transpose()) * T::lit(0.5);
        let pending = propagate::transition_mul(&phi, &self.pending_transition);
        let finite = step.state.is_finite()
            && new_ii.iter().all(|x| x.is_finite())
            && pending.iter().all(|x| x.is_finite());
        if !finite {
            return Err(Error::DivergentUpdate);
        }
        self.cov.fixed_view_mut::<15, 15>(0, 0).copy_from(&new_ii);
        self.pending_transition = pending;
        self.imu = step.state;
        self.time_ns = t_ns;
        Ok(())
    }

    // ----- clones ------------------------------------------------------------------------

    /// IMU time of a measurement of sensor `s` stamped `stamp_ns`: `stamp + t_d`.
    fn imu_time(&self, s: usize, stamp_ns: u64) -> u64 {
        // Offset rounded to ns and added in integer space: stamps near 1.7e18 ns have no
        // sub-microsecond resolution as floats.
        let td = libm::round(self.sensors[s].time_offset.to_f64() * 1e9) as i64;
        if td >= 0 {
            stamp_ns.saturating_add(td as u64)
        } else {
            stamp_ns.saturating_sub(td.unsigned_abs())
        }
    }

    /// Chooses the slot for a new clone: a free one, else the oldest that no sensor anchors.
    fn free_slot(&self) -> Result<usize, Error> {
        if let Some(i) = self.clones.iter().position(Option::is_none) {
            return Ok(i);
        }
        (0..C)
            .filter(|i| !self.anchors.contains(&Some(*i)))
            .min_by_key(|i| self.clones[*i].map(|c| c.stamp_ns).unwrap_or(0))
            .ok_or(Error::CloneWindowFull)
    }

    /// Removes clone `slot` from the state (marginalisation: its rows and columns go).
    fn drop_clone(&mut self, slot: usize) {
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
    fn clone_imu_pose(&mut self, s: usize, slot: usize, stamp_ns: u64) {
        self.flush_transition();
        self.drop_clone(slot);
        let w = self
            .last_imu
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
        });
    }

    /// Starts an odometry segment of sensor `s`: clones the IMU pose at `stamp_ns + t_d` as
    /// the start of the next relative measurement.
    pub fn anchor(&mut self, s: usize, stamp_ns: u64) -> Result<(), Error> {
        if s >= S {
            return Err(Error::UnknownSensor);
        }
        let mut draft = self.clone();
        let slot = draft.prepare_clone(s, stamp_ns)?;
        if let Some(old) = draft.anchors[s] {
            draft.drop_clone(old);
        }
        draft.clone_imu_pose(s, slot, stamp_ns);
        draft.anchors[s] = Some(slot);
        *self = draft;
        Ok(())
    }

    /// Propagates to the measurement time and picks a clone slot.
    fn prepare_clone(&mut self, s: usize, stamp_ns: u64) -> Result<usize, Error> {
        let last = self.last_imu.ok_or(Error::NotInitialized)?;
        let t = self.imu_time(s, stamp_ns);
        if t < self.time_ns {
            return Err(Error::TimeWentBackwards {
                filter_ns: self.time_ns,
                stamp_ns: t,
            });
        }
        if t - last.stamp_ns > self.config.max_imu_gap_ns {
            return Err(Error::ImuGap {
                gap_ns: t - last.stamp_ns,
            });
        }
        let slot = self.free_slot()?;
        self.advance_to(t)?;
        Ok(slot)
    }

    // ----- updates -----------------------------------------------------------------------

    /// Fuses a relative pose of sensor `s` (eq. 3.19-3.21). Its start must be the sensor's
    /// anchor (see [`Ekf::anchor`]); its end becomes the new anchor, even when the gate
    /// rejects the measurement, so the odometry chain continues.
    pub fn update_relative_pose(
        &mut self,
        s: usize,
        meas: &relative_pose::RelativePose<T>,
    ) -> Result<UpdateReport<T>, Error> {
        if s >= S {
            return Err(Error::UnknownSensor);
        }
        if !meas.is_valid() {
            return Err(if meas.delta.is_finite() {
                Error::InvalidConfig
            } else {
                Error::NonFinite
            });
        }
        let from_slot = self.anchors[s].ok_or(Error::NoAnchor)?;
        let anchor_stamp = self.clones[from_slot].map(|c| c.stamp_ns).unwrap_or(0);
        if anchor_stamp != meas.stamp_from_ns {
            return Err(if meas.stamp_from_ns < anchor_stamp {
                Error::OlderThanWindow
            } else {
                Error::NoAnchor
            });
        }
        let mut draft = self.clone();
        let to_slot = draft.prepare_clone(s, meas.stamp_to_ns)?;
        draft.clone_imu_pose(s, to_slot, meas.stamp_to_ns);
        let from = draft.clones[from_slot].ok_or(Error::OlderThanWindow)?;
        let to = draft.clones[to_slot].ok_or(Error::OlderThanWindow)?;
        let lin = relative_pose::linearize(
            &from.pose,
            &to.pose,
            &draft.sensors[s].extrinsic,
            &meas.delta,
        );
        let mut h = SMatrix::<T, 6, N>::zeros();
        let ext = Layout::<S, C>::extrinsic(s).idx;
        let cf = Layout::<S, C>::clone_orientation(from_slot).idx;
        let ct = Layout::<S, C>::clone_orientation(to_slot).idx;
        h.fixed_view_mut::<6, 6>(0, cf).copy_from(&lin.clone_from);
        h.fixed_view_mut::<6, 6>(0, ct).copy_from(&lin.clone_to);
        h.fixed_view_mut::<6, 6>(0, ext).copy_from(&lin.extrinsic);
        let linearization = Linearization {
            residual: lin.residual,
            jacobian: h,
            noise: meas.covariance,
        };
        let report = draft.fuse(
            UpdateKind::RelativePose,
            s,
            meas.stamp_to_ns,
            &linearization,
            Some(&lin.extrinsic),
        )?;
        draft.drop_clone(from_slot);
        draft.anchors[s] = Some(to_slot);
        *self = draft;
        Ok(report)
    }

    /// Zero-velocity update with the latest IMU sample (the caller decided the platform is at
    /// rest).
    pub fn update_zero_velocity(&mut self) -> Result<UpdateReport<T>, Error> {
        let sample = self.last_imu.ok_or(Error::NotInitialized)?;
        let dt = T::lit(2.5e-3);
        let n = &self.config.imu_noise;
        let noise = zero_velocity::noise(
            n.gyro_noise_density / dt.sqrt(),
            n.accel_noise_density / dt.sqrt(),
            self.config.zero_velocity_sigma,
        );
        let (residual, h_imu) = zero_velocity::linearize(&self.imu, &sample);
        let mut h = SMatrix::<T, { zero_velocity::DIM }, N>::zeros();
        h.fixed_view_mut::<{ zero_velocity::DIM }, 15>(0, 0)
            .copy_from(&h_imu);
        let lin = Linearization {
            residual,
            jacobian: h,
            noise,
        };
        let mut draft = self.clone();
        let report = draft.fuse(UpdateKind::ZeroVelocity, 0, sample.stamp_ns, &lin, None)?;
        *self = draft;
        Ok(report)
    }

    /// The shared Kalman step plus bookkeeping: applies the correction, records NIS and
    /// feeds the health monitor (which may inflate the extrinsic covariance).
    fn fuse<const M: usize>(
        &mut self,
        kind: UpdateKind,
        s: usize,
        stamp_ns: u64,
        lin: &Linearization<T, M, N>,
        extrinsic_jacobian: Option<&SMatrix<T, M, 6>>,
    ) -> Result<UpdateReport<T>, Error> {
        self.flush_transition();
        let step = update::kalman_step(&self.cov, lin, self.config.gate)?;
        if step.accepted {
            self.apply_correction(&step.correction)?;
            self.cov = step.covariance;
        }
        let innovation = extrinsic_jacobian.map(|h_e| {
            let info = h_e.transpose() * step.innovation_inverse * h_e;
            let score = h_e.transpose() * step.weighted_residual;
            ExtrinsicInnovation {
                rotation_info: info.fixed_view::<3, 3>(0, 0).clone_owned(),
                rotation_score: score.fixed_rows::<3>(0).clone_owned(),
                translation_info: info.fixed_view::<3, 3>(3, 3).clone_owned(),
                translation_score: score.fixed_rows::<3>(3).clone_owned(),
            }
        });
        let event =
            self.health
                .record(s, stamp_ns, step.nis, M, step.accepted, innovation.as_ref());
        if let Some(event) = event {
            self.react_to(&event);
        }
        Ok(UpdateReport {
            kind,
            sensor: s,
            stamp_ns,
            dof: M,
            nis: step.nis,
            threshold: step.threshold,
            accepted: step.accepted,
            event,
        })
    }

    /// A detected step: move the extrinsic by the detector's maximum-likelihood estimate of
    /// the step (it holds the information of the updates since the knock, which the
    /// converged filter could not absorb) and open the block by that estimate's covariance
    /// plus a floor, so the filter re-converges from there.
    fn react_to(&mut self, event: &HealthEvent<T>) {
        let (sensor, block, step, cov, floor) = match *event {
            HealthEvent::RotationStep {
                sensor,
                step,
                step_covariance,
                ..
            } => (
                sensor,
                Layout::<S, C>::extrinsic_rotation(sensor),
                step,
                step_covariance,
                self.config.health.inflate_rotation,
            ),
            HealthEvent::TranslationStep {
                sensor,
                step,
                step_covariance,
                ..
            } => (
                sensor,
                Layout::<S, C>::extrinsic_translation(sensor),
                step,
                step_covariance,
                self.config.health.inflate_translation,
            ),
        };
        let Some(x) = self.sensors.get_mut(sensor) else {
            return;
        };
        if block == Layout::<S, C>::extrinsic_rotation(sensor) {
            x.extrinsic = x.extrinsic.boxplus(&step, &Vector3::zeros());
        } else {
            x.extrinsic.translation += step;
        }
        let mut p = self.cov.fixed_view_mut::<3, 3>(block.idx, block.idx);
        p += cov;
        self.inflate(block, floor);
    }

    /// Adds `sigma^2` to the diagonal of block `b` (keeps the covariance positive definite).
    fn inflate(&mut self, b: Block, sigma: T) {
        for i in b.idx..b.end() {
            self.cov[(i, i)] += sigma * sigma;
        }
    }

    /// Opens sensor `s`'s extrinsic again by adding the given sigmas (rad, m), e.g. after a
    /// known re-mount.
    pub fn inflate_extrinsic(
        &mut self,
        s: usize,
        sigma_rotation: T,
        sigma_translation: T,
    ) -> Result<(), Error> {
        if s >= S {
            return Err(Error::UnknownSensor);
        }
        if !(sigma_rotation >= T::zero() && sigma_translation >= T::zero()) {
            return Err(Error::InvalidConfig);
        }
        self.inflate(Layout::<S, C>::extrinsic_rotation(s), sigma_rotation);
        self.inflate(Layout::<S, C>::extrinsic_translation(s), sigma_translation);
        Ok(())
    }

    /// `x <- x ⊞ dx` over every block.
    fn apply_correction(&mut self, dx: &SVector<T, N>) -> Result<(), Error> {
        let v3 = |b: Block| Vector3::new(dx[b.idx], dx[b.idx + 1], dx[b.idx + 2]);
        let imu_dx = dx.fixed_rows::<15>(0).clone_owned();
        let imu_state = propagate::boxplus(&self.imu, &imu_dx);
        let mut sensors = self.sensors;
        for (s, sensor) in sensors.iter_mut().enumerate() {
            sensor.extrinsic = sensor.extrinsic.boxplus(
                &v3(Layout::<S, C>::extrinsic_rotation(s)),
                &v3(Layout::<S, C>::extrinsic_translation(s)),
            );
            sensor.time_offset += dx[Layout::<S, C>::time_offset(s).idx];
        }
        let mut clones = self.clones;
        for (c, slot) in clones.iter_mut().enumerate() {
            if let Some(clone) = slot {
                clone.pose = clone.pose.boxplus(
                    &v3(Layout::<S, C>::clone_orientation(c)),
                    &v3(Layout::<S, C>::clone_position(c)),
                );
            }
        }
        let finite = imu_state.is_finite()
            && sensors
                .iter()
                .all(|x| x.extrinsic.is_finite() && x.time_offset.is_finite())
            && clones.iter().flatten().all(|c| c.pose.is_finite());
        if !finite {
            return Err(Error::DivergentUpdate);
        }
        self.imu = imu_state;
        self.sensors = sensors;
        self.clones = clones;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lie::log;
    use crate::testing::assert_mat_close;
    use nalgebra::{SVector, UnitQuaternion};

    const T0: u64 = 1_700_000_000_000_000_000;

    /// A filter spinning and accelerating with the given time-offset prior.
    fn moving_filter(time_offset: f64) -> PoseImuEkf<f64> {
        let mut init = InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81))
            .expect("gravity")
            .with_time_offset(0, time_offset, 0.01);
        init.imu.velocity = Vector3::new(0.7, -0.3, 0.2);
        init.imu.rotation = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
        let mut ekf = PoseImuEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior");
        for k in 0..=96u64 {
            ekf.propagate(&ImuSample {
                stamp_ns: T0 + k * 2_500_000,
                gyro: Vector3::new(1.2, -0.8, 0.5),
                accel: Vector3::new(0.5, 1.0, 9.0),
            })
            .expect("sample");
        }
        ekf
    }

    #[test]
    fn clone_time_offset_jacobian_matches_central_differences() {
        // Given a moving IMU and a measurement stamped between two IMU samples
        let stamp = T0 + 240_000_000 + 1_234_567;
        let td = 0.004;
        let h = 1e-4;
        // When the pose is cloned at stamp + t_d for t_d +- h
        let clone_pose = |td: f64| {
            let mut ekf = moving_filter(td);
            ekf.anchor(0, stamp).expect("anchor");
            ekf.imu().pose()
        };
        let (plus, minus) = (clone_pose(td + h), clone_pose(td - h));
        let mut numeric = SVector::<f64, 6>::zeros();
        numeric
            .fixed_rows_mut::<3>(0)
            .copy_from(&(log(&(minus.rotation.inverse() * plus.rotation)) / (2.0 * h)));
        numeric
            .fixed_rows_mut::<3>(3)
            .copy_from(&((plus.translation - minus.translation) / (2.0 * h)));
        // Then the clone's covariance with t_d is d(clone)/d(t_d) * var(t_d)
        let mut ekf = moving_filter(td);
        ekf.anchor(0, stamp).expect("anchor");
        let c = Layout::<1, 2>::clone_orientation(0).idx;
        let t = Layout::<1, 2>::time_offset(0).idx;
        let var = ekf.covariance()[(t, t)];
        let analytic = ekf.covariance().fixed_view::<6, 1>(c, t).clone_owned() / var;
        // The midpoint integrator's position is consistent with its velocity to O(|w| |a| dt^2)
        // (~1e-4 m/s here), which bounds the agreement.
        assert_mat_close(&analytic, &numeric, 2e-4);
    }

    #[test]
    fn covariance_stays_symmetric_and_positive_through_updates() {
        let mut ekf = moving_filter(0.0);
        let t = ekf.time_ns();
        ekf.anchor(0, t).expect("anchor");
        for k in 1..=20u64 {
            let stamp = t + k * 100_000_000;
            for j in 1..=32u64 {
                ekf.propagate(&ImuSample {
                    stamp_ns: stamp - 100_000_000 + j * 2_500_000,
                    gyro: Vector3::new(1.2, -0.8, 0.5),
                    accel: Vector3::new(0.5, 1.0, 9.0),
                })
                .expect("sample");
            }
            let m =
                RelativePose::with_sigmas(stamp - 100_000_000, stamp, Pose::identity(), 0.5, 0.5);
            ekf.update_relative_pose(0, &m).expect("update");
        }
        let p = ekf.covariance();
        assert_mat_close(
            &(p - p.transpose()),
            &SMatrix::<f64, 34, 34>::zeros(),
            1e-12,
        );
        let eig = p.symmetric_eigenvalues();
        assert!(
            eig.min() > -1e-12 * eig.max(),
            "negative eigenvalue {} (largest {})",
            eig.min(),
            eig.max()
        );
    }
}
