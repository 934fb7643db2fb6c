//! Calibration health monitor: what runs on the vehicle to tell whether a sensor's
//! calibration still holds.
//!
//! Per sensor it keeps
//! - a window of NIS values, whose sum is compared with chi-square bounds (a filter whose
//!   noise model or calibration is off shows a NIS sum outside them);
//! - a step-change detector for the extrinsic rotation and translation: a generalised
//!   likelihood-ratio test (GLR) of "the extrinsic jumped by an unknown `delta`" against "no
//!   jump", on exponentially forgotten innovation statistics. With `H_e` the Jacobian of
//!   the residual w.r.t. the extrinsic block and `S` the innovation covariance,
//!   `b = sum l^k H_e^T S^-1 r_k` has covariance `A2 = sum l^2k H_e^T S^-1 H_e` under "no
//!   jump", so `b^T A2^-1 b ~ chi2(3)`; a knock makes it grow with every update.
//!
//! - a jump-anchored detector for a knock: a knocked sensor's odometry moves with its mounting,
//!   so the one increment spanning the knock carries the whole rotation `delta` in its rotation
//!   residual (the Jacobian `E` w.r.t. a rotation of the mounting at the increment's end stamp
//!   only). An increment whose residual, read that way, exceeds the chi-square(3) quantile is
//!   a candidate: a knock, or an odometry glitch. While it is pending the sensor is **held
//!   out** of the filter (its updates are tested, not fused: `HealthMonitor::holds_out`), so
//!   neither hypothesis drags the shared IMU state, and the increments after it decide by
//!   Wald's sequential test between "the mounting moved by `delta`" (each residual has mean
//!   `H_R delta`) and "no change": the log-likelihood ratio
//!   `L = |delta| s - |delta|^2 a / 2`, `s = sum u^T H_R^T S^-1 r_k`,
//!   `a = sum u^T H_R^T S^-1 H_R u`, `u = delta / |delta|`, fires above `ln(1 / alpha)` and
//!   drops the candidate below `ln(beta)`.
//!
//! Excitation (how much each extrinsic sigma shrank from its prior) is read off the filter
//! covariance by `Ekf::excitation`.

use crate::chi2::{self, Confidence};
use crate::ids::SensorId;
use crate::scalar::Scalar;
use heapless::Deque;
use nalgebra::{Cholesky, Matrix3, Vector3};

/// Capacity of the NIS window.
pub const NIS_WINDOW_CAPACITY: usize = 64;

/// Tuning of the health monitor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HealthConfig<T: Scalar> {
    /// Number of updates in the NIS window (at most [`NIS_WINDOW_CAPACITY`]).
    pub nis_window: usize,
    /// Two-sided confidence of the windowed NIS bounds.
    pub nis_confidence: Confidence,
    /// Forgetting factor of the step detector per update (0.97 at 10 Hz ~ a 3 s memory).
    pub step_forgetting: T,
    /// Confidence of the step detector's chi-square(3) threshold.
    pub step_confidence: Confidence,
    /// Updates a detector must accumulate before it may fire (also its refractory period).
    pub step_min_updates: u32,
    /// Sigma (rad) added to each extrinsic rotation axis, on top of the step estimate's own
    /// covariance, when a rotation step is detected (the step estimate is biased low by
    /// what the filter absorbed before the detection).
    pub inflate_rotation: T,
    /// Sigma (m) added likewise to each translation axis on a translation step.
    pub inflate_translation: T,
    /// The step detectors of a sensor arm only once its extrinsic has converged: every
    /// rotation sigma below this (rad) and every translation sigma below
    /// `arm_sigma_translation`. Before, the innovations of the initial transient are the
    /// convergence itself, not a knock, and no alarm may come of them.
    pub arm_sigma_rotation: T,
    /// Translation half of the arming condition, m.
    pub arm_sigma_translation: T,
    /// Smallest rotation step worth an alarm, rad: the GLR statistic alone also fires on
    /// a real recording's small unmodelled errors (0.02 deg "steps" at statistics of 20-200
    /// on EuRoC `imu_april`), which are no knock. A detection needs both the statistic
    /// and an estimated step of at least this size.
    pub min_rotation_step: T,
    /// Smallest translation step worth an alarm, m (see `min_rotation_step`).
    pub min_translation_step: T,
    /// A step detector tests only the directions in which its step estimate's 1-sigma is
    /// at most this many times the smallest step worth an alarm (`min_rotation_step`,
    /// `min_translation_step`). Elsewhere a near-singular information turns noise into a
    /// large "step" (the lever arm along the axis of planar driving carries 1e-5 of the
    /// information across it). Infinite (the default) tests every direction; the vehicle
    /// monitor (`msreg monitor`) uses 1: a detector claims only steps it can resolve.
    pub resolvable_step_factor: T,
    /// After the filter reacts to a step of a sensor, that sensor's detectors stay disarmed
    /// until its extrinsic sigmas are back within this factor of their values before the
    /// step: the re-convergence is the reaction itself (the rest of the same knock, which the
    /// opened covariance absorbs), not another knock, as for the first arming.
    pub rearm_factor: T,
    /// Confidence of the jump test that makes an increment a knock candidate (chi-square(3)
    /// on its rotation residual read as the mounting moving inside it).
    pub jump_confidence: Confidence,
    /// Most updates a candidate stays pending (and its sensor held out) before it is dropped
    /// undecided (0: the jump-anchored detector is off).
    pub jump_window_updates: u32,
    /// The sequential test's miss probability `beta`: a candidate the increments since make
    /// this unlikely is dropped. Its false-alarm probability is `1 - step_confidence`.
    pub jump_miss: T,
    /// Degrees of freedom `nu` of a Student-t model of a relative pose's noise (heavy-tailed
    /// odometry: PnP poses of a real recording). A relative-pose update whose NIS `d^2`
    /// (of `m` dof, at the stated noise) exceeds `m` is fused with its noise divided by the
    /// weight `w = (nu + m) / (nu + d^2)` (`update::relative_pose::student_t_weight`), and
    /// the step detectors see its innovation at that weight; the gate, the NIS window and the
    /// jump test keep the stated noise. Infinite (the default): Gaussian, no weighting.
    pub odometry_dof: T,
    /// Whether a pending knock candidate holds its sensor out of the filter
    /// (`HealthMonitor::holds_out`).
    pub jump_holds_out: bool,
}

