//! Golden replays: fixed simulated recordings through the f64 pose-IMU, camera-IMU
//! (RepErrCal) and LiDAR-IMU pipelines, each compared with its committed output. Any change
//! of the filter's numbers then shows up as a failing test and goes in as a deliberate
//! commit: `MSREG_BLESS=1 cargo test --release --test golden_replay` rewrites the golden
//! files.

#[path = "support/common.rs"]
mod common;
#[path = "support/corners.rs"]
mod corners;

use std::path::PathBuf;

use msreg_host::calibrate::camera_imu::{self, CameraImuInput, CameraImuOptions, CameraUpdate};
use msreg_host::calibrate::driver::report::PoseImuOptions;
use msreg_host::calibrate::extrinsic::ImuExtrinsicCalibration;
use msreg_host::calibrate::lidar_imu::{self, LidarImuInput, LidarImuOptions};
use msreg_host::sim::{
    simulate_camera_imu, simulate_lidar_imu, CameraImuSimConfig, LidarImuSimConfig, LidarSimConfig,
    SimConfig,
};
use serde_json::{json, Value};

fn golden_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("tests/golden/{name}.json"))
}

/// The numbers every replay pins: extrinsic, time offset, sigmas, and the per-update NIS.
fn pinned<R>(c: &ImuExtrinsicCalibration<R>, nis: Vec<f64>, accepted: usize) -> Value {
    let q = c.t_imu_sensor.rotation.quaternion();
    let t = c.t_imu_sensor.translation.vector;
    json!({
        "q_wxyz": [q.w, q.i, q.j, q.k],
        "p": [t.x, t.y, t.z],
        "time_offset_s": c.time_offset_s,
        "covariance_diagonal": (0..6).map(|i| c.covariance[(i, i)]).collect::<Vec<_>>(),
        "nis": nis,
        "accepted": accepted,
    })
}

/// RepErrCal over 10 s of the camera-IMU simulator (seed 42, 0.1 px corner noise).
fn camera_imu_replay() -> Value {
    let config = CameraImuSimConfig {
        seed: 42,
        duration_s: 10.0,
        time_offset_s: 0.006,
        ..CameraImuSimConfig::default()
    };
    let sim = simulate_camera_imu(&config).expect("valid simulation config");
    let frames = corners::noisy_corner_frames(&sim, 0.1, 42);
    let input = CameraImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        camera: &sim.config.camera,
        frames: &frames,
    };
    let options = CameraImuOptions {
        update: CameraUpdate::Reprojection,
        ..CameraImuOptions::default()
    };
    let c = camera_imu::calibrate::<f64>(&input, &options, &mut |_| {}).expect("runs");
    let f = &c.report.filter;
    pinned(
        &c,
        f.history.iter().map(|h| h.nis).collect(),
        f.updates_accepted,
    )
}

/// LiDAR-IMU over 8 s of the LiDAR-IMU simulator (seed 42, 16 x 360 beams): the relative-pose
/// stream of NDT increments.
fn lidar_imu_replay() -> Value {
    let config = LidarImuSimConfig {
        seed: 42,
        duration_s: 8.0,
        lidar: LidarSimConfig {
            rings: 16,
            columns: 360,
            time_offset_s: -0.004,
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    };
    let sim = simulate_lidar_imu(&config).expect("valid simulation");
    let input = LidarImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        scans: &sim,
    };
    let c = lidar_imu::calibrate::<f64>(&input, &LidarImuOptions::default(), &mut |_| {})
        .expect("runs");
    let f = &c.report.filter;
    pinned(
        &c,
        f.history.iter().map(|h| h.nis).collect(),
        f.updates_accepted,
    )
}

/// The pose-IMU replay's output: final extrinsic, time offset, sigmas and the per-update NIS.
fn pose_imu_replay() -> Value {
    let mut config = SimConfig {
        seed: 42,
        duration_s: 20.0,
        ..SimConfig::default()
    };
    config.pose.time_offset_s = 0.008;
    let data = common::simulate(&config);
    let c = common::calibrate::<f64>(&data, &PoseImuOptions::default());
    let nis = c.report.history.iter().map(|h| h.nis).collect();
    pinned(&c, nis, c.report.updates_accepted)
}

/// Relative difference of every number, flattening nested arrays.
fn max_relative_difference(a: &Value, b: &Value) -> Option<f64> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64()?, y.as_f64()?);
            Some((x - y).abs() / (1e-12 + x.abs().max(y.abs())))
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .map(|(a, b)| max_relative_difference(a, b))
            .try_fold(0.0f64, |m, d| Some(m.max(d?))),
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => x
            .iter()
            .map(|(k, a)| max_relative_difference(a, y.get(k)?))
            .try_fold(0.0f64, |m, d| Some(m.max(d?))),
        _ => None,
    }
}

/// Compares `output` with the golden file `name` (or rewrites it under `MSREG_BLESS`).
fn check(name: &str, output: &Value) {
    let path = golden_path(name);
    if std::env::var_os("MSREG_BLESS").is_some() {
        let text = serde_json::to_string_pretty(output).expect("json");
        std::fs::write(&path, text + "\n").expect("write golden file");
        println!("blessed {}", path.display());
        return;
    }
    let golden: Value = serde_json::from_str(&std::fs::read_to_string(&path).expect("golden file"))
        .expect("golden json");
    // Same code, same machine kind: only the last bits of libm and summation order may
    // differ, so 1e-9 relative leaves room for those and nothing else.
    let diff = max_relative_difference(output, &golden).expect("same structure");
    assert!(
        diff < 1e-9,
        "replay differs from {} by {diff:e} (relative); bless deliberate changes",
        path.display()
    );
}

#[test]
fn pose_imu_replay_matches_the_golden_output() {
    check("pose_imu_seed42", &pose_imu_replay());
}

#[test]
fn camera_imu_replay_matches_the_golden_output() {
    check("camera_imu_seed42", &camera_imu_replay());
}

#[test]
fn lidar_imu_replay_matches_the_golden_output() {
    check("lidar_imu_seed42", &lidar_imu_replay());
}
