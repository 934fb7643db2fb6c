//! The monitor with one and with three pose sensors (issue 32): `msreg simulate drive
//! --pose-sensors N` drives (each sensor simulated from the trajectory with its own mounting),
//! replayed by the same monitor that runs two. A knock on one sensor is flagged on that
//! sensor alone, within the latency bound; an unknocked drive raises no alarm; the
//! re-estimated calibration has a `poseK` section per sensor.

use msreg_host::dataset::SectionName;
use msreg_host::monitor::{monitor, MonitorError, MonitorInput, MonitorOptions, MonitorReport};
use msreg_host::sim::{simulate_drive, DriveSim, DriveSimConfig, KnockTarget};

/// Knock time, s after the start (as host/tests/monitor_drive.rs).
const KNOCK_AT_S: f64 = 30.0;
/// The bound on the detection latency, s.
const MAX_LATENCY_S: f64 = 5.0;

/// Bound on the false alarms of [`one_pose_sensor_false_alarms_in_forty_unknocked_drives`].
/// Measured: 0 in 40 drives (0.65 h; one drive did not start); the bound is the two-sensor
/// study's (host/tests/monitor_drive.rs: at 99.999 % ~0.2 expected per hour).
const MAX_ONE_SENSOR_FALSE_ALARMS: usize = 1;

/// A drive with `sensors` pose sensors and the monitor's report of it.
fn run(seed: u64, sensors: usize, target: KnockTarget) -> (DriveSim, MonitorReport) {
    let (sim, report) = try_run(seed, sensors, target);
    (sim, report.expect("monitor"))
}

