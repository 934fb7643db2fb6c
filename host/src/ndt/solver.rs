//! Multi-resolution Newton optimisation of the NDT score with a saddle-free
//! Newton direction and Armijo backtracking.

use nalgebra::{
    Isometry3, Matrix3, Matrix6, Rotation3, SymmetricEigen, Translation3, UnitQuaternion, Vector3,
    Vector6,
};

use super::degeneracy::analyse;
use super::map::{NdtMap, NdtTarget};
use super::score::{evaluate, gradient_scatter, Evaluation, GaussFit, PoseMat};
use super::{InvalidParam, NdtError, NdtParams, NdtResult};
use crate::pointcloud::PointCloud;

/// Armijo constant of the sufficient-decrease test.
const ARMIJO_C1: f64 = 1e-4;
/// Backtracking steps before a level gives up (no decrease possible).
const MAX_BACKTRACKS: usize = 8;
/// Eigenvalues of |H| are floored at this fraction of the largest.
const HESSIAN_FLOOR: f64 = 1e-9;
/// Fewest source points that must touch a Gaussian (6 DoF need constraints).
const MIN_HITS: usize = 6;
/// Step tolerances of all but the finest level are this many times looser.
const COARSE_TOLERANCE_SCALE: f64 = 10.0;

/// Registers `source` to `target` from `guess` (= initial `T_target_source`).
/// Both clouds are used as given (voxel-filter them first); the target maps
/// are built here: use [`align`] with a prebuilt [`NdtTarget`] to reuse them.
pub fn align_scans(
    target: &PointCloud,
    source: &PointCloud,
    guess: &Isometry3<f64>,
    params: &NdtParams,
) -> Result<NdtResult, NdtError> {
    let target = NdtTarget::build(&target.positions(), params)?;
    align(&target, &source.positions(), guess, params)
}

/// Registers source points to a prebuilt target from `guess`, coarse to fine
/// over `target.levels()` (built with the same `params`).
pub fn align(
    target: &NdtTarget,
    source: &[Vector3<f64>],
    guess: &Isometry3<f64>,
    params: &NdtParams,
) -> Result<NdtResult, NdtError> {
    params.validate()?;
    if source.is_empty() {
        return Err(NdtError::EmptySource);
    }
    let mut pose = PoseMat {
        rotation: guess.rotation.to_rotation_matrix().into_inner(),
        translation: guess.translation.vector,
    };
    let mut iterations = 0;
    let mut converged = false;
    let mut last = None;
    let levels = target.levels();
    for (i, map) in levels.iter().enumerate() {
        // Coarse levels only need to land in the next level's basin.
        let tolerance_scale = if i + 1 == levels.len() {
            1.0
        } else {
            COARSE_TOLERANCE_SCALE
        };
        let level = optimise_level(map, source, &mut pose, params, tolerance_scale)?;
        iterations += level.iterations;
        converged = level.converged;
        last = Some((map, level.gauss));
    }
    let Some((map, gauss)) = last else {
        return Err(NdtError::InvalidParams(InvalidParam::NoLevel));
    };
    let final_eval = evaluate(map, source, &pose, gauss, params.neighbourhood, true);
    let rotation = pose.rotation;
    let hessian_right = to_right_perturbation(&final_eval.hessian, &rotation);
    let degenerate = analyse(&hessian_right, params.degeneracy_ratio);
    let covariance = floored_inverse(&hessian_right);
    let sandwich = |s: &Matrix6<f64>| {
        let s = to_right_perturbation(s, &rotation);
        let c = covariance * s * covariance;
        (c + c.transpose()) * 0.5
    };
    let (covariance_sandwich, covariance_clustered) = if params.sandwich_covariance {
        let scatter = gradient_scatter(map, source, &pose, gauss, params.neighbourhood);
        (
            Some(sandwich(&scatter.per_point)),
            Some(sandwich(&scatter.per_cell)),
        )
    } else {
        (None, None)
    };
    Ok(NdtResult {
        t_target_source: isometry(&pose),
        covariance,
        covariance_sandwich,
        covariance_clustered,
        fitness: final_eval.score / (gauss.d1 * source.len() as f64),
        iterations,
        converged: converged && degenerate.is_none(),
        degenerate,
    })
}

struct LevelOutcome {
    iterations: usize,
    converged: bool,
    gauss: GaussFit,
}

/// Newton iterations at one resolution; updates `pose` in place.
fn optimise_level(
    map: &NdtMap,
    source: &[Vector3<f64>],
    pose: &mut PoseMat,
    params: &NdtParams,
    tolerance_scale: f64,
) -> Result<LevelOutcome, NdtError> {
    let gauss = GaussFit::new(map.resolution(), params.outlier_ratio);
    let eval = |p: &PoseMat| evaluate(map, source, p, gauss, params.neighbourhood, true);
    let mut current = eval(pose);
    if current.hits < MIN_HITS {
        return Err(NdtError::NoOverlap {
            hits: current.hits,
            resolution: map.resolution(),
        });
    }
    let max_t = params.max_step_fraction * map.resolution();
    let mut outcome = LevelOutcome {
        iterations: 0,
        converged: false,
        gauss,
    };
    let small = |step: &Vector6<f64>| {
        step.fixed_rows::<3>(0).norm() < tolerance_scale * params.translation_epsilon
            && step.fixed_rows::<3>(3).norm() < tolerance_scale * params.rotation_epsilon
    };
    while outcome.iterations < params.max_iterations {
        outcome.iterations += 1;
        let direction = clip(newton_direction(&current), max_t, params.max_rotation_step);
        if small(&direction) {
            // The Newton step itself is below tolerance: take it unchecked.
            *pose = apply(pose, &direction);
            outcome.converged = true;
            break;
        }
        let Some((alpha, next_pose, next)) = line_search(&current, &direction, pose, &eval) else {
            // No decrease along a descent direction: at the optimum within
            // floating-point resolution.
            outcome.converged = true;
            break;
        };
        *pose = next_pose;
        current = next;
        if small(&(alpha * direction)) {
            outcome.converged = true;
            break;
        }
    }
    Ok(outcome)
}

