//! Accuracy and consistency of the LiDAR-IMU calibration on simulated hand-held recordings
//! in the indoor box world (VN-300-class IMU at 400 Hz, 10 Hz spinning LiDAR, 2 cm range
//! noise, random mounting, unknown time offset estimated).
//!
//! The CI tests run 25 s recordings of a 32 x 512 LiDAR on 5 seeds (accuracy, 3 sigma,
//! NEES band, NIS), with the default local map and scan-to-scan; the 60 s
//! Ouster-128 acceptance run over 5 seeds is `#[ignore]`d (minutes of CPU):
//! `cargo test --release -p msreg-host --test lidar_imu_accuracy -- --ignored --nocapture`.

#[path = "support/common.rs"]
mod common;
#[path = "support/lidar.rs"]
mod lidar_support;

use common::chi_square_band;
use lidar_support::{config, error};
use msreg_host::calibrate::lidar_imu::{self, LidarImuCalibration, LidarImuInput, LidarImuOptions};
use msreg_host::sim::{simulate_lidar_imu, LidarImuSim, LidarImuSimConfig};
use nalgebra::{Isometry3, Vector6};

struct Outcome {
    seed: u64,
    rot_deg: f64,
    trans_mm: f64,
    td_err_ms: f64,
    td_sigma_ms: f64,
    sigma_rot_deg: f64,
    sigma_trans_mm: f64,
    inside: bool,
    nees: f64,
    nis: f64,
    all_nis: f64,
    scale: f64,
    ndt_rot_err_deg: f64,
    ndt_trans_err_mm: f64,
    ndt_lag1: [f64; 2],
    matched: usize,
    seconds: f64,
    converged: bool,
}

/// RMS per-axis error of the fused NDT increments against the true LiDAR motion, and the
/// lag-1 autocorrelation of those errors `(rotation, translation)` over consecutive fused
/// increments (0 = white, as the filter assumes).
fn ndt_errors(sim: &LidarImuSim, c: &LidarImuCalibration) -> (f64, f64, [f64; 2]) {
    let td = sim.config.lidar.time_offset_s;
    let mut previous: Option<u64> = None;
    let (mut sr, mut st, mut n) = (0.0, 0.0, 0usize);
    let mut errors: Vec<Option<Vector6<f64>>> = Vec::new();
    for s in &c.report.scans {
        let mut this = None;
        if let (Some(prev), Some(rv), Some(t)) = (previous, s.delta_rotation, s.delta_translation) {
            let a = sim.t_g_l(sim.seconds(prev) + td);
            let b = sim.t_g_l(sim.seconds(s.reference_stamp_ns) + td);
            let truth = a.inverse() * b;
            let meas = Isometry3::from_parts(
                nalgebra::Translation3::from(nalgebra::Vector3::from(t)),
                nalgebra::UnitQuaternion::from_scaled_axis(nalgebra::Vector3::from(rv)),
            );
            let e = error(&meas, &truth);
            sr += e.fixed_rows::<3>(0).norm_squared();
            st += e.fixed_rows::<3>(3).norm_squared();
            n += 3;
            this = Some(e);
        }
        errors.push(this);
        previous = (s.status == "matched"
            || s.status == "anchor"
            || s.status.starts_with("rejected")
            || s.status.starts_with("NDT")
            || s.status.starts_with("degenerate"))
        .then_some(s.reference_stamp_ns);
    }
    let n = n.max(1) as f64;
    if std::env::var("MSREG_SIGMAS").is_ok() {
        let mut r: Vec<f64> = c
            .report
            .scans
            .iter()
            .filter_map(|s| s.sigma)
            .map(|s| s[0].max(s[1]).max(s[2]))
            .collect();
        let mut t: Vec<f64> = c
            .report
            .scans
            .iter()
            .filter_map(|s| s.sigma)
            .map(|s| s[3].max(s[4]).max(s[5]))
            .collect();
        r.sort_by(f64::total_cmp);
        t.sort_by(f64::total_cmp);
        println!(
            "median max-axis sigma: {:.4} deg, {:.2} mm",
            r[r.len() / 2].to_degrees(),
            t[t.len() / 2] * 1e3
        );
    }
    let corr = |start: usize| {
        let (mut num, mut den) = (0.0, 0.0);
        for w in errors.windows(2) {
            if let (Some(a), Some(b)) = (w[0], w[1]) {
                let (a, b) = (a.fixed_rows::<3>(start), b.fixed_rows::<3>(start));
                num += a.dot(&b);
                den += 0.5 * (a.norm_squared() + b.norm_squared());
            }
        }
        num / den.max(f64::MIN_POSITIVE)
    };
    (
        (sr / n).sqrt().to_degrees(),
        (st / n).sqrt() * 1e3,
        [corr(0), corr(3)],
    )
}

