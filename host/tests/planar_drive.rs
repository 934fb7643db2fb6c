//! Pose-IMU calibration on a car-like planar drive (`sim::drive`: figure-eight loops, lane
//! changes, +-2 deg of suspension roll and pitch): the motion is detected as planar, the
//! rotation about the axis comes from the translations, the lever arm across the axis from
//! the yaw rate, and the lever arm along the axis (the height) is held at its prior,
//! reported not observable and never claimed.
//!
//! Measured (120 s drives, 10 Hz odometry with 0.2 deg / 5 mm per increment, seeds 1-5,
//! offsets -13 .. +15 ms): rotation 0.09-0.21 deg, horizontal lever arm 8-24 mm with
//! 11-15 mm sigma per axis, time offset within 1.01 ms, exit 0. The bounds below are 3x the
//! worst of these. The 1 cm horizontal bound is out of reach at this odometry noise:
//! the lever arm across the axis shows only as `w x p`, 0.03 x p per 0.1 s increment at the
//! drive's ~0.3 rad/s against 5 mm of noise (docs/planar.md).

#[path = "support/common.rs"]
mod common;

use std::process::Command;

use common::*;
use msreg_host::calibrate::driver::report::{PoseImuCalibration, PoseImuOptions};
use msreg_host::sim::{self, SimConfig, SimDataset};
use nalgebra::Vector3;

const SEEDS: [u64; 5] = [1, 2, 3, 4, 5];
const DURATION_S: f64 = 120.0;

fn drive(seed: u64) -> SimDataset {
    let mut c = SimConfig {
        seed,
        duration_s: DURATION_S,
        ..SimConfig::default()
    };
    c.trajectory.motion = sim::MotionKind::Drive(sim::DriveConfig::default());
    c.pose.time_offset_s = (seed as f64 * 7.0 - 20.0) * 1e-3;
    simulate(&c)
}

/// The rotation axis the filter held, and the lever arm along and across it.
fn held_split(c: &PoseImuCalibration, truth: &Vector3<f64>) -> (Vector3<f64>, f64, f64) {
    let axis = Vector3::from(c.report.held_axis.expect("a held axis"));
    let p = c.t_imu_sensor.translation.vector;
    let across = |v: Vector3<f64>| v - axis * axis.dot(&v);
    (axis, axis.dot(&p), (across(p) - across(*truth)).norm())
}

#[test]
fn planar_drive_holds_the_height_and_recovers_the_rest() {
    let results = par_map(&SEEDS, |seed| {
        let data = drive(seed);
        (
            data.clone(),
            calibrate::<f64>(&data, &PoseImuOptions::default()),
        )
    });
    let mut nees_sum = 0.0;
    for (seed, (data, c)) in SEEDS.iter().zip(&results) {
        let truth = data.t_imu_pose;
        let rot = rotation_error_deg(c, &truth);
        let (nees, sigma_ratio) = rotation_consistency(data, c);
        nees_sum += nees;
        let (axis, along, across) = held_split(c, &truth.translation.vector);
        let held = c.report.observability.last().expect("rows");
        let td = (c.time_offset_s - data.time_offset_s) * 1e3;
        println!(
            "seed {seed}: rotation {rot:.3} deg (NEES {nees:.2}, largest sigma / information \
             limit {sigma_ratio:.3}), lever arm across the axis {:.1} mm, height held at \
             {along:.3} m (sigma {:.3}), t_d {td:+.3} ms, {}",
            across * 1e3,
            held.sigma,
            c.report.planar
        );
        assert!(c.report.converged, "seed {seed}: {:?}", c.report.reasons);
        assert!(axis.z.abs() > 0.99, "seed {seed}: axis {axis}");
        assert!(rot < 0.63, "seed {seed}: rotation {rot} deg");
        assert!(across < 0.072, "seed {seed}: lever arm across {across} m");
        assert!(td.abs() < 3.0, "seed {seed}: time offset {td} ms");
        // The height is never claimed: its value and sigma stay at the prior.
        assert!(along.abs() < 1e-9, "seed {seed}: height moved to {along}");
        assert!(held.status == "not observable" && held.sigma >= 0.8 * held.prior_sigma);
        // Across the axis the estimate is inside its 3 sigma.
        let sigma = c.report.observability[3]
            .sigma
            .max(c.report.observability[4].sigma);
        assert!(
            across < 3.0 * sigma * 2f64.sqrt(),
            "seed {seed}: {across} vs sigma {sigma}"
        );
        assert!(inside_three_sigma(c, &truth), "seed {seed}");
        // The weakest rotation (about the forward axis) is as good as the odometry's rotation
        // noise allows (measured ratio 0.98-1.04 on seeds 1-30).
        assert!(
            (0.88..1.12).contains(&sigma_ratio),
            "seed {seed}: sigma / limit {sigma_ratio}"
        );
    }
    let (lo, hi) = chi_square_band(3.0 * SEEDS.len() as f64);
    assert!(
        (lo..hi).contains(&nees_sum),
        "rotation NEES {nees_sum} over {} seeds outside [{lo}, {hi}]",
        SEEDS.len()
    );
}