impl<T: Scalar> HealthConfig<T> {
    /// The vehicle monitor's settings (host `msreg monitor` and the device's monitoring
    /// session): the jump-anchored knock detector on (100 updates to decide a candidate: 5 s
    /// at 20 Hz) and the odometry's noise heavy-tailed (Student-t, 4 dof: the conventional
    /// robust choice, Lange, Little and Taylor 1989; not tuned on any recording). Both off by
    /// default: during a calibration the extrinsic is still moving and an odometry's glitches
    /// (PnP poses on EuRoC `imu_april`: jumps of 1-3 deg) were confirmed as knocks.
    pub fn with_jump_detector(self) -> Self {
        Self {
            jump_window_updates: 100,
            odometry_dof: T::lit(4.0),
            ..self
        }
    }

    /// True when the settings can be used: forgetting in (0, 1], the sequential test's
    /// miss probability in (0, 1), the smallest steps and the factors positive.
    pub fn is_valid(&self) -> bool {
        let positive = |x: T| x > T::zero();
        positive(self.step_forgetting)
            && self.step_forgetting <= T::one()
            && positive(self.jump_miss)
            && self.jump_miss < T::one()
            && positive(self.min_rotation_step)
            && positive(self.min_translation_step)
            && positive(self.resolvable_step_factor)
            && positive(self.rearm_factor)
            && positive(self.odometry_dof)
    }
}

impl<T: Scalar> Default for HealthConfig<T> {
    fn default() -> Self {
        Self {
            nis_window: 50,
            nis_confidence: Confidence::P999,
            step_forgetting: T::lit(0.97),
            step_confidence: Confidence::P9999,
            step_min_updates: 15,
            inflate_rotation: T::lit(0.0035),
            inflate_translation: T::lit(0.005),
            // 0.5 deg and 2 cm: the pipelines' own "converged" bounds.
            arm_sigma_rotation: T::lit(0.5f64.to_radians()),
            arm_sigma_translation: T::lit(0.02),
            // A quarter of the 1 deg knock the monitor must flag (its step estimate is
            // biased low by what the filter absorbed before the detection), and 5 mm.
            min_rotation_step: T::lit(0.25f64.to_radians()),
            min_translation_step: T::lit(0.005),
            resolvable_step_factor: T::lit(f64::INFINITY),
            rearm_factor: T::lit(2.0),
            // Under "no change" a share 1 - c of the increments becomes a candidate and holds
            // its sensor out for at most `jump_window_updates`: at 99.99 % and 100 updates
            // (5 s at 20 Hz) at most 1 % of a sensor's updates go unfused.
            jump_confidence: Confidence::P9999,
            // Off: the calibration pipelines keep the GLR only (`with_jump_detector`).
            jump_window_updates: 0,
            jump_miss: T::lit(0.01),
            // Gaussian: the calibration pipelines weight every increment alike.
            odometry_dof: T::lit(f64::INFINITY),
            jump_holds_out: true,
        }
    }
}

/// Something the monitor noticed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HealthEvent<T: Scalar> {
    /// The extrinsic rotation of `sensor` changed; its covariance was inflated.
    RotationStep {
        /// The sensor.
        sensor: SensorId,
        /// Stamp of the update that triggered it, ns.
        stamp_ns: u64,
        /// GLR statistic (chi-square with as many dof as directions tested under "no
        /// change"), or, for a confirmed knock candidate, `2 L` (twice the sequential
        /// test's log-likelihood ratio).
        statistic: T,
        /// Estimated step (right perturbation of `R_I_S`), rad.
        step: Vector3<T>,
        /// Covariance of the estimated step, rad^2.
        step_covariance: Matrix3<T>,
    },
    /// The extrinsic translation of `sensor` changed; its covariance was inflated.
    TranslationStep {
        /// The sensor.
        sensor: SensorId,
        /// Stamp of the update that triggered it, ns.
        stamp_ns: u64,
        /// GLR statistic.
        statistic: T,
        /// Estimated step of `p_I_S`, m.
        step: Vector3<T>,
        /// Covariance of the estimated step, m^2.
        step_covariance: Matrix3<T>,
    },
}

/// Verdict of the windowed NIS test.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NisStatus {
    /// Not enough updates in the window yet.
    Filling,
    /// Inside the chi-square bounds.
    Consistent,
    /// Above the upper bound: residuals larger than the model says (miscalibration, knock,
    /// optimistic noise).
    High,
    /// Below the lower bound: noise model too pessimistic.
    Low,
}

/// Exponentially forgotten GLR statistics of a 3-dof step.
#[derive(Clone, Copy, Debug, PartialEq)]
struct StepDetector<T: Scalar> {
    info: Matrix3<T>,
    info_squared_weights: Matrix3<T>,
    score: Vector3<T>,
    updates: u32,
}

impl<T: Scalar> StepDetector<T> {
    fn new() -> Self {
        Self {
            info: Matrix3::zeros(),
            info_squared_weights: Matrix3::zeros(),
            score: Vector3::zeros(),
            updates: 0,
        }
    }

    fn add(&mut self, info: &Matrix3<T>, score: &Vector3<T>, forgetting: T) {
        self.info = self.info * forgetting + info;
        self.info_squared_weights = self.info_squared_weights * (forgetting * forgetting) + info;
        self.score = self.score * forgetting + score;
        self.updates = self.updates.saturating_add(1);
    }

