//! The replay loop: IMU samples in order, each pose fused as soon as it is due (in IMU-time
//! order across the pose sensors), as the firmware does it.
//!
//! The filter's layout is fixed at compile time (`S` sensors, `C = 2 S` clones, `N` error
//! states); [`monitor`] picks the layout for the number of pose sensors of its input
//! ([`MAX_POSE_SENSORS`](super::MAX_POSE_SENSORS) at most), and everything below is generic
//! over it.

use std::f64::consts::PI;

use msreg_estimator::chi2::{self, Confidence};
use msreg_estimator::health::{NisStatus, StepTest};
use msreg_estimator::update::relative_pose::RelativePose;
use msreg_estimator::update::UpdateReport;
use msreg_estimator::{Error as FilterError, FilterConfig, HealthEvent, SensorId};
use nalgebra::Matrix3;

use super::start::{self, Ekf, ExtrinsicSigmas, FilterPrior, Start};
use super::{
    Alarm, EstimatePoint, ExcitationPoint, GlrPoint, JumpPoint, MonitorError, MonitorInput,
    MonitorReport, NisPoint, SensorReport, MAX_POSE_SENSORS, SENSOR_NAMES,
};
use crate::calibrate::convert;
use crate::calibrate::driver::nominal_period_ns;
use crate::calibrate::observability::{self, HeldDirection};
use crate::dataset::{ExtrinsicEstimate, PoseRecord};

/// Options of [`monitor`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MonitorOptions {
    /// Floors of the calibration of record's sigmas (a file with zero sigmas, such as ground
    /// truth, still gets a filter that can move): rotation (rad), translation (m).
    pub min_prior_sigma_rotation: f64,
    /// See `min_prior_sigma_rotation`.
    pub min_prior_sigma_translation: f64,
    /// 1-sigma of the recorded time offsets (a result file carries none), s.
    pub prior_sigma_time_offset: f64,
    /// Priors of the observability run: wide, so the drive alone decides what is observed.
    pub observability_prior: ExtrinsicSigmas,
    /// Forgetting factor of the step detectors per update (`HealthConfig::step_forgetting`).
    pub step_forgetting: f64,
    /// Confidence of the step detectors' chi-square threshold per test
    /// (`HealthConfig::step_confidence`).
    pub step_confidence: Confidence,
}

impl Default for MonitorOptions {
    fn default() -> Self {
        Self {
            min_prior_sigma_rotation: 0.01f64.to_radians(),
            min_prior_sigma_translation: 0.001,
            prior_sigma_time_offset: 0.001,
            observability_prior: ExtrinsicSigmas {
                rotation: 2f64.to_radians(),
                translation: 0.1,
                time_offset: 0.005,
            },
            // The default's 3 s memory (0.97 per update at 10 Hz) at the camera's 20 Hz;
            // chosen on drive seeds 1-8, which no test uses.
            step_forgetting: 0.985,
            // 99.999 % per test: a false-alarm rate of ~0.2 per hour of driving under
            // repeated testing (99.99 %: ~2 per hour, measured 2.4); chosen on drive seeds
            // 200-299 (docs/monitor.md, "False alarms").
            step_confidence: Confidence::P99999,
        }
    }
}

/// Why a planar drive leaves the lever arm along the axis unobservable (report words).
const PLANAR_REASON: &str = "motion is planar (rotation about one axis)";
/// Re-anchor instead of fusing across an odometry gap longer than this many periods.
const MAX_GAP_PERIODS: f64 = 10.0;
/// One zero-velocity update every this many IMU samples while at rest.
pub const ZERO_VELOCITY_EVERY: u16 = 20;

/// One pose of a sensor as the filter takes it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(
    clippy::large_enum_variant,
    reason = "held in one Vec per sensor; boxing each increment would cost more than it saves"
)]
pub enum PoseStep {
    /// Starts an odometry segment at this sensor stamp, ns.
    Anchor(u64),
    /// The increment from the previous pose, sigmas scaled by the periods it spans.
    Increment(RelativePose<f64>),
}

impl PoseStep {
    /// Sensor stamp at which the step is due, ns.
    pub fn stamp_ns(&self) -> u64 {
        match self {
            PoseStep::Anchor(t) => *t,
            PoseStep::Increment(m) => m.stamp_to_ns,
        }
    }
}

