//! `msreg simulate infra`: the written layout reads back, COLMAP's +0.5 pixel convention and
//! world-to-camera poses hold, marker corners are in OpenCV order, and bad files are named.

use msreg_host::infra::dataset::InfraDataset;
use msreg_host::infra::io::InfraResultFile;
use msreg_host::infra::sim::{simulate, InfraSimConfig};
use nalgebra::{Point3, Vector3};

fn config(seed: u64) -> InfraSimConfig {
    InfraSimConfig {
        seed,
        building_seed: seed,
        ..InfraSimConfig::default()
    }
}

#[test]
fn written_dataset_reads_back_with_opencv_pixels() {
    let sim = simulate(&config(3));
    let dir = tempfile::tempdir().expect("tempdir");
    sim.write(dir.path()).expect("write");
    let data = InfraDataset::open(dir.path()).expect("read back");
    assert_eq!(data.cameras.len(), 40);
    assert_eq!(data.vo.images.len(), sim.vo.images.len());
    // COLMAP text stores OpenCV + 0.5: the raw file's principal point is 512.0.
    let cams = std::fs::read_to_string(dir.path().join("vo/cameras.txt")).expect("cameras.txt");
    assert!(
        cams.contains("OPENCV_FISHEYE 1024 1024 300 300 512 512"),
        "{cams}"
    );
    assert!((data.vo.camera.intrinsics().cu - 511.5).abs() < 1e-12);
    // A keypoint read back equals the simulated OpenCV pixel.
    let (a, b) = (
        &sim.vo.images[10].keypoints[0],
        &data.vo.images[10].keypoints[0],
    );
    assert!((a.0 - b.0).norm() < 1e-9);
    // World-to-camera: a tracked point lies in front of the (upward) keyframe camera.
    let img = &data.vo.images[10];
    let p = data.vo.points[img.keypoints[0].1.expect("tracked")];
    let in_cam = img.t_cam_world * Point3::from(p);
    assert!(in_cam.z > 0.0, "point behind camera: {in_cam}");
    for (cam, input) in sim.cameras.iter().zip(&data.cameras) {
        assert_eq!(cam.id, input.id);
        assert!(
            input.detections.as_ref().expect("markers.csv").len() >= 30,
            "{} sees the marker too rarely",
            cam.id
        );
    }
    let gt = InfraResultFile::read(&dir.path().join("groundtruth/infra.yaml")).expect("gt");
    assert_eq!(gt.infra.cameras.len(), 40);
}

#[test]
fn marker_corners_are_in_opencv_order() {
    // Top-left, top-right, bottom-right, bottom-left of the printed marker as seen by the
    // camera: going round the four corners is clockwise in the image (y down).
    let sim = simulate(&config(1));
    for det in sim.detections.iter().flatten().take(500) {
        let c = &det.corners;
        let area: f64 = (0..4)
            .map(|i| c[i].x * c[(i + 1) % 4].y - c[(i + 1) % 4].x * c[i].y)
            .sum();
        assert!(area > 0.0, "corners counter-clockwise in the image: {c:?}");
    }
}

#[test]
fn vo_drifts_about_one_percent_and_cameras_look_down() {
    for seed in 0..3 {
        let sim = simulate(&config(seed));
        assert!(
            (0.001..0.03).contains(&sim.vo_drift_fraction),
            "drift {}",
            sim.vo_drift_fraction
        );
        let up = sim
            .cameras
            .iter()
            .filter(|c| (c.t_world_cam.rotation * Vector3::z()).z > -0.45)
            .count();
        assert!(up < 40, "every camera should look down");
    }
}

#[test]
fn bad_colmap_and_csv_lines_are_named() {
    let sim = simulate(&config(2));
    let dir = tempfile::tempdir().expect("tempdir");
    sim.write(dir.path()).expect("write");
    let images = dir.path().join("vo/images.txt");
    let text = std::fs::read_to_string(&images).expect("images.txt");
    let broken = text.replacen(" 1 1700", " 1 x1700", 1);
    std::fs::write(&images, broken).expect("write");
    let err = InfraDataset::open(dir.path())
        .expect_err("bad NAME")
        .to_string();
    assert!(
        err.contains("images.txt:3:") && err.contains("NAME"),
        "{err}"
    );
    std::fs::write(&images, text).expect("restore");
    // A COLMAP camera that is not cam0's F.
    let cams = dir.path().join("vo/cameras.txt");
    let c = std::fs::read_to_string(&cams)
        .expect("cameras.txt")
        .replace(" 300 300 ", " 310 310 ");
    std::fs::write(&cams, c).expect("write");
    let err = InfraDataset::open(dir.path())
        .expect_err("mismatch")
        .to_string();
    assert!(
        err.contains("cameras.txt") && err.contains("does not match cam0"),
        "{err}"
    );
}
