//! Camera-IMU calibration on a real recording: EuRoC MAV `imu_april` (real ADIS16448 at
//! 200 Hz, 1416 images of AprilGrid corners at 20 Hz, no standstill at the start; see
//! `../shared/data/README.md`), judged against EuRoC's published Kalibr calibration.
//!
//! Measured (docs/camera_imu.md, "EuRoC"): RepErrCal 0.144 deg / 7.8 mm from Kalibr, time
//! offset -0.011 ms, mean NIS/dof 0.93, every image fused; the second half of the recording
//! alone (a start in its fastest part) within 0.04 deg / 0.9 mm of the full run;
//! MoCal 0.255 deg / 10.8 mm since the constant-extrinsic pass of pose-IMU (docs/pose-imu.md;
//! the bounds were set at 0.59 deg / 60 mm before it). The bounds below are 1.5-2x those,
//! and the 0.5-2 NIS band.
//!
//! A second, independent reference: Basalt's own calibration of the same recording
//! (`data/euroc_ds_calib.json` of github.com/VladyslavUsenko/basalt, BSD-3; double-sphere
//! camera model, spline-based batch; its fitted gyro bias [-0.0022, 0.0244, 0.0767] rad/s
//! is msreg's [-0.0017, 0.0247, 0.0772] within 0.6 mrad/s, so it is this recording). Kalibr
//! and Basalt disagree by 0.34 deg / 8.0 mm; msreg's lever arm is 1.0 mm from Basalt's
//! (bound 3 mm) and its rotation 0.23 deg from Basalt's (bound 0.7 deg: the two camera
//! models place the optical axis differently).
//!
//! The written sigmas (model error of the time blocks, issue 34) are asserted to be the
//! report's and at least the filter's; the halves' agreement within them is
//! `host/tests/camera_imu_real_halves.rs`.
//!
//! Skips with a notice when `../shared` is absent (a fresh clone).

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::Command;

use nalgebra::{Isometry3, Matrix4, Rotation3, Translation3, UnitQuaternion};

const SET: &str = "real/euroc-imu-april-cam0";

/// `T_cam_imu` read from a result file or the reference (`cam0: T_cam_imu: 4x4 rows`).
fn t_cam_imu(path: &Path) -> Isometry3<f64> {
    let doc: serde_yaml::Value = serde_yaml::from_str(&std::fs::read_to_string(path).unwrap())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let rows = doc["cam0"]["T_cam_imu"].as_sequence().unwrap();
    let m = Matrix4::from_fn(|r, c| rows[r][c].as_f64().unwrap());
    let rotation = Rotation3::from_matrix_unchecked(m.fixed_view::<3, 3>(0, 0).into_owned());
    Isometry3::from_parts(
        Translation3::from(m.fixed_view::<3, 1>(0, 3).into_owned()),
        UnitQuaternion::from_rotation_matrix(&rotation),
    )
}

/// Rotation (deg) and lever-arm (m, the camera's position in the IMU frame) differences.
fn difference(estimate: &Isometry3<f64>, reference: &Isometry3<f64>) -> (f64, f64) {
    let rotation = estimate.rotation.angle_to(&reference.rotation).to_degrees();
    let lever = |t: &Isometry3<f64>| t.inverse().translation.vector;
    (rotation, (lever(estimate) - lever(reference)).norm())
}

/// Basalt's `T_imu_cam` of cam0 on this recording (quaternion x, y, z, w; position, m).
const BASALT_Q_IMU_CAM: [f64; 4] = [
    -0.007239825785317818,
    0.007541278561558601,
    0.7017845426564943,
    0.7123125505904486,
];
const BASALT_P_IMU_CAM: [f64; 3] = [
    -0.016774788924641534,
    -0.068938940687127,
    0.005139123188382424,
];

/// Basalt's calibration as `T_cam_imu`.
fn basalt_t_cam_imu() -> Isometry3<f64> {
    let [x, y, z, w] = BASALT_Q_IMU_CAM;
    let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
    let [px, py, pz] = BASALT_P_IMU_CAM;
    Isometry3::from_parts(Translation3::new(px, py, pz), q).inverse()
}

