//! The firmware self-test: the f32 filter over the embedded sequence, from a perturbed
//! extrinsic prior, with checks that the estimate moves toward the truth and that the filter
//! stays healthy (finite state, symmetric covariance with a positive diagonal).

use msreg_estimator::na::{SMatrix, UnitQuaternion, Vector3};
use msreg_estimator::state::imu;
use msreg_estimator::{
    Error, FilterConfig, ImuNoise, ImuSample, InitialState, Layout, Pose, PoseImuEkf, RelativePose,
    UpdateReport,
};

use crate::scenario::{Event, ImuReading, PoseIncrement, ScenarioConfig, SensorSpec};

/// The filter the firmware runs: one pose sensor, f32.
pub type Filter = PoseImuEkf<f32>;
/// The pose sensor of the filter layout.
pub use msreg_estimator::SOLE_SENSOR as SENSOR;

/// Perturbation of the extrinsic prior from the truth: rotation (rad, right perturbation)
/// and translation (m). About 4 deg and 7 cm.
pub const PRIOR_ERROR: ([f32; 3], [f32; 3]) = ([0.03, -0.04, 0.05], [0.04, -0.05, 0.03]);
/// 1-sigma of the extrinsic prior: rotation (rad), translation (m).
pub const PRIOR_SIGMA: (f32, f32) = (0.1, 0.1);

/// The filter's IMU noise model, from the simulated sensors' datasheet values.
pub fn imu_noise(spec: &SensorSpec) -> ImuNoise<f32> {
    ImuNoise {
        gyro_noise_density: spec.gyro_noise_density,
        accel_noise_density: spec.accel_noise_density,
        gyro_random_walk: spec.gyro_random_walk,
        accel_random_walk: spec.accel_random_walk,
    }
}

/// Truth as an estimator pose.
pub fn truth(config: &ScenarioConfig) -> Pose<f32> {
    Pose::new(config.t_i_s.rotation, config.t_i_s.translation.vector)
}

/// The extrinsic prior: the truth perturbed by [`PRIOR_ERROR`].
pub fn prior(config: &ScenarioConfig) -> Pose<f32> {
    let (rot, trans) = PRIOR_ERROR;
    truth(config).boxplus(&Vector3::from(rot), &Vector3::from(trans))
}

/// A filter at rest at the first IMU sample, with the perturbed extrinsic prior.
pub fn new_filter(config: &ScenarioConfig, first: &ImuReading) -> Result<Filter, Error> {
    let filter_config =
        crate::propagation::device_config(FilterConfig::new(imu_noise(&config.spec)));
    let init = InitialState::at_rest(first.accel)
        .ok_or(Error::InvalidConfig)?
        .with_extrinsic(SENSOR, prior(config), PRIOR_SIGMA.0, PRIOR_SIGMA.1);
    Filter::new(&filter_config, &init)
}

/// An IMU reading of the sequence as the estimator's sample.
pub fn imu_sample(m: &ImuReading) -> ImuSample<f32> {
    ImuSample {
        stamp_ns: m.stamp_ns,
        gyro: m.gyro,
        accel: m.accel,
    }
}

/// An odometry increment of the sequence as the estimator's measurement, with the noise
/// the sensors are simulated with.
pub fn relative_pose(inc: &PoseIncrement, spec: &SensorSpec) -> RelativePose<f32> {
    let delta = Pose::new(inc.delta.rotation, inc.delta.translation.vector);
    RelativePose::with_sigmas(
        inc.stamp_from_ns,
        inc.stamp_to_ns,
        delta,
        spec.rotation_sigma,
        spec.translation_sigma,
    )
}

/// Feeds one event to the filter. Returns the update report for increments.
pub fn feed(
    filter: &mut Filter,
    spec: &SensorSpec,
    event: &Event,
) -> Result<Option<UpdateReport<f32>>, Error> {
    match event {
        Event::Imu(m) => filter.propagate(&imu_sample(m)).map(|()| None),
        Event::Anchor { stamp_ns } => filter.anchor(SENSOR, *stamp_ns).map(|()| None),
        Event::Increment(inc) => filter
            .update_relative_pose(SENSOR, &relative_pose(inc, spec))
            .map(Some),
    }
}

/// What the filter went through.
#[derive(Clone, Copy, Debug, Default)]
pub struct RunCounts {
    /// IMU samples accepted by `propagate`.
    pub imu_samples: u32,
    /// Anchors set.
    pub anchors: u32,
    /// Relative-pose updates processed (accepted or gated out).
    pub updates: u32,
    /// Updates that passed the chi-square gate.
    pub accepted: u32,
    /// Calls that returned an error.
    pub errors: u32,
    /// The first error, if any.
    pub first_error: Option<Error>,
}

impl RunCounts {
    /// Counts the outcome of one [`feed`].
    pub fn record(&mut self, event: &Event, outcome: &Result<Option<UpdateReport<f32>>, Error>) {
        match outcome {
            Err(e) => {
                self.errors += 1;
                self.first_error.get_or_insert(*e);
            }
            Ok(report) => match event {
                Event::Imu(_) => self.imu_samples += 1,
                Event::Anchor { .. } => self.anchors += 1,
                Event::Increment(_) => {
                    self.updates += 1;
                    self.accepted += u32::from(report.is_some_and(|r| r.accepted));
                }
            },
        }
    }
}

/// Distance of an extrinsic estimate from the truth.
#[derive(Clone, Copy, Debug)]
pub struct ExtrinsicError {
    /// Rotation error angle, rad.
    pub rotation: f32,
    /// Translation error norm, m.
    pub translation: f32,
}

