//! The `msreg` command line as a user meets it: exit codes, messages naming file and line,
//! result files in the docs/formats.md format.

#[path = "../../host/tests/support/common.rs"]
mod common;

use std::fs;
use std::path::Path;
use std::process::{Command, Output};

use msreg_host::dataset::CalibrationResult;
use msreg_host::sim::SimConfig;

fn msreg(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("msreg runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A simulated dataset written to `dir/name`.
fn dataset(dir: &Path, name: &str, config: &SimConfig) -> String {
    let path = dir.join(name);
    common::simulate(config)
        .write(&path)
        .expect("write dataset");
    path.to_string_lossy().into_owned()
}

fn short(seed: u64) -> SimConfig {
    SimConfig {
        seed,
        duration_s: 20.0,
        ..SimConfig::default()
    }
}

/// Replaces 1-based line `line` of `file`.
fn replace_line(file: &Path, line: usize, text: &str) {
    let content = fs::read_to_string(file).expect("read");
    let mut lines: Vec<String> = content.lines().map(String::from).collect();
    lines[line - 1] = text.to_string();
    fs::write(file, lines.join("\n") + "\n").expect("write");
}

#[test]
fn calibrate_simulate_eval_round_trip() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    let sim = msreg(
        &[
            "simulate",
            "pose-imu",
            "data",
            "--seed",
            "3",
            "--duration",
            "30",
        ],
        d,
    );
    assert!(sim.status.success(), "{}", stderr(&sim));
    let cal = msreg(
        &[
            "calibrate",
            "pose-imu",
            "data",
            "-o",
            "out.yaml",
            "--report",
            "r.json",
        ],
        d,
    );
    assert_eq!(cal.status.code(), Some(0), "{}", stderr(&cal));
    let result = CalibrationResult::read(d.join("out.yaml")).expect("result parses");
    assert!(
        result.get("pose0").is_some()
            && result.get("lidar0").is_none()
            && result.get("cam0").is_none()
    );
    let report: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(d.join("r.json")).expect("report")).expect("json");
    assert_eq!(report["converged"], true);
    assert!(report["history"].as_array().is_some_and(|h| h.len() > 200));
    let eval = msreg(&["eval", "out.yaml", "data", "--json"], d);
    assert!(eval.status.success(), "{}", stderr(&eval));
    let errors: serde_json::Value = serde_json::from_slice(&eval.stdout).expect("eval json");
    assert_eq!(errors[0]["section"], "pose0");
    eprintln!("pose-IMU round trip: {}", errors[0]);
    // Seed 3, 30 s measured 0.183 deg, 7.9 mm, -0.082 ms, inside 3 sigma (docs/infra.md):
    // bounds ~3x that.
    let e = |key: &str| errors[0][key].as_f64().expect("numeric error");
    assert!(e("rotation_deg") < 0.5, "{}", errors[0]);
    assert!(e("translation_m") < 0.025, "{}", errors[0]);
    assert!(e("time_offset_s").abs() < 0.25e-3, "{}", errors[0]);
    assert_eq!(errors[0]["within_3_sigma"], true, "{}", errors[0]);
}

#[test]
fn missing_dataset_is_exit_code_2_naming_the_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = msreg(&["calibrate", "pose-imu", "no-such-dir"], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no-such-dir"), "{}", stderr(&o));
}

#[test]
fn missing_pose_file_is_exit_code_2_naming_the_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dataset(dir.path(), "d", &short(1));
    fs::remove_file(Path::new(&data).join("pose0/data.csv")).expect("rm");
    let o = msreg(&["calibrate", "pose-imu", &data], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("pose0/data.csv"), "{}", stderr(&o));
}

#[test]
fn malformed_imu_line_is_exit_code_2_naming_file_and_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dataset(dir.path(), "d", &short(1));
    replace_line(
        &Path::new(&data).join("imu0/data.csv"),
        7,
        "123,not-a-number,0,0,0,0",
    );
    let o = msreg(&["calibrate", "pose-imu", &data], dir.path());
    assert_eq!(o.status.code(), Some(2));
    let msg = stderr(&o);
    assert!(msg.contains("imu0/data.csv:7"), "{msg}");
    assert!(!msg.contains("panicked"), "{msg}");
}

