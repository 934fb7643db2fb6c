//! The reprojection update (RepErrCal, eq. 4.2 and 4.15): the corners of a static target
//! seen in one image, through the IMU pose at the image's IMU time, the camera extrinsic
//! and the camera model.
//!
//! One image is one update (OpenVINS-style measurement compression, `update::compress`):
//! every corner is linearised at the same state; each is tested on its own 2-dof NIS from
//! the covariance of the 19 columns it touches (an outlying corner is dropped, the rest of
//! the image kept); the inliers' rows, which all live in those 19 columns, are folded into
//! a 19-row triangular factor with Givens rotations; the image is gated on the NIS of all
//! inlier rows (`chi2(2 K_inliers)`), and one update through the block-sparse core applies
//! it. It costs one covariance update per image instead of one per corner, keeps memory
//! fixed for any number of corners, and computes everything before it changes the state.
//!
//! One linearisation point per image matters for more than cost: an update that injected
//! each corner's correction and relinearised the next corner there (as this one once did)
//! moves the linearisation point along directions the image does not see (the camera
//! extrinsic against the target pose), and the filter gains information along them from
//! nothing: the joint self-test's mean LiDAR / camera / board NEES over 40 noise seeds was
//! 85 / 275 / 143 that way (6 if consistent); docs/estimator.md, "One linearisation point
//! per image".

use super::fuse::extrinsic_innovation;
use super::undo::{ColumnsUndo, StepUndo};
use super::Ekf;
use crate::camera::Camera;
use crate::chi2;
use crate::health::ExtrinsicInnovation;
use crate::ids::{FrameId, SensorId};
use crate::lie::Pose;
use crate::scalar::Scalar;
use crate::state::{imu, Layout};
use crate::update::compress::{pair_nis, Compressor};
use crate::update::reprojection::{self, CornerSet};
use crate::update::{Gain, Measurement, SparseJacobian, UpdateKind, UpdateReport};
use crate::Error;
use nalgebra::{Matrix3, SMatrix, Vector3};

/// The columns a corner's Jacobian touches (see [`Ekf::target_model_jacobian`]).
const ACTIVE: usize = 19;

/// One image's corners, gated one by one and compressed.
struct Image<T: Scalar> {
    /// The inlier rows, compressed.
    rows: Compressor<T, ACTIVE>,
    /// The state columns of the compressed rows.
    columns: [usize; ACTIVE],
    /// Per-axis pixel variance of every row.
    sigma2: T,
    /// Corners rejected by their own NIS, and the sum of those NIS.
    outliers: usize,
    outlier_nis: T,
}

/// What every pass over one image reads: camera sensor `s`, target frame `f` at `target`
/// (its estimate when the image arrived), the camera model, the corners, and the gyro
/// reading held over the last IMU interval.
struct ImageView<'a, T: Scalar> {
    s: SensorId,
    f: FrameId,
    target: Pose<T>,
    camera: &'a Camera<T>,
    meas: &'a CornerSet<'a, T>,
    held_gyro: Vector3<T>,
}

