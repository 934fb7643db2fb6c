//! The joint self-test: `JointEkf<f32>` over the joint sequence, from perturbed priors of
//! both extrinsics, both time offsets and the board pose, with checks that every
//! measurement is fused, every estimate converges and each ends inside its reported 3 sigma.

use core::mem::MaybeUninit;

use msreg_estimator::camera::Camera;
use msreg_estimator::lie;
use msreg_estimator::na::{Cholesky, Matrix6, Vector3, Vector6};
use msreg_estimator::state::imu;
use msreg_estimator::update::board_plane::BoardPlane;
use msreg_estimator::{
    CornerSet, Error, FilterConfig, InitialState, Layout, Pose, SensorId, UpdateKind, UpdateReport,
};

use super::scenario::{Image, JointConfig, JointEvent, JointScenario};
use super::{JointFilter, BOARD_FRAME, CAMERA, LIDAR};
use crate::scenario::{ImuReading, PoseIncrement};
use crate::selftest::{self, CovarianceCheck, ExtrinsicError, PRIOR_SIGMA};

/// Perturbation of the camera's extrinsic prior (rotation rad, translation m): about 3 deg
/// and 6 cm, in other directions than the LiDAR's ([`selftest::PRIOR_ERROR`]).
pub const CAMERA_PRIOR_ERROR: ([f32; 3], [f32; 3]) = ([-0.04, 0.02, 0.03], [0.03, 0.04, -0.03]);
/// 1-sigma of both time-offset priors, s (the prior mean is zero).
pub const TIME_OFFSET_SIGMA: f32 = 2e-3;
/// 1-sigma of the board-pose prior (rotation rad, position m): it is the camera prior's
/// error carried 2 m out by the first image's PnP pose.
pub const BOARD_SIGMA: (f32, f32) = (0.1, 0.25);

/// What the joint run needs besides the filter.
pub struct JointSetup {
    /// The sequence's parameters (truth included).
    pub config: JointConfig,
    /// The camera model (known, not estimated).
    pub camera: Camera<f32>,
}

/// True `T_I_S` of sensor `s` as an estimator pose.
pub fn truth(config: &JointConfig, s: SensorId) -> Pose<f32> {
    let t = if s == CAMERA {
        config.t_i_c
    } else {
        config.base.t_i_s
    };
    Pose::new(t.rotation, t.translation.vector)
}

/// The extrinsic prior of sensor `s`: the truth perturbed.
pub fn prior(config: &JointConfig, s: SensorId) -> Pose<f32> {
    let (rot, trans) = if s == CAMERA {
        CAMERA_PRIOR_ERROR
    } else {
        selftest::PRIOR_ERROR
    };
    truth(config, s).boxplus(&Vector3::from(rot), &Vector3::from(trans))
}

/// Builds the filter in `slot` (static storage: a `JointEkf<f32>` is 17 KB, and each
/// by-value copy of it would cost that much stack): at rest at the first IMU sample, both
/// extrinsic priors perturbed, zero time offsets, and the board where the first image's PnP
/// pose puts it through the camera prior (`T_G_I * T_I_C(prior) * T_C_T`, with `T_C_T` of
/// the first image taken as exact: 42 corners at 0.5 px fix it to millimetres, far below
/// the prior's error).
pub fn place_filter<'a>(
    slot: &'a mut MaybeUninit<JointFilter>,
    setup: &JointSetup,
    first: &ImuReading,
) -> Result<&'a mut JointFilter, Error> {
    let c = &setup.config;
    let init = InitialState::at_rest(first.accel)
        .ok_or(Error::InvalidConfig)?
        .with_extrinsic(LIDAR, prior(c, LIDAR), PRIOR_SIGMA.0, PRIOR_SIGMA.1)
        .with_time_offset(LIDAR, 0.0, TIME_OFFSET_SIGMA)
        .with_extrinsic(CAMERA, prior(c, CAMERA), PRIOR_SIGMA.0, PRIOR_SIGMA.1)
        .with_time_offset(CAMERA, 0.0, TIME_OFFSET_SIGMA);
    let config =
        crate::propagation::device_config(FilterConfig::new(selftest::imu_noise(&c.base.spec)));
    let filter = slot.write(JointFilter::new(&config, &init)?);
    let scenario = JointScenario::new(*c).ok_or(Error::InvalidConfig)?;
    let t_c_t = scenario.camera_to_board(c.camera_time_offset);
    let t_c_t = Pose::new(t_c_t.rotation, t_c_t.translation.vector);
    let board = filter
        .imu()
        .pose()
        .compose(&prior(c, CAMERA))
        .compose(&t_c_t);
    filter.init_frame(BOARD_FRAME, board, BOARD_SIGMA.0, BOARD_SIGMA.1)?;
    Ok(filter)
}