    /// The GLR test over the directions in which a step of `min_step` can be resolved: the
    /// eigen-directions of the information `A1` where the step's 1-sigma (at most
    /// `A1^-1/2`) is at most `factor` times `min_step`. Elsewhere (the lever arm along the
    /// axis of planar driving, a camera's roll about its direction of travel) the estimate
    /// `A1^-1 b` is noise amplified by a near-singular `A1` and says nothing about a knock.
    /// `None` when no direction is resolvable, or when `(statistic, dof)` fails `accept`
    /// (then the step and its covariance, most of the cost, are not formed: the
    /// per-update path on the device).
    fn test(
        &self,
        (min_step, factor): (T, T),
        accept: impl Fn(T, usize) -> bool,
    ) -> Option<StepTest<T>> {
        let eig = self.info.symmetric_eigen();
        let v = eig.eigenvectors;
        let resolvable = min_step * factor;
        // Infinite factor: every direction (floor 0).
        let floor = T::one() / (resolvable * resolvable);
        let keep: [bool; 3] = core::array::from_fn(|i| eig.eigenvalues[i] >= floor);
        let kept = keep.iter().filter(|k| **k).count();
        if kept == 0 {
            return None;
        }
        // In eigen-coordinates, with the dropped directions made inert (zero score, unit
        // information), the 3-dof formulas give the kept subspace's.
        let mut score = v.transpose() * self.score;
        let mut a1 = v.transpose() * self.info * v;
        let mut a2 = v.transpose() * self.info_squared_weights * v;
        for i in (0..3).filter(|i| !keep[*i]) {
            score[i] = T::zero();
            for j in 0..3 {
                for m in [&mut a1, &mut a2] {
                    m[(i, j)] = T::zero();
                    m[(j, i)] = T::zero();
                }
            }
            a1[(i, i)] = T::one();
            a2[(i, i)] = T::one();
        }
        let reg = |m: &Matrix3<T>| Matrix3::identity() * (m.trace() * T::lit(1e-9));
        let statistic = score.dot(&Cholesky::new(a2 + reg(&a2))?.solve(&score));
        if !accept(statistic, kept) {
            return None;
        }
        let a1_inv = Cholesky::new(a1 + reg(&a1))?.inverse();
        let mut cov = a1_inv * a2 * a1_inv;
        for i in (0..3).filter(|i| !keep[*i]) {
            for j in 0..3 {
                cov[(i, j)] = T::zero();
                cov[(j, i)] = T::zero();
            }
        }
        let cov = v * cov * v.transpose();
        Some(StepTest {
            statistic,
            dof: kept,
            step: v * (a1_inv * score),
            step_covariance: (cov + cov.transpose()) * T::lit(0.5),
            updates: self.updates,
        })
    }

    /// Statistic, step and its covariance when the detector is ready (`min_updates`), the
    /// statistic of [`Self::test`] exceeds its chi-square threshold at `confidence` (with
    /// as many dof as directions kept) and the estimated step is at least `min_step` long.
    fn fire(
        &self,
        min_updates: u32,
        confidence: Confidence,
        (min_step, factor): (T, T),
    ) -> Option<(T, Vector3<T>, Matrix3<T>)> {
        if self.updates < min_updates {
            return None;
        }
        let above = |statistic: T, dof: usize| statistic > chi2::quantile::<T>(dof, confidence);
        let t = self.test((min_step, factor), above)?;
        (t.step.norm() >= min_step).then_some((t.statistic, t.step, t.step_covariance))
    }
}

/// The state of one step detector's GLR test, thresholds not applied (for timelines and
/// false-alarm studies: `SensorHealth::step_tests`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepTest<T: Scalar> {
    /// GLR statistic (chi-square with `dof` degrees of freedom under "no change").
    pub statistic: T,
    /// Directions tested (resolvable, see `HealthConfig::resolvable_step_factor`).
    pub dof: usize,
    /// Estimated step (rad or m).
    pub step: Vector3<T>,
    /// Its covariance.
    pub step_covariance: Matrix3<T>,
    /// Updates the detector has accumulated since it was last reset.
    pub updates: u32,
}

/// A knock candidate: an increment whose rotation residual reads as the mounting having
/// rotated by `step` between its stamps, and the one-dof test of the increments after it.
#[derive(Clone, Copy, Debug, PartialEq)]
struct JumpCandidate<T: Scalar> {
    /// The jump statistic (chi-square(3) under "no change").
    statistic: T,
    /// The mounting's rotation inside the increment (right perturbation of `R_I_S`), rad.
    step: Vector3<T>,
    /// Its covariance, rad^2.
    covariance: Matrix3<T>,
    /// `sum u^T H_R^T S^-1 r` over the increments since.
    score: T,
    /// `A = sum H_R^T S^-1 H_R` over the increments since.
    info: Matrix3<T>,
    /// The extrinsic rotation covariance at the latest of them.
    extrinsic_covariance: Matrix3<T>,
    /// Increments seen since.
    updates: u32,
}

impl<T: Scalar> JumpCandidate<T> {
    /// A candidate from one increment's end-rotation innovation, when its statistic passes
    /// `threshold` and the rotation is at least `min_step` long.
    fn from_increment(inn: &ExtrinsicInnovation<T>, threshold: T, min_step: T) -> Option<Self> {
        let chol = Cholesky::new(inn.jump_info)?;
        let step = chol.solve(&inn.jump_score);
        let statistic = inn.jump_score.dot(&step);
        (statistic > threshold && step.norm() >= min_step).then(|| Self {
            statistic,
            step,
            covariance: chol.inverse(),
            score: T::zero(),
            info: Matrix3::zeros(),
            extrinsic_covariance: inn.rotation_covariance,
            updates: 0,
        })
    }

    /// Adds one later increment's persistent signature along the candidate's direction;
    /// the log-likelihood ratio of "the mounting moved by `step`" against "no change" over
    /// the increments since.
    fn confirm(&mut self, inn: &ExtrinsicInnovation<T>) -> T {
        self.score += self.direction().dot(&inn.rotation_score);
        self.info += inn.rotation_info;
        self.extrinsic_covariance = inn.rotation_covariance;
        self.updates = self.updates.saturating_add(1);
        self.log_likelihood_ratio()
    }

    fn direction(&self) -> Vector3<T> {
        self.step / self.step.norm()
    }