/// The steps of sensor `s`'s odometry, the one rule of the host replay and of the device's
/// stream (`msreg link replay`): poses whose IMU time (prior `t_d` of `ekf`) falls before
/// the first IMU sample `t0_ns` are dropped; the first pose after, and every pose after a gap
/// of more than [`MAX_GAP_PERIODS`] nominal periods, anchors; every other pose is the
/// increment from the one before. Also returns a note per gap.
pub fn pose_steps<const S: usize, const C: usize, const N: usize>(
    ekf: &Ekf<S, C, N>,
    s: SensorId,
    input: &MonitorInput,
    t0_ns: u64,
) -> (Vec<PoseStep>, Vec<String>) {
    let poses = input.poses[s.index()];
    let period_ns = nominal_period_ns(poses) as f64;
    let noise = &input.pose_noise[s.index()];
    let sigma = (noise.rotation_noise_rad, noise.translation_noise_m);
    let first = poses
        .iter()
        .position(|p| ekf.imu_time(s, p.stamp_ns).map_or(true, |t| t >= t0_ns))
        .unwrap_or(poses.len());
    let mut steps = Vec::with_capacity(poses.len() - first);
    let mut notes = Vec::new();
    let mut previous: Option<&PoseRecord> = None;
    for rec in &poses[first..] {
        let periods = previous.map(|p| {
            ((rec.stamp_ns.saturating_sub(p.stamp_ns)) as f64 / period_ns)
                .round()
                .max(1.0)
        });
        steps.push(match (previous, periods) {
            (Some(prev), Some(k)) if k <= MAX_GAP_PERIODS => {
                let delta = convert::pose::<f64>(&(prev.isometry().inverse() * rec.isometry()));
                PoseStep::Increment(RelativePose::with_sigmas(
                    prev.stamp_ns,
                    rec.stamp_ns,
                    delta,
                    sigma.0 * k.sqrt(),
                    sigma.1 * k.sqrt(),
                ))
            }
            (_, k) => {
                if let Some(k) = k {
                    notes.push(format!("{} ns: gap of {k} periods", rec.stamp_ns));
                }
                PoseStep::Anchor(rec.stamp_ns)
            }
        });
        previous = Some(rec);
    }
    (steps, notes)
}

/// Per-sensor replay state.
struct Feed {
    steps: Vec<PoseStep>,
    next: usize,
    /// The filter holds this sensor's segment start (the last anchor or fused increment).
    anchored: bool,
    skipped: Vec<String>,
}

/// One update as the caller sees it.
struct Fused {
    sensor: SensorId,
    t_s: f64,
    report: UpdateReport<f64>,
}

fn feeds<const S: usize, const C: usize, const N: usize>(
    ekf: &Ekf<S, C, N>,
    input: &MonitorInput,
    t0_ns: u64,
) -> [Feed; S] {
    Ekf::<S, C, N>::sensor_ids().map(|s| {
        let (steps, skipped) = pose_steps(ekf, s, input, t0_ns);
        Feed {
            steps,
            next: 0,
            anchored: false,
            skipped,
        }
    })
}

/// Applies step `feed.next` of sensor `s`; returns the update when there was one. As on the
/// device (`firmware/src/session.rs`): an increment the filter cannot chain (no anchor, or
/// older than its window) re-anchors at its end; one refused otherwise is skipped and the
/// next pose anchors.
fn fuse_next<const S: usize, const C: usize, const N: usize>(
    ekf: &mut Ekf<S, C, N>,
    s: SensorId,
    feed: &mut Feed,
) -> Option<UpdateReport<f64>> {
    let step = feed.steps[feed.next];
    feed.next += 1;
    let stamp = step.stamp_ns();
    let anchor = |ekf: &mut Ekf<S, C, N>, feed: &mut Feed| match ekf.anchor(s, stamp) {
        Ok(()) => feed.anchored = true,
        Err(e) => {
            feed.anchored = false;
            feed.skipped.push(format!("{stamp} ns: anchor: {e:?}"));
        }
    };
    let meas = match step {
        PoseStep::Increment(m) if feed.anchored => m,
        PoseStep::Increment(_) | PoseStep::Anchor(_) => {
            anchor(ekf, feed);
            return None;
        }
    };
    match ekf.update_relative_pose(s, &meas) {
        Ok(report) => Some(report),
        Err(e @ (FilterError::NoAnchor | FilterError::OlderThanWindow)) => {
            feed.skipped
                .push(format!("{stamp} ns: relative pose: {e:?}"));
            anchor(ekf, feed);
            None
        }
        Err(e) => {
            feed.skipped
                .push(format!("{stamp} ns: relative pose: {e:?}"));
            feed.anchored = false;
            None
        }
    }
}

