//! Joint LiDAR-IMU-camera calibration (issue 13) on the joint simulator: a hand-held rig in
//! front of a checkerboard on a board both sensors see, both time offsets drawn in +-20 ms.
//! Judged per sensor (`T_cam_imu`, `T_imu_lidar`, time offsets), on the derived
//! `T_cam_lidar`, and against chaining the two pairwise pipelines on the same data.
//!
//! CI runs one seed on 30 s; the acceptance run (10 seeds, 60 s, with the pairwise runs) is
//! `cargo test --release -p msreg-host --test joint_calibration -- --ignored --nocapture`
//! (`MSREG_SEEDS`, `MSREG_DURATION` shorten it; `MSREG_NO_PLANES=1` runs the joint filter
//! without the board-plane update, for comparison).
//!
//! The mean of the board-plane rows at the true state is printed (`plane rows at the
//! truth`): ~0.01-0.05 mm and ~0.1-0.3 mrad since the board's returns are selected by their
//! rays and the plane is fitted along them (docs/joint.md; before, +0.4-0.5 mm made the
//! derived `T_cam_lidar` NEES 78-126 per seed).

#[path = "support/common.rs"]
mod common;
#[path = "support/corners.rs"]
mod corners;

use common::{chi_square_band, par_map};
use msreg_host::calibrate::joint::{self, JointCalibration, JointInput, JointOptions};
use msreg_host::sim::{simulate_joint, JointSim, JointSimConfig};
use nalgebra::{Isometry3, Matrix6, Vector6};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Corner noise of the simulated detections, px.
const PIXEL_SIGMA: f64 = 0.1;

fn config(seed: u64, duration_s: f64) -> JointSimConfig {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x101_7ed);
    let mut c = JointSimConfig::default();
    c.camera.seed = seed;
    c.camera.duration_s = duration_s;
    c.camera.time_offset_s = rng.gen_range(-0.020..0.020);
    c.lidar.time_offset_s = rng.gen_range(-0.020..0.020);
    c.lidar.rings = 32;
    c.lidar.columns = 512;
    c
}

/// An estimate against its truth: rotation (deg), translation (mm), NEES (6 dof), the
/// largest axis error in its sigmas, and whether every axis is inside 3 sigma.
#[derive(Debug, Clone, Copy)]
struct Error6 {
    rotation_deg: f64,
    translation_mm: f64,
    nees: f64,
    worst_sigmas: f64,
    inside: bool,
}

fn error6(estimate: &Isometry3<f64>, covariance: &Matrix6<f64>, truth: &Isometry3<f64>) -> Error6 {
    let r = (estimate.rotation.inverse() * truth.rotation).scaled_axis();
    let p = truth.translation.vector - estimate.translation.vector;
    let e = Vector6::new(r.x, r.y, r.z, p.x, p.y, p.z);
    let worst = (0..6)
        .map(|i| e[i].abs() / covariance[(i, i)].sqrt())
        .fold(0.0, f64::max);
    Error6 {
        rotation_deg: r.norm().to_degrees(),
        translation_mm: p.norm() * 1e3,
        nees: covariance
            .try_inverse()
            .map_or(f64::NAN, |info| e.dot(&(info * e))),
        worst_sigmas: worst,
        inside: worst <= 3.0,
    }
}

/// One seed's joint run judged.
#[derive(Debug, Clone, Copy)]
struct Outcome {
    seed: u64,
    camera: Error6,
    lidar: Error6,
    cam_lidar: Error6,
    /// (error, sigma) of the camera's and the LiDAR's time offset, ms.
    camera_offset_ms: (f64, f64),
    lidar_offset_ms: (f64, f64),
    converged: bool,
    planes_fused: usize,
    /// The joint `T_cam_lidar` covariance `[dtheta; dp]`.
    cam_lidar_covariance: Matrix6<f64>,
    /// Chained pairwise `T_cam_lidar` judged against its own (independent-runs)
    /// covariance, and that covariance, when run.
    chained: Option<(Error6, Matrix6<f64>)>,
}

