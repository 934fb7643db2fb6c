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
    for (seed, (data, c)) in SEEDS.iter().zip(&results) {
        let truth = data.t_imu_pose;
        let rot = rotation_error_deg(c, &truth);
        let (axis, along, across) = held_split(c, &truth.translation.vector);
        let held = c.report.observability.last().expect("rows");
        let td = (c.time_offset_s - data.time_offset_s) * 1e3;
        println!(
            "seed {seed}: rotation {rot:.3} deg, lever arm across the axis {:.1} mm, height \
             held at {along:.3} m (sigma {:.3}), t_d {td:+.3} ms, {}",
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
    }
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