/// The drive and the monitor's report, or why it could not start.
fn try_run(
    seed: u64,
    sensors: usize,
    target: KnockTarget,
) -> (DriveSim, Result<MonitorReport, MonitorError>) {
    let sim = simulate_drive(&DriveSimConfig {
        seed,
        pose_sensors: sensors,
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

/// The knocked sensor `name` is flagged within the bound and no other sensor is; returns the
/// latency, s.
fn check_knock_flagged(r: &MonitorReport, name: &str) -> f64 {
    let alarms: Vec<_> = r.alarms.iter().map(|a| (a.t_s, a.sensor, a.kind)).collect();
    let first = r
        .first_alarm_after(name, 0.0)
        .unwrap_or_else(|| panic!("{name} not flagged: {alarms:?}"));
    let latency = first.t_s - KNOCK_AT_S;
    println!(
        "{name}: flagged {} at +{latency:.2} s; alarms {alarms:?}",
        first.kind
    );
    assert!(
        (0.0..=MAX_LATENCY_S).contains(&latency),
        "{name}: flagged {latency:.2} s after the knock"
    );
    assert!(
        r.alarms.iter().all(|a| a.sensor == name),
        "another sensor flagged: {alarms:?}"
    );
    let verdict = r.verdict();
    let moved: Vec<_> = verdict.sensors.iter().filter(|s| s.moved).collect();
    assert!(
        moved.len() == 1 && moved[0].sensor == name,
        "verdict: {moved:?}"
    );
    latency
}

/// Every sensor of `r` is within `max_deg` of the truth at the end of `sim` (the knocked one
/// within `max_knocked_deg`), and the re-estimated calibration has exactly its `poseK`
/// sections.
fn check_estimates(sim: &DriveSim, r: &MonitorReport, max_deg: f64, max_knocked_deg: f64) {
    assert_eq!(r.sensors.len(), sim.sensors.len());
    let calibration = r.calibration();
    assert_eq!(calibration.extrinsic_names().count(), sim.sensors.len());
    for (k, (s, truth)) in r.sensors.iter().zip(&sim.sensors).enumerate() {
        assert_eq!(s.name, format!("pose{k}"));
        let written = calibration
            .extrinsic(&SectionName::pose(k as u16))
            .unwrap_or_else(|| panic!("pose{k}: no section"));
        assert_eq!(written.transform, s.estimate.transform);
        let error = s
            .estimate
            .transform
            .rotation
            .angle_to(&truth.final_t_imu_pose().rotation)
            .to_degrees();
        println!("{}: {error:.3} deg from the truth", s.name);
        let bound = match truth.config.knock {
            Some(_) => max_knocked_deg,
            None => max_deg,
        };
        assert!(error < bound, "{}: {error:.3} deg from the truth", s.name);
    }
}

#[test]
fn one_pose_sensor_knock_is_flagged_and_an_unknocked_drive_is_quiet() {
    // Measured (seeds 140, 141): flagged at +2.80 s (bound: the 5 s); the knocked
    // estimate ends 0.242 deg from the truth (bound 0.75), the healthy one 0.062 deg (0.2).
    let (sim, r) = run(140, 1, KnockTarget::Pose0);
    check_knock_flagged(&r, "pose0");
    check_estimates(&sim, &r, 0.2, 0.75);
    let (sim, r) = run(141, 1, KnockTarget::None);
    assert!(r.alarms.is_empty(), "false alarm: {:?}", r.alarms);
    assert!(!r.verdict().changed());
    check_estimates(&sim, &r, 0.2, 0.75);
}

#[test]
fn three_pose_sensors_knock_is_flagged_on_the_knocked_one_and_an_unknocked_drive_is_quiet() {
    // Measured (seeds 142, 143): pose2 flagged at +1.59 s (bound 5 s), no other sensor; the
    // knocked pose2 ends 0.132 deg from the truth (bound 0.75), the others at most 0.067 deg
    // (bound 0.2).
    let (sim, r) = run(142, 3, KnockTarget::Pose(2));
    check_knock_flagged(&r, "pose2");
    check_estimates(&sim, &r, 0.2, 0.75);
    let (sim, r) = run(143, 3, KnockTarget::None);
    assert!(r.alarms.is_empty(), "false alarm: {:?}", r.alarms);
    assert!(!r.verdict().changed());
    check_estimates(&sim, &r, 0.2, 0.75);
}

#[test]
fn one_sensor_drive_is_the_two_sensor_drive_without_pose1() {
    // pose0 is drawn from the same streams whatever the number of sensors, and pose2 from
    // its own: adding a sensor changes no other sensor's data.
    let config = |n| DriveSimConfig {
        seed: 144,
        duration_s: 5.0,
        pose_sensors: n,
        knock_target: KnockTarget::None,
        ..DriveSimConfig::default()
    };
    let one = simulate_drive(&config(1)).expect("one");
    let two = simulate_drive(&config(2)).expect("two");
    let three = simulate_drive(&config(3)).expect("three");
    assert_eq!(one.imu, two.imu);
    assert_eq!(one.sensors[0], two.sensors[0]);
    assert_eq!(two.sensors[..], three.sensors[..2]);
    assert_ne!(three.sensors[2].t_imu_pose, three.sensors[0].t_imu_pose);
    let e = simulate_drive(&DriveSimConfig {
        knock_target: KnockTarget::Pose(3),
        ..config(3)
    })
    .expect_err("knock on a sensor the drive lacks");
    assert!(e.to_string().contains("pose3"), "{e}");
}

/// The false alarms of the monitor with ONE pose sensor (the LiDAR odometry alone) on the
/// unknocked 60 s drives of seeds 300-339 (the two-sensor study's drives without `pose1`;
/// they chose nothing): per drive, and the rate per hour of driving (docs/monitor.md, "Any
/// number of pose sensors").
#[test]
#[ignore = "acceptance: 40 drives, ~8 s release"]
fn one_pose_sensor_false_alarms_in_forty_unknocked_drives() {
    let seeds: Vec<u64> = (300..340).collect();
    let reports: Vec<_> = std::thread::scope(|scope| {
        let handles: Vec<_> = seeds
            .chunks(seeds.len().div_ceil(2))
            .map(|chunk| {
                scope.spawn(move || {
                    chunk
                        .iter()
                        .map(|&s| try_run(s, 1, KnockTarget::None).1)
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().expect("thread"))
            .collect()
    });
    let (mut total, mut no_start, mut hours) = (0, 0, 0.0);
    for (seed, r) in seeds.iter().zip(&reports) {
        match r {
            Ok(r) => {
                let alarms: Vec<_> = r.alarms.iter().map(|a| (a.t_s, a.statistic)).collect();
                println!("seed {seed}: alarms {alarms:?}");
                total += r.alarms.len();
                hours += r.duration_s / 3600.0;
            }
            Err(e) => {
                println!("seed {seed}: no start: {e}");
                assert!(e.is_no_start(), "seed {seed}: {e}");
                no_start += 1;
            }
        }
    }
    println!(
        "one pose sensor: {total} false alarms in {:.2} h ({} drives, {no_start} not started): {:.1} per hour",
        hours,
        seeds.len(),
        total as f64 / hours
    );
    assert!(total <= MAX_ONE_SENSOR_FALSE_ALARMS, "{total} false alarms");
    assert!(no_start <= 3, "no start on {no_start} drives");
}