/// The due step (of any sensor) with the earliest IMU time.
fn earliest_due<const S: usize, const C: usize, const N: usize>(
    ekf: &Ekf<S, C, N>,
    feeds: &[Feed; S],
) -> Option<SensorId> {
    Ekf::<S, C, N>::sensor_ids()
        .into_iter()
        .filter_map(|s| {
            let feed = &feeds[s.index()];
            let stamp = feed.steps.get(feed.next)?.stamp_ns();
            ekf.is_due(s, stamp)
                .then(|| ekf.imu_time(s, stamp).ok())
                .flatten()
                .map(|t| (t, s))
        })
        .min()
        .map(|(_, s)| s)
}

/// Runs `ekf` over the recording, calling `on_update` after every update.
fn run<const S: usize, const C: usize, const N: usize>(
    ekf: &mut Ekf<S, C, N>,
    input: &MonitorInput,
    prior: &FilterPrior<S>,
    on_update: &mut dyn FnMut(&Ekf<S, C, N>, &Fused),
) -> Result<Skipped, MonitorError> {
    let mut zero_velocity = Vec::new();
    let t0 = input.imu[0].stamp_ns;
    let mut feeds = feeds(ekf, input, t0);
    for (i, rec) in input.imu.iter().enumerate() {
        ekf.propagate(&convert::imu_sample::<f64>(rec))
            .map_err(|error| MonitorError::ImuSample {
                error,
                stamp_ns: rec.stamp_ns,
                sample: i + 1,
            })?;
        let at_rest = prior
            .zero_velocity_until_ns
            .is_some_and(|until| rec.stamp_ns <= until);
        if at_rest && i % usize::from(ZERO_VELOCITY_EVERY) == 0 && ekf.imu_period_ns().is_some() {
            // A refused zero-velocity update leaves the filter as it was; it belongs to no
            // sensor, so it is booked on neither.
            if let Err(e) = ekf.update_zero_velocity() {
                zero_velocity.push(format!("{} ns: zero velocity: {e:?}", rec.stamp_ns));
            }
        }
        while let Some(s) = earliest_due(ekf, &feeds) {
            let feed = &mut feeds[s.index()];
            let stamp = feed.steps[feed.next].stamp_ns();
            let t_s = ekf
                .imu_time(s, stamp)
                .map_or(0.0, |t| t.saturating_sub(t0) as f64 * 1e-9);
            if let Some(report) = fuse_next(ekf, s, feed) {
                on_update(
                    ekf,
                    &Fused {
                        sensor: s,
                        t_s,
                        report,
                    },
                );
            }
        }
    }
    Ok(Skipped {
        sensors: feeds.into_iter().map(|f| f.skipped).collect(),
        zero_velocity,
    })
}

/// What a replay could not use, with the reasons.
struct Skipped {
    sensors: Vec<Vec<String>>,
    zero_velocity: Vec<String>,
}

/// An alarm from a health event.
fn step_alarm(t_s: f64, event: &HealthEvent<f64>) -> Alarm {
    match *event {
        HealthEvent::RotationStep {
            sensor,
            statistic,
            step,
            ..
        } => Alarm {
            t_s,
            sensor: SENSOR_NAMES[sensor.index()],
            kind: "rotation_step",
            statistic,
            step: step.map(f64::to_degrees).into(),
        },
        HealthEvent::TranslationStep {
            sensor,
            statistic,
            step,
            ..
        } => Alarm {
            t_s,
            sensor: SENSOR_NAMES[sensor.index()],
            kind: "translation_step",
            statistic,
            step: (step * 1e3).into(),
        },
    }
}

/// The monitor run: alarms, the NIS timeline and the estimates per sensor.
struct MonitorRun {
    alarms: Vec<Alarm>,
    warnings: Vec<Alarm>,
    nis: Vec<Vec<NisPoint>>,
    estimates: Vec<Vec<EstimatePoint>>,
    /// The calibration of record.
    record: Vec<ExtrinsicEstimate>,
    high: Vec<bool>,
}