/// Saddle-free Newton: `-V |Lambda|^-1 V^T g`, eigenvalues floored.
fn newton_direction(e: &Evaluation) -> Vector6<f64> {
    let eig = SymmetricEigen::new(e.hessian);
    let max = eig.eigenvalues.abs().max().max(f64::MIN_POSITIVE);
    let inv = eig
        .eigenvalues
        .map(|l| 1.0 / l.abs().max(HESSIAN_FLOOR * max));
    -(eig.eigenvectors * Matrix6::from_diagonal(&inv) * eig.eigenvectors.transpose()) * e.gradient
}

/// Scales `d` so its translation is at most `max_t` and its rotation at most `max_r`.
fn clip(d: Vector6<f64>, max_t: f64, max_r: f64) -> Vector6<f64> {
    let t = d.fixed_rows::<3>(0).norm();
    let r = d.fixed_rows::<3>(3).norm();
    let scale = (max_t / t.max(f64::MIN_POSITIVE))
        .min(max_r / r.max(f64::MIN_POSITIVE))
        .min(1.0);
    d * scale
}

/// Backtracking from a full step until Armijo's sufficient decrease holds,
/// each shorter step from the minimum of the quadratic through `f(0)`,
/// `f'(0)` and the rejected `f(alpha)`, kept within `[0.1, 0.5] alpha`
/// (Nocedal and Wright, sec. 3.5); the accepted trial's full evaluation is
/// returned for reuse.
fn line_search(
    current: &Evaluation,
    direction: &Vector6<f64>,
    pose: &PoseMat,
    eval: &impl Fn(&PoseMat) -> Evaluation,
) -> Option<(f64, PoseMat, Evaluation)> {
    let slope = current.gradient.dot(direction);
    if slope.is_nan() || slope >= 0.0 {
        return None;
    }
    let mut alpha = 1.0;
    for _ in 0..=MAX_BACKTRACKS {
        let trial = apply(pose, &(alpha * direction));
        let e = eval(&trial);
        if e.score <= current.score + ARMIJO_C1 * alpha * slope {
            return Some((alpha, trial, e));
        }
        let curvature = e.score - current.score - slope * alpha;
        let minimiser = -slope * alpha * alpha / (2.0 * curvature);
        alpha = if minimiser.is_finite() {
            minimiser.clamp(0.1 * alpha, 0.5 * alpha)
        } else {
            0.5 * alpha
        };
    }
    None
}

/// `R <- Exp(phi) R`, `t <- t + dt` for `x = (dt, phi)`.
pub(crate) fn apply(pose: &PoseMat, x: &Vector6<f64>) -> PoseMat {
    let phi = Vector3::new(x[3], x[4], x[5]);
    let rotation = Rotation3::new(phi).into_inner() * pose.rotation;
    PoseMat {
        // Re-orthonormalise so many small updates do not drift off SO(3).
        rotation: Rotation3::from_matrix(&rotation).into_inner(),
        translation: pose.translation + Vector3::new(x[0], x[1], x[2]),
    }
}

fn isometry(pose: &PoseMat) -> Isometry3<f64> {
    let rotation = UnitQuaternion::from_matrix(&pose.rotation);
    Isometry3::from_parts(Translation3::from(pose.translation), rotation)
}

/// The Hessian w.r.t. `(dt, theta)` with `R = R_hat Exp(theta)`: since
/// `phi = R_hat theta`, `H_right = J^T H J` with `J = diag(I, R_hat)`.
fn to_right_perturbation(h: &Matrix6<f64>, rotation: &Matrix3<f64>) -> Matrix6<f64> {
    let mut j = Matrix6::identity();
    j.fixed_view_mut::<3, 3>(3, 3).copy_from(rotation);
    j.transpose() * h * j
}

/// Inverse of a symmetric matrix with eigenvalues floored at 1e-9 of the
/// largest (a pseudo-covariance that stays finite when degenerate).
fn floored_inverse(h: &Matrix6<f64>) -> Matrix6<f64> {
    let eig = SymmetricEigen::new(*h);
    let max = eig.eigenvalues.abs().max().max(f64::MIN_POSITIVE);
    let inv = eig.eigenvalues.map(|l| 1.0 / l.max(HESSIAN_FLOOR * max));
    eig.eigenvectors * Matrix6::from_diagonal(&inv) * eig.eigenvectors.transpose()
}

/// Exposes the score for tests and tools: total score, gradient and Hessian
/// (w.r.t. the left-perturbation parameters of the module docs) of `source`
/// at `pose` against `map`.
pub fn score_derivatives(
    map: &NdtMap,
    source: &[Vector3<f64>],
    pose: &Isometry3<f64>,
    params: &NdtParams,
) -> (f64, Vector6<f64>, Matrix6<f64>) {
    let gauss = GaussFit::new(map.resolution(), params.outlier_ratio);
    let pose = PoseMat {
        rotation: pose.rotation.to_rotation_matrix().into_inner(),
        translation: pose.translation.vector,
    };
    let e = evaluate(map, source, &pose, gauss, params.neighbourhood, true);
    (e.score, e.gradient, e.hessian)
}