fn run(sim_config: &LidarImuSimConfig, options: &LidarImuOptions) -> Outcome {
    let sim = simulate_lidar_imu(sim_config).expect("valid simulation");
    let input = LidarImuInput {
        imu: &sim.imu,
        imu_noise: &sim.imu_noise,
        scans: &sim,
    };
    let started = std::time::Instant::now();
    let c = lidar_imu::calibrate::<f64>(&input, options, &mut |_| {}).expect("calibration runs");
    let seconds = started.elapsed().as_secs_f64();
    let e = error(&c.t_imu_sensor, &sim.t_imu_lidar);
    let sd = |i: usize| c.covariance[(i, i)].sqrt();
    let inside = (0..6).all(|i| e[i].abs() <= 3.0 * sd(i));
    let nees = c
        .covariance
        .try_inverse()
        .map_or(f64::NAN, |info| e.dot(&(info * e)));
    let (ndt_rot_err_deg, ndt_trans_err_mm, ndt_lag1) = ndt_errors(&sim, &c);
    Outcome {
        seed: sim_config.seed,
        rot_deg: c
            .t_imu_sensor
            .rotation
            .angle_to(&sim.t_imu_lidar.rotation)
            .to_degrees(),
        trans_mm: (c.t_imu_sensor.translation.vector - sim.t_imu_lidar.translation.vector).norm()
            * 1e3,
        td_err_ms: (c.time_offset_s - sim.config.lidar.time_offset_s) * 1e3,
        td_sigma_ms: c.time_offset_sigma_s * 1e3,
        sigma_rot_deg: (0..3).map(sd).fold(0.0, f64::max).to_degrees(),
        sigma_trans_mm: (3..6).map(sd).fold(0.0, f64::max) * 1e3,
        inside,
        nees,
        nis: c.report.settled_nis_per_dof,
        all_nis: c.report.filter.mean_nis_per_dof,
        scale: c.report.final_covariance_scale,
        ndt_rot_err_deg,
        ndt_trans_err_mm,
        ndt_lag1,
        matched: c.report.scans_matched,
        seconds,
        converged: c.report.filter.converged,
    }
}

fn print(o: &Outcome) {
    println!(
        "seed {:3}: rot {:.4} deg (3sd {:.4})  trans {:.2} mm (3sd {:.2})  td err {:+.3} ms (3sd {:.3})  \
         inside 3 sigma {}  NEES {:.2}  settled NIS/dof {:.2} (all updates {:.3}, scale {:.3})  NDT rms err {:.4} deg / {:.2} mm  \
         lag-1 corr {:+.2} / {:+.2}  matched {}  {:.1} s  converged {}",
        o.seed,
        o.rot_deg,
        3.0 * o.sigma_rot_deg,
        o.trans_mm,
        3.0 * o.sigma_trans_mm,
        o.td_err_ms,
        3.0 * o.td_sigma_ms,
        o.inside,
        o.nees,
        o.nis,
        o.all_nis,
        o.scale,
        o.ndt_rot_err_deg,
        o.ndt_trans_err_mm,
        o.ndt_lag1[0],
        o.ndt_lag1[1],
        o.matched,
        o.seconds,
        o.converged
    );
}

#[test]
fn chi_square_band_matches_tables() {
    // chi2(30): 2.5 % 16.79, 97.5 % 46.98 (Wilson-Hilferty within 0.1 %); chi2(6): 1.237,
    // 14.45 (its lower tail 2.5 % low at so few dof).
    let (lo, hi) = chi_square_band(30.0);
    assert!(
        (lo - 16.79).abs() < 0.05 && (hi - 46.98).abs() < 0.05,
        "{lo} {hi}"
    );
    let (lo, hi) = chi_square_band(6.0);
    assert!(
        (lo / 1.237 - 1.0).abs() < 0.03 && (hi / 14.45 - 1.0).abs() < 0.01,
        "{lo} {hi}"
    );
}

