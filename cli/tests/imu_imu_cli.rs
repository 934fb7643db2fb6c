//! `msreg calibrate imu-imu` as a user meets it (issue 32): `msreg simulate imu-imu --imus 3`
//! writes a rig of three IMUs, the calibration writes `imu1` and `imu2` against `imu0`, and
//! `msreg eval` scores both against the ground truth. A dataset with no second IMU is exit
//! code 2 naming it.

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use serde_json::Value;

#[path = "support/run.rs"]
mod run;
use run::{msreg, ok};

#[test]
fn a_simulated_three_imu_rig_is_calibrated_and_scored() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("rig");
    let data = data.to_str().unwrap();
    ok(&msreg(&[
        "simulate", "imu-imu", data, "--imus", "3", "--seed", "7",
    ]));
    let result = dir.path().join("result.yaml");
    let report = dir.path().join("report.json");
    let out = msreg(&[
        "calibrate",
        "imu-imu",
        data,
        "-o",
        result.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]);
    ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("imu1: rotation") && stdout.contains("imu2: rotation"));
    let eval = msreg(&["eval", result.to_str().unwrap(), data, "--json"]);
    ok(&eval);
    let scored: Value = serde_json::from_slice(&eval.stdout).unwrap();
    let scored = scored.as_array().unwrap();
    let names: Vec<&str> = scored
        .iter()
        .map(|s| s["section"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["imu1", "imu2"]);
    // Bounds of host/tests/imu_imu.rs (~3x the worst of its 11 runs: 0.0029 deg, 0.21 mm,
    // 0.0035 ms).
    for s in scored {
        let deg = s["rotation_deg"].as_f64().unwrap();
        let mm = s["translation_m"].as_f64().unwrap() * 1e3;
        let ms = s["time_offset_s"].as_f64().unwrap().abs() * 1e3;
        assert!(deg < 0.01 && mm < 0.6 && ms < 0.011, "{s}");
        assert!(s["within_3_sigma"].as_bool().unwrap(), "{s}");
    }
    // The report has a row per IMU with the same numbers' sigmas.
    let rows: Value = serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    let rows = rows["imus"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for (n, row) in rows.iter().enumerate() {
        assert_eq!(row["sensor"], format!("imu{}", n + 1));
        assert!(row["held"].as_array().unwrap().is_empty());
        assert!(row["sigma_timeshift_s"].as_f64().unwrap() > 0.0);
    }
}

#[test]
fn a_dataset_without_a_second_imu_is_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("rig");
    let data_s = data.to_str().unwrap();
    ok(&msreg(&["simulate", "imu-imu", data_s, "--duration", "3"]));
    std::fs::remove_dir_all(data.join("imu1")).unwrap();
    let out = msreg(&["calibrate", "imu-imu", data_s]);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no second IMU"), "{stderr}");
}
