//! Dynamic initialisation: gravity, IMU velocity and lever arm from a moving start (no
//! standstill needed), in the spirit of VINS-Mono's visual-inertial alignment and LI-Init.
//!
//! Given the hand-eye rotation `R_I_S` (eq. 3.2-3.5), the odometry `T_O_S(t_k)` of the pose
//! sensor and the IMU pre-integrated between consecutive pose stamps
//! ([`preintegrate`]: instantaneous samples, mean of the two bounding samples per
//! sub-interval), the rigid-body constraint (eq. 3.1) with the IMU kinematics gives, per
//! interval `k` (`R_k = R_O_I(t_k) = R_O_S R_I_S^T`, `p_O_I = p_O_S - R_O_I p_I_S`):
//!
//! ```text
//! p_O_I(k+1) = p_O_I(k) + v_k dt + g_O dt^2/2 + R_k (dp_k + J_p b_a)
//! v_k+1      = v_k + g_O dt + R_k (dv_k + J_v b_a)
//! ```
//!
//! linear in the velocities `v_k` (in `O`), gravity `g_O`, the lever arm `p_I_S` and the
//! accelerometer bias `b_a` (weak priors keep the last two bounded when the motion does not
//! observe them). The linear solve is refined with `|g_O| = 9.81` on the sphere's 2-D tangent
//! plane by Gauss-Newton (VINS-Mono's `RefineGravity`), re-estimating the noise of the
//! position and velocity rows from their residuals (variance components) at each step, so
//! the covariance from the normal matrix is scaled by the residual variance. See
//! docs/initialisation.md.

pub mod preintegrate;
pub(crate) mod solve;
#[cfg(test)]
mod tests;

use msreg_estimator::{ImuState, InitialState, Scalar, SOLE_SENSOR};
use nalgebra::{
    DMatrix, Isometry3, Matrix3, Matrix3x2, SMatrix, SymmetricEigen, Translation3, UnitQuaternion,
    Vector3,
};

use super::convert;
use crate::dataset::{ImuRecord, PoseRecord};
use preintegrate::{seconds_between, ImuSeries, Preintegrated};
use solve::{GravityModel, Layout, Solution};

/// What the initialisation reads.
#[derive(Debug, Clone, Copy)]
pub struct DynamicInitInput<'a> {
    /// IMU samples (instantaneous at their stamps), strictly increasing stamps.
    pub imu: &'a [ImuRecord],
    /// Odometry `T_O_S` of the pose sensor (arbitrary origin `O`).
    pub poses: &'a [PoseRecord],
    /// `R_I_S` (hand-eye rotation, [`super::init::hand_eye_rotation`]).
    pub r_i_s: UnitQuaternion<f64>,
    /// Gyroscope bias guess, rad/s (zero without a standstill).
    pub gyro_bias: Vector3<f64>,
    /// Time offset guess `t_d`, s: a pose stamped `t_S` was taken at IMU time `t_S + t_d`.
    pub time_offset_s: f64,
}

/// Tuning of the initialisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynamicInitOptions {
    /// Length of the window from the first pose inside the IMU data, s.
    pub window_s: f64,
    /// Shortest interval between two poses used (faster pose sensors are thinned), s.
    pub min_interval_s: f64,
    /// A longer interval (an odometry gap) ends the window, s.
    pub max_interval_s: f64,
    /// Fewest pose intervals in the window.
    pub min_intervals: usize,
    /// Least rotation of the sensor away from its first pose in the window, rad.
    pub min_rotation_rad: f64,
    /// Magnitude of gravity, m/s^2.
    pub gravity_m_s2: f64,
    /// Accelerometer white noise density, m/s^2/sqrt(Hz) (`imu0/imu.yaml`).
    pub accel_noise_density: f64,
    /// 1-sigma rotation noise of one pose, rad (`pose0/sensor.yaml`'s increment noise).
    pub pose_rotation_noise_rad: f64,
    /// Prior 1-sigma of each lever-arm component (mean zero), m.
    pub lever_prior_sigma_m: f64,
    /// Prior 1-sigma of each accelerometer-bias component (mean zero), m/s^2.
    pub accel_bias_prior_sigma: f64,
    /// Gauss-Newton steps on the gravity sphere.
    pub refine_iterations: usize,
    /// A direction whose 1-sigma exceeds these is reported as weak.
    pub weak: WeakThresholds,
}

