//! The scalar types the filter runs in: `f64` on the host, `f32` on microcontrollers.

use nalgebra::RealField;

/// A floating-point scalar the estimator is generic over (`f32` or `f64`).
pub trait Scalar: RealField + Copy + Default {
    /// Converts an `f64` constant (exact for `f64`, rounded for `f32`).
    fn lit(x: f64) -> Self;
    /// Converts to `f64` (for time arithmetic in nanoseconds and for reports).
    fn to_f64(self) -> f64;
}

impl Scalar for f32 {
    fn lit(x: f64) -> Self {
        x as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
}

impl Scalar for f64 {
    fn lit(x: f64) -> Self {
        x
    }
    fn to_f64(self) -> f64 {
        self
    }
}
