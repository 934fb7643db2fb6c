//! LiDAR-camera studies on the simulator (docs/lidar_camera.md):
//!
//! - `accuracy [seeds] [poses]`: PBPC-Cal and PPC-Cal errors and MLRE per seed and LiDAR.
//! - `random-init [trials]`: PPC then PBPC from random starts (rotation sigma 90 deg per
//!   axis, translation sigma 50 cm), spread of the solutions.
//! - `timing`: simulator and feature-extraction time of one frame.
//!
//! Run: `cargo run --release -p msreg-host --example lidar_camera_study -- accuracy 5 30`

use msreg_estimator::Pose;
use msreg_host::lidar_camera::pipeline::{
    extract_simulation, solve, CalibrationOptions, FrameFeatures,
};
use msreg_host::sim::{simulate_lidar_camera, LidarCameraSim, LidarCameraSimConfig, LidarModel};
use nalgebra::{UnitQuaternion, Vector3};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

fn features(sim: &LidarCameraSim, options: &CalibrationOptions) -> Vec<FrameFeatures> {
    let (frames, rejected) = extract_simulation(sim, options);
    for r in &rejected {
        eprintln!(
            "{}: seed {}: frame {}: {}",
            sim.config.lidar.name(),
            sim.config.seed,
            r.frame,
            r.reason
        );
    }
    frames
}

fn errors(est: &Pose<f64>, truth: &nalgebra::Isometry3<f64>) -> (f64, f64) {
    (
        est.rotation.angle_to(&truth.rotation).to_degrees(),
        (est.translation - truth.translation.vector).norm() * 1e3,
    )
}

fn accuracy(seeds: u64, poses: usize) {
    println!("| LiDAR | seed | frames used | PBPC rot [deg] | PBPC trans [mm] | PBPC MLRE [px] | PPC rot [deg] | PPC trans [mm] | PPC MLRE [px] | solve [ms] |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for model in [LidarModel::Vlp32, LidarModel::Ouster] {
        for seed in 0..seeds {
            let sim = simulate_lidar_camera(&LidarCameraSimConfig {
                seed,
                lidar: model,
                poses,
                ..Default::default()
            })
            .expect("sim");
            let options = CalibrationOptions::default();
            let frames = features(&sim, &options);
            let clock = std::time::Instant::now();
            let sol = solve(&frames, &sim.camera, &options).expect("solve");
            let ms = clock.elapsed().as_secs_f64() * 1e3;
            let (r, t) = errors(&sol.t_cam_lidar, &sim.t_cam_lidar);
            let (rp, tp) = errors(&sol.t_cam_lidar_ppc, &sim.t_cam_lidar);
            println!(
                "| {} | {seed} | {} | {r:.4} | {t:.2} | {:.3} | {rp:.4} | {tp:.2} | {:.3} | {ms:.1} |",
                model.name(),
                frames.len(),
                sol.mlre_px,
                sol.mlre_ppc_px
            );
        }
    }
}

fn random_init(trials: usize) {
    let sim = simulate_lidar_camera(&LidarCameraSimConfig {
        seed: 0,
        lidar: LidarModel::Ouster,
        ..Default::default()
    })
    .expect("sim");
    let base = CalibrationOptions::default();
    let frames = features(&sim, &base);
    let reference = solve(&frames, &sim.camera, &base).expect("solve");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    let rot = Normal::new(0.0, 90f64.to_radians()).expect("normal");
    let trans = Normal::new(0.0, 0.5).expect("normal");
    let mut worst = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    let mut ok = 0;
    for _ in 0..trials {
        let start = Pose::new(
            UnitQuaternion::from_scaled_axis(Vector3::from_fn(|_, _| rot.sample(&mut rng))),
            Vector3::from_fn(|_, _| trans.sample(&mut rng)),
        );
        let options = CalibrationOptions {
            start: Some(start),
            ..base
        };
        let Ok(sol) = solve(&frames, &sim.camera, &options) else {
            continue;
        };
        let dr = sol
            .t_cam_lidar
            .rotation
            .angle_to(&reference.t_cam_lidar.rotation)
            .to_degrees();
        let dt = (sol.t_cam_lidar.translation - reference.t_cam_lidar.translation).norm() * 1e3;
        let drp = sol
            .t_cam_lidar_ppc
            .rotation
            .angle_to(&reference.t_cam_lidar_ppc.rotation)
            .to_degrees();
        let dtp =
            (sol.t_cam_lidar_ppc.translation - reference.t_cam_lidar_ppc.translation).norm() * 1e3;
        worst = (
            worst.0.max(dr),
            worst.1.max(dt),
            worst.2.max(drp),
            worst.3.max(dtp),
        );
        if dr < 0.01 && dt < 1.0 {
            ok += 1;
        }
    }
    println!("random init: {ok}/{trials} PBPC within 0.01 deg / 1 mm of the closed-form-start solution; worst PBPC {:.2e} deg {:.2e} mm, worst PPC {:.2e} deg {:.2e} mm", worst.0, worst.1, worst.2, worst.3);
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let num = |i: usize, d: u64| args.get(i).and_then(|s| s.parse().ok()).unwrap_or(d);
    match args.get(1).map(String::as_str) {
        Some("random-init") => random_init(num(2, 100) as usize),
        Some("timing") => timing(),
        _ => accuracy(num(2, 5), num(3, 30) as usize),
    }
}

/// Timing of the simulator and the feature extraction per frame (for keeping tests short).
fn timing() {
    use msreg_host::lidar_camera::camera_features::{extract_camera_board, CameraFeatureParams};
    use msreg_host::lidar_camera::lidar_features::{extract_lidar_board, LidarFeatureParams};
    let sim = simulate_lidar_camera(&LidarCameraSimConfig {
        seed: 0,
        lidar: LidarModel::Ouster,
        poses: 3,
        ..Default::default()
    })
    .expect("sim");
    for k in 0..3 {
        let t = std::time::Instant::now();
        let _ = sim.image(k);
        println!("image {k}: {:.3} s", t.elapsed().as_secs_f64());
    }
    let t = std::time::Instant::now();
    let img = sim.image(0);
    let a = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let scan = sim.scan(0);
    let b = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let _ = extract_camera_board(
        &img,
        &sim.camera,
        &sim.config.board,
        &CameraFeatureParams::default(),
    );
    let c = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let _ = extract_lidar_board(&scan, &sim.config.board, &LidarFeatureParams::default());
    let d = t.elapsed().as_secs_f64();
    println!("image {a:.3} s, scan {b:.3} s, camera features {c:.3} s, lidar features {d:.3} s");
}