/// 1-sigma above which a direction of a block counts as weakly observed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeakThresholds {
    /// Roll / pitch, rad.
    pub tilt_rad: f64,
    /// Velocity, m/s.
    pub velocity_m_s: f64,
    /// Lever arm, m.
    pub lever_m: f64,
    /// Accelerometer bias, m/s^2.
    pub accel_bias_m_s2: f64,
}

impl Default for DynamicInitOptions {
    fn default() -> Self {
        Self {
            window_s: 8.0,
            min_interval_s: 0.05,
            max_interval_s: 0.5,
            min_intervals: 10,
            min_rotation_rad: 10f64.to_radians(),
            gravity_m_s2: 9.81,
            accel_noise_density: 2e-3,
            pose_rotation_noise_rad: 0.2f64.to_radians(),
            lever_prior_sigma_m: 0.5,
            accel_bias_prior_sigma: 0.1,
            refine_iterations: 4,
            weak: WeakThresholds {
                tilt_rad: 1f64.to_radians(),
                velocity_m_s: 0.1,
                lever_m: 0.05,
                accel_bias_m_s2: 0.05,
            },
        }
    }
}

/// Why the initialisation could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum DynamicInitError {
    /// Not enough pose intervals with IMU data in the window.
    #[error(
        "{found} pose intervals with IMU data in the initialisation window; at least {needed} \
         are needed"
    )]
    TooFewPoses {
        /// Intervals found.
        found: usize,
        /// Intervals needed.
        needed: usize,
    },
    /// The sensor hardly turned: gravity, lever arm and bias cannot be told apart.
    #[error(
        "the pose sensor turned at most {rotation_deg:.1} deg in the {window_s:.1} s \
         initialisation window; at least {needed_deg:.1} deg are needed"
    )]
    TooLittleExcitation {
        /// Largest rotation away from the first pose, deg.
        rotation_deg: f64,
        /// Needed, deg.
        needed_deg: f64,
        /// Window length, s.
        window_s: f64,
    },
    /// The least squares has no unique solution.
    #[error("the initialisation least squares is singular ({stage})")]
    Singular {
        /// Which solve.
        stage: &'static str,
    },
    /// The linear solve's gravity is far from `|g|`: the rotation, the time offset or the
    /// IMU units are wrong.
    #[error(
        "the linear solve found |g| = {norm_m_s2:.2} m/s^2, far from 9.81: check R_I_S, \
         the time offset and the IMU units"
    )]
    ImplausibleGravity {
        /// `|g_O|` of the linear solve, m/s^2.
        norm_m_s2: f64,
    },
}

/// The blocks the conditioning is reported for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InitBlock {
    /// Roll and pitch of the IMU in `G` (yaw is a gauge freedom).
    Tilt,
    /// IMU velocity at the first pose, in `G`.
    Velocity,
    /// Lever arm `p_I_S`.
    LeverArm,
    /// Accelerometer bias.
    AccelBias,
}

/// The conditioning of one block: the eigen-decomposition of its marginal information.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockConditioning {
    /// The block.
    pub block: InitBlock,
    /// Eigenvalues of the marginal information matrix, ascending.
    pub information_eigenvalues: Vec<f64>,
    /// 1-sigma along each eigenvector (`1 / sqrt(eigenvalue)`).
    pub sigmas: Vec<f64>,
    /// Unit eigenvectors (for [`InitBlock::Tilt`]: rotation axes in `G`'s x-y plane).
    pub directions: Vec<Vector3<f64>>,
    /// Largest / smallest information eigenvalue.
    pub condition_number: f64,
    /// Indices of the directions whose sigma exceeds the block's weak threshold.
    pub weak: Vec<usize>,
}

/// Index ranges of the output covariance.
pub const TILT: std::ops::Range<usize> = 0..2;
/// Velocity rows of [`DynamicInit::covariance`].
pub const VELOCITY: std::ops::Range<usize> = 2..5;
/// Lever-arm rows of [`DynamicInit::covariance`].
pub const LEVER: std::ops::Range<usize> = 5..8;
/// Accelerometer-bias rows of [`DynamicInit::covariance`].
pub const ACCEL_BIAS: std::ops::Range<usize> = 8..11;