struct Run {
    exit: i32,
    t_cam_imu: Isometry3<f64>,
    time_offset_s: f64,
    /// The result file's `sigma_rot_deg` and `sigma_trans_m`.
    sigma_rot_deg: [f64; 3],
    sigma_trans_m: [f64; 3],
    report: serde_json::Value,
}

/// Three numbers of a YAML or JSON sequence.
fn triple(v: impl Fn(usize) -> Option<f64>) -> [f64; 3] {
    std::array::from_fn(|i| v(i).unwrap())
}

fn calibrate(dataset: &Path, update: &str, out: &Path) -> Run {
    let result = out.join(format!("{update}.yaml"));
    let report = out.join(format!("{update}.json"));
    let status = Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(["calibrate", "camera-imu", "--update", update, "-o"])
        .arg(&result)
        .arg("--report")
        .arg(&report)
        .arg(dataset)
        .status()
        .unwrap();
    let doc: serde_yaml::Value =
        serde_yaml::from_str(&std::fs::read_to_string(&result).unwrap()).unwrap();
    Run {
        exit: status.code().unwrap_or(-1),
        t_cam_imu: t_cam_imu(&result),
        time_offset_s: doc["cam0"]["timeshift_cam_imu"].as_f64().unwrap(),
        sigma_rot_deg: triple(|i| doc["cam0"]["sigma_rot_deg"][i].as_f64()),
        sigma_trans_m: triple(|i| doc["cam0"]["sigma_trans_m"][i].as_f64()),
        report: serde_json::from_str(&std::fs::read_to_string(&report).unwrap()).unwrap(),
    }
}

fn nis_per_dof(run: &Run) -> f64 {
    run.report["mean_nis_per_dof"].as_f64().unwrap()
}

/// The recording from `from_s` on (s after its first IMU sample), as a dataset in `dir`.
fn cut(source: &Path, from_s: f64, dir: &Path) -> PathBuf {
    let first_imu = std::fs::read_to_string(source.join("imu0/data.csv"))
        .unwrap()
        .lines()
        .find(|l| !l.starts_with('#'))
        .and_then(|l| l.split(',').next()?.parse::<u64>().ok())
        .unwrap();
    let from_ns = first_imu + (from_s * 1e9) as u64;
    for file in ["imu0/data.csv", "cam0/corners.csv"] {
        let text = std::fs::read_to_string(source.join(file)).unwrap();
        let kept: String = text
            .lines()
            .filter(|l| {
                l.starts_with('#')
                    || l.split(',').next().and_then(|t| t.parse::<u64>().ok()) >= Some(from_ns)
            })
            .map(|l| format!("{l}\n"))
            .collect();
        std::fs::create_dir_all(dir.join(file).parent().unwrap()).unwrap();
        std::fs::write(dir.join(file), kept).unwrap();
    }
    for file in ["imu0/imu.yaml", "cam0/camera.yaml", "target.yaml"] {
        std::fs::copy(source.join(file), dir.join(file)).unwrap();
    }
    dir.to_path_buf()
}

