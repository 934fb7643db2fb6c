//! The reprojection update (RepErrCal, eq. 4.2 and 4.15): the corners of a static target
//! seen in one image, through the IMU pose at the image's IMU time, the camera extrinsic
//! and the camera model.
//!
//! Every corner is linearised once, at the state the image found (the propagated prior), and
//! the corners are fused one at a time (2 rows each) against those fixed Jacobians: corner
//! `k` sees the residual `r_k - H_k dx` of the correction `dx` the corners before it have
//! accumulated, and `dx` is injected into the nominal state once, after the last corner.
//! With the linearisation point fixed this is the batch update of the stacked `2K` rows,
//! exactly (independent noise), and the sum of the sequential NIS is the stacked NIS, so the
//! gate is the batch `chi2(2 K)` test, while no `2K x N` matrix is ever formed (K is
//! unbounded, the stack is not).
//!
//! Relinearising after every corner instead (as this update once did) moves the point of
//! linearisation inside one image along directions the image cannot see (the camera
//! extrinsic against the target pose): each corner's Jacobian then comes from a different
//! state, and the filter gains information along those directions that no measurement
//! holds. From exact priors, the joint self-test's camera extrinsic ended 4 sigma off (RMS
//! over 40 noise seeds) that way; docs/estimator.md, "One linearisation point per image".

