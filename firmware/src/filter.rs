//! The filters the link runs, one per protocol [`SensorSet`], behind one type: the session
//! propagates, applies zero-velocity updates and reports estimates the same way for all,
//! and only the measurement handlers look inside. The configuration is applied as the host
//! computed it (`ImuPrior::State`, the monitor's hold axis and health tuning): nothing of
//! the prior is re-derived here.

use msreg_estimator::camera::{equidistant, radtan, Camera, Distortion, Intrinsics, Projection};
use msreg_estimator::chi2::Confidence;
use msreg_estimator::filter::MonitorEkf;
use msreg_estimator::health::NisStatus;
use msreg_estimator::na::{Quaternion, UnitQuaternion, Vector3};
use msreg_estimator::{
    CameraImuEkf, Ekf, Error as FilterError, FilterConfig, ImuNoise, ImuSample, ImuState,
    InitialState, Pose, PoseImuEkf, RelativePose, SensorId, UpdateReport,
};
use msreg_protocol::{self as protocol, CameraDistortion, CameraProjection, CameraSetup, Config};
use msreg_protocol::{Gate, ImuPrior, MonitorSetup, SensorPrior, SensorSet};

/// The camera of the camera-IMU layout, the pose sensor of the pose-IMU one.
pub use msreg_estimator::SOLE_SENSOR as SENSOR;
/// The one static target frame of the camera-IMU layout.
pub use msreg_estimator::TARGET_FRAME as TARGET;
/// The most sensors of a layout the firmware runs: the monitoring layout's two pose
/// sensors (the session keeps a queue for each).
pub const POSE_SENSORS: usize = 2;

/// The camera-IMU filter with the camera model and corner noise its updates use.
pub struct CameraFilter {
    /// IMU 15 + `T_I_C` 6 + `t_d` 1 + target frame `T_G_T` 6 states.
    pub ekf: CameraImuEkf<f32>,
    /// Projection of the configured camera.
    pub camera: Camera<f32>,
    /// Corner noise, 1-sigma per axis, pixels.
    pub pixel_sigma: f32,
}

/// The filter of the configured sensor set.
// The layouts differ in size (34, 28 and 53 states); without a heap there is no boxing.
#[allow(clippy::large_enum_variant)]
pub enum Filter {
    /// IMU + pose sensor (odometry increments).
    PoseImu(PoseImuEkf<f32>),
    /// IMU + camera observing a static target (corner reprojection).
    CameraImu(CameraFilter),
    /// On-vehicle monitoring: IMU + two pose sensors (LiDAR odometry, camera VO).
    Monitor(MonitorEkf<f32>),
}

/// The same expression on whichever [`msreg_estimator::Ekf`] the filter holds.
macro_rules! on_ekf {
    ($filter:expr, $ekf:ident => $body:expr) => {
        match $filter {
            Filter::PoseImu($ekf) => $body,
            Filter::CameraImu(CameraFilter { ekf: $ekf, .. }) => $body,
            Filter::Monitor($ekf) => $body,
        }
    };
}

impl Filter {
    /// Number of sensors of the layout (extrinsic and time offset each).
    pub fn sensor_count(&self) -> usize {
        match self {
            Filter::PoseImu(_) | Filter::CameraImu(_) => 1,
            Filter::Monitor(_) => 2,
        }
    }

    /// Sensor `wire` of the configured layout: the wire's `u8` checked against the layout
    /// (`UnknownSensor` beyond it), the only way a message's sensor reaches the filter.
    pub fn sensor_id(&self, wire: u8) -> Result<SensorId, FilterError> {
        on_ekf!(self, f => id_in(f, wire))
    }

    /// The sensors of the configured layout, in order.
    pub fn sensor_ids(&self) -> core::iter::Take<core::array::IntoIter<SensorId, POSE_SENSORS>> {
        SensorId::all::<POSE_SENSORS>()
            .into_iter()
            .take(self.sensor_count())
    }

    /// True for the layouts that take odometry (anchors and relative poses).
    pub fn takes_odometry(&self) -> bool {
        match self {
            Filter::PoseImu(_) | Filter::Monitor(_) => true,
            Filter::CameraImu(_) => false,
        }
    }

