//! `msreg export`: a result file out in another tool's format (exit 0), and bad input named
//! with exit code 2 (missing file, unknown format, a key the format needs).

use std::path::Path;
use std::process::Output;

#[path = "support/run.rs"]
mod run;
use run::msreg;

const RESULT: &str = "cam0:\n  T_cam_imu: [[0, -1, 0, 0.05], [0, 0, -1, 0.01], [1, 0, 0, -0.02], [0, 0, 0, 1]]\n  \
                      timeshift_cam_imu: 0.004\nlidar0:\n  T_imu_lidar: [[1, 0, 0, 0.3], [0, 1, 0, 0], [0, 0, 1, 0.2], [0, 0, 0, 1]]\n";

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn write_result(dir: &Path) -> String {
    let path = dir.join("result.yaml");
    std::fs::write(&path, RESULT).expect("write result");
    path.to_string_lossy().into_owned()
}

#[test]
fn tf_export_writes_both_files_with_every_sensor() {
    let dir = tempfile::tempdir().expect("tempdir");
    let result = write_result(dir.path());
    let out = dir.path().join("tf");
    let run = msreg(&[
        "export",
        &result,
        "--format",
        "tf",
        "-o",
        out.to_str().expect("utf8"),
    ]);
    assert_eq!(run.status.code(), Some(0), "{}", stderr(&run));
    let yaml = std::fs::read_to_string(out.join("static_transforms.yaml")).expect("yaml");
    let shell = std::fs::read_to_string(out.join("static_transforms.sh")).expect("sh");
    for text in [&yaml, &shell] {
        assert!(text.contains("cam0") && text.contains("lidar0"), "{text}");
    }
    assert!(shell.contains("--child-frame-id lidar0"), "{shell}");
}

#[test]
fn bad_input_is_named_with_exit_code_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    let result = write_result(dir.path());
    let out = dir.path().join("x");
    let out = out.to_str().expect("utf8");

    let missing = dir.path().join("none.yaml");
    let run = msreg(&[
        "export",
        missing.to_str().expect("utf8"),
        "--format",
        "tf",
        "-o",
        out,
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert!(stderr(&run).contains("none.yaml"), "{}", stderr(&run));

    let run = msreg(&["export", &result, "--format", "rviz", "-o", out]);
    assert_eq!(run.status.code(), Some(2));
    assert!(stderr(&run).contains("rviz"), "{}", stderr(&run));

    // Kalibr's camchain needs the camera's intrinsics, which this result does not hold.
    let run = msreg(&["export", &result, "--format", "kalibr", "-o", out]);
    assert_eq!(run.status.code(), Some(2));
    let message = stderr(&run);
    assert!(
        message.contains("result.yaml") && message.contains("cam0"),
        "{message}"
    );
}
