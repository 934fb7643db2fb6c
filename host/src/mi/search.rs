//! Coarse-to-fine grid search (parallel over candidates), continuous 6-DoF refinement of
//! the smoothed MI (Levenberg-Marquardt on a finite-difference Hessian of the analytic
//! gradient), and sigmas from the MI curvature.

use nalgebra::{Isometry3, Matrix6, SymmetricEigen, Vector6};
use rayon::prelude::*;
use serde::Serialize;

use super::histogram::MiScore;
use super::scene::{MiScene, PoseParam};

/// One grid axis: `2 * steps + 1` values spaced `half_range / steps` at the first level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridAxis {
    /// Half width of the first level.
    pub half_range: f64,
    /// Values each side of the centre.
    pub steps: usize,
}

/// Result of [`grid_search`].
#[derive(Clone, Debug, PartialEq)]
pub struct GridResult {
    /// Best parameter vector.
    pub best: Vec<f64>,
    /// Smoothed MI there.
    pub mi: f64,
    /// Candidates evaluated.
    pub evaluations: usize,
}

/// Score of a grid candidate.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridScore {
    /// B-spline smoothed MI (16 bin updates per sample; smoother).
    Smoothed,
    /// Hard-binned MI (one bin update per sample; about twice as fast).
    Hard,
}

/// Maximises the MI over `axes` (parameters start at zero) for `levels` levels,
/// each centred on the previous best with the spacing divided by `steps` (by 2 for one
/// step). `pose` maps a parameter vector to `T_cam_src`.
pub fn grid_search<F>(
    scene: &MiScene,
    axes: &[GridAxis],
    levels: usize,
    score: GridScore,
    pose: F,
) -> GridResult
where
    F: Fn(&[f64]) -> Isometry3<f64> + Sync,
{
    grid_search_by(axes, levels, |c| {
        let t = pose(c);
        match score {
            GridScore::Smoothed => scene.histogram_serial(&t).score().mi,
            GridScore::Hard => scene.hard_serial(&t),
        }
    })
}

/// The lattice of [`grid_search`] with any score of the parameter vector (higher is
/// better), evaluated in parallel over the candidates of a level.
pub fn grid_search_by<F>(axes: &[GridAxis], levels: usize, score: F) -> GridResult
where
    F: Fn(&[f64]) -> f64 + Sync,
{
    grid_search_batch(axes, levels, |candidates| {
        candidates.par_iter().map(|c| score(c)).collect()
    })
}

/// The lattice of [`grid_search`] with a score of all candidates of a level at once
/// (one value per candidate, higher is better; the scorer chooses how to parallelise).
pub fn grid_search_batch<F>(axes: &[GridAxis], levels: usize, score_all: F) -> GridResult
where
    F: Fn(&[Vec<f64>]) -> Vec<f64>,
{
    let mut centre = vec![0.0; axes.len()];
    let mut spacing: Vec<f64> = axes
        .iter()
        .map(|a| a.half_range / a.steps.max(1) as f64)
        .collect();
    let mut best_mi = f64::NEG_INFINITY;
    let mut evaluations = 0;
    for _ in 0..levels.max(1) {
        let candidates = lattice(&centre, &spacing, axes);
        evaluations += candidates.len();
        let scores = score_all(&candidates);
        let best = (0..candidates.len().min(scores.len()))
            .max_by(|&a, &b| scores[a].total_cmp(&scores[b]).then(b.cmp(&a)));
        if let Some(i) = best.filter(|&i| scores[i] > best_mi) {
            best_mi = scores[i];
            centre = candidates[i].clone();
        }
        for (s, a) in spacing.iter_mut().zip(axes) {
            *s /= a.steps.max(2) as f64;
        }
    }
    GridResult {
        best: centre,
        mi: best_mi,
        evaluations,
    }
}

/// A scored parameter vector of [`grid_search_multi`].
#[derive(Clone, Debug, PartialEq)]
pub struct Candidate {
    /// Parameters (one per axis).
    pub params: Vec<f64>,
    /// Score (higher is better).
    pub score: f64,
}

