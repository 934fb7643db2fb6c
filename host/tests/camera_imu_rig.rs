//! Camera-IMU calibration of a two-camera rig in one filter (issue 32): a stereo-like pair
//! (11 cm baseline, its own mounting and time offset per camera) on simulated 60 s
//! recordings, from corners at the simulator's true pixels of each camera plus detector-like
//! noise. Each camera is judged against its truth, and the chain `T_c1_c0` composed from the
//! filter's two extrinsics and their cross-covariance against the true chain.
//!
//! Acceptance (behind `#[ignore]`, `cargo test --release -p msreg-host --test camera_imu_rig
//! -- --ignored`): every seed within 0.05 deg / 2 mm per camera and 0.02 deg / 0.5 mm for
//! the chain, and the NEES of every camera's extrinsic and of the chain in the chi2 band.

#[path = "support/common.rs"]
mod common;
#[path = "support/corners.rs"]
mod corners;

use common::{extrinsic_error, par_map};
use corners::noisy_corner_frames;
use msreg_host::calibrate::camera_imu::{
    calibrate_cameras, CameraFrames, CameraImuOptions, CornerFrame, MultiCameraImuCalibration,
    MultiCameraImuInput,
};
use msreg_host::sim::camera::rig::{simulate_camera_rig, CameraRigSim, CameraRigSimConfig};
use msreg_host::sim::CameraImuSimConfig;
use nalgebra::{Isometry3, Matrix6};

/// Per-axis corner noise, pixels (as the single-camera accuracy study).
const PIXEL_SIGMA: f64 = 0.1;

/// A two-camera row with camera 0's time offset in +-20 ms (camera 1's 3 ms later).
fn rig(seed: u64, duration_s: f64) -> CameraRigSim {
    let base = CameraImuSimConfig {
        seed,
        duration_s,
        time_offset_s: ((seed as f64 * 2.3).sin()) * 0.02,
        ..CameraImuSimConfig::default()
    };
    simulate_camera_rig(&CameraRigSimConfig::row(base, 2)).expect("valid simulation config")
}

fn calibrate(rig: &CameraRigSim, seed: u64) -> MultiCameraImuCalibration {
    let frames: Vec<Vec<CornerFrame>> = rig
        .cameras
        .iter()
        .enumerate()
        .map(|(n, c)| noisy_corner_frames(c, PIXEL_SIGMA, seed * 16 + n as u64))
        .collect();
    let cameras: Vec<CameraFrames<'_>> = rig
        .cameras
        .iter()
        .zip(&frames)
        .map(|(c, f)| CameraFrames {
            camera: &c.config.camera,
            frames: f,
        })
        .collect();
    let c0 = &rig.cameras[0];
    let input = MultiCameraImuInput {
        imu: &c0.imu,
        imu_noise: &c0.imu_noise,
        cameras: &cameras,
    };
    calibrate_cameras::<f64>(&input, &CameraImuOptions::default(), &mut |_| {})
        .expect("calibration runs")
}

/// One estimate against its truth: error angle (deg), error norm (mm), NEES.
#[derive(Debug, Clone, Copy)]
struct Judged {
    rotation_deg: f64,
    translation_mm: f64,
    nees: f64,
}

fn judge(estimate: &Isometry3<f64>, covariance: &Matrix6<f64>, truth: &Isometry3<f64>) -> Judged {
    let e = extrinsic_error(estimate, truth);
    let info = covariance.try_inverse().expect("covariance invertible");
    Judged {
        rotation_deg: e.fixed_rows::<3>(0).norm().to_degrees(),
        translation_mm: e.fixed_rows::<3>(3).norm() * 1e3,
        nees: e.dot(&(info * e)),
    }
}

/// One seed: each camera's `T_imu_camN` and the chain `T_c1_c0`, judged; each camera's
/// time-offset error (ms) and whether it is inside 3 sigma.
#[derive(Debug)]
struct Outcome {
    seed: u64,
    cameras: Vec<Judged>,
    time_offset_ms: Vec<(f64, bool)>,
    chain: Judged,
    /// The NEES with the result file's (model-error) covariances: cameras, then the chain.
    written_nees: Vec<f64>,
    converged: bool,
}

