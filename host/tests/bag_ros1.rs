//! ROS 1 bags in: the real robot_localization test bag (IMU + wheel odometry of a Jackal)
//! and a simulated pose-IMU dataset written by this test as a ROS 1 bag.

mod bag_common;

use std::path::Path;

use bag_common::{imu_msg, odometry_msg, write_ros1_bag, Recorded};
use msreg_host::bag::wire::Dialect;
use msreg_host::bag::{
    self, BagError, BagFormat, BagWarning, ConvertOptions, Role, TopicChoice, Topics,
};
use msreg_host::calibrate::driver::report::{PoseImuCalibration, PoseImuOptions};
use msreg_host::calibrate::pose_imu::{self, PoseImuInput};
use msreg_host::dataset::{
    read_imu_csv, read_pose_csv, ImuNoiseYaml, PoseSensorYaml, IMU_CSV, IMU_YAML, POSE_CSV,
    POSE_SENSOR_YAML,
};
use msreg_host::sim::{simulate_pose_imu, SimConfig};

type TestResult = Result<(), Box<dyn std::error::Error>>;

/// The real Jackal bag, or `None` with a `SKIP:` notice (a failure under CI) where the
/// shared data is absent (`msreg_host::shared_data`).
fn real_bag() -> Option<std::path::PathBuf> {
    msreg_host::shared_data::file_or_skip("real/robot_localization-test2.bag")
}

#[test]
fn real_robot_localization_bag_converts_with_auto_detected_topics() -> TestResult {
    let Some(path) = real_bag() else {
        return Ok(());
    };
    // Given the real bag, when converted with no topic named
    let dir = tempfile::tempdir()?;
    let out = dir.path().join("rl2");
    let summary = bag::convert(&path, &Topics::default(), &out, &mut |_| {})?;
    // Then the one Imu and the one Odometry topic become imu0 and pose0, at 50 Hz
    assert_eq!(summary.format, BagFormat::Ros1);
    let streams: Vec<_> = summary
        .streams
        .iter()
        .map(|s| (s.role, s.topic.as_str(), s.frame_id.as_str(), s.written))
        .collect();
    assert_eq!(
        streams,
        [
            (Role::Imu, "/imu/data", "base_link", 3061),
            (Role::Pose, "/jackal_velocity_controller/odom", "odom", 3060),
        ]
    );
    for s in &summary.streams {
        assert!(
            (s.cadence.rate_hz - 50.0).abs() < 0.5,
            "{}",
            s.cadence.rate_hz
        );
    }
    let imu = read_imu_csv(out.join(IMU_CSV))?;
    let poses = read_pose_csv(out.join(POSE_CSV))?;
    assert_eq!((imu.len(), poses.len()), (3061, 3060));
    // At rest at the start: |a| about g, so the units check stays quiet
    assert!((imu[0].accel.norm() - 9.8).abs() < 0.3);
    // And the bag's lack of noise figures and its low IMU rate are said
    let has = |f: &dyn Fn(&BagWarning) -> bool| summary.warnings.iter().any(f);
    assert!(has(&|w| matches!(w, BagWarning::LowRate { .. })));
    assert!(has(&|w| matches!(w, BagWarning::DefaultImuNoise { .. })));
    assert!(has(&|w| matches!(w, BagWarning::DefaultPoseNoise)));
    assert!(!has(&|w| matches!(
        w,
        BagWarning::AccelUnits { .. } | BagWarning::Gaps { .. }
    )));
    assert_eq!(
        ImuNoiseYaml::read(out.join(IMU_YAML))?
            .gyroscope_noise_density
            .to_bits(),
        bag::DEFAULT_IMU_NOISE.gyroscope_noise_density.to_bits()
    );
    Ok(())
}