    /// `L = mu (s - mu / 2) / v`: `s ~ N(mu, v)` under the jump, `N(0, v)` without, with
    /// `mu = |step| a`, `a = u^T A u`, and `v = a + (A u)^T P (A u)`: the held-out residuals
    /// share the extrinsic estimate's error (covariance `P`), which no update corrects
    /// while the sensor is held out.
    fn log_likelihood_ratio(&self) -> T {
        let u = self.direction();
        let au = self.info * u;
        let a = u.dot(&au);
        let v = a + au.dot(&(self.extrinsic_covariance * au));
        if v <= T::zero() {
            return T::zero();
        }
        let mu = self.step.norm() * a;
        mu * (self.score - mu * T::lit(0.5)) / v
    }
}

/// Health of one sensor's calibration.
#[derive(Clone, Debug)]
pub struct SensorHealth<T: Scalar> {
    nis: Deque<(T, u8), NIS_WINDOW_CAPACITY>,
    nis_sum: T,
    nis_dof: usize,
    rotation: StepDetector<T>,
    translation: StepDetector<T>,
    /// Updates fused.
    pub accepted: u32,
    /// Updates rejected by the gate.
    pub rejected: u32,
    /// Steps detected so far.
    pub steps_detected: u32,
    /// The latest event.
    pub last_event: Option<HealthEvent<T>>,
    /// Rotation and translation sigma (largest axis) the extrinsic must come back under
    /// before the detectors re-arm after a reaction.
    rearm_below: Option<(T, T)>,
    /// The pending knock candidate.
    jump: Option<JumpCandidate<T>>,
}

impl<T: Scalar> Default for SensorHealth<T> {
    fn default() -> Self {
        Self {
            nis: Deque::new(),
            nis_sum: T::zero(),
            nis_dof: 0,
            rotation: StepDetector::new(),
            translation: StepDetector::new(),
            accepted: 0,
            rejected: 0,
            steps_detected: 0,
            last_event: None,
            rearm_below: None,
            jump: None,
        }
    }
}

impl<T: Scalar> SensorHealth<T> {
    /// The rotation and translation detectors' GLR tests as they stand (after the latest
    /// update), thresholds not applied; `None` for a detector with no resolvable direction.
    pub fn step_tests(&self, config: &HealthConfig<T>) -> [Option<StepTest<T>>; 2] {
        let f = config.resolvable_step_factor;
        [
            self.rotation
                .test((config.min_rotation_step, f), |_, _| true),
            self.translation
                .test((config.min_translation_step, f), |_, _| true),
        ]
    }

    /// The pending knock candidate as it stands: `(jump statistic, jump, log-likelihood
    /// ratio of the increments since, increments since)`; `None` without a candidate.
    pub fn jump_test(&self) -> Option<(T, Vector3<T>, T, u32)> {
        self.jump
            .map(|c| (c.statistic, c.step, c.log_likelihood_ratio(), c.updates))
    }

    /// Mean NIS per degree of freedom over the window (1 for a consistent filter).
    pub fn windowed_nis_per_dof(&self) -> T {
        if self.nis_dof == 0 {
            return T::zero();
        }
        self.nis_sum / T::lit(self.nis_dof as f64)
    }

    /// The windowed NIS test.
    pub fn nis_status(&self, config: &HealthConfig<T>) -> NisStatus {
        if self.nis.len() < config.nis_window.min(NIS_WINDOW_CAPACITY) {
            return NisStatus::Filling;
        }
        let hi = chi2::quantile::<T>(self.nis_dof, config.nis_confidence);
        let lo = chi2::lower_quantile::<T>(self.nis_dof, config.nis_confidence);
        if self.nis_sum > hi {
            NisStatus::High
        } else if self.nis_sum < lo {
            NisStatus::Low
        } else {
            NisStatus::Consistent
        }
    }

    /// The jump-anchored detector on one increment (`fused`: whether the filter applied
    /// it). An unfused increment whose rotation residual reads as a jump becomes the
    /// candidate unless a stronger one is pending; every other increment feeds the pending
    /// candidate's sequential test. `(2 L, step, covariance)` when the increments since
    /// confirm it (`L > ln(1 / alpha)`, `alpha = 1 - step_confidence`); the candidate is
    /// dropped when they refute it (`L < ln(beta)`) or after `jump_window_updates`.
    fn jump_step(
        &mut self,
        inn: &ExtrinsicInnovation<T>,
        fused: bool,
        config: &HealthConfig<T>,
    ) -> Option<(T, Vector3<T>, Matrix3<T>)> {
        if config.jump_window_updates == 0 {
            return None;
        }
        let threshold = chi2::quantile::<T>(3, config.jump_confidence);
        let fresh = (!fused)
            .then(|| JumpCandidate::from_increment(inn, threshold, config.min_rotation_step))
            .flatten();
        if let Some(fresh) = fresh {
            if self.jump.is_none_or(|c| c.statistic < fresh.statistic) {
                self.jump = Some(fresh);
                return None;
            }
        }
        let candidate = self.jump.as_mut()?;
        let llr = candidate.confirm(inn);
        let c = *candidate;
        let alpha = 1.0 - config.step_confidence.probability();
        if llr > T::lit(-libm::log(alpha)) {
            return Some((llr * T::lit(2.0), c.step, c.covariance));
        }
        let beta = T::lit(libm::log(config.jump_miss.to_f64()));
        if llr < beta || c.updates >= config.jump_window_updates {
            self.jump = None;
        }
        None
    }

    fn record_nis(&mut self, nis: T, dof: usize, config: &HealthConfig<T>) {
        let window = config.nis_window.clamp(1, NIS_WINDOW_CAPACITY);
        while self.nis.len() >= window {
            if let Some((old, d)) = self.nis.pop_front() {
                self.nis_sum -= old;
                self.nis_dof -= d as usize;
            }
        }
        let dof = dof.min(u8::MAX as usize) as u8;
        if self.nis.push_back((nis, dof)).is_ok() {
            self.nis_sum += nis;
            self.nis_dof += dof as usize;
        }
    }
}

