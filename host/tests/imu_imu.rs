//! Two IMUs on one simulated hand-held trajectory: imu1 against imu0 over 10 seeds.
//! imu1 is sampled from the same trajectory at its own mounting (its specific force from a
//! central difference of its own position in `G`), with its own noise, biases, rate and
//! clock offset.

use msreg_host::calibrate::imu_imu::{calibrate, ImuImuOptions, ImuSeries};
use msreg_host::sim::{Trajectory, TrajectoryConfig, GRAVITY};
use nalgebra::{Isometry3, SMatrix, SVector, Translation3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

const DURATION_S: f64 = 20.0;

struct Truth {
    t_0_1: Isometry3<f64>,
    timeshift_s: f64,
}

fn noisy(rng: &mut ChaCha8Rng, sigma: f64) -> Vector3<f64> {
    let n = Normal::new(0.0, sigma).expect("a finite, positive sigma");
    Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng))
}

/// Samples an IMU at `t_b = T_G_I0(t) * t_0_b` at `rate` Hz; stamps are `t - timeshift`.
fn sample(
    traj: &Trajectory,
    t_0_b: &Isometry3<f64>,
    rate: f64,
    timeshift: f64,
    rng: &mut ChaCha8Rng,
) -> ImuSeries {
    let (gd, ad) = (1.7e-4, 2.0e-3); // noise densities
    let (bg, ba) = (noisy(rng, 0.01), noisy(rng, 0.05));
    let mut s = ImuSeries::default();
    let h = 1e-3;
    let pos = |t: f64| (traj.isometry(t) * t_0_b).translation.vector;
    let mut t = 0.3 + rng.gen::<f64>() / rate;
    while t < DURATION_S - 0.3 {
        let iso = traj.isometry(t) * t_0_b;
        let acc = (pos(t + h) - 2.0 * pos(t) + pos(t - h)) / (h * h);
        let f = iso
            .rotation
            .inverse_transform_vector(&(acc + Vector3::new(0.0, 0.0, GRAVITY)));
        let w = t_0_b.rotation.inverse_transform_vector(&traj.body_rate(t));
        s.t.push(t - timeshift);
        s.gyro.push(w + bg + noisy(rng, gd * rate.sqrt()));
        s.accel.push(f + ba + noisy(rng, ad * rate.sqrt()));
        t += 1.0 / rate;
    }
    s
}

fn run(seed: u64) -> (SVector<f64, 7>, SMatrix<f64, 7, 7>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let traj = Trajectory::random(&TrajectoryConfig::default(), &mut rng);
    let axis = UnitQuaternion::from_scaled_axis(noisy(&mut rng, 1.0));
    let dir = noisy(&mut rng, 1.0).normalize();
    let lever = dir * rng.gen_range(0.05..0.30);
    let truth = Truth {
        t_0_1: Isometry3::from_parts(Translation3::from(lever), axis),
        timeshift_s: rng.gen_range(-0.05..0.05),
    };
    let s0 = sample(&traj, &Isometry3::identity(), 200.0, 0.0, &mut rng);
    let rate1 = rng.gen_range(100.0..400.0);
    let s1 = sample(&traj, &truth.t_0_1, rate1, truth.timeshift_s, &mut rng);
    let est = calibrate(&s0, &s1, &ImuImuOptions::default()).expect("calibrates");
    let dq = (truth.t_0_1.rotation.inverse() * est.rotation).scaled_axis();
    let dp = est.translation - truth.t_0_1.translation.vector;
    let dt = est.timeshift_s - truth.timeshift_s;
    let err = SVector::<f64, 7>::from_iterator(dq.iter().chain(dp.iter()).copied().chain([dt]));
    let mut cov = SMatrix::<f64, 7, 7>::zeros();
    let c4 = est.cov_rot_time;
    for (i, p) in [0usize, 1, 2, 6].iter().enumerate() {
        for (k, q) in [0usize, 1, 2, 6].iter().enumerate() {
            cov[(*p, *q)] = c4[(i, k)];
        }
    }
    cov.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&est.cov_translation);
    println!(
        "seed {seed}: rot {:.4} deg, lever {:.2} mm, time {:.4} ms; sigma rot {:.4} deg, lever {:.2} mm, time {:.4} ms",
        dq.norm().to_degrees(),
        dp.norm() * 1e3,
        dt * 1e3,
        est.sigma_rotation.norm().to_degrees(),
        est.sigma_translation.norm() * 1e3,
        est.sigma_timeshift_s * 1e3
    );
    (err, cov)
}

#[test]
fn imu1_within_tolerance_over_ten_seeds() {
    let mut nees = Vec::new();
    for seed in 0..10 {
        let (e, cov) = run(seed);
        assert!(
            e.fixed_rows::<3>(0).norm().to_degrees() < 0.1,
            "seed {seed} rotation"
        );
        assert!(e.fixed_rows::<3>(3).norm() < 0.005, "seed {seed} lever");
        assert!(e[6].abs() < 0.0002, "seed {seed} time");
        nees.push((e.transpose() * cov.try_inverse().expect("an invertible covariance") * e)[0]);
    }
    let mean = nees.iter().sum::<f64>() / nees.len() as f64;
    println!("NEES per seed {nees:?}, mean {mean:.2} (7 dof)");
    // Two-sided 95 % band of chi2(70) / 10: [48.76, 95.02] / 10.
    assert!(
        (4.876..=9.502).contains(&mean),
        "mean NEES {mean} outside the band"
    );
}