/// The initialisation result at the first pose of the window.
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicInit {
    /// IMU time of the first pose, s after the first IMU sample.
    pub t0_s: f64,
    /// Stamp of the first pose used (sensor clock), ns.
    pub first_pose_ns: u64,
    /// `R_G_O`: aligns `g_O` with `G`'s `-z` (shortest rotation; yaw is a gauge freedom).
    pub r_g_o: UnitQuaternion<f64>,
    /// Gravity in the odometry frame, m/s^2.
    pub gravity_o: Vector3<f64>,
    /// `R_G_I` at the first pose.
    pub r_g_i: UnitQuaternion<f64>,
    /// IMU velocity in `G` at the first pose, m/s.
    pub velocity_g: Vector3<f64>,
    /// IMU velocity in `G` at every pose of the window: (IMU time s, velocity).
    pub velocities_g: Vec<(f64, Vector3<f64>)>,
    /// Lever arm `p_I_S` (position of `S` in `I`), m.
    pub lever_arm: Vector3<f64>,
    /// Accelerometer bias, m/s^2.
    pub accel_bias: Vector3<f64>,
    /// The gyro bias the IMU was integrated with, rad/s.
    pub gyro_bias: Vector3<f64>,
    /// `R_I_S` used.
    pub r_i_s: UnitQuaternion<f64>,
    /// Covariance of (tilt: rotation error about `G` x, y, rad; velocity in `G`; lever arm;
    /// accelerometer bias), see [`TILT`], [`VELOCITY`], [`LEVER`], [`ACCEL_BIAS`].
    /// The tilt error `e` is defined by `R_G_I,true = Exp((e, 0)) R_G_I`.
    pub covariance: SMatrix<f64, 11, 11>,
    /// Conditioning per block.
    pub conditioning: Vec<BlockConditioning>,
    /// Pose intervals used.
    pub intervals: usize,
    /// Window length, s.
    pub window_s: f64,
    /// Largest sensor rotation away from the first pose in the window, rad.
    pub rotation_range_rad: f64,
    /// RMS of the position residuals (m, the noise they were weighted by) and of the velocity
    /// residuals in units of their modelled sigma (about 1 when the noise model fits).
    pub residual_rms: [f64; 2],
}

/// One pose interval of the window.
pub(crate) struct Interval {
    pub pre: Preintegrated,
    pub r_o_s_a: Matrix3<f64>,
    pub r_o_s_b: Matrix3<f64>,
    /// `p_O_S(b) - p_O_S(a)`.
    pub dp_o_s: Vector3<f64>,
    /// IMU time of `b`, s after the IMU origin.
    pub t_b: f64,
}

/// The pose intervals of the initialisation window with their IMU pre-integration.
pub(crate) struct Window {
    pub intervals: Vec<Interval>,
    /// Index of the first pose.
    pub first_pose: usize,
    /// IMU time of the first pose, s after the first IMU sample.
    pub t0: f64,
    /// `R_O_S` of the first pose.
    pub r_o_s0: Matrix3<f64>,
    /// Largest rotation away from the first pose, rad.
    pub rotation_range_rad: f64,
}

impl Window {
    /// Selects and pre-integrates the window (no excitation check).
    pub fn new(
        input: &DynamicInitInput<'_>,
        options: &DynamicInitOptions,
    ) -> Result<Self, DynamicInitError> {
        let too_few = |found| DynamicInitError::TooFewPoses {
            found,
            needed: options.min_intervals,
        };
        let series = ImuSeries {
            imu: input.imu,
            origin_ns: input.imu.first().ok_or(too_few(0))?.stamp_ns,
        };
        let time =
            |p: &PoseRecord| seconds_between(series.origin_ns, p.stamp_ns) + input.time_offset_s;
        let first_pose = input
            .poses
            .iter()
            .position(|p| time(p) >= 0.0)
            .ok_or(too_few(0))?;
        let first = &input.poses[first_pose];
        let t0 = time(first);
        let zero = Vector3::zeros();
        let mut intervals = Vec::new();
        let (mut a, mut t_a, mut range) = (first, t0, 0.0_f64);
        for b in &input.poses[first_pose + 1..] {
            let t_b = time(b);
            if t_b - t_a < options.min_interval_s {
                continue;
            }
            if t_b - t_a > options.max_interval_s || t_b - t0 > options.window_s {
                break;
            }
            let Some(pre) = series.preintegrate(t_a, t_b, &input.gyro_bias, &zero) else {
                break;
            };
            range = range.max(first.rotation.angle_to(&b.rotation));
            intervals.push(Interval {
                pre,
                r_o_s_a: a.rotation.to_rotation_matrix().into_inner(),
                r_o_s_b: b.rotation.to_rotation_matrix().into_inner(),
                dp_o_s: b.position - a.position,
                t_b,
            });
            (a, t_a) = (b, t_b);
        }
        if intervals.len() < options.min_intervals {
            return Err(too_few(intervals.len()));
        }
        Ok(Self {
            intervals,
            first_pose,
            t0,
            r_o_s0: first.rotation.to_rotation_matrix().into_inner(),
            rotation_range_rad: range,
        })
    }
}

