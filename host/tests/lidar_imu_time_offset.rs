//! LiDAR-IMU time offset: diagnostics of its bias (issue 11; docs/lidar_imu.md, "The time
//! offset's systematic error").
//!
//! `cargo test --release -p msreg-host --test lidar_imu_time_offset diagnose -- --ignored --nocapture`
//! prints per seed the time-offset error, its sigma (and the filter's own, before the front
//! end's systematic shift is added), z, the extrinsic errors, NEES, NIS/dof, and the
//! **increment time shift**: the `eps` that best explains the fused NDT increments' errors
//! as `T_L(a + t_d + eps)^-1 T_L(b + t_d + eps)` against the truth (least squares over the
//! run; an estimator-independent check of the front end), also for the filter's predicted
//! increments (NDT's initial guess). Variants by environment:
//! `MSREG_SEEDS=a..b` (default 1000..1010), `MSREG_RATE` (400), `MSREG_DURATION` (60),
//! `MSREG_RINGS` / `MSREG_COLUMNS` (32 / 512), `MSREG_RANGE_NOISE` (0.02 m),
//! `MSREG_DESKEW=oracle` (scans deskewed with the true motion before the pipeline sees
//! them), `MSREG_SEAM_DEG=x` (with the oracle: drop +-x deg of azimuth around the sweep's
//! seam), `MSREG_TD=fixed` (stamps shifted by the true offset, `t_d` not estimated),
//! `MSREG_NDT_EPS_T` / `MSREG_NDT_EPS_R` / `MSREG_NDT_ITER` / `MSREG_NDT_RES=a,b,c` /
//! `MSREG_NDT_NEIGHBOURS=7|27` / `MSREG_VOXEL` / `MSREG_LOCAL_MAP`, `MSREG_ANNEAL_SIGMA=0`
//! (count-only anneal), `MSREG_SHIFT_SIGMA_MS` (the consider sigma).

#[path = "support/common.rs"]
mod common;

use common::{chi_square_band, par_map};
use msreg_host::calibrate::lidar_imu::{self, LidarImuCalibration, LidarImuInput, LidarImuOptions};
use msreg_host::lidar::{ScanLoadError, ScanSource};
use msreg_host::ndt::Neighbourhood;
use msreg_host::pointcloud::{Point, PointCloud};
use msreg_host::sim::{simulate_lidar_imu, LidarImuSim, LidarImuSimConfig, LidarSimConfig};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn env<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The true offset of a seed: uniform in +-20 ms (the same draw as `imu_timing`).
fn drawn_offset_s(seed: u64) -> f64 {
    ChaCha8Rng::seed_from_u64(seed ^ 0x7d_0ff5e7).gen_range(-0.020..0.020)
}

/// The simulator's scans, moved into the LiDAR frame at their last firing with the true
/// motion (every point then stamped at that firing): deskewing done by an oracle.
/// `shift_ns` is added to every stamp (the offset left to estimate is `t_d - shift`).
struct Scans<'a> {
    sim: &'a LidarImuSim,
    oracle: bool,
    shift_ns: i64,
}

impl ScanSource for Scans<'_> {
    fn len(&self) -> usize {
        self.sim.len()
    }
    fn stamp_ns(&self, index: usize) -> u64 {
        (self.sim.stamp_ns(index) as i64 + self.shift_ns) as u64
    }
    fn name(&self, index: usize) -> String {
        self.sim.name(index)
    }
    fn load(&self, index: usize) -> Result<PointCloud, ScanLoadError> {
        let sim = self.sim;
        let cloud = sim.scan(index);
        if !self.oracle {
            return Ok(cloud);
        }
        let last = cloud.points.iter().map(|p| p.t_ns).max().unwrap_or(0);
        let base = sim.seconds(sim.stamp_ns(index)) + sim.config.lidar.time_offset_s;
        let t_ref = sim.t_g_l(base + f64::from(last) * 1e-9).inverse();
        let seam = env("MSREG_SEAM_DEG", 0.0f64).to_radians();
        let points = cloud
            .points
            .iter()
            .map(|p| {
                let m = t_ref * sim.t_g_l(base + f64::from(p.t_ns) * 1e-9);
                Point {
                    xyz: (m * Point3::from(p.xyz)).coords,
                    t_ns: last,
                    ..*p
                }
            })
            .filter(|p| {
                let az = p.xyz.y.atan2(p.xyz.x).rem_euclid(std::f64::consts::TAU);
                az >= seam && az <= std::f64::consts::TAU - seam
            })
            .collect();
        Ok(PointCloud::new(points))
    }
}

fn error6(a: &Isometry3<f64>, b: &Isometry3<f64>) -> Vector6<f64> {
    let r = (b.rotation.inverse() * a.rotation).scaled_axis();
    let p = a.translation.vector - b.translation.vector;
    Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z)
}

