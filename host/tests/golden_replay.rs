//! Golden replay: a fixed simulated recording through the f64 pose-IMU pipeline, compared
//! with the committed output. Any change of the filter's numbers then shows up as a failing
//! test and goes in as a deliberate commit: `MSREG_BLESS=1 cargo test --release --test
//! golden_replay` rewrites the golden file.

#[path = "support/common.rs"]
mod common;

use std::path::PathBuf;

use msreg_host::calibrate::driver::report::PoseImuOptions;
use msreg_host::sim::SimConfig;
use serde_json::{json, Value};

fn golden_path() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/golden/pose_imu_seed42.json")
}

/// The replay's output: final extrinsic, time offset, sigmas and the per-update NIS.
fn replay() -> Value {
    let mut config = SimConfig {
        seed: 42,
        duration_s: 20.0,
        ..SimConfig::default()
    };
    config.pose.time_offset_s = 0.008;
    let data = common::simulate(&config);
    let c = common::calibrate::<f64>(&data, &PoseImuOptions::default());
    let q = c.t_imu_sensor.rotation.quaternion();
    let t = c.t_imu_sensor.translation.vector;
    json!({
        "q_wxyz": [q.w, q.i, q.j, q.k],
        "p": [t.x, t.y, t.z],
        "time_offset_s": c.time_offset_s,
        "covariance_diagonal": (0..6).map(|i| c.covariance[(i, i)]).collect::<Vec<_>>(),
        "nis": c.report.history.iter().map(|h| h.nis).collect::<Vec<_>>(),
        "accepted": c.report.updates_accepted,
    })
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

#[test]
fn pose_imu_replay_matches_the_golden_output() {
    let output = replay();
    let path = golden_path();
    if std::env::var_os("MSREG_BLESS").is_some() {
        let text = serde_json::to_string_pretty(&output).expect("json");
        std::fs::write(&path, text + "\n").expect("write golden file");
        println!("blessed {}", path.display());
        return;
    }
    let golden: Value = serde_json::from_str(&std::fs::read_to_string(&path).expect("golden file"))
        .expect("golden json");
    // Same code, same machine kind: only the last bits of libm and summation order may
    // differ, so 1e-9 relative leaves room for those and nothing else.
    let diff = max_relative_difference(&output, &golden).expect("same structure");
    assert!(
        diff < 1e-9,
        "replay differs from {} by {diff:e} (relative); bless deliberate changes",
        path.display()
    );
}
