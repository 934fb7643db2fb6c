//! Levenberg-Marquardt over one pose `T` in SE(3), for problems whose residuals are
//! scalars with a known 1x6 Jacobian (point-to-plane, reprojection split per coordinate).
//!
//! - Perturbation: right on the rotation, additive on the translation ([`Pose::boxplus`]),
//!   Jacobian columns ordered `[d_theta, d_p]` as everywhere in the project.
//! - Cost: `sum_i rho(w_i r_i^2)` with a robust [`Loss`]; the normal equations are those of
//!   iteratively re-weighted least squares (`rho'` times the information `w_i`).
//! - Damping: Marquardt's `H + lambda diag(H)`; a step is taken only if it lowers the cost,
//!   otherwise `lambda` grows tenfold, so the cost never increases.
//! - Covariance: `(J^T W J)^-1` scaled by the variance factor `sum rho' w r^2 / (N - 6)`,
//!   so relative weights (e.g. 1 / points per frame) still give a covariance in metres and
//!   radians; with true information weights the factor is close to 1.

use msreg_estimator::Pose;
use nalgebra::{Matrix6, RowVector6, Vector3, Vector6};

use super::loss::Loss;

/// One scalar residual with its Jacobian and weight, evaluated at a pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Residual {
    /// `r_i`.
    pub value: f64,
    /// `d r_i / d [theta (right), p]`.
    pub jacobian: RowVector6<f64>,
    /// Information `w_i` (1 / variance, or a relative weight).
    pub weight: f64,
}

/// A least-squares problem over one SE(3) pose.
pub trait Se3Problem {
    /// Appends every residual at `pose` to `out` (cleared by the caller); `false` when the
    /// pose is outside the problem's valid region (the step is then rejected).
    fn residuals(&self, pose: &Pose<f64>, out: &mut Vec<Residual>) -> bool;
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LmOptions {
    /// Robust loss on each whitened squared residual.
    pub loss: Loss,
    /// Iteration cap (accepted or rejected steps).
    pub max_iterations: usize,
    /// Initial Marquardt damping.
    pub initial_lambda: f64,
    /// Converged when an accepted step lowers the cost by less than this fraction.
    pub relative_cost_tolerance: f64,
    /// Converged when the step (rad and m together) is shorter than this.
    pub step_tolerance: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            loss: Loss::Squared,
            max_iterations: 200,
            initial_lambda: 1e-4,
            relative_cost_tolerance: 1e-12,
            step_tolerance: 1e-10,
        }
    }
}

/// Why the solver could not run.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LmError {
    /// The start pose is invalid for the problem or has no residual.
    #[error("the problem has no valid residual at the initial pose")]
    InvalidStart,
    /// Fewer residuals than the 6 unknowns, or `J^T W J` is singular at the solution.
    #[error("the pose is not observable from the residuals (rank-deficient normal equations)")]
    Degenerate,
}

/// The solution and how it was reached.
#[derive(Clone, Debug, PartialEq)]
pub struct LmSummary {
    /// The pose at the minimum.
    pub pose: Pose<f64>,
    /// Covariance of `[d_theta (right), d_p]` (see the module docs).
    pub covariance: Matrix6<f64>,
    /// Robust cost at the start.
    pub initial_cost: f64,
    /// Robust cost at the solution.
    pub final_cost: f64,
    /// Cost after every accepted step (starting with the initial cost).
    pub history: Vec<f64>,
    /// Iterations used.
    pub iterations: usize,
    /// A tolerance was met before the iteration cap.
    pub converged: bool,
    /// Residuals at the solution.
    pub residual_count: usize,
}

/// Normal equations and robust cost at one pose.
struct Linearisation {
    hessian: Matrix6<f64>,
    gradient: Vector6<f64>,
    cost: f64,
    weighted_ssr: f64,
    count: usize,
}

