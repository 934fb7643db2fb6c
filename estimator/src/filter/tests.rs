//! Filter-level tests: clone Jacobians, covariance health through updates.

use super::*;
use crate::lie::log;
use crate::lie::Pose;
use crate::propagate::{ImuNoise, ImuSample};
use crate::state::{InitialState, Layout};
use crate::testing::assert_mat_close;
use crate::RelativePose;
use nalgebra::{SMatrix, Vector3};
use nalgebra::{SVector, UnitQuaternion};

const T0: u64 = 1_700_000_000_000_000_000;

/// A filter spinning and accelerating with the given time-offset prior.
fn moving_filter(time_offset: f64) -> PoseImuEkf<f64> {
    let mut init = InitialState::<f64, 1>::at_rest(Vector3::new(0.0, 0.0, 9.81))
        .expect("gravity")
        .with_time_offset(0, time_offset, 0.01);
    init.imu.velocity = Vector3::new(0.7, -0.3, 0.2);
    init.imu.rotation = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.0);
    let mut ekf = PoseImuEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior");
    for k in 0..=96u64 {
        ekf.propagate(&ImuSample {
            stamp_ns: T0 + k * 2_500_000,
            gyro: Vector3::new(1.2, -0.8, 0.5),
            accel: Vector3::new(0.5, 1.0, 9.0),
        })
        .expect("sample");
    }
    ekf
}

#[test]
fn clone_time_offset_jacobian_matches_central_differences() {
    // Given a moving IMU and a measurement stamped between two IMU samples
    let stamp = T0 + 240_000_000 + 1_234_567;
    let td = 0.004;
    let h = 1e-4;
    // When the pose is cloned at stamp + t_d for t_d +- h
    let clone_pose = |td: f64| {
        let mut ekf = moving_filter(td);
        ekf.anchor(0, stamp).expect("anchor");
        ekf.imu().pose()
    };
    let (plus, minus) = (clone_pose(td + h), clone_pose(td - h));
    let mut numeric = SVector::<f64, 6>::zeros();
    numeric
        .fixed_rows_mut::<3>(0)
        .copy_from(&(log(&(minus.rotation.inverse() * plus.rotation)) / (2.0 * h)));
    numeric
        .fixed_rows_mut::<3>(3)
        .copy_from(&((plus.translation - minus.translation) / (2.0 * h)));
    // Then the clone's covariance with t_d is d(clone)/d(t_d) * var(t_d)
    let mut ekf = moving_filter(td);
    ekf.anchor(0, stamp).expect("anchor");
    let c = Layout::<1, 2>::clone_orientation(0).idx;
    let t = Layout::<1, 2>::time_offset(0).idx;
    let var = ekf.covariance()[(t, t)];
    let analytic = ekf.covariance().fixed_view::<6, 1>(c, t).clone_owned() / var;
    // The midpoint integrator's position is consistent with its velocity to O(|w| |a| dt^2)
    // (~1e-4 m/s here), which bounds the agreement.
    assert_mat_close(&analytic, &numeric, 2e-4);
}

#[test]
fn covariance_stays_symmetric_and_positive_through_updates() {
    let mut ekf = moving_filter(0.0);
    let t = ekf.time_ns();
    ekf.anchor(0, t).expect("anchor");
    for k in 1..=20u64 {
        let stamp = t + k * 100_000_000;
        for j in 1..=32u64 {
            ekf.propagate(&ImuSample {
                stamp_ns: stamp - 100_000_000 + j * 2_500_000,
                gyro: Vector3::new(1.2, -0.8, 0.5),
                accel: Vector3::new(0.5, 1.0, 9.0),
            })
            .expect("sample");
        }
        let m = RelativePose::with_sigmas(stamp - 100_000_000, stamp, Pose::identity(), 0.5, 0.5);
        ekf.update_relative_pose(0, &m).expect("update");
    }
    let p = ekf.covariance();
    assert_mat_close(
        &(p - p.transpose()),
        &SMatrix::<f64, 34, 34>::zeros(),
        1e-12,
    );
    let eig = p.symmetric_eigenvalues();
    assert!(
        eig.min() > -1e-12 * eig.max(),
        "negative eigenvalue {} (largest {})",
        eig.min(),
        eig.max()
    );
}