/// `MSREG_NOISE=scale_rot,scale_trans,floor_deg,floor_m[,anneal_updates[,0 = no adaptation]]`
/// replaces the noise model, for experiments.
fn noise_override(options: &mut LidarImuOptions) {
    if let Ok(v) = std::env::var("MSREG_NOISE") {
        let v: Vec<f64> = v.split(',').filter_map(|x| x.parse().ok()).collect();
        options.covariance_scale = [v[0], v[1]];
        options.rotation_floor_rad = v[2].to_radians();
        options.translation_floor_m = v[3];
        if let Some(a) = v.get(4) {
            options.anneal_updates = *a;
        }
        if v.get(5).is_some_and(|x| *x == 0.0) {
            options.adapt = None;
        }
    }
}

/// Upper bounds on one seed's errors: rotation (deg), translation (mm), |time offset| (ms).
struct Bounds {
    rot_deg: f64,
    trans_mm: f64,
    td_ms: f64,
}

/// The 25 s, 32 x 512 CI scenario on seeds 1-5 (`MSREG_SEED_LIST` overrides) with `base`
/// options (`MSREG_NOISE` / `MSREG_LOCAL_MAP` override the noise model and the map for
/// experiments), asserting what both matching modes must meet: every seed accurate,
/// converged and inside 3 sigma per axis; the summed extrinsic NEES inside the 95 % band of
/// chi-square with 6 x 5 dof; the settled NIS/dof near 1 (the adaptive noise scale targets
/// it, the floor holds it somewhat below; a broken adaptation lands outside).
fn short_recordings_are_consistent(base: LidarImuOptions, bounds: &Bounds) -> Vec<Outcome> {
    let seeds: Vec<u64> = std::env::var("MSREG_SEED_LIST")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.parse().ok()).collect())
        .unwrap_or_else(|| (1..=5).collect());
    let mut outcomes = Vec::new();
    for &seed in &seeds {
        // 25 s is ~240 updates: anneal faster so 100 of them are past the settling point.
        let mut options = LidarImuOptions {
            anneal_updates: 45.0,
            ..base.clone()
        };
        if let Ok(k) = std::env::var("MSREG_LOCAL_MAP") {
            options = LidarImuOptions {
                anneal_updates: options.anneal_updates,
                ..LidarImuOptions::for_local_map(k.parse().unwrap_or(0))
            };
        }
        noise_override(&mut options);
        let o = run(&config(seed, 25.0, 32, 512), &options);
        print(&o);
        outcomes.push(o);
    }
    let n = outcomes.len() as f64;
    let nees_sum: f64 = outcomes.iter().map(|o| o.nees).sum();
    let (lo, hi) = chi_square_band(6.0 * n);
    let mean_nis = outcomes.iter().map(|o| o.nis).sum::<f64>() / n;
    println!(
        "local map {}: NEES sum {nees_sum:.2} (95 % band of chi2({}) [{lo:.2}, {hi:.2}]), \
         mean NEES {:.2}, mean settled NIS/dof {mean_nis:.2}",
        base.local_map_scans,
        6.0 * n,
        nees_sum / n
    );
    for o in &outcomes {
        let seed = o.seed;
        assert!(o.inside, "seed {seed}: error outside 3 sigma");
        assert!(
            o.rot_deg < bounds.rot_deg && o.trans_mm < bounds.trans_mm,
            "seed {seed}: {:.4} deg, {:.2} mm",
            o.rot_deg,
            o.trans_mm
        );
        assert!(
            o.td_err_ms.abs() < bounds.td_ms,
            "seed {seed}: time offset error {:+.3} ms",
            o.td_err_ms
        );
        assert!(o.converged, "seed {seed}: not converged");
    }
    assert!(
        (lo..=hi).contains(&nees_sum),
        "NEES sum {nees_sum:.2} outside [{lo:.2}, {hi:.2}]"
    );
    // The final floor (unmodelled, time-correlated NDT errors) keeps the NIS below 1 by
    // design (0.63-0.88 per seed scan-to-scan, 0.78-1.02 with the local map and its smaller
    // floor); this bound catches a mis-scaled filter (the fixed factor 0.3 of the first
    // version gave 0.36-0.53, a factor 10 off gives ~0.1 or ~10).
    assert!(
        (0.6..=1.5).contains(&mean_nis),
        "mean settled NIS/dof {mean_nis:.2}"
    );
    outcomes
}

