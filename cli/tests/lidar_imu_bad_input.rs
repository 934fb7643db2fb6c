//! Bad input to the LiDAR-IMU pipeline and CLI never panics: a truncated PCD is an error
//! naming the file (exit code 2), a scan with zero points and scans out of order are
//! skipped and reported, a gap in the IMU data is an error naming the sample.

use std::path::Path;
use std::process::Command;

use msreg_host::calibrate::lidar_imu::{self, LidarImuInput, LidarImuOptions};
use msreg_host::calibrate::InputError;
use msreg_host::lidar::ScanSource;
use msreg_host::pointcloud::PointCloud;
use msreg_host::sim::{simulate_lidar_imu, LidarImuSim, LidarImuSimConfig, LidarSimConfig};

type TestResult = Result<(), Box<dyn std::error::Error>>;

fn small_sim(duration_s: f64) -> Result<LidarImuSim, Box<dyn std::error::Error>> {
    Ok(simulate_lidar_imu(&LidarImuSimConfig {
        seed: 9,
        duration_s,
        lidar: LidarSimConfig {
            rings: 16,
            columns: 256,
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    })?)
}

fn in_memory(sim: &LidarImuSim) -> Vec<(u64, PointCloud)> {
    (0..sim.len())
        .map(|k| (sim.stamp_ns(k), sim.scan(k)))
        .collect()
}

fn options() -> LidarImuOptions {
    LidarImuOptions {
        init_duration_s: 3.0,
        ..LidarImuOptions::default()
    }
}

#[test]
fn zero_point_and_out_of_order_scans_are_skipped_and_reported() -> TestResult {
    let sim = small_sim(5.0)?;
    let mut scans = in_memory(&sim);
    scans[10].1 = PointCloud::default();
    scans.swap(20, 21);
    let input = LidarImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        scans: &scans,
    };
    let c = lidar_imu::calibrate::<f64>(&input, &options(), &mut |_| {})?;
    let skipped = c.report.scans_skipped.join("\n");
    assert!(skipped.contains("zero points"), "{skipped}");
    assert!(skipped.contains("out of order"), "{skipped}");
    assert!(c.report.scans_matched > 30, "{}", c.report.scans_matched);
    Ok(())
}

#[test]
fn an_imu_gap_is_an_error_naming_the_sample() -> TestResult {
    let sim = small_sim(5.0)?;
    let scans = in_memory(&sim);
    let mut imu = sim.imu.clone();
    imu.drain(1200..1300); // 0.25 s gap at 3 s
    let input = LidarImuInput {
        imu: &imu,
        imu_noise: &sim.imu_noise,
        scans: &scans,
    };
    match lidar_imu::calibrate::<f64>(&input, &options(), &mut |_| {}) {
        Err(e @ InputError::ImuSample { sample, .. }) => {
            // The first sample after the gap, 1-based.
            assert_eq!(sample, 1201, "{e}");
            assert!(e.to_string().contains("imu0/data.csv"), "{e}");
        }
        Err(e) => panic!("not the IMU-gap error: {e}"),
        Ok(_) => panic!("an IMU gap must be reported"),
    }
    Ok(())
}

#[test]
fn too_few_scans_and_no_imu_are_errors() -> TestResult {
    let sim = small_sim(5.0)?;
    let scans = in_memory(&sim);
    let two = scans[..2].to_vec();
    let input = LidarImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        scans: &two,
    };
    assert!(lidar_imu::calibrate::<f64>(&input, &options(), &mut |_| {}).is_err());
    let input = LidarImuInput {
        imu: &[],
        imu_noise: &sim.imu_noise,
        scans: &scans,
    };
    assert!(lidar_imu::calibrate::<f64>(&input, &options(), &mut |_| {}).is_err());
    Ok(())
}

fn msreg(args: &[&str]) -> Result<std::process::Output, std::io::Error> {
    Command::new(env!("CARGO_BIN_EXE_msreg"))
        .args(args)
        .output()
}

#[test]
fn cli_names_a_truncated_pcd_and_exits_2() -> TestResult {
    let dir = tempfile::tempdir()?;
    let data = dir.path().join("d");
    let d = data.to_str().ok_or("path")?;
    let out = msreg(&[
        "simulate",
        "lidar-imu",
        d,
        "--duration",
        "4",
        "--rings",
        "16",
        "--columns",
        "256",
    ])?;
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let victim = std::fs::read_dir(Path::new(&data).join("lidar0"))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "pcd"))
        .nth(7)
        .ok_or("no scan")?;
    let bytes = std::fs::read(&victim)?;
    std::fs::write(&victim, &bytes[..bytes.len() / 2])?;
    let result = dir.path().join("r.yaml");
    let out = msreg(&[
        "calibrate",
        "lidar-imu",
        d,
        "-o",
        result.to_str().ok_or("path")?,
    ])?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let name = victim.file_name().and_then(|n| n.to_str()).ok_or("name")?;
    assert!(
        stderr.contains(name) && stderr.contains("truncated"),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    Ok(())
}
