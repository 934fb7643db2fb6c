//! Camera-IMU calibration of a rig with several cameras in one filter (issue 32): the IMU,
//! every camera as a sensor of its own (extrinsic `T_imu_camN` and time offset each) and the
//! one static target, whose pose all cameras' corners observe. Each camera's corners are
//! fused through the shared IMU state and target pose, in the order of their IMU times, so
//! the filter's covariance holds the cross terms between the cameras' extrinsics, and the
//! camera chain `T_cn_cnm1` is derived from them ([`compose_chain`]).
//!
//! Each camera starts as the single-camera RepErrCal does: MoCal on its own PnP odometry,
//! then RepErrCal's prior around that estimate (the IMU state from camera 0's start). With
//! one camera, [`calibrate_cameras`] is [`calibrate`] itself.

use std::time::Instant;

use msreg_estimator::camera::Camera;
use msreg_estimator::{Ekf, FilterConfig, InitialState, Layout, Scalar, SensorId};
use nalgebra::Matrix6;

use super::chain::{compose_chain, CameraChainLink};
use super::model_error::{self, cam_imu, finite, Window};
use super::*;
use crate::calibrate::driver::report::{PoseImuOptions, Timing};
use crate::calibrate::driver::{drive_imu, ImuHooks};
use crate::calibrate::jackknife::{self, Estimate, ModelErrorReport};
use crate::dataset::{CalibrationResult, ExtrinsicEstimate, SectionName};

/// Most cameras one filter takes (the filter's dimension is fixed at compile time:
/// `15 + 7 N + 6` error states).
pub const MAX_CAMERAS: usize = 4;

/// The camera names in messages and reports, by index.
const NAMES: [&str; MAX_CAMERAS] = ["cam0", "cam1", "cam2", "cam3"];
const FOLDERS: [&str; MAX_CAMERAS] = ["cam0/", "cam1/", "cam2/", "cam3/"];

/// One camera of the rig: its model and its corner frames.
#[derive(Debug, Clone, Copy)]
pub struct CameraFrames<'a> {
    /// The camera model (`camN/camera.yaml`).
    pub camera: &'a Camera<f64>,
    /// Detected corners per image, increasing stamps.
    pub frames: &'a [CornerFrame],
}

/// What the multi-camera pipeline reads.
#[derive(Debug, Clone, Copy)]
pub struct MultiCameraImuInput<'a> {
    /// IMU samples, strictly increasing stamps.
    pub imu: &'a [ImuRecord],
    /// IMU noise densities.
    pub imu_noise: &'a ImuNoiseYaml,
    /// The cameras `cam0..camN-1`, in order.
    pub cameras: &'a [CameraFrames<'a>],
}

impl<'a> MultiCameraImuInput<'a> {
    /// The single-camera input of camera `k`.
    fn camera(&self, k: usize) -> CameraImuInput<'a> {
        let c = self.cameras[k];
        CameraImuInput {
            imu: self.imu,
            imu_noise: self.imu_noise,
            camera: c.camera,
            frames: c.frames,
        }
    }
}

/// The outcome: every camera's calibration (as the single-camera pipeline reports it) and
/// the camera chain.
#[derive(Debug, Clone)]
pub struct MultiCameraImuCalibration {
    /// Camera `n`'s `T_imu_camN`, time offset, covariance and report.
    pub cameras: Vec<CameraImuCalibration>,
    /// `chain[n - 1]`: camera `n`'s `T_cn_cnm1` with its covariance, from the joint
    /// covariance of the two extrinsics (cross terms included).
    pub chain: Vec<CameraChainLink>,
    /// `chain_model_error[n - 1]`: the link's model error and written covariance (the
    /// time-block spread of the chain itself; empty when not measured).
    pub chain_model_error: Vec<ChainModelError>,
}

