//! Measurement updates of the filter: relative pose, zero velocity, and the bookkeeping
//! every update shares (correction, NIS record, health monitor and its reaction).

use super::Ekf;
use crate::health::{ExtrinsicInnovation, HealthEvent};
use crate::lie::Pose;
use crate::propagate;
use crate::scalar::Scalar;
use crate::state::{Block, Layout};
use crate::update::{self, relative_pose, zero_velocity, Linearization, UpdateKind, UpdateReport};
use crate::Error;
use nalgebra::{SMatrix, SVector, Vector3};

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
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

    /// Zero-velocity update with the IMU reading at the filter time (the caller decided the
    /// platform is at rest). The reading's white noise is that of one sample at the stream's
    /// own period.
    pub fn update_zero_velocity(&mut self) -> Result<UpdateReport<T>, Error> {
        let sample = self.imu_now.ok_or(Error::NotInitialized)?;
        if self.imu_period_ns == 0 {
            return Err(Error::NotInitialized);
        }
        let dt = T::lit(self.imu_period_ns as f64 * 1e-9);
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
    pub(super) fn fuse<const M: usize>(
        &mut self,
        kind: UpdateKind,
        s: usize,
        stamp_ns: u64,
        lin: &Linearization<T, M, N>,
        extrinsic_jacobian: Option<&SMatrix<T, M, 6>>,
    ) -> Result<UpdateReport<T>, Error> {
        self.flush_transition();
        let (holds, count) = self.holds();
        let step = update::kalman_step(&self.cov, lin, self.config.gate, &holds[..count])?;
        if step.accepted {
            self.apply_correction(&step.correction)?;
            self.cov = step.covariance;
        }
        let innovation = extrinsic_jacobian.map(|h_e| {
            extrinsic_innovation(h_e, &step.innovation_inverse, &step.weighted_residual)
        });
        Ok(self.record_update(
            kind,
            s,
            stamp_ns,
            (step.nis, M, step.threshold),
            step.accepted,
            innovation.as_ref(),
        ))
    }

    /// Records an update's NIS `(nis, dof, threshold)` with the health monitor, reacts to
    /// what it detects, and builds the report.
    pub(super) fn record_update(
        &mut self,
        kind: UpdateKind,
        s: usize,
        stamp_ns: u64,
        (nis, dof, threshold): (T, usize, T),
        accepted: bool,
        innovation: Option<&ExtrinsicInnovation<T>>,
    ) -> UpdateReport<T> {
        // The step detectors see innovations only once the extrinsic has converged.
        let (sr, st) = self.extrinsic_sigma(s);
        let h = self.config.health;
        let armed = sr.max() < h.arm_sigma_rotation && st.max() < h.arm_sigma_translation;
        let innovation = innovation.filter(|_| armed);
        let event = self
            .health
            .record(s, stamp_ns, nis, dof, accepted, innovation);
        if let Some(event) = event {
            self.react_to(&event);
        }
        UpdateReport {
            kind,
            sensor: s,
            stamp_ns,
            dof,
            nis,
            threshold,
            accepted,
            event,
        }
    }

    /// A detected step: move the extrinsic by the detector's maximum-likelihood estimate of
    /// the step (it holds the information of the updates since the knock, which the
    /// converged filter could not absorb) and open the block by that estimate's covariance
    /// plus a floor, so the filter re-converges from there.
    pub(super) fn react_to(&mut self, event: &HealthEvent<T>) {
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
    pub(super) fn inflate(&mut self, b: Block, sigma: T) {
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
    pub(super) fn apply_correction(&mut self, dx: &SVector<T, N>) -> Result<(), Error> {
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
        let mut frames = self.frames;
        for (f, slot) in frames.iter_mut().enumerate() {
            if let Some(pose) = slot {
                *pose = pose.boxplus(
                    &v3(Layout::<S, C>::frame_orientation(f)),
                    &v3(Layout::<S, C>::frame_position(f)),
                );
            }
        }
        let finite = imu_state.is_finite()
            && sensors
                .iter()
                .all(|x| x.extrinsic.is_finite() && x.time_offset.is_finite())
            && clones.iter().flatten().all(|c| c.pose.is_finite())
            && frames.iter().flatten().all(Pose::is_finite);
        if !finite {
            return Err(Error::DivergentUpdate);
        }
        self.imu = imu_state;
        self.sensors = sensors;
        self.clones = clones;
        self.frames = frames;
        Ok(())
    }
}

/// The innovation of one update projected on a sensor's extrinsic (for the step detector):
/// `H_e^T S^-1 H_e` and `H_e^T S^-1 r`, split into rotation and translation.
pub(super) fn extrinsic_innovation<T: Scalar, const M: usize>(
    h_e: &SMatrix<T, M, 6>,
    innovation_inverse: &SMatrix<T, M, M>,
    weighted_residual: &SVector<T, M>,
) -> ExtrinsicInnovation<T> {
    let info = h_e.transpose() * innovation_inverse * h_e;
    let score = h_e.transpose() * weighted_residual;
    ExtrinsicInnovation {
        rotation_info: info.fixed_view::<3, 3>(0, 0).clone_owned(),
        rotation_score: score.fixed_rows::<3>(0).clone_owned(),
        translation_info: info.fixed_view::<3, 3>(3, 3).clone_owned(),
        translation_score: score.fixed_rows::<3>(3).clone_owned(),
    }
}