/// Sensor `s`'s extrinsic in `ekf` against `record`.
fn estimate_point<const S: usize, const C: usize, const N: usize>(
    ekf: &Ekf<S, C, N>,
    s: SensorId,
    record: &ExtrinsicEstimate,
    t_s: f64,
) -> EstimatePoint {
    let x = convert::isometry(&ekf.extrinsic(s));
    let (sr, st) = ekf.extrinsic_sigma(s);
    let rotation = (record.transform.rotation.inverse() * x.rotation).scaled_axis();
    let translation = x.translation.vector - record.transform.translation.vector;
    EstimatePoint {
        t_s,
        rotation_deg: rotation.map(f64::to_degrees).into(),
        translation_mm: (translation * 1e3).into(),
        sigma_rotation_deg: sr.map(f64::to_degrees).into(),
        sigma_translation_mm: (st * 1e3).into(),
    }
}

impl MonitorRun {
    fn record<const S: usize, const C: usize, const N: usize>(
        &mut self,
        ekf: &Ekf<S, C, N>,
        f: &Fused,
    ) {
        let k = f.sensor.index();
        self.estimates[k].push(estimate_point(ekf, f.sensor, &self.record[k], f.t_s));
        self.record_health(ekf, f);
    }

    fn record_health<const S: usize, const C: usize, const N: usize>(
        &mut self,
        ekf: &Ekf<S, C, N>,
        f: &Fused,
    ) {
        let r = &f.report;
        let dof = r.dof.max(1) as f64;
        let health = ekf.health().sensor(f.sensor);
        let config = &ekf.config().health;
        let [rotation_glr, translation_glr] = health.map_or([None, None], |h| {
            let [r, t] = h.step_tests(config);
            let point = |t: StepTest<f64>, unit: f64| GlrPoint {
                statistic: t.statistic,
                dof: t.dof,
                threshold: chi2::quantile(t.dof, config.step_confidence),
                step: t.step.norm() * unit,
            };
            [r.map(|t| point(t, 180.0 / PI)), t.map(|t| point(t, 1e3))]
        });
        self.nis[f.sensor.index()].push(NisPoint {
            t_s: f.t_s,
            nis_per_dof: r.nis / dof,
            gate_per_dof: r.threshold / dof,
            accepted: r.accepted,
            held_out: r.held_out,
            window_nis_per_dof: health.map_or(0.0, |h| h.windowed_nis_per_dof()),
            rotation_glr,
            translation_glr,
            jump: health.and_then(|h| h.jump_test()).map(
                |(statistic, step, confirmation, updates)| JumpPoint {
                    statistic,
                    step_deg: step.norm().to_degrees(),
                    confirmation,
                    threshold: -(1.0 - config.step_confidence.probability()).ln(),
                    updates,
                },
            ),
        });
        if let Some(event) = &r.event {
            self.alarms.push(step_alarm(f.t_s, event));
        }
        let high = health.is_some_and(|h| h.nis_status(&ekf.config().health) == NisStatus::High);
        if high && !self.high[f.sensor.index()] {
            self.warnings.push(Alarm {
                t_s: f.t_s,
                sensor: SENSOR_NAMES[f.sensor.index()],
                kind: "nis_high",
                statistic: health.map_or(0.0, |h| h.windowed_nis_per_dof()),
                step: [0.0; 3],
            });
        }
        self.high[f.sensor.index()] = high;
    }
}

/// The start and the monitor run's filter prior (the calibration of record with its
/// sigmas) of a drive with two pose sensors: what `msreg link replay` sends the device, whose
/// monitoring layout takes exactly two (an input with another number is refused).
pub fn monitor_prior(
    input: &MonitorInput,
    options: &MonitorOptions,
) -> Result<(Start, FilterPrior<2>), MonitorError> {
    monitor_prior_of::<2>(
        input,
        options,
        "; the device's monitoring layout takes exactly two",
    )
}