/// The probability that the joint `T_cam_lidar` is at least as accurate as the chained one
/// in both rotation and translation, if both are consistent and the joint run is the
/// efficient one: then the chained error is the joint error plus an independent part of
/// covariance `chained - joint` (the less informed of two efficient estimates differs
/// from the better one by noise uncorrelated with it). Monte Carlo over `samples` draws.
fn win_probability(joint: &Matrix6<f64>, chained: &Matrix6<f64>, samples: usize) -> f64 {
    let root = |m: Matrix6<f64>| {
        let e = m.symmetric_eigen();
        let d = e.eigenvalues.map(|l| l.max(0.0).sqrt());
        e.eigenvectors * Matrix6::from_diagonal(&d)
    };
    let (a, b) = (root(*joint), root(chained - joint));
    let mut rng = ChaCha8Rng::seed_from_u64(0x3177);
    let mut draw = || Vector6::from_fn(|_, _| rng.sample::<f64, _>(rand_distr::StandardNormal));
    let wins = (0..samples)
        .filter(|_| {
            let e = a * draw();
            let c = e + b * draw();
            e.fixed_rows::<3>(0).norm() <= c.fixed_rows::<3>(0).norm()
                && e.fixed_rows::<3>(3).norm() <= c.fixed_rows::<3>(3).norm()
        })
        .count();
    wins as f64 / samples as f64
}

/// RMS over the three axes of a `[dtheta; dp]` covariance's rotation sigma, deg.
fn rotation_sigma_deg(covariance: &Matrix6<f64>) -> f64 {
    (covariance.fixed_view::<3, 3>(0, 0).trace() / 3.0)
        .sqrt()
        .to_degrees()
}

fn judge(seed: u64, sim: &JointSim, c: &JointCalibration) -> Outcome {
    let offset = |est: f64, sigma: f64, truth: f64| ((est - truth) * 1e3, sigma * 1e3);
    Outcome {
        seed,
        camera: error6(
            &c.camera.t_imu_sensor,
            &c.camera.covariance,
            &sim.camera.t_cam_imu.inverse(),
        ),
        lidar: error6(
            &c.lidar.t_imu_sensor,
            &c.lidar.covariance,
            &sim.lidar.t_imu_lidar,
        ),
        cam_lidar: error6(&c.t_cam_lidar, &c.cam_lidar_covariance, &sim.t_cam_lidar()),
        cam_lidar_covariance: c.cam_lidar_covariance,
        camera_offset_ms: offset(
            c.camera.time_offset_s,
            c.camera.time_offset_sigma_s,
            sim.camera.config.time_offset_s,
        ),
        lidar_offset_ms: offset(
            c.lidar.time_offset_s,
            c.lidar.time_offset_sigma_s,
            sim.lidar.config.lidar.time_offset_s,
        ),
        converged: c.converged(),
        planes_fused: c.planes.fused,
        chained: None,
    }
}

/// The mean of each board-plane row at the true state (whitened rows over sqrt(K) and
/// sqrt(lambda): mm of distance, mrad of tilt), printed.
fn plane_bias(sim: &JointSim, c: &JointCalibration) {
    use msreg_estimator::update::board_plane;
    use msreg_estimator::Pose;
    let pose = |t: &Isometry3<f64>| Pose::new(t.rotation, t.translation.vector);
    let lidar = &sim.lidar;
    let mut sum = nalgebra::Vector3::zeros();
    for p in &c.plane_measurements {
        let t = lidar.seconds(p.stamp_ns) + lidar.config.lidar.time_offset_s;
        let h = board_plane::predict(
            &pose(&sim.camera.trajectory.isometry(t)),
            &pose(&lidar.t_imu_lidar),
            &pose(&sim.camera.t_g_target),
            p,
        );
        let w = [
            f64::from(p.count).sqrt(),
            p.spread[0].sqrt(),
            p.spread[1].sqrt(),
        ];
        sum += nalgebra::Vector3::new(h[0] / w[0], h[1] / w[1], h[2] / w[2]) * 1e3;
    }
    println!(
        "  plane rows at the truth, mean over {}: {:?}",
        c.plane_measurements.len(),
        (sum / c.plane_measurements.len().max(1) as f64).as_slice()
    );
}

