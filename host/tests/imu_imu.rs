//! Two IMUs on one simulated hand-held trajectory: imu1 against imu0 over 10 seeds, through
//! the dataset path a user takes (`msreg simulate imu-imu` writes, `calibrate_rig` reads).
//! imu1 is sampled by the library simulator from the trajectory remounted at its own
//! mounting (`sim::imus`), with its own noise, biases, rate (100-400 Hz) and clock offset
//! (+-50 ms); nothing in the simulator knows the estimator's model.

use msreg_host::calibrate::imu_imu::{calibrate_rig, ImuImuOptions};
use msreg_host::dataset::{Dataset, SectionName};
use msreg_host::sim::{simulate_imus, ImusSimConfig};
use nalgebra::{SMatrix, SVector};

/// Error of imu1 against the truth `(rotation vector, lever arm, time)` and its covariance.
fn run(seed: u64, imus: usize) -> Vec<(SVector<f64, 7>, SMatrix<f64, 7, 7>)> {
    let sim = simulate_imus(&ImusSimConfig {
        seed,
        imus,
        ..ImusSimConfig::default()
    })
    .expect("a valid rig");
    let dir = tempfile::tempdir().expect("a temporary directory");
    sim.write(dir.path()).expect("writes the dataset");
    let dataset = Dataset::open(dir.path()).expect("opens");
    let rig = calibrate_rig(&dataset, &ImuImuOptions::default(), |_| {}).expect("calibrates");
    assert_eq!(rig.pairs.len(), imus - 1);
    let mut out = Vec::new();
    for (n, pair) in rig.pairs.iter().enumerate() {
        let truth = &sim.imus[n + 1];
        let est = &pair.estimate;
        assert!(
            pair.held.is_empty(),
            "seed {seed} imu{}: held {:?}",
            n + 1,
            pair.held
        );
        // The result file carries the same numbers.
        let written = rig
            .result
            .extrinsic(&SectionName::imu(n as u16 + 1))
            .expect("an imuN section");
        assert!((written.transform.translation.vector - est.translation).norm() < 1e-15);
        assert!((written.timeshift_s - est.timeshift_s).abs() < 1e-15);
        let dq = (truth.t_imu0_imu.rotation.inverse() * est.rotation).scaled_axis();
        let dp = est.translation - truth.t_imu0_imu.translation.vector;
        let dt = est.timeshift_s - truth.timeshift_s;
        let err = SVector::<f64, 7>::from_iterator(dq.iter().chain(dp.iter()).copied().chain([dt]));
        let mut cov = SMatrix::<f64, 7, 7>::zeros();
        for (i, p) in [0usize, 1, 2, 6].iter().enumerate() {
            for (k, q) in [0usize, 1, 2, 6].iter().enumerate() {
                cov[(*p, *q)] = est.cov_rot_time[(i, k)];
            }
        }
        cov.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&est.cov_translation);
        println!(
            "seed {seed} imu{}: rot {:.4} deg, lever {:.2} mm, time {:.4} ms; \
             sigma rot {:.4} deg, lever {:.2} mm, time {:.4} ms",
            n + 1,
            dq.norm().to_degrees(),
            dp.norm() * 1e3,
            dt * 1e3,
            est.sigma_rotation.norm().to_degrees(),
            est.sigma_translation.norm() * 1e3,
            est.sigma_timeshift_s * 1e3
        );
        out.push((err, cov));
    }
    out
}

/// Issue bound: 0.1 deg / 5 mm / 0.2 ms per seed. The bounds ([`BOUND_ROT_DEG`] ...) are
/// ~3x the worst seed measured, so a regression shows long before the bound is
/// reached. Mean NEES measured 8.22.
#[test]
fn imu1_within_tolerance_over_ten_seeds() {
    let mut nees = Vec::new();
    let mut worst = [0.0f64; 3];
    for seed in 0..10 {
        for (e, cov) in run(seed, 2) {
            worst[0] = worst[0].max(e.fixed_rows::<3>(0).norm().to_degrees());
            worst[1] = worst[1].max(e.fixed_rows::<3>(3).norm());
            worst[2] = worst[2].max(e[6].abs());
            nees.push((e.transpose() * cov.try_inverse().expect("invertible") * e)[0]);
        }
    }
    println!(
        "worst: rot {:.4} deg, lever {:.2} mm, time {:.4} ms",
        worst[0],
        worst[1] * 1e3,
        worst[2] * 1e3
    );
    assert!(worst[0] < BOUND_ROT_DEG, "rotation {} deg", worst[0]);
    assert!(worst[1] < BOUND_LEVER_M, "lever arm {} m", worst[1]);
    assert!(worst[2] < BOUND_TIME_S, "time offset {} s", worst[2]);
    let mean = nees.iter().sum::<f64>() / nees.len() as f64;
    println!("NEES per seed {nees:?}, mean {mean:.2} (7 dof)");
    // Two-sided 95 % band of chi2(70) / 10: [48.76, 95.02] / 10.
    assert!(
        (4.876..=9.502).contains(&mean),
        "mean NEES {mean} outside the band"
    );
}

/// A rig of three IMUs: imu1 and imu2 each against imu0, written as two sections.
#[test]
fn three_imus_each_within_tolerance() {
    for (e, _) in run(42, 3) {
        assert!(e.fixed_rows::<3>(0).norm().to_degrees() < BOUND_ROT_DEG);
        assert!(e.fixed_rows::<3>(3).norm() < BOUND_LEVER_M);
        assert!(e[6].abs() < BOUND_TIME_S);
    }
}

// Measured worst over seeds 0-9 and 42 (2026-12-02): 0.0029 deg, 0.21 mm, 0.0035 ms.
const BOUND_ROT_DEG: f64 = 0.01;
const BOUND_LEVER_M: f64 = 0.0006;
const BOUND_TIME_S: f64 = 0.000_011;
