//! On-vehicle monitoring (issue 13, item 4): `msreg simulate drive` + the health monitor
//! replayed over IMU + LiDAR odometry (pose0) + camera VO (pose1) in one filter.
//!
//! Acceptance runs (ignored by default; docs/monitor.md records their output):
//! `cargo test --release -p msreg-host --test monitor_drive -- --ignored --nocapture --test-threads 1`
//! Seeds 100-109 (knocks and unknocked runs), 120-121 (default-run tests) and 300-339 (false
//! alarms) were not used to choose any constant (those were chosen on seeds 1-8, the step
//! confidence on seeds 200-299: docs/monitor.md, "False alarms").

#[path = "support/common.rs"]
mod common;

use common::par_map;
use msreg_host::monitor::{
    monitor, MonitorError, MonitorInput, MonitorOptions, MonitorReport, VerdictWords,
};
use msreg_host::sim::{simulate_drive, DriveSim, DriveSimConfig, KnockTarget};

const KNOCK_AT_S: f64 = 30.0;
/// The bound on the detection latency, s.
const MAX_LATENCY_S: f64 = 5.0;

fn run(seed: u64, target: KnockTarget) -> (DriveSim, MonitorReport) {
    let (sim, report) = try_run(seed, target);
    (sim, report.expect("monitor"))
}

/// The drive and the monitor's report, or why the monitor could not start.
fn try_run(seed: u64, target: KnockTarget) -> (DriveSim, Result<MonitorReport, MonitorError>) {
    let sim = simulate_drive(&DriveSimConfig {
        seed,
        knock_target: target,
        knock_at_s: KNOCK_AT_S,
        ..DriveSimConfig::default()
    })
    .expect("simulate");
    let noise: Vec<_> = sim
        .sensors
        .iter()
        .map(|s| msreg_host::sim::pose_sensor_yaml(&s.config))
        .collect();
    let imu_noise = msreg_host::sim::imu_noise_yaml(&sim.config.imu);
    let input = MonitorInput {
        imu: &sim.imu,
        imu_noise: &imu_noise,
        poses: sim.sensors.iter().map(|s| s.poses.as_slice()).collect(),
        pose_noise: noise.iter().collect(),
        prior: sim.sensors.iter().map(|s| s.prior).collect(),
    };
    let report = monitor(&input, &MonitorOptions::default());
    (sim, report)
}

/// Yaw the vehicle turned over `[t0, t1]`, deg (sum of |heading change| at 10 Hz).
fn turned_deg(sim: &DriveSim, t0: f64, t1: f64) -> f64 {
    let n = ((t1 - t0) / 0.1).ceil().max(1.0) as usize;
    (0..n)
        .map(|k| {
            let a = sim
                .trajectory
                .isometry(t0 + (t1 - t0) * k as f64 / n as f64);
            let b = sim
                .trajectory
                .isometry(t0 + (t1 - t0) * (k + 1) as f64 / n as f64);
            a.rotation.angle_to(&b.rotation).to_degrees()
        })
        .sum()
}

/// Outcome of one knocked run.
struct KnockOutcome {
    seed: u64,
    /// The first alarm is on the knocked sensor.
    right_sensor: bool,
    /// First alarm minus knock time, s.
    latency: f64,
    /// Alarms on the other sensor.
    cross: usize,
    /// Updates held out of the filter while a knock candidate was tested (pose0, pose1).
    held_out: [usize; 2],
}

/// One knocked run, printed.
fn knocked(seed: u64, target: KnockTarget) -> KnockOutcome {
    let (sim, r) = run(seed, target);
    let (name, other) = match target {
        KnockTarget::Pose0 => ("pose0", "pose1"),
        _ => ("pose1", "pose0"),
    };
    let alarms: Vec<_> = r.alarms.iter().map(|a| (a.t_s, a.sensor, a.kind)).collect();
    let first = r
        .alarms
        .first()
        .unwrap_or_else(|| panic!("seed {seed}: no alarm"));
    let latency = first.t_s - KNOCK_AT_S;
    let turned = turned_deg(&sim, KNOCK_AT_S, first.t_s);
    println!(
        "seed {seed}: knock on {name}: first alarm {} {} at +{latency:.2} s (turned {turned:.0} deg); alarms {alarms:?}; held out {:?}",
        first.sensor,
        first.kind,
        r.sensors.iter().map(|s| s.held_out).collect::<Vec<_>>()
    );
    KnockOutcome {
        seed,
        right_sensor: first.sensor == name,
        latency,
        cross: r.alarms.iter().filter(|a| a.sensor == other).count(),
        held_out: [0, 1].map(|k| r.sensors[k].held_out),
    }
}

