//! The dissertation's chapter-3 studies (Tables 3.1-3.4, Fig. 3.11) on the simulator, against
//! ground truth; prints markdown tables (docs/lidar_imu_studies.md).
//!
//! `cargo run --release -p msreg-host --example lidar_imu_studies [rings|imu|relative|outdoor|deskew ...]`
//! (no argument: all five; `outdoor` runs the outdoor-like scene; `noise` and `ndt-noise` measure
//! the NDT covariance against the true increment errors). Env: `MSREG_SEEDS` (default 5),
//! `MSREG_DURATION` (s, default 60),
//! `MSREG_RING_COLUMNS` (columns of the rings study, default 1024), `MSREG_COLUMNS` (columns of
//! the other studies, default 512), `MSREG_RINGS` (rings of the other studies, default 64),
//! `MSREG_LOCAL_MAP` (scans in the NDT local map, default 5 as the pipeline; 0 = scan-to-scan).

use std::time::Instant;

use anyhow::{anyhow, Result};
use msreg_host::calibrate::lidar_imu::{self, LidarImuCalibration, LidarImuInput, LidarImuOptions};
use msreg_host::sim::{
    simulate_lidar_imu, Environment, ImuSimConfig, LidarImuSimConfig, LidarSimConfig,
};
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
    let local_map_scans = env_or("MSREG_LOCAL_MAP", 5.0) as usize;
    LidarImuOptions {
        deskew,
        anneal_updates: anneal_updates(env_or("MSREG_DURATION", 60.0)),
        ..LidarImuOptions::for_local_map(local_map_scans)
    }
}

