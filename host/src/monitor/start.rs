//! How the monitor's filter starts: the IMU state from a standstill or, on a moving vehicle,
//! from the dynamic alignment of the IMU with `pose0`'s odometry (both through the pose-IMU
//! pipeline's code), the extrinsics and time offsets from the calibration of record.

use msreg_estimator::filter::MonitorEkf;
use msreg_estimator::{FilterConfig, InitialState, SensorPrior};
use nalgebra::{Isometry3, Vector3};

use super::{MonitorError, MonitorInput};
use crate::calibrate::convert;
use crate::calibrate::driver::{moving_start, nominal_period_ns, MovingStart};
use crate::calibrate::gyro_bias::{self, GyroBiasEstimate};
use crate::calibrate::init::{self, RotationIncrement, Standstill};
use crate::calibrate::planar::{self, PlanarMotion};

/// The monitor's filter with `S` pose sensors (`C` clones, `N` error states; no frames).
pub(crate) type Ekf<const S: usize, const C: usize, const N: usize> =
    msreg_estimator::Ekf<f64, S, C, N>;

/// Shortest stationary start used for the IMU prior, s.
const MIN_STANDSTILL_S: f64 = 1.0;
/// Smallest gyro-bias sigma of a bias fitted to motion, rad/s (as the pose-IMU pipeline).
const MIN_FITTED_GYRO_BIAS_SIGMA: f64 = 2e-3;
/// Floors of the moving start's tilt (rad) and velocity (m/s) sigmas (as the pose-IMU
/// pipeline: the alignment's own sigmas ignore the time-offset error).
const MIN_TILT_SIGMA: f64 = 0.6 * std::f64::consts::PI / 180.0;
const MIN_VELOCITY_SIGMA: f64 = 0.1;

/// Per-sensor prior sigmas of one run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtrinsicSigmas {
    /// Rotation per axis, rad.
    pub rotation: f64,
    /// Translation per axis, m.
    pub translation: f64,
    /// Time offset, s.
    pub time_offset: f64,
}

/// What the start found (report words and the planar axis).
#[derive(Debug, Clone)]
pub struct Start {
    /// The IMU prior, in words.
    pub imu_words: String,
    /// Planar motion found in the rotation increments of `pose0` against the gyro.
    pub planar: Option<PlanarMotion>,
    /// The standstill, if the recording starts with one (zero-velocity updates run there).
    pub standstill: Option<Standstill>,
    /// The IMU state and its sigmas (no sensors yet: [`Start::prior`] adds them).
    imu: InitialState<f64, 0>,
}

/// `pose0`'s rotation increments on the IMU clock (prior time offset).
fn increments_on_imu_clock(input: &MonitorInput, s: usize) -> Vec<RotationIncrement> {
    let poses = input.poses[s];
    let td_ns = (input.prior[s].timeshift_s * 1e9).round() as i64;
    let shift = |t: u64| t.saturating_add_signed(td_ns);
    init::pose_increments(poses, nominal_period_ns(poses).saturating_mul(10))
        .into_iter()
        .map(|(a, b, q)| (shift(a), shift(b), q))
        .collect()
}

/// The IMU prior and planar detection.
pub fn start(input: &MonitorInput) -> Result<Start, MonitorError> {
    let imu = input.imu;
    let r0 = input.prior[0].transform.rotation;
    let increments = increments_on_imu_clock(input, 0);
    let standstill = init::detect_standstill(imu, MIN_STANDSTILL_S)
        .filter(|s| s.odometry_agrees(input.poses[0], input.pose_noise[0].translation_noise_m));
    let fit = match &standstill {
        Some(_) => None,
        None => gyro_bias::estimate_gyro_bias(imu, &increments, &r0, &Vector3::zeros()),
    };
    let bias = standstill
        .as_ref()
        .map(|s| s.gyro_mean)
        .or(fit.as_ref().map(|f| f.bias))
        .unwrap_or_else(Vector3::zeros);
    let planar = planar::detect(&init::rotation_pairs(imu, increments, &bias));
    let (state, imu_words) = match &standstill {
        Some(s) => at_rest(s)?,
        None => moving(input, fit.as_ref())?,
    };
    Ok(Start {
        imu_words,
        planar,
        standstill,
        imu: state,
    })
}

fn at_rest(s: &Standstill) -> Result<(InitialState<f64, 0>, String), MonitorError> {
    let mut state =
        InitialState::<f64, 0>::at_rest(s.accel_mean).ok_or(MonitorError::NotGravity {
            accel_norm: s.accel_mean.norm(),
        })?;
    state.imu.gyro_bias = s.gyro_mean;
    let words = format!("standstill of {} samples: gravity and gyro bias", s.samples);
    Ok((state, words))
}

