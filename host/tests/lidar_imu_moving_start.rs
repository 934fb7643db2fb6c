//! LiDAR-IMU moving start (issue 11): the recording cut to begin at peak motion (the IMU
//! sample of the fastest rotation in its first 20 s, after the first second), so there is no
//! standstill to initialise from. The scans before the cut are dropped with the IMU samples.
//!
//! `cargo test --release -p msreg --test lidar_imu_moving_start -- --ignored --nocapture`
//! runs the acceptance (10 seeds, 60 s, 400 and 200 Hz).

#[path = "support/common.rs"]
mod common;

use common::{chi_square_band, par_map};
use msreg_host::calibrate::lidar_imu::{self, LidarImuInput, LidarImuOptions};
use msreg_host::dataset::ImuRecord;
use msreg_host::lidar::{ScanLoadError, ScanSource};
use msreg_host::pointcloud::PointCloud;
use msreg_host::sim::{simulate_lidar_imu, LidarImuSim, LidarImuSimConfig, LidarSimConfig};
use nalgebra::{Isometry3, UnitQuaternion, Vector3, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Acceptance bound on the time-offset error (issue 11), ms.
const MAX_TIME_OFFSET_ERROR_MS: f64 = 0.2;

/// The true offset of a seed: uniform in +-20 ms (the draw of `imu_timing`).
fn drawn_offset_s(seed: u64) -> f64 {
    ChaCha8Rng::seed_from_u64(seed ^ 0x7d_0ff5e7).gen_range(-0.020..0.020)
}

/// The IMU sample of the fastest rotation within the first 20 s (after the first second).
fn peak_motion_ns(imu: &[ImuRecord]) -> u64 {
    let t0 = imu[0].stamp_ns;
    imu.iter()
        .filter(|r| (1_000_000_000..20_000_000_000).contains(&(r.stamp_ns - t0)))
        .max_by(|a, b| a.gyro.norm().total_cmp(&b.gyro.norm()))
        .map_or(t0, |r| r.stamp_ns)
}

/// The simulator's scans from index `first` on.
struct From<'a> {
    sim: &'a LidarImuSim,
    first: usize,
}

impl ScanSource for From<'_> {
    fn len(&self) -> usize {
        self.sim.len() - self.first
    }
    fn stamp_ns(&self, index: usize) -> u64 {
        self.sim.stamp_ns(index + self.first)
    }
    fn name(&self, index: usize) -> String {
        self.sim.name(index + self.first)
    }
    fn load(&self, index: usize) -> Result<PointCloud, ScanLoadError> {
        self.sim.load(index + self.first)
    }
}

#[derive(Debug)]
struct Outcome {
    seed: u64,
    rate_hz: f64,
    cut_s: f64,
    td_true_ms: f64,
    td_err_ms: f64,
    td_sigma_ms: f64,
    rot_deg: f64,
    trans_mm: f64,
    nees: f64,
    inside: bool,
    converged: bool,
    /// Health events (alarms) the monitor raised.
    alarms: usize,
    /// Updates rejected by the gate.
    rejected: usize,
    /// Why the pipeline did not converge, and the moving-start initialisation it chose.
    notes: String,
}

