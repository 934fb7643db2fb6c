//! The dissertation's chapter-3 studies (Tables 3.1-3.4, Fig. 3.11) on the simulator, against
//! ground truth; prints markdown tables (docs/lidar_imu_studies.md).
//!
//! `cargo run --release -p msreg --example lidar_imu_studies [rings|imu|relative|deskew ...]`
//! (no argument: all four). Env: `MSREG_SEEDS` (default 2), `MSREG_DURATION` (s, default 30),
//! `MSREG_RING_COLUMNS` (columns of the rings study, default 1024), `MSREG_COLUMNS` (columns of
//! the other studies, default 512), `MSREG_RINGS` (rings of the other studies, default 64).

use std::time::Instant;

use anyhow::{anyhow, Result};
use msreg_host::calibrate::lidar_imu::{self, LidarImuCalibration, LidarImuInput, LidarImuOptions};
use msreg_host::sim::{simulate_lidar_imu, ImuSimConfig, LidarImuSimConfig, LidarSimConfig};
use nalgebra::{Isometry3, Translation3, Vector3, Vector6};

struct Run {
    calibration: LidarImuCalibration,
    truth: Isometry3<f64>,
    seconds: f64,
}

struct Metrics {
    rot_deg: f64,
    trans_mm: f64,
    sigma3_rot_deg: f64,
    sigma3_trans_mm: f64,
    inside: bool,
    nees: f64,
    nis: f64,
    matched: usize,
    scans: usize,
    converged: bool,
    seconds: f64,
}