    /// Filter time (IMU clock), ns.
    pub fn time_ns(&self) -> u64 {
        on_ekf!(self, f => f.time_ns())
    }

    /// True when a measurement of sensor `s` stamped `stamp_ns` (sensor clock) can be
    /// fused: its IMU time `stamp + t_d` is at or before the newest IMU sample (the
    /// estimator's one rule).
    pub fn is_due(&self, s: SensorId, stamp_ns: u64) -> bool {
        on_ekf!(self, f => f.is_due(s, stamp_ns))
    }

    /// IMU time `stamp + t_d` of a measurement of sensor `s` (current `t_d`), ns.
    pub fn imu_time(&self, s: SensorId, stamp_ns: u64) -> Result<u64, FilterError> {
        on_ekf!(self, f => f.imu_time(s, stamp_ns))
    }

    /// Time offset `t_d` of sensor `s`, s.
    pub fn time_offset(&self, s: SensorId) -> f32 {
        on_ekf!(self, f => f.time_offset(s))
    }

    /// Its 1-sigma, s.
    pub fn time_offset_sigma(&self, s: SensorId) -> f32 {
        on_ekf!(self, f => f.time_offset_sigma(s))
    }

    /// `T_imu_sensor` of sensor `s`.
    pub fn extrinsic(&self, s: SensorId) -> Pose<f32> {
        on_ekf!(self, f => f.extrinsic(s))
    }

    /// 1-sigma of sensor `s`'s extrinsic rotation (rad) and translation (m), per axis.
    pub fn extrinsic_sigma(&self, s: SensorId) -> (Vector3<f32>, Vector3<f32>) {
        on_ekf!(self, f => f.extrinsic_sigma(s))
    }

    /// The health monitor's windowed NIS per dof of sensor `s` and its verdict (`None`
    /// for a sensor the layout does not have).
    pub fn nis(&self, s: SensorId) -> Option<(f32, NisStatus)> {
        on_ekf!(self, f => f.health().sensor(s).map(|h| {
            (h.windowed_nis_per_dof(), h.nis_status(&f.config().health))
        }))
    }

    /// Propagates with one IMU sample. Not inlined: the propagation's temporaries (~11 KB)
    /// must not sit in the caller's frame under the updates it calls next.
    #[inline(never)]
    pub fn propagate(&mut self, sample: &ImuSample<f32>) -> Result<(), FilterError> {
        on_ekf!(self, f => out_of_line::propagate(f, sample))
    }

    /// The IMU stream's period once two samples are in (a ZUPT needs it).
    pub fn imu_period_ns(&self) -> Option<u64> {
        on_ekf!(self, f => f.imu_period_ns())
    }

    /// Starts an odometry segment of sensor `s` (the layouts without odometry have no
    /// such sensor: the session refuses their odometry on arrival).
    #[inline(never)]
    pub fn anchor(&mut self, s: SensorId, stamp_ns: u64) -> Result<(), FilterError> {
        match self {
            Filter::PoseImu(f) => f.anchor(s, stamp_ns),
            Filter::Monitor(f) => f.anchor(s, stamp_ns),
            Filter::CameraImu(_) => Err(FilterError::UnknownSensor),
        }
    }

    /// One odometry increment of sensor `s` (its own frame, as [`Filter::propagate`]).
    #[inline(never)]
    pub fn update_relative_pose(
        &mut self,
        s: SensorId,
        meas: &RelativePose<f32>,
    ) -> Result<UpdateReport<f32>, FilterError> {
        match self {
            Filter::PoseImu(f) => out_of_line::relative_pose(f, s, meas),
            Filter::Monitor(f) => out_of_line::relative_pose(f, s, meas),
            Filter::CameraImu(_) => Err(FilterError::UnknownSensor),
        }
    }

    /// Zero-velocity update with the latest sample (its own frame, as [`Filter::propagate`]).
    #[inline(never)]
    pub fn update_zero_velocity(&mut self) -> Result<UpdateReport<f32>, FilterError> {
        on_ekf!(self, f => out_of_line::zero_velocity(f))
    }
}

