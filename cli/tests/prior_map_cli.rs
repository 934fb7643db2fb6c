//! `msreg simulate prior-map` and `msreg calibrate prior-map` as a user meets them: exit 0
//! with the result, overlays and report; exit 1 when automatic matching fails (a satellite
//! image of another place), saying so; exit 2 on bad input, naming the file and line.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

use msreg_host::dataset::read_t_world_cam;
use msreg_host::mi::prior_map::init::camera_yaw;

#[path = "support/run.rs"]
mod run;
use run::msreg;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A small simulated dataset, written once per test binary.
fn dataset() -> &'static (tempfile::TempDir, PathBuf) {
    static DATA: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    DATA.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("ds");
        let p = path.to_string_lossy().into_owned();
        let out = msreg(&[
            "simulate",
            "prior-map",
            &p,
            "--seed",
            "12",
            "--small",
            "--prior-offset-m",
            "3",
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        (dir, path)
    })
}

/// A copy of the dataset to damage.
fn copy(to: &Path) -> PathBuf {
    let from = &dataset().1;
    let dst = to.join("copy");
    for sub in ["map", "cam0/data", "groundtruth"] {
        fs::create_dir_all(dst.join(sub)).expect("mkdir");
    }
    for f in [
        "map/map.pcd",
        "map/satellite.png",
        "map/satellite.yaml",
        "cam0/camera.yaml",
        "cam0/data.csv",
        "prior.yaml",
        "survey.csv",
        "groundtruth/extrinsics.yaml",
    ] {
        fs::copy(from.join(f), dst.join(f)).expect("copy");
    }
    for e in fs::read_dir(from.join("cam0/data")).expect("dir") {
        let e = e.expect("entry");
        fs::copy(e.path(), dst.join("cam0/data").join(e.file_name())).expect("copy");
    }
    dst
}