/// The time shift `eps` (s) that best explains the fused increments' errors: the measured
/// `T_L(a)_L(b)` against the true one between `a + t_d + eps` and `b + t_d + eps`, least
/// squares over all matched scans (rotation in rad, translation in m weighted 1:10).
fn increment_time_shift(
    sim: &LidarImuSim,
    c: &LidarImuCalibration,
    td: f64,
    of_prediction: bool,
) -> f64 {
    let inc = |a: f64, b: f64| sim.t_g_l(a).inverse() * sim.t_g_l(b);
    let w = Vector6::new(1.0, 1.0, 1.0, 10.0, 10.0, 10.0);
    let (mut num, mut den) = (0.0, 0.0);
    for pair in c.report.scans.windows(2) {
        let (prev, this) = (&pair[0], &pair[1]);
        if this.status != "matched" {
            continue;
        }
        let (Some(r), Some(t)) = (this.delta_rotation, this.delta_translation) else {
            continue;
        };
        let a = sim.seconds(prev.reference_stamp_ns) + td;
        let b = sim.seconds(this.reference_stamp_ns) + td;
        let meas = Isometry3::from_parts(
            Translation3::from(Vector3::from(t)),
            UnitQuaternion::from_scaled_axis(Vector3::from(r)),
        );
        let truth = inc(a, b);
        let h = 1e-4;
        let d = error6(&inc(a + h, b + h), &truth).component_mul(&w) / h;
        let e = if of_prediction {
            let Some(p) = this.predicted else { continue };
            error6(&p, &truth).component_mul(&w)
        } else {
            error6(&meas, &truth).component_mul(&w)
        };
        num += d.dot(&e);
        den += d.dot(&d);
    }
    num / den.max(1e-30)
}

struct Outcome {
    seed: u64,
    converged: bool,
    td_err_ms: f64,
    td_sigma_ms: f64,
    rot_deg: f64,
    trans_mm: f64,
    nees: f64,
    nis_all: f64,
    nis_settled: f64,
    shift_ms: f64,
    shift_p_ms: f64,
    filter_sigma_ms: f64,
}

fn run(seed: u64, rate: f64) -> Outcome {
    let duration: f64 = env("MSREG_DURATION", 60.0);
    let mut config = LidarImuSimConfig {
        seed,
        duration_s: duration,
        lidar: LidarSimConfig {
            rings: env("MSREG_RINGS", 32),
            columns: env("MSREG_COLUMNS", 512),
            time_offset_s: drawn_offset_s(seed),
            range_noise_m: env("MSREG_RANGE_NOISE", 0.02),
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    };
    config.imu.rate_hz = rate;
    let sim = simulate_lidar_imu(&config).expect("valid simulation");
    let fixed = std::env::var("MSREG_TD").as_deref() == Ok("fixed");
    let td = sim.config.lidar.time_offset_s;
    let shift_ns = if fixed { (td * 1e9).round() as i64 } else { 0 };
    let td_left = td - shift_ns as f64 * 1e-9;
    let scans = Scans {
        sim: &sim,
        oracle: std::env::var("MSREG_DESKEW").as_deref() == Ok("oracle"),
        shift_ns,
    };
    let mut options = LidarImuOptions::default();
    options.filter.estimate_time_offset = !fixed;
    options.ndt.translation_epsilon = env("MSREG_NDT_EPS_T", options.ndt.translation_epsilon);
    options.ndt.rotation_epsilon = env("MSREG_NDT_EPS_R", options.ndt.rotation_epsilon);
    options.ndt.max_iterations = env("MSREG_NDT_ITER", options.ndt.max_iterations);
    options.voxel_m = env("MSREG_VOXEL", options.voxel_m);
    if let Ok(r) = std::env::var("MSREG_NDT_RES") {
        options.ndt.resolutions = r.split(',').map(|x| x.parse().expect("m")).collect();
    }
    match std::env::var("MSREG_NDT_NEIGHBOURS").as_deref() {
        Ok("7") => options.ndt.neighbourhood = Neighbourhood::Direct7,
        Ok("27") => options.ndt.neighbourhood = Neighbourhood::Direct27,
        _ => {}
    }
    options.local_map_scans = env("MSREG_LOCAL_MAP", options.local_map_scans);
    options.anneal_by_sigma = env("MSREG_ANNEAL_SIGMA", 1) != 0;
    options.time_shift_sigma_s =
        env("MSREG_SHIFT_SIGMA_MS", options.time_shift_sigma_s * 1e3) * 1e-3;
    let input = LidarImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        scans: &scans,
    };
    let c = lidar_imu::calibrate::<f64>(&input, &options, &mut |_| {}).expect("calibration runs");
    let e = error6(&sim.t_imu_lidar, &c.t_imu_sensor);
    let nees = c
        .covariance
        .try_inverse()
        .map_or(f64::NAN, |info| e.dot(&(info * e)));
    let shift = increment_time_shift(&sim, &c, td_left, false);
    let shift_p = increment_time_shift(&sim, &c, td_left, true);
    let nis: Vec<f64> = c.report.scans.iter().filter_map(|r| r.nis).collect();
    Outcome {
        seed,
        converged: c.report.filter.converged,
        td_err_ms: (c.time_offset_s - td_left) * 1e3,
        td_sigma_ms: c.time_offset_sigma_s * 1e3,
        rot_deg: Vector3::new(e[0], e[1], e[2]).norm().to_degrees(),
        trans_mm: Vector3::new(e[3], e[4], e[5]).norm() * 1e3,
        nees,
        nis_all: nis.iter().sum::<f64>() / (6.0 * nis.len() as f64),
        nis_settled: c.report.settled_nis_per_dof,
        shift_ms: shift * 1e3,
        shift_p_ms: shift_p * 1e3,
        filter_sigma_ms: c.report.time_offset_filter_sigma_s * 1e3,
    }
}