/// The aligned solution: unknowns and gravity at the last Gauss-Newton step.
pub(crate) struct Aligned {
    pub layout: Layout,
    pub solution: Solution,
    pub gravity: Vector3<f64>,
    pub basis: Matrix3x2<f64>,
}

/// Two unit vectors spanning the plane orthogonal to `g`.
fn tangent_basis(g: &Vector3<f64>) -> Matrix3x2<f64> {
    let n = g.normalize();
    let helper = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let b1 = n.cross(&helper).normalize();
    let b2 = n.cross(&b1);
    Matrix3x2::from_columns(&[b1, b2])
}

/// The linear solve with free gravity, then `refine_iterations` Gauss-Newton steps on the
/// sphere `|g_O| = gravity_m_s2`, each re-estimating the group noise when `adapt_noise`.
pub(crate) fn align(
    window: &Window,
    r_i_s: &Matrix3<f64>,
    options: &DynamicInitOptions,
    adapt_noise: bool,
) -> Result<Aligned, DynamicInitError> {
    let priors = solve::Noise {
        accel_density: options.accel_noise_density,
        pose_rotation_rad: options.pose_rotation_noise_rad,
        lever_prior_m: options.lever_prior_sigma_m,
        accel_bias_prior: options.accel_bias_prior_sigma,
    };
    let singular = |stage| DynamicInitError::Singular { stage };
    let mut sigmas = [0.01, 1.0];
    let (layout, blocks) = solve::residual_blocks(window, r_i_s, &GravityModel::Free, &priors);
    let mut solution = solve::solve(&layout, &blocks, &sigmas).ok_or(singular("linear"))?;
    if adapt_noise {
        sigmas = solve::variance_components(&solution);
        solution = solve::solve(&layout, &blocks, &sigmas).ok_or(singular("linear"))?;
    }
    let g = options.gravity_m_s2;
    let mut gravity: Vector3<f64> = solution.x.fixed_rows::<3>(layout.gravity()).into();
    if !(0.5 * g..1.5 * g).contains(&gravity.norm()) {
        return Err(DynamicInitError::ImplausibleGravity {
            norm_m_s2: gravity.norm(),
        });
    }
    gravity *= g / gravity.norm();
    for step in 0..=options.refine_iterations {
        let basis = tangent_basis(&gravity);
        let model = GravityModel::Tangent { gravity, basis };
        let (layout, blocks) = solve::residual_blocks(window, r_i_s, &model, &priors);
        let solution = solve::solve(&layout, &blocks, &sigmas).ok_or(singular("refine"))?;
        if step == options.refine_iterations {
            return Ok(Aligned {
                layout,
                solution,
                gravity,
                basis,
            });
        }
        let w = solution.x.fixed_rows::<2>(layout.gravity());
        gravity = (gravity + basis * w).normalize() * g;
        if adapt_noise {
            sigmas = solve::variance_components(&solution);
        }
    }
    Err(singular("refine"))
}

/// Runs the dynamic initialisation on the first `options.window_s` of the recording.
pub fn initialise(
    input: &DynamicInitInput<'_>,
    options: &DynamicInitOptions,
) -> Result<DynamicInit, DynamicInitError> {
    let window = Window::new(input, options)?;
    check_excitation(&window, options)?;
    let r_i_s = input.r_i_s.to_rotation_matrix().into_inner();
    let aligned = align(&window, &r_i_s, options, true)?;
    result(input, &window, &aligned, options)
}