#[test]
fn time_going_backwards_is_exit_code_2_naming_file_and_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dataset(dir.path(), "d", &short(1));
    let file = Path::new(&data).join("pose0/data.csv");
    let content = fs::read_to_string(&file).expect("read");
    // Swap the stamps of data lines 10 and 11 (file lines 11 and 12 after the header).
    let mut lines: Vec<String> = content.lines().map(String::from).collect();
    let (a, b) = (lines[10].clone(), lines[11].clone());
    let stamp = |l: &str| l.split(',').next().expect("stamp").to_string();
    lines[10] = a.replacen(&stamp(&a), &stamp(&b), 1);
    lines[11] = b.replacen(&stamp(&b), &stamp(&a), 1);
    fs::write(&file, lines.join("\n") + "\n").expect("write");
    let o = msreg(&["calibrate", "pose-imu", &data], dir.path());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("pose0/data.csv:12"), "{}", stderr(&o));
}

#[test]
fn gap_in_imu_data_is_exit_code_2_naming_the_stamp() {
    let dir = tempfile::tempdir().expect("tempdir");
    let data = dataset(dir.path(), "d", &short(1));
    let file = Path::new(&data).join("imu0/data.csv");
    let content = fs::read_to_string(&file).expect("read");
    // Drop 0.5 s of samples (data lines 4000..4200).
    let kept: Vec<&str> = content
        .lines()
        .enumerate()
        .filter(|(i, _)| !(4000..4200).contains(i))
        .map(|(_, l)| l)
        .collect();
    fs::write(&file, kept.join("\n") + "\n").expect("write");
    let o = msreg(&["calibrate", "pose-imu", &data], dir.path());
    assert_eq!(o.status.code(), Some(2));
    let msg = stderr(&o);
    assert!(
        msg.contains("imu0/data.csv") && msg.contains("gap"),
        "{msg}"
    );
}

/// Rotation about one axis only (a yaw-only hand-held path): the planar path (docs/planar.md)
/// finds the rotation and the lever arm across the axis, holds the lever arm along it at its
/// prior, warns that it is not observable, and the result is inside its 3 sigma.
#[test]
fn rotation_about_one_axis_warns_of_the_unobservable_lever_arm() {
    let dir = tempfile::tempdir().expect("tempdir");
    let mut config = short(2);
    config.trajectory.max_roll_amplitude_rad = 0.0;
    config.trajectory.max_pitch_amplitude_rad = 0.0;
    let data = dataset(dir.path(), "d", &config);
    let o = msreg(
        &["calibrate", "pose-imu", &data, "-o", "r.yaml"],
        dir.path(),
    );
    println!("{}", stderr(&o));
    assert!(
        stderr(&o).contains("warning: translation along") && stderr(&o).contains("not observable"),
        "{}",
        stderr(&o)
    );
    assert!(dir.path().join("r.yaml").exists(), "the result is written");
    let e = msreg(&["eval", "r.yaml", &data], dir.path());
    let table = String::from_utf8_lossy(&e.stdout).to_string();
    println!("{table}");
    let row = table
        .lines()
        .find(|l| l.starts_with("pose0"))
        .unwrap_or_else(|| panic!("no pose0 row: {table}"));
    assert!(row.ends_with("yes"), "{row}");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
}