/// The rotation's NEES (3 DoF), and its largest 1-sigma over the information limit of the
/// rotation about the direction of travel (the mounting's roll). Only the odometry's
/// rotation increments tell it: an error tilts the mapped turn axis sideways, by the error
/// times the angle `theta_k` each increment turns, so `sigma >= sigma_r / sqrt(sum
/// theta_k^2)`. (About the lateral axis the translation tells it too: travel stays level;
/// about the turn axis the direction of travel does.)
fn rotation_consistency(data: &SimDataset, c: &PoseImuCalibration) -> (f64, f64) {
    let e = extrinsic_error(&c.t_imu_sensor, &data.t_imu_pose);
    let e = Vector3::new(e[0], e[1], e[2]);
    let p = c.covariance.fixed_view::<3, 3>(0, 0).into_owned();
    let nees = e.dot(&(p.try_inverse().expect("invertible") * e));
    let sum_sq: f64 = data
        .pose
        .windows(2)
        .map(|w| (w[0].rotation.inverse() * w[1].rotation).angle().powi(2))
        .sum();
    let limit = data.pose_sensor.rotation_noise_rad / sum_sq.sqrt();
    let largest = p.symmetric_eigenvalues().max().sqrt();
    (nees, largest / limit)
}

/// Seed 16's drive starts straight at a near-constant 10 m/s, which its IMU reads exactly as
/// rest: the odometry, which moves, must veto the standstill (before that check, zero-velocity
/// updates pinned the car to the ground and the gate rejected all 1198 relative poses).
#[test]
fn a_car_cruising_straight_is_not_at_rest() {
    let mut c = SimConfig {
        seed: 16,
        duration_s: 60.0,
        ..SimConfig::default()
    };
    c.trajectory.motion = sim::MotionKind::Drive(sim::DriveConfig::default());
    c.pose.time_offset_s = 0.01;
    let data = simulate(&c);
    let still = msreg_host::calibrate::init::detect_standstill(&data.imu, 0.3);
    assert!(still.is_some(), "the IMU alone sees a standstill");
    let c = calibrate::<f64>(&data, &PoseImuOptions::default());
    let total = c.report.updates_accepted + c.report.updates_rejected;
    println!(
        "seed 16, 60 s: standstill {} s, {} of {total} updates rejected, rotation {:.3} deg",
        c.report.standstill_s,
        c.report.updates_rejected,
        rotation_error_deg(&c, &data.t_imu_pose)
    );
    assert!(
        c.report.standstill_s.abs() < 1e-12,
        "{}",
        c.report.standstill_s
    );
    assert!(c.report.updates_rejected * 100 < total, "{total}");
    assert!(inside_three_sigma(&c, &data.t_imu_pose));
}

#[test]
fn cli_exits_0_and_warns_that_the_height_is_not_observable() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("drive");
    let msreg = env!("CARGO_BIN_EXE_msreg");
    let sim = Command::new(msreg)
        .args(["simulate", "pose-imu", "--motion", "drive", "--seed", "3"])
        .args(["--duration", "120"])
        .arg(&data)
        .output()
        .expect("run msreg");
    assert!(sim.status.success());
    let out = Command::new(msreg)
        .args(["calibrate", "pose-imu"])
        .arg(&data)
        .arg("-o")
        .arg(dir.path().join("result.yaml"))
        .output()
        .expect("run msreg");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("warning: translation along") && stderr.contains("not observable"),
        "{stderr}"
    );
}

/// The lever arm's NEES across the held axis (2 DoF, with the full 2 x 2 covariance).
fn lever_arm_nees_across(c: &PoseImuCalibration, truth: &Vector3<f64>) -> f64 {
    let axis = Vector3::from(c.report.held_axis.expect("a held axis"));
    let e1 = axis.cross(&Vector3::x()).normalize();
    let e2 = axis.cross(&e1);
    let basis = nalgebra::Matrix3x2::from_columns(&[e1, e2]);
    let p = c.covariance.fixed_view::<3, 3>(3, 3).into_owned();
    let e = basis.transpose() * (c.t_imu_sensor.translation.vector - truth);
    let s = basis.transpose() * p * basis;
    e.dot(&(s.try_inverse().expect("invertible") * e))
}

/// The observability-constrained filter (`PoseImuOptions::constrain_yaw`) against the
/// default one on drives 1-30: the lever arm across the axis is over-confident in both, so
/// the spurious information about the yaw about gravity (which the constraint provably
/// removes: `estimator/src/filter/yaw_gauge.rs`) is not what makes it. About 10 min on
/// 2 cores: `cargo test --release -p msreg --test planar_drive -- --ignored --nocapture`.
#[test]
#[ignore]
fn the_yaw_constraint_does_not_explain_the_lever_arm_over_confidence() {
    let seeds: Vec<u64> = (1..=30).collect();
    let runs = par_map(&seeds, |seed| {
        let data = drive(seed);
        let run = |constrain_yaw| {
            let options = PoseImuOptions {
                constrain_yaw,
                ..PoseImuOptions::default()
            };
            let c = calibrate::<f64>(&data, &options);
            let truth = data.t_imu_pose.translation.vector;
            let nees = lever_arm_nees_across(&c, &truth);
            (c.report.converged, nees, rotation_consistency(&data, &c).0)
        };
        (run(false), run(true))
    });
    let (mut free, mut constrained, mut dof) = (0.0, 0.0, 0.0);
    for (seed, (a, b)) in seeds.iter().zip(&runs) {
        println!(
            "seed {seed}: converged {} / {}; lever arm NEES (2 dof) {:.1} / {:.1}; rotation \
             NEES (3 dof) {:.1} / {:.1}",
            a.0, b.0, a.1, b.1, a.2, b.2
        );
        if a.0 && b.0 {
            free += a.1;
            constrained += b.1;
            dof += 2.0;
        }
    }
    let (lo, hi) = chi_square_band(dof);
    println!(
        "lever arm NEES over {dof} dof: {free:.1} default, {constrained:.1} constrained \
         (band [{lo:.1}, {hi:.1}])"
    );
    assert!(free > hi && constrained > hi);
    assert!((constrained / free - 1.0).abs() < 0.25);
}