/// [`DynamicInitError::TooLittleExcitation`] when the sensor turned less than required.
pub(crate) fn check_excitation(
    window: &Window,
    options: &DynamicInitOptions,
) -> Result<(), DynamicInitError> {
    if window.rotation_range_rad < options.min_rotation_rad {
        return Err(DynamicInitError::TooLittleExcitation {
            rotation_deg: window.rotation_range_rad.to_degrees(),
            needed_deg: options.min_rotation_rad.to_degrees(),
            window_s: window.intervals.last().map_or(0.0, |iv| iv.t_b - window.t0),
        });
    }
    Ok(())
}

/// The result in `G` with its covariance and conditioning.
pub(crate) fn result(
    input: &DynamicInitInput<'_>,
    window: &Window,
    aligned: &Aligned,
    options: &DynamicInitOptions,
) -> Result<DynamicInit, DynamicInitError> {
    let (layout, x) = (&aligned.layout, &aligned.solution.x);
    let r_g_o = gravity_alignment(&aligned.gravity);
    let r_o_i0 = window.r_o_s0 * input.r_i_s.to_rotation_matrix().into_inner().transpose();
    let r_g_i = r_g_o * UnitQuaternion::from_matrix(&r_o_i0);
    let velocity = |k: usize| -> Vector3<f64> { x.fixed_rows::<3>(3 * k).into() };
    let mut velocities_g = vec![(window.t0, r_g_o * velocity(0))];
    velocities_g.extend(
        window
            .intervals
            .iter()
            .enumerate()
            .map(|(k, iv)| (iv.t_b, r_g_o * velocity(k + 1))),
    );
    let covariance_full = aligned
        .solution
        .normal
        .clone()
        .cholesky()
        .ok_or(DynamicInitError::Singular {
            stage: "covariance",
        })?
        .inverse();
    let covariance = output_covariance(&covariance_full, layout, aligned, &r_g_o, &velocity(0));
    let rms =
        [0, 1].map(|g| (aligned.solution.ssr[g] / aligned.solution.rows[g].max(1) as f64).sqrt());
    Ok(DynamicInit {
        t0_s: window.t0,
        first_pose_ns: input.poses[window.first_pose].stamp_ns,
        r_g_o,
        gravity_o: aligned.gravity,
        r_g_i,
        velocity_g: r_g_o * velocity(0),
        velocities_g,
        lever_arm: x.fixed_rows::<3>(layout.lever()).into(),
        accel_bias: x.fixed_rows::<3>(layout.accel_bias()).into(),
        gyro_bias: input.gyro_bias,
        r_i_s: input.r_i_s,
        conditioning: conditioning(&covariance, &options.weak),
        covariance,
        intervals: window.intervals.len(),
        window_s: window.intervals.last().map_or(0.0, |iv| iv.t_b - window.t0),
        rotation_range_rad: window.rotation_range_rad,
        residual_rms: rms,
    })
}

/// The covariance of (tilt in `G`, `v_G`, lever, `b_a`) from that of the unknowns
/// (`w`, `v_0`, lever, `b_a`) through the first-order error model in the module docs.
fn output_covariance(
    full: &DMatrix<f64>,
    layout: &Layout,
    aligned: &Aligned,
    r_g_o: &UnitQuaternion<f64>,
    v0: &Vector3<f64>,
) -> SMatrix<f64, 11, 11> {
    let index: Vec<usize> = (layout.gravity()..layout.gravity() + 2)
        .chain(0..3)
        .chain(layout.lever()..layout.lever() + 6)
        .collect();
    let c = SMatrix::<f64, 11, 11>::from_fn(|i, j| full[(index[i], index[j])]);
    let j = output_jacobian(&aligned.gravity, &aligned.basis, r_g_o, v0);
    let out = j * c * j.transpose();
    0.5 * (out + out.transpose())
}