fn run(seed: u64, duration_s: f64) -> Outcome {
    let rig = rig(seed, duration_s);
    let c = calibrate(&rig, seed);
    let cameras = c
        .cameras
        .iter()
        .zip(&rig.cameras)
        .map(|(est, sim)| judge(&est.t_imu_sensor, &est.covariance, &sim.t_cam_imu.inverse()))
        .collect();
    let time_offset_ms = c
        .cameras
        .iter()
        .zip(&rig.cameras)
        .map(|(est, sim)| {
            let e = est.time_offset_s - sim.config.time_offset_s;
            (e * 1e3, e.abs() <= 3.0 * est.time_offset_sigma_s)
        })
        .collect();
    let true_chain = rig.cameras[1].t_cam_imu * rig.cameras[0].t_cam_imu.inverse();
    let link = &c.chain[0];
    let mut written_nees: Vec<f64> = c
        .cameras
        .iter()
        .zip(&rig.cameras)
        .map(|(est, sim)| {
            judge(
                &est.t_imu_sensor,
                &est.written_covariance().0,
                &sim.t_cam_imu.inverse(),
            )
            .nees
        })
        .collect();
    written_nees.push(
        judge(
            &link.t_cn_cnm1,
            &c.chain_model_error[0].written,
            &true_chain,
        )
        .nees,
    );
    Outcome {
        written_nees,
        seed,
        cameras,
        time_offset_ms,
        chain: judge(&link.t_cn_cnm1, &link.covariance, &true_chain),
        converged: c.converged(),
    }
}

fn print(o: &Outcome) {
    for (n, (j, td)) in o.cameras.iter().zip(&o.time_offset_ms).enumerate() {
        println!(
            "seed {} cam{n}: rotation {:.4} deg, translation {:.3} mm, NEES {:.2}, time offset \
             error {:.3} ms (inside 3 sigma {})",
            o.seed, j.rotation_deg, j.translation_mm, j.nees, td.0, td.1
        );
    }
    println!(
        "seed {} T_c1_c0: rotation {:.4} deg, translation {:.3} mm, NEES {:.2}",
        o.seed, o.chain.rotation_deg, o.chain.translation_mm, o.chain.nees
    );
}

#[test]
#[ignore = "acceptance: 10 seeds of 60 s two-camera recordings"]
fn two_camera_rig_is_accurate_and_consistent_over_ten_seeds() {
    let seeds: Vec<u64> = (1..=10).collect();
    let outcomes = par_map(&seeds, |seed| run(seed, 60.0));
    for o in &outcomes {
        print(o);
    }
    // The bounds are the acceptance figures. Measured (seeds 1-10, 6.8 s release):
    // worst camera 0.0103 deg / 0.184 mm, worst chain 0.0025 deg / 0.034 mm, time offsets
    // within 0.005 ms and inside 3 sigma.
    for o in &outcomes {
        assert!(o.converged, "{o:?}");
        for (j, td) in o.cameras.iter().zip(&o.time_offset_ms) {
            assert!(j.rotation_deg < 0.05, "{o:?}");
            assert!(j.translation_mm < 2.0, "{o:?}");
            assert!(td.1, "time offset outside 3 sigma: {o:?}");
        }
        assert!(o.chain.rotation_deg < 0.02, "{o:?}");
        assert!(o.chain.translation_mm < 0.5, "{o:?}");
    }
    // Summed over the 10 seeds each NEES is chi2(60) if consistent: 99 % two-sided band
    // [35.5, 92.0] (Wilson-Hilferty). Measured: cam0 51.9, cam1 55.4, chain 60.1 (means 5.2,
    // 5.5, 6.0).
    let band = 35.5..=92.0;
    let sum = |f: &dyn Fn(&Outcome) -> f64| outcomes.iter().map(f).sum::<f64>();
    for n in 0..2 {
        let total = sum(&|o| o.cameras[n].nees);
        println!("cam{n}: summed NEES {total:.1} (mean {:.2})", total / 10.0);
        assert!(band.contains(&total), "cam{n}: summed NEES {total:.1}");
    }
    let total = sum(&|o| o.chain.nees);
    println!("T_c1_c0: summed NEES {total:.1} (mean {:.2})", total / 10.0);
    // The result file's covariances (the filter's with the time blocks' model error, never
    // smaller) must not be optimistic; conservative is allowed.
    for (k, name) in ["cam0", "cam1", "T_c1_c0"].iter().enumerate() {
        let written = sum(&|o| o.written_nees[k]);
        println!("{name}: summed NEES with the written covariance {written:.1}");
        assert!(
            written <= *band.end(),
            "{name}: written NEES sum {written:.1}"
        );
    }
    assert!(band.contains(&total), "chain: summed NEES {total:.1}");
}
