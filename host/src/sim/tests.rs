//! Behaviour of the whole simulator: determinism, exactness of the noise-free
//! data against the filter's models, stated noise levels and the written layout.

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
        .and_then(|e| e.pose0)
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

#[test]
fn noise_free_imu_integrated_with_the_midpoint_rule_tracks_ground_truth() -> TestResult {
    let sim = simulate_pose_imu(&short_config(7).without_noise())?;
    let gravity = gravity_in_g();
    let first = sim.groundtruth.first().ok_or("no ground truth")?;
    let (mut r, mut p, mut v) = (first.rotation, first.position, first.velocity);
    let (mut max_position_error, mut max_rotation_error) = (0.0_f64, 0.0_f64);
    let steps = 10 * 400;
    for k in 0..steps {
        let sample = &sim.imu[k];
        let dt = sim.seconds(sim.imu[k + 1].stamp_ns) - sim.seconds(sample.stamp_ns);
        let r_mid = r * UnitQuaternion::from_scaled_axis(sample.gyro * (0.5 * dt));
        let a = r_mid * sample.accel + gravity;
        p += v * dt + a * (0.5 * dt * dt);
        v += a * dt;
        r *= UnitQuaternion::from_scaled_axis(sample.gyro * dt);

        let truth = &sim.groundtruth[k + 1];
        max_position_error = max_position_error.max((p - truth.position).norm());
        max_rotation_error = max_rotation_error.max(r.angle_to(&truth.rotation));
    }
    assert!(
        max_position_error < 2e-3,
        "position error {max_position_error} m"
    );
    assert!(
        max_rotation_error < 5e-5,
        "rotation error {max_rotation_error} rad"
    );
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
        let t_mid = 0.5 * (sim.seconds(sim.imu[k].stamp_ns) + sim.seconds(sim.imu[k + 1].stamp_ns));
        let truth = &sim.groundtruth[k];
        let g = sim.imu[k].gyro - sim.trajectory.body_rate(t_mid) - truth.gyro_bias;
        let a = sim.imu[k].accel - sim.trajectory.specific_force(t_mid) - truth.accel_bias;
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
    assert!((sim.extrinsics().pose0.ok_or("pose0")?.timeshift_s + 0.05).abs() < 1e-15);
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