/// `d(tilt, v_G, lever, b_a) / d(w, v_0, lever, b_a)`: with `theta_O = g_hat x (B w) / |g|`
/// the rotation of gravity, `tilt = -R_G_O theta_O` and `dv_G = R_G_O (dv_0 + [v_0]x theta_O)`.
pub(crate) fn output_jacobian(
    gravity: &Vector3<f64>,
    basis: &Matrix3x2<f64>,
    r_g_o: &UnitQuaternion<f64>,
    v0: &Vector3<f64>,
) -> SMatrix<f64, 11, 11> {
    let theta_w: Matrix3x2<f64> = gravity.normalize().cross_matrix() * basis / gravity.norm();
    let r = r_g_o.to_rotation_matrix().into_inner();
    let mut j = SMatrix::<f64, 11, 11>::zeros();
    let tilt = -r * theta_w;
    j.fixed_view_mut::<2, 2>(0, 0)
        .copy_from(&tilt.fixed_rows::<2>(0));
    j.fixed_view_mut::<3, 2>(2, 0)
        .copy_from(&(r * v0.cross_matrix() * theta_w));
    j.fixed_view_mut::<3, 3>(2, 2).copy_from(&r);
    j.fixed_view_mut::<6, 6>(5, 5).fill_with_identity();
    j
}

/// `R_G_O`: the shortest rotation taking `g_O` to `G`'s `-z`.
pub(crate) fn gravity_alignment(gravity_o: &Vector3<f64>) -> UnitQuaternion<f64> {
    UnitQuaternion::rotation_between(gravity_o, &-Vector3::z()).unwrap_or_else(|| {
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
    })
}

/// Eigen-decomposition of each block's marginal information.
fn conditioning(
    covariance: &SMatrix<f64, 11, 11>,
    weak: &WeakThresholds,
) -> Vec<BlockConditioning> {
    let blocks = [
        (InitBlock::Tilt, TILT, weak.tilt_rad),
        (InitBlock::Velocity, VELOCITY, weak.velocity_m_s),
        (InitBlock::LeverArm, LEVER, weak.lever_m),
        (InitBlock::AccelBias, ACCEL_BIAS, weak.accel_bias_m_s2),
    ];
    blocks
        .into_iter()
        .map(|(block, range, threshold)| {
            let n = range.len();
            let cov = covariance
                .view((range.start, range.start), (n, n))
                .clone_owned();
            let eigen = SymmetricEigen::new(cov);
            let mut order: Vec<usize> = (0..n).collect();
            // Ascending information = descending variance.
            order.sort_by(|&a, &b| eigen.eigenvalues[b].total_cmp(&eigen.eigenvalues[a]));
            let sigmas: Vec<f64> = order
                .iter()
                .map(|&i| eigen.eigenvalues[i].max(0.0).sqrt())
                .collect();
            let info: Vec<f64> = sigmas
                .iter()
                .map(|s| 1.0 / (s * s).max(f64::MIN_POSITIVE))
                .collect();
            let directions = order
                .iter()
                .map(|&i| {
                    let v = eigen.eigenvectors.column(i);
                    if n == 2 {
                        Vector3::new(v[0], v[1], 0.0)
                    } else {
                        Vector3::new(v[0], v[1], v[2])
                    }
                })
                .collect();
            let weak_idx = (0..n).filter(|&i| sigmas[i] > threshold).collect();
            BlockConditioning {
                block,
                condition_number: info[n - 1] / info[0],
                information_eigenvalues: info,
                sigmas,
                directions,
                weak: weak_idx,
            }
        })
        .collect()
}

/// What the filter's prior needs, at one IMU instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterPrior {
    /// IMU time, s after the first IMU sample.
    pub t_s: f64,
    /// `R_G_I`.
    pub rotation: UnitQuaternion<f64>,
    /// `v_G`, m/s.
    pub velocity: Vector3<f64>,
    /// Gyroscope bias, rad/s.
    pub gyro_bias: Vector3<f64>,
    /// Accelerometer bias, m/s^2.
    pub accel_bias: Vector3<f64>,
    /// `T_I_S` (hand-eye rotation, lever arm).
    pub t_imu_sensor: Isometry3<f64>,
    /// 1-sigma of roll / pitch (largest of the two), rad; also used for yaw (a gauge).
    pub sigma_orientation: f64,
    /// 1-sigma of the velocity (largest axis), m/s.
    pub sigma_velocity: f64,
    /// 1-sigma of the accelerometer bias (largest axis), m/s^2.
    pub sigma_accel_bias: f64,
    /// 1-sigma of the lever arm per axis (x, y, z of `I`), m.
    pub sigma_translation: Vector3<f64>,
}

