//! Host benchmark of the filter's hot paths, f64 and f32 side by side, as a markdown table.
//!
//! `cargo run --release -p msreg-estimator --example bench`
//!
//! Each figure is the median over 15 batches of the mean time per call within a batch.

use std::hint::black_box;
use std::time::Instant;

use msreg_estimator::na::Vector3;
use msreg_estimator::{
    FilterConfig, ImuNoise, ImuSample, InitialState, Pose, PoseImuEkf, RelativePose, Scalar,
    SOLE_SENSOR,
};

const T0: u64 = 1_700_000_000_000_000_000;
const IMU_DT_NS: u64 = 2_500_000;

fn filter<T: Scalar>() -> PoseImuEkf<T> {
    let init = InitialState::<T, 1>::at_rest(Vector3::new(T::zero(), T::zero(), T::lit(9.81)))
        .expect("gravity")
        .with_extrinsic(SOLE_SENSOR, Pose::identity(), T::lit(0.05), T::lit(0.3))
        .with_time_offset(SOLE_SENSOR, T::zero(), T::zero());
    PoseImuEkf::new(&FilterConfig::new(ImuNoise::vn300()), &init).expect("prior")
}

fn sample<T: Scalar>(k: u64) -> ImuSample<T> {
    let s = T::lit((k as f64 * 0.01).sin());
    ImuSample {
        stamp_ns: T0 + k * IMU_DT_NS,
        gyro: Vector3::new(s, T::lit(0.3), -s),
        accel: Vector3::new(T::lit(0.1), s, T::lit(9.81)),
    }
}

/// Median over batches of ns per call.
fn measure(batches: usize, per_batch: usize, mut f: impl FnMut(usize)) -> f64 {
    let mut times: Vec<f64> = (0..batches)
        .map(|b| {
            let start = Instant::now();
            for i in 0..per_batch {
                f(b * per_batch + i);
            }
            start.elapsed().as_nanos() as f64 / per_batch as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

struct Row {
    propagate: f64,
    relative_update: f64,
    zero_velocity: f64,
}

fn run<T: Scalar>() -> Row {
    let propagate = {
        let mut ekf = filter::<T>();
        let mut k = 0u64;
        measure(15, 20_000, |_| {
            ekf.propagate(black_box(&sample::<T>(k)))
                .expect("propagate");
            k += 1;
        })
    };
    // Relative-pose update: 40 IMU samples apart (10 Hz), timing only the update call.
    let relative_update = {
        let mut ekf = filter::<T>();
        let mut k = 0u64;
        for _ in 0..=40 {
            ekf.propagate(&sample::<T>(k)).expect("propagate");
            k += 1;
        }
        ekf.anchor(SOLE_SENSOR, T0 + (k - 1) * IMU_DT_NS)
            .expect("anchor");
        let mut total = Vec::new();
        for _ in 0..15 {
            let mut ns = 0.0;
            for _ in 0..200 {
                for _ in 0..40 {
                    ekf.propagate(&sample::<T>(k)).expect("propagate");
                    k += 1;
                }
                let to = T0 + (k - 1) * IMU_DT_NS;
                let m = RelativePose::with_sigmas(
                    to - 40 * IMU_DT_NS,
                    to,
                    Pose::identity(),
                    T::lit(0.5),
                    T::lit(0.5),
                );
                let start = Instant::now();
                let r = ekf.update_relative_pose(SOLE_SENSOR, black_box(&m));
                ns += start.elapsed().as_nanos() as f64;
                if r.is_err() {
                    let _ = ekf.anchor(SOLE_SENSOR, to);
                }
            }
            total.push(ns / 200.0);
        }
        total.sort_by(f64::total_cmp);
        total[total.len() / 2]
    };
    let zero_velocity = {
        let mut ekf = filter::<T>();
        ekf.propagate(&sample::<T>(0)).expect("propagate");
        measure(15, 2_000, |_| {
            let _ = black_box(ekf.update_zero_velocity());
        })
    };
    Row {
        propagate,
        relative_update,
        zero_velocity,
    }
}

fn main() {
    let f64_row = run::<f64>();
    let f32_row = run::<f32>();
    println!("| operation (PoseImuEkf, 34 error states) | f64 [ns] | f32 [ns] |");
    println!("|---|---:|---:|");
    for (name, a, b) in [
        (
            "IMU propagation (one sample)",
            f64_row.propagate,
            f32_row.propagate,
        ),
        (
            "relative-pose update (clone + 6-dof update)",
            f64_row.relative_update,
            f32_row.relative_update,
        ),
        (
            "zero-velocity update (9-dof)",
            f64_row.zero_velocity,
            f32_row.zero_velocity,
        ),
    ] {
        println!("| {name} | {a:.0} | {b:.0} |");
    }
    let per_second = 400.0 * f64_row.propagate + 10.0 * f64_row.relative_update;
    println!(
        "\n400 Hz IMU + 10 Hz updates (f64): {:.2} ms of CPU per second of data ({:.3} % of one core)",
        per_second * 1e-6,
        per_second * 1e-7
    );
}
