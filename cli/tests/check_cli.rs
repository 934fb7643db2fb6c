//! `msreg check` and the check `msreg calibrate` runs first: each common mistake of issue
//! #36, made by corrupting a short simulated dataset, must be named with its cause and
//! numbers (exit code 2); the good datasets pass. Also `msreg calibrate --format`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

#[path = "support/run.rs"]
mod run;
use run::msreg;

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// One short simulated recording of each kind, shared by the tests (each copies it).
fn simulated(kind: &'static str) -> &'static Path {
    static CAMERA: OnceLock<tempfile::TempDir> = OnceLock::new();
    static POSE: OnceLock<tempfile::TempDir> = OnceLock::new();
    let (cell, args): (_, &[&str]) = match kind {
        "camera-imu" => (&CAMERA, &["--duration", "8", "--seed", "3"]),
        _ => (&POSE, &["--duration", "20", "--seed", "3"]),
    };
    cell.get_or_init(|| {
        let dir = tempfile::tempdir().expect("temp dir");
        let data = dir.path().join("data");
        let data = data.to_str().expect("utf-8 path");
        let out = msreg(&[&["simulate", kind, data], args].concat());
        assert!(out.status.success(), "{}", text(&out));
        dir
    })
    .path()
}

/// A fresh copy of a simulated dataset in its own temp dir.
fn copy_of(kind: &'static str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("temp dir");
    let to = dir.path().join("data");
    copy_dir(&simulated(kind).join("data"), &to);
    (dir, to)
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("read dir").flatten() {
        let target = to.join(entry.file_name());
        if entry.path().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).expect("copy");
        }
    }
}

/// Rewrites every data line of `imu0/data.csv` with `f(stamp, values)`.
fn edit_imu(data: &Path, f: impl Fn(u64, &mut [f64])) {
    let path = data.join("imu0/data.csv");
    let text = std::fs::read_to_string(&path).expect("imu csv");
    let mut out = String::new();
    for line in text.lines() {
        if line.starts_with('#') {
            out.push_str(line);
        } else {
            let fields: Vec<&str> = line.split(',').collect();
            let stamp: u64 = fields[0].trim().parse().expect("stamp");
            let mut values: Vec<f64> = fields[1..]
                .iter()
                .map(|v| v.trim().parse().expect("value"))
                .collect();
            f(stamp, &mut values);
            let values: Vec<String> = values.iter().map(|v| format!("{v:e}")).collect();
            let shifted = STAMP_SHIFT.with(|s| s.get());
            out.push_str(&format!(
                "{},{}",
                stamp.wrapping_add_signed(shifted),
                values.join(",")
            ));
        }
        out.push('\n');
    }
    std::fs::write(&path, out).expect("write imu csv");
}

thread_local! {
    static STAMP_SHIFT: std::cell::Cell<i64> = const { std::cell::Cell::new(0) };
}

fn shift_imu(data: &Path, shift_ns: i64) {
    STAMP_SHIFT.with(|s| s.set(shift_ns));
    edit_imu(data, |_, _| {});
    STAMP_SHIFT.with(|s| s.set(0));
}

fn replace_in(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).expect("read");
    assert!(text.contains(from), "{} lacks {from}", path.display());
    std::fs::write(path, text.replace(from, to)).expect("write");
}

fn calibrate_camera_imu(data: &Path) -> (Output, String) {
    let result = data.with_file_name("result.yaml");
    let out = msreg(&[
        "calibrate",
        "camera-imu",
        data.to_str().expect("utf-8"),
        "-o",
        result.to_str().expect("utf-8"),
    ]);
    let t = text(&out);
    (out, t)
}

/// The number after `prefix` in `text`.
fn number_after(text: &str, prefix: &str) -> f64 {
    let start = text
        .find(prefix)
        .unwrap_or_else(|| panic!("no `{prefix}` in:\n{text}"))
        + prefix.len();
    let digits: String = text[start..]
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == '-')
        .collect();
    digits
        .parse()
        .unwrap_or_else(|_| panic!("no number after `{prefix}` in:\n{text}"))
}

#[test]
fn good_simulated_datasets_pass_with_their_numbers() {
    for kind in ["camera-imu", "pose-imu"] {
        let (_dir, data) = copy_of(kind);
        let out = msreg(&["check", data.to_str().expect("utf-8")]);
        let t = text(&out);
        assert!(out.status.success(), "{kind}:\n{t}");
        assert!(t.contains("0 errors, 0 warnings"), "{kind}:\n{t}");
        let stream = if kind == "camera-imu" {
            "cam0"
        } else {
            "pose0"
        };
        // Measured: 0 ms on both (the simulated clocks agree).
        let offset = number_after(&t, &format!("{stream}: time offset ~"));
        assert!(offset.abs() <= 3.0, "{kind}: offset {offset} ms\n{t}");
        assert!(t.contains("imu0: ") && t.contains("at 400.0 Hz"), "{t}");
        assert!(t.contains("excitation: imu0 turned"), "{t}");
    }
    let (_dir, data) = copy_of("camera-imu");
    let t = text(&msreg(&["check", data.to_str().expect("utf-8")]));
    // Measured 1.001 (seed 3, 8 s); bound 3x the largest deviation seen on seeds 1-3.
    let ratio = number_after(&t, "translation from PnP is ");
    assert!((ratio - 1.0).abs() < 0.006, "scale ratio {ratio}\n{t}");
    assert!(t.contains("found in 159 of 159 images"), "{t}");
}

