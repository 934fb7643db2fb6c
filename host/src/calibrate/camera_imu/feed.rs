//! The camera's measurement feed of the IMU driver: each image's corners (RepErrCal) or PnP
//! relative pose (MoCal) fused when due, with the reprojection bookkeeping of the report.

use super::*;
use crate::calibrate::convert;
use crate::calibrate::driver::report::PoseImuOptions;
use crate::calibrate::driver::verdict::Run;
use crate::calibrate::driver::ImuHooks;
use crate::calibrate::InputError;
use crate::dataset::ImuRecord;
use msreg_estimator::camera::Camera;
use msreg_estimator::{CornerObservation, CornerSet, Ekf, Error as FilterError, Scalar, SensorId};
use nalgebra::{Matrix6, Vector2};

/// The RepErrCal measurement feed: fuses every image whose IMU time has come, initialising
/// the target pose from the first image's PnP.
pub(crate) struct CornerFeed<'a, T: Scalar> {
    /// The filter's camera (its target is static frame [`TARGET_FRAME`]).
    pub(crate) sensor: SensorId,
    pub(crate) run: Run,
    pub(crate) frames: &'a [CornerFrame],
    pub(crate) next: usize,
    pub(crate) camera: Camera<T>,
    /// Corner noise of the recording (the median image's), and the floor of each image's.
    pub(crate) pixel_sigma: T,
    /// Each image's own corner noise from its PnP fit, by stamp: motion blur doubles it in
    /// the fast part of EuRoC `imu_april` (medians 0.2-0.3 px at rest, 0.4-0.55 px at 2 rad/s).
    pub(crate) frame_sigma: std::collections::HashMap<u64, f64>,
    pub(crate) prior: PoseImuOptions,
    pub(crate) reprojection: Vec<FrameReprojection>,
    pub(crate) buffer: Vec<CornerObservation<T>>,
    /// The first accepted image from this stamp on becomes the report's sample.
    pub(crate) sample_from_ns: u64,
    pub(crate) sample: Option<ReprojectionSample>,
    /// Whether the target, once placed, fixes the gauge ([`CornerFeed::with_gauge_at_target`]).
    pub(crate) gauge_at_target: bool,
    /// The camera's name in the run's skip messages (`cam0`, `cam1`, ...).
    pub(crate) name: &'static str,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    ImuHooks<T, Ekf<T, S, C, N, F>> for CornerFeed<'_, T>
{
    fn fuse_due(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
        _rec: &ImuRecord,
    ) -> Result<(), InputError> {
        while self.next_due(ekf).is_some() {
            self.fuse_next(ekf, index);
        }
        Ok(())
    }
}

impl<'a, T: Scalar> CornerFeed<'a, T> {
    /// The feed of the camera that is sensor `sensor` of the filter, over `input`'s images.
    pub(crate) fn new(
        input: &CameraImuInput<'a>,
        options: &CameraImuOptions,
        start: &Start<'_>,
        prior: PoseImuOptions,
        sensor: SensorId,
    ) -> Self {
        let frames = input.frames;
        Self {
            sensor,
            run: Run::new(
                input.imu.first().map_or(0, |r| r.stamp_ns),
                nominal_frame_period_ns(frames),
            )
            .for_sensor(sensor),
            frames,
            next: 0,
            camera: input.camera.cast::<T>(),
            pixel_sigma: T::lit(start.pixel_sigma),
            frame_sigma: match options.image_noise {
                ImageNoise::PerImage => start
                    .poses
                    .iter()
                    .filter_map(|p| Some((p.stamp_ns, frame_pixel_sigma(p)?)))
                    .collect(),
                ImageNoise::Uniform => Default::default(),
            },
            prior,
            reprojection: Vec::new(),
            buffer: Vec::new(),
            sample_from_ns: frames.get(frames.len() / 2).map_or(0, |f| f.stamp_ns),
            sample: None,
            gauge_at_target: false,
            name: "cam0",
        }
    }

    /// The same feed naming its camera `name` in the run's skip messages.
    pub(crate) fn named(mut self, name: &'static str) -> Self {
        self.name = name;
        self
    }