/// [`monitor_prior`] with `S` pose sensors (what `msreg monitor` runs); `needed` is added to
/// the error when `input` has another number.
fn monitor_prior_of<const S: usize>(
    input: &MonitorInput,
    options: &MonitorOptions,
    needed: &'static str,
) -> Result<(Start, FilterPrior<S>), MonitorError> {
    validate(input, S, needed)?;
    let start = start::start(input)?;
    let mut config = FilterConfig::new(convert::imu_noise::<f64>(input.imu_noise));
    config.health.step_forgetting = options.step_forgetting;
    config.health.step_confidence = options.step_confidence;
    // Claim only steps the drive can resolve (the lever arm along the planar axis and a
    // camera's roll about its direction of travel cannot be, docs/monitor.md).
    config.health.resolvable_step_factor = 1.0;
    // The knock's own increment (docs/estimator.md), as on the device.
    config.health = config.health.with_jump_detector();
    let sigmas: Vec<ExtrinsicSigmas> = input
        .prior
        .iter()
        .map(|p| ExtrinsicSigmas {
            rotation: p
                .sigma_rot_deg
                .amax()
                .to_radians()
                .max(options.min_prior_sigma_rotation),
            translation: p
                .sigma_trans_m
                .amax()
                .max(options.min_prior_sigma_translation),
            time_offset: options.prior_sigma_time_offset,
        })
        .collect();
    let prior = start.prior(input, &config, &sigmas);
    Ok((start, prior))
}

/// What the two runs recorded of one sensor.
struct SensorRecords {
    nis: Vec<NisPoint>,
    estimates: Vec<EstimatePoint>,
    skipped: Vec<String>,
    excitation: Vec<ExcitationPoint>,
    observability: Vec<crate::calibrate::observability::DofObservability>,
}

/// The report of sensor `s` at the end of the monitor run `ekf`.
fn sensor_report<const S: usize, const C: usize, const N: usize>(
    ekf: &Ekf<S, C, N>,
    s: SensorId,
    record: &ExtrinsicEstimate,
    r: SensorRecords,
) -> SensorReport {
    let covariance = ekf.extrinsic_covariance(s);
    let estimate = ExtrinsicEstimate::from_covariance(
        convert::isometry(&ekf.extrinsic(s)),
        ekf.time_offset(s),
        &covariance,
    );
    let prior = &record.transform;
    SensorReport {
        name: SENSOR_NAMES[s.index()],
        accepted: r.nis.iter().filter(|p| p.accepted).count(),
        rejected: r.nis.iter().filter(|p| !p.accepted && !p.held_out).count(),
        held_out: r.nis.iter().filter(|p| p.held_out).count(),
        nis: r.nis,
        estimates: r.estimates,
        excitation: r.excitation,
        observability: r.observability,
        skipped: r.skipped,
        record: *record,
        final_covariance: covariance.transpose().into(),
        rotation_change_deg: prior
            .rotation
            .angle_to(&estimate.transform.rotation)
            .to_degrees(),
        translation_change_m: (prior.translation.vector - estimate.transform.translation.vector)
            .norm(),
        final_t_imu_pose: estimate.matrix().transpose().into(),
        final_timeshift_s: estimate.timeshift_s,
        final_sigma_rot_deg: estimate.sigma_rot_deg.into(),
        final_sigma_trans_m: estimate.sigma_trans_m.into(),
        estimate,
    }
}

/// Replays the health monitor over `input` (see the module docs), in the filter layout of
/// its number of pose sensors (1 to [`MAX_POSE_SENSORS`]).
pub fn monitor(
    input: &MonitorInput,
    options: &MonitorOptions,
) -> Result<MonitorReport, MonitorError> {
    match input.poses.len() {
        1 => monitor_with::<1, 2, 34>(input, options),
        2 => monitor_with::<2, 4, 53>(input, options),
        3 => monitor_with::<3, 6, 72>(input, options),
        4 => monitor_with::<4, 8, 91>(input, options),
        _ => Err(count_error(input, "")),
    }
}