fn largest_sigma(c: &SMatrix<f64, 11, 11>, range: std::ops::Range<usize>) -> f64 {
    range.map(|i| c[(i, i)].max(0.0).sqrt()).fold(0.0, f64::max)
}

impl DynamicInit {
    /// The prior at `t_s` (s after the first IMU sample, usually 0: the filter starts at the
    /// first IMU sample): the state at the first pose carried there by the IMU (backwards
    /// when `t_s` is earlier). `None` when `t_s` is outside the IMU data.
    pub fn filter_prior(&self, imu: &[ImuRecord], t_s: f64) -> Option<FilterPrior> {
        let series = ImuSeries {
            imu,
            origin_ns: imu.first()?.stamp_ns,
        };
        let g = Vector3::new(0.0, 0.0, -self.gravity_o.norm());
        let (rotation, velocity) = if (t_s - self.t0_s).abs() < 1e-12 {
            (self.r_g_i, self.velocity_g)
        } else if t_s > self.t0_s {
            let pre = series.preintegrate(self.t0_s, t_s, &self.gyro_bias, &self.accel_bias)?;
            (
                self.r_g_i * pre.delta_r,
                self.velocity_g + g * pre.dt + self.r_g_i * pre.delta_v,
            )
        } else {
            let pre = series.preintegrate(t_s, self.t0_s, &self.gyro_bias, &self.accel_bias)?;
            let r = self.r_g_i * pre.delta_r.inverse();
            (r, self.velocity_g - g * pre.dt - r * pre.delta_v)
        };
        let c = &self.covariance;
        Some(FilterPrior {
            t_s,
            rotation,
            velocity,
            gyro_bias: self.gyro_bias,
            accel_bias: self.accel_bias,
            t_imu_sensor: Isometry3::from_parts(Translation3::from(self.lever_arm), self.r_i_s),
            sigma_orientation: largest_sigma(c, TILT),
            sigma_velocity: largest_sigma(c, VELOCITY),
            sigma_accel_bias: largest_sigma(c, ACCEL_BIAS),
            sigma_translation: Vector3::from_fn(|i, _| {
                c[(LEVER.start + i, LEVER.start + i)].sqrt()
            }),
        })
    }
}

impl FilterPrior {
    /// The filter's [`InitialState`] for one sensor: this prior's IMU state (at the origin),
    /// the extrinsic with `sigma_rotation_rad` and the largest lever-arm sigma (the filter
    /// takes one translation sigma for all axes), the time offset and its sigma (zero keeps it
    /// fixed), and `sigma_gyro_bias`; `None` when a value is not finite or a sigma not positive.
    pub fn initial_state<T: Scalar>(
        &self,
        sigma_rotation_rad: f64,
        time_offset_s: f64,
        sigma_time_offset_s: f64,
        sigma_gyro_bias: f64,
    ) -> Option<InitialState<T, 1>> {
        let imu_pose = convert::pose::<T>(&Isometry3::from_parts(
            Translation3::identity(),
            self.rotation,
        ));
        let level = convert::vec3::<T>(&Vector3::new(0.0, 0.0, 9.81));
        let mut state = InitialState::<T, 1>::at_rest(level)?;
        state.imu = ImuState {
            rotation: imu_pose.rotation,
            position: Vector3::zeros(),
            velocity: convert::vec3(&self.velocity),
            gyro_bias: convert::vec3(&self.gyro_bias),
            accel_bias: convert::vec3(&self.accel_bias),
        };
        state.sigma_orientation = T::lit(self.sigma_orientation);
        state.sigma_velocity = T::lit(self.sigma_velocity);
        state.sigma_gyro_bias = T::lit(sigma_gyro_bias);
        state.sigma_accel_bias = T::lit(self.sigma_accel_bias);
        let state = state
            .with_extrinsic(
                SOLE_SENSOR,
                convert::pose::<T>(&self.t_imu_sensor),
                T::lit(sigma_rotation_rad),
                T::lit(self.sigma_translation.max()),
            )
            .with_time_offset(
                SOLE_SENSOR,
                T::lit(time_offset_s),
                T::lit(sigma_time_offset_s),
            );
        state.is_valid().then_some(state)
    }
}