fn run(seed: u64, rate_hz: f64, duration_s: f64) -> Outcome {
    let mut config = LidarImuSimConfig {
        seed,
        duration_s,
        lidar: LidarSimConfig {
            rings: 32,
            columns: 512,
            time_offset_s: drawn_offset_s(seed),
            ..LidarSimConfig::default()
        },
        ..LidarImuSimConfig::default()
    };
    config.imu.rate_hz = rate_hz;
    let sim = simulate_lidar_imu(&config).expect("valid simulation");
    // `MSREG_CUT=0` (studies): the whole recording, standstill included.
    let cut = if std::env::var("MSREG_CUT").as_deref() == Ok("0") {
        sim.imu[0].stamp_ns
    } else {
        peak_motion_ns(&sim.imu)
    };
    let imu: Vec<ImuRecord> = sim
        .imu
        .iter()
        .filter(|r| r.stamp_ns >= cut)
        .copied()
        .collect();
    // Scans whose first firing (on the IMU clock) is after the cut.
    let td_ns = (config.lidar.time_offset_s * 1e9).round() as i64;
    let first = (0..sim.len())
        .find(|&k| sim.stamp_ns(k) as i64 + td_ns > cut as i64)
        .unwrap_or(sim.len());
    let scans = From { sim: &sim, first };
    let input = LidarImuInput {
        imu: &imu,
        imu_noise: &sim.imu_noise,
        scans: &scans,
    };
    let options = LidarImuOptions {
        anneal_by_sigma: std::env::var("MSREG_ANNEAL_SIGMA").as_deref() != Ok("0"),
        ..LidarImuOptions::default()
    };
    let c = lidar_imu::calibrate::<f64>(&input, &options, &mut |_| {}).expect("calibration runs");
    let truth: &Isometry3<f64> = &sim.t_imu_lidar;
    let r = (c.t_imu_sensor.rotation.inverse() * truth.rotation).scaled_axis();
    let p = truth.translation.vector - c.t_imu_sensor.translation.vector;
    let e = Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z);
    let nees = c
        .covariance
        .try_inverse()
        .map_or(f64::NAN, |info| e.dot(&(info * e)));
    let td_err = c.time_offset_s - config.lidar.time_offset_s;
    if std::env::var("MSREG_STUDY").is_ok() {
        study(seed, rate_hz, &sim, &c, config.lidar.time_offset_s);
    }
    Outcome {
        seed,
        rate_hz,
        cut_s: sim.seconds(cut),
        td_true_ms: config.lidar.time_offset_s * 1e3,
        td_err_ms: td_err * 1e3,
        td_sigma_ms: c.time_offset_sigma_s * 1e3,
        rot_deg: r.norm().to_degrees(),
        trans_mm: p.norm() * 1e3,
        nees,
        inside: (0..6).all(|i| e[i].abs() <= 3.0 * c.covariance[(i, i)].sqrt())
            && td_err.abs() <= 3.0 * c.time_offset_sigma_s,
        converged: c.report.filter.converged,
        alarms: c.report.filter.events.len(),
        rejected: c.report.filter.updates_rejected,
        notes: format!(
            "{}; {}; alarms at {:?}",
            c.report.filter.moving_start,
            c.report.filter.reasons.join("; "),
            c.report
                .filter
                .events
                .iter()
                .map(|e| format!("{:.1} s {} {:.2e}", e.t_s, e.kind, e.magnitude))
                .collect::<Vec<_>>()
        ),
    }
}

/// Studies (`MSREG_STUDY=1`): the extrinsic's error against its sigma early in the run,
/// and the fused increments' errors against the truth, normalised by their assigned
/// sigma, by phase of the run.
fn study(seed: u64, rate_hz: f64, sim: &LidarImuSim, c: &lidar_imu::LidarImuCalibration, td: f64) {
    let truth = &sim.t_imu_lidar;
    let mut line = String::new();
    for t in [1.0, 2.0, 3.0, 4.0, 5.0, 10.0, 20.0, 40.0] {
        let Some(h) = c
            .report
            .filter
            .history
            .iter()
            .take_while(|h| h.t_s <= t)
            .last()
        else {
            continue;
        };
        let p = truth.translation.vector - Vector3::from(h.translation_m);
        let q = UnitQuaternion::from_scaled_axis(Vector3::from(h.rotation_vector));
        let r = (q.inverse() * truth.rotation).scaled_axis();
        let zt = (0..3)
            .map(|i| (p[i] / h.sigma_trans_m[i]).abs())
            .fold(0.0, f64::max);
        let zr = (0..3)
            .map(|i| (r[i].to_degrees() / h.sigma_rot_deg[i]).abs())
            .fold(0.0, f64::max);
        line += &format!(
            " | {t:.0} s: sig {:.3} deg {:.1} mm, |z| rot {zr:.1} trans {zt:.1}",
            h.sigma_rot_deg.iter().fold(0.0f64, |a, b| a.max(*b)),
            h.sigma_trans_m.iter().fold(0.0f64, |a, b| a.max(*b)) * 1e3,
        );
    }
    println!("study {rate_hz} Hz seed {seed} extrinsic{line}");
    if std::env::var("MSREG_STUDY").as_deref() == Ok("2") {
        trace(seed, c, truth, td);
    }
    increment_study(seed, rate_hz, sim, c, td);
}