/// Result of [`grid_search_multi`].
#[derive(Clone, Debug, PartialEq)]
pub struct MultiResult {
    /// The kept candidates of the last level, best first.
    pub best: Vec<Candidate>,
    /// Candidates evaluated over all levels.
    pub evaluations: usize,
}

/// Coarse-to-fine lattice that keeps several candidates: level 0 is the lattice of `axes`
/// around zero; each next level halves the spacing and lays a 3-per-axis lattice around
/// each of the `keep` best distinct candidates of the level before (distinct: not lattice
/// neighbours of a better kept one). `score(level, params)` is evaluated in parallel over
/// the candidates of a level (the level lets the caller coarsen the objective, e.g. blur).
pub fn grid_search_multi<F>(axes: &[GridAxis], levels: usize, keep: usize, score: F) -> MultiResult
where
    F: Fn(usize, &[f64]) -> f64 + Sync,
{
    let mut spacing: Vec<f64> = axes
        .iter()
        .map(|a| a.half_range / a.steps.max(1) as f64)
        .collect();
    let mut candidates = lattice(&vec![0.0; axes.len()], &spacing, axes);
    let (mut evaluations, mut best) = (0, Vec::new());
    for level in 0..levels.max(1) {
        evaluations += candidates.len();
        let scores: Vec<f64> = candidates.par_iter().map(|c| score(level, c)).collect();
        best = distinct_best(&candidates, &scores, &spacing, keep.max(1));
        for s in &mut spacing {
            *s /= 2.0;
        }
        let one: Vec<GridAxis> = axes
            .iter()
            .map(|a| GridAxis {
                half_range: a.half_range,
                steps: 1,
            })
            .collect();
        candidates = best
            .iter()
            .flat_map(|c| lattice(&c.params, &spacing, &one))
            .collect();
        dedup_candidates(&mut candidates, &spacing);
    }
    MultiResult { best, evaluations }
}

/// The `keep` best candidates, skipping any within one `spacing` on every axis of a better
/// kept one (its lattice neighbour: the same maximum).
fn distinct_best(
    candidates: &[Vec<f64>],
    scores: &[f64],
    spacing: &[f64],
    keep: usize,
) -> Vec<Candidate> {
    let mut order: Vec<usize> = (0..candidates.len().min(scores.len())).collect();
    order.sort_by(|&a, &b| scores[b].total_cmp(&scores[a]).then(a.cmp(&b)));
    let mut kept: Vec<Candidate> = Vec::with_capacity(keep);
    for i in order {
        if kept.len() == keep {
            break;
        }
        let c = &candidates[i];
        let neighbour = kept.iter().any(|k| {
            k.params
                .iter()
                .zip(c)
                .zip(spacing)
                .all(|((a, b), s)| (a - b).abs() <= 1.5 * s)
        });
        if !neighbour {
            kept.push(Candidate {
                params: c.clone(),
                score: scores[i],
            });
        }
    }
    kept
}

/// Removes repeated lattice points (overlapping lattices around nearby centres).
fn dedup_candidates(candidates: &mut Vec<Vec<f64>>, spacing: &[f64]) {
    let key = |c: &Vec<f64>| -> Vec<i64> {
        c.iter()
            .zip(spacing)
            .map(|(v, s)| (v / (s * 1e-3)).round() as i64)
            .collect()
    };
    let mut seen = std::collections::HashSet::new();
    candidates.retain(|c| seen.insert(key(c)));
}

/// Every combination of `centre + k * spacing`, `|k| <= steps` per axis.
fn lattice(centre: &[f64], spacing: &[f64], axes: &[GridAxis]) -> Vec<Vec<f64>> {
    let mut out = vec![Vec::with_capacity(axes.len())];
    for (i, a) in axes.iter().enumerate() {
        let n = a.steps as isize;
        out = out
            .into_iter()
            .flat_map(|prefix| {
                (-n..=n).map(move |k| {
                    let mut v = prefix.clone();
                    v.push(centre[i] + k as f64 * spacing[i]);
                    v
                })
            })
            .collect();
    }
    out
}

