//! MCAP in: a simulated LiDAR-IMU dataset, CDR-encoded by this test into an MCAP file,
//! converts back to the same dataset (IMU CSV and PCD points bit-exact) and calibrates to
//! the same result as the directory.

mod bag_common;

use std::path::Path;

use bag_common::{cloud_msg, imu_msg, write_mcap, Recorded};
use msreg_host::bag::wire::Dialect;
use msreg_host::bag::{self, BagError, BagWarning, ConvertOptions, PointTime, TimeUnit, Topics};
use msreg_host::calibrate::lidar_imu::{self, LidarImuCalibration, LidarImuInput, LidarImuOptions};
use msreg_host::dataset::{
    list_scans, read_imu_csv, ImuNoiseYaml, ImuRecord, IMU_CSV, IMU_YAML, LIDAR_DIR,
};
use msreg_host::lidar::FileScans;
use msreg_host::pointcloud::read_pcd;
use msreg_host::sim::{simulate_lidar_imu, LidarImuSimConfig, LidarSimConfig};
use nalgebra::Vector3;

type TestResult = Result<(), Box<dyn std::error::Error>>;

/// Writes a small simulated LiDAR-IMU dataset (16 x 256 beams) under `dir`.
fn simulated_dataset(dir: &Path, duration_s: f64) -> TestResult {
    simulated_dataset_of(dir, duration_s, (16, 256))
}

