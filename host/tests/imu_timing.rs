//! Time offsets with instantaneous IMU samples (issue 11): the simulator writes each IMU
//! sample as the truth at its stamp (checked against an independent RK4 integrator in
//! `sim::tests`), as EuRoC / Kalibr / OpenVINS data are. The pose-IMU, LiDAR-IMU and
//! camera-IMU pipelines must then find the time offset without the half-period bias a
//! held-sample propagation gives (1.25 ms at 400 Hz, 2.5 ms at 200 Hz), at 400 and 200 Hz,
//! with offsets drawn in +-20 ms.
//!
//! CI runs one seed per pipeline and rate on short recordings; the acceptance run (10 seeds,
//! 60 s) is `cargo test --release -p msreg --test imu_timing -- --ignored --nocapture`.

#[path = "support/common.rs"]
mod common;
#[path = "support/corners.rs"]
mod corners;

use common::{chi_square_band, par_map};
use msreg_host::calibrate::camera_imu::{self, CameraImuInput, CameraImuOptions};
use msreg_host::calibrate::extrinsic::ImuExtrinsicCalibration;
use msreg_host::calibrate::lidar_imu::{self, LidarImuInput, LidarImuOptions};
use msreg_host::calibrate::pose_imu::PoseImuOptions;
use msreg_host::dataset::ImuRecord;
use msreg_host::sim::{
    simulate_camera_imu, simulate_lidar_imu, CameraImuSimConfig, LidarImuSimConfig, LidarSimConfig,
    SimConfig,
};
use nalgebra::{Isometry3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Acceptance bound on the time-offset error (issue 11), s.
const MAX_TIME_OFFSET_ERROR_S: f64 = 0.2e-3;

/// The calibration pipeline under test (each is pose/LiDAR/camera to IMU).
#[derive(Clone, Copy, Debug, PartialEq)]
#[allow(clippy::enum_variant_names)]
enum Pipeline {
    PoseImu,
    LidarImu,
    CameraImu,
}

/// One calibration judged against the truth.
#[derive(Debug)]
struct Outcome {
    pipeline: Pipeline,
    rate_hz: f64,
    seed: u64,
    true_offset_ms: f64,
    offset_error_ms: f64,
    offset_sigma_ms: f64,
    rotation_deg: f64,
    translation_mm: f64,
    nees: f64,
    inside_three_sigma: bool,
    converged: bool,
}

/// The true offset of a seed: uniform in +-20 ms, from its own stream.
fn drawn_offset_s(seed: u64) -> f64 {
    ChaCha8Rng::seed_from_u64(seed ^ 0x7d_0ff5e7).gen_range(-0.020..0.020)
}

fn judge<R>(
    (pipeline, rate_hz, seed): (Pipeline, f64, u64),
    c: &ImuExtrinsicCalibration<R>,
    truth: &Isometry3<f64>,
    true_offset_s: f64,
    converged: bool,
) -> Outcome {
    let r = (c.t_imu_sensor.rotation.inverse() * truth.rotation).scaled_axis();
    let p = truth.translation.vector - c.t_imu_sensor.translation.vector;
    let e = Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z);
    let nees = c
        .covariance
        .try_inverse()
        .map_or(f64::NAN, |info| e.dot(&(info * e)));
    let offset_error = c.time_offset_s - true_offset_s;
    Outcome {
        pipeline,
        rate_hz,
        seed,
        true_offset_ms: true_offset_s * 1e3,
        offset_error_ms: offset_error * 1e3,
        offset_sigma_ms: c.time_offset_sigma_s * 1e3,
        rotation_deg: r.norm().to_degrees(),
        translation_mm: p.norm() * 1e3,
        nees,
        inside_three_sigma: (0..6).all(|i| e[i].abs() <= 3.0 * c.covariance[(i, i)].sqrt())
            && offset_error.abs() <= 3.0 * c.time_offset_sigma_s,
        converged,
    }
}

