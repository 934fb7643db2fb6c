//! Levenberg-Marquardt for bundle-adjustment-shaped problems: a few *global* parameters
//! (intrinsics, extrinsics: a dense block) and many *local* 6-dof blocks (poses), each
//! residual touching one local block and some global columns. The local blocks are
//! eliminated by the Schur complement, so a step costs one dense solve of the global size
//! plus one 6x6 solve per local block.
//!
//! - Residuals are 2-vectors (a reprojection) with a scalar information `w`; the robust
//!   [`Loss`] acts on the whitened squared norm `s = w |r|^2` (iteratively re-weighted, as
//!   in [`super::lm`]).
//! - Damping: Marquardt's `H + lambda diag(H)` on both parts; a step is taken only when it
//!   lowers the cost, so the cost never increases.
//! - Manifolds: the problem applies a step itself ([`SchurProblem::retract`]); local
//!   blocks are typically SE(3) with [`msreg_estimator::Pose::boxplus`] ordering
//!   `[d_theta, d_p]`.
//! - Covariance of the global parameters: the inverse of the (undamped) Schur complement,
//!   the marginal of `(J^T W J)^-1`, scaled by the variance factor
//!   `sum rho' w |r|^2 / (2 N - n_global - 6 n_local)`.

use nalgebra::{DMatrix, DVector, Matrix2x6, Matrix6, SMatrix, Vector2, Vector6};

use super::loss::Loss;

/// The most global columns one residual may touch.
pub const MAX_GLOBAL_COLS: usize = 16;

/// One 2-vector residual evaluated at a state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockResidual {
    /// `r`.
    pub value: Vector2<f64>,
    /// Information `w` (1 / variance per coordinate).
    pub weight: f64,
    /// The local block it depends on.
    pub local: usize,
    /// `d r / d local`.
    pub j_local: Matrix2x6<f64>,
    /// Global columns it depends on (the first `global_len` entries).
    pub global_index: [usize; MAX_GLOBAL_COLS],
    /// How many of `global_index` are used.
    pub global_len: usize,
    /// `d r / d global[global_index[k]]` in column `k`.
    pub j_global: SMatrix<f64, 2, MAX_GLOBAL_COLS>,
}

/// A problem for [`solve_schur`].
pub trait SchurProblem {
    /// The parameters (global and local).
    type State: Clone;
    /// Number of global parameters.
    fn global_dim(&self) -> usize;
    /// Number of 6-dof local blocks.
    fn local_count(&self) -> usize;
    /// Appends every residual at `state` to `out` (cleared by the caller); `false` when the
    /// state is outside the problem's valid region (the step is then rejected).
    fn residuals(&self, state: &Self::State, out: &mut Vec<BlockResidual>) -> bool;
    /// `state` moved by a step of the global parameters and of every local block.
    fn retract(
        &self,
        state: &Self::State,
        global: &DVector<f64>,
        local: &[Vector6<f64>],
    ) -> Self::State;
}

/// Solver settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SchurOptions {
    /// Robust loss on each residual's whitened squared norm.
    pub loss: Loss,
    /// Iteration cap (accepted or rejected steps).
    pub max_iterations: usize,
    /// Initial Marquardt damping.
    pub initial_lambda: f64,
    /// Converged when an accepted step lowers the cost by less than this fraction.
    pub relative_cost_tolerance: f64,
}

impl Default for SchurOptions {
    fn default() -> Self {
        Self {
            loss: Loss::Squared,
            max_iterations: 100,
            initial_lambda: 1e-3,
            relative_cost_tolerance: 1e-10,
        }
    }
}

/// Why the solver could not run.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SchurError {
    /// No valid residual at the start.
    #[error("the problem has no valid residual at the initial state")]
    InvalidStart,
    /// The normal equations are singular at the solution (a parameter is unobservable).
    #[error("a parameter is not observable (rank-deficient normal equations)")]
    Degenerate,
}