/// The knocked sensor is flagged first, within the latency bound.
fn check_knock(o: &KnockOutcome) {
    assert!(
        o.right_sensor,
        "seed {}: the other sensor was flagged first",
        o.seed
    );
    assert!(
        (0.0..=MAX_LATENCY_S).contains(&o.latency),
        "seed {}: flagged {:.2} s after the knock",
        o.seed,
        o.latency
    );
}

fn check_unobservable_named(r: &MonitorReport) {
    let words = r.unobservable_words();
    assert!(r.planar_axis.is_some(), "planar motion not detected");
    for s in ["pose0", "pose1"] {
        assert!(
            words.iter().any(
                |w| w.starts_with(&format!("{s} translation z: not observable"))
                    && w.contains("planar")
            ),
            "{s}: {words:?}"
        );
    }
    // Rotation is observed by the drive (the observability run's sigma well under its prior).
    for s in &r.sensors {
        for row in s
            .observability
            .iter()
            .filter(|r| r.dof.starts_with("rotation"))
        {
            assert_ne!(row.status, "not observable", "{}: {row:?}", s.name);
        }
    }
}

#[test]
fn camera_knock_is_flagged_on_the_camera_and_unobservable_dofs_are_named() {
    let o = knocked(120, KnockTarget::Pose1);
    check_knock(&o);
    assert_eq!(o.cross, 0, "the LiDAR was flagged too");
    // The knock's own increment made a candidate: the camera was held out until confirmed.
    assert!(o.held_out[0] == 0 && o.held_out[1] > 0, "{:?}", o.held_out);
    let (_, r) = run(121, KnockTarget::None);
    assert!(r.alarms.is_empty(), "false alarm: {:?}", r.alarms);
    check_unobservable_named(&r);
}

/// How the verdict's account of a knock compares with the truth.
#[derive(Debug, Clone, Copy)]
struct VerdictError {
    seed: u64,
    /// Verdict angle minus the knock's, deg.
    angle: f64,
    /// The verdict's 1-sigma of the angle, deg.
    sigma: f64,
    /// Angle between the verdict's axis and the knock's, deg.
    axis: f64,
    /// The verdict's main axis is the knock's (checked where the knock's is clear).
    main_axis_agrees: bool,
    /// Verdict's onset minus the knock time, s.
    since: f64,
    /// NEES of the rotation vector's error (verdict minus knock) in the verdict's covariance
    /// (final covariance plus the record's sigmas): chi-square(3) if the +- is honest.
    nees: f64,
}

/// The verdict of a knocked run against the knock it simulated (sensor `k`).
fn verdict_error(seed: u64, sim: &DriveSim, r: &MonitorReport, k: usize) -> VerdictError {
    let v = r.verdict();
    assert!(v.changed(), "seed {seed}: no change in {v:?}");
    let moved: Vec<_> = v.sensors.iter().filter(|s| s.moved).collect();
    assert_eq!(moved.len(), 1, "seed {seed}: {moved:?}");
    let s = moved[0];
    assert_eq!(s.sensor, ["pose0", "pose1"][k], "seed {seed}");
    let truth = &sim.sensors[k];
    let knock = (truth.t_imu_pose.rotation.inverse() * truth.final_t_imu_pose().rotation)
        .scaled_axis()
        .map(f64::to_degrees);
    let axis = nalgebra::Vector3::from(s.rotation.axis);
    let true_axis = knock.normalize();
    let clear = true_axis.amax() > 0.8;
    let words = v.lines(&VerdictWords::default());
    let line = &words[0];
    println!("seed {seed}: {line}");
    let axis_name = msreg_host::monitor::AXIS_NAMES[s.rotation.main_axis];
    assert!(
        line.contains(&format!("bracket of {}", s.sensor))
            && line.contains(&format!("about its {axis_name} axis"))
            && line.contains(&format!("rotated {:.2} deg", s.rotation.angle_deg)),
        "{line}"
    );
    let report = &r.sensors[k];
    let cov = nalgebra::Matrix3::from_fn(|i, j| {
        report.final_covariance[i][j]
            + if i == j {
                report.record.sigma_rot_deg[i].to_radians().powi(2)
            } else {
                0.0
            }
    });
    let err = (nalgebra::Vector3::from(s.rotation.vector_deg) - knock).map(f64::to_radians);
    let nees = (err.transpose() * cov.try_inverse().expect("covariance") * err)[(0, 0)];
    VerdictError {
        seed,
        nees,
        angle: s.rotation.angle_deg - knock.norm(),
        sigma: s.rotation.sigma_deg,
        axis: axis.angle(&true_axis).to_degrees(),
        main_axis_agrees: !clear || s.rotation.main_axis == true_axis.iamax(),
        since: s.since_s.unwrap_or(f64::NAN) - KNOCK_AT_S,
    }
}