#[test]
fn a_square_size_of_7_cm_for_a_6_cm_board_is_named_with_the_true_size() {
    let (_dir, data) = copy_of("camera-imu");
    let target = data.join("target.yaml");
    replace_in(&target, "colSpacingMeters: 0.06", "colSpacingMeters: 0.07");
    replace_in(&target, "rowSpacingMeters: 0.06", "rowSpacingMeters: 0.07");
    let (out, t) = calibrate_camera_imu(&data);
    assert_eq!(out.status.code(), Some(2), "{t}");
    assert!(t.contains("does not match the board"), "{t}");
    // Measured: ratio 1.167 (7/6 = 1.1667), size 0.0600 m.
    let ratio = number_after(&t, "translation from PnP is ");
    assert!((ratio - 7.0 / 6.0).abs() < 0.01, "{t}");
    let size = number_after(&t, "the motion says ");
    assert!((size - 0.06).abs() < 0.0006, "{t}");
    assert!(!t.contains("rotation"), "blamed on rotation:\n{t}");
}

#[test]
fn a_square_size_in_millimetres_is_named_with_file_and_line() {
    let (_dir, data) = copy_of("camera-imu");
    let target = data.join("target.yaml");
    replace_in(&target, "rowSpacingMeters: 0.06", "rowSpacingMeters: 60");
    replace_in(&target, "colSpacingMeters: 0.06", "colSpacingMeters: 60");
    let (out, t) = calibrate_camera_imu(&data);
    assert_eq!(out.status.code(), Some(2), "{t}");
    assert!(
        t.contains("looks like millimetres; write 0.06 (metres)"),
        "{t}"
    );
    assert!(t.contains("target.yaml:4: `colSpacingMeters` is 60"), "{t}");
    assert!(t.contains("target.yaml:5: `rowSpacingMeters` is 60"), "{t}");
}

#[test]
fn an_imu_clock_1000_s_off_is_named_as_streams_that_do_not_overlap() {
    let (_dir, data) = copy_of("camera-imu");
    shift_imu(&data, 1_000_000_000_000);
    let (out, t) = calibrate_camera_imu(&data);
    assert_eq!(out.status.code(), Some(2), "{t}");
    assert!(t.contains("the streams do not overlap"), "{t}");
    assert!(
        t.contains("imu0 spans 1700001000.000 to 1700001008.000 s"),
        "{t}"
    );
    assert!(t.contains("cam0 spans 1700000000.050 to"), "{t}");
    assert!(t.contains("cam0 starts -999.950 s from imu0"), "{t}");
}

#[test]
fn an_imu_clock_200_ms_off_is_named_as_a_time_offset() {
    for kind in ["camera-imu", "pose-imu"] {
        let (_dir, data) = copy_of(kind);
        shift_imu(&data, 200_000_000);
        let out = msreg(&["check", data.to_str().expect("utf-8")]);
        let t = text(&out);
        assert_eq!(out.status.code(), Some(2), "{kind}:\n{t}");
        let stream = if kind == "camera-imu" {
            "cam0"
        } else {
            "pose0"
        };
        // Measured: 200 ms on both.
        let offset = number_after(&t, &format!("error: {stream}: time offset ~"));
        assert!((offset - 200.0).abs() <= 3.0, "{kind}:\n{t}");
        assert!(t.contains("beyond the prior range"), "{t}");
        assert!(!t.contains("not enough rotation"), "{t}");
    }
}

#[test]
fn an_empty_dataset_names_every_missing_file_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let data = dir.path().join("empty");
    std::fs::create_dir(&data).expect("mkdir");
    let (out, t) = calibrate_camera_imu(&data);
    assert_eq!(out.status.code(), Some(2), "{t}");
    for file in [
        "imu0/data.csv",
        "imu0/imu.yaml",
        "cam0/camera.yaml",
        "cam0/data.csv or ",
        "cam0/corners.csv",
        "target.yaml",
    ] {
        assert_eq!(t.matches(file).count(), 1, "{file}:\n{t}");
    }
    assert_eq!(t.lines().count(), 1, "{t}");
    let t = text(&msreg(&["check", data.to_str().expect("utf-8")]));
    assert!(t.contains("no sensor data found"), "{t}");
}

#[test]
fn a_typo_in_a_key_is_warned_by_name_with_file_and_line() {
    let (_dir, data) = copy_of("camera-imu");
    replace_in(
        &data.join("cam0/camera.yaml"),
        "distortion_coeffs:",
        "distortion_coefs:",
    );
    let (out, t) = calibrate_camera_imu(&data);
    assert_eq!(out.status.code(), Some(2), "{t}");
    assert!(
        t.contains(
            "cam0/camera.yaml:5: unknown key `distortion_coefs` ignored (did you mean \
             `distortion_coeffs`?)"
        ),
        "{t}"
    );
    assert!(
        t.contains("camera.yaml:4: missing key `distortion_coeffs`"),
        "{t}"
    );
    assert!(!t.contains(":0:"), "{t}");
}