/// One function per layout and call, never inlined: a wrapper that matched over the layouts
/// with the calls inlined got a frame holding every layout's temporaries at once (23.7 KB
/// for the zero-velocity update with three layouts).
mod out_of_line {
    use super::{Ekf, FilterError, ImuSample, RelativePose, SensorId, UpdateReport};

    #[inline(never)]
    pub(super) fn propagate<const S: usize, const C: usize, const N: usize, const F: usize>(
        f: &mut Ekf<f32, S, C, N, F>,
        sample: &ImuSample<f32>,
    ) -> Result<(), FilterError> {
        f.propagate(sample)
    }

    #[inline(never)]
    pub(super) fn relative_pose<const S: usize, const C: usize, const N: usize, const F: usize>(
        f: &mut Ekf<f32, S, C, N, F>,
        s: SensorId,
        meas: &RelativePose<f32>,
    ) -> Result<UpdateReport<f32>, FilterError> {
        f.update_relative_pose(s, meas)
    }

    #[inline(never)]
    pub(super) fn zero_velocity<const S: usize, const C: usize, const N: usize, const F: usize>(
        f: &mut Ekf<f32, S, C, N, F>,
    ) -> Result<UpdateReport<f32>, FilterError> {
        f.update_zero_velocity()
    }
}

fn confidence(g: Gate) -> Confidence {
    match g {
        Gate::P90 => Confidence::P90,
        Gate::P95 => Confidence::P95,
        Gate::P99 => Confidence::P99,
        Gate::P995 => Confidence::P995,
        Gate::P999 => Confidence::P999,
        Gate::P9999 => Confidence::P9999,
        Gate::P99999 => Confidence::P99999,
    }
}

/// A wire pose as the estimator's.
pub fn pose(p: &protocol::Pose) -> Pose<f32> {
    let [w, x, y, z] = p.rotation_wxyz;
    Pose::new(
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
        Vector3::from(p.translation_m),
    )
}

/// The camera model of a configuration (Kalibr's combinations only).
pub fn camera(setup: &CameraSetup) -> Result<Camera<f32>, FilterError> {
    let projection = match setup.projection {
        CameraProjection::Pinhole => Projection::Pinhole,
        CameraProjection::Omni { xi } => Projection::Omni { xi },
    };
    let distortion = match setup.distortion {
        CameraDistortion::None => Distortion::None,
        CameraDistortion::RadTan([k1, k2, p1, p2, k3]) => {
            Distortion::RadTan(radtan::RadTan { k1, k2, p1, p2, k3 })
        }
        CameraDistortion::Equidistant([k1, k2, k3, k4]) => {
            Distortion::Equidistant(equidistant::Equidistant { k1, k2, k3, k4 })
        }
    };
    let [fu, fv, cu, cv] = setup.intrinsics;
    let [width, height] = setup.resolution;
    Camera::new(
        projection,
        Intrinsics { fu, fv, cu, cv },
        distortion,
        (width, height),
    )
    .map_err(|_| FilterError::InvalidConfig)
}

/// The 1-sigma of a positive wire value, or the estimator's default for 0.
fn sigma_or(value: f32, default: f32) -> f32 {
    if value > 0.0 {
        value
    } else {
        default
    }
}

/// The IMU prior of a configuration: levelled on gravity at rest, or the host's state as is.
fn imu_prior<const S: usize>(p: &ImuPrior) -> Result<InitialState<f32, S>, FilterError> {
    match p {
        ImuPrior::AtRest(r) => {
            let mut init = InitialState::<f32, S>::at_rest(Vector3::from(r.accel_mean))
                .ok_or(FilterError::InvalidConfig)?;
            init.imu.gyro_bias = Vector3::from(r.gyro_bias);
            init.sigma_orientation = sigma_or(r.sigma_orientation_rad, init.sigma_orientation);
            init.sigma_velocity = sigma_or(r.sigma_velocity_m_s, init.sigma_velocity);
            Ok(init)
        }
        ImuPrior::State(s) => {
            // Any valid gravity reading: every field is overwritten below.
            let mut init = InitialState::<f32, S>::at_rest(Vector3::new(0.0, 0.0, 9.81))
                .ok_or(FilterError::InvalidConfig)?;
            let [w, x, y, z] = s.rotation_wxyz;
            let q = Quaternion::new(w, x, y, z);
            let norm = q.norm();
            if !norm.is_finite() || norm < 0.5 {
                return Err(FilterError::InvalidConfig);
            }
            init.imu = ImuState {
                rotation: UnitQuaternion::from_quaternion(q),
                position: Vector3::from(s.position_m),
                velocity: Vector3::from(s.velocity_m_s),
                gyro_bias: Vector3::from(s.gyro_bias_rad_s),
                accel_bias: Vector3::from(s.accel_bias_m_s2),
            };
            let [o, p, v, bg, ba] = s.sigmas;
            init.sigma_orientation = o;
            init.sigma_position = p;
            init.sigma_velocity = v;
            init.sigma_gyro_bias = bg;
            init.sigma_accel_bias = ba;
            Ok(init)
        }
    }
}

