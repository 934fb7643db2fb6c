//! Joint LiDAR-IMU-camera calibration (issue 13, the dissertation's chapter 5): one EKF
//! (`JointEkf`: the IMU, the LiDAR as sensor 0, the camera as sensor 1, clones and the board
//! as a static frame) estimates `T_imu_lidar`, `T_imu_cam` and both time offsets from
//!
//! - the LiDAR's relative poses (NDT on deskewed scans: the LiDAR-IMU pipeline's feed),
//! - the camera's checkerboard corners (RepErrCal: the camera-IMU pipeline's feed),
//! - the board plane: the board points of each deskewed scan against the target frame the
//!   corners observe (`msreg_estimator::update::board_plane`), which ties the two
//!   extrinsics together (eq. 5.12 in target-frame form).
//!
//! Start: the camera-IMU pipeline's (MoCal on the PnP poses, the IMU state and the camera
//! prior around its estimate) and the LiDAR-IMU pipeline's hand-eye rotation with its
//! standard prior. Measurements are fused in the order of their IMU times, whichever sensor
//! they come from. `T_cam_lidar` is derived with its covariance from the joint covariance,
//! cross terms included.

mod consistency;
mod plane;

use std::time::Instant;

use msreg_estimator::{Ekf, InitialState, JointEkf, Scalar, SensorId, SensorPrior, SensorState};
use nalgebra::{Isometry3, Matrix3, Matrix6, Point3, Vector3};

use super::camera_imu::{
    frame_poses, motion_calibration, prior_from_motion, CameraImuInput, CameraImuOptions,
    CornerFeed, CornerFrame, ExtrinsicPrior, PriorFromMotion, Start,
};
use super::convert;
use super::init;
use super::lidar_imu::{rotation_init, LidarFeed, LidarImuOptions};
use super::InputError;
use crate::calibrate::driver::report::{PoseImuCalibration, Timing};
use crate::calibrate::driver::verdict::finish;
use crate::calibrate::driver::{drive_imu, ImuHooks};
use crate::camera_yaml::CheckerboardTarget;
use crate::dataset::{ImuNoiseYaml, ImuRecord};
use crate::lidar::ScanSource;
use msreg_estimator::camera::Camera;

pub use consistency::{chained_pairwise, LoopConsistency, PairwiseRuns};
pub use plane::{BoardExtent, PlaneOptions, PlaneStats};

/// The LiDAR and the camera of the joint layout (`JointEkf`).
pub use msreg_estimator::{JOINT_CAMERA as CAMERA, JOINT_LIDAR as LIDAR};

/// What the pipeline reads.
#[derive(Clone, Copy)]
pub struct JointInput<'a> {
    /// IMU samples, strictly increasing stamps.
    pub imu: &'a [ImuRecord],
    /// IMU noise densities.
    pub imu_noise: &'a ImuNoiseYaml,
    /// The LiDAR's scans.
    pub scans: &'a dyn ScanSource,
    /// The camera model.
    pub camera: &'a Camera<f64>,
    /// Detected corners per image, increasing stamps.
    pub frames: &'a [CornerFrame],
    /// The checkerboard, with the physical board's `width_m` / `height_m`.
    pub target: &'a CheckerboardTarget,
}

/// Tuning of the pipeline: each sensor's as in its pairwise pipeline, and the planes'.
#[derive(Debug, Clone, Default)]
pub struct JointOptions {
    /// The camera's start and feed.
    pub camera: CameraImuOptions,
    /// The LiDAR's start and feed.
    pub lidar: LidarImuOptions,
    /// Board segmentation and the plane update.
    pub plane: PlaneOptions,
}

/// The joint result.
#[derive(Debug, Clone)]
pub struct JointCalibration {
    /// `T_imu_lidar`, its time offset and the LiDAR's report.
    pub lidar: PoseImuCalibration,
    /// `T_imu_cam`, its time offset and the camera's report.
    pub camera: PoseImuCalibration,
    /// `T_cam_lidar` derived from the two.
    pub t_cam_lidar: Isometry3<f64>,
    /// Its covariance `[dtheta (right); dp]`, from the joint covariance (cross terms in).
    pub cam_lidar_covariance: Matrix6<f64>,
    /// The board planes.
    pub planes: PlaneStats,
    /// Every board plane fused or gated (the LiDAR's board-point moments at each scan).
    pub plane_measurements: Vec<msreg_estimator::update::board_plane::BoardPlane<f64>>,
    /// One scan's board returns at an image's instant, halfway through the run.
    pub overlay: Option<OverlaySample>,
    /// Wall time of the start (MoCal, hand-eye) and of the filter pass, s.
    pub timing_s: Timing,
}