#[test]
fn real_bag_named_topic_errors_are_typed() -> TestResult {
    let Some(path) = real_bag() else {
        return Ok(());
    };
    let dir = tempfile::tempdir()?;
    let out = dir.path().join("x");
    let topics = Topics {
        imu: TopicChoice::Topic("/imu/nope".into()),
        ..Topics::default()
    };
    let err = bag::convert(&path, &topics, &out, &mut |_| {})
        .err()
        .ok_or("expected error")?;
    assert!(matches!(err, BagError::TopicNotFound { .. }), "{err}");
    let topics = Topics {
        imu: TopicChoice::Topic("/jackal_velocity_controller/odom".into()),
        ..Topics::default()
    };
    let err = bag::convert(&path, &topics, &out, &mut |_| {})
        .err()
        .ok_or("expected error")?;
    assert!(
        matches!(&err, BagError::WrongType { role: "imu", found, .. } if found == "nav_msgs/Odometry"),
        "{err}"
    );
    Ok(())
}

fn calibrate(dir: &Path) -> Result<PoseImuCalibration, Box<dyn std::error::Error>> {
    let imu = read_imu_csv(dir.join(IMU_CSV))?;
    let poses = read_pose_csv(dir.join(POSE_CSV))?;
    let input = PoseImuInput {
        imu: &imu,
        imu_noise: &ImuNoiseYaml::read(dir.join(IMU_YAML))?,
        poses: &poses,
        pose_noise: &PoseSensorYaml::read(dir.join(POSE_SENSOR_YAML))?,
    };
    Ok(pose_imu::calibrate::<f64>(
        &input,
        &PoseImuOptions::default(),
        &mut |_| {},
    )?)
}

#[test]
fn simulated_pose_imu_round_trips_through_a_ros1_bag() -> TestResult {
    // Given a simulated pose-IMU dataset on disk
    let dir = tempfile::tempdir()?;
    let original = dir.path().join("sim");
    let config = SimConfig {
        seed: 11,
        duration_s: 30.0,
        ..SimConfig::default()
    };
    simulate_pose_imu(&config)?.write(&original)?;
    // When its files are written as a ROS 1 bag and converted with its noise files
    let imu = read_imu_csv(original.join(IMU_CSV))?;
    let poses = read_pose_csv(original.join(POSE_CSV))?;
    let mut messages: Vec<Recorded> = imu
        .iter()
        .enumerate()
        .map(|(i, r)| Recorded {
            topic: "/imu".into(),
            msg_type: "sensor_msgs/Imu".into(),
            log_time_ns: r.stamp_ns + 500_000,
            data: imu_msg(Dialect::Ros1, i as u32, r, "imu", [0.0, 0.0]),
        })
        .collect();
    messages.extend(poses.iter().enumerate().map(|(i, p)| Recorded {
        topic: "/odom".into(),
        msg_type: "nav_msgs/Odometry".into(),
        log_time_ns: p.stamp_ns + 2_000_000,
        data: odometry_msg(Dialect::Ros1, i as u32, p, "odom", "base_link"),
    }));
    messages.sort_by_key(|m| m.log_time_ns);
    let bag_path = dir.path().join("sim.bag");
    write_ros1_bag(&bag_path, &messages);
    let converted = dir.path().join("converted");
    let options = ConvertOptions {
        imu_noise: Some(ImuNoiseYaml::read(original.join(IMU_YAML))?),
        pose_noise: Some(PoseSensorYaml::read(original.join(POSE_SENSOR_YAML))?),
        ..ConvertOptions::default()
    };
    let summary = bag::convert_with(&bag_path, &options, &converted, &mut |_| {})?;
    // Then the CSVs are bit-exact copies and the calibration is the directory's
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    assert_eq!(read_imu_csv(converted.join(IMU_CSV))?, imu);
    assert_eq!(read_pose_csv(converted.join(POSE_CSV))?, poses);
    let (a, b) = (calibrate(&original)?, calibrate(&converted)?);
    assert_eq!(a.t_imu_sensor, b.t_imu_sensor);
    assert_eq!(a.time_offset_s.to_bits(), b.time_offset_s.to_bits());
    Ok(())
}

#[test]
fn a_file_that_is_no_bag_is_refused() -> TestResult {
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("x.bag");
    std::fs::write(&path, b"not a bag at all")?;
    let err = bag::convert(&path, &Topics::default(), dir.path(), &mut |_| {})
        .err()
        .ok_or("expected error")?;
    assert!(matches!(err, BagError::UnknownFormat { .. }), "{err}");
    Ok(())
}