/// Feeds one event to the filter; the update report for measurements. Each kind of call
/// is out of line, so that their temporaries share stack instead of adding up in one frame.
pub fn feed(
    filter: &mut JointFilter,
    setup: &JointSetup,
    event: &JointEvent,
) -> Result<Option<UpdateReport<f32>>, Error> {
    match event {
        JointEvent::Imu(m) => propagate(filter, m).map(|()| None),
        JointEvent::LidarAnchor { stamp_ns } => anchor(filter, *stamp_ns).map(|()| None),
        JointEvent::LidarIncrement(inc) => relative_pose(filter, setup, inc).map(Some),
        JointEvent::Image(image) => reprojection(filter, setup, image).map(Some),
        JointEvent::Plane(plane) => board_plane(filter, plane).map(Some),
        JointEvent::BadPlane { error, .. } => Err(*error),
    }
}

#[inline(never)]
fn propagate(filter: &mut JointFilter, m: &ImuReading) -> Result<(), Error> {
    filter.propagate(&selftest::imu_sample(m))
}

#[inline(never)]
fn anchor(filter: &mut JointFilter, stamp_ns: u64) -> Result<(), Error> {
    filter.anchor(LIDAR, stamp_ns)
}

#[inline(never)]
fn relative_pose(
    filter: &mut JointFilter,
    setup: &JointSetup,
    inc: &PoseIncrement,
) -> Result<UpdateReport<f32>, Error> {
    let meas = selftest::relative_pose(inc, &setup.config.base.spec);
    filter.update_relative_pose(LIDAR, &meas)
}

#[inline(never)]
fn reprojection(
    filter: &mut JointFilter,
    setup: &JointSetup,
    image: &Image,
) -> Result<UpdateReport<f32>, Error> {
    let meas = CornerSet {
        stamp_ns: image.stamp_ns,
        corners: &image.corners,
        pixel_sigma: setup.config.pixel_sigma,
    };
    filter.update_reprojection(CAMERA, BOARD_FRAME, &setup.camera, &meas)
}

#[inline(never)]
fn board_plane(
    filter: &mut JointFilter,
    plane: &BoardPlane<f32>,
) -> Result<UpdateReport<f32>, Error> {
    filter.update_board_plane(LIDAR, BOARD_FRAME, plane)
}

/// The sensor whose clock stamps a measurement event, and the stamp; `None` for IMU samples.
fn sensor_stamp(event: &JointEvent) -> Option<(SensorId, u64)> {
    match event {
        JointEvent::Imu(_) => None,
        JointEvent::LidarAnchor { stamp_ns } | JointEvent::BadPlane { stamp_ns, .. } => {
            Some((LIDAR, *stamp_ns))
        }
        JointEvent::LidarIncrement(inc) => Some((LIDAR, inc.stamp_to_ns)),
        JointEvent::Plane(plane) => Some((LIDAR, plane.stamp_ns)),
        JointEvent::Image(image) => Some((CAMERA, image.stamp_ns)),
    }
}

/// Measurements waiting until the filter can fuse them. The one rule is the estimator's:
/// a measurement is due when its IMU time `stamp + t_d` (with the current `t_d` estimate)
/// is at or before the newest IMU sample (`Ekf::is_due`), and due measurements go in IMU
/// time order, so that one sensor's update never moves the filter past another's.
#[derive(Default)]
pub struct Pending {
    queue: heapless::Vec<JointEvent, 4>,
    dropped: u32,
}

impl Pending {
    /// Holds a measurement (an IMU sample is handed back: it is never held).
    pub fn hold(&mut self, event: JointEvent) -> Option<JointEvent> {
        if sensor_stamp(&event).is_none() {
            return Some(event);
        }
        if self.queue.push(event).is_err() {
            self.dropped += 1;
        }
        None
    }

