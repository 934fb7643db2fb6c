//! Measurement updates of the filter: relative pose, zero velocity, and the bookkeeping
//! every update shares (correction, NIS record, health monitor and its reaction).

use super::undo::{ColumnsUndo, StepUndo};
use super::yaw_gauge;
use super::Ekf;
use crate::chi2;
use crate::health::{ExtrinsicInnovation, HealthEvent};
use crate::ids::{FrameId, SensorId};
use crate::lie::Pose;
use crate::propagate;
use crate::scalar::Scalar;
use crate::state::{imu, Block, CloneState, ImuState, Layout, SensorState};
use crate::update::{
    relative_pose, zero_velocity, Gain, Measurement, SparseJacobian, UpdateKind, UpdateReport,
};
use crate::Error;
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// Fuses a relative pose of sensor `s` (eq. 3.19-3.21). Its start must be the sensor's
    /// anchor (see [`Ekf::anchor`]); its end becomes the new anchor, even when the gate
    /// rejects the measurement, so the odometry chain continues.
    pub fn update_relative_pose(
        &mut self,
        s: SensorId,
        meas: &relative_pose::RelativePose<T>,
    ) -> Result<UpdateReport<T>, Error> {
        let i = s.checked(S)?;
        if !meas.is_valid() {
            return Err(if meas.delta.is_finite() {
                Error::InvalidConfig
            } else {
                Error::NonFinite
            });
        }
        let from_slot = self.anchors[i].ok_or(Error::NoAnchor)?;
        let anchor_stamp = self.clones[from_slot].map(|c| c.stamp_ns).unwrap_or(0);
        if anchor_stamp != meas.stamp_from_ns {
            return Err(if meas.stamp_from_ns < anchor_stamp {
                Error::OlderThanWindow
            } else {
                Error::NoAnchor
            });
        }
        let t = self.reachable_imu_time(s, meas.stamp_to_ns)?;
        let to_slot = self.free_slot()?;
        let step = StepUndo::save(self);
        let report = self
            .advance_out_of_line(t)
            .and_then(|()| self.clone_and_fuse(s, from_slot, to_slot, meas));
        if report.is_err() {
            step.restore(self);
        }
        let report = report?;
        self.drop_clone(from_slot);
        self.anchors[i] = Some(to_slot);
        Ok(report)
    }

    /// The propagation in its own stack frame: its temporaries and an update's never share
    /// one frame (the stack depth is the larger of the two, not their sum).
    #[inline(never)]
    pub(super) fn advance_out_of_line(&mut self, t: u64) -> Result<(), Error> {
        self.advance_to(t)
    }

    /// After the propagation: clones the IMU pose into `to_slot` and fuses the relative
    /// pose; on error puts back the covariance columns the two wrote.
    #[inline(never)]
    fn clone_and_fuse(
        &mut self,
        s: SensorId,
        from_slot: usize,
        to_slot: usize,
        meas: &relative_pose::RelativePose<T>,
    ) -> Result<UpdateReport<T>, Error> {
        let mut columns = ColumnsUndo::new();
        columns.save(self, Some(to_slot));
        self.clone_imu_pose(s, to_slot, meas.stamp_to_ns);
        let report = self.fuse_relative_pose(s, from_slot, to_slot, meas);
        if report.is_err() {
            columns.restore(self);
        }
        report
    }

    /// The relative-pose update between two clones; changes the filter only on success.
    fn fuse_relative_pose(
        &mut self,
        s: SensorId,
        from_slot: usize,
        to_slot: usize,
        meas: &relative_pose::RelativePose<T>,
    ) -> Result<UpdateReport<T>, Error> {
        let from = self.clones[from_slot].ok_or(Error::OlderThanWindow)?;
        let to = self.clones[to_slot].ok_or(Error::OlderThanWindow)?;
        let lin = relative_pose::linearize(
            &from.pose,
            &to.pose,
            &self.sensors[s.index()].extrinsic,
            &meas.delta,
        );
        let (mut h_from, mut h_to) = (lin.clone_from, lin.clone_to);
        if self.config.constrain_yaw {
            yaw_gauge::constrain_relative_jacobian(
                &mut h_from,
                &mut h_to,
                &from.yaw_direction,
                &to.yaw_direction,
            );
        }
        let mut jacobian = SparseJacobian::<T, 6, 18>::zeros();
        jacobian.set(0, Layout::<S, C>::clone_orientation(from_slot).idx, &h_from);
        jacobian.set(6, Layout::<S, C>::clone_orientation(to_slot).idx, &h_to);
        jacobian.set(12, Layout::<S, C>::extrinsic(s).idx, &lin.extrinsic);
        let measurement = Measurement {
            residual: lin.residual,
            jacobian,
            noise: meas.covariance,
        };
        self.fuse(
            UpdateKind::RelativePose,
            Some(s),
            meas.stamp_to_ns,
            &measurement,
            Some(&lin.extrinsic),
            // The knock test's projection only where the detector runs (the vehicle monitor).
            (self.config.health.jump_window_updates > 0).then_some(&lin.extrinsic_end_rotation),
        )
    }

    /// Zero-velocity update with the IMU reading at the filter time (the caller decided the
    /// platform is at rest). The reading's white noise is that of one sample at the stream's
    /// own period ([`Ekf::imu_period_ns`]; `Error::NotInitialized` before the second
    /// sample). It belongs to no sensor: its NIS enters no sensor's health window.
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
        let mut jacobian = SparseJacobian::<T, { zero_velocity::DIM }, 15>::zeros();
        jacobian.set(0, imu::ORIENTATION.idx, &h_imu);
        let measurement = Measurement {
            residual,
            jacobian,
            noise,
        };
        self.fuse(
            UpdateKind::ZeroVelocity,
            None,
            sample.stamp_ns,
            &measurement,
            None,
            None,
        )
    }

    /// The shared update core plus bookkeeping: applies the correction, records NIS and
    /// feeds the health monitor (which may inflate the extrinsic covariance). On error the
    /// state is unchanged (up to bringing `P_IX` up to date, which changes no value).
    pub(super) fn fuse<const M: usize, const L: usize>(
        &mut self,
        kind: UpdateKind,
        sensor: Option<SensorId>,
        stamp_ns: u64,
        meas: &Measurement<T, M, L>,
        extrinsic_jacobian: Option<&SMatrix<T, M, 6>>,
        end_rotation: Option<&SMatrix<T, M, 3>>,
    ) -> Result<UpdateReport<T>, Error> {
        self.flush_transition();
        let (holds, count) = self.holds();
        let threshold = chi2::quantile::<T>(M, self.config.gate);
        let mut gain = Gain::empty();
        gain.compute_into(&self.cov, meas, threshold, &holds[..count])?;
        // A sensor with a pending knock candidate is tested, not fused (`health` module).
        let held_out = sensor.is_some_and(|s| self.health.holds_out(s));
        if held_out {
            gain.accepted = false;
        }
        let project = |gain: &Gain<T, M, N>, end_rotation| {
            sensor.zip(extrinsic_jacobian).map(|(s, h_e)| {
                let b = Layout::<S, C>::extrinsic_rotation(s);
                extrinsic_innovation(
                    (
                        &h_e.fixed_columns::<3>(0).clone_owned(),
                        &h_e.fixed_columns::<3>(3).clone_owned(),
                        end_rotation,
                    ),
                    &gain.innovation_inverse,
                    &gain.weighted_residual,
                    self.cov.fixed_view::<3, 3>(b.idx, b.idx).clone_owned(),
                )
            })
        };
        let mut innovation = project(&gain, end_rotation);
        let weight = match kind {
            UpdateKind::RelativePose => {
                relative_pose::student_t_weight(gain.nis, M, self.config.health.odometry_dof)
            }
            _ => T::one(),
        };
        if weight < T::one() {
            self.reweight(&mut gain, meas, weight, &holds[..count])?;
            // The step detectors see the weighted innovation; the jump test (an outlying
            // increment read as a knock) keeps the stated noise.
            innovation = project(&gain, None)
                .zip(innovation)
                .map(|(w, n)| ExtrinsicInnovation {
                    jump_info: n.jump_info,
                    jump_score: n.jump_score,
                    ..w
                });
        }
        self.correct(&gain)?;
        Ok(self.record_update(
            kind,
            sensor,
            stamp_ns,
            (gain.nis, M, gain.threshold),
            (gain.accepted, held_out),
            innovation.as_ref(),
        ))
    }

    /// A relative pose's Student-t reweighting (`HealthConfig::odometry_dof`): `gain`, computed
    /// at the stated noise, is computed again with the noise divided by `weight` (< 1). What
    /// the gate decided at the stated noise stands (a rejected or held-out update gets only
    /// `S^-1` and `S^-1 r` at the weighted noise, for the step detectors, and is not fused),
    /// and so do its NIS and threshold (the NIS window and the report).
    fn reweight<const M: usize, const L: usize>(
        &self,
        gain: &mut Gain<T, M, N>,
        meas: &Measurement<T, M, L>,
        weight: T,
        holds: &[crate::update::Hold<T>],
    ) -> Result<(), Error> {
        let (nis, threshold, accepted) = (gain.nis, gain.threshold, gain.accepted);
        let weighted = Measurement {
            noise: meas.noise / weight,
            ..*meas
        };
        // An infinite threshold forms the gain; zero stops after `S^-1 r` (NIS > 0 here).
        let pass = if accepted {
            T::lit(f64::INFINITY)
        } else {
            T::zero()
        };
        gain.compute_into(&self.cov, &weighted, pass, holds)?;
        gain.nis = nis;
        gain.threshold = threshold;
        gain.accepted = accepted;
        Ok(())
    }

    /// Applies a computed update (state and covariance) if the gate accepted it; the state
    /// is checked first, so an error changes nothing.
    pub(super) fn correct<const M: usize>(&mut self, gain: &Gain<T, M, N>) -> Result<(), Error> {
        if !gain.accepted {
            return Ok(());
        }
        let corrected = self.corrected(&gain.correction)?;
        gain.apply_to(&mut self.cov);
        self.commit(corrected);
        Ok(())
    }

    /// Records an update's NIS `(nis, dof, threshold)` with the health monitor of its
    /// sensor (none for a sensor-less update), reacts to what it detects, and builds the
    /// report.
    pub(super) fn record_update(
        &mut self,
        kind: UpdateKind,
        sensor: Option<SensorId>,
        stamp_ns: u64,
        (nis, dof, threshold): (T, usize, T),
        (accepted, held_out): (bool, bool),
        innovation: Option<&ExtrinsicInnovation<T>>,
    ) -> UpdateReport<T> {
        let event = sensor.and_then(|s| {
            // The step detectors see innovations only once the extrinsic has converged, and
            // after a reaction only once it has re-converged.
            let (sr, st) = self.extrinsic_sigma(s);
            let armed = self.health.armed(s, sr.max(), st.max());
            let innovation = innovation.filter(|_| armed);
            let event = self
                .health
                .record(s, stamp_ns, nis, dof, accepted, innovation);
            if event.is_some() {
                self.health.hold_until_reconverged(s, sr.max(), st.max());
            }
            event
        });
        if let Some(event) = event {
            self.react_to(&event);
        }
        UpdateReport {
            kind,
            sensor,
            stamp_ns,
            dof,
            nis,
            threshold,
            accepted,
            held_out,
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
        let Some(x) = self.sensors.get_mut(sensor.index()) else {
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
        s: SensorId,
        sigma_rotation: T,
        sigma_translation: T,
    ) -> Result<(), Error> {
        s.checked(S)?;
        if !(sigma_rotation >= T::zero() && sigma_translation >= T::zero()) {
            return Err(Error::InvalidConfig);
        }
        self.inflate(Layout::<S, C>::extrinsic_rotation(s), sigma_rotation);
        self.inflate(Layout::<S, C>::extrinsic_translation(s), sigma_translation);
        Ok(())
    }

    /// `x <- x ⊞ dx` over every block (the state only; the covariance is the caller's).
    #[cfg(test)]
    pub(super) fn apply_correction(&mut self, dx: &SVector<T, N>) -> Result<(), Error> {
        let corrected = self.corrected(dx)?;
        self.commit(corrected);
        Ok(())
    }

    /// `x ⊞ dx` over every block, checked finite, not yet committed.
    fn corrected(&self, dx: &SVector<T, N>) -> Result<Corrected<T, S, C, F>, Error> {
        let v3 = |b: Block| Vector3::new(dx[b.idx], dx[b.idx + 1], dx[b.idx + 2]);
        let imu_dx = dx.fixed_rows::<15>(0).clone_owned();
        let imu = propagate::boxplus(&self.imu, &imu_dx);
        let mut sensors = self.sensors;
        for (s, sensor) in SensorId::all::<S>().into_iter().zip(sensors.iter_mut()) {
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
        for (f, slot) in FrameId::all::<F>().into_iter().zip(frames.iter_mut()) {
            if let Some(pose) = slot {
                *pose = pose.boxplus(
                    &v3(Layout::<S, C>::frame_orientation(f)),
                    &v3(Layout::<S, C>::frame_position(f)),
                );
            }
        }
        let finite = imu.is_finite()
            && sensors
                .iter()
                .all(|x| x.extrinsic.is_finite() && x.time_offset.is_finite())
            && clones.iter().flatten().all(|c| c.pose.is_finite())
            && frames.iter().flatten().all(Pose::is_finite);
        if !finite {
            return Err(Error::DivergentUpdate);
        }
        Ok(Corrected {
            imu,
            sensors,
            clones,
            frames,
        })
    }

    fn commit(&mut self, x: Corrected<T, S, C, F>) {
        self.imu = x.imu;
        self.sensors = x.sensors;
        self.clones = x.clones;
        self.frames = x.frames;
    }
}

/// A corrected state, checked, waiting to be committed.
struct Corrected<T: Scalar, const S: usize, const C: usize, const F: usize> {
    imu: ImuState<T>,
    sensors: [SensorState<T>; S],
    clones: [Option<CloneState<T>>; C],
    frames: [Option<Pose<T>>; F],
}

/// The innovation of one update projected on a sensor's extrinsic (for the step detector):
/// `H_e^T S^-1 H_e` and `H_e^T S^-1 r` for the rotation and the translation block of
/// `H_e = [h_rotation h_translation]` (the off-diagonal blocks are not needed), and the same
/// for `E = end_rotation`, the Jacobian w.r.t. a rotation of the mounting at an increment's
/// end stamp only (zero where the measurement is not an increment); `rotation_covariance`
/// is the extrinsic rotation's covariance the knock test's variance includes.
pub(super) fn extrinsic_innovation<T: Scalar, const M: usize>(
    (h_rotation, h_translation, end_rotation): (
        &SMatrix<T, M, 3>,
        &SMatrix<T, M, 3>,
        Option<&SMatrix<T, M, 3>>,
    ),
    innovation_inverse: &SMatrix<T, M, M>,
    weighted_residual: &SVector<T, M>,
    rotation_covariance: Matrix3<T>,
) -> ExtrinsicInnovation<T> {
    let project = |h: &SMatrix<T, M, 3>| {
        let ht = h.transpose();
        (ht * innovation_inverse * h, ht * weighted_residual)
    };
    let (rotation_info, rotation_score) = project(h_rotation);
    let (translation_info, translation_score) = project(h_translation);
    let (jump_info, jump_score) =
        end_rotation.map_or((Matrix3::zeros(), Vector3::zeros()), project);
    ExtrinsicInnovation {
        rotation_info,
        rotation_score,
        translation_info,
        translation_score,
        jump_info,
        jump_score,
        rotation_covariance,
    }
}