fn env_or(name: &str, default: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn config(seed: u64, duration_s: f64, rings: usize, columns: usize) -> LidarImuSimConfig {
    LidarImuSimConfig {
        seed,
        duration_s,
        lidar: LidarSimConfig {
            rings,
            columns,
            // Same unknown time offset per seed as host/tests/lidar_imu_accuracy.rs.
            time_offset_s: ((seed * 7919) % 21) as f64 * 1e-3 - 0.010,
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    }
}

fn options(deskew: bool) -> LidarImuOptions {
    LidarImuOptions {
        deskew,
        // A 30 s recording is ~290 updates: the faster anneal of the 25 s CI test.
        anneal_updates: 45.0,
        ..LidarImuOptions::default()
    }
}

fn run(sim_config: &LidarImuSimConfig, options: &LidarImuOptions) -> Result<Run> {
    let sim = simulate_lidar_imu(sim_config).map_err(|e| anyhow!("simulation: {e}"))?;
    let input = LidarImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        scans: &sim,
    };
    let started = Instant::now();
    let calibration = lidar_imu::calibrate::<f64>(&input, options, &mut |_| {})
        .map_err(|e| anyhow!("calibration: {e}"))?;
    Ok(Run {
        calibration,
        truth: sim.t_imu_lidar,
        seconds: started.elapsed().as_secs_f64(),
    })
}

fn error(estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> Vector6<f64> {
    let r = (estimate.rotation.inverse() * truth.rotation).scaled_axis();
    let p = truth.translation.vector - estimate.translation.vector;
    Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z)
}

fn metrics(r: &Run) -> Metrics {
    let c = &r.calibration;
    let e = error(&c.t_imu_lidar, &r.truth);
    let sd = |i: usize| c.covariance[(i, i)].sqrt();
    Metrics {
        rot_deg: c
            .t_imu_lidar
            .rotation
            .angle_to(&r.truth.rotation)
            .to_degrees(),
        trans_mm: (c.t_imu_lidar.translation.vector - r.truth.translation.vector).norm() * 1e3,
        sigma3_rot_deg: 3.0 * (0..3).map(sd).fold(0.0, f64::max).to_degrees(),
        sigma3_trans_mm: 3.0 * (3..6).map(sd).fold(0.0, f64::max) * 1e3,
        inside: (0..6).all(|i| e[i].abs() <= 3.0 * sd(i)),
        nees: c
            .covariance
            .try_inverse()
            .map_or(f64::NAN, |info| e.dot(&(info * e))),
        nis: c.report.settled_nis_per_dof,
        matched: c.report.scans_matched,
        scans: c.report.scans.len(),
        converged: c.report.filter.converged,
        seconds: r.seconds,
    }
}

const HEADER: &str = "seed | rot err [deg] | 3 sigma [deg] | trans err [mm] | 3 sigma [mm] | \
inside 3 sigma | NEES | settled NIS/dof | scans fused | converged | time [s] |";
const RULE: &str = "|---:|---:|---:|---:|---:|---|---:|---:|---:|---|---:|";

fn row(label: &str, seed: u64, m: &Metrics) -> String {
    format!(
        "| {label} | {seed} | {:.4} | {:.4} | {:.2} | {:.2} | {} | {:.2} | {:.2} | {}/{} | {} | {:.1} |",
        m.rot_deg,
        m.sigma3_rot_deg,
        m.trans_mm,
        m.sigma3_trans_mm,
        if m.inside { "yes" } else { "**no**" },
        m.nees,
        m.nis,
        m.matched,
        m.scans,
        if m.converged { "yes" } else { "**no**" },
        m.seconds
    )
}

fn summary(label: &str, ms: &[Metrics]) -> String {
    let n = ms.len().max(1) as f64;
    let mean = |f: fn(&Metrics) -> f64| ms.iter().map(f).sum::<f64>() / n;
    let max = |f: fn(&Metrics) -> f64| ms.iter().map(f).fold(0.0, f64::max);
    format!(
        "| {label} | {:.4} / {:.4} | {:.2} / {:.2} | {:.4} | {:.2} | {}/{} | {:.2} | {:.1} |",
        mean(|m| m.rot_deg),
        max(|m| m.rot_deg),
        mean(|m| m.trans_mm),
        max(|m| m.trans_mm),
        mean(|m| m.sigma3_rot_deg),
        mean(|m| m.sigma3_trans_mm),
        ms.iter().filter(|m| m.inside).count(),
        ms.len(),
        mean(|m| m.nis),
        mean(|m| m.seconds)
    )
}

const SUMMARY_HEADER: &str = "mean rot err / max [deg] | mean trans err / max [mm] | \
mean 3 sigma rot [deg] | mean 3 sigma trans [mm] | inside 3 sigma | mean NIS/dof | mean time [s] |";

/// Runs one study: `cells` are (label, sim config builder, deskew).
fn study(title: &str, first_column: &str, seeds: u64, cells: &[Cell]) -> Result<()> {
    println!("### {title}\n");
    println!("| {first_column} | {HEADER}");
    println!("|---{RULE}");
    let mut summaries = Vec::new();
    for (label, make, deskew) in cells {
        let mut ms = Vec::new();
        for seed in 1..=seeds {
            let m = metrics(&run(&make(seed), &options(*deskew))?);
            println!("{}", row(label, seed, &m));
            ms.push(m);
        }
        summaries.push(summary(label, &ms));
    }
    println!("\nSummary over seeds:\n");
    println!("| {first_column} | {SUMMARY_HEADER}");
    println!("|---|---:|---:|---:|---:|---|---:|---:|");
    for s in summaries {
        println!("{s}");
    }
    println!();
    Ok(())
}

fn relative(seeds: u64, duration: f64, rings: usize, columns: usize) -> Result<()> {
    println!("### Relative verification (Table 3.4): LiDAR moved 5 cm along the IMU's y axis\n");
    println!(
        "| seed | true t_y A [mm] | est. Delta x [mm] | est. Delta y [mm] | est. Delta z [mm] | \
         est. distance [mm] | error of Delta y [%] | error of distance [%] | rot change [deg] | \
         abs trans err A / B [mm] |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for seed in 1..=seeds {
        let base = config(seed, duration, rings, columns);
        let a = run(&base, &options(true))?;
        let truth_a = a.truth;
        let mut moved = truth_a;
        moved.translation = Translation3::from(truth_a.translation.vector + Vector3::y() * 0.05);
        let b = run(
            &LidarImuSimConfig {
                t_imu_lidar: Some(moved),
                ..base
            },
            &options(true),
        )?;
        let d = b.calibration.t_imu_lidar.translation.vector
            - a.calibration.t_imu_lidar.translation.vector;
        let rot_change = a
            .calibration
            .t_imu_lidar
            .rotation
            .angle_to(&b.calibration.t_imu_lidar.rotation)
            .to_degrees();
        let (ma, mb) = (metrics(&a), metrics(&b));
        println!(
            "| {seed} | {:.1} | {:+.2} | {:+.2} | {:+.2} | {:.2} | {:.2} | {:.2} | {:.4} | {:.2} / {:.2} |",
            truth_a.translation.y * 1e3,
            d.x * 1e3,
            d.y * 1e3,
            d.z * 1e3,
            d.norm() * 1e3,
            (d.y - 0.05).abs() / 0.05 * 100.0,
            (d.norm() - 0.05).abs() / 0.05 * 100.0,
            rot_change,
            ma.trans_mm,
            mb.trans_mm
        );
    }
    println!();
    Ok(())
}

type Cell = (String, Box<dyn Fn(u64) -> LidarImuSimConfig>, bool);

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let wants = |s: &str| args.is_empty() || args.iter().any(|a| a == s);
    let seeds = env_or("MSREG_SEEDS", 2.0) as u64;
    let duration = env_or("MSREG_DURATION", 30.0);
    let ring_columns = env_or("MSREG_RING_COLUMNS", 1024.0) as usize;
    let columns = env_or("MSREG_COLUMNS", 512.0) as usize;
    let rings = env_or("MSREG_RINGS", 64.0) as usize;
    let started = Instant::now();
    println!(
        "Simulated {duration} s recordings, seeds 1..={seeds}, indoor world, 10 Hz LiDAR, \
         2 cm range noise, VN-300-class IMU, random mounting, time offset estimated.\n"
    );
    if wants("rings") {
        let cells: Vec<Cell> = [128usize, 64, 32, 16]
            .into_iter()
            .map(|r| {
                let make: Box<dyn Fn(u64) -> LidarImuSimConfig> =
                    Box::new(move |seed| config(seed, duration, r, ring_columns));
                (format!("{r} x {ring_columns}"), make, true)
            })
            .collect();
        study(
            "Rings (Tables 3.1-3.2), IMU 400 Hz",
            "rings x columns",
            seeds,
            &cells,
        )?;
    }
    if wants("imu") {
        let cells: Vec<Cell> = [400.0f64, 200.0, 100.0, 50.0]
            .into_iter()
            .map(|hz| {
                let make: Box<dyn Fn(u64) -> LidarImuSimConfig> = Box::new(move |seed| {
                    let mut c = config(seed, duration, rings, columns);
                    c.imu = ImuSimConfig {
                        rate_hz: hz,
                        ..ImuSimConfig::default()
                    };
                    c
                });
                (format!("{hz} Hz"), make, true)
            })
            .collect();
        study(
            &format!("IMU rate (Table 3.3), LiDAR {rings} x {columns}"),
            "IMU rate",
            seeds,
            &cells,
        )?;
    }
    if wants("relative") {
        relative(seeds, duration, rings, columns)?;
    }
    if wants("deskew") {
        let cells: Vec<Cell> = [true, false]
            .into_iter()
            .map(|d| {
                let make: Box<dyn Fn(u64) -> LidarImuSimConfig> =
                    Box::new(move |seed| config(seed, duration, rings, columns));
                (if d { "yes" } else { "no" }.to_string(), make, d)
            })
            .collect();
        study(
            &format!("Deskewing on / off (Fig. 3.11), LiDAR {rings} x {columns}, IMU 400 Hz"),
            "deskew",
            seeds,
            &cells,
        )?;
    }
    println!("Total wall time: {:.0} s", started.elapsed().as_secs_f64());
    Ok(())
}