fn moving(
    input: &MonitorInput,
    fit: Option<&GyroBiasEstimate>,
) -> Result<(InitialState<f64, 0>, String), MonitorError> {
    let r0 = input.prior[0].transform.rotation;
    let prior = moving_start(
        input.imu,
        input.poses[0],
        &r0,
        (fit, input.prior[0].timeshift_s),
        input.imu_noise,
    )
    .map_err(|e| match e {
        MovingStart::Failed(reason) => MonitorError::NoAlignment { reason },
        MovingStart::NotNeeded => MonitorError::NoImuPrior,
    })?;
    let accel = input.imu[0].accel;
    let mut state = InitialState::<f64, 0>::at_rest(accel)
        .or_else(|| InitialState::<f64, 0>::at_rest(Vector3::new(0.0, 0.0, 9.81)))
        .ok_or(MonitorError::NoImuPrior)?;
    state.imu.rotation =
        convert::pose::<f64>(&Isometry3::from_parts(Default::default(), prior.rotation)).rotation;
    state.imu.velocity = prior.velocity;
    state.imu.gyro_bias = prior.gyro_bias;
    state.imu.accel_bias = prior.accel_bias;
    state.sigma_orientation = prior.sigma_orientation.max(MIN_TILT_SIGMA);
    state.sigma_velocity = prior.sigma_velocity.max(MIN_VELOCITY_SIGMA);
    state.sigma_accel_bias = prior.sigma_accel_bias.max(0.05);
    state.sigma_gyro_bias = fit.map_or(0.01, |f| f.sigma.amax().max(MIN_FITTED_GYRO_BIAS_SIGMA));
    let words = format!(
        "moving start: dynamic alignment with pose0 (tilt sigma {:.2} deg, velocity sigma \
         {:.2} m/s), gyro bias {}",
        state.sigma_orientation.to_degrees(),
        state.sigma_velocity,
        match fit {
            Some(f) => format!("fitted to {} increments", f.pairs),
            None => "unknown".into(),
        }
    );
    Ok((state, words))
}

/// The IMU part of `imu` with `S` sensors at their defaults.
fn with_sensors<const S: usize>(imu: &InitialState<f64, 0>) -> InitialState<f64, S> {
    InitialState {
        imu: imu.imu,
        sigma_orientation: imu.sigma_orientation,
        sigma_position: imu.sigma_position,
        sigma_velocity: imu.sigma_velocity,
        sigma_gyro_bias: imu.sigma_gyro_bias,
        sigma_accel_bias: imu.sigma_accel_bias,
        sensors: [SensorPrior::default(); S],
    }
}

/// Everything the monitor's filter with `S` pose sensors starts from: the one source of the
/// host's f64 filter (`msreg monitor`) and, with two, of the device's configuration (`msreg
/// link replay`, which sends these values as they are).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterPrior<const S: usize = 2> {
    /// Filter and health-monitor tuning.
    pub config: FilterConfig<f64>,
    /// The IMU state and every sensor's prior, with sigmas.
    pub init: InitialState<f64, S>,
    /// Planar motion: the lever arm of every sensor along this IMU-frame axis is held.
    pub hold_axis: Option<Vector3<f64>>,
    /// Zero-velocity updates while IMU stamps are at or before this (a standstill start).
    pub zero_velocity_until_ns: Option<u64>,
}

impl FilterPrior<2> {
    /// The filter at this prior (two sensors: the device's monitoring layout).
    pub fn filter(&self) -> Result<MonitorEkf<f64>, MonitorError> {
        self.filter_of()
    }
}

impl<const S: usize> FilterPrior<S> {
    /// The filter at this prior, in the layout with `C` clones and `N` error states.
    pub fn filter_of<const C: usize, const N: usize>(&self) -> Result<Ekf<S, C, N>, MonitorError> {
        let mut ekf = Ekf::<S, C, N>::new(&self.config, &self.init)
            .map_err(|error| MonitorError::InvalidPrior { error })?;
        if let Some(axis) = self.hold_axis {
            for s in Ekf::<S, C, N>::sensor_ids() {
                ekf.hold_translation_axis(s, Some(axis))
                    .map_err(|error| MonitorError::PlanarAxis { error })?;
            }
        }
        Ok(ekf)
    }
}

impl Start {
    /// The prior at this start with the calibration of record and the given sigmas (one per
    /// sensor of `input`), the lever arm along the planar axis held for every sensor.
    pub fn prior<const S: usize>(
        &self,
        input: &MonitorInput,
        config: &FilterConfig<f64>,
        sigmas: &[ExtrinsicSigmas],
    ) -> FilterPrior<S> {
        let mut state = with_sensors::<S>(&self.imu);
        for (s, sigma) in msreg_estimator::SensorId::all::<S>()
            .into_iter()
            .zip(sigmas)
        {
            let prior = &input.prior[s.index()];
            state = state
                .with_extrinsic(
                    s,
                    convert::pose::<f64>(&prior.transform),
                    sigma.rotation,
                    sigma.translation,
                )
                .with_time_offset(s, prior.timeshift_s, sigma.time_offset);
        }
        FilterPrior {
            config: *config,
            init: state,
            hold_axis: self.planar.map(|p| p.axis_imu),
            zero_velocity_until_ns: self.standstill.as_ref().map(|s| s.until_ns),
        }
    }
}
