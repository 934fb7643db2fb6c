//! Time offsets with instantaneous IMU samples (issue 11): the simulator writes each IMU
//! sample as the truth at its stamp (checked against an independent RK4 integrator in
//! `sim::tests`), as EuRoC / Kalibr / OpenVINS data are. The pose-IMU, LiDAR-IMU and
//! camera-IMU pipelines must then find the time offset without the half-period bias a
//! held-sample propagation gives (1.25 ms at 400 Hz, 2.5 ms at 200 Hz), at 400 and 200 Hz,
//! with offsets drawn in +-20 ms.
//!
//! CI runs one seed per pipeline and rate on short recordings; the acceptance run (10 seeds,
//! 60 s) is `cargo test --release -p msreg-host --test imu_timing -- --ignored --nocapture`.

#[path = "support/common.rs"]
mod common;
#[path = "support/corners.rs"]
mod corners;

use common::{chi_square_band, par_map};
use msreg_host::calibrate::camera_imu::{self, CameraImuInput, CameraImuOptions};
use msreg_host::calibrate::driver::report::PoseImuOptions;
use msreg_host::calibrate::extrinsic::ImuExtrinsicCalibration;
use msreg_host::calibrate::lidar_imu::{self, LidarImuInput, LidarImuOptions};
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
    /// The simulator's default odometry: 0.2 deg / 5 mm per 10 Hz increment.
    PoseImu,
    /// A precise odometry (a hand-held LiDAR odometry): 0.05 deg / 1 mm per 10 Hz increment.
    PoseImuPrecise,
    LidarImu,
    CameraImu,
}

impl Pipeline {
    /// Whether the 0.2 ms bound is asserted on every seed. Not for the pose-IMU runs on the
    /// default odometry, whose own information gives `t_d` sigmas of 0.13-0.29 ms: there a
    /// seed must be within the bound or 3 sigma, and the bias is judged over the seeds. (The
    /// LiDAR-IMU and camera-IMU cells, with sigmas of 0.01-0.05 ms, were always under it.)
    fn strict(self) -> bool {
        self != Pipeline::PoseImu
    }
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
    /// Camera-IMU: the NEES with the result file's (model-error) covariance.
    written_nees: Option<f64>,
    inside_three_sigma: bool,
    converged: bool,
    /// Health-monitor events (alarms) raised during the run.
    alarms: usize,
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
    (converged, alarms): (bool, usize),
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
        written_nees: None,
        inside_three_sigma: (0..6).all(|i| e[i].abs() <= 3.0 * c.covariance[(i, i)].sqrt())
            && offset_error.abs() <= 3.0 * c.time_offset_sigma_s,
        converged,
        alarms,
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

fn pose_imu(seed: u64, rate_hz: f64, duration_s: f64, start: Start, precise: bool) -> Outcome {
    let mut config = SimConfig {
        seed,
        duration_s,
        ..SimConfig::default()
    };
    if precise {
        config.pose.rotation_noise_rad = 0.05_f64.to_radians();
        config.pose.translation_noise_m = 0.001;
    }
    config.imu.rate_hz = rate_hz;
    config.pose.time_offset_s = drawn_offset_s(seed);
    let mut data = common::simulate(&config);
    if start == Start::PeakMotion {
        let cut = peak_motion_ns(&data.imu);
        data.imu.retain(|r| r.stamp_ns >= cut);
        data.pose.retain(|p| p.stamp_ns >= cut);
    }
    let c = common::calibrate::<f64>(&data, &PoseImuOptions::default());
    let status = (c.report.converged, c.report.events.len());
    let pipeline = if precise {
        Pipeline::PoseImuPrecise
    } else {
        Pipeline::PoseImu
    };
    judge(
        (pipeline, rate_hz, seed),
        &c,
        &data.t_imu_pose,
        data.time_offset_s,
        status,
    )
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
    let status = (c.report.filter.converged, c.report.filter.events.len());
    let id = (Pipeline::LidarImu, rate_hz, seed);
    let td = sim.config.lidar.time_offset_s;
    judge(id, &c, &sim.t_imu_lidar, td, status)
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
    let status = (c.report.filter.converged, c.report.filter.events.len());
    let truth = sim.t_cam_imu.inverse();
    let id = (Pipeline::CameraImu, rate_hz, seed);
    let (written, _) = c.written_covariance();
    let written_nees = judge(
        id,
        &ImuExtrinsicCalibration {
            covariance: written,
            ..c.clone()
        },
        &truth,
        sim.config.time_offset_s,
        status,
    )
    .nees;
    Outcome {
        written_nees: Some(written_nees),
        ..judge(id, &c, &truth, sim.config.time_offset_s, status)
    }
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
        Pipeline::PoseImu => pose_imu(seed, rate_hz, duration_s, start, false),
        Pipeline::PoseImuPrecise => pose_imu(seed, rate_hz, duration_s, start, true),
        Pipeline::LidarImu => lidar_imu(seed, rate_hz, duration_s),
        Pipeline::CameraImu => camera_imu(seed, rate_hz, duration_s, start),
    })
}