use super::fuse::extrinsic_innovation;
use super::undo::Checkpoint;
use super::Ekf;
use crate::camera::Camera;
use crate::chi2;
use crate::health::ExtrinsicInnovation;
use crate::scalar::Scalar;
use crate::state::{imu, Layout};
use crate::update::reprojection::{self, CornerSet};
use crate::update::{Gain, Measurement, SparseJacobian, UpdateKind, UpdateReport};
use crate::Error;
use nalgebra::{Matrix2, Matrix3, SMatrix, SVector, Vector3};

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// Fuses the corners of target frame `f` seen by camera sensor `s` (whose extrinsic is
    /// `T_I_C`) in the image stamped `meas.stamp_ns`. The filter is propagated to the image's
    /// IMU time `stamp + t_d` over the interpolated IMU readings, so feed IMU samples until
    /// [`Ekf::is_due`] says so first. Rejected by the gate: only the health monitor records it.
    pub fn update_reprojection(
        &mut self,
        s: usize,
        f: usize,
        camera: &Camera<T>,
        meas: &CornerSet<'_, T>,
    ) -> Result<UpdateReport<T>, Error> {
        if s >= S {
            return Err(Error::UnknownSensor);
        }
        if f >= F {
            return Err(Error::UnknownFrame);
        }
        if self.frames[f].is_none() {
            return Err(Error::FrameNotInitialized);
        }
        meas.validate()?;
        let t = self.reachable_imu_time(s, meas.stamp_ns)?;
        let dof = 2 * meas.corners.len();
        let threshold = chi2::quantile::<T>(dof, self.config.gate);
        // One pass at the stated noise; a frame the gate rejects with NIS / dof up to
        // `max_noise_scale^2` gets a second pass with its noise scaled by sqrt(NIS / dof),
        // as one IRLS step of a frame-level robust loss. One draft lives at a time (the
        // loop reuses its slot), so the stack cost is that of a single pass.
        let mut scale = T::one();
        let mut first_nis = None;
        let checkpoint = Checkpoint::save(self);
        let (nis, accepted, innovation) = loop {
            let (nis, innovation) = match self.fuse_corners(s, f, camera, meas, t, scale) {
                Ok(x) => x,
                Err(e) => {
                    checkpoint.restore(self);
                    return Err(e);
                }
            };
            let raw = *first_nis.get_or_insert(nis);
            if nis <= threshold {
                break (raw, true, innovation);
            }
            checkpoint.restore(self);
            let wanted = (nis / T::lit(dof as f64)).sqrt();
            if scale > T::one() || wanted > self.config.max_noise_scale {
                break (raw, false, innovation);
            }
            scale = wanted;
        };
        Ok(self.record_update(
            UpdateKind::Reprojection,
            Some(s),
            meas.stamp_ns,
            (nis, dof, threshold),
            accepted,
            Some(&innovation),
        ))
    }

    /// Sequential update of every corner of `meas` on this (draft) filter at IMU time `t`,
    /// with the corner noise scaled by `scale`: the summed NIS (for a linear model that of
    /// the stacked measurement) and the innovation statistics for the health monitor.
    fn fuse_corners(
        &mut self,
        s: usize,
        f: usize,
        camera: &Camera<T>,
        meas: &CornerSet<'_, T>,
        t: u64,
        scale: T,
    ) -> Result<(T, ExtrinsicInnovation<T>), Error> {
        self.advance_to(t)?;
        let last = self.imu_now.ok_or(Error::NotInitialized)?;
        self.flush_transition();
        let sigma = meas.pixel_sigma * scale;
        let noise = Matrix2::identity() * (sigma * sigma);
        let mut nis = T::zero();
        let mut innovation = ExtrinsicInnovation {
            rotation_info: Matrix3::zeros(),
            rotation_score: Vector3::zeros(),
            translation_info: Matrix3::zeros(),
            translation_score: Vector3::zeros(),
        };
        let (holds, count) = self.holds();
        let target = self.frames[f].ok_or(Error::FrameNotInitialized)?;
        let (imu_pose, extrinsic) = (self.imu.pose(), self.sensors[s].extrinsic);
        let mut dx = SVector::<T, N>::zeros();
        for corner in meas.corners {
            let lin = reprojection::linearize(
                camera,
                &imu_pose,
                &extrinsic,
                &target,
                &corner.point_in_target,
                &corner.pixel,
            )
            .ok_or(Error::NotProjectable)?;
            let jacobian = self.reprojection_jacobian(s, f, &lin, &last.gyro);
            let measurement = Measurement {
                residual: lin.residual - jacobian.times(&dx),
                jacobian,
                noise,
            };
            let step = Gain::compute(
                &self.cov,
                &measurement,
                T::lit(f64::INFINITY),
                &holds[..count],
            )?;
            step.apply_to(&mut self.cov);
            dx += step.correction;
            nis += step.nis;
            let part = extrinsic_innovation(
                &lin.extrinsic_rotation,
                &lin.extrinsic_translation,
                &step.innovation_inverse,
                &step.weighted_residual,
            );
            innovation.rotation_info += part.rotation_info;
            innovation.rotation_score += part.rotation_score;
            innovation.translation_info += part.translation_info;
            innovation.translation_score += part.translation_score;
        }
        self.inject(&dx)?;
        Ok((nis, innovation))
    }

    /// The Jacobian of one corner: its 19 non-zero columns (IMU pose, extrinsic, time offset,
    /// target pose) of the 2 x N.
    pub(super) fn reprojection_jacobian(
        &self,
        s: usize,
        f: usize,
        lin: &reprojection::ReprojectionJacobians<T>,
        held_gyro: &Vector3<T>,
    ) -> SparseJacobian<T, 2, 19> {
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

    /// The 19 non-zero columns of a model that sees static frame `f` through sensor `s` at
    /// the current IMU pose (a corner, a board plane), from its blocks w.r.t. the IMU
    /// orientation and position, the extrinsic rotation and translation, and the frame's
    /// orientation and position. The time offset enters through the IMU pose at the
    /// measurement's true IMU time: `d/dt_d = H_theta w + H_p v` (as the clones carry it).
    pub(super) fn target_model_jacobian<const M: usize>(
        &self,
        s: usize,
        f: usize,
        blocks: [&SMatrix<T, M, 3>; 6],
        held_gyro: &Vector3<T>,
    ) -> SparseJacobian<T, M, 19> {
        let w = held_gyro - self.imu.gyro_bias;
        let v = self.imu.velocity;
        let at = [
            imu::ORIENTATION.idx,
            imu::POSITION.idx,
            Layout::<S, C>::extrinsic_rotation(s).idx,
            Layout::<S, C>::extrinsic_translation(s).idx,
            Layout::<S, C>::frame_orientation(f).idx,
            Layout::<S, C>::frame_position(f).idx,
        ];
        let mut h = SparseJacobian::zeros();
        for (k, (idx, block)) in at.into_iter().zip(blocks).enumerate() {
            h.set(3 * k, idx, block);
        }
        let td = blocks[0] * w + blocks[1] * v;
        h.set(18, Layout::<S, C>::time_offset(s).idx, &td);
        h
    }
}