    /// Once the target is placed, it fixes the gauge ([`Ekf::fix_gauge`]): G's origin and yaw
    /// become the target's, as Kalibr takes the target as its world frame, so the filter
    /// cannot gain spurious information along the four directions no measurement sees. The
    /// joint pipeline uses it (10 seeds: camera NEES 145.7 -> 91.6, LiDAR 91.1 -> 69.9;
    /// docs/joint.md). The camera-IMU pipeline does not: its NEES cells barely moved, and
    /// the device's f32 filter then drifted 0.85 sigma from the host's in the HIL test.
    pub(crate) fn with_gauge_at_target(mut self) -> Self {
        self.gauge_at_target = true;
        self
    }

    /// The stamp of the next image when it is due (its IMU time is within reach).
    pub(crate) fn next_due<const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> Option<u64> {
        let frame = self.frames.get(self.next)?;
        ekf.is_due(self.sensor, frame.stamp_ns)
            .then_some(frame.stamp_ns)
    }

    /// Books every image not reached as after the last IMU sample.
    pub(crate) fn skip_remaining(&mut self) {
        for frame in &self.frames[self.next..] {
            self.run
                .skip_measurement(self.name, frame.stamp_ns, "after the last IMU sample");
        }
        self.next = self.frames.len();
    }

    /// The run's bookkeeping, every image not reached booked as after the last IMU sample.
    pub(crate) fn into_run(mut self) -> Run {
        self.skip_remaining();
        self.run
    }

