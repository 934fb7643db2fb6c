//! HIL of the monitoring layout (issue 13, items 4-5): a simulated drive (`msreg simulate
//! drive`) replayed by `msreg link replay` to the link firmware's `MonitorEkf<f32>`, against
//! `msreg monitor`'s f64 run on the same files.
//!
//! Seeds: 120 (camera knocked at 30 s) and 121 (unknocked) are those of the host's default
//! monitor test (`host/tests/monitor_drive.rs`); 100-109 its acceptance seeds. No constant
//! here or in the monitor was chosen on them (the monitor's were chosen on seeds 1-8).

use std::time::{Duration, Instant};

use msreg_hil_tests::Qemu;
use msreg_host::link::{replay, summary, ReplayOptions, ReplayOutcome};
use msreg_host::monitor::DriveFiles;
use msreg_host::monitor::{monitor, MonitorOptions, MonitorReport};
use msreg_host::sim::{simulate_drive, DriveSimConfig, KnockTarget};
use msreg_protocol::{AlarmKind, Estimate, HealthState, UpdateKind};

use crate::common::{boot, isometry, ram_after_session, RAM_TARGET_BYTES};

/// Knock time of the drive scenario, s.
const KNOCK_AT_S: f64 = 30.0;
/// The bound on the detection latency, s.
const MAX_LATENCY_S: f64 = 5.0;
/// Device (f32) against `msreg monitor` (f64), final extrinsics: the bound.
const AGREE_DEG: f64 = 0.02;
/// See [`AGREE_DEG`], mm.
const AGREE_MM: f64 = 1.0;

/// One drive on the device and on the host.
pub struct DriveRun {
    /// What the device sent.
    pub outcome: ReplayOutcome,
    /// `msreg monitor` on the same files.
    pub host: MonitorReport,
    /// Wall time of the device replay, s.
    pub replay_s: f64,
    /// The QEMU that ran it (its log and RAM line).
    pub qemu: Qemu,
    /// IMU samples of the drive.
    pub imu_samples: usize,
}

/// Simulates drive `seed` (knocking `target` at 30 s), replays it to a fresh device and runs
/// the host monitor on the same files.
pub fn drive(seed: u64, target: KnockTarget) -> DriveRun {
    let sim = simulate_drive(&DriveSimConfig {
        seed,
        knock_target: target,
        knock_at_s: KNOCK_AT_S,
        ..DriveSimConfig::default()
    })
    .expect("simulate");
    let dir = tempfile::tempdir().expect("temp dir");
    sim.write(dir.path()).expect("dataset written");
    let files = DriveFiles::read(dir.path(), None).expect("drive files");
    let host =
        monitor(&files.input().expect("input"), &MonitorOptions::default()).expect("host monitor");
    let qemu = boot();
    let started = Instant::now();
    let outcome =
        replay(dir.path(), &qemu.pty, None, &ReplayOptions::default()).expect("replay runs");
    let replay_s = started.elapsed().as_secs_f64();
    println!(
        "seed {seed}: device replay {replay_s:.1} s\n{}",
        summary(&outcome.collected, outcome.status.as_ref())
    );
    DriveRun {
        outcome,
        host,
        replay_s,
        qemu,
        imu_samples: sim.imu.len(),
    }
}

/// The device's last estimate of sensor `s`.
fn last_of(run: &DriveRun, s: u8) -> Estimate {
    run.outcome
        .collected
        .estimates
        .iter()
        .rev()
        .find(|(_, e)| e.sensor == s)
        .unwrap_or_else(|| panic!("no estimate of sensor {s}"))
        .1
}

/// Device alarms as (IMU time s after the start, sensor, kind), the stamp moved by the
/// device's final time offset of that sensor.
pub fn device_alarms(run: &DriveRun) -> Vec<(f64, u8, AlarmKind)> {
    let start = run.outcome.start_ns as f64;
    run.outcome
        .collected
        .alarms
        .iter()
        .map(|(_, a)| {
            let td = f64::from(last_of(run, a.sensor).time_offset_s);
            ((a.stamp_ns as f64 - start) * 1e-9 + td, a.sensor, a.kind)
        })
        .collect()
}

/// The session ran clean: every IMU sample, every update the host made, no fault.
fn check_session(run: &DriveRun) {
    let status = run.outcome.status.expect("device status");
    assert_eq!(status.imu_samples as usize, run.imu_samples);
    assert_eq!(
        status.errors.iter().sum::<u32>(),
        0,
        "faults: {:?}",
        status.errors
    );
    for (s, sensor) in run.host.sensors.iter().enumerate() {
        let device = run
            .outcome
            .collected
            .diagnostics
            .iter()
            .filter(|(_, d)| d.kind == UpdateKind::RelativePose && d.sensor == Some(s as u8))
            .count();
        assert_eq!(
            device,
            sensor.accepted + sensor.rejected + sensor.held_out,
            "{}: device updates {device}, host {} + {} + {} held out",
            sensor.name,
            sensor.accepted,
            sensor.rejected,
            sensor.held_out
        );
    }
}