/// Writes a simulated LiDAR-IMU dataset of `(rings, columns)` beams under `dir`.
fn simulated_dataset_of(
    dir: &Path,
    duration_s: f64,
    (rings, columns): (usize, usize),
) -> TestResult {
    let config = LidarImuSimConfig {
        seed: 3,
        duration_s,
        lidar: LidarSimConfig {
            rings,
            columns,
            time_offset_s: 0.004,
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    };
    simulate_lidar_imu(&config)?.write(dir, &mut |_| {})?;
    Ok(())
}

/// The dataset's IMU rows and scans (read from its files) as CDR messages, in the order a
/// recorder would log them (a sweep arrives when it ends, 0.1 s after its stamp).
fn recorded_messages(dir: &Path) -> Result<Vec<Recorded>, Box<dyn std::error::Error>> {
    let mut out = Vec::new();
    for (seq, r) in read_imu_csv(dir.join(IMU_CSV))?.iter().enumerate() {
        out.push(Recorded {
            topic: "/imu/data".into(),
            msg_type: "sensor_msgs/Imu".into(),
            log_time_ns: r.stamp_ns + 1_000_000,
            data: imu_msg(Dialect::Cdr, seq as u32, r, "imu_link", [1e-6, 1e-4]),
        });
    }
    for (seq, scan) in list_scans(&dir.join(LIDAR_DIR))?.iter().enumerate() {
        let cloud = read_pcd(&scan.path)?;
        out.push(Recorded {
            topic: "/ouster/points".into(),
            msg_type: "sensor_msgs/PointCloud2".into(),
            log_time_ns: scan.stamp_ns + 100_000_000,
            data: cloud_msg(Dialect::Cdr, seq as u32, scan.stamp_ns, "os_lidar", &cloud),
        });
    }
    out.sort_by_key(|m| m.log_time_ns);
    Ok(out)
}

fn calibrate(dir: &Path) -> Result<LidarImuCalibration, Box<dyn std::error::Error>> {
    let imu = read_imu_csv(dir.join(IMU_CSV))?;
    let imu_noise = ImuNoiseYaml::read(dir.join(IMU_YAML))?;
    let scans = FileScans {
        files: list_scans(&dir.join(LIDAR_DIR))?,
    };
    let input = LidarImuInput {
        imu: &imu,
        imu_noise: &imu_noise,
        scans: &scans,
    };
    Ok(lidar_imu::calibrate::<f64>(
        &input,
        &LidarImuOptions::default(),
        &mut |_| {},
    )?)
}

/// Given a simulated dataset and its MCAP, when converted with the dataset's imu.yaml,
/// then the IMU rows and every scan's points are bit-exact copies.
fn assert_round_trip(original: &Path, converted: &Path) -> TestResult {
    assert_eq!(
        read_imu_csv(converted.join(IMU_CSV))?,
        read_imu_csv(original.join(IMU_CSV))?
    );
    let a = list_scans(&original.join(LIDAR_DIR))?;
    let b = list_scans(&converted.join(LIDAR_DIR))?;
    assert_eq!(
        a.iter().map(|s| s.stamp_ns).collect::<Vec<_>>(),
        b.iter().map(|s| s.stamp_ns).collect::<Vec<_>>()
    );
    for (sa, sb) in a.iter().zip(&b) {
        assert_eq!(
            read_pcd(&sa.path)?,
            read_pcd(&sb.path)?,
            "{}",
            sb.path.display()
        );
    }
    Ok(())
}

fn convert_mcap(
    dir: &Path,
    original: &Path,
) -> Result<(std::path::PathBuf, bag::ConvertSummary), Box<dyn std::error::Error>> {
    let mcap_path = dir.join("sim.mcap");
    write_mcap(&mcap_path, &recorded_messages(original)?, "cdr");
    let converted = dir.join("converted");
    let options = ConvertOptions {
        imu_noise: Some(ImuNoiseYaml::read(original.join(IMU_YAML))?),
        ..ConvertOptions::default()
    };
    let mut fractions = Vec::new();
    let summary = bag::convert_with(&mcap_path, &options, &converted, &mut |f| fractions.push(f))?;
    assert!(fractions.windows(2).all(|w| w[0] <= w[1]));
    assert_eq!(fractions.last().copied(), Some(1.0));
    Ok((converted, summary))
}

#[test]
fn simulated_lidar_imu_mcap_converts_back_bit_exact() -> TestResult {
    let dir = tempfile::tempdir()?;
    let original = dir.path().join("sim");
    simulated_dataset(&original, 3.0)?;
    let (converted, summary) = convert_mcap(dir.path(), &original)?;
    assert_round_trip(&original, &converted)?;
    assert_eq!(
        summary.lidar_time,
        Some(PointTime::Field {
            name: "t".into(),
            unit: TimeUnit::Nanoseconds,
            absolute: false,
        })
    );
    assert_eq!(
        ImuNoiseYaml::read(converted.join(IMU_YAML))?,
        ImuNoiseYaml::read(original.join(IMU_YAML))?
    );
    let imu = &summary.streams[0];
    assert_eq!(
        (imu.topic.as_str(), imu.frame_id.as_str()),
        ("/imu/data", "imu_link")
    );
    assert!(
        (imu.cadence.rate_hz - 400.0).abs() < 1e-6,
        "{}",
        imu.cadence.rate_hz
    );
    // The simulator's clean streams raise no sanity warning.
    assert!(summary.warnings.is_empty(), "{:?}", summary.warnings);
    Ok(())
}

#[test]
fn simulated_lidar_imu_mcap_calibrates_like_the_directory() -> TestResult {
    let dir = tempfile::tempdir()?;
    let original = dir.path().join("sim");
    let duration = std::env::var("MSREG_BAG_DURATION")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(12.0);
    simulated_dataset(&original, duration)?;
    let (converted, _) = convert_mcap(dir.path(), &original)?;
    assert_round_trip(&original, &converted)?;
    let a = calibrate(&original)?;
    let b = calibrate(&converted)?;
    let dr = a.t_imu_sensor.rotation.angle_to(&b.t_imu_sensor.rotation);
    let dp = (a.t_imu_sensor.translation.vector - b.t_imu_sensor.translation.vector).norm();
    let dt = (a.time_offset_s - b.time_offset_s).abs();
    eprintln!(
        "directory vs MCAP: rotation {dr:.3e} rad, translation {dp:.3e} m, time offset {dt:.3e} s"
    );
    assert!(dr <= 1e-9 && dp <= 1e-9 && dt <= 1e-9);
    Ok(())
}

/// An IMU sample at rest.
fn at_rest(stamp_ns: u64) -> ImuRecord {
    ImuRecord {
        stamp_ns,
        gyro: Vector3::zeros(),
        accel: Vector3::new(0.0, 0.0, 9.81),
    }
}

/// The error of converting `path` (auto-detected topics) under `dir`.
fn convert_error(path: &Path, dir: &Path) -> Result<BagError, Box<dyn std::error::Error>> {
    Ok(
        bag::convert(path, &Topics::default(), &dir.join("out"), &mut |_| {})
            .err()
            .ok_or("expected an error")?,
    )
}

#[test]
fn mcap_topic_in_an_unknown_encoding_is_a_typed_error() -> TestResult {
    // Given an MCAP whose only IMU channel is protobuf-encoded
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("pb.mcap");
    let message = Recorded {
        topic: "/imu".into(),
        msg_type: "sensor_msgs/Imu".into(),
        log_time_ns: 1,
        data: vec![1, 2, 3],
    };
    write_mcap(&path, &[message], "protobuf");
    // When it is converted, then the error names the topic and the encoding
    let err = convert_error(&path, dir.path())?;
    assert!(
        matches!(&err, BagError::UnsupportedEncoding { topic, encoding, .. }
            if topic == "/imu" && encoding == "protobuf"),
        "{err}"
    );
    Ok(())
}

#[test]
fn truncated_cdr_message_names_topic_and_index() -> TestResult {
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("short.mcap");
    let mut data = imu_msg(Dialect::Cdr, 0, &at_rest(5), "imu", [0.0, 0.0]);
    let good = data.clone();
    data.truncate(100);
    let messages = [good, data].map(|data| Recorded {
        topic: "/imu".into(),
        msg_type: "sensor_msgs/Imu".into(),
        log_time_ns: 1,
        data,
    });
    write_mcap(&path, &messages, "cdr");
    let err = convert_error(&path, dir.path())?;
    assert!(
        matches!(&err, BagError::Decode { topic, index: 1, .. } if topic == "/imu"),
        "{err}"
    );
    Ok(())
}

#[test]
fn zero_and_backward_stamps_are_warned_and_sorted() -> TestResult {
    // Given IMU messages at 100 Hz logged out of order, one with a zero header stamp
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("jumpy.mcap");
    let stamps = [
        1_000_000_000u64,
        1_020_000_000,
        1_010_000_000,
        0,
        1_030_000_000,
    ];
    let messages: Vec<Recorded> = stamps
        .iter()
        .enumerate()
        .map(|(i, &stamp_ns)| Recorded {
            topic: "/imu".into(),
            msg_type: "sensor_msgs/Imu".into(),
            log_time_ns: 1_000_000_000 + 10_000_000 * i as u64 + 5_000_000,
            data: imu_msg(
                Dialect::Cdr,
                i as u32,
                &at_rest(stamp_ns),
                "imu",
                [0.0, 0.0],
            ),
        })
        .collect();
    write_mcap(&path, &messages, "cdr");
    let out = dir.path().join("out");
    let summary = bag::convert(&path, &Topics::default(), &out, &mut |_| {})?;
    // Then the CSV is sorted, the zero stamp replaced by the log time, and both are warned
    let stamps: Vec<u64> = read_imu_csv(out.join(IMU_CSV))?
        .iter()
        .map(|r| r.stamp_ns)
        .collect();
    assert_eq!(
        stamps,
        [
            1_000_000_000,
            1_010_000_000,
            1_020_000_000,
            1_035_000_000,
            1_030_000_000
        ]
        .iter()
        .copied()
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect::<Vec<_>>()
    );
    let has = |f: &dyn Fn(&BagWarning) -> bool| summary.warnings.iter().any(f);
    assert!(has(&|w| matches!(
        w,
        BagWarning::ZeroStamps { count: 1, .. }
    )));
    assert!(has(&|w| matches!(
        w,
        BagWarning::TimestampJumps { count: 2, .. }
    )));
    assert!(has(&|w| matches!(w, BagWarning::DefaultImuNoise { .. })));
    Ok(())
}

#[test]
fn imu_in_g_and_deg_per_s_is_flagged() -> TestResult {
    // Given an IMU that reports acceleration in g and angular rate in deg/s
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("units.mcap");
    let messages: Vec<Recorded> = (0..20u64)
        .map(|k| {
            let r = ImuRecord {
                stamp_ns: 1_000_000_000 + k * 5_000_000,
                gyro: Vector3::new(0.0, 0.0, 90.0),
                accel: Vector3::new(0.0, 0.0, 1.0),
            };
            Recorded {
                topic: "/imu".into(),
                msg_type: "sensor_msgs/Imu".into(),
                log_time_ns: r.stamp_ns,
                data: imu_msg(Dialect::Cdr, k as u32, &r, "imu", [0.0, 0.0]),
            }
        })
        .collect();
    write_mcap(&path, &messages, "cdr");
    let summary = bag::convert(
        &path,
        &Topics::default(),
        &dir.path().join("out"),
        &mut |_| {},
    )?;
    // Then both units are questioned, and the 200 Hz rate is not
    let has = |f: &dyn Fn(&BagWarning) -> bool| summary.warnings.iter().any(f);
    assert!(has(&|w| matches!(w, BagWarning::AccelUnits { .. })));
    assert!(has(&|w| matches!(w, BagWarning::GyroUnits { .. })));
    assert!(!has(&|w| matches!(w, BagWarning::LowRate { .. })));
    Ok(())
}

#[test]
#[ignore = "benchmark: conversion throughput of a 10 s 64 x 512 MCAP; docs/bags.md"]
fn mcap_conversion_throughput() -> TestResult {
    let dir = tempfile::tempdir()?;
    let original = dir.path().join("sim");
    simulated_dataset_of(&original, 10.0, (64, 512))?;
    let mcap_path = dir.path().join("sim.mcap");
    write_mcap(&mcap_path, &recorded_messages(&original)?, "cdr");
    let options = ConvertOptions {
        imu_noise: Some(ImuNoiseYaml::read(original.join(IMU_YAML))?),
        ..ConvertOptions::default()
    };
    let started = std::time::Instant::now();
    let summary = bag::convert_with(&mcap_path, &options, &dir.path().join("out"), &mut |_| {})?;
    let seconds = started.elapsed().as_secs_f64();
    let mb = std::fs::metadata(&mcap_path)?.len() as f64 / 1e6;
    eprintln!(
        "converted {mb:.1} MB MCAP ({} scans, {} IMU rows) in {seconds:.2} s: {:.0} MB/s",
        summary.streams[1].written,
        summary.streams[0].written,
        mb / seconds
    );
    Ok(())
}