    /// The due measurement with the earliest IMU time, if any.
    pub fn next_due(&mut self, filter: &JointFilter) -> Option<JointEvent> {
        let mut best: Option<(usize, u64)> = None;
        for (k, event) in self.queue.iter().enumerate() {
            let Some((s, stamp)) = sensor_stamp(event) else {
                continue;
            };
            let due = filter.is_due(s, stamp);
            if let (true, Ok(t)) = (due, filter.imu_time(s, stamp)) {
                if best.is_none_or(|(_, b)| t < b) {
                    best = Some((k, t));
                }
            }
        }
        best.map(|(k, _)| self.queue.remove(k))
    }

    /// Measurements still waiting.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// True when nothing waits.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }

    /// Measurements lost to a full queue.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }
}

/// Feeds the sequence's events through [`Pending`]: every filter call goes through `apply`
/// (which the benchmark times). Returns the measurements left waiting and those dropped.
pub fn drive(
    filter: &mut JointFilter,
    events: impl Iterator<Item = JointEvent>,
    mut apply: impl FnMut(&mut JointFilter, &JointEvent),
) -> (usize, u32) {
    let mut pending = Pending::default();
    for event in events {
        if let Some(imu) = pending.hold(event) {
            apply(filter, &imu);
        }
        while let Some(due) = pending.next_due(filter) {
            apply(filter, &due);
        }
    }
    (pending.len(), pending.dropped())
}

/// Calls and gate outcomes of one update kind.
#[derive(Clone, Copy, Debug, Default)]
pub struct Tally {
    /// Updates processed (accepted or gated out).
    pub calls: u32,
    /// Updates the gate accepted.
    pub accepted: u32,
}

/// What the joint filter went through.
#[derive(Clone, Copy, Debug, Default)]
pub struct JointCounts {
    /// IMU samples propagated.
    pub imu_samples: u32,
    /// LiDAR anchors set.
    pub anchors: u32,
    /// LiDAR relative-pose updates.
    pub relative_poses: Tally,
    /// Reprojection updates (images).
    pub images: Tally,
    /// Board-plane updates.
    pub planes: Tally,
    /// Corners outside the image over all images (sequence validity).
    pub corners_outside: u32,
    /// Calls that returned an error.
    pub errors: u32,
    /// The first error.
    pub first_error: Option<Error>,
}

impl JointCounts {
    /// Counts the outcome of one [`feed`].
    pub fn record(
        &mut self,
        event: &JointEvent,
        outcome: &Result<Option<UpdateReport<f32>>, Error>,
    ) {
        if let JointEvent::Image(image) = event {
            self.corners_outside += image.outside;
        }
        let report = match outcome {
            Err(e) => {
                self.errors += 1;
                self.first_error.get_or_insert(*e);
                return;
            }
            Ok(None) => {
                match event {
                    JointEvent::Imu(_) => self.imu_samples += 1,
                    JointEvent::LidarAnchor { .. } => self.anchors += 1,
                    JointEvent::LidarIncrement(_)
                    | JointEvent::Image(_)
                    | JointEvent::Plane(_)
                    | JointEvent::BadPlane { .. } => {}
                }
                return;
            }
            Ok(Some(report)) => report,
        };
        let tally = match report.kind {
            UpdateKind::RelativePose => &mut self.relative_poses,
            UpdateKind::Reprojection => &mut self.images,
            UpdateKind::BoardPlane => &mut self.planes,
            UpdateKind::ZeroVelocity => return,
        };
        tally.calls += 1;
        tally.accepted += u32::from(report.accepted);
    }
}

/// One sensor's estimate against the truth.
#[derive(Clone, Copy, Debug)]
pub struct SensorResult {
    /// True extrinsic.
    pub truth: Pose<f32>,
    /// Final estimate.
    pub estimate: Pose<f32>,
    /// Error of the prior.
    pub initial_error: ExtrinsicError,
    /// Error of the estimate.
    pub final_error: ExtrinsicError,
    /// Error per axis divided by its 1-sigma (rotation x, y, z; translation x, y, z).
    pub normalized: Vector6<f32>,
    /// NEES of the 6-dof extrinsic error over the extrinsic's covariance (NaN when that
    /// covariance is not positive definite).
    pub nees: f32,
    /// Estimated time offset, s.
    pub time_offset: f32,
    /// Its error against the truth divided by its 1-sigma.
    pub time_offset_normalized: f32,
}