/// Final extrinsic and time offset of each sensor, device against host: (deg, mm, ms).
pub fn agreement(run: &DriveRun) -> [(f64, f64, f64); 2] {
    core::array::from_fn(|s| {
        let device = last_of(run, s as u8);
        let d = isometry(&device);
        let h = &run.host.sensors[s].estimate;
        (
            d.rotation.angle_to(&h.transform.rotation).to_degrees(),
            (d.translation.vector - h.transform.translation.vector).norm() * 1e3,
            (f64::from(device.time_offset_s) - h.timeshift_s) * 1e3,
        )
    })
}

fn check_agreement(run: &DriveRun) {
    let a = agreement(run);
    println!(
        "device vs host f64 (deg, mm, ms) pose0 {:?}, pose1 {:?}",
        a[0], a[1]
    );
    for (s, (deg, mm, _)) in a.iter().enumerate() {
        assert!(
            *deg <= AGREE_DEG && *mm <= AGREE_MM,
            "pose{s}: device {deg:.4} deg, {mm:.3} mm from the host (bound {AGREE_DEG} deg, {AGREE_MM} mm)"
        );
    }
}

fn check_ram(run: &DriveRun) {
    let (statics, stack, total) = ram_after_session(&run.qemu);
    println!("monitoring layout RAM: static {statics} B + stack {stack} B = {total} B");
    assert_eq!(total, statics + stack);
    assert!(
        total < RAM_TARGET_BYTES,
        "RAM {total} B >= {RAM_TARGET_BYTES} B"
    );
}

#[test]
fn drive_camera_knock_is_flagged_on_the_camera_by_the_device_within_five_seconds() {
    // Given a drive whose camera (pose1) is knocked by 1 deg at 30 s, replayed to the device
    let run = drive(120, KnockTarget::Pose1);
    check_session(&run);
    // Then the device's first alarm is a rotation step of the camera within 5 s of the knock
    let alarms = device_alarms(&run);
    let host: Vec<_> = run
        .host
        .alarms
        .iter()
        .map(|a| (a.t_s, a.sensor, a.kind))
        .collect();
    println!("device alarms {alarms:?}; host alarms {host:?}");
    let &(t, sensor, kind) = alarms.first().expect("the device must raise an alarm");
    assert_eq!((sensor, kind), (1, AlarmKind::RotationStep), "{alarms:?}");
    assert!(
        (KNOCK_AT_S..=KNOCK_AT_S + MAX_LATENCY_S).contains(&t),
        "first alarm at {t:.2} s, knock at {KNOCK_AT_S} s"
    );
    // and never the LiDAR (pose0): its estimates stay nominal, the camera's report the alarm
    assert!(alarms.iter().all(|a| a.1 == 1), "{alarms:?}");
    assert_eq!(last_of(&run, 0).health, HealthState::Nominal);
    assert_eq!(last_of(&run, 1).health, HealthState::Alarm);
    // at the update where the host's f64 monitor raised it (camera updates are 50 ms apart;
    // the times differ only by the final against the then-current t_d)
    let first_host = run
        .host
        .alarms
        .first()
        .expect("the host flags the knock too");
    assert_eq!(first_host.sensor, "pose1");
    assert!(
        (first_host.t_s - t).abs() < 0.01,
        "host {first_host:?}, device {t:.3} s"
    );
    // and it logged the alarm and stayed within 64 KiB of RAM
    let logged = run
        .qemu
        .wait_for_log("health alarm", 1, Duration::from_secs(5));
    assert!(!logged.is_empty(), "no alarm in the device log");
    assert!(
        run.qemu.undecodable_log_frames().is_empty(),
        "{:?}",
        run.qemu.undecodable_log_frames()
    );
    check_ram(&run);
}

#[test]
fn drive_without_knock_raises_no_alarm_and_device_matches_host_monitor() {
    // Given an unknocked drive replayed to the device
    let run = drive(121, KnockTarget::None);
    check_session(&run);
    // Then no alarm, as on the host
    let alarms = device_alarms(&run);
    assert!(alarms.is_empty(), "false alarm on the device: {alarms:?}");
    assert!(run.host.alarms.is_empty(), "{:?}", run.host.alarms);
    // and the device's final estimates of both sensors match msreg monitor's f64 run
    check_agreement(&run);
    check_ram(&run);
}

#[test]
#[ignore = "acceptance: 10 unknocked drives through QEMU, several minutes each"]
fn no_alarm_on_the_device_in_ten_unknocked_drives() {
    let mut failures = Vec::new();
    for seed in 100..110 {
        let run = drive(seed, KnockTarget::None);
        check_session(&run);
        let alarms = device_alarms(&run);
        let a = agreement(&run);
        println!(
            "seed {seed}: device alarms {alarms:?}, host alarms {}; device vs host (deg, mm, ms) {a:?}; replay {:.0} s",
            run.host.alarms.len(),
            run.replay_s
        );
        if !alarms.is_empty() {
            failures.push((seed, alarms));
        }
    }
    assert!(failures.is_empty(), "false alarms: {failures:?}");
}
