//! `msreg calibrate cameras` end to end on a dataset made of the real images of
//! `../shared/data/checkerboard-opencv` (linked, not copied): one camera, and the same
//! images as a two-camera rig (both cameras see the same pictures, so `T_cn_cnm1` is the
//! identity), and a rig whose stamps differ (refused, exit code 2).

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::process::Command;

use msreg_host::camera_yaml::read_camera_yaml;

const TARGET: &str = "target_type: checkerboard\ntargetRows: 6\ntargetCols: 9\n\
                      rowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n";

/// `root/camN/` with the 13 full-board images linked and stamps 50 ms apart plus `offset`.
fn camera_dir(root: &Path, data: &Path, n: usize, offset_ns: u64) {
    let cam = root.join(format!("cam{n}"));
    std::fs::create_dir_all(cam.join("data")).unwrap();
    std::fs::write(
        cam.join("camera.yaml"),
        "camera_model: pinhole\ndistortion_model: radtan\nresolution: [640, 480]\n",
    )
    .unwrap();
    let mut csv = String::from("#timestamp [ns],filename\n");
    let names = (1..=14)
        .filter(|&i| i != 10)
        .map(|i| format!("left{i:02}.jpg"));
    for (k, name) in names.enumerate() {
        std::os::unix::fs::symlink(data.join(&name), cam.join("data").join(&name)).unwrap();
        csv.push_str(&format!(
            "{},{name}\n",
            1_000_000_000 + k as u64 * 50_000_000 + offset_ns
        ));
    }
    std::fs::write(cam.join("data.csv"), csv).unwrap();
}

fn run(dataset: &Path, out: &Path) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(["calibrate", "cameras"])
        .arg(dataset)
        .arg("-o")
        .arg(out.join("result.yaml"))
        .arg("--report")
        .arg(out.join("report.json"))
        .output()
        .unwrap()
}

#[test]
fn one_camera_and_a_rig_of_the_same_images() {
    let Some(data) = msreg_host::shared_data::dir_or_skip("checkerboard-opencv") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let ds = tmp.path().join("ds");
    std::fs::create_dir_all(&ds).unwrap();
    std::fs::write(ds.join("target.yaml"), TARGET).unwrap();
    camera_dir(&ds, &data, 0, 0);
    let out = run(&ds, tmp.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stderr}");
    assert!(out.status.success(), "{stderr}");
    let cam = read_camera_yaml(&tmp.path().join("result.cam0.yaml")).unwrap();
    let k = cam.intrinsics();
    // OpenCV's 5-coefficient calibration of these images: fx = fy = 535.9 (README there).
    assert!(
        (k.fu - 535.9).abs() < 5.0 && (k.fv - 535.9).abs() < 5.0,
        "{k:?}"
    );
    let result = std::fs::read_to_string(tmp.path().join("result.yaml")).unwrap();
    let yaml: serde_yaml::Value = serde_yaml::from_str(&result).unwrap();
    for key in [
        "camera_model",
        "intrinsics",
        "distortion_model",
        "distortion_coeffs",
        "resolution",
        "sigma_intrinsics",
    ] {
        assert!(yaml["cam0"].get(key).is_some(), "{key} missing:\n{result}");
    }
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("report.json")).unwrap())
            .unwrap();
    assert_eq!(
        report["cameras"][0]["images_used"].as_u64().unwrap()
            + report["cameras"][0]["images_rejected"].as_u64().unwrap(),
        13
    );

    camera_dir(&ds, &data, 1, 200_000);
    let out = run(&ds, tmp.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stderr}");
    assert!(out.status.success(), "{stderr}");
    let result = std::fs::read_to_string(tmp.path().join("result.yaml")).unwrap();
    let yaml: serde_yaml::Value = serde_yaml::from_str(&result).unwrap();
    let t = &yaml["cam1"]["T_cn_cnm1"];
    for i in 0..3 {
        for j in 0..4 {
            let expected = if i == j { 1.0 } else { 0.0 };
            let x = t[i][j].as_f64().unwrap();
            assert!(
                (x - expected).abs() < 1e-6,
                "T_cn_cnm1[{i}][{j}] = {x}\n{result}"
            );
        }
    }
}

#[test]
fn cameras_whose_stamps_differ_are_refused() {
    let Some(data) = msreg_host::shared_data::dir_or_skip("checkerboard-opencv") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    std::fs::write(tmp.path().join("target.yaml"), TARGET).unwrap();
    camera_dir(tmp.path(), &data, 0, 0);
    camera_dir(tmp.path(), &data, 1, 12_000_000);
    let out = run(tmp.path(), tmp.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stderr}");
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("cam1 and cam0 are not synchronised") && stderr.contains("12.000 ms"),
        "{stderr}"
    );
}