/// A chain link's data-driven model error ([`crate::calibrate::jackknife`]).
#[derive(Debug, Clone)]
pub struct ChainModelError {
    /// The result file's covariance of `T_cn_cnm1` (`[dtheta (right); dp]`).
    pub written: Matrix6<f64>,
    /// What the report says of it (its time-offset entries are zero: the chain has none).
    pub report: ModelErrorReport,
}

impl MultiCameraImuCalibration {
    /// The result file: `camN.T_cam_imu` and `timeshift_cam_imu` of every camera, and
    /// `camN.T_cn_cnm1` for `N >= 1`.
    pub fn result(&self) -> CalibrationResult {
        let mut result = CalibrationResult::new();
        for (n, camera) in self.cameras.iter().enumerate() {
            result.set_extrinsic(SectionName::cam(n as u16), camera.cam_imu_estimate());
        }
        for (k, link) in self.chain.iter().enumerate() {
            let covariance = self
                .chain_model_error
                .get(k)
                .map_or(link.covariance, |m| m.written);
            result
                .section_mut(SectionName::cam(k as u16 + 1))
                .camera_chain = Some(ExtrinsicEstimate::from_covariance(
                link.t_cn_cnm1,
                0.0,
                &covariance,
            ));
        }
        result
    }

    /// True when every camera's result passed its checks.
    pub fn converged(&self) -> bool {
        self.cameras.iter().all(|c| c.report.filter.converged)
    }
}

/// Calibrates every camera of `input` against the IMU in one filter with scalar type `T`;
/// `progress` gets the fraction done. One camera is [`calibrate`]; MoCal
/// ([`CameraUpdate::Motion`]) runs one filter per camera (its chain has no cross terms).
pub fn calibrate_cameras<T: Scalar>(
    input: &MultiCameraImuInput<'_>,
    options: &CameraImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<MultiCameraImuCalibration, InputError> {
    match input.cameras.len() {
        0 => Err(InputError::TooFew {
            file: "cam0/",
            what: "cameras",
            found: 0,
            needed: 1,
        }),
        1 => Ok(MultiCameraImuCalibration {
            cameras: vec![calibrate::<T>(&input.camera(0), options, progress)?],
            chain: Vec::new(),
            chain_model_error: Vec::new(),
        }),
        2 => {
            calibrate_rig::<T, 2, { Layout::<2, 0>::dim_with_frames(1) }>(input, options, progress)
        }
        3 => {
            calibrate_rig::<T, 3, { Layout::<3, 0>::dim_with_frames(1) }>(input, options, progress)
        }
        4 => {
            calibrate_rig::<T, 4, { Layout::<4, 0>::dim_with_frames(1) }>(input, options, progress)
        }
        found => Err(InputError::TooManyCameras {
            found,
            max: MAX_CAMERAS,
        }),
    }
}

/// The `S`-camera filter (`N` error states): MoCal per camera, RepErrCal of all cameras in
/// one filter, and a verification pass with the extrinsics and time offsets held.
fn calibrate_rig<T: Scalar, const S: usize, const N: usize>(
    input: &MultiCameraImuInput<'_>,
    options: &CameraImuOptions,
    progress: &mut dyn FnMut(f64),
) -> Result<MultiCameraImuCalibration, InputError> {
    let started = Instant::now();
    let inputs: Vec<CameraImuInput<'_>> = (0..S).map(|k| input.camera(k)).collect();
    let poses: Vec<Vec<FramePose>> = inputs
        .iter()
        .map(|c| frame_poses(c.camera, c.frames))
        .collect();
    let mut motions = Vec::with_capacity(S);
    for (k, (camera, poses)) in inputs.iter().zip(&poses).enumerate() {
        let share = |f: f64| 0.3 * (k as f64 + f) / S as f64;
        let motion = motion_calibration::<T>(camera, poses, options, &mut |f| progress(share(f)))
            .map_err(|e| name_camera(e, k))?;
        motions.push(motion);
    }
    if options.update == CameraUpdate::Motion {
        let cameras: Vec<_> = motions.into_iter().map(|(m, _)| m).collect();
        let chain = independent_chain(&cameras);
        return Ok(MultiCameraImuCalibration {
            cameras,
            chain,
            chain_model_error: Vec::new(),
        });
    }
    let starts: Vec<Start<'_>> = motions
        .iter()
        .zip(&poses)
        .map(|((motion, pixel_sigma), poses)| Start {
            motion,
            pixel_sigma: *pixel_sigma,
            poses,
        })
        .collect();
    let rig = Rig {
        inputs: &inputs,
        options,
    };
    let (mut cameras, chain) =
        rig.pass::<T, S, N>(&starts, ExtrinsicPrior::AroundStart, started, &mut |f| {
            progress(0.3 + 0.6 * f)
        })?;
    let held: Vec<Start<'_>> = cameras
        .iter()
        .zip(&starts)
        .map(|(c, s)| Start { motion: c, ..*s })
        .collect();
    let (verification, _) =
        rig.pass::<T, S, N>(&held, ExtrinsicPrior::Held, Instant::now(), &mut |f| {
            progress(0.9 + 0.1 * f)
        })?;
    for (c, v) in cameras.iter_mut().zip(&verification) {
        c.report.verification_reprojection_error_px = v.report.mean_reprojection_error_px;
    }
    let mut calibration = MultiCameraImuCalibration {
        cameras,
        chain,
        chain_model_error: Vec::new(),
    };
    if options.model_error {
        rig.add_model_error::<T, S, N>(&starts, &mut calibration);
    }
    progress(1.0);
    Ok(calibration)
}

/// A camera's error named by its folder (the single-camera messages say `cam0`).
fn name_camera(error: InputError, k: usize) -> InputError {
    match error {
        InputError::TooFewTargetPoses { found, needed, .. } if k > 0 => InputError::TooFew {
            file: FOLDERS[k],
            what: "images with a target pose",
            found,
            needed,
        },
        e => e,
    }
}

/// The chain of separately calibrated cameras (no cross-covariance).
fn independent_chain(cameras: &[CameraImuCalibration]) -> Vec<CameraChainLink> {
    cameras
        .windows(2)
        .map(|w| {
            compose_chain(
                (&w[1].t_imu_sensor, &w[1].covariance),
                (&w[0].t_imu_sensor, &w[0].covariance),
                &Matrix6::zeros(),
            )
        })
        .collect()
}

/// The rig's cameras and the options every pass shares.
struct Rig<'a, 'b> {
    inputs: &'b [CameraImuInput<'a>],
    options: &'b CameraImuOptions,
}