/// Per-axis error of `estimate` against `truth` over the 1-sigma of `cov_diag`
/// (right perturbation: `R_true = R_est Exp(d)`).
fn normalized_error(estimate: &Pose<f32>, truth: &Pose<f32>, sigma: &Vector6<f32>) -> Vector6<f32> {
    let d_rot = lie::log(&(estimate.rotation.inverse() * truth.rotation));
    let d_trans = truth.translation - estimate.translation;
    let mut e = Vector6::zeros();
    for k in 0..3 {
        e[k] = d_rot[k] / sigma[k];
        e[k + 3] = d_trans[k] / sigma[k + 3];
    }
    e
}

/// `e^T P^-1 e` of the extrinsic error `e` (as [`normalized_error`]) over its 6 x 6
/// covariance `cov`; NaN when `cov` is not positive definite.
fn extrinsic_nees(estimate: &Pose<f32>, truth: &Pose<f32>, cov: &Matrix6<f32>) -> f32 {
    let d_rot = lie::log(&(estimate.rotation.inverse() * truth.rotation));
    let d_trans = truth.translation - estimate.translation;
    let e = Vector6::new(d_rot.x, d_rot.y, d_rot.z, d_trans.x, d_trans.y, d_trans.z);
    Cholesky::new(*cov).map_or(f32::NAN, |c| e.dot(&c.solve(&e)))
}

/// Sensor `s`'s result at the end of the run.
pub fn sensor_result(filter: &JointFilter, config: &JointConfig, s: SensorId) -> SensorResult {
    let truth = truth(config, s);
    let estimate = filter.extrinsic(s);
    let (sr, st) = filter.extrinsic_sigma(s);
    let sigma = Vector6::new(sr.x, sr.y, sr.z, st.x, st.y, st.z);
    let true_offset = if s == CAMERA {
        config.camera_time_offset
    } else {
        0.0
    };
    let time_offset = filter.time_offset(s);
    SensorResult {
        truth,
        estimate,
        initial_error: ExtrinsicError::between(&prior(config, s), &truth),
        final_error: ExtrinsicError::between(&estimate, &truth),
        normalized: normalized_error(&estimate, &truth, &sigma),
        nees: extrinsic_nees(&estimate, &truth, &filter.extrinsic_covariance(s)),
        time_offset,
        time_offset_normalized: (time_offset - true_offset) / filter.time_offset_sigma(s),
    }
}

/// The board pose's error per axis over its 1-sigma.
pub fn board_normalized(filter: &JointFilter, config: &JointConfig) -> Option<Vector6<f32>> {
    let estimate = filter.frame(BOARD_FRAME)?;
    let t = config.t_g_t;
    let truth = Pose::new(t.rotation, t.translation.vector);
    let cov = filter.frame_covariance(BOARD_FRAME);
    let sigma = Vector6::from_fn(|k, _| libm::sqrtf(cov[(k, k)].max(0.0)));
    Some(normalized_error(&estimate, &truth, &sigma))
}

/// NEES of the board pose's 6-dof error over its covariance.
pub fn board_nees(filter: &JointFilter, config: &JointConfig) -> Option<f32> {
    let estimate = filter.frame(BOARD_FRAME)?;
    let t = config.t_g_t;
    let truth = Pose::new(t.rotation, t.translation.vector);
    Some(extrinsic_nees(
        &estimate,
        &truth,
        &filter.frame_covariance(BOARD_FRAME),
    ))
}

/// Covariance health over the whole joint state: positive diagonal on the IMU, both
/// sensors (extrinsics and time offsets) and the board; free clone slots may be zero.
pub fn covariance_check(filter: &JointFilter) -> CovarianceCheck {
    type L = Layout<2, 4>;
    let board = L::frame_orientation(BOARD_FRAME).idx..L::frame_position(BOARD_FRAME).end();
    let required = (0..imu::DIM)
        .chain(L::extrinsic(LIDAR).idx..L::time_offset(LIDAR).end())
        .chain(L::extrinsic(CAMERA).idx..L::time_offset(CAMERA).end())
        .chain(board);
    CovarianceCheck::of_matrix(&filter.covariance(), required)
}