/// The solution and how it was reached.
#[derive(Clone, Debug)]
pub struct SchurSummary<S> {
    /// The state at the minimum.
    pub state: S,
    /// Covariance of the global parameters (module docs).
    pub covariance: DMatrix<f64>,
    /// The variance factor that scaled it.
    pub variance_factor: f64,
    /// Robust cost after every accepted step, the initial cost first.
    pub history: Vec<f64>,
    /// Iterations used.
    pub iterations: usize,
    /// A tolerance was met before the iteration cap.
    pub converged: bool,
    /// Residuals at the solution.
    pub residual_count: usize,
}

/// Normal equations split into global, local and coupling blocks.
struct Normal {
    hgg: DMatrix<f64>,
    bg: DVector<f64>,
    hll: Vec<Matrix6<f64>>,
    bl: Vec<Vector6<f64>>,
    hgl: Vec<DMatrix<f64>>,
    cost: f64,
    weighted_ssr: f64,
    count: usize,
}

fn linearise<P: SchurProblem>(
    problem: &P,
    state: &P::State,
    loss: Loss,
    buffer: &mut Vec<BlockResidual>,
) -> Option<Normal> {
    buffer.clear();
    if !problem.residuals(state, buffer) || buffer.is_empty() {
        return None;
    }
    let (g, l) = (problem.global_dim(), problem.local_count());
    let mut n = Normal {
        hgg: DMatrix::zeros(g, g),
        bg: DVector::zeros(g),
        hll: vec![Matrix6::zeros(); l],
        bl: vec![Vector6::zeros(); l],
        hgl: vec![DMatrix::zeros(g, 6); l],
        cost: 0.0,
        weighted_ssr: 0.0,
        count: buffer.len(),
    };
    for r in buffer.iter() {
        let s = r.weight * r.value.norm_squared();
        if !s.is_finite() {
            return None;
        }
        let w = r.weight * loss.weight(s);
        n.cost += loss.rho(s);
        n.weighted_ssr += w * r.value.norm_squared();
        let jl = &r.j_local;
        n.hll[r.local] += w * jl.transpose() * jl;
        n.bl[r.local] += w * jl.transpose() * r.value;
        let jg = r.j_global.columns(0, r.global_len);
        let jgl = w * jg.transpose() * jl;
        let jgg = w * jg.transpose() * jg;
        let jgb = w * jg.transpose() * r.value;
        for (a, &ia) in r.global_index[..r.global_len].iter().enumerate() {
            n.bg[ia] += jgb[a];
            for (b, &ib) in r.global_index[..r.global_len].iter().enumerate() {
                n.hgg[(ia, ib)] += jgg[(a, b)];
            }
            for c in 0..6 {
                n.hgl[r.local][(ia, c)] += jgl[(a, c)];
            }
        }
    }
    Some(n)
}

/// `S`, the right-hand side and the damped local inverses.
type Reduced = (DMatrix<f64>, DVector<f64>, Vec<Matrix6<f64>>);

/// The reduced (Schur) system `S dx_g = rhs` with damping `lambda`, and the local
/// inverses used to back-substitute.
fn reduce(n: &Normal, lambda: f64) -> Option<Reduced> {
    let g = n.bg.len();
    let mut s = n.hgg.clone();
    for k in 0..g {
        s[(k, k)] += lambda * n.hgg[(k, k)].max(1e-12);
    }
    let mut rhs = -n.bg.clone();
    let mut inverses = Vec::with_capacity(n.hll.len());
    for (i, h) in n.hll.iter().enumerate() {
        let mut u = *h;
        for k in 0..6 {
            u[(k, k)] += lambda * h[(k, k)].max(1e-12) + 1e-12;
        }
        let ui = u.cholesky()?.inverse();
        let wu = &n.hgl[i] * ui;
        s -= &wu * n.hgl[i].transpose();
        rhs += &wu * n.bl[i];
        inverses.push(ui);
    }
    Some((s, rhs, inverses))
}

fn step(n: &Normal, lambda: f64) -> Option<(DVector<f64>, Vec<Vector6<f64>>)> {
    let (s, rhs, inverses) = reduce(n, lambda)?;
    let dg = s.cholesky()?.solve(&rhs);
    let dl = inverses
        .iter()
        .enumerate()
        .map(|(i, ui)| ui * (-n.bl[i] - n.hgl[i].tr_mul(&dg)))
        .collect();
    Some((dg, dl))
}

