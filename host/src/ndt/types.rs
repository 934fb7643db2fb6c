//! Options, result and error types of NDT.

use nalgebra::{Isometry3, Matrix6};

use super::DegeneracyReport;

/// Which cells a transformed source point is scored against.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Neighbourhood {
    /// Only the cell containing the point (Magnusson's original; fastest;
    /// the default, as coarse-to-fine levels give it a wide enough basin).
    #[default]
    Direct1,
    /// The containing cell and its 6 face neighbours (ndt_omp's DIRECT7).
    Direct7,
    /// The containing cell and all 26 neighbours (closest to PCL's radius search).
    Direct27,
}

impl Neighbourhood {
    /// The voxel offsets visited.
    pub(crate) fn offsets(self) -> &'static [[i32; 3]] {
        const D7: [[i32; 3]; 7] = [
            [0, 0, 0],
            [1, 0, 0],
            [-1, 0, 0],
            [0, 1, 0],
            [0, -1, 0],
            [0, 0, 1],
            [0, 0, -1],
        ];
        const D27: [[i32; 3]; 27] = {
            let mut out = [[0; 3]; 27];
            let mut i = 0;
            while i < 27 {
                out[i] = [
                    (i % 3) as i32 - 1,
                    ((i / 3) % 3) as i32 - 1,
                    (i / 9) as i32 - 1,
                ];
                i += 1;
            }
            out
        };
        match self {
            Self::Direct1 => &D7[..1],
            Self::Direct7 => &D7,
            Self::Direct27 => &D27,
        }
    }
}

/// NDT options; `Default` is what the tests and benchmarks use.
#[derive(Debug, Clone, PartialEq)]
pub struct NdtParams {
    /// Cell sizes in metres, coarse to fine; the last one gives the result.
    pub resolutions: Vec<f64>,
    /// Expected fraction of outliers (PCL default 0.55); sets d1, d2.
    pub outlier_ratio: f64,
    /// Cells with fewer points get no Gaussian (Magnusson: 5).
    pub min_points_per_cell: usize,
    /// Covariance eigenvalues are floored at this fraction of the largest.
    pub eigenvalue_ratio: f64,
    /// Cells visited per point.
    pub neighbourhood: Neighbourhood,
    /// Newton iterations per resolution level.
    pub max_iterations: usize,
    /// Stop a level when a step moves less than this, metres...
    pub translation_epsilon: f64,
    /// ...and rotates less than this, radians.
    pub rotation_epsilon: f64,
    /// Largest translation step as a fraction of the level's resolution.
    pub max_step_fraction: f64,
    /// Largest rotation step, radians.
    pub max_rotation_step: f64,
    /// Degenerate when the smallest eigenvalue of the marginal translation
    /// or rotation information is below this fraction of its largest.
    pub degeneracy_ratio: f64,
    /// Also compute the sandwich covariances (one more pass over the source points).
    pub sandwich_covariance: bool,
}

impl Default for NdtParams {
    fn default() -> Self {
        Self {
            resolutions: vec![2.0, 1.0, 0.5],
            outlier_ratio: 0.55,
            min_points_per_cell: 5,
            eigenvalue_ratio: 0.01,
            neighbourhood: Neighbourhood::Direct1,
            max_iterations: 30,
            translation_epsilon: 1e-4,
            rotation_epsilon: 1e-5,
            max_step_fraction: 0.5,
            max_rotation_step: 0.1,
            degeneracy_ratio: 0.04,
            sandwich_covariance: false,
        }
    }
}