/// Where a moving start cuts a recording: the IMU sample of the fastest rotation within its
/// first 20 s (after the first second), so the filter starts at peak motion with no
/// standstill to initialise from.
fn peak_motion_ns(imu: &[ImuRecord]) -> u64 {
    let t0 = imu[0].stamp_ns;
    imu.iter()
        .filter(|r| (1_000_000_000..20_000_000_000).contains(&(r.stamp_ns - t0)))
        .max_by(|a, b| a.gyro.norm().total_cmp(&b.gyro.norm()))
        .map_or(t0, |r| r.stamp_ns)
}

/// How a recording starts.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Start {
    /// As simulated: at rest.
    AtRest,
    /// Cut at [`peak_motion_ns`].
    PeakMotion,
}

fn pose_imu(seed: u64, rate_hz: f64, duration_s: f64, start: Start) -> Outcome {
    let mut config = SimConfig {
        seed,
        duration_s,
        ..SimConfig::default()
    };
    config.imu.rate_hz = rate_hz;
    config.pose.time_offset_s = drawn_offset_s(seed);
    let mut data = common::simulate(&config);
    if start == Start::PeakMotion {
        let cut = peak_motion_ns(&data.imu);
        data.imu.retain(|r| r.stamp_ns >= cut);
        data.pose.retain(|p| p.stamp_ns >= cut);
    }
    let c = common::calibrate::<f64>(&data, &PoseImuOptions::default());
    let converged = c.report.converged;
    let id = (Pipeline::PoseImu, rate_hz, seed);
    judge(id, &c, &data.t_imu_pose, data.time_offset_s, converged)
}

fn lidar_imu(seed: u64, rate_hz: f64, duration_s: f64) -> Outcome {
    let mut config = LidarImuSimConfig {
        seed,
        duration_s,
        lidar: LidarSimConfig {
            rings: 32,
            columns: 512,
            time_offset_s: drawn_offset_s(seed),
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    };
    config.imu.rate_hz = rate_hz;
    let sim = simulate_lidar_imu(&config).expect("valid simulation");
    let input = LidarImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        scans: &sim,
    };
    let c = lidar_imu::calibrate::<f64>(&input, &LidarImuOptions::default(), &mut |_| {})
        .expect("calibration runs");
    let converged = c.report.filter.converged;
    let id = (Pipeline::LidarImu, rate_hz, seed);
    let td = sim.config.lidar.time_offset_s;
    judge(id, &c, &sim.t_imu_lidar, td, converged)
}

fn camera_imu(seed: u64, rate_hz: f64, duration_s: f64, start: Start) -> Outcome {
    let mut config = CameraImuSimConfig {
        seed,
        duration_s,
        time_offset_s: drawn_offset_s(seed),
        ..CameraImuSimConfig::default()
    };
    config.imu.rate_hz = rate_hz;
    let sim = simulate_camera_imu(&config).expect("valid simulation config");
    let mut frames = corners::noisy_corner_frames(&sim, 0.1, seed);
    let mut imu = sim.imu.clone();
    if start == Start::PeakMotion {
        let cut = peak_motion_ns(&imu);
        imu.retain(|r| r.stamp_ns >= cut);
        frames.retain(|f| f.stamp_ns >= cut);
    }
    let input = CameraImuInput {
        imu: &imu,
        imu_noise: &sim.imu_noise,
        camera: &sim.config.camera,
        frames: &frames,
    };
    let c = camera_imu::calibrate::<f64>(&input, &CameraImuOptions::default(), &mut |_| {})
        .expect("calibration runs");
    let converged = c.report.filter.converged;
    let truth = sim.t_cam_imu.inverse();
    let id = (Pipeline::CameraImu, rate_hz, seed);
    judge(id, &c, &truth, sim.config.time_offset_s, converged)
}

fn run(pipeline: Pipeline, rate_hz: f64, seeds: &[u64], duration_s: f64) -> Vec<Outcome> {
    run_from(pipeline, rate_hz, seeds, duration_s, Start::AtRest)
}