/// Bounds on the verdict's account of a 1 deg knock: near 3x the worst of seeds 100-109, both
/// sensors (0.132 deg, 15.7 deg, 0.10 s; docs/monitor.md, "The verdict"); the NEES bound is
/// chi-square(3) at 99.9 %.
const MAX_ANGLE_ERROR_DEG: f64 = 0.4;
const MAX_AXIS_ERROR_DEG: f64 = 47.0;
const MAX_ONSET_ERROR_S: f64 = 0.3;
const MAX_NEES: f64 = 16.27;

fn check_verdict(e: &VerdictError) {
    assert!(
        e.angle.abs() <= MAX_ANGLE_ERROR_DEG && e.angle.abs() <= 3.0 * e.sigma,
        "seed {}: angle off by {:.3} deg (sigma {:.3})",
        e.seed,
        e.angle,
        e.sigma
    );
    assert!(
        e.axis <= MAX_AXIS_ERROR_DEG && e.main_axis_agrees,
        "seed {}: axis off by {:.1} deg",
        e.seed,
        e.axis
    );
    assert!(e.nees <= MAX_NEES, "seed {}: NEES {:.1}", e.seed, e.nees);
    assert!(
        (-MAX_ONSET_ERROR_S..=MAX_ONSET_ERROR_S).contains(&e.since),
        "seed {}: onset {:.2} s from the knock",
        e.seed,
        e.since
    );
}

#[test]
fn verdict_names_sensor_axis_angle_and_onset_of_the_knock() {
    let (sim, r) = run(120, KnockTarget::Pose1);
    let e = verdict_error(120, &sim, &r, 1);
    println!("{e:?}");
    check_verdict(&e);
    // Healthy: one line, every sensor within the largest change stated.
    let (_, r) = run(121, KnockTarget::None);
    let v = r.verdict();
    assert!(!v.changed());
    let lines = v.lines(&VerdictWords::default());
    let (rot, trans) = v.largest_change();
    println!("{lines:?}");
    assert_eq!(lines.len(), 1);
    assert!(
        lines[0].starts_with(&format!(
            "OK: all 2 sensors within {rot:.2} deg / {trans:.1} mm of the calibration of record"
        )),
        "{lines:?}"
    );
    // Unknocked: the final estimates stay near the record (its own error is 0.05 deg per axis).
    assert!(rot < 0.3, "{rot} deg");
}

/// The verdict over ten knocks of each sensor (the numbers in docs/monitor.md).
#[test]
#[ignore = "acceptance: 20 drives, ~20 s release"]
fn verdict_ten_seeds_each_sensor() {
    let seeds: Vec<u64> = (100..110).collect();
    let mut all = Vec::new();
    for (target, k) in [(KnockTarget::Pose1, 1), (KnockTarget::Pose0, 0)] {
        let errors = par_map(&seeds, |s| {
            let (sim, r) = run(s, target);
            verdict_error(s, &sim, &r, k)
        });
        for e in &errors {
            println!(
                "pose{k} seed {}: angle error {:+.3} deg (sigma {:.3}), axis {:.2} deg, onset {:+.2} s, NEES {:.2}",
                e.seed, e.angle, e.sigma, e.axis, e.since, e.nees
            );
        }
        let worst = |f: fn(&VerdictError) -> f64| errors.iter().map(f).fold(0.0, f64::max);
        println!(
            "pose{k}: worst angle error {:.3} deg ({:.2} sigma), axis {:.2} deg, onset {:.2} s",
            worst(|e| e.angle.abs()),
            worst(|e| e.angle.abs() / e.sigma),
            worst(|e| e.axis),
            worst(|e| e.since.abs())
        );
        all.extend(errors);
    }
    println!(
        "mean NEES {:.2} over {} knocks (chi-square(3): 3)",
        all.iter().map(|e| e.nees).sum::<f64>() / all.len() as f64,
        all.len()
    );
    all.iter().for_each(check_verdict);
}

#[test]
#[ignore = "acceptance: 10 seeds, ~10 s release"]
fn camera_knock_ten_seeds() {
    let seeds: Vec<u64> = (100..110).collect();
    let results = par_map(&seeds, |s| knocked(s, KnockTarget::Pose1));
    println!(
        "latencies {:?}",
        results
            .iter()
            .map(|r| (r.latency * 100.0).round() / 100.0)
            .collect::<Vec<_>>()
    );
    results.iter().for_each(check_knock);
    let cross: usize = results.iter().map(|r| r.cross).sum();
    assert_eq!(cross, 0, "the LiDAR was flagged after a camera knock");
}