/// `msreg calibrate prior-map ds -o out --report report` exits 0; the report.
fn calibrate_ok(ds: &Path, out: &Path, report: &Path) -> serde_json::Value {
    let o = msreg(&[
        "calibrate",
        "prior-map",
        &ds.to_string_lossy(),
        "-o",
        &out.to_string_lossy(),
        "--report",
        &report.to_string_lossy(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    serde_json::from_str(&fs::read_to_string(report).expect("report")).expect("json")
}

#[test]
fn calibrate_writes_result_overlays_and_report() {
    let ds = &dataset().1;
    let tmp = tempfile::tempdir().expect("tempdir");
    let out = tmp.path().join("result.yaml");
    let report = tmp.path().join("report.json");
    let json = calibrate_ok(ds, &out, &report);
    let estimate = read_t_world_cam(&out).expect("result");
    let truth = read_t_world_cam(&ds.join("groundtruth/extrinsics.yaml")).expect("truth");
    assert!((estimate.translation.vector - truth.translation.vector).norm() < 0.1);
    let text = fs::read_to_string(&out).expect("result text");
    for key in [
        "sigma_rot_deg",
        "sigma_trans_m",
        "nmi:",
        "cam0_mi:",
        "observability",
    ] {
        assert!(text.contains(key), "{key} missing in\n{text}");
    }
    assert!(tmp.path().join("result.png").is_file());
    assert!(tmp.path().join("result_initial.png").is_file());
    assert_eq!(json["init"]["source"], "automatic");
    assert!(
        json["survey_median_px"].as_f64().expect("median") < 3.0,
        "{json}"
    );
    // The MI slices through the optimum: six DoFs, each peaking at the estimate.
    let slices = json["mi_slices"].as_array().expect("mi_slices");
    assert_eq!(slices.len(), 6, "{json}");
    for s in slices {
        assert_eq!(s["peak_offset"].as_f64(), Some(0.0), "{s}");
        assert_eq!(s["mi"].as_array().map(Vec::len), Some(13), "{s}");
    }
}

#[test]
fn failed_matching_exits_1_and_says_so() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = copy(tmp.path());
    // The satellite image of another intersection (seed 99).
    let other = tmp.path().join("other");
    let o = msreg(&[
        "simulate",
        "prior-map",
        &other.to_string_lossy(),
        "--seed",
        "99",
        "--small",
    ]);
    assert!(o.status.success());
    fs::copy(
        other.join("map/satellite.png"),
        ds.join("map/satellite.png"),
    )
    .expect("copy");
    let out = tmp.path().join("r.yaml");
    let o = msreg(&[
        "calibrate",
        "prior-map",
        &ds.to_string_lossy(),
        "-o",
        &out.to_string_lossy(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("automatic matching failed"),
        "{}",
        stderr(&o)
    );
    assert!(fs::read_to_string(&out)
        .expect("result")
        .contains("status: failed"));
}

/// `msreg calibrate prior-map ds` exits 2 and its message contains `needle`.
fn assert_bad_input(ds: &Path, needle: &str) {
    let o = msreg(&[
        "calibrate",
        "prior-map",
        &ds.to_string_lossy(),
        "-o",
        "/dev/null",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains(needle), "{needle}: {}", stderr(&o));
}

#[test]
fn bad_input_exits_2_naming_file_and_line() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = copy(tmp.path());
    let survey = ds.join("survey.csv");
    let mut lines: Vec<String> = fs::read_to_string(&survey)
        .expect("survey")
        .lines()
        .map(String::from)
        .collect();
    lines[2] = "1.0,2.0,oops,4.0,5.0".into();
    fs::write(&survey, lines.join("\n")).expect("write");
    assert_bad_input(&ds, "survey.csv:3");

    fs::copy(dataset().1.join("survey.csv"), &survey).expect("restore");
    fs::write(
        ds.join("prior.yaml"),
        "position: [1.0, 2.0, 8.0]\nsigma_position_m: [3.0, oops]\n",
    )
    .expect("write");
    assert_bad_input(&ds, "prior.yaml:2");

    fs::remove_file(ds.join("prior.yaml")).expect("rm");
    assert_bad_input(&ds, "prior.yaml");
}

#[test]
fn user_correspondences_replace_automatic_matching() {
    // No satellite image; eight clicked points (taken from the survey) in prior.yaml.
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = copy(tmp.path());
    fs::remove_file(ds.join("map/satellite.png")).expect("rm");
    let survey = fs::read_to_string(ds.join("survey.csv")).expect("survey");
    let mut prior = String::from("correspondences:\n");
    for line in survey
        .lines()
        .filter(|l| !l.starts_with('#'))
        .step_by(3)
        .take(8)
    {
        let v: Vec<&str> = line.split(',').collect();
        prior.push_str(&format!(
            "  - {{uv: [{}, {}], xyz: [{}, {}, {}]}}\n",
            v[3], v[4], v[0], v[1], v[2]
        ));
    }
    fs::write(ds.join("prior.yaml"), prior).expect("write");
    let out = tmp.path().join("r.yaml");
    let report = tmp.path().join("r.json");
    let json = calibrate_ok(&ds, &out, &report);
    assert_eq!(json["init"]["source"], "user_correspondences");
    assert_eq!(json["init"]["inliers"], 8);
    assert!(
        json["init"]["rms_px"].as_f64().expect("rms") < 1e-3,
        "{json}"
    );
    let estimate = read_t_world_cam(&out).expect("result");
    let truth = read_t_world_cam(&ds.join("groundtruth/extrinsics.yaml")).expect("truth");
    assert!((estimate.translation.vector - truth.translation.vector).norm() < 0.1);
}

/// The yaw of `prior.yaml`: a matched pose 90 deg off it is refused (exit 1, saying so);
/// one 4 deg off it (inside 3 sigma of 5 deg) is accepted.
#[test]
fn yaw_prior_refuses_an_inconsistent_match() {
    let tmp = tempfile::tempdir().expect("tempdir");
    let ds = copy(tmp.path());
    let truth = read_t_world_cam(&ds.join("groundtruth/extrinsics.yaml")).expect("truth");
    let yaw = camera_yaw(&truth).to_degrees();
    let prior = fs::read_to_string(ds.join("prior.yaml")).expect("prior");
    let out = tmp.path().join("r.yaml");
    let run = |offset_deg: f64| {
        fs::write(
            ds.join("prior.yaml"),
            format!(
                "{prior}\nyaw_deg: {}\nsigma_yaw_deg: 5.0\n",
                yaw + offset_deg
            ),
        )
        .expect("write");
        msreg(&[
            "calibrate",
            "prior-map",
            &ds.to_string_lossy(),
            "-o",
            &out.to_string_lossy(),
        ])
    };
    let o = run(90.0);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains("from the prior's"), "{}", stderr(&o));
    assert!(fs::read_to_string(&out)
        .expect("result")
        .contains("status: failed"));
    let o = run(4.0);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}