impl JointCalibration {
    /// True when both sensors' results passed their checks.
    pub fn converged(&self) -> bool {
        self.lidar.report.converged && self.camera.report.converged
    }
}

/// Runs the joint calibration with the filter in scalar type `T`; `progress` gets the
/// fraction done.
pub fn calibrate<T: Scalar>(
    input: &JointInput<'_>,
    options: &JointOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<JointCalibration, InputError> {
    let imu = input.imu;
    let Some(first_imu) = imu.first() else {
        return Err(InputError::NoImuSamples);
    };
    let board = BoardExtent::of(input.target)?;
    let started = Instant::now();
    let camera_input = CameraImuInput {
        imu,
        imu_noise: input.imu_noise,
        camera: input.camera,
        frames: input.frames,
    };
    let poses = frame_poses(input.camera, input.frames);
    let (motion, pixel_sigma) =
        motion_calibration::<T>(&camera_input, &poses, &options.camera, &mut |f| {
            progress(0.2 * f)
        })?;
    let start = Start {
        motion: &motion,
        pixel_sigma,
        poses: &poses,
    };
    let standstill = init::detect_standstill(imu, options.camera.prior.min_standstill_s);
    let JointStart {
        mut ekf,
        camera_prior,
        camera_rotation_init,
        lidar_rotation,
    } = joint_start::<T>(input, options, &camera_input, &start, standstill.as_ref())?;
    let init_s = started.elapsed().as_secs_f64();

    let started = Instant::now();
    let mut feed = JointFeed {
        lidar: LidarFeed::new(
            input.scans,
            &options.lidar,
            first_imu.stamp_ns,
            (LIDAR, true),
        ),
        corners: CornerFeed::new(&camera_input, &options.camera, &start, camera_prior, CAMERA)
            .with_gauge_at_target(),
        planes: plane::PlaneFeed::new(board, options.plane),
        overlay: OverlayCapture::halfway(imu),
    };
    drive_imu(
        &mut ekf,
        imu,
        standstill.as_ref(),
        &mut |f| progress(0.2 + 0.8 * f),
        &mut feed,
    )?;
    let timing = Timing {
        init: init_s,
        filter: started.elapsed().as_secs_f64(),
    };
    let (t_cam_lidar, cam_lidar_covariance) = cam_lidar(&ekf);
    let JointFeed {
        lidar,
        corners,
        planes,
        overlay,
    } = feed;
    let overlay = overlay.sample(&convert::isometry(&ekf.extrinsic(LIDAR)));
    Ok(JointCalibration {
        lidar: finish(
            &ekf,
            lidar.into_run(),
            standstill.as_ref(),
            &lidar_rotation,
            timing,
        ),
        camera: finish(
            &ekf,
            corners.into_run(),
            standstill.as_ref(),
            &camera_rotation_init,
            timing,
        ),
        t_cam_lidar,
        cam_lidar_covariance,
        planes: planes.stats(),
        plane_measurements: planes.measurements,
        overlay,
        timing_s: timing,
    })
}

/// The joint filter at its start and what the report says of it.
struct JointStart<T: Scalar> {
    ekf: JointEkf<T>,
    camera_prior: crate::calibrate::driver::report::PoseImuOptions,
    camera_rotation_init: init::RotationInit,
    lidar_rotation: init::RotationInit,
}

/// The camera's start (RepErrCal's, around MoCal's estimate) and the LiDAR's hand-eye
/// rotation, in one filter.
fn joint_start<T: Scalar>(
    input: &JointInput<'_>,
    options: &JointOptions,
    camera_input: &CameraImuInput<'_>,
    start: &Start<'_>,
    standstill: Option<&init::Standstill>,
) -> Result<JointStart<T>, InputError> {
    let camera_start = prior_from_motion::<T>(
        camera_input,
        &options.camera,
        standstill,
        start,
        ExtrinsicPrior::AroundStart,
    )?;
    let (lidar_rotation, _, _) = rotation_init(input.imu, input.scans, standstill, &options.lidar)?;
    let lidar_rotation = lidar_rotation.map_err(|error| InputError::HandEyeRotation {
        sensor: "lidar0/",
        error,
    })?;
    let camera_rotation_init = camera_start.rotation_init;
    let camera_prior = camera_start.prior;
    Ok(JointStart {
        ekf: joint_filter::<T>(camera_start, &lidar_rotation, &options.lidar)?,
        camera_prior,
        camera_rotation_init,
        lidar_rotation,
    })
}

/// The joint filter: the camera start's IMU state and camera prior (as sensor 1), and the
/// LiDAR at its hand-eye rotation with the LiDAR pipeline's prior (sensor 0).
fn joint_filter<T: Scalar>(
    camera: PriorFromMotion<T>,
    lidar_rotation: &init::RotationInit,
    options: &LidarImuOptions,
) -> Result<JointEkf<T>, InputError> {
    let prior = &options.filter;
    let lidar = SensorPrior {
        state: SensorState {
            extrinsic: convert::pose::<T>(&Isometry3::from_parts(
                Default::default(),
                lidar_rotation.rotation,
            )),
            time_offset: T::zero(),
        },
        sigma_rotation: T::lit(prior.rotation_sigma_rad),
        sigma_translation: T::lit(prior.translation_sigma_m),
        sigma_time_offset: T::lit(if prior.estimate_time_offset {
            prior.time_offset_sigma_s
        } else {
            0.0
        }),
    };
    let c = camera.initial;
    let initial = InitialState::<T, 2> {
        imu: c.imu,
        sigma_orientation: c.sigma_orientation,
        sigma_position: c.sigma_position,
        sigma_velocity: c.sigma_velocity,
        sigma_gyro_bias: c.sigma_gyro_bias,
        sigma_accel_bias: c.sigma_accel_bias,
        sensors: [lidar, c.sensors[0]],
    };
    JointEkf::<T>::new(&camera.config, &initial).map_err(|error| InputError::InvalidNoise { error })
}

/// `T_cam_lidar = T_imu_cam^-1 T_imu_lidar` and its covariance `[dtheta (right); dp]`
/// through the Jacobians of the composition, with the filter's cross-covariance of the two
/// extrinsics.
pub fn cam_lidar<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>(
    ekf: &Ekf<T, S, C, N, F>,
) -> (Isometry3<f64>, Matrix6<f64>) {
    let p = ekf.covariance();
    let block = |a: SensorId, b: SensorId| {
        let (a, b) = (
            msreg_estimator::Layout::<S, C>::extrinsic(a).idx,
            msreg_estimator::Layout::<S, C>::extrinsic(b).idx,
        );
        Matrix6::from_fn(|r, c| p[(a + r, b + c)].to_f64())
    };
    compose_cam_lidar(
        (
            &convert::isometry(&ekf.extrinsic(CAMERA)),
            &block(CAMERA, CAMERA),
        ),
        (
            &convert::isometry(&ekf.extrinsic(LIDAR)),
            &block(LIDAR, LIDAR),
        ),
        &block(CAMERA, LIDAR),
    )
}

/// `T_cam_lidar = T_imu_cam^-1 T_imu_lidar` from `(T_imu_cam, covariance)` and
/// `(T_imu_lidar, covariance)` with their cross-covariance `cl` (zero for two independent
/// runs), covariances `[dtheta (right); dp]`.
pub fn compose_cam_lidar(
    (t_i_c, cc): (&Isometry3<f64>, &Matrix6<f64>),
    (t_i_l, ll): (&Isometry3<f64>, &Matrix6<f64>),
    cl: &Matrix6<f64>,
) -> (Isometry3<f64>, Matrix6<f64>) {
    let t_c_l = t_i_c.inverse() * t_i_l;
    let (j_c, j_l) = cam_lidar_jacobians(t_i_c, &t_c_l);
    let cov = j_c * cc * j_c.transpose()
        + j_c * cl * j_l.transpose()
        + j_l * cl.transpose() * j_c.transpose()
        + j_l * ll * j_l.transpose();
    (t_c_l, (cov + cov.transpose()) * 0.5)
}

/// Derivatives of `T_cam_lidar`'s error w.r.t. the camera's and the LiDAR's extrinsic errors
/// (right rotation perturbations, additive translations).
fn cam_lidar_jacobians(
    t_i_c: &Isometry3<f64>,
    t_c_l: &Isometry3<f64>,
) -> (Matrix6<f64>, Matrix6<f64>) {
    let r_ic = t_i_c.rotation.to_rotation_matrix().into_inner();
    let r_cl = t_c_l.rotation.to_rotation_matrix().into_inner();
    let mut j_c = Matrix6::zeros();
    j_c.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&(-r_cl.transpose()));
    j_c.fixed_view_mut::<3, 3>(3, 0)
        .copy_from(&msreg_estimator::lie::skew(&t_c_l.translation.vector));
    j_c.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&(-r_ic.transpose()));
    let mut j_l = Matrix6::zeros();
    j_l.fixed_view_mut::<3, 3>(0, 0)
        .copy_from(&Matrix3::identity());
    j_l.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&r_ic.transpose());
    (j_c, j_l)
}

