//! The filters the link runs, one per protocol [`SensorSet`], behind one type: the session
//! propagates, applies zero-velocity updates and reports estimates the same way for both,
//! and only the measurement handlers look inside.

use msreg_estimator::camera::{equidistant, radtan, Camera, Distortion, Intrinsics, Projection};
use msreg_estimator::chi2::Confidence;
use msreg_estimator::health::HealthMonitor;
use msreg_estimator::na::{Quaternion, UnitQuaternion, Vector3};
use msreg_estimator::{
    CameraImuEkf, Error as FilterError, FilterConfig, ImuNoise, ImuSample, InitialState, Pose,
    PoseImuEkf, UpdateReport,
};
use msreg_protocol::{self as protocol, CameraDistortion, CameraProjection, CameraSetup, Config};
use msreg_protocol::{Gate, SensorSet};

/// The one sensor of both layouts (index of the extrinsic and time offset).
pub const SENSOR: usize = 0;
/// The one static target frame of the camera-IMU layout.
pub const TARGET: usize = 0;

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
// The layouts differ in size (34 against 28 states); without a heap there is no boxing.
#[allow(clippy::large_enum_variant)]
pub enum Filter {
    /// IMU + pose sensor (odometry increments).
    PoseImu(PoseImuEkf<f32>),
    /// IMU + camera observing a static target (corner reprojection).
    CameraImu(CameraFilter),
}

/// The same expression on whichever [`msreg_estimator::Ekf`] the filter holds.
macro_rules! on_ekf {
    ($filter:expr, $ekf:ident => $body:expr) => {
        match $filter {
            Filter::PoseImu($ekf) => $body,
            Filter::CameraImu(CameraFilter { ekf: $ekf, .. }) => $body,
        }
    };
}

impl Filter {
    /// Filter time (IMU clock), ns.
    pub fn time_ns(&self) -> u64 {
        on_ekf!(self, f => f.time_ns())
    }

    /// True when a measurement stamped `stamp_ns` (sensor clock) can be fused: its IMU time
    /// `stamp + t_d` is at or before the newest IMU sample (the estimator's one rule).
    pub fn is_due(&self, stamp_ns: u64) -> bool {
        on_ekf!(self, f => f.is_due(SENSOR, stamp_ns))
    }

    /// Time offset `t_d`, s.
    pub fn time_offset(&self) -> f32 {
        on_ekf!(self, f => f.time_offset(SENSOR))
    }

    /// Its 1-sigma, s.
    pub fn time_offset_sigma(&self) -> f32 {
        on_ekf!(self, f => f.time_offset_sigma(SENSOR))
    }

    /// `T_imu_sensor`.
    pub fn extrinsic(&self) -> Pose<f32> {
        on_ekf!(self, f => f.extrinsic(SENSOR))
    }

    /// 1-sigma of the extrinsic's rotation (rad) and translation (m), per axis.
    pub fn extrinsic_sigma(&self) -> (Vector3<f32>, Vector3<f32>) {
        on_ekf!(self, f => f.extrinsic_sigma(SENSOR))
    }

    /// The health monitor.
    pub fn health(&self) -> &HealthMonitor<f32, 1> {
        on_ekf!(self, f => f.health())
    }

    /// The filter configuration.
    pub fn config(&self) -> &FilterConfig<f32> {
        on_ekf!(self, f => f.config())
    }

    /// Propagates with one IMU sample. Not inlined: the propagation's temporaries (~11 KB)
    /// must not sit in the caller's frame under the updates it calls next.
    #[inline(never)]
    pub fn propagate(&mut self, sample: &ImuSample<f32>) -> Result<(), FilterError> {
        on_ekf!(self, f => f.propagate(sample))
    }

    /// The IMU stream's period once two samples are in (a ZUPT needs it).
    pub fn imu_period_ns(&self) -> Option<u64> {
        on_ekf!(self, f => f.imu_period_ns())
    }

    /// Zero-velocity update with the latest sample (its own frame, as [`Filter::propagate`]).
    #[inline(never)]
    pub fn update_zero_velocity(&mut self) -> Result<UpdateReport<f32>, FilterError> {
        on_ekf!(self, f => f.update_zero_velocity())
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

/// A filter from a configuration.
pub fn new_filter(c: &Config) -> Result<Filter, FilterError> {
    let n = &c.imu_noise;
    let mut fc = FilterConfig::new(ImuNoise {
        gyro_noise_density: n.gyro_noise_density,
        accel_noise_density: n.accel_noise_density,
        gyro_random_walk: n.gyro_random_walk,
        accel_random_walk: n.accel_random_walk,
    });
    fc.gate = confidence(c.gate);
    if c.max_imu_gap_ns > 0 {
        fc.max_imu_gap_ns = u64::from(c.max_imu_gap_ns);
    }
    let p = &c.imu_prior;
    let mut init = InitialState::<f32, 1>::at_rest(Vector3::from(p.accel_mean))
        .ok_or(FilterError::InvalidConfig)?;
    init.imu.gyro_bias = Vector3::from(p.gyro_bias);
    if p.sigma_orientation_rad > 0.0 {
        init.sigma_orientation = p.sigma_orientation_rad;
    }
    if p.sigma_velocity_m_s > 0.0 {
        init.sigma_velocity = p.sigma_velocity_m_s;
    }
    let extrinsic = pose(&c.extrinsic);
    if !extrinsic.is_finite() {
        return Err(FilterError::NonFinite);
    }
    let init = init
        .with_extrinsic(
            SENSOR,
            extrinsic,
            c.sigma_rotation_rad,
            c.sigma_translation_m,
        )
        .with_time_offset(SENSOR, c.time_offset_s, c.sigma_time_offset_s);
    match &c.sensors {
        SensorSet::PoseImu => Ok(Filter::PoseImu(PoseImuEkf::new(&fc, &init)?)),
        SensorSet::CameraImu(setup) => {
            let sigma = setup.pixel_sigma;
            if !(sigma.is_finite() && sigma > 0.0) {
                return Err(FilterError::InvalidConfig);
            }
            Ok(Filter::CameraImu(CameraFilter {
                camera: camera(setup)?,
                ekf: CameraImuEkf::new(&fc, &init)?,
                pixel_sigma: sigma,
            }))
        }
    }
}