fn run(seed: u64, duration_s: f64, pairwise: bool) -> Outcome {
    let sim = simulate_joint(&config(seed, duration_s)).expect("valid simulation");
    let frames = corners::noisy_corner_frames(&sim.camera, PIXEL_SIGMA, seed);
    let target = sim.target();
    let input = JointInput {
        imu: &sim.camera.imu,
        imu_noise: &sim.camera.imu_noise,
        scans: &sim.lidar,
        camera: &sim.camera.config.camera,
        frames: &frames,
        target: &target,
    };
    let mut options = JointOptions::default();
    if std::env::var_os("MSREG_NO_PLANES").is_some() {
        options.plane.arm_sigma_translation_m = 0.0;
    }
    let c = joint::calibrate::<f64>(&input, &options, &mut |_| {}).expect("joint calibration runs");
    println!("seed {seed}: planes {:?}", c.planes);
    plane_bias(&sim, &c);
    let mut outcome = judge(seed, &sim, &c);
    if pairwise {
        outcome.chained = Some(chained_pairwise(&sim, &input));
    }
    print(&outcome);
    outcome
}

/// `T_cam_lidar` from the camera-IMU and LiDAR-IMU pipelines run separately on the same
/// data, chained: judged against the composed covariance, with its RMS rotation sigma.
fn chained_pairwise(sim: &JointSim, input: &JointInput<'_>) -> (Error6, Matrix6<f64>) {
    let runs = joint::chained_pairwise(input, &JointOptions::default(), &mut |_| {})
        .expect("the pairwise pipelines run");
    let (chained, covariance) = runs.t_cam_lidar();
    (
        error6(&chained, &covariance, &sim.t_cam_lidar()),
        covariance,
    )
}

fn print(o: &Outcome) {
    let row = |name: &str, e: &Error6| {
        format!(
            "{name} {:.4} deg {:.2} mm NEES {:.1}{}",
            e.rotation_deg,
            e.translation_mm,
            e.nees,
            if e.inside {
                String::new()
            } else {
                format!(
                    " (outside 3 sigma: {:.2} sigma on one axis)",
                    e.worst_sigmas
                )
            }
        )
    };
    println!(
        "seed {}: {}; {}; {}; t_d cam {:+.3} ms (sigma {:.3}), lidar {:+.3} ms (sigma {:.3}); \
         planes {}; converged {}; rotation sigma joint {:.4} deg; chained pairwise {}",
        o.seed,
        row("cam", &o.camera),
        row("lidar", &o.lidar),
        row("cam_lidar", &o.cam_lidar),
        o.camera_offset_ms.0,
        o.camera_offset_ms.1,
        o.lidar_offset_ms.0,
        o.lidar_offset_ms.1,
        o.planes_fused,
        o.converged,
        rotation_sigma_deg(&o.cam_lidar_covariance),
        o.chained.map_or("not run".to_string(), |(e, p)| format!(
            "{} (rotation sigma {:.4} deg)",
            row("cam_lidar", &e),
            rotation_sigma_deg(&p)
        ))
    );
}

/// Seed 3, 30 s, measured: camera 0.0058 deg / 0.36 mm, LiDAR 0.0062 deg / 0.24 mm,
/// `T_cam_lidar` 0.0117 deg / 0.29 mm (all inside 3 sigma), time offsets -0.007 ms (camera)
/// and +0.046 ms (LiDAR), 271 planes; bounds about 3x.
#[test]
fn joint_calibration_one_seed() {
    let o = run(3, 30.0, false);
    assert!(o.converged, "{o:?}");
    assert!(o.planes_fused > 200, "{o:?}");
    assert!(
        o.camera.inside && o.lidar.inside && o.cam_lidar.inside,
        "{o:?}"
    );
    assert!(
        o.camera.rotation_deg < 0.018 && o.camera.translation_mm < 1.1,
        "{o:?}"
    );
    assert!(
        o.lidar.rotation_deg < 0.019 && o.lidar.translation_mm < 0.75,
        "{o:?}"
    );
    assert!(
        o.cam_lidar.rotation_deg < 0.035 && o.cam_lidar.translation_mm < 0.9,
        "{o:?}"
    );
    assert!(o.camera_offset_ms.0.abs() < 0.021, "{o:?}");
    assert!(o.lidar_offset_ms.0.abs() < 0.14, "{o:?}");
}

