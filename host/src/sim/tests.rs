//! Behaviour of the whole simulator: determinism, exactness of the noise-free
//! data against the trajectory (independent integrators), stated noise levels and the written layout.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use super::*;
use crate::dataset::Dataset;

type TestResult = Result<(), Box<dyn std::error::Error>>;

fn short_config(seed: u64) -> SimConfig {
    SimConfig {
        seed,
        duration_s: 12.0,
        ..SimConfig::default()
    }
}

fn distance(a: &Isometry3<f64>, b: &Isometry3<f64>) -> f64 {
    let d = a.inverse() * b;
    d.rotation.angle() + d.translation.vector.norm()
}

/// Exact equality of two record lists, reporting the first difference only.
fn assert_same<T: PartialEq + std::fmt::Debug>(read: &[T], written: &[T], what: &str) {
    assert_eq!(read.len(), written.len(), "{what}: length");
    if let Some(k) = (0..read.len()).find(|&k| read[k] != written[k]) {
        panic!(
            "{what}: record {k} differs: {:?} vs {:?}",
            read[k], written[k]
        );
    }
}

fn std_dev(values: &[f64]) -> f64 {
    let n = values.len() as f64;
    let mean = values.iter().sum::<f64>() / n;
    (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
}

#[test]
fn same_seed_gives_identical_data_and_another_seed_differs() -> TestResult {
    let a = simulate_pose_imu(&short_config(5))?;
    let b = simulate_pose_imu(&short_config(5))?;
    let c = simulate_pose_imu(&short_config(6))?;
    assert!(a == b, "same seed, different data");
    assert!(a.imu != c.imu && a.pose != c.pose);
    assert!(distance(&a.t_imu_pose, &c.t_imu_pose) > 1e-3);
    Ok(())
}

#[test]
fn changing_odometry_options_leaves_trajectory_and_imu_unchanged() -> TestResult {
    let base = simulate_pose_imu(&short_config(3))?;
    let mut config = short_config(3);
    config.pose.jitter_fraction = 0.2;
    config.pose.rate_hz = 20.0;
    let other = simulate_pose_imu(&config)?;
    assert!(base.trajectory == other.trajectory);
    assert!(base.imu == other.imu);
    assert!(base.t_imu_pose == other.t_imu_pose);
    Ok(())
}

#[test]
fn stamps_are_absolute_integers_at_the_stated_rates() -> TestResult {
    let sim = simulate_pose_imu(&short_config(1))?;
    assert_eq!(sim.imu[0].stamp_ns, DEFAULT_START_STAMP_NS);
    assert_eq!(sim.imu.len(), 12 * 400 + 1);
    assert_eq!(sim.imu[1].stamp_ns - sim.imu[0].stamp_ns, 2_500_000);
    assert_eq!(sim.pose.len(), 12 * 10 + 1);
    assert_eq!(sim.pose[3].stamp_ns - DEFAULT_START_STAMP_NS, 300_000_000);
    assert_eq!(sim.groundtruth.len(), sim.imu.len());
    Ok(())
}

#[test]
fn written_dataset_reads_back_through_the_dataset_readers() -> TestResult {
    let sim = simulate_pose_imu(&short_config(2))?;
    let dir = tempfile::tempdir()?;
    sim.write(dir.path())?;

    let dataset = Dataset::open(dir.path())?;
    assert_same(dataset.require_imu()?, &sim.imu, "imu");
    assert_eq!(dataset.require_imu_noise()?, &sim.imu_noise);
    assert_same(dataset.require_pose0()?, &sim.pose, "pose0");
    assert_eq!(dataset.require_pose0_sensor()?, &sim.pose_sensor);
    assert_same(
        dataset.require_groundtruth_trajectory()?,
        &sim.groundtruth,
        "groundtruth",
    );
    let meta = dataset.meta.ok_or("dataset.yaml missing")?;
    assert_eq!(meta.sensors, vec!["imu0".to_string(), "pose0".to_string()]);
    let truth = dataset
        .groundtruth_extrinsics
        .and_then(|e| e.get("pose0").copied())
        .ok_or("pose0 ground truth missing")?;
    assert!(distance(&truth.transform, &sim.t_imu_pose) < 1e-12);
    assert!(truth.sigma_rot_deg.norm() < f64::EPSILON);
    Ok(())
}

#[test]
fn noise_free_odometry_satisfies_the_hand_eye_relation() -> TestResult {
    let mut config = short_config(4).without_noise();
    config.pose.time_offset_s = 0.0137;
    config.pose.jitter_fraction = 0.2;
    config.pose.gap_s = Some((5.0, 6.0));
    let sim = simulate_pose_imu(&config)?;
    let x = sim.t_imu_pose;
    for pair in sim.pose.windows(2) {
        let t_g_i = |stamp| {
            sim.trajectory
                .isometry(sim.seconds(stamp) + config.pose.time_offset_s)
        };
        let imu_motion = t_g_i(pair[0].stamp_ns).inverse() * t_g_i(pair[1].stamp_ns);
        let sensor_motion = pair[0].isometry().inverse() * pair[1].isometry();
        let residual = distance(&(imu_motion * x), &(x * sensor_motion));
        assert!(
            residual < 1e-9,
            "residual {residual} at {}",
            pair[1].stamp_ns
        );
    }
    Ok(())
}

/// Largest position (m) and rotation (rad) error of the IMU samples integrated from the
/// first ground-truth state over `seconds`, by classical RK4 on the quaternion kinematics
/// `q' = q (0, w) / 2`, `v' = R a + g`, `p' = v` with 16 sub-steps per sample interval and
/// the readings linearly interpolated between their stamps, each stamp moved by `shift_s`.
/// Shares nothing with the estimator's discretisation.
fn rk4_tracking_error(sim: &SimDataset, seconds: f64, shift_s: f64) -> (f64, f64) {
    use nalgebra::Quaternion;
    type State = (Quaternion<f64>, Vector3<f64>, Vector3<f64>);
    let gravity = gravity_in_g();
    let t0 = sim.seconds(sim.imu[0].stamp_ns);
    let reading = |k: usize| (sim.imu[k].gyro, sim.imu[k].accel);
    let deriv = |x: &State, w: &Vector3<f64>, a: &Vector3<f64>| -> State {
        let q = x.0;
        let r = UnitQuaternion::from_quaternion(q);
        (q * Quaternion::from_imag(*w) * 0.5, x.2, r * a + gravity)
    };
    let add =
        |x: &State, d: &State, h: f64| -> State { (x.0 + d.0 * h, x.1 + d.1 * h, x.2 + d.2 * h) };
    let first = &sim.groundtruth[0];
    let mut x: State = (*first.rotation.quaternion(), first.position, first.velocity);
    let (mut max_p, mut max_r) = (0.0_f64, 0.0_f64);
    let mut k = 0;
    while sim.seconds(sim.imu[k + 1].stamp_ns) - t0 <= seconds {
        let (ta, tb) = (
            sim.seconds(sim.imu[k].stamp_ns),
            sim.seconds(sim.imu[k + 1].stamp_ns),
        );
        let ((wa, aa), (wb, ab)) = (reading(k), reading(k + 1));
        // The signal at time t, with the samples taken to be readings at their stamp + shift.
        let signal = |t: f64| {
            let f = (t - ta - shift_s) / (tb - ta);
            (wa + (wb - wa) * f, aa + (ab - aa) * f)
        };
        let n = 16;
        let h = (tb - ta) / f64::from(n);
        for i in 0..n {
            let t = ta + h * f64::from(i);
            let (w1, a1) = signal(t);
            let (w2, a2) = signal(t + 0.5 * h);
            let (w3, a3) = signal(t + h);
            let k1 = deriv(&x, &w1, &a1);
            let k2 = deriv(&add(&x, &k1, 0.5 * h), &w2, &a2);
            let k3 = deriv(&add(&x, &k2, 0.5 * h), &w2, &a2);
            let k4 = deriv(&add(&x, &k3, h), &w3, &a3);
            let sum = |f: &dyn Fn(&State) -> State| {
                let (d1, d2, d3, d4) = (f(&k1), f(&k2), f(&k3), f(&k4));
                (
                    d1.0 + d2.0 * 2.0 + d3.0 * 2.0 + d4.0,
                    d1.1 + d2.1 * 2.0 + d3.1 * 2.0 + d4.1,
                    d1.2 + d2.2 * 2.0 + d3.2 * 2.0 + d4.2,
                )
            };
            let d = sum(&|s: &State| *s);
            x = add(&x, &d, h / 6.0);
            x.0 = x.0.normalize();
        }
        k += 1;
        let truth = &sim.groundtruth[k];
        max_p = max_p.max((x.1 - truth.position).norm());
        max_r = max_r.max(UnitQuaternion::from_quaternion(x.0).angle_to(&truth.rotation));
    }
    (max_p, max_r)
}

#[test]
fn noise_free_imu_samples_integrated_independently_reproduce_the_trajectory() -> TestResult {
    // Given noise-free, bias-free samples at 400 Hz and at 200 Hz
    for rate in [400.0, 200.0] {
        let mut config = short_config(7).without_noise();
        config.imu.rate_hz = rate;
        let sim = simulate_pose_imu(&config)?;
        // When an independent RK4 integrator takes them as instantaneous readings
        let (position, rotation) = rk4_tracking_error(&sim, 10.0, 0.0);
        // Then it stays on the ground truth for 10 s. The linear interpolation between
        // readings is the only approximation, O(dt^2): measured 1.0 mm / 17 urad at 400 Hz,
        // 4.0 mm / 69 urad at 200 Hz; the bounds are 3x that.
        let scale = (400.0 / rate) * (400.0 / rate);
        assert!(
            position < 3e-3 * scale,
            "{rate} Hz: position error {position} m"
        );
        assert!(
            rotation < 5e-5 * scale,
            "{rate} Hz: rotation error {rotation} rad"
        );
        // And reading the same samples half a period late (the old midpoint convention)
        // is caught: the check can fail
        let half = 0.5 / rate;
        let (_, rotation_late) = rk4_tracking_error(&sim, 10.0, half);
        assert!(
            rotation_late > 10.0 * rotation,
            "{rate} Hz: a half-sample delay went unnoticed ({rotation_late} rad)"
        );
    }
    Ok(())
}

#[test]
fn imu_white_noise_has_the_stated_standard_deviation() -> TestResult {
    let config = SimConfig {
        duration_s: 30.0,
        ..SimConfig::default()
    };
    let sim = simulate_pose_imu(&config)?;
    let dt = 1.0 / config.imu.rate_hz;
    let (mut gyro, mut accel) = (Vec::new(), Vec::new());
    for k in 0..sim.imu.len() - 1 {
        let t = sim.seconds(sim.imu[k].stamp_ns);
        let truth = &sim.groundtruth[k];
        let g = sim.imu[k].gyro - sim.trajectory.body_rate(t) - truth.gyro_bias;
        let a = sim.imu[k].accel - sim.trajectory.specific_force(t) - truth.accel_bias;
        gyro.extend(g.iter());
        accel.extend(a.iter());
    }
    let gyro_expected = config.imu.gyroscope_noise_density / dt.sqrt();
    let accel_expected = config.imu.accelerometer_noise_density / dt.sqrt();
    assert!((std_dev(&gyro) / gyro_expected - 1.0).abs() < 0.03);
    assert!((std_dev(&accel) / accel_expected - 1.0).abs() < 0.03);

    let initial = &sim.groundtruth[0];
    assert!(initial.gyro_bias.norm() > 0.0 && initial.accel_bias.norm() > 0.0);
    Ok(())
}

#[test]
fn odometry_increment_noise_has_the_stated_standard_deviation() -> TestResult {
    let config = SimConfig::default();
    let sim = simulate_pose_imu(&config)?;
    let x = sim.t_imu_pose;
    let (mut rotation, mut translation) = (Vec::new(), Vec::new());
    for pair in sim.pose.windows(2) {
        let t_g_s = |stamp| sim.trajectory.isometry(sim.seconds(stamp)) * x;
        let truth = t_g_s(pair[0].stamp_ns).inverse() * t_g_s(pair[1].stamp_ns);
        let noisy = pair[0].isometry().inverse() * pair[1].isometry();
        rotation.extend(
            (truth.rotation.inverse() * noisy.rotation)
                .scaled_axis()
                .iter(),
        );
        translation.extend((noisy.translation.vector - truth.translation.vector).iter());
    }
    let rotation_ratio = std_dev(&rotation) / config.pose.rotation_noise_rad;
    let translation_ratio = std_dev(&translation) / config.pose.translation_noise_m;
    assert!((rotation_ratio - 1.0).abs() < 0.1, "{rotation_ratio}");
    assert!((translation_ratio - 1.0).abs() < 0.1, "{translation_ratio}");
    Ok(())
}

#[test]
fn irregular_rate_gap_and_other_rates_keep_stamps_ordered() -> TestResult {
    let mut config = short_config(8);
    config.pose.jitter_fraction = 0.2;
    config.pose.gap_s = Some((4.0, 6.0));
    let sim = simulate_pose_imu(&config)?;
    let times: Vec<f64> = sim.pose.iter().map(|r| sim.seconds(r.stamp_ns)).collect();
    assert!(times.iter().all(|t| !(4.0..=6.0).contains(t)));
    let mut irregular = false;
    for pair in times.windows(2) {
        let interval = pair[1] - pair[0];
        assert!(interval > 0.05, "{interval}");
        irregular |= (interval - 0.1).abs() > 0.01;
    }
    assert!(irregular);
    assert!(times.windows(2).any(|w| w[1] - w[0] > 1.9));

    for rate_hz in [5.0, 50.0] {
        let mut config = short_config(8);
        config.pose.rate_hz = rate_hz;
        let sim = simulate_pose_imu(&config)?;
        assert_eq!(sim.pose.len(), 12 * rate_hz as usize + 1);
    }
    Ok(())
}

#[test]
fn time_offset_shifts_the_sampled_pose() -> TestResult {
    let mut config = short_config(10).without_noise();
    config.pose.time_offset_s = -0.05;
    let origin = Isometry3::from_parts(
        Translation3::new(1.0, 2.0, 3.0),
        UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
    );
    config.pose.odom_origin = Some(origin);
    let sim = simulate_pose_imu(&config)?;
    // The first stamp whose IMU time t_S + t_d is inside the record is 0.1 s.
    assert_eq!(sim.pose[0].stamp_ns - DEFAULT_START_STAMP_NS, 100_000_000);
    assert!(distance(&sim.pose[0].isometry(), &origin) < 1e-15);
    assert!((sim.extrinsics().get("pose0").ok_or("pose0")?.timeshift_s + 0.05).abs() < 1e-15);
    Ok(())
}

#[test]
fn random_mounting_is_roughly_upside_down_and_within_30_cm() -> TestResult {
    for seed in 0..20 {
        let sim = simulate_pose_imu(&SimConfig {
            duration_s: 1.0,
            ..short_config(seed)
        })?;
        let z_of_sensor_in_imu = sim.t_imu_pose.rotation * Vector3::z();
        assert!(
            z_of_sensor_in_imu.z < -0.9,
            "seed {seed}: {z_of_sensor_in_imu}"
        );
        assert!(sim.t_imu_pose.translation.vector.amax() <= 0.3);
    }
    Ok(())
}

#[test]
fn invalid_options_are_rejected_with_their_name() {
    let mut config = SimConfig::default();
    config.pose.rate_hz = 0.0;
    let err = simulate_pose_imu(&config).err();
    assert!(matches!(
        err,
        Some(SimError::InvalidOption {
            option: "pose.rate_hz",
            ..
        })
    ));

    let mut config = SimConfig::default();
    config.pose.jitter_fraction = 0.6;
    assert!(simulate_pose_imu(&config).is_err());

    let config = SimConfig {
        duration_s: f64::NAN,
        ..SimConfig::default()
    };
    assert!(simulate_pose_imu(&config).is_err());
}