fn seeds() -> Vec<u64> {
    let range = std::env::var("MSREG_SEEDS").unwrap_or_else(|_| "1000..1010".into());
    let (a, b) = range.split_once("..").expect("MSREG_SEEDS=a..b");
    (a.parse().expect("seed")..b.parse().expect("seed")).collect()
}

/// Prints the table; returns (sum of time-offset z^2, NEES sum).
fn table(outcomes: &[Outcome]) -> (f64, f64) {
    println!(
        "| seed | t_d err [ms] | sigma [ms] | filter sigma [ms] | z | rot [deg] | trans [mm] \
         | NEES | NIS/dof all | settled | increment shift [ms] | predicted shift [ms] |"
    );
    for o in outcomes {
        println!(
            "| {} | {:+.4} | {:.4} | {:.4} | {:+.2} | {:.4} | {:.2} | {:.2} | {:.3} | {:.3} | \
             {:+.4} | {:+.4} |",
            o.seed,
            o.td_err_ms,
            o.td_sigma_ms,
            o.filter_sigma_ms,
            o.td_err_ms / o.td_sigma_ms,
            o.rot_deg,
            o.trans_mm,
            o.nees,
            o.nis_all,
            o.nis_settled,
            o.shift_ms,
            o.shift_p_ms
        );
    }
    let z2: f64 = outcomes
        .iter()
        .map(|o| (o.td_err_ms / o.td_sigma_ms).powi(2))
        .sum();
    let nees: f64 = outcomes.iter().map(|o| o.nees).sum();
    let n = outcomes.len() as f64;
    let mean = |f: fn(&Outcome) -> f64| outcomes.iter().map(f).sum::<f64>() / n;
    println!(
        "sum z^2 {z2:.1} (band {:.1?}), NEES sum {nees:.1} (band {:.1?}), mean t_d err {:+.4} ms, \
         mean increment shift {:+.4} ms, predicted {:+.4} ms, NIS/dof all {:.3}",
        chi_square_band(n),
        chi_square_band(6.0 * n),
        mean(|o| o.td_err_ms),
        mean(|o| o.shift_ms),
        mean(|o| o.shift_p_ms),
        mean(|o| o.nis_all),
    );
    (z2, nees)
}

#[test]
#[ignore = "diagnostics, ~4 min per 10 seeds of 60 s"]
fn diagnose() {
    let rate: f64 = env("MSREG_RATE", 400.0);
    table(&par_map(&seeds(), |seed| run(seed, rate)));
}

/// The LiDAR-IMU cells of the acceptance with the default options (seeds
/// 1000-1009, 60 s, 400 and 200 Hz): every seed converged with its time-offset error under
/// 0.2 ms, the sum of the time-offset z^2 and the extrinsic NEES sum inside their two-sided
/// 95 % chi-square bands.
#[test]
#[ignore = "acceptance run, ~8 min on 2 cores"]
fn ten_seeds_at_400_and_200_hz() {
    for rate in [400.0, 200.0] {
        println!("{rate} Hz");
        let outcomes = par_map(&seeds(), |seed| run(seed, rate));
        let (z2, nees) = table(&outcomes);
        let n = outcomes.len() as f64;
        for o in &outcomes {
            assert!(o.converged, "seed {}", o.seed);
            assert!(o.td_err_ms.abs() < 0.2, "seed {}: {}", o.seed, o.td_err_ms);
        }
        assert!(z2 <= chi_square_band(n).1, "sum z^2 {z2}");
        let (lo, hi) = chi_square_band(6.0 * n);
        assert!((lo..=hi).contains(&nees), "NEES sum {nees}");
    }
}