/// Minimises the problem's robust cost starting from `start`.
pub fn solve_schur<P: SchurProblem>(
    problem: &P,
    start: P::State,
    options: &SchurOptions,
) -> Result<SchurSummary<P::State>, SchurError> {
    let mut buffer = Vec::new();
    let mut state = start;
    let mut lin =
        linearise(problem, &state, options.loss, &mut buffer).ok_or(SchurError::InvalidStart)?;
    let mut history = vec![lin.cost];
    let mut lambda = options.initial_lambda;
    let (mut iterations, mut converged) = (0, false);
    while iterations < options.max_iterations {
        iterations += 1;
        let Some((dg, dl)) = step(&lin, lambda) else {
            lambda *= 10.0;
            continue;
        };
        let candidate = problem.retract(&state, &dg, &dl);
        match linearise(problem, &candidate, options.loss, &mut buffer) {
            Some(next) if next.cost <= lin.cost => {
                let decrease = lin.cost - next.cost;
                state = candidate;
                lin = next;
                history.push(lin.cost);
                lambda = (lambda * 0.3).max(1e-12);
                if decrease <= options.relative_cost_tolerance * lin.cost.max(f64::MIN_POSITIVE) {
                    converged = true;
                    break;
                }
            }
            _ => {
                lambda *= 10.0;
                if lambda > 1e10 {
                    converged = true;
                    break;
                }
            }
        }
    }
    let unknowns = problem.global_dim() + 6 * problem.local_count();
    let dof = (2 * lin.count).saturating_sub(unknowns).max(1) as f64;
    let variance_factor = lin.weighted_ssr / dof;
    let (s, _, _) = reduce(&lin, 0.0).ok_or(SchurError::Degenerate)?;
    let covariance = s
        .cholesky()
        .map(|c| c.inverse())
        .filter(|c| c.iter().all(|x| x.is_finite()))
        .ok_or(SchurError::Degenerate)?
        * variance_factor;
    Ok(SchurSummary {
        state,
        covariance,
        variance_factor,
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
    use msreg_estimator::Pose;
    use nalgebra::{UnitQuaternion, Vector3};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Points seen by a pinhole of unknown focal `f` (one global) from unknown poses.
    struct FocalAndPoses {
        points: Vec<Vector3<f64>>,
        pixels: Vec<Vec<Vector2<f64>>>,
    }

    impl SchurProblem for FocalAndPoses {
        type State = (f64, Vec<Pose<f64>>);
        fn global_dim(&self) -> usize {
            1
        }
        fn local_count(&self) -> usize {
            self.pixels.len()
        }
        fn residuals(&self, s: &Self::State, out: &mut Vec<BlockResidual>) -> bool {
            for (i, pose) in s.1.iter().enumerate() {
                let r = pose.rotation.to_rotation_matrix().into_inner();
                for (x, px) in self.points.iter().zip(&self.pixels[i]) {
                    let p = pose.transform_point(x);
                    let m = Vector2::new(p.x / p.z, p.y / p.z);
                    let jp = nalgebra::Matrix2x3::new(
                        s.0 / p.z,
                        0.0,
                        -s.0 * m.x / p.z,
                        0.0,
                        s.0 / p.z,
                        -s.0 * m.y / p.z,
                    );
                    let mut j_local = Matrix2x6::zeros();
                    j_local
                        .fixed_view_mut::<2, 3>(0, 0)
                        .copy_from(&(jp * -(r * skew(x))));
                    j_local.fixed_view_mut::<2, 3>(0, 3).copy_from(&jp);
                    let mut j_global = SMatrix::<f64, 2, MAX_GLOBAL_COLS>::zeros();
                    j_global.set_column(0, &m);
                    out.push(BlockResidual {
                        value: m * s.0 - px,
                        weight: 1.0,
                        local: i,
                        j_local,
                        global_index: [0; MAX_GLOBAL_COLS],
                        global_len: 1,
                        j_global,
                    });
                }
            }
            true
        }
        fn retract(&self, s: &Self::State, g: &DVector<f64>, l: &[Vector6<f64>]) -> Self::State {
            let poses = s
                .1
                .iter()
                .zip(l)
                .map(|(p, d)| p.boxplus(&d.fixed_rows::<3>(0).into(), &d.fixed_rows::<3>(3).into()))
                .collect();
            (s.0 + g[0], poses)
        }
    }

    fn problem(seed: u64, sigma: f64) -> (FocalAndPoses, Vec<Pose<f64>>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let points: Vec<Vector3<f64>> = (0..30)
            .map(|_| {
                Vector3::new(
                    rng.gen_range(-0.5..0.5),
                    rng.gen_range(-0.5..0.5),
                    rng.gen_range(-0.2..0.2),
                )
            })
            .collect();
        let poses: Vec<Pose<f64>> = (0..6)
            .map(|_| {
                Pose::new(
                    UnitQuaternion::from_euler_angles(
                        rng.gen_range(-0.3..0.3),
                        rng.gen_range(-0.3..0.3),
                        rng.gen_range(-1.0..1.0),
                    ),
                    Vector3::new(
                        rng.gen_range(-0.2..0.2),
                        rng.gen_range(-0.2..0.2),
                        rng.gen_range(2.0..3.0),
                    ),
                )
            })
            .collect();
        let pixels = poses
            .iter()
            .map(|pose| {
                points
                    .iter()
                    .map(|x| {
                        let p = pose.transform_point(x);
                        Vector2::new(500.0 * p.x / p.z, 500.0 * p.y / p.z)
                            + Vector2::new(rng.gen_range(-1.0..1.0), rng.gen_range(-1.0..1.0))
                                * sigma
                                * 3f64.sqrt()
                    })
                    .collect()
            })
            .collect();
        (FocalAndPoses { points, pixels }, poses)
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let (prob, poses) = problem(1, 0.0);
        let state = (480.0, poses);
        let mut base = Vec::new();
        prob.residuals(&state, &mut base);
        let h = 1e-6;
        for k in 0..7 {
            let mut dg = DVector::zeros(1);
            let mut dl = vec![Vector6::zeros(); 6];
            if k == 0 {
                dg[0] = h;
            } else {
                dl[2][k - 1] = h;
            }
            let (mut a, mut b) = (Vec::new(), Vec::new());
            prob.residuals(&prob.retract(&state, &dg, &dl), &mut a);
            prob.residuals(
                &prob.retract(&state, &(-&dg), &dl.iter().map(|d| -d).collect::<Vec<_>>()),
                &mut b,
            );
            for (i, r) in base.iter().enumerate() {
                let numeric = (a[i].value - b[i].value) / (2.0 * h);
                let analytic = if k == 0 {
                    r.j_global.column(0).into_owned()
                } else if r.local == 2 {
                    r.j_local.column(k - 1).into_owned()
                } else {
                    Vector2::zeros()
                };
                assert!(
                    (numeric - analytic).norm() < 1e-5,
                    "{k} {i}: {numeric} vs {analytic}"
                );
            }
        }
    }

    #[test]
    fn recovers_the_focal_and_its_sigma_is_consistent() {
        let mut nees = 0.0;
        for seed in 0..30 {
            let (prob, poses) = problem(seed, 0.5);
            let start: Vec<Pose<f64>> = poses
                .iter()
                .map(|p| {
                    p.boxplus(
                        &Vector3::new(0.02, -0.01, 0.03),
                        &Vector3::new(0.02, 0.01, -0.1),
                    )
                })
                .collect();
            let sol = solve_schur(&prob, (450.0, start), &SchurOptions::default()).unwrap();
            assert!(sol.converged);
            assert!(sol.history.windows(2).all(|w| w[1] <= w[0]));
            let e = sol.state.0 - 500.0;
            nees += e * e / sol.covariance[(0, 0)];
        }
        // Mean of 30 chi2(1) draws: 1, 99 % band about [0.5, 1.7].
        let mean = nees / 30.0;
        assert!((0.5..1.7).contains(&mean), "mean NEES {mean}");
    }
}
