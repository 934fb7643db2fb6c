//! `msreg simulate lidar-camera` and `msreg calibrate lidar-camera` as a user meets them:
//! bad frames rejected with a reason, too few views exit 1 with the reason, malformed input
//! exit 2 naming the file, the result readable by `msreg eval`.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

use msreg_host::dataset::CalibrationResult;

#[path = "support/run.rs"]
mod run;
use run::msreg;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// 4 good poses and the 3 bad frames, Ouster-like, written once per test binary.
fn dataset() -> &'static (tempfile::TempDir, PathBuf) {
    static DATA: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    DATA.get_or_init(|| {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("ds");
        let p = path.to_string_lossy().into_owned();
        let out = msreg(&[
            "simulate",
            "lidar-camera",
            &p,
            "--seed",
            "2",
            "--lidar",
            "ouster",
            "--poses",
            "4",
            "--bad-frames",
        ]);
        assert!(out.status.success(), "{}", stderr(&out));
        (dir, path)
    })
}

/// A copy of the dataset to damage.
fn copy(name: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("tempdir");
    let dst = dir.path().join(name);
    copy_dir(&dataset().1, &dst);
    (dir, dst)
}

fn copy_dir(src: &Path, dst: &Path) {
    fs::create_dir_all(dst).expect("mkdir");
    for e in fs::read_dir(src).expect("read_dir") {
        let e = e.expect("entry");
        let to = dst.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &to);
        } else {
            fs::copy(e.path(), &to).expect("copy");
        }
    }
}

#[test]
fn bad_frames_are_rejected_with_reasons_and_the_result_evaluates() {
    let (_, ds) = dataset();
    let out_dir = tempfile::tempdir().expect("tempdir");
    let result = out_dir.path().join("result.yaml");
    let report = out_dir.path().join("report.json");
    let ds_s = ds.to_string_lossy();
    let out = msreg(&[
        "calibrate",
        "lidar-camera",
        &ds_s,
        "-o",
        &result.to_string_lossy(),
        "--report",
        &report.to_string_lossy(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let json: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&report).expect("report")).expect("json");
    assert_eq!(json["frames_used"], 4);
    let reasons: Vec<String> = json["rejected"]
        .as_array()
        .expect("rejected")
        .iter()
        .map(|r| r["reason"].as_str().unwrap_or_default().to_string())
        .collect();
    assert_eq!(reasons.len(), 3, "{reasons:?}");
    assert!(reasons[0].contains("no board"), "{reasons:?}");
    assert!(
        reasons[1].contains("cut by the image border"),
        "{reasons:?}"
    );
    assert!(reasons[2].contains("edge-on"), "{reasons:?}");
    let frames = json["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), 4);
    assert!(frames
        .iter()
        .all(|f| f["mlre_px"].as_f64().is_some_and(|m| m < 2.0)
            && f["edges"].as_array().is_some_and(|e| e.len() == 4)));
    assert!(
        report.with_extension("png").is_file(),
        "overlay PNG written"
    );
    let estimate = CalibrationResult::read(&result).expect("result");
    assert!(estimate.get("cam0_lidar0").is_some());
    let eval = msreg(&["eval", &result.to_string_lossy(), &ds_s]);
    assert!(eval.status.success(), "{}", stderr(&eval));
    assert!(String::from_utf8_lossy(&eval.stdout).contains("cam0_lidar0"));
}

#[test]
fn too_few_views_exit_1_with_the_reason() {
    let (_tmp, ds) = copy("few");
    // Keep only two good scans (and the three bad ones).
    let mut scans: Vec<PathBuf> = fs::read_dir(ds.join("lidar0"))
        .expect("lidar0")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "pcd"))
        .collect();
    scans.sort();
    for p in &scans[..2] {
        fs::remove_file(p).expect("rm");
    }
    let out_dir = tempfile::tempdir().expect("tempdir");
    let report = out_dir.path().join("r.json");
    let out = msreg(&[
        "calibrate",
        "lidar-camera",
        &ds.to_string_lossy(),
        "-o",
        &out_dir.path().join("r.yaml").to_string_lossy(),
        "--report",
        &report.to_string_lossy(),
    ]);
    assert_eq!(out.status.code(), Some(1), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("only 2 usable views"),
        "{}",
        stderr(&out)
    );
    let json: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(&report).expect("report")).expect("json");
    assert!(json["reason"]
        .as_str()
        .is_some_and(|r| r.contains("3 of 5 frames rejected")));
}

#[test]
fn malformed_input_exits_2_naming_the_file() {
    let missing = msreg(&["calibrate", "lidar-camera", "/nonexistent/lc"]);
    assert_eq!(missing.status.code(), Some(2));
    assert!(stderr(&missing).contains("/nonexistent/lc"));

    let (_a, ds) = copy("csv");
    fs::write(ds.join("cam0/data.csv"), "#timestamp,filename\n12x,a.png\n").expect("write");
    let out = msreg(&["calibrate", "lidar-camera", &ds.to_string_lossy()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("cam0/data.csv:2"), "{}", stderr(&out));

    let (_b, ds) = copy("png");
    let png = fs::read_dir(ds.join("cam0/data"))
        .expect("data")
        .map(|e| e.expect("entry").path())
        .min()
        .expect("a png");
    fs::write(&png, b"not a png").expect("write");
    let out = msreg(&["calibrate", "lidar-camera", &ds.to_string_lossy()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains(&*png.to_string_lossy()),
        "{}",
        stderr(&out)
    );

    let (_c, ds) = copy("target");
    fs::write(
        ds.join("target.yaml"),
        "target_type: 'checkerboard'\ntargetRows: 5\ntargetCols: 6\nrowSpacingMeters: 0.1\ncolSpacingMeters: 0.1\n",
    )
    .expect("write");
    let out = msreg(&["calibrate", "lidar-camera", &ds.to_string_lossy()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("target.yaml"), "{}", stderr(&out));
}