/// The default matching and noise model (scan-to-local-map, 5 scans, its floor 0.0025 deg /
/// 0.25 mm) on the CI scenario (~25 s of CPU), with one change: `anneal_updates` 45
/// instead of the default 100. A 25 s recording has ~240 updates, fewer than the 300
/// (3 x `anneal_updates`) after which the default settles and the settled NIS is measured,
/// so with the default the NIS check would have no updates to judge; the defaults proper
/// are run by the `#[ignore]`d 60 s acceptance test (docs/lidar_imu.md).
/// Bounds ~3x the worst of seeds 1-5 (0.0120 deg, 0.88 mm, +0.064 ms; docs/lidar_imu.md,
/// "Test bounds"); seeds 101-110, never used for tuning, stay inside them. Also asserts why its floor is half the scan-to-scan one: the
/// errors of consecutive map-based increments are not positively correlated (the increment
/// `T_map_prev^-1 T_map_this` differences two map-relative poses; mean lag-1
/// autocorrelation negative in rotation and translation here, where scan-to-scan's is
/// +0.17 to +0.30 in rotation), so there is less correlated error for the floor to stand
/// for. With the scan-to-scan floor the local map is conservative here (NEES sum 13.2).
#[test]
fn local_map_defaults_with_faster_anneal_are_accurate_and_consistent_over_five_seeds() {
    let options = LidarImuOptions::default();
    assert!(
        options.local_map_scans > 0,
        "the default matches a local map"
    );
    let bounds = Bounds {
        rot_deg: 0.035,
        trans_mm: 2.6,
        td_ms: 0.2,
    };
    let outcomes = short_recordings_are_consistent(options, &bounds);
    let n = outcomes.len() as f64;
    for axis in 0..2 {
        let rho = outcomes.iter().map(|o| o.ndt_lag1[axis]).sum::<f64>() / n;
        assert!(
            rho < 0.0,
            "mean lag-1 autocorrelation {rho:+.2} (axis block {axis})"
        );
    }
}

/// Scan-to-scan matching (`LidarImuOptions::scan_to_scan`, its floor 0.005 deg / 0.5 mm) on
/// the same scenario: the mode the noise model was first sized on stays consistent.
/// Bounds ~3x the worst of seeds 1-5 (0.0154 deg, 1.39 mm, +0.144 ms).
#[test]
fn scan_to_scan_is_accurate_and_consistent_over_five_seeds() {
    let bounds = Bounds {
        rot_deg: 0.045,
        trans_mm: 4.2,
        td_ms: 0.45,
    };
    short_recordings_are_consistent(LidarImuOptions::scan_to_scan(), &bounds);
}

fn env_or(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The acceptance run: 60 s, Ouster-128 x 1024, default options; asserts every seed
/// < 0.1 deg, < 5 mm and inside 3 sigma, and the NEES sum inside its 95 % band
/// (MSREG_RINGS / MSREG_COLUMNS / MSREG_SEEDS / MSREG_DURATION / MSREG_NO_DESKEW=1 /
/// MSREG_LOCAL_MAP=K / MSREG_NOISE override, for measurements).
#[test]
#[ignore = "minutes of CPU: the 60 s Ouster-128 acceptance measurement"]
fn sixty_second_ouster_128_five_seeds() {
    let rings = env_or("MSREG_RINGS", 128);
    let columns = env_or("MSREG_COLUMNS", 1024);
    let seeds = env_or("MSREG_SEEDS", 5) as u64;
    let duration = env_or("MSREG_DURATION", 60) as f64;
    let local_map_scans = env_or(
        "MSREG_LOCAL_MAP",
        LidarImuOptions::default().local_map_scans,
    );
    let mut options = LidarImuOptions {
        deskew: std::env::var("MSREG_NO_DESKEW").is_err(),
        ..LidarImuOptions::for_local_map(local_map_scans)
    };
    noise_override(&mut options);
    let mut all_ok = true;
    let mut nees_sum = 0.0;
    for seed in 1..=seeds {
        let o = run(&config(seed, duration, rings, columns), &options);
        print(&o);
        all_ok &= o.inside && o.rot_deg < 0.1 && o.trans_mm < 5.0;
        nees_sum += o.nees;
    }
    let (lo, hi) = chi_square_band(6.0 * seeds as f64);
    println!("all seeds < 0.1 deg, < 5 mm and inside 3 sigma: {all_ok}");
    println!("NEES sum {nees_sum:.2}, 95 % band [{lo:.2}, {hi:.2}]");
    assert!(
        all_ok,
        "a seed misses the accuracy or the 3 sigma criterion"
    );
    assert!(
        (lo..=hi).contains(&nees_sum),
        "NEES sum {nees_sum:.2} outside [{lo:.2}, {hi:.2}]"
    );
}
