//! `msreg calibrate camera-imu` on a two-camera rig as a user meets it (issue 32): `msreg
//! simulate camera-imu --cameras 2` renders a stereo-like pair, the calibration detects both
//! cameras' boards and fuses them in one filter, the result file carries `cam0`, `cam1` and
//! `cam1.T_cn_cnm1`, and `msreg eval` scores all three against the ground truth. A gap in the
//! camera folders is exit code 2 naming it.

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use serde_json::Value;

#[path = "support/run.rs"]
mod run;
use run::{msreg, ok};

/// A two-camera recording of `duration` s (seed 5, camera 0 at -4 ms, camera 1 at -1 ms).
fn simulate(dir: &Path, duration: &str) -> String {
    let data = dir.join("ds");
    let data_s = data.to_str().unwrap().to_string();
    ok(&msreg(&[
        "simulate",
        "camera-imu",
        &data_s,
        "--seed",
        "5",
        "--duration",
        duration,
        "--cameras",
        "2",
        "--time-offset-ms",
        "-4",
    ]));
    data_s
}

#[test]
fn a_simulated_stereo_rig_is_calibrated_in_one_filter_and_scored() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulate(dir.path(), "5");
    let result = dir.path().join("result.yaml");
    let report = dir.path().join("report.json");
    ok(&msreg(&[
        "calibrate",
        "camera-imu",
        &data,
        "-o",
        result.to_str().unwrap(),
        "--report",
        report.to_str().unwrap(),
    ]));
    let eval = msreg(&["eval", result.to_str().unwrap(), &data, "--json"]);
    ok(&eval);
    let scored: Value = serde_json::from_slice(&eval.stdout).unwrap();
    let scored = scored.as_array().unwrap();
    let names: Vec<&str> = scored
        .iter()
        .map(|s| s["section"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["cam0", "cam1", "cam1.T_cn_cnm1"]);
    // Seed 5, 5 s, 99 rendered images per camera (measured): cam0 0.0092 deg / 0.37 mm,
    // cam1 0.0082 deg / 0.35 mm, the chain 0.0011 deg / 0.02 mm; time offsets within
    // 0.005 ms; everything inside 3 sigma.
    for (s, (max_deg, max_mm)) in scored.iter().zip([(0.03, 1.2), (0.03, 1.2), (0.004, 0.06)]) {
        let (deg, mm) = (
            s["rotation_deg"].as_f64().unwrap(),
            s["translation_m"].as_f64().unwrap() * 1e3,
        );
        assert!(deg < max_deg && mm < max_mm, "{s}");
        assert!(s["within_3_sigma"].as_bool().unwrap(), "{s}");
    }
    for s in &scored[..2] {
        assert!(s["time_offset_s"].as_f64().unwrap().abs() < 0.015e-3, "{s}");
    }
    // The report lists both cameras (their detections and fused images) and the chain.
    let report: Value = serde_json::from_str(&std::fs::read_to_string(report).unwrap()).unwrap();
    let cameras = report["cameras"].as_array().unwrap();
    assert_eq!(cameras.len(), 2);
    for (n, c) in cameras.iter().enumerate() {
        assert_eq!(c["name"], format!("cam{n}"));
        assert_eq!(c["detection"]["detected"], 99, "{}", c["detection"]);
        assert_eq!(c["updates_accepted"], 99);
        let held = c["verification_reprojection_error_px"].as_f64().unwrap();
        // Measured 0.050 and 0.047 px.
        assert!(held > 0.0 && held < 0.15, "cam{n}: {held} px");
    }
    assert_eq!(report["chain"][0]["name"], "cam1.T_cn_cnm1");
    // The chain's sigmas in the report are the result file's (the written, honest ones).
    let yaml: serde_yaml::Value =
        serde_yaml::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
    for (report_key, yaml_key) in [
        ("sigma_rot_deg", "sigma_rot_deg_cn_cnm1"),
        ("sigma_trans_m", "sigma_trans_m_cn_cnm1"),
    ] {
        let reported = report["chain"][0][report_key].as_array().unwrap();
        let written = yaml["cam1"][yaml_key].as_sequence().unwrap();
        for (r, w) in reported.iter().zip(written) {
            let (r, w) = (r.as_f64().unwrap(), w.as_f64().unwrap());
            assert!((r - w).abs() <= 1e-12 * w.abs(), "{report_key}: {r} vs {w}");
        }
    }
}

#[test]
fn a_gap_in_the_camera_folders_is_exit_code_2_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let data = simulate(dir.path(), "1");
    std::fs::rename(Path::new(&data).join("cam1"), Path::new(&data).join("cam2")).unwrap();
    let out = msreg(&["calibrate", "camera-imu", &data, "-o", "/dev/null"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("cam1 is missing"), "{err}");
}