/// Innovation statistics of one update projected on a sensor's extrinsic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExtrinsicInnovation<T: Scalar> {
    /// `H_R^T S^-1 H_R` for the rotation block.
    pub rotation_info: Matrix3<T>,
    /// `H_R^T S^-1 r`.
    pub rotation_score: Vector3<T>,
    /// `H_p^T S^-1 H_p` for the translation block.
    pub translation_info: Matrix3<T>,
    /// `H_p^T S^-1 r`.
    pub translation_score: Vector3<T>,
    /// `E^T S^-1 E` with `E` the Jacobian w.r.t. a rotation of the mounting at the end
    /// stamp of an increment only (the mounting moved between its two stamps); zero for a
    /// measurement that is not an increment.
    pub jump_info: Matrix3<T>,
    /// `E^T S^-1 r`.
    pub jump_score: Vector3<T>,
    /// The covariance of the extrinsic rotation estimate when the update was computed: the
    /// error every held-out residual shares (the sequential test's variance includes it).
    pub rotation_covariance: Matrix3<T>,
}

/// The monitor for `S` sensors.
#[derive(Clone, Debug)]
pub struct HealthMonitor<T: Scalar, const S: usize> {
    /// Tuning.
    pub config: HealthConfig<T>,
    sensors: [SensorHealth<T>; S],
}

impl<T: Scalar, const S: usize> HealthMonitor<T, S> {
    /// A monitor with empty windows.
    pub fn new(config: HealthConfig<T>) -> Self {
        Self {
            config,
            sensors: core::array::from_fn(|_| SensorHealth::default()),
        }
    }

    /// Health of sensor `s`.
    pub fn sensor(&self, s: SensorId) -> Option<&SensorHealth<T>> {
        self.sensors.get(s.index())
    }

    /// Whether sensor `s`'s step detectors may see its innovations, given the largest
    /// rotation and translation sigma of its extrinsic now: once it has converged (below the
    /// arm thresholds) and, after a reaction to a step, re-converged (see
    /// [`HealthConfig::rearm_factor`]).
    pub fn armed(&mut self, s: SensorId, sigma_rotation: T, sigma_translation: T) -> bool {
        let config = self.config;
        let Some(health) = self.sensors.get_mut(s.index()) else {
            return false;
        };
        if let Some((r, t)) = health.rearm_below {
            if sigma_rotation >= r || sigma_translation >= t {
                return false;
            }
            health.rearm_below = None;
        }
        sigma_rotation < config.arm_sigma_rotation
            && sigma_translation < config.arm_sigma_translation
    }

    /// Whether sensor `s` is held out of the filter: a knock candidate of it is pending, so
    /// its updates are tested but not fused until the candidate is confirmed or dropped.
    pub fn holds_out(&self, s: SensorId) -> bool {
        self.config.jump_holds_out
            && self
                .sensors
                .get(s.index())
                .is_some_and(|h| h.jump.is_some())
    }

    /// Holds sensor `s`'s detectors until its extrinsic sigmas are back within
    /// `rearm_factor` of the given values (its sigmas before the filter reacted to a step).
    pub fn hold_until_reconverged(&mut self, s: SensorId, sigma_rotation: T, sigma_translation: T) {
        let factor = self.config.rearm_factor;
        if let Some(health) = self.sensors.get_mut(s.index()) {
            health.rearm_below = Some((sigma_rotation * factor, sigma_translation * factor));
        }
    }

