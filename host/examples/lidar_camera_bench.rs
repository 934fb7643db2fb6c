//! Solver time of the LiDAR-camera calibration for 30 board poses (the dissertation's Ceres
//! solve took 3-11 s, Table 2.5): features are extracted once, then `solve` (closed-form
//! start, PPC-Cal, edge association, PBPC-Cal, MLRE) is timed; median of 7 runs per
//! dataset. Writes a Markdown table to stdout.
//!
//! Run: `cargo run --release -p msreg-host --example lidar_camera_bench`

use std::time::Instant;

use msreg_host::lidar_camera::pipeline::{extract_simulation, solve, CalibrationOptions};
use msreg_host::sim::{simulate_lidar_camera, LidarCameraSimConfig, LidarModel};

fn main() {
    println!("| LiDAR | seed | frames | PPC residuals | PBPC residuals | PPC [ms] | PBPC [ms] | whole solve [ms] |");
    println!("|---|---|---|---|---|---|---|---|");
    for model in [LidarModel::Vlp32, LidarModel::Ouster] {
        for seed in 0..3 {
            let config = LidarCameraSimConfig {
                seed,
                lidar: model,
                poses: 30,
                ..LidarCameraSimConfig::default()
            };
            let Ok(sim) = simulate_lidar_camera(&config) else {
                eprintln!("simulation failed");
                return;
            };
            let options = CalibrationOptions::default();
            let (frames, _) = extract_simulation(&sim, &options);
            let mut runs = Vec::new();
            let mut last = None;
            for _ in 0..7 {
                let clock = Instant::now();
                let sol = solve(&frames, &sim.camera, &options);
                runs.push(clock.elapsed().as_secs_f64() * 1e3);
                last = sol.ok();
            }
            runs.sort_by(f64::total_cmp);
            let Some(sol) = last else {
                eprintln!("solve failed");
                return;
            };
            let pbpc = sol.pbpc.as_ref();
            println!(
                "| {} | {seed} | {} | {} | {} | {:.1} | {:.2} | {:.1} |",
                model.name(),
                frames.len(),
                sol.ppc.residuals,
                pbpc.map_or(0, |r| r.residuals),
                sol.ppc.time_s * 1e3,
                pbpc.map_or(0.0, |r| r.time_s * 1e3),
                runs[runs.len() / 2]
            );
        }
    }
}
