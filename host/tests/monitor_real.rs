//! The monitor on a real recording (issue 34, item 3): EuRoC MAV `imu_april` (real ADIS16448
//! at 200 Hz, 71.9 s, AprilGrid corners of cam0 at 20 Hz; `../shared/data/README.md`) with
//! cam0's per-frame PnP pose as ONE pose sensor (`calibrate::pnp_odometry`, MoCal's odometry) and Kalibr's
//! extrinsic as the calibration of record. Healthy: no alarm, the final estimate near the
//! record. Knocked: the poses after `t` rotated by 1 deg (the camera's mount turned), flagged
//! on the sensor within 5 s. Numbers: docs/monitor.md, "A real recording" (the healthy half
//! is met and runs by default; the knock half is not met yet: ignored, fails).

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use msreg_host::calibrate::pnp_odometry::pnp_odometry;
use msreg_host::camera_yaml::read_camera_yaml;
use msreg_host::dataset::{Dataset, ExtrinsicEstimate, PoseRecord, PoseSensorYaml};
use msreg_host::monitor::{monitor, MonitorInput, MonitorOptions, MonitorReport};
use nalgebra::{UnitQuaternion, Vector3};

#[path = "support/euroc.rs"]
mod euroc;

use euroc::{corner_frames, kalibr_t_imu_cam, SET};
/// The bounds: the healthy estimate's drift from the record (deg) and the latency
/// of a 1 deg knock (s).
const MAX_DRIFT_DEG: f64 = 0.3;
const MAX_LATENCY_S: f64 = 5.0;

struct Real {
    dataset: Dataset,
    odometry: Vec<PoseRecord>,
    pose_noise: PoseSensorYaml,
    record: ExtrinsicEstimate,
}

/// The recording with its PnP odometry; `None` (a `SKIP:` line, a panic under CI) when absent.
fn load() -> Option<Real> {
    let dir = msreg_host::shared_data::dir_or_skip(SET)?;
    let camera = read_camera_yaml(&dir.join("cam0/camera.yaml")).unwrap();
    let (odometry, pose_noise) = pnp_odometry(&camera, &corner_frames(&dir));
    // Kalibr states no sigma in the file: the record is credited with 0.1 deg / 5 mm per
    // axis (Kalibr and Basalt differ by 0.34 deg / 8 mm on this recording,
    // cli/tests/euroc_camera_imu_real.rs), and a zero time offset.
    let record = ExtrinsicEstimate {
        transform: kalibr_t_imu_cam(&dir),
        timeshift_s: 0.0,
        sigma_rot_deg: Vector3::repeat(0.1),
        sigma_trans_m: Vector3::repeat(0.005),
    };
    Some(Real {
        dataset: Dataset::open(&dir).unwrap(),
        odometry,
        pose_noise,
        record,
    })
}

/// The monitor over the real IMU and `odometry`.
fn run(real: &Real, odometry: &[PoseRecord]) -> MonitorReport {
    let input = MonitorInput {
        imu: real.dataset.require_imu().unwrap(),
        imu_noise: real.dataset.require_imu_noise().unwrap(),
        poses: vec![odometry],
        pose_noise: vec![&real.pose_noise],
        prior: vec![real.record],
    };
    monitor(&input, &MonitorOptions::default()).unwrap()
}

/// The odometry with the camera's mount turned by `angle_deg` about its own `axis` from
/// IMU time `at_s` after the first IMU sample on: every pose after it is `T_T_C * delta`.
fn knocked(real: &Real, at_s: f64, axis: Vector3<f64>, angle_deg: f64) -> Vec<PoseRecord> {
    let t0 = real.dataset.require_imu().unwrap()[0].stamp_ns;
    let at_ns = t0 + (at_s * 1e9) as u64;
    let delta = UnitQuaternion::from_scaled_axis(axis.normalize() * angle_deg.to_radians());
    real.odometry
        .iter()
        .map(|p| {
            let mut p = *p;
            if p.stamp_ns >= at_ns {
                p.rotation *= delta;
            }
            p
        })
        .collect()
}

fn alarms(r: &MonitorReport) -> Vec<(f64, &str, &str, f64)> {
    r.alarms
        .iter()
        .map(|a| (a.t_s, a.sensor, a.kind, a.statistic))
        .collect()
}

/// The healthy recording: no alarm, the final estimate within 0.3 deg of the record (the
/// issue's bounds). Measured (2026-12-02, Student-t odometry, 4 dof): 0 alarms, 0.185 deg /
/// 13.6 mm; with the Gaussian model before: 4 alarms, 0.223 deg. ~0.5 s in release.
#[test]
fn real_camera_monitor_is_quiet_when_healthy() {
    let Some(real) = &load() else {
        return;
    };
    let healthy = run(real, &real.odometry);
    let s = &healthy.sensors[0];
    let mut nis: Vec<f64> = s.nis.iter().map(|p| p.nis_per_dof).collect();
    nis.sort_by(f64::total_cmp);
    let q = |f: f64| nis[((nis.len() - 1) as f64 * f) as usize];
    println!(
        "{} PnP poses, increment noise {:.4} deg / {:.2} mm; {:.1} s; healthy: alarms {:?}, \
         warnings {}, drift {:.3} deg / {:.1} mm, accepted {} rejected {} held out {}; \
         NIS/dof quantiles 10/50/90/99 %: {:.2} {:.2} {:.2} {:.2}",
        real.odometry.len(),
        real.pose_noise.rotation_noise_rad.to_degrees(),
        real.pose_noise.translation_noise_m * 1e3,
        healthy.duration_s,
        alarms(&healthy),
        healthy.warnings.len(),
        s.rotation_change_deg,
        s.translation_change_m * 1e3,
        s.accepted,
        s.rejected,
        s.held_out,
        q(0.1),
        q(0.5),
        q(0.9),
        q(0.99),
    );
    assert!(
        healthy.alarms.is_empty(),
        "false alarm: {:?}",
        alarms(&healthy)
    );
    assert!(
        s.rotation_change_deg < MAX_DRIFT_DEG,
        "drift {:.3} deg",
        s.rotation_change_deg
    );
}

/// A 1 deg knock, flagged on the sensor within 5 s. FAILS today (2026-12-02): with the
/// Student-t odometry the knocks about y (+2.03 s) and about x+y at 25 s (+1.33 s) are
/// flagged in time, those about x (+8.48 s) and z (+7.44 s) late (docs/monitor.md, "A real
/// recording"). Ignored until then; not in the acceptance list.
#[test]
#[ignore = "fails today: knocks about x and z flagged after 8.5 s and 7.4 s (docs/monitor.md)"]
fn real_camera_monitor_flags_a_knock_within_5_s() {
    let Some(real) = &load() else {
        return;
    };
    let mut latencies = Vec::new();
    for (at_s, axis) in [
        (40.0, Vector3::x()),
        (40.0, Vector3::y()),
        (40.0, Vector3::z()),
        (25.0, Vector3::new(1.0, 1.0, 0.0)),
    ] {
        let r = run(real, &knocked(real, at_s, axis, 1.0));
        let first = r.first_alarm_after("pose0", 0.0).map(|a| a.t_s - at_s);
        println!(
            "knock 1 deg about {:?} at {at_s} s: first alarm {first:?} s after; alarms {:?}; \
             final {:.3} deg from the record",
            axis.as_slice(),
            alarms(&r),
            r.sensors[0].rotation_change_deg
        );
        latencies.push(first);
    }
    for l in &latencies {
        let l = l.expect("knock not flagged");
        assert!((0.0..=MAX_LATENCY_S).contains(&l), "flagged {l:.2} s after");
    }
}