fn print(o: &Outcome) {
    println!(
        "{:?} {:>3} Hz seed {:3}: t_d {:+7.3} ms, error {:+.4} ms (sigma {:.4} ms), rotation \
         {:.4} deg, translation {:.2} mm, NEES {:.2}, inside 3 sigma {}, converged {} (exit \
         {}), alarms {}",
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
        o.converged,
        u8::from(!o.converged),
        o.alarms
    );
}

/// Every outcome converged, and its time-offset error within the bound, or within 3 sigma where the recording's information does not
/// allow the bound (the pose-IMU odometry's drift gives sigmas of 0.13-0.23 ms on its own;
/// a bound below the information limit is reported, not asserted, and the bias is then
/// judged by the z-scores over seeds, [`check_cell`]).
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

/// Seed 1009 at 200 Hz with the precise odometry: while the pipeline fused the increments of
/// its standstill, the time offset wandered from -3 to +59 ms across its prior (truth
/// -7.4 ms), the first moving increment pulled it to a 6-sigma-wrong value, the gate refused
/// 33 increments and the monitor raised a `rotation_step` alarm at 6 s. Increments surely at
/// rest now only anchor the odometry (docs/initialisation.md).
#[test]
fn a_standstill_does_not_move_the_time_offset() {
    let o = pose_imu(1009, 200.0, 60.0, Start::AtRest, true);
    print(&o);
    assert!(o.converged && o.alarms == 0, "{o:?}");
    assert!(
        o.offset_error_ms.abs() < MAX_TIME_OFFSET_ERROR_S * 1e3,
        "{o:?}"
    );
    assert!(o.inside_three_sigma, "{o:?}");
}

/// Moving starts (issue 11): the pose-IMU and camera-IMU runs cut to start at peak motion
/// (no standstill: dynamic initialisation) meet the same bounds, with no health alarm. One
/// seed per pipeline here, plus camera-IMU seed 2000, which diverged (first image NIS 1.4e6,
/// rotation 12 deg off) while RepErrCal's time-offset prior was floored at 5 ms; the
/// `ten_seeds_moving_start_*` tests are the acceptance runs.
#[test]
fn moving_start_at_peak_motion_is_unbiased() {
    for (pipeline, seeds) in [
        (Pipeline::PoseImu, &[5][..]),
        (Pipeline::CameraImu, &[5, 2000][..]),
    ] {
        let outcomes = run_from(pipeline, 400.0, seeds, 30.0, Start::PeakMotion);
        assert_unbiased(&outcomes);
        assert!(
            outcomes
                .iter()
                .all(|o| o.inside_three_sigma && o.alarms == 0),
            "{outcomes:?}"
        );
    }
}

/// The checks of one acceptance cell (one pipeline, rate and start over 10 seeds), as
/// messages of what failed (empty: it passed), after printing every seed and the summary:
/// every seed converged (exit 0) with no health alarm, its time-offset error within the
/// bound (or 3 sigma where the bound is not [`Pipeline::strict`]); the sum over seeds of the squared
/// time-offset z-scores inside the two-sided 95 % band of a chi-square with one DoF per seed,
/// and their mean error (the bias a held-sample propagation gives, dt / 2, is 6-20 sigma
/// here) below the bound; NEES summed over the cell inside its two-sided 95 %
/// chi-square band (6 DoF per seed). The share inside 3 sigma and the worst errors are
/// reported.
fn check_cell(label: &str, outcomes: &[Outcome]) -> Vec<String> {
    for o in outcomes {
        print(o);
    }
    let mut failures = Vec::new();
    for o in outcomes {
        let bound_ms = if o.pipeline.strict() {
            MAX_TIME_OFFSET_ERROR_S * 1e3
        } else {
            (MAX_TIME_OFFSET_ERROR_S * 1e3).max(3.0 * o.offset_sigma_ms)
        };
        if !o.converged || o.alarms > 0 || o.offset_error_ms.abs() >= bound_ms {
            failures.push(format!("{label}: seed {}: {o:?}", o.seed));
        }
    }
    let n = outcomes.len() as f64;
    let z2: f64 = outcomes
        .iter()
        .map(|o| (o.offset_error_ms / o.offset_sigma_ms).powi(2))
        .sum();
    let mean = outcomes.iter().map(|o| o.offset_error_ms).sum::<f64>() / n;
    let (_, z2_hi) = chi_square_band(n);
    if z2 > z2_hi || mean.abs() >= MAX_TIME_OFFSET_ERROR_S * 1e3 {
        failures.push(format!(
            "{label}: time offset mean {mean:+.4} ms, sum z^2 {z2:.1} (at most {z2_hi:.1})"
        ));
    }
    let nees: f64 = outcomes.iter().map(|o| o.nees).sum();
    let (lo, hi) = chi_square_band(6.0 * n);
    if !(lo..=hi).contains(&nees) {
        failures.push(format!(
            "{label}: NEES sum {nees:.1} outside {lo:.1}-{hi:.1}"
        ));
    }
    // The result file's covariance (camera-IMU: the filter's with the model error of the
    // time blocks, never smaller) must not be optimistic; conservative is allowed.
    if outcomes.iter().all(|o| o.written_nees.is_some()) {
        let written: f64 = outcomes.iter().filter_map(|o| o.written_nees).sum();
        println!(
            "{label}: NEES sum with the written covariance {written:.1} (filter's {nees:.1}, at \
             most {hi:.1})"
        );
        if written > hi || written > nees * (1.0 + 1e-9) {
            failures.push(format!("{label}: written NEES sum {written:.1}"));
        }
    }
    let worst = |f: fn(&Outcome) -> f64| outcomes.iter().map(f).fold(0.0, f64::max);
    let count = |f: fn(&Outcome) -> bool| outcomes.iter().filter(|o| f(o)).count();
    println!(
        "{label}: worst time offset error {:.4} ms ({}/{} under 0.2 ms; mean {mean:+.4} ms, sum \
         z^2 {z2:.1}, at most {z2_hi:.1}), NEES sum {nees:.1} (band {lo:.1}-{hi:.1}), inside \
         3 sigma {}/{}, worst rotation {:.4} deg, worst translation {:.2} mm, exit 0 on {}/{}, \
         alarms {}",
        worst(|o| o.offset_error_ms.abs()),
        count(|o| o.offset_error_ms.abs() < MAX_TIME_OFFSET_ERROR_S * 1e3),
        outcomes.len(),
        count(|o| o.inside_three_sigma),
        outcomes.len(),
        worst(|o| o.rotation_deg),
        worst(|o| o.translation_mm),
        count(|o| o.converged),
        outcomes.len(),
        outcomes.iter().map(|o| o.alarms).sum::<usize>(),
    );
    failures
}