/// The floor's decay constant: the default 100 updates for a minute (600 scans), a sixth of
/// the updates for shorter recordings (45 for the 25 s CI test), so the noise model settles
/// and adapts in the second half of every recording.
fn anneal_updates(duration_s: f64) -> f64 {
    (duration_s * 10.0 / 6.0).clamp(20.0, 100.0)
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
    let e = error(&c.t_imu_sensor, &r.truth);
    let sd = |i: usize| c.covariance[(i, i)].sqrt();
    Metrics {
        rot_deg: c
            .t_imu_sensor
            .rotation
            .angle_to(&r.truth.rotation)
            .to_degrees(),
        trans_mm: (c.t_imu_sensor.translation.vector - r.truth.translation.vector).norm() * 1e3,
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
        let d = b.calibration.t_imu_sensor.translation.vector
            - a.calibration.t_imu_sensor.translation.vector;
        let rot_change = a
            .calibration
            .t_imu_sensor
            .rotation
            .angle_to(&b.calibration.t_imu_sensor.rotation)
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

/// Per-increment errors of the fused NDT measurements against the true LiDAR motion,
/// normalised by each NDT covariance estimate: mean `e^T Sigma^-1 e / 6` (1 = the estimate is
/// the right size), after `settle_s` (the extrinsic used for deskewing has converged).
fn noise(seeds: u64, duration: f64, cells: &[(usize, usize)], settle_s: f64) -> Result<()> {
    println!("### Size of NDT's covariance estimates against the true increment errors\n");
    println!(
        "| rings x columns | seed | increments | Hessian | sandwich | cell-clustered sandwich | \
         clustered: trans / rot | lag-1 corr. of errors (rot, trans) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---|---|");
    for &(rings, columns) in cells {
        for seed in 1..=seeds {
            let sim = simulate_lidar_imu(&config(seed, duration, rings, columns))
                .map_err(|e| anyhow!("simulation: {e}"))?;
            let input = LidarImuInput {
                imu: &sim.imu,
                imu_noise: &sim.imu_noise,
                scans: &sim,
            };
            let mut opts = options(true);
            opts.ndt.sandwich_covariance = true;
            let c = lidar_imu::calibrate::<f64>(&input, &opts, &mut |_| {})
                .map_err(|e| anyhow!("calibration: {e}"))?;
            let td = sim.config.lidar.time_offset_s;
            let mut q = [0.0f64; 3];
            let mut blocks = [0.0f64; 2];
            let mut errors: Vec<Option<Vector6<f64>>> = Vec::new();
            let mut n = 0usize;
            let mut previous: Option<u64> = None;
            for s in &c.report.scans {
                let mut this = None;
                if let (Some(prev), Some(ndt)) = (previous, &s.ndt) {
                    let a = sim.t_g_l(sim.seconds(prev) + td);
                    let b = sim.t_g_l(sim.seconds(s.reference_stamp_ns) + td);
                    // NDT's order: [t; theta], theta a right perturbation.
                    let e = error(&ndt.t_target_source, &(a.inverse() * b));
                    let e = Vector6::new(e[3], e[4], e[5], e[0], e[1], e[2]);
                    if s.t_s > settle_s {
                        for (k, cov) in [
                            Some(ndt.covariance),
                            ndt.covariance_sandwich,
                            ndt.covariance_clustered,
                        ]
                        .iter()
                        .flatten()
                        .enumerate()
                        {
                            let info = cov.try_inverse().unwrap_or_else(nalgebra::Matrix6::zeros);
                            q[k] += e.dot(&(info * e));
                        }
                        let cov = ndt.covariance_clustered.unwrap_or(ndt.covariance);
                        for (b, range) in [(0, 0..3), (1, 3..6)] {
                            let sub = cov.view((range.start, range.start), (3, 3)).into_owned();
                            let es = e.rows(range.start, 3).into_owned();
                            if let Some(info) = sub.try_inverse() {
                                blocks[b] += es.dot(&(info * &es));
                            }
                        }
                        n += 1;
                        this = Some(e);
                    }
                }
                errors.push(this);
                // The next match's target is this scan unless it was dropped before NDT.
                let target = s.status == "matched"
                    || s.status == "anchor"
                    || s.status.starts_with("rejected")
                    || s.status.starts_with("NDT")
                    || s.status.starts_with("degenerate");
                previous = target.then_some(s.reference_stamp_ns);
            }
            let corr = |range: std::ops::Range<usize>| {
                let (mut num, mut den) = (0.0, 0.0);
                for w in errors.windows(2) {
                    if let (Some(a), Some(b)) = (w[0], w[1]) {
                        for i in range.clone() {
                            num += a[i] * b[i];
                            den += 0.5 * (a[i] * a[i] + b[i] * b[i]);
                        }
                    }
                }
                num / den.max(f64::MIN_POSITIVE)
            };
            let m = n.max(1) as f64;
            println!(
                "| {rings} x {columns} | {seed} | {n} | {:.3} | {:.3} | {:.3} | {:.3} / {:.3} | {:+.2}, {:+.2} |",
                q[0] / (6.0 * m),
                q[1] / (6.0 * m),
                q[2] / (6.0 * m),
                blocks[0] / (3.0 * m),
                blocks[1] / (3.0 * m),
                corr(3..6),
                corr(0..3),
            );
        }
    }
    println!();
    Ok(())
}

/// NDT's error statistics in isolation: consecutive scans deskewed with the *true* motion,
/// voxel-filtered and matched from the true increment as the pipeline does; errors
/// normalised by each covariance estimate, and their lag-1 autocorrelation.
fn ndt_noise(seeds: u64, duration: f64, cells: &[(usize, usize)]) -> Result<()> {
    use msreg_host::ndt::{align, NdtTarget};
    use msreg_host::pointcloud::voxel_downsample;
    println!("### NDT alone (scans deskewed with the true motion)\n");
    println!(
        "| rings x columns | seed | increments | Hessian | sandwich | cell-clustered sandwich | \
         Hessian: trans / rot | lag-1 corr. of errors (rot, trans) |"
    );
    println!("|---|---:|---:|---:|---:|---:|---|---|");
    let mut opts = LidarImuOptions::default();
    opts.ndt.sandwich_covariance = true;
    for &(rings, columns) in cells {
        for seed in 1..=seeds {
            let sim = simulate_lidar_imu(&config(seed, duration, rings, columns))
                .map_err(|e| anyhow!("simulation: {e}"))?;
            let td = sim.config.lidar.time_offset_s;
            let mut previous: Option<(Isometry3<f64>, NdtTarget)> = None;
            let mut q = [0.0f64; 3];
            let mut blocks = [0.0f64; 2];
            let mut errors: Vec<Vector6<f64>> = Vec::new();
            for k in 0..sim.scan_stamps.len() {
                let mut cloud = sim.scan(k);
                let t0 = sim.seconds(sim.scan_stamps[k]) + td;
                let last = cloud.points.iter().map(|p| p.t_ns).max().unwrap_or(0);
                let t_ref = sim.t_g_l(t0 + f64::from(last) * 1e-9);
                let inv_ref = t_ref.inverse();
                for p in &mut cloud.points {
                    let t_i = sim.t_g_l(t0 + f64::from(p.t_ns) * 1e-9);
                    p.xyz = (inv_ref * t_i).transform_point(&p.xyz.into()).coords;
                }
                let points = voxel_downsample(&cloud, opts.voxel_m).positions();
                if t0 > 1.0 {
                    if let Some((t_prev, target)) = &previous {
                        let truth = t_prev.inverse() * t_ref;
                        if let Ok(r) = align(target, &points, &truth, &opts.ndt) {
                            let e = error(&r.t_target_source, &truth);
                            let e = Vector6::new(e[3], e[4], e[5], e[0], e[1], e[2]);
                            for (i, cov) in [
                                Some(r.covariance),
                                r.covariance_sandwich,
                                r.covariance_clustered,
                            ]
                            .iter()
                            .flatten()
                            .enumerate()
                            {
                                if let Some(info) = cov.try_inverse() {
                                    q[i] += e.dot(&(info * e));
                                }
                            }
                            for (b, start) in [(0, 0), (1, 3)] {
                                let sub = r.covariance.view((start, start), (3, 3)).into_owned();
                                let es = e.rows(start, 3).into_owned();
                                if let Some(info) = sub.try_inverse() {
                                    blocks[b] += es.dot(&(info * &es));
                                }
                            }
                            errors.push(e);
                        }
                    }
                }
                previous = NdtTarget::build(&points, &opts.ndt)
                    .ok()
                    .map(|t| (t_ref, t));
            }
            let corr = |start: usize| {
                let (mut num, mut den) = (0.0, 0.0);
                for w in errors.windows(2) {
                    let (a, b) = (w[0].rows(start, 3), w[1].rows(start, 3));
                    num += a.dot(&b);
                    den += 0.5 * (a.norm_squared() + b.norm_squared());
                }
                num / den.max(f64::MIN_POSITIVE)
            };
            let m = errors.len().max(1) as f64;
            println!(
                "| {rings} x {columns} | {seed} | {} | {:.3} | {:.3} | {:.3} | {:.3} / {:.3} | {:+.2}, {:+.2} |",
                errors.len(),
                q[0] / (6.0 * m),
                q[1] / (6.0 * m),
                q[2] / (6.0 * m),
                blocks[0] / (3.0 * m),
                blocks[1] / (3.0 * m),
                corr(3),
                corr(0),
            );
        }
    }
    println!();
    Ok(())
}

type Cell = (String, Box<dyn Fn(u64) -> LidarImuSimConfig>, bool);

#[allow(clippy::too_many_lines)] // one dispatch over the studies
fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let wants = |s: &str| args.is_empty() || args.iter().any(|a| a == s);
    let seeds = env_or("MSREG_SEEDS", 5.0) as u64;
    let duration = env_or("MSREG_DURATION", 60.0);
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
    if args.iter().any(|a| a == "ndt-noise") {
        ndt_noise(
            seeds,
            duration,
            &[(128, 1024), (64, 1024), (32, 512), (16, 1024)],
        )?;
    }
    if args.iter().any(|a| a == "noise") {
        noise(
            seeds,
            duration,
            &[(128, 1024), (64, 1024), (32, 512), (16, 1024)],
            15.0,
        )?;
    }
    if wants("outdoor") {
        // The indoor reference is the deskewing study's "yes" rows (same configuration).
        let cells: Vec<Cell> = [Environment::Outdoor]
            .into_iter()
            .map(|environment| {
                let make: Box<dyn Fn(u64) -> LidarImuSimConfig> = Box::new(move |seed| {
                    let mut c = config(seed, duration, rings, columns);
                    c.lidar.environment = environment;
                    c
                });
                (format!("{environment:?}").to_lowercase(), make, true)
            })
            .collect();
        study(
            &format!("Outdoor-like scene, LiDAR {rings} x {columns}, IMU 400 Hz"),
            "environment",
            seeds,
            &cells,
        )?;
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
