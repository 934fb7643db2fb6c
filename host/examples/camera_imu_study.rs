//! Camera-IMU study on the simulator (docs/camera_imu.md, the dissertation's Tables
//! 4.1-4.4 against ground truth): per seed, a recording is rendered (noise, motion blur,
//! uneven lighting), the checkerboard detected in every image, and both measurement models
//! run on the same corners, exactly as `msreg calibrate camera-imu` does. Prints markdown.
//!
//! Run: `cargo run --release -p msreg-host --example camera_imu_study -- [seeds] [duration_s]`

use msreg_host::calibrate::camera_imu::detect_corner_frames;
use msreg_host::calibrate::camera_imu::{
    calibrate, CameraImuCalibration, CameraImuInput, CameraImuOptions, CameraUpdate,
};
use msreg_host::dataset::{CalibrationResult, Dataset, ExtrinsicEstimate};
use msreg_host::eval::{compare, SectionErrors};
use msreg_host::sim::camera::{simulate_camera_imu, CameraImuSimConfig};
use msreg_host::vision::{CameraDataset, DetectorParams};

/// Time offsets of the seeds, ms (cycled).
const TIME_OFFSETS_MS: [f64; 5] = [5.0, -3.0, 8.0, 0.0, -6.0];

struct Run {
    seed: u64,
    truth: ExtrinsicEstimate,
    results: Vec<(
        CameraUpdate,
        ExtrinsicEstimate,
        SectionErrors,
        CameraImuCalibration,
    )>,
    images: usize,
    detected: usize,
    detect_s: f64,
}

fn run(seed: u64, duration_s: f64) -> anyhow::Result<Run> {
    let config = CameraImuSimConfig {
        seed,
        duration_s,
        time_offset_s: TIME_OFFSETS_MS[seed as usize % TIME_OFFSETS_MS.len()] * 1e-3,
        ..CameraImuSimConfig::default()
    }
    .with_blur_and_noise();
    let sim = simulate_camera_imu(&config).map_err(|e| anyhow::anyhow!("{e}"))?;
    let dir = tempfile::tempdir()?;
    sim.write(dir.path(), &|_| {})?;
    let dataset = Dataset::open(dir.path())?;
    let camera_data = CameraDataset::open(dir.path())?;
    let (frames, detection) =
        detect_corner_frames(&camera_data, &DetectorParams::default(), &|_| {})?;
    let truth = CalibrationResult::read(dir.path().join("groundtruth/extrinsics.yaml"))?
        .get("cam0")
        .copied()
        .ok_or_else(|| anyhow::anyhow!("no cam0 truth"))?;
    let input = CameraImuInput {
        imu: dataset.require_imu()?,
        imu_noise: dataset.require_imu_noise()?,
        camera: &camera_data.camera,
        frames: &frames,
    };
    let mut results = Vec::new();
    for update in [CameraUpdate::Motion, CameraUpdate::Reprojection] {
        let options = CameraImuOptions {
            update,
            ..CameraImuOptions::default()
        };
        let c = calibrate::<f64>(&input, &options, &mut |_| {})
            .map_err(|e| anyhow::anyhow!("seed {seed}: {e:?}"))?;
        let estimate = c.cam_imu_estimate();
        let errors = compare("cam0", &estimate, &truth);
        results.push((update, estimate, errors, c));
    }
    Ok(Run {
        seed,
        truth,
        results,
        images: detection.images,
        detected: detection.detected,
        detect_s: detection.time_s,
    })
}

fn name(update: CameraUpdate) -> &'static str {
    match update {
        CameraUpdate::Motion => "MoCal",
        CameraUpdate::Reprojection => "RepErrCal",
    }
}

/// `T_cam_imu` as roll/pitch/yaw (deg) and x/y/z (cm), as the dissertation tabulates.
fn pose_cells(e: &ExtrinsicEstimate) -> String {
    let (r, p, y) = e.transform.rotation.euler_angles();
    let t = e.transform.translation.vector * 100.0;
    format!(
        "{:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.3}",
        r.to_degrees(),
        p.to_degrees(),
        y.to_degrees(),
        t.x,
        t.y,
        t.z,
        e.timeshift_s * 1e3
    )
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let seeds: u64 = args.get(1).map_or(Ok(5), |s| s.parse())?;
    let duration_s: f64 = args.get(2).map_or(Ok(60.0), |s| s.parse())?;
    let mut runs = Vec::new();
    for seed in 1..=seeds {
        eprintln!("seed {seed}: rendering, detecting, calibrating ...");
        runs.push(run(seed, duration_s)?);
    }

    println!("### Estimates of T_cam_imu (Tables 4.1-4.2)\n");
    println!("| seed | source | roll [deg] | pitch [deg] | yaw [deg] | x [cm] | y [cm] | z [cm] | t_d [ms] |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &runs {
        println!("| {} | truth | {} |", r.seed, pose_cells(&r.truth));
        for (update, estimate, _, _) in &r.results {
            println!(
                "| {} | {} | {} |",
                r.seed,
                name(*update),
                pose_cells(estimate)
            );
        }
    }

    println!("\n### Errors against ground truth (Table 4.3)\n");
    println!("| seed | method | rotation [deg] | 3-sigma max [deg] | translation [mm] | 3-sigma max [mm] | time offset [ms] | 3-sigma [ms] | inside 3 sigma |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &runs {
        for (update, _, e, c) in &r.results {
            let max = |v: [f64; 3]| v.iter().copied().fold(0.0, f64::max);
            println!(
                "| {} | {} | {:.4} | {:.4} | {:.3} | {:.3} | {:.4} | {:.4} | {} |",
                r.seed,
                name(*update),
                e.rotation_deg,
                3.0 * max(e.sigma_rot_deg),
                e.translation_m * 1e3,
                3.0 * max(e.sigma_trans_m) * 1e3,
                e.time_offset_s * 1e3,
                3.0 * c.time_offset_sigma_s * 1e3,
                if e.within_3_sigma && e.time_offset_s.abs() < 3.0 * c.time_offset_sigma_s {
                    "yes"
                } else {
                    "no"
                }
            );
        }
    }

    println!("\n### Mean reprojection error (Table 4.4) and detection\n");
    println!("| seed | images | board detected | detection [s] | pixel sigma [px] | MoCal [px] | RepErrCal [px] | MoCal NIS/dof | RepErrCal NIS/dof |");
    println!("|---|---|---|---|---|---|---|---|---|");
    for r in &runs {
        let report = |i: usize| &r.results[i].3.report;
        println!(
            "| {} | {} | {} | {:.1} | {:.3} | {:.4} | {:.4} | {:.2} | {:.2} |",
            r.seed,
            r.images,
            r.detected,
            r.detect_s,
            report(1).pixel_sigma,
            report(0).verification_reprojection_error_px,
            report(1).verification_reprojection_error_px,
            report(0).filter.mean_nis_per_dof,
            report(1).filter.mean_nis_per_dof,
        );
    }
    Ok(())
}
