//! Batch non-linear least squares: a Levenberg-Marquardt solver over one SE(3) pose with
//! robust losses and the covariance of its result ([`lm`], [`loss`]). The LiDAR-camera
//! calibration (chapter 2) uses it; problems with more than one pose (bundle adjustment)
//! can reuse its loss functions and damping strategy; [`ba`] is the Schur-complement LM
//! for those (global intrinsics and extrinsics, many local poses).

pub mod ba;
pub mod lm;
pub mod loss;

pub use ba::{
    solve_schur, BlockResidual, SchurError, SchurOptions, SchurProblem, SchurSummary,
    MAX_GLOBAL_COLS,
};
pub use lm::{solve_se3, LmError, LmOptions, LmSummary, Residual, Se3Problem};
pub use loss::Loss;