/// What fusing an image did: the first pass's `(nis, dof, threshold)`, whether a pass was
/// accepted, and its innovation on the extrinsic.
struct Outcome<T: Scalar> {
    stats: (T, usize, T),
    accepted: bool,
    innovation: ExtrinsicInnovation<T>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize> Ekf<T, S, C, N, F> {
    /// Fuses the corners of target frame `f` seen by camera sensor `s` (whose extrinsic is
    /// `T_I_C`) in the image stamped `meas.stamp_ns`. The filter is propagated to the image's
    /// IMU time `stamp + t_d` over the interpolated IMU readings, so feed IMU samples until
    /// [`Ekf::is_due`] says so first. A corner whose own NIS fails the gate (`chi2(2)` at the
    /// configured confidence) is left out; the report's dof counts the inlier rows. Rejected
    /// by the gate: only the health monitor records it. On error the filter is unchanged.
    pub fn update_reprojection(
        &mut self,
        s: SensorId,
        f: FrameId,
        camera: &Camera<T>,
        meas: &CornerSet<'_, T>,
    ) -> Result<UpdateReport<T>, Error> {
        self.check_target_model(s, f)?;
        meas.validate()?;
        let t = self.reachable_imu_time(s, meas.stamp_ns)?;
        let step = StepUndo::save(self);
        let outcome = self
            .advance_out_of_line(t)
            .and_then(|()| self.fuse_image(s, f, camera, meas));
        let outcome = match outcome {
            Ok(outcome) => outcome,
            Err(e) => {
                step.restore(self);
                return Err(e);
            }
        };
        if !outcome.accepted {
            // A gated image leaves the filter where it was, propagation included.
            step.restore(self);
        }
        Ok(self.record_update(
            UpdateKind::Reprojection,
            Some(s),
            meas.stamp_ns,
            outcome.stats,
            (outcome.accepted, false),
            Some(&outcome.innovation),
        ))
    }

    /// Fuses the image at the filter's (propagated) time; on error or when the gate
    /// rejects, puts back the covariance columns it wrote.
    #[inline(never)]
    fn fuse_image(
        &mut self,
        s: SensorId,
        f: FrameId,
        camera: &Camera<T>,
        meas: &CornerSet<'_, T>,
    ) -> Result<Outcome<T>, Error> {
        let mut columns = ColumnsUndo::new();
        columns.save(self, None);
        let outcome = self.gate_and_fuse_image(s, f, camera, meas);
        if !outcome.as_ref().is_ok_and(|o| o.accepted) {
            columns.restore(self);
        }
        outcome
    }

    /// One pass at the stated noise; an image the gate rejects with NIS / dof up to
    /// `max_noise_scale^2` gets a second pass with its noise scaled by sqrt(NIS / dof), as
    /// one IRLS step of a frame-level robust loss. Nothing but `P_IX` (brought up to date)
    /// is written before the gate has accepted. The stats are the first pass's.
    fn gate_and_fuse_image(
        &mut self,
        s: SensorId,
        f: FrameId,
        camera: &Camera<T>,
        meas: &CornerSet<'_, T>,
    ) -> Result<Outcome<T>, Error> {
        let last = self.imu_now.ok_or(Error::NotInitialized)?;
        self.flush_transition();
        let view = ImageView {
            s,
            f,
            target: self.frames[f.index()].ok_or(Error::FrameNotInitialized)?,
            camera,
            meas,
            held_gyro: last.gyro,
        };
        let mut scale = T::one();
        let mut first = None;
        loop {
            let pass = self.image_pass(&view, scale)?;
            let stats = *first.get_or_insert(pass.stats);
            if pass.accepted {
                return Ok(Outcome { stats, ..pass });
            }
            let (nis, dof, _) = pass.stats;
            let wanted = (nis / T::lit(dof as f64)).sqrt();
            if scale > T::one() || wanted <= T::one() || wanted > self.config.max_noise_scale {
                return Ok(Outcome { stats, ..pass });
            }
            scale = wanted;
        }
    }

    /// One pass over the image at pixel sigma `meas.pixel_sigma * scale`: compress, gate,
    /// and apply when accepted. Out of line, so that its gain (`N x 19` twice) is one
    /// frame's, popped before another pass.
    #[inline(never)]
    fn image_pass(&mut self, view: &ImageView<'_, T>, scale: T) -> Result<Outcome<T>, Error> {
        let image = self.compress_image(view, scale)?;
        let rows = image.rows.rows();
        if rows == 0 {
            // Every corner an outlier: the image is rejected on their NIS.
            let dof = 2 * image.outliers;
            let threshold = chi2::quantile::<T>(dof, self.config.gate);
            return Ok(Outcome {
                stats: (image.outlier_nis, dof, threshold),
                accepted: false,
                innovation: no_innovation(),
            });
        }
        let threshold = chi2::quantile::<T>(rows, self.config.gate);
        let leftover = image.rows.leftover() / image.sigma2;
        let (holds, count) = self.holds();
        let mut gain = Gain::empty();
        gain.compute_into(
            &self.cov,
            &image.measurement(),
            threshold - leftover,
            &holds[..count],
        )?;
        self.correct(&gain)?;
        Ok(Outcome {
            stats: (gain.nis + leftover, rows, threshold),
            accepted: gain.accepted,
            innovation: image.innovation(&gain),
        })
    }

    /// Linearises every corner at the current state with pixel sigma `meas.pixel_sigma *
    /// scale`, drops those whose own NIS fails the 2-dof gate, and compresses the rest.
    #[inline(never)]
    fn compress_image(&self, view: &ImageView<'_, T>, scale: T) -> Result<Image<T>, Error> {
        let ImageView {
            s,
            f,
            ref target,
            camera,
            meas,
            ref held_gyro,
        } = *view;
        let sigma = meas.pixel_sigma * scale;
        let corner_gate = chi2::quantile::<T>(2, self.config.gate);
        let (pose, extrinsic) = (self.imu.pose(), self.sensors[s.index()].extrinsic);
        let mut image = Image {
            rows: Compressor::new(),
            columns: [0; ACTIVE],
            sigma2: sigma * sigma,
            outliers: 0,
            outlier_nis: T::zero(),
        };
        let mut p_sub = None;
        for corner in meas.corners {
            let lin = reprojection::linearize(
                camera,
                &pose,
                &extrinsic,
                target,
                &corner.point_in_target,
                &corner.pixel,
            )
            .ok_or(Error::NotProjectable)?;
            let h = self.reprojection_jacobian(s, f, &lin, held_gyro);
            let finite = |m: &[T]| m.iter().all(|x| x.is_finite());
            if !finite(h.values.as_slice()) || !finite(lin.residual.as_slice()) {
                return Err(Error::NonFinite);
            }
            let p = match p_sub {
                Some(ref p) => p,
                None => p_sub.insert(h.sub_covariance(&self.cov)?),
            };
            let nis = pair_nis(p, &h.values, &lin.residual, image.sigma2)
                .ok_or(Error::SingularInnovation)?;
            if nis > corner_gate {
                image.outliers += 1;
                image.outlier_nis += nis;
                continue;
            }
            image.columns = h.columns;
            image.rows.add_rows(&h.values, &lin.residual);
        }
        Ok(image)
    }

    /// The Jacobian of one corner: its 19 non-zero columns (IMU pose, extrinsic, time offset,
    /// target pose) of the 2 x N.
    pub(super) fn reprojection_jacobian(
        &self,
        s: SensorId,
        f: FrameId,
        lin: &reprojection::ReprojectionJacobians<T>,
        held_gyro: &Vector3<T>,
    ) -> SparseJacobian<T, 2, ACTIVE> {
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
        s: SensorId,
        f: FrameId,
        blocks: [&SMatrix<T, M, 3>; 6],
        held_gyro: &Vector3<T>,
    ) -> SparseJacobian<T, M, ACTIVE> {
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

/// Where [`Ekf::target_model_jacobian`] stores the extrinsic rotation and translation.
const EXTRINSIC_ROTATION_AT: usize = 6;
const EXTRINSIC_TRANSLATION_AT: usize = 9;

impl<T: Scalar> Image<T> {
    /// The compressed rows as a measurement over their 19 columns.
    fn measurement(&self) -> Measurement<T, ACTIVE, ACTIVE> {
        Measurement {
            residual: *self.rows.residual(),
            jacobian: SparseJacobian {
                columns: self.columns,
                values: *self.rows.upper(),
            },
            noise: SMatrix::<T, ACTIVE, ACTIVE>::identity() * self.sigma2,
        }
    }

    /// The innovation projected on the camera extrinsic for the health monitor, from the
    /// compressed rows: the rows the compression dropped have no extrinsic component
    /// (`Q2^T H = 0`), so this equals the stacked image's.
    fn innovation<const N: usize>(&self, gain: &Gain<T, ACTIVE, N>) -> ExtrinsicInnovation<T> {
        let u = self.rows.upper();
        // No end rotation: an image is no increment, so no knock candidate rests on it and
        // the candidate test's covariance is not needed.
        extrinsic_innovation(
            (
                &u.fixed_columns::<3>(EXTRINSIC_ROTATION_AT).clone_owned(),
                &u.fixed_columns::<3>(EXTRINSIC_TRANSLATION_AT).clone_owned(),
                None,
            ),
            &gain.innovation_inverse,
            &gain.weighted_residual,
            Matrix3::zeros(),
        )
    }
}

/// No information (an image without a gain).
fn no_innovation<T: Scalar>() -> ExtrinsicInnovation<T> {
    ExtrinsicInnovation {
        rotation_info: Matrix3::zeros(),
        rotation_score: Vector3::zeros(),
        translation_info: Matrix3::zeros(),
        translation_score: Vector3::zeros(),
        jump_info: Matrix3::zeros(),
        jump_score: Vector3::zeros(),
        rotation_covariance: Matrix3::zeros(),
    }
}

#[cfg(test)]
mod tests {
    //! The reprojection Jacobian of a rig's second camera (issue 32): in a two-camera layout
    //! the corners camera 1 sees depend on its own extrinsic and time offset, the IMU pose and
    //! the target, and on nothing of camera 0.
    use super::*;
    use crate::filter::tests::reprojection::{camera, STAMP};
    use crate::filter::tests::T0;
    use crate::filter::FilterConfig;
    use crate::propagate::{ImuNoise, ImuSample};
    use crate::state::InitialState;
    use crate::testing::assert_mat_close;
    use nalgebra::{SVector, UnitQuaternion, Vector2};

    /// Two cameras, one target: `15 + 2 * 7 + 6` error states.
    const N: usize = 35;
    type RigEkf = Ekf<f64, 2, 0, N, 1>;
    const CAM0: SensorId = SensorId::at::<0, 2>();
    const CAM1: SensorId = SensorId::at::<1, 2>();
    const TARGET: FrameId = FrameId::at::<0, 1>();

    /// `T_I_C0`, and `T_I_C1` 11 cm along camera 0's x axis, turned 4 deg towards it.
    fn extrinsics() -> (Pose<f64>, Pose<f64>) {
        let c0 = Pose::new(
            UnitQuaternion::from_euler_angles(-1.5, 0.03, -1.6),
            Vector3::new(0.06, -0.02, 0.01),
        );
        let c0_c1 = Pose::new(
            UnitQuaternion::from_euler_angles(0.005, -0.07, 0.003),
            Vector3::new(0.11, 0.002, -0.003),
        );
        (c0, c0.compose(&c0_c1))
    }

    /// A spinning, accelerating rig with camera 1's time offset `td1` (camera 0's 2 ms), the
    /// target 0.8 m in front of camera 1 at 4 ms after the stamp whatever `td1` is.
    fn rig_filter(td1: f64) -> RigEkf {
        let (c0, c1) = extrinsics();
        let mut init = InitialState::<f64, 2>::at_rest(Vector3::new(0.0, 0.0, 9.81))
            .expect("gravity")
            .with_extrinsic(CAM0, c0, 0.02, 0.02)
            .with_time_offset(CAM0, 0.002, 0.01)
            .with_extrinsic(CAM1, c1, 0.02, 0.02)
            .with_time_offset(CAM1, td1, 0.01);
        init.imu.velocity = Vector3::new(0.7, -0.3, 0.2);
        init.imu.rotation = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
        let mut ekf = RigEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior");
        // Samples every 2.5 ms up to 240 ms, then the look-ahead at 260 ms: the filter
        // stands at 240 ms, before the image.
        for stamp_ns in (0..=96u64)
            .map(|k| T0 + k * 2_500_000)
            .chain([T0 + 260_000_000])
        {
            ekf.propagate(&ImuSample {
                stamp_ns,
                gyro: Vector3::new(1.2, -0.8, 0.5),
                accel: Vector3::new(0.5, 1.0, 9.0),
            })
            .expect("sample");
        }
        let mut at_image = ekf.clone();
        at_image.advance_to(STAMP + 4_000_000).expect("advance");
        let target_in_camera = Pose::new(
            UnitQuaternion::from_euler_angles(0.2, -0.3, 0.1),
            Vector3::new(-0.12, -0.1, 0.8),
        );
        let target = at_image
            .imu()
            .pose()
            .compose(&c1)
            .compose(&target_in_camera);
        ekf.init_frame(TARGET, target, 0.05, 0.05).expect("frame");
        ekf
    }

    /// Where camera 1 sees the corner `p` at its image's IMU time.
    fn predicted(ekf: &RigEkf, p: &Vector3<f64>) -> Vector2<f64> {
        let mut at_image = ekf.clone();
        let t = at_image
            .imu_time(CAM1, STAMP)
            .expect("sensor")
            .max(at_image.time_ns());
        at_image.advance_to(t).expect("advance");
        let p_c = reprojection::point_in_camera(
            &at_image.imu().pose(),
            &at_image.extrinsic(CAM1),
            &at_image.frame(TARGET).expect("frame"),
            p,
        );
        camera().project(&p_c).expect("in view").pixel
    }

    #[test]
    fn second_camera_jacobian_matches_central_differences_over_the_whole_state() {
        // Given the rig standing at camera 1's image IMU time
        let td1 = 0.005;
        let corner = Vector3::new(0.15, 0.05, 0.0);
        let mut at_image = rig_filter(td1);
        at_image
            .advance_to(at_image.imu_time(CAM1, STAMP).expect("sensor"))
            .expect("advance");
        // When every error-state direction is perturbed there
        let h = 1e-6;
        let mut numeric = SMatrix::<f64, 2, N>::zeros();
        for i in 0..N {
            let shifted = |sign: f64| {
                let mut e = at_image.clone();
                let mut dx = SVector::<f64, N>::zeros();
                dx[i] = sign * h;
                e.apply_correction(&dx).expect("finite");
                predicted(&e, &corner)
            };
            numeric.set_column(i, &((shifted(1.0) - shifted(-1.0)) / (2.0 * h)));
        }
        // and camera 1's time offset through the propagation to another IMU time
        let h_td = 1e-5;
        let td_column = (predicted(&rig_filter(td1 + h_td), &corner)
            - predicted(&rig_filter(td1 - h_td), &corner))
            / (2.0 * h_td);
        numeric.set_column(Layout::<2, 0>::time_offset(CAM1).idx, &td_column);
        // Then the analytic Jacobian agrees, camera 0's columns zero on both sides
        let lin = reprojection::linearize(
            &camera(),
            &at_image.imu().pose(),
            &at_image.extrinsic(CAM1),
            &at_image.frame(TARGET).expect("frame"),
            &corner,
            &Vector2::zeros(),
        )
        .expect("in view");
        let gyro = at_image.imu_now.expect("imu").gyro;
        let analytic: SMatrix<f64, 2, N> = at_image
            .reprojection_jacobian(CAM1, TARGET, &lin, &gyro)
            .to_dense();
        let cam0 = Layout::<2, 0>::extrinsic(CAM0).idx;
        assert!(analytic.columns(cam0, 7).amax() == 0.0);
        assert!(numeric.columns(cam0, 7).amax() < 1e-6, "{numeric}");
        assert!(
            analytic
                .columns(Layout::<2, 0>::extrinsic(CAM1).idx, 7)
                .amax()
                > 1.0
        );
        // Pixels per unit error are O(500); the time-offset column carries the midpoint
        // integrator's O(|w| |a| dt^2) velocity inconsistency (as the one-camera test).
        assert_mat_close(&(analytic / 1000.0), &(numeric / 1000.0), 2e-4);
    }
}
