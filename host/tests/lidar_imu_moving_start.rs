//! LiDAR-IMU moving start (issue 11): the recording cut to begin at peak motion (the IMU
//! sample of the fastest rotation in its first 20 s, after the first second), so there is no
//! standstill to initialise from. The scans before the cut are dropped with the IMU samples.
//!
//! `cargo test --release -p msreg-host --test lidar_imu_moving_start -- --ignored --nocapture`
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

/// The simulator's scans from index `first` on; from scan `knock` on (absolute index) the
/// LiDAR is knocked: its mounting `T_I_L` becomes `T_I_L * delta`, so every point it
/// measures is `delta^-1 p` in the new sensor frame.
struct From<'a> {
    sim: &'a LidarImuSim,
    first: usize,
    knock: Option<(usize, Isometry3<f64>)>,
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
        let mut cloud = self.sim.load(index + self.first)?;
        if let Some((_, delta)) = self.knock.filter(|(k, _)| index + self.first >= *k) {
            let inverse = delta.inverse();
            for p in &mut cloud.points {
                p.xyz = inverse * nalgebra::Point3::from(p.xyz).coords;
            }
        }
        Ok(cloud)
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

/// The recording cut at peak motion (or not at all with `MSREG_CUT=0`), optionally with a
/// knock `delta` of the LiDAR mounting at IMU time `t_s` after the cut, calibrated; and the
/// cut's stamp.
fn calibrate_cut(
    sim: &LidarImuSim,
    knock: Option<(f64, Isometry3<f64>)>,
) -> (lidar_imu::LidarImuCalibration, u64) {
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
    // Scans whose first firing (on the IMU clock) is after the cut (or the knock).
    let td_ns = (sim.config.lidar.time_offset_s * 1e9).round() as i64;
    let after = |t_ns: u64| {
        (0..sim.len())
            .find(|&k| sim.stamp_ns(k) as i64 + td_ns > t_ns as i64)
            .unwrap_or(sim.len())
    };
    let first = after(cut);
    let knock = knock.map(|(t_s, delta)| (after(cut + (t_s * 1e9) as u64), delta));
    let scans = From { sim, first, knock };
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
    (c, cut)
}

/// The acceptance scenario: 32 x 512 LiDAR, offset drawn in +-20 ms.
fn simulate(seed: u64, rate_hz: f64, duration_s: f64) -> LidarImuSim {
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
    simulate_lidar_imu(&config).expect("valid simulation")
}

fn run(seed: u64, rate_hz: f64, duration_s: f64) -> Outcome {
    let sim = simulate(seed, rate_hz, duration_s);
    let config = &sim.config;
    let (c, cut) = calibrate_cut(&sim, None);
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
    // The same of the innovations (measured minus predicted increment), which the
    // pipeline can see.
    let mut lag_innovation = [0.0f64; 2];
    let mut last_innovation: Option<(usize, Vector6<f64>)> = None;
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
        let u = normalised(&er, &et, &sigma);
        if let Some((_, v)) = last.filter(|(j, _)| *j + 1 == k && matched >= 100) {
            for (b, range) in [(0, 0..3), (1, 3..6)] {
                for i in range {
                    lag[b][0] += u[i] * v[i];
                    lag[b][1] += 0.5 * (u[i] * u[i] + v[i] * v[i]);
                }
            }
        }
        last = Some((k, u));
        if let Some(p) = this.predicted {
            let ir = (p.rotation.inverse() * UnitQuaternion::from_scaled_axis(Vector3::from(r)))
                .scaled_axis();
            let it = Vector3::from(t) - p.translation.vector;
            let n = normalised(&ir, &it, &sigma);
            if let Some((_, v)) = last_innovation.filter(|(j, _)| *j + 1 == k && matched >= 100) {
                lag_innovation[0] += n.dot(&v);
                lag_innovation[1] += 0.5 * (n.norm_squared() + v.norm_squared());
            }
            last_innovation = Some((k, n));
        }
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
         rot {:+.2}, trans {:+.2}; of the innovations {:+.2}; final scale {:.3}, settled \
         NIS/dof {:.2}",
        lag[0][0] / lag[0][1],
        lag[1][0] / lag[1][1],
        lag_innovation[0] / lag_innovation[1],
        c.report.final_covariance_scale,
        c.report.settled_nis_per_dof
    );
}

/// `[rotation; translation]` divided per component by `sigma`.
fn normalised(
    rotation: &Vector3<f64>,
    translation: &Vector3<f64>,
    sigma: &[f64; 6],
) -> Vector6<f64> {
    Vector6::from_fn(|i, _| {
        if i < 3 {
            rotation[i] / sigma[i]
        } else {
            translation[i - 3] / sigma[i]
        }
    })
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

/// A 1 deg knock of the LiDAR 30 s after a moving start (seed 7, 400 Hz, 75 s simulated,
/// cut at peak motion in the first 20 s): flagged as a rotation step within 5 s, once, and 20 s later the estimate sits
/// inside its 3 sigma around the new mounting (the pose-IMU health test's criteria).
#[test]
fn knock_after_a_moving_start_is_flagged_and_reestimated() {
    const KNOCK_AT_S: f64 = 30.0;
    let sim = simulate(7, 400.0, 75.0);
    let axis = Vector3::new(0.3, -0.8, 0.5).normalize();
    let delta = Isometry3::from_parts(
        Default::default(),
        UnitQuaternion::from_scaled_axis(axis * 1f64.to_radians()),
    );
    // History and event times are seconds since the first IMU sample: the cut.
    let (c, _) = calibrate_cut(&sim, Some((KNOCK_AT_S, delta)));
    let truth = sim.t_imu_lidar * delta;
    let history = &c.report.filter.history;
    let at = |t: f64| {
        history
            .iter()
            .take_while(|h| h.t_s <= t)
            .last()
            .expect("updates before t")
    };
    let error_deg = |t: f64| {
        let q = UnitQuaternion::from_scaled_axis(Vector3::from(at(t).rotation_vector));
        (q.inverse() * truth.rotation)
            .scaled_axis()
            .map(f64::to_degrees)
    };
    let events: Vec<_> = c
        .report
        .filter
        .events
        .iter()
        .map(|e| (e.t_s, e.kind))
        .collect();
    let h = at(KNOCK_AT_S + 20.0);
    println!(
        "knock: events {events:?}; error before {:.3} deg, +20 s {:.4?} deg (1-sigma {:.4?} deg)",
        error_deg(KNOCK_AT_S - 0.1).norm(),
        error_deg(KNOCK_AT_S + 20.0),
        h.sigma_rot_deg
    );
    let first = c
        .report
        .filter
        .events
        .first()
        .expect("the knock is flagged");
    assert_eq!(first.kind, "rotation_step", "{events:?}");
    assert!(
        (KNOCK_AT_S..=KNOCK_AT_S + 5.0).contains(&first.t_s),
        "{events:?}"
    );
    assert_eq!(events.len(), 1, "flagged more than once: {events:?}");
    let e = error_deg(KNOCK_AT_S + 20.0);
    for i in 0..3 {
        assert!(
            e[i].abs() <= 3.0 * h.sigma_rot_deg[i],
            "axis {i}: {e:?} vs {h:?}"
        );
    }
}