/// Refinement settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefineOptions {
    /// Iteration limit.
    pub max_iterations: usize,
    /// Finite-difference step of the Hessian, as mean image motion (px).
    pub fd_px: f64,
    /// Largest step, as mean image motion summed over DoFs (px).
    pub max_step_px: f64,
    /// Converged when a step moves the image less than this (px).
    pub tolerance_px: f64,
    /// Image cell (px) counted as one independent sample for the sigmas.
    pub cell_px: f64,
    /// Recompute the finite-difference Hessian every this many iterations.
    pub hessian_every: usize,
    /// DoFs of `delta` held at the starting value (not stepped; reported unconstrained and
    /// `poor`): those the MI does not determine.
    pub held: [bool; 6],
    /// One sigma of the initial guess per DoF of `delta` (rad, m; positive): the
    /// uncertainty the start already has. A DoF about which the MI gives less information
    /// than this is reported unconstrained, with this sigma ([`Constraint`]).
    pub prior_sigma: Vector6<f64>,
}

/// The initial guess's sigma of `--targetless` unless the guess file gives one: the
/// basin it searches (`BasinOptions::default`: 2 deg per rotation axis, 10 cm per
/// translation axis; issue 15's perturbations reach that far).
pub fn default_prior_sigma() -> Vector6<f64> {
    let r = 2f64.to_radians();
    Vector6::new(r, r, r, 0.10, 0.10, 0.10)
}

impl Default for RefineOptions {
    fn default() -> Self {
        Self {
            max_iterations: 40,
            fd_px: 0.5,
            max_step_px: 8.0,
            tolerance_px: 0.02,
            cell_px: 3.0,
            hessian_every: 4,
            held: [false; 6],
            prior_sigma: default_prior_sigma(),
        }
    }
}

/// How well one DoF is determined.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Observability {
    /// One sigma moves the image by less than 0.5 px.
    Strong,
    /// 0.5 to 3 px.
    Weak,
    /// More than 3 px, or unconstrained ([`Constraint`]).
    Poor,
}

/// What determines a DoF's reported sigma.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Constraint {
    /// The MI's curvature: it gives more information about the DoF than the initial
    /// guess's sigma does (the posterior variance is below half the prior's).
    Measured,
    /// Held at the initial value ([`RefineOptions::held`]): the search found the MI flat
    /// along it; sigma = the initial guess's.
    HeldAtInitial,
    /// The MI curves upwards along it (the end is not a maximum there; with the curvature's
    /// magnitude it would be measured); sigma = the initial guess's.
    NotAMaximum,
    /// The MI is (nearly) flat along it: its curvature gives less information than the
    /// initial guess's sigma; sigma = the initial guess's.
    Flat,
}

impl Constraint {
    /// True unless [`Constraint::Measured`].
    pub fn is_unconstrained(self) -> bool {
        self != Self::Measured
    }

    /// The name in files (as serialised).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Measured => "measured",
            Self::HeldAtInitial => "held_at_initial",
            Self::NotAMaximum => "not_a_maximum",
            Self::Flat => "flat",
        }
    }

    /// Why, in words (for messages).
    pub fn why(self) -> &'static str {
        match self {
            Self::Measured => "determined by the MI curvature",
            Self::HeldAtInitial => {
                "held at the initial value (the MI profile along it is flat within the search \
                 range)"
            }
            Self::NotAMaximum => "the MI curves upwards along it (not a maximum)",
            Self::Flat => {
                "the MI is flat along it (less information than the initial guess's sigma)"
            }
        }
    }
}

/// A refined pose with its curvature-based uncertainty.
#[derive(Clone, Debug)]
pub struct Refined {
    /// The state pose (see [`PoseParam`]).
    pub x: Isometry3<f64>,
    /// Smoothed MI / NMI at the optimum.
    pub smoothed: MiScore,
    /// Hard-binned MI / NMI at the optimum.
    pub hard: MiScore,
    /// Hessian of the smoothed MI w.r.t. `delta` at the optimum.
    pub hessian: Matrix6<f64>,
    /// `[omega (rad); v (m)]`: the inverse of the MI's information `n_eff (-H)` on its
    /// positive eigen-directions plus the initial guess's (`diag(prior_sigma^-2)`), with
    /// the rows and columns of unconstrained DoFs replaced by the prior's variance alone
    /// ([`uncertainty`]); no sigma exceeds the prior's.
    pub covariance: Matrix6<f64>,
    /// What determines each DoF's sigma.
    pub constraint: [Constraint; 6],
    /// The initial guess's sigma ([`RefineOptions::prior_sigma`]).
    pub prior_sigma: Vector6<f64>,
    /// Independent samples assumed (occupied image cells).
    pub n_eff: usize,
    /// Mean image motion per unit of each DoF (px/rad, px/m).
    pub pixels_per_unit: Vector6<f64>,
    /// Per DoF.
    pub observability: [Observability; 6],
    /// Iterations used.
    pub iterations: usize,
    /// True when the step tolerance was reached before the iteration limit.
    pub converged: bool,
    /// DoFs held at the starting value ([`RefineOptions::held`]).
    pub held: [bool; 6],
}