/// The filter of one pass at its start, and what each camera's report says of it.
struct RigStart<T: Scalar, const S: usize, const N: usize> {
    ekf: Ekf<T, S, 0, N, 1>,
    priors: Vec<PoseImuOptions>,
    rotation_inits: Vec<init::RotationInit>,
    /// Report words of the IMU start: gyro bias and moving start (camera 0's).
    words: (String, String),
}

impl Rig<'_, '_> {
    /// One RepErrCal pass of the rig's filter from `starts` (one per camera): every camera's
    /// calibration and the chain.
    fn pass<T: Scalar, const S: usize, const N: usize>(
        &self,
        starts: &[Start<'_>],
        extrinsic_prior: ExtrinsicPrior,
        started: Instant,
        progress: &mut dyn FnMut(f64),
    ) -> Result<(Vec<CameraImuCalibration>, Vec<CameraChainLink>), InputError> {
        let imu = self.inputs[0].imu;
        if imu.is_empty() {
            return Err(InputError::NoImuSamples);
        }
        let standstill = init::detect_standstill(imu, self.options.prior.min_standstill_s);
        let RigStart {
            mut ekf,
            priors,
            rotation_inits,
            words,
        } = self.start::<T, S, N>(standstill.as_ref(), starts, extrinsic_prior)?;
        let init_s = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let mut feed = RigFeed {
            feeds: (0..S)
                .map(|k| {
                    CornerFeed::new(
                        &self.inputs[k],
                        self.options,
                        &starts[k],
                        priors[k],
                        sensor::<S>(k),
                    )
                    .named(NAMES[k])
                })
                .collect(),
        };
        drive_imu(&mut ekf, imu, standstill.as_ref(), progress, &mut feed)?;
        let timing = Timing {
            init: init_s,
            filter: started.elapsed().as_secs_f64(),
        };
        let mut cameras = Vec::with_capacity(S);
        for (k, mut corners) in feed.feeds.into_iter().enumerate() {
            corners.skip_remaining();
            let CornerFeed {
                run,
                reprojection,
                sample,
                pixel_sigma,
                ..
            } = corners;
            let calibration = finish(&ekf, run, standstill.as_ref(), &rotation_inits[k], timing);
            cameras.push(reprojection_report(
                calibration,
                (reprojection, sample),
                (starts[k].motion, &priors[k], pixel_sigma.to_f64()),
                words.clone(),
            ));
        }
        Ok((cameras, chain(&ekf)))
    }

    /// The rig's filter: camera 0's start sets the IMU state and the filter configuration,
    /// each camera's own start its extrinsic and time-offset prior (sensor `k`).
    fn start<T: Scalar, const S: usize, const N: usize>(
        &self,
        standstill: Option<&init::Standstill>,
        starts: &[Start<'_>],
        extrinsic_prior: ExtrinsicPrior,
    ) -> Result<RigStart<T, S, N>, InputError> {
        let mut priors = Vec::with_capacity(S);
        let mut rotation_inits = Vec::with_capacity(S);
        let mut sensors = Vec::with_capacity(S);
        let mut first: Option<FirstStart<T>> = None;
        for (k, start) in starts.iter().enumerate() {
            let p = prior_from_motion::<T>(
                &self.inputs[k],
                self.options,
                standstill,
                start,
                extrinsic_prior,
            )?;
            priors.push(p.prior);
            rotation_inits.push(p.rotation_init);
            sensors.push(p.initial.sensors[0]);
            first.get_or_insert((p.initial, p.config, (p.gyro_bias_init, p.moving_start)));
        }
        let Some((c, config, words)) = first else {
            return Err(InputError::NoImuSamples);
        };
        let initial = InitialState::<T, S> {
            imu: c.imu,
            sigma_orientation: c.sigma_orientation,
            sigma_position: c.sigma_position,
            sigma_velocity: c.sigma_velocity,
            sigma_gyro_bias: c.sigma_gyro_bias,
            sigma_accel_bias: c.sigma_accel_bias,
            sensors: std::array::from_fn(|k| sensors[k]),
        };
        let ekf = Ekf::<T, S, 0, N, 1>::new(&config, &initial)
            .map_err(|error| InputError::InvalidNoise { error })?;
        Ok(RigStart {
            ekf,
            priors,
            rotation_inits,
            words,
        })
    }
}

impl Rig<'_, '_> {
    /// Every camera's and chain link's model error: the rig's RepErrCal on each time block
    /// alone (in parallel) from the same starts, each one's spread against its covariances
    /// ([`crate::calibrate::jackknife`]); the chain's from the blocks' own chains.
    fn add_model_error<T: Scalar, const S: usize, const N: usize>(
        &self,
        starts: &[Start<'_>],
        calibration: &mut MultiCameraImuCalibration,
    ) {
        use rayon::prelude::*;
        let started = Instant::now();
        let blocks = model_error::blocks_of(self.inputs[0].imu);
        let runs: Vec<Result<_, String>> = blocks
            .par_iter()
            .map(|span| {
                let windows: Vec<Window<'_>> = (self.inputs.iter().zip(starts))
                    .map(|(input, s)| Window::of(input, s.poses, *span))
                    .collect();
                let inputs: Vec<CameraImuInput<'_>> = windows.iter().map(|w| w.input).collect();
                let starts: Vec<Start<'_>> = (windows.iter().zip(starts))
                    .map(|(w, s)| Start {
                        poses: w.poses,
                        ..*s
                    })
                    .collect();
                let rig = Rig {
                    inputs: &inputs,
                    options: self.options,
                };
                rig.pass::<T, S, N>(
                    &starts,
                    ExtrinsicPrior::AroundStart,
                    Instant::now(),
                    &mut |_| {},
                )
                .map_err(|e| e.to_string())
            })
            .collect();
        let time_s = started.elapsed().as_secs_f64();
        for (k, camera) in calibration.cameras.iter_mut().enumerate() {
            let per_block: Vec<Result<Estimate, String>> = (runs.iter())
                .map(|r| finite(cam_imu(&r.as_ref().map_err(Clone::clone)?.0[k])))
                .collect();
            let (written, report) = jackknife::model_error(&cam_imu(camera), &per_block, time_s);
            model_error::set_model_error(camera, written, report);
        }
        let link = |l: &CameraChainLink| Estimate::new(l.t_cn_cnm1, &l.covariance, 0.0, 0.0);
        calibration.chain_model_error = (calibration.chain.iter().enumerate())
            .map(|(k, full)| {
                let per_block: Vec<Result<Estimate, String>> = (runs.iter())
                    .map(|r| finite(link(&r.as_ref().map_err(Clone::clone)?.1[k])))
                    .collect();
                let (written, report) = jackknife::model_error(&link(full), &per_block, time_s);
                ChainModelError {
                    written: written.fixed_view::<6, 6>(0, 0).into_owned(),
                    report,
                }
            })
            .collect();
    }
}

/// Camera 0's start: the IMU prior, the filter configuration and the report words of the
/// IMU start.
type FirstStart<T> = (InitialState<T, 1>, FilterConfig<T>, (String, String));

/// Camera `k` of an `S`-camera filter.
fn sensor<const S: usize>(k: usize) -> SensorId {
    SensorId::all::<S>()[k]
}

/// Every link `T_cn_cnm1` of the filter's cameras, from its joint covariance.
fn chain<T: Scalar, const S: usize, const N: usize>(
    ekf: &Ekf<T, S, 0, N, 1>,
) -> Vec<CameraChainLink> {
    let p = ekf.covariance();
    let block = |a: SensorId, b: SensorId| {
        let (a, b) = (
            Layout::<S, 0>::extrinsic(a).idx,
            Layout::<S, 0>::extrinsic(b).idx,
        );
        Matrix6::from_fn(|r, c| p[(a + r, b + c)].to_f64())
    };
    let ids = SensorId::all::<S>();
    ids.windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            compose_chain(
                (&convert_isometry(ekf, b), &block(b, b)),
                (&convert_isometry(ekf, a), &block(a, a)),
                &block(b, a),
            )
        })
        .collect()
}

fn convert_isometry<T: Scalar, const S: usize, const N: usize>(
    ekf: &Ekf<T, S, 0, N, 1>,
    s: SensorId,
) -> nalgebra::Isometry3<f64> {
    crate::calibrate::convert::isometry(&ekf.extrinsic(s))
}

/// The corner feeds of every camera, fused in the order of their images' IMU times.
struct RigFeed<'a, T: Scalar> {
    feeds: Vec<CornerFeed<'a, T>>,
}

impl<T: Scalar, const S: usize, const C: usize, const N: usize, const F: usize>
    ImuHooks<T, Ekf<T, S, C, N, F>> for RigFeed<'_, T>
{
    fn fuse_due(
        &mut self,
        ekf: &mut Ekf<T, S, C, N, F>,
        index: usize,
        _rec: &ImuRecord,
    ) -> Result<(), InputError> {
        loop {
            let next = self
                .feeds
                .iter()
                .enumerate()
                .filter_map(|(k, f)| {
                    let stamp = f.next_due(ekf)?;
                    Some((ekf.imu_time(f.sensor, stamp).unwrap_or(u64::MAX), k))
                })
                .min();
            let Some((_, k)) = next else {
                return Ok(());
            };
            self.feeds[k].fuse_next(ekf, index);
        }
    }
}