#[test]
fn demo_prints_the_table() {
    let dir = tempfile::tempdir().expect("tempdir");
    let keep = dir.path().join("demo");
    let o = msreg(&["demo", "--keep", &keep.to_string_lossy()], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("inside 3 sigma"), "{out}");
    // One row per section of each pipeline's result, in the demo's order.
    let sections: Vec<&str> = out
        .lines()
        .filter(|l| {
            l.split_whitespace()
                .next()
                .is_some_and(|s| ["pose0", "cam0", "lidar0", "cam0_lidar0"].contains(&s))
        })
        .inspect(|row| assert!(row.ends_with("yes"), "{row}"))
        .filter_map(|l| l.split_whitespace().next())
        .collect();
    assert_eq!(
        sections,
        [
            "pose0",
            "cam0",
            "lidar0",
            "cam0_lidar0",
            "cam0",
            "lidar0",
            "cam0_lidar0"
        ],
        "{out}"
    );
    for pipeline in [
        "pose-imu",
        "camera-imu",
        "lidar-imu",
        "lidar-camera",
        "joint",
    ] {
        assert!(
            out.contains(&format!("{pipeline:<13} converged")),
            "{pipeline}: {out}"
        );
        assert!(keep.join(pipeline).join("result.yaml").is_file());
    }
    // The joint calibration draws the board's LiDAR returns over an image.
    let data = keep.join("joint").join("dataset");
    let overlay = dir.path().join("overlay.png");
    let o = msreg(
        &[
            "calibrate",
            "joint",
            &data.to_string_lossy(),
            "--overlay",
            &overlay.to_string_lossy(),
        ],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(overlay.is_file(), "{}", stderr(&o));
    // It needs the board's size to find it in the scans.
    let target = data.join("target.yaml");
    let text = std::fs::read_to_string(&target).expect("target.yaml");
    let without_size: String = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("width_m"))
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(&target, without_size).expect("write target.yaml");
    let o = msreg(&["calibrate", "joint", &data.to_string_lossy()], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("target.yaml"), "{}", stderr(&o));
    assert!(stderr(&o).contains("width_m"), "{}", stderr(&o));
}

#[test]
fn demo_only_runs_the_named_pipelines() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = msreg(&["demo", "--only", "pose-imu"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("pose0") && !out.contains("lidar0"), "{out}");
    let o = msreg(&["demo", "--only", "radar-imu"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
}

#[test]
fn truncated_pcd_is_exit_code_2_naming_the_file() {
    use msreg_host::pointcloud::{encode_pcd, PcdEncoding, PcdWriteOptions, PointCloud};
    let dir = tempfile::tempdir().expect("tempdir");
    let cloud =
        PointCloud::from_xyz((0..500).map(|i| nalgebra::Vector3::new(i as f64 * 0.01, 1.0, 2.0)));
    let bytes = encode_pcd(
        &cloud,
        PcdWriteOptions {
            encoding: PcdEncoding::Binary,
            xyz_f64: false,
        },
    );
    fs::write(dir.path().join("full.pcd"), &bytes).expect("write");
    fs::write(dir.path().join("cut.pcd"), &bytes[..bytes.len() - 100]).expect("write");
    let o = msreg(&["match", "full.pcd", "cut.pcd"], dir.path());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("cut.pcd"), "{}", stderr(&o));
    let o = msreg(
        &["match", "full.pcd", "full.pcd", "--guess", "1,2"],
        dir.path(),
    );
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("--guess"), "{}", stderr(&o));
}

#[test]
fn detect_checkerboard_reports_bad_input_with_exit_code_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let d = dir.path();
    fs::write(
        d.join("target.yaml"),
        "target_type: checkerboard\ntargetRows: 6\ntargetCols: 9\nrowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n",
    )
    .expect("write");
    fs::write(
        d.join("board.yaml"),
        "target_type: board\nwidth_m: 1.0\nheight_m: 0.8\n",
    )
    .expect("write");
    fs::write(d.join("corrupt.png"), b"not a png").expect("write");
    let o = msreg(
        &[
            "detect",
            "checkerboard",
            "missing.png",
            "--target",
            "target.yaml",
        ],
        d,
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("missing.png"), "{}", stderr(&o));
    let o = msreg(
        &[
            "detect",
            "checkerboard",
            "corrupt.png",
            "--target",
            "target.yaml",
        ],
        d,
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("corrupt.png"), "{}", stderr(&o));
    let o = msreg(
        &[
            "detect",
            "checkerboard",
            "corrupt.png",
            "--target",
            "board.yaml",
        ],
        d,
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("board.yaml"), "{}", stderr(&o));
}