/// The fused increments' errors against the truth, normalised by their assigned sigma, by
/// phase of the run, and their lag-1 autocorrelation.
fn increment_study(
    seed: u64,
    rate_hz: f64,
    sim: &LidarImuSim,
    c: &lidar_imu::LidarImuCalibration,
    td: f64,
) {
    let inc = |a: f64, b: f64| sim.t_g_l(a).inverse() * sim.t_g_l(b);
    let mut phases = [[0.0f64; 3]; 4];
    let mut matched = 0usize;
    // Lag-1 autocorrelation of the normalised errors of consecutive fused increments
    // (after update 100): sums of u_k u_(k-1) and u_k^2, rotation and translation.
    let mut lag = [[0.0f64; 2]; 2];
    let mut last: Option<(usize, Vector6<f64>)> = None;
    for (k, pair) in c.report.scans.windows(2).enumerate() {
        let (prev, this) = (&pair[0], &pair[1]);
        let (Some(r), Some(t), Some(sigma)) =
            (this.delta_rotation, this.delta_translation, this.sigma)
        else {
            continue;
        };
        if this.status != "matched" {
            continue;
        }
        let a = sim.seconds(prev.reference_stamp_ns) + td;
        let b = sim.seconds(this.reference_stamp_ns) + td;
        let truth = inc(a, b);
        let er = (truth.rotation.inverse() * UnitQuaternion::from_scaled_axis(Vector3::from(r)))
            .scaled_axis();
        let et = Vector3::from(t) - truth.translation.vector;
        let u = Vector6::from_fn(|i, _| {
            if i < 3 {
                er[i] / sigma[i]
            } else {
                et[i - 3] / sigma[i]
            }
        });
        if let Some((_, v)) = last.filter(|(j, _)| *j + 1 == k && matched >= 100) {
            for (b, range) in [(0, 0..3), (1, 3..6)] {
                for i in range {
                    lag[b][0] += u[i] * v[i];
                    lag[b][1] += 0.5 * (u[i] * u[i] + v[i] * v[i]);
                }
            }
        }
        last = Some((k, u));
        let phase = match matched {
            0..=99 => 0,
            100..=199 => 1,
            200..=349 => 2,
            _ => 3,
        };
        matched += 1;
        let cell = &mut phases[phase];
        cell[0] += (0..3).map(|i| (er[i] / sigma[i]).powi(2)).sum::<f64>() / 3.0;
        cell[1] += (0..3).map(|i| (et[i] / sigma[i + 3]).powi(2)).sum::<f64>() / 3.0;
        cell[2] += 1.0;
    }
    println!(
        "study {rate_hz} Hz seed {seed} increments: mean (e/sigma)^2 rot, trans by updates \
         0-99 / 100-199 / 200-349 / 350+: {}",
        phases
            .iter()
            .map(|c| format!("{:.3}, {:.3} (n {})", c[0] / c[2], c[1] / c[2], c[2]))
            .collect::<Vec<_>>()
            .join(" / ")
    );
    println!(
        "study {rate_hz} Hz seed {seed} lag-1 autocorrelation of increment errors (after 100): \
         rot {:+.2}, trans {:+.2}; final scale {:.3}, settled NIS/dof {:.2}",
        lag[0][0] / lag[0][1],
        lag[1][0] / lag[1][1],
        c.report.final_covariance_scale,
        c.report.settled_nis_per_dof
    );
}

/// The first 60 updates: time offset, translation error and sigma, NIS (`MSREG_STUDY=2`).
fn trace(seed: u64, c: &lidar_imu::LidarImuCalibration, truth: &Isometry3<f64>, td: f64) {
    for h in c.report.filter.history.iter().take(60) {
        let p = Vector3::from(h.translation_m) - truth.translation.vector;
        println!(
            "trace seed {seed} {:.2} s: t_d err {:+.3} ms (sigma {:.3}), trans err [{:+.1}, \
             {:+.1}, {:+.1}] mm (sigma [{:.1}, {:.1}, {:.1}]), NIS {:.1} {}",
            h.t_s,
            (h.time_offset_s - td) * 1e3,
            h.sigma_time_offset_s * 1e3,
            p.x * 1e3,
            p.y * 1e3,
            p.z * 1e3,
            h.sigma_trans_m[0] * 1e3,
            h.sigma_trans_m[1] * 1e3,
            h.sigma_trans_m[2] * 1e3,
            h.nis,
            h.accepted
        );
    }
}

