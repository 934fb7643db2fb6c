//! The pose-IMU calibration on the data real odometry produces: f32 as on the firmware,
//! arbitrary odometry origins and absolute stamps, irregular rates, gaps, slow and fast
//! pose sensors.

#[path = "support/common.rs"]
mod common;

use common::*;
use msreg_host::calibrate::driver::report::PoseImuOptions;
use msreg_host::dataset::PoseRecord;
use msreg_host::sim::SimConfig;
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

fn config(seed: u64) -> SimConfig {
    let mut c = SimConfig {
        seed,
        ..SimConfig::default()
    };
    c.pose.time_offset_s = 0.012;
    c
}

#[test]
fn f32_filter_ends_within_0_02_deg_and_1_mm_of_f64() {
    for seed in [1, 2, 3] {
        let data = simulate(&config(seed));
        let c64 = calibrate::<f64>(&data, &PoseImuOptions::default());
        let c32 = calibrate::<f32>(&data, &PoseImuOptions::default());
        let d_rot = c64
            .t_imu_sensor
            .rotation
            .angle_to(&c32.t_imu_sensor.rotation)
            .to_degrees();
        let d_trans =
            (c64.t_imu_sensor.translation.vector - c32.t_imu_sensor.translation.vector).norm();
        println!(
            "seed {seed}: f32 - f64: {d_rot:.5} deg, {:.3} mm, {:.4} ms",
            d_trans * 1e3,
            (c32.time_offset_s - c64.time_offset_s) * 1e3
        );
        assert!(d_rot < 0.02, "seed {seed}: {d_rot} deg");
        assert!(d_trans < 1e-3, "seed {seed}: {d_trans} m");
        assert!(c32.report.converged, "{:?}", c32.report.reasons);
    }
}

#[test]
fn result_does_not_depend_on_odometry_origin_or_absolute_stamps() {
    let data = simulate(&config(7));
    // The same recording with the odometry re-expressed in another frame and every stamp
    // moved from ~1.7e18 ns to ~1e9 ns.
    let mut moved = data.clone();
    let origin = Isometry3::from_parts(
        Translation3::new(-1234.5, 678.9, 42.0),
        UnitQuaternion::from_euler_angles(2.0, -1.0, 0.5),
    );
    let shift = data.imu[0].stamp_ns - 1_000_000_000;
    for p in &mut moved.pose {
        let iso = origin * p.isometry();
        *p = PoseRecord::from_isometry(p.stamp_ns - shift, &iso);
    }
    for r in &mut moved.imu {
        r.stamp_ns -= shift;
    }
    let a = calibrate::<f64>(&data, &PoseImuOptions::default());
    let b = calibrate::<f64>(&moved, &PoseImuOptions::default());
    let d_rot = a
        .t_imu_sensor
        .rotation
        .angle_to(&b.t_imu_sensor.rotation)
        .to_degrees();
    let d_trans = (a.t_imu_sensor.translation.vector - b.t_imu_sensor.translation.vector).norm();
    let d_time = (a.time_offset_s - b.time_offset_s).abs();
    println!(
        "origin/stamp change moved the result by {d_rot:.2e} deg, {d_trans:.2e} m, {d_time:.2e} s"
    );
    // Only floating-point rounding of the re-expressed odometry may differ.
    assert!(
        d_rot < 1e-6 && d_trans < 1e-7 && d_time < 1e-9,
        "{d_rot} deg, {d_trans} m, {d_time} s"
    );
}

/// Runs a scenario over three seeds and checks the foundation's per-seed bounds.
fn assert_scenario(name: &str, edit: impl Fn(&mut SimConfig)) {
    for seed in [11, 12, 13] {
        let mut c = config(seed);
        edit(&mut c);
        let data = simulate(&c);
        let r = calibrate::<f64>(&data, &PoseImuOptions::default());
        let rot = rotation_error_deg(&r, &data.t_imu_pose);
        let trans = translation_error_m(&r, &data.t_imu_pose);
        let dt = (r.time_offset_s - data.time_offset_s).abs();
        println!(
            "{name} seed {seed}: rot {rot:.4} deg (3 sigma {:.4}), trans {:.2} mm (3 sigma {:.2}), time {:.3} ms, \
             NIS/dof {:.2}, rejected {}, skipped {}",
            3.0 * r.imu_sensor_estimate().sigma_rot_deg.amax(),
            trans * 1e3,
            3e3 * r.imu_sensor_estimate().sigma_trans_m.amax(),
            dt * 1e3,
            r.report.mean_nis_per_dof,
            r.report.updates_rejected,
            r.report.poses_skipped.len()
        );
        assert!(
            r.report.converged,
            "{name} seed {seed}: {:?}",
            r.report.reasons
        );
        assert!(
            rot < 0.25 && trans < 0.006 && dt < 1e-3,
            "{name} seed {seed}"
        );
        assert!(
            inside_three_sigma(&r, &data.t_imu_pose),
            "{name} seed {seed}: outside 3 sigma"
        );
    }
}

#[test]
fn irregular_odometry_rate_is_handled() {
    assert_scenario("jitter 20 %", |c| c.pose.jitter_fraction = 0.2);
}

#[test]
fn odometry_gap_is_bridged() {
    assert_scenario("gap 20-23 s", |c| c.pose.gap_s = Some((20.0, 23.0)));
}

/// Odometry drift grows with time, not with the number of increments: a sensor at `rate_hz`
/// has the 10 Hz noise per increment scaled by `sqrt(10 / rate_hz)`.
fn set_rate(c: &mut SimConfig, rate_hz: f64) {
    let scale = (10.0 / rate_hz).sqrt();
    c.pose.rate_hz = rate_hz;
    c.pose.rotation_noise_rad *= scale;
    c.pose.translation_noise_m *= scale;
}

#[test]
fn slow_pose_sensor_at_5_hz() {
    assert_scenario("5 Hz", |c| set_rate(c, 5.0));
}

#[test]
fn fast_pose_sensor_at_50_hz() {
    assert_scenario("50 Hz", |c| set_rate(c, 50.0));
}