/// Outcome of one registration.
#[derive(Debug, Clone, PartialEq)]
pub struct NdtResult {
    /// Pose of the source scan in the target frame: `p_target = T p_source`.
    pub t_target_source: Isometry3<f64>,
    /// 6x6 covariance of `[t; theta]` (translation additive in the target
    /// frame, rotation a right perturbation `R = R_hat Exp(theta)`): the
    /// inverse Hessian of the finest level's score at the optimum, with
    /// eigenvalues floored (so it stays finite when degenerate: read
    /// `degenerate` first). Optimistic; see the module docs.
    pub covariance: Matrix6<f64>,
    /// Sandwich (M-estimator) covariance `H^-1 S H^-1`, `S = sum_i g_i g_i^T` over the
    /// per-point gradients at the optimum: independent of the score's scale (d1, d2) and
    /// set by the actual residual spread, but still reading points as independent.
    /// Present when `NdtParams::sandwich_covariance` asked for it.
    pub covariance_sandwich: Option<Matrix6<f64>>,
    /// Cluster-robust sandwich: `S` summed per target cell first, since points scored
    /// against the same cell share its (noisy) estimated Gaussian. With the above.
    pub covariance_clustered: Option<Matrix6<f64>>,
    /// Mean normalised score per source point at the result,
    /// `sum_k sum_cells exp(-d2/2 m_k) / N` on the finest level: 0 when no
    /// point lies near a Gaussian, about 1 when every point sits on a cell
    /// mean (can slightly exceed 1 with overlapping neighbourhoods).
    pub fitness: f64,
    /// Newton iterations summed over all levels.
    pub iterations: usize,
    /// True when the finest level met the step tolerances within
    /// `max_iterations` **and** no degeneracy was detected.
    pub converged: bool,
    /// Present when the Hessian is near-singular in some direction.
    pub degenerate: Option<DegeneracyReport>,
}

/// Why NDT could not run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum NdtError {
    /// The source cloud is empty.
    #[error("NDT: the source cloud is empty")]
    EmptySource,
    /// No target cell has enough points at this resolution.
    #[error("NDT: no target cell at resolution {resolution} m has {min_points} points or more")]
    EmptyTarget {
        /// The resolution, m.
        resolution: f64,
        /// The `min_points_per_cell` in force.
        min_points: usize,
    },
    /// No source point falls near a target Gaussian from the guess.
    #[error("NDT: only {hits} source points overlap the target at resolution {resolution} m")]
    NoOverlap {
        /// Points that touched at least one cell.
        hits: usize,
        /// The resolution, m.
        resolution: f64,
    },
    /// Inconsistent options.
    #[error("NDT: invalid parameter: {0}")]
    InvalidParams(InvalidParam),
}

/// Which NDT option is out of its range.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum InvalidParam {
    /// `resolutions` is empty or holds a non-positive or non-finite value.
    #[error("resolutions must be non-empty, positive and finite")]
    Resolutions,
    /// `outlier_ratio` outside (0, 1).
    #[error("outlier_ratio must be in (0, 1)")]
    OutlierRatio,
    /// `min_points_per_cell` below 3.
    #[error("min_points_per_cell must be at least 3")]
    MinPointsPerCell,
    /// `eigenvalue_ratio` outside (0, 1].
    #[error("eigenvalue_ratio must be in (0, 1]")]
    EigenvalueRatio,
    /// `max_iterations` is zero.
    #[error("max_iterations must be positive")]
    MaxIterations,
    /// A non-positive step limit.
    #[error("step limits must be positive")]
    StepLimits,
    /// The target map has no resolution level.
    #[error("the target has no level")]
    NoLevel,
}

impl NdtParams {
    /// Checks the options.
    pub fn validate(&self) -> Result<(), NdtError> {
        let bad = |p| Err(NdtError::InvalidParams(p));
        if self.resolutions.is_empty()
            || self
                .resolutions
                .iter()
                .any(|r| !(r.is_finite() && *r > 0.0))
        {
            return bad(InvalidParam::Resolutions);
        }
        if !(self.outlier_ratio > 0.0 && self.outlier_ratio < 1.0) {
            return bad(InvalidParam::OutlierRatio);
        }
        if self.min_points_per_cell < 3 {
            return bad(InvalidParam::MinPointsPerCell);
        }
        if !(self.eigenvalue_ratio > 0.0 && self.eigenvalue_ratio <= 1.0) {
            return bad(InvalidParam::EigenvalueRatio);
        }
        if self.max_iterations == 0 {
            return bad(InvalidParam::MaxIterations);
        }
        if !(self.max_step_fraction > 0.0 && self.max_rotation_step > 0.0) {
            return bad(InvalidParam::StepLimits);
        }
        Ok(())
    }
}