/// One pipeline's acceptance cells at 400 and 200 Hz, 10 seeds each, 60 s; both rates run
/// and print before anything is asserted. `MSREG_RATES=200` (comma-separated, Hz) runs only
/// the named rates, for studies of one cell.
fn acceptance(pipeline: Pipeline, seeds: std::ops::Range<u64>, start: Start) {
    let seeds: Vec<u64> = seeds.collect();
    let mut failures = Vec::new();
    let rates: Vec<f64> = std::env::var("MSREG_RATES").map_or(vec![400.0, 200.0], |v| {
        v.split(',')
            .map(|r| {
                r.parse()
                    .unwrap_or_else(|e| panic!("MSREG_RATES: {r:?}: {e}"))
            })
            .collect()
    });
    for rate in rates {
        let outcomes = run_from(pipeline, rate, &seeds, 60.0, start);
        failures.extend(check_cell(
            &format!("{pipeline:?} {rate} Hz {start:?}"),
            &outcomes,
        ));
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The acceptance run, one test per pipeline so that one failing pipeline hides no other:
/// `cargo test --release -p msreg-host --test imu_timing -- --ignored --nocapture ten_seeds`.
#[test]
#[ignore = "acceptance run, ~15 s on 2 cores"]
fn ten_seeds_pose_imu() {
    acceptance(Pipeline::PoseImu, 1000..1010, Start::AtRest);
}

/// Pose-IMU with a precise odometry, at rest and from a moving start: with the information
/// there (`t_d` sigma well under 0.2 / 3 ms), the 0.2 ms bound holds on every seed.
#[test]
#[ignore = "acceptance run, ~5 s on 2 cores"]
fn ten_seeds_pose_imu_precise_odometry() {
    acceptance(Pipeline::PoseImuPrecise, 1000..1010, Start::AtRest);
    acceptance(Pipeline::PoseImuPrecise, 2000..2010, Start::PeakMotion);
}

#[test]
#[ignore = "acceptance run, ~7 min on 2 cores"]
fn ten_seeds_lidar_imu() {
    acceptance(Pipeline::LidarImu, 1000..1010, Start::AtRest);
}

#[test]
#[ignore = "acceptance run, ~40 s on 2 cores"]
fn ten_seeds_camera_imu() {
    acceptance(Pipeline::CameraImu, 1000..1010, Start::AtRest);
}

/// The moving-start acceptance runs: 10 seeds per pipeline (pose-IMU, camera-IMU) and rate,
/// 60 s cut at peak motion; the same checks. The LiDAR-IMU scans are not cut here (its scan
/// source is the simulator itself).
#[test]
#[ignore = "acceptance run, ~10 s on 2 cores"]
fn ten_seeds_moving_start_pose_imu() {
    acceptance(Pipeline::PoseImu, 2000..2010, Start::PeakMotion);
}

#[test]
#[ignore = "acceptance run, ~70 s on 2 cores"]
fn ten_seeds_moving_start_camera_imu() {
    acceptance(Pipeline::CameraImu, 2000..2010, Start::PeakMotion);
}
