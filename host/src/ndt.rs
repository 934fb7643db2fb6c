//! Point-to-distribution NDT scan matching (Magnusson 2009, ch. 6; Biber and
//! Strasser 2003): the scan-matching step of the LiDAR-IMU filter
//! (dissertation ch. 3, Fig. 3.5b).
//!
//! - **Target** ([`NdtTarget`], [`NdtMap`]): one voxel map per resolution, each
//!   cell with at least `min_points_per_cell` points holding the mean and the
//!   inverse covariance; eigenvalues below `eigenvalue_ratio * lambda_max` are
//!   raised to it (Magnusson sec. 6.2, PCL's 0.01).
//! - **Score** (Magnusson eq. 6.9-6.10): every transformed source point `x`
//!   scores `d1 exp(-d2/2 (x-mu)^T Sigma^-1 (x-mu))` against the cells of
//!   its [`Neighbourhood`] (default: only the cell containing it; 7 or 27 cells optional);
//!   `d1 < 0`, `d2` come from the resolution and the outlier ratio (eq. 6.8),
//!   and the sum is minimised.
//! - **Parameters**: the pose `T_target_source = (R, t)` is updated as
//!   `R <- Exp(phi) R`, `t <- t + dt` with `x = (dt, phi)` (translation, then
//!   rotation vector; left perturbation about the target origin of the
//!   rotated-only point `q = R p`). Each Newton iteration re-linearises at
//!   `x = 0`, where the analytic gradient and Hessian are exact (eq. 6.12-6.13
//!   with `dq/dphi = -[q]x`, `d2q/dphi_i dphi_j = (e_j q_i + e_i q_j)/2 - delta_ij q`).
//! - **Step** ([`solver`]): Newton direction from the Hessian with its eigenvalues
//!   made positive (saddle-free Newton: `|lambda|`, floored), the step
//!   clipped to half a cell of translation and 0.1 rad, then backtracking
//!   (halving) with the Armijo sufficient-decrease test `f(x+a d) <= f(x) + 1e-4 a g^T d`.
//!   Coarse-to-fine over `resolutions`.
//! - **Threads**: the score, gradient and Hessian are a rayon fold/reduce over
//!   source points.
//! - **Output** ([`NdtResult`]): covariance = inverse Hessian of the finest
//!   level's score (a Laplace approximation that reads the score as a
//!   negative log-likelihood of independent points, so it is optimistic)
//!   expressed in the project's convention (rotation as a right perturbation
//!   `R = R_hat Exp(dtheta)`, translation additive, order `[t; theta]`);
//!   fitness = mean normalised score per source point (see [`NdtResult::fitness`]);
//!   degeneracy from the eigenvalues of the marginal translation and rotation
//!   information ([`DegeneracyReport`]).
//! - **Local map** ([`LocalMap`]): sliding window of the last K scans already
//!   in a common frame, voxel-downsampled, with per-cell sums added on
//!   insertion and subtracted on eviction.
//! - The box-world scenes of its tests and benchmarks are [`crate::sim::BoxWorld`]
//!   (`host/tests/ndt_box_world.rs`, `examples/ndt_bench.rs`).

mod degeneracy;
mod local_map;
mod map;
mod score;
pub mod solver;
mod types;

#[cfg(test)]
mod tests;

pub use degeneracy::DegeneracyReport;
pub use local_map::LocalMap;
pub use map::{NdtCell, NdtMap, NdtTarget};
pub use solver::{align, align_scans};
pub use types::{InvalidParam, NdtError, NdtParams, NdtResult, Neighbourhood};