/// Central finite-difference Hessian of the analytic gradient, symmetrised.
pub fn hessian(
    scene: &MiScene,
    param: PoseParam,
    x: &Isometry3<f64>,
    steps: &Vector6<f64>,
) -> Matrix6<f64> {
    let mut h = Matrix6::zeros();
    for k in 0..6 {
        let mut d = Vector6::zeros();
        d[k] = steps[k];
        let gp = scene.evaluate(param, &param.retract(x, &d)).gradient;
        let gm = scene.evaluate(param, &param.retract(x, &(-d))).gradient;
        h.set_column(k, &((gp - gm) / (2.0 * steps[k])));
    }
    (h + h.transpose()) * 0.5
}

/// `-H` with its eigenvalues floored at `1e-6` of the largest (a positive definite
/// curvature for the step; the true `H` is kept for the sigmas).
fn positive_curvature(h: &Matrix6<f64>) -> Matrix6<f64> {
    let eig = SymmetricEigen::new(-h);
    let top = eig.eigenvalues.max().max(1e-300);
    let floored = eig.eigenvalues.map(|e| e.max(1e-6 * top));
    eig.eigenvectors * Matrix6::from_diagonal(&floored) * eig.eigenvectors.transpose()
}

/// `m` with the rows and columns of the held DoFs replaced by those of `diagonal * I`.
fn mask_held(m: &Matrix6<f64>, held: &[bool; 6], diagonal: f64) -> Matrix6<f64> {
    Matrix6::from_fn(|i, j| match (held[i] || held[j], i == j) {
        (false, _) => m[(i, j)],
        (true, true) => diagonal,
        (true, false) => 0.0,
    })
}

/// `v` with the held DoFs zeroed.
fn zero_held(v: &Vector6<f64>, held: &[bool; 6]) -> Vector6<f64> {
    Vector6::from_fn(|k, _| if held[k] { 0.0 } else { v[k] })
}

/// Maximises the smoothed MI over the DoFs not held from state `x0`.
pub fn refine(
    scene: &MiScene,
    param: PoseParam,
    x0: &Isometry3<f64>,
    options: &RefineOptions,
) -> Refined {
    let mut x = *x0;
    let ppu = scene.pixels_per_unit(param, &x).map(|v| v.max(1e-9));
    let fd = ppu.map(|v| options.fd_px / v);
    let mut current = scene.evaluate(param, &x);
    let mut lambda = 1e-3;
    let (mut iterations, mut converged) = (0, false);
    let mut a = Matrix6::zeros();
    while iterations < options.max_iterations && !converged {
        // The curvature (12 gradient evaluations) is refreshed every few iterations only.
        if iterations % options.hessian_every.max(1) == 0 {
            a = mask_held(
                &positive_curvature(&hessian(scene, param, &x, &fd)),
                &options.held,
                1.0,
            );
        }
        iterations += 1;
        let mut accepted = false;
        while lambda < 1e8 {
            let damped = a + Matrix6::from_diagonal(&a.diagonal()) * lambda;
            let gradient = zero_held(&current.gradient, &options.held);
            let Some(step) = damped.cholesky().map(|c| c.solve(&gradient)) else {
                lambda *= 10.0;
                continue;
            };
            let motion = step.component_mul(&ppu).abs().sum();
            let step = step * (options.max_step_px / motion).min(1.0);
            let candidate = param.retract(&x, &step);
            let next = scene.evaluate(param, &candidate);
            if next.score.mi > current.score.mi {
                x = candidate;
                current = next;
                lambda = (lambda / 3.0).max(1e-6);
                accepted = true;
                converged = motion.min(options.max_step_px) < options.tolerance_px;
                break;
            }
            lambda *= 4.0;
        }
        if !accepted {
            converged = true;
        }
    }
    finish(scene, param, x, &fd, options, iterations, converged)
}

