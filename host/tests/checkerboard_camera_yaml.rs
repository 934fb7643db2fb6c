//! Kalibr `camera.yaml` and `target.yaml` readers: the models and layouts Kalibr writes are
//! read into cameras/targets; unknown or unsupported models, wrong coefficient counts and
//! malformed YAML are errors naming the file (and the line).

// A test crate: its helpers may panic on bad fixtures.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use msreg_estimator::camera::{Distortion, Projection};
use msreg_host::camera_yaml::{
    parse_camera_yaml, parse_target_yaml, read_camera_yaml, read_target_yaml, Board, Target,
    YamlError,
};
use nalgebra::{Vector2, Vector3};

const KALIBR_PINHOLE: &str = "\
cam0:
  cam_overlaps: []
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375]
  resolution: [752, 480]
  rostopic: /cam0/image_raw
";

#[test]
fn a_kalibr_camchain_entry_under_cam0_is_read() {
    let cam = parse_camera_yaml(Path::new("camera.yaml"), KALIBR_PINHOLE).unwrap();
    assert_eq!(cam.resolution, (752, 480));
    assert_eq!(*cam.projection(), Projection::Pinhole);
    assert!(matches!(cam.distortion(), Distortion::RadTan(d) if d.k3 == 0.0));
    assert!((cam.intrinsics().fu - 458.654).abs() < 1e-12);
    let p = cam.project(&Vector3::new(0.1, -0.05, 1.0)).unwrap().pixel;
    assert!((cam.unproject(&p).unwrap() - Vector3::new(0.1, -0.05, 1.0).normalize()).norm() < 1e-9);
}

#[test]
fn top_level_equidistant_omni_and_none_models_are_read() {
    let eq = "camera_model: pinhole\nintrinsics: [290.05, 289.39, 399.94, 273.89]\n\
              distortion_model: equidistant\n\
              distortion_coeffs: [-0.030464, -0.019695, 0.002098, 0.001030]\n\
              resolution: [800, 503]\n";
    let cam = parse_camera_yaml(Path::new("fisheye.yaml"), eq).unwrap();
    assert!(matches!(cam.distortion(), Distortion::Equidistant(_)));
    let omni = "camera_model: omni\nintrinsics: [0.9, 750, 748, 640, 480]\n\
                distortion_model: radtan\ndistortion_coeffs: [-0.2, 0.05, 0.001, -0.001]\n\
                resolution: [1280, 960]\n";
    let cam = parse_camera_yaml(Path::new("omni.yaml"), omni).unwrap();
    assert_eq!(*cam.projection(), Projection::Omni { xi: 0.9 });
    let none = "camera_model: pinhole\nintrinsics: [500, 500, 320, 240]\n\
                distortion_model: none\ndistortion_coeffs: []\nresolution: [640, 480]\n";
    let cam = parse_camera_yaml(Path::new("none.yaml"), none).unwrap();
    assert_eq!(*cam.distortion(), Distortion::None);
    assert!(
        (cam.project(&Vector3::new(0.0, 0.0, 1.0)).unwrap().pixel - Vector2::new(320.0, 240.0))
            .norm()
            < 1e-12
    );
}

fn error_of(text: &str) -> String {
    let err = parse_camera_yaml(Path::new("cams/camera.yaml"), text).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("cams/camera.yaml"), "{msg}");
    msg
}

#[test]
fn unknown_and_unsupported_camera_models_are_errors_naming_file_and_line() {
    let unknown = KALIBR_PINHOLE.replace("camera_model: pinhole", "camera_model: fisheye62");
    let msg = error_of(&unknown);
    assert!(
        msg.contains("camera.yaml:3:") && msg.contains("fisheye62"),
        "{msg}"
    );
    let ds =
        "camera_model: ds\nintrinsics: [0.1, 0.6, 300, 300, 320, 240]\nresolution: [640, 480]\n";
    let msg = error_of(ds);
    // Calibrated by `msreg calibrate cameras`, refused by the pipelines that cannot use it yet.
    assert!(
        msg.contains(":1:") && msg.contains("`ds`") && msg.contains("not yet supported"),
        "{msg}"
    );
    let dist = KALIBR_PINHOLE.replace("distortion_model: radtan", "distortion_model: fov");
    assert!(error_of(&dist).contains("fov"));
}