#[test]
#[ignore = "real-data acceptance: three CLI calibrations, RepErrCal with its time blocks; 11 s"]
fn euroc_imu_april_matches_kalibr() {
    let Some(dir) = msreg_host::shared_data::dir_or_skip(SET) else {
        return;
    };
    let reference = {
        // groundtruth/extrinsics.yaml has the result file's `cam0: T_cam_imu` shape.
        t_cam_imu(&dir.join("groundtruth/extrinsics.yaml"))
    };
    let out = tempfile::tempdir().unwrap();

    let full = calibrate(&dir, "reprojection", out.path());
    let (rotation, lever) = difference(&full.t_cam_imu, &reference);
    println!(
        "RepErrCal: {rotation:.3} deg, {:.1} mm from Kalibr, t_d {:.3} ms, NIS/dof {:.2}",
        lever * 1e3,
        full.time_offset_s * 1e3,
        nis_per_dof(&full)
    );
    assert_eq!(
        full.exit, 0,
        "RepErrCal must converge: {}",
        full.report["reasons"]
    );
    assert!(rotation < 0.25, "rotation {rotation} deg from Kalibr");
    assert!(lever < 0.012, "lever arm {lever} m from Kalibr");
    // The second reference: Basalt on the same recording, 0.34 deg / 8.0 mm from Kalibr.
    let (rotation, lever) = difference(&full.t_cam_imu, &basalt_t_cam_imu());
    let (between_r, between_t) = difference(&basalt_t_cam_imu(), &reference);
    println!(
        "RepErrCal: {rotation:.3} deg, {:.1} mm from Basalt (Basalt vs Kalibr: {between_r:.3} deg, {:.1} mm)",
        lever * 1e3,
        between_t * 1e3
    );
    assert!(lever < 0.003, "lever arm {lever} m from Basalt");
    assert!(rotation < 0.7, "rotation {rotation} deg from Basalt");
    // EuRoC's camera and IMU are hardware-synchronised.
    assert!(
        full.time_offset_s.abs() < 0.5e-3,
        "{} s",
        full.time_offset_s
    );
    assert!((0.5..2.0).contains(&nis_per_dof(&full)));
    assert_eq!(full.report["updates_rejected"].as_u64(), Some(0));
    assert_eq!(full.report["events"].as_array().map(Vec::len), Some(0));
    assert!(full.report["gyro_bias_init"]
        .as_str()
        .unwrap()
        .starts_with("fitted"));

    // The result file holds the model error's sigmas (issue 34): the report's written ones,
    // never below the filter's. Measured: filter 0.003 deg / 0.07-0.09 mm, written
    // [0.029, 0.029, 0.015] deg, [0.46, 0.47, 0.25] mm (12 blocks).
    let m = &full.report["model_error"];
    let json = |key: &str| triple(|i| m[key][i].as_f64());
    // (serde_json's float parser is not correctly rounded: within 1e-12.)
    let same = |a: [f64; 3], b: [f64; 3]| (0..3).all(|i| (a[i] - b[i]).abs() <= 1e-12 * a[i]);
    assert!(same(full.sigma_rot_deg, json("sigma_rot_deg")), "{m}");
    assert!(same(full.sigma_trans_m, json("sigma_trans_m")), "{m}");
    assert_eq!(m["blocks_used"].as_u64(), Some(12), "{m}");
    for i in 0..3 {
        assert!(json("sigma_rot_deg")[i] >= json("filter_sigma_rot_deg")[i]);
        assert!(json("sigma_trans_m")[i] >= json("filter_sigma_trans_m")[i]);
    }
    println!(
        "written sigma rot {:.4?} deg, trans {:.3?} mm (filter's {:.4?} deg, {:.3?} mm)",
        full.sigma_rot_deg,
        full.sigma_trans_m.map(|v| v * 1e3),
        json("filter_sigma_rot_deg"),
        json("filter_sigma_trans_m").map(|v| v * 1e3)
    );

    // A start in the fastest part (the second half alone) lands on the same result.
    let half = calibrate(
        &cut(&dir, 35.0, &out.path().join("half")),
        "reprojection",
        &out.path().join("half"),
    );
    let (rotation, lever) = difference(&half.t_cam_imu, &full.t_cam_imu);
    println!(
        "second half vs full: {rotation:.3} deg, {:.1} mm",
        lever * 1e3
    );
    assert_eq!(half.exit, 0, "{}", half.report["reasons"]);
    assert!(
        rotation < 0.12 && lever < 0.003,
        "{rotation} deg, {lever} m"
    );

    let motion = calibrate(&dir, "motion", out.path());
    let (rotation, lever) = difference(&motion.t_cam_imu, &reference);
    println!(
        "MoCal: {rotation:.3} deg, {:.1} mm from Kalibr, NIS/dof {:.2}",
        lever * 1e3,
        nis_per_dof(&motion)
    );
    assert!(rotation < 1.0 && lever < 0.1, "{rotation} deg, {lever} m");
}
