//! Camera and pose topics through MCAP: raw images become PNGs with the same pixels,
//! `geometry_msgs/PoseStamped` becomes `pose0/`, two IMU topics make auto-detection step
//! back with a warning, and the camera files are copied when given.

mod bag_common;

use bag_common::{imu_msg, mono8_image_msg, pose_stamped_msg, write_mcap, Recorded};
use msreg_host::bag::wire::Dialect;
use msreg_host::bag::{self, BagWarning, ConvertOptions, Role, TopicChoice, Topics};
use msreg_host::dataset::{
    read_camera_csv, read_pose_csv, ImuRecord, PoseRecord, CAMERA_CSV, CAMERA_YAML, POSE_CSV,
    TARGET_YAML,
};
use nalgebra::{UnitQuaternion, Vector3};

type TestResult = Result<(), Box<dyn std::error::Error>>;

const T0: u64 = 1_700_000_000_000_000_000;

fn recorded(topic: &str, msg_type: &str, log_time_ns: u64, data: Vec<u8>) -> Recorded {
    Recorded {
        topic: topic.into(),
        msg_type: msg_type.into(),
        log_time_ns,
        data,
    }
}

/// Three 5 x 4 grey images, two IMU topics, ten poses at 10 Hz.
fn messages() -> (Vec<Recorded>, Vec<Vec<u8>>, Vec<PoseRecord>) {
    let images: Vec<Vec<u8>> = (0..3u8)
        .map(|k| {
            (0..20u8)
                .map(|i| i.wrapping_mul(13).wrapping_add(k))
                .collect()
        })
        .collect();
    let poses: Vec<PoseRecord> = (0..10)
        .map(|k| PoseRecord {
            stamp_ns: T0 + k * 100_000_000,
            position: Vector3::new(0.1 * k as f64, 0.0, 0.5),
            rotation: UnitQuaternion::from_euler_angles(0.0, 0.0, 0.05 * k as f64),
        })
        .collect();
    let mut out = Vec::new();
    for (k, img) in images.iter().enumerate() {
        let stamp = T0 + k as u64 * 50_000_000;
        let data = mono8_image_msg(Dialect::Cdr, stamp, "cam", (5, 8), img);
        out.push(recorded(
            "/cam/image_raw",
            "sensor_msgs/Image",
            stamp + 1,
            data,
        ));
    }
    for (k, p) in poses.iter().enumerate() {
        let data = pose_stamped_msg(Dialect::Cdr, k as u32, p, "map");
        out.push(recorded(
            "/vo/pose",
            "geometry_msgs/PoseStamped",
            p.stamp_ns + 2,
            data,
        ));
    }
    for topic in ["/imu_a", "/imu_b"] {
        let r = ImuRecord {
            stamp_ns: T0,
            gyro: Vector3::zeros(),
            accel: Vector3::new(0.0, 0.0, 9.81),
        };
        let data = imu_msg(Dialect::Cdr, 0, &r, "imu", [0.0, 0.0]);
        out.push(recorded(topic, "sensor_msgs/Imu", T0 + 3, data));
    }
    out.sort_by_key(|m| m.log_time_ns);
    (out, images, poses)
}

#[test]
fn images_and_pose_stamped_convert_and_two_imus_are_not_guessed() -> TestResult {
    // Given an MCAP with a camera, a PoseStamped topic and two IMU topics
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("cam.mcap");
    let (recording, images, poses) = messages();
    write_mcap(&path, &recording, "cdr");
    // When converted with auto-detection
    let out = dir.path().join("out");
    let summary = bag::convert(&path, &Topics::default(), &out, &mut |_| {})?;
    // Then the camera frames are PNGs with the same pixels (row padding dropped)
    let frames = read_camera_csv(out.join(CAMERA_CSV))?;
    assert_eq!(frames.len(), 3);
    for (k, (frame, pixels)) in frames.iter().zip(&images).enumerate() {
        assert_eq!(frame.stamp_ns, T0 + k as u64 * 50_000_000);
        let png = image::open(&frame.path)?.to_luma8();
        assert_eq!((png.width(), png.height()), (5, 4));
        assert_eq!(&png.into_raw(), pixels);
    }
    // And the poses are the PoseStamped ones
    assert_eq!(read_pose_csv(out.join(POSE_CSV))?, poses);
    // And the IMU role was skipped with a warning naming both topics
    let roles: Vec<Role> = summary.streams.iter().map(|s| s.role).collect();
    assert_eq!(roles, [Role::Camera, Role::Pose]);
    assert!(summary.warnings.iter().any(|w| matches!(
        w,
        BagWarning::AmbiguousTopic { role: "imu", candidates } if candidates.len() == 2
    )));
    let missing = |f: &str| {
        summary
            .warnings
            .iter()
            .any(|w| matches!(w, BagWarning::MissingCameraFile { file } if *file == f))
    };
    assert!(missing(CAMERA_YAML) && missing(TARGET_YAML));
    Ok(())
}

#[test]
fn named_imu_and_camera_files_are_used() -> TestResult {
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("cam.mcap");
    write_mcap(&path, &messages().0, "cdr");
    let camera_yaml = dir.path().join("camera.yaml");
    std::fs::write(&camera_yaml, "camera_model: pinhole\n")?;
    let target_yaml = dir.path().join("target.yaml");
    std::fs::write(&target_yaml, "target_type: checkerboard\n")?;
    let options = ConvertOptions {
        topics: Topics {
            imu: TopicChoice::Topic("/imu_b".into()),
            pose: TopicChoice::Skip,
            ..Topics::default()
        },
        camera_yaml: Some(camera_yaml),
        target_yaml: Some(target_yaml),
        ..ConvertOptions::default()
    };
    let out = dir.path().join("out");
    let summary = bag::convert_with(&path, &options, &out, &mut |_| {})?;
    let topics: Vec<&str> = summary.streams.iter().map(|s| s.topic.as_str()).collect();
    assert_eq!(topics, ["/imu_b", "/cam/image_raw"]);
    assert_eq!(
        std::fs::read_to_string(out.join(CAMERA_YAML))?,
        "camera_model: pinhole\n"
    );
    assert!(out.join(TARGET_YAML).is_file());
    assert!(!out.join("pose0").exists());
    Ok(())
}
