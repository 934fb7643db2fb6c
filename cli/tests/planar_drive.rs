//! Pose-IMU calibration on a car-like planar drive (`sim::drive`: figure-eight loops, lane
//! changes, +-2 deg of suspension roll and pitch): the motion is detected as planar, the
//! rotation about the axis comes from the translations, the lever arm across the axis from
//! the yaw rate, and the lever arm along the axis (the height) is held at its prior,
//! reported not observable and never claimed.
//!
//! Measured (120 s drives, 10 Hz odometry with 0.2 deg / 5 mm per increment, seeds 1-5,
//! offsets -13 .. +15 ms): rotation 0.08-0.18 deg, horizontal lever arm 4-26 mm with
//! 11-15 mm sigma per axis, time offset within 1.09 ms, exit 0. The bounds below are about
//! 3x the worst of these (rotation 0.55 deg, lever arm 72 mm: 2.8x). The issue's 1 cm horizontal bound is out of reach on this drive at this
//! odometry noise: the lever arm across the axis shows only as `w x p`, 0.03 x p per 0.1 s
//! increment at the drive's ~0.3 rad/s against 5 mm of noise (docs/planar.md).
//!
//! A calibration manoeuvre carries that information: ten minutes of a parking-lot
//! figure-eight (`DriveConfig::figure_eight`) meet the issue's 0.2 deg and 1 cm on every
//! seed, with the same odometry, and are consistent over 30 more seeds (the last two tests).

#[path = "../../host/tests/support/common.rs"]
mod common;

use std::process::Command;

use common::*;
use msreg_host::calibrate::driver::report::{PoseImuCalibration, PoseImuOptions};
use msreg_host::sim::{self, SimConfig, SimDataset};
use nalgebra::Vector3;

const SEEDS: [u64; 5] = [1, 2, 3, 4, 5];
const DURATION_S: f64 = 120.0;

fn drive(seed: u64) -> SimDataset {
    drive_of(sim::DriveConfig::default(), seed, DURATION_S)
}

/// A drive of this shape and length; the time offset `((7 seed) mod 41) - 20` ms, inside
/// +-20 ms (seeds 1-5: -13 .. +15 ms).
fn drive_of(shape: sim::DriveConfig, seed: u64, duration_s: f64) -> SimDataset {
    let mut c = SimConfig {
        seed,
        duration_s,
        ..SimConfig::default()
    };
    c.trajectory.motion = sim::MotionKind::Drive(shape);
    c.pose.time_offset_s = (((7 * seed) % 41) as f64 - 20.0) * 1e-3;
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
        assert!(rot < 0.55, "seed {seed}: rotation {rot} deg");
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
    for (motion, duration) in [("drive", "120"), ("figure-eight", "600")] {
        cli_warns_that_the_height_is_not_observable(motion, duration);
    }
}