impl<T: Scalar> JointFeed<'_, T> {
    /// Fuses the next image (stamp `stamp`), due at IMU time `t`, and moves the LiDAR's
    /// pose history with the update's correction.
    fn fuse_image(&mut self, ekf: &mut JointEkf<T>, index: usize, (t, stamp): (u64, u64)) {
        let before = predicted_pose(ekf, t);
        if let (Some(_), None, Some((_, pose))) = (&self.overlay.scan, &self.overlay.image, before)
        {
            self.overlay.image = Some((stamp, pose));
        }
        self.corners.fuse_next(ekf, index);
        self.pose_moved(ekf, &before);
    }

    /// Fuses the next scan, due at IMU time `t`, and its board plane.
    fn fuse_scan(&mut self, ekf: &mut JointEkf<T>, index: usize, t: u64) {
        self.lidar.fuse_next(ekf, index);
        let Some((stamp, cloud)) = self.lidar.take_deskewed() else {
            return;
        };
        let before = predicted_pose(ekf, t);
        let planes = self.planes.measurements.len();
        self.planes.fuse(ekf, stamp, &cloud);
        self.pose_moved(ekf, &before);
        let new_plane = self.planes.measurements.len() > planes;
        if let (None, true, Some((t, pose))) = (&self.overlay.scan, new_plane, before) {
            if t >= self.overlay.after_ns {
                self.overlay.scan = Some((std::mem::take(&mut self.planes.last_returns), pose));
            }
        }
    }

    /// An update at IMU time `t` changed the pose there from `before` (a failed update
    /// that left the filter elsewhere moved nothing).
    fn pose_moved(&mut self, ekf: &JointEkf<T>, before: &Option<(u64, Isometry3<f64>)>) {
        if let Some((t, before)) = before.filter(|(t, _)| *t == ekf.time_ns()) {
            let after = convert::isometry(&ekf.imu().pose());
            self.lidar.filter_corrected(t, &before, &after);
        }
    }
}

