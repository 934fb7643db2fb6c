//! Feature extraction on simulated frames against the simulator's truth.

use nalgebra::Vector3;

use super::camera_features::{extract_camera_board, CameraFeatureParams, CameraReject};
use super::lidar_features::{extract_lidar_board, LidarFeatureParams, LidarReject};
use crate::sim::lidar_camera::{
    simulate_lidar_camera, FrameKind, LidarCameraSimConfig, LidarModel,
};

#[test]
fn features_of_a_good_frame_match_the_truth_and_bad_frames_are_rejected() {
    let sim = simulate_lidar_camera(&LidarCameraSimConfig {
        seed: 5,
        lidar: LidarModel::Ouster,
        poses: 1,
        bad_frames: true,
        ..LidarCameraSimConfig::default()
    })
    .expect("simulate");
    let board = sim.config.board;
    let truth = sim.frames[0].t_lidar_target;
    let lidar = extract_lidar_board(&sim.scan(0), &board, &LidarFeatureParams::default())
        .expect("board in the scan");
    // Plane normal within 1 deg, sides within 3 cm of the board's.
    let n_true = truth.rotation * Vector3::z();
    assert!(lidar.normal.dot(&n_true).abs() > 1f64.to_radians().cos());
    let mut sides = lidar.quality.side_lengths_m;
    sides.sort_by(f64::total_cmp);
    for (s, t) in sides.iter().zip([0.8, 0.8, 1.0, 1.0]) {
        assert!((s - t).abs() < 0.03, "sides {sides:?}");
    }
    // Edge points lie on the true board edges within 2 cm.
    for e in &lidar.edges {
        for p in &e.points {
            let local = truth.inverse_transform_point(&nalgebra::Point3::from(*p));
            let to_edge = (0.5 * board.width_m - local.x.abs())
                .abs()
                .min((0.5 * board.height_m - local.y.abs()).abs());
            assert!(to_edge < 0.02, "edge point {to_edge} m from the edges");
        }
    }
    let cam = extract_camera_board(
        &sim.image(0),
        &sim.camera,
        &board,
        &CameraFeatureParams::default(),
    )
    .expect("board in the image");
    let t_cam_target = sim.t_cam_target(0).expect("frame 0");
    let n_cam = t_cam_target.rotation * Vector3::z();
    assert!(cam.normal.dot(&n_cam) > 0.2f64.to_radians().cos());
    assert!((cam.offset - n_cam.dot(&t_cam_target.translation.vector)).abs() < 0.01);
    // Every true board corner lies on two back-projected planes (within 0.05 deg).
    for corner in board.corners() {
        let x = (t_cam_target * nalgebra::Point3::from(corner))
            .coords
            .normalize();
        let on = cam
            .edges
            .iter()
            .filter(|e| e.normal.dot(&x).abs() < 0.05f64.to_radians())
            .count();
        assert_eq!(on, 2, "corner {corner:?}");
    }
    for (k, kind) in sim.frames.iter().enumerate().map(|(k, f)| (k, f.kind)) {
        let img = sim.image(k);
        let result =
            extract_camera_board(&img, &sim.camera, &board, &CameraFeatureParams::default());
        match kind {
            FrameKind::Good => assert!(result.is_ok()),
            FrameKind::Missing => {
                assert_eq!(result.unwrap_err(), CameraReject::NoBoard);
                let l = extract_lidar_board(&sim.scan(k), &board, &LidarFeatureParams::default());
                assert!(matches!(l, Err(LidarReject::NoBoard { .. })), "{l:?}");
            }
            FrameKind::CutByBorder => assert_eq!(result.unwrap_err(), CameraReject::CutByBorder),
            FrameKind::EdgeOn => {
                assert!(
                    matches!(result, Err(CameraReject::EdgeOn { .. })),
                    "{result:?}"
                );
            }
        }
    }
}