/// [`monitor`] in the layout with `S` sensors.
fn monitor_with<const S: usize, const C: usize, const N: usize>(
    input: &MonitorInput,
    options: &MonitorOptions,
) -> Result<MonitorReport, MonitorError> {
    let (start, prior) = monitor_prior_of::<S>(input, options, "")?;
    let mut ekf = prior.filter_of::<C, N>()?;
    let mut m = MonitorRun {
        alarms: Vec::new(),
        warnings: Vec::new(),
        nis: vec![Vec::new(); S],
        estimates: vec![Vec::new(); S],
        record: input.prior.clone(),
        high: vec![false; S],
    };
    let Skipped {
        sensors: skipped,
        zero_velocity,
    } = run(&mut ekf, input, &prior, &mut |e, f| m.record(e, f))?;
    let (excitation, observability) = observability_run::<S, C, N>(input, &start, &prior, options)?;
    let t0 = input.imu[0].stamp_ns;
    let duration_s = input
        .imu
        .last()
        .map_or(0.0, |r| (r.stamp_ns - t0) as f64 * 1e-9);
    let mut parts = m
        .nis
        .into_iter()
        .zip(m.estimates)
        .zip(skipped)
        .zip(excitation.into_iter().zip(observability));
    let sensors: Vec<SensorReport> = Ekf::<S, C, N>::sensor_ids()
        .into_iter()
        .filter_map(|s| {
            let (((nis, estimates), skipped), (excitation, observability)) = parts.next()?;
            Some(sensor_report(
                &ekf,
                s,
                &input.prior[s.index()],
                SensorRecords {
                    nis,
                    estimates,
                    skipped,
                    excitation,
                    observability,
                },
            ))
        })
        .collect();
    Ok(MonitorReport {
        start_stamp_ns: t0,
        duration_s,
        start: start.imu_words.clone(),
        planar_axis: start.planar.map(|p| p.axis_imu.into()),
        planar_axis_ratio: start.planar.map(|p| p.axis_ratio),
        alarms: m.alarms,
        warnings: m.warnings,
        sensors,
        zero_velocity_skipped: zero_velocity,
    })
}

type Observability = (
    Vec<Vec<ExcitationPoint>>,
    Vec<Vec<crate::calibrate::observability::DofObservability>>,
);

/// The observability run: wide priors, alarms off; excitation over time and the final
/// per-DoF table of each sensor.
fn observability_run<const S: usize, const C: usize, const N: usize>(
    input: &MonitorInput,
    start: &Start,
    monitor_prior: &FilterPrior<S>,
    options: &MonitorOptions,
) -> Result<Observability, MonitorError> {
    let mut config = monitor_prior.config;
    // Never armed: sigmas are never negative.
    config.health.arm_sigma_rotation = -1.0;
    config.health.arm_sigma_translation = -1.0;
    let prior = start.prior::<S>(input, &config, &[options.observability_prior; S]);
    let mut ekf = prior.filter_of::<C, N>()?;
    let mut excitation: Vec<Vec<ExcitationPoint>> = vec![Vec::new(); S];
    run(&mut ekf, input, &prior, &mut |e, f| {
        excitation[f.sensor.index()].push(ExcitationPoint {
            t_s: f.t_s,
            excitation: e.excitation(f.sensor),
        })
    })?;
    let held = start.planar.map(|p| HeldDirection {
        axis: p.axis_imu,
        reason: PLANAR_REASON.into(),
    });
    let tables = Ekf::<S, C, N>::sensor_ids().map(|s| {
        let (sr, st) = ekf.extrinsic_sigma(s);
        let sigma = [sr.x, sr.y, sr.z, st.x, st.y, st.z, ekf.time_offset_sigma(s)];
        let cov = ekf.extrinsic_covariance(s);
        let translation_cov: Matrix3<f64> = cov.fixed_view::<3, 3>(3, 3).into_owned();
        observability::table(&sigma, &ekf.prior_sigma(s), &translation_cov, held.as_ref())
    });
    Ok((excitation, tables.into()))
}

/// The error for an input whose pose sensors are not 1 to [`MAX_POSE_SENSORS`] (or whose
/// odometries, noise files and calibrations of record differ in number).
fn count_error(input: &MonitorInput, needed: &'static str) -> MonitorError {
    MonitorError::PoseSensorCount {
        poses: input.poses.len(),
        noise: input.pose_noise.len(),
        prior: input.prior.len(),
        max: MAX_POSE_SENSORS,
        needed,
    }
}

/// Enough data to run, with messages naming the file; `sensors` pose sensors in each part.
fn validate(
    input: &MonitorInput,
    sensors: usize,
    needed: &'static str,
) -> Result<(), MonitorError> {
    let counts = [input.poses.len(), input.pose_noise.len(), input.prior.len()];
    if counts.iter().any(|&n| n != sensors) || sensors > MAX_POSE_SENSORS {
        return Err(count_error(input, needed));
    }
    if input.imu.len() < 2 {
        return Err(MonitorError::TooFewImuSamples);
    }
    for (s, poses) in input.poses.iter().enumerate() {
        if poses.len() < 2 {
            return Err(MonitorError::TooFewPoses {
                sensor: SENSOR_NAMES[s],
            });
        }
    }
    Ok(())
}