    /// Records one update of sensor `s`; returns a step event when one is detected (the
    /// caller then inflates the extrinsic covariance).
    pub fn record(
        &mut self,
        s: SensorId,
        stamp_ns: u64,
        nis: T,
        dof: usize,
        accepted: bool,
        innovation: Option<&ExtrinsicInnovation<T>>,
    ) -> Option<HealthEvent<T>> {
        let config = self.config;
        let health = self.sensors.get_mut(s.index())?;
        if accepted {
            health.accepted = health.accepted.saturating_add(1);
        } else {
            health.rejected = health.rejected.saturating_add(1);
        }
        health.record_nis(nis, dof, &config);
        let Some(inn) = innovation else {
            // Disarmed: no candidate may stay pending (it would hold the sensor out for good).
            health.jump = None;
            return None;
        };
        // A held-out increment's residual is against an IMU state no update corrects: its
        // dead-reckoning error is shared by every held-out residual, not white, so it feeds
        // the pending candidate's test (which accounts for it) but not the GLR detectors.
        let held_out = config.jump_holds_out && health.jump.is_some();
        if !held_out {
            let l = config.step_forgetting;
            health
                .rotation
                .add(&inn.rotation_info, &inn.rotation_score, l);
            health
                .translation
                .add(&inn.translation_info, &inn.translation_score, l);
        }
        let confidence = config.step_confidence;
        let min = config.step_min_updates;
        // A confirmed jump first: its step estimate is one increment's direct measurement.
        let rotation = health.jump_step(inn, accepted, &config).or_else(|| {
            health.rotation.fire(
                min,
                confidence,
                (config.min_rotation_step, config.resolvable_step_factor),
            )
        });
        let event = if let Some((statistic, step, step_covariance)) = rotation {
            Some(HealthEvent::RotationStep {
                sensor: s,
                stamp_ns,
                statistic,
                step,
                step_covariance,
            })
        } else {
            health
                .translation
                .fire(
                    min,
                    confidence,
                    (config.min_translation_step, config.resolvable_step_factor),
                )
                .map(
                    |(statistic, step, step_covariance)| HealthEvent::TranslationStep {
                        sensor: s,
                        stamp_ns,
                        statistic,
                        step,
                        step_covariance,
                    },
                )
        };
        if event.is_some() {
            health.steps_detected = health.steps_detected.saturating_add(1);
            health.last_event = event;
            // The filter's reaction to a step also settles what the other sensors saw of
            // it through the shared IMU state: every GLR detector starts again. A knock
            // candidate rests on its own sensor's increment and stays, but the event's.
            for h in self.sensors.iter_mut() {
                h.rotation = StepDetector::new();
                h.translation = StepDetector::new();
            }
            if let Some(h) = self.sensors.get_mut(s.index()) {
                h.jump = None;
            }
        }
        event
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SENSOR: SensorId = SensorId::at::<0, 2>();

    #[test]
    fn detectors_rearm_only_after_the_reaction_has_reconverged() {
        let mut m = HealthMonitor::<f64, 2>::new(HealthConfig::default().with_jump_detector());
        assert!(m.armed(SENSOR, 1e-4, 1e-3));
        // Not converged yet: the first arming.
        assert!(!m.armed(SENSOR, 1e-2, 1e-3));
        m.hold_until_reconverged(SENSOR, 1e-4, 1e-3);
        // Within the arm thresholds but not back within 2x of the sigmas before the step.
        assert!(!m.armed(SENSOR, 3e-4, 5e-4));
        assert!(!m.armed(SENSOR, 1e-4, 2.5e-3));
        // The other sensor is not held.
        assert!(m.armed(SensorId::at::<1, 2>(), 3e-4, 5e-4));
        assert!(m.armed(SENSOR, 1.5e-4, 1.5e-3));
        // Once re-converged the hold is gone: the ordinary arming applies again.
        assert!(m.armed(SENSOR, 3e-4, 5e-4));
    }

    /// Information per update and axis: a 1-sigma of 0.18 deg per update.
    const INFO: f64 = 1e5;

    fn innovation(r: Vector3<f64>) -> ExtrinsicInnovation<f64> {
        // H = I, S = 1 / INFO: info = INFO I, score = INFO r (r the rotation error, rad).
        ExtrinsicInnovation {
            rotation_info: Matrix3::identity() * INFO,
            rotation_score: r * INFO,
            translation_info: Matrix3::identity() * INFO,
            translation_score: Vector3::zeros(),
            jump_info: Matrix3::zeros(),
            jump_score: Vector3::zeros(),
            rotation_covariance: Matrix3::zeros(),
        }
    }

    #[test]
    fn persistent_bias_fires_the_rotation_detector() {
        let mut m = HealthMonitor::<f64, 1>::new(HealthConfig::default().with_jump_detector());
        // 1.5 sigma per update: 0.27 deg, above the 0.25 deg worth an alarm.
        let bias = 1.5 / INFO.sqrt();
        let mut fired = None;
        for k in 0..100 {
            if let Some(e) = m.record(
                SENSOR,
                k,
                3.0,
                6,
                true,
                Some(&innovation(Vector3::new(bias, 0.0, 0.0))),
            ) {
                fired = Some((k, e));
                break;
            }
        }
        let (k, e) = fired.expect("a 1.5-sigma bias on every update must be detected");
        assert!(k < 30, "detected late: {k}");
        assert!(matches!(e, HealthEvent::RotationStep { .. }));
    }

    #[test]
    fn a_significant_but_irrelevant_step_does_not_fire() {
        // Precise updates (information 1e6 per axis) biased by 1.5 sigma each: the GLR
        // statistic grows as for a knock, but the step they imply is 1.5e-3 rad, below
        // the 0.25 deg that matters.
        let mut m = HealthMonitor::<f64, 1>::new(HealthConfig::default().with_jump_detector());
        let info = Matrix3::identity() * 1e6;
        for k in 0..200u64 {
            let inn = ExtrinsicInnovation {
                rotation_info: info,
                rotation_score: Vector3::new(1.5e3, 0.0, 0.0),
                translation_info: info,
                translation_score: Vector3::zeros(),
                jump_info: Matrix3::zeros(),
                jump_score: Vector3::zeros(),
                rotation_covariance: Matrix3::zeros(),
            };
            assert!(
                m.record(SENSOR, k, 3.0, 6, true, Some(&inn)).is_none(),
                "alarm at {k}"
            );
        }
    }

    #[test]
    fn an_unresolvable_direction_does_not_fire() {
        // Two axes well informed and unbiased; the third carries 1e-3 of their information
        // (a step's sigma there is far above 0.25 deg) and a 3-sigma bias: the estimate
        // along it is large, but it cannot be resolved, so no alarm.
        let config = HealthConfig {
            resolvable_step_factor: 1.0,
            ..HealthConfig::default()
        };
        let mut m = HealthMonitor::<f64, 1>::new(config);
        let info = Matrix3::from_diagonal(&Vector3::new(INFO, INFO, INFO * 1e-3));
        for k in 0..300u64 {
            let inn = ExtrinsicInnovation {
                rotation_info: info,
                rotation_score: Vector3::new(0.0, 0.0, 3.0 * (INFO * 1e-3).sqrt()),
                translation_info: info,
                translation_score: Vector3::zeros(),
                jump_info: Matrix3::zeros(),
                jump_score: Vector3::zeros(),
                rotation_covariance: Matrix3::zeros(),
            };
            assert!(
                m.record(SENSOR, k, 3.0, 6, true, Some(&inn)).is_none(),
                "alarm at {k}"
            );
        }
    }

    /// An increment whose rotation residual is `jump` (rad), at `INFO` per axis, with no
    /// persistent signature.
    fn jump_increment(jump: Vector3<f64>) -> ExtrinsicInnovation<f64> {
        ExtrinsicInnovation {
            jump_info: Matrix3::identity() * INFO,
            jump_score: jump * INFO,
            ..innovation(Vector3::zeros())
        }
    }

    /// Persistent signature per increment: a step of `step` seen at 1/100 of the jump's
    /// information (the conjugation `delta x theta_k` of a 0.1 rad increment), plus a
    /// zero-mean +-1 sigma alternation.
    fn after_jump(step: Vector3<f64>, k: u64) -> ExtrinsicInnovation<f64> {
        let info = INFO * 1e-2;
        let noise = if k % 2 == 0 { 1.0 } else { -1.0 } * info.sqrt();
        ExtrinsicInnovation {
            rotation_info: Matrix3::identity() * info,
            rotation_score: step * info + Vector3::new(noise, -noise, noise),
            ..innovation(Vector3::zeros())
        }
    }

    #[test]
    fn a_jump_confirmed_by_the_increments_after_it_fires_with_the_jump() {
        let config = HealthConfig::default().with_jump_detector();
        let mut m = HealthMonitor::<f64, 1>::new(config);
        let knock = Vector3::new(0.0, 1.0, -1.0).normalize() * 1f64.to_radians();
        assert!(m
            .record(SENSOR, 0, 50.0, 6, false, Some(&jump_increment(knock)))
            .is_none());
        assert!(
            m.holds_out(SENSOR),
            "a pending candidate holds its sensor out"
        );
        // Per increment the log-likelihood ratio gains |delta|^2 a / 2 = 0.15 on average
        // ((0.0175 rad)^2 * 1e3 / 2), so ln(1 / 1e-4) = 9.2 takes ~60 increments; the 3-dof
        // GLR with forgetting (threshold 21.1 at 99.99 %, ~66-update memory) saturates near
        // 0.3 * 33 = 10 and never fires.
        let fired = (1..100u64)
            .find_map(|k| {
                m.record(SENSOR, k, 6.0, 6, true, Some(&after_jump(knock, k)))
                    .map(|e| (k, e))
            })
            .expect("a confirmed jump must fire");
        let (k, event) = fired;
        assert!((40..90).contains(&k), "fired at {k}");
        let HealthEvent::RotationStep {
            step,
            step_covariance,
            statistic,
            ..
        } = event
        else {
            panic!("{event:?}");
        };
        assert!(statistic > chi2::quantile::<f64>(1, config.step_confidence));
        // The step is the jump's estimate, with the jump's covariance.
        assert!((step - knock).norm() < 1e-12, "{step:?}");
        assert!((step_covariance - Matrix3::identity() / INFO).norm() < 1e-12);
    }

    #[test]
    fn a_glitch_the_increments_after_it_do_not_confirm_raises_no_alarm() {
        let mut m = HealthMonitor::<f64, 1>::new(HealthConfig::default().with_jump_detector());
        let glitch = Vector3::new(0.0, 1.0, -1.0).normalize() * 1f64.to_radians();
        assert!(m
            .record(SENSOR, 0, 50.0, 6, false, Some(&jump_increment(glitch)))
            .is_none());
        // Zero-mean afterwards, or the persistent signature of the opposite step. The
        // log-likelihood ratio falls by 0.15 per increment (+-0.8 from the alternation):
        // below ln(0.01) = -4.6 after 30-35, when the candidate is dropped and the sensor
        // fused again.
        for k in 1..150u64 {
            let inn = after_jump(Vector3::zeros(), k);
            assert!(
                m.record(SENSOR, k, 6.0, 6, true, Some(&inn)).is_none(),
                "{k}"
            );
            if !(25..=35).contains(&k) {
                assert_eq!(m.holds_out(SENSOR), k < 25, "{k}");
            }
        }
        let mut m = HealthMonitor::<f64, 1>::new(HealthConfig::default().with_jump_detector());
        m.record(SENSOR, 0, 50.0, 6, false, Some(&jump_increment(glitch)));
        for k in 1..90u64 {
            let inn = after_jump(-glitch, k);
            assert!(
                m.record(SENSOR, k, 6.0, 6, true, Some(&inn)).is_none(),
                "{k}"
            );
        }
    }

    #[test]
    fn a_jump_below_the_test_or_the_smallest_step_is_no_candidate() {
        let config = HealthConfig::default().with_jump_detector();
        // 4.7 sigma per axis on two axes (chi-square 45 > 16.3) but 0.12 deg long
        // (information 1e7 per axis), and 2 sigma (chi-square 8) but 1 deg long.
        let precise = ExtrinsicInnovation {
            jump_info: Matrix3::identity() * 1e7,
            jump_score: Vector3::new(0.0, 1.0, 1.0) * 1.5e4,
            ..innovation(Vector3::zeros())
        };
        let vague = ExtrinsicInnovation {
            jump_info: Matrix3::identity() * 8e3,
            jump_score: Vector3::new(0.0, 1.0, 1.0).normalize() * 1f64.to_radians() * 8e3,
            ..innovation(Vector3::zeros())
        };
        for jump in [precise, vague] {
            let mut m = HealthMonitor::<f64, 1>::new(config);
            m.record(SENSOR, 0, 50.0, 6, false, Some(&jump));
            assert!(m.sensor(SENSOR).unwrap().jump.is_none(), "{jump:?}");
        }
    }

    /// The knock of `a_jump_confirmed_by_the_increments_after_it_fires_with_the_jump`: the
    /// update index it fires at, if any, after `setup` ran on the monitor after the jump.
    fn confirmed_at(
        after: impl Fn(Vector3<f64>, u64) -> ExtrinsicInnovation<f64>,
        setup: impl Fn(&mut HealthMonitor<f64, 2>),
    ) -> Option<u64> {
        let mut m = HealthMonitor::<f64, 2>::new(HealthConfig::default().with_jump_detector());
        let knock = Vector3::new(0.0, 1.0, -1.0).normalize() * 1f64.to_radians();
        m.record(SENSOR, 0, 50.0, 6, false, Some(&jump_increment(knock)));
        setup(&mut m);
        (1..200u64).find(|k| {
            m.record(SENSOR, *k, 6.0, 6, false, Some(&after(knock, *k)))
                .is_some()
        })
    }

    #[test]
    fn later_increments_that_are_candidates_themselves_still_confirm_the_first() {
        // A large knock with large later increments: each later residual is a weaker jump
        // of its own (0.9 of the first here: chi-square 24.7 against 30.5, both above the
        // 21.1 of a candidate) and must feed the test, not stall it.
        let plain = confirmed_at(after_jump, |_| ()).expect("plain");
        let weaker = confirmed_at(
            |knock, k| ExtrinsicInnovation {
                jump_info: Matrix3::identity() * INFO,
                jump_score: knock * 0.9 * INFO,
                ..after_jump(knock, k)
            },
            |_| (),
        )
        .expect("later candidates must feed the test");
        assert_eq!(plain, weaker);
    }

    #[test]
    fn the_extrinsic_uncertainty_shared_by_the_held_out_residuals_slows_the_test() {
        // With the extrinsic estimate's own error (0.3 deg sigma) shared by every held-out
        // residual, the same evidence counts for less.
        let plain = confirmed_at(after_jump, |_| ()).expect("plain");
        let sigma = 0.3f64.to_radians();
        let shared = confirmed_at(
            |knock, k| ExtrinsicInnovation {
                rotation_covariance: Matrix3::identity() * sigma * sigma,
                ..after_jump(knock, k)
            },
            |_| (),
        );
        assert!(shared.is_none_or(|k| k > plain), "{shared:?} vs {plain}");
    }

    #[test]
    fn a_candidate_survives_another_sensors_event_but_not_its_own_disarming() {
        let other = SensorId::at::<1, 2>();
        // Another sensor's step resets the GLR detectors, not this sensor's candidate.
        let plain = confirmed_at(after_jump, |_| ()).expect("plain");
        let kept = confirmed_at(after_jump, |m| {
            let big = innovation(Vector3::new(0.05, 0.0, 0.0));
            assert!((0..40u64).any(|k| m.record(other, k, 6.0, 6, true, Some(&big)).is_some()));
            assert!(m.holds_out(SENSOR));
        });
        assert_eq!(kept, Some(plain));
        // A disarmed update (no innovation) drops it: it would hold the sensor out for good.
        let mut m = HealthMonitor::<f64, 1>::new(HealthConfig::default().with_jump_detector());
        let knock = Vector3::new(0.0, 1.0, 0.0) * 1f64.to_radians();
        m.record(SENSOR, 0, 50.0, 6, false, Some(&jump_increment(knock)));
        assert!(m.holds_out(SENSOR));
        m.record(SENSOR, 1, 6.0, 6, false, None);
        assert!(!m.holds_out(SENSOR));
    }

    #[test]
    fn held_out_increments_feed_the_candidates_test_not_the_glr() {
        // A biased increment on every update while a candidate is pending: the GLR does
        // not see them (their residuals share the free-running IMU's error); without the
        // hold-out (`jump_holds_out` false) it does.
        let glr_updates = |holds: bool| {
            let config = HealthConfig {
                jump_holds_out: holds,
                ..HealthConfig::default().with_jump_detector()
            };
            let mut m = HealthMonitor::<f64, 1>::new(config);
            let knock = Vector3::new(0.0, 1.0, 0.0) * 1f64.to_radians();
            m.record(SENSOR, 0, 50.0, 6, false, Some(&jump_increment(knock)));
            assert!(m.sensor(SENSOR).unwrap().jump.is_some());
            assert_eq!(m.holds_out(SENSOR), holds);
            for k in 1..5u64 {
                m.record(SENSOR, k, 6.0, 6, true, Some(&after_jump(knock, k)));
            }
            let [rotation, _] = m.sensor(SENSOR).unwrap().step_tests(&config);
            rotation.map_or(0, |t| t.updates)
        };
        // The candidate's own increment (not held out when it arrived) and none after.
        assert_eq!(glr_updates(true), 1);
        assert_eq!(glr_updates(false), 5);
    }

    #[test]
    fn a_fused_increment_is_no_candidate_and_bad_settings_are_refused() {
        let mut m = HealthMonitor::<f64, 1>::new(HealthConfig::default().with_jump_detector());
        let knock = Vector3::new(0.0, 1.0, 0.0) * 1f64.to_radians();
        m.record(SENSOR, 0, 20.0, 6, true, Some(&jump_increment(knock)));
        assert!(
            !m.holds_out(SENSOR),
            "a fused increment was absorbed, not held"
        );
        for jump_miss in [0.0, 1.0, -0.1, f64::NAN] {
            let c = HealthConfig {
                jump_miss,
                ..HealthConfig::default()
            };
            assert!(!c.is_valid(), "{jump_miss}");
        }
        assert!(HealthConfig::<f32>::default().is_valid());
    }

    #[test]
    fn step_tests_report_the_glr_statistic_before_any_threshold() {
        let config = HealthConfig::default();
        let mut m = HealthMonitor::<f64, 1>::new(config);
        // 0.5 sigma per update on one axis, 10 updates: below the threshold.
        let r = 0.5 / INFO.sqrt();
        for k in 0..10u64 {
            let inn = innovation(Vector3::new(r, 0.0, 0.0));
            assert!(m.record(SENSOR, k, 3.0, 6, true, Some(&inn)).is_none());
        }
        let [rotation, translation] = m.sensor(SENSOR).unwrap().step_tests(&config);
        let t = rotation.expect("rotation test");
        // b = INFO r sum l^k, A2 = INFO sum l^2k (per axis): b^2 / A2.
        let l = config.step_forgetting;
        let (s1, s2): (f64, f64) =
            (0..10).fold((0.0, 0.0), |(a, b), k| (a + l.powi(k), b + l.powi(2 * k)));
        let expected = INFO * r * r * s1 * s1 / s2;
        assert!(
            (t.statistic - expected).abs() < 1e-6 * expected,
            "{t:?} vs {expected}"
        );
        assert_eq!((t.dof, t.updates), (3, 10));
        assert!((t.step.x - r).abs() < 1e-9 && t.step.yz().norm() < 1e-12);
        // The translation score is zero: statistic 0.
        assert!(translation.expect("translation test").statistic.abs() < 1e-12);
    }

    #[test]
    fn zero_mean_residuals_do_not_fire() {
        let mut m = HealthMonitor::<f64, 1>::new(HealthConfig::default().with_jump_detector());
        // Alternating signs: zero-mean, unit variance (in sigmas).
        let sd = 1.0 / INFO.sqrt();
        for k in 0..1000u64 {
            let s = if k % 2 == 0 { sd } else { -sd };
            let e = m.record(
                SENSOR,
                k,
                3.0,
                3,
                true,
                Some(&innovation(Vector3::new(s, -s, s))),
            );
            assert!(e.is_none(), "false alarm at {k}");
        }
    }

    #[test]
    fn nis_window_flags_large_residuals() {
        let cfg = HealthConfig::<f64>::default();
        let mut m = HealthMonitor::<f64, 1>::new(cfg);
        for k in 0..60 {
            m.record(SENSOR, k, 6.0, 6, true, None);
        }
        assert_eq!(
            m.sensor(SENSOR).unwrap().nis_status(&cfg),
            NisStatus::Consistent
        );
        for k in 0..60 {
            m.record(SENSOR, k, 20.0, 6, true, None);
        }
        assert_eq!(m.sensor(SENSOR).unwrap().nis_status(&cfg), NisStatus::High);
    }
}
