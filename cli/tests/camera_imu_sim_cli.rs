//! `msreg simulate camera-imu` end to end: the written dataset feeds `msreg detect
//! checkerboard` directly (target.yaml, camera.yaml, images), and bad options are exit code 2.

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::{Command, Output};

use msreg_host::dataset::{read_camera_csv, CalibrationResult};

fn msreg(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap()
}

#[test]
fn simulated_camera_dataset_feeds_the_detector_cli() {
    let dir = tempfile::tempdir().unwrap();
    let out = msreg(
        &[
            "simulate",
            "camera-imu",
            "data",
            "--seed",
            "3",
            "--duration",
            "1.5",
            "--blur",
            "--noise",
            "--time-offset-ms",
            "-3",
            "--model",
            "pinhole-equidistant",
        ],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let data = dir.path().join("data");
    let truth = CalibrationResult::read(data.join("groundtruth/extrinsics.yaml")).unwrap();
    let cam0 = *truth.get("cam0").unwrap();
    assert!((cam0.timeshift_s + 0.003).abs() < 1e-15);
    assert!(std::fs::read_to_string(data.join("cam0/camera.yaml"))
        .unwrap()
        .contains("equidistant"));
    let frames = read_camera_csv(data.join("cam0/data.csv")).unwrap();
    assert_eq!(frames.len(), 29);
    let image = frames[5].path.to_str().unwrap();
    let out = msreg(
        &[
            "detect",
            "checkerboard",
            image,
            "--target",
            "data/target.yaml",
            "--camera",
            "data/cam0/camera.yaml",
        ],
        dir.path(),
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let csv = String::from_utf8(out.stdout).unwrap();
    assert_eq!(csv.lines().count(), 1 + 42, "{csv}");
}

#[test]
fn bad_simulation_options_are_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (vec!["--rate-hz", "0"], "rate_hz"),
        (vec!["--time-offset-ms", "500"], "time_offset_s"),
        (vec!["--duration", "0.1"], "duration"),
        (vec!["--model", "fisheye62"], "fisheye62"),
    ] {
        let mut all = vec!["simulate", "camera-imu", "out"];
        all.extend(args.iter());
        let out = msreg(&all, dir.path());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}