/// The time an update at IMU time `t` would be fused at (`t`, or the filter's time if later)
/// and the filter's IMU pose there before it.
fn predicted_pose<T: Scalar>(ekf: &JointEkf<T>, t: u64) -> Option<(u64, Isometry3<f64>)> {
    let t = t.max(ekf.time_ns());
    ekf.predict_imu(t)
        .ok()
        .map(|s| (t, convert::isometry(&s.pose())))
}

/// The three feeds of the joint filter, fused in the order of their IMU times.
struct JointFeed<'a, T: Scalar> {
    lidar: LidarFeed<'a>,
    corners: CornerFeed<'a, T>,
    planes: plane::PlaneFeed,
    overlay: OverlayCapture,
}

/// One scan's board returns moved to the instant of an image, to draw them over it with a
/// `T_cam_lidar` (`msreg calibrate joint --overlay`).
#[derive(Debug, Clone, PartialEq)]
pub struct OverlaySample {
    /// Stamp of the image, ns (camera clock).
    pub image_stamp_ns: u64,
    /// The board returns in L at the image's instant (moved with the filter's motion and
    /// `T_imu_lidar`), m.
    pub returns_in_lidar: Vec<Vector3<f64>>,
}

/// Halfway through the run, the first board plane's returns and the IMU pose at its scan,
/// then the next image's stamp and the IMU pose there.
struct OverlayCapture {
    after_ns: u64,
    scan: Option<(Vec<Vector3<f64>>, Isometry3<f64>)>,
    image: Option<(u64, Isometry3<f64>)>,
}

impl OverlayCapture {
    fn halfway(imu: &[ImuRecord]) -> Self {
        let (first, last) = (
            imu.first().map_or(0, |r| r.stamp_ns),
            imu.last().map_or(0, |r| r.stamp_ns),
        );
        Self {
            after_ns: first + (last.saturating_sub(first)) / 2,
            scan: None,
            image: None,
        }
    }

    fn sample(self, t_i_l: &Isometry3<f64>) -> Option<OverlaySample> {
        let ((returns, at_scan), (image_stamp_ns, at_image)) = (self.scan?, self.image?);
        let motion = t_i_l.inverse() * at_image.inverse() * at_scan * t_i_l;
        Some(OverlaySample {
            image_stamp_ns,
            returns_in_lidar: returns
                .iter()
                .map(|p| (motion * Point3::from(*p)).coords)
                .collect(),
        })
    }
}

