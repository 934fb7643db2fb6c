//! Batch non-linear least squares: a Levenberg-Marquardt solver over one SE(3) pose with
//! robust losses and the covariance of its result ([`lm`], [`loss`]). The LiDAR-camera
//! calibration (chapter 2) uses it; problems with more than one pose (bundle adjustment)
//! can reuse its loss functions and damping strategy.

pub mod lm;
pub mod loss;

pub use lm::{solve_se3, LmError, LmOptions, LmSummary, Residual, Se3Problem};
pub use loss::Loss;