fn run_from(
    pipeline: Pipeline,
    rate_hz: f64,
    seeds: &[u64],
    duration_s: f64,
    start: Start,
) -> Vec<Outcome> {
    par_map(seeds, |seed| match pipeline {
        Pipeline::PoseImu => pose_imu(seed, rate_hz, duration_s, start),
        Pipeline::LidarImu => lidar_imu(seed, rate_hz, duration_s),
        Pipeline::CameraImu => camera_imu(seed, rate_hz, duration_s, start),
    })
}

fn print(o: &Outcome) {
    println!(
        "{:?} {:>3} Hz seed {:3}: t_d {:+7.3} ms, error {:+.4} ms (sigma {:.4} ms), rotation \
         {:.4} deg, translation {:.2} mm, NEES {:.2}, inside 3 sigma {}, converged {}",
        o.pipeline,
        o.rate_hz,
        o.seed,
        o.true_offset_ms,
        o.offset_error_ms,
        o.offset_sigma_ms,
        o.rotation_deg,
        o.translation_mm,
        o.nees,
        o.inside_three_sigma,
        o.converged
    );
}

/// Every outcome converged, and its time-offset error within the bound, or within 3 sigma where the recording's information does not
/// allow the bound (the pose-IMU odometry's drift gives sigmas of 0.13-0.23 ms on its own;
/// a bound below the information limit is reported, not asserted, and the bias is then
/// judged by the z-scores over seeds, `assert_time_offset_consistent`).
fn assert_unbiased(outcomes: &[Outcome]) {
    for o in outcomes {
        print(o);
    }
    for o in outcomes {
        assert!(o.converged, "{o:?}");
        let bound_ms = (MAX_TIME_OFFSET_ERROR_S * 1e3).max(3.0 * o.offset_sigma_ms);
        assert!(
            o.offset_error_ms.abs() < bound_ms,
            "time offset error {:.4} ms: {o:?}",
            o.offset_error_ms
        );
    }
}

/// Sum over seeds of the squared time-offset z-scores inside the two-sided 95 % band of a
/// chi-square with one DoF per seed, and the mean error (the bias a held-sample propagation
/// gives, dt / 2, is 6-20 sigma here) below the bound.
fn assert_time_offset_consistent(outcomes: &[Outcome]) {
    let z2: f64 = outcomes
        .iter()
        .map(|o| (o.offset_error_ms / o.offset_sigma_ms).powi(2))
        .sum();
    let mean = outcomes.iter().map(|o| o.offset_error_ms).sum::<f64>() / outcomes.len() as f64;
    let (lo, hi) = chi_square_band(outcomes.len() as f64);
    println!("  time offset: mean error {mean:+.4} ms, sum of z^2 {z2:.1} (band {lo:.1}-{hi:.1})");
    assert!(
        z2 <= hi,
        "time-offset errors beyond their sigmas: sum z^2 {z2}"
    );
    assert!(
        mean.abs() < MAX_TIME_OFFSET_ERROR_S * 1e3,
        "time-offset bias {mean} ms"
    );
}

#[test]
fn pose_imu_time_offset_is_unbiased_at_400_and_200_hz() {
    for rate in [400.0, 200.0] {
        let outcomes = run(Pipeline::PoseImu, rate, &[1, 2], 30.0);
        assert_unbiased(&outcomes);
        assert!(outcomes.iter().all(|o| o.inside_three_sigma));
    }
}

#[test]
fn lidar_imu_time_offset_is_unbiased_at_400_and_200_hz() {
    for rate in [400.0, 200.0] {
        let outcomes = run(Pipeline::LidarImu, rate, &[3], 20.0);
        assert_unbiased(&outcomes);
        assert!(outcomes.iter().all(|o| o.inside_three_sigma));
    }
}

#[test]
fn camera_imu_time_offset_is_unbiased_at_400_and_200_hz() {
    for rate in [400.0, 200.0] {
        let outcomes = run(Pipeline::CameraImu, rate, &[4], 20.0);
        assert_unbiased(&outcomes);
        assert!(outcomes.iter().all(|o| o.inside_three_sigma));
    }
}