fn linearise(
    problem: &dyn Se3Problem,
    pose: &Pose<f64>,
    loss: Loss,
    buffer: &mut Vec<Residual>,
) -> Option<Linearisation> {
    buffer.clear();
    if !problem.residuals(pose, buffer) || buffer.is_empty() {
        return None;
    }
    let mut lin = Linearisation {
        hessian: Matrix6::zeros(),
        gradient: Vector6::zeros(),
        cost: 0.0,
        weighted_ssr: 0.0,
        count: buffer.len(),
    };
    for r in buffer.iter() {
        let s = r.weight * r.value * r.value;
        if !s.is_finite() {
            return None;
        }
        let w = r.weight * loss.weight(s);
        lin.cost += loss.rho(s);
        lin.weighted_ssr += w * r.value * r.value;
        let jt = r.jacobian.transpose();
        lin.hessian.ger(w, &jt, &jt, 1.0);
        lin.gradient.axpy(w * r.value, &jt, 1.0);
    }
    Some(lin)
}

/// Minimises the problem's robust cost starting from `start`.
pub fn solve_se3(
    problem: &dyn Se3Problem,
    start: Pose<f64>,
    options: &LmOptions,
) -> Result<LmSummary, LmError> {
    let mut buffer = Vec::new();
    let mut pose = start;
    let mut lin =
        linearise(problem, &pose, options.loss, &mut buffer).ok_or(LmError::InvalidStart)?;
    if lin.count < 6 {
        return Err(LmError::Degenerate);
    }
    let initial_cost = lin.cost;
    let mut history = vec![lin.cost];
    let mut lambda = options.initial_lambda;
    let mut converged = false;
    let mut iterations = 0;
    while iterations < options.max_iterations {
        iterations += 1;
        let mut damped = lin.hessian;
        for k in 0..6 {
            damped[(k, k)] += lambda * lin.hessian[(k, k)].max(1e-12);
        }
        let Some(step) = damped.cholesky().map(|ch| ch.solve(&(-lin.gradient))) else {
            lambda *= 10.0;
            continue;
        };
        let candidate = pose.boxplus(
            &Vector3::new(step[0], step[1], step[2]),
            &Vector3::new(step[3], step[4], step[5]),
        );
        match linearise(problem, &candidate, options.loss, &mut buffer) {
            Some(next) if next.cost <= lin.cost => {
                let decrease = lin.cost - next.cost;
                pose = candidate;
                lin = next;
                history.push(lin.cost);
                lambda = (lambda * 0.3).max(1e-15);
                if decrease <= options.relative_cost_tolerance * lin.cost.max(f64::MIN_POSITIVE)
                    || step.norm() < options.step_tolerance
                {
                    converged = true;
                    break;
                }
            }
            _ => {
                lambda *= 10.0;
                if lambda > 1e12 {
                    // No step in any direction lowers the cost: a minimum to machine precision.
                    converged = true;
                    break;
                }
            }
        }
    }
    let dof = lin.count.saturating_sub(6).max(1) as f64;
    let covariance = lin
        .hessian
        .try_inverse()
        .filter(|c| c.iter().all(|x| x.is_finite()) && (0..6).all(|k| c[(k, k)] > 0.0))
        .ok_or(LmError::Degenerate)?
        * (lin.weighted_ssr / dof);
    Ok(LmSummary {
        pose,
        covariance,
        initial_cost,
        final_cost: lin.cost,
        history,
        iterations,
        converged,
        residual_count: lin.count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use msreg_estimator::lie::skew;
    use nalgebra::UnitQuaternion;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Point-to-plane: `n . (R p + t) - d` for points `p` known to lie on planes `(n, d)`.
    struct PointToPlane {
        items: Vec<(Vector3<f64>, Vector3<f64>, f64)>,
    }

    impl Se3Problem for PointToPlane {
        fn residuals(&self, pose: &Pose<f64>, out: &mut Vec<Residual>) -> bool {
            let r = pose.rotation.to_rotation_matrix().into_inner();
            for (p, n, d) in &self.items {
                let j_rot = -(n.transpose() * r * skew(p));
                let mut jacobian = RowVector6::zeros();
                jacobian.fixed_view_mut::<1, 3>(0, 0).copy_from(&j_rot);
                jacobian
                    .fixed_view_mut::<1, 3>(0, 3)
                    .copy_from(&n.transpose());
                out.push(Residual {
                    value: n.dot(&pose.transform_point(p)) - d,
                    jacobian,
                    weight: 1.0,
                });
            }
            true
        }
    }

    fn problem(truth: &Pose<f64>, noise: f64, outliers: usize, seed: u64) -> PointToPlane {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut items = Vec::new();
        for k in 0..12 {
            let n =
                Vector3::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0), 1.0).normalize();
            let d = 2.0 + k as f64 * 0.2;
            for _ in 0..40 {
                // A point on the plane in the target frame, mapped back to the source.
                let u = n.cross(&Vector3::x()).normalize();
                let v = n.cross(&u);
                let q = n * d
                    + u * rng.gen_range(-0.5..0.5)
                    + v * rng.gen_range(-0.5..0.5)
                    + n * noise * rng.gen_range(-1.7..1.7);
                let p = truth.inverse().transform_point(&q);
                items.push((p, n, d));
            }
        }
        for item in items.iter_mut().take(outliers) {
            item.2 += 0.5;
        }
        PointToPlane { items }
    }

    fn truth() -> Pose<f64> {
        Pose::new(
            UnitQuaternion::from_euler_angles(0.3, -1.2, 2.0),
            Vector3::new(0.1, -0.2, 0.05),
        )
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let prob = problem(&truth(), 0.01, 0, 1);
        let pose = Pose::new(
            UnitQuaternion::from_euler_angles(0.2, -1.0, 1.7),
            Vector3::new(0.0, 0.1, -0.1),
        );
        let mut base = Vec::new();
        assert!(prob.residuals(&pose, &mut base));
        let h = 1e-6;
        let step = |d: &Vector6<f64>| {
            pose.boxplus(
                &d.fixed_rows::<3>(0).into_owned(),
                &d.fixed_rows::<3>(3).into_owned(),
            )
        };
        for k in 0..6 {
            let mut d = Vector6::zeros();
            d[k] = h;
            let (mut a, mut b) = (Vec::new(), Vec::new());
            prob.residuals(&step(&d), &mut a);
            prob.residuals(&step(&-d), &mut b);
            for i in 0..base.len() {
                let numeric = (a[i].value - b[i].value) / (2.0 * h);
                assert!((numeric - base[i].jacobian[k]).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn converges_from_far_and_covariance_matches_the_spread() {
        let truth = truth();
        let mut errors = Vec::new();
        for seed in 0..40 {
            let prob = problem(&truth, 0.01, 0, seed);
            let start = Pose::new(
                UnitQuaternion::from_euler_angles(0.0, -0.5, 1.0),
                Vector3::zeros(),
            );
            let sol = solve_se3(&prob, start, &LmOptions::default()).unwrap();
            assert!(sol.converged);
            assert!(sol.history.windows(2).all(|w| w[1] <= w[0]));
            // Error in the solver's perturbation: truth = estimate [+] e.
            let rot = (sol.pose.rotation.inverse() * truth.rotation).scaled_axis();
            let trans = truth.translation - sol.pose.translation;
            let e = Vector6::new(rot.x, rot.y, rot.z, trans.x, trans.y, trans.z);
            let cov_inv = sol.covariance.try_inverse().unwrap();
            errors.push((e.transpose() * cov_inv * e)[0]);
        }
        // NEES of a 6-dof estimate: mean 6, well inside [4, 8.5] over 40 runs.
        let nees = errors.iter().sum::<f64>() / errors.len() as f64;
        assert!((4.0..8.5).contains(&nees), "mean NEES {nees}");
    }

    #[test]
    fn robust_losses_reject_gross_outliers() {
        let truth = truth();
        let prob = problem(&truth, 0.005, 40, 7);
        let start = Pose::new(UnitQuaternion::identity(), Vector3::zeros());
        let error = |loss| {
            let opts = LmOptions {
                loss,
                ..LmOptions::default()
            };
            let sol = solve_se3(&prob, start, &opts).unwrap();
            (sol.pose.translation - truth.translation).norm()
        };
        let plain = error(Loss::Squared);
        let huber = error(Loss::Huber(0.02));
        let cauchy = error(Loss::Cauchy(0.02));
        assert!(huber < plain / 3.0, "huber {huber} plain {plain}");
        assert!(cauchy < 0.003, "cauchy {cauchy}");
    }

    #[test]
    fn too_few_residuals_are_degenerate() {
        let mut prob = problem(&truth(), 0.0, 0, 3);
        prob.items.truncate(5);
        let err = solve_se3(&prob, Pose::identity(), &LmOptions::default()).unwrap_err();
        assert_eq!(err, LmError::Degenerate);
    }
}
