//! Propagation error over one second against the simulator's exact motion
//! (docs/estimator.md, "Propagation accuracy"):
//! `cargo run --release -p msreg-host --example propagation_error`.
//!
//! Noise-free instantaneous samples of the hand-held camera-IMU trajectory (seed 1000), from
//! the true state, a window every 2 s from 6 s to 56 s: the two-sample mean held over each
//! interval (the model before the quadratic signal) against the estimator's step over
//! `ImuSignal` (what `Ekf::propagate` runs).

use msreg_estimator::propagate::{step, ImuInterval, ImuNoise, ImuSample, ImuSignal};
use msreg_estimator::ImuState;
use msreg_host::sim::{simulate_camera_imu, CameraImuSimConfig, Trajectory};
use nalgebra::Vector3;

fn reading(trajectory: &Trajectory, stamp_ns: u64) -> ImuSample<f64> {
    let t = stamp_ns as f64 * 1e-9;
    ImuSample {
        stamp_ns,
        gyro: trajectory.body_rate(t),
        accel: trajectory.specific_force(t),
    }
}

fn true_state(trajectory: &Trajectory, stamp_ns: u64) -> ImuState<f64> {
    let t = stamp_ns as f64 * 1e-9;
    let (rotation, position) = trajectory.pose(t);
    ImuState {
        rotation,
        position,
        velocity: trajectory.velocity(t),
        gyro_bias: Vector3::zeros(),
        accel_bias: Vector3::zeros(),
    }
}

/// Rotation [rad] and position [m] error after one second from `t0_ns`.
fn window(trajectory: &Trajectory, t0_ns: u64, period_ns: u64, quadratic: bool) -> (f64, f64) {
    let noise = ImuNoise::vn300();
    let mut x = true_state(trajectory, t0_ns);
    let mut stamp = t0_ns;
    while stamp < t0_ns + 1_000_000_000 {
        let (a, b) = (
            reading(trajectory, stamp),
            reading(trajectory, stamp + period_ns),
        );
        let interval = if quadratic {
            let before = reading(trajectory, stamp - period_ns);
            ImuSignal::new(Some(&before), &a, &b).interval(a.stamp_ns, b.stamp_ns)
        } else {
            let mean = ImuInterval::linear((a.gyro, a.accel), (b.gyro, b.accel), 0.0);
            let dt = period_ns as f64 * 1e-9;
            ImuInterval::constant(mean.gyro_mean, mean.accel_mean, dt)
        };
        x = step(&x, &interval, &noise).state;
        stamp += period_ns;
    }
    let truth = true_state(trajectory, stamp);
    (
        (truth.rotation.inverse() * x.rotation).scaled_axis().norm(),
        (truth.position - x.position).norm(),
    )
}

fn main() {
    let sim = simulate_camera_imu(&CameraImuSimConfig {
        seed: 1000,
        duration_s: 60.0,
        ..CameraImuSimConfig::default()
    })
    .expect("valid simulation");
    println!("| IMU rate | model | rotation error, RMS [rad] | position error, worst [m] |");
    println!("|---|---|---:|---:|");
    for rate_hz in [200u64, 400, 1000] {
        let period_ns = 1_000_000_000 / rate_hz;
        for (quadratic, name) in [
            (false, "two-sample mean"),
            (true, "quadratic + coning / sculling"),
        ] {
            let errors: Vec<(f64, f64)> = (3..29u64)
                .map(|k| window(&sim.trajectory, k * 2_000_000_000, period_ns, quadratic))
                .collect();
            let rms = (errors.iter().map(|e| e.0 * e.0).sum::<f64>() / errors.len() as f64).sqrt();
            let worst = errors.iter().map(|e| e.1).fold(0.0, f64::max);
            println!("| {rate_hz} Hz | {name} | {rms:.2e} | {worst:.2e} |");
        }
    }
}
