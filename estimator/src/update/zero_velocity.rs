//! Zero-velocity update: at standstill the IMU measures only its biases and gravity.
//!
//! `z = [w_m; a_m; 0]`, `h(x) = [b_g; b_a - R_G_I^T g; v_G_I]`, with `g = (0, 0, -9.81)`.
//! Detecting standstill is the caller's decision (e.g. low gyro/accel variance); this module
//! is only the model.

use crate::lie::skew;
use crate::propagate::{ImuSample, GRAVITY};
use crate::scalar::Scalar;
use crate::state::{imu, ImuState};
use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

/// Residual dimension.
pub const DIM: usize = 9;

/// Residual and Jacobian (w.r.t. the 15-dim IMU error state) of a zero-velocity update.
pub fn linearize<T: Scalar>(
    x: &ImuState<T>,
    sample: &ImuSample<T>,
) -> (SVector<T, DIM>, SMatrix<T, DIM, 15>) {
    let g = Vector3::new(T::zero(), T::zero(), -T::lit(GRAVITY));
    let g_in_imu = x.rotation.inverse() * g;
    let mut r = SVector::<T, DIM>::zeros();
    r.fixed_rows_mut::<3>(0)
        .copy_from(&(sample.gyro - x.gyro_bias));
    r.fixed_rows_mut::<3>(3)
        .copy_from(&(sample.accel - (x.accel_bias - g_in_imu)));
    r.fixed_rows_mut::<3>(6).copy_from(&(-x.velocity));

    let mut h = SMatrix::<T, DIM, 15>::zeros();
    let eye = Matrix3::identity();
    h.fixed_view_mut::<3, 3>(0, imu::GYRO_BIAS.idx)
        .copy_from(&eye);
    h.fixed_view_mut::<3, 3>(3, imu::ACCEL_BIAS.idx)
        .copy_from(&eye);
    h.fixed_view_mut::<3, 3>(3, imu::ORIENTATION.idx)
        .copy_from(&(-skew(&g_in_imu)));
    h.fixed_view_mut::<3, 3>(6, imu::VELOCITY.idx)
        .copy_from(&eye);
    (r, h)
}

/// Noise of the zero-velocity residual: one IMU sample's white noise (densities over the
/// sample period) and a velocity sigma for "standing still" (hand tremor, vibration).
pub fn noise<T: Scalar>(gyro_sigma: T, accel_sigma: T, velocity_sigma: T) -> SMatrix<T, DIM, DIM> {
    let mut r = SMatrix::<T, DIM, DIM>::zeros();
    for i in 0..3 {
        r[(i, i)] = gyro_sigma * gyro_sigma;
        r[(i + 3, i + 3)] = accel_sigma * accel_sigma;
        r[(i + 6, i + 6)] = velocity_sigma * velocity_sigma;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::propagate::boxplus;
    use crate::testing::{assert_mat_close, central_diff};
    use nalgebra::UnitQuaternion;

    #[test]
    fn jacobian_matches_central_differences() {
        let x = ImuState {
            rotation: UnitQuaternion::from_euler_angles(0.4, -0.3, 1.0),
            position: Vector3::new(1.0, 2.0, 3.0),
            velocity: Vector3::new(0.01, -0.02, 0.0),
            gyro_bias: Vector3::new(1e-3, 0.0, -1e-3),
            accel_bias: Vector3::new(0.01, 0.02, -0.03),
        };
        let sample = ImuSample {
            stamp_ns: 0,
            gyro: Vector3::new(1e-3, 2e-3, 0.0),
            accel: Vector3::new(0.1, -0.2, 9.8),
        };
        let (_, h) = linearize(&x, &sample);
        // r(x ⊞ d) = r(x) - H d
        let numeric = central_diff::<DIM, 15>(|d| -linearize(&boxplus(&x, &d), &sample).0);
        assert_mat_close(&h, &numeric, 1e-7);
    }
}