#[test]
fn imu_units_of_g_and_deg_per_s_are_named() {
    let (_dir, data) = copy_of("pose-imu");
    edit_imu(&data, |_, v| v[3..].iter_mut().for_each(|a| *a /= 9.80665));
    let t = text(&msreg(&["check", data.to_str().expect("utf-8")]));
    assert!(t.contains("the accelerometer looks like it is in g"), "{t}");
    let (_dir, data) = copy_of("pose-imu");
    edit_imu(&data, |_, v| {
        v[..3].iter_mut().for_each(|w| *w = w.to_degrees())
    });
    let t = text(&msreg(&["check", data.to_str().expect("utf-8")]));
    assert!(t.contains("the gyro looks like it is in deg/s"), "{t}");
}

/// `--format` writes what `msreg export` writes, beside the result file. (kalibr and
/// openvins need the camera's intrinsics in the result, which `calibrate camera-imu` does not
/// write: they are the input's; tf and urdf need only the extrinsics.)
#[test]
fn calibrate_format_exports_next_to_the_result() {
    let (dir, data) = copy_of("camera-imu");
    for format in ["tf", "urdf"] {
        let out_dir = dir.path().join(format!("out-{format}"));
        std::fs::create_dir(&out_dir).expect("mkdir");
        let result = out_dir.join("result.yaml");
        let out = msreg(&[
            "calibrate",
            "camera-imu",
            data.to_str().expect("utf-8"),
            "-o",
            result.to_str().expect("utf-8"),
            "--format",
            format,
        ]);
        assert!(out.status.success(), "{}", text(&out));
        let exported = dir.path().join(format!("exported-{format}"));
        std::fs::create_dir(&exported).expect("mkdir");
        let again = msreg(&[
            "export",
            result.to_str().expect("utf-8"),
            "--format",
            format,
            "-o",
            exported.to_str().expect("utf-8"),
        ]);
        assert!(again.status.success(), "{}", text(&again));
        let mut files = 0;
        for entry in std::fs::read_dir(&exported).expect("exported").flatten() {
            let beside = out_dir.join(entry.file_name());
            let a = std::fs::read_to_string(entry.path()).expect("read");
            let b = std::fs::read_to_string(&beside).expect("--format wrote the same file");
            assert_eq!(a, b, "{}", beside.display());
            assert!(a.contains("cam0"), "{a}");
            assert!(text(&out).contains(&beside.display().to_string()));
            files += 1;
        }
        assert!(files >= 1, "{format}");
    }
    let bad = msreg(&["calibrate", "camera-imu", "x", "--format", "rviz"]);
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad));
}

/// The real EuRoC imu_april recording (corners from Kalibr's detector in cam0/corners.csv,
/// 200 Hz IMU): no error, its clock offset and the target's scale.
#[test]
fn the_real_euroc_recording_passes_with_its_offset_and_scale() {
    let Some(data) = msreg_host::shared_data::dir_or_skip("real/euroc-imu-april-cam0") else {
        return;
    };
    let out = msreg(&["check", data.to_str().expect("utf-8")]);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    assert!(t.contains("0 errors"), "{t}");
    // Measured -1 ms (Kalibr's published timeshift for this recording is under 1 ms).
    let offset = number_after(&t, "cam0: time offset ~");
    assert!(offset.abs() <= 3.0, "{t}");
    // Measured 1.008 +- 0.004 over 1398 images, gravity 9.79 m/s^2.
    let ratio = number_after(&t, "translation from PnP is ");
    assert!((ratio - 1.0).abs() < 0.025, "{t}");
    let gravity = number_after(&t, "gravity ");
    assert!((gravity - 9.81).abs() < 0.1, "{t}");
}

/// `msreg demo` without `--keep` prints no path of its temporary directory (it is removed at
/// the end); with `--keep` it prints that directory.
#[test]
fn demo_prints_only_the_keep_path() {
    let dir = tempfile::tempdir().expect("temp dir");
    let scratch = dir.path().join("scratch");
    std::fs::create_dir(&scratch).expect("mkdir");
    let out = Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(["demo", "--only", "pose-imu"])
        .env("TMPDIR", &scratch)
        .output()
        .expect("the msreg binary runs");
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    assert!(t.contains("pose0"), "{t}");
    assert!(!t.contains(scratch.to_str().expect("utf-8")), "{t}");
    let keep = dir.path().join("kept");
    let out = msreg(&[
        "demo",
        "--only",
        "pose-imu",
        "--keep",
        keep.to_str().expect("utf-8"),
    ]);
    let t = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(out.status.success(), "{t}");
    assert!(t.contains(&format!("in {}", keep.display())), "{t}");
}