/// Sensor `wire` of filter `_f`'s layout ([`Filter::sensor_id`]).
fn id_in<const S: usize, const C: usize, const N: usize, const F: usize>(
    _f: &Ekf<f32, S, C, N, F>,
    wire: u8,
) -> Result<SensorId, FilterError> {
    SensorId::from_wire::<S>(wire)
}

/// Sets sensor `s`'s prior from the wire.
fn with_sensor<const S: usize>(
    init: InitialState<f32, S>,
    s: SensorId,
    p: &SensorPrior,
) -> Result<InitialState<f32, S>, FilterError> {
    let extrinsic = pose(&p.extrinsic);
    if !extrinsic.is_finite() {
        return Err(FilterError::NonFinite);
    }
    Ok(init
        .with_extrinsic(s, extrinsic, p.sigma_rotation_rad, p.sigma_translation_m)
        .with_time_offset(s, p.time_offset_s, p.sigma_time_offset_s))
}

pub use crate::propagation::device_config;

/// The filter tuning of a configuration (the health tuning of the monitor layout on top).
fn filter_config(c: &Config) -> Result<FilterConfig<f32>, FilterError> {
    let n = &c.imu_noise;
    let mut fc = device_config(FilterConfig::new(ImuNoise {
        gyro_noise_density: n.gyro_noise_density,
        accel_noise_density: n.accel_noise_density,
        gyro_random_walk: n.gyro_random_walk,
        accel_random_walk: n.accel_random_walk,
    }));
    fc.gate = confidence(c.gate);
    if c.max_imu_gap_ns > 0 {
        fc.max_imu_gap_ns = u64::from(c.max_imu_gap_ns);
    }
    match &c.sensors {
        SensorSet::PoseImu | SensorSet::CameraImu(_) => {}
        SensorSet::Monitor(m) => {
            let forgetting_ok = m.step_forgetting > 0.0 && m.step_forgetting <= 1.0;
            // Infinite is allowed (every direction tested); NaN and <= 0 are not.
            let factor = m.resolvable_step_factor;
            if !forgetting_ok || factor.is_nan() || factor <= 0.0 {
                return Err(FilterError::InvalidConfig);
            }
            fc.health.step_forgetting = m.step_forgetting;
            fc.health.resolvable_step_factor = m.resolvable_step_factor;
            fc.health.step_confidence = confidence(m.step_confidence);
            // The knock's own increment, as `msreg monitor` (docs/estimator.md).
            fc.health = fc.health.with_jump_detector();
        }
    }
    Ok(fc)
}

/// `Ekf::new` for a prior already checked, as the `Option<Filter>` the session keeps: the
/// caller assigns the result to its slot, so LLVM builds it there (one 14 KB temporary for
/// the monitoring filter instead of three); `None` only if the check missed something.
#[inline(never)]
fn build<const S: usize, const C: usize, const N: usize, const F: usize>(
    fc: &FilterConfig<f32>,
    init: &InitialState<f32, S>,
    variant: fn(Ekf<f32, S, C, N, F>) -> Filter,
) -> Option<Filter> {
    Ekf::new(fc, init).ok().map(variant)
}