impl ExtrinsicError {
    /// Error of `estimate` against `truth`.
    pub fn between(estimate: &Pose<f32>, truth: &Pose<f32>) -> Self {
        Self {
            rotation: estimate.rotation.angle_to(&truth.rotation),
            translation: (estimate.translation - truth.translation).norm(),
        }
    }
}

/// Health of the covariance.
#[derive(Clone, Copy, Debug)]
pub struct CovarianceCheck {
    /// Largest `|P_ij - P_ji|`.
    pub max_asymmetry: f32,
    /// Smallest diagonal entry of the IMU and extrinsic blocks (negative if any diagonal
    /// entry of the whole matrix is).
    pub min_diagonal: f32,
    /// Whether every entry is finite.
    pub finite: bool,
}

impl CovarianceCheck {
    /// Inspects the filter's full error-state covariance. Free clone slots and states held
    /// fixed (the time offset here) have zero rows, so the diagonal must be positive on the
    /// IMU and extrinsic blocks and non-negative everywhere.
    pub fn of(filter: &Filter) -> Self {
        let extrinsic = Layout::<1, 2>::extrinsic(SENSOR);
        let required = (0..imu::DIM).chain(extrinsic.idx..extrinsic.end());
        Self::of_matrix(&filter.covariance(), required)
    }

    /// Inspects a covariance whose diagonal must be positive at the indices `required` and
    /// non-negative everywhere.
    pub fn of_matrix<const N: usize>(
        p: &SMatrix<f32, N, N>,
        required: impl Iterator<Item = usize>,
    ) -> Self {
        let mut max_asymmetry = 0.0f32;
        let mut finite = true;
        for i in 0..N {
            for j in 0..N {
                max_asymmetry = max_asymmetry.max((p[(i, j)] - p[(j, i)]).abs());
                finite &= p[(i, j)].is_finite();
            }
        }
        let min_required = required.map(|i| p[(i, i)]).fold(f32::INFINITY, f32::min);
        let min_any = (0..N).map(|i| p[(i, i)]).fold(f32::INFINITY, f32::min);
        Self {
            max_asymmetry,
            min_diagonal: if min_any < 0.0 { min_any } else { min_required },
            finite,
        }
    }

    /// Symmetric to f32 round-off, finite, positive diagonal.
    pub fn passed(&self) -> bool {
        self.finite && self.max_asymmetry <= 1e-6 && self.min_diagonal > 0.0
    }
}

/// Everything the self-test found.
#[derive(Clone, Copy, Debug)]
pub struct SelfTestReport {
    /// What the filter processed.
    pub counts: RunCounts,
    /// True extrinsic.
    pub truth: Pose<f32>,
    /// Final estimate.
    pub estimate: Pose<f32>,
    /// Error of the prior.
    pub initial_error: ExtrinsicError,
    /// Error of the final estimate.
    pub final_error: ExtrinsicError,
    /// Final 1-sigma: rotation axes (rad), translation (m).
    pub sigma: (Vector3<f32>, Vector3<f32>),
    /// Covariance health at the end.
    pub covariance: CovarianceCheck,
}

/// Named pass/fail checks of a [`SelfTestReport`].
pub struct Checks {
    /// `(name, passed)` per check.
    pub items: [(&'static str, bool); 6],
}

impl Checks {
    /// True when every check passed.
    pub fn all_passed(&self) -> bool {
        self.items.iter().all(|(_, ok)| *ok)
    }
}

impl SelfTestReport {
    /// Evaluates the checks against the expected counts of `config`.
    pub fn checks(&self, config: &ScenarioConfig) -> Checks {
        let c = &self.counts;
        let expected_updates = (config.pose_count() - 1) as u32;
        let finite = self.estimate.is_finite()
            && self
                .sigma
                .0
                .iter()
                .chain(self.sigma.1.iter())
                .all(|s| s.is_finite());
        Checks {
            items: [
                (
                    "every sample and pose processed without error",
                    c.errors == 0
                        && u64::from(c.imu_samples) == config.imu_count()
                        && c.updates == expected_updates,
                ),
                (
                    "at least 90% of updates pass the gate",
                    c.accepted * 10 >= expected_updates * 9,
                ),
                ("estimate and sigmas finite", finite),
                (
                    "rotation error at most a quarter of the prior's",
                    self.final_error.rotation <= 0.25 * self.initial_error.rotation,
                ),
                (
                    "translation error at most a quarter of the prior's",
                    self.final_error.translation <= 0.25 * self.initial_error.translation,
                ),
                (
                    "covariance symmetric, finite, positive diagonal",
                    self.covariance.passed(),
                ),
            ],
        }
    }
}

/// Runs the filter over `events` (the sequence of `config`) and reports.
pub fn run(
    config: &ScenarioConfig,
    filter: &mut Filter,
    events: impl Iterator<Item = Event>,
) -> SelfTestReport {
    let mut counts = RunCounts::default();
    for event in events {
        let outcome = feed(filter, &config.spec, &event);
        counts.record(&event, &outcome);
    }
    let truth = truth(config);
    let estimate = filter.extrinsic(SENSOR);
    SelfTestReport {
        counts,
        truth,
        estimate,
        initial_error: ExtrinsicError::between(&prior(config), &truth),
        final_error: ExtrinsicError::between(&estimate, &truth),
        sigma: filter.extrinsic_sigma(SENSOR),
        covariance: CovarianceCheck::of(filter),
    }
}

/// Roll, pitch, yaw of a rotation in degrees (for printing).
pub fn rpy_deg(q: &UnitQuaternion<f32>) -> [f32; 3] {
    let (r, p, y) = q.euler_angles();
    [r.to_degrees(), p.to_degrees(), y.to_degrees()]
}