    /// Fuses the image [`CornerFeed::next_due`] found due (`index`: the IMU sample fed
    /// last), initialising the target from it when none is yet.
    pub(crate) fn fuse_next<const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
    ) {
        let Some(frame) = self.frames.get(self.next) else {
            return;
        };
        self.next += 1;
        if index == 0 {
            self.run
                .skip_measurement(self.name, frame.stamp_ns, "before the first IMU sample");
            return;
        }
        if frame.corners.len() < MIN_CORNERS {
            self.run
                .skip_measurement(self.name, frame.stamp_ns, "too few corners");
            return;
        }
        if ekf.frame(TARGET_FRAME).is_none() {
            if let Err(why) = self.init_target(ekf, frame) {
                self.run.skip_measurement(self.name, frame.stamp_ns, &why);
                return;
            }
        }
        self.fuse(ekf, frame);
    }

    /// `T_G_T = T_G_I T_I_C T_C_T(PnP)` at the image's IMU time, with its full
    /// cross-covariance with the IMU pose, the extrinsic and the time offset
    /// ([`Ekf::init_frame_relative`]): the extrinsic prior's error is in the target's pose
    /// once, as a correlation, not a second time as independent sigmas. The PnP pose gets
    /// the documented conservative sigmas of [`target_prior_sigmas`] (independent per axis),
    /// the same the `link` replay sends the device in its `TargetPose`, so that host and
    /// device start alike (the PnP fit's own covariance, `sigma^2 (J^T J)^-1`, is tighter;
    /// with it the host's f64 RepErrCal and the device's f32 differed by 2.8 host sigma in
    /// translation in the camera HIL test). With [`CornerFeed::with_gauge_at_target`] the
    /// target then fixes the gauge. The image is then also fused.
    pub(crate) fn init_target<const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &mut Ekf<T, S, C, N, F>,
        frame: &CornerFrame,
    ) -> Result<(), String> {
        let camera = self.camera.cast::<f64>();
        let pnp = pnp_of(&camera, frame).map_err(|e| format!("no PnP pose for the target: {e}"))?;
        let (r, p) = target_prior_sigmas(&self.prior, pnp.t_cam_target.translation.norm());
        let cov = Matrix6::from_diagonal(&nalgebra::Vector6::new(
            r * r,
            r * r,
            r * r,
            p * p,
            p * p,
            p * p,
        ))
        .map(T::lit);
        ekf.init_frame_relative(
            TARGET_FRAME,
            self.sensor,
            frame.stamp_ns,
            &convert::pose::<T>(&convert::isometry(&pnp.t_cam_target)),
            &cov,
        )
        .and_then(|()| {
            if self.gauge_at_target {
                ekf.fix_gauge(TARGET_FRAME)
            } else {
                Ok(())
            }
        })
        .map_err(|e| format!("cannot initialise the target: {e}"))
    }

    pub(crate) fn fuse<const S: usize, const C: usize, const N: usize, const F: usize>(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        frame: &CornerFrame,
    ) {
        self.buffer.clear();
        self.buffer
            .extend(frame.corners.iter().map(|c| CornerObservation {
                point_in_target: convert::vec3(&c.point_in_target),
                pixel: Vector2::new(T::lit(c.pixel.x), T::lit(c.pixel.y)),
            }));
        let before = self.mean_error(ekf);
        let own = self
            .frame_sigma
            .get(&frame.stamp_ns)
            .copied()
            .unwrap_or(0.0);
        let meas = CornerSet {
            stamp_ns: frame.stamp_ns,
            corners: &self.buffer,
            pixel_sigma: self.pixel_sigma.max(T::lit(own)),
        };
        match ekf.update_reprojection(self.sensor, TARGET_FRAME, &self.camera, &meas) {
            Ok(report) => {
                self.run.record_update(ekf, frame.stamp_ns, &report);
                let after = self.mean_error(ekf);
                if report.accepted && self.sample.is_none() && frame.stamp_ns >= self.sample_from_ns
                {
                    self.sample = self.reprojection_sample(ekf, frame.stamp_ns);
                }
                self.reprojection.push(FrameReprojection {
                    t_s: self.run.seconds(frame.stamp_ns),
                    corners: frame.corners.len(),
                    mean_error_before_px: before,
                    mean_error_px: after,
                    accepted: report.accepted,
                });
            }
            Err(FilterError::NotProjectable) => self.run.skip_measurement(
                self.name,
                frame.stamp_ns,
                "corners not projectable at the estimate",
            ),
            Err(e) => self
                .run
                .skip_measurement(self.name, frame.stamp_ns, &format!("{e}")),
        }
    }

    /// The buffered corners and their reprojection at the current state.
    pub(crate) fn reprojection_sample<
        const S: usize,
        const C: usize,
        const N: usize,
        const F: usize,
    >(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
        stamp_ns: u64,
    ) -> Option<ReprojectionSample> {
        let target = ekf.frame(TARGET_FRAME)?;
        let pixel = |p: &Vector2<T>| Vector2::new(p.x.to_f64(), p.y.to_f64());
        let reprojected = self
            .buffer
            .iter()
            .map(|c| {
                let p = msreg_estimator::update::reprojection::point_in_camera(
                    &ekf.imu().pose(),
                    &ekf.extrinsic(self.sensor),
                    &target,
                    &c.point_in_target,
                );
                self.camera.project(&p).map(|x| pixel(&x.pixel))
            })
            .collect::<Option<Vec<_>>>()?;
        Some(ReprojectionSample {
            stamp_ns,
            detected: self.buffer.iter().map(|c| pixel(&c.pixel)).collect(),
            reprojected,
        })
    }

    /// Mean distance between the buffered corners and their projection at the filter's
    /// current state (NaN when one does not project).
    pub(crate) fn mean_error<const S: usize, const C: usize, const N: usize, const F: usize>(
        &self,
        ekf: &Ekf<T, S, C, N, F>,
    ) -> f64 {
        let Some(target) = ekf.frame(TARGET_FRAME) else {
            return f64::NAN;
        };
        let imu = ekf.imu().pose();
        let extrinsic = ekf.extrinsic(self.sensor);
        let mut sum = 0.0;
        for c in &self.buffer {
            let p = msreg_estimator::update::reprojection::point_in_camera(
                &imu,
                &extrinsic,
                &target,
                &c.point_in_target,
            );
            match self.camera.project(&p) {
                Some(projected) => sum += (projected.pixel - c.pixel).norm().to_f64(),
                None => return f64::NAN,
            }
        }
        sum / self.buffer.len().max(1) as f64
    }
}