/// The acceptance run: 10 seeds per pipeline and rate, 60 s recordings; NEES summed over
/// each cell inside its two-sided 95 % chi-square band (6 DoF per seed), the time-offset
/// z-scores likewise, and the share of seeds inside 3 sigma reported.
#[test]
#[ignore = "acceptance run, ~10 min on 2 cores"]
fn ten_seeds_per_pipeline_and_rate() {
    let seeds: Vec<u64> = (1000..1010).collect();
    for pipeline in [Pipeline::PoseImu, Pipeline::LidarImu, Pipeline::CameraImu] {
        for rate in [400.0, 200.0] {
            let outcomes = run(pipeline, rate, &seeds, 60.0);
            assert_unbiased(&outcomes);
            assert_time_offset_consistent(&outcomes);
            let nees: f64 = outcomes.iter().map(|o| o.nees).sum();
            let worst = outcomes
                .iter()
                .map(|o| o.offset_error_ms.abs())
                .fold(0.0, f64::max);
            let inside = outcomes.iter().filter(|o| o.inside_three_sigma).count();
            println!(
                "  inside 3 sigma on every axis: {inside}/{}",
                outcomes.len()
            );
            let within = outcomes
                .iter()
                .filter(|o| o.offset_error_ms.abs() < MAX_TIME_OFFSET_ERROR_S * 1e3)
                .count();
            println!(
                "{pipeline:?} {rate} Hz: worst time offset error {worst:.4} ms ({within}/{} under \
                 0.2 ms), NEES sum {nees:.1} (band for {} DoF: {:?})",
                outcomes.len(),
                6 * outcomes.len(),
                chi_square_band(6.0 * outcomes.len() as f64)
            );
            let (lo, hi) = chi_square_band(6.0 * outcomes.len() as f64);
            assert!(
                (lo..=hi).contains(&nees),
                "{pipeline:?} {rate} Hz: NEES sum {nees}"
            );
        }
    }
}

/// Moving starts (issue 11): the pose-IMU and camera-IMU runs cut to start at peak motion
/// (no standstill: dynamic initialisation) meet the same bounds. One seed per pipeline and
/// rate here; `ten_seeds_moving_start` is the acceptance run.
#[test]
fn moving_start_at_peak_motion_is_unbiased() {
    for pipeline in [Pipeline::PoseImu, Pipeline::CameraImu] {
        let outcomes = run_from(pipeline, 400.0, &[5], 30.0, Start::PeakMotion);
        assert_unbiased(&outcomes);
        assert!(
            outcomes.iter().all(|o| o.inside_three_sigma),
            "{outcomes:?}"
        );
    }
}

/// The moving-start acceptance run: 10 seeds per pipeline (pose-IMU, camera-IMU) and rate,
/// 60 s cut at peak motion; the same checks as [`ten_seeds_per_pipeline_and_rate`]. The
/// LiDAR-IMU scans are not cut here (its scan source is the simulator itself).
#[test]
#[ignore = "acceptance run, ~6 min on 2 cores"]
fn ten_seeds_moving_start() {
    let seeds: Vec<u64> = (2000..2010).collect();
    for pipeline in [Pipeline::PoseImu, Pipeline::CameraImu] {
        for rate in [400.0, 200.0] {
            let outcomes = run_from(pipeline, rate, &seeds, 60.0, Start::PeakMotion);
            assert_unbiased(&outcomes);
            assert_time_offset_consistent(&outcomes);
            let nees: f64 = outcomes.iter().map(|o| o.nees).sum();
            let (lo, hi) = chi_square_band(6.0 * outcomes.len() as f64);
            let inside = outcomes.iter().filter(|o| o.inside_three_sigma).count();
            println!(
                "{pipeline:?} {rate} Hz moving start: NEES sum {nees:.1} (band {lo:.1}-{hi:.1}), \
                 inside 3 sigma {inside}/{}",
                outcomes.len()
            );
            assert!(
                (lo..=hi).contains(&nees),
                "{pipeline:?} {rate} Hz: NEES sum {nees}"
            );
        }
    }
}
