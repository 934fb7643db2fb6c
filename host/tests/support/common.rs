//! Shared helpers of the host integration tests: simulate, calibrate, compare with truth.
#![allow(dead_code)]

use msreg_estimator::Scalar;
use msreg_host::calibrate::driver::report::{PoseImuCalibration, PoseImuOptions};
use msreg_host::calibrate::pose_imu::{self, PoseImuInput};
use msreg_host::sim::{self, SimConfig, SimDataset};
use nalgebra::{Isometry3, Vector6};

/// Simulates `config` (panics on an invalid config: test setup error).
pub fn simulate(config: &SimConfig) -> SimDataset {
    sim::simulate_pose_imu(config).expect("valid simulation config")
}

/// Calibrates a simulated dataset with the filter in `T`.
pub fn calibrate<T: Scalar>(data: &SimDataset, options: &PoseImuOptions) -> PoseImuCalibration {
    let input = PoseImuInput {
        imu: &data.imu,
        imu_noise: &data.imu_noise,
        poses: &data.pose,
        pose_noise: &data.pose_sensor,
    };
    pose_imu::calibrate::<T>(&input, options, &mut |_| {}).expect("calibration runs")
}

/// Error of the estimate in the filter's convention: `[Log(R_est^T R_true); p_true - p_est]`.
pub fn extrinsic_error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> Vector6<f64> {
    let r = (estimate.rotation.inverse() * truth.rotation).scaled_axis();
    let p = truth.translation.vector - estimate.translation.vector;
    Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z)
}

/// Normalised estimation error squared of the extrinsic.
pub fn nees(c: &PoseImuCalibration, truth: &Isometry3<f64>) -> f64 {
    let e = extrinsic_error(&c.t_imu_sensor, truth);
    let info = c
        .covariance
        .try_inverse()
        .expect("extrinsic covariance invertible");
    e.dot(&(info * e))
}

/// Every axis inside 3 sigma.
pub fn inside_three_sigma(c: &PoseImuCalibration, truth: &Isometry3<f64>) -> bool {
    let e = extrinsic_error(&c.t_imu_sensor, truth);
    (0..6).all(|i| e[i].abs() <= 3.0 * c.covariance[(i, i)].sqrt())
}

/// Rotation error angle, deg.
pub fn rotation_error_deg(c: &PoseImuCalibration, truth: &Isometry3<f64>) -> f64 {
    c.t_imu_sensor
        .rotation
        .angle_to(&truth.rotation)
        .to_degrees()
}

/// Translation error norm, m.
pub fn translation_error_m(c: &PoseImuCalibration, truth: &Isometry3<f64>) -> f64 {
    (c.t_imu_sensor.translation.vector - truth.translation.vector).norm()
}

/// Median of a slice.
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Runs `f` over `seeds` on two threads (the CI machine has two cores); results in seed order.
pub fn par_map<R: Send>(seeds: &[u64], f: impl Fn(u64) -> R + Sync) -> Vec<R> {
    let mut out: Vec<Option<R>> = seeds.iter().map(|_| None).collect();
    std::thread::scope(|scope| {
        let (even, odd): (Vec<_>, Vec<_>) = out
            .iter_mut()
            .zip(seeds)
            .enumerate()
            .partition(|(i, _)| i % 2 == 0);
        let f = &f;
        for half in [even, odd] {
            scope.spawn(move || {
                for (_, (slot, seed)) in half {
                    *slot = Some(f(*seed));
                }
            });
        }
    });
    out.into_iter()
        .map(|r| r.expect("every seed ran"))
        .collect()
}

/// Two-sided 95 % band of a chi-square with `k` DoF (Wilson-Hilferty).
pub fn chi_square_band(k: f64) -> (f64, f64) {
    let quantile = |z: f64| {
        let c = 2.0 / (9.0 * k);
        k * (1.0 - c + z * c.sqrt()).powi(3)
    };
    (quantile(-1.959_964), quantile(1.959_964))
}