fn check(outcomes: &[Outcome]) {
    for o in outcomes {
        println!(
            "LiDAR-IMU moving start {:>3} Hz seed {}: cut at {:.2} s, t_d {:+.3} ms, error \
             {:+.4} ms (sigma {:.4}), rotation {:.4} deg, translation {:.2} mm, NEES {:.2}, inside 3 \
             sigma {}, converged {}, {} alarms, {} updates gated ({})",
            o.rate_hz,
            o.seed,
            o.cut_s,
            o.td_true_ms,
            o.td_err_ms,
            o.td_sigma_ms,
            o.rot_deg,
            o.trans_mm,
            o.nees,
            o.inside,
            o.converged,
            o.alarms,
            o.rejected,
            o.notes
        );
    }
    for o in outcomes {
        assert!(o.converged, "{o:?}");
        assert_eq!(o.alarms, 0, "{o:?}");
        assert!(o.td_err_ms.abs() < MAX_TIME_OFFSET_ERROR_MS, "{o:?}");
        // The LiDAR-IMU bounds of docs/lidar_imu.md's CI scenario (~3x its worst seed).
        assert!(o.rot_deg < 0.035 && o.trans_mm < 2.6, "{o:?}");
        assert!(o.inside, "{o:?}");
    }
}

/// One seed per rate, 30 s cut at peak motion (CI). Before the moving start fed the LiDAR
/// odometry to the dynamic alignment, 400 Hz did not converge on this seed (0.28 deg /
/// 383 mm, 123 of 128 updates gated; docs/lidar_imu.md).
#[test]
fn moving_start_converges_at_400_and_200_hz() {
    let outcomes: Vec<Outcome> = [400.0, 200.0]
        .into_iter()
        .map(|rate| run(7, rate, 30.0))
        .collect();
    check(&outcomes);
}

/// The acceptance: 10 seeds per rate, 60 s, cut at peak motion; the NEES sum and the
/// time-offset z-scores inside their two-sided 95 % chi-square bands.
#[test]
#[ignore = "acceptance run, ~8 min on 2 cores"]
fn ten_seeds_moving_start() {
    // `MSREG_SEED_LIST=a,b,..` and `MSREG_RATES=400` run other seeds or one rate (studies).
    let list = |name: &str, default: Vec<f64>| -> Vec<f64> {
        std::env::var(name).map_or(default, |v| {
            v.split(',')
                .map(|x| x.trim().parse().expect("a number"))
                .collect()
        })
    };
    let seeds: Vec<u64> = list("MSREG_SEED_LIST", (2000..2010u32).map(f64::from).collect())
        .into_iter()
        .map(|s| s as u64)
        .collect();
    for rate in list("MSREG_RATES", vec![400.0, 200.0]) {
        let outcomes = par_map(&seeds, |seed| run(seed, rate, 60.0));
        check(&outcomes);
        let n = outcomes.len() as f64;
        let nees: f64 = outcomes.iter().map(|o| o.nees).sum();
        let z2: f64 = outcomes
            .iter()
            .map(|o| (o.td_err_ms / o.td_sigma_ms).powi(2))
            .sum();
        let (lo, hi) = chi_square_band(6.0 * n);
        let (zlo, zhi) = chi_square_band(n);
        println!(
            "{rate} Hz: NEES sum {nees:.1} (band {lo:.1}-{hi:.1}), time-offset sum z^2 {z2:.1} \
             (band {zlo:.1}-{zhi:.1})"
        );
        assert!((lo..=hi).contains(&nees), "NEES sum {nees}");
        assert!(z2 <= zhi, "time-offset sum z^2 {z2}");
    }
}