/// The reported covariance and what determines each DoF, from the MI's `information`
/// (`n_eff (-H)`, held rows and columns zeroed) and the initial guess's `prior_sigma`.
/// The MI informs only along its positive eigen-directions (a direction of zero or upward
/// curvature carries none), so the posterior is `P = (I+ + P0^-1)^-1` with `I+` the
/// positive part. A DoF is measured when `P_kk < prior_k^2 / 2` (the MI gives at least as
/// much information about it as the guess); otherwise it is unconstrained: not a maximum
/// when the curvature's magnitude (`|I|` in place of `I+`) would have measured it, else
/// flat. Unconstrained DoFs get the prior's variance and no correlation.
pub fn uncertainty(
    information: &Matrix6<f64>,
    held: &[bool; 6],
    prior_sigma: &Vector6<f64>,
) -> (Matrix6<f64>, [Constraint; 6]) {
    let prior_var = prior_sigma.map(|s| s.abs().max(1e-12).powi(2));
    let prior_info = Matrix6::from_diagonal(&prior_var.map(f64::recip));
    let eig = SymmetricEigen::new(mask_held(information, held, 0.0));
    let with = |f: fn(f64) -> f64| {
        let info = eig.eigenvectors
            * Matrix6::from_diagonal(&eig.eigenvalues.map(f))
            * eig.eigenvectors.transpose();
        let total = info + prior_info;
        total
            .cholesky()
            .map_or(Matrix6::from_diagonal(&prior_var), |c| c.inverse())
    };
    let posterior = with(|e| e.max(0.0));
    let magnitude = with(f64::abs);
    let constraint: [Constraint; 6] = std::array::from_fn(|k| {
        if held[k] {
            Constraint::HeldAtInitial
        } else if posterior[(k, k)] < 0.5 * prior_var[k] {
            Constraint::Measured
        } else if magnitude[(k, k)] < 0.5 * prior_var[k] {
            Constraint::NotAMaximum
        } else {
            Constraint::Flat
        }
    });
    let free = |k: usize| !constraint[k].is_unconstrained();
    let covariance = Matrix6::from_fn(|i, j| match (free(i) && free(j), i == j) {
        (true, _) => posterior[(i, j)],
        (false, true) => prior_var[i],
        (false, false) => 0.0,
    });
    (covariance, constraint)
}

fn finish(
    scene: &MiScene,
    param: PoseParam,
    x: Isometry3<f64>,
    fd: &Vector6<f64>,
    options: &RefineOptions,
    iterations: usize,
    converged: bool,
) -> Refined {
    let t = param.t_cam_src(&x);
    let h = hessian(scene, param, &x, fd);
    let n_eff = scene.occupied_cells(&t, options.cell_px).max(1);
    // Held DoFs carry no information (their rows and columns are zeroed).
    let information = mask_held(&(-h * n_eff as f64), &options.held, 0.0);
    let (covariance, constraint) = uncertainty(&information, &options.held, &options.prior_sigma);
    let ppu = scene.pixels_per_unit(param, &x);
    let observability = std::array::from_fn(|k| {
        let px = covariance[(k, k)].max(0.0).sqrt() * ppu[k];
        if constraint[k].is_unconstrained() || !px.is_finite() || px > 3.0 {
            Observability::Poor
        } else if px > 0.5 {
            Observability::Weak
        } else {
            Observability::Strong
        }
    });
    Refined {
        x,
        smoothed: scene.smoothed(&t),
        hard: scene.hard(&t),
        hessian: h,
        covariance,
        constraint,
        prior_sigma: options.prior_sigma,
        n_eff,
        pixels_per_unit: ppu,
        observability,
        iterations,
        converged,
        held: options.held,
    }
}