/// What the covariances say the win count against chained pairwise can be: the per-seed
/// win probability, its sum, and the chance of 8 or more wins (Poisson-binomial), printed;
/// asserts the measured count is within 3 sigma of it and the joint covariance is the
/// smaller on every seed.
fn check_against_chained(outcomes: &[Outcome], better: usize) {
    // What the covariances say the win count can be: the per-seed win probability, its
    // sum, and the chance of 8 or more wins (Poisson-binomial).
    let p_win: Vec<f64> = outcomes
        .iter()
        .filter_map(|o| {
            o.chained
                .map(|(_, p)| win_probability(&o.cam_lidar_covariance, &p, 20_000))
        })
        .collect();
    let expected: f64 = p_win.iter().sum();
    let spread = p_win.iter().map(|p| p * (1.0 - p)).sum::<f64>().sqrt();
    let mut count = vec![1.0];
    for p in &p_win {
        let mut next = vec![0.0; count.len() + 1];
        for (k, c) in count.iter().enumerate() {
            next[k] += c * (1.0 - p);
            next[k + 1] += c * p;
        }
        count = next;
    }
    let eight_or_more: f64 = count.iter().skip(8).sum();
    println!(
        "win probability per seed {:?}; expected wins {expected:.1} +- {spread:.1}; \
         P(>= 8 wins) {eight_or_more:.2}",
        p_win
            .iter()
            .map(|p| (p * 100.0).round() / 100.0)
            .collect::<Vec<_>>()
    );
    assert!(
        better as f64 >= expected - 3.0 * spread,
        "{better} wins against {expected:.1} +- {spread:.1} expected"
    );
    // The joint run is the better informed on every seed, in rotation and translation.
    for o in outcomes {
        let (_, p) = o.chained.expect("pairwise run");
        let j = &o.cam_lidar_covariance;
        assert!(
            j.fixed_view::<3, 3>(0, 0).trace() < p.fixed_view::<3, 3>(0, 0).trace()
                && j.fixed_view::<3, 3>(3, 3).trace() < p.fixed_view::<3, 3>(3, 3).trace(),
            "seed {}: joint covariance not below the chained one",
            o.seed
        );
    }
}

/// The acceptance run of issue 13 (10 seeds, 60 s).
#[test]
#[ignore = "acceptance run, ~15 min on 2 cores"]
fn ten_seeds_joint_against_chained_pairwise() {
    // `MSREG_SEEDS` / `MSREG_DURATION` shorten the run while investigating.
    let env = |key: &str, default: f64| {
        std::env::var(key)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(default)
    };
    let seeds: Vec<u64> = (100..100 + env("MSREG_SEEDS", 10.0) as u64).collect();
    let duration = env("MSREG_DURATION", 60.0);
    let outcomes = par_map(&seeds, |s| run(s, duration, true));
    let nees = |f: fn(&Outcome) -> f64| outcomes.iter().map(f).sum::<f64>();
    let band = chi_square_band(6.0 * outcomes.len() as f64);
    let better = outcomes
        .iter()
        .filter(|o| {
            o.chained.is_some_and(|(e, _)| {
                o.cam_lidar.rotation_deg <= e.rotation_deg
                    && o.cam_lidar.translation_mm <= e.translation_mm
            })
        })
        .count();
    println!(
        "NEES sums (band {band:?}): camera {:.1}, lidar {:.1}, cam_lidar {:.1}; joint at least \
         as accurate as chained pairwise (rotation and translation) on {better}/{}",
        nees(|o| o.camera.nees),
        nees(|o| o.lidar.nees),
        nees(|o| o.cam_lidar.nees),
        outcomes.len()
    );
    check_against_chained(&outcomes, better);
    let chained_nees: f64 = outcomes
        .iter()
        .filter_map(|o| o.chained.map(|(e, _)| e.nees))
        .sum();
    println!("chained pairwise T_cam_lidar NEES sum {chained_nees:.1} (independent runs assumed)");
    for o in &outcomes {
        assert!(o.converged, "{o:?}");
        assert!(
            o.camera.rotation_deg < 0.05 && o.camera.translation_mm < 2.0,
            "{o:?}"
        );
        assert!(
            o.lidar.rotation_deg < 0.1 && o.lidar.translation_mm < 5.0,
            "{o:?}"
        );
        assert!(
            o.cam_lidar.rotation_deg < 0.1 && o.cam_lidar.translation_mm < 3.0,
            "{o:?}"
        );
        assert!(
            o.camera_offset_ms.0.abs() < 0.5 && o.lidar_offset_ms.0.abs() < 0.5,
            "{o:?}"
        );
    }
    for f in [
        (|o: &Outcome| o.camera.nees) as fn(&Outcome) -> f64,
        |o| o.lidar.nees,
        |o| o.cam_lidar.nees,
    ] {
        let sum = nees(f);
        assert!(
            (band.0..=band.1).contains(&sum),
            "NEES sum {sum}, band {band:?}"
        );
    }
}