#[test]
fn wrong_counts_and_malformed_yaml_are_errors() {
    let short =
        KALIBR_PINHOLE.replace("[458.654, 457.296, 367.215, 248.375]", "[458.654, 457.296]");
    assert!(error_of(&short).contains("intrinsics"));
    let coeffs = KALIBR_PINHOLE.replace("1.76187114e-05]", "1.76187114e-05, 0.1, 0.2]");
    assert!(error_of(&coeffs).contains("coefficients"));
    let negative = KALIBR_PINHOLE.replace("458.654,", "-458.654,");
    assert!(error_of(&negative).contains("invalid camera"));
    let broken = "camera_model: pinhole\nintrinsics: [1, 2\n";
    let err = parse_camera_yaml(Path::new("cams/camera.yaml"), broken).unwrap_err();
    assert!(matches!(err, YamlError::Syntax { .. }), "{err}");
    let err = read_camera_yaml(Path::new("/nonexistent/camera.yaml")).unwrap_err();
    assert!(
        matches!(err, YamlError::Io { .. }) && err.to_string().contains("/nonexistent/camera.yaml")
    );
}

#[test]
fn kalibr_checkerboard_and_board_targets_are_read() {
    let text = "target_type: 'checkerboard'\ntargetCols: 9\ntargetRows: 6\n\
                rowSpacingMeters: 0.025\ncolSpacingMeters: 0.03\n";
    let Target::Checkerboard(cb) = parse_target_yaml(Path::new("target.yaml"), text).unwrap()
    else {
        panic!("not a checkerboard")
    };
    assert_eq!((cb.rows, cb.cols), (6, 9));
    assert_eq!(cb.width_m, None);
    // Kalibr: id r * cols + c at (r * row spacing, c * col spacing, 0).
    assert!((cb.corner_in_target(9 + 2) - Vector3::new(0.025, 0.06, 0.0)).norm() < 1e-15);
    let with_size = format!("{text}width_m: 0.5\nheight_m: 0.4\n");
    let Target::Checkerboard(cb) = parse_target_yaml(Path::new("t.yaml"), &with_size).unwrap()
    else {
        panic!("not a checkerboard")
    };
    assert_eq!((cb.width_m, cb.height_m), (Some(0.5), Some(0.4)));
    let board = "target_type: board\nwidth_m: 1.0\nheight_m: 0.8\n";
    assert_eq!(
        parse_target_yaml(Path::new("t.yaml"), board).unwrap(),
        Target::Board(Board {
            width_m: 1.0,
            height_m: 0.8
        })
    );
}

#[test]
fn bad_targets_are_errors_naming_file_and_line() {
    let april = "target_type: 'aprilgrid'\ntagCols: 6\n";
    let msg = parse_target_yaml(Path::new("cfg/target.yaml"), april)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("cfg/target.yaml:1:") && msg.contains("aprilgrid"),
        "{msg}"
    );
    let tiny = "target_type: checkerboard\ntargetCols: 2\ntargetRows: 6\n\
                rowSpacingMeters: 0.025\ncolSpacingMeters: 0.025\n";
    let msg = parse_target_yaml(Path::new("t.yaml"), tiny)
        .unwrap_err()
        .to_string();
    assert!(
        msg.contains("t.yaml:2:") && msg.contains("targetCols"),
        "{msg}"
    );
    let missing = "target_type: checkerboard\ntargetCols: 9\ntargetRows: 6\n";
    let msg = parse_target_yaml(Path::new("t.yaml"), missing)
        .unwrap_err()
        .to_string();
    assert!(msg.contains("rowSpacingMeters"), "{msg}");
    assert!(read_target_yaml(Path::new("/nonexistent/target.yaml")).is_err());
}

#[test]
fn written_camera_and_target_yaml_read_back_exactly() {
    use msreg_host::camera_yaml::{camera_yaml_string, checkerboard_yaml_string};
    for text in [
        KALIBR_PINHOLE,
        "camera_model: pinhole\nintrinsics: [290.05, 289.39, 399.94, 273.89]\n\
         distortion_model: equidistant\n\
         distortion_coeffs: [-0.030464, -0.019695, 0.002098, 1.0e-9]\n\
         resolution: [800, 503]\n",
        "camera_model: omni\nintrinsics: [0.9, 750, 748, 640, 480]\n\
         distortion_model: none\ndistortion_coeffs: []\nresolution: [1280, 960]\n",
    ] {
        let cam = parse_camera_yaml(Path::new("in.yaml"), text).unwrap();
        let written = camera_yaml_string(&cam);
        assert_eq!(
            parse_camera_yaml(Path::new("out.yaml"), &written).unwrap(),
            cam,
            "{written}"
        );
    }
    let text = "target_type: 'checkerboard'\ntargetCols: 7\ntargetRows: 6\n\
                rowSpacingMeters: 0.06\ncolSpacingMeters: 0.055\nwidth_m: 0.6\n";
    let Target::Checkerboard(cb) = parse_target_yaml(Path::new("t.yaml"), text).unwrap() else {
        panic!("not a checkerboard")
    };
    let written = checkerboard_yaml_string(&cb);
    assert_eq!(
        parse_target_yaml(Path::new("t.yaml"), &written).unwrap(),
        Target::Checkerboard(cb)
    );
}
