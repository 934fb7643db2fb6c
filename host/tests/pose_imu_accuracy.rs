//! Accuracy and consistency of the pose-IMU calibration over Monte Carlo seeds of the
//! simulator at realistic noise: VN-300-class IMU at 400 Hz, odometry at 10 Hz drifting
//! 0.2 deg / 5 mm per increment, 60 s hand-held excitation, random mounting (roll near
//! 180 deg) and a random time offset of up to +-20 ms, estimated.

#[path = "support/common.rs"]
mod common;

use common::*;
use msreg_host::calibrate::driver::report::PoseImuOptions;
use msreg_host::sim::SimConfig;

const SEEDS: std::ops::Range<u64> = 100..120;

struct SeedResult {
    seed: u64,
    rot_deg: f64,
    trans_m: f64,
    time_err_s: f64,
    nees: f64,
    inside: bool,
    hand_eye_deg: f64,
    nis_per_dof: f64,
}

fn run(seed: u64) -> SeedResult {
    let mut config = SimConfig {
        seed,
        ..SimConfig::default()
    };
    // Deterministic per seed, spread over +-20 ms.
    config.pose.time_offset_s = ((seed * 7919) % 41) as f64 * 1e-3 - 0.020;
    let data = simulate(&config);
    let c = calibrate::<f64>(&data, &PoseImuOptions::default());
    assert!(c.report.converged, "seed {seed}: {:?}", c.report.reasons);
    SeedResult {
        seed,
        rot_deg: rotation_error_deg(&c, &data.t_imu_pose),
        trans_m: translation_error_m(&c, &data.t_imu_pose),
        time_err_s: c.time_offset_s - data.time_offset_s,
        nees: nees(&c, &data.t_imu_pose),
        inside: inside_three_sigma(&c, &data.t_imu_pose),
        hand_eye_deg: nalgebra::UnitQuaternion::from_scaled_axis(nalgebra::Vector3::from(
            c.report.hand_eye_rotation_vector,
        ))
        .angle_to(&data.t_imu_pose.rotation)
        .to_degrees(),
        nis_per_dof: c.report.mean_nis_per_dof,
    }
}

#[test]
fn twenty_seeds_are_accurate_and_consistent() {
    let seeds: Vec<u64> = SEEDS.collect();
    let results = par_map(&seeds, run);
    for r in &results {
        println!(
            "seed {:3}: rot {:.4} deg  trans {:.2} mm  time {:+.3} ms  NEES {:.2}  inside 3 sigma: {}  \
             (hand-eye init {:.4} deg, NIS/dof {:.3})",
            r.seed,
            r.rot_deg,
            r.trans_m * 1e3,
            r.time_err_s * 1e3,
            r.nees,
            r.inside,
            r.hand_eye_deg,
            r.nis_per_dof
        );
    }
    let rot: Vec<f64> = results.iter().map(|r| r.rot_deg).collect();
    let trans: Vec<f64> = results.iter().map(|r| r.trans_m).collect();
    let mean_nees = results.iter().map(|r| r.nees).sum::<f64>() / results.len() as f64;
    let inside = results.iter().filter(|r| r.inside).count();
    let hand_eye: Vec<f64> = results.iter().map(|r| r.hand_eye_deg).collect();
    let mean_nis = results.iter().map(|r| r.nis_per_dof).sum::<f64>() / results.len() as f64;
    println!(
        "median rot {:.4} deg (hand-eye rotation-only init: {:.4} deg), median trans {:.2} mm, \
         mean NEES {:.2}, mean NIS/dof {:.3}, inside 3 sigma {}/{}",
        median(&rot),
        median(&hand_eye),
        median(&trans) * 1e3,
        mean_nees,
        mean_nis,
        inside,
        results.len()
    );
    // Innovation consistency: ~12,000 six-dof updates make the mean NIS per dof exact to
    // about 0.5 %; 5 % either way means a mis-modelled noise.
    assert!(
        (0.95..=1.05).contains(&mean_nis),
        "mean NIS per dof {mean_nis:.3}"
    );

    // Accuracy (foundation issue): medians and every seed.
    assert!(
        median(&rot) < 0.1,
        "median rotation error {:.4} deg",
        median(&rot)
    );
    assert!(
        median(&trans) < 0.003,
        "median translation error {:.2} mm",
        median(&trans) * 1e3
    );
    for r in &results {
        assert!(
            r.rot_deg < 0.25,
            "seed {}: rotation error {:.4} deg",
            r.seed,
            r.rot_deg
        );
        assert!(
            r.trans_m < 0.006,
            "seed {}: translation error {:.2} mm",
            r.seed,
            r.trans_m * 1e3
        );
        assert!(
            r.time_err_s.abs() < 1e-3,
            "seed {}: time offset error {:.3} ms",
            r.seed,
            r.time_err_s * 1e3
        );
        assert!(
            r.inside,
            "seed {}: error outside the reported 3 sigma",
            r.seed
        );
    }
    // Consistency: the mean of 20 chi2(6) NEES values lies in the two-sided 95 % band
    // [chi2.ppf(0.025, 120), chi2.ppf(0.975, 120)] / 20 = [91.573, 152.211] / 20.
    assert!(
        (91.573 / 20.0..=152.211 / 20.0).contains(&mean_nees),
        "mean NEES {mean_nees:.2} outside [4.58, 7.61]"
    );
    assert!(
        inside * 100 >= 95 * results.len(),
        "only {inside} runs inside 3 sigma"
    );
}