impl<T: Scalar> ImuHooks<T, JointEkf<T>> for JointFeed<'_, T> {
    fn fuse_due(
        &mut self,
        ekf: &mut JointEkf<T>,
        index: usize,
        _rec: &ImuRecord,
    ) -> Result<(), InputError> {
        loop {
            let imu_time =
                |s: SensorId, stamp: Option<u64>| stamp.and_then(|t| ekf.imu_time(s, t).ok());
            let scan = imu_time(LIDAR, self.lidar.next_due(ekf)?);
            let image_stamp = self.corners.next_due(ekf);
            let image = imu_time(CAMERA, image_stamp).zip(image_stamp);
            match (scan, image) {
                (None, None) => return Ok(()),
                (Some(l), Some(c)) if c.0 < l => self.fuse_image(ekf, index, c),
                (Some(l), _) => self.fuse_scan(ekf, index, l),
                (None, Some(c)) => self.fuse_image(ekf, index, c),
            }
        }
    }

    fn after_sample(&mut self, ekf: &JointEkf<T>, rec: &ImuRecord) {
        ImuHooks::<T, JointEkf<T>>::after_sample(&mut self.lidar, ekf, rec);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_estimator::{FilterConfig, ImuNoise, Pose};
    use nalgebra::{UnitQuaternion, Vector3, Vector6};

    /// The derived covariance's Jacobians against central differences of the composition.
    #[test]
    fn cam_lidar_jacobians_match_central_differences() {
        let t_i_c = Isometry3::from_parts(
            Vector3::new(0.05, -0.02, 0.1).into(),
            UnitQuaternion::from_euler_angles(-1.5, 0.1, -1.6),
        );
        let t_i_l = Isometry3::from_parts(
            Vector3::new(0.1, 0.2, -0.05).into(),
            UnitQuaternion::from_euler_angles(0.1, -0.2, 0.7),
        );
        let t_c_l = t_i_c.inverse() * t_i_l;
        let (j_c, j_l) = cam_lidar_jacobians(&t_i_c, &t_c_l);
        let perturb = |t: &Isometry3<f64>, d: &Vector6<f64>| {
            let p = convert::pose::<f64>(t).boxplus(
                &Vector3::new(d[0], d[1], d[2]),
                &Vector3::new(d[3], d[4], d[5]),
            );
            convert::isometry(&p)
        };
        let error = |t: &Isometry3<f64>| {
            let r = (t_c_l.rotation.inverse() * t.rotation).scaled_axis();
            let p = t.translation.vector - t_c_l.translation.vector;
            Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z)
        };
        let h = 1e-6;
        for (which, analytic) in [(0, j_c), (1, j_l)] {
            for k in 0..6 {
                let mut d = Vector6::zeros();
                d[k] = h;
                let shifted = |d: Vector6<f64>| {
                    if which == 0 {
                        error(&(perturb(&t_i_c, &d).inverse() * t_i_l))
                    } else {
                        error(&(t_i_c.inverse() * perturb(&t_i_l, &d)))
                    }
                };
                let numeric = (shifted(d) - shifted(-d)) / (2.0 * h);
                assert!(
                    (numeric - analytic.column(k)).norm() < 1e-6,
                    "{which} {k}: {numeric} vs {}",
                    analytic.column(k)
                );
            }
        }
    }

    /// With independent extrinsic priors the derived covariance is the sum of the two
    /// propagated ones; the filter's values go through unchanged.
    #[test]
    fn cam_lidar_of_a_fresh_filter_composes_the_priors() {
        let mut init = InitialState::<f64, 2>::at_rest(Vector3::new(0.0, 0.0, 9.81))
            .expect("gravity")
            .with_extrinsic(
                CAMERA,
                Pose::new(
                    UnitQuaternion::from_euler_angles(-1.5, 0.0, -1.6),
                    Vector3::new(0.05, 0.0, 0.1),
                ),
                0.01,
                0.02,
            )
            .with_extrinsic(LIDAR, Pose::identity(), 0.03, 0.05);
        init.imu.velocity = Vector3::zeros();
        let ekf = JointEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior");
        let (t, cov) = cam_lidar(&ekf);
        let expected = convert::isometry(&ekf.extrinsic(CAMERA)).inverse();
        assert!((t.to_homogeneous() - expected.to_homogeneous()).abs().max() < 1e-12);
        // Rotation: 0.01^2 (camera, rotated) + 0.03^2 (LiDAR) per axis.
        for k in 0..3 {
            assert!((cov[(k, k)] - (1e-4 + 9e-4)).abs() < 1e-12, "{cov}");
        }
    }
}