fn cli_warns_that_the_height_is_not_observable(motion: &str, duration: &str) {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dir.path().join("drive");
    let msreg = env!("CARGO_BIN_EXE_msreg");
    let sim = Command::new(msreg)
        .args(["simulate", "pose-imu", "--motion", motion, "--seed", "3"])
        .args(["--duration", duration])
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
    assert_eq!(out.status.code(), Some(0), "{motion}: {stderr}");
    assert!(
        stderr.contains("warning: translation along") && stderr.contains("not observable"),
        "{motion}: {stderr}"
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

/// The observability-constrained filter (`PoseImuOptions::constrain_yaw`, the default under
/// planar motion) against the unconstrained one on drives 1-30, both from the
/// direction-of-travel start. Measured: lever arm across the axis NEES 133.4 unconstrained
/// against 63.7 constrained over the 29 seeds both converge on (58 dof, band
/// [38.8, 80.9]); seed 11, where the unconstrained filter ends 19 cm off with a 14 mm sigma
/// (NEES 192), does not converge constrained and says so (exit 1). The spurious information
/// about the rotation about gravity (`estimator/src/filter/yaw_gauge.rs`) is what made the
/// lever arm over-confident; before the travel start, the scan's 4-21 deg start errors hid
/// it (docs/planar.md). About 15 s on 2 cores.
#[test]
fn the_yaw_constraint_makes_the_lever_arm_consistent() {
    let seeds: Vec<u64> = (1..=30).collect();
    let runs = par_map(&seeds, |seed| {
        let data = drive(seed);
        let run = |constrain_yaw| {
            let options = PoseImuOptions {
                constrain_yaw: Some(constrain_yaw),
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
        "lever arm NEES over {dof} dof: {free:.1} unconstrained, {constrained:.1} constrained \
         (band [{lo:.1}, {hi:.1}])"
    );
    assert!(free > hi, "unconstrained {free}");
    assert!((lo..hi).contains(&constrained), "constrained {constrained}");
    let lost = runs.iter().filter(|(_, b)| !b.0).count();
    assert!(lost <= 1, "{lost} constrained runs did not converge");
}

/// What one figure-eight run gives: the errors, and each estimate's NEES.
struct FigureEightRun {
    converged: bool,
    events: usize,
    rotation_deg: f64,
    rotation_nees: f64,
    across_m: f64,
    across_nees: f64,
    time_offset_ms: f64,
    time_offset_nees: f64,
}

fn figure_eight(seed: u64) -> (FigureEightRun, SimDataset, PoseImuCalibration) {
    let data = drive_of(sim::DriveConfig::figure_eight(), seed, FIGURE_EIGHT_S);
    let c = calibrate::<f64>(&data, &PoseImuOptions::default());
    let truth = data.t_imu_pose;
    let td = c.time_offset_s - data.time_offset_s;
    let run = FigureEightRun {
        converged: c.report.converged,
        events: c.report.events.len(),
        rotation_deg: rotation_error_deg(&c, &truth),
        rotation_nees: rotation_consistency(&data, &c).0,
        across_m: held_split(&c, &truth.translation.vector).2,
        across_nees: lever_arm_nees_across(&c, &truth.translation.vector),
        time_offset_ms: td * 1e3,
        time_offset_nees: (td / c.time_offset_sigma_s).powi(2),
    };
    println!(
        "seed {seed}: rotation {:.3} deg (NEES {:.2}), lever arm across the axis {:.1} mm \
         (NEES {:.2}), t_d {:+.3} ms (NEES {:.2}), events {}",
        run.rotation_deg,
        run.rotation_nees,
        run.across_m * 1e3,
        run.across_nees,
        run.time_offset_ms,
        run.time_offset_nees,
        run.events
    );
    (run, data, c)
}

/// Sums of the rotation (3 dof), lever-arm (2 dof) and time-offset (1 dof) NEES, each
/// asserted inside its 95 % chi-square band.
fn assert_nees_bands(runs: &[FigureEightRun]) {
    let n = runs.len() as f64;
    for (name, dof, sum) in [
        (
            "rotation",
            3.0,
            runs.iter().map(|r| r.rotation_nees).sum::<f64>(),
        ),
        (
            "lever arm across",
            2.0,
            runs.iter().map(|r| r.across_nees).sum(),
        ),
        (
            "time offset",
            1.0,
            runs.iter().map(|r| r.time_offset_nees).sum(),
        ),
    ] {
        let (lo, hi) = chi_square_band(dof * n);
        println!(
            "{name} NEES {sum:.1} over {} dof, band [{lo:.1}, {hi:.1}]",
            dof * n
        );
        assert!(
            (lo..hi).contains(&sum),
            "{name} NEES {sum} outside [{lo}, {hi}]"
        );
    }
}

/// Ten minutes of a calibration figure-eight (`DriveConfig::figure_eight`).
const FIGURE_EIGHT_S: f64 = 600.0;

/// The issue's planar acceptance: with a drive that carries the information (a 10 min
/// parking-lot figure-eight, the same odometry noise as above), the rotation is within
/// 0.2 deg and the lever arm across the axis within 1 cm on every seed, each estimate is
/// inside its 3 sigma, the height is held and reported not observable, and no health event
/// is raised. (The NEES bands need more than five seeds: the next test.)
///
/// Measured (seeds 1-5): rotation 0.018-0.181 deg, lever arm 1.2-3.2 mm, t_d within
/// 0.88 ms (sigma 0.6-0.7 ms). The bounds are the issue's: 1.1x the worst rotation (0.2 deg
/// is about 3 sigma of the mounting's roll here, docs/planar.md) and 3.1x the worst lever
/// arm.
#[test]
fn a_calibration_figure_eight_meets_the_issue_bounds() {
    let runs = par_map(&SEEDS, figure_eight);
    for (seed, (run, data, c)) in SEEDS.iter().zip(&runs) {
        assert!(run.converged, "seed {seed}: {:?}", c.report.reasons);
        assert_eq!(run.events, 0, "seed {seed}: {:?}", c.report.events);
        assert!(
            run.rotation_deg < 0.2,
            "seed {seed}: {} deg",
            run.rotation_deg
        );
        assert!(run.across_m < 0.01, "seed {seed}: {} m", run.across_m);
        assert!(
            run.time_offset_nees < 9.0,
            "seed {seed}: t_d beyond 3 sigma"
        );
        assert!(inside_three_sigma(c, &data.t_imu_pose), "seed {seed}");
        let (axis, along, _) = held_split(c, &data.t_imu_pose.translation.vector);
        let held = c.report.observability.last().expect("rows");
        assert!(axis.z.abs() > 0.99, "seed {seed}: axis {axis}");
        assert!(along.abs() < 1e-9, "seed {seed}: height moved to {along}");
        assert!(held.status == "not observable" && held.sigma >= 0.8 * held.prior_sigma);
    }
}

/// Consistency over 30 more figure-eights (seeds 11-40; about 35 s on 2 cores): the NEES
/// sums of the rotation, the lever arm across the axis and the time offset inside their
/// 95 % bands. Measured: 105.1 over 90 dof, 60.6 over 60, 27.6 over 30; all converged, no
/// event; the worst rotation 0.174 deg and lever arm 7.9 mm.
#[test]
fn figure_eights_are_consistent_over_thirty_seeds() {
    let seeds: Vec<u64> = (11..=40).collect();
    let runs = par_map(&seeds, |seed| figure_eight(seed).0);
    for (seed, run) in seeds.iter().zip(&runs) {
        assert!(run.converged && run.events == 0, "seed {seed}");
        assert!(run.rotation_deg < 0.2 && run.across_m < 0.01, "seed {seed}");
    }
    assert_nees_bands(&runs);
}