/// What `Ekf::new` would refuse, checked before the slot is touched.
fn check_prior<const S: usize>(
    fc: &FilterConfig<f32>,
    init: &InitialState<f32, S>,
) -> Result<(), FilterError> {
    if init.is_valid() && fc.imu_noise.is_valid() {
        Ok(())
    } else {
        Err(FilterError::InvalidConfig)
    }
}

/// The planar hold axis of a monitor setup, checked as `Ekf::hold_translation_axis` checks
/// it (before anything is replaced).
fn hold_axis(m: &MonitorSetup) -> Result<Option<Vector3<f32>>, FilterError> {
    let Some(axis) = m.hold_translation_axis.map(Vector3::from) else {
        return Ok(None);
    };
    let norm = axis.norm();
    if !norm.is_finite() {
        return Err(FilterError::NonFinite);
    }
    if norm <= 0.0 {
        return Err(FilterError::InvalidConfig);
    }
    Ok(Some(axis))
}

/// The monitoring filter into `slot`: both sensors' priors, the lever arm along the planar
/// axis held. One layout per function, so that only the configured one's temporaries are
/// on the stack.
#[inline(never)]
fn place_monitor(
    slot: &mut Option<Filter>,
    fc: &FilterConfig<f32>,
    c: &Config,
    m: &MonitorSetup,
) -> Result<(), FilterError> {
    let [pose0, pose1] = MonitorEkf::<f32>::sensor_ids();
    let init = with_sensor(imu_prior::<2>(&c.imu_prior)?, pose0, &c.sensor)?;
    let init = with_sensor(init, pose1, &m.pose1)?;
    let axis = hold_axis(m)?;
    check_prior(fc, &init)?;
    *slot = build(fc, &init, Filter::Monitor);
    match (slot.as_mut(), axis) {
        (Some(Filter::Monitor(ekf)), Some(axis)) => {
            for s in MonitorEkf::<f32>::sensor_ids() {
                ekf.hold_translation_axis(s, Some(axis))?;
            }
            Ok(())
        }
        (Some(_), None) => Ok(()),
        (Some(Filter::PoseImu(_) | Filter::CameraImu(_)), Some(_)) | (None, _) => {
            Err(FilterError::InvalidConfig)
        }
    }
}

/// The pose-IMU filter into `slot`.
#[inline(never)]
fn place_pose_imu(
    slot: &mut Option<Filter>,
    fc: &FilterConfig<f32>,
    c: &Config,
) -> Result<(), FilterError> {
    let init = with_sensor(imu_prior::<1>(&c.imu_prior)?, SENSOR, &c.sensor)?;
    check_prior(fc, &init)?;
    *slot = build(fc, &init, Filter::PoseImu);
    slot.as_ref().map(|_| ()).ok_or(FilterError::InvalidConfig)
}

/// The camera-IMU filter with its camera into `slot`.
#[inline(never)]
fn place_camera_imu(
    slot: &mut Option<Filter>,
    fc: &FilterConfig<f32>,
    c: &Config,
    setup: &CameraSetup,
) -> Result<(), FilterError> {
    let sigma = setup.pixel_sigma;
    if !(sigma.is_finite() && sigma > 0.0) {
        return Err(FilterError::InvalidConfig);
    }
    let init = with_sensor(imu_prior::<1>(&c.imu_prior)?, SENSOR, &c.sensor)?;
    let camera = camera(setup)?;
    check_prior(fc, &init)?;
    *slot = Some(Filter::CameraImu(CameraFilter {
        camera,
        ekf: Ekf::new(fc, &init)?,
        pixel_sigma: sigma,
    }));
    Ok(())
}

/// Replaces `slot` with the filter of a configuration. Everything the filter could refuse
/// is checked first, so an invalid configuration leaves `slot` as it was. Each layout is
/// built in its own function (the monitoring filter is 14 KB, and each by-value copy of it
/// is stack).
#[inline(never)]
pub fn configure(slot: &mut Option<Filter>, c: &Config) -> Result<(), FilterError> {
    let fc = filter_config(c)?;
    match &c.sensors {
        SensorSet::PoseImu => place_pose_imu(slot, &fc, c),
        SensorSet::CameraImu(setup) => place_camera_imu(slot, &fc, c, setup),
        SensorSet::Monitor(m) => place_monitor(slot, &fc, c, m),
    }
}