#[test]
#[ignore = "acceptance: 10 seeds, ~10 s release"]
fn lidar_knock_ten_seeds() {
    let seeds: Vec<u64> = (100..110).collect();
    let results = par_map(&seeds, |s| knocked(s, KnockTarget::Pose0));
    println!(
        "right sensor first {} of 10; latencies {:?}; alarms on pose1 per seed {:?}",
        results.iter().filter(|r| r.right_sensor).count(),
        results
            .iter()
            .map(|r| (r.latency * 100.0).round() / 100.0)
            .collect::<Vec<_>>(),
        results.iter().map(|r| r.cross).collect::<Vec<_>>()
    );
    results.iter().for_each(check_knock);
}

#[test]
#[ignore = "acceptance: 10 seeds, ~10 s release"]
fn no_alarm_in_ten_unknocked_drives() {
    let seeds: Vec<u64> = (100..110).collect();
    let reports = par_map(&seeds, |s| run(s, KnockTarget::None).1);
    for (seed, r) in seeds.iter().zip(&reports) {
        println!(
            "seed {seed}: alarms {:?}; nis_high warnings {}",
            r.alarms
                .iter()
                .map(|a| (a.t_s, a.sensor, a.kind))
                .collect::<Vec<_>>(),
            r.warnings.len()
        );
        check_unobservable_named(r);
    }
    for (seed, r) in seeds.iter().zip(&reports) {
        assert!(
            r.alarms.is_empty(),
            "seed {seed}: false alarm {:?}",
            r.alarms
        );
    }
}

/// Largest GLR statistic of any step detector of `sensor` over the drive (between alarms),
/// with its dof and threshold (docs/monitor.md, "False alarms").
fn max_glr(r: &MonitorReport, sensor: &str) -> Option<(f64, usize, f64)> {
    r.sensors
        .iter()
        .filter(|s| s.name == sensor)
        .flat_map(|s| &s.nis)
        .flat_map(|p| [p.rotation_glr, p.translation_glr])
        .flatten()
        .map(|g| (g.statistic, g.dof, g.threshold))
        .max_by(|a, b| a.0.total_cmp(&b.0))
}

/// Unknocked 60 s drives on seeds 300-339, which chose nothing (the step confidence was
/// chosen on seeds 200-299): the false alarms per drive. A drive on which the monitor cannot
/// start (too little rotation for the dynamic alignment) is counted apart: no monitoring,
/// no alarm. Expected under repeated testing at the default confidence and the measured
/// count: docs/monitor.md, "False alarms".
#[test]
#[ignore = "acceptance: 40 drives, ~40 s release"]
fn false_alarms_in_forty_unknocked_drives() {
    const MAX_FALSE_ALARMS: usize = 1;
    const MAX_NO_START: usize = 3;
    let seeds: Vec<u64> = (300..340).collect();
    let reports = par_map(&seeds, |s| try_run(s, KnockTarget::None).1);
    let mut no_start = 0;
    let mut total = 0;
    let (mut held, mut updates) = ([0usize; 2], [0usize; 2]);
    for (seed, r) in seeds.iter().zip(&reports) {
        let r = match r {
            Ok(r) => r,
            Err(e) => {
                println!("seed {seed}: no start: {e}");
                assert!(e.is_no_start(), "seed {seed}: {e}");
                no_start += 1;
                continue;
            }
        };
        println!(
            "seed {seed}: max GLR (statistic, dof, threshold) pose0 {:?} pose1 {:?}; alarms {:?}",
            max_glr(r, "pose0"),
            max_glr(r, "pose1"),
            r.alarms
                .iter()
                .map(|a| (a.t_s, a.sensor, a.statistic))
                .collect::<Vec<_>>()
        );
        total += r.alarms.len();
        for (k, s) in r.sensors.iter().enumerate() {
            held[k] += s.held_out;
            updates[k] += s.nis.len();
        }
    }
    println!(
        "updates held out while a knock candidate was tested: pose0 {} of {}, pose1 {} of {}",
        held[0], updates[0], held[1], updates[1]
    );
    println!(
        "false alarms in {} drives: {total}; monitor not started on {no_start}",
        seeds.len()
    );
    assert!(
        total <= MAX_FALSE_ALARMS,
        "{total} false alarms in {} unknocked drives",
        seeds.len()
    );
    assert!(no_start <= MAX_NO_START, "no start on {no_start} drives");
}
